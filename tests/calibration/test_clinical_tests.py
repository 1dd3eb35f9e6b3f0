"""The coupled clinical tests (calibration.clinical_tests): simulated limbs whose truth is the
limb itself, and the real recordings (the value or "not reached", never an invented one)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from calibration.clinical_tests import coupled_measures, format_coupled_tests
from calibration.extraction import LimbExtractor
from calibration.joint_angles import from_angles
from models import quaternion as Q
from models.limb import Limb, dump_limb
from models.shapes import shape_path
from rig.cli import main
from rig.readback import load_joint_orientations
from rig.readback.progress import ProgressResult, Visit, coupled_test_rows
from rig.report.limb import LimbReportData, render_limb_html
from rig.report.progress import progress_section_html
from rig.sim.clinical_truth import coupled_test_truth
from rig.sim.patients import anatomical_limb

REAL = Path(__file__).parent / "data" / "real"


def test_ten_simulated_legs_and_arms_within_3_degrees_of_their_own_limits():
    errors: dict[str, float] = {}
    for seed in range(10):
        side = "left" if seed % 2 else "right"
        for kind in ("leg", "arm"):
            limb = anatomical_limb(200 + seed, kind, side)
            truth = coupled_test_truth(limb)
            got = coupled_measures(limb)
            assert {m.spec.key for m in got} == set(truth)
            for m in got:
                assert m.status == "limits" and m.coupled is True
                err = abs(m.value - truth[m.spec.key])
                errors[m.spec.key] = max(errors.get(m.spec.key, 0.0), err)
    print("worst |error| per test (deg):", {k: round(v, 3) for k, v in errors.items()})
    assert max(errors.values()) <= 3.0, errors


def test_verdicts_follow_table_4_thresholds():
    limb = anatomical_limb(3, "leg")
    by = {m.spec.key: m for m in coupled_measures(limb)}
    # seed 3: dorsiflexion 13.4° straight, 19.1° bent: the short-gastrocnemius pattern
    assert "short gastrocnemius" in by["silfverskiold_bent"].verdict
    pop = by["popliteal_angle"]
    assert pop.value > 40 and "short hamstrings" in pop.verdict
    assert "no short two-joint" in by["thomas_knee"].verdict
    text = format_coupled_tests(list(by.values()))
    assert "s13102-021-00242-y" in text and "Popliteal angle" in text


def test_an_uncoupled_pair_is_computed_from_the_uncoupled_limits_and_says_so():
    d = anatomical_limb(4, "leg").to_dict()
    d["joints"][2] = {**d["joints"][2], "constraint": d["joints"][2]["coupled"]["keyframes"][0][
        "constraint"]}
    d["joints"][2].pop("coupled")
    limb = Limb.from_dict(d)
    by = {m.spec.key: m for m in coupled_measures(limb)}
    s, b = by["silfverskiold_straight"], by["silfverskiold_bent"]
    assert s.coupled is False and "uncoupled limits" in s.notes[0]
    assert abs(s.value - b.value) < 1e-9  # the knee changes nothing without a coupling
    assert by["straight_leg_raise"].coupled is True
    # with a recording at the position, the uncoupled limits are not the test's reading
    q = np.zeros((20, 3, 4))
    q[..., 0] = 1.0
    q[:, 2] = from_angles(np.full(20, 5.0), 0.0, 0.0, "ankle")
    s = {m.spec.key: m for m in coupled_measures(limb, q)}["silfverskiold_straight"]
    assert s.status == "recording" and abs(s.value - 5.0) < 1e-6 and s.verdict is None
    assert s.from_limits == by["silfverskiold_straight"].value


def test_a_recording_that_never_reaches_the_position_gives_no_value():
    limb = anatomical_limb(5, "leg")
    # every posture neutral: the knee straight, the hip never at 90°, the knee never at 90°
    q = np.zeros((20, 3, 4))
    q[..., 0] = 1.0
    q[:, 2] = from_angles(np.zeros(20), 0.0, 0.0, "ankle")
    by = {m.spec.key: m for m in coupled_measures(limb, q)}
    for key in ("popliteal_angle", "silfverskiold_bent", "thomas_hip"):
        m = by[key]
        assert m.value is None and m.status == "not reached in this recording"
        assert m.from_limits is not None  # the limits had one: not shown as the test's value
    slr = by["straight_leg_raise"]
    assert slr.reached and abs(slr.recorded) < 1e-6 and slr.value == slr.from_limits


def _chain(file: str, segments: list[str], joints: list[str]) -> np.ndarray:
    return np.stack([load_joint_orientations(str(REAL / file), parent=p, child=c, frames="isb",
                                             joint=j).q
                     for j, p, c in zip(joints, segments[:-1], segments[1:], strict=True)],
                    axis=1)


@pytest.mark.parametrize("file,letter,side,limb", [
    ("xio_ximu3_lower_body.sto", "r", "right", "leg"),
    ("opensense_xsens_walking.sto", "l", "left", "leg"),
    ("cmu_61_07_salsa.sto", "r", "right", "leg"),
    ("cmu_61_07_salsa.sto", "r", "right", "arm"),
    ("cmu_60_02_salsa.sto", "r", "right", "arm"),
])
def test_real_recordings_give_the_value_or_not_reached(file, letter, side, limb):
    if limb == "leg":
        segs = ["pelvis", f"femur_{letter}", f"tibia_{letter}", f"calcn_{letter}"]
        names = ["hip", "knee", "ankle"]
    else:
        segs = ["thorax", f"humerus_{letter}", f"ulna_{letter}", f"hand_{letter}"]
        names = ["shoulder", "elbow", "wrist"]
    q = _chain(file, segs, names)
    got = coupled_measures(None, q, joint_names=names, side=side)
    print(file, limb, {m.spec.key: (None if m.value is None else round(m.value, 1))
                       for m in got})
    for m in got:
        if m.value is None:
            assert m.status == "not reached in this recording" and m.samples_at_position == 0
        else:  # a value is a recorded posture's reading, never a filled-in one
            assert m.status == "recording" and m.samples_at_position > 0
            assert m.value == m.recorded and m.verdict is None
    statuses = {m.status for m in got}
    if file == "opensense_xsens_walking.sto":  # walking: the hip never near 90°
        by = {m.spec.key: m for m in got}
        assert by["popliteal_angle"].value is None
        assert by["straight_leg_raise"].value is not None
    assert statuses <= {"recording", "not reached in this recording"}


def _run(args, capsys):
    with pytest.raises(SystemExit) as exc:
        main(args)
    out = capsys.readouterr()
    return exc.value.code, out.out, out.err


def test_rig_rom_coupled_tests_of_a_limb_file(tmp_path, capsys):
    f = tmp_path / "leg.yaml"
    dump_limb(anatomical_limb(3, "leg"), f)
    code, out, _ = _run(["rom", "--constraint", str(f), "--joint", "knee", "--coupled-tests",
                         "--json"], capsys)
    assert code == 0
    tests = {m["measure"]: m for m in json.loads(out)["coupled_tests"]}
    assert tests["silfverskiold_bent"]["status"] == "limits"
    assert "short gastrocnemius" in tests["silfverskiold_bent"]["verdict"]
    assert "s13102-021-00242-y" in tests["popliteal_angle"]["source"]
    code, out, _ = _run(["rom", "--constraint", str(f), "--joint", "knee"], capsys)
    assert code == 0 and "coupled clinical tests" in out  # on by default for a limb file
    code, out, _ = _run(["rom", "--constraint", str(f), "--joint", "knee",
                         "--no-coupled-tests", "--json"], capsys)
    assert code == 0 and "coupled_tests" not in json.loads(out)
    code, out, _ = _run(["rom", "--constraint", str(shape_path("original")), "--json"],
                        capsys)
    assert code == 0 and "coupled_tests" not in json.loads(out)  # one joint: says nothing
    code, _, err = _run(["rom", "--constraint", shape_path("original"), "--coupled-tests"],
                        capsys)
    assert code == 2 and "--coupled-tests reads a limb file" in err
    assert "Traceback" not in err
    code, _, err = _run(["rom", str(REAL / "xio_ximu3_lower_body.sto"), "--joint", "knee",
                         "--parent", "femur_r", "--child", "tibia_r", "--frames", "isb",
                         "--coupled-tests"], capsys)
    assert code == 2 and "not an orientation file" in err


def test_the_limb_report_section(tmp_path):
    limb = anatomical_limb(6, "arm")
    n = 30
    elbow = np.linspace(0.0, 100.0, n)
    q = {"shoulder": Q.from_axis_angle(np.array([0.0, 0.0, 1.0]), np.radians(np.full(n, 40.0))),
         "elbow": from_angles(elbow, 0.0, 0.0, "elbow"),
         "wrist": np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))}
    postures = np.stack([q[j] for j in limb.joint_names], axis=1)
    # the page alone (limb_report_data, seconds of figures, adds the same list when asked)
    data = LimbReportData(patient="P-1", side="right", limb="arm", limb_name=limb.name,
                          joint_order=limb.joint_names, samples=n,
                          coupled_tests=coupled_measures(limb, postures, side="right"))
    html = render_limb_html(data)
    assert "<h2>Coupled clinical tests</h2>" in html and "Shoulder flexion, elbow bent" in html
    by = {m.spec.key: m for m in data.coupled_tests}
    assert by["shoulder_flexion_straight"].reached and by["shoulder_flexion_bent"].reached
    assert abs(by["shoulder_flexion_bent"].recorded - 40.0) < 1e-6
    assert by["shoulder_extension_bent"].value == by["shoulder_extension_bent"].from_limits
    data.coupled_tests = None
    assert "Coupled clinical tests" not in render_limb_html(data)


@pytest.mark.parametrize("file,letter,side", [("xio_ximu3_lower_body.sto", "r", "right"),
                                              ("opensense_xsens_walking.sto", "l", "left")])
def test_real_recordings_with_the_limits_extracted_from_them(file, letter, side):
    q = _chain(file, ["pelvis", f"femur_{letter}", f"tibia_{letter}", f"calcn_{letter}"],
               ["hip", "knee", "ankle"])
    limb = LimbExtractor("leg").fit(q, side=side).limb_
    got = coupled_measures(limb, q, side=side)
    print(file, {m.spec.key: (m.status, None if m.value is None else round(m.value, 1))
                 for m in got})
    for m in got:
        if not m.reached:  # the limits may have a value there; the test has none
            assert m.value is None and m.status == "not reached in this recording"
        elif m.coupled is False:  # uncoupled limits are not the test's: the recording's
            assert m.value == m.recorded and m.status == "recording" and m.verdict is None
            assert "recording's own reading" in m.notes[0]
        else:
            assert m.value == m.from_limits
            assert m.status == ("limits" if m.value is not None else "not possible")
    if file == "opensense_xsens_walking.sto":
        assert {m.spec.key: m for m in got}["popliteal_angle"].value is None


def test_progress_shows_each_visits_coupled_tests():
    """``rig progress`` (table) and the report's progress section list every visit's coupled
    tests without a flag: the value, or the status where a visit never reached the position."""
    def visit(sid, day, value, usable=True):
        m = {"label": "Straight-leg raise", "value": value,
             "status": "recording" if value is not None else "not reached in this recording"}
        return Visit(sid, 1.8e9 + day * 86400.0, "hip", "right", "leg", "imu", "ended", False,
                     0.5, True, {"flexion": 100.0}, [] if usable else ["interrupted"],
                     tests={"straight_leg_raise": m})
    res = ProgressResult("P-1", [visit(1, 0, 61.24), visit(2, 7, None, usable=False)], {})
    rows = coupled_test_rows(res.visits)
    assert [r["text"] for r in rows] == ["61.2°", "not reached in this recording"]
    text = res.table()
    assert "coupled clinical tests across visits" in text and "61.2°" in text
    html = "\n".join(progress_section_html(res))
    assert "Coupled clinical tests across visits" in html and "not reached in this" in html
    assert "coupled" not in ProgressResult("P-2", [], {}).table()
