"""Sessions: one recording or one live-loop enforcement of one patient, with the process
that writes it and that writer's heartbeat (:mod:`rig.store.liveness`).

A session is the parent of every other row of the store but patients: its sensors and samples
(:mod:`rig.store.samples`), calibrations, annotations, boundaries, models and runs each check
it exists. Listing sessions reads their sensors' counters and counts their runs in the same
transaction, so a listing costs per session, not per sample.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from typing import Any

from sqlalchemy import select
from sqlalchemy.engine import Connection

from rig.errors import RigConfigError
from rig.store import schema as S
from rig.store.liveness import STALE_AFTER_S, Liveness, Probe, judge, probe_process, this_writer
from rig.store.patients import PatientRepository
from rig.store.rows import (
    SIDES,
    Database,
    Repository,
    check_choice,
    dumps,
    finite,
    loads,
)
from rig.store.runs import interrupt_runs, run_counts
from rig.store.samples import SampleRepository, recording_span, sensor_spans

SESSION_KINDS = ("record", "enforce")
SESSION_STATUSES = ("running", "completed", "interrupted", "device_lost", "failed")


class SessionRepository(Repository):
    """The ``sessions`` table: ``store.sessions``.

    Parameters
    ----------
    db : Database
        The store.
    patients : PatientRepository
        Where a new session's patient is looked up.
    samples : SampleRepository
        Where an interrupted session's samples are counted.
    """

    table = S.sessions
    what = "session"
    json_columns = ("meta",)

    def __init__(self, db: Database, patients: PatientRepository,
                 samples: SampleRepository) -> None:
        super().__init__(db)
        self._patients = patients
        self._samples = samples

    def start(
        self,
        patient_id: int,
        *,
        rig_name: str | None = None,
        joint: str | None = None,
        side: str | None = None,
        kind: str = "record",
        meta: Mapping[str, Any] | None = None,
        started_at: float | None = None,
    ) -> int:
        """Open a session (status ``running``) and return its id.

        The calling process is recorded as the session's writer (host name, pid, process
        start; :mod:`rig.store.liveness`) until a sample writer claims it. ``started_at``
        (Unix time; default now) dates a session entered after the fact (a past visit).
        """
        kind = check_choice("kind", kind, SESSION_KINDS)
        side = check_choice("side", side, SIDES)
        self._patients.get(patient_id)
        me = this_writer()
        with self.db.transaction() as conn:
            res = conn.execute(
                S.sessions.insert().values(
                    patient_id=int(patient_id), rig_name=rig_name, joint=joint, side=side,
                    kind=kind, status="running",
                    started_at=time.time() if started_at is None else finite(
                        "started_at", started_at),
                    meta=dumps(meta),
                    writer_host=me.host, writer_pid=me.pid, writer_start=me.start,
                )
            )
            return int(res.inserted_primary_key[0])

    def claim_writer(self, session_id: int) -> None:
        """Record the calling process as the writer of ``session_id`` (a heartbeat too)."""
        me = this_writer()
        with self.db.transaction() as conn:
            conn.execute(S.sessions.update().where(S.sessions.c.id == int(session_id)).values(
                writer_host=me.host, writer_pid=me.pid, writer_start=me.start,
                heartbeat_at=time.time(),
            ))

    def end(
        self,
        session_id: int,
        *,
        status: str = "completed",
        meta: Mapping[str, Any] | None = None,
        dropped: int | None = None,
    ) -> None:
        """Close a session: ``status`` (one of :data:`SESSION_STATUSES`), ``meta`` merged into
        the session's, ``dropped`` (samples lost before the store) recorded when given."""
        status = check_choice("status", status, SESSION_STATUSES)
        cur = self.get(session_id)
        merged = dict(cur["meta"])
        merged.update(meta or {})
        values: dict[str, Any] = {"status": status, "ended_at": time.time(),
                                  "meta": dumps(merged)}
        if dropped is not None:
            values["dropped"] = int(dropped)
        with self.db.transaction() as conn:
            conn.execute(
                S.sessions.update().where(S.sessions.c.id == int(session_id)).values(**values)
            )

    def merge_meta(self, session_id: int, meta: Mapping[str, Any]) -> None:
        """Merge ``meta`` into the session's metadata (top-level keys replaced), e.g. a
        reader's cached results (``rig progress`` keeps each session's range of motion under
        ``rom_cache``)."""
        sc = S.sessions.c
        with self.db.transaction() as conn:  # read and write in one transaction
            row = conn.execute(select(sc.meta).where(sc.id == int(session_id))).first()
            if row is None:
                raise RigConfigError(f"no session {session_id} in {self.db.url}")
            merged = dict(loads(row[0]) or {})
            merged.update(meta)
            conn.execute(S.sessions.update().where(sc.id == int(session_id))
                         .values(meta=dumps(merged)))

    def set_dropped(self, session_id: int, dropped: int) -> None:
        """Record how many samples were lost before reaching the store (sequence gaps, full
        queues); the count is shown by ``rig session list``."""
        with self.db.transaction() as conn:
            conn.execute(
                S.sessions.update()
                .where(S.sessions.c.id == int(session_id))
                .values(dropped=int(dropped))
            )

    def get(self, session_id: int) -> dict:
        """The session row, ``meta`` decoded, plus ``pseudonym`` of its patient."""
        q = (
            select(S.sessions, S.patients.c.pseudonym)
            .join(S.patients, S.patients.c.id == S.sessions.c.patient_id)
            .where(S.sessions.c.id == int(session_id))
        )
        with self.db.transaction(write=False) as conn:
            row = conn.execute(q).mappings().first()
        if row is None:
            raise RigConfigError(f"no session {session_id} in {self.db.url}")
        return self._row(row)

    def list(self, *, stale_after_s: float = STALE_AFTER_S, now: float | None = None,
             host: str | None = None, probe: Probe = probe_process,
             patient: str | None = None, since: float | None = None,
             limit: int | None = None) -> list[dict]:
        """Sessions, oldest first, with their patient's pseudonym and sample counts.

        ``patient`` keeps one pseudonym's, ``since`` those started at or after that Unix time,
        ``limit`` the newest that many (of those). The counts are the sensors' own (schema v5,
        kept by the sample writer), so a listing costs per session, not per sample.

        Each dict has the session columns plus ``pseudonym``, ``samples`` (total),
        ``samples_by_sensor`` ({name: count}), ``recording_s`` (the time the samples span: the
        devices' own clock where they stamp their samples, else the host's — for a recording
        made faster than real time, the patient's time), ``runs`` (number of live-loop runs),
        ``last_sample_at`` (Unix time of the newest sample, None when unknown) and
        ``liveness`` (``{"state", "reason"}``: for a ``running`` session ``live``,
        ``interrupted`` or ``unknown`` by :func:`rig.store.liveness.judge` with the keyword
        arguments given; ``ended`` otherwise).
        """
        sc = S.sessions.c
        q = (select(S.sessions, S.patients.c.pseudonym)
             .join(S.patients, S.patients.c.id == sc.patient_id))
        if patient is not None:
            q = q.where(S.patients.c.pseudonym == patient)
        if since is not None:
            q = q.where(sc.started_at >= float(since))
        q = q.order_by(sc.id.desc())
        if limit is not None:
            q = q.limit(int(limit))
        with self.db.transaction(write=False) as conn:
            rows = [dict(r) for r in conn.execute(q).mappings()][::-1]
            ids = [r["id"] for r in rows]
            sensors: dict[int, list] = {}
            nruns: dict[int, int] = {}
            for chunk in range(0, len(ids), 900):  # bound the IN list
                part = ids[chunk:chunk + 900]
                sensors.update(sensor_spans(conn, part))
                nruns.update(run_counts(conn, part))
        for r in rows:
            mine = sensors.get(r["id"], [])
            r["meta"] = loads(r["meta"])
            r["samples_by_sensor"] = dict(sorted((nm, int(n)) for nm, n, *_ in mine if n))
            r["samples"] = sum(r["samples_by_sensor"].values())
            r["recording_s"] = recording_span(mine)
            r["runs"] = nruns.get(r["id"], 0)
            r["last_sample_at"] = last_sample_at(r)
            r["liveness"] = judge(r, host=host, now=now, stale_after_s=stale_after_s,
                                  probe=probe).as_dict()
        return rows

    def liveness(self, session_id: int, *, stale_after_s: float = STALE_AFTER_S,
                 now: float | None = None, host: str | None = None,
                 probe: Probe = probe_process) -> Liveness:
        """Whether the writer of ``session_id`` is alive (:func:`rig.store.liveness.judge`)."""
        return judge(self.get(session_id), host=host, now=now,
                     stale_after_s=stale_after_s, probe=probe)

    def close_interrupted(self, session_id: int, *, force: bool = False,
                          stale_after_s: float = STALE_AFTER_S, now: float | None = None,
                          host: str | None = None, probe: Probe = probe_process) -> dict:
        """Close a ``running`` session whose writer died (``kill -9``, power cut).

        The session gets status ``interrupted`` and ``ended_at`` = the Unix time of its last
        sample (without samples: its writer's last commit, else its start); its runs still
        ``running`` become ``interrupted`` with the same end. ``meta["recovered"]`` records
        what was judged and when. Samples, calibrations and annotations are untouched.

        Refused (:class:`RigConfigError`) when the session is not ``running``, or -- unless
        ``force`` -- when its writer is alive or cannot be judged (a session older than schema
        version 3). Returns ``{"id", "ended_at", "samples", "liveness"}``.
        """
        sess = self.get(session_id)
        if sess["status"] != "running":
            raise RigConfigError(f"session {session_id} is not running: it ended as "
                                 f"{sess['status']!r}")
        live = judge(sess, host=host, now=now, stale_after_s=stale_after_s, probe=probe)
        if not force and live.state == "live":
            raise RigConfigError(f"session {session_id} is still being written ({live.reason}); "
                                 "stop that recording, or use --force")
        if not force and live.state == "unknown":
            raise RigConfigError(f"session {session_id}: cannot tell whether it is still being "
                                 f"written ({live.reason}); make sure it is not, then use "
                                 "--force")
        n = self._samples.count(session_id)
        end = last_sample_at(sess)
        if end is None and n:
            lo, hi = self._samples.t_range(session_id)
            # a session older than schema 3 has no clock offset: start + the samples' span
            end = float(sess["started_at"]) + max(0.0, float(hi) - float(lo))
        if end is None:
            end = max(float(sess["started_at"]),
                      float(sess["heartbeat_at"] or sess["started_at"]))
        meta = dict(sess["meta"])
        meta["recovered"] = {
            "liveness": live.state, "reason": live.reason, "forced": bool(force),
            "closed_at": time.time() if now is None else float(now),
            "end": "last sample" if n else "last commit",
        }
        with self.db.transaction() as conn:
            res = conn.execute(
                S.sessions.update()
                .where((S.sessions.c.id == int(session_id)) & (S.sessions.c.status == "running"))
                .values(status="interrupted", ended_at=end, meta=dumps(meta))
            )
            if res.rowcount != 1:
                raise RigConfigError(f"session {session_id} was ended meanwhile; not closed")
            interrupt_runs(conn, int(session_id), end)
        return {"id": int(session_id), "ended_at": end, "samples": n,
                "liveness": live.as_dict()}

    def heartbeat(self, conn: Connection, session_id: int, **values: Any) -> None:
        """Set session ``session_id``'s heartbeat (Unix time now) and ``values`` in the
        caller's transaction ``conn`` (a writer's commit)."""
        conn.execute(S.sessions.update().where(S.sessions.c.id == int(session_id))
                     .values(heartbeat_at=time.time(), **values))


def last_sample_at(row: Mapping[str, Any]) -> float | None:
    """Unix time of a session's newest sample as its writer stored it, kept within the
    session's life (after its start, not after its writer's last commit)."""
    t = row.get("last_sample_at")
    if t is None:
        return None
    t = max(float(t), float(row["started_at"]))
    beat = row.get("heartbeat_at")
    return t if beat is None else min(t, max(float(beat), float(row["started_at"])))
