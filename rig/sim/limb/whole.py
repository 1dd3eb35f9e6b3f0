""":class:`SimulatedWholeLimb`: a simulated patient's whole arm or leg — four segments, three
joints, an IMU on each segment — moving inside a known limb constraint (:class:`models.limb.Limb`).

Frames (rig segment frames, :mod:`calibration.frames`, :mod:`calibration.joint_angles`)
---------------------------------------------------------------------------------------
Segments, proximal to distal: thorax, upper arm, forearm, hand (arm) or pelvis, thigh, shank,
foot (leg). Every segment has +X along it distally, +Y anterior, +Z to the body's right; the
foot +X to the toes, +Y superior. Joint ``j`` (shoulder, elbow, wrist / hip, knee, ankle) is
its child segment relative to its parent, ``q_j`` (the limb file's orientation). The root
segment (thorax or pelvis) relative to world is :class:`~rig.sim.limb.motion.Posture`: a fixed
orientation (default: heading 35°, and a 90° pitch so that +X hangs down) times a slow sway.
Segment ``k``'s orientation is ``root(t) ⊗ q_0 ⊗ … ⊗ q_{k−1}``; sensor ``i`` strapped on segment
``k`` with the mounting ``mount_i`` (:class:`~rig.sim.limb.sensors.SensorMount`, its ``segment``
the segment's name) is at ``root(t) ⊗ q_0 ⊗ … ⊗ q_{k−1} ⊗ mount_i``.

Motion (the shoulder patient's recipe, :mod:`rig.sim.limb.motion`, on every joint)
----------------------------------------------------------------------------------
- **Free motion.** A ball or two-axis joint swings about a motion centre (the mean direction of
  its loosest keyframe's region) with seeded sinusoids as
  :class:`~rig.sim.limb.motion.JointMotion`'s (RMS ``excursion`` times the region's reach, at
  most 90°; twist about the middle of its interval, RMS ``excursion`` times half of it); a
  hinge turns about its axis, ``mid + excursion · half · x(t)`` over its interval (a forearm
  joint likewise about its flexion axis, then about the limb axis over its rotation
  interval, each from its own sinusoid: ``F(θ(t)) ⊗ R(φ(t))``); a hinge's
  angle and a twist saturate smoothly 170° from the middle (never through the middle of the
  excluded arc, where the clamp would change ends). With ``excursion = 1`` every joint is
  pushed beyond its limits often, independently, so the patient presses into every limit,
  the coupled ones at many knee or elbow angles.
- **Stop at the limits.** A swing direction outside its region moves back along the great
  circle towards the motion centre onto the boundary (bisection on the limb oracle's verdict,
  the other joints as the oracle corrects them: a coupled region at its hinge's corrected
  angle), then the exact hierarchical projection of the limb oracle
  (:meth:`models.oracle.ConstraintOracle.project`: the hinge first, the joints coupled to it
  against their limits at the corrected hinge angle; the twist clamp). The oracle's nearest
  point alone jumps where a target crosses the medial axis of a concave notch or of a region's
  excluded cap (a shoulder's): measured on seeds 3, 5, 8 at 50 Hz over 240 s, the leg's joints
  then move at most 250-490°/s (p99 135-260°/s); the shoulder at p99 250-300°/s with a few
  samples in a thousand above 500°/s, where the arm, raised overhead, passes near the limb
  axis's antipode and the swing-twist decomposition (hence the twist limit) turns fast.
- **Following.** :class:`~rig.sim.limb.motion.RateLimit` on the knot grid (every
  ``smooth_s``): the limb is on the projected target while the arc to the next one stays in
  range, and otherwise moves towards it at most ``max_speed_dps`` per joint (400°/s), around
  the range in steps of 1° each brought into it by the oracle's nearest point. The target
  itself can jump (the radial stop where a ray grazes a non-star-shaped region, a coupled
  region changing with its hinge, the swing-twist decomposition near the limb axis's
  antipode): measured on arm 102 before the follower, joint speeds of 3,100°/s for a few
  samples, gyroscope readings of 3,270°/s and specific forces of 7,800 m/s², which a host
  fusion could not follow (tilt 30-77° off for a minute).
- **Smoothing.** :class:`~rig.sim.limb.motion.SmoothPath`: the uniform cubic B-spline through
  the followed knots, each joint splined on its own, normalised — and **not** projected again:
  the nearest point of a spline value outside jumps across a notch's medial axis (0.7-2.7° in
  a sample on arm 101; a position step a few milliseconds wide is a spike of thousands of
  m/s² at an accelerometer, and biases a fusion's tilt for seconds). So the limb overshoots
  its limits a little where the spline rounds a corner or slides along a concave limit, as
  soft tissue gives: on arms and legs 101-103 over 300 s, 1-5 % of the samples lie outside by
  more than 0.01°, p99 of those 0.24-0.73°, at most 1.4°; hinges never. Stateless: a value does
  not depend on what else is evaluated (the knots are computed in order from the start and
  kept).
- **Schedule.** :class:`~rig.sim.limb.schedule.Schedule` per joint: the calibration protocol
  (:class:`calibration.protocol.LimbCalibrationProtocol`: neutral pose, then each joint's
  flexion/extension; a single-joint :class:`~calibration.protocol.CalibrationProtocol` is
  performed by the proximal joint, the others at their neutral) from ``protocol_start_s``, the
  neutral pose before it, a smoothstep hand-over to free motion over ``blend_s``; optional
  neutral checkpoints, each joint's neutral pose (clinical zero,
  :func:`calibration.joint_angles.from_angles`) perturbed by the patient's repeatability. The
  scripted poses go through the projection too: the patient performs them within its limits.

Sensors (:mod:`rig.sim.limb.sensors`)
-------------------------------------
The same error processes as the shoulder patient's (:class:`~rig.sim.limb.sensors.SensorErrors`:
white noise, drift, magnetic disturbances, calibration status, raw gyroscope, accelerometer and
magnetometer). The accelerometers' linear acceleration comes from the limb's geometry: the
proximal joint centre (shoulder, hip) is fixed in the world, as the shoulder patient's is;
segment ``k ≥ 1``'s sensor sits half-way along it, at ``Σ_{m<k} R_m L_m x̂ + R_k L_k x̂ / 2``
from that centre (``R_m`` segment ``m``'s orientation, ``L_m`` its length,
:data:`SEGMENT_LENGTHS_M`: upper arm 0.30 m, forearm 0.26, hand 0.08; thigh 0.43, shank 0.42,
foot 0.15); the root's sensor its length above a world-fixed pivot (thorax 0.30 m, pelvis
0.15 m; along the root's −X, superior).

Random streams, all from ``seed``: the motion's sinusoids, then the sensor errors draw from the
seeded generator in that order; the neutral poses and the accelerometer/magnetometer noise have
seed sequences of their own (nothing drawn from the generator). Misplaced straps are drawn by
the caller (:func:`limb_mounts`; :meth:`SimulatedWholeLimb.misplaced_straps`, which
:func:`rig.sim.patients.seeded_patient` calls).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from calibration.protocol import LimbCalibrationProtocol
from models import quaternion as Q
from models.constraint import JointConstraint
from models.limb import Limb
from models.limits import ConeSwing, PolygonSwing
from models.oracle import ConstraintOracle
from rig.sim.limb.base import (
    SimulatedLimb,
    SimulatedState,
    default_world_from_root,
    seeded,
)
from rig.sim.limb.motion import JointMotion, Posture, RateLimit, Sinusoids, SmoothPath
from rig.sim.limb.schedule import NeutralCheckpoints, NeutralPoses, Schedule
from rig.sim.limb.sensors import NoiseModel, SensorErrors, SensorMount

__all__ = ["LIMB_SEGMENTS", "SEGMENT_LENGTHS_M", "SimulatedWholeLimb", "WholeLimbState",
           "limb_mounts"]

_X = np.array([1.0, 0.0, 0.0])
_Y = np.array([0.0, 1.0, 0.0])
_Z = np.array([0.0, 0.0, 1.0])
_LIMB_KEY = 0x4368  # spawn-key word of each joint's neutral-pose seed sequence

#: The limbs a :class:`SimulatedWholeLimb` can be: limb → joints and segments, proximal to
#: distal (:data:`calibration.protocol.LIMB_CHAINS`).
LIMB_SEGMENTS: dict[str, tuple[tuple[str, ...], tuple[str, ...]]] = {
    "arm": (("shoulder", "elbow", "wrist"), ("thorax", "upper-arm", "forearm", "hand")),
    "leg": (("hip", "knee", "ankle"), ("pelvis", "thigh", "shank", "foot")),
}

#: Segment lengths (m), proximal to distal; the root's is its sensor's height above the
#: root's world-fixed pivot. Adult segment lengths of the order of Winter's anthropometric
#: proportions (Winter, *Biomechanics and Motor Control of Human Movement*, 4th ed., 2009,
#: Fig. 4.1: upper arm 0.186 H, forearm 0.146 H, hand 0.108 H to the fingertips, thigh 0.245 H,
#: leg 0.246 H, foot length 0.152 H; H ≈ 1.7 m, the hand to the knuckles).
SEGMENT_LENGTHS_M: dict[str, tuple[float, float, float, float]] = {
    "arm": (0.30, 0.30, 0.26, 0.08),
    "leg": (0.15, 0.43, 0.42, 0.15),
}

# nominal straps, sensor frame relative to segment frame: the root's as the shoulder patient's
# thorax sensor (rig.sim.limb.default_mounts), the limb segments' on their lateral sides
_NOMINAL = (((_Z, -90.0),), ((_X, 90.0), (_Y, 7.0)), ((_X, 80.0), (_Y, -4.0)),
            ((_X, 100.0), (_Z, 5.0)))


def limb_mounts(segments: Sequence[str], rng: np.random.Generator | None = None,
                 misplace_deg: float = 0.0) -> list[SensorMount]:
    """One sensor per segment (sensor ``i`` on ``segments[i]``) at nominal straps (none the
    identity, as straps are in practice), each turned by ``misplace_deg`` about a random axis
    (``mount ⊗ exp(misplace_deg · axis)``, sensor frame, axes drawn from ``rng``) — the draws
    of :func:`rig.sim.limb.sensors.misplaced_mounts`."""
    if len(segments) != len(_NOMINAL):
        raise ValueError(f"a chain wears {len(_NOMINAL)} sensors, got {len(segments)} segments")
    out = []
    for seg, parts in zip(segments, _NOMINAL, strict=True):
        q = np.array([1.0, 0.0, 0.0, 0.0])
        for axis, deg in parts:
            q = Q.multiply(q, Q.from_axis_angle(axis, math.radians(deg)))
        if misplace_deg:
            if rng is None:
                raise ValueError("misplaced straps need a random generator")
            axis = rng.standard_normal(3)
            axis /= np.linalg.norm(axis)
            q = Q.multiply(q, Q.from_axis_angle(axis, math.radians(misplace_deg)))
        out.append(SensorMount(seg, tuple(Q.canonical(q))))
    return out


@dataclass(frozen=True)
class WholeLimbState(SimulatedState):
    """Ground truth of a whole limb at times ``t`` (N,).

    Attributes
    ----------
    t : (N,) float64, seconds since the simulation started
    joints : (N, J, 4) float64, each joint's child segment relative to its parent (the limb
        file's joint order)
    root : (N, 4) float64, the root segment (thorax, pelvis) relative to world
    segments : (N, J + 1, 4) float64, every segment relative to world
    sensors : (N, S, 4) float64, each sensor relative to world (error-free)
    """

    t: np.ndarray
    joints: np.ndarray
    root: np.ndarray
    segments: np.ndarray
    sensors: np.ndarray


@dataclass(frozen=True, eq=False)
class _JointScript:
    """One joint's part of a protocol, as :class:`~rig.sim.limb.schedule.Schedule` takes it
    (``joint(u) -> (N, 4)``, ``duration_s``): a limb protocol's joint ``index``
    (``joint_orientations``), or a single-joint protocol (``joint``) performed by the proximal
    joint while the others hold ``neutral``."""

    protocol: object
    index: int
    side: str
    neutral: np.ndarray

    @property
    def duration_s(self) -> float:
        return float(self.protocol.duration_s)

    def joint(self, u) -> np.ndarray:
        u = np.atleast_1d(np.asarray(u, dtype=np.float64))
        if hasattr(self.protocol, "joint_orientations"):
            return self.protocol.joint_orientations(u, self.side)[:, self.index]
        if self.index == 0:
            return np.asarray(self.protocol.joint(u), dtype=np.float64).reshape(-1, 4)
        return np.tile(self.neutral, (len(u), 1))


@dataclass(frozen=True, eq=False)
class _LimbSchedule:
    """Each joint's :class:`~rig.sim.limb.schedule.Schedule` (one object: a protocol set
    meanwhile applies to the whole limb from the next call, and keys the spline's cache)."""

    joints: tuple[Schedule, ...]

    @property
    def first(self) -> Schedule:
        return self.joints[0]


