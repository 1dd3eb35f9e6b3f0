"""models.evaluation (held-out protocol, boundary sets) and the field model it scores."""

from __future__ import annotations

import math

import numpy as np
import pytest

from models import quaternion as quat
from models.constraint import JointConstraint
from models.evaluation import (
    evaluate_model,
    held_out_orientations,
    irregular_boundaries,
    random_star_polygon,
    regular_boundaries,
)
from models.field import FieldModel, grid_directions, node_index
from models.oracle import ConstraintOracle


def test_held_out_orientations_half_near_the_boundary():
    c = JointConstraint.cone([0, 1, 0], 40, twist=(-30, 60))
    o = ConstraintOracle(c)
    q = held_out_orientations(c, 2000, 1, oracle=o)
    assert q.shape == (2000, 4)
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-12)
    near = np.abs(o.signed_distance(q)) <= math.radians(20)
    # the near half plus the uniform draws that happen to fall in the band
    assert 0.5 <= near.mean() <= 0.75
    assert (q[:, 0] < 0).mean() > 0.3  # both quaternion signs
    np.testing.assert_array_equal(q, held_out_orientations(c, 2000, 1, oracle=o))


def test_boundary_sets_are_seeded_concave_and_twisted():
    irr = irregular_boundaries(3, seed=123)
    assert len(irr) == 8 and all(c.twist is not None for c in irr.values())
    again = irregular_boundaries(3, seed=123)
    assert all(irr[k] == again[k] for k in irr)
    star = random_star_polygon(7)
    v = star.swing.vertices
    # concave: some vertex turns the other way (sign of the triple product flips)
    turn = np.einsum("ij,ij->i", np.cross(v - np.roll(v, 1, 0), np.roll(v, -1, 0) - v), v)
    assert (turn > 0).any() and (turn < 0).any()
    assert len(regular_boundaries()) == 18


def test_node_index_finds_the_nearest_node():
    g = 40
    nodes = grid_directions(g)
    d = quat.random_unit_vectors(3000, np.random.default_rng(2))
    got = nodes[node_index(d, g)]
    spacing = math.sqrt(4 * math.pi) / g
    err = quat.angle_between(got, d)
    assert err.max() < 1.5 * spacing and err.mean() < 0.5 * spacing  # map distortion ≤ ~1.6
    k = np.arange(len(nodes)) % (g + 1) ** 2
    u, v = 2 * (k // (g + 1)) / g - 1, 2 * (k % (g + 1)) / g - 1
    inside = np.abs(u) + np.abs(v) <= 1  # nodes outside the diamond only pad the table
    back = nodes[node_index(nodes[inside], g)]  # a node maps to itself (or its equator twin)
    np.testing.assert_allclose(back, nodes[inside], atol=1e-12)


@pytest.mark.parametrize("which", ["original +twist", "star 123"])
def test_field_model_meets_the_targets_on_irregular_boundaries(which):
    c = irregular_boundaries(1, seed=123)[which]
    o = ConstraintOracle(c)
    f = FieldModel.from_constraint(c, grid=200, oracle=o)
    m = evaluate_model(f, c, n=4000, seed=5, oracle=o)
    assert m["mean_3d_error_pct"] < 0.8
    assert m["frac_invalid_violating_1deg"] < 0.01
    assert m["mean_identity_error_deg"] < 0.2
    assert m["p99_angular_error_deg"] < 5.0


def test_field_leaves_valid_orientations_unchanged_and_clamps_twist_exactly():
    c = JointConstraint.cone([1, 0, 0], 50, twist=(-40, 70))
    o = ConstraintOracle(c)
    f = FieldModel.from_constraint(c, grid=100, oracle=o)
    q = quat.random_quaternions(4000, np.random.default_rng(3))
    corr = f.predict(q)
    valid = o.is_valid(q)
    margin = -o.signed_distance(q)
    deep = valid & (margin > math.radians(3))  # farther inside than a node spacing
    np.testing.assert_allclose(np.abs(corr[deep, 0]), 1.0, atol=1e-12)
    corrected = quat.multiply(corr, q)
    phi = np.degrees(quat.twist_angle(corrected))
    assert phi.min() >= -40 - 1e-6 and phi.max() <= 70 + 1e-6
    # twist-only constraint: the limb direction never moves
    t = JointConstraint.from_dict({"name": "t", "twist": {"min_deg": -20, "max_deg": 20}})
    ft = FieldModel.from_constraint(t)
    assert ft.table is None
    out = quat.multiply(ft.predict(q), q)
    np.testing.assert_allclose(quat.limb_direction(out), quat.limb_direction(q), atol=1e-9)
    np.testing.assert_allclose(ConstraintOracle(t).signed_distance(out).clip(0), 0, atol=1e-9)


@pytest.mark.parametrize(("twist_deg", "expected"), [(140.0, 30.0), (160.0, -90.0),
                                                      (-100.0, -90.0), (40.0, 30.0)])
def test_twist_clamps_to_the_nearer_limit_across_the_wrap(twist_deg, expected):
    c = JointConstraint.from_dict({"name": "t", "twist": {"min_deg": -90, "max_deg": 30}})
    f = FieldModel.from_constraint(c)
    q = quat.from_axis_angle([1, 0, 0], math.radians(twist_deg))[None]
    out = quat.multiply(f.predict(q), q)
    assert math.isclose(math.degrees(quat.twist_angle(out)[0]), expected, abs_tol=1e-6)
    np.testing.assert_allclose(ConstraintOracle(c).project(q), out, atol=1e-9)
