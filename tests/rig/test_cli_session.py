"""``rig session list`` and ``rig export`` as a user runs them."""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import subprocess
import sys

import numpy as np
import pytest

from rig.store import SampleWriter, open_store
from rig.store import schema as S
from rig.store.io import read_samples_csv, read_sto


@pytest.fixture
def db(tmp_path):
    path = tmp_path / "clinic.db"
    rng = np.random.default_rng(5)
    with open_store(path) as store:
        p1 = store.patients.add("P-0001", side="right")
        s1 = store.sessions.start(p1, rig_name="sim-imu", joint="shoulder", side="right")
        t = np.arange(200) / 400.0
        q = rng.normal(size=(200, 4))
        q /= np.linalg.norm(q, axis=1, keepdims=True)
        with SampleWriter(store, s1) as w:
            w.add_many(t, None, "thorax", "sensor", q)
            w.add_many(t, None, "humerus", "sensor", q[::-1])
            w.set_dropped(2)
        store.sessions.end(s1, status="completed")
        p2 = store.patients.add("P-0002")
        s2 = store.sessions.start(p2, rig_name="sim-shoulder", kind="enforce")
        store.runs.end(store.runs.start(s2), {"cycles": 0})
    return path


def test_session_list_filters_and_pages(db, rig_cli):
    code, out, err = rig_cli(["session", "list", "--db", str(db), "--patient", "P-0002"])
    assert code == 0 and "P-0002" in out and "P-0001" not in out
    code, out, _ = rig_cli(["session", "list", "--db", str(db), "--limit", "1", "--json"])
    assert [r["pseudonym"] for r in json.loads(out)] == ["P-0002"]  # the newest
    code, out, _ = rig_cli(["session", "list", "--db", str(db), "--since", "2999-01-01"])
    assert code == 0 and out.strip() == "no sessions"
    code, _, err = rig_cli(["session", "list", "--db", str(db), "--since", "yesterday"])
    assert code == 2 and "--since 'yesterday'" in err and err.count("\n") == 1


def test_session_list_shows_pseudonym_kind_counts_status(db, rig_cli):
    code, out, err = rig_cli(["session", "list", "--db", str(db)])
    assert code == 0 and err == ""
    lines = out.splitlines()
    assert lines[0].split() == ["id", "patient", "kind", "joint", "started", "recorded",
                                "samples", "last", "sample", "dropped", "status"]
    assert "0.5 s" in lines[1]  # the samples' span (0 to 199/400 s), not the wall clock
    assert "P-0001" in lines[1] and "record" in lines[1] and "right shoulder" in lines[1]
    assert "400 (humerus 200, thorax 200)" in lines[1] and "completed" in lines[1]
    assert "P-0002" in lines[2] and "enforce" in lines[2] and "1 run" in lines[2]
    assert "running (not ended)" in lines[2]  # written by this process: alive
    code, out, _ = rig_cli(["session", "list", "--db", str(db), "--json"])
    rows = json.loads(out)
    assert [r["samples"] for r in rows] == [400, 0] and rows[0]["dropped"] == 2


def test_missing_database_is_an_error_not_a_new_file(tmp_path, rig_cli):
    missing = tmp_path / "typo.db"
    code, out, err = rig_cli(["session", "list", "--db", str(missing)])
    assert code == 2 and out == ""
    assert err.startswith("rig: error: no database at") and err.count("\n") == 1
    assert not missing.exists()


