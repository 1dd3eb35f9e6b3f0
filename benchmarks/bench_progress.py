"""``rig progress`` on a large clinic: 5,000 patients x 20 sessions; its cost is per patient.

    python benchmarks/bench_progress.py [--patients 100,1000,5000] [--sessions 20] [--repeats 5]

The store is built fast and synthetic: each session holds a stored range-of-motion result
(``meta["rom_cache"]``, what ``rig progress`` keeps after computing a session's range of
motion once from its samples) and no samples — the figures measure reading a patient's
visits, the changes and the MDC verdicts, not the one-off computation from samples (which
``rig rom`` costs per session, once). Sessions are bulk-inserted into the store's own
``sessions`` table in one transaction per batch (the store's API commits, and fsyncs, once per
session: 100,000 fsyncs would measure the disk). The store grows to each size in turn and
``rig progress`` is timed for one patient at each: in process (median of ``--repeats`` calls,
peak Python memory by tracemalloc) and as the CLI in a child process (wall time, peak RSS).

Never asserts on time; figures depend on the disk and on what else runs on the machine.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
import tracemalloc
from pathlib import Path

import common  # first: one BLAS thread, this checkout on sys.path
import numpy as np

from rig import __version__
from rig.readback.progress import ROM_CACHE_VERSION, ProgressRequest, run_progress
from rig.store import open_store
from rig.store import schema as S
from rig.store.rows import dumps

JOINTS = ("elbow", "knee")
DAY = 86_400.0


def _cache(rng: np.random.Generator, joint: str, base: float, k: int, cut: bool) -> dict:
    moves = {"elbow": ("flexion", "extension"), "knee": ("flexion", "extension")}[joint]
    values = {m: round(float(base + 2.0 * k + rng.normal(0, 2)), 2) for m in moves}
    facts = {"status": "interrupted" if cut else "completed", "interrupted": cut,
             "coverage": None, "explored_sectors": 0, "sectors": 0,
             "coverage_sufficient": None, "simulated": True, "unmeasured_drift": False}
    return {"version": ROM_CACHE_VERSION, "rig": __version__, "method": "servo",
            "joints": {joint: {"values": values, "facts": facts}}}


def grow(db: Path, start: int, stop: int, sessions: int, rng: np.random.Generator) -> None:
    """Patients ``start``..``stop``-1 (pseudonyms P-000000...), each with ``sessions``
    ended sessions alternating two joints, one in ten interrupted."""
    t0 = 1_750_000_000.0
    with open_store(db) as store, store.transaction() as conn:
        for i in range(start, stop):
            pid = conn.execute(S.patients.insert().values(
                pseudonym=f"P-{i:06d}", created_at=t0)).inserted_primary_key[0]
            rows = []
            for k in range(sessions):
                joint = JOINTS[k % 2]
                cut = k % 10 == 7
                t = t0 + (k // 2) * 14 * DAY + (k % 2) * 600
                rows.append({"patient_id": pid, "rig_name": "sim-servo", "joint": joint,
                             "side": "right", "kind": "record",
                             "status": "interrupted" if cut else "completed",
                             "started_at": t, "ended_at": t + 300, "dropped": 0,
                             "meta": dumps({"rom_cache": _cache(rng, joint, 100.0, k // 2,
                                                                cut)})})
            conn.execute(S.sessions.insert(), rows)


def measure(db: Path, patient: str, repeats: int) -> dict:
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        res = run_progress(ProgressRequest(str(db), patient))
        times.append(time.perf_counter() - t)
    tracemalloc.start()
    run_progress(ProgressRequest(str(db), patient))
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    env = {**os.environ, "PYTHONPATH": str(common.ROOT)}
    t = time.perf_counter()
    out = subprocess.run([sys.executable, "-c",
                          "import resource, sys\nfrom rig.cli import main\n"
                          "try:\n    main(sys.argv[1:])\nexcept SystemExit:\n    pass\n"
                          "print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss, "
                          "file=sys.stderr)",
                          "progress", "--db", str(db), "--patient", patient, "--json"],
                         capture_output=True, text=True, env=env, check=True)
    cli_s = time.perf_counter() - t
    json.loads(out.stdout)
    return {"median_ms": 1000 * statistics.median(times), "peak_kib": peak / 1024,
            "cli_s": cli_s, "cli_rss_mib": int(out.stderr.strip().splitlines()[-1]) / 1024,
            "visits": len(res.visits), "cached": res.cached, "computed": res.computed,
            "db_mib": db.stat().st_size / 2**20}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--patients", default="100,1000,5000")
    ap.add_argument("--sessions", type=int, default=20)
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    print(f"machine: a Python loop of 10^7 additions {common.additions_s():.2f} s "
          f"({time.strftime('%Y-%m-%d %H:%M')})")
    sizes = [int(s) for s in args.patients.split(",")]
    rng = np.random.default_rng(42)
    with tempfile.TemporaryDirectory() as tmp:
        db = Path(tmp) / "clinic.db"
        done = 0
        print(f"rig progress, one patient of N x {args.sessions} sessions (rig {__version__})")
        print(f"{'patients':>9} {'sessions':>9} {'build s':>8} {'db MiB':>7} {'median ms':>10} "
              f"{'peak KiB':>9} {'CLI s':>6} {'CLI RSS MiB':>12}")
        for n in sizes:
            t = time.perf_counter()
            grow(db, done, n, args.sessions, rng)
            build = time.perf_counter() - t
            done = n
            r = measure(db, f"P-{n // 2:06d}", args.repeats)
            print(f"{n:>9} {n * args.sessions:>9} {build:>8.1f} {r['db_mib']:>7.1f} "
                  f"{r['median_ms']:>10.1f} {r['peak_kib']:>9.0f} {r['cli_s']:>6.2f} "
                  f"{r['cli_rss_mib']:>12.1f}")
        print(f"({r['visits']} visits per patient, {r['cached']} read from the cache, "
              f"{r['computed']} computed; this process's peak RSS "
              f"{resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MiB)")


if __name__ == "__main__":
    main()
