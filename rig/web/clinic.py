"""What the web app's pages and its JSON API do, once for both: patients by pseudonym, their
sessions, a session's report (rendered by :func:`rig.report.run_report` into the server's
cache), a patient's progress (:func:`rig.readback.progress.run_progress`), and a session's
files (constraint, limb file, model, ``.sto`` export through
:func:`rig.store.io.export_session`).

Every check is the service's own (the CLI's one-line :class:`~rig.errors.RigConfigError`);
what is the web's only is the ownership of ids: a session is reached through its patient, and
another patient's session id is refused (:class:`NotFound`). Nothing here writes a file
outside the server's cache folder, and every file there is owner-only.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import threading
import time
import uuid
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from rig import __version__
from rig.errors import RigConfigError, user_errors
from rig.store import Store
from rig.store.io import export_session
from rig.store.pseudonyms import pseudonym_concerns

if TYPE_CHECKING:
    from rig.readback.progress import ProgressResult

__all__ = ["DOWNLOADS", "NotFound", "PseudonymConcern", "ReportOptions", "create_patient",
           "download", "find_patients", "patient", "patient_sessions", "progress",
           "progress_html", "prune_reports", "render_report", "session_of", "session_summary"]

#: the files a session offers: name → (what, file suffix)
DOWNLOADS = {"constraint": ("the joint's constraint (YAML)", ".yaml"),
             "limb": ("the limb file (YAML)", ".yaml"),
             "model": ("the trained model (ONNX)", ".onnx"),
             "export": ("the orientations as an OpenSim .sto", ".sto")}
#: the longest search text accepted (a pseudonym is at most 64 characters)
MAX_SEARCH = 64
#: the most patients a list page shows (the newest; a search narrows it)
PAGE_ROWS = 200
#: a cached report replaced by a newer one is deleted once it is this old (s): a request that
#: is sending it has long finished
PRUNE_GRACE_S = 600.0

# matplotlib's pyplot (the report's and the progress section's figures) is not thread-safe:
# one rendering at a time
_RENDER = threading.Lock()
# one lock per report file being rendered: a second request for it waits and reads the file
_KEY_LOCKS: dict[str, threading.Lock] = {}
_KEY_LOCKS_GUARD = threading.Lock()


class NotFound(RigConfigError):
    """An id that is not there, or not this patient's (HTTP 404)."""


class PseudonymConcern(RigConfigError):
    """A pseudonym that looks like it identifies the person, not confirmed (HTTP 409): the
    CLI's warning, asked before anything is written."""


# --------------------------------------------------------------------------- patients
def find_patients(store: Store, text: str | None = None) -> list[dict]:
    """Every patient (``id``, ``pseudonym``, ``side``, ``created_at``), newest first, or those
    whose pseudonym contains ``text`` (case-insensitive). One query on the patients table: a
    patient's sessions are on its own page (counting them here would read every session)."""
    if text is not None:
        if not isinstance(text, str):
            raise RigConfigError(f"search: give text, got {type(text).__name__}")
        if len(text) > MAX_SEARCH:
            raise RigConfigError(f"search: at most {MAX_SEARCH} characters")
        text = text.strip().lower()
    return [{"id": int(p["id"]), "pseudonym": p["pseudonym"], "side": p["side"],
             "created_at": p["created_at"]}
            for p in reversed(store.patients.list())
            if not text or text in p["pseudonym"].lower()]


def create_patient(store: Store, pseudonym: Any, side: Any = None, *,
                   confirm: bool = False) -> tuple[int, str | None]:
    """Register a patient; returns ``(id, warning)``. A pseudonym that looks like a name, a
    birth date, an e-mail address or a phone number (:func:`pseudonym_concerns`, the CLI's
    warning) is refused unless ``confirm``; then the warning comes back with the id."""
    if not isinstance(pseudonym, str) or not pseudonym.strip():
        raise RigConfigError("pseudonym: give the patient's pseudonym (e.g. P-0042)")
    if side in ("", None):
        side = None
    elif not isinstance(side, str):
        raise RigConfigError(f"side must be left or right, got {side!r}")
    if not isinstance(confirm, bool):
        raise RigConfigError(f"confirm must be true or false, got {confirm!r}")
    pseudonym = pseudonym.strip()
    concerns = pseudonym_concerns(pseudonym)
    warning = None
    if concerns:
        warning = (f"the pseudonym looks like it holds {' and '.join(concerns)}: the store is "
                   "meant for pseudonyms only (e.g. P-0042); keep the link to the person "
                   "outside it")
        if not confirm:
            raise PseudonymConcern(warning)
    return store.patients.add(pseudonym, side=side), warning


def patient(store: Store, patient_id: int) -> dict:
    """The patient row ``patient_id`` (:class:`NotFound` when there is none)."""
    try:
        return store.patients.get(int(patient_id))
    except RigConfigError as err:
        raise NotFound(f"no patient {patient_id}") from err


