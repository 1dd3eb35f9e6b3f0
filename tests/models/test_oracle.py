"""Property tests of the exact oracle (models.oracle)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from models import quaternion as Q
from models.constraint import JointConstraint
from models.errors import QuaternionError
from models.oracle import BOUNDARY_TOLERANCE, ConstraintOracle, polygon_area_sr

SETTINGS = settings(max_examples=60, deadline=None)


# -- strategies -------------------------------------------------------------------------------
@st.composite
def unit_quaternions(draw):
    v = draw(
        st.tuples(*[st.floats(-1, 1, allow_nan=False) for _ in range(4)]).filter(
            lambda t: math.sqrt(sum(c * c for c in t)) > 1e-3
        )
    )
    q = np.array(v)
    return q / np.linalg.norm(q)


@st.composite
def unit_vectors(draw):
    v = draw(
        st.tuples(*[st.floats(-1, 1, allow_nan=False) for _ in range(3)]).filter(
            lambda t: math.sqrt(sum(c * c for c in t)) > 1e-3
        )
    )
    v = np.array(v)
    return v / np.linalg.norm(v)


def star_polygon(centre, radii_deg, phase=0.0):
    """Vertices of a star-shaped spherical polygon around ``centre`` (simple by construction:
    straight lines in the gnomonic chart are great circles, angular gaps < 180°)."""
    m = len(radii_deg)
    th = phase + np.linspace(0.0, 2 * np.pi, m, endpoint=False)
    r = np.tan(np.radians(radii_deg))
    local = np.stack([np.ones(m), r * np.cos(th), r * np.sin(th)], axis=1)
    local /= np.linalg.norm(local, axis=1, keepdims=True)
    rot = Q.from_two_vectors(np.array([1.0, 0, 0]), np.asarray(centre, float))
    return Q.rotate(rot, local)


@st.composite
def polygon_constraints(draw):
    centre = draw(unit_vectors())
    m = draw(st.integers(3, 40))
    radii = draw(st.lists(st.floats(5, 80), min_size=m, max_size=m))
    phase = draw(st.floats(0, 2 * np.pi))
    verts = star_polygon(centre, radii, phase)
    # half the time the valid region is the complement (more than a hemisphere)
    interior = centre if draw(st.booleans()) else -centre
    twist = draw(st.none() | st.tuples(st.floats(-170, 0), st.floats(0, 170)))
    return JointConstraint.polygon(verts, interior, twist=twist)


@st.composite
def cone_constraints(draw, with_twist=True):
    centre = draw(unit_vectors())
    radius = draw(st.floats(1, 179))
    twist = (
        draw(st.none() | st.tuples(st.floats(-170, 0), st.floats(0, 170))) if with_twist else None
    )
    return JointConstraint.cone(centre, radius, twist=twist)


any_constraint = st.one_of(cone_constraints(), polygon_constraints())


def same_rotation(p, q, atol=1e-9):
    return min(np.abs(p - q).max(), np.abs(p + q).max()) <= atol


# -- the properties the issue names -------------------------------------------------------------
@SETTINGS
@given(any_constraint, st.lists(unit_quaternions(), min_size=1, max_size=20))
def test_projection_is_valid_and_idempotent(constraint, qs):
    o = ConstraintOracle(constraint)
    q = np.array(qs)
    p = o.project(q)
    assert o.is_valid(p).all()
    np.testing.assert_allclose(o.project(p), p, atol=1e-9)


@SETTINGS
@given(any_constraint, st.lists(unit_quaternions(), min_size=1, max_size=20))
def test_valid_orientations_project_to_themselves(constraint, qs):
    o = ConstraintOracle(constraint)
    q = np.array(qs)
    r = o.evaluate(q)
    np.testing.assert_allclose(r.projected[r.valid], q[r.valid], rtol=0, atol=1e-15)
    np.testing.assert_array_equal(r.correction[r.valid], np.tile(Q.IDENTITY, (r.valid.sum(), 1)))
    assert (r.distance[r.valid] <= 0).all() and (r.distance[~r.valid] > 0).all()


@SETTINGS
@given(
    st.one_of(cone_constraints(with_twist=False), polygon_constraints()),
    st.lists(unit_quaternions(), min_size=1, max_size=20),
)
def test_correction_angle_equals_swing_distance(constraint, qs):
    if constraint.twist is not None:
        constraint = JointConstraint(name="s", swing=constraint.swing)
    o = ConstraintOracle(constraint)
    q = np.array(qs)
    r = o.evaluate(q)
    d = Q.rotate(q, Q.LIMB_AXIS)
    swing = o.swing_distance(d)
    out = swing > BOUNDARY_TOLERANCE
    np.testing.assert_allclose(Q.angle(r.correction[out]), swing[out], atol=1e-9)
    np.testing.assert_allclose(r.distance, np.where(out, swing, swing), atol=1e-9)


@SETTINGS
@given(any_constraint, st.lists(unit_quaternions(), min_size=1, max_size=20))
def test_q_and_minus_q_agree(constraint, qs):
    o = ConstraintOracle(constraint)
    q = np.array(qs)
    a, b = o.evaluate(q), o.evaluate(-q)
    np.testing.assert_array_equal(a.valid, b.valid)
    np.testing.assert_allclose(a.distance, b.distance, atol=1e-12)
    np.testing.assert_allclose(a.correction, b.correction, atol=1e-12)
    np.testing.assert_allclose(a.projected, -b.projected, atol=1e-12)  # sign follows input


@SETTINGS
@given(st.lists(unit_vectors(), min_size=1, max_size=30), unit_vectors(), st.floats(1, 179))
def test_cone_matches_thesis_closed_form(vs, centre, radius_deg):
    """Thesis eq. 59-68 for twist-free inputs: Qi = rotation X->V, Qo rotates P towards C."""
    V = np.array(vs)
    X = np.array([1.0, 0.0, 0.0])
    Qi = Q.from_two_vectors(X, V)  # eq. 59-60: angle acos(V·X), axis X × V
    P = Q.rotate(Qi, X)  # eq. 61
    theta = Q.angle_between(P, centre)  # eq. 62
    rmax = math.radians(radius_deg)
    o = ConstraintOracle(JointConstraint.cone(centre, radius_deg))
    corr = o.correction(Qi)
    for i in range(len(V)):
        if theta[i] <= rmax:  # eq. 63: valid -> identity
            assert np.array_equal(corr[i], Q.IDENTITY)
            continue
        axis = np.cross(P[i], centre)
        n = np.linalg.norm(axis)
        if n < 1e-6:  # exactly opposite the centre: every direction is a nearest one
            continue
        dtheta = theta[i] - rmax  # eq. 64
        expected = Q.from_axis_angle(axis / n, dtheta)  # eq. 65-68
        assert same_rotation(corr[i], expected, atol=1e-9)


@pytest.mark.parametrize("radius_deg", [10.0, 45.0, 120.0])
def test_cone_and_360_vertex_polygon_agree_within_sagitta(radius_deg):
    rng = np.random.default_rng(7)
    centre = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    verts = star_polygon(centre, np.full(360, radius_deg))
    cone = ConstraintOracle(JointConstraint.cone(centre, radius_deg))
    poly = ConstraintOracle(JointConstraint.polygon(verts, centre))
    # sagitta: how far an edge's midpoint sags inside the circle
    mid = verts[0] + verts[1]
    mid /= np.linalg.norm(mid)
    sagitta = math.radians(radius_deg) - Q.angle_between(mid, centre)
    d = Q.random_unit_vectors(5000, rng)
    diff = np.abs(cone.swing_distance(d) - poly.swing_distance(d))
    assert sagitta > 0
    assert diff.max() <= sagitta + 1e-9
    q = Q.random_quaternions(5000, rng)
    a, b = cone.evaluate(q), poly.evaluate(q)
    limb_a = Q.rotate(a.projected, Q.LIMB_AXIS)
    limb_b = Q.rotate(b.projected, Q.LIMB_AXIS)
    far = (
        np.abs(cone.swing_distance(Q.rotate(q, Q.LIMB_AXIS)) - math.pi + math.radians(radius_deg))
        > 0.05
    )
    # away from the correctional discontinuity the corrected limbs agree to within half an edge
    # (outside a polygon's convex vertex every nearest point is the vertex itself)
    half_edge = Q.angle_between(verts[0], verts[1]) / 2
    assert Q.angle_between(limb_a[far], limb_b[far]).max() <= half_edge + sagitta + 1e-9


# -- polygon machinery against independent references -----------------------------------------
def crossing_inside(verts, interior, p):
    """Reference inside test: parity of boundary crossings of the arc interior->p."""
    n = len(verts)
    inside = np.ones(len(p), dtype=bool)
    for i in range(n):
        a, b = verts[i], verts[(i + 1) % n]
        na = np.cross(a, b)
        na /= np.linalg.norm(na)
        nb = np.cross(interior, p)
        nb /= np.linalg.norm(nb, axis=1, keepdims=True)
        x = np.cross(na, nb)
        x /= np.linalg.norm(x, axis=1, keepdims=True)
        for s in (1.0, -1.0):
            y = s * x
            on_edge = (np.cross(a, y) @ na >= 0) & (np.einsum("ij,j->i", np.cross(y, b), na) >= 0)
            on_path = (
                np.einsum("ij,ij->i", np.cross(np.broadcast_to(interior, p.shape), y), nb) >= 0
            ) & (np.einsum("ij,ij->i", np.cross(y, p), nb) >= 0)
            inside ^= on_edge & on_path
    return inside


@pytest.mark.parametrize("seed", range(4))
def test_polygon_inside_matches_crossing_parity(seed):
    rng = np.random.default_rng(seed)
    centre = Q.random_unit_vectors(1, rng)[0]
    radii = rng.uniform(10, 80, size=rng.integers(5, 60))
    verts = star_polygon(centre, radii)
    for interior in (centre, -centre):
        o = ConstraintOracle(JointConstraint.polygon(verts, interior))
        p = Q.random_unit_vectors(4000, rng)
        dist = o.swing_distance(p)
        clear = np.abs(dist) > 1e-6
        ref = crossing_inside(verts, interior, p)
        np.testing.assert_array_equal((dist <= 0)[clear], ref[clear])


@pytest.mark.parametrize("seed", range(3))
def test_polygon_grid_search_equals_brute_force(seed):
    rng = np.random.default_rng(100 + seed)
    th = np.linspace(0, 2 * np.pi, 300, endpoint=False)
    radii = 45 + 25 * np.sin(3 * th + seed) + rng.uniform(-3, 3, size=300)
    verts = star_polygon(Q.random_unit_vectors(1, rng)[0], radii)
    o = ConstraintOracle(JointConstraint.polygon(verts, verts.mean(axis=0)))
    solver = o._swing
    p = Q.random_unit_vectors(5000, rng)
    fast_d, fast_b = solver.nearest(p)
    ref_d, ref_b = solver._brute(p, need_point=True)
    np.testing.assert_array_equal(fast_d, ref_d)
    np.testing.assert_array_equal(fast_b, ref_b)


def test_polygon_nearest_point_is_on_the_boundary_and_nearest():
    rng = np.random.default_rng(5)
    verts = star_polygon([0, 0, 1], [40, 15, 60, 30, 55, 20, 50])  # concave
    o = ConstraintOracle(JointConstraint.polygon(verts, [0, 0, 1]))
    p = Q.random_unit_vectors(3000, rng)
    b = o.nearest_swing_point(p)
    out = o.swing_distance(p) > 1e-9
    np.testing.assert_allclose(o.swing_distance(b[out]), 0.0, atol=1e-9)
    # no densely sampled boundary point is nearer than the reported one
    t = np.linspace(0, 1, 400)[:, None, None]
    a0, a1 = verts, np.roll(verts, -1, axis=0)
    dense = ((1 - t) * a0 + t * a1).reshape(-1, 3)
    dense /= np.linalg.norm(dense, axis=1, keepdims=True)
    reported = Q.angle_between(p[out], b[out])
    best = np.min(np.arccos(np.clip(p[out] @ dense.T, -1, 1)), axis=1)
    assert (reported <= best + 1e-9).all()


def test_polygon_area_matches_cone_and_complement():
    centre = np.array([0.0, 1.0, 0.0])
    verts = star_polygon(centre, np.full(720, 60.0))
    inner = JointConstraint.polygon(verts, centre).swing
    outer = JointConstraint.polygon(verts, -centre).swing
    cap = 2 * math.pi * (1 - math.cos(math.radians(60)))
    assert polygon_area_sr(inner) == pytest.approx(cap, rel=1e-3)
    assert polygon_area_sr(outer) == pytest.approx(4 * math.pi - cap, rel=1e-3)


# -- twist -------------------------------------------------------------------------------------
def test_twist_is_clamped_to_the_nearer_limit_and_swing_kept():
    o = ConstraintOracle(JointConstraint.cone([1, 0, 0], 90, twist=(-30, 45)))
    for phi_deg, expect in [(60, 45), (-50, -30), (170, 45), (-170, -30), (10, 10)]:
        q = Q.from_axis_angle(np.array([1.0, 0, 0]), math.radians(phi_deg))
        p = o.project(q)
        assert math.degrees(Q.twist_angle(p)) == pytest.approx(expect, abs=1e-9)
        np.testing.assert_allclose(Q.rotate(p, Q.LIMB_AXIS), [1, 0, 0], atol=1e-12)
    # exactly half-way round: documented to go to max
    mid = math.radians((-30 + 45) / 2 + 180)
    p = o.project(Q.from_axis_angle(np.array([1.0, 0, 0]), mid))
    assert math.degrees(Q.twist_angle(p)) == pytest.approx(45, abs=1e-6)


def test_swing_and_twist_violations_together():
    o = ConstraintOracle(JointConstraint.cone([1, 0, 0], 30, twist=(-10, 10)))
    rng = np.random.default_rng(2)
    q = Q.random_quaternions(5000, rng)
    r = o.evaluate(q)
    assert o.is_valid(r.projected).all()
    np.testing.assert_array_equal(o.is_valid(q), r.valid)
    limb = Q.rotate(r.projected, Q.LIMB_AXIS)
    assert (Q.angle_between(limb, [1, 0, 0]) <= math.radians(30) + 1e-9).all()
    tw = np.degrees(Q.twist_angle(r.projected))
    assert (tw >= -10 - 1e-7).all() and (tw <= 10 + 1e-7).all()


def test_twist_only_constraint():
    c = JointConstraint.from_dict({"name": "forearm", "twist": {"min_deg": -80, "max_deg": 80}})
    o = ConstraintOracle(c)
    rng = np.random.default_rng(3)
    q = Q.random_quaternions(2000, rng)
    tw = np.degrees(Q.twist_angle(q))
    np.testing.assert_array_equal(o.is_valid(q), np.abs(tw) <= 80)


# -- determinism at discontinuities ------------------------------------------------------------
def test_cone_antipode_resolves_deterministically():
    o = ConstraintOracle(JointConstraint.cone([1, 0, 0], 40))
    q = Q.from_axis_angle(np.array([0.0, 0, 1]), math.pi)  # limb points to -X
    a = o.project(q)
    b = o.project(q.copy())
    np.testing.assert_array_equal(a, b)
    limb = Q.rotate(a, Q.LIMB_AXIS)
    assert Q.angle_between(limb, [1, 0, 0]) == pytest.approx(math.radians(40), abs=1e-9)
    # the documented axis: centre × (basis axis least aligned with the centre) -> rotation in x-z
    assert abs(limb[1]) < 1e-12


def test_polygon_equidistant_point_takes_lowest_edge():
    verts = star_polygon([1, 0, 0], np.full(4, 30.0))
    o = ConstraintOracle(JointConstraint.polygon(verts, [1, 0, 0]))
    # -X is equidistant from all four edges (by symmetry) -> edge 0 wins
    p = np.array([[-1.0, 0.0, 0.0]])
    b = o.nearest_swing_point(p)
    solver = o._swing
    d_edge0 = solver._pair_keys(p, np.array([0]))[0][0]
    d_found = np.sum((p - b) ** 2)
    assert d_found == pytest.approx(d_edge0, abs=1e-12)


# -- single-orientation path -------------------------------------------------------------------
@SETTINGS
@given(any_constraint, unit_quaternions())
def test_scalar_path_equals_batch_path(constraint, q):
    o = ConstraintOracle(constraint)
    one = o.evaluate(q)
    many = o.evaluate(q[None, :])
    assert bool(one.valid) == bool(many.valid[0])
    np.testing.assert_allclose(one.distance, many.distance[0], atol=1e-12)
    np.testing.assert_allclose(one.projected, many.projected[0], atol=1e-12)
    np.testing.assert_allclose(one.correction, many.correction[0], atol=1e-12)


# -- bad input ---------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "q, message",
    [
        ([np.nan, 0, 0, 1], "NaN"),
        ([np.inf, 0, 0, 0], "NaN or infinite"),
        ([0, 0, 0, 0], "zero norm"),
        ([2, 0, 0, 0], "not a unit quaternion"),
        ([1, 0, 0], "shape"),
        ([[1, 0, 0, 0], [0, 0, 0, 0]], r"orientation\[1\] has zero norm"),
    ],
)
def test_bad_quaternions_are_rejected_with_a_clear_message(q, message):
    o = ConstraintOracle(JointConstraint.cone([1, 0, 0], 45))
    with pytest.raises(QuaternionError, match=message):
        o.evaluate(np.asarray(q, dtype=float))
    with pytest.raises(QuaternionError):
        o.is_valid(np.asarray(q, dtype=float))


def test_normalisation_only_when_asked():
    o = ConstraintOracle(JointConstraint.cone([1, 0, 0], 45))
    q = np.array([2.0, 0, 0, 0])
    assert o.is_valid(q, normalize=True)
    np.testing.assert_allclose(o.project(q, normalize=True), [1, 0, 0, 0])
