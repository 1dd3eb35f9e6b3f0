"""``rig report --db DB --session ID [--model M.onnx] [--out report.html]``: the clinician's
report of any session, one self-contained HTML page (click code over
:func:`rig.report.run_report`).

Sections without data are left out: a session without a boundary or usable samples has no
range-of-motion table, one without a model no model section, one without enforcement runs no
enforcement summary.
"""

from __future__ import annotations

import click

from rig.readback.data import FUSION_CHOICES


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
@click.option("--fusion", type=click.Choice(FUSION_CHOICES), default="auto",
              show_default=True, help="IMU recordings: orientations fused by the devices, or by "
              "VQF on the host from the raw samples (auto: VQF when every sample has raw data).")
@click.option("--coupled-tests/--no-coupled-tests", default=True, show_default=True,
              help="A whole arm or leg: the section of coupled clinical tests (straight-leg "
              "raise, popliteal angle, Silfverskiöld, Thomas test; the shoulder's reach with "
              "the elbow straight vs bent). A session of one joint has none.")
def report(db, session_id, model_path, out_path, age, sex, reference_path, fusion,
           coupled_tests) -> None:
    """Write the clinician's HTML report of a session."""
    from rig.report import ReportRequest, run_report

    result = run_report(ReportRequest(db, session_id, out_path, model=model_path, age=age,
                                      sex=sex, reference=reference_path, fusion=fusion,
                                      coupled_tests=coupled_tests))
    click.echo(f"wrote {result.path}")
