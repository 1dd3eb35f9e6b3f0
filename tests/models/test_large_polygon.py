"""Polygons with thousands of vertices (models.geometry, models.oracle): brute-force answers.

A 3000-vertex boundary is far past what the cube-map grid can hold in short lists, so most of
the sphere is served by the tree of bounding caps; these tests pin its answers (and the
validation's) to exhaustive references. They assert behaviour only, never time.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from models import quaternion as Q
from models.constraint import JointConstraint
from models.errors import ConstraintError, GeometryError
from models.geometry import (
    SphericalPolygon,
    _arcs_cross,
    arc_distance,
    check_polygon,
    first_crossing,
)
from models.oracle import ConstraintOracle


def wobbly_star(m: int, seed: int, centre=(0.3, -0.4, 0.866)):
    """A concave star-shaped polygon of ``m`` vertices around ``centre`` and the unit centre.

    Radius 50° ± 15° (three lobes) plus a random smooth wobble and a per-vertex jitter; simple by
    construction (gnomonic chart about the centre, azimuths in order).
    """
    rng = np.random.default_rng(seed)
    step = 2 * np.pi / m
    th = np.arange(m) * step + rng.uniform(-0.4, 0.4, size=m) * step
    k = np.arange(4, 25)
    amp = rng.normal(scale=3.0, size=(2, len(k))) / k
    wobble = np.cos(np.outer(th, k)) @ amp[0] + np.sin(np.outer(th, k)) @ amp[1]
    jitter = rng.uniform(-0.3, 0.3, size=m) * np.degrees(step) * 0.75
    return chart(centre, th, 50 + 15 * np.sin(3 * th) + wobble + jitter)


def chart(centre, azimuth, radius_deg):
    """Unit points at ``radius_deg`` from ``centre`` and the given azimuths (radians), and the
    unit centre."""
    c = np.asarray(centre, float) / np.linalg.norm(centre)
    r = np.tan(np.radians(radius_deg))
    az = np.asarray(azimuth, float)
    local = np.stack([np.ones_like(az), r * np.cos(az), r * np.sin(az)], axis=-1)
    local /= np.linalg.norm(local, axis=-1, keepdims=True)
    rot = Q.from_two_vectors(np.array([1.0, 0, 0]), c)
    return Q.rotate(rot, local), c


def first_crossing_exhaustive(verts):
    """Reference: every pair of non-adjacent edges, in (i, j) order (the former O(M²) search)."""
    m = len(verts)
    a0, a1 = verts, np.roll(verts, -1, axis=0)
    n = np.cross(a0, a1)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    for i in range(m - 2):
        j = np.arange(i + 2, m - 1 if i == 0 else m)
        if len(j) == 0:
            continue
        ii = np.full(len(j), i)
        hits = _arcs_cross(a0[ii], a1[ii], n[ii], a0[j], a1[j], n[j])
        if hits.any():
            return i, int(j[np.argmax(hits)])
    return None


def directions(verts, rng, n=4000):
    """Uniform directions, directions within ~1e-4 rad of the boundary, vertices, edge midpoints."""
    u = Q.random_unit_vectors(n, rng)
    near = verts[rng.integers(0, len(verts), n // 4)] + rng.normal(scale=1e-4, size=(n // 4, 3))
    mids = verts[:200] + np.roll(verts, -1, axis=0)[:200]
    p = np.vstack((u, near, verts[::10], mids))
    return p / np.linalg.norm(p, axis=1, keepdims=True)


@pytest.fixture(scope="module")
def big():
    verts, centre = wobbly_star(3000, seed=21)
    return verts, centre, SphericalPolygon(verts, centre)


# -- validation -------------------------------------------------------------------------------
def test_a_3000_vertex_polygon_validates():
    verts, centre = wobbly_star(3000, seed=21)
    assert first_crossing(verts) is None
    check_polygon(verts, centre)
    check_polygon(verts, -centre)  # the complement: more than a hemisphere
    c = JointConstraint.polygon(verts, centre, twist=(-40, 40))
    assert len(c.swing.vertices) == 3000
    area = c.swing.area_sr()
    assert 0 < area < 2 * math.pi
    assert JointConstraint.polygon(verts, -centre).swing.area_sr() == pytest.approx(
        4 * math.pi - area, abs=1e-9
    )


def _defects(verts, centre):
    """Self-intersecting variants of a star polygon: (name, vertices).

    A *spike* moves vertex k to the far side of the centre, 75° out — beyond the boundary there
    (which stays within about 70°), so its two edges must cross the far side.
    """
    m = len(verts)

    def spike(v, k):
        az = 2 * np.pi * k / m + np.pi
        v[k] = chart(centre, az, 75.0)[0]

    two = verts.copy()  # a late and an early defect: the early one is named
    spike(two, 1700)
    spike(two, 450)
    touch = verts.copy()  # vertex 600 on the middle of edge 1200-1201: a touch counts
    mid = verts[1200] + verts[1201]
    touch[600] = mid / np.linalg.norm(mid)
    wrap = verts.copy()  # the crossing involves the closing edge (m-1 -> 0)
    spike(wrap, m - 1)
    swap = verts.copy()  # two far-apart vertices exchanged
    swap[[300, 1300]] = swap[[1300, 300]]
    return [("two spikes", two), ("touch", touch), ("wrap", wrap), ("swap", swap)]


@pytest.mark.parametrize("case", range(4))
def test_a_self_intersecting_2000_vertex_polygon_names_the_same_first_crossing(case):
    verts, centre = wobbly_star(2000, seed=5)
    name, bad = _defects(verts, centre)[case]
    expected = first_crossing_exhaustive(bad)
    assert expected is not None, name
    assert first_crossing(bad) == expected
    i, j = expected
    m = len(bad)
    message = f"edge {i}-{(i + 1) % m} crosses edge {j}-{(j + 1) % m}"
    with pytest.raises(GeometryError, match=message) as info:
        check_polygon(bad, centre)
    assert info.value.part == "vertices"
    with pytest.raises(ConstraintError, match=message) as info:
        JointConstraint.polygon(bad, centre)
    assert "swing.polygon.vertices" in str(info.value)


# -- nearest edge -----------------------------------------------------------------------------
def test_nearest_equals_brute_force_bit_for_bit(big):
    verts, _, poly = big
    assert poly.tree_fraction > 0.5  # most cells are served by the tree here
    p = directions(verts, np.random.default_rng(1))
    fast_d, fast_b = poly.nearest(p)
    ref_d, ref_b = poly.brute_nearest(p, need_point=True)
    np.testing.assert_array_equal(fast_d, ref_d)
    np.testing.assert_array_equal(fast_b, ref_b)
    np.testing.assert_array_equal(poly.nearest(p, need_point=False)[0], ref_d)


def test_nearest_matches_an_independent_arc_distance(big):
    verts, centre, poly = big
    rng = np.random.default_rng(2)
    p = directions(verts, rng, n=400)
    v1 = np.roll(verts, -1, axis=0)
    ref = np.full(len(p), np.inf)
    for a, b in zip(verts, v1, strict=True):
        ref = np.minimum(ref, arc_distance(p, a, b))
    dist, b = poly.nearest(p)
    np.testing.assert_allclose(np.abs(dist), ref, rtol=0, atol=1e-9)
    np.testing.assert_allclose(Q.angle_between(p, b), ref, rtol=0, atol=1e-9)
    # the sign: inside near the centre, outside far from it (the boundary stays between about
    # 30° and 70° from the centre)
    ang = Q.angle_between(p, centre)
    assert (dist[ang < math.radians(20)] < 0).all()
    assert (dist[ang > math.radians(80)] > 0).all()


def test_the_tree_and_the_grid_agree_where_both_could_serve():
    """On a 300-vertex polygon the grid serves every cell; sending every point to the tree
    instead must not change a bit (both rank a superset of the nearest edges by one key)."""
    verts, centre = wobbly_star(300, seed=3)
    rng = np.random.default_rng(4)
    for interior in (centre, -centre):
        poly = SphericalPolygon(verts, interior)
        assert poly.tree_fraction == 0.0
        p = directions(verts, rng, n=3000)
        grid = poly.nearest(p)
        poly.cell_tree = np.ones_like(poly.cell_tree)
        tree = poly.nearest(p)
        np.testing.assert_array_equal(grid[0], tree[0])
        np.testing.assert_array_equal(grid[1], tree[1])


def test_the_tree_prunes(big):
    verts, _, poly = big
    p = Q.random_unit_vectors(2000, np.random.default_rng(6))
    owner, edge = poly._tree.search(p, 0.0)
    assert np.array_equal(np.unique(owner), np.arange(len(p)))
    assert len(edge) / len(p) < 0.05 * len(verts)  # a few dozen edges per point, not thousands


def test_single_path_equals_batch_path(big):
    verts, _, poly = big
    p = directions(verts, np.random.default_rng(7), n=300)
    dist, b = poly.nearest(p)
    for i in range(len(p)):
        d1, b1 = poly.nearest_one(tuple(p[i]))
        assert d1 == pytest.approx(dist[i], abs=1e-12)
        np.testing.assert_allclose(b1, b[i], rtol=0, atol=1e-12)


def test_oracle_on_a_3000_vertex_constraint(big):
    verts, centre, _ = big
    o = ConstraintOracle(JointConstraint.polygon(verts, centre, twist=(-40, 40)))
    rng = np.random.default_rng(8)
    q = Q.random_quaternions(3000, rng)
    r = o.evaluate(q)
    assert o.is_valid(r.projected).all()
    np.testing.assert_array_equal(o.is_valid(q), r.valid)
    d = Q.rotate(q, Q.LIMB_AXIS)
    np.testing.assert_array_equal(o._swing.nearest(d)[0], o._swing.brute_nearest(d)[0])
    np.testing.assert_allclose(o.swing_distance(d), r.swing_distance, rtol=0, atol=1e-12)
    for k in range(0, 3000, 25):  # the control loop's path: the same answers
        one = o.evaluate(q[k])
        assert bool(one.valid) == bool(r.valid[k])
        np.testing.assert_allclose(one.distance, r.distance[k], atol=1e-12)
        np.testing.assert_allclose(one.projected, r.projected[k], atol=1e-12)
