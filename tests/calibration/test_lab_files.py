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

from calibration import markers
from calibration.frames import joint_to_rig
from calibration.joint_angles import joint_angles
from models import quaternion as Q
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


#: a BVH of a spine and a right leg, no arm (tests/rig/test_report_files.py uses it too)
LEGS_ONLY_BVH = """HIERARCHY
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
    f.write_text(LEGS_ONLY_BVH)
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
        f.write_text(LEGS_ONLY_BVH.replace("0 90 0 0 0 0 0 0 0 30 0 0 -45 0 0",
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


# --- upper body (Plug-in Gait's arm markers) and a second BVH source (NaturalPoint Arena) ---

ARMS = str(DATA / "pycgm_vicon_movement_trial_arms.c3d")
ARENA = str(DATA / "arena_louise_cycling.bvh")


@pytest.mark.parametrize("s, S, side", [("r", "R", "right"), ("l", "L", "left")])
def test_c3d_arm_markers_give_plug_in_gaits_elbow(s, S, side):
    """Elbow flexion from the arm markers' ISB frames (Wu 2005, Plug-in Gait's joint centres)
    against Plug-in Gait's own ``ElbowAngles`` of the same frames: every frame within 0.1°
    (measured 0.01° RMS), and the hinge ``rig boundary`` writes from each within 1° at both
    ends (measured 0.01°) — one recording in two forms."""
    mine = _flexion(ARMS, "elbow", side, f"humerus_{s}", f"ulna_{s}")
    pig = _flexion(ARMS, "elbow", side, None, f"{S}ElbowAngles")
    assert np.max(np.abs(mine - pig)) <= 0.1
    assert np.ptp(pig) > 5.0
    hinges = [extract(RecordingSource(ARMS, parent=p, child=c, joint="elbow").load(),
                      side=side).constraint_.hinge
              for p, c in ((f"humerus_{s}", f"ulna_{s}"), (None, f"{S}ElbowAngles"))]
    assert abs(hinges[0].min_deg - hinges[1].min_deg) <= 1.0
    assert abs(hinges[0].max_deg - hinges[1].max_deg) <= 1.0


@pytest.mark.parametrize("s, S, side", [("r", "R", "right"), ("l", "L", "left")])
def test_plug_in_gaits_elbow_angles_are_its_own_centres_angle(s, S, side):
    """The file's ``ElbowAngles`` read as an ISB elbow (sign and side) equal the angle between
    Plug-in Gait's own humerus (SJC → EJC) and forearm (EJC → WJC) axes from the centres the
    file stores (``CLO``, ``HUO``, ``RAO``): our reading of its angles is its geometry."""
    import ezc3d  # the test reads the file's stored joint centres

    c = ezc3d.c3d(ARMS)
    labels = [str(x) for x in c["parameters"]["POINT"]["LABELS"]["value"]]
    p = {k: c["data"]["points"][:3, labels.index(f"{S}{k}"), :].T for k in ("CLO", "HUO", "RAO")}
    a = p["CLO"] - p["HUO"]
    b = p["HUO"] - p["RAO"]
    cos = np.sum(a * b, axis=1) / np.linalg.norm(a, axis=1) / np.linalg.norm(b, axis=1)
    geometric = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
    pig = _flexion(ARMS, "elbow", side, None, f"{S}ElbowAngles")
    np.testing.assert_allclose(pig, geometric, atol=0.05)


def test_c3d_arm_segments_are_isb_frames_of_every_arm_segment():
    t = read_c3d(ARMS)
    assert {"thorax", "humerus_r", "ulna_r", "hand_r", "humerus_l", "ulna_l", "hand_l"} <= \
        set(t.labels)
    assert "pelvis" in t.missing and "thorax" not in t.missing


def test_a_c3d_without_the_hand_marker_is_one_line(tmp_path, capsys):
    import ezc3d  # the test rewrites the excerpt without a marker

    c = ezc3d.c3d(ARMS)
    labels = [str(x) for x in c["parameters"]["POINT"]["LABELS"]["value"]]
    keep = [i for i, lab in enumerate(labels) if lab != "LFIN"]
    out = ezc3d.c3d()
    out["parameters"]["POINT"]["RATE"]["value"] = [120.0]
    out["parameters"]["POINT"]["LABELS"]["value"] = [labels[i] for i in keep]
    out["data"]["points"] = c["data"]["points"][:, keep, :]
    f = tmp_path / "no_lfin.c3d"
    out.write(str(f))
    code, _, err = _run(["rom", str(f), "--joint", "wrist", "--parent", "ulna_l", "--child",
                         "hand_l", "--side", "left"], capsys)
    assert code == 2 and len(err.strip().splitlines()) == 1
    assert "LFIN" in err and "hand_l" in err


def _bvh_channels(path: str, joint: str) -> np.ndarray:
    """One joint's rotation channels (N, 3) as the file writes them, read from its text."""
    text = Path(path).read_text().split("\n")
    order, cols, k = [], [], 0
    for line in text:
        w = line.split()
        if w[:1] in (["ROOT"], ["JOINT"]):
            order.append(w[1])
        if w[:1] == ["CHANNELS"]:
            if order[-1] == joint:
                cols = list(range(k + int(w[1]) - 3, k + int(w[1])))
                names = w[-3:]
            k += int(w[1])
        if w[:1] == ["MOTION"]:
            break
    start = text.index("MOTION") + 3
    rows = np.array([[float(x) for x in ln.split()] for ln in text[start:] if ln.strip()])
    assert names == ["Zrotation", "Xrotation", "Yrotation"]  # this file's order, every joint
    return rows[:, cols]


