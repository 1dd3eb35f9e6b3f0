"""What the web app's HTTP tests share: a small clinic store, and the real ``rig serve`` started
as a child process on 127.0.0.1, port 0 (a free port, read from its first line), talked to over
HTTP.

``clinic_store(path)`` writes two patients: P-0042 with two servo sessions of the right elbow
(two visits: a progress), P-0043 with one session that has a stored boundary, a limb file and
a registered model file (the downloads). Joint samples sweep to known peaks as in
tests/rig/test_progress.py; no simulator runs.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import httpx
import numpy as np

from calibration.joint_angles import from_angles
from rig.store import SampleWriter, open_store

ROOT = Path(__file__).resolve().parents[2]
T0 = 1_780_000_000.0  # 2026-05-28
DAY = 86_400.0
CONSTRAINT = "name: downloaded\n"  # stored text: the download sends it back unchanged


def _sweep(pos: float, neg: float, n: int = 120) -> np.ndarray:
    up = np.linspace(0.0, pos, n // 4)
    down = np.linspace(pos, -neg, n // 2)
    back = np.linspace(-neg, 0.0, n // 4)
    return np.concatenate([up, np.full(8, pos), down, np.full(8, -neg), back])


def _session(store, pid: int, t: float, flex: float, ext: float) -> int:
    sid = store.sessions.start(pid, rig_name="sim-servo", joint="elbow", side="right",
                               started_at=t)
    store.samples.add_sensor(sid, "elbow", segment="elbow", kind="joint", port="sim://dynamixel")
    q = from_angles(_sweep(flex, ext), np.zeros(1), 0.0, "elbow", "right")
    with SampleWriter(store, sid) as w:
        w.add_many(np.arange(len(q)) / 50.0, None, "elbow", "joint", q)
    store.sessions.end(sid, status="completed", meta={})
    return sid


def clinic_store(db: Path) -> dict:
    """Write the test clinic into a new store at ``db``; returns the ids."""
    model = db.parent / "p43.onnx"
    model.write_bytes(b"not a real model: the download sends these bytes")
    with open_store(db) as store:
        a = store.patients.add("P-0042", side="right")
        b = store.patients.add("P-0043")
        s1 = _session(store, a, T0, 100, 10)
        s3 = _session(store, b, T0 + 500, 110, 5)
        s2 = _session(store, a, T0 + 28 * DAY, 122, 12)
        bid = store.boundaries.add(s3, CONSTRAINT)
        store.boundaries.add(s3, "name: limb\n", meta={"kind": "limb"})
        store.models.add(model, sha256=hashlib.sha256(model.read_bytes()).hexdigest(),
                         boundary_id=bid, session_id=s3)
    return {"p42": a, "p43": b, "p42_visits": (s1, s2), "p43_session": s3, "model": model}


#: the tables a refused request must leave as they were
TABLES = ("patients", "sessions", "boundaries", "models", "samples")


def snapshot(tmp, cache) -> tuple:
    """The store's rows (hashed per table) and every file of the server's cache."""
    con = sqlite3.connect(f"file:{tmp / 'clinic.db'}?mode=ro", uri=True)
    try:
        rows = {t: hashlib.sha256(repr(con.execute(f"SELECT * FROM {t} ORDER BY id")
                                       .fetchall()).encode()).hexdigest() for t in TABLES}
    finally:
        con.close()
    files = sorted(str(p.relative_to(cache)) for p in cache.rglob("*") if p.is_file())
    return rows, files


class Server:
    """``rig serve`` in a child process; ``url``, ``log()`` (what it printed so far: its URL
    line, uvicorn's messages and access log)."""

    def __init__(self, args: list[str], tmp: Path) -> None:
        self.logfile = tmp / f"serve-{len(list(tmp.glob('serve-*.log')))}.log"
        env = {**os.environ, "PYTHONUNBUFFERED": "1", "OMP_NUM_THREADS": "1"}
        with self.logfile.open("wb") as out:
            self.proc = subprocess.Popen(
                [sys.executable, "-m", "rig", "serve", "--port", "0", *args],
                stdout=out, stderr=subprocess.STDOUT, cwd=ROOT, env=env)
        deadline = time.monotonic() + 60.0
        while True:  # the first line names the URL once the socket listens
            first = self.log().split("\n", 1)[0]
            if first.startswith("rig serve: http://") or self.proc.poll() is not None:
                break
            if time.monotonic() > deadline:
                break
            time.sleep(0.05)
        if not first.startswith("rig serve: http://"):
            self.stop()
            raise RuntimeError(f"rig serve did not start: {self.log()}")
        self.url = first.split()[2].rstrip("/")

    def log(self) -> str:
        return self.logfile.read_text(errors="replace")

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()


@contextlib.contextmanager
def running(args: list[str], tmp: Path):
    server = Server(args, tmp)
    try:
        yield server
    finally:
        server.stop()


def client(server: Server) -> httpx.Client:
    """A client with the CSRF cookie (from a first GET); its token in ``headers``."""
    c = httpx.Client(base_url=server.url, timeout=60.0)
    c.get("/login")
    c.headers["x-csrftoken"] = c.cookies["csrftoken"]
    return c

