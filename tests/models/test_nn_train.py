"""Training pipeline helpers: canonicalisation, overshoot, pattern generation, smoke run."""

from __future__ import annotations

import math

import numpy as np

from models import quaternion as quat
from models.constraint import JointConstraint
from models.nn.config import get_config
from models.nn.train import (
    canonical_reference,
    canonicalise,
    overshoot,
    train_correction,
    training_patterns,
)


def test_canonical_reference_and_sign_rule():
    c = JointConstraint.cone([0, 1, 0], 40)
    ref = canonical_reference(c, "centre")
    np.testing.assert_allclose(quat.limb_direction(ref), [0, 1, 0], atol=1e-12)
    assert canonical_reference(c, "none") is None
    np.testing.assert_array_equal(canonical_reference(c, "w-positive"), quat.IDENTITY)
    q = quat.random_quaternions(100, np.random.default_rng(0))
    a, b = canonicalise(q, ref), canonicalise(-q, ref)
    np.testing.assert_array_equal(a, b)
    assert np.all(a @ ref >= 0)


def test_overshoot_lengthens_only_real_corrections():
    t = np.array([quat.IDENTITY, quat.from_axis_angle(np.array([0.0, 0.0, 1.0]),
                                                      math.radians(10.0))])
    out = overshoot(t, 1.5)
    np.testing.assert_array_equal(out[0], quat.IDENTITY)
    assert math.isclose(math.degrees(quat.angle(out[1])), 11.5, rel_tol=1e-9)
    np.testing.assert_allclose(out[1, 1:] / np.linalg.norm(out[1, 1:]), [0, 0, 1])
    np.testing.assert_array_equal(overshoot(t, 0.0), t)


def test_patterns_are_exact_corrections():
    from models.oracle import ConstraintOracle

    c = JointConstraint.cone([1, 0, 0], 30)
    q, t = training_patterns(c, 200, np.random.default_rng(1))
    oracle = ConstraintOracle(c)
    np.testing.assert_allclose(t, quat.canonical(oracle.correction(q)), atol=1e-12)
    valid = oracle.is_valid(q)
    assert 0.3 < valid.mean() < 0.7  # even distribution: half valid


def test_small_training_run_gives_sane_metrics():
    c = JointConstraint.cone([1, 0, 0], 60)
    cfg = get_config("best", {"evolution": {"population": 3},
                              "training": {"max_epochs": 300, "min_epochs": 300},
                              "data": {"train": 300, "validation": 100, "test": 300}})
    m = train_correction(c, cfg, np.random.default_rng(2))
    assert m.metrics["mean_3d_error_pct"] < 5.0
    assert m.network.n_hidden == 20 and len(m.data_sha256) == 64
    assert m.network.info["hidden_activations"][0] == "leaky_relu"


def test_swing_map_for_swing_constraints_and_fallback_with_twist_limits():
    tiny = {"evolution": {"population": 2},
            "training": {"max_epochs": 30, "min_epochs": 30},
            "data": {"train": 120, "validation": 60, "test": 100}}
    m = train_correction(JointConstraint.cone([1, 0, 0], 50), get_config("best", tiny),
                         np.random.default_rng(3))
    assert m.network.input_map == "swing"
    m = train_correction(JointConstraint.cone([1, 0, 0], 50, twist=(-40, 40)),
                         get_config("best", tiny), np.random.default_rng(3))
    assert m.network.input_map == "canonical" and m.network.canonical_ref is not None
