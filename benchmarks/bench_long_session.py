"""Costs that grow with the recording: reading a long session back, and the store's listing.

``make``
    Records simulated IMU sessions of ``--minutes`` (default 10 30 60 120) through the whole
    recording stack — stream board on a pty, 2 sensors at 400 Hz with raw accelerometer /
    gyroscope / magnetometer samples, the guided calibration performed by the patient, then
    free motion with a return to the neutral pose every 20 s (neutral checkpoints), on a
    lockstep clock faster than real time — into ``--dir`` (default ``/tmp/rig-long``), one
    SQLite file per length (``long-<minutes>.db``). A 60-minute session is ~2.9 M samples.
    ``--rom`` records as ``rig record`` does by default, with the range of motion computed at
    the end, and prints the recorder's peak resident memory.
``measure``
    For each of those files, the commands a clinician runs on the session, each as its own
    process (``rig boundary … --no-store``, ``rig rom``, ``rig report``), timed, with the peak
    resident memory of the process (``getrusage(RUSAGE_CHILDREN).ru_maxrss``); medians over
    ``--repeats``.
``list``
    ``rig session list`` on stores of ``--sessions`` (default 500 20000) sessions of
    ``--samples`` samples each (built directly through the store's writer): wall time, peak
    memory, and the same with ``--limit 20`` and ``--patient``.

Figures, never assertions. Usage::

    .venv/bin/python benchmarks/bench_long_session.py make [--minutes 10 30 60 120]
    .venv/bin/python benchmarks/bench_long_session.py measure [--minutes ...] [--repeats 3]
    .venv/bin/python benchmarks/bench_long_session.py list [--sessions 500 20000]
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

import common  # noqa: F401  (first: one BLAS thread, this checkout on sys.path)

RIG = [sys.executable, "-m", "rig"]


def make(minutes: list[float], out: Path, rate: int = 400, rom: bool = False) -> None:
    from models.constraint import dump_constraint
    from rig.record import RecordOptions, record_session
    from rig.record.lockstep import CountingDisplay, LockstepClock
    from rig.record.rigio import load_config, open_rig
    from rig.sim.patients import star_constraint

    out.mkdir(parents=True, exist_ok=True)
    for m in minutes:
        db = out / (f"long-{m:g}-rom.db" if rom else f"long-{m:g}.db")
        if db.exists():
            print(f"{db} exists, kept")
            continue
        cpath = out / "patient.yaml"
        dump_constraint(star_constraint(11), cpath)
        port = (f"sim://imu-stream?sensors=2&rate={rate}&patient={cpath}&seed=11"
                "&misplace_deg=25&neutral=20&clock=manual&flow=on&max_lag=none")
        cfg = out / "rig.yaml"
        cfg.write_text(f"name: long-imu\njoint: {{name: shoulder, side: right, parent: thorax, "
                       f"child: humerus}}\nsensors:\n  port: \"{port}\"\n  protocol: stream\n"
                       f"  rate_hz: {rate}\n  raw: true\n  segments: {{thorax: 0, humerus: 1}}\n")
        rig = open_rig(load_config(str(cfg)), calibrate=True)
        shown = CountingDisplay()
        t0 = time.perf_counter()
        with LockstepClock(rig.simulators[0].clock, lambda s=shown: s.samples, 2.0 * rate,
                           step_s=0.02, window_s=0.1) as lock:
            res = record_session(
                RecordOptions(rig=str(cfg), db=str(db), patient="LONG-1", duration_s=60.0 * m,
                              rom=rom),
                display=shown, rig=rig,
                on_event=lambda name, info: name == "session" and lock.start())
        print(f"{db}: {res.status}, {res.samples} samples, dropped {res.dropped}, "
              f"{os.path.getsize(db) / 1e6:.0f} MB, {time.perf_counter() - t0:.0f} s to record"
              + (f", range of motion at the end: {'stored' if res.rom else 'none'}; peak "
                 f"resident memory of this process so far "
                 f"{resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MiB"
                 if rom else ""), flush=True)


def _timed(argv: list[str]) -> tuple[float, float, str]:
    """(wall s, peak RSS MiB, stderr tail) of one child process."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(proc.pid, 0)  # this child's own resource usage
    wall = time.perf_counter() - t0
    proc.returncode = os.waitstatus_to_exitcode(status)
    err = proc.stderr.read().decode(errors="replace").strip().splitlines()
    proc.stderr.close()
    return wall, usage.ru_maxrss / 1024.0, ("" if proc.returncode == 0 else
                                            f"exit {proc.returncode}: {err[-1] if err else ''}")


