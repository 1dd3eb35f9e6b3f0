"""Calibrations: a session's calibration results (IMU-to-segment alignment, heading, ...),
each a JSON document with its kind and residual."""

from __future__ import annotations

import time
from collections.abc import Mapping
from typing import Any

from rig.store import schema as S
from rig.store.rows import Repository, check_text, dumps, finite


class CalibrationRepository(Repository):
    """The ``calibrations`` table: ``store.calibrations``."""

    table = S.calibrations
    what = "calibration"
    json_columns = ("data",)

    def add(self, session_id: int, kind: str, data: Mapping[str, Any],
            residual_deg: float | None = None) -> int:
        """Store a calibration result (``data`` JSON-serialisable; arrays become lists)."""
        kind = check_text("calibration kind", kind, 64)
        self._require_session(session_id)
        res_deg = None if residual_deg is None else finite("residual_deg", residual_deg)
        return self._insert(session_id=int(session_id), kind=kind, data=dumps(data),
                            residual_deg=res_deg, created_at=time.time())

    def list(self, session_id: int) -> list[dict]:
        """The calibrations of a session, oldest first, ``data`` decoded."""
        return self._of_session(session_id)
