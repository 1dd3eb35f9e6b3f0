"""Clinical angles of the elbow, wrist, hip, knee and ankle (issue 21, part 3): the ISB /
Grood-Suntay Cardan angles read back, their signs checked against where the segment points,
peaks per movement, and the mistakes a caller can make."""

from __future__ import annotations

import numpy as np
import pytest

from calibration.joint_angles import (
    JOINT_ANGLES,
    NORMATIVE,
    angle_peaks,
    from_angles,
    joint_angles,
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
