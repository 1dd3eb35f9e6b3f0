"""Wall time of one full thesis-protocol evolution (TABLE II) on one core.

Population 50 × 20 generations (+ the initial one), ≤ 500 RPROP epochs, stop at MSE 0.001,
500 training + 250 validation patterns, max 20 hidden nodes; the whole population trains at
once (stacked tensors). The thesis needed 16-18 h per experiment (Java, Pentium 4).

    python benchmarks/bench_evolution.py [--runs 3] [--quick]

Prints the median of ``--runs`` seeds for a regular boundary (45° cone about +X) and for the
irregular 'original' shape, and the float32 / float64 comparison: wall time and the process's
CPU time (the honest one-core figure on a shared machine). Never asserts on time.
"""

from __future__ import annotations

import argparse
import statistics
import time

import common  # noqa: F401  (first: one BLAS thread, this checkout on sys.path)
import numpy as np

from models.constraint import JointConstraint
from models.nn.config import get_config
from models.nn.evolution import evolve
from models.nn.train import canonical_reference, canonicalise, split, training_patterns


def one_run(constraint, seed: int, dtype: str, quick: bool) -> tuple[float, dict]:
    over = {"evolution": {"repeats": 1}, "training": {"dtype": dtype}}
    if quick:
        over["evolution"].update({"population": 10, "generations": 2})
    cfg = get_config("thesis", over)
    rng = np.random.default_rng(seed)
    dc = cfg["data"]
    q, t = training_patterns(constraint, dc["train"] + dc["validation"], rng,
                             hemisphere=dc["hemisphere"])
    x = canonicalise(q, canonical_reference(constraint, cfg["network"]["canonicalise"]))
    xtr, ttr, xva, tva = split(x, t, (dc["train"], dc["validation"]), rng)
    t0, c0 = time.perf_counter(), time.process_time()
    res = evolve(cfg, xtr, ttr, xva, tva, rng)
    return time.perf_counter() - t0, {"val_mse": res.val_mse, "hidden": res.network.n_hidden,
                                      "cpu": time.process_time() - c0}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--quick", action="store_true", help="tiny population, smoke test")
    args = ap.parse_args()
    from models.shapes import load_shape

    cases = [("regular 45° cone (+X)", JointConstraint.cone([1, 0, 0], 45)),
             ("irregular 'original'", load_shape("original"))]
    print(f"thesis protocol (population 50 × 20 generations, ≤ 500 epochs, 500 patterns), "
          f"one core, {args.runs} runs each")
    for name, c in cases:
        for dtype in ("float32", "float64"):
            runs = args.runs if dtype == "float32" else 1
            times, infos = zip(*(one_run(c, s, dtype, args.quick) for s in range(runs)),
                               strict=True)
            cpu = [i["cpu"] for i in infos]
            print(f"  {name:<24} {dtype}: wall median {statistics.median(times):6.2f} s "
                  f"(runs {', '.join(f'{t:.2f}' for t in times)}), CPU median "
                  f"{statistics.median(cpu):6.2f} s (runs {', '.join(f'{t:.2f}' for t in cpu)}); "
                  "best val MSE "
                  f"{statistics.median(i['val_mse'] for i in infos):.2e}, hidden "
                  f"{statistics.median(i['hidden'] for i in infos):.0f}")


if __name__ == "__main__":
    main()
