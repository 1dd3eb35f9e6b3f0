"""``rig record`` on the simulated limbs beside busy processes: does the device stay?

Runs ``rig record --rig sim-leg`` and ``--rig sim-arm`` (the command a user types, in a child
process, guided calibration included: the simulated patient performs it) ``--runs`` times each
(default 20) while ``--busy`` processes (default 2, each a ``yes > /dev/null``) keep the cores
busy, and prints per rig: runs, sessions that lost their device (``device_lost``: the driver
gave up on the board, exit 1), sessions with 0 samples, the median samples per session, and
the median wall time per run. A simulated board stands in for hardware, which answers and
streams on time whatever the host does: the target is 0 device-lost sessions.

Each run is start-up, the guided calibration (neutral pose 5 s, then 8 s per joint: about 31 s
of sample time), then ``--duration`` seconds of recording (default 3) — about 40 s a run, so
20 runs of each rig take about 25 minutes. ``--no-rom`` is passed: the range of motion is
computed after the device is closed, and is not what is measured here.

The machine-speed line (a Python loop of 10**7 additions, timed before the busy processes
start) lets figures from different days be compared.

Usage::

    .venv/bin/python benchmarks/bench_record_load.py [--runs 20] [--busy 2] [--duration 3]
        [--rigs sim-leg sim-arm] [--nice 0]
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import sqlite3
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

import common
from common import additions_s


@contextlib.contextmanager
def busy(n: int) -> Iterator[None]:
    """``n`` processes ``yes > /dev/null`` for the duration (each keeps a core busy)."""
    procs = [subprocess.Popen(["yes"], stdout=subprocess.DEVNULL) for _ in range(n)]
    try:
        yield
    finally:
        for p in procs:
            p.terminate()
        for p in procs:
            p.wait()


def one_run(rig: str, db: Path, duration: float, nice: int) -> dict:
    """One ``rig record`` in a child process; its exit status, samples and error line."""
    cmd = [sys.executable, "-m", "rig", "record", "--rig", rig, "--db", str(db),
           "--patient", "P-LOAD", "--duration", f"{duration:g}", "--display", "plain",
           "--no-rom"]
    if nice:
        cmd = ["nice", "-n", str(nice), *cmd]
    t0 = time.monotonic()
    proc = subprocess.run(cmd, stdin=subprocess.DEVNULL, capture_output=True, text=True,
                          env=common.child_env(), timeout=600)
    wall = time.monotonic() - t0
    status, samples = "none", 0
    if db.exists():
        with contextlib.closing(sqlite3.connect(db)) as con:
            row = con.execute("SELECT id, status FROM sessions ORDER BY id DESC LIMIT 1"
                              ).fetchone()
            if row is not None:
                status = row[1]
                samples = con.execute("SELECT COUNT(*) FROM samples WHERE session_id = ?",
                                      (row[0],)).fetchone()[0]
    errors = [ln for ln in proc.stderr.splitlines() if ln.startswith("rig: error")]
    return {"rc": proc.returncode, "status": status, "samples": int(samples), "wall": wall,
            "error": errors[-1] if errors else ""}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=20, help="runs per rig (default 20)")
    ap.add_argument("--busy", type=int, default=2, help="busy processes beside (default 2)")
    ap.add_argument("--duration", type=float, default=3.0,
                    help="seconds recorded after the calibration (default 3)")
    ap.add_argument("--rigs", nargs="+", default=["sim-leg", "sim-arm"])
    ap.add_argument("--nice", type=int, default=0, help="run rig record at this nice level")
    ap.add_argument("--json", type=Path, help="also write every run's outcome here")
    args = ap.parse_args(argv)
    speed = additions_s()
    print(f"machine: {os.cpu_count()} CPUs, a Python loop of 10**7 additions {speed:.2f} s "
          f"(before the busy processes); {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}")
    print(f"{args.runs} runs per rig beside {args.busy} busy processes (yes > /dev/null), "
          f"--duration {args.duration:g}{f', nice {args.nice}' if args.nice else ''}",
          flush=True)
    outcomes: dict[str, list[dict]] = {rig: [] for rig in args.rigs}
    with tempfile.TemporaryDirectory() as tmp, busy(args.busy):
        for k in range(args.runs):
            for rig in args.rigs:  # alternate, so a change in the machine's load hits both
                r = one_run(rig, Path(tmp) / f"{rig}-{k}.db", args.duration, args.nice)
                outcomes[rig].append(r)
                print(f"  {rig} run {k + 1}: rc {r['rc']}, {r['status']}, {r['samples']} "
                      f"samples, {r['wall']:.0f} s{'  ' + r['error'] if r['error'] else ''}",
                      flush=True)
    print(f"\n{'rig':8s} {'runs':>4s} {'device lost':>11s} {'0 samples':>9s} "
          f"{'samples (median)':>16s} {'wall s (median)':>15s}")
    for rig, rs in outcomes.items():
        lost = sum(r["status"] == "device_lost" for r in rs)
        empty = sum(r["samples"] == 0 for r in rs)
        print(f"{rig:8s} {len(rs):4d} {lost:11d} {empty:9d} "
              f"{statistics.median(r['samples'] for r in rs):16.0f} "
              f"{statistics.median(r['wall'] for r in rs):15.1f}")
    others = sorted({r["status"] for rs in outcomes.values() for r in rs} - {"completed"})
    if others:
        print(f"statuses other than completed: {', '.join(others)}")
    print(f"target: 0 device-lost sessions of {args.runs} per rig")
    if args.json:
        args.json.write_text(json.dumps({"loop_s": speed, "args": vars(args) | {
            "json": str(args.json)}, "runs": outcomes}, indent=1))


if __name__ == "__main__":
    main()
