"""Batched writers for high-rate rows: samples (recording) and telemetry (live loop).

Rows handed to ``add`` go to an in-memory list; a background thread commits the list every
``flush_interval_s`` (default 0.5 s) as one transaction with one ``executemany``. So a
``kill -9`` loses at most the rows added since the last commit -- under one second's worth.

The :class:`SampleWriter` adds a backstop that does not depend on the thread being scheduled:
when the oldest pending row has waited ``max_latency_s`` (0.8 s), the ``add`` call itself
commits before returning. The :class:`TelemetryWriter` never blocks its caller (the control
loop); it relies on the thread alone.

A writer is made on an open store (``SampleWriter(store, session_id)``,
``TelemetryWriter(store, run_id)``) and uses its repositories and transactions; the store knows
nothing of its writers.

A database error in the background thread is kept and raised by the next ``add``/``flush``/
``close``; the rows that failed stay pending.

Both writers keep their session's liveness record (:mod:`rig.store.liveness`): on creation they
record the calling process as the session's writer, and every commit also sets the session's
``heartbeat_at`` (Unix time of the commit) in the same transaction -- one ``UPDATE`` by primary
key, no extra commit. With nothing to commit, the thread still refreshes the heartbeat every
:data:`~rig.store.liveness.IDLE_HEARTBEAT_S` seconds. The :class:`SampleWriter` also stores
``last_sample_at``: the newest committed sample's ``t`` (the host's monotonic clock, as the
sources stamp it) converted to Unix time with the clocks' offset at the commit, never later
than the commit itself.

Samples may carry the IMU's raw reading (``raw=``: accelerometer m/s², gyroscope rad/s,
magnetometer µT, sensor frame; the columns :data:`~rig.store.schema.RAW_COLUMNS`). NaN values
are stored as SQL NULL and read back as NaN; a commit in which no sample has a raw reading
inserts only the orientation columns, so recordings without raw readings cost what they did.
"""

from __future__ import annotations

import json
import math
import threading
import time
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from rig.errors import RigConfigError
from rig.store import schema as S
from rig.store.liveness import IDLE_HEARTBEAT_S
from rig.store.store import Store

_NO_RAW = (None,) * 9