def patient_sessions(store: Store, patient_id: int) -> list[dict]:
    """The patient's sessions, newest first (``rig session list``'s rows)."""
    p = patient(store, patient_id)
    return store.sessions.list(patient=p["pseudonym"])[::-1]


def patient_of_session(store: Store, session_id: int) -> int:
    """The id of the patient session ``session_id`` belongs to (:class:`NotFound`)."""
    try:
        return int(store.sessions.get(int(session_id))["patient_id"])
    except (RigConfigError, KeyError, TypeError) as err:
        raise NotFound(f"no session {session_id}") from err


def session_of(store: Store, patient_id: int, session_id: int) -> dict:
    """Session ``session_id`` of patient ``patient_id`` as ``rig session list`` gives it
    (counts, liveness); :class:`NotFound` when it is not there or is another patient's."""
    p = patient(store, patient_id)
    for s in store.sessions.list(patient=p["pseudonym"]):
        if int(s["id"]) == int(session_id):
            return s
    raise NotFound(f"patient {patient_id} has no session {session_id}")


def _services():
    """The report and progress services and the session-shape reader — imported lazily, on the
    first page that needs them: they bring matplotlib, scipy and numba (~2 s), which the
    server's start and its lists do without."""
    from rig.readback import progress as _progress  # lazy: see the docstring
    from rig.readback import sessions as _sessions  # lazy
    from rig.report import progress as _report_progress  # lazy
    from rig.report import session as _report  # lazy
    return _progress, _sessions, _report, _report_progress


def _latest_boundary(store: Store, session_id: int, limb: bool) -> dict | None:
    rows = store.boundaries.list(session_id, limb=limb)
    return rows[-1] if rows else None


def _latest_model(store: Store, session_id: int) -> dict | None:
    """The last model registered with the session (or one of its boundaries) whose file is
    still there."""
    models = store.models.list(session_id=session_id)
    for b in store.boundaries.list(session_id):
        models += store.models.list(boundary_id=int(b["id"]))
    for m in sorted(models, key=lambda m: int(m["id"]), reverse=True):
        if Path(m["path"]).is_file():
            return m
    return None


def session_summary(store: Store, patient_id: int, session_id: int) -> dict:
    """A session for its page and the API: the row, its limb (or None), and which files it
    offers (``downloads``: name → what)."""
    s = session_of(store, patient_id, session_id)
    have = {"constraint": _latest_boundary(store, session_id, False) is not None,
            "limb": _latest_boundary(store, session_id, True) is not None,
            "model": _latest_model(store, session_id) is not None,
            "export": s["samples"] > 0}
    return {"session": s, "limb": _services()[1].session_limb(s),
            "downloads": {k: DOWNLOADS[k][0] for k, ok in have.items() if ok}}


# --------------------------------------------------------------------------- files
@dataclass
class Download:
    """A file to send: its bytes or path, the name the browser saves it under (no pseudonym),
    and whether the server deletes the path once sent."""

    filename: str
    media_type: str
    content: bytes | None = None
    path: Path | None = None
    temporary: bool = False


def download(store: Store, cache_dir: Path, patient_id: int, session_id: int,
             what: str) -> Download:
    """Session ``session_id``'s file ``what`` (:data:`DOWNLOADS`)."""
    if what not in DOWNLOADS:
        raise NotFound(f"no download {what!r}: one of {', '.join(DOWNLOADS)}")
    session_of(store, patient_id, session_id)
    name = f"session-{int(session_id)}-{what}{DOWNLOADS[what][1]}"
    if what in ("constraint", "limb"):
        b = _latest_boundary(store, session_id, what == "limb")
        if b is None:
            cmd = "--limb arm|leg " if what == "limb" else ""
            thing = "limb file" if what == "limb" else "boundary"
            raise NotFound(f"session {session_id} has no {thing} yet (extract it: rig boundary "
                           f"--session {session_id} {cmd}--db DB)")
        return Download(name, "application/yaml", content=b["constraint_yaml"].encode())
    if what == "model":
        m = _latest_model(store, session_id)
        if m is None:
            raise NotFound(f"session {session_id} has no trained model whose file is there")
        return Download(name, "application/octet-stream", path=Path(m["path"]))
    out = _cache_file(cache_dir, "exports", f"{uuid.uuid4().hex}.sto")
    try:
        export_session(store, session_id, "sto", out)
    except BaseException:
        out.unlink(missing_ok=True)
        raise
    return Download(name, "text/plain", path=out, temporary=True)


def _cache_file(cache_dir: Path, sub: str, name: str) -> Path:
    folder = Path(cache_dir) / sub
    folder.mkdir(mode=0o700, parents=True, exist_ok=True)
    return folder / name


