"""Boundary extraction benchmark: accuracy on held-out simulated patients, and speed.

Accuracy
    Held-out patients: seeded random concave star polygons (``rig.sim.patients.star_constraint``,
    seeds 100+; the method and its defaults were set on an earlier star generator's seeds
    0-7, not on these) and the thesis shapes ``original``, ``c-shape`` and
    ``highly-irregular`` with a twist range added, each recorded two ways:

    - **imu**: the simulated patient (``rig.sim.patients.simulated_patient``) performs the
      calibration protocol, then moves freely; two IMUs strapped at misplaced orientations
      (25° off the default straps), with white noise, heading/tilt drift and magnetic
      disturbances (the default ``NoiseModel``); ``ImuJointCalibration`` → joint orientations
      → ``BoundaryExtractor`` (status-flagged samples dropped);
    - **servo**: the back-driven servo limb — the true joint read through three 4096-tick
      encoders.

    Reported per patient and as medians: the symmetric mean boundary distance to the truth
    (``calibration.boundary.boundary_distance``), its Hausdorff distance, the fraction of the
    patient's true directions more than 1° / 2° outside the extracted region ("recorded region
    left out"), the twist-limit errors, and the largest error of the peak clinical angles
    (``calibration.clinical.range_of_motion`` of the extracted constraint against the truth's).

Speed
    Median wall time of ``BoundaryExtractor().fit`` on 100 000 recorded samples (servo path).

Run::

    .venv/bin/python benchmarks/bench_boundary.py            # full: ~5 min on 2 cores
    .venv/bin/python benchmarks/bench_boundary.py --quick    # 2 patients, short recordings
"""

from __future__ import annotations

import argparse
import math
import os
import time

import common  # noqa: F401  (first: one BLAS thread, this checkout on sys.path)
import numpy as np

from calibration import (
    BoundaryExtractor,
    ImuJointCalibration,
    boundary_distance,
    outside_fraction,
    range_of_motion,
    status_ok,
)
from models import quaternion as Q
from models.constraint import JointConstraint
from models.shapes import load_shape
from rig.sim.patients import record_imu, record_servo, seeded_patient, star_constraint

X = np.array([1.0, 0.0, 0.0])
SHAPES = ("original", "c-shape", "highly-irregular")
SHAPE_TWIST = {"original": (-45.0, 60.0), "c-shape": (-30.0, 70.0),
               "highly-irregular": (-55.0, 40.0)}


def patients(n_star: int, shapes: bool):
    for seed in range(100, 100 + n_star):
        yield f"star-{seed}", star_constraint(seed), seed
    if shapes:
        for k, name in enumerate(SHAPES):
            c = load_shape(name)
            lo, hi = SHAPE_TWIST[name]
            d = c.to_dict()
            d["twist"] = {"min_deg": lo, "max_deg": hi}
            d.pop("provenance", None)
            yield name, JointConstraint.from_dict(d), 200 + k


def joint_from_imu(rec):
    s, f = rec.window("static"), rec.window("functional")
    cal = ImuJointCalibration().fit(rec.thorax[s], rec.limb[s], rec.thorax[f], rec.limb[f],
                                    static_ok=status_ok(rec.status[s]),
                                    functional_ok=status_ok(rec.status[f]))
    free = rec.window("free")
    return cal.transform(rec.thorax[free], rec.limb[free]), rec.status[free], cal.residual_deg_


def peak_error(extracted: JointConstraint, truth: JointConstraint) -> float:
    a = range_of_motion(extracted, "right").to_dict()
    b = range_of_motion(truth, "right").to_dict()
    errs = []
    for m in a:
        if m == "side":
            continue
        if a[m] is None or b[m] is None:
            if (a[m] is None) != (b[m] is None):
                errs.append(math.inf)
            continue
        errs.append(abs(a[m] - b[m]))
    return max(errs) if errs else 0.0


