"""The session store: the database, and one repository per concern on it.

``open_store(url_or_path)`` gives a :class:`Store` on

* a plain path or ``sqlite:///PATH`` -- an embedded SQLite file (the default), or
* ``postgresql://user@host/db`` -- a PostgreSQL server (driver: psycopg 3, extra ``pg``).

The :class:`Store` holds what is the database's: the engine (opened by :mod:`rig.store.engine`,
which says how SQLite is set up and how read-only files are opened), transactions, the schema
version and its migrations, read-only handling, closing. What is kept in it is reached through
its repositories (``store.patients``, ``store.sessions``, ``store.samples``, ...; see
:mod:`rig.store`), each the only writer of its tables' SQL.

A read-only file is not migrated: an older schema is refused with the way out (copy it
somewhere writable once). ``open_store(..., readonly=True)`` asks for the same on any file.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator

from sqlalchemy import inspect, text
from sqlalchemy.engine import Connection, Engine
from sqlalchemy.exc import DatabaseError, IntegrityError, OperationalError

from rig.errors import RigConfigError, RigConnectionError
from rig.store import schema as S
from rig.store.annotations import AnnotationRepository
from rig.store.boundaries import BoundaryRepository
from rig.store.calibrations import CalibrationRepository
from rig.store.engine import describe_url, postgres_engine, sqlite_engine, sqlite_path
from rig.store.jobs import JobRepository
from rig.store.patients import PatientRepository
from rig.store.runs import RunRepository
from rig.store.samples import SampleRepository
from rig.store.sessions import SessionRepository
from rig.store.trained_models import ModelRepository


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
    path = sqlite_path(s)
    ro = None
    if path is not None:
        engine, ro = sqlite_engine(path, create, readonly)
    elif s.startswith(("postgresql://", "postgresql+", "postgres://")):
        engine = postgres_engine(s)
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


class Store:
    """The database of patients, sessions, samples, calibrations, boundaries, models, runs
    and telemetry, and its repositories.

    Thread-safe: every repository method checks a connection out of the engine's pool for its
    own transaction. High-rate rows go through a :class:`~rig.store.writers.SampleWriter` or a
    :class:`~rig.store.writers.TelemetryWriter`.

    Attributes
    ----------
    patients : PatientRepository
        Pseudonymised patients.
    sessions : SessionRepository
        Recording and enforcement sessions, their writers and liveness.
    samples : SampleRepository
        A session's sensors and their samples.
    calibrations : CalibrationRepository
        Calibration results of a session.
    annotations : AnnotationRepository
        A clinician's notes in a session.
    boundaries : BoundaryRepository
        Extracted boundaries (constraint and limb files).
    models : ModelRepository
        Trained model files.
    runs : RunRepository
        Live-loop runs and their per-cycle telemetry.
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
        self.patients = PatientRepository(self)
        self.samples = SampleRepository(self)
        self.runs = RunRepository(self)
        self.sessions = SessionRepository(self, self.patients, self.samples)
        self.calibrations = CalibrationRepository(self)
        self.annotations = AnnotationRepository(self)
        self.boundaries = BoundaryRepository(self)
        self.models = ModelRepository(self)
        self.jobs = JobRepository(self)

    # -- the database ------------------------------------------------------------------------
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
    def transaction(self, write: bool = True) -> Iterator[Connection]:
        """One transaction (``write``: ``BEGIN IMMEDIATE`` on SQLite, refused on a read-only
        store); database errors become :class:`RigConnectionError` (a ``UNIQUE`` violation
        stays an :class:`~sqlalchemy.exc.IntegrityError` for the caller to name)."""
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
            with self.transaction(write=False) as conn:
                self._refuse_foreign(conn)
                have = S.current_version(conn)
            if have != S.SCHEMA_VERSION:
                raise RigConfigError(
                    f"database {self.url} is read-only and has schema version {have}; this "
                    f"rig reads version {S.SCHEMA_VERSION}: copy it somewhere writable and "
                    "open it there once to upgrade it")
            return
        with self.transaction(write=True) as conn:
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
        with self.transaction(write=False) as conn:
            return S.current_version(conn)

    def check_integrity(self) -> str:
        """``"ok"`` or the problems found (SQLite ``PRAGMA integrity_check``; PostgreSQL: "ok")."""
        if self.dialect != "sqlite":
            with self.transaction(write=False) as conn:
                conn.execute(text("SELECT 1"))
            return "ok"
        with self.transaction(write=False) as conn:
            rows = conn.exec_driver_sql("PRAGMA integrity_check").all()
        return "\n".join(str(r[0]) for r in rows)

