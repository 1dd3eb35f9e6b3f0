"""Limb models on held-out limbs (issue 20): end-point and per-joint errors, violations.

    python benchmarks/bench_limb.py [--limbs 10] [--n 6000] [--methods exact,uncoupled,geometric]

Every held-out limb of :func:`models.limb_evaluation.held_out_limbs` (legs and arms with a
concave ball joint coupled to a hinge through 3-4 keyframes, a hinge, a two-axis joint; seeds
from ``HELD_OUT_LIMB_SEED``, none used to tune anything) is scored on
:func:`~models.limb_evaluation.held_out_postures` (a third uniform, a third near a boundary, a
third valid) by :func:`~models.limb_evaluation.evaluate_limb_model`. Methods:

``exact``      the limb oracle itself (the metrics' sanity check: every figure 0);
``uncoupled``  each coupled joint at its loosest limits (what ignoring the coupling costs);
``geometric``  the limb model (``models.limb_model``): the exact oracle compiled into one ONNX
               graph, run by onnxruntime (float32); also its file size, single-call latency
               (median of 3000 ``correct_one`` calls) and batched throughput (median of 5
               calls on 10,000 postures), one thread.

Prints one row per limb and method and the mean over limbs against the issue's targets.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import common  # noqa: F401  (first: one BLAS thread, this checkout on sys.path)
import numpy as np

from models.limb_evaluation import (
    evaluate_limb_model,
    held_out_limbs,
    held_out_postures,
    uncoupled_model,
)
from models.limb_model import export_limb_model, load_limb_model
from models.limb_oracle import LimbOracle

TARGETS = (("end_mean_3d_error_pct", "end-point mean 3-D error %", "<= 0.5"),
           ("frac_invalid_left_1deg", "invalid left > 1° out (fraction)", "<= 0.01"),
           ("valid_moved_deg", "valid inputs moved (mean °)", "<= 0.1"),
           ("end_p99_direction_error_deg", "p99 end-point direction error °", "<= 3"))


SPEED: list[dict] = []


def method(name, limb, oracle, tmp: Path, q):
    if name == "exact":
        return oracle.correction
    if name == "uncoupled":
        return uncoupled_model(limb)
    if name == "geometric":
        model = load_limb_model(export_limb_model(limb, tmp / f"{limb.name}.onnx"), limb)
        SPEED.append(speed(model, q))
        return model.correction
    raise SystemExit(f"--methods: unknown method {name!r} (exact, uncoupled, geometric)")


def speed(model, q) -> dict:
    q32 = np.ascontiguousarray(q, dtype=np.float32)
    for i in range(300):
        model.correct_one(q32[i % len(q32)])
    lat = []
    for i in range(3000):
        t0 = time.perf_counter_ns()
        model.correct_one(q32[i % len(q32)])
        lat.append(time.perf_counter_ns() - t0)
    big = np.resize(q32, (10_000, *q32.shape[1:]))
    runs = []
    for _ in range(5):
        t0 = time.perf_counter()
        model.correction(big)
        runs.append(time.perf_counter() - t0)
    return {"bytes": model.size_bytes, "single_us": statistics.median(lat) / 1e3,
            "per_s": len(big) / statistics.median(runs)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--limbs", type=int, default=10)
    ap.add_argument("--n", type=int, default=6000, help="postures per limb")
    ap.add_argument("--methods", default="exact,uncoupled")
    args = ap.parse_args()
    names = args.methods.split(",")
    rows: dict[str, list[dict]] = {m: [] for m in names}
    print(f"{'limb':<10} {'method':<10} {'end %':>7} {'p99 end °':>9} {'left>1°':>8} "
          f"{'moved °':>8} {'max viol °':>10}  joint dir err ° (mean)")
    tmp = Path(tempfile.mkdtemp(prefix="bench-limb-"))
    for i, (label, limb) in enumerate(held_out_limbs(args.limbs).items()):
        oracle = LimbOracle(limb)
        q = held_out_postures(limb, args.n, 1000 + i, oracle=oracle)
        for m in names:
            r = evaluate_limb_model(method(m, limb, oracle, tmp, q), oracle, q)
            rows[m].append(r)
            print(f"{label:<10} {m:<10} {r['end_mean_3d_error_pct']:7.3f} "
                  f"{r['end_p99_direction_error_deg']:9.2f} {r['frac_invalid_left_1deg']:8.3f} "
                  f"{r['valid_moved_deg']:8.3f} {r['max_violation_deg']:10.2f}  "
                  f"{', '.join(f'{x:.2f}' for x in r['joint_mean_direction_error_deg'])}")
    print(f"\nmean over {args.limbs} held-out limbs ({args.n} postures each)")
    print(f"{'target':<36} {'goal':>8} " + " ".join(f"{m:>10}" for m in names))
    for key, label, goal in TARGETS:
        vals = " ".join(f"{np.mean([r[key] for r in rows[m]]):10.3f}" for m in names)
        print(f"{label:<36} {goal:>8} {vals}")
    if SPEED:
        med = {k: statistics.median(x[k] for x in SPEED) for k in SPEED[0]}
        print(f"\ngeometric limb model, median over {len(SPEED)} limbs: file "
              f"{med['bytes'] / 1e3:.0f} kB (target <= 2 MB); onnxruntime single call "
              f"{med['single_us']:.0f} µs (target <= 50); batched {med['per_s']:,.0f} limbs/s "
              f"(target >= 500,000); build: no training (compiled in "
              f"< 1 s)")


if __name__ == "__main__":
    main()
