"""End-to-end accuracy of ``rig record`` on a simulated patient whose range of motion is known.

The whole stack, nothing bypassed: a seeded patient (:func:`star_patient`) written to a
constraint file → a simulator on a real pty (``sim://imu-stream`` with sensor noise, drift,
magnetic disturbances and misplaced straps on a lockstep manual clock, or the back-driven servo
limb ``sim://dynamixel?...&patient=`` on a scaled clock) → the real driver and orientation
source → :func:`rig.record.record_session` (guided calibration performed by the simulated
patient, store) → joint orientations read back from the store through the stored calibration
(:func:`rig.readback.joint_orientations_from_store`) → boundary extraction
(:func:`rig.readback.extract`, i.e. :class:`calibration.boundary.BoundaryExtractor`) →
compared with the patient's truth:

- ``mean_deg`` / ``hausdorff_deg``: symmetric mean / largest distance between the extracted and
  the true swing boundaries (:func:`calibration.boundary.boundary_distance`);
- ``out1_pct`` / ``out2_pct``: % of the true limb directions during the recording more than
  1° / 2° outside the extracted region ("recorded region left out"). On the servo path the
  true directions are those the back-driven chain actually took: where the patient's motion
  leaves the chain's reach (joint limits) the servo limb stays put, as its driver does, and
  ``unreachable_pct`` says for how much of the recording;
- ``twist_deg``: the larger of the two twist-limit errors;
- ``peaks``: the clinical peaks (:func:`calibration.clinical.range_of_motion`) of both
  constraints, ``peaks_deg`` the largest difference, ``swing_peaks_deg`` over flexion,
  extension, abduction, adduction and horizontal adduction only;
- ``peak_sensitivity_deg``: a property of the truth alone — how far its swing peaks move when
  the clinical planes turn by ±1° (where the boundary runs nearly along a plane, a peak is
  ill-conditioned: a tangential error of a degree moves it by several);
- ``twist_offset_deg`` / ``twist_wander_deg``: mean and standard deviation over the recording of
  the per-sample twist error (recorded joint orientation against the truth at the same instant,
  samples the extractor keeps): how much of ``twist_deg`` is a constant offset (the heading
  misalignment at calibration) and how much drifts during the session.

A benchmark harness, not part of the product: used by ``benchmarks/bench_record.py accuracy``
(held-out seeds) and one fast seeded test (``tests/rig/test_record_accuracy.py``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from models import quaternion as Q
from rig.sim.patients import star_patient  # the factory of simulated patients (re-exported)

__all__ = ["AccuracyResult", "record_imu_patient", "record_servo_patient", "star_patient"]

_SWING_PEAKS = ("flexion", "extension", "abduction", "adduction", "horizontal_adduction")


@dataclass
class AccuracyResult:
    """One recorded patient compared with its truth (see the module docstring)."""

    patient: str
    path: str  # "imu" or "servo"
    status: str
    samples: int
    dropped: int
    calibration_residual_deg: float | None
    mean_deg: float
    hausdorff_deg: float
    out1_pct: float
    out2_pct: float
    twist_deg: float
    peaks_deg: float
    swing_peaks_deg: float
    unreachable_pct: float = 0.0
    twist_offset_deg: float = math.nan
    twist_wander_deg: float = math.nan
    peaks: dict = field(default_factory=dict)  # movement -> (extracted, truth)
    twist: tuple = ()  # ((lo, hi) extracted, (lo, hi) truth)
    fusion: str = ""  # IMU path: the read path's orientation source ("vqf" or "device")
    peak_sensitivity_deg: float = math.nan  # of the truth: see _peak_sensitivity


def _compare(name, path, res, store_path, truth, truth_q, recorded_q=None,
             unreachable_pct: float = 0.0, fusion: str = "auto") -> AccuracyResult:
    from calibration.boundary import boundary_distance, outside_fraction
    from calibration.clinical import range_of_motion
    from rig.readback import extract, joint_orientations_from_store
    from rig.store import open_store

    with open_store(store_path, create=False) as store:
        data = joint_orientations_from_store(store, res.session_id, fusion=fusion)
    ex = extract(data, side="right")
    est = ex.constraint_
    d = boundary_distance(est, truth)
    dirs = Q.rotate(truth_q if recorded_q is None else recorded_q, np.array([1.0, 0.0, 0.0]))
    lo, hi = ex.twist_deg_
    a = range_of_motion(est, "right", directions=data.directions).to_dict()
    b = range_of_motion(truth, "right").to_dict()
    peaks, errs, swing_errs = {}, [], []
    for m, tv in b.items():
        if m == "side":
            continue
        ev = a[m]
        peaks[m] = (ev, tv)
        err = (0.0 if ev is None and tv is None else
               math.inf if ev is None or tv is None else abs(ev - tv))
        errs.append(err)
        if m in _SWING_PEAKS:
            swing_errs.append(err)
    tw_off, tw_wander = _twist_error(data, truth_q if recorded_q is None else recorded_q,
                                     ex.limb_axis, ex.min_system_status)
    cal = res.calibration
    return AccuracyResult(
        patient=name, path=path, status=res.status, samples=res.samples, dropped=res.dropped,
        calibration_residual_deg=None if cal is None else float(cal.residual_deg),
        mean_deg=float(d["mean_deg"]), hausdorff_deg=float(d["hausdorff_deg"]),
        out1_pct=100.0 * float(outside_fraction(est, dirs, 1.0)),
        out2_pct=100.0 * float(outside_fraction(est, dirs, 2.0)),
        twist_deg=max(abs(lo - truth.twist.min_deg), abs(hi - truth.twist.max_deg)),
        peaks_deg=max(errs), swing_peaks_deg=max(swing_errs), twist_offset_deg=tw_off,
        twist_wander_deg=tw_wander, unreachable_pct=unreachable_pct, peaks=peaks,
        twist=((float(lo), float(hi)), (truth.twist.min_deg, truth.twist.max_deg)),
        peak_sensitivity_deg=_peak_sensitivity(truth, b),
        fusion=str((data.provenance.get("fusion") or {}).get("method", "")) if path == "imu"
        else "")


def _peak_sensitivity(truth, peaks_true: dict) -> float:
    """How much the truth's own swing peaks move when the clinical planes turn by ±1° about the
    thorax vertical (+X): the largest change, degrees. A peak where the boundary runs nearly
    along the plane moves by several degrees per degree; no measurement whose planes are
    aligned only to within a degree can be held to 2° there."""
    from calibration.clinical import range_of_motion
    from models.constraint import JointConstraint
    from models.limits import PolygonSwing

    if not isinstance(truth.swing, PolygonSwing):
        return 0.0
    worst = 0.0
    for deg in (-1.0, 1.0):
        r = Q.from_axis_angle(np.array([1.0, 0.0, 0.0]), math.radians(deg))
        verts = Q.rotate(np.broadcast_to(r, (len(truth.swing.vertices), 4)),
                         Q.check_vectors(truth.swing.vertices))
        inner = Q.rotate(r, Q.check_vectors(truth.swing.interior))
        turned = JointConstraint.polygon(verts, inner)
        got = range_of_motion(turned, "right").to_dict()
        for m in _SWING_PEAKS:
            a, b = got[m], peaks_true[m]
            if a is not None and b is not None:
                worst = max(worst, abs(a - b))
    return worst


def _twist_error(data, truth_q, axis, min_status: int) -> tuple[float, float]:
    """Mean and std (degrees) of recorded minus true twist, sample by sample."""
    q = np.asarray(data.q)
    if len(q) != len(truth_q):  # not paired one to one with the truth: no figure
        return math.nan, math.nan
    d = np.degrees(Q.twist_angle(q, axis) - Q.twist_angle(truth_q, axis))
    d = (d + 180.0) % 360.0 - 180.0
    if data.status is not None:
        d = d[(np.asarray(data.status).astype(np.int64) >> 6) >= min_status]
    return (float(d.mean()), float(d.std())) if d.size else (math.nan, math.nan)


def _rig_yaml(tmp: Path, body: str) -> Path:
    p = tmp / "rig.yaml"
    p.write_text(body)
    return p


def record_imu_patient(constraint, seed: int, tmp: str | Path, *, free_s: float = 300.0,
                       rate_hz: int = 100, misplace_deg: float = 25.0, neutral_s: float = 20.0,
                       display=None, step_s: float = 0.05, window_s: float = 0.5,
                       raw: bool = True, fusion="auto"):
    """Record ``constraint`` worn as two IMUs (``sim://imu-stream``, noise on, straps turned
    ``misplace_deg`` off, patient performing the calibration protocol, then returning to
    neutral every ``neutral_s`` seconds — 0: never — with 2° repeatability; raw accelerometer,
    gyroscope and magnetometer samples recorded too unless ``raw=False``) for ``free_s``
    seconds of free motion after calibration, faster than real time (:class:`LockstepClock`),
    and compare the extracted boundary with the truth, reading the session back with
    ``fusion`` (``joint_orientations_from_store``: "auto", "vqf" or "device"). A sequence of
    fusions reads the one recording back once per fusion and returns ``{fusion: result}``."""
    from models.constraint import dump_constraint
    from rig.record import RecordOptions, record_session
    from rig.record.lockstep import CountingDisplay, LockstepClock
    from rig.record.rigio import load_config, open_rig
    from rig.store import open_store

    tmp = Path(tmp)
    cpath = tmp / f"patient-{seed}.yaml"
    dump_constraint(constraint, cpath)
    port = (f"sim://imu-stream?sensors=2&rate={rate_hz}&patient={cpath}&seed={seed}"
            f"&misplace_deg={misplace_deg:g}&neutral={neutral_s:g}&clock=manual&flow=on"
            "&max_lag=none")
    cfg = _rig_yaml(tmp, f"name: accuracy-imu\njoint: {{name: shoulder, side: right, parent: "
                         f"thorax, child: humerus}}\nsensors:\n  port: \"{port}\"\n"
                         f"  protocol: stream\n  rate_hz: {rate_hz}\n"
                         f"  raw: {'true' if raw else 'false'}\n"
                         f"  segments: {{thorax: 0, humerus: 1}}\n")
    db = tmp / f"imu-{seed}.db"
    rig = open_rig(load_config(str(cfg)), calibrate=True)
    limb = rig.patients[0]
    shown = CountingDisplay(display)
    with LockstepClock(rig.simulators[0].clock, lambda: shown.samples, 2.0 * rate_hz,
                       step_s=step_s, window_s=window_s) as lock:
        res = record_session(
            RecordOptions(rig=str(cfg), db=str(db), patient=f"IMU-{seed}", duration_s=free_s),
            display=shown, rig=rig,
            on_event=lambda name, info: name == "session" and lock.start())
    with open_store(db, create=False) as store:
        s = store.samples(res.session_id, name="humerus")
    truth_q = limb.joint(s["device_t"] - rig.device_t0)
    name = constraint.name or f"star-{seed}"
    if isinstance(fusion, str):
        return _compare(name, "imu", res, db, constraint, truth_q, fusion=fusion)
    return {f: _compare(name, "imu", res, db, constraint, truth_q, fusion=f) for f in fusion}


def record_servo_patient(constraint, seed: int, tmp: str | Path, *, free_s: float = 300.0,
                         time_scale: float = 10.0, rate_hz: float = 200.0,
                         display=None) -> AccuracyResult:
    """Record ``constraint`` on the back-driven servo limb (``sim-shoulder``'s chain, patient
    time ``time_scale`` × real time, servos read at ``rate_hz`` real Hz) for ``free_s``
    seconds of patient time after the calibration protocol, and compare with the truth."""
    from importlib import resources

    from models.constraint import dump_constraint
    from rig.record import PlainDisplay, RecordOptions, record_session
    from rig.record.rigio import load_config, open_rig
    from rig.sim.urls import with_keys

    tmp = Path(tmp)
    cpath = tmp / f"patient-{seed}.yaml"
    dump_constraint(constraint, cpath)
    base = load_config("sim-shoulder")
    text = resources.files("rig").joinpath("configs", "sim-shoulder.yaml").read_text()
    url = with_keys(base.servos.port, patient=cpath, seed=seed, time_scale=f"{time_scale:g}")
    cfg = _rig_yaml(tmp, text.replace(base.servos.port, url))
    db = tmp / f"servo-{seed}.db"
    rig = open_rig(load_config(str(cfg)), rate_hz=rate_hz, calibrate=True)
    limb = rig.patients[0]
    shown = display if display is not None else PlainDisplay(_Null())
    res = record_session(RecordOptions(rig=str(cfg), db=str(db), patient=f"SERVO-{seed}",
                                       duration_s=free_s / time_scale, rom=False),
                         display=shown, rig=rig)
    from rig.record.pump import SampleBatch
    from rig.store import open_store

    with open_store(db, create=False) as store:
        s = store.samples(res.session_id)
    n = len(s["t"])
    batch = SampleBatch(s["t"], np.full(n, np.nan), s["name"], s["kind"], s["q"], s["status"])
    truth_q = limb.joint(rig.patient_time(batch))
    chain_q, unreachable = rig.simulated_patients[0].follow(truth_q)
    return _compare(constraint.name or f"star-{seed}", "servo", res, db, constraint, truth_q,
                    recorded_q=chain_q, unreachable_pct=100.0 * unreachable / max(n, 1))


class _Null:
    def write(self, text: str) -> int:
        return len(text)

    def flush(self) -> None:
        pass
