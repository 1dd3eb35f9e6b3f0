"""Schema of the session store and its ordered migrations.

Layout (current version :data:`SCHEMA_VERSION`)::

    schema_version(version PK, applied_at, description)        one row per applied migration
    patients(id, pseudonym UNIQUE, side, notes, created_at)     a pseudonym only -- no name fields
     +-- sessions(id, patient_id, rig_name, joint, side, kind, status,
     |            started_at, ended_at, dropped, meta,
     |            writer_host, writer_pid, writer_start, heartbeat_at, last_sample_at)  (v3)
          +-- sensors(id, session_id, name, segment, kind, port)       UNIQUE(session_id, name)
          +-- samples(id, session_id, sensor_id, t, device_t, w, x, y, z, status,
          |           acc_x, acc_y, acc_z, gyr_x, gyr_y, gyr_z, mag_x, mag_y, mag_z)  (v4)
          |        index (session_id, sensor_id, t); (v4) partial index (session_id,
          |        sensor_id) of the samples with a raw reading
          +-- calibrations(id, session_id, kind, data, residual_deg, created_at)
          +-- annotations(id, session_id, t, text, created_at)
          +-- boundaries(id, session_id NULL, constraint_yaml, meta, created_at)
          |     +-- models(id, boundary_id NULL, session_id NULL, path, sha256, metrics, created_at)
          +-- runs(id, session_id, status, started_at, ended_at, meta, summary)         (v2)
                +-- telemetry(id, run_id, cycle, t_s, target_w..z, commanded_w..z,
                |             present_w..z, read_ms, compute_ms, write_ms, cycle_ms,
                |             correction_deg, violation_deg, intervention, fault, extra)
                +-- telemetry_joints(id, run_id, cycle, joint, target_w..z, correction_w..z,
                                     commanded_w..z, present_w..z, correction_deg,
                                     violation_deg, distance_deg, intervention)        (v6)
                         index (run_id, joint, cycle)
    jobs(id, kind, status, resource, patient_id NULL, session_id NULL, params, progress,
         result, message, created_at, ended_at, writer_host, writer_pid, writer_start,
         heartbeat_at)                                                               (v7)

Units: times ``t``, ``device_t``, ``t_s`` in seconds (``t`` on the recording host's monotonic
clock, ``started_at``/``ended_at``/``created_at`` Unix time); quaternions scalar-first
``w, x, y, z`` (Hamilton), one float64 column per component; angles in degrees. JSON columns
(``meta``, ``data``, ``metrics``, ``summary``, ``extra``) are text written by :mod:`json`, so
SQLite and PostgreSQL store the same bytes.

Migration policy: migrations are *append-only* functions ``_mN(conn)`` in :data:`MIGRATIONS`;
each creates or alters tables with definitions frozen inside the function (never the current
:data:`metadata`, which may change later), runs in one transaction together with the row it
adds to ``schema_version``, and is never edited once released. A database newer than the code
is refused, never downgraded. ``tests/rig/test_store.py`` checks that version-1, -2 and -3
databases are migrated to the current schema with their data intact, and that the migrated
tables equal :data:`metadata`.

Version 3 adds columns to ``sessions`` (``ALTER TABLE ... ADD COLUMN``, nullable, so rows of
older sessions read as "writer unknown"): who writes the session (``writer_host``,
``writer_pid``, ``writer_start`` -- see :mod:`rig.store.liveness`) and the writer's heartbeat
(``heartbeat_at``, Unix time of its last commit; ``last_sample_at``, Unix time of the newest
sample committed).

Version 4 adds nine nullable float64 columns to ``samples`` (:data:`RAW_COLUMNS`): the IMU's
raw reading -- accelerometer ``acc_x..z`` (m/s², specific force), gyroscope ``gyr_x..z``
(rad/s), magnetometer ``mag_x..z`` (µT), all in the sensor frame. NULL where a sample has no
raw reading (every sample written before version 4, joint samples, devices that do not send
it). A partial index ``ix_samples_raw`` (session_id, sensor_id) holds only the samples with a
raw reading (any of the nine not NULL), so "does this session have raw readings?" is an index
lookup instead of a scan.

Version 6 adds ``telemetry_joints``: a run of a limb of several joints keeps one row per cycle
and joint (the joint by its name in the limb file), its target, the model's correction, the
orientation of the goal ticks written, the present orientation, the correction's angle, the
violation and signed distance of what was commanded (degrees) and the supervisor's
intervention bits; the cycle's row in ``telemetry`` keeps the whole limb's figures (its
``target``/``commanded``/``present`` columns NULL). One-joint runs write no row there.

Version 7 adds ``jobs``: the web app's long work (a recording, a boundary extraction, a
training; :mod:`rig.web.jobs`), run by the server process off the request path. ``resource``
names what the job holds (a rig's ports: one job at a time per port), ``params`` what it was
asked, ``progress`` its latest progress (phase, counts, coverage, the prompts said so far) so a
page reloaded later finds it, ``result`` what it made; the writer columns and heartbeat are
the sessions' (:mod:`rig.store.liveness`), so a job whose server died shows as such.
"""

