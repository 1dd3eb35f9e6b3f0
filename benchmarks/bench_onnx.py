"""Inference speed of exported correction models through onnxruntime, in-process.

    python benchmarks/bench_onnx.py [--model MODEL.onnx] [--calls 20000]

Without ``--model`` it builds the ``field`` model (:mod:`models.field`, the default of
``rig train``) of the 'original' shape with and without a twist range, then exports two
networks of ``--hidden`` nodes (default 20; leaky ReLU as in the ``best`` preset, sigmoid as
in the thesis preset) with random weights — latency does not depend on the weights. Prints the
median single-orientation latency
(``CorrectionModel.correct_one`` and a (1, 4) ``correction`` call) and batched throughput.
Never asserts on time.
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

from models import quaternion as quat
from models.nn import activations as act
from models.nn.gmlp import GMLP, PopulationSpec, init_params
from models.onnx_io import export_onnx, load_model


def _network(kind: str, rng, h: int = 20) -> GMLP:
    spec = PopulationSpec(np.ones((1, 5, h), bool), np.ones((1, h + 5, 4), bool),
                          np.full((1, h), act.index_of(kind)), np.zeros((1, 4), int))
    if kind == "leaky_relu":  # as the best preset: in-graph swing map
        return GMLP.from_population(init_params(spec, rng), spec, 0, input_map="swing")
    return GMLP.from_population(init_params(spec, rng), spec, 0,
                                canonical_ref=np.array([1.0, 0.0, 0.0, 0.0]))


def bench(path: Path, calls: int) -> None:
    m = load_model(path)
    rng = np.random.default_rng(0)
    qs = quat.random_quaternions(calls, rng)
    lat = single_latencies_ns(m, qs)
    q1 = qs[:1].astype(np.float32)
    lat2 = []
    for _ in range(calls):
        t0 = time.perf_counter_ns()
        m.correction(q1)
        lat2.append(time.perf_counter_ns() - t0)
    print(f"  single orientation: correct_one median {statistics.median(lat) / 1e3:.2f} µs "
          f"(p99 {np.percentile(lat, 99) / 1e3:.2f} µs); correction((1, 4)) median "
          f"{statistics.median(lat2) / 1e3:.2f} µs")
    big = quat.random_quaternions(1_000_000, rng).astype(np.float32)
    for n in (1_000, 10_000, 100_000, 1_000_000):
        x = big[:n]
        m.correction(x)
        reps = max(3, 2_000_000 // n)
        t0 = time.perf_counter()
        for _ in range(reps):
            m.correction(x)
        dt = (time.perf_counter() - t0) / reps
        print(f"  batch {n:>9,}: {n / dt / 1e6:6.2f} M orientations/s")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--model", type=Path)
    ap.add_argument("--calls", type=int, default=20_000)
    ap.add_argument("--hidden", type=int, default=20, help="hidden nodes of the random networks")
    args = ap.parse_args()
    if args.model:
        print(args.model)
        bench(args.model, args.calls)
        return
    rng = np.random.default_rng(1)
    with tempfile.TemporaryDirectory() as d:
        from models.constraint import JointConstraint
        from models.field import FieldModel
        from models.shapes import load_shape

        s = load_shape("original").swing
        for tw in ((-45.0, 70.0), None):
            c = JointConstraint.polygon(s.vertices, s.interior, twist=tw, name="original")
            t0 = time.perf_counter()
            f = FieldModel.from_constraint(c)
            build = time.perf_counter() - t0
            p = export_onnx(f, Path(d) / "field.onnx", constraint_yaml=c.to_yaml())
            print(f"preset field (swing table, grid {f.grid}), 'original'"
                  f"{f' + twist {tw}' if tw else ', no twist'}: built in {build:.2f} s")
            bench(p, args.calls)
        for kind in ("leaky_relu", "sigmoid"):
            p = export_onnx(_network(kind, rng, args.hidden), Path(d) / f"{kind}.onnx",
                            constraint_yaml="name: bench\n")
            pre = "swing map" if kind == "leaky_relu" else "hemisphere canonicalisation"
            print(f"{args.hidden} hidden {kind} + linear output, {pre} + normalisation in-graph")
            bench(p, args.calls)


if __name__ == "__main__":
    main()