class _BatchWriter:
    """Pending rows + a flusher thread; subclasses define :meth:`_write`."""

    _kind = "rows"

    def __init__(self, store: Store, *, flush_interval_s: float,
                 max_latency_s: float | None) -> None:
        if not (0.0 < flush_interval_s <= 1.0):
            raise RigConfigError(
                f"flush_interval_s must be in (0, 1] s (commits at least every second), "
                f"got {flush_interval_s}"
            )
        self._store = store
        self.flush_interval_s = float(flush_interval_s)
        self.max_latency_s = max_latency_s
        self._pending: list = []
        self._oldest: float | None = None  # monotonic time the oldest pending row was added
        self._lock = threading.Lock()  # guards _pending / _oldest
        self._flush_lock = threading.Lock()  # one flush at a time
        self._stop = threading.Event()
        self._error: BaseException | None = None
        self._closed = False
        self.added = 0  #: rows handed to add/add_many
        self.written = 0  #: rows committed
        self.commits = 0  #: transactions committed
        self.session_id = int(self._session_of(store))
        store.sessions.claim_writer(self.session_id)
        self._beat = time.monotonic()  # when the heartbeat was last written
        self._thread = threading.Thread(
            target=self._run, name=f"rig-store-{self._kind}-writer", daemon=True
        )
        self._thread.start()

    # context manager, idempotent close
    def __enter__(self):
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _run(self) -> None:
        while not self._stop.wait(self.flush_interval_s):
            try:
                self.flush()
            except BaseException as err:  # kept for the producer; see _raise_pending_error
                self._error = err
                return

    def _raise_pending_error(self) -> None:
        if self._error is not None:
            err, self._error = self._error, None
            raise err

    def _append(self, rows: list) -> None:
        if self._closed:
            raise RigConfigError(f"{type(self).__name__} is closed")
        self._raise_pending_error()
        now = time.monotonic()
        with self._lock:
            if not self._pending:
                self._oldest = now
            self._pending.extend(rows)
            oldest = self._oldest
        self.added += len(rows)
        if self.max_latency_s is not None and oldest is not None \
                and now - oldest >= self.max_latency_s:
            self.flush()  # the flusher thread is late: commit here

    @property
    def pending(self) -> int:
        """Rows added but not committed yet."""
        with self._lock:
            return len(self._pending)

    def flush(self) -> int:
        """Commit every pending row now; returns how many were committed."""
        with self._flush_lock:
            with self._lock:
                rows, self._pending = self._pending, []
                oldest, self._oldest = self._oldest, None
            if not rows:
                self._write_extra()
                return 0
            try:
                self._write(rows)
            except BaseException:
                with self._lock:  # keep them for the next attempt
                    self._pending[:0] = rows
                    self._oldest = oldest
                raise
            self.written += len(rows)
            self.commits += 1
            return len(rows)

    def _session_of(self, store: Store) -> int:  # pragma: no cover - abstract
        raise NotImplementedError

    def _write(self, rows: list) -> None:  # pragma: no cover - abstract
        raise NotImplementedError

    def _heartbeat(self, conn, **values: Any) -> None:
        """Set the session's heartbeat (and ``values``) inside the caller's transaction."""
        self._store.sessions.heartbeat(conn, self.session_id, **values)
        self._beat = time.monotonic()

    def _idle_due(self) -> bool:
        return time.monotonic() - self._beat >= IDLE_HEARTBEAT_S

    def _write_extra(self) -> None:
        """State written even without rows: the heartbeat when it is due."""
        if self._idle_due():
            with self._store.transaction() as conn:
                self._heartbeat(conn)

    def close(self) -> None:
        """Stop the thread and commit what is pending (idempotent)."""
        if self._closed:
            return
        self._closed = True
        self._stop.set()
        self._thread.join()
        self._raise_pending_error()
        self.flush()