from __future__ import annotations

import time
from collections.abc import Callable

from sqlalchemy import (
    BigInteger,
    Column,
    Double,
    ForeignKey,
    Index,
    Integer,
    MetaData,
    SmallInteger,
    String,
    Table,
    Text,
    UniqueConstraint,
    func,
    inspect,
    select,
    text,
)
from sqlalchemy.engine import Connection

#: SQLite's rowid alias must be INTEGER; PostgreSQL gets BIGSERIAL for the big tables.
BigId = BigInteger().with_variant(Integer(), "sqlite")


def _v1_tables(md: MetaData) -> None:
    """Version-1 tables, frozen: recording (patients .. models)."""
    Table(
        "schema_version",
        md,
        Column("version", Integer, primary_key=True, autoincrement=False),
        Column("applied_at", Double, nullable=False),
        Column("description", Text, nullable=False),
    )
    Table(
        "patients",
        md,
        Column("id", Integer, primary_key=True),
        Column("pseudonym", String(64), nullable=False, unique=True),
        Column("side", String(8)),
        Column("notes", Text),
        Column("created_at", Double, nullable=False),
    )
    Table(
        "sessions",
        md,
        Column("id", Integer, primary_key=True),
        Column("patient_id", Integer, ForeignKey("patients.id"), nullable=False, index=True),
        Column("rig_name", String(128)),
        Column("joint", String(64)),
        Column("side", String(8)),
        Column("kind", String(16), nullable=False),
        Column("status", String(16), nullable=False),
        Column("started_at", Double, nullable=False),
        Column("ended_at", Double),
        Column("dropped", BigInteger, nullable=False, server_default="0"),
        Column("meta", Text, nullable=False, server_default="{}"),
    )
    Table(
        "sensors",
        md,
        Column("id", Integer, primary_key=True),
        Column("session_id", Integer, ForeignKey("sessions.id"), nullable=False),
        Column("name", String(64), nullable=False),
        Column("segment", String(64)),
        Column("kind", String(16), nullable=False),
        Column("port", Text),
        UniqueConstraint("session_id", "name", name="uq_sensors_session_name"),
    )
    Table(
        "samples",
        md,
        Column("id", BigId, primary_key=True),
        Column("session_id", Integer, ForeignKey("sessions.id"), nullable=False),
        Column("sensor_id", Integer, ForeignKey("sensors.id"), nullable=False),
        Column("t", Double, nullable=False),
        Column("device_t", Double),
        Column("w", Double, nullable=False),
        Column("x", Double, nullable=False),
        Column("y", Double, nullable=False),
        Column("z", Double, nullable=False),
        Column("status", SmallInteger, nullable=False, server_default="0"),
        Index("ix_samples_session_sensor_t", "session_id", "sensor_id", "t"),
    )
    Table(
        "calibrations",
        md,
        Column("id", Integer, primary_key=True),
        Column("session_id", Integer, ForeignKey("sessions.id"), nullable=False, index=True),
        Column("kind", String(64), nullable=False),
        Column("data", Text, nullable=False),
        Column("residual_deg", Double),
        Column("created_at", Double, nullable=False),
    )
    Table(
        "annotations",
        md,
        Column("id", Integer, primary_key=True),
        Column("session_id", Integer, ForeignKey("sessions.id"), nullable=False, index=True),
        Column("t", Double, nullable=False),
        Column("text", Text, nullable=False),
        Column("created_at", Double, nullable=False),
    )
    Table(
        "boundaries",
        md,
        Column("id", Integer, primary_key=True),
        Column("session_id", Integer, ForeignKey("sessions.id"), index=True),
        Column("constraint_yaml", Text, nullable=False),
        Column("meta", Text, nullable=False, server_default="{}"),
        Column("created_at", Double, nullable=False),
    )
    Table(
        "models",
        md,
        Column("id", Integer, primary_key=True),
        Column("boundary_id", Integer, ForeignKey("boundaries.id"), index=True),
        Column("session_id", Integer, ForeignKey("sessions.id"), index=True),
        Column("path", Text, nullable=False),
        Column("sha256", String(64), nullable=False),
        Column("metrics", Text, nullable=False, server_default="{}"),
        Column("created_at", Double, nullable=False),
    )


