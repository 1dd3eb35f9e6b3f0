"""Shared fixtures.

``no_leaks`` (autouse) fails any test that leaves a thread, a child process or a pseudo-terminal
running: simulators must be shut down by the test (context managers, fixtures), never left to
the interpreter's exit. ``pg_server`` / ``db_url``: the store on SQLite and on a private
PostgreSQL server. ``rig_cli``: runs ``rig ARGS`` in-process and returns (exit status, stdout,
stderr). ``sim_leg`` / ``sim_leg_motion``: a simulated leg and 180 s of its motion, shared.
Hypothesis runs derandomized, without an example database (the ``ci`` profile, at the end of
this file).
"""

from __future__ import annotations

import os
import threading
import time

import pytest


@pytest.fixture
def rig_cli(capsys):
    """``rig_cli(args)`` runs ``rig`` with ``args`` in this process (the entry point
    :func:`rig.cli.main`, which always exits) and returns ``(exit status, stdout, stderr)``."""
    from rig.cli import main

    def run(args):
        with pytest.raises(SystemExit) as exc:
            main([str(a) for a in args])
        out = capsys.readouterr()
        return exc.value.code, out.out, out.err

    return run


@pytest.fixture(scope="session")
def sim_leg():
    """A simulated leg (``anatomical_limb(11, "leg")``: the hip and ankle coupled to the knee)
    without sensor errors."""
    from rig.sim.limb import NoiseModel, SimulatedWholeLimb
    from rig.sim.patients import anatomical_limb

    return SimulatedWholeLimb(anatomical_limb(11, "leg"), seed=11, noise=NoiseModel.ideal())


@pytest.fixture(scope="session")
def sim_leg_motion(sim_leg):
    """``(t, q)``: 180 s of :func:`sim_leg`'s true joint orientations at 25 Hz."""
    import numpy as np

    t = np.arange(0.0, 180.0, 0.04)
    return t, sim_leg.joints(t)


def _open_ptys() -> set[str]:
    found = set()
    fd_dir = "/proc/self/fd"
    try:
        names = os.listdir(fd_dir)
    except OSError:  # not Linux
        return found
    for name in names:
        try:
            target = os.readlink(os.path.join(fd_dir, name))
        except OSError:
            continue
        if target.startswith("/dev/pts/") or target == "/dev/ptmx":
            found.add(f"fd {name} -> {target}")
    return found


def _children() -> set[int]:
    kids: set[int] = set()
    task_dir = f"/proc/{os.getpid()}/task"
    try:
        tasks = os.listdir(task_dir)
    except OSError:
        return kids
    for tid in tasks:
        try:
            with open(f"{task_dir}/{tid}/children") as fh:
                kids.update(int(p) for p in fh.read().split())
        except OSError:
            continue
    # zombies already reaped by the test do not count; running ones do
    alive = set()
    for pid in kids:
        try:
            with open(f"/proc/{pid}/stat") as fh:
                if fh.read().split(") ", 1)[1][0] != "Z":
                    alive.add(pid)
        except OSError:
            continue
    return alive


@pytest.fixture(autouse=True)
def no_leaks():
    threads_before = set(threading.enumerate())
    ptys_before = _open_ptys()
    kids_before = _children()
    yield
    # a thread that was told to stop may need a moment to return from its last call
    deadline = time.monotonic() + 2.0
    for t in threading.enumerate():
        if t not in threads_before and t.is_alive():
            t.join(max(0.0, deadline - time.monotonic()))
    extra_threads = [t for t in threading.enumerate() if t not in threads_before and t.is_alive()]
    extra_ptys = _open_ptys() - ptys_before
    extra_kids = _children() - kids_before
    problems = []
    if extra_threads:
        problems.append(f"threads left running: {[t.name for t in extra_threads]}")
    if extra_ptys:
        problems.append(f"pseudo-terminals left open: {sorted(extra_ptys)}")
    if extra_kids:
        problems.append(f"child processes left running: {sorted(extra_kids)}")
    if problems:
        pytest.fail("; ".join(problems))


