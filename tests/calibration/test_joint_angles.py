"""Clinical angles of the elbow, wrist, hip, knee and ankle (issue 21, part 3): the ISB /
Grood-Suntay Cardan angles read back, their signs checked against where the segment points,
peaks per movement, and the mistakes a caller can make."""

from __future__ import annotations

import json

import numpy as np
import pytest

from calibration import joint_angles as ja
from calibration.joint_angles import (
    CLINICAL_MOVEMENTS,
    JOINT_ANGLES,
    NORMATIVE,
    POPULATION,
    UNKNOWN_AGE,
    JointRangeOfMotion,
    allowed_rom,
    angle_peaks,
    constraint_rom,
    from_angles,
    joint_angles,
    largest_rom,
    population_band,
    population_reference,
)
from models import quaternion as Q


@pytest.mark.parametrize("joint", sorted(JOINT_ANGLES))
@pytest.mark.parametrize("side", ["right", "left"])
def test_angles_read_back_what_made_the_orientation(joint, side):
    rng = np.random.default_rng(3)
    a, b, c = rng.uniform(-150, 150, 500), rng.uniform(-80, 80, 500), rng.uniform(-150, 150, 500)
    got = joint_angles(from_angles(a, b, c, joint, side), joint, side)
    np.testing.assert_allclose(got["alpha"], a, atol=1e-9)
    np.testing.assert_allclose(got["beta"], b, atol=1e-9)
    np.testing.assert_allclose(got["gamma"], c, atol=1e-9)


def _where(joint, side, v, **angles):
    """Where the child segment's rig axis ``v`` points in the parent's rig frame."""
    kw = {"alpha": 0.0, "beta": 0.0, "gamma": 0.0, **angles}
    q = from_angles(kw["alpha"], kw["beta"], kw["gamma"], joint, side)[0]
    return Q.rotate(q, np.asarray(v, dtype=float))


X, Y, Z = np.eye(3)


def test_neutral_is_zero_and_the_ankles_neutral_points_the_toes_forward():
    for joint in ("elbow", "wrist", "hip", "knee"):
        assert all(abs(v[0]) < 1e-12 for v in joint_angles([1.0, 0, 0, 0], joint).values())
    np.testing.assert_allclose(_where("ankle", "right", X), Y, atol=1e-12)  # toes anterior


@pytest.mark.parametrize("side", ["right", "left"])
def test_signs_follow_the_segment(side):
    medial = -1.0 if side == "right" else 1.0  # +Z is the body's right for either side
    # flexion brings the thigh, forearm and hand forward; knee flexion takes the shank back
    assert _where("hip", side, X, alpha=90)[1] == pytest.approx(1.0)
    assert _where("elbow", side, X, alpha=90)[1] == pytest.approx(1.0)
    assert _where("wrist", side, X, alpha=60)[1] > 0.8
    assert _where("knee", side, X, alpha=90)[1] == pytest.approx(-1.0)
    # adduction and ulnar deviation move the distal segment towards the midline
    assert np.sign(_where("hip", side, X, beta=20)[2]) == medial
    assert np.sign(_where("knee", side, X, beta=10)[2]) == medial
    assert np.sign(_where("wrist", side, X, beta=20)[2]) == medial
    # internal rotation and pronation turn the anterior face medially
    assert np.sign(_where("hip", side, Y, gamma=30)[2]) == medial
    assert np.sign(_where("elbow", side, Y, gamma=30)[2]) == medial
    # dorsiflexion lifts the toes (towards the knee: the shank's −X); inversion turns the sole
    # (the foot's −Y) to face the midline; internal rotation turns the toes medially
    assert _where("ankle", side, X, alpha=20)[0] < -0.3
    assert np.sign(_where("ankle", side, -Y, beta=20)[2]) == medial
    assert np.sign(_where("ankle", side, X, gamma=20)[2]) == medial


