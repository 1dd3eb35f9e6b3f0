"""The elbow, wrist, knee and ankle (and the hip as a joint of the leg) on real recordings our
simulator did not produce: every joint's boundary holds what people did, hinge intervals sit on
the recorded extremes, and the clinical table reads the same recording.

Recordings (``data/real``, sources and licences in its README): optical motion capture of two
people dancing (CMU: arms and legs) and two inertial recordings of the lower body (x-io x-IMU3,
Xsens MTw via OpenSense), segment orientations in ISB frames (the foot's the ISB calcaneus
frame).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from calibration.frames import SEGMENT_TO_ISB, segment_to_rig
from calibration.joints import JOINTS, hinge_angles
from models.constraint import load_constraint
from models.oracle import ConstraintOracle
from rig.cli import main
from rig.readback import RecordingSource, extract
from rig.store.io import OrientationTable, read_sto, write_sto

DATA = Path(__file__).parent / "data" / "real"

_ARM = [(f, j, p.format(s), c.format(s), s) for f in ("cmu_61_07_salsa.sto", "cmu_60_02_salsa.sto")
        for s in "rl" for j, p, c in (("elbow", "humerus_{}", "ulna_{}"),
                                      ("wrist", "ulna_{}", "hand_{}"))]
_LEG = [(f, j, p.format(s), c.format(s), s)
        for f in ("cmu_61_07_salsa.sto", "xio_ximu3_lower_body.sto", "opensense_xsens_walking.sto")
        for s in "rl" for j, p, c in (("knee", "femur_{}", "tibia_{}"),
                                      ("ankle", "tibia_{}", "calcn_{}"),
                                      ("hip", "pelvis", "femur_{}"))]
CASES = _ARM + _LEG


def _side(s: str) -> str:
    return "right" if s == "r" else "left"


def run(args, capsys):
    with pytest.raises(SystemExit) as exc:
        main(args)
    out = capsys.readouterr()
    return exc.value.code, out.out, out.err


@pytest.mark.parametrize("file, joint, reference, limb, s", CASES)
def test_every_joint_holds_what_people_did(file, joint, reference, limb, s):
    data = RecordingSource(str(DATA / file), parent=reference, child=limb, frames="isb",
                           joint=joint).load()
    assert data.joint == joint
    ex = extract(data, side=_side(s))
    c = ex.constraint_
    assert c.joint == joint and c.side == _side(s)
    if JOINTS[joint].kind == "hinge":
        assert c.kind == "hinge"
        theta = hinge_angles(data.q, c.hinge.axis)
        inside = np.mean((theta >= c.hinge.min_deg) & (theta <= c.hinge.max_deg))
        # the interval sits on the recorded extremes (clean recordings: no spike, no inset)
        assert abs(c.hinge.min_deg - theta.min()) <= 3.0
        assert abs(c.hinge.max_deg - theta.max()) <= 3.0
        assert ex.report()["off_axis_rms_deg"] > 0.0  # reported, not fitted away
    else:
        # whole orientations (swing and twist) inside the written constraint
        inside = np.mean(ConstraintOracle(c).signed_distance(data.q) <= 0.0)
        if JOINTS[joint].kind == "two-axis":
            width = c.twist.max_deg - c.twist.min_deg
            assert c.kind == ("two-axis" if width <= 30.0 else "ball")
            assert (c.kind == "ball") == ("kind_note" in c.provenance)
    assert inside >= 0.97, f"{file} {joint} {s}: {100 * inside:.2f} % inside"


def test_isb_and_rig_frames_give_the_same_ankle(tmp_path):
    """The foot's rig frame is the ISB calcaneus frame: a file converted to rig frames segment
    by segment reads the same joint orientations, hence the same boundary."""
    table = read_sto(DATA / "xio_ximu3_lower_body.sto")
    rig = OrientationTable(time=table.time, columns={
        "tibia_r": segment_to_rig(table.columns["tibia_r"], "isb", "shank"),
        "calcn_r": segment_to_rig(table.columns["calcn_r"], "isb", "foot")})
    np.testing.assert_array_equal(rig.columns["calcn_r"], table.columns["calcn_r"])
    assert np.array_equal(SEGMENT_TO_ISB["foot"], np.eye(3))
    write_sto(tmp_path / "rig.sto", rig)
    a = RecordingSource(str(DATA / "xio_ximu3_lower_body.sto"), parent="tibia_r",
                        child="calcn_r", frames="isb", joint="ankle").load()
    b = RecordingSource(str(tmp_path / "rig.sto"), parent="tibia_r", child="calcn_r",
                        frames="rig", joint="ankle").load()
    np.testing.assert_allclose(np.abs(np.sum(a.q * b.q, axis=1)), 1.0, atol=1e-9)
    # standing at the start: the foot's long axis points along the shank's +Y (anterior)
    assert (a.directions[:10] @ np.array([0.0, 1.0, 0.0])).min() > 0.9


def test_boundary_and_rom_for_a_knee_at_the_cli(tmp_path, capsys):
    out = tmp_path / "knee.yaml"
    src = str(DATA / "xio_ximu3_lower_body.sto")
    code, stdout, err = run(["boundary", src, "--joint", "knee", "--parent", "femur_l",
                             "--child", "tibia_l", "--frames", "isb", "--side", "left",
                             "--out", str(out)], capsys)
    assert code == 0, err
    assert "hinge" in stdout and "off-axis" in stdout
    c = load_constraint(out)
    assert c.kind == "hinge" and c.joint == "knee" and c.side == "left"
    code, stdout, err = run(["rom", src, "--joint", "knee", "--parent", "femur_l", "--child",
                             "tibia_l", "--frames", "isb", "--side", "left", "--json"], capsys)
    assert code == 0, err
    rec = json.loads(stdout)
    assert rec["joint"] == "knee" and rec["side"] == "left"
    # the recording's flexion peak and the written interval's end agree (both within the
    # knee's out-of-axis motion of each other: the Cardan angle and the hinge angle differ)
    code, stdout, err = run(["rom", "--constraint", str(out), "--json"], capsys)
    assert code == 0, err
    con = json.loads(stdout)
    assert con["joint"] == "knee" and con["flexion"] == pytest.approx(c.hinge.max_deg, abs=0.2)
    assert abs(rec["flexion"] - con["flexion"]) < 10.0
    assert con["flexion"] > 110.0  # the recording's high-knee raise


@pytest.mark.parametrize("args, needle", [
    (["--joint", "toe"], "'--joint'"),
    (["--joint", "knee", "--child", "nope", "--parent", "femur_l"], "nope"),
])
def test_bad_joint_options_are_one_line_errors(args, needle, capsys):
    code, _, err = run(["rom", str(DATA / "xio_ximu3_lower_body.sto"), "--frames", "isb",
                        *args], capsys)
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and needle in lines[0], err