def _v2_tables(md: MetaData) -> None:
    """Version-2 tables, frozen: the live loop's runs and per-cycle telemetry."""
    Table(
        "runs",
        md,
        Column("id", Integer, primary_key=True),
        Column("session_id", Integer, ForeignKey("sessions.id"), nullable=False, index=True),
        Column("status", String(16), nullable=False),
        Column("started_at", Double, nullable=False),
        Column("ended_at", Double),
        Column("meta", Text, nullable=False, server_default="{}"),
        Column("summary", Text),
    )
    cols = [
        Column("id", BigId, primary_key=True),
        Column("run_id", Integer, ForeignKey("runs.id"), nullable=False),
        Column("cycle", BigInteger),
        Column("t_s", Double, nullable=False),
    ]
    for group in ("target", "commanded", "present"):
        cols += [Column(f"{group}_{c}", Double) for c in "wxyz"]
    cols += [
        Column(name, Double)
        for name in (
            "read_ms",
            "compute_ms",
            "write_ms",
            "cycle_ms",
            "correction_deg",
            "violation_deg",
        )
    ]
    cols += [
        Column("intervention", SmallInteger, nullable=False, server_default="0"),
        Column("fault", Text),
        Column("extra", Text),
    ]
    Table("telemetry", md, *cols, Index("ix_telemetry_run_t", "run_id", "t_s"))


def _v3_session_columns() -> list[Column]:
    """Version-3 columns of ``sessions``, frozen: writer identity and heartbeat."""
    return [
        Column("writer_host", String(255)),
        Column("writer_pid", Integer),
        Column("writer_start", String(80)),
        Column("heartbeat_at", Double),
        Column("last_sample_at", Double),
    ]


def _v3_tables(md: MetaData) -> None:
    for col in _v3_session_columns():
        md.tables["sessions"].append_column(col)


#: The raw-reading columns of ``samples`` (v4), in the order of ``SampleBatch.raw``.
RAW_COLUMNS: tuple[str, ...] = tuple(
    f"{group}_{axis}" for group in ("acc", "gyr", "mag") for axis in "xyz"
)


def _v4_sample_columns() -> list[Column]:
    """Version-4 columns of ``samples``, frozen: the IMU's raw reading, sensor frame."""
    return [
        Column(name, Double)
        for name in ("acc_x", "acc_y", "acc_z", "gyr_x", "gyr_y", "gyr_z",
                     "mag_x", "mag_y", "mag_z")
    ]


def _v4_raw_index(samples_table: Table) -> Index:
    """Version-4 partial index, frozen: the samples that have a raw reading, so that a reader
    learns whether a session (or sensor) has any without scanning its samples."""
    has_raw = func.coalesce(*(samples_table.c[c] for c in (
        "acc_x", "acc_y", "acc_z", "gyr_x", "gyr_y", "gyr_z", "mag_x", "mag_y", "mag_z",
    ))).is_not(None)
    return Index("ix_samples_raw", samples_table.c.session_id, samples_table.c.sensor_id,
                 sqlite_where=has_raw, postgresql_where=has_raw)


def _v4_tables(md: MetaData) -> None:
    for col in _v4_sample_columns():
        md.tables["samples"].append_column(col)
    _v4_raw_index(md.tables["samples"])  # attaches itself to the table