def test_export_sto_and_csv(db, tmp_path, rig_cli):
    code, out, _ = rig_cli(["export", "--db", str(db), "--session", "1", "--format", "sto",
                            "--out", str(tmp_path / "s1.sto")])
    assert code == 0 and "wrote 200 rows (thorax_imu, humerus_imu)" in out
    table = read_sto(tmp_path / "s1.sto")
    with open_store(db, create=False) as store:
        np.testing.assert_array_equal(table.get("humerus"), store.samples.read(1, "humerus")["q"])
    code, out, _ = rig_cli(["export", "--db", str(db), "--session", "1",
                            "--out", str(tmp_path / "s1.csv")])  # format from the suffix
    assert code == 0 and "wrote 400 rows" in out
    assert read_samples_csv(tmp_path / "s1.csv")["t"].size == 400


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--session", "9", "--format", "sto"], "no session 9 in"),
        (["--session", "2", "--format", "csv"], "session 2 has no samples"),
        (["--session", "1", "--format", "c3d"], "Invalid value for '--format'"),
        (["--session", "1"], "cannot tell the format from the suffix"),
    ],
)
def test_export_mistakes_are_one_line_exit_2(db, tmp_path, args, message, rig_cli):
    code, out, err = rig_cli(["export", "--db", str(db), *args, "--out", str(tmp_path / "x.out")])
    assert code == 2, (out, err)
    assert err.startswith("rig: error:") and message in err and err.count("\n") == 1
    assert not (tmp_path / "x.out").exists()


def test_export_into_a_missing_directory(db, tmp_path, rig_cli):
    code, _, err = rig_cli(["export", "--db", str(db), "--session", "1", "--format", "sto",
                            "--out", str(tmp_path / "nope" / "x.sto")])
    assert code == 2 and "does not exist" in err


def test_session_list_through_the_console_script(db):
    """The installed entry point, as a person types it: no traceback on a bad URL."""
    r = subprocess.run([sys.executable, "-m", "rig", "session", "list", "--db", "mysql://x/y"],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 2
    assert r.stderr.strip().startswith("rig: error: --db mysql://x/y: unsupported scheme")
    assert "Traceback" not in r.stderr
    r = subprocess.run([sys.executable, "-m", "rig", "session", "list", "--db", str(db)],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 0 and "P-0001" in r.stdout


def test_session_list_on_postgresql(pg_server, rig_cli):
    url = pg_server.new_database()
    with open_store(url) as store:
        sid = store.sessions.start(store.patients.add("PG-1"))
        with SampleWriter(store, sid) as w:
            w.add(0.0, None, "humerus", "sensor", [1.0, 0, 0, 0])
    code, out, _ = rig_cli(["session", "list", "--db", url])
    assert code == 0 and "PG-1" in out and "1 (humerus 1)" in out


def _dead_pid() -> int:
    """The pid of a child that has exited and been reaped."""
    child = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                           capture_output=True, text=True, check=True, timeout=60)
    return int(child.stdout)


def _orphan(url, pid):
    """Session 2 of the fixture as a killed recorder leaves it: running, writer ``pid``."""
    with open_store(url, create=False) as store:
        with SampleWriter(store, 2) as w:
            w.add_many(np.arange(5) / 400.0, None, "humerus", "sensor",
                       np.tile([1.0, 0, 0, 0], (5, 1)))
        with store.engine.begin() as conn:  # then the writer process vanishes
            conn.execute(S.sessions.update().where(S.sessions.c.id == 2).values(writer_pid=pid))


def test_killed_session_is_listed_interrupted_and_closed(db, rig_cli):
    _orphan(db, _dead_pid())
    code, out, _ = rig_cli(["session", "list", "--db", str(db)])
    assert code == 0
    lines = out.splitlines()
    assert "interrupted (not closed)" in lines[2] and "5 (humerus 5)" in lines[2]
    assert lines[3].startswith("session 2: writer pid ") and "is gone" in lines[3]
    assert f"rig session close --db {db} --session 2" in lines[3]
    code, out, _ = rig_cli(["session", "list", "--db", str(db), "--json"])
    row = json.loads(out)[1]
    assert row["status"] == "running" and row["liveness"]["state"] == "interrupted"
    assert row["samples"] == 5 and row["last_sample_at"] is not None

    code, out, err = rig_cli(["session", "close", "--db", str(db), "--session", "2"])
    assert code == 0 and err == ""
    assert out.startswith("session 2 closed as interrupted: 5 samples, ended at its last "
                          "sample")
    with open_store(db, create=False) as store:
        s = store.sessions.get(2)
        assert s["status"] == "interrupted" and s["ended_at"] == row["last_sample_at"]
        assert [r["status"] for r in store.runs.list(2)] == ["completed"]  # it had ended
    code, out, _ = rig_cli(["session", "list", "--db", str(db)])
    assert out.splitlines()[2].endswith("interrupted") and len(out.splitlines()) == 3
    code, out, _ = rig_cli(["export", "--db", str(db), "--session", "2", "--format", "csv",
                            "--out", str(db.parent / "s2.csv")])
    assert code == 0 and "wrote 5 rows" in out


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--session", "2"], "session 2 is still being written (writer pid "),
        (["--session", "1"], "session 1 is not running: it ended as 'completed'"),
        (["--session", "7"], "no session 7 in"),
        (["--session", "2", "--stale-after", "0"], "--stale-after must be > 0 seconds"),
    ],
)
def test_close_mistakes_are_one_line_exit_2(db, args, message, rig_cli):
    code, out, err = rig_cli(["session", "close", "--db", str(db), *args])
    assert code == 2 and out == ""
    assert err.startswith("rig: error:") and message in err and err.count("\n") == 1
    with open_store(db, create=False) as store:
        assert store.sessions.get(2)["status"] == "running"


