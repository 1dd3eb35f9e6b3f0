"""The session store on both back ends: SQLite (always) and PostgreSQL (a private server the
``pg_server`` fixture starts when the distribution's binaries are installed)."""

from __future__ import annotations

import hashlib
import os
import re
import stat
import time

import numpy as np
import pytest
from sqlalchemy import create_engine, func, inspect, select

from rig.errors import RigConfigError
from rig.store import (
    SCHEMA_VERSION,
    TELEMETRY_COLUMNS,
    SampleWriter,
    TelemetryWriter,
    open_store,
)
from rig.store import schema as S
from rig.store.samples import raw_probe


def _unit(rng, n):
    q = rng.normal(size=(n, 4))
    return q / np.linalg.norm(q, axis=1, keepdims=True)


@pytest.fixture
def store(db_url):
    with open_store(db_url) as s:
        yield s


@pytest.fixture
def session(store):
    pid = store.patients.add("P-0001", side="right")
    sid = store.sessions.start(pid, rig_name="sim-imu", joint="shoulder", side="right",
                               meta={"rate_hz": 400})
    return sid


def test_the_store_is_the_database_and_one_repository_per_concern(store, session):
    """The rooms of the store: ``store.<repository>.<verb>``, nothing of the old flat API left,
    and every "no such row" the same one line naming the store."""
    rooms = ("patients", "sessions", "samples", "calibrations", "annotations", "boundaries",
             "models", "runs")
    for room in rooms:
        assert getattr(store, room).db is store
    flat = ("add_patient", "ensure_patient", "start_session", "end_session", "get_session",
            "list_sessions", "add_sensor", "sample_writer", "recording_span", "sample_count",
            "add_calibration", "add_boundary", "get_boundary", "add_model", "models_for",
            "start_run", "get_run", "telemetry_writer", "telemetry", "raw", "_tx")
    assert not [name for name in flat if hasattr(store, name)]
    for call, what in ((lambda: store.samples.read(999), "session"),
                       (lambda: store.calibrations.add(999, "k", {}), "session"),
                       (lambda: store.boundaries.get(999), "boundary"),
                       (lambda: store.models.get(999), "model"),
                       (lambda: store.runs.get(999), "run"),
                       (lambda: store.models.add("m.onnx", sha256="0" * 64, boundary_id=999),
                        "boundary")):
        with pytest.raises(RigConfigError, match=re.escape(f"no {what} 999 in {store.url}")):
            call()


def test_patients_are_pseudonyms_only(store):
    cols = {c["name"] for c in inspect(store.engine).get_columns("patients")}
    assert cols == {"id", "pseudonym", "side", "notes", "created_at"}
    pid = store.patients.add("P-0001", side="left")
    assert store.patients.get(pid)["pseudonym"] == "P-0001"
    assert store.patients.ensure("P-0001") == pid
    other = store.patients.ensure("P-0002")
    assert other != pid
    assert [p["pseudonym"] for p in store.patients.list()] == ["P-0001", "P-0002"]
    with pytest.raises(RigConfigError, match="already exists"):
        store.patients.add("P-0001")
    with pytest.raises(RigConfigError, match="side"):
        store.patients.add("P-0003", side="up")
    with pytest.raises(RigConfigError, match="no patient 999"):
        store.patients.get(999)


def test_session_lifecycle(store, session):
    s = store.sessions.get(session)
    assert s["status"] == "running" and s["ended_at"] is None
    assert s["pseudonym"] == "P-0001" and s["meta"] == {"rate_hz": 400}
    store.sessions.end(session, status="interrupted", meta={"reason": "ctrl-c"}, dropped=3)
    s = store.sessions.get(session)
    assert s["status"] == "interrupted" and s["dropped"] == 3
    assert s["meta"] == {"rate_hz": 400, "reason": "ctrl-c"}
    assert s["ended_at"] >= s["started_at"]
    with pytest.raises(RigConfigError, match="status"):
        store.sessions.end(session, status="finished-ish")
    with pytest.raises(RigConfigError, match="kind"):
        store.sessions.start(s["patient_id"], kind="play")
    with pytest.raises(RigConfigError, match="no session 77"):
        store.sessions.get(77)
    with pytest.raises(RigConfigError, match="finite"):
        store.sessions.start(s["patient_id"], meta={"x": float("nan")})


