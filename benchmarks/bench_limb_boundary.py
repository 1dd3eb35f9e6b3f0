"""``rig boundary --limb`` against ``--joint`` on the same recording (issue 37, item 3): does a
limb file keep what each joint reached, and does each of its joints say what the one-joint
extraction says?

Per limb, the recorded postures ``q`` (N, 3, 4) go through both paths as the CLI runs them:

- ``--limb``: :class:`calibration.boundary.LimbExtractor` with the sample times, the status
  and each joint's measured slow error (:func:`rig.readback.boundary.extract_limb`'s call);
- ``--joint``: :func:`rig.readback.boundary.extract` on each joint's orientations alone
  (``rig boundary --joint NAME``'s call), with that joint's measured slow error.

Columns, per joint:

``chain%`` / ``joint%``
    Recorded postures the limb file (the ``--joint`` file) holds: the joint's orientation
    inside its limits (a coupled joint at its recorded hinge angle; a hinge: its recorded angle
    inside the interval), or beyond them by no more than the joint's measured slow error
    explains at that posture — the twist's singular reach at its swing
    (:func:`calibration.boundary.twist.singular_reach`: a twist end counts a sample near the
    limb axis's antipode only beyond it, so such a sample may lie that far outside). Target
    ≥ 99.5 % for ``chain%``.
``strict%``
    The limb file's share with no allowance: inside.
``d°`` (movement)
    The largest difference, over the movements both report, between the clinical peaks
    ``rig rom --constraint`` reads from the limb file's joint
    (:func:`calibration.joint_angles.allowed_rom`: a coupled joint's largest over its
    keyframes) and from the ``--joint`` file; for a hinge its two ends. Target ≤ 0.5°.

Sources:

- simulated limbs from **held-out** seeds (``rig.sim.patients.simulated_patient(seed, limb,
  "right", neutral=20)``; seeds 101-105 are the ones ``benchmarks/bench_limb_imu.py`` calls
  held out: tests and development used seeds 0-20), recorded by
  :func:`~rig.sim.patients.record_limb_imu` (the limb protocol, then ``--duration`` s of free
  motion at ``--rate`` Hz) and read as a session is read by default: each sensor's raw samples
  fused on the host (VQF), the limb calibration fitted on the protocol windows with the
  neutral checkpoints as standings of the root, the heading corrected at the checkpoints and
  each joint's slow error measured (the read path's steps; as ``bench_limb_imu.py``'s ``vqf``
  path, repeated here because scripts share code only through ``common``);
- the real recordings in ``tests/calibration/data/real`` that hold a whole limb (no status, no
  slow error: files).

Run::

    .venv/bin/python benchmarks/bench_limb_boundary.py                 # 10 limbs + real
    .venv/bin/python benchmarks/bench_limb_boundary.py --seeds 101 --limbs leg --no-real
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import time
from pathlib import Path

import common  # first: one BLAS thread, this checkout on sys.path
import numpy as np

from calibration import LimbImuCalibration
from calibration.errors import CalibrationError
from calibration.heading import LimbHeadingCorrection
from calibration.joint_angles import allowed_rom
from calibration.joints import JOINTS, LIMB_CHAINS, hinge_angles
from models.oracle import ConstraintOracle

DATA = common.ROOT / "tests" / "calibration" / "data" / "real"
#: whole limbs in the real recordings: limb → ISB segment columns ({} = r or l)
REAL = {"arm": ("thorax", "humerus_{}", "ulna_{}", "hand_{}"),
        "leg": ("pelvis", "femur_{}", "tibia_{}", "calcn_{}")}


def read_like_a_session(seed: int, limb: str, side: str, duration: float, rate: float):
    """A simulated limb recorded and read back as the read path reads a session: postures
    (N, 3, 4) of the free motion, their times, and each joint's measured slow error."""
    from calibration.fusion import fuse_vqf
    from rig.sim.patients import record_limb_imu, seeded_patient

    chain = seeded_patient(seed, limb, side, neutral=20.0)
    rec = record_limb_imu(chain, duration, rate)
    windows = np.asarray(chain.neutral_windows(float(rec.t[-1])),
                         dtype=np.float64).reshape(-1, 2)
    qs = [fuse_vqf(rec.t, np.concatenate((rec.accel[:, k], rec.gyro[:, k], rec.mag[:, k]),
                                         axis=1)).q for k in range(rec.quaternions.shape[1])]
    rec = dataclasses.replace(rec, quaternions=np.stack(qs, axis=1))
    st = rec.window("static")
    names = [j for j in rec.windows if j != "static"]
    up = [rec.quaternions[(rec.t >= a) & (rec.t <= b)] for a, b in windows]
    cal = LimbImuCalibration(limb, side).fit(
        rec.quaternions[st], {j: rec.quaternions[rec.window(j)] for j in names},
        upright=up or None)
    a, b = rec.windows["static"]
    hc = LimbHeadingCorrection(cal).fit(rec.t, rec.quaternions, windows,
                                        anchors=[0.5 * (a + b)])
    t0, t1 = float(rec.t.min()), float(rec.t.max())
    slow = {name: hc.sensors_[child].uncertainty_deg(t0, t1) if child in hc.sensors_ else None
            for name, _, child in LIMB_CHAINS[limb]}
    free = rec.window("free")
    q = cal.transform(hc.apply(rec.t, rec.quaternions)[free])
    return q, rec.t[free], slow