@pytest.mark.parametrize("joint, parent, child", [("RightKnee", "femur_r", "tibia_r"),
                                                  ("LeftElbow", "humerus_l", "ulna_l")])
def test_arena_bvh_joint_is_the_files_own_rotation(joint, parent, child):
    """The Arena skeleton's knee (elbow) — the tibia relative to the femur as read — turns by
    the angle of the file's own ``RightKnee`` channels (Z, X, Y intrinsic, degrees), read here
    from the text: the hierarchy and channel order are the file's, mapped by its joint names."""
    from scipy.spatial.transform import Rotation  # the reference reading, independent of bvhio

    t = read_bvh(ARENA)
    rel = Q.multiply(Q.conjugate(t.get(parent)), t.get(child))
    mine = np.degrees(2 * np.arccos(np.clip(np.abs(rel[:, 0]), 0.0, 1.0)))
    ref = Rotation.from_euler("ZXY", _bvh_channels(ARENA, joint), degrees=True).magnitude()
    np.testing.assert_allclose(mine, np.degrees(ref), atol=0.01)  # bvhio computes in float32


def test_arena_bvh_cycling_is_plausible():
    """No second format of this recording is public: the plausibility checks of the data
    README — knee flexion at the bottom of the pedal stroke within the 20-40° of saddle-height
    studies (Priego Quesada et al. 2016), every peak within AAOS's normal range, the legs in
    antiphase."""
    t = read_bvh(ARENA)
    assert t.meta["has"] == "skeleton arena" and len(t) == 300 and t.rate_hz == 100.0
    knees = [_flexion(ARENA, "knee", side, f"femur_{s}", f"tibia_{s}")
             for s, side in (("r", "right"), ("l", "left"))]
    for k in knees:
        assert 20.0 <= k.min() <= 40.0 and k.max() <= 135.0
        assert 70.0 < np.ptp(k) < 100.0
    assert np.corrcoef(knees[0], knees[1])[0, 1] < -0.8
    hip = _flexion(ARENA, "hip", "right", "pelvis", "femur_r")
    assert hip.max() <= 120.0


def test_arena_bvh_has_no_hands_and_says_why(capsys):
    code, _, err = _run(["rom", ARENA, "--joint", "wrist", "--parent", "ulna_r", "--child",
                         "hand_r", "--side", "right"], capsys)
    assert code == 2 and len(err.strip().splitlines()) == 1
    assert "hand bone" in err and "skeleton arena" in err


