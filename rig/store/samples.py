"""Samples: a session's sensors (data streams) and their orientation samples.

A sensor row (``sensors``) names a stream of a session -- an IMU on a segment, or a joint --
and keeps its sample count and time span (schema v5), updated by the transaction that inserts
its samples, so counting or listing never scans the samples. The samples themselves are read
back as numpy arrays, a chunk of driver rows at a time; the high-rate inserting is the
:class:`~rig.store.writers.SampleWriter`'s, through :meth:`SampleRepository.insert`.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from typing import Any

import numpy as np
from sqlalchemy import case, func, literal, select
from sqlalchemy.engine import Connection
from sqlalchemy.exc import IntegrityError

from rig.errors import RigConfigError
from rig.store import schema as S
from rig.store.rows import Repository, check_choice, check_text

SENSOR_KINDS = ("sensor", "joint")


class SampleRepository(Repository):
    """The ``sensors`` and ``samples`` tables: ``store.samples``."""

    table = S.sensors
    what = "sensor"

    def add_sensor(self, session_id: int, name: str, *, segment: str | None = None,
                   kind: str = "sensor", port: str | None = None) -> int:
        """Describe a data stream of the session (an IMU on ``segment``, or a joint) -> id."""
        name = check_text("sensor name", name, 64)
        kind = check_choice("kind", kind, SENSOR_KINDS)
        self._require_session(session_id)
        try:
            with self.db.transaction() as conn:
                return self.insert_sensor(conn, int(session_id), name, segment, kind, port)
        except IntegrityError as err:
            raise RigConfigError(f"session {session_id} already has a sensor {name!r}") from err

    @staticmethod
    def insert_sensor(conn: Connection, session_id: int, name: str, segment: str | None,
                      kind: str, port: str | None) -> int:
        """Insert a sensor row in the caller's transaction ``conn``; its id."""
        res = conn.execute(
            S.sensors.insert().values(
                session_id=session_id, name=name, segment=segment, kind=kind, port=port
            )
        )
        return int(res.inserted_primary_key[0])

    def sensor_id(self, conn: Connection, session_id: int, name: str, kind: str) -> int:
        """The id of session ``session_id``'s sensor ``name``, in the caller's transaction
        ``conn``; a new sensor (on the segment of its name) when there is none."""
        row = conn.execute(
            select(S.sensors.c.id).where(
                (S.sensors.c.session_id == session_id) & (S.sensors.c.name == name)
            )
        ).first()
        if row is not None:
            return int(row[0])
        if kind not in SENSOR_KINDS:
            raise RigConfigError(f"sample kind must be 'sensor' or 'joint', got {kind!r}")
        return self.insert_sensor(conn, session_id, name, name, kind, None)

    @staticmethod
    def insert(conn: Connection, params: list[dict]) -> None:
        """Insert sample rows (one dict each, the same keys in every one) in the caller's
        transaction ``conn``, and add them to their sensors' counts and time spans."""
        conn.execute(S.samples.insert(), params)
        _count(conn, params)

    def sensors(self, session_id: int) -> list[dict]:
        """The session's sensor rows, by id."""
        return self._of_session(session_id)

    def read(self, session_id: int, name: str | None = None, *,
             raw: bool = True) -> dict[str, np.ndarray]:
        """Recorded samples of a session, in arrival order (``raw=False``: without the raw
        readings, which are then a read-only NaN view costing nothing).

        Returns
        -------
        dict
            ``t`` (N,) float64 s (host monotonic clock), ``device_t`` (N,) float64 s (NaN where
            the device has no clock), ``name`` (N,) str, ``kind`` (N,) str, ``q`` (N, 4) float64
            ``w, x, y, z``, ``status`` (N,) int64, ``raw`` (N, 9) float64: the IMU's raw
            reading ``acc_x..z`` (m/s²), ``gyr_x..z`` (rad/s), ``mag_x..z`` (µT), sensor frame,
            NaN where none was stored. Restricted to sensor ``name`` when given.
        """
        self._require_session(session_id)
        sensors = self.sensors(session_id)
        by_id = {int(r["id"]): r for r in sensors}
        q = (
            select(
                S.samples.c.t, S.samples.c.device_t, S.samples.c.sensor_id, S.samples.c.w,
                S.samples.c.x, S.samples.c.y, S.samples.c.z, S.samples.c.status,
            )
            .where(S.samples.c.session_id == int(session_id))
            .order_by(S.samples.c.id)
        )
        if name is not None:
            sel = [int(r["id"]) for r in sensors if r["name"] == name]
            q = q.where(S.samples.c.sensor_id == (sel[0] if sel else -1))
        else:
            sel = list(by_id)
        # the sensors' counts (schema v5) size the arrays; rows are converted a chunk at a
        # time, so the driver's Python tuples never hold more than one chunk
        n = sum(int(by_id[i].get("n_samples") or 0) for i in sel)
        out = SampleArrays(n, by_id)
        # Nine more cells per row double the driver's fetch time even when they are all NULL,
        # so they are fetched only when some sample has a raw reading.
        with self.db.transaction(write=False) as conn:
            raw = raw and conn.execute(raw_probe(q.whereclause)).first() is not None
            if raw:
                q = q.add_columns(*(S.samples.c[c] for c in S.RAW_COLUMNS))
            for rows in fetch_chunks(conn, q):
                out.add(rows, raw)
        return out.result()

    def raw(self, session_id: int, name: str) -> np.ndarray:
        """(N, 9) the raw readings of sensor ``name``'s samples, in arrival order (as in
        :meth:`read`: NaN where none was stored), and nothing else — the columns the host's
        fusion needs, fetched a chunk at a time into one array."""
        c = S.samples.c
        sensors = {r["name"]: r for r in self.sensors(session_id)}
        row = sensors.get(name)
        if row is None:
            return np.zeros((0, 9))
        out = np.empty((int(row.get("n_samples") or 0), 9))
        q = (select(*(c[k] for k in S.RAW_COLUMNS))
             .where((c.session_id == int(session_id)) & (c.sensor_id == int(row["id"])))
             .order_by(c.id))
        k = 0
        with self.db.transaction(write=False) as conn:
            for rows in fetch_chunks(conn, q):
                if k + len(rows) > len(out):  # more than the count said
                    out = np.concatenate((out[:k], np.empty((k + len(rows), 9))))
                out[k:k + len(rows)] = nan_where_null(np.array(rows, dtype=object))
                k += len(rows)
        return out[:k]

    def complete_raw_count(self, session_id: int, name: str) -> int:
        """How many of sensor ``name``'s samples have all nine raw readings (counted by the
        database, nothing fetched)."""
        c = S.samples.c
        sid = select(S.sensors.c.id).where((S.sensors.c.session_id == int(session_id))
                                           & (S.sensors.c.name == name)).scalar_subquery()
        where = (c.session_id == int(session_id)) & (c.sensor_id == sid)
        for col in S.RAW_COLUMNS:
            where = where & c[col].is_not(None)
        with self.db.transaction(write=False) as conn:
            return int(conn.execute(select(func.count()).select_from(S.samples)
                                    .where(where)).scalar_one())

    def span(self, session_id: int) -> float | None:
        """The time a session's samples span, seconds (devices' clock where every stream has
        one, else the host's): the patient's time, also for a recording made faster than
        real time. None without samples."""
        with self.db.transaction(write=False) as conn:
            rows = sensor_spans(conn, [int(session_id)]).get(int(session_id), [])
        return recording_span([tuple(r) for r in rows])

    def count(self, session_id: int) -> int:
        """Samples of a session (the sensors' counts: no scan of the samples)."""
        with self.db.transaction(write=False) as conn:
            return int(conn.execute(
                select(func.coalesce(func.sum(S.sensors.c.n_samples), 0))
                .where(S.sensors.c.session_id == int(session_id))
            ).scalar_one())

    def t_range(self, session_id: int) -> tuple[Any, Any]:
        """The smallest and largest ``t`` of a session's samples (a scan of its samples)."""
        with self.db.transaction(write=False) as conn:
            lo, hi = conn.execute(
                select(func.min(S.samples.c.t), func.max(S.samples.c.t))
                .where(S.samples.c.session_id == int(session_id))
            ).one()
        return lo, hi


