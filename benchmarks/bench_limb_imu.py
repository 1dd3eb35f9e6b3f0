"""The IMU path on held-out simulated arms and legs (issue 21): limb calibration, chain
extraction, coupling and clinical peaks against the patient's true limits.

Per patient (``rig.sim.patients.simulated_patient(seed, limb, side)``: the anatomical arm or leg of
:func:`~rig.sim.patients.anatomical_limb` wearing four IMUs strapped 25° off their nominal
mounts, with the default ``NoiseModel``: white noise, heading drift (an Ornstein-Uhlenbeck
process, 2° standard deviation per sensor, 30 s), tilt drift and magnetic disturbances; no
neutral checkpoints):

1. :func:`~rig.sim.patients.record_limb_imu`: the limb calibration protocol
   (:class:`~calibration.protocol.LimbCalibrationProtocol`), then ``--duration`` s of free
   motion at ``--rate`` Hz;
2. :class:`~calibration.limb_calibration.LimbImuCalibration` fitted on the protocol's windows
   (:meth:`~rig.sim.limb.SimulatedWholeLimb.protocol_windows`; the samples whose four status bytes
   pass :func:`~calibration.alignment.status_ok`), applied to the free motion: joint
   orientations (N, 3, 4);
3. :class:`~calibration.boundary.LimbExtractor` on them, with the sample times and, per
   sample, the lowest of the four status bytes (the system level is the top bits);
4. compared with the truth, the patient's :class:`~models.limb.Limb`.

Two paths per patient, on the same recording: ``imu`` (steps 1-4: the issue's path, the
device-fused quaternions) and ``truth`` (step 3 on the true joint orientations of the free
motion: the extraction and coupling test alone, what the IMU path would give with perfect
sensors and calibration). ``--paths`` may add ``vqf``: the raw samples fused on the host
(:func:`calibration.fusion.fuse_vqf`) instead of the device quaternions; and ``pose``: steps 2-4
on the error-free sensor orientations (``LimbRecording.sensors_true``: no noise, drift or
fusion), so that ``cal°`` is the calibration's own error — what the patient's posture during the
static pose puts on every joint (the root's sway leans every segment alike, and gravity is taken
as each segment's long axis; the root's lean is measured against the neutral checkpoints and
taken off, step 7 of :mod:`calibration.limb_calibration`, on this path and ``vqf`` — the read
path does so on the host's fusion, whose sensors share one world) — and ``truth`` → ``pose`` →
``vqf`` splits the joint orientations' error into calibration and sensors. Its other columns are
not the IMU path's without the sensors' errors: error-free data carry no measured slow error, so
the twist's singular reach (:func:`calibration.boundary.twist.singular_reach`) is off, and a
twist end taken from a posture near the arm raised overhead, where a frame error of 2° turns the
twist by ~10°, moves a shoulder's rotation peaks by that much.

Seeds: held out. Tests and one-off checks used seeds 0-13 (``tests/rig/sim``,
``tests/calibration``, the NOTES' seed-11 leg); defects were looked for and fixed on seeds 1-20
(one, shoulder couplings from over-smoothed keyframes, was first seen here on seeds 102 and 103,
and fixed after reproducing it on seeds 1-10); the default figures are seeds 101-105 (right arm
and leg) and the left arm and leg of seed 101. A path that fails on a patient (a
``CalibrationError``) is printed as FAILED and left out of that path's medians.

Comparison conventions (columns)
--------------------------------
``bnd°`` (ball and two-axis joints; target ≤ 2°)
    Symmetric mean boundary distance (:func:`calibration.boundary.boundary_distance`, the
    shoulder benchmark's measure: swing regions only, boundary points every 0.25°, exact
    oracle) between the extracted limits and the truth's **at the same coupling angle**,
    averaged over the truth's keyframe angles when either side couples the joint (shoulder
    and hip: elbow/knee 0, 45, 90°; ankle: knee 0, 90°), each side's limits evaluated there by
    its own coupling (:meth:`models.limb.Coupling.at`: keyframes interpolated, clamped beyond
    the end ones); the one constraint otherwise (wrist). An uncoupled extraction is compared at
    every angle with its one region: a missed coupling costs here, as it would in use.
``loose°``
    The same distance between the loosest limits of each side (a coupled joint's keyframe with
    the largest swing region): where the joint went at any hinge angle.
``hinge°`` (elbow, knee; target ≤ 2°)
    The larger of the two interval ends' errors against the truth's interval.
``kf°`` (coupled joints; target ≤ 3°)
    Per extracted keyframe at angle ``a``, the boundary distance to the truth's limits at
    ``a``; the largest over the keyframes (each is listed below the table).
``found`` (extracted / true)
    Whether the joint's limits were written coupled, and whether the truth's are
    (``LimbExtractor`` tests the shoulder, hip, wrist and ankle; the truth couples the
    shoulder and hip, and the ankle: the gastrocnemius, 5-8° more dorsiflexion with the knee
    bent).
``rec°`` / ``con°`` (clinical peaks; target ≤ 2°)
    Elbow, wrist, hip, knee, ankle: :func:`calibration.joint_angles.recorded_rom` of the
    calibrated joint orientations against that of the true ones (``rec``), and against what
    the truth's limits allow (``con``, :func:`~calibration.joint_angles.allowed_rom`: a
    coupled joint's largest over its keyframes, movement by movement).
    Shoulder: :func:`~calibration.joint_angles.allowed_rom` of the extracted limits (a coupled
    shoulder's largest over its keyframes, as ``rig rom`` reads a limb file) with the
    calibrated directions against the truth's limits with the true directions (``rec``) and
    without them (``con``). The largest error over the movements both report. ``con`` on the
    ``truth`` path is the gap between where the patient went and the truth's limits. (Until
    2026-11-25 the shoulder's peaks were read at each side's keyframe with the largest swing
    region: an extracted keyframe whose samples fell short of one movement read it short,
    up to 15° on the truth path.)
``in%`` / ``in1%`` ("no recorded region left out")
    Share of the **true** joint orientations of the free motion that the extracted limb file
    accepts (:class:`models.oracle.ConstraintOracle`, exact: swing and twist; a coupled joint at
    its corrected hinge angle), and within 1° of it; ``limb``: every joint. A hinge's true
    orientations dwell exactly at its ends, so 0.0001° of calibration error there shows in
    ``in%``, not in ``in1%``.
``cal°``
    Median angle between the calibrated and the true joint orientations over the free motion
    (calibration and sensor errors together).

The targets are judged on the medians over patients, per joint (worst beside them).

Run::

    .venv/bin/python benchmarks/bench_limb_imu.py            # seeds 101-105 + 2 left: 7.5 min
    .venv/bin/python benchmarks/bench_limb_imu.py --quick    # seed 101, 120 s, right: 40 s
    .venv/bin/python benchmarks/bench_limb_imu.py --seeds 1,2,3 --left "" --duration 300
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import time

import common  # noqa: F401  (first: one BLAS thread, this checkout on sys.path)
import numpy as np

from calibration import (
    CalibrationError,
    LimbImuCalibration,
    boundary_distance,
    status_ok,
)
from calibration.extraction import LimbExtractor
from calibration.heading import LimbHeadingCorrection
from calibration.joint_angles import allowed_rom, recorded_rom
from calibration.joints import JOINTS, LIMB_CHAINS
from models import quaternion as Q
from models.limits import PolygonSwing
from models.oracle import ConstraintOracle
from rig.sim.patients import anatomical_limb, record_limb_imu, seeded_patient

X = np.array([1.0, 0.0, 0.0])
#: column → (target, what it says)
TARGETS = {"bnd": (2.0, "swing boundary ≤ 2°"), "hinge": (2.0, "hinge ends ≤ 2°"),
           "kf": (3.0, "coupling keyframes ≤ 3°"), "rec": (2.0, "peaks vs true recording ≤ 2°"),
           "con": (2.0, "peaks vs true constraint ≤ 2°")}


def _area(c) -> float:
    return c.swing.area_sr() if isinstance(c.swing, PolygonSwing) else 0.0


def loosest(joint):
    """A joint's constraint, or its coupled keyframe with the largest swing region."""
    if joint.coupling is None:
        return joint.constraint
    return max(joint.coupling.keyframes, key=_area)


