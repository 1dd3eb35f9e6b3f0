"""Simulated patients: one factory for the tests, the benchmarks and ``rig record``'s accuracy.

A simulated patient is a known range of motion (a :class:`models.constraint.JointConstraint`)
worn by a :class:`rig.sim.limb.SimulatedLimb`. Everything that needs a patient whose truth is
known builds it here: the calibration tests (``tests/calibration``), the boundary benchmark
(``benchmarks/bench_boundary.py``, offline recordings), and the end-to-end accuracy check of
``rig record`` (``benchmarks/record_accuracy.py``, ``benchmarks/bench_record.py accuracy``, through
the simulators on real ptys).

- :func:`star_patient`: a seeded random concave star polygon
  (:func:`models.evaluation.random_star_polygon`) turned so that its centre lies within
  ``max_tilt_deg`` of the arm at the side (+X), with a twist range ``[-a, b]``, ``a, b`` in
  20-70°. Seeds 101-105 are ``bench_record.py accuracy``'s held-out patients and 100-104
  ``bench_boundary.py``'s; tests use other seeds.
- :func:`misplaced_mounts`: the default straps (:func:`rig.sim.limb.default_mounts`) each turned
  ``misplace_deg`` about a random axis — the draws of the ``misplace_deg`` key of
  ``sim://imu-stream`` / ``sim://bno055`` (:mod:`rig.sim.imu`).
- :func:`patient_limb`: the patient wearing misplaced sensors and performing the guided
  calibration protocol (:class:`calibration.protocol.CalibrationProtocol`) through
  :class:`~rig.sim.limb.SimulatedLimb`'s own ``calibration_protocol`` support, then moving
  freely.
- :func:`patient_from_url`: the one resolver of a port string's patient keys (``patient=<shape
  name | constraint file>``, ``seed``, ``noise``, ...; :data:`PATIENT_KEYS`) into a
  :class:`~rig.sim.limb.SimulatedLimb`, for the IMU simulators and the back-driven servo chain
  (:mod:`rig.devices._sim_backends`); :func:`resolve_patient` the shape-or-file part. Errors are
  one-line :class:`~rig.errors.RigConfigError` naming the port and the key.
- :func:`record_imu` / :func:`record_servo`: offline recordings (no pty, no driver) for fast
  tests and benchmarks — the two IMUs through the sensor error model (noise, drift, magnetic
  disturbances, misplaced straps; :meth:`~rig.sim.limb.SimulatedLimb.measure_many`), or the
  back-driven servo limb (the true joint read through three encoders of 4096 ticks per turn,
  no drift). A :class:`Recording` holds the samples and the protocol's phase windows.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from models import quaternion as Q
from rig.errors import RigConfigError
from rig.sim.limb import NoiseModel, SensorMount, SimulatedLimb, default_mounts
from rig.sim.urls import SimUrl

__all__ = ["PATIENT_KEYS", "Recording", "misplaced_mounts", "patient_from_url", "patient_limb",
           "record_imu", "record_servo", "resolve_patient", "star_patient"]

_ENCODER_TICKS = 4096  # per turn: rig.sim.dynamixel.servo.TICKS_PER_REV (X-series)

PATIENT_KEYS = ("patient", "seed", "noise", "misplace_deg", "excursion", "speed", "calibrate",
                "neutral", "neutral_sd")
"""The port-string keys of a simulated patient (:func:`patient_from_url`); a simulator accepts
those it lists as known."""
_NEUTRAL_HOLD_S = 2.0  # SimulatedLimb's defaults: neutral hold and ramp, seconds
_NEUTRAL_RAMP_S = 1.5


def star_patient(seed: int, *, max_tilt_deg: float = 10.0):
    """A seeded random concave star polygon (:func:`models.evaluation.random_star_polygon`)
    turned so that its centre lies within ``max_tilt_deg`` of the arm at the side (+X) — the
    neutral pose of the calibration protocol must be reachable — with a physiological twist
    range ``[-a, b]``, ``a, b`` uniform in 20-70° (0 = neutral rotation inside it).

    Returns
    -------
    models.constraint.JointConstraint
    """
    from models.constraint import JointConstraint
    from models.evaluation import random_star_polygon

    rng = np.random.default_rng([seed, 0xACC])
    star = random_star_polygon(seed, name=f"star-{seed}", twist=False)
    c = Q.check_vectors(star.swing.interior)
    tilt = math.radians(rng.uniform(0.0, max_tilt_deg))
    az = rng.uniform(0.0, 2.0 * math.pi)
    target = np.array([math.cos(tilt), math.sin(tilt) * math.cos(az),
                       math.sin(tilt) * math.sin(az)])
    r = Q.from_two_vectors(c, target)
    verts = Q.rotate(np.broadcast_to(r, (len(star.swing.vertices), 4)),
                     Q.check_vectors(star.swing.vertices))
    twist = (-float(rng.uniform(20.0, 70.0)), float(rng.uniform(20.0, 70.0)))
    return JointConstraint.polygon(verts, target, twist=twist, name=f"star-{seed}")


def misplaced_mounts(rng: np.random.Generator, misplace_deg: float = 25.0,
                     sensors: int = 2) -> list[SensorMount]:
    """Sensor 0 on the thorax, the others on the limb (:func:`rig.sim.limb.default_mounts`),
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


