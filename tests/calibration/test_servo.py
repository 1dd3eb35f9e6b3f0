"""Servo-chain zero and direction calibration."""

from __future__ import annotations

import numpy as np
import pytest

from calibration import CalibrationError, ServoChainCalibration
from calibration.servo import chain_forward

AXES = np.array([[0, 0, 1.0], [0, 1.0, 0], [1.0, 0, 0]])


@pytest.mark.parametrize("n", [1, 2, 3])
def test_recovers_zero_and_direction_from_known_poses(n):
    rng = np.random.default_rng(n)
    zero = np.array([2048.0, 1000.0, 3500.0])[:n]
    direction = np.array([1, -1, -1])[:n]
    ticks = zero + rng.uniform(-700, 700, (10, n))
    poses = chain_forward(AXES[:n], ticks, zero, direction)
    read = np.round(ticks + rng.normal(0, 1.0, ticks.shape))  # encoder noise ~1 tick
    cal = ServoChainCalibration(AXES[:n]).fit(read, poses)
    assert cal.direction_.tolist() == direction.tolist()
    np.testing.assert_allclose(cal.zero_ticks_, zero, atol=3.0)
    assert cal.residual_deg_ < 0.3
    assert cal.to_dict()["direction"] == direction.tolist()


def test_a_joint_that_does_not_move_is_refused():
    ticks = np.array([[2048.0, 2048.0], [2300.0, 2049.0]])
    poses = chain_forward(AXES[:2], ticks, [2048.0, 2048.0], [1, 1])
    with pytest.raises(CalibrationError, match="joint 1"):
        ServoChainCalibration(AXES[:2]).fit(ticks, poses)


def test_non_orthogonal_axes_are_refused():
    with pytest.raises(ValueError, match="orthogonal"):
        ServoChainCalibration([[0, 0, 1.0], [0, 1.0, 1.0]])