def keyframes(joint) -> list:
    """A joint's constraint, or its coupled keyframes' (read as ``rig rom`` reads a limb file:
    movement by movement the largest over them, :func:`calibration.joint_angles.allowed_rom`)."""
    return [joint.constraint] if joint.coupling is None else list(joint.coupling.keyframes)


def limits_at(joint, angle_deg: float):
    """A joint's limits at a coupling angle (its own constraint when uncoupled)."""
    return joint.constraint if joint.coupling is None else joint.coupling.at(angle_deg)


def calibrate(rec, limb: str, side: str, status: bool = True,
              upright: np.ndarray | None = None) -> LimbImuCalibration:
    """The limb calibration from the recording's protocol windows (status-checked samples
    unless ``status`` is False: the devices' status bytes do not describe a host fusion); with
    ``upright`` (K, 2) windows, the neutral checkpoints as further standings of the root (step
    7 of :mod:`calibration.limb_calibration`; the read path does so on the host's fusion)."""
    ok = status_ok(rec.status) if status else np.ones(len(rec.t), dtype=bool)
    st = rec.window("static")
    names = [j for j in rec.windows if j != "static"]
    fn = {j: rec.quaternions[rec.window(j)] for j in names}
    fok = {j: ok[rec.window(j)] for j in names}
    up = None
    if upright is not None and len(upright):
        up = [rec.quaternions[(rec.t >= a) & (rec.t <= b) & ok] for a, b in upright]
    return LimbImuCalibration(limb, side).fit(rec.quaternions[st], fn, static_ok=ok[st],
                                              functional_ok=fok, upright=up)


