"""``rig progress``: one patient's range of motion across visits, each change against the
minimal detectable change of its joint, movement and method (click options over
:func:`rig.readback.progress.run_progress`).
"""

from __future__ import annotations

import json

import click

from calibration.joints import JOINTS

JOINT_NAMES = tuple(JOINTS)


@click.command()
@click.option("--db", required=True, help="Store: a file path, sqlite:///PATH or "
              "postgresql://...")
@click.option("--patient", required=True, help="The patient's pseudonym.")
@click.option("--joint", type=click.Choice(JOINT_NAMES), default=None,
              help="Only this joint (default: every joint the patient's sessions recorded).")
@click.option("--json", "as_json", is_flag=True,
              help="Print one JSON object: visits, series of changes with MDC verdicts.")
def progress(db, patient, joint, as_json) -> None:
    """Print a patient's progress across visits: every movement per visit, the change since
    the first and the previous usable visit, and whether it exceeds the MDC."""
    from rig.readback.progress import ProgressRequest, run_progress

    result = run_progress(ProgressRequest(db, patient, joint))
    click.echo(json.dumps(result.to_json()) if as_json else result.table())
