"""``rig session ...``: what the session store holds, and closing sessions whose recorder died."""

from __future__ import annotations

import json
import math
import time

import click

from rig.store.liveness import STALE_AFTER_S

_DB_HELP = "Store: a file path, sqlite:///PATH or postgresql://USER@HOST/DB."
_STALE_HELP = (f"A session written on another host counts as interrupted when its writer's "
               f"last heartbeat is older than this (s; default {STALE_AFTER_S:g}). A writer on "
               "this host is judged by its process instead.")


@click.group()
def session() -> None:
    """Inspect recording and enforcement sessions in a store (--db); close interrupted ones."""


def _when(ts: float | None) -> str:
    if ts is None:
        return "-"
    return time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(ts))


def _status(r: dict) -> str:
    if r["status"] != "running":
        return r["status"]
    state = (r.get("liveness") or {}).get("state")
    if state == "interrupted":
        return "interrupted (not closed)"
    if state == "unknown":
        return "running (not ended; writer unknown)"
    return "running (not ended)"


def format_sessions(rows: list[dict], db: str = "DB") -> str:
    """The table ``rig session list`` prints, and a note under it for every session whose
    writer is gone but that is not closed yet."""
    from rig.readback.sessions import session_limb

    if not rows:
        return "no sessions"
    head = ("id", "patient", "kind", "joint", "started", "recorded", "samples", "last sample",
            "dropped", "status")
    table = []
    notes = []
    for r in rows:
        span = r.get("recording_s")  # the time the samples span (the patient's time)
        dur = "-" if span is None else f"{span:.1f} s"
        by = ", ".join(f"{k} {v}" for k, v in r["samples_by_sensor"].items())
        samples = f"{r['samples']}" + (f" ({by})" if by else "")
        if r["runs"]:
            samples += f", {r['runs']} run{'s' if r['runs'] != 1 else ''}"
        # a whole-limb session is named by its limb ("right leg"), not its first joint
        joint = " ".join(x for x in (r.get("side"), session_limb(r) or r.get("joint"))
                         if x) or "-"
        last = _when(r.get("last_sample_at")) if r["samples"] else "-"
        table.append((str(r["id"]), r["pseudonym"], r["kind"], joint, _when(r["started_at"]),
                      dur, samples, last, str(r["dropped"]), _status(r)))
        if r["status"] == "running" and (r.get("liveness") or {}).get("state") == "interrupted":
            notes.append(f"session {r['id']}: {r['liveness']['reason']}; close it with "
                         f"rig session close --db {db} --session {r['id']}")
    widths = [max(len(h), *(len(row[i]) for row in table)) for i, h in enumerate(head)]
    lines = ["  ".join(h.ljust(w) for h, w in zip(head, widths, strict=True)).rstrip()]
    for row in table:
        lines.append("  ".join(c.ljust(w) for c, w in zip(row, widths, strict=True)).rstrip())
    return "\n".join(lines + notes)


def _check_stale(stale_after: float) -> float:
    from rig.errors import RigConfigError

    if not (math.isfinite(stale_after) and stale_after > 0):
        raise RigConfigError(f"--stale-after must be > 0 seconds, got {stale_after}")
    return stale_after


def _since(text: str | None) -> float | None:
    """``--since``: a date ``YYYY-MM-DD`` (local midnight) or date and time, as Unix time."""
    import datetime as dt

    from rig.errors import RigConfigError

    if text is None:
        return None
    try:
        return dt.datetime.fromisoformat(text.strip()).timestamp()
    except ValueError:
        raise RigConfigError(f"--since {text!r}: expected a date YYYY-MM-DD or "
                             "YYYY-MM-DDTHH:MM") from None


@session.command("list")
@click.option("--db", "db", required=True, help=_DB_HELP)
@click.option("--patient", default=None, metavar="PSEUDONYM", help="Only this patient's.")
@click.option("--since", default=None, metavar="DATE",
              help="Only sessions started on or after this date (YYYY-MM-DD[THH:MM]).")
@click.option("--limit", type=click.IntRange(min=1), default=None, metavar="N",
              help="Only the newest N sessions (of those selected).")
@click.option("--json", "as_json", is_flag=True, help="Print JSON instead of a table.")
@click.option("--stale-after", type=float, default=STALE_AFTER_S, show_default=True,
              metavar="SECONDS", help=_STALE_HELP)
def list_(db: str, patient: str | None, since: str | None, limit: int | None, as_json: bool,
          stale_after: float) -> None:
    """List sessions: patient pseudonym, kind, start, recorded time, sample counts, last
    sample, status (oldest first).

    A session still marked running whose writer is gone (killed, power cut) shows as
    'interrupted (not closed)'. 'recorded' is the time the samples span (the patient's time,
    also for a recording made faster than real time).
    """
    from rig.store import open_store

    _check_stale(stale_after)
    since_t = _since(since)
    with open_store(db, create=False) as store:
        rows = store.sessions.list(stale_after_s=stale_after, patient=patient, since=since_t,
                                   limit=limit)
    if as_json:
        click.echo(json.dumps(rows, indent=1, sort_keys=True))
    else:
        click.echo(format_sessions(rows, db))


@session.command("close")
@click.option("--db", "db", required=True, help=_DB_HELP)
@click.option("--session", "session_id", type=int, required=True, help="Session id.")
@click.option("--force", is_flag=True,
              help="Close it even though its writer looks alive or cannot be judged.")
@click.option("--stale-after", type=float, default=STALE_AFTER_S, show_default=True,
              metavar="SECONDS", help=_STALE_HELP)
def close(db: str, session_id: int, force: bool, stale_after: float) -> None:
    """Close a running session whose recorder died: status 'interrupted', end time = its last
    sample. Refused (exit 2) while its writer is alive, unless --force."""
    from rig.store import open_store

    _check_stale(stale_after)
    with open_store(db, create=False) as store:
        res = store.sessions.close_interrupted(session_id, force=force, stale_after_s=stale_after)
    what = "last sample" if res["samples"] else "last commit (no samples)"
    click.echo(f"session {res['id']} closed as interrupted: {res['samples']} samples, "
               f"ended at its {what} {_when(res['ended_at'])} ({res['liveness']['reason']})")