def sensor_spans(conn: Connection, session_ids: list[int]) -> dict[int, list[tuple]]:
    """The sensors' ``(name, n_samples, first_t, last_t, first_device_t, last_device_t)`` of
    each session in ``session_ids``, in the caller's transaction (see :func:`recording_span`)."""
    c = S.sensors.c
    out: dict[int, list] = {}
    for row in conn.execute(
            select(c.session_id, c.name, c.n_samples, c.first_t, c.last_t,
                   c.first_device_t, c.last_device_t)
            .where(c.session_id.in_(session_ids))):
        out.setdefault(int(row[0]), []).append(row[1:])
    return out


def recording_span(sensors: list) -> float | None:
    """The time a session's samples span (seconds) from its sensors' (name, n, first_t, last_t,
    first_device_t, last_device_t): on the devices' clock when every sensor with samples has
    one, else on the host's."""
    have = [x for x in sensors if x[1]]
    if not have:
        return None
    if all(x[4] is not None and x[5] is not None for x in have):
        return float(max(x[5] for x in have) - min(x[4] for x in have))
    return float(max(x[3] for x in have) - min(x[2] for x in have))


def raw_probe(where):
    """A query giving one sample matching ``where`` that has a raw reading, if any. Its
    condition is the partial index ``ix_samples_raw``'s, so the database answers it from that
    index instead of scanning the samples."""
    has_raw = func.coalesce(*(S.samples.c[c] for c in S.RAW_COLUMNS)).is_not(None)
    return select(S.samples.c.id).where(where, has_raw).limit(1)


def nan_where_null(cols: np.ndarray) -> np.ndarray:
    """An object array of numbers and ``None`` (SQL NULL) as float64, NaN for ``None``."""
    null = np.equal(cols, None)
    return np.where(null, np.nan, cols).astype(np.float64) if null.any() \
        else cols.astype(np.float64)


