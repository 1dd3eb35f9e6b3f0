"""Training pipeline helpers: canonicalisation, overshoot, pattern generation, smoke run."""

from __future__ import annotations

import math

import numpy as np
import pytest

from models import quaternion as quat
from models.constraint import JointConstraint
from models.nn.config import ConfigError, get_config
from models.nn.train import (
    canonical_reference,
    canonicalise,
    centre_frame,
    overshoot,
    target_to_frame,
    to_frame,
    train_correction,
    training_patterns,
)
from models.oracle import ConstraintOracle
from models.shapes import load_shape


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
    assert m.network.n_hidden == cfg["network"]["max_hidden"] == 80 and len(m.data_sha256) == 64
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


def test_frame_config_field():
    assert get_config("best")["network"]["frame"] == "centre"
    assert get_config("thesis")["network"]["frame"] == "parent"
    assert get_config("fixed")["network"]["frame"] == "parent"
    with pytest.raises(ConfigError, match=r"network\.frame"):
        get_config("best", {"network": {"frame": "child"}})


def test_centre_frame_of_cone_and_polygon():
    r = centre_frame(JointConstraint.cone([0, 0, 1], 30))
    np.testing.assert_allclose(quat.limb_direction(r), [0, 0, 1], atol=1e-12)
    shape = load_shape("c-shape")
    oracle = ConstraintOracle(shape)
    d = quat.limb_direction(centre_frame(shape, n_grid=4000))
    assert oracle.is_valid(quat.from_two_vectors(quat.LIMB_AXIS, d)[None])[0]
    # its antipode lies deeper in the invalid region than the interior point's antipode
    depth = [oracle.signed_distance(quat.from_two_vectors(quat.LIMB_AXIS, -v)[None])[0]
             for v in (d, shape.swing.interior)]
    assert depth[0] >= depth[1]


def test_centre_frame_targets_are_the_x_cone_problem():
    """In the centre frame a +Y cone's patterns are exactly those of the same +X cone."""
    rc = centre_frame(JointConstraint.cone([0, 1, 0], 40))
    q = quat.random_quaternions(500, np.random.default_rng(4))
    t = ConstraintOracle(JointConstraint.cone([0, 1, 0], 40)).correction(q)
    tx = ConstraintOracle(JointConstraint.cone([1, 0, 0], 40)).correction(to_frame(q, rc))
    np.testing.assert_allclose(target_to_frame(t, rc), quat.canonical(tx), atol=1e-12)
    # mapping back: R_c ⊗ (t' ⊗ q') = t ⊗ q
    tp = target_to_frame(t, rc)
    back = quat.multiply(np.broadcast_to(rc, q.shape), quat.multiply(tp, to_frame(q, rc)))
    np.testing.assert_allclose(back, quat.multiply(t, q), atol=1e-12)


@pytest.mark.parametrize("twist", [None, (-40, 40)])
def test_centre_frame_network_predicts_parent_frame_corrections(twist):
    tiny = {"evolution": {"population": 2},
            "training": {"max_epochs": 200, "min_epochs": 200},
            "data": {"train": 200, "validation": 60, "test": 200}}
    c = JointConstraint.cone([0, 0, 1], 50, twist=twist)
    m = train_correction(c, get_config("best", tiny), np.random.default_rng(5))
    assert m.network.frame is not None and m.network.info["frame"] == "centre"
    q = quat.random_quaternions(300, np.random.default_rng(6))
    y = m.network.predict(q)
    np.testing.assert_allclose(np.linalg.norm(y, axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(m.network.predict(-q), y, atol=1e-12)
    if twist is None:
        assert m.metrics["mean_3d_error_pct"] < 5.0