def patient_limb(constraint, seed: int, *, noise: NoiseModel | None = None,
                 misplace_deg: float = 25.0, protocol="default",
                 protocol_start_s: float = 5.0, **kwargs) -> SimulatedLimb:
    """The patient ``constraint`` wearing two misplaced IMUs, performing the calibration
    protocol, then moving freely.

    Parameters
    ----------
    constraint : JointConstraint
    seed : int
        Seeds the motion and the sensor errors; the straps are drawn from
        ``default_rng([seed, 0x5EA7])`` (as ``sim://imu-stream?seed=...`` draws them).
    noise : NoiseModel, optional
        Default: :class:`~rig.sim.limb.NoiseModel` (noise, drift, disturbances on).
    misplace_deg : float
        How far each strap is turned off its nominal mounting (:func:`misplaced_mounts`).
    protocol : CalibrationProtocol or None
        ``"default"``: ``CalibrationProtocol()``; None: free motion from time 0.
    protocol_start_s : float
        When the protocol starts: 5 s, by which the sensors' calibration status has reached 3
        under the default noise model (``calibration_time_s`` 5 s).
    **kwargs
        Further :class:`~rig.sim.limb.SimulatedLimb` keywords (``sway_deg``, ``excursion``,
        ``neutral_every_s`` and the other neutral-checkpoint keywords, ...).
    """
    if isinstance(protocol, str) and protocol == "default":
        from calibration.protocol import CalibrationProtocol

        protocol = CalibrationProtocol()
    mounts = misplaced_mounts(np.random.default_rng([seed, 0x5EA7]), misplace_deg)
    return SimulatedLimb(constraint, sensors=mounts, noise=noise, seed=seed,
                         calibration_protocol=protocol, protocol_start_s=protocol_start_s,
                         **kwargs)


def resolve_patient(value: str, *, url: str, key: str = "patient"):
    """The range of motion a port string's ``patient=`` names: a shipped shape or a
    constraint file.

    Parameters
    ----------
    value : str
        One of :data:`models.shapes.SHAPES` (``original``, ``c-shape``, ...) or a path to a
        constraint YAML file.
    url : str
        The port string (named in errors).

    Returns
    -------
    models.constraint.JointConstraint

    Raises
    ------
    RigConfigError
        Neither a shape nor a readable, valid constraint file: one line naming the port, the
        key and the value.
    """
    from models.constraint import load_constraint
    from models.shapes import SHAPES, load_shape

    if value in SHAPES:
        return load_shape(value)
    try:
        c = load_constraint(value)
        c.require_kind("a simulated patient")
        return c
    except FileNotFoundError:
        raise RigConfigError(f"{url}: {key}={value!r}: not a shape name ({', '.join(SHAPES)}) "
                             f"nor an existing constraint file") from None
    except (OSError, ValueError) as err:  # ConstraintError is a ValueError
        raise RigConfigError(f"{url}: {key}={value!r}: {_one_line(err)}") from err


def _one_line(err: BaseException) -> str:
    return " ".join(str(err).split())


def patient_from_url(q: SimUrl, *, sensors: int = 2,
                     misplaced_straps: bool = True) -> SimulatedLimb:
    """The simulated patient a port string's patient keys describe (the keys the URL's
    simulator accepts among :data:`PATIENT_KEYS`; absent keys take their defaults).

    ``patient`` (a shape or a constraint file, :func:`resolve_patient`; default the 60° cone
    :data:`rig.sim.limb.DEFAULT_CONSTRAINT`), ``seed`` (0), ``noise`` (on: ``NoiseModel()``;
    off: ``NoiseModel.ideal()``), ``misplace_deg`` (5: each strap turned this far,
    :func:`misplaced_mounts` of ``default_rng([seed, 0x5EA7])``), ``excursion`` (1, in
    (0, 3]), ``speed`` (1, in (0, 20]), ``calibrate`` (off: the guided calibration protocol
    from 2 s), ``neutral`` (0 or a checkpoint interval >= 6 s), ``neutral_sd`` (2°, 0..10).

    Parameters
    ----------
    q : SimUrl
        The parsed port string.
    sensors : int
        Sensors the patient wears (0 on the thorax, the others on the limb).
    misplaced_straps : bool
        Straps drawn by ``misplace_deg`` (IMU simulators); False: the default mountings
        (:func:`rig.sim.limb.default_mounts`; a servo limb wears no IMU).

    Raises
    ------
    RigConfigError
        A bad value or patient, one line naming the port and the key.
    """
    seed = q.integer("seed", 0)
    patient = q.text("patient")
    constraint = resolve_patient(patient, url=q.url) if patient is not None else None
    noise = NoiseModel() if q.flag("noise", True) else NoiseModel.ideal()
    misplace = q.number("misplace_deg", 5.0, 0.0, 90.0) if misplaced_straps else None
    excursion = q.number("excursion", 1.0, 0.0, 3.0, open_lo=True)
    speed = q.number("speed", 1.0, 0.0, 20.0, open_lo=True)
    neutral = q.number("neutral", 0.0, 0.0)
    least = 2.0 * _NEUTRAL_RAMP_S + _NEUTRAL_HOLD_S + 1.0
    if 0.0 < neutral < least:
        raise RigConfigError(f"{q.url}: neutral={q.text('neutral')!r}: must be 0 (off) or a "
                             f"checkpoint interval >= {least:g} s")
    neutral_sd = q.number("neutral_sd", 2.0, 0.0, 10.0)
    protocol = None
    if q.flag("calibrate", False):
        from calibration.protocol import CalibrationProtocol

        protocol = CalibrationProtocol()
    mounts: int | list[SensorMount] = sensors
    if misplace is not None:  # drawn from a stream of their own: the motion is unchanged
        mounts = misplaced_mounts(np.random.default_rng([seed, 0x5EA7]), misplace, sensors)
    try:
        return SimulatedLimb(constraint, sensors=mounts, noise=noise, excursion=excursion,
                             speed=speed, seed=seed, calibration_protocol=protocol,
                             neutral_every_s=neutral, neutral_hold_s=_NEUTRAL_HOLD_S,
                             neutral_ramp_s=_NEUTRAL_RAMP_S, neutral_sd_deg=neutral_sd)
    except ValueError as err:
        raise RigConfigError(f"{q.url}: patient={patient!r}: {_one_line(err)}") from err


