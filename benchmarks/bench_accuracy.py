"""Accuracy and inference cost of the presets, activations, and what the targets take.

    python benchmarks/bench_accuracy.py [--only presets,activations,capacity] [--seeds 1]
        [--quick]

Every model is trained by :func:`models.nn.train.train_correction`, exported to ONNX and
*evaluated through onnxruntime* (the deployed artefact) on 3000 fresh held-out orientations of
the training distribution (even) and on 3000 uniformly distributed limb directions. Latency is
the median single-orientation ``CorrectionModel.correct_one`` call. Prints Markdown tables.
Never asserts on time.

- ``presets``: ``best``, ``fixed``, ``thesis`` (one repeat) on a regular boundary (45° cone
  about +X) and an irregular one (the 'original' shape).
- ``activations``: hidden activation under the ``best`` training regime (fixed topology, 20
  nodes, 2000 epochs), same two constraints.
- ``capacity``: what lower errors cost — 40 and 80 hidden nodes, 2000 patterns, 3000 epochs.
- ``sweep``: ``best`` (or ``--preset``) over all regular boundaries of the thesis (radii 5, 20,
  45, 90, 135, 150° about +X, +Y, +Z) and the five irregular shapes; prints per-constraint
  rows and the means. ``--override '{"network": {"frame": "parent"}}'`` gives the parent-frame
  input encoding (the ``best`` default before the centre frame).
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_v] = "1"

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np
from bench_onnx import single_latencies_ns  # benchmarks/ is on the path when run as a script

from models import metrics as M
from models.constraint import JointConstraint
from models.nn.config import get_config
from models.nn.train import _oracle, train_correction, training_patterns
from models.onnx_io import export_onnx, load_model
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
    oracle = _oracle(c)
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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", default="presets,activations,capacity")
    ap.add_argument("--seeds", type=int, default=1)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--preset", default="best")
    ap.add_argument("--override", default="{}", help="JSON override for the sweep's preset")
    args = ap.parse_args()
    groups = args.only.split(",")
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