def measure(minutes: list[float], out: Path, repeats: int) -> None:
    print(f"{os.cpu_count()} CPUs; medians of {repeats} runs; peak resident memory of the "
          "command's process")
    print(f"{'session':>9s} {'samples':>9s} {'command':>9s} {'time s':>8s} {'peak MiB':>9s}")
    for m in minutes:
        db = out / f"long-{m:g}.db"
        if not db.exists():
            print(f"{db}: missing (run `make` first)")
            continue
        from rig.store import open_store

        with open_store(db, create=False) as st:
            n = st.samples.count(1)
        cmds = {
            "boundary": [*RIG, "boundary", "--db", str(db), "--session", "1", "--out",
                         str(out / "b.yaml"), "--no-store"],
            "rom": [*RIG, "rom", "--db", str(db), "--session", "1"],
            "report": [*RIG, "report", "--db", str(db), "--session", "1", "--out",
                       str(out / "r.html")],
        }
        for name, argv in cmds.items():
            runs = [_timed(argv) for _ in range(repeats)]
            bad = [r[2] for r in runs if r[2]]
            wall = statistics.median(r[0] for r in runs)
            rss = statistics.median(r[1] for r in runs)
            print(f"{m:>7g} m {n:>9d} {name:>9s} {wall:8.1f} {rss:9.0f}"
                  + (f"  FAILED: {bad[0]}" if bad else ""), flush=True)


def build_store(path: Path, sessions: int, samples: int) -> None:
    import numpy as np

    from rig.store import SampleWriter, open_store

    rng = np.random.default_rng(1)
    q = rng.normal(size=(samples, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    t = np.arange(samples) / 100.0
    with open_store(path) as st:
        for k in range(sessions):
            pid = st.patients.ensure(f"P-{k % 1000:04d}")
            sid = st.sessions.start(pid, rig_name="sim-shoulder", joint="shoulder", side="right")
            st.samples.add_sensor(sid, "shoulder", segment="humerus", kind="joint", port="sim://x")
            with SampleWriter(st, sid) as w:
                w.add_many(t + k, None, "shoulder", "joint", q, 0)
            st.sessions.end(sid, status="completed")


def listing(counts: list[int], samples: int, out: Path, repeats: int) -> None:
    print(f"rig session list; stores of N sessions x {samples} samples")
    print(f"{'sessions':>9s} {'command':>28s} {'time s':>8s} {'peak MiB':>9s}")
    for n in counts:
        db = out / f"list-{n}x{samples}.db"
        if not db.exists():
            t0 = time.perf_counter()
            build_store(db, n, samples)
            print(f"  (built {db} in {time.perf_counter() - t0:.0f} s)", flush=True)
        for label, extra in (("list", []), ("list --limit 20", ["--limit", "20"]),
                             ("list --patient P-0007", ["--patient", "P-0007"])):
            runs = [_timed([*RIG, "session", "list", "--db", str(db), *extra])
                    for _ in range(repeats)]
            print(f"{n:>9d} {label:>28s} {statistics.median(r[0] for r in runs):8.2f} "
                  f"{statistics.median(r[1] for r in runs):9.0f}", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    sub = ap.add_subparsers(dest="what", required=True)
    for name in ("make", "measure"):
        p = sub.add_parser(name)
        p.add_argument("--minutes", type=float, nargs="+", default=[10, 30, 60, 120])
        p.add_argument("--dir", type=Path, default=Path("/tmp/rig-long"))
        p.add_argument("--repeats", type=int, default=3)
        if name == "make":
            p.add_argument("--rom", action="store_true",
                           help="record as `rig record` does by default: the range of motion "
                                "computed at the end (files long-<minutes>-rom.db); prints the "
                                "recorder's peak resident memory (one length per run for a "
                                "figure per length)")
    p = sub.add_parser("list")
    p.add_argument("--sessions", type=int, nargs="+", default=[500, 20000])
    p.add_argument("--samples", type=int, default=100)
    p.add_argument("--dir", type=Path, default=Path("/tmp/rig-long"))
    p.add_argument("--repeats", type=int, default=3)
    a = ap.parse_args()
    resource.setrlimit(resource.RLIMIT_CORE, (0, 0))
    if a.what == "make":
        make(a.minutes, a.dir, rom=a.rom)
    elif a.what == "measure":
        measure(a.minutes, a.dir, a.repeats)
    else:
        a.dir.mkdir(parents=True, exist_ok=True)
        listing(a.sessions, a.samples, a.dir, a.repeats)


if __name__ == "__main__":
    main()
