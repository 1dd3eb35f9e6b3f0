"""The guided recording in the browser, the live coverage view, and a session's long work.

``router`` (a FastAPI ``APIRouter``) is mounted by the app (:mod:`rig.web.app`), which must set
``app.state.jobs`` to a :class:`rig.web.jobs.JobRunner` and serve ``rig/web/static`` at
``/static``. Pages extend ``base.html``; their script is ``static/live.js`` (no inline script:
the page's data travels in ``data-*`` attributes), the swing map a canvas it draws.

Pages
-----
``GET /record[?patient=ID]``
    Choose the patient, the rig (the shipped configurations, simulators included: what it
    records, joint or whole limb, and its side), the side and the duration; Start.
``GET /jobs/{id}``
    A job. A recording: the calibration's steps and prompts as ``rig record`` prints them (a
    **Continue** button where it waits for Enter), the live coverage view (the swing map's
    visited cells and each sector's reach, the twist reached, what is left to explore, the
    counters), **Stop** (the session ends ``completed``) and **Interrupt** (``interrupted``,
    as Ctrl-C); both keep everything recorded. Then the session's next steps. A boundary or
    training job: its progress lines and result.
``GET /sessions/{id}/work``
    From a session: extract the boundary, train the model (with progress), its jobs, links to
    the session's page (report, downloads).

API (JSON; a user mistake is ``{"error": "<the CLI's one line>"}`` with a 4xx status)
-------------------------------------------------------------------------------------
``POST /api/record`` ``{"patient_id", "rig", "side"?, "duration_s"?, "calibrate"?}`` →
``{"job_id", "url"}``; ``POST /api/sessions/{id}/boundary``, ``POST /api/sessions/{id}/train``
``{"preset"?}`` → ``{"job_id", "url"}``; ``GET /api/jobs/{id}`` (the stored job);
``GET /api/jobs/{id}/events`` (``text/event-stream``, :class:`rig.web.jobs.Channel`; a job not
running here gets its stored state and ``end``); ``POST /api/jobs/{id}/continue|stop|interrupt``.
"""

from __future__ import annotations

import json
import math
from typing import Any

from fastapi import APIRouter, Request
from fastapi.responses import JSONResponse, StreamingResponse
from starlette.concurrency import run_in_threadpool

from rig.errors import RigConfigError, RigConnectionError, user_errors
from rig.store import JobBusyError, open_store
from rig.training import PRESET_NAMES
from rig.training.limb import LIMB_PRESETS
from rig.web.jobs import JobRunner, RecordJob
from rig.web.render import page

__all__ = ["router"]

router = APIRouter()

#: Largest JSON body an API route reads (bytes).
MAX_BODY = 16_384


def _runner(request: Request) -> JobRunner:
    return request.app.state.jobs


def _error(err: BaseException) -> JSONResponse:
    """A user mistake as JSON: 409 busy, 404 an unknown id, 503 a missing device, else 400."""
    text = str(err) or type(err).__name__
    if isinstance(err, JobBusyError):
        code = 409
    elif isinstance(err, RigConfigError) and text.startswith("no "):
        code = 404
    elif isinstance(err, (RigConnectionError, FileNotFoundError, TimeoutError)):
        code = 503
    else:
        code = 400
    return JSONResponse({"error": text}, status_code=code)


async def _body(request: Request) -> dict:
    raw = await request.body()
    if len(raw) > MAX_BODY:
        raise RigConfigError(f"request body too large ({len(raw)} bytes > {MAX_BODY})")
    if not raw.strip():
        return {}
    try:
        data = json.loads(raw)
    except ValueError as err:
        raise RigConfigError("the request body must be a JSON object") from err
    if not isinstance(data, dict):
        raise RigConfigError("the request body must be a JSON object")
    return data


def _int(data: dict, key: str) -> int:
    v = data.get(key)
    if isinstance(v, str) and v.strip().isdigit():
        v = int(v)
    if not isinstance(v, int) or isinstance(v, bool) or v < 1:
        raise RigConfigError(f"{key}: expected a positive whole number, got {v!r}")
    return v


def _seconds(data: dict, key: str) -> float | None:
    v = data.get(key)
    if v is None or (isinstance(v, str) and not v.strip()):
        return None
    try:
        s = float(v)
    except (TypeError, ValueError) as err:
        raise RigConfigError(f"{key}: expected seconds, got {v!r}") from err
    if not math.isfinite(s) or s <= 0:
        raise RigConfigError(f"{key} must be > 0 seconds, got {v!r}")
    return s


def _choice(data: dict, key: str, choices: tuple[str, ...] | None = None) -> str | None:
    v = data.get(key)
    if v is None or v == "":
        return None
    if not isinstance(v, str) or (choices is not None and v not in choices):
        want = f"one of {', '.join(choices)}" if choices else "text"
        raise RigConfigError(f"{key}: expected {want}, got {v!r}")
    return v


def _flag(data: dict, key: str, default: bool) -> bool:
    v = data.get(key, default)
    if not isinstance(v, bool):
        raise RigConfigError(f"{key}: expected true or false, got {v!r}")
    return v


# -- pages ---------------------------------------------------------------------------------
@router.get("/record")
def record_page(request: Request, patient: int | None = None):
    """The guided recording's form."""
    runner = _runner(request)
    with open_store(runner.db, create=False) as store:
        patients = store.patients.list()
    return page(request, "record.html", {
        "patients": patients, "chosen": patient, "rigs": runner.rig_choices()})