def pytest_collection_modifyitems(config, items):
    """Skip ``@pytest.mark.hardware`` tests unless an environment variable names a real port."""
    has_port = any(os.environ.get(v) for v in ("RIG_DXL_PORT", "RIG_IMU_PORT"))
    if has_port:
        return
    skip = pytest.mark.skip(reason="no hardware: set RIG_DXL_PORT or RIG_IMU_PORT to a real port")
    for item in items:
        if "hardware" in item.keywords:
            item.add_marker(skip)


# =============================================================================================
# PostgreSQL server for the store tests (owner: store helper; nothing above depends on it).
#
# ``pg_server`` (session scope) starts a throw-away PostgreSQL cluster with the distribution's
# binaries (Debian: /usr/lib/postgresql/<version>/bin, package ``postgresql``; or the directory
# in RIG_PG_BINDIR): initdb + pg_ctl into a temporary directory, listening on a unix socket in
# that directory only (no TCP port), as the ``postgres`` user when the tests run as root. Tests
# skip cleanly when the binaries or the psycopg driver are missing; with RIG_REQUIRE_PG=1 (set
# by .ci/run after installing the package) a server that does not start fails instead.
# ``db_url`` is parametrised over both back ends: a fresh SQLite file, a fresh PG database.
# =============================================================================================
import glob as _glob  # noqa: E402  (this block is appended; see its header)
import shutil as _shutil  # noqa: E402
import subprocess as _subprocess  # noqa: E402
import tempfile as _tempfile  # noqa: E402


def _pg_bindir() -> str | None:
    candidates = []
    if os.environ.get("RIG_PG_BINDIR"):
        candidates.append(os.environ["RIG_PG_BINDIR"])

    def _ver(p: str) -> float:
        try:
            return float(p.rstrip("/").split("/")[-2])
        except ValueError:
            return 0.0

    candidates += sorted(_glob.glob("/usr/lib/postgresql/*/bin"), key=_ver, reverse=True)
    on_path = _shutil.which("initdb")
    if on_path:
        candidates.append(os.path.dirname(on_path))
    for d in candidates:
        if os.access(os.path.join(d, "initdb"), os.X_OK) and os.access(
            os.path.join(d, "pg_ctl"), os.X_OK
        ):
            return d
    return None


class PostgresServer:
    """A private PostgreSQL cluster on a unix socket; ``new_database()`` -> SQLAlchemy URL."""

    def __init__(self, bindir: str) -> None:
        self.bindir = bindir
        self.dir = _tempfile.mkdtemp(prefix="rig-pg-")
        self.data = os.path.join(self.dir, "data")
        self.log = os.path.join(self.dir, "server.log")
        self.user = None  # OS user running the server; None = this process's user
        self._n = 0
        if os.geteuid() == 0:
            import pwd

            try:
                pw = pwd.getpwnam("postgres")
            except KeyError:
                self.cleanup()
                pytest.skip("running as root and no 'postgres' user to run PostgreSQL as")
            self.user = "postgres"
            os.chown(self.dir, pw.pw_uid, pw.pw_gid)

    def _run(self, *args: str, timeout: float = 120) -> _subprocess.CompletedProcess:
        cmd = [os.path.join(self.bindir, args[0]), *args[1:]]
        if self.user:
            cmd = ["runuser", "-u", self.user, "--", *cmd]
        env = dict(os.environ, LC_ALL="C", LANG="C")
        return _subprocess.run(
            cmd, cwd=self.dir, env=env, capture_output=True, text=True, timeout=timeout
        )

    def start(self) -> None:
        r = self._run("initdb", "-D", self.data, "-A", "trust", "-U", "rig", "-E", "UTF8",
                      "--no-locale", "--no-sync")
        if r.returncode != 0:
            raise RuntimeError(f"initdb failed: {r.stderr.strip()[-800:]}")
        opts = (f"-c listen_addresses='' -c unix_socket_directories='{self.dir}' "
                "-c fsync=off -c synchronous_commit=off -c full_page_writes=off "
                "-c max_connections=40")
        r = self._run("pg_ctl", "-D", self.data, "-l", self.log, "-w", "-t", "60",
                      "-o", opts, "start")
        if r.returncode != 0:
            log = ""
            try:
                with open(self.log) as fh:
                    log = fh.read()[-800:]
            except OSError:
                pass
            raise RuntimeError(f"pg_ctl start failed: {r.stderr.strip()[-400:]} {log}")

    def url(self, dbname: str) -> str:
        return f"postgresql+psycopg://rig@/{dbname}?host={self.dir}"

    def new_database(self) -> str:
        """Create an empty database and return its URL."""
        import psycopg

        self._n += 1
        name = f"rigtest_{os.getpid()}_{self._n}"
        with psycopg.connect(host=self.dir, user="rig", dbname="postgres",
                             autocommit=True) as conn:
            conn.execute(f'CREATE DATABASE "{name}"')
        return self.url(name)

    def stop(self) -> None:
        if os.path.isdir(self.data):
            self._run("pg_ctl", "-D", self.data, "-m", "immediate", "-w", "stop", timeout=60)

    def cleanup(self) -> None:
        _shutil.rmtree(self.dir, ignore_errors=True)


