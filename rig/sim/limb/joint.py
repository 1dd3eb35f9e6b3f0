""":class:`SimulatedJoint`: a simulated patient's limb of one joint (by default a shoulder below
the thorax), composed of its parts.

- the thorax's posture and the shoulder's free motion and stop at the limits
  (:mod:`rig.sim.limb.motion`: :class:`~rig.sim.limb.motion.Posture`,
  :class:`~rig.sim.limb.motion.JointMotion`, the smoothing
  :class:`~rig.sim.limb.motion.SmoothPath`);
- what the patient does when (:mod:`rig.sim.limb.schedule`: the calibration protocol, the
  neutral checkpoints);
- the sensors (:mod:`rig.sim.limb.sensors`: placement, error processes, raw readings).

The joint orientation at time ``t`` is ``SmoothPath(P(schedule.target(t, free(t))))``, then
``P`` once more (``P``: :meth:`~rig.sim.limb.motion.JointMotion.project`); each sensor's true
orientation ``thorax(t) ⊗ [joint(t) ⊗] mount``, its readings that through the error model.

Random streams, all from ``seed`` (so every output is reproducible): the motion's sinusoids,
then the default mountings, then the sensor errors draw from the seeded generator in that
order; the neutral poses and the accelerometer/magnetometer noise have seed sequences of their
own derived from the generator's (nothing drawn from it).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from calibration.protocol import CalibrationProtocol
from models.constraint import JointConstraint
from rig.sim.limb.base import (
    SimulatedLimb,
    SimulatedState,
    default_world_from_root,
    forwarded,
    seeded,
)
from rig.sim.limb.motion import JointMotion, Posture, Sinusoids, SmoothPath
from rig.sim.limb.schedule import NeutralCheckpoints, NeutralPoses, Schedule
from rig.sim.limb.sensors import (
    NoiseModel,
    SensorErrors,
    SensorMount,
    SensorPlacement,
    default_mounts,
    misplaced_mounts,
)

__all__ = ["DEFAULT_CONSTRAINT", "JointState", "SimulatedJoint"]


DEFAULT_CONSTRAINT = JointConstraint.cone((1.0, 0.0, 0.0), 60.0, twist=(-45.0, 45.0),
                                          name="default-cone")
"""The range of motion of a :class:`SimulatedJoint` given none: 60° cone about +X, twist ±45°."""


@dataclass(frozen=True)
class JointState(SimulatedState):
    """Ground truth of a one-joint limb at times ``t`` (N,).

    Attributes
    ----------
    t : (N,) float64, seconds since the simulation started
    joint : (N, 4) float64, limb relative to thorax
    thorax : (N, 4) float64, thorax relative to world
    sensors : (N, S, 4) float64, each sensor relative to world (error-free)
    """

    t: np.ndarray
    joint: np.ndarray
    thorax: np.ndarray
    sensors: np.ndarray


class SimulatedJoint(SimulatedLimb):
    """A limb of one joint (a shoulder by default): its motion, sensor placement and sensor
    errors; seeded and reproducible.

    Parameters
    ----------
    constraint : JointConstraint, optional
        The patient's range of motion (limb relative to thorax); default
        :data:`DEFAULT_CONSTRAINT`. Motion outside it is projected onto it by
        :class:`models.oracle.ConstraintOracle`.
    centre, reach_deg, twist_deg : optional
        Centre (thorax frame), reach and twist interval of the motion; default from the
        constraint (:class:`~rig.sim.limb.motion.JointMotion`).
    excursion : float
        RMS of the raw motion relative to the reach (1.0: outside the range ~1/3 of the time).
    speed : float
        Multiplies all motion frequencies (1.0: 0.03-0.3 Hz components).
    sensors : int or sequence of SensorMount
        Number of sensors (placed by :func:`~rig.sim.limb.sensors.default_mounts`) or explicit
        mountings.
    noise : NoiseModel
    world_from_thorax : (4,) array_like, optional
        Fixed part of the thorax orientation relative to world (default: heading 35°, and a
        90° pitch so that the limb axis +X hangs down at the identity joint orientation).
    sway_deg : float
        Amplitude of the thorax's postural sway.
    seed : int or numpy Generator
        Seeds motion, mountings and errors.
    calibration_protocol : CalibrationProtocol, optional
        The guided calibration the patient performs before moving freely
        (:mod:`rig.sim.limb.schedule`); None (default): free motion from time 0.
    protocol_start_s : float
        Patient time (s) at which the protocol starts; before it the patient stands in the
        neutral pose (sensors strapped, fusion calibrating).
    blend_s : float
        Length of the hand-over from the protocol's last pose to the free motion, seconds.
    neutral_every_s : float
        Interval between neutral checkpoints, seconds (:mod:`rig.sim.limb.schedule`); 0
        (default): none, and the motion is exactly that of a limb without checkpoints.
        Otherwise at least ``2 * neutral_ramp_s + neutral_hold_s + 1``.
    neutral_hold_s : float
        How long the patient holds the neutral pose at each checkpoint, seconds (> 0).
    neutral_ramp_s : float
        How long the patient takes to move into and out of the neutral pose, seconds (> 0).
    neutral_sd_deg : float
        The patient's repeatability of the neutral pose: standard deviation of its axial
        rotation, degrees (>= 0; the two swing components have half of it).
    limb_lever_m : float
        Distance of every limb sensor from the shoulder centre along the limb axis, metres
        (the shoulder centre is fixed in the world); sets the accelerometer's linear
        acceleration.
    thorax_lever_m : float
        Height of the thorax sensor above a world-fixed pelvis pivot (along the thorax's −X,
        superior), metres.
    smooth_s : float
        Knot spacing of the motion's B-spline, seconds (:mod:`rig.sim.limb.motion`).

    Attributes
    ----------
    motion : JointMotion
        The shoulder's free motion and its stop at the limits.
    posture : Posture
        The thorax relative to world.
    schedule : Schedule
        What the patient does when (replaced by :meth:`perform_protocol`).
    placement : SensorPlacement
        Where the sensors sit.
    sensor_errors : SensorErrors
        The sensors' error processes (stateful: :meth:`measure` times must not go back).
    """

    def __init__(
        self,
        constraint: JointConstraint | None = None,
        *,
        centre: Sequence[float] | None = None,
        reach_deg: float | None = None,
        twist_deg: tuple[float, float] | None = None,
        excursion: float = 1.0,
        speed: float = 1.0,
        sensors: int | Sequence[SensorMount] = 2,
        noise: NoiseModel | None = None,
        world_from_thorax: Sequence[float] | None = None,
        sway_deg: float = 2.0,
        seed: int | np.random.Generator | None = 0,
        calibration_protocol=None,
        protocol_start_s: float = 2.0,
        blend_s: float = 3.0,
        neutral_every_s: float = 0.0,
        neutral_hold_s: float = 2.0,
        neutral_ramp_s: float = 1.5,
        neutral_sd_deg: float = 2.0,
        limb_lever_m: float = 0.15,
        thorax_lever_m: float = 0.3,
        smooth_s: float = 0.04,
    ) -> None:
        rng, seed_seq = seeded(seed)
        checkpoints = NeutralCheckpoints(neutral_every_s, neutral_hold_s, neutral_ramp_s)
        if constraint is None:
            constraint = DEFAULT_CONSTRAINT
        self.check_limits(constraint, "constraint")
        if not excursion > 0 or not speed > 0:
            raise ValueError("excursion and speed must be > 0")
        # (row, component) sinusoids: swing u, swing v, twist, sway x, sway y
        series = Sinusoids.draw(rng, 5, speed)
        self.motion = JointMotion(constraint, series.rows(0, 3), centre=centre,
                                  reach_deg=reach_deg, twist_deg=twist_deg, excursion=excursion)
        self._neutral = NeutralPoses(neutral_sd_deg, seed_seq, self.motion.limb_axis)
        if world_from_thorax is None:
            world_from_thorax = default_world_from_root()
        self.posture = Posture(world_from_thorax, sway_deg, series.rows(3, 5))
        mounts = default_mounts(sensors, rng) if isinstance(sensors, int) else list(sensors)
        self.placement = SensorPlacement(mounts, self.motion.limb_axis, limb_lever_m,
                                         thorax_lever_m)
        self._schedule = Schedule(blend_s=blend_s, checkpoints=checkpoints)
        if calibration_protocol is not None:
            self.perform_protocol(calibration_protocol, protocol_start_s)
        self.noise = noise if noise is not None else NoiseModel()
        self.sensor_errors = SensorErrors(self.noise, self.placement, rng, seed_seq)
        self._path = SmoothPath(smooth_s)

    limits_type = JointConstraint

    @classmethod
    def calibration_protocol_for(cls, limits: JointConstraint) -> CalibrationProtocol:
        """A joint's guided calibration (:class:`calibration.protocol.CalibrationProtocol`)."""
        return CalibrationProtocol()

    @classmethod
    def misplaced_straps(cls, limits: JointConstraint, rng: np.random.Generator,
                         misplace_deg: float) -> list[SensorMount]:
        """Two sensors, thorax and limb (:func:`~rig.sim.limb.sensors.misplaced_mounts`)."""
        return misplaced_mounts(rng, misplace_deg)

    @classmethod
    def from_constraint(cls, constraint: JointConstraint, **kwargs) -> SimulatedJoint:
        """A limb whose range of motion is ``constraint`` (same as ``SimulatedJoint(constraint,
        **kwargs)``)."""
        return cls(constraint, **kwargs)

    # -- the parts' parameters, as attributes of the patient --------------------------------
    constraint = forwarded("motion.constraint", "The range of motion (JointConstraint).")
    oracle = forwarded("motion.oracle", "Its exact oracle (models.oracle.ConstraintOracle).")
    limb_axis = forwarded("motion.limb_axis", "The limb's long axis (3,), limb frame.")
    centre = forwarded("motion.centre", "Centre of the motion (3,), thorax frame.")
    reach = forwarded("motion.reach", "Reach of the motion from its centre, radians.")
    twist_centre = forwarded("motion.twist_centre", "Middle of the twist explored, radians.")
    twist_half = forwarded("motion.twist_half", "Half the twist range explored, radians.")
    excursion = forwarded("motion.excursion", "RMS of the raw motion relative to the reach.")
    world_from_thorax = forwarded("posture.world_from_root",
                                  "Fixed part of the thorax relative to world (4,).")
    mounts = forwarded("placement.mounts", "Where the sensors sit (list of SensorMount).")
    limb_lever_m = forwarded("placement.limb_lever_m", "Limb sensors' lever arm, metres.")
    thorax_lever_m = forwarded("placement.thorax_lever_m", "Thorax sensor's lever arm, metres.")
    schedule = forwarded("_schedule", "What the patient does when (Schedule).")
    calibration_protocol = forwarded("_schedule.protocol",
                                     "The protocol the patient performs, or None.")
    neutral_sd_deg = forwarded("_neutral.sd_deg",
                               "Repeatability of the neutral pose (axial rotation SD), degrees.")

    # -- schedule -------------------------------------------------------------------------
    def perform_protocol(self, protocol, start_s: float = 2.0) -> None:
        """Have the patient perform ``protocol`` from patient time ``start_s`` (seconds).

        Changes the motion at every time: call it before the simulator has sampled times after
        ``min(start_s, now)`` (a servo simulator back-driven by this limb samples lazily, so
        setting it at once after opening the port is enough when ``start_s`` lies ahead).
        ``protocol=None`` returns to free motion from time 0.
        """
        # one assignment: the simulator threads see either the old or the new schedule
        self._schedule = self._schedule.with_protocol(protocol, start_s)

    def neutral_poses(self, k) -> np.ndarray:
        """Neutral pose (joint orientation, before the oracle's projection) of checkpoints
        ``k`` (int or (K,) ints >= 1), (K, 4): the identity perturbed by the patient's
        repeatability (:mod:`rig.sim.limb.schedule`). Deterministic per seed and checkpoint."""
        return self._neutral(k)

    # -- ground truth ---------------------------------------------------------------------
    def raw_joint(self, t) -> np.ndarray:
        """Unconstrained joint orientation (N, 4) at times ``t`` (N,) seconds, before projection."""
        return self.motion.free(t)

    def project(self, q) -> np.ndarray:
        """Orientations (N, 4) brought into the range the way the patient's arm stops
        (:meth:`rig.sim.limb.motion.JointMotion.project`)."""
        return self.motion.project(q)

    def target(self, t) -> np.ndarray:
        """The patient's target (N, 4) at times ``t`` (N,) seconds before the smoothing: the
        free motion with the protocol and the neutral checkpoints blended in, projected into
        the range — the motion's B-spline control points are its values on the knot grid."""
        t = np.atleast_1d(np.asarray(t, dtype=np.float64))
        return self._target(t, self._schedule)

    def _target(self, t: np.ndarray, schedule: Schedule) -> np.ndarray:
        return self.motion.project(schedule.target(t, self.motion.free(t), self._neutral))

    def joint(self, t) -> np.ndarray:
        """Joint orientation (N, 4), limb relative to thorax, inside the range of motion
        (after the calibration protocol when the patient performs one; in the neutral pose at
        the neutral checkpoints when ``neutral_every_s > 0``), at times ``t`` (N,) seconds.

        The uniform cubic B-spline (knots every ``smooth_s``) whose control points are
        :meth:`target` on the global grid ``i · smooth_s``, projected once more into the range
        (:mod:`rig.sim.limb.motion`): twice continuously differentiable wherever that last
        projection does nothing. Stateless: the value at a time does not depend on what else
        is evaluated, or in which order."""
        t = np.atleast_1d(np.asarray(t, dtype=np.float64))
        if not len(t):
            return np.empty((0, 4))
        schedule = self._schedule  # one snapshot: a protocol set meanwhile applies next call
        q = self._path(t, lambda ts: self._target(ts, schedule), schedule)
        return self.motion.project(q)

    def joints(self, t) -> np.ndarray:
        """The posture (N, 1, 4) at times ``t`` (N,): :meth:`joint` as a limb of one joint
        (:meth:`SimulatedWholeLimb.joints <rig.sim.limb.SimulatedWholeLimb.joints>`' shape)."""
        return self.joint(t)[:, None]

    def thorax(self, t) -> np.ndarray:
        """Thorax relative to world (N, 4) at times ``t`` (N,)."""
        return self.posture(t)

    def truth(self, t) -> JointState:
        """Error-free state at times ``t`` (scalar or (N,), seconds)."""
        t = np.atleast_1d(np.asarray(t, dtype=np.float64))
        joint = self.joint(t)
        thorax = self.thorax(t)
        return JointState(t=t, joint=joint, thorax=thorax,
                          sensors=self.placement.orientations(thorax, joint))
