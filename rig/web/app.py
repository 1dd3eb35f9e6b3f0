"""The web application: :func:`create_app` puts the rooms together.

Layers, outermost first (each a middleware over the next)::

    SecurityHeaders      CSP, nosniff, frame-ancestors, no-referrer, no-store on every answer
    BodyLimit            413 for a body over settings.max_upload_bytes
    CSRF                 asgi-csrf double-submit token + same-origin check (unsafe methods)
    SessionMiddleware    the signed login-session cookie (itsdangerous)
    LoginGate            a login when the server needs one (rig.web.security)
    routes               security.router (login), pages.router (HTML), api.router (/api/),
                         /static (rig/web/static: every asset shipped, no CDN)

Every mistake is answered by :func:`rig.web.render.error_response`: the one-line message the
CLI gives (``RigConfigError`` and the other :func:`rig.errors.user_errors`), an unknown id
(404), a form field of the wrong type, as a page or as ``{"error": ...}`` — never a
traceback (an unexpected error says "internal error" and the server's log has the rest).
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import logging
from pathlib import Path

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.staticfiles import StaticFiles
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.middleware.sessions import SessionMiddleware

from rig import __version__
from rig.errors import user_errors
from rig.store import open_store
from rig.web import api, live, pages, security
from rig.web.clinic import NotFound, PseudonymConcern
from rig.web.jobs import JobRunner, offered_rigs
from rig.web.render import TEMPLATES, error_response
from rig.web.settings import WebSettings

__all__ = ["create_app", "validation_message"]

log = logging.getLogger("rig.web")
STATIC = Path(__file__).with_name("static")


def _utc(t: float | None) -> str:
    if t is None:
        return "–"
    return _dt.datetime.fromtimestamp(float(t), _dt.timezone.utc).strftime("%Y-%m-%d %H:%M")


TEMPLATES.env.filters["utc"] = _utc

_TYPE_WORDS = {"int_parsing": "must be a whole number", "int_type": "must be a whole number",
               "string_type": "must be text", "bool_type": "must be true or false",
               "bool_parsing": "must be true or false", "missing": "is missing",
               "extra_forbidden": "is not a field of this request",
               "literal_error": "must be one of", "dict_type": "must be a JSON object",
               "model_type": "must be a JSON object", "string_too_long": "is too long"}


def validation_message(exc: RequestValidationError) -> tuple[str, int]:
    """One line for FastAPI's validation errors (the first), and the status: 404 for a path
    id that is not a number, 400 for a body that is not JSON, else 422."""
    err = exc.errors()[0]
    loc = [str(x) for x in err.get("loc", ())]
    where, field = (loc[0] if loc else "request"), ".".join(loc[1:])
    kind = err.get("type", "")
    if kind == "json_invalid":
        return "the body is not valid JSON", 400
    words = _TYPE_WORDS.get(kind, err.get("msg", "is not valid"))
    if kind == "literal_error":
        words = err.get("msg", words).replace("Input should be", "must be")
    got = err.get("input")
    shown = "" if kind == "missing" or isinstance(got, (dict, list)) or got is None else \
        f", got {str(got)[:20]!r}"
    if where == "body" and not field:
        return ("the body must be a JSON object" if kind != "missing"
                else "the body is missing: send a JSON object"), 422
    status = 404 if where == "path" else 422
    return f"{field or where}: {words}{shown}", status


def create_app(settings: WebSettings) -> FastAPI:
    """The application for ``settings`` (the store is opened now, and created when it is a
    new SQLite file; :func:`rig.web.security.check_binding` has been passed)."""
    security.check_binding(settings)
    settings.cache_dir.mkdir(mode=0o700, parents=True, exist_ok=True)
    store = open_store(settings.db, readonly=False)
    jobs = JobRunner(settings.db, settings.files_dir, rigs=offered_rigs(settings.rigs))

    @contextlib.asynccontextmanager
    async def lifespan(app: FastAPI):
        try:
            yield
        finally:
            jobs.close()  # a recording still running is interrupted, its samples committed
            store.close()

    app = FastAPI(title="rig clinic", version=__version__, docs_url=None, redoc_url=None,
                  openapi_url=None, lifespan=lifespan)
    app.state.settings = settings
    app.state.store = store
    app.state.jobs = jobs
    app.state.login_throttle = security.LoginThrottle()

    app.include_router(security.router)
    app.include_router(pages.router)
    app.include_router(api.router)
    app.include_router(live.router)
    app.mount("/static", StaticFiles(directory=str(STATIC)), name="static")

    @app.exception_handler(NotFound)
    async def not_found(request: Request, exc: NotFound):
        return error_response(request, str(exc), 404)

    @app.exception_handler(PseudonymConcern)
    async def concern(request: Request, exc: PseudonymConcern):
        return error_response(request, str(exc) + " (send confirm to create it anyway)", 409)

    async def user_error(request: Request, exc: Exception):
        msg = str(exc) or type(exc).__name__
        return error_response(request, msg, 400)

    for cls in user_errors():
        app.add_exception_handler(cls, user_error)

    @app.exception_handler(RequestValidationError)
    async def invalid(request: Request, exc: RequestValidationError):
        msg, status = validation_message(exc)
        return error_response(request, msg, status)

    @app.exception_handler(StarletteHTTPException)
    async def http_error(request: Request, exc: StarletteHTTPException):
        msg = {404: f"no page {request.url.path}",
               405: f"{request.method} is not allowed on {request.url.path}"}.get(
                   exc.status_code, str(exc.detail))
        return error_response(request, msg, exc.status_code)

    @app.exception_handler(Exception)
    async def internal(request: Request, exc: Exception):
        log.exception("internal error on %s %s", request.method, request.url.path)
        return error_response(request, "internal error (the server's log has the details)",
                              500)

    app.add_middleware(security.LoginGate, settings=settings)
    app.add_middleware(SessionMiddleware, secret_key=settings.secret,
                       session_cookie="rig_session", max_age=security.SESSION_MAX_AGE_S,
                       same_site="lax", https_only=False)
    app.add_middleware(_Csrf, settings=settings)
    app.add_middleware(security.BodyLimit, limit=settings.max_upload_bytes)
    app.add_middleware(security.SecurityHeaders)
    return app


class _Csrf:
    """:func:`rig.web.security.csrf_middleware` as a Starlette middleware class."""

    def __init__(self, app, settings: WebSettings) -> None:
        self.inner = security.csrf_middleware(app, settings)

    async def __call__(self, scope, receive, send) -> None:
        await self.inner(scope, receive, send)
