"""What a ``rig serve`` server is given: the store, where it listens, who may log in, where it
keeps the files it renders. One frozen dataclass, read by every part of the app through
``request.app.state.settings``.
"""

from __future__ import annotations

import ipaddress
import os
from dataclasses import dataclass
from pathlib import Path

__all__ = ["DEFAULT_HOST", "DEFAULT_PORT", "MAX_UPLOAD_BYTES", "WebSettings", "is_loopback"]

DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 8765
#: the largest request body accepted (a form, a constraint file): bytes
MAX_UPLOAD_BYTES = 1 << 20


def is_loopback(host: str) -> bool:
    """Whether ``host`` is this machine only (``127.0.0.0/8``, ``::1``, ``localhost``): a
    server bound there is reached by local users only."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


@dataclass(frozen=True)
class WebSettings:
    """A server's settings.

    Parameters
    ----------
    db : str
        The store: a SQLite path, ``sqlite:///PATH`` or ``postgresql://...`` (as ``--db``).
    cache_dir : path
        A private folder (0700) for what the server renders (reports, exports); per server.
    users_path : path or None
        The users file (:mod:`rig.web.security`); None: no users.
    host : str
        The address the server is bound to; any but the loopback makes every page ask for a
        login (:attr:`require_login`).
    secret : str
        Signs the login-session cookie and the CSRF token; random per server start unless
        given.
    max_upload_bytes : int
        The largest request body accepted.
    login : bool
        Ask for a login even on the loopback.
    rigs : tuple of str
        Rig configuration files offered besides the shipped ones (``rig serve --rig``),
        checked when the server starts.
    files_dir : path or None
        Where the jobs (:class:`rig.web.jobs.JobRunner`) write a session's boundaries and
        models, kept after the server stops; None: a ``files`` folder in ``cache_dir``.
    """

    db: str
    cache_dir: Path
    users_path: Path | None = None
    host: str = DEFAULT_HOST
    secret: str = ""
    max_upload_bytes: int = MAX_UPLOAD_BYTES
    login: bool = False
    files_dir: Path | None = None
    rigs: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if not self.secret:
            object.__setattr__(self, "secret", os.urandom(32).hex())
        object.__setattr__(self, "cache_dir", Path(self.cache_dir))
        object.__setattr__(self, "files_dir", self.cache_dir / "files"
                           if self.files_dir is None else Path(self.files_dir))

    @property
    def require_login(self) -> bool:
        """Every page needs a logged-in user: bound beyond the loopback, or asked to."""
        return self.login or not is_loopback(self.host)
