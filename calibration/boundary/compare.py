"""Swing regions compared: boundary points, boundary distance, what a boundary holds.

**Symmetric mean boundary distance** (:func:`boundary_distance`) between swing regions ``A``
and ``B``: ``D = ½ (mean_{a ∈ ∂A} dist(a, ∂B) + mean_{b ∈ ∂B} dist(b, ∂A))`` with points
spaced evenly (0.25°) along each boundary by arc length (:func:`boundary_points`,
:func:`swing_boundary_points`) and ``dist`` the geodesic distance to the other boundary
(exact, :class:`models.oracle.ConstraintOracle`). It is the mean of the two directed average
Hausdorff distances; the maximum of the per-point distances (Hausdorff) is reported too.

**What a boundary holds** (:func:`inside_share`, :func:`outside_fraction`): the share of
directions inside a constraint's swing region (within a tolerance), by the exact oracle's
signed distance — measured on the constraint written (step 8).

Documented in docs/calibration.md, "Boundary extraction" (step 8) and "Accuracy measure".
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from models import quaternion as Q
from models.constraint import JointConstraint
from models.oracle import ConstraintOracle

__all__ = [
    "Inside",
    "boundary_distance",
    "boundary_points",
    "inside_share",
    "outside_fraction",
    "swing_boundary_points",
    "swing_oracle",
]


def boundary_points(vertices, step_deg: float = 0.25) -> tuple[np.ndarray, np.ndarray]:
    """Points evenly spaced along a spherical polygon's great-circle edges.

    Parameters
    ----------
    vertices : (M, 3) array_like, unit, in boundary order
    step_deg : float, spacing along each edge (at most)

    Returns
    -------
    points : (K, 3) unit
    length_deg : (K,) arc length each point stands for (sums to the perimeter)
    """
    v = Q.check_vectors(vertices, name="vertices")
    w = np.roll(v, -1, axis=0)
    out, lens = [], []
    for a, b in zip(v, w, strict=True):
        ang = float(Q.angle_between(a, b))
        n = max(1, math.ceil(math.degrees(ang) / step_deg))
        t = (np.arange(n) + 0.5) / n
        s = math.sin(ang)
        pts = (np.sin((1 - t) * ang)[:, None] * a + np.sin(t * ang)[:, None] * b) / s
        out.append(pts)
        lens.append(np.full(n, math.degrees(ang) / n))
    return np.concatenate(out), np.concatenate(lens)


def swing_oracle(constraint: JointConstraint):
    """The exact oracle of ``constraint``'s swing region alone (no twist limits), and the
    swing region itself.

    Raises
    ------
    TypeError
        ``constraint`` is not a :class:`~models.constraint.JointConstraint`.
    """

    if isinstance(constraint, JointConstraint):
        c = constraint
        return ConstraintOracle(JointConstraint.from_dict(
            {"name": "swing", "limb_axis": [float(x) for x in c.limb_axis],
             "swing": c.swing.to_dict()})), c.swing
    raise TypeError("expected a JointConstraint")


def swing_boundary_points(swing, step_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """Points along a swing region's boundary (a polygon's edges, :func:`boundary_points`, or
    a cone's circle) and the arc length each stands for, degrees."""
    if hasattr(swing, "vertices"):
        return boundary_points(swing.vertices, step_deg)
    # a cone: a circle of points
    c = np.asarray(swing.centre, dtype=float)
    u, v = Q.tangent_basis(c)
    n = max(8, math.ceil(360.0 * math.sin(swing.radius) / step_deg))
    a = 2 * math.pi * (np.arange(n) + 0.5) / n
    r = swing.radius
    pts = math.cos(r) * c + math.sin(r) * (np.cos(a)[:, None] * u + np.sin(a)[:, None] * v)
    return pts, np.full(n, 360.0 * math.sin(r) / n)


def boundary_distance(a: JointConstraint, b: JointConstraint, step_deg: float = 0.25) -> dict:
    """Symmetric mean boundary-to-boundary distance of two swing regions (see module doc).

    Returns
    -------
    dict with ``mean_deg`` (the symmetric mean ``D``), ``a_to_b_deg``, ``b_to_a_deg`` (directed
    arc-length-weighted means), ``hausdorff_deg`` (largest point distance either way),
    ``p95_deg`` (the point distance either way exceeded along 5 % of the two boundaries'
    length: a difference over a stretch of boundary, not at one spike).
    """
    oa, sa = swing_oracle(a)
    ob, sb = swing_oracle(b)
    pa, la = swing_boundary_points(sa, step_deg)
    pb, lb = swing_boundary_points(sb, step_deg)
    da = np.degrees(np.abs(ob.swing_distance(pa)))
    db = np.degrees(np.abs(oa.swing_distance(pb)))
    ab = float(np.sum(da * la) / la.sum())
    ba = float(np.sum(db * lb) / lb.sum())
    d, w = np.concatenate((da, db)), np.concatenate((la, lb))
    order = np.argsort(d)
    cum = np.cumsum(w[order])
    p95 = float(d[order][min(np.searchsorted(cum, 0.95 * cum[-1]), len(d) - 1)])
    return {"mean_deg": 0.5 * (ab + ba), "a_to_b_deg": ab, "b_to_a_deg": ba,
            "hausdorff_deg": float(max(da.max(), db.max())), "p95_deg": p95}


def outside_fraction(constraint: JointConstraint, directions, tolerance_deg: float = 1.0) -> float:
    """Fraction of limb directions (N, 3) more than ``tolerance_deg`` outside the swing region."""
    o, _ = swing_oracle(constraint)
    dist = o.swing_distance(Q.check_vectors(directions, name="directions"))
    return float(np.mean(dist > math.radians(tolerance_deg)))


@dataclass(frozen=True)
class Inside:
    """What a swing region holds of a set of directions.

    Attributes
    ----------
    share : float, inside (signed distance ≤ 0)
    within_1deg : float, inside or within 1° of the boundary
    farthest_outside_deg : float, ≥ 0, the farthest direction outside (0 when none is)
    directions : int, directions measured
    """

    share: float
    within_1deg: float
    farthest_outside_deg: float
    directions: int


def inside_share(constraint: JointConstraint, directions: np.ndarray) -> Inside:
    """What ``constraint``'s swing region holds of unit ``directions`` (N, 3), by the exact
    oracle's signed distance."""
    o, _ = swing_oracle(constraint)
    dist = np.degrees(o.swing_distance(directions))
    return Inside(float(np.mean(dist <= 0.0)), float(np.mean(dist <= 1.0)),
                  float(max(0.0, dist.max())), len(directions))
