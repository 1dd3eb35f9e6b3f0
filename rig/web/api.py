"""The JSON API under ``/api/``: the same :mod:`rig.web.clinic` calls as the pages, for
scripts and tests. Bodies are JSON objects whose unknown keys and wrong types are refused (one
line, ``{"error": ...}``, 4xx); writes carry the ``x-csrftoken`` header (the ``csrftoken``
cookie's value, :mod:`rig.web.security`).

====================================  =======================================================
``GET  /api/patients``                every patient (id, pseudonym, side), newest first
``POST /api/patients``                ``{"pseudonym", "side"?, "confirm"?}`` → 201 ``{"id"}``
``POST /api/patients/search``         ``{"q"}`` → the patients whose pseudonym contains it
``GET  /api/patients/{id}``           the patient and its sessions
``GET  /api/patients/{id}/sessions/{sid}``   the session and the files it offers
``GET  /api/patients/{id}/progress``  ``rig progress --json`` (``?joint=knee``)
====================================  =======================================================
"""

from __future__ import annotations

from typing import Literal

from fastapi import APIRouter, Request
from pydantic import BaseModel, ConfigDict, Field
from starlette.responses import JSONResponse

from rig.web import clinic

__all__ = ["router"]

router = APIRouter(prefix="/api")

#: the session columns the API shows (``meta`` and the writer's bookkeeping are the store's)
SESSION_FIELDS = ("id", "patient_id", "kind", "rig_name", "joint", "side", "status",
                  "started_at", "ended_at", "dropped", "samples", "samples_by_sensor",
                  "recording_s", "runs", "last_sample_at", "liveness")


class PatientIn(BaseModel):
    """A new patient: a pseudonym, optionally the side; ``confirm`` creates one whose
    pseudonym looks like it identifies the person (the warning comes back)."""

    model_config = ConfigDict(extra="forbid", strict=True)
    pseudonym: str = Field(max_length=64)
    side: Literal["left", "right"] | None = None
    confirm: bool = False


class SearchIn(BaseModel):
    model_config = ConfigDict(extra="forbid", strict=True)
    q: str = Field(max_length=clinic.MAX_SEARCH)


def _session_json(s: dict) -> dict:
    return {k: s.get(k) for k in SESSION_FIELDS}


@router.get("/patients")
def patients(request: Request) -> JSONResponse:
    return JSONResponse({"patients": clinic.find_patients(request.app.state.store)})


@router.post("/patients")
def create(request: Request, body: PatientIn) -> JSONResponse:
    pid, warning = clinic.create_patient(request.app.state.store, body.pseudonym, body.side,
                                         confirm=body.confirm)
    return JSONResponse({"id": pid, "warning": warning}, status_code=201)


@router.post("/patients/search")
def search(request: Request, body: SearchIn) -> JSONResponse:
    return JSONResponse({"patients": clinic.find_patients(request.app.state.store, body.q)})


@router.get("/patients/{patient_id}")
def patient(request: Request, patient_id: int) -> JSONResponse:
    store = request.app.state.store
    p = clinic.patient(store, patient_id)
    return JSONResponse({"id": p["id"], "pseudonym": p["pseudonym"], "side": p["side"],
                         "sessions": [_session_json(s)
                                      for s in clinic.patient_sessions(store, patient_id)]})


@router.get("/patients/{patient_id}/sessions/{session_id}")
def session(request: Request, patient_id: int, session_id: int) -> JSONResponse:
    summary = clinic.session_summary(request.app.state.store, patient_id, session_id)
    base = f"/patients/{patient_id}/sessions/{session_id}"
    return JSONResponse({"session": _session_json(summary["session"]),
                         "limb": summary["limb"], "report": f"{base}/report",
                         "downloads": {k: f"{base}/files/{k}" for k in summary["downloads"]}})


@router.get("/patients/{patient_id}/progress")
def progress(request: Request, patient_id: int, joint: str = "") -> JSONResponse:
    result = clinic.progress(request.app.state.settings.db, request.app.state.store,
                             patient_id, joint or None)
    return JSONResponse(result.to_json())