def test_close_live_session_with_force(db, rig_cli):
    code, out, _ = rig_cli(["session", "close", "--db", str(db), "--session", "2", "--force"])
    assert code == 0 and "closed as interrupted: 0 samples" in out
    assert f"writer pid {os.getpid()}" in out


def test_close_on_postgresql(pg_server, rig_cli):
    url = pg_server.new_database()
    with open_store(url) as store:
        s1 = store.sessions.start(store.patients.add("PG-1"))
        assert s1 == 1
        sid = store.sessions.start(store.patients.add("PG-2"))
        assert sid == 2
    _orphan(url, _dead_pid())
    code, out, _ = rig_cli(["session", "list", "--db", url])
    assert code == 0 and "interrupted (not closed)" in out.splitlines()[2]
    code, out, _ = rig_cli(["session", "close", "--db", url, "--session", "2"])
    assert code == 0 and "closed as interrupted: 5 samples" in out
    with open_store(url, create=False) as store:
        assert store.sessions.get(2)["status"] == "interrupted"


def _new_servo_db(path):
    """A small servo-limb recording (joint samples), ended, in a new store; its session id."""
    from rig.sim.patients import record_servo, seeded_patient, star_constraint

    rec = record_servo(seeded_patient(7, star_constraint(7)), 40.0, 50.0)
    with open_store(path) as store:
        sid = store.sessions.start(store.patients.add("P-RO"), rig_name="sim-shoulder",
                                   joint="shoulder", side="right")
        store.samples.add_sensor(sid, "shoulder", segment="humerus", kind="joint",
                                 port="sim://dynamixel")
        with SampleWriter(store, sid) as w:
            w.add_many(rec.t, None, "shoulder", "joint", rec.limb, 0)
        store.sessions.end(sid, status="completed")
        store.sessions.start(store.patients.add("P-RUN"), rig_name="sim-shoulder")  # not ended
    return sid


@pytest.fixture(scope="module")
def _servo_template(tmp_path_factory):
    """:func:`_new_servo_db` built once for the module: ``(path, session id)``. Closed, the
    store is the one file (its WAL checkpointed into it)."""
    path = tmp_path_factory.mktemp("servo") / "template.db"
    sid = _new_servo_db(path)
    assert sorted(p.name for p in path.parent.iterdir()) == ["template.db"]
    return path, sid


@pytest.fixture
def servo_db(_servo_template):
    """``servo_db(path)``: a copy of the module's servo-limb recording at ``path`` (a new
    file, as :func:`_new_servo_db` would write it); returns the recorded session's id."""
    template, sid = _servo_template

    def make(path):
        shutil.copyfile(template, path)
        return sid

    return make


def test_a_read_only_store_reads_and_refuses_writes_in_one_line(tmp_path, servo_db):
    sid = servo_db(tmp_path / "a.db")
    with open_store(tmp_path / "a.db", create=False, readonly=True) as store:
        assert store.readonly and store.sessions.list()[0]["samples"] > 1000
        assert store.samples.read(sid)["q"].shape[1] == 4
        with pytest.raises(Exception, match="is read-only") as err:
            store.patients.add("P-NEW")
        assert "\n" not in str(err.value)


