"""The simulated patient's orientation sensors: where they sit, and what they report.

Placement (:class:`SensorPlacement`)
------------------------------------
Sensor ``i`` is strapped on a segment (``"thorax"``, the parent, or ``"limb"``) with a fixed
mounting rotation ``mount`` (sensor relative to segment, :class:`SensorMount`; the default
straps :func:`default_mounts`, each turned off them by :func:`misplaced_mounts`). Its true
orientation relative to world is::

    q_world_sensor = thorax(t) ⊗ [joint(t) ⊗] mount

Sensor errors (per sensor, :class:`NoiseModel`; the processes: :class:`SensorErrors`)
-------------------------------------------------------------------------------------
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
  (TRIAD of the ideal accelerometer and magnetometer gives the device's quaternion);
- the calibration status (``CALIB_STAT`` byte) rises from 0 to 3 per component at seeded times
  spread over ``calibration_time_s``; during a disturbance of more than 3° the magnetometer
  (and so the system) status drops to 1.

Random streams: the initial drift, the gyroscope biases, the calibration times and the first
disturbance gaps are drawn from the patient's generator (in that order, after the motion and
the mountings); then four generators seeded from it carry the drift, the white noise, the
gyroscope noise and the disturbance events, and the accelerometer/magnetometer noise has a
stream of its own derived from the seed sequence without drawing from it — so the numbers do
not depend on how a simulator batches its calls, and every other draw is as without raw
samples.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from models import quaternion as Q
from rig.sim.limb._rotations import exp_map

__all__ = [
    "GRAVITY",
    "RAW_STEP_S",
    "NoiseModel",
    "Readings",
    "SensorErrors",
    "SensorMount",
    "SensorPlacement",
    "default_mounts",
    "misplaced_mounts",
]

_X = np.array([1.0, 0.0, 0.0])
_Y = np.array([0.0, 1.0, 0.0])
_Z = np.array([0.0, 0.0, 1.0])

GRAVITY = 9.81
"""m/s², the accelerometer's specific force at rest, along world +Z (up)."""
RAW_STEP_S = 1e-3
"""Finite-difference step of the gyroscope and accelerometer, seconds."""
_RAW_KEY = 0x5241  # spawn-key word of the accelerometer/magnetometer noise stream
_DISTURBED_RAD = math.radians(3.0)  # a disturbance beyond this drops the magnetometer status


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
    """Where a sensor sits: ``segment`` names the segment (the shoulder patient's ``"thorax"``
    or ``"limb"``; a chain's segment names, :class:`rig.sim.limb.whole.SimulatedWholeLimb`);
    ``mount`` (4,) is the sensor frame relative to the segment frame."""

    segment: str
    mount: tuple[float, float, float, float]

    def __post_init__(self) -> None:
        if not isinstance(self.segment, str) or not self.segment:
            raise ValueError(f"segment must be a segment name, got {self.segment!r}")


def default_mounts(n: int, rng: np.random.Generator) -> list[SensorMount]:
    """Sensor 0 on the thorax, sensor 1 on the limb's lateral side, further limb sensors at
    seeded random mountings (all different from the identity, as straps are in practice)."""
    if n < 1:
        raise ValueError(f"need at least one sensor, got {n}")
    mounts = [SensorMount("thorax", tuple(Q.from_axis_angle(_Z, math.radians(-90.0))))]
    tilt = Q.multiply(Q.from_axis_angle(_X, math.radians(90.0)),
                      Q.from_axis_angle(_Y, math.radians(7.0)))
    mounts.append(SensorMount("limb", tuple(tilt)))
    for q in Q.random_quaternions(max(0, n - 2), rng):
        mounts.append(SensorMount("limb", tuple(Q.canonical(q))))
    return mounts[:n]


def misplaced_mounts(rng: np.random.Generator, misplace_deg: float = 25.0,
                     sensors: int = 2) -> list[SensorMount]:
    """Sensor 0 on the thorax, the others on the limb (:func:`default_mounts`),
    each strap turned by ``misplace_deg`` about a random axis (sensor frame):
    ``mount ⊗ exp(misplace_deg · axis)``. ``misplace_deg = 0``: the default straps."""
    mounts = default_mounts(sensors, rng)
    if not misplace_deg:
        return mounts
    out = []
    for m in mounts:
        axis = rng.standard_normal(3)
        axis /= np.linalg.norm(axis)
        err = Q.from_axis_angle(axis, math.radians(misplace_deg))
        out.append(SensorMount(m.segment, tuple(Q.canonical(Q.multiply(m.mount, err)))))
    return out


