"""Files from motion labs (C3D, BVH) read into the rig's joints, on real recordings our simulator
did not produce (``data/real``, sources and licences in its README):

- a Vicon Plug-in Gait C3D (pyCGM's sample): the knee, hip and ankle from its markers against
  the joint angles Plug-in Gait stored in the same file;
- a Qualisys C3D with ISB landmarks (ezc3d's sample): its segments per Wu 2002;
- the CMU salsa 61_07 as BVH (the file the ``.sto`` excerpt was made from): the same segments
  and the same boundary from either format.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from calibration.joint_angles import joint_angles
from rig.cli import main
from rig.errors import RigConfigError
from rig.readback import RecordingSource, extract
from rig.store.io import OrientationTable, read_sto, write_sto
from rig.store.labfiles import read_bvh, read_c3d

DATA = Path(__file__).parent / "data" / "real"
PIG = str(DATA / "pycgm_vicon_movement_trial.c3d")
QUALISYS = str(DATA / "ezc3d_qualisys_gait.c3d")
BVH = str(DATA / "cmu_61_07_salsa_daz.bvh")
BVH_FRAMES = 400  # the excerpt's frames: the .sto's first 400 rows (both start at frame 5)


def _flexion(file: str, joint: str, side: str, parent: str | None, child: str) -> np.ndarray:
    q = RecordingSource(file, parent=parent, child=child, joint=joint).load().q
    return joint_angles(q.reshape(-1, 4), joint, side)["alpha"]


def _run(args, capsys):
    with pytest.raises(SystemExit) as exc:
        main(args)
    out = capsys.readouterr()
    return exc.value.code, out.out, out.err


@pytest.mark.parametrize("joint, seg", [("hip", ("pelvis", "femur_{}")),
                                        ("knee", ("femur_{}", "tibia_{}")),
                                        ("ankle", ("tibia_{}", "calcn_{}"))])
@pytest.mark.parametrize("s, S, side", [("r", "R", "right"), ("l", "L", "left")])
def test_c3d_markers_give_plug_in_gaits_range(joint, seg, s, S, side):
    """Flexion (ankle: dorsiflexion) from the markers' ISB frames against Plug-in Gait's own
    angles of the same frames: the range within 3°, every frame within 3° RMS (the ankle: PiG's
    static-trial offset, a constant, is not in a dynamic trial)."""
    mine = _flexion(PIG, joint, side, seg[0].format(s), seg[1].format(s))
    name = f"{S}{joint.capitalize()}Angles"
    pig = _flexion(PIG, joint, side, None, name)
    assert abs(np.ptp(mine) - np.ptp(pig)) <= 3.0, (np.ptp(mine), np.ptp(pig))
    if joint != "ankle":
        assert np.sqrt(np.mean((mine - pig) ** 2)) <= 3.0
    assert np.ptp(pig) > 20.0  # the trial moves the joint


def test_c3d_rom_at_the_cli_reads_markers_and_model_alike(capsys):
    arcs = []
    for extra in (["--parent", "femur_r", "--child", "tibia_r"], ["--child", "RKneeAngles"]):
        code, out, err = _run(["rom", PIG, "--joint", "knee", "--side", "right", "--json",
                               *extra], capsys)
        assert code == 0, err
        rec = json.loads(out)
        arcs.append(rec["flexion"] + rec["extension"])
    assert abs(arcs[0] - arcs[1]) <= 3.0, arcs


@pytest.mark.parametrize("s, S, side", [("r", "R", "right"), ("l", "L", "left")])
def test_c3d_markers_and_plug_in_gait_give_the_same_knee_boundary(s, S, side):
    """The knee's hinge interval from the markers and from the file's ``KneeAngles``: the same
    recording in two forms (measured: 0.2° and 0.7° apart at the ends, right; 0.1° and 0.8°,
    left)."""
    hinges = [extract(RecordingSource(PIG, parent=p, child=c, joint="knee").load(),
                      side=side).constraint_.hinge
              for p, c in ((f"femur_{s}", f"tibia_{s}"), (None, f"{S}KneeAngles"))]
    assert abs(hinges[0].min_deg - hinges[1].min_deg) <= 1.0
    assert abs(hinges[0].max_deg - hinges[1].max_deg) <= 1.0


def test_c3d_isb_landmarks_build_every_leg_segment():
    t = read_c3d(QUALISYS)
    assert t.meta["has"] == "marker set isb-landmarks" and not t.missing
    assert set(t.labels) == {"pelvis", "femur_r", "tibia_r", "calcn_r", "femur_l", "tibia_l",
                             "calcn_l"}
    assert len(t) == 340 and t.rate_hz == 200.0
    for s, side in (("r", "right"), ("l", "left")):
        knee = _flexion(QUALISYS, "knee", side, f"femur_{s}", f"tibia_{s}")
        # walking: the knee flexes 55-75° over a stride and nearly straightens
        assert 55.0 < np.ptp(knee) < 75.0 and knee.min() < 10.0


@pytest.mark.parametrize("file", [PIG, BVH])
@pytest.mark.parametrize("frames", ["rig", "isb"])
def test_frames_on_a_lab_file_is_one_line(file, frames):
    """A C3D's or BVH's segment frames come from its markers or skeleton: ``--frames`` is
    refused before the file is read, rather than silently ignored."""
    src = RecordingSource(file, parent="tibia_l", child="calcn_l", joint="ankle",
                          frames=frames)
    with pytest.raises(RigConfigError, match="--frames does not apply"):
        src.load()


def test_bvh_segments_are_the_sto_made_from_the_same_file():
    bvh, sto = read_bvh(BVH), read_sto(DATA / "cmu_61_07_salsa.sto")
    assert bvh.meta["has"] == "skeleton daz" and len(bvh) == BVH_FRAMES
    for col in sto.labels:
        a, b = bvh.get(col), sto.get(col)[:BVH_FRAMES]
        err = np.degrees(2 * np.arccos(np.clip(np.abs(np.sum(a * b, axis=1)), 0.0, 1.0)))
        assert err.max() < 0.2, (col, err.max())  # the .sto's 6 significant digits


@pytest.mark.parametrize("joint, parent, child, side", [
    ("knee", "femur_r", "tibia_r", "right"), ("elbow", "humerus_l", "ulna_l", "left")])
def test_bvh_and_sto_give_the_same_boundary(tmp_path, joint, parent, child, side):
    sto = read_sto(DATA / "cmu_61_07_salsa.sto")
    cut = OrientationTable(sto.time[:BVH_FRAMES], {c: sto.get(c)[:BVH_FRAMES]
                                                     for c in (parent, child)}, sto.rate_hz)
    write_sto(tmp_path / "cut.sto", cut)
    hinges = []
    for file, frames in ((BVH, None), (str(tmp_path / "cut.sto"), "isb")):
        data = RecordingSource(file, parent=parent, child=child, joint=joint,
                               frames=frames).load()
        hinges.append(extract(data, side=side).constraint_.hinge)
    assert abs(hinges[0].min_deg - hinges[1].min_deg) <= 1.0
    assert abs(hinges[0].max_deg - hinges[1].max_deg) <= 1.0


def test_a_c3d_without_the_markers_asked_for_is_one_line(tmp_path, capsys):
    import ezc3d  # the test rewrites the excerpt without a marker

    c = ezc3d.c3d(PIG)
    labels = list(c["parameters"]["POINT"]["LABELS"]["value"])
    keep = [i for i, lab in enumerate(labels) if lab != "RTHI"]
    out = ezc3d.c3d()
    out["parameters"]["POINT"]["RATE"]["value"] = [120.0]
    out["parameters"]["POINT"]["LABELS"]["value"] = [labels[i] for i in keep]
    out["data"]["points"] = c["data"]["points"][:, keep, :]
    f = tmp_path / "no_rthi.c3d"
    out.write(str(f))
    code, _, err = _run(["rom", str(f), "--joint", "knee", "--parent", "femur_r", "--child",
                         "tibia_r", "--side", "right"], capsys)
    assert code == 2 and len(err.strip().splitlines()) == 1
    assert "RTHI" in err and "tibia_r" in err and "plug-in-gait" in err and "femur_l" in err


_LEGS_ONLY = """HIERARCHY
ROOT Hips
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT Spine1
  {
    OFFSET 0 10 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    End Site
    {
      OFFSET 0 10 0
    }
  }
  JOINT RightUpLeg
  {
    OFFSET -8 0 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    JOINT RightLeg
    {
      OFFSET 0 -40 0
      CHANNELS 3 Zrotation Xrotation Yrotation
      End Site
      {
        OFFSET 0 -40 0
      }
    }
  }
}
MOTION
Frames: 2
Frame Time: 0.01
0 90 0 0 0 0 0 0 0 0 0 0 0 0 0
0 90 0 0 0 0 0 0 0 30 0 0 -45 0 0
"""


def test_a_bvh_without_the_joints_asked_for_is_one_line(tmp_path, capsys):
    f = tmp_path / "legs.bvh"
    f.write_text(_LEGS_ONLY)
    code, _, err = _run(["rom", str(f), "--joint", "elbow", "--parent", "humerus_r",
                         "--child", "ulna_r", "--side", "right"], capsys)
    assert code == 2 and len(err.strip().splitlines()) == 1
    assert "RightForeArm" in err and "skeleton mb" in err and "femur_r" in err


def test_a_bvh_knee_reads_the_files_rotation():
    """The second frame turns the shank 45° about the BVH's X (its Xrotation channel; the rest
    pose faces +Z, so X is the subject's left-right axis): a knee flexion of 45°."""
    import tempfile

    with tempfile.TemporaryDirectory() as d:
        f = Path(d) / "legs.bvh"
        f.write_text(_LEGS_ONLY.replace("0 90 0 0 0 0 0 0 0 30 0 0 -45 0 0",
                                            "0 90 0 0 0 0 0 0 0 0 0 0 0 45 0"))
        knee = _flexion(str(f), "knee", "right", "femur_r", "tibia_r")
    assert knee[0] == pytest.approx(0.0, abs=1e-4)
    assert knee[1] == pytest.approx(45.0, abs=1e-4)  # bvhio computes in float32


def test_unreadable_lab_files_are_config_errors(tmp_path):
    bad = tmp_path / "bad.c3d"
    bad.write_bytes(b"not a c3d")
    with pytest.raises(RigConfigError, match="not a readable C3D"):
        read_c3d(bad)
    bad = tmp_path / "bad.bvh"
    bad.write_text("HIERARCHY\nnothing\n")
    with pytest.raises(RigConfigError, match="not a readable BVH"):
        read_bvh(bad)
