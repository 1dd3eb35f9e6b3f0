"""The session store: one small class in front of SQLAlchemy Core.

``open_store(url_or_path)`` gives a :class:`Store` on

* a plain path or ``sqlite:///PATH`` -- an embedded SQLite file (the default), or
* ``postgresql://user@host/db`` -- a PostgreSQL server (driver: psycopg 3, extra ``pg``).

Nothing else in the project writes SQL. Every method takes and returns plain Python types or
numpy arrays; rows come back as dicts.

SQLite set-up (applied to every connection) and why:

* ``journal_mode=WAL``: readers (``rig session list`` in another terminal) never block the
  recorder's commits, and a commit is one append to the ``-wal`` file.
* ``synchronous=FULL``: each commit fsyncs the WAL. A ``kill -9`` of the process loses nothing
  committed even with ``NORMAL`` (the OS keeps the written pages); ``FULL`` extends the same
  guarantee to power loss and OS crashes. The :class:`~rig.store.writers.SampleWriter` commits
  about twice a second, so the fsync costs a few milliseconds per second.
* ``foreign_keys=ON``, ``busy_timeout=10000`` (a second writer waits instead of failing).
* transactions are opened by the store itself (``BEGIN`` for reads, ``BEGIN IMMEDIATE`` for
  writes), so DDL is transactional and a migration is all-or-nothing.

A new SQLite file is created owner-only (``0600``) before SQLite opens it; SQLite gives its
``-wal`` and ``-shm`` files the permissions of the database file.

**Read-only files.** A database file this process may read but not write (an archived copy, a
colleague's file), or whose folder does not take the ``-wal`` and ``-shm`` files every writer
needs (an immutable folder, a read-only mount, a write-protected share), is opened read-only
(SQLite ``mode=ro``): every reading command works, and a command that would write says so in
one line. Where a WAL database cannot even be read that way (``mode=ro`` still needs a ``-shm``
file, which the folder will not take), it is opened ``immutable=1``: SQLite then takes no
locks and ignores any ``-wal`` file, which is safe only because nothing can write a database
in that folder; a ``-wal`` file left beside it with changes not yet in the database is refused
instead, with the way out (copy both files), so nothing it holds is silently left out. A
read-only file is not migrated: an older schema is refused with the way out (copy it somewhere
writable once). ``open_store(..., readonly=True)`` asks for the same on any file.

**Another application's database.** A SQLite file that holds tables but not the rig's
``schema_version`` (with its columns) is refused untouched, naming a few of its tables; only an
empty file (or a new one) becomes a rig database.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import math
import os
import re
import stat
import time
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

import numpy as np
from sqlalchemy import create_engine, event, func, select, text
from sqlalchemy.engine import Connection, Engine, make_url
from sqlalchemy.exc import (
    ArgumentError,
    DatabaseError,
    IntegrityError,
    NoSuchModuleError,
    OperationalError,
)
from sqlalchemy.pool import StaticPool

from rig.errors import RigConfigError, RigConnectionError
from rig.store import schema as S
from rig.store.liveness import STALE_AFTER_S, Liveness, Probe, judge, probe_process, this_writer

SESSION_KINDS = ("record", "enforce")
SESSION_STATUSES = ("running", "completed", "interrupted", "device_lost", "failed")
RUN_STATUSES = ("running", "completed", "interrupted", "safe_state", "failed")
SIDES = ("left", "right")


def _dumps(obj: Any) -> str:
    """JSON text of ``obj``; numpy scalars/arrays become numbers/lists; NaN is refused."""

    def default(o: Any) -> Any:
        if isinstance(o, np.ndarray):
            return o.tolist()
        if isinstance(o, np.generic):
            return o.item()
        if isinstance(o, Path):
            return str(o)
        raise TypeError(f"{type(o).__name__} is not JSON serialisable")

    try:
        return json.dumps({} if obj is None else obj, default=default, allow_nan=False,
                          sort_keys=True)
    except ValueError as err:
        raise RigConfigError(
            f"cannot store {obj!r:.80}: numbers must be finite (JSON has no NaN/inf)"
        ) from err
    except TypeError as err:
        raise RigConfigError(f"cannot store {obj!r:.80}: {err}") from err


def _loads(s: str | None) -> Any:
    return None if s is None else json.loads(s)


def describe_url(url_or_path: str | os.PathLike) -> str:
    """The database as shown to a person: a path, or a URL with its password hidden."""
    s = os.fspath(url_or_path)
    if "://" not in s:
        return s
    try:
        return make_url(s).render_as_string(hide_password=True)
    except ArgumentError:
        return s


def _sqlite_path(s: str) -> str | None:
    """Filesystem path of a SQLite URL or plain path; ``None`` for a URL of another scheme."""
    if s.startswith("sqlite://"):
        rest = s[len("sqlite://"):]
        if rest in ("", "/", "/:memory:"):
            return ":memory:"
        if not rest.startswith("/"):
            raise RigConfigError(f"bad SQLite URL {s!r}: use sqlite:///relative/path or "
                                 "sqlite:////absolute/path")
        return rest[1:].split("?", 1)[0]
    if "://" in s:
        return None
    return s


def _create_owner_only(path: Path) -> None:
    """Create an empty file readable and writable by its owner only (0600), atomically."""
    fd = os.open(path, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o600)
    try:
        os.fchmod(fd, 0o600)  # whatever the umask
    finally:
        os.close(fd)


def _readonly_reason(p: Path) -> str | None:
    """Why this process cannot write the existing database file ``p`` (None: it can). Every
    write needs the file and, for its ``-wal`` / ``-shm`` files, a folder that takes new files:
    tried, since permission bits do not stop root (an immutable folder or a read-only mount
    does)."""
    import errno

    from models.fileio import probe_folder

    try:
        os.close(os.open(p, os.O_WRONLY))  # neither created nor truncated: left as it is
    except OSError as err:
        return {errno.EROFS: "read-only file system",
                errno.EPERM: "the file may not be modified"}.get(err.errno, "no write permission")
    try:
        probe_folder(p.parent)
    except OSError:
        return "its folder does not take the -wal and -shm files a write needs"
    return None


def _readonly_connect(p: Path, shown: str):
    """A ``connect`` for SQLAlchemy's ``creator``: the file opened read-only (``mode=ro``),
    else (a WAL database whose ``-shm`` cannot be created) as immutable — unless a ``-wal``
    file beside it holds changes, which immutable would leave out."""
    import sqlite3
    from urllib.parse import quote

    uri = f"file:{quote(str(p.resolve()))}?mode=ro"

    def connect():
        conn = None
        try:
            conn = sqlite3.connect(uri, uri=True, check_same_thread=False, timeout=10.0)
            conn.execute("SELECT count(*) FROM sqlite_master").fetchall()
            return conn
        except sqlite3.OperationalError:
            if conn is not None:
                conn.close()
            wal = p.with_name(p.name + "-wal")
            if wal.exists() and wal.stat().st_size > 0:
                raise RigConfigError(
                    f"--db {shown}: read-only, and {wal.name} beside it holds changes not yet "
                    f"in the database that cannot be read without creating {p.name}-shm in a "
                    f"folder that takes no new files: copy {p.name} and {wal.name} to a "
                    "writable folder and open the copy") from None
            return sqlite3.connect(uri + "&immutable=1", uri=True, check_same_thread=False)

    return connect


def _refuse_foreign_file(p: Path, shown: str) -> None:
    """Refuse, before anything writes to it (not even the switch to WAL), a SQLite file that
    holds tables but no rig ``schema_version``; a file that is not SQLite at all too."""
    import sqlite3

    if p.stat().st_size == 0:
        return  # a new, empty file: it becomes a rig database
    try:
        conn = _readonly_connect(p, shown)()
        try:
            tables = sorted(r[0] for r in conn.execute(
                "SELECT name FROM sqlite_master WHERE type = 'table'"))
            cols = ({r[1] for r in conn.execute("PRAGMA table_info(schema_version)")}
                    if "schema_version" in tables else set())
        finally:
            conn.close()
    except sqlite3.DatabaseError as err:
        raise RigConfigError(f"--db {shown}: not a database the rig can read ({err})") from None
    if tables and not {"version", "applied_at", "description"} <= cols:
        listed = ", ".join(tables[:5]) + (", ..." if len(tables) > 5 else "")
        raise RigConfigError(
            f"--db {shown}: not a rig database (it holds another application's tables: "
            f"{listed}); left untouched — give a new file or a rig database")


def _sqlite_engine(path: str, create: bool,
                   readonly: bool | None) -> tuple[Engine, str | None]:
    """The engine of a SQLite file, and why it is read-only (None: it is not; with
    ``readonly=None``, when the file exists and this process cannot write it, see
    :func:`_readonly_reason`; ``readonly=False`` refuses such a file in one line)."""
    reason = None
    if path == ":memory:":
        engine = create_engine(
            "sqlite://", poolclass=StaticPool, connect_args={"check_same_thread": False}
        )
        readonly = False
    else:
        p = Path(path).expanduser()
        if p.is_dir():
            raise RigConfigError(f"--db {path}: is a directory, expected a database file")
        if not p.exists():
            if not create:
                raise RigConfigError(
                    f"no database at {path} (a recording creates it: rig record --db {path})"
                )
            from models.errors import OutputPathError
            from models.fileio import check_output

            try:  # a folder that takes the file, its -wal and -shm
                check_output(p, "--db")
            except OutputPathError as err:
                raise RigConfigError(str(err)) from None
            try:
                _create_owner_only(p)
            except FileExistsError:
                pass  # another process created it between the check and here
            except OSError as err:
                raise RigConfigError(f"--db {path}: cannot create: {err.strerror}") from err
        elif not os.access(p, os.R_OK):
            raise RigConfigError(f"--db {path}: permission denied")
        if readonly:
            reason = "opened read-only"
        elif p.exists():
            reason = _readonly_reason(p)
            if reason is not None and readonly is False:
                raise RigConfigError(f"database {path} is read-only ({reason}): this command "
                                     "writes to it; copy it somewhere writable first")
            readonly = reason is not None
        if p.exists():
            _refuse_foreign_file(p, path)
        if readonly:
            if not p.exists():
                raise RigConfigError(f"no database at {path}")
            engine = create_engine("sqlite://", creator=_readonly_connect(p, path))
        else:
            engine = create_engine(
                f"sqlite:///{p}",
                connect_args={"check_same_thread": False, "timeout": 10.0},
            )

    @event.listens_for(engine, "connect")
    def _on_connect(dbapi_conn, _record):  # pragma: no cover - exercised by every test
        # the store opens transactions itself (see _begin): no implicit ones from pysqlite
        dbapi_conn.isolation_level = None
        cur = dbapi_conn.cursor()
        if path != ":memory:" and not readonly:
            cur.execute("PRAGMA journal_mode=WAL")
        cur.execute("PRAGMA synchronous=FULL")
        cur.execute("PRAGMA foreign_keys=ON")
        cur.execute("PRAGMA busy_timeout=10000")
        cur.close()

    @event.listens_for(engine, "begin")
    def _begin(conn):  # pragma: no cover - exercised by every test
        write = conn.get_execution_options().get("rig_write", False)
        conn.exec_driver_sql("BEGIN IMMEDIATE" if write else "BEGIN")

    return engine, (reason if readonly else None)


def _postgres_engine(s: str) -> Engine:
    url = make_url(s)
    if url.drivername in ("postgresql", "postgres"):
        url = url.set(drivername="postgresql+psycopg")
    try:
        return create_engine(url, pool_pre_ping=True)
    except (NoSuchModuleError, ModuleNotFoundError) as err:
        raise RigConfigError(
            f"--db {describe_url(s)}: PostgreSQL needs the psycopg driver "
            "(pip install 'jointlimits-rig[pg]')"
        ) from err


def open_store(url_or_path: str | os.PathLike, *, create: bool = True,
               readonly: bool | None = None) -> Store:
    """Open (and create or migrate) the store at ``url_or_path``.

    Parameters
    ----------
    url_or_path : str or path
        A filesystem path or ``sqlite:///PATH`` (SQLite, the default), or
        ``postgresql://user[:password]@host[:port]/dbname`` (also
        ``postgresql://user@/dbname?host=/socket/dir``).
    create : bool
        Create a missing SQLite file (owner-only, 0600). ``False`` makes a missing file a
        :class:`~rig.errors.RigConfigError` -- for commands that only read.
    readonly : bool or None
        Open a SQLite file read-only; None (default): when this process cannot write it or
        its folder (:attr:`Store.readonly_reason` says which). A read-only store refuses
        every write with a one-line error. False: a command that must write refuses such a
        file at once, in one line.

    Returns
    -------
    Store
        Migrated to :data:`~rig.store.schema.SCHEMA_VERSION` (a read-only one must already
        be); close it (or use ``with``).

    Raises
    ------
    RigConfigError
        Bad URL or path, missing file with ``create=False``, a database newer than this code,
        another application's database, a read-only database of an older schema.
    RigConnectionError
        The database server cannot be reached or the file cannot be opened.
    """
    s = os.fspath(url_or_path)
    if not s:
        raise RigConfigError("--db: empty database path")
    path = _sqlite_path(s)
    ro = None
    if path is not None:
        engine, ro = _sqlite_engine(path, create, readonly)
    elif s.startswith(("postgresql://", "postgresql+", "postgres://")):
        engine = _postgres_engine(s)
    else:
        scheme = s.split("://", 1)[0]
        raise RigConfigError(
            f"--db {describe_url(s)}: unsupported scheme {scheme!r}; use a file path, "
            "sqlite:///PATH or postgresql://USER@HOST/DB"
        )
    store = Store(engine, describe_url(s), readonly=ro is not None, readonly_reason=ro)
    try:
        store._migrate()
    except BaseException:
        store.close()
        raise
    return store


#: ``meta["kind"]`` of a stored boundary that is a whole limb file (``rig boundary --chain`` on
#: a session), not one joint's constraint
LIMB_BOUNDARY = "limb"


class Store:
    """Patients, sessions, samples, calibrations, boundaries, models, runs and telemetry.

    Thread-safe: every method checks a connection out of the engine's pool for its own
    transaction. Use :meth:`sample_writer` / :meth:`telemetry_writer` for high-rate rows.
    """

    def __init__(self, engine: Engine, display: str, *, readonly: bool = False,
                 readonly_reason: str | None = None) -> None:
        self.engine = engine
        self.url = display
        self.dialect = engine.dialect.name  # "sqlite" | "postgresql"
        self.readonly = bool(readonly)
        #: why a read-only store is read-only (``"no write permission"``, ...), for messages
        self.readonly_reason = readonly_reason or ("opened read-only" if readonly else None)
        self._closed = False

    # -- plumbing ------------------------------------------------------------------------
    def __enter__(self) -> Store:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Release every pooled connection (idempotent)."""
        if not self._closed:
            self._closed = True
            self.engine.dispose()

    def __repr__(self) -> str:
        return f"Store({self.url!r})"

    @contextlib.contextmanager
    def _tx(self, write: bool = True) -> Iterator[Connection]:
        """One transaction; database errors become :class:`RigConnectionError`."""
        if self._closed:
            raise RigConnectionError(f"store {self.url} is closed")
        if write and self.readonly:
            raise RigConfigError(f"database {self.url} is read-only ({self.readonly_reason}): "
                                 "this would change it; copy it somewhere writable first")
        try:
            with self.engine.connect() as conn:
                if write:
                    conn.execution_options(rig_write=True)
                with conn.begin():
                    yield conn
        except IntegrityError:
            raise  # the callers turn these into messages about the duplicate
        except OperationalError as err:
            detail = " ".join(str(err.orig).split())  # one line: psycopg adds hints
            raise RigConnectionError(f"database {self.url}: {detail}") from err
        except DatabaseError as err:  # e.g. "file is not a database"
            detail = " ".join(str(err.orig).split())
            raise RigConfigError(f"--db {self.url}: {detail}") from err

    def _migrate(self, target: int | None = None) -> None:
        target = S.SCHEMA_VERSION if target is None else target
        if self.readonly:
            with self._tx(write=False) as conn:
                self._refuse_foreign(conn)
                have = S.current_version(conn)
            if have != S.SCHEMA_VERSION:
                raise RigConfigError(
                    f"database {self.url} is read-only and has schema version {have}; this "
                    f"rig reads version {S.SCHEMA_VERSION}: copy it somewhere writable and "
                    "open it there once to upgrade it")
            return
        with self._tx(write=True) as conn:
            self._refuse_foreign(conn)
            if self.dialect == "postgresql":
                # one migrator at a time across processes
                conn.execute(text("SELECT pg_advisory_xact_lock(7274420)"))
            have = S.current_version(conn)
            if have > S.SCHEMA_VERSION:
                raise RigConfigError(
                    f"database {self.url} has schema version {have}, newer than this rig "
                    f"understands ({S.SCHEMA_VERSION}); upgrade jointlimits-rig"
                )
            if have < target:
                S.apply_migrations(conn, have, target)

    def _refuse_foreign(self, conn: Connection) -> None:
        """Refuse, untouched, a database that holds tables but is not a rig store."""
        from sqlalchemy import inspect

        ins = inspect(conn)
        tables = sorted(ins.get_table_names())
        if not tables:
            return
        ours = "schema_version" in tables and {"version", "applied_at", "description"} <= {
            c["name"] for c in ins.get_columns("schema_version")}
        if not ours:
            shown = ", ".join(tables[:5]) + (", ..." if len(tables) > 5 else "")
            raise RigConfigError(
                f"--db {self.url}: not a rig database (it holds another application's tables: "
                f"{shown}); left untouched — give a new file or a rig database")

    def schema_version(self) -> int:
        """The database's schema version."""
        with self._tx(write=False) as conn:
            return S.current_version(conn)

    def check_integrity(self) -> str:
        """``"ok"`` or the problems found (SQLite ``PRAGMA integrity_check``; PostgreSQL: "ok")."""
        if self.dialect != "sqlite":
            with self._tx(write=False) as conn:
                conn.execute(text("SELECT 1"))
            return "ok"
        with self._tx(write=False) as conn:
            rows = conn.exec_driver_sql("PRAGMA integrity_check").all()
        return "\n".join(str(r[0]) for r in rows)

    # -- patients ------------------------------------------------------------------------
    def add_patient(self, pseudonym: str, *, side: str | None = None,
                    notes: str | None = None) -> int:
        """Register a patient under a pseudonym and return its id.

        Only a pseudonym is stored -- the store has no name, birth-date or contact fields, and
        the mapping from pseudonym to person stays with the clinic. ``notes`` must not identify
        the patient either.
        """
        pseudonym = _check_text("pseudonym", pseudonym, 64)
        side = _check_choice("side", side, SIDES)
        try:
            with self._tx() as conn:
                res = conn.execute(
                    S.patients.insert().values(
                        pseudonym=pseudonym, side=side, notes=notes, created_at=time.time()
                    )
                )
                return int(res.inserted_primary_key[0])
        except IntegrityError as err:
            raise RigConfigError(f"patient {pseudonym!r} already exists in {self.url}") from err

    def ensure_patient(self, pseudonym: str, *, side: str | None = None) -> int:
        """The id of patient ``pseudonym``, registering it first if it is new."""
        found = self.find_patient(pseudonym)
        if found is not None:
            return int(found["id"])
        try:
            return self.add_patient(pseudonym, side=side)
        except RigConfigError:  # created concurrently
            found = self.find_patient(pseudonym)
            if found is None:
                raise
            return int(found["id"])

    def find_patient(self, pseudonym: str) -> dict | None:
        """The patient row with this pseudonym, or ``None``."""
        with self._tx(write=False) as conn:
            row = conn.execute(
                select(S.patients).where(S.patients.c.pseudonym == pseudonym)
            ).mappings().first()
        return None if row is None else dict(row)

    def get_patient(self, patient_id: int) -> dict:
        """The patient row ``patient_id`` (``id``, ``pseudonym``, ``side``, ``notes``...)."""
        with self._tx(write=False) as conn:
            row = conn.execute(
                select(S.patients).where(S.patients.c.id == int(patient_id))
            ).mappings().first()
        if row is None:
            raise RigConfigError(f"no patient {patient_id} in {self.url}")
        return dict(row)

    def list_patients(self) -> list[dict]:
        with self._tx(write=False) as conn:
            rows = conn.execute(select(S.patients).order_by(S.patients.c.id)).mappings().all()
        return [dict(r) for r in rows]

    # -- sessions ------------------------------------------------------------------------
    def start_session(
        self,
        patient_id: int,
        *,
        rig_name: str | None = None,
        joint: str | None = None,
        side: str | None = None,
        kind: str = "record",
        meta: Mapping[str, Any] | None = None,
    ) -> int:
        """Open a session (status ``running``) and return its id.

        The calling process is recorded as the session's writer (host name, pid, process
        start; :mod:`rig.store.liveness`) until a sample writer claims it.
        """
        kind = _check_choice("kind", kind, SESSION_KINDS)
        side = _check_choice("side", side, SIDES)
        self.get_patient(patient_id)
        me = this_writer()
        with self._tx() as conn:
            res = conn.execute(
                S.sessions.insert().values(
                    patient_id=int(patient_id), rig_name=rig_name, joint=joint, side=side,
                    kind=kind, status="running", started_at=time.time(), meta=_dumps(meta),
                    writer_host=me.host, writer_pid=me.pid, writer_start=me.start,
                )
            )
            return int(res.inserted_primary_key[0])

    def _claim_writer(self, session_id: int) -> None:
        """Record the calling process as the writer of ``session_id`` (a heartbeat too)."""
        me = this_writer()
        with self._tx() as conn:
            conn.execute(S.sessions.update().where(S.sessions.c.id == int(session_id)).values(
                writer_host=me.host, writer_pid=me.pid, writer_start=me.start,
                heartbeat_at=time.time(),
            ))

    def end_session(
        self,
        session_id: int,
        *,
        status: str = "completed",
        meta: Mapping[str, Any] | None = None,
        dropped: int | None = None,
    ) -> None:
        """Close a session: ``status`` (one of :data:`SESSION_STATUSES`), ``meta`` merged into
        the session's, ``dropped`` (samples lost before the store) recorded when given."""
        status = _check_choice("status", status, SESSION_STATUSES)
        cur = self.get_session(session_id)
        merged = dict(cur["meta"])
        merged.update(meta or {})
        values: dict[str, Any] = {"status": status, "ended_at": time.time(),
                                  "meta": _dumps(merged)}
        if dropped is not None:
            values["dropped"] = int(dropped)
        with self._tx() as conn:
            conn.execute(
                S.sessions.update().where(S.sessions.c.id == int(session_id)).values(**values)
            )

    def set_dropped(self, session_id: int, dropped: int) -> None:
        """Record how many samples were lost before reaching the store (sequence gaps, full
        queues); the count is shown by ``rig session list``."""
        with self._tx() as conn:
            conn.execute(
                S.sessions.update()
                .where(S.sessions.c.id == int(session_id))
                .values(dropped=int(dropped))
            )

    def get_session(self, session_id: int) -> dict:
        """The session row, ``meta`` decoded, plus ``pseudonym`` of its patient."""
        q = (
            select(S.sessions, S.patients.c.pseudonym)
            .join(S.patients, S.patients.c.id == S.sessions.c.patient_id)
            .where(S.sessions.c.id == int(session_id))
        )
        with self._tx(write=False) as conn:
            row = conn.execute(q).mappings().first()
        if row is None:
            raise RigConfigError(f"no session {session_id} in {self.url}")
        out = dict(row)
        out["meta"] = _loads(out["meta"])
        return out

    def list_sessions(self, *, stale_after_s: float = STALE_AFTER_S, now: float | None = None,
                      host: str | None = None, probe: Probe = probe_process,
                      patient: str | None = None, since: float | None = None,
                      limit: int | None = None) -> list[dict]:
        """Sessions, oldest first, with their patient's pseudonym and sample counts.

        ``patient`` keeps one pseudonym's, ``since`` those started at or after that Unix time,
        ``limit`` the newest that many (of those). The counts are the sensors' own (schema v5,
        kept by the sample writer), so a listing costs per session, not per sample.

        Each dict has the session columns plus ``pseudonym``, ``samples`` (total),
        ``samples_by_sensor`` ({name: count}), ``recording_s`` (the time the samples span: the
        devices' own clock where they stamp their samples, else the host's — for a recording
        made faster than real time, the patient's time), ``runs`` (number of live-loop runs),
        ``last_sample_at`` (Unix time of the newest sample, None when unknown) and
        ``liveness`` (``{"state", "reason"}``: for a ``running`` session ``live``,
        ``interrupted`` or ``unknown`` by :func:`rig.store.liveness.judge` with the keyword
        arguments given; ``ended`` otherwise).
        """
        sc = S.sessions.c
        q = (select(S.sessions, S.patients.c.pseudonym)
             .join(S.patients, S.patients.c.id == sc.patient_id))
        if patient is not None:
            q = q.where(S.patients.c.pseudonym == patient)
        if since is not None:
            q = q.where(sc.started_at >= float(since))
        q = q.order_by(sc.id.desc())
        if limit is not None:
            q = q.limit(int(limit))
        c = S.sensors.c
        with self._tx(write=False) as conn:
            rows = [dict(r) for r in conn.execute(q).mappings()][::-1]
            ids = [r["id"] for r in rows]
            sensors: dict[int, list] = {}
            nruns: dict[int, int] = {}
            for chunk in range(0, len(ids), 900):  # bound the IN list
                part = ids[chunk:chunk + 900]
                for row in conn.execute(
                        select(c.session_id, c.name, c.n_samples, c.first_t, c.last_t,
                               c.first_device_t, c.last_device_t)
                        .where(c.session_id.in_(part))):
                    sensors.setdefault(int(row[0]), []).append(row[1:])
                for sid, n in conn.execute(select(S.runs.c.session_id, func.count())
                                           .where(S.runs.c.session_id.in_(part))
                                           .group_by(S.runs.c.session_id)):
                    nruns[int(sid)] = int(n)
        for r in rows:
            mine = sensors.get(r["id"], [])
            r["meta"] = _loads(r["meta"])
            r["samples_by_sensor"] = dict(sorted((nm, int(n)) for nm, n, *_ in mine if n))
            r["samples"] = sum(r["samples_by_sensor"].values())
            r["recording_s"] = _span(mine)
            r["runs"] = nruns.get(r["id"], 0)
            r["last_sample_at"] = _last_sample_at(r)
            r["liveness"] = judge(r, host=host, now=now, stale_after_s=stale_after_s,
                                  probe=probe).as_dict()
        return rows

    def session_liveness(self, session_id: int, *, stale_after_s: float = STALE_AFTER_S,
                         now: float | None = None, host: str | None = None,
                         probe: Probe = probe_process) -> Liveness:
        """Whether the writer of ``session_id`` is alive (:func:`rig.store.liveness.judge`)."""
        return judge(self.get_session(session_id), host=host, now=now,
                     stale_after_s=stale_after_s, probe=probe)

    def close_interrupted(self, session_id: int, *, force: bool = False,
                          stale_after_s: float = STALE_AFTER_S, now: float | None = None,
                          host: str | None = None, probe: Probe = probe_process) -> dict:
        """Close a ``running`` session whose writer died (``kill -9``, power cut).

        The session gets status ``interrupted`` and ``ended_at`` = the Unix time of its last
        sample (without samples: its writer's last commit, else its start); its runs still
        ``running`` become ``interrupted`` with the same end. ``meta["recovered"]`` records
        what was judged and when. Samples, calibrations and annotations are untouched.

        Refused (:class:`RigConfigError`) when the session is not ``running``, or -- unless
        ``force`` -- when its writer is alive or cannot be judged (a session older than schema
        version 3). Returns ``{"id", "ended_at", "samples", "liveness"}``.
        """
        sess = self.get_session(session_id)
        if sess["status"] != "running":
            raise RigConfigError(f"session {session_id} is not running: it ended as "
                                 f"{sess['status']!r}")
        live = judge(sess, host=host, now=now, stale_after_s=stale_after_s, probe=probe)
        if not force and live.state == "live":
            raise RigConfigError(f"session {session_id} is still being written ({live.reason}); "
                                 "stop that recording, or use --force")
        if not force and live.state == "unknown":
            raise RigConfigError(f"session {session_id}: cannot tell whether it is still being "
                                 f"written ({live.reason}); make sure it is not, then use "
                                 "--force")
        n = self.sample_count(session_id)
        end = _last_sample_at(sess)
        if end is None and n:
            end = self._estimate_last_sample(session_id, sess)
        if end is None:
            end = max(float(sess["started_at"]),
                      float(sess["heartbeat_at"] or sess["started_at"]))
        meta = dict(sess["meta"])
        meta["recovered"] = {
            "liveness": live.state, "reason": live.reason, "forced": bool(force),
            "closed_at": time.time() if now is None else float(now),
            "end": "last sample" if n else "last commit",
        }
        with self._tx() as conn:
            res = conn.execute(
                S.sessions.update()
                .where((S.sessions.c.id == int(session_id)) & (S.sessions.c.status == "running"))
                .values(status="interrupted", ended_at=end, meta=_dumps(meta))
            )
            if res.rowcount != 1:
                raise RigConfigError(f"session {session_id} was ended meanwhile; not closed")
            conn.execute(
                S.runs.update()
                .where((S.runs.c.session_id == int(session_id)) & (S.runs.c.status == "running"))
                .values(status="interrupted", ended_at=end)
            )
        return {"id": int(session_id), "ended_at": end, "samples": n,
                "liveness": live.as_dict()}

    def _estimate_last_sample(self, session_id: int, sess: dict) -> float:
        """A session older than schema 3 has no clock offset: start + the samples' span."""
        with self._tx(write=False) as conn:
            lo, hi = conn.execute(
                select(func.min(S.samples.c.t), func.max(S.samples.c.t))
                .where(S.samples.c.session_id == int(session_id))
            ).one()
        return float(sess["started_at"]) + max(0.0, float(hi) - float(lo))

    # -- sensors and samples -------------------------------------------------------------
    def add_sensor(self, session_id: int, name: str, *, segment: str | None = None,
                   kind: str = "sensor", port: str | None = None) -> int:
        """Describe a data stream of the session (an IMU on ``segment``, or a joint) -> id."""
        name = _check_text("sensor name", name, 64)
        kind = _check_choice("kind", kind, ("sensor", "joint"))
        self.get_session(session_id)
        try:
            with self._tx() as conn:
                return self._insert_sensor(conn, int(session_id), name, segment, kind, port)
        except IntegrityError as err:
            raise RigConfigError(f"session {session_id} already has a sensor {name!r}") from err

    @staticmethod
    def _insert_sensor(conn: Connection, session_id: int, name: str, segment: str | None,
                       kind: str, port: str | None) -> int:
        res = conn.execute(
            S.sensors.insert().values(
                session_id=session_id, name=name, segment=segment, kind=kind, port=port
            )
        )
        return int(res.inserted_primary_key[0])

    def sensors(self, session_id: int) -> list[dict]:
        with self._tx(write=False) as conn:
            rows = conn.execute(
                select(S.sensors)
                .where(S.sensors.c.session_id == int(session_id))
                .order_by(S.sensors.c.id)
            ).mappings().all()
        return [dict(r) for r in rows]

    def sample_writer(self, session_id: int, *, flush_interval_s: float = 0.5):
        """A :class:`~rig.store.writers.SampleWriter` for ``session_id`` (close it)."""
        from rig.store.writers import SampleWriter

        self.get_session(session_id)
        return SampleWriter(self, int(session_id), flush_interval_s=flush_interval_s)

    def samples(self, session_id: int, name: str | None = None, *,
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
        self.get_session(session_id)
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
        out = _SampleArrays(n, by_id)
        # Nine more cells per row double the driver's fetch time even when they are all NULL,
        # so they are fetched only when some sample has a raw reading.
        with self._tx(write=False) as conn:
            raw = raw and conn.execute(_raw_probe(q.whereclause)).first() is not None
            if raw:
                q = q.add_columns(*(S.samples.c[c] for c in S.RAW_COLUMNS))
            for rows in _fetch_chunks(conn, q):
                out.add(rows, raw)
        return out.result()

    def raw(self, session_id: int, name: str) -> np.ndarray:
        """(N, 9) the raw readings of sensor ``name``'s samples, in arrival order (as in
        :meth:`samples`: NaN where none was stored), and nothing else — the columns the host's
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
        with self._tx(write=False) as conn:
            for rows in _fetch_chunks(conn, q):
                if k + len(rows) > len(out):  # more than the count said
                    out = np.concatenate((out[:k], np.empty((k + len(rows), 9))))
                out[k:k + len(rows)] = _nan_where_null(np.array(rows, dtype=object))
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
        with self._tx(write=False) as conn:
            return int(conn.execute(select(func.count()).select_from(S.samples)
                                    .where(where)).scalar_one())

    def recording_span(self, session_id: int) -> float | None:
        """The time a session's samples span, seconds (devices' clock where every stream has
        one, else the host's): the patient's time, also for a recording made faster than
        real time. None without samples."""
        c = S.sensors.c
        with self._tx(write=False) as conn:
            rows = conn.execute(select(c.name, c.n_samples, c.first_t, c.last_t,
                                       c.first_device_t, c.last_device_t)
                                .where(c.session_id == int(session_id))).all()
        return _span([tuple(r) for r in rows])

    def sample_count(self, session_id: int) -> int:
        """Samples of a session (the sensors' counts: no scan of the samples)."""
        with self._tx(write=False) as conn:
            return int(conn.execute(
                select(func.coalesce(func.sum(S.sensors.c.n_samples), 0))
                .where(S.sensors.c.session_id == int(session_id))
            ).scalar_one())

    # -- calibrations, annotations, boundaries, models -------------------------------------
    def add_calibration(self, session_id: int, kind: str, data: Mapping[str, Any],
                        residual_deg: float | None = None) -> int:
        """Store a calibration result (``data`` JSON-serialisable; arrays become lists)."""
        kind = _check_text("calibration kind", kind, 64)
        self.get_session(session_id)
        res_deg = None if residual_deg is None else _finite("residual_deg", residual_deg)
        with self._tx() as conn:
            res = conn.execute(S.calibrations.insert().values(
                session_id=int(session_id), kind=kind, data=_dumps(data),
                residual_deg=res_deg, created_at=time.time(),
            ))
            return int(res.inserted_primary_key[0])

    def calibrations(self, session_id: int) -> list[dict]:
        with self._tx(write=False) as conn:
            rows = conn.execute(
                select(S.calibrations).where(S.calibrations.c.session_id == int(session_id))
                .order_by(S.calibrations.c.id)
            ).mappings().all()
        return [dict(r, data=_loads(r["data"])) for r in rows]

    def add_annotation(self, session_id: int, t: float, text_: str) -> int:
        """A clinician's note at time ``t`` (s, the samples' clock)."""
        self.get_session(session_id)
        with self._tx() as conn:
            res = conn.execute(S.annotations.insert().values(
                session_id=int(session_id), t=_finite("t", t), text=str(text_),
                created_at=time.time(),
            ))
            return int(res.inserted_primary_key[0])

    def annotations(self, session_id: int) -> list[dict]:
        with self._tx(write=False) as conn:
            rows = conn.execute(
                select(S.annotations).where(S.annotations.c.session_id == int(session_id))
                .order_by(S.annotations.c.t, S.annotations.c.id)
            ).mappings().all()
        return [dict(r) for r in rows]

    def add_boundary(self, session_id: int | None, constraint_yaml: str,
                     meta: Mapping[str, Any] | None = None) -> int:
        """Store an extracted boundary: the constraint file's YAML text and its provenance.
        ``session_id`` is ``None`` for a boundary extracted from an imported file."""
        if not isinstance(constraint_yaml, str) or not constraint_yaml.strip():
            raise RigConfigError("boundary: constraint_yaml must be non-empty YAML text")
        if session_id is not None:
            self.get_session(session_id)
        with self._tx() as conn:
            res = conn.execute(S.boundaries.insert().values(
                session_id=None if session_id is None else int(session_id),
                constraint_yaml=constraint_yaml, meta=_dumps(meta), created_at=time.time(),
            ))
            return int(res.inserted_primary_key[0])

    def get_boundary(self, boundary_id: int) -> dict:
        with self._tx(write=False) as conn:
            row = conn.execute(
                select(S.boundaries).where(S.boundaries.c.id == int(boundary_id))
            ).mappings().first()
        if row is None:
            raise RigConfigError(f"no boundary {boundary_id} in {self.url}")
        return dict(row, meta=_loads(row["meta"]))

    def boundaries(self, session_id: int, *, limb: bool | None = None) -> list[dict]:
        """The boundaries stored with a session, oldest first: every one, or (``limb``) only
        the whole-limb files (``meta.kind`` ``"limb"``, :data:`LIMB_BOUNDARY`) or only the
        single joints' constraints."""
        with self._tx(write=False) as conn:
            rows = conn.execute(
                select(S.boundaries).where(S.boundaries.c.session_id == int(session_id))
                .order_by(S.boundaries.c.id)
            ).mappings().all()
        out = [dict(r, meta=_loads(r["meta"])) for r in rows]
        if limb is None:
            return out
        return [r for r in out if ((r["meta"] or {}).get("kind") == LIMB_BOUNDARY) == limb]

    def add_model(self, path: str | os.PathLike, *, sha256: str | None = None,
                  metrics: Mapping[str, Any] | None = None, boundary_id: int | None = None,
                  session_id: int | None = None) -> int:
        """Register a trained model file: its path, SHA-256 (computed from the file when not
        given) and metrics; linked to the boundary it learned and/or the session."""
        path = os.fspath(path)
        if sha256 is None:
            sha256 = file_sha256(path)
        sha256 = str(sha256).lower()
        if len(sha256) != 64 or any(c not in "0123456789abcdef" for c in sha256):
            raise RigConfigError(f"model {path}: sha256 must be 64 hex digits, got {sha256!r}")
        if boundary_id is not None:
            self.get_boundary(boundary_id)
        if session_id is not None:
            self.get_session(session_id)
        with self._tx() as conn:
            res = conn.execute(S.models.insert().values(
                boundary_id=boundary_id, session_id=session_id, path=path, sha256=sha256,
                metrics=_dumps(metrics), created_at=time.time(),
            ))
            return int(res.inserted_primary_key[0])

    def get_model(self, model_id: int) -> dict:
        with self._tx(write=False) as conn:
            row = conn.execute(
                select(S.models).where(S.models.c.id == int(model_id))
            ).mappings().first()
        if row is None:
            raise RigConfigError(f"no model {model_id} in {self.url}")
        return dict(row, metrics=_loads(row["metrics"]))

    def models_for(self, *, boundary_id: int | None = None,
                   session_id: int | None = None) -> list[dict]:
        q = select(S.models).order_by(S.models.c.id)
        if boundary_id is not None:
            q = q.where(S.models.c.boundary_id == int(boundary_id))
        if session_id is not None:
            q = q.where(S.models.c.session_id == int(session_id))
        with self._tx(write=False) as conn:
            rows = conn.execute(q).mappings().all()
        return [dict(r, metrics=_loads(r["metrics"])) for r in rows]

    # -- live loop -------------------------------------------------------------------------
    def start_run(self, session_id: int, meta: Mapping[str, Any] | None = None) -> int:
        """Open a live-loop run (status ``running``) within a session."""
        self.get_session(session_id)
        with self._tx() as conn:
            res = conn.execute(S.runs.insert().values(
                session_id=int(session_id), status="running", started_at=time.time(),
                meta=_dumps(meta),
            ))
            return int(res.inserted_primary_key[0])

    def end_run(self, run_id: int, summary: Mapping[str, Any] | None = None, *,
                status: str = "completed") -> None:
        """Close a run with its end-of-run summary (``rate_hz``, ``cycles``, ``p99_cycle_ms``)."""
        status = _check_choice("status", status, RUN_STATUSES)
        self.get_run(run_id)
        with self._tx() as conn:
            conn.execute(S.runs.update().where(S.runs.c.id == int(run_id)).values(
                status=status, ended_at=time.time(), summary=_dumps(summary),
            ))

    def get_run(self, run_id: int) -> dict:
        with self._tx(write=False) as conn:
            row = conn.execute(
                select(S.runs).where(S.runs.c.id == int(run_id))
            ).mappings().first()
        if row is None:
            raise RigConfigError(f"no run {run_id} in {self.url}")
        return dict(row, meta=_loads(row["meta"]), summary=_loads(row["summary"]))

    def runs(self, session_id: int) -> list[dict]:
        with self._tx(write=False) as conn:
            rows = conn.execute(
                select(S.runs).where(S.runs.c.session_id == int(session_id))
                .order_by(S.runs.c.id)
            ).mappings().all()
        return [dict(r, meta=_loads(r["meta"]), summary=_loads(r["summary"])) for r in rows]

    def telemetry_writer(self, run_id: int, *, flush_interval_s: float = 0.5):
        """A :class:`~rig.store.writers.TelemetryWriter` for ``run_id`` (close it)."""
        from rig.store.writers import TelemetryWriter

        self.get_run(run_id)
        return TelemetryWriter(self, int(run_id), flush_interval_s=flush_interval_s)

    def telemetry(self, run_id: int) -> dict[str, np.ndarray]:
        """Telemetry of a run in cycle order: one array per column of
        :data:`~rig.store.schema.TELEMETRY_COLUMNS` (float64, NaN for missing; ``fault`` and
        ``extra`` as object arrays, ``extra`` decoded)."""
        cols = [S.telemetry.c[n] for n in S.TELEMETRY_COLUMNS] + [S.telemetry.c.extra]
        q = select(*cols).where(S.telemetry.c.run_id == int(run_id)).order_by(S.telemetry.c.id)
        with self._tx(write=False) as conn:
            rows = conn.execute(q).all()
        names = [*S.TELEMETRY_COLUMNS, "extra"]
        data = list(zip(*rows, strict=True)) if rows else [() for _ in names]
        out: dict[str, np.ndarray] = {}
        for name, col in zip(names, data, strict=True):
            if name == "fault":
                out[name] = np.array(col, dtype=object)
            elif name == "extra":
                out[name] = np.array([_loads(v) for v in col], dtype=object)
            elif name in ("cycle", "intervention"):
                out[name] = np.array([-1 if v is None else v for v in col], dtype=np.int64)
            else:
                out[name] = np.array([np.nan if v is None else v for v in col], dtype=np.float64)
        return out


def _span(sensors: list) -> float | None:
    """The time a session's samples span (seconds) from its sensors' (name, n, first_t, last_t,
    first_device_t, last_device_t): on the devices' clock when every sensor with samples has
    one, else on the host's."""
    have = [x for x in sensors if x[1]]
    if not have:
        return None
    if all(x[4] is not None and x[5] is not None for x in have):
        return float(max(x[5] for x in have) - min(x[4] for x in have))
    return float(max(x[3] for x in have) - min(x[2] for x in have))


def _last_sample_at(row: Mapping[str, Any]) -> float | None:
    """Unix time of a session's newest sample as its writer stored it, kept within the
    session's life (after its start, not after its writer's last commit)."""
    t = row.get("last_sample_at")
    if t is None:
        return None
    t = max(float(t), float(row["started_at"]))
    beat = row.get("heartbeat_at")
    return t if beat is None else min(t, max(float(beat), float(row["started_at"])))


def _raw_probe(where):
    """A query giving one sample matching ``where`` that has a raw reading, if any. Its
    condition is the partial index ``ix_samples_raw``'s, so the database answers it from that
    index instead of scanning the samples."""
    has_raw = func.coalesce(*(S.samples.c[c] for c in S.RAW_COLUMNS)).is_not(None)
    return select(S.samples.c.id).where(where, has_raw).limit(1)


def _nan_where_null(cols: np.ndarray) -> np.ndarray:
    """An object array of numbers and ``None`` (SQL NULL) as float64, NaN for ``None``."""
    null = np.equal(cols, None)
    return np.where(null, np.nan, cols).astype(np.float64) if null.any() \
        else cols.astype(np.float64)


class _SampleArrays:
    """The arrays :meth:`Store.samples` returns, filled chunk by chunk (grown if the sensors'
    counts fall short, trimmed if they overshoot)."""

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
            c["raw"][k:k + m] = _nan_where_null(a[:, 8:17])
        self.n = k + m

    def result(self) -> dict[str, np.ndarray]:
        n, c = self.n, self.cols
        at = np.searchsorted(self.ids, c["sensor"][:n])
        # no raw reading at all: a read-only view of NaN, no memory per sample
        raw = c["raw"][:n] if "raw" in c else np.broadcast_to(np.nan, (n, 9))
        return {"t": c["t"][:n], "device_t": c["device_t"][:n], "name": self.names[at],
                "kind": self.kinds[at], "q": c["q"][:n], "status": c["status"][:n],
                "raw": raw}


def _fetch_chunks(conn: Connection, stmt, size: int = 65536):
    """Rows of a SELECT as lists of plain tuples, ``size`` at a time, from the driver's cursor
    in the caller's transaction (see :func:`_fetch_tuples`)."""
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


def _fetch_tuples(conn: Connection, stmt) -> list[tuple]:
    """Rows of a SELECT as plain tuples from the driver's cursor, in the caller's transaction.

    For bulk reads only: SQLAlchemy's Row objects cost about 20x more to turn into numpy
    arrays than tuples. The SQL is still SQLAlchemy's, compiled for the connection's dialect.
    """
    comp = stmt.compile(dialect=conn.dialect)
    params = (tuple(comp.params[k] for k in comp.positiontup) if comp.positional
              else comp.params)
    cur = conn.connection.dbapi_connection.cursor()
    try:
        cur.execute(comp.string, params)
        return cur.fetchall()
    finally:
        cur.close()


def file_sha256(path: str | os.PathLike) -> str:
    """Hex SHA-256 of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def file_mode(path: str | os.PathLike) -> int:
    """Permission bits of a file (``0o600`` for a store created here)."""
    return stat.S_IMODE(os.stat(path).st_mode)


_DATE = re.compile(r"(?<!\d)(\d{4}[-./]\d{1,2}[-./]\d{1,2}|\d{1,2}[-./]\d{1,2}[-./]\d{2,4}"
                   r"|(19|20)\d{2}(0[1-9]|1[0-2])(0[1-9]|[12]\d|3[01]))(?!\d)")


def pseudonym_concerns(pseudonym: str) -> list[str]:
    """What in a pseudonym looks like it identifies a person (empty when nothing does): a date
    (a birth date), two or more capitalised words (a name), an e-mail address or a phone
    number. Used to warn at the command line; the store keeps whatever it is given."""
    out = []
    if _DATE.search(pseudonym):
        out.append("a date (a birth date identifies a person)")
    words = [w for w in re.split(r"[\s,;_]+", pseudonym) if w]
    if sum(_name_like(w) for w in words) >= 2:
        out.append("a person's name")
    if re.search(r"[^@\s]+@[^@\s]+\.[a-z]{2,}", pseudonym, re.I):
        out.append("an e-mail address")
    if re.search(r"(\+|00)\d[\d ./-]{7,}", pseudonym) or re.search(r"\d{3}[ .-]\d{3,4}[ .-]\d{3,4}",
                                                                 pseudonym):
        out.append("a phone number")
    return out


def pseudonym_warning(pseudonym: str | None) -> str | None:
    """The warning a command prints for a pseudonym that looks like it identifies the person
    (:func:`pseudonym_concerns`), or None."""
    concerns = pseudonym_concerns(pseudonym) if pseudonym else []
    if not concerns:
        return None
    return (f"--patient {pseudonym!r} looks like it holds {' and '.join(concerns)}: the store "
            "is meant for pseudonyms only (e.g. P-0042); keep the link to the person outside it")


def _name_like(word: str) -> bool:
    """A capitalised word of letters (hyphenated parts too: Anna-Lena, O'Brien)."""
    parts = re.split(r"[-'’]", word)
    return len(word) >= 2 and parts[0] != "" and all(
        p.isalpha() and p[:1].isupper() and (len(p) == 1 or p[1:].islower())
        for p in parts if p)


def _check_text(what: str, value: Any, max_len: int) -> str:
    if not isinstance(value, str) or not value.strip():
        raise RigConfigError(f"{what} must be a non-empty string, got {value!r}")
    if len(value) > max_len:
        raise RigConfigError(f"{what} {value[:20]!r}... is longer than {max_len} characters")
    return value


def _check_choice(what: str, value: Any, choices: tuple[str, ...]) -> Any:
    if value is None and what == "side":
        return None
    if value not in choices:
        raise RigConfigError(f"{what} must be one of {', '.join(choices)}; got {value!r}")
    return value


def _finite(what: str, value: Any) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError) as err:
        raise RigConfigError(f"{what} must be a number, got {value!r}") from err
    if not math.isfinite(v):
        raise RigConfigError(f"{what} must be finite, got {value!r}")
    return v