def test_samples_round_trip_exactly(store, session):
    rng = np.random.default_rng(1)
    store.samples.add_sensor(session, "thorax", segment="thorax", kind="sensor", port="sim://imu-stream")
    n = 3000
    t = 100.0 + np.arange(n) / 400.0
    q_th, q_hu = _unit(rng, n), _unit(rng, n)
    with SampleWriter(store, session) as w:
        w.add_many(t, t * 1.5, "thorax", "sensor", q_th, 3)
        w.add_many(t, None, "humerus", "sensor", q_hu, np.arange(n) % 4)
        w.add(t[-1] + 1, None, "shoulder", "joint", [1.0, 0.0, 0.0, 0.0], 0)
        w.set_dropped(7)
    assert w.added == w.written == 2 * n + 1 and w.pending == 0
    all_ = store.samples.read(session)
    assert all_["q"].shape == (2 * n + 1, 4)
    th = store.samples.read(session, "thorax")
    np.testing.assert_array_equal(th["t"], t)
    np.testing.assert_array_equal(th["device_t"], t * 1.5)
    np.testing.assert_array_equal(th["q"], q_th)  # bit-exact float64
    assert set(th["status"]) == {3} and set(th["kind"]) == {"sensor"}
    hu = store.samples.read(session, "humerus")
    np.testing.assert_array_equal(hu["q"], q_hu)
    assert np.isnan(hu["device_t"]).all()
    np.testing.assert_array_equal(hu["status"], np.arange(n) % 4)
    sh = store.samples.read(session, "shoulder")
    assert list(sh["kind"]) == ["joint"]
    sensors = {r["name"]: r for r in store.samples.sensors(session)}
    assert sensors["thorax"]["port"] == "sim://imu-stream"  # the registered row is reused
    assert sensors["humerus"]["kind"] == "sensor" and sensors["shoulder"]["kind"] == "joint"
    [row] = store.sessions.list()
    assert row["samples"] == 2 * n + 1 and row["dropped"] == 7
    assert row["samples_by_sensor"] == {"humerus": n, "shoulder": 1, "thorax": n}
    assert row["pseudonym"] == "P-0001" and row["kind"] == "record"
    assert store.samples.count(session) == 2 * n + 1


def _raw(rng, n):
    """Raw readings (N, 9): accelerometer ~g, gyroscope ~1 rad/s, magnetometer ~48 uT."""
    return rng.normal(size=(n, 9)) * np.repeat([9.81, 1.0, 48.0], 3)


def test_raw_readings_round_trip_exactly_nan_as_null(store, session):
    rng = np.random.default_rng(4)
    n = 500
    t = np.arange(n) / 400.0
    raw = _raw(rng, n)
    raw[7] = np.nan  # a sample without a raw reading
    raw[9, 6:] = np.nan  # a sample without its magnetometer
    q = _unit(rng, n)
    with SampleWriter(store, session) as w:
        w.add_many(t, t, "humerus", "sensor", q, 3, raw=raw)
        w.add_many(t, None, "thorax", "sensor", q)  # no raw at all, same commit
        w.add(t[-1] + 1.0, None, "humerus", "sensor", q[0], 3, raw=raw[0])
        w.add(t[-1] + 2.0, None, "humerus", "sensor", q[1], 3, raw=[np.nan] * 9)
        w.add(t[-1] + 3.0, None, "humerus", "sensor", q[2], 3)
    hu = store.samples.read(session, "humerus")
    assert hu["raw"].shape == (n + 3, 9) and hu["raw"].dtype == np.float64
    np.testing.assert_array_equal(hu["raw"][:n], raw)  # bit-exact, NaN where NaN
    np.testing.assert_array_equal(hu["raw"][n], raw[0])
    assert np.isnan(hu["raw"][n + 1:]).all()
    np.testing.assert_array_equal(hu["q"][:n], q)
    th = store.samples.read(session, "thorax")
    assert th["raw"].shape == (n, 9) and np.isnan(th["raw"]).all()
    all_ = store.samples.read(session)
    assert all_["raw"].shape == (2 * n + 3, 9)
    np.testing.assert_array_equal(all_["raw"][all_["name"] == "humerus"], hu["raw"])
    # stored as SQL NULL, not as a NaN value: a missing reading is a missing value
    with store.engine.connect() as conn:
        nulls = conn.execute(select(func.count()).select_from(S.samples).where(
            S.samples.c.mag_x.is_(None))).scalar_one()
    assert nulls == n + 2 + 1 + 1  # thorax, humerus rows 7 and 9, the NaN row, the last add


def test_samples_without_raw_read_as_nan(store, session):
    with SampleWriter(store, session) as w:
        w.add_many(np.arange(10.0), None, "humerus", "sensor", np.tile([1.0, 0, 0, 0], (10, 1)),
                   raw=np.full((10, 9), np.nan))
    s = store.samples.read(session)
    assert s["raw"].shape == (10, 9) and np.isnan(s["raw"]).all()
    assert store.samples.read(session, "nobody")["raw"].shape == (0, 9)


