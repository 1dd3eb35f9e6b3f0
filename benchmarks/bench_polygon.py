"""Cost of large spherical polygons in the CLI: ``rig constraint check`` and ``rig train``.

For each vertex count it writes a seeded random simple spherical polygon (a star-shaped radial
function around a random centre: three lobes of ±15° on 50°, a random smooth wobble and a small
per-vertex jitter — concave, and simple by construction, since straight lines in the gnomonic
chart about the centre are great circles and the vertices go round it in azimuth order) as a
constraint YAML file with a constant twist range, then runs

    .venv/bin/rig constraint check FILE
    .venv/bin/rig train --constraint FILE --out M.onnx          (default preset: field)

as child processes, each ``--repeats`` times, and prints the median wall time and the median peak
resident set size of the child (``os.wait4``'s rusage: that child alone, not a running maximum
over all children). Prints figures; asserts nothing.

Run::

    .venv/bin/python benchmarks/bench_polygon.py                       # 1k, 10k, 30k vertices
    .venv/bin/python benchmarks/bench_polygon.py --sizes 1000,10000 --repeats 1
    .venv/bin/python benchmarks/bench_polygon.py --mem-limit-gb 8      # a run needing more fails
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import common  # noqa: F401  (first: one BLAS thread, this checkout on sys.path)
import numpy as np
import yaml
from common import ROOT


def star_vertices(m: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (m, 3) of a concave star-shaped polygon around a random centre, and the centre.

    Radius ``50 + 15 sin 3θ`` degrees plus a seeded random smooth wobble (Fourier modes 4-24,
    amplitude ~3/k degrees) plus a per-vertex jitter of ±0.3 of the vertex spacing; azimuths
    evenly spaced with a jitter of less than half a step (so their order is kept).
    """
    centre = rng.normal(size=3)
    centre /= np.linalg.norm(centre)
    step = 2.0 * np.pi / m
    th = np.arange(m) * step + rng.uniform(-0.4, 0.4, size=m) * step
    k = np.arange(4, 25)
    amp = rng.normal(scale=3.0, size=(2, len(k))) / k
    wobble = np.cos(np.outer(th, k)) @ amp[0] + np.sin(np.outer(th, k)) @ amp[1]
    jitter = rng.uniform(-0.3, 0.3, size=m) * np.degrees(step) * np.sin(np.radians(50.0))
    r = np.radians(50.0 + 15.0 * np.sin(3.0 * th) + wobble + jitter)
    t = np.tan(r)
    local = np.stack([np.ones(m), t * np.cos(th), t * np.sin(th)], axis=1)
    local /= np.linalg.norm(local, axis=1, keepdims=True)
    # an orthonormal frame (centre, u, w): the chart's x axis is the centre
    u = np.cross(centre, [1.0, 0.0, 0.0] if abs(centre[0]) < 0.9 else [0.0, 1.0, 0.0])
    u /= np.linalg.norm(u)
    w = np.cross(centre, u)
    frame = np.stack([centre, u, w])  # rows: where local x, y, z go
    return local @ frame, centre


def write_constraint(path: Path, m: int, seed: int) -> None:
    """A constraint file with an ``m``-vertex polygon swing and a constant twist range."""
    verts, centre = star_vertices(m, np.random.default_rng(seed))
    doc = {
        "name": f"bench-star-{m}",
        "limb_axis": [1.0, 0.0, 0.0],
        "swing": {"polygon": {"vertices": verts.round(12).tolist(),
                              "interior": centre.round(12).tolist()}},
        "twist": {"min_deg": -60.0, "max_deg": 60.0},
        "provenance": {"generator": "benchmarks/bench_polygon.py", "seed": seed},
    }
    path.write_text(yaml.safe_dump(doc, sort_keys=False, default_flow_style=None),
                    encoding="utf-8")


