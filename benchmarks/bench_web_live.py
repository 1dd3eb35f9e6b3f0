"""The live coverage view: sample-to-screen latency in a real browser, and samples dropped with
ten viewers open during a recording.

    python benchmarks/bench_web_live.py [--seconds 30] [--viewers 10] [--rig sim-imu]

A real uvicorn server on 127.0.0.1 (the live router on the minimal app of
``tests/web/server.py``), a real SQLite store, the shipped simulated rig at its real rate (the
simulated patient on the host's clock), and Debian's headless Chromium under Selenium.

Latency: each ``status`` event (the counters) and ``coverage`` event (the swing map, refreshed
by the recorder about 4 times a second) carries the newest sample's host time (its ``t``, put on the
Unix clock); the page, when it has drawn the event (the animation frame after the DOM update),
notes ``performance.timeOrigin + performance.now()``; both clocks are this machine's.
Selenium reads the page's list (``window.rigLive.draws``) at the end. Two recordings of
``--seconds`` each, without calibration (the recording proper from the start):

1. one viewer (the browser tab);
2. ``--viewers`` viewers: the tab plus ``viewers - 1`` raw Server-Sent-Event clients reading
   the same stream — latency in the tab, and samples dropped: the recorder's own counts
   (samples written, sequence gaps at the device, queue overflow) against the samples the
   session holds in the store.

Target p95 <= 250 ms and 0 samples dropped. Figures are printed, never asserted.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import threading
import time
import urllib.request
from pathlib import Path

import common  # first: one BLAS thread, this checkout on sys.path
import numpy as np
from selenium.webdriver.common.by import By
from selenium.webdriver.support.ui import Select, WebDriverWait

from rig.store import open_store
from tests.web.browser import quit_chromium, start_chromium
from tests.web.server import live_app, serving


def _sse_client(base: str, job_id: int, counts: dict, key: int) -> None:
    """A raw viewer: reads the job's stream to its end, counting events."""
    req = urllib.request.Request(f"{base}/api/jobs/{job_id}/events")
    n = 0
    with urllib.request.urlopen(req, timeout=600) as resp:
        for line in resp:
            if line.startswith(b"event: "):
                n += 1
                if line.startswith(b"event: end"):
                    break
    counts[key] = n


def _record(drv, base: str, patient: int, rig: str, seconds: float, viewers: int) -> dict:
    drv.get(f"{base}/record?patient={patient}")
    Select(drv.find_element(By.NAME, "rig")).select_by_value(rig)
    drv.find_element(By.NAME, "duration_s").send_keys(str(seconds))
    box = drv.find_element(By.NAME, "calibrate")
    if box.is_selected():
        box.click()
    drv.find_element(By.ID, "start").click()
    WebDriverWait(drv, 60).until(lambda d: d.execute_script(
        "return document.getElementById('job') && window.rigLive;"))
    job_id = int(drv.find_element(By.ID, "job").get_attribute("data-job"))
    counts: dict[int, int] = {}
    clients = [threading.Thread(target=_sse_client, args=(base, job_id, counts, k), daemon=True)
               for k in range(viewers - 1)]
    for c in clients:
        c.start()
    end = WebDriverWait(drv, seconds + 120, poll_frequency=0.5).until(
        lambda d: d.execute_script("return window.rigLive.ended;"))
    for c in clients:
        c.join(60)
    draws = drv.execute_script("return window.rigLive.draws;")
    lat = {what: np.array([d["drawn_ms"] - d["sample_ms"] for d in draws if d["what"] == what],
                          dtype=np.float64) for what in ("status", "coverage")}
    return {"job": job_id, "end": end, "latency_ms": lat, "client_events": counts}


def _report(title: str, run: dict, db: str) -> None:
    res = run["end"]["result"]
    with open_store(db, create=False) as store:
        stored = store.samples.count(res["session_id"])
    print(f"\n{title}")
    for what, lat in run["latency_ms"].items():
        if not len(lat):
            print(f"  no {what} event drawn")
            continue
        p50, p95, p99 = np.percentile(lat, [50, 95, 99])
        print(f"  sample-to-screen latency, {len(lat)} {what} events drawn: p50 {p50:.1f} ms, "
              f"p95 {p95:.1f} ms, p99 {p99:.1f} ms, max {lat.max():.1f} ms "
              f"(target p95 <= 250 ms: {'met' if p95 <= 250 else 'MISSED'})")
    lost = res["gaps"] + res["overflow"] + (res["samples"] - stored)
    print(f"  session {res['session_id']} {res['status']}: recorder wrote {res['samples']} "
          f"samples, the store holds {stored}; sequence gaps {res['gaps']}, queue overflow "
          f"{res['overflow']} -> samples dropped {lost}")
    if run["client_events"]:
        ev = sorted(run["client_events"].values())
        print(f"  {len(ev)} raw SSE viewers received {ev[0]}..{ev[-1]} events each")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=30.0)
    ap.add_argument("--viewers", type=int, default=10)
    ap.add_argument("--rig", default="sim-imu")
    args = ap.parse_args()
    print(f"machine: a Python loop of 10^7 additions {common.additions_s():.2f} s "
          f"({time.strftime('%Y-%m-%d %H:%M')})")
    tmp = Path(tempfile.mkdtemp(prefix="bench-web-live-"))
    db = str(tmp / "rig.db")
    with open_store(db) as store:
        patient = store.patients.ensure("P-BENCH")
    print(f"bench_web_live: rig {args.rig}, {args.seconds:g} s per recording, "
          f"{os.cpu_count()} CPUs, {time.strftime('%Y-%m-%d %H:%M')}")
    app = live_app(db, tmp / "files", rigs={args.rig: args.rig})
    with serving(app) as base:
        drv = start_chromium()
        try:
            one = _record(drv, base, patient, args.rig, args.seconds, 1)
            _report("1 viewer (the browser tab)", one, db)
            many = _record(drv, base, patient, args.rig, args.seconds, args.viewers)
            _report(f"{args.viewers} viewers (the tab + {args.viewers - 1} SSE clients)",
                    many, db)
        finally:
            quit_chromium(drv)


if __name__ == "__main__":
    main()
