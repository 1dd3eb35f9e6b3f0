"""Security of the web app: who may log in, the login session, CSRF, request size, headers, and
an access log that shows no query strings.

- **Binding.** ``rig serve`` listens on 127.0.0.1 unless told otherwise. Bound to any other
  address it refuses to start until a user exists (:func:`check_binding`), and then every page
  and API call needs a logged-in user (:class:`LoginGate`; ``--login`` asks for it on the
  loopback too).
- **Users** live in a users file (JSON, owner-only 0600, beside the SQLite store by default):
  name → Argon2id hash (``argon2-cffi``, its default parameters: RFC 9106's second
  recommended option). Set with ``rig serve --add-user NAME`` (the password is prompted).
- **Login session**: Starlette's ``SessionMiddleware`` (a cookie signed with ``itsdangerous``,
  HttpOnly, SameSite=Lax, 8 h).
- **CSRF**: ``asgi-csrf`` (the Datasette project's double-submit-cookie middleware): every
  POST/PUT/PATCH/DELETE must carry the signed ``csrftoken`` cookie's value, in the form's
  first field ``csrftoken`` or in the ``x-csrftoken`` header. ``starlette-csrf`` accepts the
  header only, so plain HTML forms could not post without a script; asgi-csrf reads both.
  asgi-csrf lets a request with no cookie at all through (nothing to forge, it reasons);
  here every unsafe request is checked (:class:`_Everywhere`), because on the loopback
  without a login a cross-site form carries no cookie and would otherwise pass. An
  ``Origin`` header naming another site is refused as well.
- **Request size**: a body over ``max_upload_bytes`` is refused with 413 before any of it
  reaches a form parser (:class:`BodyLimit`).
- **Headers** on every answer (:class:`SecurityHeaders`): a Content-Security-Policy without
  inline scripts (``script-src 'self'``), ``frame-ancestors 'none'``,
  ``X-Content-Type-Options: nosniff``, ``Referrer-Policy: no-referrer``,
  ``Cache-Control: no-store`` (patient data is not cached by the browser).
- **No pseudonym in a URL or a log**: patients and sessions are reached by numeric id, a
  search is a POST, and the access log drops query strings (:class:`QueryFreeAccessLog`).
"""

from __future__ import annotations

import functools
import json
import logging
import math
import re
import secrets
import time
from collections.abc import Awaitable, Callable
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

from argon2 import PasswordHasher
from argon2.exceptions import InvalidHashError, VerificationError
from asgi_csrf import asgi_csrf
from fastapi import APIRouter, Form, Request
from python_multipart.exceptions import FormParserError
from python_multipart.multipart import FormParser, parse_options_header
from starlette.responses import RedirectResponse

from models.fileio import write_owner_only
from rig.errors import RigConfigError
from rig.web.render import error_response, page, wants_json
from rig.web.settings import WebSettings, is_loopback

__all__ = [
    "MIN_PASSWORD",
    "BodyLimit",
    "LoginGate",
    "LoginThrottle",
    "QueryFreeAccessLog",
    "SecurityHeaders",
    "UserFile",
    "check_binding",
    "csrf_middleware",
    "router",
]

#: the shortest password accepted (NIST SP 800-63B, 5.1.1.2: at least 8 characters)
MIN_PASSWORD = 8
USER_NAME = re.compile(r"^[A-Za-z0-9_.-]{1,64}$")
SESSION_MAX_AGE_S = 8 * 3600
#: pages reachable without a login (the login form itself, the static files)
OPEN_PATHS = ("/login", "/static/")

_HASHER = PasswordHasher()


@functools.cache
def _dummy_hash() -> str:
    """A hash to verify against when the user does not exist, so that both answers take as
    long (made once, when first needed)."""
    return _HASHER.hash(secrets.token_hex(16))


ASGIApp = Callable[[dict, Callable, Callable], Awaitable[None]]


