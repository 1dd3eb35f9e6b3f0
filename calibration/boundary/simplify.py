"""The polygon written: simplified *around* the region, mapped back to the sphere (step 5).

Douglas-Peucker (topology-preserving, :meth:`shapely.Polygon.simplify`) with tolerance
``tol`` of the region grown by ``tol + margin`` (:func:`simplify_around`): the simplified
boundary lies between ``margin`` and ``2 tol + margin`` outside the region, so simplification
never cuts recorded range off; ``tol`` grows by 1.25× until at most ``max_vertices`` remain.
The vertices are mapped back to the sphere (:func:`spherical_polygon`), where they are joined
by great-circle edges; the interior point is the pole of inaccessibility
(:func:`shapely.ops.polylabel`), or the projection centre when that is nearly as deep. (If a
great-circle edge still leaves a held sample outside — it bulges inwards of its straight image
in the plane — the caller triples the margin and simplifies again:
:class:`calibration.boundary.BoundaryExtractor`.)

Documented in docs/calibration.md, "Boundary extraction", step 5.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from calibration.boundary.projection import Projection
from calibration.errors import CalibrationError

__all__ = ["MARGIN_DEG", "SphericalPolygon", "simplify_around", "spherical_polygon"]

#: Least clearance (degrees) between the region and the simplified polygon around it.
MARGIN_DEG = 0.01


def simplify_around(poly, tol: float, margin: float, max_vertices: int) -> np.ndarray:
    """Vertices (M, 2) of a polygon *around* ``poly`` with at most ``max_vertices``:
    Douglas-Peucker with tolerance ``tol`` of ``poly`` grown by ``tol + margin``, whose
    boundary then lies between ``margin`` and ``2 tol + margin`` outside ``poly`` — nothing
    the region holds is cut off; ``tol`` grows by 1.25× until the budget is met.

    Raises
    ------
    CalibrationError
        No valid polygon within the budget after 40 tries.
    """
    for _ in range(40):
        grown = poly.buffer(tol + margin, quad_segs=4)
        s = grown.simplify(tol, preserve_topology=True)
        if s.geom_type == "Polygon" and s.is_valid and s.area > 0:
            ring = np.asarray(s.exterior.coords)[:-1]
            if len(ring) <= max_vertices:
                return ring
        tol *= 1.25
    raise CalibrationError("could not simplify the boundary to the vertex budget")


@dataclass(frozen=True)
class SphericalPolygon:
    """A swing polygon on the sphere and its image in the plane.

    Attributes
    ----------
    vertices : (M, 3) float64, unit, parent frame, in boundary order
    interior : (3,) float64, unit, a point inside
    plane : shapely.Polygon, the vertices' plane image (azimuthal-equidistant degrees)
    """

    vertices: np.ndarray
    interior: np.ndarray
    plane: Any


def spherical_polygon(verts2d: np.ndarray, proj: Projection) -> SphericalPolygon:
    """Plane vertices (M, 2) mapped back by ``proj``, with an interior point: the pole of
    inaccessibility, or the projection centre when it is inside at least half as deep."""
    import shapely
    from shapely.ops import polylabel

    verts = proj.inverse(verts2d)
    spoly = shapely.Polygon(verts2d)
    pole = polylabel(spoly, tolerance=0.1)
    depth_pole = spoly.exterior.distance(pole)
    origin = shapely.Point(0.0, 0.0)
    interior2d = np.array([[pole.x, pole.y]])
    if spoly.contains(origin) and spoly.exterior.distance(origin) >= 0.5 * depth_pole:
        interior2d = np.zeros((1, 2))
    return SphericalPolygon(verts, proj.inverse(interior2d)[0], spoly)
