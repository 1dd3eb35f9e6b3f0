"""``rig report --db DB --session ID [--model M.onnx] [--out report.html]``: the clinician's
report of any session, one self-contained HTML page (:mod:`rig.report.session`).

Sections without data are left out: a session without a boundary or usable samples has no
range-of-motion table, one without a model no model section, one without enforcement runs no
enforcement summary.
"""

from __future__ import annotations

from pathlib import Path

import click


@click.command("report")
@click.option("--db", required=True, metavar="DB",
              help="Session store: a SQLite path, sqlite:///... or postgresql://...")
@click.option("--session", "session_id", required=True, type=click.IntRange(min=1),
              metavar="ID", help="Session id (see rig session list).")
@click.option("--model", "model_path", default=None, type=click.Path(dir_okay=False),
              metavar="M.onnx", help="Model to evaluate (default: the last one registered "
                                     "with the session, if its file exists).")
@click.option("--out", "out_path", default="report.html", show_default=True,
              type=click.Path(dir_okay=False), help="HTML file to write.")
@click.option("--age", type=click.IntRange(min=18, max=110), default=None,
              help="Patient age, for the population reference band.")
@click.option("--sex", type=click.Choice(["female", "male"]), default=None,
              help="Patient sex, for the population reference.")
@click.option("--reference", "reference_path", default=None, type=click.Path(dir_okay=False),
              metavar="C.yaml", help="A constraint drawn dashed for comparison (e.g. a "
                                     "simulated patient's true range).")
@click.option("--fusion", type=click.Choice(["auto", "device", "vqf"]), default="auto",
              show_default=True, help="IMU recordings: orientations fused by the devices, or by "
              "VQF on the host from the raw samples (auto: VQF when every sample has raw data).")
def report(db, session_id, model_path, out_path, age, sex, reference_path, fusion) -> None:
    """Write the clinician's HTML report of a session."""
    path = run_report(db, session_id, out_path, model=model_path, age=age, sex=sex,
                      reference=reference_path, fusion=fusion)
    click.echo(f"wrote {path}")


def run_report(db, session_id: int, out_path, *, model=None, age=None, sex=None,
               reference=None, fusion: str = "auto") -> Path:
    """What ``rig report`` does; checks every file and the session before drawing anything."""
    from rig.errors import RigConfigError
    from rig.report.session import report_for_session
    from rig.store import open_store

    out = Path(out_path)
    if out.is_dir():
        raise RigConfigError(f"--out {out_path}: is a directory")
    if not out.parent.is_dir():
        raise RigConfigError(f"--out {out_path}: directory {out.parent} does not exist")
    if model is not None and not Path(model).is_file():
        raise RigConfigError(f"--model {model}: no such file")
    ref = None
    if reference is not None:
        from models.constraint import load_constraint

        ref = load_constraint(reference)
    with open_store(db, create=False) as store:
        store.get_session(session_id)  # "no session N in DB" before any work
        return report_for_session(store, session_id, out, model=model, age=age, sex=sex,
                                  reference=ref, fusion=fusion)
