"""The shipped irregular swing boundaries (models.shapes)."""

from __future__ import annotations

import numpy as np
import pytest

from models import quaternion as Q
from models.constraint import load_constraint
from models.errors import DatasetError
from models.limits import PolygonSwing
from models.oracle import ConstraintOracle, polygon_area_sr
from models.shapes import SHAPES, load_shape, shape_path


def test_names_in_thesis_order():
    assert SHAPES == ("original", "small", "large", "c-shape", "highly-irregular")


@pytest.mark.parametrize("name", SHAPES)
def test_each_shape_is_a_valid_polygon_file_around_x(name):
    path = shape_path(name)
    assert path.is_file() and path.suffix == ".yaml"
    c = load_constraint(path)  # validates: simple polygon, interior strictly inside
    assert c == load_shape(name)
    assert isinstance(c.swing, PolygonSwing)
    assert 20 <= len(c.swing.vertices) <= 60
    np.testing.assert_allclose(c.limb_axis, [1.0, 0.0, 0.0])
    assert c.provenance["kind"] == "synthetic"  # where the outline came from, kept on load
    oracle = ConstraintOracle(c)
    assert oracle.swing_distance(np.array([1.0, 0.0, 0.0])) < 0.0  # +X is inside
    assert oracle.swing_distance(np.array([-1.0, 0.0, 0.0])) > 0.0


def test_extents_are_plausible_for_a_shoulder():
    def extent(name):
        v = load_shape(name).swing.vertices
        return np.degrees(Q.angle_between(v, np.array([1.0, 0.0, 0.0])))

    e = extent("original")
    assert 35 <= e.min() and e.max() <= 75
    assert extent("small").max() < e.min()
    assert extent("large").max() > e.max()
    areas = {n: polygon_area_sr(load_shape(n).swing) for n in SHAPES}
    assert areas["small"] < areas["original"] < areas["large"]


@pytest.mark.parametrize("name", ["original", "c-shape", "highly-irregular"])
def test_concave(name):
    """Two valid directions whose geodesic midpoint is invalid exist (not convex)."""
    oracle = ConstraintOracle(load_shape(name))
    rng = np.random.default_rng(0)
    d = Q.random_unit_vectors(20000, rng)
    d = d[oracle.swing_distance(d) < 0][:1500]
    a, b = d[rng.integers(0, len(d), 5000)], d[rng.integers(0, len(d), 5000)]
    mid = a + b
    mid = mid[np.linalg.norm(mid, axis=1) > 1e-6]
    assert (oracle.swing_distance(mid) > 0).any()


def test_c_shape_notch_is_pronounced():
    oracle = ConstraintOracle(load_shape("c-shape"))
    ang = np.radians(30.0)
    towards_y = np.array([np.cos(ang), np.sin(ang), 0.0])
    towards_minus_y = np.array([np.cos(ang), -np.sin(ang), 0.0])
    assert oracle.swing_distance(towards_y) > 0.0  # inside the notch: invalid
    assert oracle.swing_distance(towards_minus_y) < 0.0


def test_unknown_name_lists_the_valid_ones():
    with pytest.raises(DatasetError, match="original, small, large, c-shape, highly-irregular"):
        load_shape("banana")
    with pytest.raises(DatasetError, match="banana"):
        shape_path("banana")