def test_sqlite_finds_raw_readings_through_the_partial_index(tmp_path):
    """Whether a session has raw readings is looked up in ix_samples_raw, not scanned."""
    with open_store(tmp_path / "r.db") as store:
        sid = store.sessions.start(store.patients.add("P-1"))
        for where in (S.samples.c.session_id == sid,
                      (S.samples.c.session_id == sid) & (S.samples.c.sensor_id == 1)):
            stmt = raw_probe(where).compile(store.engine, compile_kwargs={"literal_binds": True})
            with store.engine.connect() as conn:
                plan = " ".join(r[-1] for r in conn.exec_driver_sql(f"EXPLAIN QUERY PLAN {stmt}"))
            assert "USING INDEX ix_samples_raw" in plan, plan


def test_writer_refuses_bad_raw_readings(store, session):
    q = np.tile([1.0, 0, 0, 0], (4, 1))
    with SampleWriter(store, session) as w:
        with pytest.raises(RigConfigError, match=r"raw must have shape \(4, 9\)"):
            w.add_many(np.arange(4.0), None, "humerus", "sensor", q, raw=np.zeros((4, 6)))
        bad = np.zeros((4, 9))
        bad[2, 4] = np.inf
        with pytest.raises(RigConfigError, match=r"sample 2 .*raw reading must be finite"):
            w.add_many(np.arange(4.0), None, "humerus", "sensor", q, raw=bad)
        with pytest.raises(RigConfigError, match="raw must have 9 values"):
            w.add(0.0, None, "humerus", "sensor", q[0], raw=[0.0] * 3)
        with pytest.raises(RigConfigError, match="must be finite"):
            w.add(0.0, None, "humerus", "sensor", q[0], raw=[-np.inf] + [0.0] * 8)
    assert w.written == 0 and store.samples.count(session) == 0


def test_recorders_write_path_keeps_raw(store, session):
    """rig record's writer step: OrientationSample.raw -> SampleBatch.raw -> the store."""
    from rig.devices.sources import OrientationSample
    from rig.record.pump import batch_from_samples
    from rig.record.session import _write

    rng = np.random.default_rng(6)
    raw = _raw(rng, 6)
    samples = [
        OrientationSample(k / 100, k / 100, name, "sensor", np.array([1.0, 0, 0, 0]), 3,
                          raw=None if k == 4 else raw[k])
        for k in range(6) for name in ("thorax", "humerus")
    ]
    with SampleWriter(store, session) as w:
        _write(w, batch_from_samples(samples))
    got = store.samples.read(session, "humerus")["raw"]
    expect = raw.copy()
    expect[4] = np.nan
    np.testing.assert_array_equal(got, expect)


def test_writer_refuses_bad_samples(store, session):
    with SampleWriter(store, session) as w:
        with pytest.raises(RigConfigError, match="finite and non-zero"):
            w.add(0.0, None, "humerus", "sensor", [float("nan"), 0, 0, 1])
        with pytest.raises(RigConfigError, match="finite and non-zero"):
            w.add(0.0, None, "humerus", "sensor", [0, 0, 0, 0])
        q = np.tile([1.0, 0, 0, 0], (5, 1))
        q[3] = 0.0
        with pytest.raises(RigConfigError, match="sample 3"):
            w.add_many(np.arange(5.0), None, "humerus", "sensor", q)
        with pytest.raises(RigConfigError, match="shape"):
            w.add_many(np.arange(5.0), None, "humerus", "sensor", q[:, :3])
    assert w.written == 0
    assert store.samples.count(session) == 0


def test_background_thread_commits_without_close(db_url, store, session):
    w = SampleWriter(store, session, flush_interval_s=0.2)
    try:
        w.add(0.0, None, "humerus", "sensor", [1.0, 0, 0, 0])
        for _ in range(1500):  # polls, bounded so that a wedged thread cannot hang the suite
            if w.commits:
                break
            time.sleep(0.02)
        assert w.commits >= 1 and w.pending == 0
        with open_store(db_url, create=False) as other:  # another connection pool sees it
            assert other.samples.count(session) == 1
    finally:
        w.close()


def test_add_commits_itself_when_the_thread_is_late(store, session):
    # max_latency_s=0: every add finds its rows "too old" and commits before returning
    w = SampleWriter(store, session, flush_interval_s=1.0, max_latency_s=0.0)
    try:
        for k in range(5):
            w.add(float(k), None, "humerus", "sensor", [1.0, 0, 0, 0])
            assert w.pending == 0
            assert store.samples.count(session) == k + 1
    finally:
        w.close()


def test_flush_interval_must_commit_every_second(store, session):
    with pytest.raises(RigConfigError, match="at least every second"):
        SampleWriter(store, session, flush_interval_s=2.0)


