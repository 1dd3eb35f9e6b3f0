"""``kill -9`` of a real ``rig record`` mid-session (sim-imu): the store survives.

The child reports, once a second, the host time ``last_t`` of the newest sample it has handed
to the store's writer. After SIGKILL the database must pass ``PRAGMA integrity_check``, the
samples kept must reach to within one second of the last ``last_t`` the child reported
(judged on the samples' own timestamps, not on the wall clock), the kept samples must be
complete up to there (no holes in the device's sample grid), and the session must be readable
and exportable with ``rig export``.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np

from rig.record.rigio import load_config
from rig.store import open_store

REPO = Path(__file__).resolve().parents[2]


def test_kill_9_loses_at_most_one_second(tmp_path):
    db = tmp_path / "crash.db"
    rate = load_config("sim-imu").sensors.rate_hz
    proc = subprocess.Popen(
        [sys.executable, "-m", "rig", "record", "--rig", "sim-imu", "--db", str(db),
         "--patient", "P-crash", "--no-calibration", "--events", "--display", "plain"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=REPO,
        env={**os.environ, "PYTHONUNBUFFERED": "1"})
    reported = []
    session_id = None
    try:
        for line in proc.stdout:
            ev = json.loads(line)
            if ev["event"] == "session":
                session_id = ev["session_id"]
            if ev["event"] == "committed" and ev["samples"] > 0:
                reported.append(ev)
                if len(reported) >= 3:
                    break
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        proc.stdout.close()
        proc.stderr.close()
    assert proc.returncode == -signal.SIGKILL
    assert session_id is not None and reported
    last_reported_t = reported[-1]["last_t"]

    with open_store(db) as store:
        assert store.check_integrity() == "ok"
        s = store.get_session(session_id)
        assert s["status"] == "running"  # nobody lived to close it
        data = store.samples(session_id)
    t = np.asarray(data["t"])
    assert len(t) > 0
    # at most one second of samples (their own host timestamps) missing
    assert t.max() >= last_reported_t - 1.0, (t.max(), last_reported_t)
    # what was kept is complete: per sensor, device timestamps on the grid without holes
    names = np.asarray(data["name"])
    dev = np.asarray(data["device_t"], dtype=float)
    for name in ("thorax", "humerus"):
        d = np.sort(dev[names == name])
        steps = np.round(np.diff(d) * rate).astype(int)
        assert np.all(steps == 1), np.unique(steps)

    out = tmp_path / "crash.csv"
    res = subprocess.run(
        [sys.executable, "-m", "rig", "export", "--db", str(db), "--session", str(session_id),
         "--format", "csv", "--out", str(out)],
        capture_output=True, text=True, cwd=REPO, timeout=120)
    assert res.returncode == 0, res.stderr
    rows = [ln for ln in out.read_text().splitlines() if ln and not ln.startswith("#")]
    assert len(rows) > 1
