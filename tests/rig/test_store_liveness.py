"""Who writes a session, its heartbeat, the liveness rule and closing an interrupted session.

The rule (:func:`rig.store.liveness.judge`) is tested with injected hosts, times and process
probes -- no wall-clock condition, no real dead process needed. The probe itself is checked on
this process and on a child that has exited and been reaped.
"""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import time

import numpy as np
import pytest

from rig.errors import RigConfigError
from rig.store import SampleWriter, TelemetryWriter, open_store
from rig.store import schema as S
from rig.store.liveness import (
    IDLE_HEARTBEAT_S,
    STALE_AFTER_S,
    judge,
    probe_process,
    this_writer,
)

BOOT = "3f1e0c6a-boot"
ROW = {"status": "running", "started_at": 1000.0, "writer_host": "rig-pc", "writer_pid": 4242,
       "writer_start": f"{BOOT}/777", "heartbeat_at": 1500.0}


def probe_of(table):
    """A process table as a probe: pid -> start token; absent = no such process."""
    return lambda pid: (pid in table, table.get(pid))


# -- the rule --------------------------------------------------------------------------------


def test_dead_pid_on_this_host_is_interrupted():
    got = judge(ROW, host="rig-pc", now=1501.0, probe=probe_of({}))
    assert got.state == "interrupted" and "pid 4242 on rig-pc is gone" in got.reason


def test_live_pid_with_its_start_is_live_whatever_the_heartbeat():
    probe = probe_of({4242: f"{BOOT}/777"})
    assert judge(ROW, host="rig-pc", now=1501.0, probe=probe).state == "live"
    # a live process with a silent device: an old heartbeat does not make it interrupted
    assert judge(ROW, host="rig-pc", now=1500.0 + 10 * STALE_AFTER_S, probe=probe).state == "live"


def test_reused_pid_is_interrupted():
    got = judge(ROW, host="rig-pc", now=1501.0, probe=probe_of({4242: f"{BOOT}/9001"}))
    assert got.state == "interrupted" and "reused" in got.reason


def test_pid_of_an_earlier_boot_is_interrupted():
    """A power cut: after the reboot the pid may exist again, with another boot id."""
    got = judge(ROW, host="rig-pc", now=1501.0, probe=probe_of({4242: "other-boot/777"}))
    assert got.state == "interrupted" and "restarted" in got.reason


def test_platform_without_start_times_falls_back_to_the_pid():
    assert judge(ROW, host="rig-pc", probe=probe_of({4242: None})).state == "live"
    row = dict(ROW, writer_start=None)
    assert judge(row, host="rig-pc", probe=probe_of({4242: f"{BOOT}/1"})).state == "live"


def test_other_host_is_judged_by_the_heartbeat():
    never = probe_of({})  # must not matter: the pid is another host's

    def at(now, **kw):
        return judge(ROW, host="laptop", now=now, probe=never, **kw)

    assert at(1500.0 + STALE_AFTER_S).state == "live"  # exactly at the threshold: still live
    stale = at(1500.0 + STALE_AFTER_S + 1.0)
    assert stale.state == "interrupted" and "last heartbeat 61 s ago" in stale.reason
    assert at(1520.0, stale_after_s=10.0).state == "interrupted"
    assert at(1505.0, stale_after_s=10.0).state == "live"
    # before the first commit, the start is the last sign of life
    row = dict(ROW, heartbeat_at=None)
    assert judge(row, host="laptop", now=1030.0, stale_after_s=10.0,
                 probe=never).state == "interrupted"
    assert judge(row, host="laptop", now=1005.0, stale_after_s=10.0, probe=never).state == "live"


def test_unknown_writer_and_ended_sessions():
    legacy = dict(ROW, writer_host=None, writer_pid=None, writer_start=None, heartbeat_at=None)
    assert judge(legacy, host="rig-pc", now=1e9, probe=probe_of({})).state == "unknown"
    assert judge(dict(ROW, status="completed"), host="rig-pc",
                 probe=probe_of({})).state == "ended"


def test_probe_sees_this_process_and_not_a_reaped_child():
    alive, start = probe_process(os.getpid())
    assert alive
    assert this_writer().pid == os.getpid() and this_writer().host == socket.gethostname()
    if os.path.exists("/proc/self/stat"):
        assert start is not None and start == this_writer().start
    # a child that has exited but is not reaped yet (a zombie) is gone already
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    try:
        os.waitid(os.P_PID, child.pid, os.WEXITED | os.WNOWAIT)  # exited, still a zombie
        assert probe_process(child.pid) == (False, None)
    finally:
        child.wait()
    assert probe_process(child.pid) == (False, None)  # reaped
    assert probe_process(0) == (False, None)


# -- the store: writer identity, heartbeat, close ------------------------------------------------


@pytest.fixture
def store(db_url):
    with open_store(db_url) as s:
        yield s


def _set(store, sid, **values):
    with store.engine.begin() as conn:
        conn.execute(S.sessions.update().where(S.sessions.c.id == sid).values(**values))


