"""Opening a store's database: a SQLite file or a PostgreSQL URL, as an SQLAlchemy engine.

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
instead, with the way out (copy both files), so nothing it holds is silently left out.

**Another application's database.** A SQLite file that holds tables but not the rig's
``schema_version`` (with its columns) is refused untouched, naming a few of its tables; only an
empty file (or a new one) becomes a rig database.
"""

from __future__ import annotations

import errno
import os
import sqlite3
from pathlib import Path
from urllib.parse import quote

from sqlalchemy import create_engine, event
from sqlalchemy.engine import Engine, make_url
from sqlalchemy.exc import ArgumentError, NoSuchModuleError
from sqlalchemy.pool import StaticPool

from models.errors import OutputPathError
from models.fileio import check_output, probe_folder
from rig.errors import RigConfigError


def describe_url(url_or_path: str | os.PathLike) -> str:
    """The database as shown to a person: a path, or a URL with its password hidden."""
    s = os.fspath(url_or_path)
    if "://" not in s:
        return s
    try:
        return make_url(s).render_as_string(hide_password=True)
    except ArgumentError:
        return s


def sqlite_path(s: str) -> str | None:
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


def sqlite_engine(path: str, create: bool,
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


def postgres_engine(s: str) -> Engine:
    """The engine of a PostgreSQL URL (driver: psycopg 3)."""
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
