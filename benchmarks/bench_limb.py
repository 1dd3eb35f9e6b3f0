"""Limb models on held-out limbs (issue 20): end-point and per-joint errors, violations.

    python benchmarks/bench_limb.py [--limbs 10] [--n 6000] [--methods exact,uncoupled,geometric]

Every held-out limb of :func:`models.limb_evaluation.held_out_limbs` (legs and arms with a
concave ball joint coupled to a hinge through 3-4 keyframes, a hinge, a two-axis joint; seeds
from ``HELD_OUT_LIMB_SEED``, none used to tune anything) is scored on
:func:`~models.limb_evaluation.held_out_postures` (a third uniform, a third near a boundary, a
third valid) by :func:`~models.evaluation.evaluate_model`. Methods:

``exact``      the limb oracle itself (the metrics' sanity check: every figure 0);
``uncoupled``  each coupled joint at its loosest limits (what ignoring the coupling costs);
``geometric``  the limb model (``models.limb_model``): the exact oracle compiled into one ONNX
               graph, run by onnxruntime (float32); also its file size, its graph's node
               count, single-call latency (median of 3000 ``correct_one`` calls) and batched
               throughput (median of 5 ``correction`` calls on 10,000 postures: chunks of
               1,024 on one worker per core; and the same 10,000 in one call on one thread);
``network``    the trained limb model: a distance field per coupled polygon swing
               (``models.nn.ndf``, seed 0), everything else exact in the same graph; the same
               figures plus its training time (wall and CPU seconds: a field alone on two
               cores trains on two threads, ``models.nn.ndf.fit_limb_fields``).
``network@F/F/…`` the same trained fields with other projection step fractions (e.g.
               ``network@0.5/0.5/0.5/1/1``, the shipped ones before 2026-11-28), accuracy only.

``--single K``: instead, the same network family on K held-out single ball joints (concave
stars with twist, ``bench_accuracy``'s held-out set) beside today's default, the tabulated
field.

Prints one row per limb and method and the mean over limbs against the issue's targets.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import statistics
import tempfile
import time
from pathlib import Path

import common  # noqa: F401  (first: one BLAS thread, this checkout on sys.path)
import numpy as np
import onnx

from models.evaluation import evaluate_model
from models.limb_evaluation import (
    held_out_limbs,
    held_out_postures,
    uncoupled_model,
)
from models.limb_model import export_limb_model
from models.nn.ndf import fit_limb_fields, fit_swing_field
from models.onnx_io import load_model
from models.oracle import ConstraintOracle

TARGETS = (("end_mean_3d_error_pct", "end-point mean 3-D error %", "<= 0.5"),
           ("frac_invalid_violating_1deg", "invalid left > 1° out (fraction)", "<= 0.01"),
           ("valid_moved_deg", "valid inputs moved (mean °)", "<= 0.1"),
           ("end_p99_direction_error_deg", "p99 end-point direction error °", "<= 3"))


SPEED: dict[str, list[dict]] = {"geometric": [], "network": []}


#: the trained fields of the limb being scored: ``network@…`` reuses ``network``'s
TRAINED: dict[str, tuple] = {}


def _fields(limb) -> tuple[dict, dict, float]:
    if limb.name not in TRAINED:
        TRAINED.clear()
        c0 = time.process_time()
        fields, facts = fit_limb_fields(limb, seed=0)
        TRAINED[limb.name] = (fields, facts, time.process_time() - c0)
    return TRAINED[limb.name]


def method(name, limb, oracle, tmp: Path, q):
    if name == "exact":
        return oracle.correction
    if name == "uncoupled":
        return uncoupled_model(limb)
    if name.startswith("network@"):  # the same fields, other projection step fractions
        try:
            steps = tuple(float(x) for x in name.split("@", 1)[1].split("/"))
        except ValueError:
            raise SystemExit(f"--methods: {name!r}: expected network@F/F/..., e.g. "
                             "network@0.5/0.5/0.5/1/1") from None
        fields, facts, _ = _fields(limb)
        fields = {k: dataclasses.replace(v, steps=steps) for k, v in fields.items()}
        tag = "-".join(f"{x:g}" for x in steps)
        path = export_limb_model(limb, tmp / f"{limb.name}-network@{tag}.onnx", fields, facts)
        return load_model(path, limb).correction
    if name in ("geometric", "network"):
        fields, facts, cpu = None, None, 0.0
        if name == "network":
            fields, facts, cpu = _fields(limb)
        path = export_limb_model(limb, tmp / f"{limb.name}-{name}.onnx", fields, facts)
        model = load_model(path, limb)
        f = facts or {}
        SPEED[name].append({**speed(model, q), "train_cpu_s": cpu,
                            "train_wall_s": f.get("seconds", 0.0),
                            "threads": f.get("workers", 0) * f.get("parts", 1)})
        return model.correction
    raise SystemExit(f"--methods: unknown method {name!r} (exact, uncoupled, geometric, "
                     f"network, network@F/F/...)")


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
    runs, one = [], []
    for _ in range(5):
        t0 = time.perf_counter()
        model.correction(big)
        runs.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        model.session.run(None, {"orientations": big})
        one.append(time.perf_counter() - t0)
    return {"bytes": model.size_bytes, "nodes": len(onnx.load(str(model.path)).graph.node),
            "single_us": statistics.median(lat) / 1e3,
            "per_s": len(big) / statistics.median(runs),
            "per_s_one_thread": len(big) / statistics.median(one)}


def single(k: int, n: int) -> None:
    """The distance-field network on single ball joints against today's default (the
    tabulated field, preset ``field``), on the held-out irregular boundaries of
    ``bench_accuracy`` (random stars with twist, seeds from ``HELD_OUT_SEED``)."""
    from models.evaluation import held_out_orientations, irregular_boundaries
    from models.field import FieldModel
    from models.kinds.ball import evaluate_ball
    from models.oracle import ConstraintOracle

    stars = [(name, c) for name, c in irregular_boundaries(k).items()
             if name.startswith("star")][:k]
    keys = (("mean_3d_error_pct", "mean 3-D error %", "<= 0.3"),
            ("frac_invalid_violating_1deg", "invalid > 1° out", "<= 0.005"),
            ("mean_identity_error_deg", "valid moved °", ""),
            ("p99_angular_error_deg", "p99 dir err °", ""))
    rows: dict[str, list[dict]] = {"field": [], "network": []}
    for name, c in stars:
        oracle = ConstraintOracle(c)
        q = held_out_orientations(c, n, 4321, oracle=oracle)
        table = FieldModel.from_constraint(c)
        c0 = time.process_time()
        net = fit_swing_field(c, np.random.default_rng(0))
        cpu = time.process_time() - c0
        lims = (c.twist.min, c.twist.max) if c.twist is not None else None

        def predict(x, net=net, c=c, lims=lims):
            def nearest(d):
                out, b = net.project(d, np.zeros(len(d)))
                return np.where(out, 1.0, -1.0), b
            x = x / np.linalg.norm(x, axis=1, keepdims=True)
            return evaluate_ball(x, np.asarray(c.limb_axis), nearest,
                                 None if lims is None else (lambda e: lims)).correction
        for label, model in (("field", table), ("network", predict)):
            r = evaluate_model(model, c, q=q, oracle=oracle)
            rows[label].append(r)
            print(f"{name:<10} {label:<8} " + " ".join(f"{r[k_]:8.3f}" for k_, _, _ in keys)
                  + (f"   trained {cpu:.0f} s CPU" if label == "network" else ""), flush=True)
    print(f"\nmean over {len(stars)} held-out single ball joints ({n} orientations each)")
    for key, label, goal in keys:
        print(f"{label:<22} {goal:>8} " + " ".join(
            f"{np.mean([r[key] for r in rows[m]]):10.3f}" for m in rows))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--limbs", type=int, default=10)
    ap.add_argument("--n", type=int, default=6000, help="postures per limb")
    ap.add_argument("--methods", default="exact,uncoupled,geometric,network")
    ap.add_argument("--single", type=int, default=0, metavar="K",
                    help="instead: the network family on K held-out single ball joints "
                         "(concave stars with twist) beside the tabulated field")
    args = ap.parse_args()
    if args.single:
        single(args.single, args.n)
        return
    names = args.methods.split(",")
    rows: dict[str, list[dict]] = {m: [] for m in names}
    print(f"{'limb':<10} {'method':<10} {'end %':>7} {'p99 end °':>9} {'left>1°':>8} "
          f"{'moved °':>8} {'max viol °':>10}  joint dir err ° (mean)")
    tmp = Path(tempfile.mkdtemp(prefix="bench-limb-"))
    for i, (label, limb) in enumerate(held_out_limbs(args.limbs).items()):
        oracle = ConstraintOracle(limb)
        q = held_out_postures(limb, args.n, 1000 + i, oracle=oracle)
        for m in names:
            r = evaluate_model(method(m, limb, oracle, tmp, q), limb, q=q, oracle=oracle)
            rows[m].append(r)
            print(f"{label:<10} {m:<10} {r['end_mean_3d_error_pct']:7.3f} "
                  f"{r['end_p99_direction_error_deg']:9.2f} "
                  f"{r['frac_invalid_violating_1deg']:8.3f} "
                  f"{r['valid_moved_deg']:8.3f} {r['max_violation_deg']:10.2f}  "
                  f"{', '.join(f'{x:.2f}' for x in r['joint_mean_direction_error_deg'])}")
    print(f"\nmean over {args.limbs} held-out limbs ({args.n} postures each)")
    print(f"{'target':<36} {'goal':>8} " + " ".join(f"{m:>10}" for m in names))
    for key, label, goal in TARGETS:
        vals = " ".join(f"{np.mean([r[key] for r in rows[m]]):10.3f}" for m in names)
        print(f"{label:<36} {goal:>8} {vals}")
    for name, runs in SPEED.items():
        if not runs:
            continue
        med = {k: statistics.median(x[k] for x in runs) for k in runs[0]}
        worst = max(x["train_wall_s"] for x in runs)
        train = (f"training {med['train_wall_s']:.0f} s median ({worst:.0f} s worst; "
                 f"{med['train_cpu_s']:.0f} s CPU on {med['threads']:.0f} thread(s)) "
                 f"(target <= 300)" if name == "network" else "no training")
        print(f"\n{name} limb model, median over {len(runs)} limbs: file "
              f"{med['bytes'] / 1e3:.0f} kB (target <= 2 MB), {med['nodes']:.0f} graph nodes; "
              f"onnxruntime single call {med['single_us']:.0f} µs (target <= 50); batched "
              f"{med['per_s']:,.0f} limbs/s on {os.cpu_count()} cores (target >= 500,000), "
              f"{med['per_s_one_thread']:,.0f} in one call on one thread; {train}")


if __name__ == "__main__":
    main()