class SampleWriter(_BatchWriter):
    """Batched, crash-safe sample insertion for one session.

    ``SampleWriter(store, session_id)``; close it (or use ``with``). ``add`` costs a few
    microseconds; the rows are committed by a background thread every ``flush_interval_s``
    and, as a backstop, by ``add`` itself once the oldest pending row is ``max_latency_s``
    old.

    Attributes
    ----------
    added, written, commits : int
        Rows handed over, rows committed, transactions committed.
    dropped : int
        Samples the caller lost before the store (set it; written to the session on the next
        commit and on close).
    """

    _kind = "sample"

    def __init__(self, store: Store, session_id: int, *, flush_interval_s: float = 0.5,
                 max_latency_s: float = 0.8) -> None:
        store.sessions.get(session_id)  # no such session: one line
        self._sid = int(session_id)
        self._sensor_ids: dict[str, int] = {
            r["name"]: int(r["id"]) for r in store.samples.sensors(self._sid)
        }
        self.dropped = 0
        self._dropped_written = 0
        self._t_max = -math.inf  # newest sample time committed (host monotonic clock)
        super().__init__(store, flush_interval_s=flush_interval_s,
                         max_latency_s=max_latency_s)

    def set_dropped(self, n: int) -> None:
        """Total samples lost upstream so far (sequence gaps, a full queue)."""
        self.dropped = int(n)

    def add(self, t: float, device_t: float | None, name: str, kind: str,
            q: Sequence[float] | np.ndarray, status: int = 0,
            raw: Sequence[float] | np.ndarray | None = None) -> None:
        """Queue one sample.

        Parameters
        ----------
        t : float
            Host monotonic time, s.
        device_t : float or None
            Device timestamp, s.
        name : str
            Sensor or joint name (a sensors row is created for a new name).
        kind : str
            ``"sensor"`` or ``"joint"``.
        q : (4,) float
            Orientation ``w, x, y, z``; must be finite and non-zero (not renormalised here).
        status : int
            Calibration status byte, or 0.
        raw : (9,) float or None
            The IMU's raw reading ``acc_x, acc_y, acc_z`` (m/s²), ``gyr_x..z`` (rad/s),
            ``mag_x..z`` (µT), sensor frame; NaN values are stored as NULL (none). Infinite
            values are refused.
        """
        w, x, y, z = float(q[0]), float(q[1]), float(q[2]), float(q[3])
        t = float(t)
        n2 = w * w + x * x + y * y + z * z
        if not (math.isfinite(n2) and n2 > 0.0 and math.isfinite(t)):
            raise RigConfigError(
                f"sample of {name!r} at t={t}: quaternion must be finite and non-zero, "
                f"got {(w, x, y, z)}"
            )
        dt = None if device_t is None else float(device_t)
        rw = None if raw is None else _raw_row(raw, name, t)
        self._append([(t, dt, name, kind, w, x, y, z, int(status), rw)])

    def add_many(self, t: np.ndarray, device_t: np.ndarray | None, name: str | Sequence[str],
                 kind: str | Sequence[str], q: np.ndarray, status: np.ndarray | int = 0,
                 raw: np.ndarray | None = None) -> None:
        """Queue N samples: ``t`` (N,), ``device_t`` (N,) or None (NaN = none), ``name`` and
        ``kind`` a string or (N,), ``q`` (N, 4) ``w, x, y, z``, ``status`` (N,) or an int,
        ``raw`` (N, 9) or None: the raw readings as in :meth:`add` (NaN = none, stored as
        NULL; a row of NaN is a sample without a raw reading)."""
        t = np.asarray(t, dtype=np.float64).reshape(-1)
        q = np.asarray(q, dtype=np.float64)
        n = t.shape[0]
        if q.shape != (n, 4):
            raise RigConfigError(f"add_many: q must have shape ({n}, 4), got {q.shape}")
        norm2 = np.einsum("ij,ij->i", q, q)
        bad = ~(np.isfinite(norm2) & (norm2 > 0.0) & np.isfinite(t))
        if bad.any():
            i = int(np.argmax(bad))
            raise RigConfigError(
                f"add_many: sample {i} (t={t[i]}): quaternion must be finite and non-zero, "
                f"got {q[i].tolist()}"
            )
        if device_t is None:
            dts: list = [None] * n
        else:
            d = np.asarray(device_t, dtype=np.float64).reshape(-1)
            if d.shape != (n,):
                raise RigConfigError(f"add_many: device_t must have shape ({n},)")
            dts = [None if math.isnan(v) else v for v in d.tolist()]
        names = [name] * n if isinstance(name, str) else list(name)
        kinds = [kind] * n if isinstance(kind, str) else list(kind)
        st = np.broadcast_to(np.asarray(status, dtype=np.int64), (n,)).tolist()
        if len(names) != n or len(kinds) != n:
            raise RigConfigError(f"add_many: name and kind must be a string or have length {n}")
        raws = _raw_rows(raw, n, t)
        ql = q.tolist()
        if raws is None:
            rows = [
                (tt, dd, nm, kd, qq[0], qq[1], qq[2], qq[3], ss, None)
                for tt, dd, nm, kd, qq, ss in zip(t.tolist(), dts, names, kinds, ql, st,
                                                  strict=True)
            ]
        else:
            rows = [
                (tt, dd, nm, kd, qq[0], qq[1], qq[2], qq[3], ss, rr)
                for tt, dd, nm, kd, qq, ss, rr in zip(t.tolist(), dts, names, kinds, ql, st,
                                                      raws, strict=True)
            ]
        self._append(rows)

    def _session_of(self, store: Store) -> int:
        return self._sid

    def _sensor_id(self, conn, name: str, kind: str, new: dict[str, int]) -> int:
        sid = self._sensor_ids.get(name)
        if sid is None:
            sid = new.get(name)
        if sid is None:
            sid = self._store.samples.sensor_id(conn, self.session_id, name, kind)
            new[name] = sid
        return sid

    def _write(self, rows: list) -> None:
        sid = self.session_id
        new: dict[str, int] = {}  # sensors created in this transaction: cached after commit
        with self._store.transaction() as conn:
            params = [
                {
                    "session_id": sid,
                    "sensor_id": self._sensor_id(conn, nm, kd, new),
                    "t": t, "device_t": dt, "w": w, "x": x, "y": y, "z": z, "status": st,
                }
                for (t, dt, nm, kd, w, x, y, z, st, _) in rows
            ]
            if any(r[9] is not None for r in rows):  # executemany: the same keys in every row
                for p, r in zip(params, rows, strict=True):
                    p.update(zip(S.RAW_COLUMNS, _NO_RAW if r[9] is None else r[9], strict=True))
            self._store.samples.insert(conn, params)
            t_max = max(self._t_max, max(r[0] for r in rows))
            # the newest sample's t on the Unix clock, never after this commit
            wall, mono = time.time(), time.monotonic()
            values = {"last_sample_at": min(wall, wall - (mono - t_max))}
            dropped = self.dropped
            if dropped != self._dropped_written:
                values["dropped"] = int(dropped)
            self._heartbeat(conn, **values)
        self._t_max = t_max
        self._dropped_written = dropped
        self._sensor_ids.update(new)

    def _write_extra(self) -> None:
        dropped = self.dropped
        if dropped != self._dropped_written or self._idle_due():
            with self._store.transaction() as conn:
                self._heartbeat(conn, dropped=int(dropped))
            self._dropped_written = dropped


