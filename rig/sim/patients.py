"""Simulated patients: one factory for the tests, the benchmarks and ``rig record``'s accuracy.

A simulated patient is a known range of motion worn by a :class:`rig.sim.limb.SimulatedLimb`: a
joint's constraint (:class:`models.constraint.JointConstraint`) by a
:class:`~rig.sim.limb.SimulatedJoint`, an arm's or leg's limits (:class:`models.limb.Limb`) by a
:class:`~rig.sim.limb.SimulatedWholeLimb`. Everything that needs a patient whose truth is known
builds it here: the calibration tests (``tests/calibration``), the boundary benchmarks
(``benchmarks/bench_boundary.py``, ``benchmarks/bench_chain_boundary.py``, offline recordings),
and the end-to-end accuracy check of ``rig record`` (``benchmarks/record_accuracy.py``,
``benchmarks/bench_record.py accuracy``, through the simulators on real ptys).

- :func:`seeded_patient`: the one factory — the patient of a seed and its limits (a joint's
  constraint, a limb file, or an anatomical ``"arm"`` / ``"leg"``) wearing misplaced sensors
  and performing its calibration protocol, then moving freely.
- :func:`star_constraint`: a seeded random concave star polygon
  (:func:`models.evaluation.random_star_polygon`) turned so that its centre lies within
  ``max_tilt_deg`` of the arm at the side (+X), with a twist range ``[-a, b]``, ``a, b`` in
  20-70°. Seeds 101-105 are ``bench_record.py accuracy``'s held-out patients and 100-104
  ``bench_boundary.py``'s; tests use other seeds.
- :func:`anatomical_limb`: a seeded, physiologically plausible arm or leg with couplings.
- :func:`patient_class`: which simulated limb wears given limits (each limb's
  :attr:`~rig.sim.limb.SimulatedLimb.limits_type`); the limb itself says what differs — its
  calibration protocol and its straps (``misplace_deg``: :func:`rig.sim.limb.misplaced_mounts`
  for a joint, the draws of the ``misplace_deg`` key of ``sim://imu-stream`` / ``sim://bno055``,
  :mod:`rig.sim.imu`; :func:`rig.sim.limb.limb_mounts` for an arm or leg).
- :func:`patient_from_url`: the one resolver of a port string's patient keys (``patient=<shape
  name | constraint file>``, ``seed``, ``noise``, ...; :data:`PATIENT_KEYS`) into a
  :class:`~rig.sim.limb.SimulatedJoint`, for the IMU simulators and the back-driven servo
  joint (:mod:`rig.devices._sim_backends`); :func:`resolve_patient` the shape-or-file part;
  :func:`limb_from_url` an arm's or leg's (:data:`LIMB_KEYS`). Errors are one-line
  :class:`~rig.errors.RigConfigError` naming the port and the key.
- :func:`record_imu` / :func:`record_servo`: offline recordings (no pty, no driver) for fast
  tests and benchmarks — the two IMUs through the sensor error model (noise, drift, magnetic
  disturbances, misplaced straps; :meth:`~rig.sim.limb.SimulatedLimb.measure_many`), or the
  back-driven servo joint (the true joint read through three encoders, 4096 ticks per turn by
  default — an X series' — or each its own, no drift). A :class:`Recording` holds the samples
  and the protocol's phase windows;
  :func:`record_limb_imu` / :class:`LimbRecording` the same for an arm or leg.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from calibration.clinical import mirror_directions
from calibration.joint_angles import from_angles
from calibration.joints import JOINTS
from calibration.protocol import CalibrationProtocol
from models import quaternion as Q
from models.constraint import JointConstraint, load_constraint
from models.evaluation import random_star_polygon
from models.kinds import DEFAULT_KIND, get_kind
from models.limb import Limb, load_limits
from models.shapes import SHAPES, load_shape
from rig.errors import RigConfigError
from rig.sim.limb import (
    NoiseModel,
    SensorMount,
    SimulatedJoint,
    SimulatedLimb,
    SimulatedWholeLimb,
    misplaced_mounts,
)
from rig.sim.urls import SimUrl

__all__ = ["LIMB_KEYS", "PATIENT_KEYS", "LimbRecording", "Recording", "anatomical_limb",
           "limb_from_url", "patient_class", "patient_from_url", "record_imu",
           "record_limb_imu", "record_servo", "resolve_patient", "seeded_patient",
           "star_constraint"]

_ENCODER_TICKS = 4096.0  # per turn, by default: an X series' (rig.devices.kinematics.TICKS_PER_REV)

PATIENT_KEYS = ("patient", "seed", "noise", "misplace_deg", "excursion", "speed", "calibrate",
                "neutral", "neutral_sd")
"""The port-string keys of a simulated patient (:func:`patient_from_url`); a simulator accepts
those it lists as known."""
LIMB_KEYS = ("limb", "side")
"""The port-string keys of an arm or leg patient (:func:`limb_from_url`; ``sim://imu-stream``
only)."""
_NEUTRAL_HOLD_S = 2.0  # SimulatedJoint's defaults: neutral hold and ramp, seconds
_NEUTRAL_RAMP_S = 1.5


def star_constraint(seed: int, *, max_tilt_deg: float = 10.0) -> JointConstraint:
    """A seeded random concave star polygon (:func:`models.evaluation.random_star_polygon`)
    turned so that its centre lies within ``max_tilt_deg`` of the arm at the side (+X) — the
    neutral pose of the calibration protocol must be reachable — with a physiological twist
    range ``[-a, b]``, ``a, b`` uniform in 20-70° (0 = neutral rotation inside it).

    Returns
    -------
    models.constraint.JointConstraint
    """
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
    if value in SHAPES:
        return load_shape(value)
    try:
        c = load_constraint(value)
        c.require_swing_twist("a simulated patient")
        return c
    except FileNotFoundError:
        raise RigConfigError(f"{url}: {key}={value!r}: not a shape name ({', '.join(SHAPES)}) "
                             f"nor an existing constraint file") from None
    except (OSError, ValueError) as err:  # ConstraintError is a ValueError
        raise RigConfigError(f"{url}: {key}={value!r}: {_one_line(err)}") from err


def _one_line(err: BaseException) -> str:
    return " ".join(str(err).split())


def _motion_keys(q: SimUrl) -> tuple[NoiseModel, float, float, float, float]:
    """The keys every simulated patient reads alike: ``noise``, ``excursion``, ``speed``,
    ``neutral`` (0 or a checkpoint interval long enough for the ramps and the hold) and
    ``neutral_sd``; one-line errors naming the port and the key."""
    noise = NoiseModel() if q.flag("noise", True) else NoiseModel.ideal()
    excursion = q.number("excursion", 1.0, 0.0, 3.0, open_lo=True)
    speed = q.number("speed", 1.0, 0.0, 20.0, open_lo=True)
    neutral = q.number("neutral", 0.0, 0.0)
    least = 2.0 * _NEUTRAL_RAMP_S + _NEUTRAL_HOLD_S + 1.0
    if 0.0 < neutral < least:
        raise RigConfigError(f"{q.url}: neutral={q.text('neutral')!r}: must be 0 (off) or a "
                             f"checkpoint interval >= {least:g} s")
    return noise, excursion, speed, neutral, q.number("neutral_sd", 2.0, 0.0, 10.0)


def patient_from_url(q: SimUrl, *, sensors: int = 2,
                     misplaced_straps: bool = True) -> SimulatedJoint:
    """The simulated patient a port string's patient keys describe (the keys the URL's
    simulator accepts among :data:`PATIENT_KEYS`; absent keys take their defaults).

    ``patient`` (a shape or a constraint file, :func:`resolve_patient`; default the 60° cone
    :data:`rig.sim.limb.DEFAULT_CONSTRAINT`), ``seed`` (0), ``noise`` (on: ``NoiseModel()``;
    off: ``NoiseModel.ideal()``), ``misplace_deg`` (5: each strap turned this far,
    :func:`rig.sim.limb.misplaced_mounts` of ``default_rng([seed, 0x5EA7])``), ``excursion``
    (1, in (0, 3]), ``speed`` (1, in (0, 20]), ``calibrate`` (off: the guided calibration
    protocol from 2 s), ``neutral`` (0 or a checkpoint interval >= 6 s), ``neutral_sd`` (2°,
    0..10).

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
    noise, excursion, speed, neutral, neutral_sd = _motion_keys(q)
    misplace = q.number("misplace_deg", 5.0, 0.0, 90.0) if misplaced_straps else None
    protocol = None
    if q.flag("calibrate", False):
        protocol = CalibrationProtocol()
    mounts: int | list[SensorMount] = sensors
    if misplace is not None:  # drawn from a stream of their own: the motion is unchanged
        mounts = misplaced_mounts(np.random.default_rng([seed, 0x5EA7]), misplace, sensors)
    try:
        return SimulatedJoint(constraint, sensors=mounts, noise=noise, excursion=excursion,
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
    """Sample times from 0 to the end of the patient's protocol plus ``duration_s``."""
    n = round((limb.protocol_end_s + duration_s) * rate_hz)
    return np.arange(n) / rate_hz


def record_imu(limb: SimulatedJoint, duration_s: float, rate_hz: float = 100.0,
               chunk: int = 2000) -> Recording:
    """Sample the limb's two sensors (0 thorax, 1 limb) at ``rate_hz`` from time 0 to the end of
    the protocol plus ``duration_s`` seconds, through the sensor error model
    (:meth:`~rig.sim.limb.SimulatedJoint.measure_many`, ``chunk`` samples per call)."""
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


def record_servo(limb: SimulatedJoint, duration_s: float, rate_hz: float = 100.0, *,
                 ticks_per_rev=_ENCODER_TICKS) -> Recording:
    """The back-driven servo limb: the true joint read through 3 encoders (Z-Y-X axes) of
    ``ticks_per_rev`` ticks per turn, i.e. quantised to 0.088° per joint at an X series' 4096
    (0.29° at an AX-12A's 1228.8); no drift, no straps, no tick range. ``thorax`` is the
    identity, ``limb`` the servos' forward kinematics.

    Parameters
    ----------
    ticks_per_rev : float or (3,) array_like of float
        Each encoder's resolution (the servo model's ``units.ticks_per_rev``), Z, Y, X.
    """
    t = _times(limb, duration_s, rate_hz)
    n = len(t)
    truth = limb.joint(t)
    step = 2 * math.pi / (float(ticks_per_rev) if np.ndim(ticks_per_rev) == 0 else
                          np.asarray(ticks_per_rev, dtype=np.float64).reshape(3))
    ticks = np.round(Q.to_rotation(truth).as_euler("ZYX") / step)
    fk = Q.from_rotation(Rotation.from_euler("ZYX", ticks * step))
    return Recording(t, np.tile(Q.IDENTITY, (n, 1)), fk, np.full(n, 0xFF), truth,
                     limb.calibration_protocol, limb.protocol_start_s)


# ---------------------------------------------------------------------------------------------
# Anatomical arms and legs (limb constraints with couplings)

_CHAINS = {"arm": (("shoulder", "thorax", "upper-arm"), ("elbow", "upper-arm", "forearm"),
                   ("wrist", "forearm", "hand")),
           "leg": (("hip", "pelvis", "thigh"), ("knee", "thigh", "shank"),
                   ("ankle", "shank", "foot"))}
_AZ_STEP_DEG = 10  # swing polygons: a vertex every 10° of azimuth about the neutral direction


def _clinical_basis(joint: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Right side, rig frames of the parent segment: the child's long axis (+X) in the neutral
    pose ``n``, and the tangent directions in which it moves with the positive clinical
    movements: ``e1`` flexion (ankle: dorsiflexion), ``e2`` adduction (wrist: ulnar deviation;
    ankle: the toes turned medially, inversion with internal rotation).

    The shoulder's are the rig's own (arm hanging along +X, flexion about +Z, abduction towards
    +Z, :class:`calibration.protocol.CalibrationProtocol`); the others come from
    :func:`calibration.joint_angles.from_angles` (pure α and pure β, or γ for the ankle, whose β
    turns the foot about its own long axis: a twist, not a swing)."""
    x = np.array([1.0, 0.0, 0.0])
    if joint == "shoulder":
        return x, np.array([0.0, 1.0, 0.0]), np.array([0.0, 0.0, -1.0])

    def axis(a, b, g):
        return Q.rotate(from_angles(a, b, g, joint)[0], x)

    second = (0.0, 0.0, 90.0) if joint == "ankle" else (0.0, 90.0, 0.0)
    return axis(0.0, 0.0, 0.0), axis(90.0, 0.0, 0.0), axis(*second)


def _swing_polygon(joint: str, radii: tuple[float, float, float, float],
                   notches: list[tuple[float, float, float]], jitter: np.ndarray) -> dict:
    """A swing polygon star-shaped about the neutral direction (right side): vertex ``k`` at
    azimuth ``10° k`` (0° flexion, 90° adduction, 180° extension, 270° abduction: :func:
    `_clinical_basis`) and angle ``ρ(ψ)`` from the neutral direction. ``radii`` are ``ρ`` at the
    four cardinal azimuths (the clinical limits of the pure movements, exactly: those vertices
    lie on the movements' great circles); between them ``ρ`` follows an ellipse in each quadrant,
    times ``jitter`` (per vertex, 1 at the cardinal ones), minus the ``notches`` ``(azimuth
    deg, width deg, depth fraction)`` (Gaussian dents: the polygon is concave)."""
    n, e1, e2 = _clinical_basis(joint)
    psi = np.radians(np.arange(0, 360, _AZ_STEP_DEG, dtype=np.float64))
    quad = np.minimum((psi // (0.5 * math.pi)).astype(int), 3)
    u = psi - quad * 0.5 * math.pi
    ra = np.radians(np.asarray(radii))[quad]
    rb = np.radians(np.asarray(radii))[(quad + 1) % 4]
    rho = 1.0 / np.sqrt(np.cos(u) ** 2 / ra**2 + np.sin(u) ** 2 / rb**2) * jitter
    for at, width, depth in notches:
        d = np.angle(np.exp(1j * (psi - math.radians(at))))
        rho = rho * (1.0 - depth * np.exp(-0.5 * (d / math.radians(width)) ** 2))
    tangent = np.cos(psi)[:, None] * e1 + np.sin(psi)[:, None] * e2
    v = np.cos(rho)[:, None] * n + np.sin(rho)[:, None] * tangent
    return {"polygon": {"vertices": v.tolist(), "interior": n.tolist()}}


def _notches(rng: np.random.Generator, count: int) -> list[tuple[float, float, float]]:
    """``count`` notches in distinct quadrants, 30-60° from the cardinal azimuths and narrow
    (σ 6-9°), so that the clinical limits of the pure movements stay where they are drawn (to
    0.5 %)."""
    quads = rng.permutation(4)[:count]
    return [(float(90 * q + 10 * rng.integers(3, 7)), float(rng.uniform(6.0, 9.0)),
             float(rng.uniform(0.15, 0.3))) for q in quads]


def _jitter(rng: np.random.Generator) -> np.ndarray:
    j = rng.uniform(0.97, 1.03, size=360 // _AZ_STEP_DEG)
    j[:: 90 // _AZ_STEP_DEG] = 1.0
    return j


def _mirror_constraint(c: dict) -> dict:
    """A right limb's joint constraint mirrored to the left (:func:`calibration.clinical.
    mirror_directions`: directions ``(x, y, z) → (x, y, −z)``; a rotation's axis
    ``(x, y, z) → (−x, −y, z)`` with the same angle, so a twist about +X changes sign)."""
    out = dict(c)
    if "swing" in c:
        p = c["swing"]["polygon"]
        out["swing"] = {"polygon": {"vertices": mirror_directions(p["vertices"]).tolist(),
                                    "interior": mirror_directions(p["interior"]).tolist()}}
    if "twist" in c:
        out["twist"] = {"min_deg": -c["twist"]["max_deg"], "max_deg": -c["twist"]["min_deg"]}
    if get_kind(c.get("kind", DEFAULT_KIND)).single_axis:  # the hinge's axis block
        ax = c["hinge"]["axis"]
        out["hinge"] = {**c["hinge"], "axis": [-ax[0], -ax[1], ax[2]]}
    return out


def _mirror_joint(j: dict) -> dict:
    out = dict(j)
    if "constraint" in j:
        out["constraint"] = _mirror_constraint(j["constraint"])
    else:
        out["coupled"] = {"by": j["coupled"]["by"], "keyframes": [
            {"at_deg": k["at_deg"], "constraint": _mirror_constraint(k["constraint"])}
            for k in j["coupled"]["keyframes"]]}
    return out


def _u(rng: np.random.Generator, lo: float, hi: float) -> float:
    return float(rng.uniform(lo, hi))


def _leg(rng: np.random.Generator, kinds: dict) -> tuple[list[dict], dict]:
    # hip (AAOS 1965: flexion 120, extension 30, abduction 45, adduction 30, rotation 45 each)
    flex, slr = _u(rng, 100.0, 125.0), _u(rng, 60.0, 80.0)
    ext, add, abd = _u(rng, 10.0, 30.0), _u(rng, 15.0, 30.0), _u(rng, 30.0, 50.0)
    internal, external = _u(rng, 30.0, 45.0), _u(rng, 35.0, 50.0)
    hip_notches, hip_jitter = _notches(rng, int(rng.integers(1, 3))), _jitter(rng)
    # knee (Grood-Suntay flexion = the hinge angle about (0, 0, -1))
    knee_lo, knee_hi = -_u(rng, 0.0, 5.0), _u(rng, 130.0, 150.0)
    # ankle: dorsiflexion (more with the knee bent: the gastrocnemius), plantarflexion, the toes
    # turned medially (inversion) and laterally (eversion), a narrow twist
    dorsi, dorsi_bent, plantar = _u(rng, 10.0, 17.0), _u(rng, 5.0, 8.0), _u(rng, 40.0, 55.0)
    inv, ev, ankle_tw = _u(rng, 20.0, 35.0), _u(rng, 10.0, 20.0), _u(rng, 3.0, 6.0)
    ankle_notches, ankle_jitter = _notches(rng, 1), _jitter(rng)
    hip_twist = {"min_deg": -internal, "max_deg": external}
    hip_kf = []
    for at, f in ((0.0, slr), (45.0, slr + 0.5 * (flex - slr)), (90.0, flex)):
        hip_kf.append({"at_deg": at, "constraint": {
            "swing": _swing_polygon("hip", (f, add, ext, abd), hip_notches, hip_jitter),
            "twist": dict(hip_twist)}})
    ankle_kf = []
    for at, d in ((0.0, dorsi), (90.0, dorsi + dorsi_bent)):
        ankle_kf.append({"at_deg": at, "constraint": {
            "kind": "two-axis",
            "swing": _swing_polygon("ankle", (d, inv, plantar, ev), ankle_notches, ankle_jitter),
            "twist": {"min_deg": -ankle_tw, "max_deg": ankle_tw}}})
    joints = [
        {"coupled": {"by": "knee", "keyframes": hip_kf}},
        {"constraint": {"kind": "hinge", "hinge": {"axis": [0.0, 0.0, -1.0],
                                                   "min_deg": knee_lo, "max_deg": knee_hi}}},
        {"coupled": {"by": "knee", "keyframes": ankle_kf}},
    ]
    clinical = {"hip": {"flexion": flex, "flexion_knee_straight": slr, "extension": ext,
                        "abduction": abd, "adduction": add, "internal_rotation": internal,
                        "external_rotation": external},
                "knee": {"flexion": knee_hi, "extension": -knee_lo},
                "ankle": {"dorsiflexion": dorsi, "dorsiflexion_knee_bent": dorsi + dorsi_bent,
                          "plantarflexion": plantar, "inversion": inv, "eversion": ev,
                          "twist": ankle_tw}}
    return joints, clinical


def _arm(rng: np.random.Generator, kinds: dict) -> tuple[list[dict], dict]:
    # shoulder (AAOS 1965: flexion 180, extension 60, abduction 180, adduction 30-ish); below 165°
    # so that no vertex nears the neutral direction's antipode (swing-twist is singular there)
    flex, abd = _u(rng, 150.0, 162.0), _u(rng, 150.0, 162.0)
    ext, ext_straight = _u(rng, 45.0, 60.0), _u(rng, 10.0, 20.0)
    add = _u(rng, 20.0, 40.0)
    internal, external = _u(rng, 55.0, 75.0), _u(rng, 60.0, 90.0)
    sh_notches, sh_jitter = _notches(rng, int(rng.integers(1, 3))), _jitter(rng)
    elbow_lo, elbow_hi = -_u(rng, 0.0, 5.0), _u(rng, 135.0, 150.0)
    wflex, wext = _u(rng, 60.0, 80.0), _u(rng, 50.0, 70.0)
    radial, ulnar, wrist_tw = _u(rng, 15.0, 25.0), _u(rng, 25.0, 35.0), _u(rng, 3.0, 6.0)
    wr_notches, wr_jitter = _notches(rng, 1), _jitter(rng)
    elbow, elbow_clinical = _ELBOWS[kinds.get("elbow", "hinge")](rng, elbow_lo, elbow_hi)
    sh_twist = {"min_deg": -internal, "max_deg": external}
    sh_kf = []
    for at, e in ((0.0, ext - ext_straight), (45.0, ext - 0.5 * ext_straight), (90.0, ext)):
        sh_kf.append({"at_deg": at, "constraint": {
            "swing": _swing_polygon("shoulder", (flex, add, e, abd), sh_notches, sh_jitter),
            "twist": dict(sh_twist)}})
    joints = [
        {"coupled": {"by": "elbow", "keyframes": sh_kf}},
        {"constraint": elbow},
        {"constraint": {"kind": "two-axis",
                        "swing": _swing_polygon("wrist", (wflex, ulnar, wext, radial),
                                                wr_notches, wr_jitter),
                        "twist": {"min_deg": -wrist_tw, "max_deg": wrist_tw}}},
    ]
    clinical = {"shoulder": {"flexion": flex, "extension": ext,
                             "extension_elbow_straight": ext - ext_straight, "abduction": abd,
                             "adduction": add, "internal_rotation": internal,
                             "external_rotation": external},
                "elbow": {"flexion": elbow_hi, "extension": -elbow_lo, **elbow_clinical},
                "wrist": {"flexion": wflex, "extension": wext, "radial_deviation": radial,
                          "ulnar_deviation": ulnar, "twist": wrist_tw}}
    return joints, clinical


def _hinge_elbow(rng: np.random.Generator, lo: float, hi: float) -> tuple[dict, dict]:
    """The elbow a hinge about +Z over ``[lo, hi]`` degrees (draws nothing more); its
    constraint and its clinical limits beyond flexion and extension (none)."""
    return {"kind": "hinge", "hinge": {"axis": [0.0, 0.0, 1.0], "min_deg": lo,
                                       "max_deg": hi}}, {}


def _forearm_elbow(rng: np.random.Generator, lo: float, hi: float) -> tuple[dict, dict]:
    """The elbow a forearm joint: flexion about +Z over ``[lo, hi]``, then pronation 70-85° and
    supination 75-90° about the forearm's long axis (AAOS 1965: 80 and 80; pronation is the
    rotation's negative direction, :mod:`models.kinds.forearm`). Drawn after every other draw
    of the arm (:func:`anatomical_limb` calls it last): the rest of the arm is the hinge arm's
    of the same seed."""
    pron, sup = _u(rng, 70.0, 85.0), _u(rng, 75.0, 90.0)
    return {"kind": "forearm", "forearm": {"flexion": {"axis": [0.0, 0.0, 1.0], "min_deg": lo,
                                                       "max_deg": hi},
                                           "rotation": {"min_deg": -pron, "max_deg": sup}}}, \
        {"pronation": pron, "supination": sup}


#: How an anatomical arm's elbow is drawn, by its kind (:func:`anatomical_limb`'s ``kinds``).
_ELBOWS = {"hinge": _hinge_elbow, "forearm": _forearm_elbow}
#: The kinds an anatomical limb's joints may take: their own (calibration.joints) or these.
_KIND_OPTIONS = {"elbow": tuple(_ELBOWS)}


def anatomical_limb(seed: int, limb: str = "leg", side: str = "right", *,
                    kinds: dict[str, str] | None = None):
    """A seeded, physiologically plausible arm or leg with couplings: the ground truth of a
    :class:`~rig.sim.limb.SimulatedWholeLimb` patient.

    Rig segment frames (:mod:`calibration.frames`, :mod:`calibration.joint_angles`): every
    segment +X along it distally, +Y anterior, +Z to the right; the foot +X to the toes, +Y
    superior. Clinical ranges (degrees, uniform per seed; AAOS 1965 as the reference of what is
    normal, ``calibration.joint_angles.NORMATIVE``):

    - **leg** — hip: a ball joint, the thigh's direction in a concave polygon about the thigh
      hanging down (flexion 100-125, extension 10-30, abduction 30-50, adduction 15-30, one or
      two notches), twist internal 30-45 / external 35-50 rotation; **coupled to the knee**
      (the hamstrings): keyframes at knee 0, 45 and 90°, hip flexion 60-80 (the straight-leg
      raise) with the knee straight, half-way at 45°, full from 90°. Knee: a hinge about
      ``(0, 0, −1)``, so its angle is Grood-Suntay knee flexion, ``[−(0..5), 130..150]``.
      Ankle: two-axis, the toes' direction in a polygon about the shank's +Y (the neutral pose)
      — dorsiflexion 10-17 with the knee straight, 5-8 more from knee 90° (**coupled to the
      knee**: the gastrocnemius), plantarflexion 40-55, the toes turned medially 20-35
      (inversion with internal rotation) and laterally 10-20 (eversion) — twist ±3-6°.
    - **arm** — shoulder: a ball joint, polygon about the arm hanging down (flexion 150-172,
      abduction 150-162 — below 165° so that the arm raised stays away from the limb axis's
      antipode, where the swing-twist twist is singular —, adduction 20-40, extension 45-60
      with the elbow bent), twist internal
      55-75 / external 60-90; **coupled to the elbow** (the biceps' long head): keyframes at
      elbow 0, 45, 90°, extension 10-20° less with the elbow straight. Elbow: a hinge about
      ``(0, 0, 1)`` (its angle is elbow flexion), ``[−(0..5), 135..150]``. Wrist: two-axis,
      flexion 60-80, extension 50-70, radial 15-25, ulnar deviation 25-35, twist ±3-6°.
      With ``kinds={"elbow": "forearm"}`` the elbow is a forearm joint (:mod:`models.kinds.
      forearm`): the same flexion interval, then pronation 70-85 and supination 75-90 about
      the forearm's long axis — drawn last, so the rest of the arm is the hinge arm's of the
      seed (a servo arm's elbow turns about both, ``rig/configs/sim-servo-arm.yaml``).

    Each pure movement's limit is a polygon vertex on that movement's great circle, so
    :func:`calibration.joint_angles.joint_angles` of the boundary reads it back; the neutral
    pose (every clinical angle 0) is inside every joint's limits. A left limb is the right one
    mirrored (:func:`calibration.clinical.mirror_directions`; twist intervals change sign).

    Parameters
    ----------
    seed : int
    limb : {"arm", "leg"}
    side : {"right", "left"}
    kinds : dict, optional
        Joint → kind (:mod:`models.kinds`) where it differs from the joint's own
        (:data:`calibration.joints.JOINTS`): the arm's elbow may be a ``forearm``; a joint's
        own kind may be given too.

    Returns
    -------
    models.limb.Limb
        Named ``sim-<limb>-<seed>``, its ``provenance`` holding the drawn clinical limits
        (degrees, ``provenance["clinical"]``).
    """
    if limb not in _CHAINS:
        raise ValueError(f"limb must be 'arm' or 'leg', got {limb!r}")
    if side not in ("left", "right"):
        raise ValueError(f"side must be 'left' or 'right', got {side!r}")
    kinds = dict(kinds or {})
    for joint, kind in kinds.items():
        spec = JOINTS.get(joint)
        if spec is None or spec.limb != limb:
            raise ValueError(f"kinds: the {limb} has no joint {joint!r}")
        allowed = (spec.kind, *_KIND_OPTIONS.get(joint, ()))
        if kind not in allowed:
            raise ValueError(f"kinds: the simulated {joint} is a {' or a '.join(allowed)}, "
                             f"not a {kind}")
    rng = np.random.default_rng([seed, 0x11B, 0 if limb == "arm" else 1])
    joints, clinical = (_arm if limb == "arm" else _leg)(rng, kinds)
    doc_joints = []
    for (name, parent, child), body in zip(_CHAINS[limb], joints, strict=True):
        j = {"name": name, "parent": parent, "child": child, **body}
        doc_joints.append(_mirror_joint(j) if side == "left" else j)
    doc = {"name": f"sim-{limb}-{seed}", "limb": limb, "side": side, "joints": doc_joints,
           "provenance": {"generator": "rig.sim.patients.anatomical_limb", "seed": int(seed),
                          "clinical": _rounded(clinical)}}
    return Limb.from_dict(doc, source=f"anatomical {side} {limb} {seed}")


def _rounded(d: dict) -> dict:
    return {k: _rounded(v) if isinstance(v, dict) else round(float(v), 3) for k, v in d.items()}


# ---------------------------------------------------------------------------------------------
# The factory (a joint's patient or an arm's or leg's), port strings, offline recordings

#: The simulated limbs, each under the limits it wears (:attr:`SimulatedLimb.limits_type`).
_WEARERS: dict[type, type[SimulatedLimb]] = {
    cls.limits_type: cls for cls in (SimulatedJoint, SimulatedWholeLimb)}


def patient_class(limits) -> type[SimulatedLimb] | None:
    """The simulated limb that wears ``limits``: a :class:`~rig.sim.limb.SimulatedJoint` a
    joint's constraint, a :class:`~rig.sim.limb.SimulatedWholeLimb` a limb file's limits; None
    for anything else.

    Parameters
    ----------
    limits : object

    Returns
    -------
    type or None
        A subclass of :class:`~rig.sim.limb.SimulatedLimb`.
    """
    return next((_WEARERS[t] for t in type(limits).__mro__ if t in _WEARERS), None)



def seeded_patient(seed: int, limb, side: str = "right", *, noise: NoiseModel | None = None,
                      misplace_deg: float = 25.0, calibrate: bool = True,
                      protocol_start_s: float = 5.0, neutral: float = 0.0,
                      **kwargs) -> SimulatedLimb:
    """The simulated patient of ``seed``: a limb of one joint or a whole arm or leg wearing
    misplaced IMUs, performing its calibration protocol, then moving freely.

    Parameters
    ----------
    seed : int
        Seeds the motion and the sensor errors (and an anatomical limb's limits); the straps are
        drawn from ``default_rng([seed, 0x5EA7])`` (as ``sim://imu-stream?seed=...`` draws
        them).
    limb : JointConstraint, models.limb.Limb or {"arm", "leg"}
        The patient's true limits: a joint's constraint (a :class:`~rig.sim.limb.SimulatedJoint`
        wearing two IMUs, thorax and limb, :func:`rig.sim.limb.misplaced_mounts`; e.g.
        :func:`star_constraint` ``(seed)``), a limb file's :class:`~models.limb.Limb`, or the
        :func:`anatomical_limb` ``(seed, limb, side)`` (a :class:`~rig.sim.limb.SimulatedWholeLimb`
        wearing one IMU per segment, :func:`rig.sim.limb.limb_mounts`).
    side : {"right", "left"}
        The side of an anatomical limb (a given Limb's own side is kept; unused for a joint).
    noise : NoiseModel, optional
        Default: :class:`~rig.sim.limb.NoiseModel` (noise, drift, disturbances on).
    misplace_deg : float
        How far each strap is turned off its nominal mounting.
    calibrate : bool
        Perform the calibration protocol from ``protocol_start_s`` (a joint's
        :class:`calibration.protocol.CalibrationProtocol`, a limb's
        :class:`calibration.protocol.LimbCalibrationProtocol`); False: free motion from time 0.
    protocol_start_s : float
        When the protocol starts: 5 s, by which the sensors' calibration status has reached 3
        under the default noise model (``calibration_time_s`` 5 s).
    neutral : float
        Neutral checkpoints every this many seconds (0: none).
    **kwargs
        Further keywords of the limb's class (``sway_deg``, ``excursion``, the other
        neutral-checkpoint keywords, ...).

    Returns
    -------
    SimulatedLimb
        A :class:`~rig.sim.limb.SimulatedJoint` or a :class:`~rig.sim.limb.SimulatedWholeLimb`.
    """
    rng = np.random.default_rng([seed, 0x5EA7])
    wearer = patient_class(limb)
    if wearer is None:  # not limits but a name: the anatomical arm or leg of the seed
        limb = anatomical_limb(seed, limb, side)
        wearer = patient_class(limb)
    protocol = wearer.calibration_protocol_for(limb) if calibrate else None
    return wearer(limb, sensors=wearer.misplaced_straps(limb, rng, misplace_deg), noise=noise,
                  seed=seed, calibration_protocol=protocol, protocol_start_s=protocol_start_s,
                  neutral_every_s=neutral, **kwargs)


def limb_from_url(q: SimUrl, *, sensors: int | None = None, kinds: dict[str, str] | None = None,
                  misplaced_straps: bool = True):
    """The arm or leg patient a port string describes, or None when it names none: ``limb=arm|leg``
    (an :func:`anatomical_limb` of ``seed`` and ``side``) or ``patient=`` a limb file
    (:func:`models.limb.load_limits`; ``side`` is then the file's). The other patient keys as
    :func:`patient_from_url` reads them (``seed``, ``noise``, ``misplace_deg``, ``excursion``,
    ``speed``, ``calibrate``: the limb calibration protocol from 2 s, ``neutral``,
    ``neutral_sd``).

    Parameters
    ----------
    q : SimUrl
    sensors : int or None
        The port's ``sensors`` value: an arm or leg wears 4.
    kinds : dict, optional
        The anatomical limb's joint kinds (:func:`anatomical_limb`; a servo arm's forearm
        elbow).
    misplaced_straps : bool
        Straps drawn by ``misplace_deg`` (IMU simulators); False: the nominal straps (a servo
        limb wears no IMU).

    Raises
    ------
    RigConfigError
        A bad value, ``side`` without a limb, a sensor count other than 4, an unreadable limb
        file: one line naming the port and the key.
    """
    limb_key = q.text("limb")
    side_key = q.text("side")
    patient = q.text("patient")
    truth = None
    if limb_key is None and patient is not None and patient.endswith((".yaml", ".yml")):
        truth = _limb_file(patient, q.url)
    if limb_key is None and truth is None:
        if side_key is not None:
            raise RigConfigError(f"{q.url}: side={side_key!r}: needs limb=arm|leg (the "
                                 f"shoulder patient's side is its constraint's)")
        return None
    if limb_key is not None:
        kind = q.choice("limb", "leg", ("arm", "leg"))
        if patient is not None:
            raise RigConfigError(f"{q.url}: patient={patient!r}: limb={kind} draws the "
                                 f"patient's limits; give one of them")
    side = q.choice("side", "right", ("left", "right"))
    if truth is not None and side_key is not None and truth.side not in (None, side):
        raise RigConfigError(f"{q.url}: side={side_key!r}: the limb file is a {truth.side} "
                             f"{truth.limb or 'limb'}")
    if sensors is not None and sensors != 4:
        raise RigConfigError(f"{q.url}: sensors={q.text('sensors')!r}: an arm or leg "
                             f"patient wears 4 sensors (one per segment)")
    seed = q.integer("seed", 0)
    noise, excursion, speed, neutral, neutral_sd = _motion_keys(q)
    misplace = q.number("misplace_deg", 5.0, 0.0, 90.0) if misplaced_straps else 0.0
    calibrate = q.flag("calibrate", False)
    if truth is None:
        try:
            truth = anatomical_limb(seed, kind, side, kinds=kinds)
        except ValueError as err:
            raise RigConfigError(f"{q.url}: limb={kind}: {_one_line(err)}") from err
    try:
        return seeded_patient(seed, truth, noise=noise, misplace_deg=misplace,
                             calibrate=calibrate, protocol_start_s=2.0, neutral=neutral,
                             excursion=excursion, speed=speed, neutral_hold_s=_NEUTRAL_HOLD_S,
                             neutral_ramp_s=_NEUTRAL_RAMP_S, neutral_sd_deg=neutral_sd)
    except ValueError as err:
        key = "patient" if limb_key is None else "limb"
        raise RigConfigError(f"{q.url}: {key}={q.text(key)!r}: {_one_line(err)}") from err


def _limb_file(path: str, url: str):
    """The :class:`models.limb.Limb` a ``patient=`` limb file holds, or None when the file is a
    constraint file (the shoulder patient's)."""
    try:
        limits = load_limits(path)
    except FileNotFoundError:
        return None  # resolve_patient names it
    except (OSError, ValueError) as err:
        raise RigConfigError(f"{url}: patient={path!r}: {_one_line(err)}") from err
    # The user's patient= names a file of either format: what it holds decides which patient
    # the port string describes. This is the one place that reads it (limb_from_url's caller
    # builds the joint's patient from the same file when this says None).
    return limits if isinstance(limits, Limb) else None


@dataclass
class LimbRecording:
    """Samples of one simulated arm or leg session, offline (arrays over N instants, S = 4 sensors).

    Attributes
    ----------
    t : (N,) s, patient time
    quaternions : (N, S, 4) each sensor in its world, with errors
    gyro, accel, mag : (N, S, 3) raw readings, sensor frames (rad/s, m/s², µT)
    status : (N, S) CALIB_STAT bytes
    joints : (N, J, 4) ground-truth joint orientations
    root : (N, 4) ground-truth root segment relative to world
    sensors_true : (N, S, 4) error-free sensor orientations
    segments : tuple of str, the sensors' segments, proximal to distal
    windows : dict phase -> (t0, t1), the protocol's phase windows in recording time
    start_s, end_s : when the protocol started and ended (0 and 0 without one)
    """

    t: np.ndarray
    quaternions: np.ndarray
    gyro: np.ndarray
    accel: np.ndarray
    mag: np.ndarray
    status: np.ndarray
    joints: np.ndarray
    root: np.ndarray
    sensors_true: np.ndarray
    segments: tuple[str, ...]
    windows: dict
    start_s: float
    end_s: float

    def window(self, phase: str) -> np.ndarray:
        """Mask of the samples in a protocol phase (``"static"``, a joint's name) or of the
        free motion after the protocol (``"free"``)."""
        if phase == "free":
            return self.t >= self.end_s
        if phase not in self.windows:
            raise ValueError(f"no phase {phase!r}; phases: {', '.join(self.windows) or 'none'}")
        a, b = self.windows[phase]
        return (self.t >= a) & (self.t <= b)


def record_limb_imu(limb: SimulatedWholeLimb, duration_s: float, rate_hz: float = 100.0,
                    chunk: int = 2000) -> LimbRecording:
    """Sample a :class:`~rig.sim.limb.SimulatedWholeLimb`'s sensors at ``rate_hz`` from time 0
    to the end of its protocol plus ``duration_s`` seconds, through the sensor error model
    (:meth:`~rig.sim.limb.SimulatedWholeLimb.measure_many`, ``chunk`` samples per call; no pty)."""
    t = _times(limb, duration_s, rate_hz)
    parts: dict[str, list] = {k: [] for k in ("q", "g", "a", "m", "c", "j", "r", "s")}
    for i in range(0, len(t), chunk):
        ms = limb.measure_many(t[i:i + chunk])
        parts["q"].append(np.stack([m.quaternions for m in ms]))
        parts["g"].append(np.stack([m.gyro for m in ms]))
        parts["a"].append(np.stack([m.accel for m in ms]))
        parts["m"].append(np.stack([m.mag for m in ms]))
        parts["c"].append(np.stack([m.calibration for m in ms]).astype(np.int64))
        parts["j"].append(np.concatenate([m.truth.joints for m in ms]))
        parts["r"].append(np.concatenate([m.truth.root for m in ms]))
        parts["s"].append(np.concatenate([m.truth.sensors for m in ms]))
    cat = {k: (np.concatenate(v) if v else None) for k, v in parts.items()}
    return LimbRecording(t, cat["q"], cat["g"], cat["a"], cat["m"], cat["c"], cat["j"],
                          cat["r"], cat["s"], tuple(m.segment for m in limb.mounts),
                          limb.protocol_windows(), limb.protocol_start_s,
                          limb.protocol_end_s)