class SensorPlacement:
    """Sensors strapped on the segments: mounting rotation and lever arm of each.

    Parameters
    ----------
    mounts : sequence of SensorMount
    limb_axis : (3,) float64, unit
        The limb's long axis (limb frame).
    limb_lever_m : float
        Distance of every limb sensor from the world-fixed joint centre along the limb axis.
    thorax_lever_m : float
        Height of the thorax sensor above a world-fixed pelvis pivot (thorax −X), metres.
    """

    def __init__(self, mounts: Sequence[SensorMount], limb_axis: np.ndarray,
                 limb_lever_m: float = 0.15, thorax_lever_m: float = 0.3) -> None:
        self.mounts = list(mounts)
        if not self.mounts:
            raise ValueError("need at least one sensor")
        for m in self.mounts:
            if m.segment not in ("thorax", "limb"):
                raise ValueError(f"segment must be 'thorax' or 'limb', got {m.segment!r}")
        self.mount_q = Q.check_quaternions(np.array([m.mount for m in self.mounts]),
                                           normalize=True, name="mount")
        self.on_limb = np.array([m.segment == "limb" for m in self.mounts])
        for name, v in (("limb_lever_m", limb_lever_m), ("thorax_lever_m", thorax_lever_m)):
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"{name} must be >= 0, got {v!r}")
        self.limb_lever_m = float(limb_lever_m)
        self.thorax_lever_m = float(thorax_lever_m)
        # each sensor's position relative to its world-fixed pivot, in the sensor frame
        lever = np.where(self.on_limb[:, None], self.limb_lever_m * limb_axis,
                         -self.thorax_lever_m * _X)
        self.lever = Q.rotate(Q.conjugate(self.mount_q), lever)  # (S, 3) m

    def __len__(self) -> int:
        return len(self.mounts)

    def orientations(self, thorax: np.ndarray, joint: np.ndarray) -> np.ndarray:
        """Each sensor relative to world (N, S, 4), error-free, from the thorax relative to
        world and the joint (limb relative to thorax), both (N, 4)."""
        segment = np.where(self.on_limb[None, :, None], Q.multiply(thorax, joint)[:, None, :],
                           thorax[:, None, :])
        return Q.multiply(segment, self.mount_q[None, :, :])


@dataclass(frozen=True)
class Readings:
    """What the sensors report at ``K`` instants (arrays over K, S sensors).

    Attributes
    ----------
    quaternions : (K, S, 4) float64, unit, sensor relative to world, with errors
    gyro : (K, S, 3) float64, rad/s, sensor frame
    calibration : (K, S) int, ``CALIB_STAT`` bytes
    accel : (K, S, 3) float64, m/s², sensor frame
    mag : (K, S, 3) float64, µT, sensor frame
    """

    quaternions: np.ndarray
    gyro: np.ndarray
    calibration: np.ndarray
    accel: np.ndarray
    mag: np.ndarray


@dataclass
class _Disturbances:
    """One sensor's magnetic disturbance events and calibration times."""

    calib_times: np.ndarray  # (3,) s, full calibration of gyr, acc, mag
    events: list[tuple[float, float, float]] = field(default_factory=list)  # start, dur, peak
    next_event: float = math.inf