def test_calibrations_annotations_boundaries_models(store, session, tmp_path):
    cid = store.calibrations.add(session, "sensor-to-segment",
                                 {"q": np.array([1.0, 0, 0, 0]), "n": np.int64(3)}, 1.25)
    [c] = store.calibrations.list(session)
    assert c["id"] == cid and c["data"] == {"q": [1.0, 0.0, 0.0, 0.0], "n": 3}
    assert c["residual_deg"] == 1.25
    store.annotations.add(session, 12.5, "arm at maximal abduction")
    store.annotations.add(session, 2.0, "start")
    assert [a["text"] for a in store.annotations.list(session)] == ["start",
                                                                "arm at maximal abduction"]
    yaml_text = "name: p1\nswing:\n  type: cone\n"
    bid = store.boundaries.add(session, yaml_text, {"samples": 1000, "method": "test"})
    b = store.boundaries.get(bid)
    assert b["constraint_yaml"] == yaml_text and b["meta"]["samples"] == 1000
    assert store.boundaries.add(None, yaml_text) != bid  # from an imported file
    with pytest.raises(RigConfigError, match="non-empty"):
        store.boundaries.add(session, "  ")
    model = tmp_path / "m.onnx"
    model.write_bytes(b"\x08\x01not really onnx")
    mid = store.models.add(model, metrics={"mean_3d_error_pct": 0.5}, boundary_id=bid,
                           session_id=session)
    m = store.models.get(mid)
    assert m["sha256"] == hashlib.sha256(model.read_bytes()).hexdigest()
    assert m["metrics"] == {"mean_3d_error_pct": 0.5} and m["path"] == str(model)
    assert [x["id"] for x in store.models.list(boundary_id=bid)] == [mid]
    with pytest.raises(RigConfigError, match="64 hex"):
        store.models.add(model, sha256="abc")
    with pytest.raises(RigConfigError, match="no boundary"):
        store.models.add(model, sha256="0" * 64, boundary_id=999)


def test_runs_and_telemetry(store, session):
    rid = store.runs.start(session, {"model": "m.onnx", "rate_hz": 200})
    rows = []
    for k in range(250):
        rows.append({
            "cycle": k, "t_s": k / 200, "target_w": 1.0, "target_x": 0.0, "target_y": 0.0,
            "target_z": 0.0, "commanded_w": np.float64(1.0), "read_ms": 0.3,
            "violation_deg": float("nan") if k == 3 else 0.0, "intervention": k % 50 == 0,
            "fault": "timeout" if k == 7 else None, "overrun": k == 9,
        })
    with TelemetryWriter(store, rid) as tw:
        for r in rows:
            tw.add(r)
    store.runs.end(rid, {"cycles": 250, "p99_cycle_ms": 1.2})
    run = store.runs.get(rid)
    assert run["status"] == "completed" and run["summary"]["cycles"] == 250
    tel = store.runs.telemetry(rid)
    assert set(TELEMETRY_COLUMNS) <= set(tel)
    np.testing.assert_array_equal(tel["cycle"], np.arange(250))
    np.testing.assert_array_equal(tel["t_s"], np.arange(250) / 200)
    assert np.isnan(tel["violation_deg"][3]) and tel["violation_deg"][4] == 0.0
    assert np.isnan(tel["present_w"]).all()
    assert tel["intervention"].sum() == 5
    assert tel["fault"][7] == "timeout" and tel["fault"][8] is None
    assert tel["extra"][9] == {"overrun": True}
    assert [r["id"] for r in store.runs.list(session)] == [rid]
    assert store.sessions.list()[0]["runs"] == 1
    with pytest.raises(RigConfigError, match="t_s"):
        with TelemetryWriter(store, rid) as tw:
            tw.add({"cycle": 1})