def _v5_sensor_columns() -> list[Column]:
    """Version-5 columns of ``sensors``, frozen: how many samples the stream has and the time
    they span (host ``t`` and the device's own clock), kept by the sample writer in the
    transaction that inserts them, so a listing costs per session, not per sample."""
    return [
        Column("n_samples", BigInteger, nullable=False, server_default="0"),
        Column("first_t", Double),
        Column("last_t", Double),
        Column("first_device_t", Double),
        Column("last_device_t", Double),
    ]


def _v5_tables(md: MetaData) -> None:
    for col in _v5_sensor_columns():
        md.tables["sensors"].append_column(col)


#: One joint's telemetry columns in ``telemetry_joints`` (v6), after ``run_id, cycle, joint``.
JOINT_TELEMETRY_COLUMNS: tuple[str, ...] = (
    *(f"{g}_{c}" for g in ("target", "correction", "commanded", "present") for c in "wxyz"),
    "correction_deg", "violation_deg", "distance_deg", "intervention",
)


def _v6_tables(md: MetaData) -> None:
    """Version-6 table, frozen: a limb run's per-joint telemetry."""
    cols = [
        Column("id", BigId, primary_key=True),
        Column("run_id", Integer, ForeignKey("runs.id"), nullable=False),
        Column("cycle", BigInteger, nullable=False),
        Column("joint", String(64), nullable=False),
    ]
    cols += [Column(f"{g}_{c}", Double) for g in ("target", "correction", "commanded",
                                                  "present") for c in "wxyz"]
    cols += [Column(n, Double) for n in ("correction_deg", "violation_deg", "distance_deg")]
    cols += [Column("intervention", Integer, nullable=False, server_default="0")]
    Table("telemetry_joints", md, *cols,
          Index("ix_telemetry_joints_run", "run_id", "joint", "cycle"))


def _v7_tables(md: MetaData) -> None:
    """Version-7 table, frozen: the web app's long jobs (recording, boundary, training)."""
    Table(
        "jobs",
        md,
        Column("id", Integer, primary_key=True),
        Column("kind", String(16), nullable=False),
        Column("status", String(16), nullable=False),
        Column("resource", String(256), nullable=False),
        Column("patient_id", Integer, ForeignKey("patients.id")),
        Column("session_id", Integer, ForeignKey("sessions.id"), index=True),
        Column("params", Text, nullable=False, server_default="{}"),
        Column("progress", Text, nullable=False, server_default="{}"),
        Column("result", Text, nullable=False, server_default="{}"),
        Column("message", Text),
        Column("created_at", Double, nullable=False),
        Column("ended_at", Double),
        Column("writer_host", String(255)),
        Column("writer_pid", Integer),
        Column("writer_start", String(128)),
        Column("heartbeat_at", Double),
    )


def _m1(conn: Connection) -> None:
    md = MetaData()
    _v1_tables(md)
    md.create_all(conn)


def _m2(conn: Connection) -> None:
    md = MetaData()
    _v1_tables(md)  # foreign-key targets only; they exist already
    _v2_tables(md)
    md.create_all(conn, tables=[md.tables["runs"], md.tables["telemetry"]])


def _m3(conn: Connection) -> None:
    prep = conn.dialect.identifier_preparer
    for col in _v3_session_columns():
        conn.execute(text(
            f"ALTER TABLE sessions ADD COLUMN {prep.quote(col.name)} "
            f"{col.type.compile(dialect=conn.dialect)}"
        ))


def _m4(conn: Connection) -> None:
    prep = conn.dialect.identifier_preparer
    for col in _v4_sample_columns():  # nullable, no default: old rows read as "no raw"
        conn.execute(text(
            f"ALTER TABLE samples ADD COLUMN {prep.quote(col.name)} "
            f"{col.type.compile(dialect=conn.dialect)}"
        ))
    md = MetaData()
    _v1_tables(md)
    for col in _v4_sample_columns():
        md.tables["samples"].append_column(col)
    _v4_raw_index(md.tables["samples"]).create(conn)  # empty: no old sample has raw


