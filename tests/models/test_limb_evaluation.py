"""Held-out limbs, test postures and limb-model metrics (issue 20, part 5)."""

from __future__ import annotations

import numpy as np
import pytest

from models import quaternion as Q
from models.evaluation import evaluate_model
from models.limb_evaluation import (
    HELD_OUT_LIMB_SEED,
    held_out_limbs,
    held_out_postures,
    random_limb,
    uncoupled_model,
)
from models.oracle import ConstraintOracle


@pytest.fixture(scope="module")
def leg():
    limb = random_limb(HELD_OUT_LIMB_SEED - 1, "leg")  # a tuning seed, not a held-out one
    return limb, ConstraintOracle(limb)


def test_held_out_limbs_are_legs_and_arms_with_a_coupling_of_3_or_more_keyframes():
    limbs = held_out_limbs(4)
    assert [lb.limb for lb in limbs.values()] == ["leg", "arm", "leg", "arm"]
    for limb in limbs.values():
        assert [j.kind for j in limb.joints] == ["ball", "hinge", "two-axis"]
        cp = limb.joints[0].coupling
        assert cp.by == limb.joints[1].name and len(cp.keyframes) >= 3
        counts = {len(c.swing.vertices) for c in cp.keyframes}
        assert len(counts) > 1  # keyframe polygons of different vertex counts
    again = held_out_limbs(4)
    assert [lb.content_hash() for lb in again.values()] == \
        [lb.content_hash() for lb in limbs.values()]


def test_postures_are_a_third_valid_and_reproducible(leg):
    limb, oracle = leg
    q = held_out_postures(limb, 900, 3, oracle=oracle)
    assert q.shape == (900, 3, 4)
    np.testing.assert_allclose(np.linalg.norm(q, axis=2), 1.0, atol=1e-12)
    valid = oracle.evaluate(q).limb_valid
    assert valid.mean() >= 1 / 3
    np.testing.assert_array_equal(q, held_out_postures(limb, 900, 3, oracle=oracle))


def test_the_exact_model_scores_zero_and_ignoring_the_coupling_costs(leg):
    limb, oracle = leg
    q = held_out_postures(limb, 1500, 4, oracle=oracle)
    exact = evaluate_model(oracle.correction, limb, q=q, oracle=oracle)
    assert exact["end_mean_3d_error_pct"] < 1e-9 and exact["frac_invalid_violating_1deg"] == 0.0
    assert exact["valid_moved_deg"] < 1e-9 and exact["max_violation_deg"] < 1e-6
    loose = evaluate_model(uncoupled_model(limb), limb, q=q, oracle=oracle)
    # the loosest limits contain every valid posture: nothing valid moves …
    assert loose["valid_moved_deg"] < 1e-9
    # … but many invalid postures are left outside the limits at their knee angle
    assert loose["frac_invalid_violating_1deg"] > 0.2 and loose["end_mean_3d_error_pct"] > 0.5
    assert loose["joint_mean_direction_error_deg"][1:] == pytest.approx([0.0, 0.0], abs=1e-9)


def test_a_model_that_corrects_nothing_is_scored_as_such(leg):
    limb, oracle = leg
    q = held_out_postures(limb, 600, 5, oracle=oracle)
    ident = evaluate_model(lambda x: np.tile(Q.IDENTITY, (*x.shape[:2], 1)), limb, q=q,
                           oracle=oracle)
    invalid = ~oracle.evaluate(q).limb_valid
    assert ident["frac_invalid_violating_1deg"] > 0.9 and invalid.any()
    assert ident["valid_moved_deg"] == 0.0