def test_peaks_ignore_a_single_spike_and_report_both_directions():
    t = np.linspace(0, 1, 400)
    flex = 100 * np.sin(np.pi * t) - 10  # 10° of extension at either end, 90° flexion
    flex[200] = 170.0  # one bad sample
    angles = {"alpha": flex, "beta": np.zeros_like(t), "gamma": 5 * np.sin(2 * np.pi * t)}
    p = angle_peaks(angles, "knee")
    assert p["flexion"] == pytest.approx(90.0, abs=0.01)
    assert p["extension"] == pytest.approx(10.0, abs=0.01)
    assert p["adduction"] == 0.0 and p["abduction"] == 0.0
    assert p["internal_rotation"] == pytest.approx(5.0, abs=0.01)
    assert p["external_rotation"] == pytest.approx(5.0, abs=0.01)


def test_every_normative_movement_is_a_movement_of_its_joint():
    for joint, values in NORMATIVE["aaos"].items():
        names = {m for pair in JOINT_ANGLES[joint].movements for m in pair}
        assert set(values) <= names, joint
    for joint, movement in NORMATIVE["not_comparable"]:
        assert movement in NORMATIVE["aaos"][joint]


def test_mistakes_are_named():
    with pytest.raises(ValueError, match="joint must be one of"):
        joint_angles([1.0, 0, 0, 0], "shoulder")
    with pytest.raises(ValueError, match="side must be"):
        joint_angles([1.0, 0, 0, 0], "knee", side="up")
    with pytest.raises(ValueError, match="window"):
        angle_peaks({"alpha": [1.0], "beta": [0.0], "gamma": [0.0]}, "knee", window=0)
    with pytest.raises(ValueError):
        joint_angles([np.nan, 0, 0, 0], "knee")


# -- population values ----------------------------------------------------------------------------
def test_population_values_read_back_as_published():
    # Soucie 2011 / CDC, age 2-8, read on the CDC page
    assert population_reference("knee", "flexion", age=5, sex="female") == "153 (women, 2-8)"
    (v,) = population_band("hip", "extension", age=5, sex="male")
    assert (v.mean, v.ci95, v.age_lo, v.age_hi) == (28.3, (27.2, 29.4), 2, 8)
    # Boone & Azen 1979 (men) and Macedo & Magee 2008 (women), TABLE A.1
    assert population_reference("elbow", "supination", sex="male") == "82 (men, 1-54)"
    assert population_reference("wrist", "ulnar_deviation", sex="female") == "41 (women, 18-59)"
    assert population_band("elbow", "flexion", sex="female")[0].mean == 149.0


def test_every_population_value_is_a_clinical_movement_with_a_source_and_a_place():
    for joint, src in POPULATION.items():
        assert src["source"] and src["cite"] and src["measured"]
        for movement, values in src["movements"].items():
            assert movement in CLINICAL_MOVEMENTS[joint], (joint, movement)
            for v in values:
                assert v.sex in ("female", "male") and v.age_lo <= v.age_hi and v.where
                assert v.ci95 is None or v.ci95[0] <= v.mean <= v.ci95[1]
            bands = [(v.sex, v.age_lo) for v in values]
            assert len(bands) == len(set(bands)), (joint, movement)  # one value a band


def test_sex_and_age_select_the_band():
    assert population_reference("knee", "flexion", age=52, sex="female") == "138 (women, 45-69)"
    assert population_reference("knee", "flexion", age=52, sex="male") == "133 (men, 45-69)"
    assert population_reference("knee", "flexion", age=30, sex="male") == "138 (men, 20-44)"
    assert population_reference("knee", "flexion", age=44.9, sex="male") == "138 (men, 20-44)"
    # sex unknown: women and men apart
    assert (population_reference("hip", "flexion", age=60)
            == "131 (women, 45-69) / 127 (men, 45-69)")
    # age unknown: the adult band of UNKNOWN_AGE, named in the text
    assert UNKNOWN_AGE == 30
    assert (population_reference("ankle", "plantarflexion")
            == "62 (women, 20-44) / 55 (men, 20-44)")
    # past the oldest adult band: the oldest, named
    assert population_reference("hip", "extension", age=80, sex="female") == "17 (women, 45-69)"
    assert (population_reference("elbow", "pronation", age=70)
            == "92 (women, 18-59) / 76 (men, 1-54)")
    # between bands (Soucie 9-19 not tabulated here), under the youngest, or a child-only band
    # for an adult: nothing
    assert population_reference("knee", "flexion", age=12, sex="female") is None
    assert population_reference("ankle", "dorsiflexion", age=1) is None
    assert population_reference("knee", "extension", age=40) is None
    assert population_reference("elbow", "flexion", age=10) == "143 (men, 1-54)"  # women 18-59


