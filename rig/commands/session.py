"""``rig session ...``: what the session store holds."""

from __future__ import annotations

import json
import time

import click


@click.group()
def session() -> None:
    """Inspect recording and enforcement sessions in a store (--db)."""


def _when(ts: float | None) -> str:
    if ts is None:
        return "-"
    return time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(ts))


def format_sessions(rows: list[dict]) -> str:
    """The table ``rig session list`` prints."""
    if not rows:
        return "no sessions"
    head = ("id", "patient", "kind", "joint", "started", "duration", "samples", "dropped",
            "status")
    table = []
    for r in rows:
        dur = "-" if r["ended_at"] is None else f"{r['ended_at'] - r['started_at']:.1f} s"
        by = ", ".join(f"{k} {v}" for k, v in r["samples_by_sensor"].items())
        samples = f"{r['samples']}" + (f" ({by})" if by else "")
        if r["runs"]:
            samples += f", {r['runs']} run{'s' if r['runs'] != 1 else ''}"
        joint = " ".join(x for x in (r.get("side"), r.get("joint")) if x) or "-"
        status = r["status"] + (" (not ended)" if r["status"] == "running" else "")
        table.append((str(r["id"]), r["pseudonym"], r["kind"], joint, _when(r["started_at"]),
                      dur, samples, str(r["dropped"]), status))
    widths = [max(len(h), *(len(row[i]) for row in table)) for i, h in enumerate(head)]
    lines = ["  ".join(h.ljust(w) for h, w in zip(head, widths, strict=True)).rstrip()]
    for row in table:
        lines.append("  ".join(c.ljust(w) for c, w in zip(row, widths, strict=True)).rstrip())
    return "\n".join(lines)


@session.command("list")
@click.option("--db", "db", required=True, help="Store: a file path, sqlite:///PATH or "
              "postgresql://USER@HOST/DB.")
@click.option("--json", "as_json", is_flag=True, help="Print JSON instead of a table.")
def list_(db: str, as_json: bool) -> None:
    """List sessions: patient pseudonym, kind, start, sample counts, status."""
    from rig.store import open_store

    with open_store(db, create=False) as store:
        rows = store.list_sessions()
    if as_json:
        click.echo(json.dumps(rows, indent=1, sort_keys=True))
    else:
        click.echo(format_sessions(rows))