@router.get("/jobs/{job_id}")
def job_page(request: Request, job_id: int):
    """A job: the live view of a recording, the progress of a boundary or training."""
    runner = _runner(request)
    try:
        job = runner.job(job_id)
    except user_errors() as err:
        return page(request, "job.html", {"error": str(err), "job": None},
                                          status=404)
    return page(request, "job.html", {"job": job, "error": None})


@router.get("/sessions/{session_id}/work")
def work_page(request: Request, session_id: int):
    """A session's boundary and training, and its jobs."""
    runner = _runner(request)
    try:
        with open_store(runner.db, create=False) as store:
            session = store.sessions.get(session_id)
            jobs = store.jobs.list(session_id=session_id)
            boundaries = store.boundaries.list(session_id)
            models = store.models.list(session_id=session_id)
    except user_errors() as err:
        return page(request, "work.html", {"error": str(err)},
                                          status=404)
    return page(request, "work.html", {
        "error": None, "session": session, "jobs": jobs, "boundaries": boundaries,
        "models": models, "presets": PRESET_NAMES + LIMB_PRESETS})


# -- API -----------------------------------------------------------------------------------
@router.post("/api/record")
async def start_record(request: Request):
    """Start a guided recording (checks, opens the rig, returns at once)."""
    try:
        data = await _body(request)
        job = RecordJob(patient_id=_int(data, "patient_id"),
                        rig=_choice(data, "rig") or "",
                        side=_choice(data, "side", ("left", "right")),
                        duration_s=_seconds(data, "duration_s"),
                        calibrate=_flag(data, "calibrate", True))
        if not job.rig:
            raise RigConfigError("rig: choose a rig")
        job_id = await _in_thread(_runner(request).start_record, job)
    except user_errors() as err:
        return _error(err)
    return {"job_id": job_id, "url": f"/jobs/{job_id}"}


@router.post("/api/sessions/{session_id}/boundary")
async def start_boundary(request: Request, session_id: int):
    """Extract the session's boundary (a job)."""
    try:
        await _body(request)
        job_id = await _in_thread(_runner(request).start_boundary, session_id)
    except user_errors() as err:
        return _error(err)
    return {"job_id": job_id, "url": f"/jobs/{job_id}"}


@router.post("/api/sessions/{session_id}/train")
async def start_train(request: Request, session_id: int):
    """Train a model on the session's newest boundary (a job)."""
    try:
        data = await _body(request)
        preset = _choice(data, "preset")
        job_id = await _in_thread(_runner(request).start_train, session_id, preset=preset)
    except user_errors() as err:
        return _error(err)
    return {"job_id": job_id, "url": f"/jobs/{job_id}"}


@router.get("/api/jobs/{job_id}")
def job_state(request: Request, job_id: int):
    """The stored job (status, progress, result, message, session)."""
    try:
        return _public(_runner(request).job(job_id))
    except user_errors() as err:
        return _error(err)


@router.get("/api/jobs/{job_id}/events")
async def job_events(request: Request, job_id: int):
    """Server-Sent Events of a job (see :class:`rig.web.jobs.Channel`)."""
    runner = _runner(request)
    channel = runner.channel(job_id)
    headers = {"Cache-Control": "no-store", "X-Accel-Buffering": "no"}
    if channel is None:  # ended, or run by a server that is gone: its stored state, then end
        try:
            job = await _in_thread(runner.job, job_id)
        except user_errors() as err:
            return _error(err)
        return StreamingResponse(_stored_events(job), media_type="text/event-stream",
                                 headers=headers)
    try:
        cursor = int(request.headers.get("last-event-id", "0") or 0)
    except ValueError:
        cursor = 0
    return StreamingResponse(channel.sse(cursor), media_type="text/event-stream",
                             headers=headers)


@router.post("/api/jobs/{job_id}/{action}")
async def job_action(request: Request, job_id: int, action: str):
    """``continue`` (Enter where ``rig record`` waits for it), ``stop`` (end ``completed``),
    ``interrupt`` (end ``interrupted``)."""
    runner = _runner(request)
    do = {"continue": runner.press, "stop": runner.stop, "interrupt": runner.interrupt}
    try:
        await _body(request)
        if action not in do:
            raise RigConfigError(f"action {action!r}: expected continue, stop or interrupt")
        do[action](job_id)
    except user_errors() as err:
        return _error(err)
    return {"ok": True}


async def _in_thread(fn, *args, **kwargs):
    return await run_in_threadpool(fn, *args, **kwargs)


def _public(job: dict) -> dict[str, Any]:
    """What the API shows of a job (no writer host or pid)."""
    keep = ("id", "kind", "state", "status", "session_id", "patient_id", "params", "progress",
            "result", "message", "created_at", "ended_at", "live")
    return {k: job.get(k) for k in keep}


async def _stored_events(job: dict):
    """A job not running here: its stored messages, status and coverage, session, then end."""
    prog = job.get("progress") or {}
    out = [("message", {"text": text}) for text in prog.get("messages", [])]
    out += [(name, prog[name]) for name in ("coverage", "status") if prog.get(name)]
    if job.get("session_id"):
        out.append(("session", {"session_id": job["session_id"]}))
    if job["state"] == "running":  # run by another process: it says nothing more here
        message = "this job runs in another server process"
    else:
        message = job.get("message") or ""
    out.append(("end", {"status": job["state"], "message": message,
                        "result": job.get("result") or {}}))
    for seq, (name, data) in enumerate(out, 1):
        yield f"id: {seq}\nevent: {name}\ndata: {json.dumps(data)}\n\n"
