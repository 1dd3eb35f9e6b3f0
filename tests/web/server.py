"""A real uvicorn server on 127.0.0.1 (a free port) in a thread, serving the live router.

Until the app (:mod:`rig.web.app`, ``create_app``) is merged, :func:`live_app` is the minimal
app the live router needs: ``app.state.jobs`` (a :class:`rig.web.jobs.JobRunner`), the router,
and ``rig/web/static`` at ``/static``. Tests and ``benchmarks/bench_web_live.py`` talk HTTP to
it (never an in-process test client).
"""

from __future__ import annotations

import contextlib
import json
import socket
import threading
import time
import urllib.error
import urllib.request
from collections.abc import Iterator, Mapping
from pathlib import Path

import uvicorn
from fastapi import FastAPI
from fastapi.staticfiles import StaticFiles

from rig.record.rigio import OpenRig, open_rig
from rig.web import live
from rig.web.jobs import JobRunner

STATIC = Path(live.__file__).resolve().parent / "static"


class _AsHardware(OpenRig):
    """A simulated rig the recorder takes for hardware: no simulated patient it may follow,
    so it prompts and waits for Enter as ``rig record`` does on hardware."""

    @property
    def simulated(self) -> bool:
        return False


def opener_as_hardware(*names: str):
    """A :class:`~rig.web.jobs.JobRunner` ``opener``: the rigs ``names`` (configuration
    names) open as :func:`~rig.record.rigio.open_rig` opens them, then answer as hardware."""

    def opener(config, *, calibrate: bool):
        rig = open_rig(config, calibrate=calibrate)
        if config.name in names:
            rig.__class__ = _AsHardware
        return rig

    return opener


def live_app(db: str, files_dir: Path, *, rigs: Mapping[str, str] | None = None,
             **runner: object) -> FastAPI:
    """The live router on a minimal app (what ``create_app`` must also provide); ``runner``:
    more keyword arguments of the :class:`~rig.web.jobs.JobRunner`."""
    app = FastAPI()
    app.state.jobs = JobRunner(db, files_dir, rigs=rigs, **runner)
    app.include_router(live.router)
    app.mount("/static", StaticFiles(directory=STATIC), name="static")
    return app


@contextlib.contextmanager
def serving(app: FastAPI) -> Iterator[str]:
    """Serve ``app`` on 127.0.0.1 (a free port) in a thread; yields the base URL. At the end
    the server stops and the app's jobs are waited for (recordings interrupted)."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    sock.bind(("127.0.0.1", 0))
    port = sock.getsockname()[1]
    server = uvicorn.Server(uvicorn.Config(app, log_level="warning", access_log=False,
                                           lifespan="off"))
    thread = threading.Thread(target=server.run, kwargs={"sockets": [sock]},
                              name="rig-web-test-server", daemon=True)
    thread.start()
    deadline = time.monotonic() + 30.0
    while not server.started:
        if not thread.is_alive() or time.monotonic() > deadline:
            raise RuntimeError("the test server did not start")
        time.sleep(0.01)
    try:
        yield f"http://127.0.0.1:{port}"
    finally:
        app.state.jobs.close()
        server.should_exit = True
        thread.join(30.0)
        sock.close()


def call(base: str, path: str, body: object = None, *, method: str | None = None,
         raw: bytes | None = None, headers: Mapping[str, str] | None = None
         ) -> tuple[int, dict]:
    """An HTTP request (POST with a JSON ``body``, or GET); ``(status, JSON reply)``."""
    data = raw if raw is not None else (None if body is None else json.dumps(body).encode())
    req = urllib.request.Request(base + path, data=data, method=method or (
        "GET" if data is None else "POST"), headers={"Content-Type": "application/json",
                                                      **(headers or {})})
    try:
        with urllib.request.urlopen(req, timeout=60) as resp:
            return resp.status, json.loads(resp.read() or b"{}")
    except urllib.error.HTTPError as err:
        with err:
            return err.code, json.loads(err.read() or b"{}")


def events(base: str, job_id: int, *, until: str = "end") -> Iterator[tuple[str, dict]]:
    """The job's Server-Sent Events, ``(name, data)``, up to and with the first ``until``."""
    req = urllib.request.Request(f"{base}/api/jobs/{job_id}/events")
    with urllib.request.urlopen(req, timeout=120) as resp:
        name, data = None, []
        for line in resp:
            line = line.decode().rstrip("\n")
            if line.startswith("event: "):
                name = line[7:]
            elif line.startswith("data: "):
                data.append(line[6:])
            elif not line and name is not None:
                yield name, json.loads("".join(data))
                if name == until:
                    return
                name, data = None, []
