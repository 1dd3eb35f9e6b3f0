"""Speed of the exact oracle (issue: foundation). Prints figures; asserts nothing.

Targets: exact projection on a 500-vertex concave polygon >= 200 k orientations/s batched on one
core, and a single-orientation call <= 50 µs median.

Run: python benchmarks/bench_oracle.py [--repeats 7] [--n 200000]
"""

from __future__ import annotations

import argparse
import statistics
import time

import common  # noqa: F401  (first: one BLAS thread, this checkout on sys.path)
import numpy as np

from models import quaternion as Q
from models.constraint import JointConstraint
from models.oracle import ConstraintOracle


def concave_polygon(m: int = 500) -> JointConstraint:
    """A three-lobed shoulder-like boundary around +X (radius 50° ± 15°), concave between lobes."""
    th = np.linspace(0.0, 2 * np.pi, m, endpoint=False)
    r = np.radians(50 + 15 * np.sin(3 * th))
    verts = np.stack([np.cos(r), np.sin(r) * np.cos(th), np.sin(r) * np.sin(th)], axis=1)
    return JointConstraint.polygon(verts, [1, 0, 0], twist=(-60, 60), name=f"concave-{m}")


def with_twist_table(c: JointConstraint, k: int = 36) -> JointConstraint:
    """The same swing with swing-dependent twist limits: a ``by_swing`` table of ``k`` points
    (Fibonacci directions, limits varying smoothly, bandwidth 20°)."""
    i = np.arange(k) + 0.5
    z = 1.0 - 2.0 * i / k
    az = np.pi * (1.0 + np.sqrt(5.0)) * i
    d = np.stack([z, np.sqrt(1 - z * z) * np.cos(az), np.sqrt(1 - z * z) * np.sin(az)], axis=1)
    lo = -60 + 20 * (1 + d[:, 1]) / 2
    hi = 60 - 30 * (1 + d[:, 2]) / 2
    points = [{"direction": v.tolist(), "min_deg": float(a), "max_deg": float(b)}
              for v, a, b in zip(d, lo, hi, strict=True)]
    data = c.to_dict()
    data["twist"] = {"min_deg": -60, "max_deg": 60,
                     "by_swing": {"bandwidth_deg": 20, "points": points}}
    data["name"] += f"-table{k}"
    return JointConstraint.from_dict(data)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--n", type=int, default=200_000)
    ap.add_argument("--single", type=int, default=5000, help="single calls per repeat")
    args = ap.parse_args()

    rng = np.random.default_rng(0)
    t = time.perf_counter()
    c = concave_polygon()
    t_validate = time.perf_counter() - t
    t = time.perf_counter()
    oracle = ConstraintOracle(c)
    t_build = time.perf_counter() - t
    cone = ConstraintOracle(JointConstraint.cone([1, 0, 0], 50, twist=(-60, 60)))
    cases = [("polygon-500", oracle), ("cone", cone)]
    if hasattr(c.twist, "by_swing"):  # swing-dependent twist limits (twist.by_swing)
        cases.append(("polygon+tab36", ConstraintOracle(with_twist_table(c))))
        cases.append(("cone+tab36", ConstraintOracle(with_twist_table(cone.constraint))))
    print(f"polygon: {len(c.swing.vertices)} vertices, concave, twist -60..60 deg")
    print(f"  load+validate {t_validate * 1e3:.0f} ms, oracle set-up {t_build * 1e3:.0f} ms "
          f"(grid {oracle._swing.G}, {oracle._swing.mean_candidates:.1f} candidate edges/cell)")

    q = Q.random_quaternions(args.n, rng)  # uniform over SO(3), both hemispheres
    oracle.project(q[:1000])  # warm-up
    for name, o in cases:
        rates = []
        for _ in range(args.repeats):
            t = time.perf_counter()
            o.project(q)
            rates.append(args.n / (time.perf_counter() - t))
        print(f"batched project, {name:13s}: median {statistics.median(rates) / 1e3:7.0f} k/s "
              f"(min {min(rates) / 1e3:.0f}, max {max(rates) / 1e3:.0f}; {args.repeats} runs "
              f"of {args.n})")

    singles = q[: args.single]
    tuples = [tuple(float(v) for v in qi) for qi in singles]
    for label, calls in (
        ("single project", lambda o: [(o.project, (qi,)) for qi in singles]),
        # the supervisor's query (plain floats in and out, no result arrays)
        ("loop query    ", lambda o: [(o.distance_projected_one, t) for t in tuples]),
    ):
        for name, o in cases:
            work = calls(o)
            meds = []
            for _ in range(args.repeats):
                ts = np.empty(len(work))
                for i, (fn, a) in enumerate(work):
                    t = time.perf_counter()
                    fn(*a)
                    ts[i] = time.perf_counter() - t
                meds.append(float(np.median(ts)))
            print(f"{label}, {name:13s}: median {statistics.median(meds) * 1e6:6.1f} µs "
                  f"(per-run medians {min(meds) * 1e6:.1f}..{max(meds) * 1e6:.1f} µs; "
                  f"{args.repeats} runs of {len(work)})")


if __name__ == "__main__":
    main()
