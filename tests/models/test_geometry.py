"""Spherical-polygon geometry (models.geometry) against independent references."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from models import quaternion as Q
from models.errors import GeometryError
from models.geometry import (
    SphericalPolygon,
    arc_distance,
    boundary_distance,
    check_polygon,
    densify,
    first_contact_along,
    first_crossing,
    polygon_area,
)


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


def dense_boundary(verts, per_edge=400):
    t = np.linspace(0, 1, per_edge)[:, None, None]
    a0, a1 = verts, np.roll(verts, -1, axis=0)
    dense = ((1 - t) * a0 + t * a1).reshape(-1, 3)
    return dense / np.linalg.norm(dense, axis=1, keepdims=True)


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


# -- point in polygon, nearest point ----------------------------------------------------------
@pytest.mark.parametrize("seed", range(4))
def test_contains_matches_crossing_parity(seed):
    rng = np.random.default_rng(seed)
    centre = Q.random_unit_vectors(1, rng)[0]
    radii = rng.uniform(10, 80, size=rng.integers(5, 60))
    verts = star_polygon(centre, radii)
    for interior in (centre, -centre):
        poly = SphericalPolygon(verts, interior)
        p = Q.random_unit_vectors(4000, rng)
        dist = poly.signed_distance(p)
        clear = np.abs(dist) > 1e-6
        ref = crossing_inside(verts, interior, p)
        np.testing.assert_array_equal(poly.contains(p)[clear], ref[clear])
        assert clear.mean() > 0.99


@pytest.mark.parametrize("seed", range(3))
def test_grid_search_equals_brute_force(seed):
    rng = np.random.default_rng(100 + seed)
    th = np.linspace(0, 2 * np.pi, 300, endpoint=False)
    radii = 45 + 25 * np.sin(3 * th + seed) + rng.uniform(-3, 3, size=300)
    verts = star_polygon(Q.random_unit_vectors(1, rng)[0], radii)
    poly = SphericalPolygon(verts, verts.mean(axis=0))
    assert poly.mean_candidates < 0.2 * len(verts)  # the grid actually prunes
    p = Q.random_unit_vectors(5000, rng)
    fast_d, fast_b = poly.nearest(p)
    ref_d, ref_b = poly.brute_nearest(p, need_point=True)
    np.testing.assert_array_equal(fast_d, ref_d)
    np.testing.assert_array_equal(fast_b, ref_b)


def test_the_grid_is_built_when_it_pays_and_changes_no_answer():
    """A polygon answers its first GRID_AFTER_POINTS points by brute force (no grid: a
    boundary compared once never pays for one), then builds its grid; the answers are the same
    bits either way."""
    rng = np.random.default_rng(12)
    th = np.linspace(0, 2 * np.pi, 120, endpoint=False)
    verts = star_polygon([0.3, -0.2, 0.9], 50 + 15 * np.sin(4 * th) + rng.uniform(-2, 2, 120))
    poly = SphericalPolygon(verts, [0.3, -0.2, 0.9])
    p = Q.random_unit_vectors(SphericalPolygon.GRID_AFTER_POINTS, rng)
    before = poly.nearest(p)
    assert "G" not in vars(poly)  # answered without a grid
    after = poly.nearest(p[:10])  # past the threshold: the grid is built
    assert "G" in vars(poly) and poly.mean_candidates < 0.2 * len(verts)
    np.testing.assert_array_equal(after[0], before[0][:10])
    np.testing.assert_array_equal(after[1], before[1][:10])
    np.testing.assert_array_equal(poly.nearest(p)[0], before[0])
    np.testing.assert_array_equal(poly.nearest(p)[1], before[1])


def test_single_point_path_equals_batch():
    rng = np.random.default_rng(9)
    verts = star_polygon([0.2, 0.9, 0.1], rng.uniform(15, 70, size=80))
    poly = SphericalPolygon(verts, [0.2, 0.9, 0.1])
    p = Q.random_unit_vectors(500, rng)
    dist, b = poly.nearest(p)
    for i in range(len(p)):
        d1, b1 = poly.nearest_one(tuple(p[i]))
        assert d1 == pytest.approx(dist[i], abs=1e-12)
        np.testing.assert_allclose(b1, b[i], atol=1e-12)


def test_nearest_point_is_on_the_boundary_and_nearest():
    rng = np.random.default_rng(5)
    verts = star_polygon([0, 0, 1], [40, 15, 60, 30, 55, 20, 50])  # concave
    poly = SphericalPolygon(verts, [0, 0, 1])
    p = Q.random_unit_vectors(3000, rng)
    b = poly.nearest_point(p)
    np.testing.assert_allclose(poly.signed_distance(b), 0.0, atol=1e-9)
    dense = dense_boundary(verts)
    reported = Q.angle_between(p, b)
    best = np.min(np.arccos(np.clip(p @ dense.T, -1, 1)), axis=1)
    assert (reported <= best + 1e-9).all()
    np.testing.assert_allclose(np.abs(poly.signed_distance(p)), reported, atol=1e-9)


def test_equidistant_point_takes_lowest_edge_and_first_vertex():
    verts = star_polygon([1, 0, 0], np.full(4, 30.0))
    poly = SphericalPolygon(verts, [1, 0, 0])
    # -X is equally far from every vertex (by symmetry) and every edge's nearest point is a
    # vertex: edge 0 wins, and of its two ends the first
    b = poly.nearest_point(np.array([[-1.0, 0.0, 0.0]]))[0]
    np.testing.assert_allclose(b, verts[0], atol=1e-12)


def test_arc_distance_matches_dense_sampling():
    rng = np.random.default_rng(11)
    a = np.array([1.0, 0.0, 0.0])
    b = np.array([0.6, 0.8, 0.0])
    p = Q.random_unit_vectors(2000, rng)
    got = arc_distance(p, a, b)
    t = np.linspace(0, 1, 4001)[:, None]
    arc = (1 - t) * a + t * b
    arc /= np.linalg.norm(arc, axis=1, keepdims=True)
    ref = np.min(np.arccos(np.clip(p @ arc.T, -1, 1)), axis=1)
    np.testing.assert_allclose(got, ref, atol=2e-4)  # sampling step ~1.3e-4 rad
    assert (got <= ref + 1e-12).all()


def test_densify_steps_and_stays_on_the_edges():
    verts = star_polygon([0, 1, 0], [40, 25, 60, 35, 50])
    pts = densify(verts, max_step_deg=0.5)
    steps = Q.angle_between(pts, np.roll(pts, -1, axis=0))
    assert steps.max() <= math.radians(0.5) + 1e-12
    assert boundary_distance(verts, pts[0]) == pytest.approx(0.0, abs=1e-12)
    poly = SphericalPolygon(verts, [0, 1, 0])
    np.testing.assert_allclose(poly.signed_distance(pts), 0.0, atol=1e-12)


# -- area ---------------------------------------------------------------------------------------
def test_area_matches_cap_and_complement():
    centre = np.array([0.0, 1.0, 0.0])
    verts = star_polygon(centre, np.full(720, 60.0))
    cap = 2 * math.pi * (1 - math.cos(math.radians(60)))
    assert polygon_area(verts, centre) == pytest.approx(cap, rel=1e-3)
    assert polygon_area(verts, -centre) == pytest.approx(4 * math.pi - cap, rel=1e-3)
    assert SphericalPolygon(verts, centre).area() == polygon_area(verts, centre)


def test_octant_triangle_has_area_pi_over_2():
    tri = np.eye(3)
    assert polygon_area(tri, [1, 1, 1]) == pytest.approx(math.pi / 2, abs=1e-12)
    assert polygon_area(tri[::-1], [1, 1, 1]) == pytest.approx(math.pi / 2, abs=1e-12)


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**32 - 1))
def test_area_agrees_with_monte_carlo(seed):
    rng = np.random.default_rng(seed)
    centre = Q.random_unit_vectors(1, rng)[0]
    verts = star_polygon(centre, rng.uniform(10, 80, size=rng.integers(3, 30)))
    poly = SphericalPolygon(verts, centre)
    p = Q.random_unit_vectors(20000, rng)
    frac = poly.contains(p).mean()
    se = math.sqrt(max(frac * (1 - frac), 1e-4) / len(p))
    assert abs(poly.area() / (4 * math.pi) - frac) < 5 * se


# -- validity -----------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "vertices, interior, message, part",
    [
        ([[1, 0.5, 0.5], [1, -0.5, 0.5]], None, "at least 3", "vertices"),
        (
            [[1, 0.5, 0.5], [1, 0.5, 0.5], [1, -0.5, -0.5]],
            None,
            "vertices 0 and 1 coincide",
            "vertices",
        ),
        ([[1, 0, 0], [-1, 0, 0], [0, 1, 0]], None, "antipodal", "vertices"),
        ([[1, 0, 0], [0, 1, 0], [-1, 0.01, 0], [0, -1, 0]], None, "great circle", "vertices"),
        (
            [[1, 0.5, 0.5], [1, -0.5, -0.5], [1, 0.5, -0.5], [1, -0.5, 0.5]],
            None,
            "edge 0-1 crosses edge 2-3",
            "vertices",
        ),
        (
            [[1, 0.5, 0.5], [1, -0.5, 0.5], [1, -0.5, -0.5], [1, 0.5, -0.5]],
            [1, 0.5, 0],
            "strictly inside",
            "interior",
        ),
    ],
)
def test_check_polygon_names_the_defect(vertices, interior, message, part):
    v = np.asarray(vertices, float)
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    if interior is not None:
        interior = np.asarray(interior, float) / np.linalg.norm(interior)
    with pytest.raises(GeometryError, match=message) as info:
        check_polygon(v, interior)
    assert info.value.part == part


def test_simple_polygons_pass_and_have_no_crossing():
    rng = np.random.default_rng(1)
    for _ in range(20):
        centre = Q.random_unit_vectors(1, rng)[0]
        verts = star_polygon(centre, rng.uniform(5, 85, size=rng.integers(3, 50)))
        assert first_crossing(verts) is None
        check_polygon(verts, centre)
        check_polygon(verts, -centre)


def _lerp_polygon(a, b, t):
    v = (1.0 - t) * a + t * b
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def _simple(v) -> bool:
    try:
        check_polygon(v)
    except GeometryError:
        return False
    return True


def test_interpolated_star_polygons_never_touch_themselves():
    """Two star polygons on the same rays: every interpolation between them is star-shaped on
    those rays, so simple at every t."""
    rng = np.random.default_rng(4)
    for _ in range(10):
        centre = Q.random_unit_vectors(1, rng)[0]
        m = int(rng.integers(5, 60))
        a = star_polygon(centre, rng.uniform(10, 80, m))
        b = star_polygon(centre, rng.uniform(10, 80, m))
        assert first_contact_along(a, b) is None


@pytest.mark.parametrize("seed", range(3))
def test_the_first_contact_is_exact_where_sampling_is_not(seed):
    """Jittered interpolations, against a dense scan (501 steps): the polygon is simple just
    before the contact found, touches itself at it (a vertex on an edge, to rounding), and
    every sampled failure comes after it; a contact between samples that the scan missed
    is a fold narrower than its step (the 16-step check once let one of 0.8° of elbow angle
    through: a limb file whose limits there could not be built)."""
    rng = np.random.default_rng(seed)
    centre = Q.random_unit_vectors(1, rng)[0]
    m = 24
    a = star_polygon(centre, rng.uniform(20, 40, m))
    b = a + rng.normal(0.0, 0.12, a.shape)
    b /= np.linalg.norm(b, axis=1, keepdims=True)
    t = first_contact_along(a, b)
    steps = np.linspace(0.0, 1.0, 501)
    bad = [s for s in steps if not _simple(_lerp_polygon(a, b, s))]
    assert t is not None or not bad
    if t is None:
        return
    assert _simple(_lerp_polygon(a, b, t - 1e-7))
    if bad:
        assert t <= bad[0]
    v = _lerp_polygon(a, b, t)
    nxt = np.roll(v, -1, axis=0)
    g = np.cross(v, nxt)
    g /= np.linalg.norm(g, axis=1, keepdims=True)
    # some vertex lies on some other edge's great circle at t
    off = np.abs(v @ g.T)
    for i in range(m):
        off[i, i] = off[i, (i - 1) % m] = np.inf
    assert off.min() < 1e-9


def test_a_fold_between_sampled_steps_is_found():
    """A 12-vertex star whose jittered interpolation folds over itself for t in about
    (0.8853, 0.9008) only — between the 16-step samples 14/16 and 15/16, which all pass — is
    found at its first contact."""
    rng = np.random.default_rng(27)
    a = star_polygon(np.array([1.0, 0.0, 0.0]), rng.uniform(20, 40, 12))
    b = a + rng.normal(0.0, 0.15, a.shape)
    b /= np.linalg.norm(b, axis=1, keepdims=True)
    assert all(_simple(_lerp_polygon(a, b, k / 16)) for k in range(17))
    t = first_contact_along(a, b)
    assert t == pytest.approx(0.8853, abs=1e-4)
    assert not _simple(_lerp_polygon(a, b, t + 1e-3))


def test_signed_queries_need_an_interior_point():
    verts = star_polygon([1, 0, 0], [30, 30, 30])
    with pytest.raises(GeometryError, match="interior"):
        SphericalPolygon(verts).signed_distance(np.array([[1.0, 0, 0]]))
