"""Golden cases: clinical angles and ranges of motion on the real recordings, and boundary
extraction through its classes (BoundaryExtractor, HingeExtractor, LimbExtractor) on seeded
simulated motion (joint and limb)."""

from __future__ import annotations

import numpy as np

from calibration.boundary import BoundaryExtractor
from calibration.boundary.hinge import HingeExtractor
from calibration.clinical import isb_angles, range_of_motion
from calibration.extraction import LimbExtractor
from calibration.joint_angles import (
    allowed_rom,
    angle_peaks,
    constraint_rom,
    joint_angles,
    recorded_rom,
)
from rig.readback import load_joint_orientations
from rig.readback.files import limb_orientations_from_file
from rig.sim.patients import anatomical_limb, seeded_patient, star_constraint
from tests.golden.cli import REAL
from tests.golden.harness import case
from tests.golden.util import jtext

#: (name, file, joint, reference column, limb column, side): every joint of the real excerpts
REAL_JOINTS = [
    ("shoulder_cmu61_r", "cmu_61_07_salsa.sto", "shoulder", "thorax", "humerus_r", "right"),
    ("shoulder_cmu60_l", "cmu_60_02_salsa.sto", "shoulder", "thorax", "humerus_l", "left"),
    ("elbow_cmu60_r", "cmu_60_02_salsa.sto", "elbow", "humerus_r", "ulna_r", "right"),
    ("wrist_cmu61_l", "cmu_61_07_salsa.sto", "wrist", "ulna_l", "hand_l", "left"),
    ("hip_xio_r", "xio_ximu3_lower_body.sto", "hip", "pelvis", "femur_r", "right"),
    ("knee_xio_l", "xio_ximu3_lower_body.sto", "knee", "femur_l", "tibia_l", "left"),
    ("ankle_xsens_r", "opensense_xsens_walking.sto", "ankle", "tibia_r", "calcn_r", "right"),
    ("knee_cmu61_r", "cmu_61_07_salsa.sto", "knee", "femur_r", "tibia_r", "right"),
]


def _rom(r) -> dict:
    return {"joint": r.joint, "side": r.side, "peaks": r.peaks, "arc": r.arc}


@case("joint")
def case_clinical_angles_real() -> dict:
    """Joint orientations read from the real recordings (ISB frames), their clinical angles
    (joint_angles, the shoulder's isb_angles), peaks and recorded range of motion."""
    out: dict = {}
    for name, file, joint, ref, limb, side in REAL_JOINTS:
        d = load_joint_orientations(str(REAL / file), parent=ref, child=limb, frames="isb",
                                    joint=joint)
        out[f"{name}_q"] = d.q
        if joint == "shoulder":  # ISB's shoulder angles (calibration.clinical)
            for k, v in isb_angles(d.q, side).items():
                out[f"{name}_isb_{k}"] = np.asarray(v)
            continue
        ang = joint_angles(d.q, joint, side)
        for k, v in ang.items():
            out[f"{name}_{k}"] = v
        out[f"{name}_peaks"] = jtext(angle_peaks(ang, joint))
        rom = recorded_rom(d.q, joint, side)
        out[f"{name}_rom"] = jtext(_rom(rom))
        out[f"{name}_rom_table"] = rom.table(age=40, sex="female")
    return out


@case("limb")
def case_clinical_limbs_real() -> dict:
    """Whole limbs read from the real recordings (limb_orientations_from_file): postures and
    every joint's recorded range of motion."""
    out: dict = {}
    for name, file, limb, cols in (
            ("arm_cmu61_r", "cmu_61_07_salsa.sto", "arm", "thorax,humerus_r,ulna_r,hand_r"),
            ("leg_xio_l", "xio_ximu3_lower_body.sto", "leg", "pelvis,femur_l,tibia_l,calcn_l")):
        rec = limb_orientations_from_file(str(REAL / file), cols.split(","), limb,
                                          frames="isb")
        q = rec.joint_q
        out[f"{name}_q"] = q
        out[f"{name}_t"] = rec.t
        joints = ("shoulder", "elbow", "wrist") if limb == "arm" else ("hip", "knee", "ankle")
        side = "right" if cols.endswith("_r") else "left"
        out[f"{name}_rom"] = jtext({j: _rom(recorded_rom(q[:, i], j, side))
                                    for i, j in enumerate(joints) if j != "shoulder"})
    return out


@case("joint")
def case_clinical_constraint_rom() -> dict:
    """Range of motion of constraints: a star patient's shoulder (range_of_motion,
    constraint_rom), each joint of the anatomical arm and leg taken alone."""
    c = star_constraint(3)
    out = {"shoulder_range_of_motion": jtext(range_of_motion(c).to_dict()),
           "shoulder_range_of_motion_left": jtext(range_of_motion(c, "left").to_dict())}
    for limb in (anatomical_limb(7, "arm"), anatomical_limb(11, "leg")):
        for j in limb.joints:
            if j.constraint is not None and j.name != "shoulder":
                out[f"{limb.limb}_{j.name}"] = jtext(_rom(constraint_rom(j.constraint, j.name)))
    return out


@case("limb")
def case_clinical_allowed_rom_limbs() -> dict:
    """allowed_rom of the anatomical limbs' joints over their keyframes (couplings)."""
    out = {}
    for limb in (anatomical_limb(7, "arm"), anatomical_limb(11, "leg"),
                 anatomical_limb(5, "arm", "left")):
        for j in limb.joints:
            cons = [j.constraint] if j.constraint is not None else list(j.coupling.keyframes)
            r = allowed_rom(cons, j.name, limb.side)
            out[f"{limb.name.replace('-', '_')}_{limb.side}_{j.name}"] = jtext(
                r.to_dict() if hasattr(r, "to_dict") else _rom(r))
    return out


@case("joint")
def case_extract_joint() -> dict:
    """BoundaryExtractor on a star patient's true motion (ball joint) and HingeExtractor on an
    anatomical knee's: the constraint written and the report."""
    from rig.sim.limb import NoiseModel

    sim = seeded_patient(9, star_constraint(9), noise=NoiseModel.ideal(), calibrate=False)
    t = np.arange(0.0, 120.0, 0.04)
    q = sim.joint(t)
    ex = BoundaryExtractor().fit(q, t=t)
    out = {"ball_yaml": ex.constraint_.to_yaml(), "ball_report": jtext(ex.report())}
    ex2 = BoundaryExtractor(alpha_deg=8.0, max_vertices=24).fit(q, t=t)
    out["ball_coarse_yaml"] = ex2.constraint_.to_yaml()
    leg = seeded_patient(11, "leg", calibrate=False)
    knee = leg.joints(np.arange(0.0, 60.0, 0.04))[:, 1]
    hx = HingeExtractor(axis=(0.0, 0.0, -1.0)).fit(knee)
    out["knee_yaml"] = hx.constraint_.to_yaml()
    out["knee_report"] = jtext(hx.report())
    return out


@case("limb")
def case_extract_chain() -> dict:
    """LimbExtractor on the true motion of an anatomical leg and arm (couplings tested): the
    limb file and the report."""
    out = {}
    for name, seed in (("leg", 11), ("arm", 7)):
        sim = seeded_patient(seed, name, calibrate=False)
        t = np.arange(0.0, 90.0, 0.05)
        q = sim.joints(t)
        ex = LimbExtractor(name).fit(q, t=t, side="right")
        out[f"{name}_yaml"] = ex.limb_.to_yaml()
        out[f"{name}_report"] = jtext(ex.report())
        out[f"{name}_couplings"] = jtext(ex.couplings_)
    return out
