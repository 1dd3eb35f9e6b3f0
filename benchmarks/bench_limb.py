"""Limb models on held-out limbs (issue 20): end-point and per-joint errors, violations.

    python benchmarks/bench_limb.py [--limbs 10] [--n 6000] [--methods uncoupled]

Every held-out limb of :func:`models.limb_evaluation.held_out_limbs` (legs and arms with a
concave ball joint coupled to a hinge through 3-4 keyframes, a hinge, a two-axis joint; seeds
from ``HELD_OUT_LIMB_SEED``, none used to tune anything) is scored on
:func:`~models.limb_evaluation.held_out_postures` (a third uniform, a third near a boundary, a
third valid) by :func:`~models.limb_evaluation.evaluate_limb_model`. Methods:

``exact``      the limb oracle itself (the metrics' sanity check: every figure 0);
``uncoupled``  each coupled joint at its loosest limits (what ignoring the coupling costs).

Prints one row per limb and method and the mean over limbs against the issue's targets.
"""

from __future__ import annotations

import argparse

import common  # noqa: F401  (first: one BLAS thread, this checkout on sys.path)
import numpy as np

from models.limb_evaluation import (
    evaluate_limb_model,
    held_out_limbs,
    held_out_postures,
    uncoupled_model,
)
from models.limb_oracle import LimbOracle

TARGETS = (("end_mean_3d_error_pct", "end-point mean 3-D error %", "<= 0.5"),
           ("frac_invalid_left_1deg", "invalid left > 1° out (fraction)", "<= 0.01"),
           ("valid_moved_deg", "valid inputs moved (mean °)", "<= 0.1"),
           ("end_p99_direction_error_deg", "p99 end-point direction error °", "<= 3"))


def method(name, limb, oracle):
    if name == "exact":
        return oracle.correction
    if name == "uncoupled":
        return uncoupled_model(limb)
    raise SystemExit(f"--methods: unknown method {name!r} (exact, uncoupled)")


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
    for i, (label, limb) in enumerate(held_out_limbs(args.limbs).items()):
        oracle = LimbOracle(limb)
        q = held_out_postures(limb, args.n, 1000 + i, oracle=oracle)
        for m in names:
            r = evaluate_limb_model(method(m, limb, oracle), oracle, q)
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


if __name__ == "__main__":
    main()
