"""``rig report --db DB --session ID [--model M.onnx] [--out report.html]``: the clinician's
report of any session, one self-contained HTML page (click code over
:func:`rig.report.run_report`); ``rig report FILE [--parent COL] --child COL [--joint J]
[--frames rig|isb]`` or ``rig report FILE --limb arm|leg --segments COL,...``: the report of
an orientation file or a motion lab's C3D or BVH, read as ``rig boundary`` reads it
(:mod:`rig.report.files`; the file's options through the same helpers, ``--db/--session`` and
FILE exclusive).

Sections without data are left out: a session without a boundary or usable samples has no
range-of-motion table, one without a model no model section, one without enforcement runs no
enforcement summary.
"""

from __future__ import annotations

import click

from calibration.frames import FRAMES
from calibration.joints import JOINTS, LIMB_CHAINS
from rig.commands._options import file_columns
from rig.readback.data import FUSION_CHOICES

JOINT_NAMES = tuple(JOINTS)
LIMBS = tuple(LIMB_CHAINS)


@click.command("report")
@click.argument("file", required=False, type=click.Path(dir_okay=False))
@click.option("--db", default=None, metavar="DB",
              help="Session store: a SQLite path, sqlite:///... or postgresql://...")
@click.option("--session", "session_id", default=None, type=click.IntRange(min=1),
              metavar="ID", help="Session id (see rig session list).")
@click.option("--parent", default=None, help="FILE column of the joint's parent segment "
              "(the shoulder's: thorax).")
@click.option("--child", default=None, help="FILE column of the joint's child segment (joint "
              "orientations when --parent is not given).")
@click.option("--joint", type=click.Choice(JOINT_NAMES), default=None,
              help="FILE: the joint whose segments --parent and --child are (default: the "
              "file's, else the shoulder).")
@click.option("--limb", default=None, metavar="arm|leg", help="FILE: a whole arm or leg from "
              "its --segments (every joint, the couplings the recording supports).")
@click.option("--segments", default=None, help="With --limb arm|leg: the segment columns "
              "proximal to distal, COL,COL,COL (after --parent) or all four.")
@click.option("--chain", "chain", type=click.Choice(LIMBS), default=None, hidden=True,
              help="Old spelling of --limb arm|leg.")
@click.option("--limb-axis", default=None, help="FILE: limb long axis in the limb frame, "
              "x,y,z (default: the long axis of --frames).")
@click.option("--frames", type=click.Choice(FRAMES), default=None,
              help="Segment frames of a .sto or CSV FILE: rig (default) or isb (ISB / "
              "OpenSim); a C3D's or BVH's come from its markers or skeleton.")
@click.option("--side", type=click.Choice(["left", "right"]), default=None,
              help="FILE: the body side (default: the file's, else its column names', else "
              "right).")
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
def report(file, db, session_id, parent, child, joint, limb, segments, chain, limb_axis,
           frames, side, model_path, out_path, age, sex, reference_path, fusion,
           coupled_tests) -> None:
    """Write the clinician's HTML report of a session (--db --session) or of a file: an
    OpenSim .sto or CSV of orientations, or a motion lab's C3D or BVH, read as rig boundary
    reads it (--parent/--child [--joint], or --limb arm|leg --segments ...)."""
    from rig.errors import RigConfigError
    from rig.readback import BoundaryRequest, RecordingSource
    from rig.report import ReportRequest, run_report

    parent, child, whole = file_columns(parent, child, None, limb)
    if chain is not None:
        click.echo(f"rig: note: --chain is now --limb: rig report FILE --limb {chain} ...",
                   err=True)
        if whole is not None:
            raise RigConfigError("--limb does not apply with --chain (the limb names its "
                                 "joints and segments)")
        whole = chain
    file_only = {"--parent": parent, "--child": child, "--joint": joint, "--limb": whole,
                 "--segments": segments, "--limb-axis": limb_axis, "--frames": frames,
                 "--side": side}
    request = None
    if file is None:
        given = [k for k, v in file_only.items() if v is not None]
        if given:
            raise RigConfigError(f"{', '.join(given)} appl{'ies' if len(given) == 1 else 'y'} "
                                 "to a FILE's report; a session's report shows what the "
                                 "session recorded")
    else:
        if whole is None and segments is not None:
            raise RigConfigError("--segments applies with --limb arm|leg")
        if whole is not None:
            for flag in ("--joint", "--limb-axis", "--child"):
                if file_only[flag] is not None:
                    raise RigConfigError(f"{flag} does not apply with --limb {whole} (the "
                                         "limb names its joints; its columns are --segments)")
        request = BoundaryRequest(
            RecordingSource(file, None, None, parent, child, limb_axis, frames, fusion, joint),
            out_path, side=side, limb=whole, segments=segments, store=False)
    result = run_report(ReportRequest(db, session_id, out_path, model=model_path, age=age,
                                      sex=sex, reference=reference_path, fusion=fusion,
                                      coupled_tests=coupled_tests, file=request))
    click.echo(f"wrote {result.path}")