def _loosest(joint) -> JointConstraint:
    """A swing joint's constraint, or its coupled keyframe with the largest region."""
    if joint.constraint is not None:
        return joint.constraint

    def size(c: JointConstraint) -> float:
        if isinstance(c.swing, PolygonSwing):
            return c.swing.area_sr()
        if isinstance(c.swing, ConeSwing):
            return c.swing.radius
        return 0.0

    return max(joint.coupling.keyframes, key=size)


def _region_centre(c: JointConstraint) -> np.ndarray:
    """The mean direction of a swing region (4,096 fixed directions on the sphere, those inside
    averaged): a centre for the motion that lies deep in the region even when it spans more than
    a hemisphere (a shoulder). Falls back to the polygon's interior point or the cone's centre."""
    swing = c.swing
    if isinstance(swing, ConeSwing):
        return Q.check_vectors(swing.centre)
    fallback = Q.check_vectors(swing.interior) if isinstance(swing, PolygonSwing) else (
        Q.check_vectors(c.limb_axis))
    d = Q.random_unit_vectors(4096, np.random.default_rng(0x5EED))
    inside = ConstraintOracle(c).swing_distance(d) <= 0.0
    m = d[inside].sum(axis=0)
    if inside.sum() < 16 or np.linalg.norm(m) < 1e-3 * inside.sum():
        return fallback
    m /= np.linalg.norm(m)
    return m if ConstraintOracle(c).swing_distance(m[None])[0] < 0.0 else fallback


