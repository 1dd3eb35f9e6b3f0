"""``rig serve`` under load on the loopback: 50 concurrent clients browsing reports and sessions.

    python benchmarks/bench_web_load.py [--clients 50] [--duration 60] [--patients 20]
                                        [--record 20]

A clinic store is written (``--patients`` patients, two servo visits of the right elbow each:
joint samples sweeping to known peaks, as tests/web/conftest.py writes them), the real
``rig serve`` starts in a child process on 127.0.0.1 (port 0, no access log), and each
session's report is asked for once (rendered into the server's cache; the time of that first
rendering is printed apart). Then ``--clients`` clients, each its own HTTP connection (httpx,
one asyncio task each), browse for ``--duration`` seconds with no pause: a page picked at
random among the patients list, a patient, a session, a session's report, and the JSON API's
patient — the way a clinic's screens would. Printed: requests, requests per second,
latency p50 / p99 / max (ms) overall and per kind of page, and errors (any answer but 200, or
a failed connection). The server and the clients share this machine's cores.

With ``--record S`` a recording runs meanwhile: ``rig record --rig sim-shoulder --duration S``
into the same store, started with the clients; printed are its samples, the samples its
writer dropped (the session's ``dropped``), its status, and whether it ended within the load.

Never asserts; figures depend on the machine and on what else runs on it.
"""

from __future__ import annotations

import argparse
import asyncio
import random
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import common  # first: one BLAS thread, this checkout on sys.path
import httpx
import numpy as np

from calibration.joint_angles import from_angles
from rig.store import SampleWriter, open_store

ROOT = common.ROOT
T0 = 1_780_000_000.0
DAY = 86_400.0


