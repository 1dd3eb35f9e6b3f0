"""The forearm joint kind in calibration (calibration.kinds.forearm): elbow flexion and forearm
pronation–supination from joint orientations alone, their AAOS norms, the extraction of a
``kind: forearm`` constraint — and the recorded extremes of the real arm recordings (CMU,
``data/real``: the x-io and Xsens excerpts are lower-body only)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from calibration.extraction.joint import fit_joint
from calibration.joint_angles import NORMATIVE, joint_angles
from calibration.joints import JOINTS
from calibration.kinds import calibration_kind
from models import quaternion as Q
from models.kinds import KINDS
from models.oracle import ConstraintOracle
from rig.readback import RecordingSource

DATA = Path(__file__).parent / "data" / "real"
Z, X = np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 0.0])
KIND = calibration_kind("forearm")

#: file, side, recorded (min, max) flexion and (min, max) pronation, degrees (humerus → ulna)
RECORDED = [
    ("cmu_61_07_salsa.sto", "r", (37.743, 159.723), (5.836, 58.161)),
    ("cmu_61_07_salsa.sto", "l", (32.100, 170.904), (4.319, 60.453)),
    ("cmu_60_02_salsa.sto", "r", (31.796, 149.112), (4.246, 54.998)),
    ("cmu_60_02_salsa.sto", "l", (31.333, 149.753), (4.142, 55.134)),
]


def _elbow(file: str, s: str):
    return RecordingSource(str(DATA / file), parent=f"humerus_{s}", child=f"ulna_{s}",
                           frames="isb", joint="elbow").load()


def test_norms_are_aaos_as_the_elbow_table_gives_them():
    assert KIND.norms == {m: NORMATIVE["aaos"]["elbow"][m]
                          for m in ("flexion", "extension", "pronation", "supination")}
    assert "AAOS 1965" in KIND.norms_source
    assert [m for pair in KIND.movements for m in pair] == ["flexion", "extension",
                                                            "pronation", "supination"]


@pytest.mark.parametrize("side", ["right", "left"])
def test_clinical_angles_are_the_elbow_cardan_angles(side):
    """Flexion is the ISB elbow's α and pronation its γ (Wu 2005): exactly on orientations
    with a carrying angle too (the floating axis is orthogonal to both)."""
    rng = np.random.default_rng(4)
    q = Q.multiply(Q.multiply(Q.from_axis_angle(Z, np.radians(rng.uniform(-10, 150, 300))),
                              Q.from_axis_angle(np.array([0.0, 1.0, 0.0]),
                                                np.radians(rng.uniform(-30, 30, 300)))),
                   Q.from_axis_angle(X, np.radians(rng.uniform(-85, 85, 300))))
    ours = KIND.clinical_angles(q, side)
    cardan = joint_angles(q, "elbow", side)
    np.testing.assert_allclose(ours["flexion"], cardan["alpha"], atol=1e-9)
    np.testing.assert_allclose(ours["pronation"], cardan["gamma"], atol=1e-9)


@pytest.mark.parametrize("file, s, flexion, pronation", RECORDED)
def test_recorded_extremes_of_the_real_arms(file, s, flexion, pronation):
    side = "right" if s == "r" else "left"
    data = _elbow(file, s)
    ang = KIND.clinical_angles(data.q, side)
    assert (ang["flexion"].min(), ang["flexion"].max()) == pytest.approx(flexion, abs=1e-3)
    assert (ang["pronation"].min(), ang["pronation"].max()) == pytest.approx(pronation, abs=1e-3)
    peaks = KIND.clinical_peaks(data.q, side)
    assert peaks == pytest.approx({"flexion": flexion[1], "extension": 0.0,
                                   "pronation": pronation[1], "supination": 0.0}, abs=1e-3)
    cardan = joint_angles(data.q, "elbow", side)
    np.testing.assert_allclose(ang["pronation"], cardan["gamma"], atol=1e-6)


@pytest.mark.parametrize("file, s, flexion, pronation", RECORDED[:2])
def test_extraction_holds_the_recorded_extremes(file, s, flexion, pronation):
    data = _elbow(file, s)
    ex = KIND.extractor(JOINTS["elbow"], limb_axis=(1.0, 0.0, 0.0), alpha_deg=4.0,
                        max_vertices=64, by_swing="auto", name="recorded")
    ex = fit_joint(ex, data.q, t=data.t, slow_error_deg=1.0)
    c = ex.constraint_
    f = c.limits
    assert c.kind == "forearm"
    assert (f.flexion_min_deg, f.flexion_max_deg) == pytest.approx(flexion, abs=1e-3)
    rot = np.sort(-np.array(pronation) if s == "r" else np.array(pronation))  # joint's own φ
    assert (f.rotation_min_deg, f.rotation_max_deg) == pytest.approx(tuple(rot), abs=1e-3)
    assert ex.report()["off_axis_rms_deg"] > 20.0  # CMU's carrying angle: reported, not fitted
    # what was recorded, with its carrying angle taken out, is inside the written limits
    theta = np.radians(KIND.clinical_angles(data.q, "right")["flexion"])
    phi = -np.radians(KIND.clinical_angles(data.q, "right")["pronation"])
    on_set = Q.multiply(Q.from_axis_angle(Z, theta), Q.from_axis_angle(X, phi))
    assert ConstraintOracle(c).is_valid(on_set).all()


def test_every_models_kind_has_its_calibration_kind():
    for name in KINDS:
        assert calibration_kind(name).name == name


FOREARM_FILE = """\
name: p42-forearm
kind: forearm
joint: elbow
side: right
forearm:
  flexion: {axis: [0, 0, 1], min_deg: 0, max_deg: 140}
  rotation: {min_deg: -70, max_deg: 80}
