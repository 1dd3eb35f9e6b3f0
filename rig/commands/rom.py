"""``rig rom``: the clinical range-of-motion table of a session, a file or a constraint.

Peaks (flexion, extension, abduction, adduction, horizontal adduction, internal and external
rotation) come from the patient's boundary (:func:`calibration.clinical.range_of_motion`):
extracted from the recording as ``rig boundary`` does, or read from ``--constraint``. They are
printed next to the AAOS values and the Gill et al. 2020 population reference.
"""

from __future__ import annotations

import json
from pathlib import Path

import click

from calibration.frames import FRAMES
from rig.errors import RigConfigError


@click.command()
@click.argument("file", required=False, type=click.Path(dir_okay=False))
@click.option("--db", default=None, help="Store: a file path, sqlite:///PATH or postgresql://...")
@click.option("--session", "session_id", default=None, type=click.IntRange(min=1),
              help="Session id (see rig session list).")
@click.option("--reference", default=None, help="FILE column of the thorax.")
@click.option("--limb", default=None, help="FILE column of the upper arm (joint orientations "
              "when --reference is not given).")
@click.option("--limb-axis", default=None, help="Limb long axis in the limb frame, x,y,z "
              "(default: the long axis of --frames).")
@click.option("--frames", type=click.Choice(FRAMES), default=None,
              help="Segment frames of FILE: rig (+X distal, +Y anterior, +Z right; default) or "
              "isb (+Y proximal, +X anterior, +Z right: ISB / OpenSim).")
@click.option("--constraint", "constraint_path", default=None,
              type=click.Path(dir_okay=False), help="Use this constraint file instead of a "
              "recording.")
@click.option("--side", type=click.Choice(["left", "right"]), default=None,
              help="Arm side (default: the session's or the constraint's, else right).")
@click.option("--age", type=click.IntRange(min=18, max=110), default=None,
              help="Patient age, for the population reference band.")
@click.option("--sex", type=click.Choice(["female", "male"]), default=None,
              help="Patient sex, for the population reference.")
@click.option("--fusion", type=click.Choice(["auto", "device", "vqf"]), default="auto",
              show_default=True, help="IMU sessions: orientations fused by the devices, or by "
              "VQF on the host from the raw samples (auto: VQF when every sample has raw data).")
@click.option("--json", "as_json", is_flag=True,
              help="Print one JSON object: movement -> degrees or null, plus joint, side, "
              "coverage, interrupted.")
def rom(file, db, session_id, reference, limb, limb_axis, frames, constraint_path, side, age,
        sex, fusion, as_json) -> None:
    """Print the clinical range of motion (ISB angles, peaks, normative values)."""
    from calibration.clinical import format_rom_table, range_of_motion

    facts = None
    if constraint_path is not None:
        if file is not None or db is not None or session_id is not None:
            raise RigConfigError("give either --constraint or a recording, not both")
        if frames is not None:
            raise RigConfigError("--frames applies to orientation files, not to --constraint")
        if not Path(constraint_path).is_file():
            raise RigConfigError(f"{constraint_path}: no such file")
        from models.constraint import load_constraint

        constraint = load_constraint(constraint_path)
        side = side or getattr(constraint, "side", None) or "right"
        source = constraint_path
        joint = getattr(constraint, "joint", None)
    else:
        from rig.commands.boundary import check_source, extract, load_joint_orientations

        check_source(file, db, session_id, reference, limb, frames)
        data = load_joint_orientations(file, db=db, session_id=session_id, reference=reference,
                                       limb=limb, limb_axis=limb_axis, fusion=fusion,
                                       frames=frames)
        side = side or data.side or "right"
        constraint = extract(data, side=side).constraint_
        source = file if file is not None else f"session {session_id}"
        if data.orientations is not None:
            source += f" (IMU orientations {data.orientations})"
        facts = data.facts()
        joint = data.joint
    result = range_of_motion(constraint, side,
                             directions=None if facts is None else data.directions)
    if as_json:
        click.echo(json.dumps(rom_json(result, joint=joint, facts=facts, source=source)))
        return
    lines = [source]
    if facts is not None:
        lines += [f"warning: {w}" for w in facts.warnings()]
    lines.append(format_rom_table(result, age=age, sex=sex))
    click.echo("\n".join(lines))


def rom_json(result, *, joint: str | None, facts=None, source: str | None = None) -> dict:
    """``rig rom --json``: movement (snake_case, as in the table) → degrees (2 decimals) or
    None, plus ``joint``, ``side``, ``coverage`` (share of the swing sphere's sectors
    explored, 0-1; None for a constraint file), ``interrupted`` (None when unknown: files and
    constraints), ``neutral_outside_deg`` and ``warnings``."""
    out: dict = {"joint": joint or "shoulder", "side": result.side}
    for m in result.MOVEMENTS:
        v = getattr(result, m)
        out[m] = None if v is None else round(float(v), 2)
    out["coverage"] = None if facts is None or facts.coverage is None \
        else round(facts.coverage, 4)
    out["interrupted"] = None if facts is None else facts.interrupted
    out["neutral_outside_deg"] = round(float(result.neutral_outside_deg), 2)
    out["warnings"] = [] if facts is None else facts.warnings()
    if source is not None:
        out["source"] = source
    return out