def fused(rec):
    """The recording with each sensor's raw samples fused on the host (VQF)."""
    from calibration.fusion import fuse_vqf

    q = [fuse_vqf(rec.t, np.concatenate((rec.accel[:, k], rec.gyro[:, k], rec.mag[:, k]),
                                        axis=1)).q for k in range(rec.quaternions.shape[1])]
    return dataclasses.replace(rec, quaternions=np.stack(q, axis=1))


def _peak_error(a: dict, b: dict) -> tuple[float, str]:
    """The largest error over the movements both report, and that movement."""
    errs = [(abs(a[m] - b[m]), m) for m in a if m != "side" and a.get(m) is not None
            and b.get(m) is not None]
    return max(errs) if errs else (math.nan, "")


class Truth:
    """The patient's limits and what is read from them once (clinical peaks)."""

    def __init__(self, seed: int, limb: str, side: str, q_true: np.ndarray):
        self.limb = anatomical_limb(seed, limb, side)
        self.side = side
        self.q = q_true
        self.rec_peaks, self.con_peaks = [], []
        for j, joint in enumerate(self.limb.joints):
            c = keyframes(joint)
            if joint.name == "shoulder":
                self.rec_peaks.append(allowed_rom(c, "shoulder", side, directions=Q.rotate(
                    q_true[:, j], X)).to_dict())
                self.con_peaks.append(allowed_rom(c, "shoulder", side).to_dict())
            else:
                self.rec_peaks.append(recorded_rom(q_true[:, j], joint.name, side).peaks)
                self.con_peaks.append(allowed_rom(c, joint.name, side).peaks)