# ``rig`` runs each list of arguments given in argv[1] (JSON) in turn, in this one process, as
# it would in a process of its own: its exit status, stdout and stderr (warnings shown afresh,
# an uncaught exception's traceback) go into the one JSON line printed at the end.
_BATCH = """
import contextlib, io, json, sys, traceback, warnings
from rig.cli import main
results = []
for args in json.loads(sys.argv[1]):
    out, err = io.StringIO(), io.StringIO()
    with warnings.catch_warnings(), contextlib.redirect_stdout(out), \\
            contextlib.redirect_stderr(err):
        try:
            main(args)
            code = 0
        except SystemExit as exc:
            code = exc.code
            if code is None:
                code = 0
            elif not isinstance(code, int):
                print(code, file=sys.stderr)
                code = 1
        except BaseException:
            traceback.print_exc()
            code = 1
    results.append([code, out.getvalue(), err.getvalue()])
print(json.dumps(results))
"""


def _rig_batch(commands, cwd, prefix=()):
    """Each of ``commands`` (argument lists) as ``rig`` runs it, all in ONE new Python process
    (under ``prefix``: a mount namespace of its own), in turn: a
    :class:`subprocess.CompletedProcess` each (exit status, stdout, stderr). The same files
    and permissions as a process per command, the interpreter's start-up (about 1 s) paid
    once; nothing written past the commands' own streams."""
    args = json.dumps([[str(a) for a in c] for c in commands])
    r = subprocess.run([*prefix, sys.executable, "-c", _BATCH, args], capture_output=True,
                       text=True, cwd=cwd, timeout=300)
    assert r.returncode == 0 and r.stderr == "" and r.stdout.count("\n") == 1, r
    return [subprocess.CompletedProcess(c, *res)
            for c, res in zip(commands, json.loads(r.stdout), strict=True)]


def test_an_archived_file_we_may_not_write_is_read_read_only(tmp_path, servo_db):
    # the user can read the file but not write it (as root, that takes another user)
    share = tmp_path / "share"
    share.mkdir()
    db = share / "archive.db"
    sid = servo_db(db)
    os.chmod(db, 0o444)
    immutable = False
    if os.geteuid() == 0:  # root writes any file it may read: make it immutable instead
        r = subprocess.run(["chattr", "+i", str(db)], capture_output=True, text=True)
        if r.returncode != 0:
            pytest.skip(f"cannot make a file read-only for root here: {r.stderr.strip()}")
        immutable = True
    assert not os.access(db, os.W_OK)
    before = db.read_bytes()
    try:
        listed, rom, boundary, close = _rig_batch([
            ("session", "list", "--db", db),
            ("rom", "--db", db, "--session", sid, "--json"),
            ("boundary", "--db", db, "--session", sid, "--out", share / "b.yaml"),
            ("session", "close", "--db", db, "--session", sid + 1, "--force")], cwd=share)
        assert listed.returncode == 0, listed.stderr
        assert "P-RO" in listed.stdout
        assert rom.returncode == 0, rom.stderr
        assert json.loads(rom.stdout)["flexion"] is not None
        assert boundary.returncode == 2 and "is read-only" in boundary.stderr
        assert "add --no-store" in boundary.stderr and boundary.stderr.count("\n") == 1
        assert close.returncode == 2 and "read-only" in close.stderr
        assert close.stderr.count("\n") == 1
        assert db.read_bytes() == before  # nothing changed
    finally:
        if immutable:
            subprocess.run(["chattr", "-i", str(db)], check=True)


