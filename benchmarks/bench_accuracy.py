"""Accuracy of the models against issue 9's targets, beside the analytic peer; older sweeps.

    python benchmarks/bench_accuracy.py [--only targets] [--n 10000] [--random 20]
        [--methods field,peer[,best]]
    python benchmarks/bench_accuracy.py --only presets,activations,capacity|sweep [--quick]

``targets`` (the default): every held-out boundary of :mod:`models.evaluation` — the five thesis
shapes with twist limits and ``--random`` seeded concave star polygons with twist ranges
(irregular), cones of radius 5-150° about +X, +Y, +Z (regular) — gets a model per method, built
by :func:`models.nn.train.train_correction`, exported to ONNX and **evaluated through
onnxruntime**; the analytic peer (``bench_peer.VanDenBergenClamp``, numpy) is scored on the
*same* orientations (:func:`models.evaluation.held_out_orientations`, ``--n`` per boundary).
Prints one row per boundary and method, the mean per set, and the target table. Build times
are wall-clock on a shared machine (contended); accuracy figures are not affected.

The other groups are the earlier preset studies (trained GMLPs on a 45° cone and 'original',
thesis-style test patterns): ``presets``, ``activations``, ``capacity``, ``sweep``.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import common  # noqa: F401  (first: one BLAS thread, this checkout on sys.path)
import numpy as np
from common import single_latencies_ns
from peers import VanDenBergenClamp

from models import metrics as M
from models.constraint import JointConstraint
from models.nn.config import get_config
from models.nn.train import train_correction, training_patterns
from models.onnx_io import export_onnx, load_model
from models.oracle import ConstraintOracle
from models.shapes import load_shape


def constraints():
    return {"cone X 45°": JointConstraint.cone([1, 0, 0], 45, name="cone45"),
            "original": load_shape("original")}


def latency_us(model, n=5000) -> float:
    qs = np.random.default_rng(0).standard_normal((n, 4))
    return statistics.median(single_latencies_ns(model, qs, warmup=500)) / 1e3


def run(label, c, preset, override, seed, quick) -> dict:
    if quick:
        override = {**override, "evolution": {**override.get("evolution", {}),
                                              "population": 4, "generations": 1},
                    "training": {**override.get("training", {}), "max_epochs": 50,
                                 "min_epochs": 10},
                    "data": {"train": 200, "validation": 100, "test": 300}}
    cfg = get_config(preset, override)
    t0 = time.perf_counter()
    m = train_correction(c, cfg, np.random.default_rng(seed))
    train_s = time.perf_counter() - t0
    oracle = ConstraintOracle(c)
    with tempfile.TemporaryDirectory() as d:
        p = export_onnx(m.network, Path(d) / "m.onnx", constraint_yaml=c.to_yaml(),
                        training_data_sha256=m.data_sha256, metrics=m.metrics)
        model = load_model(p, expected_constraint=c)
        rng = np.random.default_rng(10_000 + seed)
        n = 300 if quick else 3000
        q_even, _ = training_patterns(c, n, rng, distribution="even", order="random",
                                      hemisphere="ambiguous", oracle=oracle)
        q_uni, _ = training_patterns(c, n, rng, distribution="uniform", order="random",
                                     hemisphere="ambiguous", oracle=oracle)
        from models.datasets import quaternion_dataset

        q_tw = quaternion_dataset(c, n, 20_000 + seed, twist=True, hemisphere="ambiguous",
                                  order="random").inputs
        even = M.evaluate(model.correction, oracle, q_even)
        uni = M.evaluate(model.correction, oracle, q_uni)
        tw = M.evaluate(model.correction, oracle, q_tw)
        us = latency_us(model, 1000 if quick else 5000)
    return {"label": label, "even": even, "uniform": uni, "twisted": tw, "us": us,
            "train_s": train_s,
            "hidden": m.network.n_hidden, "links": m.network.n_links}


def table(rows) -> None:
    print("| model | constraint | mean 3-D % (even) | max 3-D % | MSE | invalid > 1° out | "
          "mean identity err ° | mean 3-D % (uniform) | mean 3-D % (twisted) | hidden / links | "
          "train s | µs |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for cname, r in rows:
        e, u = r["even"], r["uniform"]
        print(f"| {r['label']} | {cname} | {e['mean_3d_error_pct']:.3f} | "
              f"{e['max_3d_error_pct']:.2f} | {e['mse']:.2e} | "
              f"{100 * e['frac_invalid_violating_1deg']:.1f} % | "
              f"{e['mean_identity_error_deg']:.3f} | {u['mean_3d_error_pct']:.3f} | "
              f"{r['twisted']['mean_3d_error_pct']:.3f} | "
              f"{r['hidden']} / {r['links']} | {r['train_s']:.1f} | {r['us']:.1f} |", flush=True)


def sweep(args) -> None:
    import json

    from models.shapes import SHAPES

    over = json.loads(args.override)
    cs = {f"cone {ax} {r}°": JointConstraint.cone(v, r, name=f"cone-{ax}-{r}")
          for ax, v in (("X", [1, 0, 0]), ("Y", [0, 1, 0]), ("Z", [0, 0, 1]))
          for r in (5, 20, 45, 90, 135, 150)}
    cs.update({s: load_shape(s) for s in SHAPES})
    rows = []
    for cname, c in cs.items():
        for seed in range(args.seeds):
            r = run(f"preset {args.preset}", c, args.preset, over, seed, args.quick)
            rows.append((cname, r))
            print(f"# {cname} / seed {seed}: 3-D {r['even']['mean_3d_error_pct']:.3f} %, "
                  f"{r['train_s']:.1f} s", flush=True)
    table(rows)
    for kind, sel in (("regular", lambda n: n.startswith("cone")),
                      ("irregular", lambda n: not n.startswith("cone"))):
        rs = [r for n, r in rows if sel(n)]
        if not rs:
            continue
        e = [r["even"] for r in rs]
        print(f"{kind}: mean 3-D {np.mean([m['mean_3d_error_pct'] for m in e]):.3f} %, "
              f"max {max(m['max_3d_error_pct'] for m in e):.2f} %, MSE "
              f"{np.mean([m['mse'] for m in e]):.2e}, invalid > 1° out "
              f"{100 * np.mean([m['frac_invalid_violating_1deg'] for m in e]):.2f} %, "
              f"uniform-direction 3-D "
              f"{np.mean([r['uniform']['mean_3d_error_pct'] for r in rs]):.3f} %")


def _build(method: str, c, seed: int):
    """(ONNX CorrectionModel or numpy predict, build seconds) of one method for ``c``."""
    if method == "peer":
        t0 = time.perf_counter()
        m = VanDenBergenClamp(c)
        return m.predict, time.perf_counter() - t0
    t0 = time.perf_counter()
    tm = train_correction(c, get_config(method), np.random.default_rng(seed))
    dt = time.perf_counter() - t0
    d = tempfile.mkdtemp()
    p = export_onnx(tm.network, Path(d) / "m.onnx", constraint_yaml=c.to_yaml(),
                    training_data_sha256=tm.data_sha256, metrics=tm.metrics)
    return load_model(p, expected_constraint=c), dt


TARGETS = {"irregular": {"mean_3d_error_pct": 0.8, "frac_invalid_violating_1deg": 0.01,
                         "mean_identity_error_deg": 0.2, "p99_angular_error_deg": 5.0},
           "regular": {"mean_3d_error_pct": 0.4, "frac_invalid_violating_1deg": 0.005}}


def targets(args) -> None:
    from models.evaluation import (
        TARGET_METRICS,
        evaluate_model,
        held_out_orientations,
        irregular_boundaries,
        regular_boundaries,
        summarise,
    )

    methods = args.methods.split(",")
    sets = {"irregular": irregular_boundaries(args.random), "regular": regular_boundaries()}
    sets = {k: v for k, v in sets.items() if k in args.sets.split(",")}
    hdr = " | ".join(lab for _, lab in TARGET_METRICS)
    print(f"| set | boundary | method | {hdr} | build s |")
    print("|---|---|---|" + "---|" * (len(TARGET_METRICS) + 1))
    res: dict[tuple[str, str], list] = {}
    times: dict[tuple[str, str], list] = {}
    for sname, cs in sets.items():
        for i, (name, c) in enumerate(cs.items()):
            oracle = ConstraintOracle(c)
            q = held_out_orientations(c, args.n, 50_000 + i, oracle=oracle)
            for meth in methods:
                model, dt = _build(meth, c, i)
                m = evaluate_model(model, c, q=q, oracle=oracle)
                res.setdefault((sname, meth), []).append(m)
                times.setdefault((sname, meth), []).append(dt)
                vals = []
                for k, _ in TARGET_METRICS:
                    vals.append(f"{100 * m[k]:.2f} %" if k.startswith("frac") else f"{m[k]:.3f}")
                print(f"| {sname} | {name} | {meth} | {' | '.join(vals)} | {dt:.2f} |",
                      flush=True)
    print("\n## Means over boundaries (same orientations for every method)\n")
    print(f"| set | method | {hdr} | median build s | target met |")
    print("|---|---|" + "---|" * (len(TARGET_METRICS) + 2))
    for (sname, meth), rows in res.items():
        s = summarise(rows)
        ok = all(s[k] <= v for k, v in TARGETS[sname].items())
        vals = [f"{100 * s[k]:.3f} %" if k.startswith("frac") else f"{s[k]:.3f}"
                for k, _ in TARGET_METRICS]
        print(f"| {sname} | {meth} | {' | '.join(vals)} | "
              f"{statistics.median(times[(sname, meth)]):.2f} | {'yes' if ok else 'no'} |")
    for sname in sets:
        if (sname, "peer") in res:
            peer = summarise(res[(sname, "peer")])["mean_3d_error_pct"]
            for meth in methods:
                if meth != "peer":
                    ours = summarise(res[(sname, meth)])["mean_3d_error_pct"]
                    ratio = peer / ours if ours > 0 else float("inf")
                    print(f"{sname}: peer / {meth} mean 3-D error = {peer:.3f} / {ours:.3f} = "
                          f"{ratio:.1f}×")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", default="targets")
    ap.add_argument("--n", type=int, default=10_000, help="targets: orientations per boundary")
    ap.add_argument("--random", type=int, default=20, help="targets: random star polygons")
    ap.add_argument("--methods", default="field,peer",
                    help="targets: presets of rig train and/or 'peer', comma-separated")
    ap.add_argument("--sets", default="irregular,regular", help="targets: boundary sets")
    ap.add_argument("--seeds", type=int, default=1)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--preset", default="best")
    ap.add_argument("--override", default="{}", help="JSON override for the sweep's preset")
    args = ap.parse_args()
    groups = args.only.split(",")
    if "targets" in groups:
        targets(args)
        return
    if "sweep" in groups:
        sweep(args)
        return
    cs = constraints()
    plans = []
    if "presets" in groups:
        for preset in ("best", "fixed", "thesis"):
            over = {"evolution": {"repeats": 1}} if preset == "thesis" else {}
            plans.append((f"preset {preset}", preset, over))
    if "activations" in groups:
        for a in ("relu", "tanh", "sigmoid", "hardtanh"):
            plans.append((f"best regime, {a}", "best", {"network": {"hidden_activations": [a]}}))
        plans.append(("best regime, leaky_relu+tanh mix", "best",
                      {"network": {"hidden_activations": ["leaky_relu", "tanh"]},
                       "evolution": {"evolve_activations": True}}))
    if "capacity" in groups:
        for h in (40, 80):
            plans.append((f"leaky_relu, {h} hidden, 2000 patterns, 3000 epochs", "best",
                          {"network": {"max_hidden": h},
                           "training": {"max_epochs": 3000, "min_epochs": 3000},
                           "data": {"train": 2000}}))
    rows = []
    for label, preset, over in plans:
        for cname, c in cs.items():
            for seed in range(args.seeds):
                r = run(label, c, preset, over, seed, args.quick)
                rows.append((cname, r))
                e3 = r["even"]["mean_3d_error_pct"]
                print(f"# {label} / {cname} / seed {seed}: 3-D {e3:.3f} %, "
                      f"{r['train_s']:.1f} s", flush=True)
    table(rows)


if __name__ == "__main__":
    main()