def _ideal_arm(flexion_deg: np.ndarray, side: str, pronation_deg: float) -> dict:
    """Plug-in Gait's upper-body markers on an ideal arm, by its own model (default subject
    measurements): lab = thorax frame (X forward, Y up, Z right); the upper arm 20° abducted;
    xELB on the flexion axis; the wrist bar turned ``pronation_deg`` about the forearm."""
    sign = 1.0 if side == "right" else -1.0
    S = "R" if side == "right" else "L"
    d = markers.DEFAULT_WIDTHS_MM
    r = d["MarkerDiameter"] / 2
    n = len(flexion_deg)
    fixed = {"CLAV": [0.0, 0, 0], "C7": [-120.0, 0, 0], "STRN": [40.0, -160, 0],
             "T10": [-160.0, -160, 0]}
    out = {k: np.tile(v, (n, 1)) for k, v in fixed.items()}
    sjc = np.array([-r, 0.0, sign * 180.0])  # level with the thorax origin (r behind CLAV)
    out[f"{S}SHO"] = np.tile(sjc + np.array([0.0, d["ShoulderOffset"] + r, 0.0]), (n, 1))
    a = np.radians(20.0)
    down = np.array([0.0, -np.cos(a), sign * np.sin(a)])
    axis = np.array([0.0, np.sin(a) * sign, np.cos(a)])  # the flexion axis, towards the right
    ejc = sjc + 300.0 * down
    out[f"{S}ELB"] = np.tile(ejc + sign * (d["ElbowWidth"] / 2 + r) * axis, (n, 1))
    forward = np.cross(-down, axis)
    rows = {"WRA": [], "WRB": [], "FIN": []}
    for f in np.radians(flexion_deg):
        fd = np.cos(f) * down + np.sin(f) * forward
        wjc = ejc + 250.0 * fd
        x0 = np.cross(-fd, axis)
        p = np.radians(pronation_deg)
        zf = np.cos(p) * axis + sign * np.sin(p) * x0
        mid = wjc.copy()
        for _ in range(30):  # Plug-in Gait's wrist centre, anterior of the bar's midpoint
            y = (ejc - mid) / np.linalg.norm(ejc - mid)
            z = zf - np.dot(zf, y) * y
            mid = wjc - (d["WristWidth"] / 2 + r) * np.cross(y, z / np.linalg.norm(z))
        rows["WRA"].append(mid + sign * 30.0 * zf)
        rows["WRB"].append(mid - sign * 30.0 * zf)
        rows["FIN"].append(wjc + 80.0 * fd - (d["HandThickness"] / 2 + r) * np.cross(-fd, zf))
    out.update({f"{S}{k}": np.array(v) for k, v in rows.items()})
    return out


@pytest.mark.parametrize("side", ["right", "left"])
def test_an_ideal_arm_reads_its_flexion_and_pronation(side):
    """On an ideal arm the thorax is the lab frame, and flexion and pronation (the forearm's
    rotation) are exact where Plug-in Gait's elbow centre is (from 110°; near extension it
    reads flexion high by construction, module doc: 30° at 5°)."""
    s = side[0]
    flexion = np.array([5.0, 35.0, 80.0, 110.0, 140.0])
    name, segs, _ = markers.segment_frames(_ideal_arm(flexion, side, 30.0))
    assert name == "plug-in-gait"
    np.testing.assert_allclose(segs["thorax"], np.tile([1.0, 0, 0, 0], (5, 1)), atol=1e-9)
    q = joint_to_rig(Q.multiply(Q.conjugate(segs[f"humerus_{s}"]), segs[f"ulna_{s}"]), "isb",
                     "upper-arm", "forearm")
    got = joint_angles(q, "elbow", side)
    assert np.all(np.abs(got["alpha"][3:] - flexion[3:]) < 1.0), got["alpha"]
    assert np.all(got["alpha"][:3] > flexion[:3])  # high near extension, as Plug-in Gait
    np.testing.assert_allclose(got["gamma"][3:], 30.0, atol=0.1)
    np.testing.assert_allclose(got["beta"], 0.0, atol=1e-6)
