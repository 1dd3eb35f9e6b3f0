"""``rig boundary`` and ``rig rom`` through the CLI entry point."""

from __future__ import annotations

import numpy as np
import pytest

from calibration.clinical import RangeOfMotion
from models.constraint import load_constraint
from rig.cli import main
from rig.store import SampleWriter, open_store
from rig.store.io import OrientationTable, write_csv, write_sto


def run(args, capsys):
    with pytest.raises(SystemExit) as exc:
        main(args)
    out = capsys.readouterr()
    return exc.value.code, out.out, out.err


@pytest.fixture(scope="module")
def sto_file(servo_patient, tmp_path_factory):
    _, rec = servo_patient
    path = tmp_path_factory.mktemp("rec") / "patient.sto"
    write_sto(path, OrientationTable(time=rec.t, columns={"thorax_imu": rec.thorax,
                                                          "humerus_imu": rec.limb}, rate_hz=50.0))
    return path


@pytest.fixture(scope="module")
def short_sto_file(servo_patient, tmp_path_factory):
    """The first 60 s of :func:`sto_file`'s recording (the calibration protocol and some free
    motion): enough for an extraction, for tests that compare two spellings of one command."""
    _, rec = servo_patient
    keep = rec.t < rec.t[0] + 60.0
    path = tmp_path_factory.mktemp("rec") / "patient_60s.sto"
    write_sto(path, OrientationTable(time=rec.t[keep], columns={
        "thorax_imu": rec.thorax[keep], "humerus_imu": rec.limb[keep]}, rate_hz=50.0))
    return path


def test_boundary_from_sto_writes_a_loadable_constraint(sto_file, tmp_path, capsys):
    out = tmp_path / "c.yaml"
    code, stdout, err = run(["boundary", str(sto_file), "--parent", "thorax",
                             "--child", "humerus", "--out", str(out), "--side", "left"], capsys)
    assert code == 0, err
    assert "wrote" in stdout and "twist" in stdout
    c = load_constraint(out)
    assert c.provenance["file"] == "patient.sto" and c.provenance["reference"] == "thorax"
    assert c.side == "left"


def test_boundary_from_csv_with_joint_column(servo_patient, tmp_path, capsys):
    _, rec = servo_patient
    csv = tmp_path / "joint.csv"
    write_csv(csv, OrientationTable(time=rec.t, columns={"shoulder": rec.limb}))
    code, _, err = run(["boundary", str(csv), "--child", "shoulder", "--out",
                        str(tmp_path / "c.yaml")], capsys)
    assert code == 0, err


def test_boundary_from_a_session_is_stored(servo_patient, tmp_path, capsys):
    _, rec = servo_patient
    db = tmp_path / "s.db"
    with open_store(db) as st:
        pid = st.patients.add("P-001")
        sid = st.sessions.start(pid, rig_name="sim-shoulder", joint="shoulder", side="right")
        st.samples.add_sensor(sid, "shoulder", segment="humerus", kind="joint", port="sim://dynamixel")
        with SampleWriter(st, sid) as w:
            w.add_many(rec.t, None, "shoulder", "joint", rec.limb, 0)
        st.sessions.end(sid, status="completed", meta={})
    out = tmp_path / "c.yaml"
    code, _, err = run(["boundary", "--db", str(db), "--session", str(sid), "--out", str(out)],
                       capsys)
    assert code == 0, err
    c = load_constraint(out)
    assert c.provenance["session"] == sid and c.patient == "P-001"
    # named after the patient, the session and when it started: unique across databases
    import re

    assert re.fullmatch(rf"P-001-session-{sid}-\d{{8}}T\d{{6}}Z", c.name), c.name
    code, stdout, err = run(["rom", "--db", str(db), "--session", str(sid), "--age", "50",
                             "--sex", "female"], capsys)
    assert code == 0, err
    assert "flexion" in stdout and "AAOS" in stdout