def test_writers_record_who_writes_and_beat_at_each_commit(store):
    sid = store.sessions.start(store.patients.add("P-1"))
    s = store.sessions.get(sid)
    me = this_writer()
    assert (s["writer_host"], s["writer_pid"], s["writer_start"]) == (me.host, me.pid, me.start)
    assert s["heartbeat_at"] is None and s["last_sample_at"] is None
    w = SampleWriter(store, sid, flush_interval_s=1.0)
    try:
        _set(store, sid, heartbeat_at=None)
        t = time.monotonic()  # the samples' clock, as the sources stamp it
        w.add_many(t + np.arange(4) * 0.01, None, "humerus", "sensor",
                   np.tile([1.0, 0, 0, 0], (4, 1)))
        w.flush()  # (or the writer's thread did)
        assert w.written == 4
        s = store.sessions.get(sid)
        assert s["heartbeat_at"] is not None and s["last_sample_at"] <= s["heartbeat_at"]
        # idle: nothing to commit, the heartbeat is still refreshed once it is due
        _set(store, sid, heartbeat_at=0.0)
        w._beat -= IDLE_HEARTBEAT_S  # as if that long had passed since the last beat
        assert w.flush() == 0
        assert store.sessions.get(sid)["heartbeat_at"] > 0.0
    finally:
        w.close()
    # an enforcement session beats through its telemetry writer
    rid = store.runs.start(sid)
    _set(store, sid, heartbeat_at=None)
    with TelemetryWriter(store, rid) as tw:
        tw.add({"t_s": 0.0})
    assert store.sessions.get(sid)["heartbeat_at"] is not None


def _killed_session(store, n=20):
    """A session whose samples were committed by a writer that then vanished."""
    sid = store.sessions.start(store.patients.add("P-killed"))
    with SampleWriter(store, sid) as w:
        w.add_many(100.0 + np.arange(n) * 0.01, None, "humerus", "sensor",
                   np.tile([1.0, 0, 0, 0], (n, 1)))
    rid = store.runs.start(sid)
    _set(store, sid, writer_host="rig-pc", writer_pid=4242, writer_start=f"{BOOT}/777",
         started_at=1000.0, heartbeat_at=1500.0, last_sample_at=1499.6)
    return sid, rid


def test_list_shows_the_killed_session_interrupted_with_its_last_sample(store):
    sid, _ = _killed_session(store)
    [row] = store.sessions.list(host="rig-pc", now=1501.0, probe=probe_of({}))
    assert row["status"] == "running" and row["liveness"]["state"] == "interrupted"
    assert row["samples"] == 20 and row["last_sample_at"] == 1499.6
    [row] = store.sessions.list(host="rig-pc", probe=probe_of({4242: f"{BOOT}/777"}))
    assert row["liveness"]["state"] == "live"
    # a last sample outside the session's life is clamped into it
    _set(store, sid, last_sample_at=3.0)
    assert store.sessions.list(host="x", now=1501.0)[0]["last_sample_at"] == 1000.0


def test_close_refuses_a_live_writer_and_closes_a_dead_one(store):
    sid, rid = _killed_session(store)
    live = probe_of({4242: f"{BOOT}/777"})
    with pytest.raises(RigConfigError, match=r"still being written .*use --force"):
        store.sessions.close_interrupted(sid, host="rig-pc", probe=live)
    assert store.sessions.get(sid)["status"] == "running"
    res = store.sessions.close_interrupted(sid, host="rig-pc", now=1501.0, probe=probe_of({}))
    assert res == {"id": sid, "ended_at": 1499.6, "samples": 20,
                   "liveness": {"state": "interrupted",
                                "reason": "writer pid 4242 on rig-pc is gone"}}
    s = store.sessions.get(sid)
    assert s["status"] == "interrupted" and s["ended_at"] == 1499.6
    assert s["meta"]["recovered"]["forced"] is False
    assert s["meta"]["recovered"]["end"] == "last sample"
    run = store.runs.get(rid)
    assert run["status"] == "interrupted" and run["ended_at"] == 1499.6
    assert store.samples.read(sid)["t"].size == 20  # the data stays readable
    with pytest.raises(RigConfigError, match="is not running: it ended as 'interrupted'"):
        store.sessions.close_interrupted(sid, force=True)


def test_close_with_force_and_without_samples(store):
    sid = store.sessions.start(store.patients.add("P-enf"), kind="enforce")
    _set(store, sid, started_at=1000.0, heartbeat_at=1200.0)
    with pytest.raises(RigConfigError, match="still being written"):
        store.sessions.close_interrupted(sid)  # this very process: alive
    res = store.sessions.close_interrupted(sid, force=True)
    assert res["ended_at"] == 1200.0 and res["samples"] == 0  # its writer's last commit
    assert store.sessions.get(sid)["meta"]["recovered"]["forced"] is True
    with pytest.raises(RigConfigError, match="no session 99"):
        store.sessions.close_interrupted(99)


def test_stale_heartbeat_from_another_host_can_be_closed(store):
    sid, _ = _killed_session(store)
    with pytest.raises(RigConfigError, match="still being written"):
        store.sessions.close_interrupted(sid, host="laptop", now=1520.0, stale_after_s=30.0)
    res = store.sessions.close_interrupted(sid, host="laptop", now=1531.0, stale_after_s=30.0)
    assert res["liveness"]["state"] == "interrupted" and res["ended_at"] == 1499.6