def _m5(conn: Connection) -> None:
    prep = conn.dialect.identifier_preparer
    for col in _v5_sensor_columns():
        default = " NOT NULL DEFAULT 0" if col.name == "n_samples" else ""
        conn.execute(text(
            f"ALTER TABLE sensors ADD COLUMN {prep.quote(col.name)} "
            f"{col.type.compile(dialect=conn.dialect)}{default}"
        ))
    # the existing samples, counted once (each sensor's rows through the session/sensor index)
    match = "samples.session_id = sensors.session_id AND samples.sensor_id = sensors.id"
    conn.execute(text(
        "UPDATE sensors SET "
        f"n_samples = (SELECT count(*) FROM samples WHERE {match}), "
        f"first_t = (SELECT min(t) FROM samples WHERE {match}), "
        f"last_t = (SELECT max(t) FROM samples WHERE {match}), "
        f"first_device_t = (SELECT min(device_t) FROM samples WHERE {match}), "
        f"last_device_t = (SELECT max(device_t) FROM samples WHERE {match})"
    ))


def _m6(conn: Connection) -> None:
    md = MetaData()
    _v1_tables(md)  # foreign-key targets only; they exist already
    _v2_tables(md)
    _v6_tables(md)
    md.create_all(conn, tables=[md.tables["telemetry_joints"]])


def _m7(conn: Connection) -> None:
    md = MetaData()
    _v1_tables(md)  # foreign-key targets only; they exist already
    _v7_tables(md)
    md.create_all(conn, tables=[md.tables["jobs"]])


#: Ordered, append-only: (version, description, function).
MIGRATIONS: list[tuple[int, str, Callable[[Connection], None]]] = [
    (1, "recording: patients, sessions, sensors, samples, calibrations, annotations, "
        "boundaries, models", _m1),
    (2, "live loop: runs, telemetry", _m2),
    (3, "sessions: writer (host, pid, process start) and heartbeat", _m3),
    (4, "samples: raw accelerometer, gyroscope, magnetometer (acc_x..mag_z)", _m4),
    (5, "sensors: sample counts and time spans, kept by the writer", _m5),
    (6, "live loop: per-joint telemetry of a limb's runs (telemetry_joints)", _m6),
    (7, "web app: long jobs (recording, boundary, training) and their progress", _m7),
]

#: The version this code reads and writes.
SCHEMA_VERSION = MIGRATIONS[-1][0]

# ---------------------------------------------------------------------------------------------
# The current schema, used by every query. Must equal what the migrations build (tested).
metadata = MetaData()
_v1_tables(metadata)
_v2_tables(metadata)
_v3_tables(metadata)
_v4_tables(metadata)
_v5_tables(metadata)
_v6_tables(metadata)
_v7_tables(metadata)

schema_version = metadata.tables["schema_version"]
patients = metadata.tables["patients"]
sessions = metadata.tables["sessions"]
sensors = metadata.tables["sensors"]
samples = metadata.tables["samples"]
calibrations = metadata.tables["calibrations"]
annotations = metadata.tables["annotations"]
boundaries = metadata.tables["boundaries"]
models = metadata.tables["models"]
runs = metadata.tables["runs"]
telemetry = metadata.tables["telemetry"]
telemetry_joints = metadata.tables["telemetry_joints"]
jobs = metadata.tables["jobs"]

#: Telemetry keys stored in their own columns; any other key of a row goes to ``extra`` (JSON).
TELEMETRY_COLUMNS: tuple[str, ...] = tuple(
    c.name for c in telemetry.columns if c.name not in ("id", "run_id", "extra")
)


def current_version(conn: Connection) -> int:
    """Highest applied migration, 0 for an empty database."""
    if not inspect(conn).has_table("schema_version"):
        return 0
    v = conn.execute(select(schema_version.c.version).order_by(schema_version.c.version.desc()))
    row = v.first()
    return 0 if row is None else int(row[0])


def apply_migrations(conn: Connection, start: int, target: int) -> list[int]:
    """Apply migrations ``start+1 .. target`` on ``conn`` (inside the caller's transaction)."""
    done = []
    for version, description, fn in MIGRATIONS:
        if start < version <= target:
            fn(conn)
            conn.execute(
                schema_version.insert().values(
                    version=version, applied_at=time.time(), description=description
                )
            )
            done.append(version)
    return done
