"""``rig rom``: the clinical range-of-motion table of a session, a file or a constraint (click
options over :func:`rig.readback.run_rom`), next to the AAOS values and the Gill et al. 2020
population reference.
"""

from __future__ import annotations

import json

import click

from calibration.frames import FRAMES
from calibration.joints import JOINTS
from rig.commands._options import file_columns
from rig.readback.data import FUSION_CHOICES

JOINT_NAMES = tuple(JOINTS)


@click.command()
@click.argument("file", required=False, type=click.Path(dir_okay=False))
@click.option("--db", default=None, help="Store: a file path, sqlite:///PATH or postgresql://...")
@click.option("--session", "session_id", default=None, type=click.IntRange(min=1),
              help="Session id (see rig session list).")
@click.option("--parent", default=None, help="FILE column of the joint's parent segment "
              "(the shoulder's: thorax).")
@click.option("--child", default=None, help="FILE column of the joint's child segment (the "
              "shoulder's: upper arm; joint orientations when --parent is not given).")
@click.option("--reference", default=None, hidden=True, help="Old spelling of --parent.")
@click.option("--limb", default=None, hidden=True, help="Old spelling of --child COLUMN.")
@click.option("--limb-axis", default=None, help="Limb long axis in the limb frame, x,y,z "
              "(default: the long axis of --frames).")
@click.option("--joint", type=click.Choice(JOINT_NAMES), default=None,
              help="The joint: shoulder (default), elbow, wrist, hip, knee or ankle; its "
              "segments are --parent and --child (a session: the joint it recorded).")
@click.option("--frames", type=click.Choice(FRAMES), default=None,
              help="Segment frames of FILE: rig (+X distal, +Y anterior, +Z right; default) or "
              "isb (+Y proximal, +X anterior, +Z right: ISB / OpenSim).")
@click.option("--constraint", "constraint_path", default=None,
              type=click.Path(dir_okay=False), help="Use this constraint file instead of a "
              "recording.")
@click.option("--side", type=click.Choice(["left", "right"]), default=None,
              help="Body side (default: the session's or the constraint's, else right).")
@click.option("--age", type=click.IntRange(min=18, max=110), default=None,
              help="Patient age, for the population reference band.")
@click.option("--sex", type=click.Choice(["female", "male"]), default=None,
              help="Patient sex, for the population reference.")
@click.option("--fusion", type=click.Choice(FUSION_CHOICES), default="auto",
              show_default=True, help="IMU sessions: orientations fused by the devices, or by "
              "VQF on the host from the raw samples (auto: VQF when every sample has raw data).")
@click.option("--coupled-tests/--no-coupled-tests", default=None,
              help="The coupled clinical tests (straight-leg raise, popliteal angle, "
              "Silfverskiöld, Thomas test; the shoulder's reach with the elbow straight vs "
              "bent): shown by default for a limb file (--constraint LIMB.yaml --joint J) or a "
              "whole-limb session; --coupled-tests requires them, --no-coupled-tests leaves "
              "them out.")
@click.option("--json", "as_json", is_flag=True,
              help="Print one JSON object: movement -> degrees or null, plus joint, side, "
              "coverage, interrupted.")
def rom(file, db, session_id, parent, child, reference, limb, limb_axis, joint, frames,
        constraint_path, side, age, sex, fusion, coupled_tests, as_json) -> None:
    """Print the clinical range of motion (ISB angles, peaks, normative values)."""
    from rig.errors import RigConfigError
    from rig.readback import RecordingSource, RomRequest, run_rom

    parent, child, whole = file_columns(parent, child, reference, limb)
    if whole is not None:
        raise RigConfigError(f"--limb {whole} (a whole limb) does not apply to rig rom; a "
                             f"file's column named {whole} is --child {whole}")
    source = RecordingSource(file, db, session_id, parent, child, limb_axis, frames, fusion,
                             joint)
    result = run_rom(RomRequest(source, constraint=constraint_path, side=side, joint=joint,
                                coupled_tests=coupled_tests))
    click.echo(json.dumps(result.to_json(age=age, sex=sex)) if as_json
               else result.table(age=age, sex=sex))