def test_rom_json_of_an_interrupted_session(servo_patient, tmp_path, capsys):
    import json

    _, rec = servo_patient
    db = tmp_path / "s.db"
    with open_store(db) as st:
        pid = st.patients.add("P-002")
        sid = st.sessions.start(pid, rig_name="sim-shoulder", joint="shoulder", side="left")
        st.samples.add_sensor(sid, "shoulder", segment="humerus", kind="joint", port="sim://dynamixel")
        with SampleWriter(st, sid) as w:
            w.add_many(rec.t, None, "shoulder", "joint", rec.limb, 0)
        st.sessions.end(sid, status="interrupted", meta={})
    code, stdout, err = run(["rom", "--db", str(db), "--session", str(sid), "--json"], capsys)
    assert code == 0, err
    rom = json.loads(stdout)  # one JSON object, nothing else printed
    assert rom["joint"] == "shoulder" and rom["side"] == "left"
    assert set(RangeOfMotion.MOVEMENTS) <= set(rom)
    assert all(rom[m] is None or isinstance(rom[m], float) for m in RangeOfMotion.MOVEMENTS)
    assert rom["interrupted"] is True and 0.0 <= rom["coverage"] <= 1.0
    assert any("cut short" in w for w in rom["warnings"])
    # the table says it too
    code, stdout, err = run(["rom", "--db", str(db), "--session", str(sid)], capsys)
    assert code == 0 and "warning: the session was cut short" in stdout
    code, stdout, err = run(["boundary", "--db", str(db), "--session", str(sid), "--out",
                             str(tmp_path / "b.yaml")], capsys)
    assert code == 0 and "warning: the session was cut short" in stdout
    assert load_constraint(tmp_path / "b.yaml").provenance["recording"]["interrupted"] is True


