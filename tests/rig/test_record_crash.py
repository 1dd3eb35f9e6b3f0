"""``kill -9`` of a real ``rig record`` mid-session (sim-imu): the store survives.

The child reports, once a second, the host time ``last_t`` of the newest sample it has handed
to the store's writer. After SIGKILL the database must pass ``PRAGMA integrity_check``, the
samples kept must reach to within one second of the last ``last_t`` the child reported
(judged on the samples' own timestamps, not on the wall clock), the kept samples must be
complete up to there (no holes in the device's sample grid), and the session must be readable
and exportable with ``rig export``.

``rig session list`` then shows the session as interrupted (its writer process is gone) with
its samples and last sample; ``rig session close`` closes it as ``interrupted`` with the end
time of its last sample, refuses a second close, and the closed session still exports and
feeds ``rig boundary``. The recording is calibrated (the simulated patient performs the
protocol at 4x real time) and killed during the recording proper.
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
from tests.rig.rigs import reap, sim_imu_yaml

REPO = Path(__file__).resolve().parents[2]


def _rig_yaml(tmp_path: Path) -> Path:
    """The shipped sim-imu rig with the patient's time 4x real time (a shorter calibration)."""
    return sim_imu_yaml(tmp_path, port_suffix="&time_scale=4", name="crash-imu")


def test_kill_9_loses_at_most_one_second(tmp_path, rig_cli):
    db = tmp_path / "crash.db"
    rate = load_config("sim-imu").sensors.rate_hz
    proc = subprocess.Popen(
        [sys.executable, "-m", "rig", "record", "--rig", str(_rig_yaml(tmp_path)), "--db",
         str(db), "--patient", "P-crash", "--events", "--display", "plain"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=REPO,
        env={**os.environ, "PYTHONUNBUFFERED": "1"})
    reported = []
    session_id = None
    calibrated = False
    try:
        for line in proc.stdout:
            ev = json.loads(line)
            if ev["event"] == "session":
                session_id = ev["session_id"]
            calibrated = calibrated or ev["event"] == "calibrated"
            if calibrated and ev["event"] == "committed" and ev["samples"] > 0:
                reported.append(ev)
                if len(reported) >= 3:
                    break
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=30)
    finally:
        reap(proc)
    assert proc.returncode == -signal.SIGKILL
    assert session_id is not None and reported
    last_reported_t = reported[-1]["last_t"]

    with open_store(db) as store:
        assert store.check_integrity() == "ok"
        s = store.sessions.get(session_id)
        assert s["status"] == "running"  # nobody lived to close it
        data = store.samples.read(session_id)
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

    # the dead recorder's session: listed as interrupted, with its samples and last sample
    code, out, err = rig_cli(["session", "list", "--db", db, "--json"])
    assert code == 0, err
    [row] = [r for r in json.loads(out) if r["id"] == session_id]
    assert row["status"] == "running" and row["liveness"]["state"] == "interrupted"
    assert f"writer pid {proc.pid} on " in row["liveness"]["reason"]
    assert row["samples"] == len(t) and row["last_sample_at"] is not None
    assert row["started_at"] <= row["last_sample_at"] <= row["heartbeat_at"]
    _, table, _ = rig_cli(["session", "list", "--db", db])
    [line] = [ln for ln in table.splitlines() if ln.startswith(f"{session_id} ")]
    assert "interrupted (not closed)" in line and f" {len(t)} (" in line

    code, out, err = rig_cli(["session", "close", "--db", db, "--session", session_id])
    assert code == 0, err
    assert f"closed as interrupted: {len(t)} samples, ended at its last sample" in out
    with open_store(db, create=False) as store:
        s = store.sessions.get(session_id)
        assert s["status"] == "interrupted" and s["ended_at"] == row["last_sample_at"]
        assert s["meta"]["recovered"]["liveness"] == "interrupted"
        assert len(store.calibrations.list(session_id)) == 1
    code, _, err = rig_cli(["session", "close", "--db", db, "--session", session_id])
    assert code == 2 and err.count("\n") == 1
    assert "is not running: it ended as 'interrupted'" in err

    out = tmp_path / "crash.csv"
    code, _, err = rig_cli(["export", "--db", db, "--session", session_id, "--format", "csv",
                            "--out", out])
    assert code == 0, err
    rows = [ln for ln in out.read_text().splitlines() if ln and not ln.startswith("#")]
    assert len(rows) == len(t) + 1  # header + every sample
    # the closed session is a recording like any other for rig boundary
    code, _, err = rig_cli(["boundary", "--db", db, "--session", session_id, "--out",
                            tmp_path / "crash-boundary.yaml"])
    assert code == 0, err
    assert (tmp_path / "crash-boundary.yaml").read_text().strip()