def test_a_joint_or_movement_with_no_source_shows_a_dash_and_says_so(monkeypatch):
    rom = JointRangeOfMotion("hip", "right", {m: 20.0 for m in CLINICAL_MOVEMENTS["hip"]})
    assert population_reference("hip", "abduction", age=30, sex="male") is None
    lines = rom.table(age=30, sex="male").splitlines()
    row = next(x for x in lines if x.startswith("abduction"))
    assert row.rstrip().endswith("—")
    assert any(x.startswith("note: no population value for abduction, adduction") for x in lines)
    # a joint without a source
    monkeypatch.setattr(ja, "POPULATION", {k: v for k, v in POPULATION.items() if k != "wrist"})
    wrist = JointRangeOfMotion("wrist", "left", {m: 10.0 for m in CLINICAL_MOVEMENTS["wrist"]})
    assert population_reference("wrist", "flexion", sex="female") is None
    text = wrist.table(sex="female")
    rows = text.splitlines()[3:7]
    assert len(rows) == 4 and all(r.rstrip().endswith("—") for r in rows)
    assert "note: no published population values found for the wrist" in text
    assert "population =" not in text
    out = wrist.to_json(sex="female")
    assert out["population_source"] is None
    assert set(out["population"].values()) == {None}


def test_table_has_the_population_column_and_its_source():
    rom = JointRangeOfMotion("knee", "right", {"flexion": 130.0, "extension": 2.0}, (-2.0, 130.0))
    text = rom.table(age=52, sex="female")
    header = text.splitlines()[1]
    assert header.split()[:3] == ["movement", "measured", "AAOS"]
    assert "population (women, age 52)" in header
    assert "138 (women, 45-69)" in text
    assert "population = Soucie JM et al. 2011, Haemophilia 17:500-507" in text
    assert "age unknown" not in text
    assert "age unknown: the population band of a 30-year-old" in rom.table()
    assert "135°" in rom.table()  # AAOS column unchanged


def test_json_keeps_its_keys_adds_the_population_and_round_trips():
    rom = JointRangeOfMotion("elbow", "left", {"flexion": 140.123, "extension": 0.0,
                                               "pronation": None, "supination": 80.0},
                             (-0.5, 140.1))
    old = {"joint", "side", "arc", *CLINICAL_MOVEMENTS["elbow"]}
    plain = rom.to_json()
    assert old <= set(plain) and plain["flexion"] == 140.12 and plain["pronation"] is None
    out = rom.to_json(age=40, sex="male")
    assert {k: out[k] for k in old} == {k: plain[k] for k in old}
    assert out["population"]["flexion"] == "143 (men, 1-54)"
    assert out["population_values"]["flexion"] == [
        {"sex": "male", "age": [1, 54], "mean": 143.0, "sd": None, "ci95": None,
         "source": "Boone DC & Azen SP 1979, J Bone Joint Surg Am 61:756-759",
         "method": "active motion, universal goniometer (men only)"}]
    # a hinge has no forearm rotation: no value, no population to compare with (issue 37)
    assert out["supination"] is None and out["population_values"]["supination"] == []
    assert out["not_measured"] == {"pronation": "not measured by a hinge",
                                   "supination": "not measured by a hinge"}
    assert out["population_source"].startswith("men: Boone DC, Azen SP.")
    assert out["population_for"] == {"age": 40, "sex": "male"}
    assert json.loads(json.dumps(out)) == out
    knee = JointRangeOfMotion("knee", "right", {"flexion": 120.0, "extension": 0.0})
    k = json.loads(json.dumps(knee.to_json(age=5)))
    assert k["population_values"]["flexion"][0]["ci95"] == [151.2, 154.0]
    assert k == knee.to_json(age=5)