def test_v1_database_is_migrated_with_its_data(db_url):
    url = db_url if "://" in db_url else f"sqlite:///{db_url}"
    engine = create_engine(url)
    try:
        with engine.begin() as conn:
            assert S.apply_migrations(conn, 0, 1) == [1]
            pid = conn.execute(S.patients.insert().values(
                pseudonym="OLD-1", created_at=1.0)).inserted_primary_key[0]
            sid = conn.execute(S.sessions.insert().values(
                patient_id=pid, kind="record", status="completed", started_at=1.0,
                ended_at=2.0)).inserted_primary_key[0]
            snr = conn.execute(S.sensors.insert().values(
                session_id=sid, name="humerus", kind="sensor")).inserted_primary_key[0]
            conn.execute(S.samples.insert(), [
                {"session_id": sid, "sensor_id": snr, "t": k * 0.01, "device_t": None,
                 "w": 1.0, "x": 0.0, "y": 0.0, "z": 0.0, "status": 0} for k in range(10)])
        with engine.connect() as conn:
            assert set(inspect(conn).get_table_names()) == {
                "schema_version", "patients", "sessions", "sensors", "samples", "calibrations",
                "annotations", "boundaries", "models"}
            assert S.current_version(conn) == 1
    finally:
        engine.dispose()

    with open_store(db_url, create=False) as store:
        assert store.schema_version() == SCHEMA_VERSION == 7
        [row] = store.sessions.list()
        assert row["pseudonym"] == "OLD-1" and row["samples"] == 10 and row["runs"] == 0
        rid = store.runs.start(row["id"])  # the v2 tables work on the migrated database
        with TelemetryWriter(store, rid) as tw:
            tw.add({"t_s": 0.0})
        assert store.runs.telemetry(rid)["t_s"].tolist() == [0.0]
        _assert_schema_is_current(store)
    with open_store(db_url, create=False) as store:  # a second open migrates nothing
        assert store.schema_version() == 7
        assert [r["version"] for r in _versions(store)] == [1, 2, 3, 4, 5, 6, 7]


def _assert_schema_is_current(store):
    """The migrated schema is exactly the schema the code queries."""
    insp = inspect(store.engine)
    assert set(insp.get_table_names()) == set(S.metadata.tables)
    for name, table in S.metadata.tables.items():
        got = {c["name"]: c["nullable"] for c in insp.get_columns(name)}
        assert got == {c.name: c.nullable for c in table.columns}, name
        idx = {i["name"] for i in insp.get_indexes(name)}
        assert {i.name for i in table.indexes} <= idx, name


def test_v2_database_is_migrated_and_its_running_session_closed(db_url):
    """A version-2 store with a completed session and one left 'running' by a killed
    recorder: v3 adds the writer/heartbeat columns, keeps the data, and the old running session
    (writer unknown) can be listed and closed only with force."""
    url = db_url if "://" in db_url else f"sqlite:///{db_url}"
    engine = create_engine(url)
    v2_sessions = ("id", "patient_id", "rig_name", "joint", "side", "kind", "status",
                   "started_at", "ended_at", "dropped", "meta")
    try:
        with engine.begin() as conn:
            assert S.apply_migrations(conn, 0, 2) == [1, 2]
            pid = conn.execute(S.patients.insert().values(
                pseudonym="OLD-2", created_at=1.0)).inserted_primary_key[0]
            done = conn.execute(S.sessions.insert().values(
                patient_id=pid, kind="record", status="completed", started_at=1000.0,
                ended_at=1010.0, meta='{"a": 1}')).inserted_primary_key[0]
            killed = conn.execute(S.sessions.insert().values(
                patient_id=pid, kind="record", status="running", started_at=2000.0,
                meta="{}")).inserted_primary_key[0]
            for sid in (done, killed):
                snr = conn.execute(S.sensors.insert().values(
                    session_id=sid, name="humerus", kind="sensor")).inserted_primary_key[0]
                conn.execute(S.samples.insert(), [
                    {"session_id": sid, "sensor_id": snr, "t": 50.0 + k * 0.25,
                     "device_t": None, "w": 1.0, "x": 0.0, "y": 0.0, "z": 0.0, "status": 0}
                    for k in range(9)])
            rid = conn.execute(S.runs.insert().values(
                session_id=done, status="completed", started_at=1001.0,
                meta="{}")).inserted_primary_key[0]
            conn.execute(S.telemetry.insert().values(run_id=rid, t_s=0.5, intervention=0))
        with engine.connect() as conn:
            assert S.current_version(conn) == 2
            cols = [c["name"] for c in inspect(conn).get_columns("sessions")]
            assert tuple(cols) == v2_sessions
    finally:
        engine.dispose()

    with open_store(db_url, create=False) as store:
        assert store.schema_version() == 7
        _assert_schema_is_current(store)
        rows = {r["id"]: r for r in store.sessions.list()}
        assert rows[done]["status"] == "completed" and rows[done]["meta"] == {"a": 1}
        assert rows[done]["samples"] == rows[killed]["samples"] == 9
        assert rows[done]["runs"] == 1 and store.runs.telemetry(rid)["t_s"].tolist() == [0.5]
        old = rows[killed]
        assert old["writer_host"] is None and old["heartbeat_at"] is None
        assert old["last_sample_at"] is None
        assert old["liveness"]["state"] == "unknown"
        with pytest.raises(RigConfigError, match="cannot tell whether it is still being"):
            store.sessions.close_interrupted(killed)
        res = store.sessions.close_interrupted(killed, force=True)
        # no clock offset before v3: start + the samples' span (8 x 0.25 s)
        assert res["ended_at"] == 2002.0 and res["samples"] == 9
        s = store.sessions.get(killed)
        assert s["status"] == "interrupted" and s["ended_at"] == 2002.0
        assert s["meta"]["recovered"]["forced"] is True
        # a new session on the migrated store records its writer
        new = store.sessions.start(store.patients.ensure("OLD-2"))
        with SampleWriter(store, new) as w:
            w.add(1.0, None, "humerus", "sensor", [1.0, 0, 0, 0])
        row = store.sessions.get(new)
        assert row["writer_pid"] == os.getpid() and row["heartbeat_at"] is not None


