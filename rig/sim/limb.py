"""A simulated human shoulder carrying orientation sensors: ground truth plus a sensor error model.

Frames and quaternions (scalar-first, Hamilton, conventions of :mod:`models.quaternion`)
---------------------------------------------------------------------------------------
- **world** — the sensors' earth frame (BNO055 fusion output): Z up, heading from magnetic north.
- **thorax** — the parent segment. ``thorax(t)`` is the thorax relative to world: a fixed
  ``world_from_thorax`` (default: heading 35°, and a 90° pitch so that the limb axis +X hangs
  down at the identity joint orientation) times a slow postural sway of ±``sway_deg``.
- **limb** — the upper arm, long axis +X. ``joint(t)`` is the limb relative to the thorax: the
  ground truth that calibration must recover.
- **sensor i** — strapped on the thorax (``segment="thorax"``) or the limb with a fixed mounting
  rotation ``mount`` (sensor relative to segment). Its true orientation relative to world is::

      q_world_sensor = thorax(t) ⊗ [joint(t) ⊗] mount

Motion
------
The swing direction is a 2-D excursion ``s(t)`` in the tangent plane at the centre ``c`` of the
range of motion (exponential map: ``d = cos|s| c + sin|s| ŝ``), the twist ``φ(t)`` an excursion
about the middle of the twist range; both are sums of sinusoids with seeded random frequencies
(0.03-0.3 Hz) and phases, so the motion is smooth, closed-form and evaluable at any time (the
swing angle saturates smoothly between 120° and 170° from the centre: a push through the
centre's antipode would flip its azimuth). Each
axis's RMS is ``excursion`` times the reach of the range (cone radius, or the largest
centre-to-vertex angle of a polygon; half the twist range), so with ``excursion = 1`` about a third
of the time the raw motion lies outside the range; it is then brought onto the boundary
("Continuity" below), and the limb slides **along the limit** — the motion a boundary
recording needs.

Continuity. The nearest-point projection of a target outside a concave boundary jumps where
the target crosses the exterior's medial axis (on ``star_patient(204)``: up to 16,000°/s at
100 Hz; the arm would teleport, and a gyroscope or accelerometer could not follow). Two things
keep the arm's motion physical:

- **Radial stop.** For a polygon range star-shaped about the motion's centre (every seeded star
  patient; checked at construction) a swing direction outside moves back along the great
  circle towards the centre onto the boundary (:meth:`SimulatedLimb.project`), continuous in
  the target: the arm stops where its push meets the limit and slides along it as the push
  turns. Other ranges use the oracle's nearest point (a cone's is radial anyway). The twist
  is then clamped by the oracle.
- **Smoothing.** ``joint(t)`` is the uniform cubic B-spline with knots every ``smooth_s``
  (40 ms) whose control points are that projected target on the global grid
  ``i · smooth_s``, brought into the range once more by the same projection (a B-spline cuts
  a concave corner): twice continuously differentiable except where that last projection
  acts, so the accelerometer sees finite accelerations (a brief jolt of tens of m/s² where the
  arm meets a concave limit, a few samples per minute) and the gyroscope integrates to the
  truth. Stateless: a value does not depend on what else is evaluated, or in which order.

Measured on star patients 201/204/212 at 1 kHz: angular speed p99 160-210°/s, max 180-320°/s;
evaluating 120 s at 1 kHz takes ~0.2 s.

The range of motion is a :class:`models.constraint.JointConstraint` (default: a 60° cone about
+X with twist ±45°), projected by the exact oracle :class:`models.oracle.ConstraintOracle` —
the one implementation the datasets, the evaluation and the live supervisor use too.

Sensor errors (per sensor, :class:`NoiseModel`)
-----------------------------------------------
``q_measured = E_world(t) ⊗ q_world_sensor(t) ⊗ exp(n)``, quantised by the protocol, with

- ``n ~ N(0, white_deg²)`` per axis, sensor frame, independent per sample;
- ``E_world = exp(e(t) + h(t) ẑ)``: ``e`` an Ornstein-Uhlenbeck process (gyro-bias drift that the
  fusion keeps bounded: heading std ``drift_heading_deg``, tilt std ``drift_tilt_deg``,
  correlation time ``drift_time_s``), exact discretisation ``e ← a e + √(1-a²) σ ξ``,
  ``a = exp(-Δt/τ)``; ``h`` the sum of magnetic disturbances: Poisson events (rate
  ``disturbance_rate_hz``) of peak ``N(0, disturbance_deg²)`` shaped ``sin²(π u)`` over
  ``u ∈ [0, 1]`` of a duration uniform in ``disturbance_duration_s``;
- the gyroscope reads the true sensor-frame angular rate (from ``q(t)* ⊗ q(t + 1 ms)``) plus a
  constant bias ``N(0, gyro_bias_dps²)`` and white noise ``N(0, gyro_noise_dps²)``;
- the accelerometer reads the specific force ``R_sᵀ (a_lin + 9.81 ẑ)`` m/s² plus white noise
  ``N(0, accel_noise²)``, ``a_lin`` the central second difference (1 ms) of the sensor's world
  position: limb sensors ``limb_lever_m`` (0.15 m) along the limb axis from a world-fixed
  shoulder centre, the thorax sensor ``thorax_lever_m`` (0.3 m) above (thorax −X) a world-fixed
  pelvis pivot;
- the magnetometer reads ``R_sᵀ (m_h' + m_v)`` µT plus white noise ``N(0, mag_noise_ut²)``: the
  earth field ``field_ut · (0, cos dip, −sin dip)`` (north = world +Y) with its horizontal part
  turned by ``−h(t)`` about world Z — the same disturbance event as the fused heading error
  ``h(t)`` above, the sign with which a fusion that follows the field fully reports ``+h``
  (TRIAD of the ideal accelerometer and magnetometer gives the device's quaternion); the
  accelerometer/magnetometer noise has a random stream of its own (derived from the seed
  sequence), so every other draw is unchanged;
- the calibration status (``CALIB_STAT`` byte) rises from 0 to 3 per component at seeded times
  spread over ``calibration_time_s``; during a disturbance of more than 3° the magnetometer
  (and so the system) status drops to 1.

Guided calibration protocol (optional)
--------------------------------------
With a ``calibration_protocol`` (duck-typed as :class:`calibration.protocol.CalibrationProtocol`:
``joint(u) -> (N, 4)``, ``duration_s``) the patient first performs it: neutral pose (the identity
joint orientation) until ``protocol_start_s``, then ``protocol.joint(t - protocol_start_s)``,
then a smooth hand-over to the free motion over ``blend_s`` seconds,
``q(t) = P(slerp(q_protocol_end, q_free_raw(t), w))`` with ``w = smoothstep((t - t_end) /
blend_s)`` (C¹: the velocity is continuous at both ends of the blend), everything through the
oracle's projection ``P``, so a protocol pose outside the patient's range is performed at the
nearest reachable pose, as a real patient would.

Neutral checkpoints (optional)
------------------------------
With ``neutral_every_s > 0`` the patient returns to the neutral pose at regular intervals (as
a clinician has them do between movements, so that the IMUs' relative heading can be
re-zeroed). Checkpoint ``k = 1, 2, ...`` holds the window ``[t_k, t_k + neutral_hold_s]``,
``t_k = start + k · neutral_every_s``, ``start = protocol_end_s + blend_s`` with a calibration
protocol, else 0 (:meth:`SimulatedLimb.neutral_windows`). The patient moves from the free
motion to the checkpoint's neutral pose ``n_k`` over ``[t_k - ramp, t_k]``, holds it, and moves
back over ``[t_k + hold, t_k + hold + ramp]``: ``q(t) = P(slerp(q_free_raw(t), n_k, w))``, ``w``
a smoothstep rising over the first ramp, 1 over the hold, falling over the second (C¹), through
the projection ``P`` like the protocol. ``n_k = exp(r)`` is the identity perturbed by the
patient's repeatability: ``r`` has the limb-axis (axial rotation) component
``N(0, neutral_sd_deg²)`` and the two others ``N(0, (neutral_sd_deg / 2)²)``, drawn from a seed
sequence of its own per checkpoint (:meth:`SimulatedLimb.neutral_poses`), so every other draw
is the same with checkpoints on or off, and ``n_k`` does not depend on the order in which
times are sampled.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from models import quaternion as Q
from models.constraint import ConeSwing, JointConstraint, PolygonSwing
from models.oracle import ConstraintOracle

__all__ = [
    "DEFAULT_CONSTRAINT",
    "LimbState",
    "Measurement",
    "NoiseModel",
    "SensorMount",
    "SimulatedLimb",
    "default_mounts",
]

_Z = np.array([0.0, 0.0, 1.0])
_Y = np.array([0.0, 1.0, 0.0])

GRAVITY = 9.81
"""m/s², the accelerometer's specific force at rest, along world +Z (up)."""
_RAW_STEP_S = 1e-3  # finite-difference step of the gyroscope and accelerometer, seconds
_CP_CACHE = 4096  # control points of the motion's B-spline kept (joint())
_PUSH_KNEE = math.radians(120.0)  # raw swing angle from the centre beyond which it saturates
_PUSH_ROOM = math.radians(50.0)  # ... towards 170°