@dataclass
class Recording:
    """Samples of one simulated session (arrays over N instants)."""

    t: np.ndarray  # (N,) s, patient time (the protocol starts at start_s)
    thorax: np.ndarray  # (N, 4) thorax sensor in its world (IMU) or identity (servo)
    limb: np.ndarray  # (N, 4) limb sensor in its world (IMU) or joint FK (servo)
    status: np.ndarray  # (N,) CALIB_STAT byte of the sensor with the lower system level, or 0xFF
    truth: np.ndarray  # (N, 4) ground-truth joint orientation
    protocol: object  # CalibrationProtocol or None
    start_s: float  # when the protocol started

    @property
    def end_s(self) -> float:
        """When the protocol ended (free motion follows, blended in by the limb)."""
        return self.start_s + (self.protocol.duration_s if self.protocol is not None else 0.0)

    def window(self, phase: str) -> np.ndarray:
        """Mask of the samples in a protocol phase (``"static"``, ``"functional"``) or of the
        free motion after the protocol (``"free"``)."""
        if phase == "free":
            return self.t >= self.end_s
        if self.protocol is None:
            raise ValueError("this recording has no calibration protocol")
        a, b = self.protocol.windows()[phase]
        return (self.t >= self.start_s + a) & (self.t <= self.start_s + b)


def _times(limb: SimulatedLimb, duration_s: float, rate_hz: float) -> np.ndarray:
    n = round((limb.protocol_end_s + duration_s) * rate_hz)
    return np.arange(n) / rate_hz


def record_imu(limb: SimulatedLimb, duration_s: float, rate_hz: float = 100.0,
               chunk: int = 2000) -> Recording:
    """Sample the limb's two sensors (0 thorax, 1 limb) at ``rate_hz`` from time 0 to the end of
    the protocol plus ``duration_s`` seconds, through the sensor error model
    (:meth:`~rig.sim.limb.SimulatedLimb.measure_many`, ``chunk`` samples per call)."""
    t = _times(limb, duration_s, rate_hz)
    thorax, arm, status, truth = [], [], [], []
    for i in range(0, len(t), chunk):
        ms = limb.measure_many(t[i:i + chunk])
        q = np.stack([m.quaternions for m in ms])
        cal = np.stack([m.calibration for m in ms]).astype(np.int64)
        thorax.append(q[:, 0])
        arm.append(q[:, 1])
        status.append(np.where((cal[:, 0] >> 6) <= (cal[:, 1] >> 6), cal[:, 0], cal[:, 1]))
        truth.append(np.stack([m.truth.joint[0] for m in ms]))
    return Recording(t, np.concatenate(thorax), np.concatenate(arm), np.concatenate(status),
                     np.concatenate(truth), limb.calibration_protocol, limb.protocol_start_s)


def record_servo(limb: SimulatedLimb, duration_s: float, rate_hz: float = 100.0) -> Recording:
    """The back-driven servo limb: the true joint read through 3 encoders of 4096 ticks per turn
    (Z-Y-X chain), i.e. quantised to 0.088° per joint; no drift, no straps. ``thorax`` is the
    identity, ``limb`` the chain's forward kinematics."""
    from scipy.spatial.transform import Rotation

    t = _times(limb, duration_s, rate_hz)
    n = len(t)
    truth = limb.joint(t)
    step = 2 * math.pi / _ENCODER_TICKS
    ticks = np.round(Q.to_rotation(truth).as_euler("ZYX") / step)
    fk = Q.from_rotation(Rotation.from_euler("ZYX", ticks * step))
    return Recording(t, np.tile(Q.IDENTITY, (n, 1)), fk, np.full(n, 0xFF), truth,
                     limb.calibration_protocol, limb.protocol_start_s)