def _cached(folder: str | None, seed: int, limb: str, duration: float, rate: float):
    """:func:`read_like_a_session`, kept in ``folder`` when given."""
    if folder is None:
        return read_like_a_session(seed, limb, "right", duration, rate)
    path = Path(folder) / f"{limb}-{seed}-{duration:g}s-{rate:g}hz.npz"
    if path.is_file():
        z = np.load(path, allow_pickle=True)
        return z["q"], z["t"], z["slow"].item()
    q, t, slow = read_like_a_session(seed, limb, "right", duration, rate)
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez(path, q=q, t=t, slow=np.array(slow, dtype=object))
    return q, t, slow


def compare(q: np.ndarray, t: np.ndarray, limb: str, side: str,
            slow: dict | None) -> list[dict]:
    """Both paths on one recording: per joint the shares held and the peaks' differences."""
    from calibration.boundary.twist import singular_reach
    from calibration.extraction import LimbExtractor
    from models import quaternion as Q
    from rig.readback.boundary import extract
    from rig.readback.data import JointData

    slow = slow or {}
    ex = LimbExtractor(limb).fit(q, t=t, side=side, slow_error_deg=slow or None)
    lb = ex.limb_
    res = ConstraintOracle(lb).evaluate(q, normalize=True)
    rows = []
    for j, joint in enumerate(lb.joints):
        spec = JOINTS[joint.name]
        axis = np.asarray(spec.limb_axis, dtype=np.float64)
        reach = singular_reach(np.arccos(np.clip(Q.rotate(q[:, j], axis) @ axis, -1.0, 1.0)),
                               slow.get(joint.name))
        reach = 0.0 if reach is None else reach
        prov = {"limb": limb}  # as a whole-limb session's joint (JointData.select) says
        if slow.get(joint.name) is not None:
            prov["heading_correction"] = {"uncertainty_deg": slow[joint.name]}
        data = JointData.of_joint(q[:, j], joint.name, t=t,
                                  limb_axis=np.asarray(spec.limb_axis, dtype=np.float64),
                                  side=side, provenance=prov)
        one = extract(data, side=side).constraint_
        row = {"joint": joint.name, "coupled": joint.coupling is not None}
        if spec.kind == "hinge":
            th = hinge_angles(q[:, j], spec.hinge_axis)
            h, h1 = joint.constraint.hinge, one.hinge
            row["chain"] = row["strict"] = float(np.mean((th >= h.min_deg)
                                                         & (th <= h.max_deg)))
            row["joint%"] = float(np.mean((th >= h1.min_deg) & (th <= h1.max_deg)))
            d = {"min": abs(h.min_deg - h1.min_deg), "max": abs(h.max_deg - h1.max_deg)}
        else:
            row["strict"] = float(np.mean(res.valid[:, j]))
            row["chain"] = float(np.mean(res.valid[:, j] | (res.distance[:, j] <= reach)))
            row["joint%"] = float(np.mean(ConstraintOracle(one).signed_distance(
                q[:, j], normalize=True) <= reach))
            kf = [joint.constraint] if joint.coupling is None else list(joint.coupling.keyframes)
            a = allowed_rom(kf, joint.name, side)
            b = allowed_rom([one], joint.name, side)
            a = a.to_dict() if hasattr(a, "to_dict") and joint.name == "shoulder" else a.peaks
            b = b.to_dict() if hasattr(b, "to_dict") and joint.name == "shoulder" else b.peaks
            d = {m: abs(a[m] - b[m]) for m in a if m in b and isinstance(a[m], (int, float))
                 and isinstance(b[m], (int, float)) and m != "side"}
        m = max(d, key=d.get) if d else ""
        row["d"], row["d_m"] = (d[m], m) if d else (math.nan, "")
        rows.append(row)
    return rows