@dataclass(frozen=True)
class _Placement:
    """What :class:`~rig.sim.limb.sensors.SensorErrors` asks of a placement: the number of
    sensors; no fixed lever arms (a whole limb gives the sensors' positions with each call)."""

    n: int
    lever: None = None

    def __len__(self) -> int:
        return self.n


_REACH_CAP = math.radians(90.0)  # the swing's RMS is excursion times its reach, at most this
_PUSH_KNEE = math.radians(110.0)  # a swing's raw angle from its centre saturates beyond this
_PUSH_ROOM = math.radians(30.0)  # ... towards this much more
_HINGE_ROOM = math.radians(170.0)  # a hinge's raw excursion from its middle saturates below
_TWIST_ROOM = math.radians(170.0)  # ... and a swing joint's twist from the middle of its range
_STOP_STEPS = 14  # bisection halvings of the radial stop: 2^-14 of the arc (< 0.01°)
_CHORD_TOL = math.radians(0.1)  # the arc between two targets counts as in range this close


def _arc(c: np.ndarray, d: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Points (N, 3) a fraction ``s`` (N,) of the way along the great circle from ``c`` to
    ``d`` (both (N, 3), unit, not antipodal)."""
    ang = np.arccos(np.clip(np.einsum("ij,ij->i", c, d), -1.0, 1.0))
    sa = np.sin(ang)
    safe = np.where(sa > 1e-12, sa, 1.0)
    wa = np.where(sa > 1e-12, np.sin((1.0 - s) * ang) / safe, 1.0 - s)
    wb = np.where(sa > 1e-12, np.sin(s * ang) / safe, s)
    p = wa[:, None] * c + wb[:, None] * d
    return p / np.linalg.norm(p, axis=1, keepdims=True)


def _free(m, t: np.ndarray) -> np.ndarray:
    """A joint's free orientation (N, 4) at times ``t``: a hinge's own; a swing joint's as
    :meth:`~rig.sim.limb.motion.JointMotion.free` draws it (the same sinusoids, reach and
    twist about the motion centre), except that the reach counts up to 90° (a shoulder's
    region spans more than a hemisphere: at its full reach the arm would swing at several
    hundred °/s) and the push saturates smoothly from ``min(reach, 110°)`` towards 30° more
    (not 120° → 170°): the radial stop aims from the centre, and a direction near the
    centre's antipode has no steady azimuth about it."""
    if isinstance(m, (_HingeMotion, _ForearmMotion)):
        return m.free(t)
    return m.free(t, reach_cap=_REACH_CAP, knee=min(m.reach, _PUSH_KNEE), room=_PUSH_ROOM,
                  twist_room=_TWIST_ROOM)


class _HingeMotion:
    """A hinge's free motion about its axis: ``mid + L tanh(excursion · half · x(t) / L)``
    (radians), ``L`` = 170°: nearly linear over the interval and past it, but never round to
    the far side of the circle, where the clamp would flip to the other end."""

    def __init__(self, c: JointConstraint, series: Sinusoids, excursion: float) -> None:
        self.axis = Q.check_vectors(c.hinge.axis)
        self.mid = 0.5 * (c.hinge.min + c.hinge.max)
        self.half = 0.5 * (c.hinge.max - c.hinge.min)
        self.series = series
        self.excursion = float(excursion)

    def free(self, t: np.ndarray) -> np.ndarray:
        room = _HINGE_ROOM
        angle = self.mid + room * np.tanh(self.excursion * self.half * self.series(0, t) / room)
        return Q.from_axis_angle(self.axis, angle)


class _ForearmMotion:
    """A forearm joint's free motion: flexion about its axis then rotation about the limb axis
    (:mod:`models.kinds.forearm`), each as a hinge's (:class:`_HingeMotion`) over its own
    interval, from its own sinusoid: ``F(θ(t)) ⊗ R(φ(t))``."""

    def __init__(self, c: JointConstraint, series: Sinusoids, excursion: float) -> None:
        lim = c.limits
        self.axis = Q.check_vectors(lim.axis)
        self.limb_axis = Q.check_vectors(c.limb_axis)
        self.intervals = [np.radians([lim.flexion_min_deg, lim.flexion_max_deg]),
                          np.radians([lim.rotation_min_deg, lim.rotation_max_deg])]
        self.series = series
        self.excursion = float(excursion)

    def free(self, t: np.ndarray) -> np.ndarray:
        room = _HINGE_ROOM
        angles = [0.5 * (lo + hi) + room * np.tanh(
            self.excursion * 0.5 * (hi - lo) * self.series(k, t) / room)
            for k, (lo, hi) in enumerate(self.intervals)]
        return Q.multiply(Q.from_axis_angle(self.axis, angles[0]),
                          Q.from_axis_angle(self.limb_axis, angles[1]))


class SimulatedWholeLimb(SimulatedLimb):
    """A patient's arm or leg — its segments' motion within a known limb constraint, four
    sensors and their errors; seeded and reproducible (module docstring).

    The interface of :class:`~rig.sim.limb.SimulatedLimb` that the IMU simulators use:
    :attr:`n_sensors`, :attr:`mounts`, :meth:`measure`, :meth:`measure_many` and :meth:`truth`
    (a :class:`WholeLimbState`: the joint orientations (N, J, 4), the root, segments and sensors).

    Parameters
    ----------
    limb : models.limb.Limb
        The ground truth: an arm (shoulder, elbow, wrist) or a leg (hip, knee, ankle) in rig
        segment frames (:func:`rig.sim.patients.anatomical_limb`, or a limb file); its ``side``
        (default right) sets the protocol's and the neutral poses' side.
    sensors : sequence of SensorMount, optional
        Where the sensors sit, each ``segment`` one of :attr:`segments`; default one per
        segment at the nominal straps (:func:`limb_mounts`).
    noise : NoiseModel, optional
        Default :class:`~rig.sim.limb.NoiseModel` (noise, drift, disturbances on).
    excursion : float
        RMS of each joint's raw motion relative to its range (module docstring).
    speed : float
        Multiplies every motion frequency (1: 0.03-0.3 Hz components).
    world_from_root : (4,) array_like, optional
        Fixed part of the root segment's orientation (default: heading 35°, +X down).
    sway_deg : float
        Amplitude of the root's postural sway.
    seed : int or numpy Generator
    calibration_protocol : LimbCalibrationProtocol or CalibrationProtocol, optional
        Performed from ``protocol_start_s`` (neutral pose before it), then a hand-over of
        ``blend_s`` to free motion; None: free motion from time 0.
    protocol_start_s, blend_s : float
    neutral_every_s, neutral_hold_s, neutral_ramp_s, neutral_sd_deg : float
        Neutral checkpoints, as :class:`~rig.sim.limb.SimulatedLimb`'s (every joint at its
        clinical zero, each perturbed about its child's long axis by ``neutral_sd_deg``).
    lengths_m : (4,) float, optional
        Segment lengths, proximal to distal, the root's its sensor's lever (default
        :data:`SEGMENT_LENGTHS_M`).
    smooth_s : float
        Knot spacing of the motion's B-spline (and of its follower), seconds.
    max_speed_dps : float
        The follower's speed limit per joint, °/s (module docstring, "Following").
    """

    def __init__(
        self,
        limb: Limb,
        *,
        sensors: Sequence[SensorMount] | None = None,
        noise: NoiseModel | None = None,
        excursion: float = 1.0,
        speed: float = 1.0,
        world_from_root: Sequence[float] | None = None,
        sway_deg: float = 2.0,
        seed: int | np.random.Generator | None = 0,
        calibration_protocol=None,
        protocol_start_s: float = 2.0,
        blend_s: float = 3.0,
        neutral_every_s: float = 0.0,
        neutral_hold_s: float = 2.0,
        neutral_ramp_s: float = 1.5,
        neutral_sd_deg: float = 2.0,
        lengths_m: Sequence[float] | None = None,
        smooth_s: float = 0.04,
        max_speed_dps: float = 400.0,
    ) -> None:
        self.check_limits(limb, "limb")
        kind = limb.limb if limb.limb in LIMB_SEGMENTS else None
        joint_names = tuple(j.name for j in limb.joints)
        if kind is None:  # a limb file without 'limb:': tell it by its joints
            kind = next((k for k, (js, _) in LIMB_SEGMENTS.items() if js == joint_names), None)
        if kind is None or LIMB_SEGMENTS[kind][0] != joint_names:
            raise ValueError(f"a simulated chain is an arm (shoulder, elbow, wrist) or a leg "
                             f"(hip, knee, ankle); limb {limb.name!r} has joints "
                             f"{', '.join(joint_names)}")
        if not excursion > 0 or not speed > 0:
            raise ValueError("excursion and speed must be > 0")
        self.limb = limb
        self.kind = kind
        self.side = limb.side or "right"
        self.segments: tuple[str, ...] = (limb.joints[0].parent,
                                          *(j.child for j in limb.joints))
        self.oracle = ConstraintOracle(limb)
        self.excursion = float(excursion)
        rng, seed_seq = seeded(seed)
        # (row, component): per swing joint swing u, swing v, twist; per hinge its angle; per
        # forearm joint its flexion and rotation; sway
        flexes = [j.joint_kind.flexion_rotation for j in limb.joints]
        rows = [1 if j.joint_kind.single_axis else 2 if f else 3
                for j, f in zip(limb.joints, flexes, strict=True)]
        series = Sinusoids.draw(rng, sum(rows) + 2, speed)
        self.motions: list[JointMotion | _HingeMotion | _ForearmMotion] = []
        r = 0
        for j, n, f in zip(limb.joints, rows, flexes, strict=True):
            if j.joint_kind.single_axis:
                self.motions.append(_HingeMotion(j.loosest(), series.rows(r, r + 1), excursion))
            elif f:
                self.motions.append(_ForearmMotion(j.loosest(), series.rows(r, r + 2),
                                                   excursion))
            else:
                c = _loosest(j)
                self.motions.append(JointMotion(c, series.rows(r, r + 3),
                                                centre=_region_centre(c),
                                                excursion=excursion))
            r += n
        if world_from_root is None:
            world_from_root = default_world_from_root()
        self.posture = Posture(world_from_root, sway_deg, series.rows(r, r + 2))

        self.neutral = LimbCalibrationProtocol(kind).joint_orientations([-1.0], self.side)[0]
        self._neutral = [
            NeutralPoses(neutral_sd_deg, np.random.SeedSequence(
                seed_seq.entropy, spawn_key=(*seed_seq.spawn_key, _LIMB_KEY, i)),
                Q.check_vectors(j.limb_axis))
            for i, j in enumerate(limb.joints)]
        mounts = list(sensors) if sensors is not None else limb_mounts(self.segments)
        for m in mounts:
            if m.segment not in self.segments:
                raise ValueError(f"sensor on segment {m.segment!r}: not a segment of the "
                                 f"{kind} ({', '.join(self.segments)})")
        self.mounts = mounts
        self._sensor_segment = np.array([self.segments.index(m.segment) for m in mounts])
        self._mount_q = Q.check_quaternions(np.array([m.mount for m in mounts]), normalize=True,
                                            name="mount")
        lengths = SEGMENT_LENGTHS_M[kind] if lengths_m is None else tuple(lengths_m)
        if len(lengths) != len(self.segments) or not all(
                math.isfinite(v) and v >= 0 for v in lengths):
            raise ValueError(f"lengths_m: {len(self.segments)} lengths >= 0 expected, got "
                             f"{lengths!r}")
        self.lengths_m = tuple(float(v) for v in lengths)
        self._axes = [Q.check_vectors(j.limb_axis) for j in limb.joints]
        checkpoints = NeutralCheckpoints(neutral_every_s, neutral_hold_s, neutral_ramp_s)
        self._schedule = _LimbSchedule(tuple(
            Schedule(blend_s=blend_s, checkpoints=checkpoints) for _ in limb.joints))
        if calibration_protocol is not None:
            self.perform_protocol(calibration_protocol, protocol_start_s)
        self.noise = noise if noise is not None else NoiseModel()
        self.sensor_errors = SensorErrors(self.noise, _Placement(len(mounts)), rng, seed_seq)
        self._path = SmoothPath(smooth_s)
        self._follow = RateLimit(smooth_s, math.radians(max_speed_dps), self._nearest,
                                 self._near_range)

    limits_type = Limb

    @classmethod
    def calibration_protocol_for(cls, limits: Limb) -> LimbCalibrationProtocol:
        """The limb's guided calibration (:class:`calibration.protocol.LimbCalibrationProtocol`
        of an arm or a leg, told by the limb's joints).

        Raises
        ------
        ValueError
            The joints are neither an arm's nor a leg's.
        """
        names = tuple(j.name for j in limits.joints)
        kind = next((k for k, (joints, _) in LIMB_SEGMENTS.items() if names == joints), None)
        if kind is None:
            raise ValueError(f"limb {limits.name!r}: joints {', '.join(names)} are neither an "
                             f"arm (shoulder, elbow, wrist) nor a leg (hip, knee, ankle)")
        return LimbCalibrationProtocol(kind)

    @classmethod
    def misplaced_straps(cls, limits: Limb, rng: np.random.Generator,
                         misplace_deg: float) -> list[SensorMount]:
        """One sensor per segment (:func:`limb_mounts`)."""
        return limb_mounts((limits.joints[0].parent, *(j.child for j in limits.joints)), rng,
                           misplace_deg)

    @property
    def schedule(self) -> Schedule:
        """The proximal joint's schedule (every joint's has the same times)."""
        return self._schedule.first

    @property
    def calibration_protocol(self):
        """The protocol the patient performs, or None."""
        p = self._schedule.first.protocol
        return None if p is None else p.protocol

    # -- schedule ----------------------------------------------------------------------------
    def perform_protocol(self, protocol, start_s: float = 2.0) -> None:
        """Have the patient perform ``protocol`` from patient time ``start_s`` (seconds): a
        :class:`calibration.protocol.LimbCalibrationProtocol` of this limb, or a single-joint
        protocol (``joint(u)``, ``duration_s``) performed by the proximal joint with the others
        at their clinical zero; None returns to free motion from time 0. Changes the motion at
        every time (call it before sampling times after ``min(start_s, now)``)."""
        if protocol is not None and getattr(protocol, "limb", self.kind) != self.kind:
            raise ValueError(f"a {protocol.limb} protocol for a {self.kind} patient")
        scheds = []
        for i, s in enumerate(self._schedule.joints):
            script = None if protocol is None else _JointScript(protocol, i, self.side,
                                                                self.neutral[i])
            scheds.append(s.with_protocol(script, start_s))
        self._schedule = _LimbSchedule(tuple(scheds))  # one assignment: threads see either

    def protocol_windows(self) -> dict[str, tuple[float, float]]:
        """The protocol's phase windows in patient time (``{}`` without a protocol)."""
        p = self.calibration_protocol
        if p is None:
            return {}
        t0 = self.protocol_start_s
        return {k: (t0 + a, t0 + b) for k, (a, b) in p.windows().items()}

    def neutral_poses(self, k) -> np.ndarray:
        """Every joint's neutral pose at checkpoints ``k`` (K, J, 4), before the projection."""
        return np.stack([Q.multiply(self.neutral[i], self._neutral[i](k))
                         for i in range(len(self._neutral))], axis=1)

    # -- ground truth --------------------------------------------------------------------------
    def raw_joints(self, t) -> np.ndarray:
        """Unconstrained joint orientations (N, J, 4) at times ``t`` (N,): the free motion."""
        t = np.atleast_1d(np.asarray(t, dtype=np.float64))
        return np.stack([_free(m, t) for m in self.motions], axis=1)

    def project(self, q) -> np.ndarray:
        """Postures (N, J, 4) brought into the limb's range the way the patient stops: each
        swing joint's direction outside its region moved back along the great circle towards
        its motion centre onto the boundary (:meth:`_radial_stop`), then the oracle's exact
        hierarchical projection (normalised first)."""
        q = np.asarray(q, dtype=np.float64)
        q = q / np.linalg.norm(q, axis=-1, keepdims=True)
        q = self._radial_stop(q)
        p = self.oracle.project(q, normalize=True)
        return p / np.linalg.norm(p, axis=-1, keepdims=True)

    def _radial_stop(self, q: np.ndarray) -> np.ndarray:
        """Swing joints' directions outside their regions, moved along the great circle from
        the motion centre onto the boundary (bisection on the limb oracle's verdict for the
        pure swing, :data:`_STOP_STEPS` halvings, with every other joint as the oracle corrects
        it: a coupled region at its source's corrected angle), the twist kept. Continuous in
        the target where the region is star-shaped about the centre, unlike the nearest point,
        which jumps across a concave notch's (or an excluded cap's) medial axis."""
        base = self.oracle.project(q, normalize=True)
        out = q.copy()
        for j, m in enumerate(self.motions):
            if not isinstance(m, JointMotion):
                continue
            axis = m.limb_axis
            d = Q.rotate(q[:, j], axis)
            trial = base.copy()
            trial[:, j] = Q.from_two_vectors(axis, d)
            rows = np.nonzero(~self.oracle.joint_is_valid(trial, j))[0]
            if not len(rows):
                continue
            c = np.broadcast_to(m.centre, (len(rows), 3))
            dd = d[rows]
            lo, hi = np.zeros(len(rows)), np.ones(len(rows))
            sub = trial[rows]
            for _ in range(_STOP_STEPS):
                mid = 0.5 * (lo + hi)
                p = _arc(c, dd, mid)
                sub[:, j] = Q.from_two_vectors(axis, p)
                ok = self.oracle.joint_is_valid(sub, j)
                lo, hi = np.where(ok, mid, lo), np.where(ok, hi, mid)
            p = _arc(c, dd, lo)
            old = Q.from_two_vectors(axis, dd)
            new = Q.from_two_vectors(axis, p)
            out[rows, j] = Q.multiply(new, Q.multiply(Q.conjugate(old), q[rows, j]))
        return out

    def target(self, t) -> np.ndarray:
        """The patient's target (N, J, 4) at times ``t`` before the following and smoothing:
        the free motion projected, the protocol and the checkpoints blended in (between
        postures in range: a hinge's blend towards neutral from beyond its far end would
        otherwise cross the excluded arc), projected again."""
        t = np.atleast_1d(np.asarray(t, dtype=np.float64))
        return self._target(t, self._schedule)

    def _target(self, t: np.ndarray, schedule: _LimbSchedule) -> np.ndarray:
        free = self.project(self.raw_joints(t))  # blends run between postures in range
        q = np.stack([s.target(t, free[:, i], self._neutral_pose(i))
                      for i, s in enumerate(schedule.joints)], axis=1)
        blended = np.any(q != free, axis=(1, 2))  # the rest are in range already
        if blended.any():
            q[blended] = self.project(q[blended])
        return q

    def _neutral_pose(self, i: int):
        def pose(k):
            return Q.multiply(self.neutral[i], self._neutral[i](k))
        return pose

    def joints(self, t) -> np.ndarray:
        """Joint orientations (N, J, 4) at times ``t`` (N,) seconds: the B-spline through the
        followed :meth:`target` on the knot grid (module docstring: in range but for the
        spline's overshoot, under 1.5°)."""
        t = np.atleast_1d(np.asarray(t, dtype=np.float64))
        if not len(t):
            return np.empty((0, len(self.limb.joints), 4))
        schedule = self._schedule  # one snapshot

        def knots(ts):
            return self._follow(ts, lambda u: self._target(u, schedule), schedule)

        q = self._path(t, knots, schedule)
        return q / np.linalg.norm(q, axis=-1, keepdims=True)

    def _near_range(self, q: np.ndarray) -> np.ndarray:
        """(N, J) bool: each joint within :data:`_CHORD_TOL` of its range."""
        return self.oracle.evaluate(q, normalize=True).distance <= _CHORD_TOL

    def _nearest(self, q: np.ndarray) -> np.ndarray:
        """Postures (N, J, 4) brought into range by the oracle's nearest point (normalised):
        for postures near the range (a follower's step, a spline between valid knots), where
        the nearest point does not jump."""
        p = self.oracle.project(q, normalize=True)
        return p / np.linalg.norm(p, axis=-1, keepdims=True)

    def root(self, t) -> np.ndarray:
        """The root segment (thorax, pelvis) relative to world (N, 4)."""
        return self.posture(t)

    def truth(self, t) -> WholeLimbState:
        """Error-free state at times ``t`` (scalar or (N,), seconds)."""
        t = np.atleast_1d(np.asarray(t, dtype=np.float64))
        joints = self.joints(t)
        root = self.root(t)
        segs = [root]
        for i in range(joints.shape[1]):
            segs.append(Q.multiply(segs[-1], joints[:, i]))
        segments = np.stack(segs, axis=1)
        sensors = Q.multiply(segments[:, self._sensor_segment], self._mount_q[None])
        return WholeLimbState(t=t, joints=joints, root=root, segments=segments, sensors=sensors)

    def positions(self, segments: np.ndarray) -> np.ndarray:
        """Each sensor's world position (N, S, 3), m, from the segments' orientations
        (N, J + 1, 4): the root's sensor above its world-fixed pivot, the others from the
        world-fixed proximal joint centre (module docstring)."""
        n = len(segments)
        mid = np.empty((n, len(self.segments), 3))
        mid[:, 0] = Q.rotate(segments[:, 0], -self.lengths_m[0] * _X)
        base = np.zeros((n, 3))  # segment k's proximal end; segment 1's is the fixed centre
        for k in range(1, len(self.segments)):
            along = Q.rotate(segments[:, k], self.lengths_m[k] * self._axes[k - 1])
            mid[:, k] = base + 0.5 * along
            base = base + along
        return mid[:, self._sensor_segment]

    def _positions(self, truth: WholeLimbState) -> np.ndarray:
        return self.positions(truth.segments)