def test_v3_database_gains_raw_columns_with_its_samples_intact(db_url):
    """A version-3 store (samples without raw columns, a session being written) migrates to
    v4: the nine raw columns are appended, nullable; old samples read back unchanged with raw
    NaN; new samples on the same session store their raw readings."""
    url = db_url if "://" in db_url else f"sqlite:///{db_url}"
    engine = create_engine(url)
    v3_samples = ("id", "session_id", "sensor_id", "t", "device_t", "w", "x", "y", "z",
                  "status")
    rng = np.random.default_rng(8)
    q = _unit(rng, 12)
    try:
        with engine.begin() as conn:
            assert S.apply_migrations(conn, 0, 3) == [1, 2, 3]
            pid = conn.execute(S.patients.insert().values(
                pseudonym="OLD-3", created_at=1.0)).inserted_primary_key[0]
            sid = conn.execute(S.sessions.insert().values(
                patient_id=pid, kind="record", status="completed", started_at=1000.0,
                ended_at=1010.0, meta="{}", writer_host="h", writer_pid=1,
                heartbeat_at=1010.0, last_sample_at=1009.0)).inserted_primary_key[0]
            snr = conn.execute(S.sensors.insert().values(
                session_id=sid, name="humerus", kind="sensor")).inserted_primary_key[0]
            conn.execute(S.samples.insert(), [
                {"session_id": sid, "sensor_id": snr, "t": 5.0 + k / 400, "device_t": k / 400,
                 "w": q[k, 0], "x": q[k, 1], "y": q[k, 2], "z": q[k, 3], "status": 3}
                for k in range(12)])
        with engine.connect() as conn:
            assert S.current_version(conn) == 3
            cols = [c["name"] for c in inspect(conn).get_columns("samples")]
            assert tuple(cols) == v3_samples
    finally:
        engine.dispose()

    with open_store(db_url, create=False) as store:
        assert store.schema_version() == 7
        _assert_schema_is_current(store)
        cols = [c for c in inspect(store.engine).get_columns("samples")]
        assert tuple(c["name"] for c in cols) == v3_samples + S.RAW_COLUMNS  # appended
        assert all(c["nullable"] for c in cols[len(v3_samples):])
        assert [r["version"] for r in _versions(store)] == [1, 2, 3, 4, 5, 6, 7]
        s = store.samples.read(sid)
        np.testing.assert_array_equal(s["q"], q)
        np.testing.assert_array_equal(s["t"], 5.0 + np.arange(12) / 400)
        assert s["raw"].shape == (12, 9) and np.isnan(s["raw"]).all()
        raw = _raw(rng, 3)
        with SampleWriter(store, sid) as w:
            w.add_many(6.0 + np.arange(3.0), None, "humerus", "sensor", q[:3], raw=raw)
        s = store.samples.read(sid)
        assert np.isnan(s["raw"][:12]).all()
        np.testing.assert_array_equal(s["raw"][12:], raw)
        assert store.sessions.get(sid)["writer_pid"] == os.getpid()  # the v3 columns still work


def _versions(store):
    with store.engine.connect() as conn:
        return [dict(r) for r in conn.execute(
            select(S.schema_version).order_by(S.schema_version.c.version)).mappings()]


def test_newer_database_is_refused(db_url):
    with open_store(db_url) as store:
        with store.engine.begin() as conn:
            conn.execute(S.schema_version.insert().values(
                version=99, applied_at=0.0, description="from the future"))
    with pytest.raises(RigConfigError, match="schema version 99, newer"):
        open_store(db_url)


# -- SQLite specifics ----------------------------------------------------------------------------


def _mode(p) -> int:
    return stat.S_IMODE(os.stat(p).st_mode)