class UserFile:
    """The users of a server: a JSON file ``{"users": {name: {"hash", "created_at"}}}``,
    owner-only. A missing file has no users."""

    def __init__(self, path: str | Path, hasher: PasswordHasher | None = None) -> None:
        self.path = Path(path)
        # a new hash's parameters (argon2-cffi's defaults); a stored hash is checked with the
        # parameters written in it
        self.hasher = hasher or _HASHER

    def users(self) -> dict[str, dict]:
        """name → record (``hash``, ``created_at``)."""
        if not self.path.exists():
            return {}
        try:
            data = json.loads(self.path.read_text(encoding="utf-8"))
            users = data["users"]
            if not isinstance(users, dict):
                raise TypeError
        except (ValueError, KeyError, TypeError) as err:
            raise RigConfigError(f"{self.path}: not a rig users file (expected "
                                 '{"users": {...}})') from err
        return users

    def add(self, name: str, password: str) -> None:
        """Add ``name`` (or change its password), hashed with Argon2id."""
        if not USER_NAME.match(name or ""):
            raise RigConfigError(f"user name {name!r}: use 1-64 letters, digits, '.', '_' or "
                                 "'-'")
        if len(password) < MIN_PASSWORD:
            raise RigConfigError(f"password: at least {MIN_PASSWORD} characters")
        users = self.users()
        users[name] = {"hash": self.hasher.hash(password), "created_at": time.time()}
        write_owner_only(self.path, json.dumps({"users": users}, indent=1) + "\n")

    def verify(self, name: str, password: str) -> bool:
        """Whether ``password`` is ``name``'s (the same work whether or not the user
        exists)."""
        rec = self.users().get(name)
        stored = rec.get("hash") if isinstance(rec, dict) else None
        try:
            return _HASHER.verify(stored or _dummy_hash(), password) and bool(stored)
        except (VerificationError, InvalidHashError):
            return False


def check_binding(settings: WebSettings) -> None:
    """Refuse a server that would need a login but has nobody to log in (one line)."""
    if not settings.require_login:
        return
    n = len(UserFile(settings.users_path).users()) if settings.users_path else 0
    if n == 0:
        where = ("bound to " + settings.host if not is_loopback(settings.host)
                 else "with --login")
        raise RigConfigError(
            f"rig serve {where} needs a login and there is no user yet: add one with "
            f"rig serve --db DB --add-user NAME (or keep the default --host 127.0.0.1)")


# --------------------------------------------------------------------------- login
router = APIRouter()


#: Failed logins allowed for one user name, and from one client address, within
#: :data:`LOGIN_WINDOW_S`; beyond them every attempt is refused (429, the password not even
#: checked) until the oldest failure is older than the window — a password cannot be guessed
#: at the speed of the loopback (OWASP ASVS 4.0 V2.2.1, anti-automation).
LOGIN_FAILURES_PER_USER = 5
LOGIN_FAILURES_PER_ADDRESS = 20
LOGIN_WINDOW_S = 900.0
#: user names and addresses with failures kept before the stale ones are swept (memory stays
#: bounded however many names are guessed)
LOGIN_KEYS_KEPT = 10_000


