"""ISB angles, clinical peaks, normative values."""

from __future__ import annotations

import math

import numpy as np
import pytest

from calibration import NORMATIVE, format_rom_table, isb_angles, range_of_motion
from calibration.clinical import mirror_quaternions, normative_band
from models import quaternion as Q
from models.constraint import JointConstraint

Z = np.array([0.0, 0.0, 1.0])  # rig +Z: lateral for a right arm; flexion is about +Z
Y = np.array([0.0, 1.0, 0.0])
X = np.array([1.0, 0.0, 0.0])


def test_flexion_abduction_and_rotation_angles():
    flex = isb_angles(Q.from_axis_angle(Z, math.radians(60)))
    assert flex["elevation"][0] == pytest.approx(60.0)
    assert flex["plane_of_elevation"][0] == pytest.approx(90.0)
    abd = isb_angles(Q.from_axis_angle(-Y, math.radians(70)))  # +X (down) towards +Z (lateral)
    assert abd["elevation"][0] == pytest.approx(70.0)
    assert abd["plane_of_elevation"][0] == pytest.approx(0.0, abs=1e-9)
    # external rotation of a right arm = positive twist about the distal axis +X
    er = isb_angles(Q.from_axis_angle(X, math.radians(30)))
    assert er["axial_rotation"][0] == pytest.approx(-30.0)  # ISB: internal positive
    assert er["sequence"][0] == 1  # X-Z'-Y'' at the side (Y-X'-Y'' is gimbal-locked)
    assert math.isnan(er["plane_of_elevation"][0])
    high = isb_angles(Q.multiply(Q.from_axis_angle(-Y, math.radians(90)),
                                 Q.from_axis_angle(X, math.radians(30))))
    assert high["sequence"][0] == 0
    assert high["axial_rotation"][0] == pytest.approx(-30.0)


def test_left_arm_is_the_mirror_image():
    rng = np.random.default_rng(0)
    q = Q.random_quaternions(20, rng)
    right = isb_angles(q, "right")
    left = isb_angles(mirror_quaternions(q), "left")
    for k in ("elevation", "axial_rotation"):
        np.testing.assert_allclose(left[k], right[k], atol=1e-9)


def test_peaks_of_a_cone_and_the_twist_mapping():
    c = JointConstraint.cone((1.0, 0, 0), 50.0, twist=(-40.0, 70.0))
    r = range_of_motion(c, "right")
    for m in ("flexion", "extension", "abduction", "adduction"):
        assert getattr(r, m) == pytest.approx(50.0, abs=0.01)
    assert r.horizontal_adduction is None  # straight ahead at 90° is outside a 50° cone
    assert r.external_rotation == pytest.approx(70.0)
    assert r.internal_rotation == pytest.approx(40.0)
    left = range_of_motion(c, "left")
    assert left.external_rotation == pytest.approx(40.0)
    assert left.internal_rotation == pytest.approx(70.0)


def test_peaks_of_an_off_centre_cone_and_horizontal_adduction():
    # a cone leaning forward: more flexion than extension; reaches straight ahead at 90°
    centre = Q.rotate(Q.from_axis_angle(Z, math.radians(60)), X)
    r = range_of_motion(JointConstraint.cone(centre, 70.0), "right")
    assert r.flexion == pytest.approx(130.0, abs=0.01)
    assert r.extension == pytest.approx(10.0, abs=0.01)
    assert r.horizontal_adduction is not None and r.horizontal_adduction > 0
    mirrored = JointConstraint.cone(centre * [1, 1, -1], 70.0)
    assert range_of_motion(mirrored, "left").flexion == pytest.approx(130.0, abs=0.01)


def test_normative_values_and_table():
    assert NORMATIVE["aaos"] == {"flexion": 180.0, "extension": 60.0, "abduction": 180.0,
                                 "internal_rotation": 70.0, "external_rotation": 90.0}
    assert normative_band("flexion", sex="male") == 161.5
    assert normative_band("abduction", age=47, sex="female") == 152.0
    assert normative_band("abduction", age=90, sex="male") == 132.0
    assert normative_band("extension", age=47, sex="female") is None
    text = format_rom_table(range_of_motion(JointConstraint.cone((1.0, 0, 0), 50.0)),
                            age=30, sex="female")
    assert "flexion" in text and "180°" in text and "Gill" in text