def run_child(cmd: list[str], log: Path, timeout: float,
              mem_limit: int | None = None) -> tuple[float, float, int]:
    """Wall time (s), peak RSS (MB) and exit status of one child process.

    ``mem_limit`` (bytes) caps the child's address space (RLIMIT_AS): a run that would need
    more fails with a MemoryError instead of pushing the machine into swap or the OOM killer.
    """

    def limit() -> None:
        if mem_limit is not None:
            resource.setrlimit(resource.RLIMIT_AS, (mem_limit, mem_limit))

    with log.open("wb") as out:
        t0 = time.perf_counter()
        proc = subprocess.Popen(cmd, stdout=out, stderr=subprocess.STDOUT, cwd=ROOT,
                                preexec_fn=limit)
        deadline = t0 + timeout
        while True:
            pid, status, usage = os.wait4(proc.pid, os.WNOHANG)
            if pid:
                break
            if time.perf_counter() > deadline:
                proc.kill()
                pid, status, usage = os.wait4(proc.pid, 0)
                break
            time.sleep(0.02)
        wall = time.perf_counter() - t0
    proc.returncode = os.waitstatus_to_exitcode(status)  # already reaped: tell Popen
    return wall, usage.ru_maxrss / 1024.0, proc.returncode  # ru_maxrss is in KiB on Linux


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="1000,10000,30000",
                    help="comma-separated vertex counts (default 1000,10000,30000)")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--timeout", type=float, default=1800.0, help="per child, seconds")
    ap.add_argument("--mem-limit-gb", type=float, default=None,
                    help="cap each child's address space (GB); a run needing more fails")
    ap.add_argument("--workdir", default=None,
                    help="where to write the YAML files, models and logs (default: a temp dir)")
    args = ap.parse_args()
    sizes = [int(s) for s in args.sizes.split(",") if s.strip()]
    mem_limit = None if args.mem_limit_gb is None else int(args.mem_limit_gb * 2**30)

    rig = Path(sys.executable).with_name("rig")
    if not rig.exists():
        sys.exit(f"{rig} not found: install the project into this interpreter's environment")
    tmp = None
    if args.workdir:
        work = Path(args.workdir)
        work.mkdir(parents=True, exist_ok=True)
    else:
        tmp = tempfile.TemporaryDirectory(prefix="bench-polygon-")
        work = Path(tmp.name)

    cap = f", address space capped at {args.mem_limit_gb:g} GB" if mem_limit else ""
    print(f"polygon cost in the CLI: median of {args.repeats} run(s), one thread, "
          f"seed {args.seed}{cap}")
    print(f"{'vertices':>9}  {'command':<17} {'wall s':>8} {'peak RSS MB':>12}  status")
    for m in sizes:
        path = work / f"star-{m}.yaml"
        write_constraint(path, m, args.seed + m)
        commands = {
            "constraint check": [str(rig), "constraint", "check", str(path)],
            "train (field)": [str(rig), "train", "--constraint", str(path),
                              "--out", str(work / f"star-{m}.onnx")],
        }
        for name, cmd in commands.items():
            walls, peaks, codes = [], [], []
            for r in range(args.repeats):
                log = work / f"star-{m}-{name.split()[0]}-{r}.log"
                wall, peak, code = run_child(cmd, log, args.timeout, mem_limit)
                walls.append(wall)
                peaks.append(peak)
                codes.append(code)
                if code != 0:  # a failure repeats: no need to wait for it again
                    lines = log.read_text(errors="replace").strip().splitlines()
                    why = lines[-1][:100] if lines else "no output"
                    break
            status = "ok" if all(c == 0 for c in codes) else f"FAILED (exit {codes[-1]}: {why})"
            print(f"{m:>9}  {name:<17} {statistics.median(walls):>8.2f} "
                  f"{statistics.median(peaks):>12.0f}  {status}", flush=True)
    if tmp is not None:
        tmp.cleanup()


if __name__ == "__main__":
    main()