class SensorErrors:
    """The error processes of the sensors of a :class:`SensorPlacement` (module docstring);
    stateful: the times asked for must not go back.

    Parameters
    ----------
    noise : NoiseModel
    placement : SensorPlacement
        The sensors (their number, and the lever arms of the accelerometers).
    rng : numpy.random.Generator
        The patient's generator, drawn from (module docstring, "Random streams").
    seed : numpy.random.SeedSequence
        The patient's seed sequence (the accelerometer/magnetometer stream derives from it).
    """

    def __init__(self, noise: NoiseModel, placement: SensorPlacement,
                 rng: np.random.Generator, seed: np.random.SeedSequence) -> None:
        self.noise = nz = noise
        self.placement = placement
        self.n = n = len(placement)
        self._rng = rng
        self._last_t: float | None = None
        self._drift = rng.standard_normal((n, 3)) * np.radians(
            [nz.drift_tilt_deg, nz.drift_tilt_deg, nz.drift_heading_deg])  # rad, world frame
        self._bias = rng.standard_normal((n, 3)) * math.radians(nz.gyro_bias_dps)  # rad/s
        self._sensors = []
        for _ in range(n):
            e = _Disturbances(calib_times=nz.calibration_time_s * rng.uniform(0.2, 1.0, size=3))
            e.next_event = self._event_gap()
            self._sensors.append(e)
        # one stream per error process: the numbers do not depend on how a simulator batches
        # its calls (measure_many of 64 samples or 1 draws the same values per sample)
        self._rng_drift, self._rng_white, self._rng_gyro, self._rng = (
            np.random.default_rng(int(x)) for x in rng.integers(0, 2**63 - 1, size=4))
        self._rng_raw = np.random.default_rng(
            np.random.SeedSequence(seed.entropy, spawn_key=(*seed.spawn_key, _RAW_KEY)))

    def _event_gap(self) -> float:
        rate = self.noise.disturbance_rate_hz
        return float(self._rng.exponential(1.0 / rate)) if rate > 0 else math.inf

    def one(self, t: float, sensors: np.ndarray, elapsed: float,
            positions: np.ndarray | None = None) -> Readings:
        """Readings (K = 1) at time ``t`` from the true sensor orientations ``sensors``
        (3, S, 4) at ``t``, ``t + h``, ``t - h`` (h = :data:`RAW_STEP_S`); ``elapsed``: time
        the sensors have been fusing (calibration progress); ``positions`` (3, S, 3): the
        sensors' world positions at those times relative to world-fixed points, when the
        placement's fixed lever arms do not give them (a chain of segments)."""
        t = float(t)
        if self._last_t is not None and t < self._last_t:
            raise ValueError(f"measure() went back in time: {t} < {self._last_t}")
        dt = 0.0 if self._last_t is None else t - self._last_t
        self._last_t = t
        nz = self.noise
        s = self.n
        q_true = sensors[0]
        gyro = _rate(q_true, sensors[1])
        sig = np.radians([nz.drift_tilt_deg, nz.drift_tilt_deg, nz.drift_heading_deg])
        if dt > 0:
            a = math.exp(-dt / nz.drift_time_s)
            self._drift = a * self._drift + math.sqrt(1.0 - a * a) * sig * (
                self._rng_drift.standard_normal((s, 3)))
        heading = np.array([self._disturbance(err, t) for err in self._sensors])
        e_world = exp_map(self._drift + heading[:, None] * _Z)
        white = exp_map(self._rng_white.standard_normal((s, 3)) * math.radians(nz.white_deg))
        q = Q.multiply(Q.multiply(e_world, q_true), white)
        out_q = Q.canonical(q / np.linalg.norm(q, axis=1, keepdims=True))
        gyro += self._bias + self._rng_gyro.standard_normal((s, 3)) * math.radians(
            nz.gyro_noise_dps)
        disturbed = np.abs(heading) > _DISTURBED_RAD
        calib = np.array([_calibration_byte(err.calib_times, elapsed, bool(d))
                          for err, d in zip(self._sensors, disturbed, strict=True)])
        accel, mag = self._raw(q_true, sensors[1], sensors[2], heading, positions)
        return Readings(out_q[None], gyro[None], calib[None], accel[None], mag[None])

    def many(self, ts: np.ndarray, q_true: np.ndarray, q_next: np.ndarray,
             q_prev: np.ndarray, positions: np.ndarray | None = None) -> Readings:
        """Readings at increasing times ``ts`` (K,), vectorised, from the true sensor
        orientations (K, S, 4) at ``ts``, ``ts + h``, ``ts - h`` (and optionally their world
        positions ``positions`` (3, K, S, 3), as in :meth:`one`); calibration progress is
        ``ts``. The same error processes as ``K`` calls of :meth:`one` (the random draws are
        made in another order, so the numbers differ)."""
        k = len(ts)
        if np.any(np.diff(ts) < 0) or (self._last_t is not None and ts[0] < self._last_t):
            raise ValueError("measure_many() times must increase and not go back in time")
        prev = ts[0] if self._last_t is None else self._last_t
        dts = np.diff(np.concatenate(([prev], ts)))
        self._last_t = float(ts[-1])
        nz = self.noise
        s = self.n
        gyro = _rate(q_true, q_next)  # (K, S, 3)
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
        heading = np.array([[self._disturbance(err, float(t)) for err in self._sensors]
                            for t in ts])  # (K, S)
        e_world = exp_map(drift + heading[..., None] * _Z)
        white = exp_map(self._rng_white.standard_normal((k, s, 3)) * math.radians(nz.white_deg))
        q = Q.multiply(Q.multiply(e_world, q_true), white)
        out_q = Q.canonical(q / np.linalg.norm(q, axis=-1, keepdims=True))
        gyro = gyro + self._bias + self._rng_gyro.standard_normal((k, s, 3)) * math.radians(
            nz.gyro_noise_dps)
        times = np.array([err.calib_times for err in self._sensors])  # (S, 3)
        with np.errstate(divide="ignore", invalid="ignore"):
            levels = np.where(times[None] <= 0, 3,
                              np.minimum(3, np.floor(4.0 * ts[:, None, None] /
                                                     np.where(times > 0, times, 1.0)[None])))
        levels = levels.astype(int)
        mag = np.where(np.abs(heading) > _DISTURBED_RAD, np.minimum(levels[..., 2], 1),
                       levels[..., 2])
        system = np.minimum(np.minimum(levels[..., 0], levels[..., 1]), mag)
        calib = (system << 6) | (levels[..., 0] << 4) | (levels[..., 1] << 2) | mag
        accel, field_ = self._raw(q_true, q_next, q_prev, heading, positions)
        return Readings(out_q, gyro, calib, accel, field_)

    def _raw(self, q_true: np.ndarray, q_next: np.ndarray, q_prev: np.ndarray,
             heading: np.ndarray, positions: np.ndarray | None
             ) -> tuple[np.ndarray, np.ndarray]:
        accel, mag = specific_force_and_field(q_true, q_next, q_prev, self.placement.lever,
                                              heading, self.noise.earth_field, positions)
        noise = self._rng_raw.standard_normal((*heading.shape, 6))
        return (accel + self.noise.accel_noise * noise[..., :3],
                mag + self.noise.mag_noise_ut * noise[..., 3:])

    def _disturbance(self, err: _Disturbances, t: float) -> float:
        nz = self.noise
        while err.next_event <= t:
            dur = float(self._rng.uniform(*nz.disturbance_duration_s))
            peak = float(self._rng.standard_normal()) * math.radians(nz.disturbance_deg)
            err.events.append((err.next_event, dur, peak))
            err.next_event += self._event_gap()
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


