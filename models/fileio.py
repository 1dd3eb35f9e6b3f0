"""Files that may carry a patient's data: written owner-only, atomically.

A constraint file, a trained model (its metadata embeds the constraint and the patient's
pseudonym), a report, telemetry and run summaries identify a patient by pseudonym and describe
their body. They are created readable and writable by their owner only (``0600``, whatever the
umask), as the session database is. Whole files are written to a temporary name beside the
target, flushed to disk and renamed over it, so a crash never leaves half a file under the final
name; a file that grows while it is written (telemetry) is opened owner-only from the start.

:func:`check_output` is the one check every output path passes before the work that fills it
(and before anything is written to a device): the folder must take a new file, which is tried,
not inferred from permission bits (root writes through ``0555``, not into ``/proc``, a read-only
mount or an immutable folder).
"""

from __future__ import annotations

import contextlib
import errno
import os
import tempfile
from pathlib import Path
from typing import IO

from models.errors import OutputPathError

__all__ = ["check_output", "open_owner_only", "probe_folder", "write_owner_only"]


def probe_folder(folder: str | os.PathLike) -> None:
    """Create and remove an empty file in ``folder``; raises :class:`OSError` when the folder
    does not take new files (the only test that holds for root, read-only mounts, immutable
    folders and pseudo file systems alike)."""
    fd, tmp = tempfile.mkstemp(prefix=".probe.", suffix=".tmp", dir=folder)
    os.close(fd)
    os.unlink(tmp)


def _reason(err: OSError) -> str:
    if err.errno == errno.ENOENT:  # the folder is there: /proc and the like refuse new names
        return "it does not take new files"
    return (err.strerror or str(err)).lower()


def check_output(path: str | os.PathLike, option: str = "--out", *,
                 folder: bool = False) -> Path:
    """Check, before any work, that ``path`` can be written; returns it as a :class:`Path`.

    A file (``folder=False``): not a folder, its folder exists and takes a new file (the
    temporary sibling :func:`write_owner_only` renames), and an existing regular file may be
    opened for writing (an immutable file may not be replaced). A folder (``folder=True``,
    created with its parents by the caller): not a file, and its nearest existing folder takes
    a new file.

    Raises
    ------
    OutputPathError
        One line naming ``option``, the path and the reason, e.g. ``--out /proc/x.yaml: cannot
        write in /proc (it does not take new files)``.
    """
    shown = f"{option} {os.fspath(path)}"
    if not os.fspath(path):
        raise OutputPathError(f"{option}: empty path")
    p = Path(path)
    if folder:
        if p.exists() and not p.is_dir():
            raise OutputPathError(f"{shown}: is a file, expected a folder")
        where = p
        while not where.exists() and where != where.parent:
            where = where.parent
    else:
        if p.is_dir():
            raise OutputPathError(f"{shown}: is a directory (give a file name)")
        where = p.parent
        if not where.exists():
            raise OutputPathError(f"{shown}: directory {where} does not exist")
    if not where.is_dir():
        raise OutputPathError(f"{shown}: {where} is not a directory")
    try:
        probe_folder(where)
    except OSError as err:
        raise OutputPathError(f"{shown}: cannot write in {where} ({_reason(err)})") from None
    if not folder and p.is_file():
        try:  # neither created nor truncated: the file is left as it is
            os.close(os.open(p, os.O_WRONLY | os.O_APPEND))
        except OSError as err:
            raise OutputPathError(f"{shown}: cannot replace it ({_reason(err)})") from None
    return p


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
