"""Plane geometry of the swing region (shapely polygons, azimuthal-equidistant degrees).

Which piece of a region covers each point (:func:`label_parts`), and distances of many points
to a boundary (:func:`boundary_distance_2d`, :func:`ring_distance`): the nearest of the
boundary's points 0.05° apart, from a k-d tree — exact distances to a ring of thousands of
vertices are slow for 10⁵ points, and 0.025° is far below what the method resolves.

Used by steps 4 and 4b of docs/calibration.md, "Boundary extraction".
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["boundary_distance_2d", "label_parts", "ring_distance"]


def label_parts(parts, xy: np.ndarray) -> np.ndarray:
    """Index (N,) of the part (a sequence of polygons) covering each point (N, 2), or -1; the
    first part wins where parts overlap."""
    import shapely

    out = np.full(len(xy), -1, dtype=np.int64)
    for k, g in enumerate(parts):
        shapely.prepare(g)
        out[(out < 0) & shapely.intersects_xy(g, xy[:, 0], xy[:, 1])] = k
    return out


def boundary_distance_2d(geom, xy: np.ndarray, step: float = 0.05) -> np.ndarray:
    """Distance (N,) of points (N, 2) to the boundary of ``geom`` (or to a line), to within
    ``step / 2`` (:func:`ring_distance`)."""
    line = geom if geom.geom_type in ("LineString", "LinearRing", "MultiLineString") \
        else geom.boundary
    return ring_distance(line, xy, step)[0]


def ring_distance(line, xy: np.ndarray, step: float = 0.05,
                  bound: float = math.inf) -> tuple[np.ndarray, np.ndarray]:
    """Distance (N,) of points (N, 2) to a line and, for a single ring or line, the arc length
    (N,) along it of their nearest point; both to within ``step / 2``, from one k-d tree query
    of the line's points ``step`` apart. Points farther than ``bound`` get ``inf`` (and arc 0):
    the tree stops searching for them, which makes the query several times faster on a
    recording whose samples are mostly far from the boundary."""
    import shapely
    from scipy.spatial import cKDTree

    pts = shapely.get_coordinates(shapely.segmentize(line, step))
    if len(xy) == 0 or len(pts) == 0:
        return np.zeros(len(xy)), np.zeros(len(xy))
    arc = np.concatenate(([0.0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1)), [0.0]))
    dist, k = cKDTree(pts).query(xy, distance_upper_bound=bound)
    return dist, arc[k]  # k == len(pts) beyond the bound: the appended 0
