"""Simulated patients for the calibration tests and ``benchmarks/bench_boundary.py``.

- :func:`star_patient`: a seeded random concave star-shaped polygon (great-circle edges) with a
  twist range, centred within ``max_tilt_deg`` of the arm-at-the-side direction (+X) so that the
  neutral pose is inside the range.
- :class:`ScriptedLimb`: :class:`rig.sim.limb.SimulatedLimb` whose joint follows the calibration
  protocol (:class:`calibration.protocol.CalibrationProtocol`, through the patient's range) for
  its first seconds, then the simulator's free motion.
- :func:`record_imu` / :func:`record_servo`: recordings through the sensor error model (IMU:
  noise, drift, magnetic disturbances, misplaced sensors) or a back-driven servo limb (encoder
  quantisation, no drift).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from calibration.protocol import CalibrationProtocol
from models import quaternion as Q
from models.constraint import JointConstraint
from rig.sim.limb import NoiseModel, SensorMount, SimulatedLimb


def star_patient(seed: int, *, vertices: int = 40, max_tilt_deg: float = 20.0) -> JointConstraint:
    """A random concave star polygon about a centre near +X, with a random twist range.

    Radius (degrees from the centre) against azimuth: a base of 35-60°, two or three lobes and
    one notch of 10-25° depth; twist range ``[-a, b]`` with ``a, b`` in 20-70°.
    """
    rng = np.random.default_rng(seed)
    tilt = math.radians(rng.uniform(0.0, max_tilt_deg))
    az = rng.uniform(0, 2 * math.pi)
    centre = np.array([math.cos(tilt), math.sin(tilt) * math.cos(az),
                       math.sin(tilt) * math.sin(az)])
    phi = np.linspace(0.0, 2 * math.pi, vertices, endpoint=False)
    base = rng.uniform(35.0, 60.0)
    r = np.full(vertices, base)
    for k in rng.choice([2, 3, 4], size=2, replace=False):
        r += rng.uniform(3.0, 9.0) * np.cos(k * phi + rng.uniform(0, 2 * math.pi))
    notch_at = rng.uniform(0, 2 * math.pi)
    width = rng.uniform(0.35, 0.7)
    gap = np.angle(np.exp(1j * (phi - notch_at)))
    r -= rng.uniform(10.0, 25.0) * np.exp(-0.5 * (gap / (width / 2.5)) ** 2)
    r = np.clip(r, 15.0, 85.0)
    u = np.cross(centre, [0.0, 0.0, 1.0])
    u /= np.linalg.norm(u)
    v = np.cross(centre, u)
    rr = np.radians(r)
    verts = (np.cos(rr)[:, None] * centre
             + np.sin(rr)[:, None] * (np.cos(phi)[:, None] * u + np.sin(phi)[:, None] * v))
    tw = (-float(rng.uniform(20, 70)), float(rng.uniform(20, 70)))
    return JointConstraint.from_dict({
        "name": f"star-{seed}",
        "limb_axis": [1.0, 0.0, 0.0],
        "swing": {"polygon": {"vertices": verts.tolist(), "interior": centre.tolist()}},
        "twist": {"min_deg": tw[0], "max_deg": tw[1]},
    })


class ScriptedLimb(SimulatedLimb):
    """A simulated limb that performs the calibration protocol first (see module doc)."""

    def __init__(self, *args, protocol: CalibrationProtocol | None = None, start_s: float = 5.0,
                 **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.protocol = protocol if protocol is not None else CalibrationProtocol()
        #: the protocol starts once the sensors have had time to calibrate (status 3)
        self.start_s = float(start_s)

    def joint(self, t) -> np.ndarray:
        t = np.atleast_1d(np.asarray(t, dtype=np.float64)) - self.start_s
        t0 = self.protocol.duration_s
        free = super().joint(np.maximum(t - t0, 0.0))
        scripted = np.asarray(self.oracle.project(self.protocol.joint(t), normalize=True),
                              dtype=np.float64)
        scripted = scripted.reshape(-1, 4)
        return np.where((t < t0)[:, None], scripted, free)


@dataclass
class Recording:
    """Samples of one simulated session (arrays over N instants)."""

    t: np.ndarray  # (N,) s since the protocol start
    thorax: np.ndarray  # (N, 4) thorax sensor in its world (IMU) or identity (servo)
    limb: np.ndarray  # (N, 4) limb sensor in its world (IMU) or joint FK (servo)
    status: np.ndarray  # (N,) worst calibration byte of the two sensors (IMU) or 0xFF
    truth: np.ndarray  # (N, 4) ground-truth joint orientation
    protocol: CalibrationProtocol
    start_s: float  # when the protocol started

    def window(self, phase: str) -> np.ndarray:
        """Mask of the samples in a protocol phase ("static", "functional") or "free"."""
        if phase == "free":
            return self.t >= self.start_s + self.protocol.duration_s
        a, b = self.protocol.windows()[phase]
        return (self.t >= self.start_s + a) & (self.t <= self.start_s + b)


def misplaced_mounts(rng: np.random.Generator, misplace_deg: float = 25.0) -> list[SensorMount]:
    """Thorax and upper-arm sensors strapped at random orientations: the default straps
    (:func:`rig.sim.limb.default_mounts`) turned by a random rotation of ``misplace_deg``."""
    from rig.sim.limb import default_mounts

    out = []
    for m in default_mounts(2, rng):
        axis = Q.random_unit_vectors(1, rng)[0]
        err = Q.from_axis_angle(axis, math.radians(misplace_deg))
        out.append(SensorMount(m.segment, tuple(Q.canonical(Q.multiply(err, m.mount)))))
    return out


def make_limb(constraint: JointConstraint, seed: int, *, noise: NoiseModel | None = None,
              misplace_deg: float = 25.0, **kwargs) -> ScriptedLimb:
    """The patient with misplaced sensors (further keywords go to :class:`ScriptedLimb`)."""
    rng = np.random.default_rng(10_000 + seed)
    return ScriptedLimb(constraint, sensors=misplaced_mounts(rng, misplace_deg),
                        noise=noise, seed=seed, **kwargs)


def record_imu(limb: ScriptedLimb, duration_s: float, rate_hz: float = 100.0) -> Recording:
    """Sample ``limb.measure`` at ``rate_hz`` for the protocol plus ``duration_s`` seconds."""
    n = round((limb.start_s + limb.protocol.duration_s + duration_s) * rate_hz)
    t = np.arange(n) / rate_hz
    thorax = np.empty((n, 4))
    arm = np.empty((n, 4))
    status = np.empty(n, dtype=np.int64)
    truth = np.empty((n, 4))
    for i, ti in enumerate(t):
        m = limb.measure(float(ti))
        thorax[i], arm[i] = m.quaternions[0], m.quaternions[1]
        status[i] = min(int(m.calibration[0]), int(m.calibration[1]), key=lambda b: b >> 6)
        truth[i] = m.truth.joint[0]
    return Recording(t, thorax, arm, status, truth, limb.protocol, limb.start_s)


def record_servo(limb: ScriptedLimb, duration_s: float, rate_hz: float = 100.0,
                 seed: int = 0) -> Recording:
    """A back-driven servo limb: the joint read through 3 encoders of 4096 ticks per turn
    (Z-Y-X chain), i.e. the truth quantised to 0.088° per joint; no drift, no mounts."""
    n = round((limb.start_s + limb.protocol.duration_s + duration_s) * rate_hz)
    t = np.arange(n) / rate_hz
    truth = limb.joint(t)
    from scipy.spatial.transform import Rotation

    step = 2 * math.pi / 4096
    ang = Q.to_rotation(truth).as_euler("ZYX")
    ticks = np.round(ang / step)
    fk = Q.from_rotation(Rotation.from_euler("ZYX", ticks * step))
    ident = np.tile(Q.IDENTITY, (n, 1))
    return Recording(t, ident, fk, np.full(n, 0xFF), truth, limb.protocol, limb.start_s)
