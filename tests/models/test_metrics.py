"""Metrics against hand-computed values on the exact cone oracle."""

from __future__ import annotations

import math

import numpy as np

from models import metrics as M
from models import quaternion as quat
from models.constraint import JointConstraint
from models.datasets import quaternion_dataset
from models.oracle import ConstraintOracle


def _cone(radius_deg):
    return ConstraintOracle(JointConstraint.cone([1, 0, 0], radius_deg))


def test_exact_prediction_scores_zero():
    rng = np.random.default_rng(0)
    oracle = _cone(40)
    q = quaternion_dataset(JointConstraint.cone([1, 0, 0], 40), 400, rng).inputs
    m = M.evaluate(oracle.correction, oracle, q)
    assert m["mse"] < 1e-20 and m["mean_3d_error_pct"] < 1e-6
    assert m["frac_invalid_violating_1deg"] == 0.0 and m["max_violation_deg"] < 1e-6
    assert m["max_identity_error_deg"] < 1e-6
    # sign of the inputs does not matter
    m2 = M.evaluate(oracle.correction, oracle, -q)
    assert m2["mean_3d_error_pct"] < 1e-6


def test_identity_prediction_errors_equal_the_distance_outside():
    oracle = _cone(30)
    # limb at 50 degrees from the centre about Z: 20 degrees outside
    q = quat.from_axis_angle(np.array([[0.0, 0.0, 1.0]]), np.radians([50.0]))
    ident = lambda qq: np.tile(quat.IDENTITY, (len(qq), 1))  # noqa: E731
    m = M.evaluate(ident, oracle, q)
    chord = 2 * math.sin(math.radians(20) / 2)
    assert math.isclose(m["mean_3d_error_pct"], 50 * chord, rel_tol=1e-9)
    assert math.isclose(m["mean_angular_error_deg"], 20.0, rel_tol=1e-9)
    assert math.isclose(m["max_violation_deg"], 20.0, rel_tol=1e-9)
    assert m["frac_invalid_violating_1deg"] == 1.0
    assert m["frac_above_2pct"] == 1.0 and m["frac_above_7_5pct"] == 1.0
    err = M.three_d_error_percent(q, oracle.correction(q), ident(q))
    assert err.shape == (1,)


def test_identity_error_on_valid_inputs():
    oracle = _cone(90)
    q = quat.from_axis_angle(np.array([[0.0, 1.0, 0.0]]), np.radians([10.0]))
    wrong = quat.from_axis_angle(np.array([[1.0, 0.0, 0.0]]), np.radians([3.0]))
    m = M.evaluate(lambda qq: wrong, oracle, q)
    assert math.isclose(m["mean_identity_error_deg"], 3.0, rel_tol=1e-9)
    assert math.isclose(M.mse(wrong, quat.IDENTITY[None]),
                        np.mean((wrong - quat.IDENTITY) ** 2))
