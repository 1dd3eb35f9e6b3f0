""":class:`SimulatedLimb`: what every simulated patient's limb is — one or more joints below a
root segment (the thorax, the pelvis), IMUs strapped on its segments, seeded and reproducible.

Two limbs derive from it: :class:`rig.sim.limb.joint.SimulatedJoint`, a limb of one joint (by
default a shoulder below the thorax) moving inside a :class:`models.constraint.JointConstraint`,
and :class:`rig.sim.limb.whole.SimulatedWholeLimb`, a whole arm or leg (three joints, four
segments) inside a :class:`models.limb.Limb`. They move differently (a whole limb follows its
targets at a speed limit and stops against coupled limits; a one-joint limb's motion is older
and its recordings are kept bit for bit), so each draws and moves its joints itself; what they
share is here: the seeded random streams, the root's posture, the schedule's times (calibration
protocol, neutral checkpoints), the smoothing's knot spacing and the sensors' readings
(:meth:`SimulatedLimb.measure`, :meth:`SimulatedLimb.measure_many`).
"""

from __future__ import annotations

import math
import operator
from dataclasses import dataclass, fields

import numpy as np

from models import quaternion as Q
from rig.sim.limb.sensors import RAW_STEP_S, Readings, SensorMount

__all__ = ["Measurement", "SimulatedLimb", "SimulatedState", "default_world_from_root",
           "forwarded", "seeded"]

_Y = np.array([0.0, 1.0, 0.0])
_Z = np.array([0.0, 0.0, 1.0])


def forwarded(path: str, doc: str) -> property:
    """A read-only attribute of a patient read from one of its parts.

    Parameters
    ----------
    path : str
        Dotted attribute path from the patient (``"motion.centre"``).
    doc : str
        The attribute's docstring.

    Returns
    -------
    property
    """
    get = operator.attrgetter(path)
    return property(get, doc=doc)


def seeded(seed: int | np.random.Generator | None) -> tuple[np.random.Generator,
                                                            np.random.SeedSequence]:
    """The patient's generator and the seed sequence its derived streams spawn from.

    Parameters
    ----------
    seed : int, numpy Generator or None
        An int (or None) seeds a new generator; a generator is used as it is.

    Returns
    -------
    rng : numpy.random.Generator
        Draws the motion, the default mountings and the sensor errors, in that order.
    seed_seq : numpy.random.SeedSequence
        The generator's own seed sequence (``SeedSequence(0)`` when it has none): the neutral
        poses and the raw readings' noise derive theirs from it without drawing from ``rng``.
    """
    rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
    # the derived streams' seed sequence: from the seed, without drawing from it
    ss = getattr(rng.bit_generator, "seed_seq", None)
    seed_seq = ss if isinstance(ss, np.random.SeedSequence) else np.random.SeedSequence(0)
    return rng, seed_seq


def default_world_from_root() -> np.ndarray:
    """The root segment's fixed orientation relative to world when none is given: heading 35°,
    and a 90° pitch so that the limb's +X hangs down at the identity joint orientation.

    Returns
    -------
    (4,) float64, scalar-first
    """
    return Q.multiply(Q.from_axis_angle(_Z, math.radians(35.0)),
                      Q.from_axis_angle(_Y, math.radians(90.0)))


@dataclass(frozen=True)
class SimulatedState:
    """Ground truth at times ``t`` (N,): every field an array over the N instants."""

    def rows(self, a: int, b: int) -> SimulatedState:
        """The instants ``a:b`` of every field."""
        return type(self)(**{f.name: getattr(self, f.name)[a:b] for f in fields(self)})


@dataclass(frozen=True)
class Measurement:
    """What the sensors report at one instant ``t`` (seconds).

    Attributes
    ----------
    quaternions : (S, 4) float64, unit, sensor relative to world, with errors
    gyro : (S, 3) float64, rad/s, sensor frame
    calibration : (S,) int, ``CALIB_STAT`` bytes
    truth : SimulatedState with N = 1 (the limb's: joint or whole limb)
    accel : (S, 3) float64, m/s², sensor frame: specific force (+9.81 along world up at rest)
    mag : (S, 3) float64, µT, sensor frame
    """

    t: float
    quaternions: np.ndarray
    gyro: np.ndarray
    calibration: np.ndarray
    truth: SimulatedState
    accel: np.ndarray
    mag: np.ndarray