@pytest.mark.parametrize("args, message", [
    (["boundary", "--out", "c.yaml"], "give a recording"),
    (["boundary", "missing.sto", "--child", "h", "--out", "c.yaml"], "no such file"),
    (["boundary", "{sto}", "--out", "c.yaml"], "--child"),
    (["boundary", "{sto}", "--parent", "thx", "--child", "humerus", "--out", "c.yaml"],
     "no column 'thx'"),
    (["boundary", "{sto}", "--child", "humerus", "--limb-axis", "1,0", "--out", "c.yaml"],
     "--limb-axis"),
    (["boundary", "{sto}", "--db", "x.db", "--session", "1", "--child", "h", "--out", "c.yaml"],
     "not both"),
    (["rom", "--constraint", "nope.yaml"], "no such file"),
    (["rom", "--constraint", "nope.yaml", "--frames", "isb"], "--frames applies"),
    (["boundary", "--db", "x.db", "--session", "1", "--frames", "isb", "--out", "c.yaml"],
     "--frames applies to files"),
    (["boundary", "{sto}", "--child", "humerus", "--frames", "opensim", "--out", "c.yaml"],
     "--frames"),
])
def test_bad_input_is_one_line_exit_2(args, message, sto_file, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    args = [a.format(sto=sto_file) for a in args]
    code, _, err = run(args, capsys)
    assert code == 2
    assert err.startswith("rig: error:") and message in err
    assert len(err.strip().splitlines()) == 1


def test_rom_from_a_constraint_file(capsys, tmp_path):
    from models.constraint import JointConstraint, dump_constraint

    path = tmp_path / "cone.yaml"
    dump_constraint(JointConstraint.cone((1.0, 0, 0), 50.0, twist=(-30.0, 60.0)), path)
    code, stdout, err = run(["rom", "--constraint", str(path)], capsys)
    assert code == 0, err
    line = next(ln for ln in stdout.splitlines() if ln.startswith("external rotation"))
    measured = line.split(")")[1].split()[0]
    assert np.isclose(float(measured.rstrip("°")), 60.0)


def test_rom_flags_a_knee_angle_beyond_what_people_reach(tmp_path, capsys):
    """Issue 37: sensor orientations read as segments gave a knee extension of 176.6° without
    a word; ``rig rom`` now flags it, in the text and the JSON, with its likely cause."""
    import json

    from calibration.joint_angles import from_angles
    from models import quaternion as Q

    alpha = np.concatenate([np.linspace(0.0, 110.0, 150), np.full(20, -176.6),
                            np.linspace(-176.6, 0.0, 150)])
    zero = np.zeros_like(alpha)
    knee = from_angles(alpha, zero, zero, "knee", "right")
    path = tmp_path / "leg.sto"
    write_sto(path, OrientationTable(time=np.arange(len(alpha)) / 100.0, columns={
        "thigh_imu": np.tile(Q.IDENTITY, (len(alpha), 1)), "shank_imu": knee}, rate_hz=100.0))
    args = ["rom", str(path), "--joint", "knee", "--parent", "thigh", "--child", "shank"]
    code, stdout, err = run(args, capsys)
    assert code == 0, err
    warning = next(ln for ln in stdout.splitlines() if ln.startswith("warning: knee extension"))
    assert "176.6° is beyond what people reach" in warning and "sensor orientations" in warning
    assert not any("knee flexion" in ln for ln in stdout.splitlines() if "warning" in ln)
    code, stdout, err = run([*args, "--json"], capsys)
    out = json.loads(stdout)
    assert set(out["beyond_reach"]) == {"extension"}
    assert out["beyond_reach"]["extension"]["source"] == "Soucie 2011"
    assert any("beyond what people reach" in w for w in out["warnings"])


REAL = __import__("pathlib").Path(__file__).parent / "data" / "real" / "cmu_61_07_salsa.sto"


@pytest.mark.parametrize("args, message", [
    (["boundary", "{f}", "--limb", "arm", "--segments", "pelvis,femur_r,tibia_r,calcn_r"],
     "column 'pelvis' is a pelvis, not the thorax (reading the arm: --limb arm)"),
    (["boundary", "{f}", "--joint", "elbow", "--parent", "femur_r", "--child", "tibia_r"],
     "column 'femur_r' is a thigh, not the upper-arm (reading the elbow: --joint elbow); "
     "these columns are a knee: --joint knee"),
    (["boundary", "{f}", "--joint", "knee", "--parent", "femur_r", "--child", "tibia_r",
      "--side", "left"], "column 'femur_r' is a right segment, but the left side is asked"),
    (["boundary", "{f}", "--limb", "leg", "--segments", "pelvis,femur_r,tibia_r,calcn_r",
      "--side", "left"], "column 'femur_r' is a right segment, but the left side is asked"),
    (["boundary", "{f}", "--limb", "leg", "--segments", "pelvis,femur_l,tibia_r,calcn_r"],
     "--segments 'pelvis', 'femur_l', 'tibia_r', 'calcn_r' mix the left and right sides"),
    (["boundary", "{f}", "--parent", "pelvis", "--child", "femur_r"],
     "reading the shoulder, the file's joint or the default: give --joint); these columns "
     "are a hip: --joint hip"),
    (["rom", "{f}", "--joint", "knee", "--parent", "femur_l", "--child", "tibia_l",
      "--side", "right"], "column 'femur_l' is a left segment, but the right side is asked"),
])
def test_columns_that_contradict_the_joint_chain_or_side_are_refused(args, message, tmp_path,
                                                                     capsys):
    """Issue 37, case 2: OpenSim/ISB segment names (femur_r, calcn_r, ulna_r, …) are read,
    and a --limb arm|leg, --joint or --side they contradict is refused before any work."""
    out = ["--out", str(tmp_path / "c.yaml")] if args[0] == "boundary" else []
    code, _, err = run([a.format(f=REAL) for a in args] + out, capsys)
    assert code == 2 and message in err and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "c.yaml").exists()


def test_column_names_of_other_tools_name_a_segment_and_side():
    from calibration.joints import columns_mismatch, joint_of_columns, segment_of_column

    for name, want in (("femur_r_imu", ("thigh", "right")), ("RightForeArm", ("forearm", "right")),
                       ("calcn_l", ("foot", "left")), ("T8", ("thorax", None)),
                       ("humerus_imu", ("upper-arm", None)), ("ulna_r", ("forearm", "right")),
                       ("LeftLowerLeg", ("shank", "left")), ("upper-arm", ("upper-arm", None)),
                       ("s1", (None, None)), ("thorax", ("thorax", None))):
        assert segment_of_column(name) == want, name
    assert joint_of_columns("pelvis_imu", "femur_r_imu") == "hip"
    assert joint_of_columns("humerus_r", "ulna_r") == "elbow"
    assert joint_of_columns(None, "ulna_r") is None
    assert columns_mismatch(["s1", "s2"], ["thorax", "upper-arm"], side="left") is None
    assert columns_mismatch(["thorax", "humerus_l"], ["thorax", "upper-arm"], side="left") is None


