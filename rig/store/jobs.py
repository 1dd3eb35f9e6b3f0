"""Jobs: the web app's long work (a recording, a boundary extraction, a training), run by the
server process off the request path (:mod:`rig.web.jobs`).

A job is opened ``running`` by the process that runs it (its writer: host, pid, process start,
as a session's; :mod:`rig.store.liveness`), updated with its latest progress while it runs (a
heartbeat each time) and closed with its status, result and one-line message. A job left
``running`` by a server that died reads as ``died`` (:meth:`JobRepository.get`,
:meth:`JobRepository.list`: the ``state`` key) and is closed so by
:meth:`JobRepository.close_died`.

One job at a time per ``resource`` (a rig's ports; a session's boundary or model):
:meth:`JobRepository.start` refuses, in one line, a second live job on the same resource, in the
transaction that would insert it.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from typing import Any

from sqlalchemy import select

from rig.errors import RigConfigError
from rig.store import schema as S
from rig.store.liveness import Probe, judge, probe_process, this_writer
from rig.store.rows import Repository, check_choice, check_text, dumps

JOB_KINDS = ("record", "boundary", "train")
JOB_STATUSES = ("running", "completed", "interrupted", "failed", "died")


class JobBusyError(RigConfigError):
    """A job is asked for a resource another live job holds (the message names that job)."""


class JobRepository(Repository):
    """The ``jobs`` table: ``store.jobs``."""

    table = S.jobs
    what = "job"
    json_columns = ("params", "progress", "result")

    def start(self, kind: str, resource: str, *, params: Mapping[str, Any] | None = None,
              patient_id: int | None = None, session_id: int | None = None,
              probe: Probe = probe_process) -> int:
        """Open a job (status ``running``, the calling process its writer) and return its id.

        Raises
        ------
        JobBusyError
            Another job on ``resource`` is running and its writer is alive.
        """
        kind = check_choice("kind", kind, JOB_KINDS)
        resource = check_text("resource", resource, 256)
        me = this_writer()
        now = time.time()
        with self.db.transaction() as conn:
            _refuse_busy(conn, resource, probe)
            res = conn.execute(S.jobs.insert().values(
                kind=kind, status="running", resource=resource, patient_id=patient_id,
                session_id=session_id, params=dumps(params), progress="{}", result="{}",
                created_at=now, writer_host=me.host, writer_pid=me.pid,
                writer_start=me.start, heartbeat_at=now))
            return int(res.inserted_primary_key[0])

    def check_free(self, resource: str, *, probe: Probe = probe_process) -> None:
        """Raise :class:`JobBusyError` when a live job holds ``resource`` (before a caller
        opens it; :meth:`start` checks again as it inserts)."""
        with self.db.transaction(write=False) as conn:
            _refuse_busy(conn, resource, probe)

    def update(self, job_id: int, *, progress: Mapping[str, Any] | None = None,
               session_id: int | None = None) -> None:
        """Replace a running job's progress (and set its session once known); a heartbeat."""
        values: dict[str, Any] = {"heartbeat_at": time.time()}
        if progress is not None:
            values["progress"] = dumps(progress)
        if session_id is not None:
            values["session_id"] = int(session_id)
        with self.db.transaction() as conn:
            conn.execute(S.jobs.update().where(S.jobs.c.id == int(job_id)).values(**values))

    def end(self, job_id: int, status: str, *, result: Mapping[str, Any] | None = None,
            message: str | None = None, progress: Mapping[str, Any] | None = None) -> None:
        """Close a job with its status, result and one-line message."""
        status = check_choice("status", status, JOB_STATUSES)
        values: dict[str, Any] = {"status": status, "ended_at": time.time(),
                                  "result": dumps(result), "message": message}
        if progress is not None:
            values["progress"] = dumps(progress)
        with self.db.transaction() as conn:
            conn.execute(S.jobs.update().where(S.jobs.c.id == int(job_id)).values(**values))

    def get(self, job_id: int, *, probe: Probe = probe_process) -> dict:
        """The job ``job_id``; ``state`` is its status, or ``died`` for a running job whose
        writer is gone."""
        row = self._get(job_id)
        row["state"] = _state(row, probe)
        return row

    def list(self, *, session_id: int | None = None, patient_id: int | None = None,
             kind: str | None = None, limit: int = 50,
             probe: Probe = probe_process) -> list[dict]:
        """Jobs, newest first (with ``state`` as :meth:`get`)."""
        c = S.jobs.c
        q = select(S.jobs)
        if session_id is not None:
            q = q.where(c.session_id == int(session_id))
        if patient_id is not None:
            q = q.where(c.patient_id == int(patient_id))
        if kind is not None:
            q = q.where(c.kind == kind)
        rows = self._list(q.order_by(c.id.desc()).limit(int(limit)))
        for r in rows:
            r["state"] = _state(r, probe)
        return rows

    def close_died(self, *, probe: Probe = probe_process) -> list[int]:
        """Close every ``running`` job whose writer is gone as ``died``; their ids."""
        dead = [r for r in self._list(select(S.jobs).where(S.jobs.c.status == "running"))
                if _state(r, probe) == "died"]
        for r in dead:
            self.end(r["id"], "died", result=r["result"], progress=r["progress"],
                     message="the server stopped while this job ran; what it had stored "
                             "is kept")
        return [int(r["id"]) for r in dead]


def _refuse_busy(conn, resource: str, probe: Probe) -> None:
    running = conn.execute(select(S.jobs).where(
        (S.jobs.c.resource == resource) & (S.jobs.c.status == "running"))).mappings().all()
    for row in running:
        if _state(dict(row), probe) == "running":
            raise JobBusyError(f"busy: job {row['id']} ({row['kind']}) is running on "
                               f"{_what(resource)}; wait for it or stop it first")


def _state(row: dict, probe: Probe) -> str:
    if row["status"] != "running":
        return str(row["status"])
    live = judge({**row, "started_at": row["created_at"]}, probe=probe)
    return "running" if live.state == "live" else "died"


def _what(resource: str) -> str:
    kind, _, name = resource.partition(":")
    return {"rig": f"the rig's port {name}", "session": f"session {name}"}.get(kind, resource)