def _raw_row(raw: Sequence[float] | np.ndarray, name: str, t: float) -> tuple | None:
    """One raw reading as column values (NaN -> None), or None when it has no value."""
    r = np.asarray(raw, dtype=np.float64).reshape(-1)
    if r.shape != (9,):
        raise RigConfigError(f"sample of {name!r} at t={t}: raw must have 9 values "
                             f"(acc, gyr, mag x/y/z), got {r.shape[0]}")
    if np.isinf(r).any():
        raise RigConfigError(f"sample of {name!r} at t={t}: raw reading must be finite "
                             f"(NaN for none), got {r.tolist()}")
    vals = r.tolist()
    if all(v != v for v in vals):  # all NaN: no raw reading
        return None
    return tuple(None if v != v else v for v in vals)


def _raw_rows(raw: np.ndarray | None, n: int, t: np.ndarray) -> list | None:
    """N raw readings as column-value tuples (NaN -> None; a NaN row -> None), or None when
    no sample has one."""
    if raw is None:
        return None
    r = np.asarray(raw, dtype=np.float64)
    if r.shape != (n, 9):
        raise RigConfigError(f"add_many: raw must have shape ({n}, 9), got {r.shape}")
    inf = np.isinf(r).any(axis=1)
    if inf.any():
        i = int(np.argmax(inf))
        raise RigConfigError(f"add_many: sample {i} (t={t[i]}): raw reading must be finite "
                             f"(NaN for none), got {r[i].tolist()}")
    nan = np.isnan(r)
    has = ~nan.all(axis=1)
    if not has.any():
        return None
    if nan.any():
        obj = r.astype(object)
        obj[nan] = None
        vals = obj.tolist()
    else:
        vals = r.tolist()
    return [tuple(v) if h else None for v, h in zip(vals, has.tolist(), strict=True)]