def test_sqlite_file_is_owner_only_with_wal(tmp_path):
    path = tmp_path / "clinic.db"
    old = os.umask(0o022)  # a typical umask that would give 0644
    try:
        with open_store(path) as store:
            pid = store.patients.add("P-1")
            sid = store.sessions.start(pid)
            w = SampleWriter(store, sid)
            try:
                w.add(0.0, None, "humerus", "sensor", [1.0, 0, 0, 0])
                w.flush()
                wal, shm = tmp_path / "clinic.db-wal", tmp_path / "clinic.db-shm"
                assert wal.exists() and shm.exists()
                assert _mode(path) == _mode(wal) == _mode(shm) == 0o600
                with store.engine.connect() as conn:
                    assert conn.exec_driver_sql("PRAGMA journal_mode").scalar() == "wal"
                    assert conn.exec_driver_sql("PRAGMA synchronous").scalar() == 2  # FULL
                    assert conn.exec_driver_sql("PRAGMA foreign_keys").scalar() == 1
            finally:
                w.close()
            assert store.check_integrity() == "ok"
    finally:
        os.umask(old)
    assert _mode(path) == 0o600


def test_sqlite_paths_and_urls(tmp_path):
    missing = tmp_path / "none.db"
    with pytest.raises(RigConfigError, match="no database at"):
        open_store(missing, create=False)
    assert not missing.exists()
    with pytest.raises(RigConfigError, match="is a directory"):
        open_store(tmp_path)
    with pytest.raises(RigConfigError, match="does not exist"):
        open_store(tmp_path / "no-dir" / "x.db")
    with pytest.raises(RigConfigError, match="unsupported scheme 'mysql'"):
        open_store("mysql://u@h/db")
    junk = tmp_path / "notes.txt"
    junk.write_text("not a database\n" * 100)
    with pytest.raises(RigConfigError, match="file is not a database"):
        open_store(junk, create=False)
    with open_store(f"sqlite:///{tmp_path}/u.db") as s:
        s.patients.add("P-9")
    with open_store(tmp_path / "u.db", create=False) as s:
        assert s.patients.find("P-9") is not None
        assert s.patients.find("P-10") is None


def test_two_processes_worth_of_connections_share_a_file(tmp_path):
    """A reader (rig session list) while the recorder's writer commits: WAL lets both go on."""
    path = tmp_path / "r.db"
    with open_store(path) as rec, open_store(path, create=False) as viewer:
        sid = rec.sessions.start(rec.patients.add("P-1"))
        with SampleWriter(rec, sid) as w:
            for k in range(5):
                w.add_many(np.arange(100) + 100.0 * k, None, "humerus", "sensor",
                           np.tile([1.0, 0, 0, 0], (100, 1)))
                w.flush()
                assert viewer.sessions.list()[0]["samples"] == 100 * (k + 1)