def _exp_map(rotvec: np.ndarray) -> np.ndarray:
    """Quaternion of rotation vectors ``(..., 3)`` (radians, axis × angle)."""
    rotvec = np.asarray(rotvec, dtype=np.float64)
    theta = np.linalg.norm(rotvec, axis=-1, keepdims=True)
    half = 0.5 * theta
    # sin(θ/2)/θ, with its limit 1/2 at θ = 0
    k = np.where(theta > 1e-12, np.sin(half) / np.where(theta > 1e-12, theta, 1.0), 0.5)
    return np.concatenate((np.cos(half), k * rotvec), axis=-1)


def _tangent_basis(c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    u = np.cross(c, np.eye(3)[int(np.argmin(np.abs(c)))])
    u /= np.linalg.norm(u)
    return u, np.cross(c, u)


DEFAULT_CONSTRAINT = JointConstraint.cone((1.0, 0.0, 0.0), 60.0, twist=(-45.0, 45.0),
                                          name="default-cone")
"""The range of motion of a :class:`SimulatedLimb` given none: 60° cone about +X, twist ±45°."""


@dataclass(frozen=True)
class NoiseModel:
    """Sensor error parameters (see the module docstring). Angles in degrees, times in seconds."""

    white_deg: float = 0.3
    drift_heading_deg: float = 2.0
    drift_tilt_deg: float = 0.3
    drift_time_s: float = 30.0
    disturbance_rate_hz: float = 1.0 / 30.0
    disturbance_deg: float = 8.0
    disturbance_duration_s: tuple[float, float] = (1.0, 4.0)
    gyro_bias_dps: float = 0.2
    gyro_noise_dps: float = 0.1
    calibration_time_s: float = 5.0
    field_ut: float = 48.0
    dip_deg: float = 64.0
    accel_noise: float = 0.02
    mag_noise_ut: float = 0.5

    def __post_init__(self) -> None:
        for name in ("white_deg", "drift_heading_deg", "drift_tilt_deg", "disturbance_rate_hz",
                     "disturbance_deg", "gyro_bias_dps", "gyro_noise_dps", "calibration_time_s",
                     "field_ut", "accel_noise", "mag_noise_ut"):
            if not getattr(self, name) >= 0.0:
                raise ValueError(f"{name} must be >= 0, got {getattr(self, name)!r}")
        if not self.drift_time_s > 0.0:
            raise ValueError(f"drift_time_s must be > 0, got {self.drift_time_s!r}")
        lo, hi = self.disturbance_duration_s
        if not 0.0 < lo <= hi:
            raise ValueError(f"disturbance_duration_s must be 0 < min <= max, got {lo}, {hi}")
        if not -90.0 <= self.dip_deg <= 90.0:
            raise ValueError(f"dip_deg must be in [-90, 90], got {self.dip_deg!r}")

    @property
    def earth_field(self) -> np.ndarray:
        """The earth's magnetic field in the world frame (3,), µT: ``F (0, cos dip, -sin dip)``
        (magnetic north = world +Y, Z up)."""
        dip = math.radians(self.dip_deg)
        return self.field_ut * np.array([0.0, math.cos(dip), -math.sin(dip)])

    @classmethod
    def ideal(cls) -> NoiseModel:
        """No errors at all, calibrated from the start: measured == truth (up to quantisation)."""
        return cls(white_deg=0.0, drift_heading_deg=0.0, drift_tilt_deg=0.0,
                   disturbance_rate_hz=0.0, gyro_bias_dps=0.0, gyro_noise_dps=0.0,
                   calibration_time_s=0.0, accel_noise=0.0, mag_noise_ut=0.0)


@dataclass(frozen=True)
class SensorMount:
    """Where a sensor sits: ``segment`` is ``"thorax"`` or ``"limb"``; ``mount`` (4,) is the
    sensor frame relative to the segment frame."""

    segment: str
    mount: tuple[float, float, float, float]

    def __post_init__(self) -> None:
        if self.segment not in ("thorax", "limb"):
            raise ValueError(f"segment must be 'thorax' or 'limb', got {self.segment!r}")


def default_mounts(n: int, rng: np.random.Generator) -> list[SensorMount]:
    """Sensor 0 on the thorax, sensor 1 on the limb's lateral side, further limb sensors at
    seeded random mountings (all different from the identity, as straps are in practice)."""
    if n < 1:
        raise ValueError(f"need at least one sensor, got {n}")
    mounts = [SensorMount("thorax", tuple(Q.from_axis_angle(_Z, math.radians(-90.0))))]
    tilt = Q.multiply(Q.from_axis_angle(np.array([1.0, 0.0, 0.0]), math.radians(90.0)),
                      Q.from_axis_angle(_Y, math.radians(7.0)))
    mounts.append(SensorMount("limb", tuple(tilt)))
    for q in Q.random_quaternions(max(0, n - 2), rng):
        mounts.append(SensorMount("limb", tuple(Q.canonical(q))))
    return mounts[:n]


@dataclass(frozen=True)
class LimbState:
    """Ground truth at times ``t`` (N,).

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


@dataclass(frozen=True)
class Measurement:
    """What the sensors report at one instant ``t`` (seconds).

    Attributes
    ----------
    quaternions : (S, 4) float64, unit, sensor relative to world, with errors
    gyro : (S, 3) float64, rad/s, sensor frame
    calibration : (S,) int, ``CALIB_STAT`` bytes
    truth : LimbState with N = 1
    accel : (S, 3) float64, m/s², sensor frame: specific force (+9.81 along world up at rest)
    mag : (S, 3) float64, µT, sensor frame
    """

    t: float
    quaternions: np.ndarray
    gyro: np.ndarray
    calibration: np.ndarray
    truth: LimbState
    accel: np.ndarray
    mag: np.ndarray


@dataclass
class _SensorErrors:
    calib_times: np.ndarray  # (3,) s, full calibration of gyr, acc, mag
    events: list[tuple[float, float, float]] = field(default_factory=list)  # start, dur, peak
    next_event: float = math.inf


class SimulatedLimb:
    """Shoulder motion, sensor placement and sensor errors; seeded and reproducible.

    Parameters
    ----------
    constraint : JointConstraint, optional
        The patient's range of motion (limb relative to thorax); default
        :data:`DEFAULT_CONSTRAINT`. Motion outside it is projected onto it by
        :class:`models.oracle.ConstraintOracle`.
    centre : (3,) array_like, optional
        Centre of the motion (thorax frame); default: the cone centre / polygon interior of
        the constraint, else the limb axis.
    reach_deg : float, optional
        Angular reach of the range from ``centre``; default from the constraint (60° if its
        swing is unlimited).
    twist_deg : (float, float), optional
        Twist interval the motion explores; default from the constraint or (-45, 45).
    excursion : float
        RMS of the raw motion relative to the reach (1.0: outside the range ~1/3 of the time).
    speed : float
        Multiplies all motion frequencies (1.0: 0.03-0.3 Hz components).
    sensors : int or sequence of SensorMount
        Number of sensors (placed by :func:`default_mounts`) or explicit mountings.
    noise : NoiseModel
    world_from_thorax : (4,) array_like, optional
        Fixed part of the thorax orientation relative to world.
    sway_deg : float
        Amplitude of the thorax's postural sway.
    seed : int or numpy Generator
        Seeds motion, mountings and errors.
    calibration_protocol : CalibrationProtocol, optional
        The guided calibration the patient performs before moving freely (see the module
        docstring); None (default): free motion from time 0.
    protocol_start_s : float
        Patient time (s) at which the protocol starts; before it the patient stands in the
        neutral pose (sensors strapped, fusion calibrating).
    blend_s : float
        Length of the hand-over from the protocol's last pose to the free motion, seconds.
    neutral_every_s : float
        Interval between neutral checkpoints, seconds (see the module docstring); 0 (default):
        none, and the motion is exactly that of a limb without checkpoints. Otherwise at least
        ``2 * neutral_ramp_s + neutral_hold_s + 1``.
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
        rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
        # the neutral poses' own seed sequence: derived from the seed without drawing from it
        ss = getattr(rng.bit_generator, "seed_seq", None)
        self._neutral_seed = ss if isinstance(ss, np.random.SeedSequence) else (
            np.random.SeedSequence(0))
        self._neutral_cache: dict[int, np.ndarray] = {}
        self._set_neutral(neutral_every_s, neutral_hold_s, neutral_ramp_s, neutral_sd_deg)
        if constraint is None:
            constraint = DEFAULT_CONSTRAINT
        if not isinstance(constraint, JointConstraint):
            raise TypeError(f"constraint must be a models.constraint.JointConstraint, got "
                            f"{type(constraint).__name__}")
        self.constraint = constraint
        self.oracle = ConstraintOracle(constraint)
        self.noise = noise if noise is not None else NoiseModel()
        if not excursion > 0 or not speed > 0:
            raise ValueError("excursion and speed must be > 0")
        self.limb_axis = Q.check_vectors(constraint.limb_axis)
        c_default, reach_default, twist_default = _describe_range(constraint)
        self.centre = Q.check_vectors(centre if centre is not None else
                                      (c_default if c_default is not None else self.limb_axis))
        self.reach = math.radians(reach_deg if reach_deg is not None else reach_default)
        tw = twist_deg if twist_deg is not None else twist_default
        self.twist_centre = math.radians(0.5 * (tw[0] + tw[1]))
        self.twist_half = math.radians(max(0.5 * (tw[1] - tw[0]), 5.0))
        self.excursion = float(excursion)
        self._u, self._v = _tangent_basis(self.centre)
        # (axis, component) sinusoids: swing u, swing v, twist, sway x, sway y
        self._freq = rng.uniform(0.03, 0.3, size=(5, 4)) * speed
        self._phase = rng.uniform(0.0, 2.0 * math.pi, size=(5, 4))
        w = rng.uniform(0.5, 1.0, size=(5, 4))
        # RMS of Σ a sin(...) is sqrt(Σ a²/2): scale so every axis has unit RMS
        self._amp = w * np.sqrt(2.0 / np.sum(w**2, axis=1, keepdims=True))
        self._sway = math.radians(sway_deg)
        if world_from_thorax is None:
            world_from_thorax = Q.multiply(Q.from_axis_angle(_Z, math.radians(35.0)),
                                           Q.from_axis_angle(_Y, math.radians(90.0)))
        self.world_from_thorax = Q.check_quaternions(world_from_thorax, name="world_from_thorax")
        self.mounts = (default_mounts(sensors, rng) if isinstance(sensors, int)
                       else list(sensors))
        if not self.mounts:
            raise ValueError("need at least one sensor")
        self._mount_q = Q.check_quaternions(np.array([m.mount for m in self.mounts]),
                                            normalize=True, name="mount")
        self._on_limb = np.array([m.segment == "limb" for m in self.mounts])
        self._rng = rng
        self._last_t: float | None = None
        if not blend_s > 0:
            raise ValueError(f"blend_s must be > 0, got {blend_s!r}")
        self.blend_s = float(blend_s)
        self._plan = None
        self.calibration_protocol = None
        self.protocol_start_s = 0.0
        if calibration_protocol is not None:
            self.perform_protocol(calibration_protocol, protocol_start_s)
        nz = self.noise
        n = len(self.mounts)
        self._drift = rng.standard_normal((n, 3)) * np.radians(
            [nz.drift_tilt_deg, nz.drift_tilt_deg, nz.drift_heading_deg])  # rad, world frame
        self._bias = rng.standard_normal((n, 3)) * math.radians(nz.gyro_bias_dps)  # rad/s
        self._errors = []
        for _ in range(n):
            e = _SensorErrors(calib_times=nz.calibration_time_s * rng.uniform(0.2, 1.0, size=3))
            e.next_event = self._draw_event_gap()
            self._errors.append(e)
        # one stream per error process: the numbers do not depend on how a simulator batches
        # its calls (measure_many of 64 samples or 1 draws the same values per sample)
        self._rng_drift, self._rng_white, self._rng_gyro, self._rng = (
            np.random.default_rng(int(x)) for x in rng.integers(0, 2**63 - 1, size=4))
        # accelerometer and magnetometer white noise: a stream of its own, derived from the
        # seed sequence without drawing from it (every other draw is as without it)
        ss = self._neutral_seed
        self._rng_raw = np.random.default_rng(
            np.random.SeedSequence(ss.entropy, spawn_key=(*ss.spawn_key, 0x5241)))
        for name, v in (("limb_lever_m", limb_lever_m), ("thorax_lever_m", thorax_lever_m)):
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"{name} must be >= 0, got {v!r}")
        if not (math.isfinite(smooth_s) and smooth_s > 0):
            raise ValueError(f"smooth_s must be > 0, got {smooth_s!r}")
        self.smooth_s = float(smooth_s)
        self._cp_cache: dict[int, np.ndarray] = {}  # cleared when the protocol changes
        self._cp_plan = self._plan
        self._cp_lock = threading.Lock()
        self._radial = _StarRadial.of(constraint, self.centre)
        self.limb_lever_m = float(limb_lever_m)
        self.thorax_lever_m = float(thorax_lever_m)
        # each sensor's position relative to its world-fixed pivot, in the sensor frame
        lever = np.where(self._on_limb[:, None], self.limb_lever_m * self.limb_axis,
                         -self.thorax_lever_m * np.array([1.0, 0.0, 0.0]))
        self._lever_sensor = Q.rotate(Q.conjugate(self._mount_q), lever)  # (S, 3) m

    @classmethod
    def from_constraint(cls, constraint: JointConstraint, **kwargs) -> SimulatedLimb:
        """A limb whose range of motion is ``constraint`` (same as ``SimulatedLimb(constraint,
        **kwargs)``)."""
        return cls(constraint, **kwargs)

    @property
    def n_sensors(self) -> int:
        return len(self.mounts)

    def perform_protocol(self, protocol, start_s: float = 2.0) -> None:
        """Have the patient perform ``protocol`` from patient time ``start_s`` (seconds).

        Changes the motion at every time: call it before the simulator has sampled times after
        ``min(start_s, now)`` (a servo simulator back-driven by this limb samples lazily, so
        setting it at once after opening the port is enough when ``start_s`` lies ahead).
        ``protocol=None`` returns to free motion from time 0.
        """
        if protocol is not None:
            if not (math.isfinite(start_s) and start_s >= 0):
                raise ValueError(f"protocol_start_s must be >= 0, got {start_s!r}")
            if not protocol.duration_s > 0:
                raise ValueError("the protocol must last > 0 s")
        # one assignment: the simulator threads see either the old or the new plan
        self._plan = None if protocol is None else (protocol, float(start_s))
        self.calibration_protocol = protocol
        self.protocol_start_s = float(start_s) if protocol is not None else 0.0

    @property
    def protocol_end_s(self) -> float:
        """Patient time at which the protocol has ended (free motion, blended, follows);
        0 without a protocol."""
        plan = self._plan
        return 0.0 if plan is None else plan[1] + plan[0].duration_s

    # -- neutral checkpoints --------------------------------------------------------------
    def _set_neutral(self, every: float, hold: float, ramp: float, sd: float) -> None:
        every, hold, ramp, sd = float(every), float(hold), float(ramp), float(sd)
        if not (math.isfinite(hold) and hold > 0):
            raise ValueError(f"neutral_hold_s must be > 0, got {hold!r}")
        if not (math.isfinite(ramp) and ramp > 0):
            raise ValueError(f"neutral_ramp_s must be > 0, got {ramp!r}")
        if not (math.isfinite(sd) and sd >= 0):
            raise ValueError(f"neutral_sd_deg must be >= 0, got {sd!r}")
        least = 2.0 * ramp + hold + 1.0
        if not (math.isfinite(every) and (every == 0.0 or every >= least)):
            raise ValueError(f"neutral_every_s must be 0 (off) or >= 2 * neutral_ramp_s + "
                             f"neutral_hold_s + 1 = {least:g}, got {every!r}")
        self.neutral_every_s = every
        self.neutral_hold_s = hold
        self.neutral_ramp_s = ramp
        self.neutral_sd_deg = sd

    def _neutral_start(self, plan) -> float:
        return 0.0 if plan is None else plan[1] + plan[0].duration_s + self.blend_s

    @property
    def neutral_start_s(self) -> float:
        """Patient time from which neutral checkpoints are counted: the end of the protocol's
        hand-over to free motion (``protocol_end_s + blend_s``), or 0 without a protocol.
        Checkpoint ``k`` starts its hold at ``neutral_start_s + k * neutral_every_s``."""
        return self._neutral_start(self._plan)

    def neutral_windows(self, t_end: float) -> np.ndarray:
        """Hold windows ``[t_k, t_k + neutral_hold_s]`` (K, 2) of the neutral checkpoints
        ``k = 1, 2, ...`` that end by patient time ``t_end`` (seconds); ``(0, 2)`` when
        ``neutral_every_s`` is 0."""
        every = self.neutral_every_s
        start = self._neutral_start(self._plan)
        if every <= 0 or not t_end >= start + every + self.neutral_hold_s:
            return np.empty((0, 2))
        k = np.arange(1, math.floor((t_end - self.neutral_hold_s - start) / every) + 2)
        t0 = start + k * every
        t0 = t0[t0 + self.neutral_hold_s <= t_end]
        return np.stack((t0, t0 + self.neutral_hold_s), axis=1)

    def neutral_poses(self, k) -> np.ndarray:
        """Neutral pose (joint orientation, before the oracle's projection) of checkpoints
        ``k`` (int or (K,) ints >= 1), (K, 4): the identity perturbed by the patient's
        repeatability (module docstring). Deterministic per seed and checkpoint."""
        ks = np.atleast_1d(np.asarray(k, dtype=np.int64))
        if np.any(ks < 1):
            raise ValueError("neutral checkpoints are numbered from 1")
        sd = math.radians(self.neutral_sd_deg)
        u, v = _tangent_basis(self.limb_axis)
        out = np.empty((len(ks), 4))
        ss = self._neutral_seed
        for i, kk in enumerate(ks.tolist()):
            z = self._neutral_cache.get(kk)
            if z is None:
                child = np.random.SeedSequence(ss.entropy,
                                               spawn_key=(*ss.spawn_key, 0x4E75, kk))
                z = np.random.default_rng(child).standard_normal(3)
                self._neutral_cache[kk] = z
            rotvec = sd * (z[0] * self.limb_axis + 0.5 * z[1] * u + 0.5 * z[2] * v)
            out[i] = _exp_map(rotvec)
        return out

    def _neutral_blend(self, t: np.ndarray, q: np.ndarray, plan) -> np.ndarray:
        """``q`` (N, 4) with the neutral checkpoints' ramps and holds applied (unprojected)."""
        every, hold, ramp = self.neutral_every_s, self.neutral_hold_s, self.neutral_ramp_s
        start = self._neutral_start(plan)
        k = np.floor((t - start + ramp) / every)
        x = t - (start + k * every)  # time since t_k, in [-ramp, every - ramp)
        s = np.clip(np.minimum((x + ramp) / ramp, (hold + ramp - x) / ramp), 0.0, 1.0)
        w = s * s * (3.0 - 2.0 * s)  # smoothstep: C1 at every end
        active = (k >= 1) & (w > 0.0)
        if not active.any():
            return q
        ka = k[active].astype(np.int64)
        uniq, inv = np.unique(ka, return_inverse=True)
        pose = self.neutral_poses(uniq)[inv]
        wa = w[active]
        out = q.copy()
        out[active] = np.where((wa >= 1.0)[:, None], pose, _slerp(q[active], pose, wa))
        return out

    # -- ground truth ---------------------------------------------------------------------
    def _series(self, row: int, t: np.ndarray) -> np.ndarray:
        arg = 2.0 * math.pi * self._freq[row] * t[:, None] + self._phase[row]
        # a row-wise sum, not a matrix product: BLAS may round differently with the batch size,
        # and a value must not depend on what else is evaluated with it
        return (np.sin(arg) * self._amp[row]).sum(axis=1)

    def raw_joint(self, t) -> np.ndarray:
        """Unconstrained joint orientation (N, 4) at times ``t`` (N,) seconds, before projection."""
        t = np.atleast_1d(np.asarray(t, dtype=np.float64))
        sigma = self.excursion * self.reach / math.sqrt(2.0)
        su = sigma * self._series(0, t)
        sv = sigma * self._series(1, t)
        ang = np.hypot(su, sv)
        safe = np.where(ang > 1e-12, ang, 1.0)
        dirn = (su[:, None] * self._u + sv[:, None] * self._v) / safe[:, None]
        # beyond 120° from the centre the push saturates smoothly (C1) below 170°: a push
        # through the centre's antipode would flip its azimuth, and the arm with it
        over = np.maximum(ang - _PUSH_KNEE, 0.0)
        ang = np.minimum(ang, _PUSH_KNEE) + _PUSH_ROOM * np.tanh(over / _PUSH_ROOM)
        d = np.cos(ang)[:, None] * self.centre + np.sin(ang)[:, None] * dirn
        swing = Q.from_two_vectors(self.limb_axis, d)
        phi = self.twist_centre + self.excursion * self.twist_half * self._series(2, t)
        return Q.multiply(swing, Q.from_axis_angle(self.limb_axis, phi))

    def joint(self, t) -> np.ndarray:
        """Joint orientation (N, 4), limb relative to thorax, inside the range of motion
        (after the calibration protocol when the patient performs one; in the neutral pose at
        the neutral checkpoints when ``neutral_every_s > 0``), at times ``t`` (N,) seconds.

        The uniform cubic B-spline (knots every ``smooth_s``) whose control points are the
        projected target on the global grid ``i · smooth_s``, projected once more into the range
        (module docstring): twice continuously differentiable wherever that last projection
        does nothing. Stateless: the value at a time does not depend on what else is
        evaluated, or in which order."""
        t = np.atleast_1d(np.asarray(t, dtype=np.float64))
        if not len(t):
            return np.empty((0, 4))
        x = t / self.smooth_s
        i0 = np.floor(x)
        f = (x - i0)[:, None]
        idx = i0[:, None] + np.arange(-1.0, 3.0)  # (N, 4) control points of each span
        uniq, inv = np.unique(idx, return_inverse=True)
        c = self._control_points(uniq)[inv.reshape(-1)].reshape(len(t), 4, 4)
        c = c * np.where(np.sum(c * c[:, 1:2], axis=-1) < 0.0, -1.0, 1.0)[..., None]
        w = np.concatenate(((1.0 - f) ** 3, 3.0 * f**3 - 6.0 * f**2 + 4.0,
                            -3.0 * f**3 + 3.0 * f**2 + 3.0 * f + 1.0, f**3), axis=1) / 6.0
        # term by term (elementwise, so a row's value does not depend on the batch)
        q = w[:, 0:1] * c[:, 0] + w[:, 1:2] * c[:, 1] + w[:, 2:3] * c[:, 2] + w[:, 3:4] * c[:, 3]
        return self.project(q)

    def _control_points(self, index: np.ndarray) -> np.ndarray:
        """The projected target at grid points ``index · smooth_s`` (N, 4), kept for the last
        few thousand points asked for: a simulator sampling at 200 Hz asks for each point about
        40 times (a pure function of the index, so keeping it changes no value)."""
        keys = index.astype(np.int64).tolist()
        plan = self._plan
        with self._cp_lock:
            cache = self._cp_cache
            if self._cp_plan is not plan:  # a new protocol changes the target everywhere
                cache.clear()
                self._cp_plan = plan
            missing = [k for k in keys if k not in cache]
            if missing:
                vals = self._closed_joint(np.asarray(missing, dtype=np.float64) * self.smooth_s,
                                          plan)
                if len(cache) > _CP_CACHE:
                    for k in list(cache)[:len(cache) // 2]:
                        del cache[k]
                cache.update(zip(missing, vals, strict=True))
            return np.array([cache[k] for k in keys])

    def _closed_joint(self, t: np.ndarray, plan) -> np.ndarray:
        """``P(target(t))`` (N, 4): the raw, protocol and checkpoint target, projected into the
        range (:meth:`project`)."""
        raw = self.raw_joint(t)
        if plan is not None:
            protocol, start = plan
            u = t - start
            scripted = np.asarray(protocol.joint(u), dtype=np.float64).reshape(-1, 4)
            x = np.clip((u - protocol.duration_s) / self.blend_s, 0.0, 1.0)
            w = x * x * (3.0 - 2.0 * x)  # smoothstep: C1 at both ends
            raw = np.where((w >= 1.0)[:, None], raw, _slerp(scripted, raw, w))
        if self.neutral_every_s > 0:
            raw = self._neutral_blend(t, raw, plan)
        return self.project(raw)

    def project(self, q) -> np.ndarray:
        """Orientations (N, 4) brought into the range the way the patient's arm stops: a swing
        direction outside a polygon that is star-shaped about the motion's centre moves back
        along the great circle towards the centre to the boundary (continuous in the target),
        then the oracle's projection (the twist clamp; the nearest point for other ranges)."""
        q = np.asarray(q, dtype=np.float64).reshape(-1, 4)
        q = q / np.linalg.norm(q, axis=1, keepdims=True)
        if self._radial is not None:
            d = Q.rotate(q, self.limb_axis)
            out = self.oracle.swing_distance(d) > 0.0
            if out.any():
                p = self._radial.boundary(d[out])
                old = Q.from_two_vectors(self.limb_axis, d[out])
                new = Q.from_two_vectors(self.limb_axis, p)
                q = q.copy()
                q[out] = Q.multiply(new, Q.multiply(Q.conjugate(old), q[out]))
        q = self.oracle.project(q, normalize=True).reshape(-1, 4)
        return q / np.linalg.norm(q, axis=1, keepdims=True)

    def thorax(self, t) -> np.ndarray:
        """Thorax relative to world (N, 4) at times ``t`` (N,)."""
        t = np.atleast_1d(np.asarray(t, dtype=np.float64))
        sway = np.stack((self._sway * self._series(3, t), self._sway * self._series(4, t),
                         np.zeros_like(t)), axis=-1)
        return Q.multiply(self.world_from_thorax, _exp_map(sway))

    def truth(self, t) -> LimbState:
        """Error-free state at times ``t`` (scalar or (N,), seconds)."""
        t = np.atleast_1d(np.asarray(t, dtype=np.float64))
        joint = self.joint(t)
        thorax = self.thorax(t)
        segment = np.where(self._on_limb[None, :, None], Q.multiply(thorax, joint)[:, None, :],
                           thorax[:, None, :])
        sensors = Q.multiply(segment, self._mount_q[None, :, :])
        return LimbState(t=t, joint=joint, thorax=thorax, sensors=sensors)

    # -- measurements ---------------------------------------------------------------------
    def _draw_event_gap(self) -> float:
        rate = self.noise.disturbance_rate_hz
        return float(self._rng.exponential(1.0 / rate)) if rate > 0 else math.inf

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
        if self._last_t is not None and t < self._last_t:
            raise ValueError(f"measure() went back in time: {t} < {self._last_t}")
        dt = 0.0 if self._last_t is None else t - self._last_t
        self._last_t = t
        nz = self.noise
        h = _RAW_STEP_S
        ts = np.array([t, t + h, t - h])
        truth = self.truth(ts)
        q_true = truth.sensors[0]
        # sensor-frame angular rate from q(t)* ⊗ q(t + 1 ms)
        rel = Q.multiply(Q.conjugate(q_true), truth.sensors[1])
        rel *= np.where(rel[:, :1] < 0, -1.0, 1.0)
        gyro = 2.0 * rel[:, 1:] / h
        elapsed = t if calibration_elapsed_s is None else calibration_elapsed_s
        s = self.n_sensors
        sig = np.radians([nz.drift_tilt_deg, nz.drift_tilt_deg, nz.drift_heading_deg])
        if dt > 0:
            a = math.exp(-dt / nz.drift_time_s)
            self._drift = a * self._drift + math.sqrt(1.0 - a * a) * sig * (
                self._rng_drift.standard_normal((s, 3)))
        heading = np.array([self._disturbance(err, t) for err in self._errors])
        e_world = _exp_map(self._drift + heading[:, None] * _Z)
        white = _exp_map(self._rng_white.standard_normal((s, 3)) * math.radians(nz.white_deg))
        q = Q.multiply(Q.multiply(e_world, q_true), white)
        out_q = Q.canonical(q / np.linalg.norm(q, axis=1, keepdims=True))
        gyro += self._bias + self._rng_gyro.standard_normal((s, 3)) * math.radians(
            nz.gyro_noise_dps)
        disturbed = np.abs(heading) > math.radians(3.0)
        calib = np.array([_calibration_byte(err.calib_times, elapsed, bool(d))
                          for err, d in zip(self._errors, disturbed, strict=True)])
        accel, mag = self._raw(q_true, truth.sensors[1], truth.sensors[2], heading)
        return Measurement(t=t, quaternions=out_q, gyro=gyro, calibration=calib,
                           truth=LimbState(truth.t[:1], truth.joint[:1], truth.thorax[:1],
                                           truth.sensors[:1]), accel=accel, mag=mag)

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
        if np.any(np.diff(ts) < 0) or (self._last_t is not None and ts[0] < self._last_t):
            raise ValueError("measure_many() times must increase and not go back in time")
        prev = ts[0] if self._last_t is None else self._last_t
        dts = np.diff(np.concatenate(([prev], ts)))
        self._last_t = float(ts[-1])
        nz = self.noise
        s = self.n_sensors
        h = _RAW_STEP_S
        truth = self.truth(np.concatenate((ts, ts + h, ts - h)))
        q_true, q_next, q_prev = truth.sensors[:k], truth.sensors[k:2 * k], truth.sensors[2 * k:]
        rel = Q.multiply(Q.conjugate(q_true), q_next)
        rel *= np.where(rel[..., :1] < 0, -1.0, 1.0)
        gyro = 2.0 * rel[..., 1:] / h  # (K, S, 3)
        sig = np.radians([nz.drift_tilt_deg, nz.drift_tilt_deg, nz.drift_heading_deg])
        xi = self._rng_drift.standard_normal((k, s, 3))
        a = np.exp(-dts / nz.drift_time_s)
        b = np.sqrt(1.0 - a * a)
        drift = np.empty((k, s, 3))
        e = self._drift
        for i in range(k):  # Ornstein-Uhlenbeck, exact discretisation
            if dts[i] > 0:
                e = a[i] * e + b[i] * sig * xi[i]
            drift[i] = e
        self._drift = e
        heading = np.array([[self._disturbance(err, float(t)) for err in self._errors]
                            for t in ts])  # (K, S)
        e_world = _exp_map(drift + heading[..., None] * _Z)
        white = _exp_map(self._rng_white.standard_normal((k, s, 3)) * math.radians(nz.white_deg))
        q = Q.multiply(Q.multiply(e_world, q_true), white)
        out_q = Q.canonical(q / np.linalg.norm(q, axis=-1, keepdims=True))
        gyro = gyro + self._bias + self._rng_gyro.standard_normal((k, s, 3)) * math.radians(
            nz.gyro_noise_dps)
        times = np.array([err.calib_times for err in self._errors])  # (S, 3)
        with np.errstate(divide="ignore", invalid="ignore"):
            levels = np.where(times[None] <= 0, 3,
                              np.minimum(3, np.floor(4.0 * ts[:, None, None] /
                                                     np.where(times > 0, times, 1.0)[None])))
        levels = levels.astype(int)
        mag = np.where(np.abs(heading) > math.radians(3.0), np.minimum(levels[..., 2], 1),
                       levels[..., 2])
        system = np.minimum(np.minimum(levels[..., 0], levels[..., 1]), mag)
        calib = (system << 6) | (levels[..., 0] << 4) | (levels[..., 1] << 2) | mag
        accel, field_ = self._raw(q_true, q_next, q_prev, heading)
        return [Measurement(t=float(ts[i]), quaternions=out_q[i], gyro=gyro[i],
                            calibration=calib[i],
                            truth=LimbState(truth.t[i:i + 1], truth.joint[i:i + 1],
                                            truth.thorax[i:i + 1], truth.sensors[i:i + 1]),
                            accel=accel[i], mag=field_[i])
                for i in range(k)]

    def _raw(self, q_true: np.ndarray, q_next: np.ndarray, q_prev: np.ndarray,
             heading: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Accelerometer and magnetometer (..., S, 3) in the sensor frame from the true sensor
        orientations at ``t``, ``t + h``, ``t - h`` (h = 1 ms) and the heading disturbance
        ``heading`` (..., S) rad of the device-fusion model."""
        nz = self.noise
        h = _RAW_STEP_S
        # sensor positions relative to their world-fixed pivots; central second difference
        lever = self._lever_sensor
        p0 = Q.rotate(q_true, lever)
        a_lin = (Q.rotate(q_next, lever) - 2.0 * p0 + Q.rotate(q_prev, lever)) / (h * h)
        f_world = a_lin + GRAVITY * _Z
        # magnetometer: the earth field with its horizontal part turned by -h(t) about world Z:
        # a field the device's fusion follows fully reads as a heading error of +h(t)
        m = nz.earth_field
        c, s = np.cos(heading), np.sin(heading)
        m_world = np.stack((c * m[0] + s * m[1], -s * m[0] + c * m[1],
                            np.full_like(heading, m[2])), axis=-1)
        inv = Q.conjugate(q_true)
        noise = self._rng_raw.standard_normal((*heading.shape, 6))
        accel = Q.rotate(inv, f_world) + nz.accel_noise * noise[..., :3]
        mag = Q.rotate(inv, m_world) + nz.mag_noise_ut * noise[..., 3:]
        return accel, mag

    def _disturbance(self, err: _SensorErrors, t: float) -> float:
        nz = self.noise
        while err.next_event <= t:
            dur = float(self._rng.uniform(*nz.disturbance_duration_s))
            peak = float(self._rng.standard_normal()) * math.radians(nz.disturbance_deg)
            err.events.append((err.next_event, dur, peak))
            err.next_event += self._draw_event_gap()
        total = 0.0
        keep = []
        for start, dur, peak in err.events:
            u = (t - start) / dur
            if u < 1.0:
                keep.append((start, dur, peak))
                if u >= 0.0:
                    total += peak * math.sin(math.pi * u) ** 2
        err.events = keep
        return total


class _StarRadial:
    """Radial projection onto a spherical polygon star-shaped about a centre ``c``: the
    boundary point on the great circle from ``c`` through a direction. The vertices' azimuths
    about ``c`` turn monotonically once round, so each azimuth meets exactly one edge and the
    projection is continuous in the direction."""

    def __init__(self, vertices: np.ndarray, centre: np.ndarray, u: np.ndarray,
                 v: np.ndarray, az: np.ndarray) -> None:
        self.c, self.u, self.v, self.az = centre, u, v, az  # az ascending, one turn
        self.normal = np.cross(vertices, np.roll(vertices, -1, axis=0))  # edge k: k → k+1

    @classmethod
    def of(cls, constraint: JointConstraint, centre: np.ndarray) -> _StarRadial | None:
        """The projection, or None when the range is not a polygon star-shaped about
        ``centre`` (the oracle's nearest point is used then)."""
        swing = constraint.swing
        if not isinstance(swing, PolygonSwing):
            return None
        verts = Q.check_vectors(swing.vertices)
        if np.any(verts @ centre <= -1.0 + 1e-9):
            return None  # a vertex at the centre's antipode has no azimuth
        u, v = _tangent_basis(centre)
        az = np.unwrap(np.arctan2(verts @ v, verts @ u))
        if az[-1] < az[0]:  # clockwise about the centre: walk it the other way
            verts = verts[::-1]
            az = np.unwrap(np.arctan2(verts @ v, verts @ u))
        steps = np.diff(np.r_[az, az[0] + 2.0 * math.pi])
        if not np.all(steps > 0.0):
            return None  # not star-shaped about the centre
        return cls(verts, centre, u, v, az)

    def boundary(self, d: np.ndarray) -> np.ndarray:
        """Boundary points (N, 3) on the great circles from the centre through ``d`` (N, 3)."""
        a = np.arctan2(d @ self.v, d @ self.u)
        a = self.az[0] + (a - self.az[0]) % (2.0 * math.pi)
        k = np.clip(np.searchsorted(self.az, a, side="right") - 1, 0, len(self.az) - 1)
        p = np.cross(np.cross(self.c, d), self.normal[k])
        p /= np.linalg.norm(p, axis=1, keepdims=True)
        tangent = d - (d @ self.c)[:, None] * self.c
        return p * np.where(np.sum(p * tangent, axis=1) < 0.0, -1.0, 1.0)[:, None]


def _slerp(a: np.ndarray, b: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Spherical interpolation ``a ⊗ exp(w log(a* ⊗ b))`` (N, 4), shortest arc, ``w`` (N,)."""
    rel = Q.multiply(Q.conjugate(a), b)
    rel *= np.where(rel[:, :1] < 0, -1.0, 1.0)
    vn = np.linalg.norm(rel[:, 1:], axis=1)
    ang = 2.0 * np.arctan2(vn, rel[:, 0])  # rotation angle of a* b, [0, π]
    axis = rel[:, 1:] / np.where(vn > 1e-15, vn, 1.0)[:, None]
    return Q.multiply(a, _exp_map(axis * (w * ang)[:, None]))


def _calibration_byte(times: np.ndarray, elapsed: float, disturbed: bool) -> int:
    levels = []
    for tc in times:
        levels.append(3 if tc <= 0 else min(3, int(4.0 * elapsed / tc)))
    gyr, acc, mag = levels
    if disturbed:
        mag = min(mag, 1)
    system = min(gyr, acc, mag)
    return (system << 6) | (gyr << 4) | (acc << 2) | mag


def _describe_range(constraint: JointConstraint
                    ) -> tuple[np.ndarray | None, float, tuple[float, float]]:
    """Centre, reach (deg) and twist interval (deg) the motion should explore."""
    centre, reach, twist = None, 60.0, (-45.0, 45.0)
    swing = constraint.swing
    if isinstance(swing, ConeSwing):
        centre, reach = np.asarray(swing.centre, float), float(swing.radius_deg)
    elif isinstance(swing, PolygonSwing):
        centre = Q.check_vectors(swing.interior)
        verts = Q.check_vectors(swing.vertices)
        reach = float(np.degrees(np.max(Q.angle_between(verts, centre))))
    if constraint.twist is not None:
        twist = (float(constraint.twist.min_deg), float(constraint.twist.max_deg))
    return centre, reach, twist