@contextlib.contextmanager
def _write_protected(*paths):
    """``paths`` (files and folders) as on write-protected media: immutable for root, whom
    permission bits do not stop (skipped where ``chattr`` does not work), else ``0444`` /
    ``0555``; undone on the way out."""
    root = os.geteuid() == 0
    done = []
    try:
        for p in paths:
            if root:
                r = subprocess.run(["chattr", "+i", str(p)], capture_output=True, text=True)
                if r.returncode != 0:
                    pytest.skip(f"cannot make a file immutable here: {r.stderr.strip()}")
            else:
                p.chmod(0o555 if p.is_dir() else 0o444)
            done.append(p)
        yield
    finally:
        for p in reversed(done):
            if root:
                subprocess.run(["chattr", "-i", str(p)], check=True)
            else:
                p.chmod(0o755 if p.is_dir() else 0o644)


_RO_MOUNT = 'mount --bind "$0" "$0" && mount -o remount,ro,bind "$0" && exec "$@"'


@pytest.mark.parametrize("protected", ["file and folder", "folder", "read-only mount"])
def test_an_archive_on_write_protected_media_is_read(tmp_path, protected, servo_db):
    # the folder too: SQLite cannot create the WAL database's -shm (mode=ro alone fails)
    share, out = tmp_path / "share", tmp_path / "out"
    share.mkdir()
    out.mkdir()
    db = share / "archive.db"
    sid = servo_db(db)
    before = db.read_bytes()
    root = os.geteuid() == 0
    prefix: list[str] = []
    if protected == "read-only mount":  # the commands in a mount namespace of their own
        if not root:
            pytest.skip("a read-only bind mount needs root (the chmod variants run here)")
        prefix = ["unshare", "--mount", "sh", "-c", _RO_MOUNT, str(share)]
        r = subprocess.run([*prefix, "sh", "-c", f"! touch {share}/probe 2>/dev/null"],
                           capture_output=True, text=True)
        if r.returncode != 0:
            pytest.skip(f"no read-only bind mount here: {r.stderr.strip()}")
        protect, reason = contextlib.nullcontext(), "read-only file system"
    elif protected == "file and folder":
        protect = _write_protected(db, share)
        reason = "the file may not be modified" if root else "no write permission"
    else:
        protect = _write_protected(share)
        reason = "its folder does not take the -wal and -shm files"

    reads = [("session", "list", "--db", db), ("rom", "--db", db, "--session", sid, "--json")]
    if protected == "file and folder":  # the other cases open the same read-only way
        reads += [("export", "--db", db, "--session", sid, "--out", out / "s.csv"),
                  ("boundary", "--db", db, "--session", sid, "--no-store", "--out",
                   out / "b.yaml"),
                  ("report", "--db", db, "--session", sid, "--out", out / "r.html")]
    # what must write says so in one line, before any work
    writes = [("boundary", "--db", db, "--session", sid, "--out", out / "b2.yaml"),
              ("boundary", "--db", db, "--session", sid, "--limb", "arm",
               "--out", out / "limb.yaml"),
              ("session", "close", "--db", db, "--session", sid + 1, "--force"),
              ("record", "--rig", "sim-shoulder", "--db", db, "--patient", "P-2",
               "--duration", "1")]
    with protect:
        done = _rig_batch([*reads, *writes], cwd=out, prefix=prefix)
        r = done[0]
        assert r.returncode == 0 and "P-RO" in r.stdout, r.stderr
        r = done[1]
        assert r.returncode == 0 and json.loads(r.stdout)["flexion"] is not None, r.stderr
        if protected == "file and folder":
            r = done[2]
            assert r.returncode == 0 and read_samples_csv(out / "s.csv")["t"].size > 1000, \
                r.stderr
            r = done[3]
            assert r.returncode == 0 and (out / "b.yaml").is_file(), r.stderr
            r = done[4]
            assert r.returncode == 0 and (out / "r.html").is_file(), r.stderr
        for args, r in zip(writes, done[len(reads):], strict=True):
            assert r.returncode == 2 and r.stderr.count("\n") == 1, (args, r.stderr)
            assert f"is read-only ({reason}" in r.stderr, r.stderr
            assert "Traceback" not in r.stderr and "unable to open" not in r.stderr
            if args[0] == "boundary":
                assert "add --no-store" in r.stderr
        assert not (out / "b2.yaml").exists() and not (out / "limb.yaml").exists()
        assert sorted(p.name for p in share.iterdir()) == ["archive.db"]  # no -wal, -shm
    assert db.read_bytes() == before
    with open_store(db, create=False) as store:  # writable again: nothing was changed
        assert store.sessions.get(sid + 1)["status"] == "running"