def evaluate(name, truth, q, status, truth_q):
    ex = BoundaryExtractor().fit(q, status=status)
    d = boundary_distance(ex.constraint_, truth)
    dirs = Q.rotate(truth_q, X)
    lo, hi = ex.twist_deg_
    return {
        "patient": name,
        "mean": d["mean_deg"],
        "hausdorff": d["hausdorff_deg"],
        "out1": 100 * outside_fraction(ex.constraint_, dirs, 1.0),
        "out2": 100 * outside_fraction(ex.constraint_, dirs, 2.0),
        "twist": max(abs(lo - truth.twist.min_deg), abs(hi - truth.twist.max_deg)),
        "peaks": peak_error(ex.constraint_, truth),
        "vertices": len(ex.vertices_),
        "sparse": sum(a.length_deg for a in ex.sparse_arcs_),
    }


def show(title, rows):
    print(f"\n{title}")
    head = (f"{'patient':18s} {'mean°':>6s} {'Haus°':>6s} {'out>1°%':>8s} {'out>2°%':>8s} "
            f"{'twist°':>7s} {'peaks°':>7s} {'verts':>5s} {'sparse°':>7s}")
    print(head)
    for r in rows:
        print(f"{r['patient']:18s} {r['mean']:6.2f} {r['hausdorff']:6.2f} {r['out1']:8.2f} "
              f"{r['out2']:8.2f} {r['twist']:7.2f} {r['peaks']:7.2f} {r['vertices']:5d} "
              f"{r['sparse']:7.1f}")
    med = {k: float(np.median([r[k] for r in rows])) for k in
           ("mean", "hausdorff", "out1", "out2", "twist", "peaks")}
    mx = {k: float(np.max([r[k] for r in rows])) for k in ("mean", "twist", "peaks")}
    print(f"{'median':18s} {med['mean']:6.2f} {med['hausdorff']:6.2f} {med['out1']:8.2f} "
          f"{med['out2']:8.2f} {med['twist']:7.2f} {med['peaks']:7.2f}")
    print(f"{'worst':18s} {mx['mean']:6.2f} {'':6s} {'':8s} {'':8s} {mx['twist']:7.2f} "
          f"{mx['peaks']:7.2f}")


def timing(repeats: int) -> None:
    truth = star_constraint(100)
    rate = 100_000 / 600.0
    rec = record_servo(seeded_patient(100, truth), 600.0 - 20.0, rate)
    q = rec.limb[:100_000]
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        BoundaryExtractor().fit(q)
        times.append(time.perf_counter() - t0)
    print(f"\nextraction of {len(q)} samples: median {np.median(times):.3f} s "
          f"(min {min(times):.3f}, max {max(times):.3f}, {repeats} runs, "
          f"{os.cpu_count()} CPUs seen, shared machine)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--stars", type=int, default=5, help="held-out star patients")
    ap.add_argument("--duration", type=float, default=300.0, help="free recording, s")
    ap.add_argument("--rate", type=float, default=100.0, help="sample rate, Hz")
    ap.add_argument("--no-shapes", action="store_true", help="skip the thesis shapes")
    ap.add_argument("--repeats", type=int, default=5, help="timing repeats")
    ap.add_argument("--quick", action="store_true", help="2 patients, 120 s, no shapes")
    a = ap.parse_args()
    if a.quick:
        a.stars, a.duration, a.no_shapes, a.repeats = 2, 120.0, True, 3
    imu_rows, servo_rows = [], []
    for name, truth, seed in patients(a.stars, not a.no_shapes):
        limb = seeded_patient(seed, truth)
        rec = record_servo(limb, a.duration, a.rate)
        free = rec.window("free")
        servo_rows.append(evaluate(name, truth, rec.limb[free], None, rec.truth[free]))
        limb = seeded_patient(seed, truth)
        rec = record_imu(limb, a.duration, a.rate)
        q, status, _ = joint_from_imu(rec)
        imu_rows.append(evaluate(name, truth, q, status, rec.truth[rec.window("free")]))
        print(f"  {name}: servo {servo_rows[-1]['mean']:.2f}°, imu {imu_rows[-1]['mean']:.2f}°",
              flush=True)
    show(f"servo path ({a.duration:g} s at {a.rate:g} Hz per patient)", servo_rows)
    show(f"IMU path ({a.duration:g} s at {a.rate:g} Hz, noise + drift + disturbances, "
         "misplaced sensors)", imu_rows)
    timing(a.repeats)


if __name__ == "__main__":
    main()