# --------------------------------------------------------------------------- report
@dataclass(frozen=True)
class ReportOptions:
    """What ``rig report`` takes besides the session: the patient's age and sex (the
    population band; checked by :func:`check`), the coupled clinical tests, and a reference
    constraint's YAML text (drawn dashed) with the name it was uploaded under."""

    age: int | None = None
    sex: str | None = None
    coupled_tests: bool = False
    reference: bytes | None = None
    reference_name: str | None = None

    def check(self) -> None:
        """The CLI's limits (``--age`` 18-110, ``--sex female|male``), one line each."""
        if self.age is not None and not (isinstance(self.age, int) and 18 <= self.age <= 110):
            raise RigConfigError(f"age must be a whole number of years from 18 to 110, got "
                                 f"{self.age!r}")
        if self.sex not in (None, "female", "male"):
            raise RigConfigError(f"sex must be female or male, got {self.sex!r}")
        if self.reference is not None:
            name = self.reference_name or ""
            if not name or name != os.path.basename(name) or "\\" in name or name in (".", ".."):
                raise RigConfigError(f"reference file name {name!r}: give a plain file name "
                                     "(no folders)")
            if not name.lower().endswith((".yaml", ".yml")):
                raise RigConfigError(f"reference file {name!r}: a constraint or limb file "
                                     "(.yaml) is expected")
            try:
                self.reference.decode("utf-8")
            except UnicodeDecodeError as err:
                raise RigConfigError(f"reference file {name!r}: not UTF-8 text") from err

    def key(self) -> dict:
        return {"age": self.age, "sex": self.sex, "coupled": self.coupled_tests,
                "ref": None if self.reference is None
                else hashlib.sha256(self.reference).hexdigest()}


def _report_key(store: Store, sess: dict, options: ReportOptions) -> str:
    """What the report of ``sess`` depends on: the rig's version, the patient's sessions
    (the progress section), this session's samples, boundaries and models, the options."""
    sid = int(sess["id"])
    visits = [(int(s["id"]), s["status"], s["ended_at"], s["samples"], s["last_sample_at"])
              for s in store.sessions.list(patient=sess["pseudonym"])]
    parts = {"v": __version__, "session": sid, "visits": visits,
             "boundaries": [int(b["id"]) for b in store.boundaries.list(sid)],
             "models": [(int(m["id"]), m["sha256"]) for m in
                        store.models.list(session_id=sid)],
             "options": options.key()}
    return hashlib.sha256(json.dumps(parts, default=str).encode()).hexdigest()[:32]


def render_report(store: Store, settings_db: str, cache_dir: Path, patient_id: int,
                  session_id: int, options: ReportOptions | None = None) -> Path:
    """The report of session ``session_id`` (of patient ``patient_id``) as a file in the
    cache, rendered by :func:`rig.report.run_report` unless the same report is there already
    (same data, same options). Returns its path."""
    options = options or ReportOptions()
    options.check()
    sess = session_of(store, patient_id, session_id)
    key = _report_key(store, sess, options)
    out = _cache_file(cache_dir, "reports", f"session-{int(session_id)}-{key}.html")
    with _KEY_LOCKS_GUARD:
        lock = _KEY_LOCKS.setdefault(key, threading.Lock())
    with lock:
        if out.is_file():
            return out
        ref = None
        if options.reference is not None:
            ref = _cache_file(cache_dir, "uploads", f"{uuid.uuid4().hex}.yaml")
            ref.write_bytes(options.reference)
            os.chmod(ref, 0o600)
        try:
            report = _services()[2]
            with _RENDER:
                report.run_report(report.ReportRequest(
                    settings_db, int(session_id), out, age=options.age, sex=options.sex,
                    reference=ref, coupled_tests=options.coupled_tests))
        except user_errors() as err:
            out.unlink(missing_ok=True)
            if ref is None or str(ref) not in str(err):
                raise
            # the upload's name, not the server's temporary file
            raise RigConfigError(str(err).replace(str(ref), options.reference_name or
                                                  "reference")) from err
        except BaseException:
            out.unlink(missing_ok=True)
            raise
        finally:
            if ref is not None:
                ref.unlink(missing_ok=True)
    prune_reports(out)
    return out


def prune_reports(newest: Path, *, grace_s: float = PRUNE_GRACE_S,
                  now: float | None = None) -> list[Path]:
    """Delete the session's other cached reports (older data or other options) last written
    more than ``grace_s`` ago — one being sent now is left alone; returns those deleted."""
    now = time.time() if now is None else now
    sid = newest.name.split("-")[1]
    gone = []
    for old in newest.parent.glob(f"session-{sid}-*.html"):
        with contextlib.suppress(FileNotFoundError):
            if old != newest and now - old.stat().st_mtime > grace_s:
                old.unlink()
                gone.append(old)
    return gone


# --------------------------------------------------------------------------- progress
def progress(db: str, store: Store, patient_id: int, joint: str | None = None
             ) -> ProgressResult:
    """:func:`rig.readback.progress.run_progress` for patient ``patient_id``."""
    p = patient(store, patient_id)
    if joint in ("", None):
        joint = None
    prog = _services()[0]
    return prog.run_progress(prog.ProgressRequest(db, p["pseudonym"], joint))


def progress_html(result: ProgressResult) -> str:
    """The report's progress section (figures and tables) for a page."""
    with _RENDER:
        return "\n".join(_services()[3].progress_section_html(result))
