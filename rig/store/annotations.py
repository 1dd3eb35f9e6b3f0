"""Annotations: a clinician's notes at moments of a session (on the samples' clock)."""

from __future__ import annotations

import time

from rig.store import schema as S
from rig.store.rows import Repository, finite


class AnnotationRepository(Repository):
    """The ``annotations`` table: ``store.annotations``."""

    table = S.annotations
    what = "annotation"

    def add(self, session_id: int, t: float, text: str) -> int:
        """A clinician's note at time ``t`` (s, the samples' clock)."""
        self._require_session(session_id)
        return self._insert(session_id=int(session_id), t=finite("t", t), text=str(text),
                            created_at=time.time())

    def list(self, session_id: int) -> list[dict]:
        """The notes of a session in time order."""
        return self._of_session(session_id, S.annotations.c.t, S.annotations.c.id)
