"""Runs: the live loop's enforcement runs within a session, and their per-cycle telemetry.

A run is opened ``running`` and closed with its end-of-run summary; the cycles' telemetry
rows are inserted by the :class:`~rig.store.writers.TelemetryWriter` (through
:meth:`RunRepository.insert_telemetry`) and read back as one array per column.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from typing import Any

import numpy as np
from sqlalchemy import func, select
from sqlalchemy.engine import Connection

from rig.store import schema as S
from rig.store.rows import Repository, check_choice, dumps, loads

RUN_STATUSES = ("running", "completed", "interrupted", "safe_state", "failed")


class RunRepository(Repository):
    """The ``runs`` and ``telemetry`` tables: ``store.runs``."""

    table = S.runs
    what = "run"
    json_columns = ("meta", "summary")

    def start(self, session_id: int, meta: Mapping[str, Any] | None = None) -> int:
        """Open a live-loop run (status ``running``) within a session."""
        self._require_session(session_id)
        return self._insert(session_id=int(session_id), status="running",
                            started_at=time.time(), meta=dumps(meta))

    def end(self, run_id: int, summary: Mapping[str, Any] | None = None, *,
            status: str = "completed") -> None:
        """Close a run with its end-of-run summary (``rate_hz``, ``cycles``, ``p99_cycle_ms``)."""
        status = check_choice("status", status, RUN_STATUSES)
        self.get(run_id)
        with self.db.transaction() as conn:
            conn.execute(S.runs.update().where(S.runs.c.id == int(run_id)).values(
                status=status, ended_at=time.time(), summary=dumps(summary),
            ))

    def get(self, run_id: int) -> dict:
        """The run ``run_id``, ``meta`` and ``summary`` decoded."""
        return self._get(run_id)

    @staticmethod
    def insert_telemetry(conn: Connection, params: list[dict]) -> None:
        """Insert telemetry rows (one dict each, the same keys in every one) in the caller's
        transaction ``conn``."""
        conn.execute(S.telemetry.insert(), params)

    @staticmethod
    def insert_joint_telemetry(conn: Connection, params: list[dict]) -> None:
        """Insert a limb run's per-joint telemetry rows (``run_id``, ``cycle``, ``joint`` and
        :data:`~rig.store.schema.JOINT_TELEMETRY_COLUMNS`) in the caller's transaction."""
        conn.execute(S.telemetry_joints.insert(), params)

    def telemetry(self, run_id: int) -> dict[str, np.ndarray]:
        """Telemetry of a run in cycle order: one array per column of
        :data:`~rig.store.schema.TELEMETRY_COLUMNS` (float64, NaN for missing; ``fault`` and
        ``extra`` as object arrays, ``extra`` decoded), then the numeric keys of ``extra`` as
        columns of their own (a limb run's per-joint columns, named as in its CSV)."""
        cols = [S.telemetry.c[n] for n in S.TELEMETRY_COLUMNS] + [S.telemetry.c.extra]
        q = select(*cols).where(S.telemetry.c.run_id == int(run_id)).order_by(S.telemetry.c.id)
        with self.db.transaction(write=False) as conn:
            rows = conn.execute(q).all()
        names = [*S.TELEMETRY_COLUMNS, "extra"]
        data = list(zip(*rows, strict=True)) if rows else [() for _ in names]
        out: dict[str, np.ndarray] = {}
        for name, col in zip(names, data, strict=True):
            if name == "fault":
                out[name] = np.array(col, dtype=object)
            elif name == "extra":
                out[name] = np.array([loads(v) for v in col], dtype=object)
            elif name in ("cycle", "intervention"):
                out[name] = np.array([-1 if v is None else v for v in col], dtype=np.int64)
            else:
                out[name] = np.array([np.nan if v is None else v for v in col], dtype=np.float64)
        out.update(_joint_columns(self.db, int(run_id), out["cycle"]))
        out.update(_extra_columns(out["extra"], out))
        return out

    def list(self, session_id: int) -> list[dict]:
        """The runs of a session, oldest first."""
        return self._of_session(session_id)


def _joint_columns(db, run_id: int, cycles: np.ndarray) -> dict[str, np.ndarray]:
    """A limb run's per-joint telemetry as columns ``<joint>_<column>`` (the CSV's names),
    aligned with the run's cycles (NaN, or -1 for ``intervention``, where a cycle has no row
    of that joint); the joints in the order they first appear."""
    t = S.telemetry_joints
    cols = [t.c.joint, t.c.cycle] + [t.c[c] for c in S.JOINT_TELEMETRY_COLUMNS]
    q = select(*cols).where(t.c.run_id == run_id).order_by(t.c.id)
    with db.transaction(write=False) as conn:
        rows = conn.execute(q).all()
    if not rows:
        return {}
    where = {int(c): i for i, c in enumerate(cycles.tolist())}
    names = list(dict.fromkeys(r[0] for r in rows))
    out: dict[str, np.ndarray] = {}
    for name in names:
        for c in S.JOINT_TELEMETRY_COLUMNS:
            out[f"{name}_{c}"] = (np.full(len(cycles), -1, dtype=np.int64)
                                  if c == "intervention" else np.full(len(cycles), np.nan))
    for r in rows:
        i = where.get(int(r[1]))
        if i is None:
            continue
        for c, v in zip(S.JOINT_TELEMETRY_COLUMNS, r[2:], strict=True):
            if v is not None:
                out[f"{r[0]}_{c}"][i] = v
    return out


def _extra_columns(extra: np.ndarray, have: dict) -> dict[str, np.ndarray]:
    """The numeric keys of the ``extra`` JSON as columns of their own (a limb's per-joint
    telemetry, ``<joint>_commanded_w`` ...: the CSV's names), NaN where a row lacks one;
    ``*_intervention`` as int64 (-1 where missing). Keys of a column, and keys with any
    non-numeric value, are left in ``extra``."""
    keys: dict[str, bool] = {}
    for d in extra:
        for k, v in (d or {}).items():
            numeric = v is None or (isinstance(v, (int, float)) and not isinstance(v, bool))
            keys[k] = keys.get(k, True) and numeric
    out: dict[str, np.ndarray] = {}
    for k, numeric in keys.items():
        if not numeric or k in have:
            continue
        vals = [(d or {}).get(k) for d in extra]
        if k.endswith("_intervention"):
            out[k] = np.array([-1 if v is None else v for v in vals], dtype=np.int64)
        else:
            out[k] = np.array([np.nan if v is None else v for v in vals], dtype=np.float64)
    return out


def run_counts(conn: Connection, session_ids: list[int]) -> dict[int, int]:
    """How many runs each session in ``session_ids`` has (those with none left out), in the
    caller's transaction."""
    return {int(sid): int(n) for sid, n in conn.execute(
        select(S.runs.c.session_id, func.count())
        .where(S.runs.c.session_id.in_(session_ids))
        .group_by(S.runs.c.session_id))}


def interrupt_runs(conn: Connection, session_id: int, end: float) -> None:
    """Mark a session's runs still ``running`` ``interrupted``, ended at ``end``, in the
    caller's transaction."""
    conn.execute(
        S.runs.update()
        .where((S.runs.c.session_id == int(session_id)) & (S.runs.c.status == "running"))
        .values(status="interrupted", ended_at=end)
    )
