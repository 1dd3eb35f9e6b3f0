"""Session-store throughput: sustained sample inserts and commit latency.

    python benchmarks/bench_store.py [--db URL_OR_PATH] [--rows 400000] [--repeats 5]

Without ``--db`` it uses a fresh SQLite file in a temporary directory (WAL, synchronous=FULL,
exactly as ``rig record`` opens it); give ``--db postgresql://...`` to measure a server.

Prints medians over ``--repeats`` runs of:

* bulk rate -- ``SampleWriter.add_many`` in blocks of 800 rows, committed every 0.5 s by the
  writer's thread (rows/s from first add to close);
* per-sample rate -- ``SampleWriter.add`` one row at a time (what a reader thread does);
* read back -- ``store.samples.read`` of the bulk session (rows/s);
* commit latency -- one transaction of 400 rows (0.5 s of 2 sensors x 400 Hz) via ``flush``;
* cost of real time -- CPU seconds the store spends per second of a 2 x 400 Hz recording.

Never asserts on time. Figures depend on the disk (each SQLite commit is an fsync) and on
what else runs on the machine.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import common  # noqa: F401  (first: one BLAS thread, this checkout on sys.path)
import numpy as np

from rig.store import SampleWriter, open_store


def _unit(rng: np.random.Generator, n: int) -> np.ndarray:
    q = rng.normal(size=(n, 4))
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def bench(db: str, rows: int, repeats: int) -> None:
    rng = np.random.default_rng(0)
    store = open_store(db)
    pid = store.patients.ensure("BENCH")
    bulk, single, commit_ms, cpu_per_s, read = [], [], [], [], []
    block = 800
    q = _unit(rng, block)
    for r in range(repeats):
        sid = store.sessions.start(pid, rig_name="bench", meta={"repeat": r})
        # bulk
        w = SampleWriter(store, sid)
        t0 = time.perf_counter()
        for k in range(0, rows, block):
            t = (k + np.arange(block)) / 800.0
            w.add_many(t, t, "humerus" if k % 1600 else "thorax", "sensor", q, 3)
        w.close()
        bulk.append(rows / (time.perf_counter() - t0))
        t0 = time.perf_counter()
        got = store.samples.read(sid)["t"].size
        read.append(got / (time.perf_counter() - t0))
        # one row at a time
        n1 = min(rows, 100_000)
        w = SampleWriter(store, sid)
        qs = q.tolist()
        t0 = time.perf_counter()
        for k in range(n1):
            w.add(float(k), None, "humerus", "sensor", qs[k % block], 3)
        w.close()
        single.append(n1 / (time.perf_counter() - t0))
        # commit latency of 0.5 s of a 2 x 400 Hz recording
        w = SampleWriter(store, sid, flush_interval_s=1.0)
        lat = []
        for k in range(20):
            t = (k * 200 + np.arange(200)) / 400.0
            w.add_many(t, None, "thorax", "sensor", q[:200], 3)
            w.add_many(t, None, "humerus", "sensor", q[200:400], 3)
            t1 = time.perf_counter()
            w.flush()
            lat.append((time.perf_counter() - t1) * 1e3)
        w.close()
        commit_ms.append(statistics.median(lat))
        # CPU cost of real time: 10 simulated seconds, rows handed over as a reader would
        w = SampleWriter(store, sid)
        c0 = time.process_time()
        for s in range(10 * 400):
            t = s / 400.0
            w.add(t, t, "thorax", "sensor", qs[s % block], 3)
            w.add(t, t, "humerus", "sensor", qs[(s + 1) % block], 3)
        w.close()
        cpu_per_s.append((time.process_time() - c0) / 10.0)
    total = sum(r["samples"] for r in store.sessions.list())
    store.close()
    print(f"store: {store.url} ({store.dialect}); {repeats} repeats, {total} rows written")
    print(f"  bulk add_many          {statistics.median(bulk):12,.0f} rows/s (median)")
    print(f"  per-sample add         {statistics.median(single):12,.0f} rows/s (median)")
    print(f"  read back samples.read {statistics.median(read):12,.0f} rows/s (median)")
    print(f"  commit of 400 rows     {statistics.median(commit_ms):12.2f} ms   (median)")
    print(f"  CPU per recorded s     {1e3 * statistics.median(cpu_per_s):12.1f} ms   "
          "(2 sensors x 400 Hz, median)")
    need = 800.0
    print(f"  headroom over 2 x 400 Hz: {statistics.median(single) / need:,.0f}x (per-sample)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--db", default=None, help="store path or URL (default: temporary SQLite)")
    ap.add_argument("--rows", type=int, default=400_000)
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    if args.db:
        bench(args.db, args.rows, args.repeats)
        return
    with tempfile.TemporaryDirectory() as d:
        bench(str(Path(d) / "bench.db"), args.rows, args.repeats)


if __name__ == "__main__":
    main()