def analyse(truth: Truth, q: np.ndarray, t: np.ndarray, status, limb: str,
            slow: dict | None = None) -> dict:
    """Extract the limb from joint orientations ``q`` (N, 3, 4) and compare with the truth
    (``slow``: each joint's measured slow error, as the read path passes it)."""
    side = truth.side
    t0 = time.perf_counter()
    ex = LimbExtractor(limb).fit(q, t=t, status=status, side=side, slow_error_deg=slow)
    t_ext = time.perf_counter() - t0
    got = ex.limb_
    res = ConstraintOracle(got).evaluate(truth.q, normalize=True)
    cal_err = np.degrees(Q.angle(Q.multiply(Q.conjugate(truth.q), q)))
    joints = []
    for j, (tj, gj) in enumerate(zip(truth.limb.joints, got.joints, strict=True)):
        kind = JOINTS[tj.name].kind
        row = {"joint": tj.name, "kind": kind, "cal": float(np.median(cal_err[:, j])),
               "in": 100 * float(np.mean(res.valid[:, j])),
               "in1": 100 * float(np.mean(res.distance[:, j] <= math.radians(1.0)))}
        if kind == "hinge":
            th, gh = tj.constraint.hinge, gj.constraint.hinge
            row["hinge"] = max(abs(gh.min_deg - th.min_deg), abs(gh.max_deg - th.max_deg))
        else:
            if tj.coupling is not None:
                angles = tj.coupling.at_deg
            elif gj.coupling is not None:
                angles = gj.coupling.at_deg
            else:
                angles = (0.0,)
            row["bnd"] = float(np.mean([boundary_distance(limits_at(gj, a), limits_at(tj, a))
                                        ["mean_deg"] for a in angles]))
            row["loose"] = boundary_distance(loosest(gj), loosest(tj))["mean_deg"]
            row["truth_coupled"] = tj.coupling is not None
            row["found"] = gj.coupling is not None
            if gj.coupling is not None:
                row["kf_list"] = [(a, boundary_distance(c, limits_at(tj, a))["mean_deg"])
                                  for a, c in zip(gj.coupling.at_deg, gj.coupling.keyframes,
                                                  strict=True)]
                row["kf"] = max(d for _, d in row["kf_list"])
        if tj.name == "shoulder":
            mine = allowed_rom(keyframes(gj), "shoulder", side,
                               directions=Q.rotate(q[:, j], X)).to_dict()
        else:
            mine = recorded_rom(q[:, j], tj.name, side, status=status).peaks
        row["rec"], row["rec_m"] = _peak_error(mine, truth.rec_peaks[j])
        row["con"], row["con_m"] = _peak_error(mine, truth.con_peaks[j])
        joints.append(row)
    return {"joints": joints, "limb_in": 100 * float(np.mean(res.valid.all(axis=1))),
            "limb_in1": 100 * float(np.mean((res.distance <= math.radians(1.0)).all(axis=1))),
            "coupled": ex.coupled_, "note": ex.coupling_note_, "t_ext": t_ext}


def heading_corrected(rec, cal: LimbImuCalibration, windows: np.ndarray,
                      status: np.ndarray | None) -> tuple[np.ndarray, dict]:
    """The recording's sensors with their heading drift removed at the neutral checkpoints
    (:class:`calibration.heading.LimbHeadingCorrection`, anchored at the static window's
    centre, as the read path does; unchanged without checkpoints), and each joint's slow error
    as the read path measures it (:attr:`rig.readback.data.JointData.slow_errors_deg`: the
    correction's uncertainty for the joint's distal sensor over the recording)."""
    if not len(windows):
        return rec.quaternions, {}
    a, b = rec.windows["static"]
    hc = LimbHeadingCorrection(cal).fit(rec.t, rec.quaternions, windows,
                                        status=status, anchors=[0.5 * (a + b)])
    t0, t1 = float(rec.t.min()), float(rec.t.max())
    slow = {name: hc.sensors_[child].uncertainty_deg(t0, t1) if child in hc.sensors_ else None
            for name, _, child in LIMB_CHAINS[cal.limb]}
    return hc.apply(rec.t, rec.quaternions), slow


def evaluate(seed: int, limb: str, side: str, duration: float, rate: float,
             paths: list[str], neutral: float = 20.0) -> dict:
    """One patient: record, then every path."""
    t0 = time.perf_counter()
    chain = seeded_patient(seed, limb, side, neutral=neutral)
    rec = record_limb_imu(chain, duration, rate)
    windows = np.asarray(chain.neutral_windows(float(rec.t[-1])), dtype=np.float64).reshape(-1, 2)
    t_rec = time.perf_counter() - t0
    free = rec.window("free")
    truth = Truth(seed, limb, side, rec.joints[free])
    out = {"patient": f"{limb}-{seed}-{side}", "samples": int(free.sum()), "t_rec": t_rec,
           "paths": {}}
    for path in paths:
        try:
            if path == "truth":
                r = analyse(truth, rec.joints[free], rec.t[free], None, limb)
                r["residual"] = math.nan
            elif path == "pose":  # error-free sensors: the calibration's own error
                src = dataclasses.replace(rec, quaternions=rec.sensors_true)
                cal = calibrate(src, limb, side, status=False, upright=windows)
                r = analyse(truth, cal.transform(src.quaternions[free]), rec.t[free], None,
                            limb)
                r["residual"] = cal.residual_deg_
            else:
                host = path == "vqf"  # as the read path: no status bytes for a host fusion
                src = fused(rec) if host else rec
                status = None if host else rec.status.min(axis=1)
                cal = calibrate(src, limb, side, status=not host,
                                upright=windows if host else None)
                q, slow = heading_corrected(src, cal, windows, status)
                r = analyse(truth, cal.transform(q[free]), rec.t[free],
                            None if status is None else status[free], limb, slow)
                r["slow"] = slow
                r["residual"] = cal.residual_deg_
        except CalibrationError as err:  # a failure is a figure too
            r = {"error": str(err)}
        out["paths"][path] = r
    out["t_total"] = time.perf_counter() - t0
    return out