class TelemetryWriter(_BatchWriter):
    """Batched per-cycle telemetry of a live-loop run; ``add`` never blocks on the database.

    ``add(row)`` takes a dict: keys in :data:`rig.store.schema.TELEMETRY_COLUMNS` (``t_s``
    required; ``cycle``, ``target_w..z``, ``commanded_w..z``, ``present_w..z``, ``read_ms``,
    ``compute_ms``, ``write_ms``, ``cycle_ms``, ``correction_deg``, ``violation_deg``,
    ``intervention``, ``fault``) go to their columns; any other key is kept in the ``extra``
    JSON column. The dict is not copied: do not mutate it after ``add``.
    """

    _kind = "telemetry"

    def __init__(self, store: Store, run_id: int, *, flush_interval_s: float = 0.5) -> None:
        self.run_id = int(run_id)
        super().__init__(store, flush_interval_s=flush_interval_s, max_latency_s=None)

    def _session_of(self, store: Store) -> int:
        return int(store.runs.get(self.run_id)["session_id"])

    def add(self, row: Mapping[str, Any]) -> None:
        """Queue one cycle's row (cheap: an append under a lock)."""
        self._append([row])

    def add_many(self, rows: Sequence[Mapping[str, Any]]) -> None:
        self._append(list(rows))

    def _convert(self, row: Mapping[str, Any], joints: list[dict]) -> dict:
        out: dict[str, Any] = {"run_id": self.run_id}
        extra: dict[str, Any] = {}
        per_joint: dict[str, dict[str, Any]] = {}
        for k, v in row.items():
            if k in _TELEMETRY_SET:
                out[k] = _plain(v)
                continue
            split = _joint_key(k)
            if split is None:
                extra[k] = _plain(v)
            else:
                per_joint.setdefault(split[0], {})[split[1]] = _plain(v)
        if out.get("t_s") is None:
            raise RigConfigError(f"telemetry row without t_s: {dict(row)!r:.120}")
        if "intervention" in out:
            out["intervention"] = int(bool(out["intervention"]))
        if out.get("fault") is not None:
            out["fault"] = str(out["fault"])
        for k in _FLOAT_COLUMNS:
            v = out.get(k)
            if v is not None and not math.isfinite(float(v)):
                out[k] = None  # SQL NULL: not measured / not applicable
        out["extra"] = (
            json.dumps(extra, sort_keys=True, default=_plain, allow_nan=True) if extra else None
        )
        if per_joint:
            cycle = out.get("cycle")
            if cycle is None:
                raise RigConfigError(f"per-joint telemetry without cycle: {dict(row)!r:.120}")
            for name, values in per_joint.items():
                jr = {"run_id": self.run_id, "cycle": int(cycle), "joint": name}
                for c in S.JOINT_TELEMETRY_COLUMNS:
                    v = values.get(c)
                    if c == "intervention":
                        jr[c] = 0 if v is None else int(v)
                    else:
                        jr[c] = None if v is None or not math.isfinite(float(v)) else float(v)
                joints.append(jr)
        return out

    def _write(self, rows: list) -> None:
        joints: list[dict] = []
        params = [self._convert(r, joints) for r in rows]
        keys = set().union(*(p.keys() for p in params))
        for p in params:  # executemany needs the same keys in every row
            for k in keys:
                p.setdefault(k, 0 if k == "intervention" else None)
        with self._store.transaction() as conn:
            self._store.runs.insert_telemetry(conn, params)
            if joints:
                self._store.runs.insert_joint_telemetry(conn, joints)
            self._heartbeat(conn)


_TELEMETRY_SET = frozenset(S.TELEMETRY_COLUMNS)
_JOINT_SUFFIXES = tuple((f"_{c}", c) for c in S.JOINT_TELEMETRY_COLUMNS)


def _joint_key(key: str) -> tuple[str, str] | None:
    """``("elbow", "commanded_w")`` for a limb run's per-joint key ``elbow_commanded_w``; None
    for any other key."""
    for suffix, column in _JOINT_SUFFIXES:
        if key.endswith(suffix) and len(key) > len(suffix):
            return key[:-len(suffix)], column
    return None
_FLOAT_COLUMNS = tuple(
    c for c in S.TELEMETRY_COLUMNS if c not in ("cycle", "intervention", "fault")
)


def _plain(v: Any) -> Any:
    if isinstance(v, np.generic):
        return v.item()
    if isinstance(v, np.ndarray):
        return v.tolist()
    return v