class SimulatedLimb:
    """A simulated patient's limb of one or more joints carrying IMUs (abstract).

    A subclass sets ``posture`` (:class:`~rig.sim.limb.motion.Posture`), ``noise``,
    ``sensor_errors`` (:class:`~rig.sim.limb.sensors.SensorErrors`), ``_path``
    (:class:`~rig.sim.limb.motion.SmoothPath`) and ``mounts``, and implements
    :attr:`schedule`, :attr:`calibration_protocol`, :meth:`perform_protocol`, :meth:`truth`
    (a :class:`SimulatedState` with a ``sensors`` field (N, S, 4)) and, when its sensors' lever
    arms move with the joints, :meth:`_positions`; and says what it wears: its
    :attr:`limits_type`, what a seeded patient wearing such limits performs
    (:meth:`calibration_protocol_for`) and where its straps sit (:meth:`misplaced_straps`) —
    :func:`rig.sim.patients.seeded_patient` chooses the limb by them, no one asks "a joint or
    a whole limb?".
    """

    limits_type: type
    """The limits the limb moves inside (a joint's constraint, a limb file's limits)."""

    @classmethod
    def check_limits(cls, limits, name: str):
        """``limits`` as given, if they are what the limb wears (:attr:`limits_type`).

        Parameters
        ----------
        limits : object
        name : str
            The argument's name, for the error.

        Raises
        ------
        TypeError
            Anything else: names the argument and the type expected.
        """
        expected = cls.limits_type
        if not isinstance(limits, expected):
            raise TypeError(f"{name} must be a {expected.__module__}.{expected.__qualname__}, "
                            f"got {type(limits).__name__}")
        return limits

    @classmethod
    def calibration_protocol_for(cls, limits):
        """The guided calibration protocol a patient wearing ``limits`` performs."""
        raise NotImplementedError

    @classmethod
    def misplaced_straps(cls, limits, rng: np.random.Generator,
                         misplace_deg: float) -> list[SensorMount]:
        """The sensors a patient wearing ``limits`` is given, each strap turned
        ``misplace_deg`` about an axis drawn from ``rng``."""
        raise NotImplementedError

    # -- the schedule's times, as attributes of the patient ------------------------------------
    protocol_start_s = forwarded("schedule.start_s",
                                 "Patient time (s) at which the protocol starts; 0 without one.")
    protocol_end_s = forwarded("schedule.protocol_end_s",
                               "Patient time at which the protocol has ended (free motion, "
                               "blended, follows); 0 without a protocol.")
    blend_s = forwarded("schedule.blend_s", "Length of the protocol's hand-over, seconds.")
    neutral_every_s = forwarded("schedule.checkpoints.every_s",
                                "Interval between neutral checkpoints, seconds (0: none).")
    neutral_hold_s = forwarded("schedule.checkpoints.hold_s",
                               "How long each neutral pose is held, seconds.")
    neutral_ramp_s = forwarded("schedule.checkpoints.ramp_s",
                               "How long the patient takes into and out of it, seconds.")
    neutral_start_s = forwarded("schedule.neutral_start_s",
                                "Patient time from which neutral checkpoints are counted: the "
                                "end of the protocol's hand-over to free motion "
                                "(protocol_end_s + blend_s), or 0 without a protocol. "
                                "Checkpoint k holds from neutral_start_s + k * neutral_every_s.")
    smooth_s = forwarded("_path.step_s", "Knot spacing of the motion's B-spline, seconds.")

    @property
    def schedule(self):
        """What the patient does when (:class:`~rig.sim.limb.schedule.Schedule`; a whole
        limb's proximal joint's, every joint's having the same times)."""
        raise NotImplementedError

    @property
    def n_sensors(self) -> int:
        """How many sensors the patient wears."""
        return len(self.mounts)

    def neutral_windows(self, t_end: float) -> np.ndarray:
        """Hold windows ``[t_k, t_k + neutral_hold_s]`` (K, 2) of the neutral checkpoints
        ``k = 1, 2, ...`` that end by patient time ``t_end`` (seconds); ``(0, 2)`` when
        ``neutral_every_s`` is 0."""
        return self.schedule.neutral_windows(t_end)

    def truth(self, t) -> SimulatedState:
        """Error-free state at times ``t`` (scalar or (N,), seconds)."""
        raise NotImplementedError

    def _positions(self, truth: SimulatedState) -> np.ndarray | None:
        """Each sensor's world position (3N, S, 3) at the instants of ``truth``, or None when
        the sensors' lever arms are fixed (:class:`~rig.sim.limb.sensors.SensorPlacement`)."""
        return None

    # -- measurements ---------------------------------------------------------------------
    def measure(self, t: float, calibration_elapsed_s: float | None = None) -> Measurement:
        """Sensor outputs at time ``t`` (seconds; calls must not go back in time).

        Parameters
        ----------
        t : float
            Simulation time, seconds.
        calibration_elapsed_s : float, optional
            Time the sensors have been fusing (calibration progress); default ``t``.
        """
        t = float(t)
        h = RAW_STEP_S
        truth = self.truth(np.array([t, t + h, t - h]))
        elapsed = t if calibration_elapsed_s is None else calibration_elapsed_s
        r = self.sensor_errors.one(t, truth.sensors, elapsed, positions=self._positions(truth))
        return Measurement(t=t, quaternions=r.quaternions[0], gyro=r.gyro[0],
                           calibration=r.calibration[0], truth=truth.rows(0, 1),
                           accel=r.accel[0], mag=r.mag[0])

    def measure_many(self, ts) -> list[Measurement]:
        """Sensor outputs at increasing times ``ts`` (K,) seconds, vectorised.

        The same error process as ``K`` calls of :meth:`measure` (same models and parameters;
        the random draws are made in another order, so the numbers differ), at a fraction of
        the cost: what a stream device producing hundreds of samples per second needs.
        """
        ts = np.atleast_1d(np.asarray(ts, dtype=np.float64))
        k = len(ts)
        if k == 0:
            return []
        h = RAW_STEP_S
        truth = self.truth(np.concatenate((ts, ts + h, ts - h)))
        s = truth.sensors
        pos = self._positions(truth)
        if pos is not None:
            pos = pos.reshape(3, k, -1, 3)
        r: Readings = self.sensor_errors.many(ts, s[:k], s[k:2 * k], s[2 * k:], positions=pos)
        return [Measurement(t=float(ts[i]), quaternions=r.quaternions[i], gyro=r.gyro[i],
                            calibration=r.calibration[i], truth=truth.rows(i, i + 1),
                            accel=r.accel[i], mag=r.mag[i])
                for i in range(k)]