def _rate(q: np.ndarray, q_next: np.ndarray) -> np.ndarray:
    """Sensor-frame angular rate (..., 3) rad/s from ``q(t)* ⊗ q(t + h)``."""
    rel = Q.multiply(Q.conjugate(q), q_next)
    rel *= np.where(rel[..., :1] < 0, -1.0, 1.0)
    return 2.0 * rel[..., 1:] / RAW_STEP_S


def specific_force_and_field(q_true: np.ndarray, q_next: np.ndarray, q_prev: np.ndarray,
                             lever: np.ndarray | None, heading: np.ndarray,
                             earth_field: np.ndarray, positions: np.ndarray | None = None
                             ) -> tuple[np.ndarray, np.ndarray]:
    """Error-free accelerometer (m/s²) and magnetometer (µT) readings (..., S, 3), sensor frame.

    Parameters
    ----------
    q_true, q_next, q_prev : (..., S, 4) float64
        Sensor relative to world at ``t``, ``t + h``, ``t - h`` (h = :data:`RAW_STEP_S`).
    lever : (S, 3) float64, m, or None
        Each sensor's position relative to its world-fixed pivot, sensor frame (a sensor on
        one segment turning about a fixed point); unused when ``positions`` is given.
    heading : (..., S) float64, rad
        The heading disturbance of the device-fusion model.
    earth_field : (3,) float64, µT, world frame
    positions : (3, ..., S, 3) float64, m, optional
        The sensors' world positions at ``t``, ``t + h``, ``t - h`` relative to world-fixed
        points (a sensor on a chain of segments, :mod:`rig.sim.limb.whole`); default from
        ``lever``.
    """
    h = RAW_STEP_S
    # sensor positions relative to their world-fixed pivots; central second difference
    if positions is None:
        p0 = Q.rotate(q_true, lever)
        a_lin = (Q.rotate(q_next, lever) - 2.0 * p0 + Q.rotate(q_prev, lever)) / (h * h)
    else:
        a_lin = (positions[1] - 2.0 * positions[0] + positions[2]) / (h * h)
    f_world = a_lin + GRAVITY * _Z
    # magnetometer: the earth field with its horizontal part turned by -h(t) about world Z:
    # a field the device's fusion follows fully reads as a heading error of +h(t)
    m = earth_field
    c, s = np.cos(heading), np.sin(heading)
    m_world = np.stack((c * m[0] + s * m[1], -s * m[0] + c * m[1],
                        np.full_like(heading, m[2])), axis=-1)
    inv = Q.conjugate(q_true)
    return Q.rotate(inv, f_world), Q.rotate(inv, m_world)


def _calibration_byte(times: np.ndarray, elapsed: float, disturbed: bool) -> int:
    levels = []
    for tc in times:
        levels.append(3 if tc <= 0 else min(3, int(4.0 * elapsed / tc)))
    gyr, acc, mag = levels
    if disturbed:
        mag = min(mag, 1)
    system = min(gyr, acc, mag)
    return (system << 6) | (gyr << 4) | (acc << 2) | mag
