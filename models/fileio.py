"""Files that may carry a patient's data: written owner-only, atomically.

A constraint file, a trained model (its metadata embeds the constraint and the patient's
pseudonym), a report, telemetry and run summaries identify a patient by pseudonym and describe
their body. They are created readable and writable by their owner only (``0600``, whatever the
umask), as the session database is. Whole files are written to a temporary name beside the
target, flushed to disk and renamed over it, so a crash never leaves half a file under the final
name; a file that grows while it is written (telemetry) is opened owner-only from the start.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path
from typing import IO

__all__ = ["open_owner_only", "write_owner_only"]


def write_owner_only(path: str | os.PathLike, data: str | bytes) -> Path:
    """Write ``data`` (text is UTF-8) to ``path`` atomically, mode ``0600``; returns the path.

    The directory must exist. An existing file at ``path`` is replaced (and ends up ``0600``).
    """
    p = Path(path)
    raw = data.encode("utf-8") if isinstance(data, str) else bytes(data)
    fd, tmp = tempfile.mkstemp(prefix=f".{p.name}.", suffix=".tmp", dir=p.parent)
    try:
        os.fchmod(fd, 0o600)  # mkstemp's default, stated: whatever the umask
        with os.fdopen(fd, "wb") as fh:
            fh.write(raw)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, p)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise
    return p


def open_owner_only(path: str | os.PathLike, mode: str = "w", **kwargs) -> IO:
    """``open(path, mode)`` for writing a file created (or truncated) with mode ``0600``.

    ``mode`` is ``"w"``/``"wb"`` (truncate) or ``"a"``/``"ab"`` (append); ``kwargs`` go to
    :func:`open` (``newline``, ``encoding``).
    """
    if mode not in ("w", "wb", "a", "ab"):
        raise ValueError(f"mode must be 'w', 'wb', 'a' or 'ab', got {mode!r}")
    flags = os.O_WRONLY | os.O_CREAT | (os.O_APPEND if mode.startswith("a") else os.O_TRUNC)
    fd = os.open(os.fspath(path), flags, 0o600)
    try:
        os.fchmod(fd, 0o600)  # an existing file too
        return open(fd, mode, **kwargs)
    except BaseException:
        os.close(fd)
        raise
