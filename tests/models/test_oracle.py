"""Property tests of the exact oracle (models.oracle)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from models import quaternion as Q
from models.constraint import JointConstraint
from models.errors import QuaternionError
from models.kinds.base import BOUNDARY_TOLERANCE
from models.oracle import ConstraintOracle

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


#: constant twist ranges that touch ±180° (the wrap-around cases of issue 9 item 3)
EDGE_TWISTS = [(-90.0, 180.0), (-180.0, -170.0), (-180.0, 90.0), (170.0, 180.0), (-180.0, 180.0)]


@st.composite
def twist_tables(draw):
    """A ``twist:`` mapping with a ``by_swing`` table (envelope = hull of the points)."""
    k = draw(st.integers(1, 12))
    points = []
    for _ in range(k):
        lo = draw(st.floats(-180, 60))
        hi = draw(st.floats(lo, 180))
        points.append({"direction": draw(unit_vectors()).tolist(), "min_deg": lo, "max_deg": hi})
    if draw(st.booleans()):  # some tables reach the ±180° wrap
        points[0]["min_deg"], points[-1]["max_deg"] = -180.0, 180.0
    return {
        "min_deg": min(p["min_deg"] for p in points),
        "max_deg": max(p["max_deg"] for p in points),
        "by_swing": {"bandwidth_deg": draw(st.floats(5, 120)), "points": points},
    }


def twists():
    return (
        st.none()
        | st.tuples(st.floats(-170, 0), st.floats(0, 170))
        | st.sampled_from(EDGE_TWISTS)
        | twist_tables()
    )


@st.composite
def polygon_constraints(draw):
    centre = draw(unit_vectors())
    m = draw(st.integers(3, 40))
    radii = draw(st.lists(st.floats(5, 80), min_size=m, max_size=m))
    phase = draw(st.floats(0, 2 * np.pi))
    verts = star_polygon(centre, radii, phase)
    # half the time the valid region is the complement (more than a hemisphere)
    interior = centre if draw(st.booleans()) else -centre
    return JointConstraint.polygon(verts, interior, twist=draw(twists()))


@st.composite
def cone_constraints(draw, with_twist=True):
    centre = draw(unit_vectors())
    radius = draw(st.floats(1, 179))
    twist = draw(twists()) if with_twist else None
    return JointConstraint.cone(centre, radius, twist=twist)


@st.composite
def twist_only_constraints(draw):
    twist = draw(twists().filter(lambda t: t is not None))
    if isinstance(twist, tuple):
        twist = {"min_deg": twist[0], "max_deg": twist[1]}
    return JointConstraint.from_dict({"name": "twist-only", "twist": twist})


any_constraint = st.one_of(cone_constraints(), polygon_constraints(), twist_only_constraints())


@st.composite
def half_turn_quaternions(draw):
    """Orientations whose twist about +X is exactly half a turn (w = 0 exactly), either sign."""
    sy, sz = draw(st.floats(-1, 1)), draw(st.floats(-1, 1))
    c = draw(st.floats(0.01, 1))
    n = math.sqrt(c * c + sy * sy + sz * sz)
    w, y, z = c / n, sy / n, sz / n
    q = np.array([0.0, w, z, -y])  # (w, 0, y, z) ⊗ (0, 1, 0, 0), computed exactly
    return -q if draw(st.booleans()) else q


orientations = unit_quaternions() | half_turn_quaternions()


def same_rotation(p, q, atol=1e-9):
    return min(np.abs(p - q).max(), np.abs(p + q).max()) <= atol


def assert_same_correction(a, b, atol=1e-12):
    """Corrections ``a``, ``b`` (4,) are equal to ``atol``, and both keep the contract ``w >= 0``.

    A correction is a rotation returned as its ``w >= 0`` representative. For a half turn
    (``w`` zero up to rounding) that representative is not determined: two computations that
    round ``w`` to ``+1e-17`` and ``-0.0`` return ``c`` and ``-c`` (the same rotation). Only
    there is the other sign accepted; everywhere else this is the plain element-wise check.
    """
    assert a[0] >= 0.0 and b[0] >= 0.0
    if max(a[0], b[0]) <= atol and np.dot(a, b) < 0.0:
        b = -b
    np.testing.assert_allclose(a, b, atol=atol)


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


# -- swing-dependent twist (twist.by_swing) ------------------------------------------------------
def table_constraint(swing="cone", bandwidth=30.0):
    """Twist wide open towards +Y, narrow towards -Y and +Z."""
    twist = {
        "min_deg": -80,
        "max_deg": 80,
        "by_swing": {
            "bandwidth_deg": bandwidth,
            "points": [
                {"direction": [0, 1, 0], "min_deg": -80, "max_deg": 80},
                {"direction": [0, -1, 0], "min_deg": -5, "max_deg": 5},
                {"direction": [0, 0, 1], "min_deg": -20, "max_deg": 0},
                {"direction": [1, 0, 0], "min_deg": -40, "max_deg": 30},
            ],
        },
    }
    if swing == "cone":
        return JointConstraint.cone([1, 0, 0], 60, twist=twist)
    verts = star_polygon([1, 0, 0], [60, 30, 65, 45, 55, 25, 60, 50])
    return JointConstraint.polygon(verts, [1, 0, 0], twist=twist)


@pytest.mark.parametrize("swing", ["cone", "polygon"])
def test_twist_is_clamped_to_the_limits_at_the_corrected_direction(swing):
    c = table_constraint(swing)
    o = ConstraintOracle(c)
    rng = np.random.default_rng(4)
    q = Q.random_quaternions(20000, rng)
    r = o.evaluate(q)
    e = Q.rotate(r.projected, Q.LIMB_AXIS)
    lo, hi = o.twist_limits_at(e)
    phi = Q.twist_angle(r.projected)
    assert ((phi >= lo - 1e-9) & (phi <= hi + 1e-9)).all()
    assert o.is_valid(r.projected).all()
    np.testing.assert_allclose(o.project(r.projected), r.projected, atol=1e-9)
    # the swing correction alone fixes the direction: the twist clamp never moves the limb
    swing_only = ConstraintOracle(JointConstraint(name="s", swing=c.swing))
    np.testing.assert_allclose(e, Q.rotate(swing_only.project(q), Q.LIMB_AXIS), atol=1e-12)
    # a clamped twist sits exactly on the limit of the corrected direction
    clamped = ~r.valid & (np.abs(phi - lo) > 1e-9) & (np.abs(phi - hi) > 1e-9)
    tw_in = Q.twist_angle(q)
    lo_in, hi_in = o.twist_limits_at(Q.rotate(q, Q.LIMB_AXIS))
    swing_ok = o.swing_distance(Q.rotate(q, Q.LIMB_AXIS)) <= BOUNDARY_TOLERANCE
    assert not (clamped & swing_ok & ((tw_in < lo_in) | (tw_in > hi_in))).any()
    # validity of the input uses the limits at its own direction
    inside_tw = (tw_in >= lo_in - 1e-9) & (tw_in <= hi_in + 1e-9)
    np.testing.assert_array_equal(r.valid, swing_ok & inside_tw)


def test_limits_at_the_corrected_not_the_input_direction():
    o = ConstraintOracle(table_constraint("cone"))
    # limb beyond the 60° cone towards -Y (narrow twist there), twist 60°
    d = np.array([math.cos(math.radians(100)), -math.sin(math.radians(100)), 0.0])
    swing = Q.from_two_vectors(np.array([1.0, 0, 0]), d)
    q = Q.multiply(swing, Q.from_axis_angle(np.array([1.0, 0, 0]), math.radians(60)))
    p = o.project(q)
    e = Q.rotate(p, Q.LIMB_AXIS)
    assert Q.angle_between(e, [1, 0, 0]) == pytest.approx(math.radians(60), abs=1e-9)
    _, hi_e = o.twist_limits_at(e)
    _, hi_d = o.twist_limits_at(d)
    assert abs(hi_e - hi_d) > math.radians(1)  # the two directions' limits really differ
    assert Q.twist_angle(p) == pytest.approx(hi_e, abs=1e-9)
    np.testing.assert_allclose(o.project(q[None, :])[0], p, atol=1e-12)


def test_a_uniform_table_behaves_like_a_constant_twist():
    rng = np.random.default_rng(8)
    dirs = Q.random_unit_vectors(7, rng)
    table = {
        "min_deg": -35,
        "max_deg": 50,
        "by_swing": {
            "bandwidth_deg": 25,
            "points": [{"direction": d.tolist(), "min_deg": -35, "max_deg": 50} for d in dirs],
        },
    }
    verts = star_polygon([0, 0, 1], [40, 15, 60, 30, 55, 20, 50])
    a = ConstraintOracle(JointConstraint.polygon(verts, [0, 0, 1], twist=table))
    b = ConstraintOracle(JointConstraint.polygon(verts, [0, 0, 1], twist=(-35, 50)))
    q = Q.random_quaternions(5000, rng)
    ra, rb = a.evaluate(q), b.evaluate(q)
    np.testing.assert_array_equal(ra.valid, rb.valid)
    np.testing.assert_allclose(ra.projected, rb.projected, atol=1e-12)
    np.testing.assert_allclose(ra.distance, rb.distance, atol=1e-12)
    lo, hi = a.twist_limits_at(Q.random_unit_vectors(100, rng))
    np.testing.assert_allclose(lo, math.radians(-35), atol=1e-14)
    np.testing.assert_allclose(hi, math.radians(50), atol=1e-14)


def test_twist_only_constraint_with_a_table():
    c = JointConstraint.from_dict({"name": "forearm", "twist": table_constraint().twist.to_dict()})
    o = ConstraintOracle(c)
    rng = np.random.default_rng(3)
    q = Q.random_quaternions(3000, rng)
    lo, hi = o.twist_limits_at(Q.rotate(q, Q.LIMB_AXIS))
    tw = Q.twist_angle(q)
    np.testing.assert_array_equal(o.is_valid(q), (tw >= lo - 1e-9) & (tw <= hi + 1e-9))
    np.testing.assert_allclose(
        Q.rotate(o.project(q), Q.LIMB_AXIS), Q.rotate(q, Q.LIMB_AXIS), atol=1e-12
    )


def test_twist_limits_at_checks_directions_and_handles_no_twist():
    o = ConstraintOracle(JointConstraint.cone([1, 0, 0], 40))
    lo, hi = o.twist_limits_at(np.array([[1.0, 0, 0], [0, 2.0, 0]]))
    np.testing.assert_array_equal(lo, [-math.pi] * 2)
    np.testing.assert_array_equal(hi, [math.pi] * 2)
    with pytest.raises(QuaternionError, match="zero length"):
        o.twist_limits_at(np.zeros(3))


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


# -- single-orientation path -------------------------------------------------------------------
#: a twist pinned to 0° and a half-turn twist: the correction is a half turn, whose w the two
#: paths round to +5.6e-17 and -0.0 (the example that once failed and was replayed forever)
HALF_TURN_CORRECTION = (
    JointConstraint.from_dict({"name": "pinned", "twist": {"min_deg": 0.0, "max_deg": 0.0}}),
    np.array([0.0, 0.408248290463863, 0.816496580927726, -0.408248290463863]),
)


@settings(max_examples=150, deadline=None)
@given(any_constraint, orientations)
@example(*HALF_TURN_CORRECTION)
def test_scalar_path_equals_batch_path(constraint, q):
    """Cones, polygons and twist-only; constant, ±180°-touching and swing-dependent twist;
    orientations with a twist of exactly ±π among them, and corrections of exactly half a turn."""
    o = ConstraintOracle(constraint)
    one = o.evaluate(q)
    many = o.evaluate(q[None, :])
    assert bool(one.valid) == bool(many.valid[0])
    assert bool(o.is_valid(q)) == bool(o.is_valid(q[None, :])[0]) == bool(one.valid)
    np.testing.assert_allclose(one.distance, many.distance[0], atol=1e-12)
    np.testing.assert_allclose(one.projected, many.projected[0], atol=1e-12)  # the input's sign
    assert_same_correction(one.correction, many.correction[0])  # a rotation, w >= 0
    np.testing.assert_allclose(one.twist, many.twist[0], atol=1e-12)
    for single in (o.project(q), o.correction(q), o.signed_distance(q)):
        assert np.shape(single) in ((4,), ())


@settings(max_examples=100, deadline=None)
@given(any_constraint, orientations, st.floats(0.5, 2.0))
def test_the_control_loops_query_is_evaluate_in_plain_floats(constraint, q, scale):
    """``distance_projected_one`` (the supervisor's query, compiled) answers what
    ``evaluate`` does, for unnormalised input too; a NaN is refused as ``evaluate`` refuses it."""
    o = ConstraintOracle(constraint)
    d, p = o.distance_projected_one(*(float(v) * scale for v in q))
    one = o.evaluate(q)
    assert isinstance(d, float) and len(p) == 4 and all(isinstance(v, float) for v in p)
    assert d == pytest.approx(float(one.distance), abs=1e-12)
    np.testing.assert_allclose(p, one.projected, rtol=0, atol=1e-12)
    with pytest.raises(QuaternionError):
        o.distance_projected_one(math.nan, 0.0, 0.0, 0.0)


@pytest.mark.parametrize("twist", EDGE_TWISTS)
@pytest.mark.parametrize("q", [(0.0, 1.0, 0.0, 0.0), (-0.0, -1.0, 0.0, 0.0)])
def test_half_turn_twist_is_inside_ranges_reaching_180(twist, q):
    """Issue 9 item 3: twist range (-90°, 180°) and q = (0, 1, 0, 0) were valid in the batch
    path and invalid in the single path. A twist of ±π is inside any range reaching ±180°."""
    q = np.array(q)
    for c in (
        JointConstraint.cone([1, 0, 0], 30, twist=twist),
        JointConstraint.polygon(star_polygon([1, 0, 0], [30, 40, 35, 20]), [1, 0, 0], twist=twist),
    ):
        o = ConstraintOracle(c)
        assert o.is_valid(q) and o.is_valid(q[None, :])[0]
        assert o.evaluate(q).valid and o.evaluate(q[None, :]).valid[0]
        assert o.signed_distance(q) == pytest.approx(0.0, abs=1e-12)  # on the twist limit
        np.testing.assert_array_equal(o.correction(q), Q.IDENTITY)


def test_half_turn_twist_outside_is_clamped_the_same_on_both_paths():
    o = ConstraintOracle(JointConstraint.cone([1, 0, 0], 30, twist=(-30, 45)))
    q = np.array([0.0, 1.0, 0.0, 0.0])  # twist π: 135° from max, 150° from min
    one, many = o.project(q), o.project(q[None, :])[0]
    np.testing.assert_allclose(one, many, atol=1e-15)
    assert math.degrees(Q.twist_angle(one)) == pytest.approx(45.0, abs=1e-9)
    assert not o.is_valid(q) and not o.is_valid(q[None, :])[0]


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


@pytest.mark.parametrize("twist", [(-180.0, -170.0), (10.0, 20.0)])
def test_twist_is_not_limited_where_it_is_undefined(twist):
    """Limb exactly opposite its axis (q = half turn about z): no twist is defined and no
    rotation about the axis changes that, so the twist limit does not apply there."""
    q = np.array([0.0, 0.0, 0.0, 1.0])
    twist_only = ConstraintOracle(
        JointConstraint.from_dict({"twist": {"min_deg": twist[0], "max_deg": twist[1]}})
    )
    for qq in (q, q[None, :]):
        assert np.all(twist_only.is_valid(qq))
        np.testing.assert_array_equal(twist_only.project(qq), qq)
        assert np.all(twist_only.signed_distance(qq) == 0.0)
    # with a swing limit that excludes -X the swing is corrected and the twist then clamped
    o = ConstraintOracle(JointConstraint.cone([1, 0, 0], 120, twist=twist))
    one, many = o.project(q), o.project(q[None, :])[0]
    np.testing.assert_allclose(one, many, atol=1e-12)
    assert o.is_valid(one) and not o.is_valid(q)
    limb = Q.rotate(one, Q.LIMB_AXIS)
    assert math.degrees(Q.angle_between(limb, [1, 0, 0])) == pytest.approx(120, abs=1e-9)
    tw = math.degrees(Q.twist_angle(one))
    assert twist[0] - 1e-9 <= tw <= twist[1] + 1e-9 or (twist[0] == -180 and tw == 180)


# -- one oracle for a joint and a limb (issue 38) -----------------------------------------------
ONE_JOINT_LIMITS = {
    "ball": {"swing": {"cone": {"centre": [0.6, 0.8, 0.0], "radius_deg": 50}},
             "twist": {"min_deg": -40, "max_deg": 70}},
    "hinge": {"kind": "hinge", "hinge": {"axis": [0, 0, 1], "min_deg": 5, "max_deg": 140}},
    "two-axis": {"kind": "two-axis", "swing": {"cone": {"centre": [0, -1, 0.2],
                                                          "radius_deg": 30}},
                 "twist": {"min_deg": -5, "max_deg": 5}},
    "forearm": {"kind": "forearm", "forearm": {
        "flexion": {"axis": [0, 0, 1], "min_deg": 0, "max_deg": 145},
        "rotation": {"min_deg": -80, "max_deg": 70}}},
}


@pytest.mark.parametrize("kind", sorted(ONE_JOINT_LIMITS))
def test_a_limb_of_one_joint_answers_as_its_joint_bit_for_bit(kind):
    """A one-joint constraint is a limb of one joint: the oracle built from a limb file of that
    joint gives the joint's answers on postures (N, 1, 4), bit for bit (on the same unit
    orientations)."""
    from models.limb import Limb

    body = ONE_JOINT_LIMITS[kind]
    joint = ConstraintOracle(JointConstraint.from_dict(body))
    limb = ConstraintOracle(Limb.from_dict({"name": "one", "joints": [
        {"name": "elbow", "parent": "upper-arm", "child": "forearm", "constraint": body}]}))
    assert (joint.n_joints, limb.n_joints) == (1, 1) and limb.constraint is None
    np.testing.assert_array_equal(joint.axes, limb.axes)
    q = Q.random_quaternions(2000, np.random.default_rng(38))
    # a limb's postures are checked (made unit) once as postures, then once per joint as one
    # joint's orientations are: the joint compared on the postures' check (the same rounding)
    a, b = joint.evaluate(Q.check_quaternions(q)), limb.evaluate(q[:, None])
    for name in ("valid", "distance", "projected", "correction"):
        assert getattr(a, name).tobytes() == getattr(b, name)[:, 0].tobytes(), name
    assert np.isnan(b.coupling_angle).all()
    one = limb.evaluate(q[7][None])  # one posture (J, 4)
    assert one.projected.shape == (1, 4) and one.projected.tobytes() == a.projected[7].tobytes()
    assert joint.joint_is_valid(q, 0).tobytes() == limb.joint_is_valid(q[:, None], 0).tobytes()
    np.testing.assert_array_equal(joint.end_points(q), limb.end_points(q[:, None]))
    assert limb.prepare() is limb and joint.prepare() is joint


def test_a_limbs_oracle_refuses_one_joints_queries_and_shapes():
    from models.limb import Limb

    limb = ConstraintOracle(Limb.from_dict({"name": "one", "joints": [
        {"name": "elbow", "parent": "upper-arm", "child": "forearm",
         "constraint": ONE_JOINT_LIMITS["hinge"]}]}))
    for call in (lambda: limb.distance_projected_one(1.0, 0.0, 0.0, 0.0),
                 lambda: limb.swing_distance([1.0, 0.0, 0.0]),
                 lambda: limb.nearest_swing_point([1.0, 0.0, 0.0]),
                 lambda: limb.twist_limits_at([1.0, 0.0, 0.0])):
        with pytest.raises(TypeError, match="a limb's oracle answers postures"):
            call()
    with pytest.raises(QuaternionError, match=r"expected shape \(N, 1, 4\)"):
        limb.evaluate(np.array([[1.0, 0, 0, 0], [1.0, 0, 0, 0]]))
    joint = ConstraintOracle(JointConstraint.from_dict(ONE_JOINT_LIMITS["hinge"]))
    with pytest.raises(IndexError, match="joint 0 only"):
        joint.joint_is_valid(np.array([1.0, 0, 0, 0]), 1)
