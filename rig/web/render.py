"""Pages and error answers: the templates (``rig/web/templates/``, Jinja2 with autoescaping),
and the one way every part of the app answers a mistake — an HTML page with the one-line
message the CLI gives, or ``{"error": message}`` on the JSON API (``/api/``) — with a 4xx
status and never a traceback.

Templates extend ``base.html`` (blocks ``title`` and ``content``); every page gets
``csrf_token`` (put it first in a form: ``<input type="hidden" name="csrftoken" ...>``; a
script sends it as the ``x-csrftoken`` header) and ``user`` (the logged-in user, or None).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from fastapi.templating import Jinja2Templates
from starlette.requests import Request
from starlette.responses import HTMLResponse, JSONResponse, Response

__all__ = ["TEMPLATES", "csrf_token", "error_response", "page", "wants_json"]

TEMPLATES = Jinja2Templates(directory=str(Path(__file__).with_name("templates")))


def wants_json(request: Request) -> bool:
    """The JSON API's requests (``/api/...``) are answered in JSON, every other in HTML."""
    return request.url.path.startswith("/api/")


def csrf_token(request: Request) -> str:
    """The request's CSRF token (the signed value of the ``csrftoken`` cookie; set on the
    answer when the browser has none yet)."""
    get = request.scope.get("csrftoken")
    return get() if callable(get) else ""


def page(request: Request, name: str, context: dict[str, Any] | None = None, *,
         status: int = 200) -> HTMLResponse:
    """Template ``name`` rendered with ``context`` plus ``csrf_token`` and ``user``."""
    ctx = {"csrf_token": csrf_token(request),
           "user": request.scope.get("rig_user"),
           "require_login": request.scope.get("rig_require_login", False)}
    ctx.update(context or {})
    return TEMPLATES.TemplateResponse(request, name, ctx, status_code=status)


def error_response(request: Request, message: str, status: int = 400) -> Response:
    """A refusal: ``{"error": message}`` for the API, else the error page; ``message`` is one
    line, the same the CLI prints after ``rig: error:``."""
    if wants_json(request):
        return JSONResponse({"error": message}, status_code=status)
    return page(request, "error.html", {"message": message, "status": status}, status=status)