def _sweep(pos: float, neg: float, n: int = 120) -> np.ndarray:
    up = np.linspace(0.0, pos, n // 4)
    down = np.linspace(pos, -neg, n // 2)
    back = np.linspace(-neg, 0.0, n // 4)
    return np.concatenate([up, np.full(8, pos), down, np.full(8, -neg), back])


def build(db: Path, patients: int, rng: np.random.Generator) -> list[tuple[int, int]]:
    """The clinic: ``patients`` patients with two elbow visits each; (patient, session)
    pairs."""
    pairs = []
    with open_store(db) as store:
        for k in range(patients):
            pid = store.patients.add(f"P-{k:04d}", side="right")
            for visit in range(2):
                flex = float(100 + 10 * visit + rng.normal(0, 3))
                sid = store.sessions.start(pid, rig_name="sim-servo", joint="elbow",
                                           side="right", started_at=T0 + k * 60 + visit * 28 * DAY)
                store.samples.add_sensor(sid, "elbow", segment="elbow", kind="joint",
                                         port="sim://dynamixel")
                q = from_angles(_sweep(flex, 10.0), np.zeros(1), 0.0, "elbow", "right")
                with SampleWriter(store, sid) as w:
                    w.add_many(np.arange(len(q)) / 50.0, None, "elbow", "joint", q)
                store.sessions.end(sid, status="completed", meta={})
                pairs.append((pid, sid))
    return pairs


def start_server(db: Path, tmp: Path) -> tuple[subprocess.Popen, str]:
    log = tmp / "serve.log"
    with log.open("wb") as out:
        proc = subprocess.Popen([sys.executable, "-m", "rig", "serve", "--db", str(db),
                                 "--port", "0", "--no-access-log", "--cache", str(tmp / "cache")],
                                stdout=out, stderr=subprocess.STDOUT, cwd=ROOT,
                                env={**common.child_env(), "PYTHONUNBUFFERED": "1"})
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and proc.poll() is None:
        m = re.match(r"rig serve: (http://\S+?)/? ", log.read_text())
        if m:
            return proc, m.group(1)
        time.sleep(0.1)
    proc.kill()
    raise SystemExit(f"rig serve did not start: {log.read_text()}")


def pages(pairs: list[tuple[int, int]], rng: random.Random) -> tuple[str, str]:
    pid, sid = rng.choice(pairs)
    kind = rng.choice(("patients", "patient", "session", "report", "api"))
    return kind, {"patients": "/patients", "patient": f"/patients/{pid}",
                  "session": f"/patients/{pid}/sessions/{sid}",
                  "report": f"/patients/{pid}/sessions/{sid}/report",
                  "api": f"/api/patients/{pid}"}[kind]


async def client(url: str, pairs, seed: int, until: float, out: list, errors: list) -> None:
    rng = random.Random(seed)
    async with httpx.AsyncClient(base_url=url, timeout=60.0) as c:
        while time.monotonic() < until:
            kind, path = pages(pairs, rng)
            t = time.perf_counter()
            try:
                r = await c.get(path)
                ok = r.status_code == 200
                await r.aread()
            except httpx.HTTPError as err:
                ok = False
                r = err
            dt = time.perf_counter() - t
            if ok:
                out.append((kind, dt))
            else:
                errors.append((kind, path, str(getattr(r, "status_code", r))))


async def load(url: str, pairs, clients: int, duration: float) -> tuple[list, list, float]:
    out: list = []
    errors: list = []
    t0 = time.monotonic()
    until = t0 + duration
    await asyncio.gather(*(client(url, pairs, k, until, out, errors) for k in range(clients)))
    return out, errors, time.monotonic() - t0


def pct(xs: list[float], q: float) -> float:
    xs = sorted(xs)
    return 1000 * xs[min(len(xs) - 1, round(q / 100 * (len(xs) - 1)))]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--clients", type=int, default=50)
    ap.add_argument("--duration", type=float, default=60.0)
    ap.add_argument("--patients", type=int, default=20)
    ap.add_argument("--seed", type=int, default=43)
    ap.add_argument("--record", type=float, default=0.0,
                    help="a recording of this many seconds runs meanwhile (0: none)")
    a = ap.parse_args()
    print(f"machine: a Python loop of 10^7 additions {common.additions_s():.2f} s "
          f"({time.strftime('%Y-%m-%d %H:%M')})")
    with tempfile.TemporaryDirectory(prefix="bench-web-") as tmpdir:
        tmp = Path(tmpdir)
        t = time.perf_counter()
        pairs = build(tmp / "clinic.db", a.patients, np.random.default_rng(a.seed))
        print(f"clinic: {a.patients} patients, {len(pairs)} sessions "
              f"({time.perf_counter() - t:.1f} s to write)")
        proc, url = start_server(tmp / "clinic.db", tmp)
        try:
            with httpx.Client(base_url=url, timeout=120.0) as c:
                t = time.perf_counter()
                firsts = []
                for pid, sid in pairs:
                    t1 = time.perf_counter()
                    c.get(f"/patients/{pid}/sessions/{sid}/report").raise_for_status()
                    firsts.append(time.perf_counter() - t1)
                print(f"reports rendered once into the cache: {len(pairs)} in "
                      f"{time.perf_counter() - t:.1f} s (median {statistics.median(firsts):.2f} "
                      "s each)")
            rec = None
            if a.record:
                rec = subprocess.Popen(
                    [sys.executable, "-m", "rig", "record", "--rig", "sim-shoulder", "--db",
                     str(tmp / "clinic.db"), "--patient", "P-REC", "--duration",
                     f"{a.record:g}"], stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                    stderr=(tmp / "record.err").open("wb"), cwd=ROOT, env=common.child_env())
            t_load = time.monotonic()
            out, errors, wall = asyncio.run(load(url, pairs, a.clients, a.duration))
            if rec is not None:
                within = rec.poll() is not None
                rc = rec.wait()
                took = time.monotonic() - t_load
                with open_store(tmp / "clinic.db", create=False) as store:
                    s = store.sessions.list(patient="P-REC")[-1]
                print(f"recording meanwhile (rig record --rig sim-shoulder --duration "
                      f"{a.record:g}): exit {rc}, {s['samples']} samples, dropped "
                      f"{s['dropped']}, status {s['status']}, took {took:.1f} s "
                      f"({'within' if within else 'beyond'} the load)")
        finally:
            proc.terminate()
            proc.wait(30)
    lat = [dt for _, dt in out]
    n = len(out) + len(errors)
    print(f"{a.clients} clients for {wall:.1f} s on {url}: {n} requests, "
          f"{n / wall:.1f} requests/s, errors {len(errors)}")
    if lat:
        print(f"latency ms: p50 {pct(lat, 50):.1f}  p99 {pct(lat, 99):.1f}  "
              f"max {1000 * max(lat):.1f}")
    for kind in ("patients", "patient", "session", "report", "api"):
        ks = [dt for k, dt in out if k == kind]
        if ks:
            print(f"  {kind:9s} {len(ks):6d} requests  p50 {pct(ks, 50):7.1f}  "
                  f"p99 {pct(ks, 99):7.1f} ms")
    for e in errors[:5]:
        print("  error:", *e)


if __name__ == "__main__":
    main()