def _f(v, width: int = 6, digits: int = 2) -> str:
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return f"{'-':>{width}s}"
    return f"{v:{width}.{digits}f}"


HEAD = (f"  {'joint':9s} {'cal°':>6s} {'bnd°':>6s} {'loose°':>6s} {'hinge°':>6s} {'kf°':>6s} "
        f"{'found':>7s} {'rec°':>6s} {'con°':>6s} {'in%':>7s} {'in1%':>7s}")


def show(p: dict, path: str) -> None:
    r = p["paths"][path]
    if "error" in r:
        print(f"\n{p['patient']} [{path}]: FAILED — {r['error']}")
        return
    res = "" if math.isnan(r["residual"]) else f", calibration residual {r['residual']:.2f}°"
    print(f"\n{p['patient']} [{path}]: {p['samples']} free samples{res}, extraction "
          f"{r['t_ext']:.1f} s")
    print(f"  coupling: {'yes' if r['coupled'] else 'no'} — {r['note']}")
    print(HEAD)
    for j in r["joints"]:
        found = "-" if j["kind"] == "hinge" else (
            f"{'yes' if j['found'] else 'no'}/{'yes' if j['truth_coupled'] else 'no'}")
        print(f"  {j['joint']:9s} {_f(j['cal'])} {_f(j.get('bnd'))} {_f(j.get('loose'))} "
              f"{_f(j.get('hinge'))} {_f(j.get('kf'))} {found:>7s} {_f(j['rec'])} "
              f"{_f(j['con'])} {_f(j['in'], 7)} {_f(j['in1'], 7)}")
        notes = []
        if "kf_list" in j:
            notes.append("keyframes " + ", ".join(f"{a:.0f}°: {d:.2f}" for a, d in j["kf_list"]))
        if j["rec_m"] or j["con_m"]:
            notes.append(f"peaks: rec {j['rec_m'] or '-'}, con {j['con_m'] or '-'}")
        if notes:
            print(f"  {'':9s} " + "; ".join(notes))
    print(f"  {'limb':9s} {'':55s} {_f(r['limb_in'], 7)} {_f(r['limb_in1'], 7)}")


def _values(js: list[dict], key: str) -> list[float]:
    return [j[key] for j in js if j.get(key) is not None and not math.isnan(j[key])]