def test_a_wal_left_beside_a_write_protected_archive_is_not_silently_left_out(tmp_path,
                                                                              servo_db):
    import sqlite3

    work, share = tmp_path / "work", tmp_path / "share"
    work.mkdir()
    share.mkdir()
    servo_db(work / "a.db")
    # a change still in the -wal when the files were archived (the writer never checkpointed)
    conn = sqlite3.connect(work / "a.db")
    conn.execute("PRAGMA wal_autocheckpoint=0")
    conn.execute("INSERT INTO patients (pseudonym, created_at) VALUES ('P-LATE', 0)")
    conn.commit()
    for name in ("a.db", "a.db-wal"):
        shutil.copy2(work / name, share / name)
    conn.close()
    assert (share / "a.db-wal").stat().st_size > 0
    with _write_protected(share / "a.db", share / "a.db-wal", share):
        with pytest.raises(Exception, match=r"a.db-wal beside it holds changes not yet in the "
                                            r"database .* copy a.db and a.db-wal") as err:
            open_store(share / "a.db", create=False)
        assert "\n" not in str(err.value)
    with open_store(share / "a.db", create=False) as store:  # copied somewhere writable: all there
        assert "P-LATE" in {s["pseudonym"] for s in store.patients.list()}


def test_another_applications_database_is_refused_untouched(tmp_path, rig_cli):
    import sqlite3

    other = tmp_path / "other.db"
    with sqlite3.connect(other) as conn:
        conn.execute("CREATE TABLE invoices (id INTEGER PRIMARY KEY, total REAL)")
        conn.execute("INSERT INTO invoices (total) VALUES (12.5)")
    before = other.read_bytes()
    code, _, err = rig_cli(["record", "--rig", "sim-shoulder", "--db", str(other), "--patient",
                            "P-1", "--duration", "1"])
    assert code == 2 and "not a rig database" in err and "invoices" in err
    assert err.count("\n") == 1
    code, _, err = rig_cli(["session", "list", "--db", str(other)])
    assert code == 2 and "not a rig database" in err
    assert other.read_bytes() == before
    with sqlite3.connect(other) as conn:
        assert [r[0] for r in conn.execute("SELECT name FROM sqlite_master")] == ["invoices"]


@pytest.mark.parametrize(("pseudonym", "what"), [
    ("John Smith 1970-01-01", "a date (a birth date identifies a person) and a person's name"),
    ("P-19700101", "a date"), ("Anna-Lena Müller", "a person's name"),
    ("jsmith@clinic.org", "an e-mail address"), ("+44 20 7946 0958", "a phone number"),
])
def test_a_pseudonym_that_looks_like_a_person_is_warned_about(tmp_path, pseudonym, what, rig_cli):
    from rig.store.pseudonyms import pseudonym_concerns

    assert pseudonym_concerns(pseudonym)[0].startswith(what.split(" and ")[0][:6])
    code, _, err = rig_cli(["record", "--rig", "sim-shoulder", "--db", str(tmp_path / "w.db"),
                              "--patient", pseudonym, "--duration", "0.3", "--no-calibration",
                              "--no-rom", "--display", "plain"])
    assert code == 0, err
    warnings = [ln for ln in err.splitlines() if ln.startswith("warning: --patient")]
    assert len(warnings) == 1 and what in warnings[0] and "pseudonyms only" in warnings[0]


@pytest.mark.parametrize("pseudonym", ["P-0042", "SIM-0000", "IMU-7", "patient 12", "BENCH"])
def test_ordinary_pseudonyms_are_not_warned_about(pseudonym):
    from rig.store.pseudonyms import pseudonym_concerns, pseudonym_warning

    assert pseudonym_concerns(pseudonym) == [] and pseudonym_warning(pseudonym) is None
