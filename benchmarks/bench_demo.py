"""How long ``rig demo`` takes, stage by stage (issue 11's target: ≤ 3 minutes on 2 cores).

Runs the demo pipeline (:func:`rig.demo.run_demo`, exactly what ``rig demo`` runs) ``--runs``
times in temporary folders and prints the median time of every stage and of the whole, with
the verdicts of each run. The machine may be shared: the script says how many CPUs it sees and
its load average; treat contended figures as upper bounds.

Usage::

    .venv/bin/python benchmarks/bench_demo.py [--runs 3] [--quick] [--seed 0]
"""

from __future__ import annotations

import argparse
import io
import os
import statistics
import tempfile
from pathlib import Path

import common  # noqa: F401  (first: one BLAS thread, this checkout on sys.path)


def main(argv=None) -> None:
    from rich.console import Console

    from rig.demo import DemoOptions, run_demo

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--quick", action="store_true", help="the test suite's size")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    times: dict[str, list[float]] = {}
    totals = []
    for k in range(args.runs):
        with tempfile.TemporaryDirectory() as tmp:
            console = Console(file=io.StringIO(), width=200)
            res = run_demo(DemoOptions(out=Path(tmp) / "demo", seed=args.seed + k,
                                       quick=args.quick), console=console)
        totals.append(res.total_s)
        for s in res.stages:
            times.setdefault(s.name, []).append(s.seconds)
        print(f"run {k + 1}: {res.total_s:.1f} s; "
              + ", ".join(f"{s.name} {s.verdict}" for s in res.stages), flush=True)
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"\nrig demo{' --quick' if args.quick else ''}: medians over {args.runs} runs, "
          f"{os.cpu_count()} CPUs, load average {load:.1f} (shared machine: contended figures)")
    for name, ts in times.items():
        print(f"  {name:<18} {statistics.median(ts):6.1f} s")
    print(f"  {'total':<18} {statistics.median(totals):6.1f} s   (target ≤ 180 s)")


if __name__ == "__main__":
    main()