@pytest.fixture(scope="session")
def pg_server():
    """A running private PostgreSQL server, or a skip saying why there is none."""
    bindir = _pg_bindir()
    if bindir is None:
        pytest.skip("PostgreSQL binaries not installed (Debian: apt-get install postgresql)")
    try:
        import psycopg  # noqa: F401
    except ImportError:
        pytest.skip("psycopg not installed (pip install 'psycopg[binary]')")
    server = PostgresServer(bindir)
    try:
        server.start()
    except (RuntimeError, OSError, _subprocess.TimeoutExpired) as err:
        server.stop()
        server.cleanup()
        if os.environ.get("RIG_REQUIRE_PG"):
            pytest.fail(f"PostgreSQL did not start: {err}")
        pytest.skip(f"PostgreSQL did not start: {err}")
    try:
        yield server
    finally:
        server.stop()
        server.cleanup()


@pytest.fixture(params=["sqlite", "postgresql"])
def db_url(request, tmp_path) -> str:
    """A fresh, empty store location on each back end: a SQLite file path, a PG URL."""
    if request.param == "sqlite":
        return str(tmp_path / "rig.db")
    return request.getfixturevalue("pg_server").new_database()


# =============================================================================================
# Hypothesis: deterministic property tests.
#
# The project rule is "tests are deterministic; property tests derandomized in CI". The ``ci``
# profile is therefore loaded by default, for plain ``pytest`` too: ``derandomize=True`` (the
# examples follow from each test's name, the same on every run and machine), no example
# database (a failure found once is not replayed on every later run from a ``.hypothesis/``
# directory; it is fixed at its root and, if worth keeping, pinned with ``@example``) and no
# deadline (shared CI machines are slow). ``HYPOTHESIS_PROFILE=dev`` opts out: fresh random
# examples on every run, still without a database; a failure prints its ``@reproduce_failure``
# line. Hypothesis's own cache files (e.g. the constants it collects from the code under test)
# go to a temporary directory removed at exit, never into the tree — unless
# HYPOTHESIS_STORAGE_DIRECTORY names a place for them.
#
# Note: Hypothesis also draws constants found in the project's modules that are imported at the
# time; a run of one file and a run of the whole suite may therefore try different examples —
# each is reproducible on its own.
# =============================================================================================
import atexit as _atexit  # noqa: E402  (this block is appended; see its header)

from hypothesis import settings as _hyp_settings  # noqa: E402
from hypothesis.configuration import set_hypothesis_home_dir as _set_hyp_home  # noqa: E402

_hyp_settings.register_profile(
    "ci", derandomize=True, database=None, deadline=None, print_blob=True
)
_hyp_settings.register_profile(
    "dev", derandomize=False, database=None, deadline=None, print_blob=True
)
_hyp_settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE") or "ci")

if not os.environ.get("HYPOTHESIS_STORAGE_DIRECTORY"):
    _hyp_home = _tempfile.mkdtemp(prefix="rig-hypothesis-")
    os.environ["HYPOTHESIS_STORAGE_DIRECTORY"] = _hyp_home  # child processes too
    _set_hyp_home(_hyp_home)
    _atexit.register(_shutil.rmtree, _hyp_home, True)