"""


def test_rom_of_a_forearm_constraint_reads_pronation_and_supination():
    """`rig rom --constraint` on a forearm file: the elbow's table shows the file's pronation
    (−φ) and supination (+φ), not "not measured by a hinge" as for the elbow's own kind."""
    from calibration.joint_angles import constraint_rom
    from models.constraint import loads_constraint

    rom = constraint_rom(loads_constraint(FOREARM_FILE), "elbow", "right")
    assert rom.peaks["pronation"] == pytest.approx(70.0, abs=1e-6)
    assert rom.peaks["supination"] == pytest.approx(80.0, abs=1e-6)
    assert rom.peaks["flexion"] == pytest.approx(140.0, abs=1e-6)
    table = rom.table()
    assert "not measured" not in table and "pronation      70.0°" in table
    assert rom.to_json()["not_measured"] == {}


def test_rig_boundary_extracts_a_forearm_constraint_from_a_real_arm(rig_cli, tmp_path):
    """`rig boundary --joint elbow --kind forearm` on the CMU arm: a forearm file holding the
    recorded flexion and pronation extremes, said in its own lines; `rig rom` reads it back;
    `--kind` with a whole limb is a one-line error."""
    out = tmp_path / "fa.yaml"
    code, text, err = rig_cli(["boundary", str(DATA / "cmu_60_02_salsa.sto"), "--parent",
                               "humerus_r", "--child", "ulna_r", "--joint", "elbow", "--frames",
                               "isb", "--kind", "forearm", "--out", str(out)])
    assert code == 0, err
    assert "flexion     31.8 .. 149.1 deg" in text and "pronation 55.0" in text
    from models.constraint import load_constraint

    c = load_constraint(out)
    assert c.kind == "forearm" and c.joint == "elbow"
    assert c.limits.flexion_max_deg == pytest.approx(149.112, abs=1e-3)
    assert c.limits.rotation_min_deg == pytest.approx(-54.998, abs=1e-3)
    code, text, err = rig_cli(["rom", "--constraint", str(out)])
    assert code == 0 and "pronation" in text and "not measured" not in text
    code, text, err = rig_cli(["boundary", str(DATA / "cmu_60_02_salsa.sto"), "--limb", "arm",
                          "--segments", "thorax,humerus_r,ulna_r,hand_r", "--kind", "forearm",
                          "--out", str(tmp_path / "x.yaml")])
    assert code == 2 and err.count("\n") == 1 and "--kind applies to one joint" in err


def test_an_elbows_forearm_file_is_refused_for_the_knee():
    """The flexion axis tells an elbow (+Z) from a knee (−Z) for a forearm joint as for a
    hinge: an unbound forearm file about +Z is no knee's, and no shoulder's (a ball joint)."""
    from calibration.joints import joint_mismatch
    from models.constraint import loads_constraint

    c = loads_constraint(FOREARM_FILE.replace("joint: elbow\n", ""))
    assert joint_mismatch(c, for_joint="elbow", for_side="right") is None
    assert "is a forearm about [0.0, 0.0, 1.0], but the knee's turns about" in joint_mismatch(
        c, for_joint="knee", for_side="right")
    assert "but the shoulder is a ball joint" in joint_mismatch(c, for_joint="shoulder",
                                                                for_side="right")