def show(label: str, rows: list[dict], seconds: float) -> None:
    for k, r in enumerate(rows):
        head = f"{label:<30}" if k == 0 else " " * 30
        print(f"{head} {r['joint']:<9}{'c' if r['coupled'] else ' '} {100 * r['chain']:7.2f} "
              f"{100 * r['strict']:7.2f} {100 * r['joint%']:7.2f} {r['d']:6.2f} {r['d_m']}",
              flush=True)
    print(f"{'':30} ({seconds:.0f} s)", flush=True)


def summary(all_rows: dict[str, list[dict]], title: str) -> None:
    print(f"\n{title}: per joint, worst / median over limbs")
    print(f"{'joint':<9} {'n':>3} {'chain% worst':>12} {'median':>7} {'strict% worst':>13} "
          f"{'joint% worst':>12} {'d° worst':>9} {'median':>7}  (targets: chain% >= 99.5, "
          "d <= 0.5)")
    by: dict[str, list[dict]] = {}
    for rows in all_rows.values():
        for r in rows:
            by.setdefault(r["joint"], []).append(r)
    for name, rs in by.items():
        c = [100 * r["chain"] for r in rs]
        c1 = [100 * r["joint%"] for r in rs]
        cs = [100 * r["strict"] for r in rs]
        d = [r["d"] for r in rs if not math.isnan(r["d"])]
        worst = max(rs, key=lambda r: r["d"])
        print(f"{name:<9} {len(rs):3d} {min(c):12.2f} {np.median(c):7.2f} {min(cs):13.2f} "
              f"{min(c1):12.2f} "
              f"{max(d):9.2f} {np.median(d):7.2f}  (worst: {worst['d_m']})")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", default="101,102,103,104,105",
                    help="held-out seeds (right arm and leg of each)")
    ap.add_argument("--limbs", default="arm,leg")
    ap.add_argument("--duration", type=float, default=300.0, help="free motion, s")
    ap.add_argument("--rate", type=float, default=100.0, help="sample rate, Hz")
    ap.add_argument("--no-real", action="store_true", help="skip the real recordings")
    ap.add_argument("--no-sim", action="store_true", help="skip the simulated limbs")
    ap.add_argument("--cache", default=None,
                    help="a folder keeping each simulated limb's read-back postures (.npz), "
                         "so that a second run skips recording and reading")
    a = ap.parse_args()
    seeds = [int(s) for s in a.seeds.split(",") if s.strip()]
    limbs = [x.strip() for x in a.limbs.split(",") if x.strip()]
    t_all = time.perf_counter()
    print(f"{'limb':<30} {'joint':<9}  {'chain%':>7} {'strict%':>7} {'joint%':>7} {'d°':>6} "
          "movement")
    sim: dict[str, list[dict]] = {}
    for seed in [] if a.no_sim else seeds:
        for limb in limbs:
            t0 = time.perf_counter()
            label = f"{limb}-{seed}-right" + (" (held out)" if seed > 100 else "")
            try:
                q, t, slow = _cached(a.cache, seed, limb, a.duration, a.rate)
                sim[label] = compare(q, t, limb, "right", slow)
            except CalibrationError as err:
                print(f"{label:<30} FAILED: {err}")
                continue
            show(label, sim[label], time.perf_counter() - t0)
    real: dict[str, list[dict]] = {}
    if not a.no_real:
        from rig.readback.files import limb_orientations_from_file
        from rig.store.io import read_orientations

        for path in sorted(Path(DATA).glob("*.sto")):
            have = set(read_orientations(str(path)).columns)
            for limb, names in REAL.items():
                for s, side in (("r", "right"), ("l", "left")):
                    cols = [n.format(s) for n in names]
                    if not set(cols) <= have:
                        continue
                    t0 = time.perf_counter()
                    rec = limb_orientations_from_file(str(path), cols, limb, "isb")
                    label = f"{path.stem[:22]} {limb} {s}"
                    real[label] = compare(rec.joint_q, rec.t, limb, side, None)
                    show(label, real[label], time.perf_counter() - t0)
    if sim:
        summary(sim, f"simulated, held-out seeds {a.seeds} ({len(sim)} limbs, "
                     f"{a.duration:g} s at {a.rate:g} Hz)")
    if real:
        summary(real, f"real recordings ({len(real)} limbs)")
    print(f"\n{time.perf_counter() - t_all:.0f} s wall")


if __name__ == "__main__":
    main()