def test_population_mistakes_are_named():
    with pytest.raises(ValueError, match="sex must be"):
        population_reference("knee", "flexion", sex="f")
    with pytest.raises(ValueError, match="age must be"):
        population_reference("knee", "flexion", age=-3)
    with pytest.raises(ValueError, match="joint must be one of"):
        population_reference("shoulder", "flexion")
    with pytest.raises(ValueError, match="sex must be"):
        JointRangeOfMotion("knee", "right", {}).table(sex="x")


def test_recorded_rom_leaves_out_the_samples_the_sensors_flag():
    """A stretch recorded during a magnetic disturbance (the sensors' system calibration level
    down to 1) is not a peak: with ``status`` the knee's flexion peak is the undisturbed
    recording's; without, the disturbed stretch's."""
    alpha = np.concatenate([np.linspace(0.0, 90.0, 400), np.full(50, 120.0),
                            np.linspace(90.0, 0.0, 400)])
    q = ja.from_angles(alpha, np.zeros_like(alpha), np.zeros_like(alpha), "knee", "right")
    status = np.full(len(alpha), 0xFF)
    status[400:450] = (1 << 6) | 0x3F  # system level 1: disturbed
    assert ja.recorded_rom(q, "knee", "right").peaks["flexion"] == pytest.approx(120.0, abs=0.01)
    flagged = ja.recorded_rom(q, "knee", "right", status=status)
    assert flagged.peaks["flexion"] == pytest.approx(90.0, abs=0.3)  # running median of 5
    # nothing trustworthy at all: every sample is used rather than none
    none_ok = ja.recorded_rom(q, "knee", "right", status=np.zeros(len(alpha), int))
    assert none_ok.peaks["flexion"] == pytest.approx(120.0, abs=0.01)


def test_a_coupled_joint_allows_the_largest_over_its_keyframes():
    """What a coupled joint allows at some angle of the joint it depends on: movement by
    movement the largest over its keyframes, not one keyframe's reading (the straight-leg
    raise reads the hip's flexion 30-50° short; the straight elbow the shoulder's extension
    10-20° short)."""
    from calibration.clinical import range_of_motion
    from rig.sim.patients import anatomical_limb

    leg, arm = anatomical_limb(4, "leg", "right"), anatomical_limb(4, "arm", "right")
    hip = list(leg.joints[0].coupling.keyframes)
    truth = leg.provenance["clinical"]["hip"]
    got = allowed_rom(hip, "hip", "right")
    assert abs(got.peaks["flexion"] - truth["flexion"]) < 1.0
    assert abs(constraint_rom(hip[0], "hip").peaks["flexion"]
               - truth["flexion_knee_straight"]) < 1.0
    shoulder = list(arm.joints[0].coupling.keyframes)
    truth = arm.provenance["clinical"]["shoulder"]
    got = allowed_rom(shoulder, "shoulder", "right")
    assert abs(got.extension - truth["extension"]) < 0.5
    assert abs(range_of_motion(shoulder[0]).extension - truth["extension_elbow_straight"]) < 0.5
    assert allowed_rom(shoulder[0], "shoulder") == range_of_motion(shoulder[0])
    # with a recording, each peak the smaller of the limits' (largest) and the recording's
    d = Q.rotate(Q.from_axis_angle(np.array([0.0, 0.0, 1.0]), np.radians([-10.0, -20.0, 30.0])),
                 np.array([1.0, 0.0, 0.0]))
    rec = allowed_rom(shoulder, "shoulder", "right", directions=d)
    assert rec.extension == range_of_motion(shoulder[-1], directions=d).extension
    assert rec.extension is not None and rec.extension < 35.0 and rec.flexion < 35.0
    with pytest.raises(ValueError, match="no ranges"):
        largest_rom([])