def summary(patients: list[dict], path: str) -> None:
    failed = [p["patient"] for p in patients if "error" in p["paths"][path]]
    patients = [p for p in patients if "error" not in p["paths"][path]]
    if failed:
        print(f"\n[{path}] FAILED on {len(failed)} patient(s), left out below: "
              f"{', '.join(failed)}")
    if not patients:
        return
    by: dict[str, list[dict]] = {}
    for p in patients:
        for j in p["paths"][path]["joints"]:
            by.setdefault(j["joint"], []).append(j)
    print(f"\n[{path}] medians over {len(patients)} patients (worst in brackets)")
    print(HEAD)
    for name, js in by.items():
        cells = []
        for key, width in (("cal", 6), ("bnd", 6), ("loose", 6), ("hinge", 6), ("kf", 6)):
            v = _values(js, key)
            cells.append(_f(float(np.median(v)) if v else None, width))
        cpl = [j for j in js if j["kind"] != "hinge"]
        found = f"{sum(j['found'] for j in cpl)}/{len(cpl)}" if cpl else "-"
        rest = [_f(float(np.median(_values(js, k)))) for k in ("rec", "con")]
        rest += [_f(float(np.median(_values(js, k))), 7) for k in ("in", "in1")]
        print(f"  {name:9s} {' '.join(cells)} {found:>7s} {' '.join(rest)}")
        worst = []
        for key in ("cal", "bnd", "loose", "hinge", "kf", "rec", "con", "in", "in1"):
            v = _values(js, key)
            w = (min(v) if key in ("in", "in1") else max(v)) if v else None
            worst.append(_f(w, 7 if key in ("in", "in1") else 6))
        print(f"  {'':9s} " + " ".join(worst[:5]) + f" {'':7s} " + " ".join(worst[5:]))
    li = [p["paths"][path]["limb_in"] for p in patients]
    li1 = [p["paths"][path]["limb_in1"] for p in patients]
    print(f"  {'limb':9s} {'':55s} {_f(float(np.median(li)), 7)} "
          f"{_f(float(np.median(li1)), 7)}   (worst {min(li):.2f}, {min(li1):.2f})")

    print(f"\n[{path}] targets: median per joint over patients")
    for key, (goal, label) in TARGETS.items():
        for name, js in by.items():
            v = _values(js, key)
            if not v:
                continue
            med = float(np.median(v))
            within = sum(x <= goal for x in v)
            print(f"  {label:30s} {name:9s} median {med:6.2f}  worst {max(v):6.2f}  "
                  f"{within}/{len(v)} within  {'MET' if med <= goal else 'NOT MET'}")
    for name, js in by.items():
        true_c = [j for j in js if j.get("truth_coupled")]
        if true_c:
            n = sum(j["found"] for j in true_c)
            print(f"  {'coupling found where true':30s} {name:9s} {n}/{len(true_c)}"
                  f"{'':34s}{'MET' if n == len(true_c) else 'NOT MET'}")
        false_c = [j for j in js if "found" in j and not j.get("truth_coupled")]
        if false_c:
            n = sum(j["found"] for j in false_c)
            print(f"  {'no coupling where none':30s} {name:9s} {len(false_c) - n}/"
                  f"{len(false_c)}{'':34s}{'MET' if n == 0 else 'NOT MET'}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", default="101,102,103,104,105",
                    help="held-out seeds, comma-separated (right arm and leg of each)")
    ap.add_argument("--left", default="101",
                    help="seeds whose left arm and leg are run too ('' for none)")
    ap.add_argument("--limbs", default="arm,leg")
    ap.add_argument("--duration", type=float, default=300.0, help="free motion, s")
    ap.add_argument("--rate", type=float, default=100.0, help="sample rate, Hz")
    ap.add_argument("--paths", default="vqf,imu,truth",
                    help="vqf (the read path's default for sessions with raw samples), imu (the "
                         "devices' quaternions), truth, pose (the calibration on error-free "
                         "sensors); comma-separated")
    ap.add_argument("--neutral", type=float, default=20.0,
                    help="neutral checkpoints every this many seconds (0: none, no heading "
                         "correction)")
    ap.add_argument("--quick", action="store_true", help="the first seed, 120 s, right only")
    a = ap.parse_args()
    seeds = [int(s) for s in a.seeds.split(",") if s.strip()]
    left = [int(s) for s in a.left.split(",") if s.strip()]
    limbs = [x.strip() for x in a.limbs.split(",") if x.strip()]
    paths = [x.strip() for x in a.paths.split(",") if x.strip()]
    for p in paths:
        if p not in ("imu", "truth", "vqf", "pose"):
            raise SystemExit(f"--paths: unknown path {p!r} (imu, truth, vqf, pose)")
    if a.quick:
        seeds, left, a.duration = seeds[:1], [], 120.0
    runs = [(s, limb, "right") for s in seeds for limb in limbs]
    runs += [(s, limb, "left") for s in left for limb in limbs]
    t0 = time.perf_counter()
    patients = []
    for seed, limb, side in runs:
        p = evaluate(seed, limb, side, a.duration, a.rate, paths, a.neutral)
        patients.append(p)
        for path in paths:
            show(p, path)
        print(f"  ({p['patient']}: recording {p['t_rec']:.0f} s, all paths "
              f"{p['t_total']:.0f} s)", flush=True)
    for path in paths:
        summary(patients, path)
    print(f"\n{len(patients)} patients, {a.duration:g} s of free motion at {a.rate:g} Hz each, "
          f"paths {', '.join(paths)}: {time.perf_counter() - t0:.0f} s wall")


if __name__ == "__main__":
    main()
