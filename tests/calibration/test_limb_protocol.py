"""The limb calibration protocol: phases, and each movement a pure flexion of its joint."""

import numpy as np
import pytest

from calibration.joint_angles import joint_angles
from calibration.protocol import LIMB_CHAINS, LimbCalibrationProtocol
from models import quaternion as Q


@pytest.mark.parametrize("limb", sorted(LIMB_CHAINS))
@pytest.mark.parametrize("side", ["right", "left"])
def test_each_movement_flexes_its_joint_only(limb, side):
    p = LimbCalibrationProtocol(limb)
    w = p.windows()
    assert list(w) == ["static", *p.joints]
    t = np.linspace(0.0, p.duration_s, 2001)
    q = p.joint_orientations(t, side)
    a = p.angles(t)
    assert q.shape == (len(t), 3, 4)
    for i, joint in enumerate(p.joints):
        moving = (t >= w[joint][0]) & (t <= w[joint][1])
        flex, ext = p.amplitude(joint)
        assert a[moving, i].max() == pytest.approx(flex, abs=0.5)
        assert a[moving, i].min() == pytest.approx(-ext, abs=0.5)
        assert np.all(a[~moving & ((t < w[joint][0] - 1) | (t > w[joint][1] + 1)), i] == 0)
        if joint == "shoulder":
            continue
        ang = joint_angles(q[:, i], joint, side)
        np.testing.assert_allclose(ang["alpha"], a[:, i], atol=1e-9)
        np.testing.assert_allclose(ang["beta"], 0.0, atol=1e-9)
        np.testing.assert_allclose(ang["gamma"], 0.0, atol=1e-9)
    static = (t >= w["static"][0]) & (t <= w["static"][1])
    zero = joint_angles(q[static, -1], p.joints[-1], side)
    assert np.abs(zero["alpha"]).max() < 1e-9
    if limb == "arm":  # the shoulder's zero is the identity
        np.testing.assert_allclose(Q.angle(q[static, 0]), 0.0, atol=1e-12)


def test_bad_protocols_are_refused():
    with pytest.raises(ValueError, match="limb must be"):
        LimbCalibrationProtocol("tail")
    with pytest.raises(ValueError, match="not a joint of the leg"):
        LimbCalibrationProtocol("leg", amplitudes=(("elbow", 30.0, 0.0),))
    with pytest.raises(ValueError, match="settle_s"):
        LimbCalibrationProtocol("arm", movement_s=1.0, settle_s=0.5)