# -- issue 37: movements a joint's kind cannot measure; angles beyond physiological reach ------
def test_the_kind_decides_which_movements_are_measured():
    """One place (:func:`not_measured`, from the joint's kind) says the elbow hinge has no
    pronation or supination; the recorded peaks, the constraint's and the table agree."""
    assert ja.not_measured("elbow") == {"pronation": "not measured by a hinge",
                                        "supination": "not measured by a hinge"}
    for joint in ("shoulder", "wrist", "hip", "knee", "ankle"):
        assert ja.not_measured(joint) == {}
    with pytest.raises(ValueError, match="joint must be one of"):
        ja.not_measured("neck")
    # a forearm turned 30° about its long axis while the elbow bends: out-of-axis motion of
    # the hinge, which before was read as 30° of pronation ("38 % of AAOS")
    alpha = np.linspace(0.0, 140.0, 300)
    gamma = 30.0 * np.sin(np.linspace(0.0, 6.0, 300))
    q = ja.from_angles(alpha, np.zeros_like(alpha), gamma, "elbow", "right")
    rec = ja.recorded_rom(q, "elbow", "right")
    assert rec.peaks["pronation"] is None and rec.peaks["supination"] is None
    assert rec.peaks["flexion"] == pytest.approx(140.0, abs=0.5)
    text = rec.table()
    row = next(line for line in text.splitlines() if line.startswith("pronation"))
    assert "not measured by a hinge" in row and "80°" not in row
    assert "not a deficit" in text


def test_widest_norms_come_from_the_cited_tables():
    """The physiological maxima are the cited norms' widest values plus the stated margin: no
    number of their own."""
    from calibration.clinical import NORMATIVE as SHOULDER

    assert ja.WIDEST_NORMS["knee"]["extension"] == (6.9, "Soucie 2011")  # 5.4, CI to 6.9
    assert ja.WIDEST_NORMS["knee"]["flexion"][0] == max(
        NORMATIVE["aaos"]["knee"]["flexion"],
        *(v.ci95[1] if v.ci95 else v.mean for v in POPULATION["knee"]["movements"]["flexion"]))
    assert ja.WIDEST_NORMS["shoulder"]["flexion"][0] == SHOULDER["aaos"]["flexion"]
    assert ja.physiological_max("knee", "extension") == pytest.approx(
        6.9 + ja.REACH_MARGIN_DEG)
    assert ja.physiological_max("shoulder", "adduction") is None  # no norm: not judged
    for joint, moves in CLINICAL_MOVEMENTS.items():
        for m in moves:
            assert ja.physiological_max(joint, m) is not None, (joint, m)


def test_a_knee_bent_backwards_is_flagged_with_its_likely_cause():
    """Sensor orientations read as segments (the rig's own ``rig export``) gave a knee
    extension of 176.6° without a word; now it is flagged, with what likely caused it."""
    alpha = np.concatenate([np.linspace(0.0, 120.0, 200), np.full(20, -176.6),
                            np.linspace(-176.6, 0.0, 200)])
    q = ja.from_angles(alpha, np.zeros_like(alpha), np.zeros_like(alpha), "knee", "right")
    rec = ja.recorded_rom(q, "knee", "right")
    far = ja.beyond_reach(rec)
    assert set(far) == {"extension"}
    assert far["extension"]["value"] == pytest.approx(176.6, abs=0.1)
    assert "beyond what people reach" in far["extension"]["text"]
    assert "sensor orientations" in far["extension"]["text"]
    assert "--parent/--child" in far["extension"]["text"]
    ok = JointRangeOfMotion("knee", "right", {"flexion": 150.0, "extension": 10.0})
    assert ja.beyond_reach(ok) == {}
