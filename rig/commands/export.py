"""``rig export``: a session's samples as an OpenSim ``.sto`` or a CSV file."""

from __future__ import annotations

from pathlib import Path

import click

from rig.errors import RigConfigError


@click.command()
@click.option("--db", "db", required=True, help="Store: a file path, sqlite:///PATH or "
              "postgresql://USER@HOST/DB.")
@click.option("--session", "session_id", required=True, type=click.IntRange(min=1),
              help="Session id (see rig session list).")
@click.option("--format", "fmt", type=click.Choice(["sto", "csv"]), default=None,
              help="sto: OpenSim orientations (one <segment>_imu column per sensor); csv: every "
              "sample, t_s,device_t_s,name,kind,w,x,y,z,status (then acc_x..mag_z when the "
              "session has raw IMU readings). Default: from --out's suffix.")
@click.option("--out", "out", required=True, type=click.Path(dir_okay=False),
              help="Output file (written atomically).")
def export(db: str, session_id: int, fmt: str | None, out: str) -> None:
    """Export a session's recorded orientations."""
    from models.fileio import check_output
    from rig.store import open_store
    from rig.store.io import export_session

    if fmt is None:
        suffix = Path(out).suffix.lower().lstrip(".")
        if suffix not in ("sto", "csv"):
            raise RigConfigError(f"--out {out}: cannot tell the format from the suffix; "
                                 "give --format sto|csv")
        fmt = suffix
    check_output(out, "--out")
    with open_store(db, create=False) as store:
        summary = export_session(store, session_id, fmt, out)
    extra = ""
    if summary["dropped_rows"]:
        extra = (f"; {summary['dropped_rows']} rows without a sample of every sensor within "
                 "half a period left out")
    what = ", ".join(summary.get("columns") or summary.get("names") or [])
    click.echo(f"wrote {summary['rows']} rows ({what}) to {out}{extra}")