def test_a_side_other_than_the_sessions_is_refused_before_reading(servo_patient, tmp_path,
                                                                   capsys):
    """Issue 37: ``--side left`` on a right shoulder's session mirrored its clinical angles."""
    _, rec = servo_patient
    db = tmp_path / "s.db"
    with open_store(db) as st:
        sid = st.sessions.start(st.patients.add("P-001"), rig_name="sim-shoulder",
                                joint="shoulder", side="right")
        st.samples.add_sensor(sid, "shoulder", segment="humerus", kind="joint", port="sim://dynamixel")
        with SampleWriter(st, sid) as w:
            w.add_many(rec.t, None, "shoulder", "joint", rec.limb, 0)
        st.sessions.end(sid, status="completed", meta={})
    for args in (["boundary", "--db", db, "--session", sid, "--side", "left", "--out",
                  tmp_path / "c.yaml"],
                 ["rom", "--db", db, "--session", sid, "--side", "left"],
                 ["boundary", "--db", db, "--session", sid, "--limb", "arm", "--side", "left",
                  "--out", tmp_path / "c.yaml"]):
        code, _, err = run([str(a) for a in args], capsys)
        assert code == 2 and "--side left: session 1 recorded the right shoulder" in err, err
    assert not (tmp_path / "c.yaml").exists()


# --- a file's segment columns are --parent/--child; --limb is only a whole limb ---------------

NOTE_PARENT = "rig: note: --reference is now --parent"
NOTE_CHILD = "rig: note: --limb COLUMN is now --child COLUMN"


@pytest.mark.parametrize("command", ["boundary", "rom"])
def test_the_old_column_spellings_work_with_one_note_each(command, short_sto_file, tmp_path,
                                                         capsys):
    """Each old spelling gives the new one's output, with one note each (on a 60 s excerpt:
    four extractions of the whole 300 s took 5 s)."""
    def call(*columns):
        extra = ["--out", str(tmp_path / "c.yaml")] if command == "boundary" else ["--json"]
        return run([command, str(short_sto_file), *columns, *extra], capsys)

    new = call("--parent", "thorax", "--child", "humerus")
    old = call("--reference", "thorax", "--limb", "humerus")
    assert new[0] == old[0] == 0, old[2]
    assert new[2] == ""
    assert old[2].splitlines() == [NOTE_PARENT, NOTE_CHILD]
    assert old[1] == new[1]
    code, _, err = call("--parent", "thorax", "--limb", "humerus")
    assert code == 0 and err.splitlines() == [NOTE_CHILD]
    code, _, err = call("--reference", "thorax", "--child", "humerus")
    assert code == 0 and err.splitlines() == [NOTE_PARENT]


@pytest.mark.parametrize("args, message", [
    (["--parent", "thorax", "--reference", "thorax", "--child", "humerus"], "give --parent once"),
    (["--parent", "thorax", "--child", "humerus", "--limb", "humerus"], "give --child once"),
])
def test_an_old_and_a_new_spelling_together_are_refused(args, message, sto_file, tmp_path,
                                                        capsys):
    code, _, err = run(["boundary", str(sto_file), *args, "--out", str(tmp_path / "c.yaml")],
                       capsys)
    assert code == 2 and err.splitlines()[-1].startswith("rig: error:") and message in err


def test_child_arm_is_a_column_and_limb_arm_is_the_whole_arm(servo_patient, tmp_path, capsys):
    """A column named ``arm`` is read with ``--child arm``; ``--limb arm`` is the whole arm
    (it wants the arm's four segment columns), not that column, and no note is printed."""
    _, rec = servo_patient
    csv = tmp_path / "joint.csv"
    write_csv(csv, OrientationTable(time=rec.t, columns={"arm": rec.limb}))
    out = tmp_path / "c.yaml"
    code, _, err = run(["boundary", str(csv), "--child", "arm", "--out", str(out)], capsys)
    assert code == 0 and err == "", err
    assert load_constraint(out).provenance["limb"] == "arm"
    code, _, err = run(["boundary", str(csv), "--limb", "arm", "--out", str(out)], capsys)
    assert code == 2 and "note" not in err
    assert err.strip() == "rig: error: --limb arm needs --segments COL,COL,COL (proximal to distal)"
    code, _, err = run(["rom", str(csv), "--limb", "arm"], capsys)
    assert code == 2 and "is --child arm" in err and len(err.strip().splitlines()) == 1