class SampleArrays:
    """The arrays :meth:`SampleRepository.read` returns, filled chunk by chunk (grown if the
    sensors' counts fall short, trimmed if they overshoot).

    Parameters
    ----------
    n : int
        Rows expected (the sensors' counts).
    by_id : dict
        The session's sensor rows by id.
    """

    def __init__(self, n: int, by_id: dict[int, dict]) -> None:
        self.n = 0
        self.ids = np.array(sorted(by_id), dtype=np.int64)
        self.names = np.array([by_id[int(i)]["name"] for i in self.ids] + [None], dtype=object)
        self.kinds = np.array([by_id[int(i)]["kind"] for i in self.ids] + [None], dtype=object)
        self.cols = self._alloc(max(n, 0))

    @staticmethod
    def _alloc(n: int) -> dict[str, np.ndarray]:
        return {"t": np.empty(n), "device_t": np.empty(n), "sensor": np.empty(n, np.int64),
                "q": np.empty((n, 4)), "status": np.empty(n, np.int64)}

    def add(self, rows: list[tuple], raw: bool) -> None:
        k, m = self.n, len(rows)
        if k + m > len(self.cols["t"]):  # more rows than the counts said: grow
            bigger = self._alloc(max(2 * (k + m), 1024))
            if "raw" in self.cols:
                bigger["raw"] = np.full((len(bigger["t"]), 9), np.nan)
            for key, a in self.cols.items():
                bigger[key][:k] = a[:k]
            self.cols = bigger
        if raw and "raw" not in self.cols:  # only sessions with raw readings pay for them
            self.cols["raw"] = np.full((len(self.cols["t"]), 9), np.nan)
        a = np.array(rows, dtype=object)
        c = self.cols
        c["t"][k:k + m] = a[:, 0].astype(np.float64)
        dev = a[:, 1]
        missing = np.equal(dev, None)
        c["device_t"][k:k + m] = np.where(missing, np.nan, dev).astype(np.float64) \
            if missing.any() else dev.astype(np.float64)
        c["sensor"][k:k + m] = a[:, 2].astype(np.int64)
        c["q"][k:k + m] = a[:, 3:7].astype(np.float64)
        c["status"][k:k + m] = a[:, 7].astype(np.int64)
        if raw:
            c["raw"][k:k + m] = nan_where_null(a[:, 8:17])
        self.n = k + m

    def result(self) -> dict[str, np.ndarray]:
        n, c = self.n, self.cols
        at = np.searchsorted(self.ids, c["sensor"][:n])
        # no raw reading at all: a read-only view of NaN, no memory per sample
        raw = c["raw"][:n] if "raw" in c else np.broadcast_to(np.nan, (n, 9))
        return {"t": c["t"][:n], "device_t": c["device_t"][:n], "name": self.names[at],
                "kind": self.kinds[at], "q": c["q"][:n], "status": c["status"][:n],
                "raw": raw}


def fetch_chunks(conn: Connection, stmt, size: int = 65536) -> Iterator[list[tuple]]:
    """Rows of a SELECT as lists of plain tuples, ``size`` at a time, from the driver's cursor
    in the caller's transaction.

    For bulk reads only: SQLAlchemy's Row objects cost about 20x more to turn into numpy
    arrays than tuples. The SQL is still SQLAlchemy's, compiled for the connection's dialect.
    """
    comp = stmt.compile(dialect=conn.dialect)
    params = (tuple(comp.params[k] for k in comp.positiontup) if comp.positional
              else comp.params)
    cur = conn.connection.dbapi_connection.cursor()
    try:
        cur.execute(comp.string, params)
        while True:
            rows = cur.fetchmany(size)
            if not rows:
                return
            yield rows
    finally:
        cur.close()



def _count(conn: Connection, params: list[dict]) -> None:
    """Add the inserted rows to their sensors' counts and time spans (schema v5), in the
    inserting transaction: one UPDATE per sensor in the batch."""
    per: dict[int, list] = {}
    for p in params:
        per.setdefault(p["sensor_id"], []).append((p["t"], p["device_t"]))
    c = S.sensors.c
    for sensor_id, tt in per.items():
        t = [x for x, _ in tt]
        dev = [d for _, d in tt if d is not None and math.isfinite(d)]

        def lower(col, v):
            return col if v is None else case(((col.is_(None)) | (col > v), literal(v)),
                                              else_=col)

        def upper(col, v):
            return col if v is None else case(((col.is_(None)) | (col < v), literal(v)),
                                              else_=col)

        conn.execute(S.sensors.update().where(c.id == sensor_id).values(
            n_samples=c.n_samples + len(tt),
            first_t=lower(c.first_t, min(t)), last_t=upper(c.last_t, max(t)),
            first_device_t=lower(c.first_device_t, min(dev) if dev else None),
            last_device_t=upper(c.last_device_t, max(dev) if dev else None)))
