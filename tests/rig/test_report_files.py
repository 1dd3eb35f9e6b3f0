"""``rig report FILE``: the report of a motion lab's C3D or BVH, or an OpenSim ``.sto``, read as
``rig boundary`` reads it, on the real excerpts of ``tests/calibration/data/real`` (sources in
its README): one joint (a limb of one joint) or a whole leg, the header saying what was read
from the file and naming no patient; bad input one line, exit 2, nothing written."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from rig.cli import main
from tests.calibration.test_lab_files import LEGS_ONLY_BVH

DATA = Path(__file__).parents[1] / "calibration" / "data" / "real"
PIG = str(DATA / "pycgm_vicon_movement_trial.c3d")
BVH = str(DATA / "cmu_61_07_salsa_daz.bvh")
STO = str(DATA / "xio_ximu3_lower_body.sto")



def _run(args, capsys) -> tuple[int, str, str]:
    with pytest.raises(SystemExit) as exc:
        main(args)
    out = capsys.readouterr()
    return exc.value.code, out.out, out.err


def _report(args, tmp_path, capsys, name="r.html") -> str:
    out = tmp_path / name
    code, text, err = _run(["report", *args, "--out", str(out)], capsys)
    assert code == 0, err
    assert text.strip() == f"wrote {out}"
    return out.read_text(encoding="utf-8")


def _joints(page: str) -> list[str]:
    return re.findall(r"<section class='joint' data-joint='(\w+)'", page)


def test_a_c3d_knee_from_its_markers(tmp_path, capsys):
    page = _report([PIG, "--joint", "knee", "--parent", "femur_r", "--child", "tibia_r",
                    "--age", "50", "--sex", "female"], tmp_path, capsys)
    assert _joints(page) == ["knee"]
    assert "Range of motion report — right knee" in page
    for fact in ("From file</td><td>pycgm_vicon_movement_trial.c3d",
                 "C3D (markers and model outputs)", "marker set plug-in-gait",
                 "columns femur_r → tibia_r", "323 at 120 Hz (2.7 s)"):
        assert fact in page, fact
    assert "Patient" not in page and "Session" not in page  # a file names no patient
    assert "women, 45-69" in page and "Soucie" in page  # the population column, 50, female
    assert "<h2>Couplings</h2>" not in page  # one joint: nothing to couple


def test_a_bvh_elbow_its_side_from_the_columns(tmp_path, capsys):
    cols = ["--joint", "elbow", "--parent", "humerus_l", "--child", "ulna_l"]
    ref = tmp_path / "elbow.yaml"  # the same file's boundary, drawn dashed
    code, _, err = _run(["boundary", BVH, *cols, "--side", "left", "--name", "truth",
                         "--out", str(ref)], capsys)
    assert code == 0, err
    page = _report([BVH, *cols, "--reference", str(ref)], tmp_path, capsys)
    assert _joints(page) == ["elbow"] and "— left elbow" in page
    assert "Reference (dashed)</td><td>truth" in page
    assert "BVH (skeleton and joint rotations)" in page and "skeleton daz" in page
    assert "400 at 60 Hz" in page and "no side given" not in page


def test_a_sto_whole_leg(tmp_path, capsys):
    page = _report([STO, "--limb", "leg", "--segments", "pelvis,femur_r,tibia_r,calcn_r",
                    "--frames", "isb", "--coupled-tests"], tmp_path, capsys)
    assert _joints(page) == ["hip", "knee", "ankle"] and "— right leg" in page
    assert "OpenSim orientations (.sto)" in page and "ISB / OpenSim (--frames isb)" in page
    assert "segments pelvis → femur_r → tibia_r → calcn_r" in page
    assert "930 at 50 Hz (18.6 s)" in page and "rig boundary --limb leg" in page
    assert "<h2>Couplings</h2>" in page and "<h2>Coupled clinical tests</h2>" in page


def _bad_cases(tmp_path: Path) -> list[tuple[list[str], str]]:
    legs = tmp_path / "legs.bvh"
    legs.write_text(LEGS_ONLY_BVH)  # a BVH of two legs and no arm
    (tmp_path / "notes.md").write_text("hello")
    return [
        ([str(tmp_path / "missing.c3d"), "--child", "tibia_r"], "no such file"),
        ([str(tmp_path / "notes.md"), "--child", "tibia_r"], "unknown format '.md'"),
        ([PIG, "--joint", "elbow", "--parent", "humerus_r", "--child", "ulna_r"],
         "no 'ulna_r': it needs CLAV"),
        ([str(legs), "--joint", "elbow", "--parent", "humerus_r", "--child", "ulna_r"],
         "RightForeArm"),
        ([PIG, "--joint", "knee", "--parent", "femur_r", "--child", "tibia_r", "--frames",
          "isb"], "--frames does not apply to a C3D file"),
        ([PIG, "--child", "tibia_r", "--db", str(tmp_path / "s.db"), "--session", "1"],
         "give either FILE or --db/--session"),
        (["--db", str(tmp_path / "s.db"), "--session", "1", "--joint", "knee"],
         "--joint applies to a FILE's report"),
        ([PIG, "--limb", "leg", "--segments", "pelvis,femur_r,tibia_r", "--joint", "knee"],
         "--joint does not apply with --limb leg"),
        ([], "give a recording"),
    ]


def test_bad_input_is_one_line_and_writes_nothing(tmp_path, capsys):
    out = tmp_path / "bad.html"
    for args, msg in _bad_cases(tmp_path):
        code, _, err = _run(["report", *args, "--out", str(out)], capsys)
        assert code == 2, (args, err)
        assert msg in err and len(err.strip().splitlines()) == 1, (args, err)
        assert not out.exists(), args