def test_v4_database_gains_sensor_counts_kept_by_the_writer(db_url):
    """A version-4 store migrates to v5: each sensor's sample count and time span (host and
    device clocks) are counted once from its samples, then kept by the writer; the listing and
    sample_count read them instead of the samples."""
    url = db_url if "://" in db_url else f"sqlite:///{db_url}"
    engine = create_engine(url)
    rng = np.random.default_rng(9)
    q = _unit(rng, 20)
    try:
        with engine.begin() as conn:
            assert S.apply_migrations(conn, 0, 4) == [1, 2, 3, 4]
            pid = conn.execute(S.patients.insert().values(
                pseudonym="OLD-4", created_at=1.0)).inserted_primary_key[0]
            sid = conn.execute(S.sessions.insert().values(
                patient_id=pid, kind="record", status="completed", started_at=1000.0,
                ended_at=1010.0, meta="{}")).inserted_primary_key[0]
            ids = [conn.execute(S.sensors.insert().values(
                session_id=sid, name=nm, kind="sensor")).inserted_primary_key[0]
                for nm in ("thorax", "humerus")]
            conn.execute(S.samples.insert(), [
                {"session_id": sid, "sensor_id": ids[k % 2], "t": 5.0 + (k // 2) / 10,
                 "device_t": 100.0 + (k // 2) / 400, "w": q[k, 0], "x": q[k, 1],
                 "y": q[k, 2], "z": q[k, 3], "status": 3} for k in range(20)])
            empty = conn.execute(S.sessions.insert().values(
                patient_id=pid, kind="record", status="completed", started_at=2000.0,
                meta="{}")).inserted_primary_key[0]
    finally:
        engine.dispose()
    with open_store(db_url, create=False) as store:
        assert store.schema_version() == 7
        _assert_schema_is_current(store)
        rows = {r["id"]: r for r in store.sessions.list()}
        assert rows[sid]["samples_by_sensor"] == {"humerus": 10, "thorax": 10}
        assert rows[sid]["recording_s"] == pytest.approx(9 / 400)  # the device clock's span
        assert rows[empty]["samples"] == 0 and rows[empty]["recording_s"] is None
        sens = {r["name"]: r for r in store.samples.sensors(sid)}
        assert sens["thorax"]["first_t"] == 5.0 and sens["thorax"]["last_t"] == 5.9
        # the writer keeps them: counts, and the spans widened both ways
        with SampleWriter(store, sid) as w:
            w.add_many(np.array([4.0, 7.0]), np.array([99.0, 101.0]), "thorax", "sensor",
                       q[:2])
            w.add(8.0, None, "elbow", "sensor", q[0])
        assert store.samples.count(sid) == 23
        sens = {r["name"]: r for r in store.samples.sensors(sid)}
        assert sens["thorax"]["n_samples"] == 12
        assert (sens["thorax"]["first_t"], sens["thorax"]["last_t"]) == (4.0, 7.0)
        assert (sens["thorax"]["first_device_t"], sens["thorax"]["last_device_t"]) == (99.0,
                                                                                       101.0)
        assert sens["elbow"]["n_samples"] == 1 and sens["elbow"]["first_device_t"] is None
        # a sensor without a device clock: the session's span falls back to the host's
        assert store.sessions.list()[0]["recording_s"] == pytest.approx(8.0 - 4.0)


def test_session_listing_filters(tmp_path):
    with open_store(tmp_path / "f.db") as store:
        made = []
        for k in range(6):
            pid = store.patients.ensure(f"P-{k % 2}")
            sid = store.sessions.start(pid)
            store.sessions.end(sid)
            made.append(sid)
        starts = {r["id"]: r["started_at"] for r in store.sessions.list()}
        assert [r["id"] for r in store.sessions.list(limit=2)] == made[-2:]  # newest, in order
        assert {r["pseudonym"] for r in store.sessions.list(patient="P-1")} == {"P-1"}
        assert len(store.sessions.list(patient="P-1")) == 3
        later = [i for i in made if starts[i] >= starts[made[4]]]
        assert [r["id"] for r in store.sessions.list(since=starts[made[4]])] == later
        assert store.sessions.list(patient="nobody") == []


def test_raw_readings_alone_and_their_complete_count(tmp_path):
    rng = np.random.default_rng(10)
    q = _unit(rng, 6)
    raw = _raw(rng, 6)
    raw[2, 4] = np.nan  # one sample with its gyroscope's y missing
    with open_store(tmp_path / "r.db") as store:
        sid = store.sessions.start(store.patients.add("P-R"))
        with SampleWriter(store, sid) as w:
            w.add_many(np.arange(6.0), None, "humerus", "sensor", q, raw=raw)
            w.add_many(np.arange(6.0), None, "thorax", "sensor", q)
        got = store.samples.raw(sid, "humerus")
        np.testing.assert_array_equal(got, store.samples.read(sid, name="humerus")["raw"])
        np.testing.assert_array_equal(got, raw)
        assert store.samples.complete_raw_count(sid, "humerus") == 5
        assert store.samples.complete_raw_count(sid, "thorax") == 0
        assert np.isnan(store.samples.raw(sid, "thorax")).all()
        assert store.samples.raw(sid, "none").shape == (0, 9)
        lean = store.samples.read(sid, name="humerus", raw=False)
        assert np.isnan(lean["raw"]).all() and not lean["raw"].flags.writeable


def test_a_limbs_per_joint_telemetry_reads_back_by_the_csvs_names(store, session):
    from rig.loop.telemetry import Telemetry, telemetry_columns
    from rig.store import TelemetryWriter
    rid = store.runs.start(session, {"limb": "arm"})
    cols = telemetry_columns(["shoulder", "elbow"])
    tel = Telemetry(store_writer=TelemetryWriter(store, rid), columns=cols)
    for k in range(5):
        row = [float(k)] * len(cols)
        row[cols.index("elbow_intervention")] = 8
        row[cols.index("faults")] = 0
        tel.record(tuple(row))
    tel.close()
    back = store.runs.telemetry(rid)
    assert back["elbow_commanded_w"].tolist() == [0.0, 1.0, 2.0, 3.0, 4.0]
    assert back["shoulder_violation_deg"][4] == 4.0
    assert back["elbow_intervention"].dtype == np.int64 and (back["elbow_intervention"] == 8).all()
    assert back["cycle_ms"].tolist() == [0.0, 1.0, 2.0, 3.0, 4.0]
    # kept in their own table (v6), one row per cycle and joint, not in the JSON column
    assert not any(k.startswith(("elbow_", "shoulder_")) for e in back["extra"] for k in (e or {}))
    with store.transaction(write=False) as conn:
        rows = conn.execute(select(S.telemetry_joints.c.joint, S.telemetry_joints.c.cycle)
                            .where(S.telemetry_joints.c.run_id == rid)).all()
    assert sorted(rows) == sorted((j, k) for j in ("shoulder", "elbow") for k in range(5))