class LoginThrottle:
    """Failed logins per user name and per client address over a sliding window.

    Parameters
    ----------
    clock : callable
        Seconds, monotonic (``time.monotonic``; tests give their own).
    """

    def __init__(self, clock: Callable[[], float] = time.monotonic) -> None:
        self.clock = clock
        self._failed: dict[tuple[str, str], list[float]] = {}

    def _recent(self, key: tuple[str, str], now: float) -> list[float]:
        got = [t for t in self._failed.get(key, ()) if now - t < LOGIN_WINDOW_S]
        if got:
            self._failed[key] = got
        else:
            self._failed.pop(key, None)
        return got

    def wait_s(self, address: str, user: str) -> float:
        """Seconds before ``user`` may try again from ``address`` (0: now)."""
        now = self.clock()
        wait = 0.0
        for key, limit in ((("user", user), LOGIN_FAILURES_PER_USER),
                           (("address", address), LOGIN_FAILURES_PER_ADDRESS)):
            recent = self._recent(key, now)
            if len(recent) >= limit:
                wait = max(wait, LOGIN_WINDOW_S - (now - recent[-limit]))
        return wait

    def failed(self, address: str, user: str) -> None:
        """One failed login of ``user`` from ``address``."""
        now = self.clock()
        if len(self._failed) > LOGIN_KEYS_KEPT:  # many names guessed: forget the stale ones
            for key in list(self._failed):
                self._recent(key, now)
        for key in (("user", user), ("address", address)):
            self._failed.setdefault(key, []).append(now)

    def succeeded(self, user: str) -> None:
        """``user`` logged in: its own failures are forgotten (the address's are not)."""
        self._failed.pop(("user", user), None)


@router.get("/login")
def login_form(request: Request):
    return page(request, "login.html", {"next": _safe_next(request.query_params.get("next"))})


@router.post("/login")
def login(request: Request, username: str = Form(""), password: str = Form(""),
          next: str = Form("/")):
    settings: WebSettings = request.app.state.settings
    users = UserFile(settings.users_path) if settings.users_path else None
    if not username or not password:
        return page(request, "login.html", {"error": "give a user name and a password",
                                            "next": _safe_next(next)}, status=400)
    throttle: LoginThrottle = request.app.state.login_throttle
    address = request.client.host if request.client else "?"
    wait = throttle.wait_s(address, username)
    if wait > 0:
        return page(request, "login.html", {
            "error": f"too many failed logins: try again in {math.ceil(wait / 60)} min",
            "next": _safe_next(next)}, status=429)
    if users is None or not users.verify(username, password):
        throttle.failed(address, username)
        return page(request, "login.html", {"error": "wrong user name or password",
                                            "next": _safe_next(next)}, status=401)
    throttle.succeeded(username)
    request.session.clear()
    request.session["user"] = username
    request.session["since"] = time.time()
    return RedirectResponse(_safe_next(next), status_code=303)


@router.post("/logout")
def logout(request: Request):
    request.session.clear()
    return RedirectResponse("/login" if request.app.state.settings.require_login else "/",
                            status_code=303)


def _safe_next(target: str | None) -> str:
    """Where to go after the login: a path of this site only (no ``//host``, no scheme)."""
    if not target or not target.startswith("/") or target.startswith("//") or "\\" in target:
        return "/"
    return target


class LoginGate:
    """ASGI middleware (inside the session's): when the server needs a login, a request
    without a logged-in user is sent to the login page (a page) or refused with 401 (the API,
    and any other method). Puts ``rig_user`` and ``rig_require_login`` in the scope for the
    pages."""

    def __init__(self, app: ASGIApp, settings: WebSettings) -> None:
        self.app = app
        self.settings = settings

    async def __call__(self, scope: dict, receive: Callable, send: Callable) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        user = (scope.get("session") or {}).get("user")
        scope["rig_user"] = user
        scope["rig_require_login"] = self.settings.require_login
        path = scope["path"]
        if self.settings.require_login and user is None and not path.startswith(OPEN_PATHS):
            request = Request(scope)
            if wants_json(request) or scope["method"] not in ("GET", "HEAD"):
                answer = error_response(request, "log in first" + (
                    " (POST /login)" if wants_json(request) else ""), 401)
            else:
                answer = RedirectResponse(f"/login?next={path}", status_code=303)
            await answer(scope, _no_body, send)
            return
        await self.app(scope, receive, send)


# --------------------------------------------------------------------------- CSRF
class _Everywhere:
    """asgi-csrf's ``always_protect`` holds paths checked even without cookies: every path."""

    def __contains__(self, path: object) -> bool:
        return True


