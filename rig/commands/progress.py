"""``rig progress``: one patient's range of motion across visits, each change against the
minimal detectable change of its joint, movement and method, and with ``--age`` / ``--sex``
each movement's published norm for the patient (click options over
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
@click.option("--age", type=click.IntRange(min=18, max=110), default=None,
              help="Patient age: each movement's published norm for the age band (with "
              "its source and method).")
@click.option("--sex", type=click.Choice(["female", "male"]), default=None,
              help="Patient sex: each movement's published norm for the sex.")
@click.option("--json", "as_json", is_flag=True,
              help="Print one JSON object: visits, series of changes with MDC verdicts (and "
              "the norms with --age/--sex).")
def progress(db, patient, joint, age, sex, as_json) -> None:
    """Print a patient's progress across visits: every movement per visit, the change since
    the first and the previous usable visit, and whether it exceeds the MDC."""
    from rig.readback.progress import ProgressRequest, run_progress

    result = run_progress(ProgressRequest(db, patient, joint, age=age, sex=sex))
    click.echo(json.dumps(result.to_json()) if as_json else result.table())
