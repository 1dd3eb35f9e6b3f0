"""Golden cases: the read-back services called as the CLI calls them (``run_boundary`` of one
joint and of a whole limb, ``run_rom`` with their request dataclasses) on the real recordings:
results, warnings, the files written (joint and limb)."""

from __future__ import annotations

from rig.readback.boundary import BoundaryRequest, run_boundary
from rig.readback.rom import RomRequest, run_rom
from rig.readback.source import RecordingSource
from tests.golden.cli import REAL, root_relative
from tests.golden.harness import case, normalise, tmpdir
from tests.golden.util import jtext


def _text(s: str, tmp) -> str:
    return root_relative(normalise(s, [tmp]))


@case("joint")
def case_services_joint() -> dict:
    """run_boundary and run_rom on a knee (hinge) and a hip (ball) from the x-io recording; run_rom
    of the constraint written."""
    out: dict = {}
    xio = str(REAL / "xio_ximu3_lower_body.sto")
    with tmpdir() as d:
        for name, joint, ref, limb in (("knee", "knee", "femur_r", "tibia_r"),
                                       ("hip", "hip", "pelvis", "femur_l")):
            src = RecordingSource(xio, parent=ref, child=limb, frames="isb", joint=joint)
            r = run_boundary(BoundaryRequest(src, d / f"{name}.yaml", max_vertices=32))
            out[f"{name}_describe"] = _text(r.describe(), d)
            out[f"{name}_warnings"] = jtext(r.warnings)
            out[f"{name}_yaml"] = _text(r.constraint.to_yaml(), d)
            out[f"{name}_file"] = _text((d / f"{name}.yaml").read_text(), d)
            out[f"{name}_q"] = r.data.q
            out[f"{name}_report"] = _text(jtext(r.extractor.report()), d)
            rom = run_rom(RomRequest(source=src, side="left" if limb.endswith("_l") else None))
            out[f"{name}_rom_json"] = _text(jtext(rom.to_json(age=60, sex="male")), d)
            out[f"{name}_rom_table"] = _text(rom.table(), d)
            out[f"{name}_rom_warnings"] = jtext(rom.warnings)
            c = run_rom(RomRequest(constraint=str(d / f"{name}.yaml")))
            out[f"{name}_constraint_rom_json"] = _text(jtext(c.to_json()), d)
    return out


@case("limb")
def case_services_limb() -> dict:
    """run_boundary of a whole limb on the Xsens legs and CMU's left arm: the limb file, the
    summary."""
    out: dict = {}
    with tmpdir() as d:
        for name, file, limb, cols in (
                ("leg_xsens_r", "opensense_xsens_walking.sto", "leg",
                 "pelvis,femur_r,tibia_r,calcn_r"),
                ("arm_cmu60_l", "cmu_60_02_salsa.sto", "arm",
                 "thorax,humerus_l,ulna_l,hand_l")):
            r = run_boundary(BoundaryRequest(RecordingSource(str(REAL / file), frames="isb"),
                                             d / f"{name}.yaml", limb=limb, segments=cols))
            out[f"{name}_describe"] = _text(r.describe(), d)
            out[f"{name}_file"] = _text((d / f"{name}.yaml").read_text(), d)
            out[f"{name}_report"] = _text(jtext(r.extractor.report()), d)
            out[f"{name}_boundary_id"] = jtext(r.boundary_id)
    return out
