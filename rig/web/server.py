"""``rig serve`` as a library: the app of :func:`rig.web.app.create_app` on uvicorn, on a socket
bound here (port 0: a free port, told through ``on_ready``), the access log without query
strings, a private cache folder removed at the end.
"""

from __future__ import annotations

import logging
import shutil
import socket
import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import uvicorn

from rig.errors import RigConfigError
from rig.web.app import create_app
from rig.web.jobs import offered_rigs
from rig.web.security import QueryFreeAccessLog, check_binding
from rig.web.settings import DEFAULT_HOST, DEFAULT_PORT, WebSettings

__all__ = ["ServeRequest", "bind", "default_users_path", "run_server"]


def default_users_path(db: str) -> Path | None:
    """The users file beside a SQLite store (``clinic.db`` → ``clinic.db.users.json``); None
    for a server database (give ``--users``)."""
    if "://" in db and not db.startswith("sqlite:///"):
        return None
    path = db[len("sqlite:///"):] if db.startswith("sqlite:///") else db
    return Path(path + ".users.json")


def default_files_path(db: str) -> Path:
    """Where the jobs write a session's files (boundaries, models): beside a SQLite store
    (``clinic.db`` → ``clinic.db.files/``), else ``rig-files/`` in the current folder. Kept
    after the server stops: the store registers the models by path."""
    if "://" in db and not db.startswith("sqlite:///"):
        return Path("rig-files")
    path = db[len("sqlite:///"):] if db.startswith("sqlite:///") else db
    return Path(path + ".files")


def bind(host: str, port: int) -> socket.socket:
    """A listening TCP socket on ``host:port`` (one line when it cannot be had)."""
    try:
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)
    except socket.gaierror as err:
        raise RigConfigError(f"--host {host}: not an address of this machine ({err})") from err
    family, _, _, _, addr = infos[0]
    sock = socket.socket(family, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind(addr)
    except OSError as err:
        sock.close()
        raise RigConfigError(f"--host {host} --port {port}: cannot listen there "
                             f"({err.strerror})") from err
    sock.listen(2048)
    sock.set_inheritable(True)
    return sock


@dataclass(frozen=True)
class ServeRequest:
    """What ``rig serve`` is asked: the store, the address, the users file (default beside a
    SQLite store), a login even on the loopback, the access log, the cache folder (default: a
    private temporary folder removed at the end)."""

    db: str
    host: str = DEFAULT_HOST
    port: int = DEFAULT_PORT
    users: str | None = None
    login: bool = False
    access_log: bool = True
    cache: str | None = None
    #: where the jobs write a session's boundaries and models (default
    #: :func:`default_files_path`)
    files: str | None = None
    #: rig configuration files offered besides the shipped ones (``--rig``)
    rigs: tuple[str, ...] = ()


def run_server(request: ServeRequest, on_ready: Callable[[str], None] = print) -> None:
    """Serve until interrupted (Ctrl-C, SIGTERM). ``on_ready`` gets the line naming the URL
    once the socket listens."""
    if not (0 <= request.port <= 65535):
        raise RigConfigError(f"--port must be 0-65535, got {request.port}")
    users = Path(request.users) if request.users else default_users_path(request.db)
    files = Path(request.files) if request.files else default_files_path(request.db)
    settings_args = {"db": request.db, "users_path": users, "host": request.host,
                     "login": request.login, "files_dir": files, "rigs": tuple(request.rigs)}
    # the binding's rule first (no store opened, no socket taken), then the address
    check_binding(WebSettings(cache_dir=Path("."), **settings_args))
    offered_rigs(request.rigs)  # each --rig file read: one line before the socket is taken
    own_cache = request.cache is None
    with bind(request.host, request.port) as sock:
        cache = Path(tempfile.mkdtemp(prefix="rig-web-")) if own_cache else Path(request.cache)
        try:
            settings = WebSettings(cache_dir=cache, **settings_args)
            app = create_app(settings)
            host, port = sock.getsockname()[:2]
            shown = f"[{host}]" if ":" in host else host
            config = uvicorn.Config(app, log_level="info" if request.access_log else "warning",
                                    access_log=request.access_log, proxy_headers=False,
                                    server_header=False, timeout_graceful_shutdown=5)
            # after the Config: it sets uvicorn's loggers up
            logging.getLogger("uvicorn.access").addFilter(QueryFreeAccessLog())
            server = uvicorn.Server(config)
            login = "login required" if settings.require_login else "no login (loopback)"
            on_ready(f"rig serve: http://{shown}:{port}/ ({login}; store {request.db})")
            server.run(sockets=[sock])
        finally:
            if own_cache:
                shutil.rmtree(cache, ignore_errors=True)
