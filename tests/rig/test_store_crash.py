"""``kill -9`` of a process recording through the SampleWriter loses at most one second.

The child writes two sensors at 400 Hz each through the public store API, paced to real time
(never faster), and after every batch prints how many samples per sensor it has handed to the
writer. The parent kills it with SIGKILL mid-stream, then compares the child's last report with
the database -- by sample counts and the samples' own clock (``device_t = index / 400``), not
by any wall-clock measurement. The session is then judged interrupted (its writer is gone) and
closed.
"""

from __future__ import annotations

import os
import signal
import sqlite3
import subprocess
import sys
import textwrap

import numpy as np

from rig.store import open_store
from rig.store.io import export_session, read_samples_csv, read_sto
from tests.rig.rigs import reap

RATE = 400.0
BATCH = 4  # samples per sensor between two reports

CHILD = textwrap.dedent(
    f"""
    import sys, time
    import numpy as np
    from rig.store import SampleWriter, open_store

    def q_of(i, phase):
        a = 0.001 * i + phase
        return [np.cos(a), np.sin(a), 0.0, 0.0]

    store = open_store(sys.argv[1])
    sid = store.sessions.start(store.patients.add("CRASH-1"), rig_name="sim-imu",
                               joint="shoulder", side="right")
    print("session", sid, flush=True)
    w = SampleWriter(store, sid, flush_interval_s=0.5)
    k = 0
    start = time.monotonic()
    while True:
        for _ in range({BATCH}):
            t = time.monotonic()
            w.add(t, k / {RATE}, "thorax", "sensor", q_of(k, 0.0), 3)
            w.add(t, k / {RATE}, "humerus", "sensor", q_of(k, 1.0), 3)
            k += 1
        print(k, repr(t), flush=True)  # samples per sensor handed to the writer so far
        # real-time pacing that never catches up faster than {RATE} Hz after a stall
        ahead = start + k / {RATE} - time.monotonic()
        if ahead > 0:
            time.sleep(ahead)
        else:
            start = time.monotonic() - k / {RATE}
    """
)


def test_kill_9_loses_at_most_one_second(tmp_path):
    db = tmp_path / "crash.db"
    script = tmp_path / "child.py"
    script.write_text(CHILD)
    proc = subprocess.Popen([sys.executable, str(script), str(db)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        first = proc.stdout.readline()
        assert first.startswith("session "), proc.stderr.read()
        sid = int(first.split()[1])
        while True:  # 3 s of samples (several commits) before the kill
            line = proc.stdout.readline()
            assert line, f"child ended early: {proc.stderr.read()}"
            if int(line.split()[0]) >= 3 * RATE:
                break
        os.kill(proc.pid, signal.SIGKILL)
        rest = proc.stdout.read()  # reports printed before the kill landed
    finally:
        reap(proc)
    assert proc.returncode == -signal.SIGKILL
    reports = [line for line in (line, *rest.splitlines()) if line.strip()]
    k_reported = int(reports[-1].split()[0])

    con = sqlite3.connect(db)  # SQLite's own check, independent of the store
    try:
        assert con.execute("PRAGMA integrity_check").fetchall() == [("ok",)]
    finally:
        con.close()

    with open_store(db, create=False) as store:
        session = store.sessions.get(sid)
        assert session["status"] == "running"  # it never ended, and says so
        live = store.sessions.liveness(sid)  # ... but its writer is gone
        assert live.state == "interrupted" and f"pid {proc.pid} " in live.reason
        counts = {}
        for name, phase in (("thorax", 0.0), ("humerus", 1.0)):
            s = store.samples.read(sid, name)
            m = s["t"].size
            counts[name] = m
            idx = np.arange(m)
            # a gap-free prefix of what the child wrote, values intact
            np.testing.assert_array_equal(s["device_t"], idx / RATE)
            a = 0.001 * idx + phase
            np.testing.assert_array_equal(s["q"][:, 0], np.cos(a))
            np.testing.assert_array_equal(s["q"][:, 1], np.sin(a))
            # at most one second of samples lost, at most one unreported batch extra
            assert k_reported - m <= RATE, (k_reported, m)
            assert m <= k_reported + BATCH
            assert (k_reported - 1) / RATE - s["device_t"][-1] <= 1.0
        print(f"kill -9: child reported {k_reported} per sensor, database has {counts}")
        assert abs(counts["thorax"] - counts["humerus"]) <= 1
        # closed as interrupted at its last sample (the samples' clock is the host's monotonic
        # one here, as in a recording), then still readable and exportable
        closed = store.sessions.close_interrupted(sid)
        session = store.sessions.get(sid)
        assert session["status"] == "interrupted"
        assert session["ended_at"] == closed["ended_at"] == store.sessions.list()[0][
            "last_sample_at"]
        assert session["started_at"] <= session["ended_at"] <= session["heartbeat_at"]
        info = export_session(store, sid, "sto", tmp_path / "crash.sto")
        table = read_sto(tmp_path / "crash.sto")
        assert len(table) == info["rows"] == min(counts.values())
        export_session(store, sid, "csv", tmp_path / "crash.csv")
        assert read_samples_csv(tmp_path / "crash.csv")["t"].size == sum(counts.values())
        assert store.sessions.list()[0]["samples"] == sum(counts.values())
