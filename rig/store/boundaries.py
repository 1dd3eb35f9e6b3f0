"""Boundaries: extracted constraint files (one joint's, or a whole limb's) as YAML text with
their provenance, from a session or from an imported file."""

from __future__ import annotations

import time
from collections.abc import Mapping
from typing import Any

from rig.errors import RigConfigError
from rig.store import schema as S
from rig.store.rows import Repository, dumps

#: ``meta["kind"]`` of a stored boundary that is a whole limb file (``rig boundary --chain`` on
#: a session), not one joint's constraint
LIMB_BOUNDARY = "limb"


class BoundaryRepository(Repository):
    """The ``boundaries`` table: ``store.boundaries``."""

    table = S.boundaries
    what = "boundary"
    json_columns = ("meta",)

    def add(self, session_id: int | None, constraint_yaml: str,
            meta: Mapping[str, Any] | None = None) -> int:
        """Store an extracted boundary: the constraint file's YAML text and its provenance.
        ``session_id`` is ``None`` for a boundary extracted from an imported file."""
        if not isinstance(constraint_yaml, str) or not constraint_yaml.strip():
            raise RigConfigError("boundary: constraint_yaml must be non-empty YAML text")
        if session_id is not None:
            self._require_session(session_id)
        return self._insert(session_id=None if session_id is None else int(session_id),
                            constraint_yaml=constraint_yaml, meta=dumps(meta),
                            created_at=time.time())

    def get(self, boundary_id: int) -> dict:
        """The boundary ``boundary_id``, ``meta`` decoded."""
        return self._get(boundary_id)

    def list(self, session_id: int, *, limb: bool | None = None) -> list[dict]:
        """The boundaries stored with a session, oldest first: every one, or (``limb``) only
        the whole-limb files (``meta.kind`` ``"limb"``, :data:`LIMB_BOUNDARY`) or only the
        single joints' constraints."""
        out = self._of_session(session_id)
        # the caller's filter, not a branch: which stored rows are limb files is decided here
        # only, by the tag rig boundary --limb writes (LIMB_BOUNDARY)
        if limb is None:
            return out
        return [r for r in out if ((r["meta"] or {}).get("kind") == LIMB_BOUNDARY) == limb]
