"""Trained models: a model file registered by its path and SHA-256, with its metrics, linked to
the boundary it learned and/or the session it came from."""

from __future__ import annotations

import hashlib
import os
import time
from collections.abc import Mapping
from typing import Any

from sqlalchemy import select

from rig.errors import RigConfigError
from rig.store import schema as S
from rig.store.rows import Repository, dumps


class ModelRepository(Repository):
    """The ``models`` table: ``store.models``."""

    table = S.models
    what = "model"
    json_columns = ("metrics",)

    def add(self, path: str | os.PathLike, *, sha256: str | None = None,
            metrics: Mapping[str, Any] | None = None, boundary_id: int | None = None,
            session_id: int | None = None) -> int:
        """Register a trained model file: its path, SHA-256 (computed from the file when not
        given) and metrics; linked to the boundary it learned and/or the session."""
        path = os.fspath(path)
        if sha256 is None:
            sha256 = file_sha256(path)
        sha256 = str(sha256).lower()
        if len(sha256) != 64 or any(c not in "0123456789abcdef" for c in sha256):
            raise RigConfigError(f"model {path}: sha256 must be 64 hex digits, got {sha256!r}")
        if boundary_id is not None:
            self._require(S.boundaries, boundary_id, "boundary")
        if session_id is not None:
            self._require_session(session_id)
        return self._insert(boundary_id=boundary_id, session_id=session_id, path=path,
                            sha256=sha256, metrics=dumps(metrics), created_at=time.time())

    def get(self, model_id: int) -> dict:
        """The model ``model_id``, ``metrics`` decoded."""
        return self._get(model_id)

    def list(self, *, boundary_id: int | None = None,
             session_id: int | None = None) -> list[dict]:
        """The registered models, oldest first: every one, or those of a boundary and/or a
        session."""
        q = select(S.models).order_by(S.models.c.id)
        if boundary_id is not None:
            q = q.where(S.models.c.boundary_id == int(boundary_id))
        if session_id is not None:
            q = q.where(S.models.c.session_id == int(session_id))
        return self._list(q)


def file_sha256(path: str | os.PathLike) -> str:
    """Hex SHA-256 of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()