async def _csrf_failed(scope: dict, send: Callable, message_id: Any) -> None:
    request = Request(scope)
    why = getattr(message_id, "name", message_id)
    msg = ("the form's csrftoken field must come before any file" if why == "FILE_BEFORE_TOKEN"
           else "missing or wrong CSRF token: reload the page and send the form again "
                "(API: send the csrftoken cookie's value as the x-csrftoken header)")
    await error_response(request, msg, 403)(scope, _no_body, send)


async def _no_body() -> dict:
    return {"type": "http.request", "body": b"", "more_body": False}


def _is_multipart(scope: dict) -> bool:
    ctype = dict(scope.get("headers") or []).get(b"content-type", b"")
    return ctype.split(b";", 1)[0].strip().lower() == b"multipart/form-data"


class _MultipartToken:
    """The form-field check of a ``multipart/form-data`` request, which asgi-csrf 0.11 cannot
    make with python-multipart >= 0.0.13 (its parser's ``FileClass`` argument is gone): the
    same rule — the first part is the ``csrftoken`` field, equal to the cookie's token (the
    value asgi-csrf verified, ``scope["csrftoken"]``); a file before it is refused. The
    body (at most ``max_upload_bytes``, :class:`BodyLimit`) is parsed in memory and
    replayed."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: dict, receive: Callable, send: Callable) -> None:
        if scope["type"] != "http" or scope["method"] in SAFE_METHODS or not _is_multipart(
                scope) or _header_token_ok(scope):
            await self.app(scope, receive, send)
            return
        messages, body = [], b""
        while True:
            message = await receive()
            messages.append(message)
            body += message.get("body", b"")
            if message["type"] != "http.request" or not message.get("more_body", False):
                break
        ctype = dict(scope.get("headers") or []).get(b"content-type", b"")
        parts: list[tuple[str, bytes | None, bytes | None]] = []
        try:
            _, params = parse_options_header(ctype)
            parser = FormParser("multipart/form-data",
                                lambda f: parts.append(("field", f.field_name, f.value)),
                                lambda f: parts.append(("file", f.field_name, None)),
                                boundary=params.get(b"boundary"))
            parser.write(body)
            parser.finalize()
        except (FormParserError, ValueError):
            parts = []
        expected = scope["csrftoken"]() if callable(scope.get("csrftoken")) else ""
        first = parts[0] if parts else ("none", None, None)
        if first[0] == "file":
            await _csrf_failed(scope, send, "FILE_BEFORE_TOKEN")
            return
        got = (first[2] or b"").decode("utf-8", "replace") if first[1] == b"csrftoken" else ""
        if not expected or not secrets.compare_digest(got, expected):
            await _csrf_failed(scope, send, "MULTIPART_MISMATCH")
            return

        async def replay() -> dict:
            return messages.pop(0) if messages else await receive()

        await self.app(scope, replay, send)


SAFE_METHODS = ("GET", "HEAD", "OPTIONS", "TRACE")


def _header_token_ok(scope: dict) -> bool:
    """The ``x-csrftoken`` header matched (asgi-csrf let the request through for it)."""
    headers = dict(scope.get("headers") or [])
    got = headers.get(b"x-csrftoken", b"").decode("latin-1")
    expected = scope["csrftoken"]() if callable(scope.get("csrftoken")) else ""
    return bool(got) and bool(expected) and secrets.compare_digest(got, expected)


def csrf_middleware(app: ASGIApp, settings: WebSettings) -> ASGIApp:
    """``app`` behind asgi-csrf (and :class:`_MultipartToken` for multipart forms) and a
    same-origin check on unsafe requests."""
    guarded = asgi_csrf(_MultipartToken(app), signing_secret=settings.secret,
                        always_protect=_Everywhere(), skip_if_scope=_is_multipart,
                        send_csrf_failed=_csrf_failed, cookie_samesite="Strict")

    async def wrapped(scope: dict, receive: Callable, send: Callable) -> None:
        if scope["type"] == "http" and scope["method"] not in ("GET", "HEAD", "OPTIONS"):
            headers = dict(scope.get("headers") or [])
            origin = headers.get(b"origin", b"").decode("latin-1")
            host = headers.get(b"host", b"").decode("latin-1")
            if origin and origin != "null" and urlsplit(origin).netloc != host:
                request = Request(scope)
                await error_response(request, f"a form from another site ({origin}) is "
                                     "refused", 403)(scope, _no_body, send)
                return
        await guarded(scope, receive, send)

    return wrapped


# --------------------------------------------------------------------------- body size
class BodyLimit:
    """ASGI middleware: a request body over ``limit`` bytes is refused with 413 (by its
    Content-Length at once, or as it streams in), before any parser sees it."""

    def __init__(self, app: ASGIApp, limit: int) -> None:
        self.app = app
        self.limit = int(limit)

    async def __call__(self, scope: dict, receive: Callable, send: Callable) -> None:
        if scope["type"] != "http" or scope["method"] in ("GET", "HEAD", "OPTIONS"):
            await self.app(scope, receive, send)
            return
        headers = dict(scope.get("headers") or [])
        declared = headers.get(b"content-length")
        if declared is not None:
            try:
                too_big = int(declared) > self.limit
            except ValueError:
                too_big = True
            if too_big:
                await self._refuse(scope, send)
                return
        messages, size = [], 0
        while True:
            message = await receive()
            if message["type"] != "http.request":
                messages.append(message)
                break
            size += len(message.get("body", b""))
            if size > self.limit:
                await self._refuse(scope, send)
                return
            messages.append(message)
            if not message.get("more_body", False):
                break

        async def replay() -> dict:
            return messages.pop(0) if messages else await receive()

        await self.app(scope, replay, send)

    async def _refuse(self, scope: dict, send: Callable) -> None:
        request = Request(scope)
        await error_response(request, f"the request is larger than the "
                             f"{self.limit // 1024} KiB this server accepts",
                             413)(scope, _no_body, send)


# --------------------------------------------------------------------------- headers
CSP = ("default-src 'self'; script-src 'self'; style-src 'self'; img-src 'self' data:; "
       "connect-src 'self'; object-src 'none'; base-uri 'none'; form-action 'self'; "
       "frame-ancestors 'none'")


class SecurityHeaders:
    """ASGI middleware: the security headers on every answer (a route's own
    Content-Security-Policy, such as the report's, is kept)."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: dict, receive: Callable, send: Callable) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return

        async def with_headers(message: dict) -> None:
            if message["type"] == "http.response.start":
                headers = list(message.get("headers") or [])
                have = {k.lower() for k, _ in headers}
                for k, v in ((b"content-security-policy", CSP.encode()),
                             (b"x-content-type-options", b"nosniff"),
                             (b"x-frame-options", b"DENY"),
                             (b"referrer-policy", b"no-referrer"),
                             (b"cache-control", b"no-store")):
                    if k not in have:
                        headers.append((k, v))
                message = {**message, "headers": headers}
            await send(message)

        await self.app(scope, receive, with_headers)


#: the served report: a self-contained page with its own <style> and data: images, no script
REPORT_CSP = ("default-src 'none'; style-src 'unsafe-inline'; img-src data:; "
              "frame-ancestors 'none'; base-uri 'none'; form-action 'none'")


# --------------------------------------------------------------------------- access log
class QueryFreeAccessLog(logging.Filter):
    """A filter for uvicorn's access log: the path without its query string (whatever a
    client put there is not kept)."""

    def filter(self, record: logging.LogRecord) -> bool:
        args = record.args
        if isinstance(args, tuple) and len(args) >= 3 and isinstance(args[2], str):
            record.args = (*args[:2], args[2].split("?", 1)[0], *args[3:])
        return True
