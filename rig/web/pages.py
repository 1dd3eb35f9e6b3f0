"""The clinician's pages: patients (list, search, create with the pseudonym check), a patient's
sessions, a session (its facts, report options, files), the report served inline, the
progress across visits. Each page calls :mod:`rig.web.clinic` (the service functions the CLI
runs); a mistake comes back as the error page (:mod:`rig.web.app`'s handlers).

URLs hold numeric ids only — never a pseudonym: the search is a POST.
"""

from __future__ import annotations

from fastapi import APIRouter, File, Form, Request, UploadFile
from starlette.background import BackgroundTask
from starlette.responses import FileResponse, RedirectResponse, Response

from rig.errors import RigConfigError
from rig.web import clinic
from rig.web.render import page
from rig.web.security import REPORT_CSP
from rig.web.settings import WebSettings

__all__ = ["router"]

router = APIRouter()
_NO_FILE = File(None)


def _store(request: Request):
    return request.app.state.store


def _settings(request: Request) -> WebSettings:
    return request.app.state.settings


@router.get("/")
def home() -> Response:
    return RedirectResponse("/patients", status_code=303)


@router.get("/patients")
def patients(request: Request) -> Response:
    return _patients_page(request, clinic.find_patients(_store(request)))


@router.post("/patients/search")
def search(request: Request, q: str = Form("")) -> Response:
    return _patients_page(request, clinic.find_patients(_store(request), q), q=q)


def _patients_page(request: Request, found: list[dict], status: int = 200, **ctx) -> Response:
    """The patients page: the newest :data:`clinic.PAGE_ROWS` of ``found``."""
    return page(request, "patients.html", {"patients": found[:clinic.PAGE_ROWS],
                                           "total": len(found), **ctx}, status=status)


@router.post("/patients")
def create(request: Request, pseudonym: str = Form(""), side: str = Form(""),
           confirm: str = Form("")) -> Response:
    store = _store(request)
    try:
        pid, warning = clinic.create_patient(store, pseudonym, side or None,
                                             confirm=confirm == "yes")
    except clinic.PseudonymConcern as err:
        return _patients_page(request, clinic.find_patients(store), 409, warning=str(err),
                              pseudonym=pseudonym, side=side)
    except RigConfigError as err:
        return _patients_page(request, clinic.find_patients(store), 400, error=str(err),
                              pseudonym=pseudonym)
    if warning:
        request.session["warning"] = warning
    return RedirectResponse(f"/patients/{pid}", status_code=303)


@router.get("/patients/{patient_id}")
def patient(request: Request, patient_id: int) -> Response:
    store = _store(request)
    p = clinic.patient(store, patient_id)
    warning = request.session.pop("warning", None)
    return page(request, "patient.html", {"patient": p, "warning": warning,
                                          "sessions": clinic.patient_sessions(store,
                                                                              patient_id)})


@router.get("/patients/{patient_id}/sessions/{session_id}")
def session(request: Request, patient_id: int, session_id: int) -> Response:
    store = _store(request)
    summary = clinic.session_summary(store, patient_id, session_id)
    return page(request, "session.html", {"patient": clinic.patient(store, patient_id),
                                          "s": summary["session"], "limb": summary["limb"],
                                          "downloads": summary["downloads"]})


@router.get("/sessions/{session_id}")
def session_by_id(request: Request, session_id: int) -> Response:
    """A session's page by its id alone (the live view's and the jobs' links): its patient's
    session page."""
    pid = clinic.patient_of_session(_store(request), session_id)
    return RedirectResponse(f"/patients/{pid}/sessions/{int(session_id)}", status_code=303)


def _report_response(path) -> Response:
    return FileResponse(path, media_type="text/html; charset=utf-8",
                        headers={"Content-Security-Policy": REPORT_CSP,
                                 "Content-Disposition": "inline"})


@router.get("/patients/{patient_id}/sessions/{session_id}/report")
def report(request: Request, patient_id: int, session_id: int) -> Response:
    s = _settings(request)
    return _report_response(clinic.render_report(_store(request), s.db, s.cache_dir,
                                                 patient_id, session_id))


@router.post("/patients/{patient_id}/sessions/{session_id}/report")
def report_with_options(request: Request, patient_id: int, session_id: int,
                        age: str = Form(""), sex: str = Form(""),
                        coupled_tests: str = Form(""),
                        reference: UploadFile | None = _NO_FILE) -> Response:
    s = _settings(request)
    ref, ref_name = None, None
    if reference is not None and reference.filename:
        ref, ref_name = reference.file.read(), reference.filename
    options = clinic.ReportOptions(age=_whole_number("age", age), sex=sex or None,
                                   coupled_tests=coupled_tests == "yes", reference=ref,
                                   reference_name=ref_name)
    return _report_response(clinic.render_report(_store(request), s.db, s.cache_dir,
                                                 patient_id, session_id, options))


def _whole_number(what: str, text: str) -> int | None:
    text = (text or "").strip()
    if not text:
        return None
    try:
        return int(text)
    except ValueError as err:
        raise RigConfigError(f"{what} must be a whole number, got {text[:20]!r}") from err


@router.get("/patients/{patient_id}/sessions/{session_id}/files/{what}")
def download(request: Request, patient_id: int, session_id: int, what: str) -> Response:
    s = _settings(request)
    d = clinic.download(_store(request), s.cache_dir, patient_id, session_id, what)
    disposition = f'attachment; filename="{d.filename}"'
    if d.content is not None:
        return Response(d.content, media_type=d.media_type,
                        headers={"Content-Disposition": disposition})
    return FileResponse(d.path, media_type=d.media_type,
                        headers={"Content-Disposition": disposition},
                        background=BackgroundTask(d.path.unlink, missing_ok=True)
                        if d.temporary else None)


@router.get("/patients/{patient_id}/progress")
def progress(request: Request, patient_id: int, joint: str = "") -> Response:
    store = _store(request)
    p = clinic.patient(store, patient_id)
    result = clinic.progress(_settings(request).db, store, patient_id, joint or None)
    return page(request, "progress.html", {
        "patient": p, "result": result, "joint": joint or "",
        "joints": ["", *sorted({v.joint for v in result.visits})],
        "section": clinic.progress_html(result)})
