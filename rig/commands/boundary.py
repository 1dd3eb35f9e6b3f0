"""``rig boundary``: a patient-specific constraint file from a recording (click options over
:func:`rig.readback.run_boundary`).

Input is a recorded session (``--db DB --session ID``) or an imported orientation file
(``FILE.sto`` / ``FILE.csv``, or a motion lab's ``FILE.c3d`` / ``FILE.bvh`` read into segment
columns by :mod:`rig.store.labfiles`, with ``--parent COLUMN --child COLUMN``: joint orientation
= parent⁻¹ ⊗ child; with ``--child`` alone the column already holds joint orientations).

A whole arm or leg is ``--limb arm|leg``, as in ``rig demo --limb``: a whole-limb session
(``--db --session``) or a file's ``--segments``; ``--limb`` means nothing else (a column named
``arm`` is ``--child arm``). The old spellings are still accepted, each with a one-line note on
stderr naming the new one (:func:`rig.commands._options.file_columns`): ``--chain arm|leg``,
``--reference COLUMN`` and ``--limb COLUMN`` (a value that is not a limb).
"""

from __future__ import annotations

import click

from calibration.frames import FRAMES
from calibration.joints import JOINTS, LIMB_CHAINS
from models.kinds import KINDS
from rig.commands._options import file_columns
from rig.readback.boundary import BY_SWING_CHOICES
from rig.readback.data import FUSION_CHOICES

JOINT_NAMES = tuple(JOINTS)
LIMBS = tuple(LIMB_CHAINS)


@click.command()
@click.argument("file", required=False, type=click.Path(dir_okay=False))
@click.option("--db", default=None, help="Store: a file path, sqlite:///PATH or postgresql://...")
@click.option("--session", "session_id", default=None, type=click.IntRange(min=1),
              help="Session id (see rig session list).")
@click.option("--parent", default=None, help="FILE column of the joint's parent segment "
              "(the shoulder's: thorax).")
@click.option("--child", default=None, help="FILE column of the joint's child segment (joint "
              "orientations when --parent is not given).")
@click.option("--reference", default=None, hidden=True, help="Old spelling of --parent.")
@click.option("--limb", default=None, metavar="arm|leg", help="A whole arm or leg (--limb "
              "arm|leg) from a session recorded on an arm or leg rig or from FILE's --segments: "
              "writes a limb file, with a coupling where the recording supports one.")
@click.option("--limb-axis", default=None, help="Limb long axis in the limb frame, x,y,z "
              "(default: the long axis of --frames, 1,0,0 in rig frames).")
@click.option("--joint", type=click.Choice(JOINT_NAMES), default=None,
              help="The joint: shoulder (default), elbow, wrist, hip, knee or ankle; its "
              "segments are --parent and --child (a session: the joint it recorded).")
@click.option("--kind", type=click.Choice(KINDS), default=None,
              help="The joint kind to extract (default: the joint's own — the elbow and knee "
              "hinges, a ball otherwise, two-axis for the wrist and ankle when their twist is "
              "narrow); forearm: an elbow's flexion and its pronation-supination.")
@click.option("--chain", "chain", type=click.Choice(LIMBS), default=None, hidden=True,
              help="Old spelling of --limb arm|leg.")
@click.option("--segments", default=None, help="With --limb arm|leg: the segment columns "
              "proximal to distal, COL,COL,COL (after --parent) or all four.")
@click.option("--frames", type=click.Choice(FRAMES), default=None,
              help="Segment frames of FILE: rig (+X distal, +Y anterior, +Z right; default) or "
              "isb (+Y proximal, +X anterior, +Z right: ISB / OpenSim).")
@click.option("--out", "out", required=True, type=click.Path(dir_okay=False),
              help="Constraint file to write (YAML).")
@click.option("--name", default=None, help="Constraint name (default from the source).")
@click.option("--side", type=click.Choice(["left", "right"]), default=None,
              help="Body side recorded in the constraint (default: the session's).")
@click.option("--alpha-deg", default=4.0, show_default=True, type=click.FloatRange(min=0.5),
              help="Alpha-shape radius: concavities narrower than ~2x this are bridged.")
@click.option("--max-vertices", default=64, show_default=True, type=click.IntRange(min=3),
              help="Vertex budget of the boundary polygon.")
@click.option("--by-swing", type=click.Choice(BY_SWING_CHOICES), default="auto",
              show_default=True, help="Swing-dependent twist limits.")
@click.option("--store/--no-store", "store_result", default=True, show_default=True,
              help="With --db: also store the boundary (with --limb arm|leg, the limb file) in the "
                   "session database.")
@click.option("--fusion", type=click.Choice(FUSION_CHOICES), default="auto", show_default=True,
              help="IMU sessions: orientations fused by the devices, or by VQF on the host "
              "from the raw samples (auto: VQF when every sample has raw data).")
def boundary(file, db, session_id, parent, child, reference, limb, limb_axis, joint, kind,
             chain, segments, frames, out, name, side, alpha_deg, max_vertices, by_swing,
             store_result, fusion) -> None:
    """Extract a patient-specific constraint (swing polygon + twist range) from a recording.

    FILE is an OpenSim .sto or a CSV of orientations, or a motion lab's C3D or BVH (segment
    columns pelvis, femur_r, tibia_r, calcn_r, ...); or use --db DB --session ID.
    """
    from rig.errors import RigConfigError
    from rig.readback import BoundaryRequest, RecordingSource, run_boundary

    parent, child, whole = file_columns(parent, child, reference, limb)
    if chain is not None:
        click.echo(f"rig: note: --chain is now --limb: rig boundary --limb {chain} ...",
                   err=True)
        if whole is not None:
            raise RigConfigError("--limb does not apply with --chain (the limb names its "
                                 "joints and segments)")
        whole = chain
    if whole is not None or segments is not None:
        if whole is None:
            raise RigConfigError("--segments applies with --limb arm|leg")
        for flag, value in (("--joint", joint), ("--limb-axis", limb_axis)):
            if value is not None:
                raise RigConfigError(f"{flag} does not apply with --limb {whole} (the limb "
                                     "names its joints and segments)")
    result = run_boundary(BoundaryRequest(
        RecordingSource(file, db, session_id, parent, child, limb_axis, frames, fusion,
                        joint),
        out, name=name, side=side, alpha_deg=alpha_deg, max_vertices=max_vertices,
        by_swing=by_swing, store=store_result, limb=whole, segments=segments, kind=kind))
    click.echo(result.describe())
    for w in result.warnings:
        click.echo(f"warning: {w}")
