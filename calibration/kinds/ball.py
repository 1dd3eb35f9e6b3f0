"""The ball joint in ``calibration/``: its swing region and twist extracted from the recorded
orientations (:class:`calibration.boundary.BoundaryExtractor`); it measures all three Cardan
angles, read where the other angles are near neutral (a goniometer's reading).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from calibration.boundary.compare import swing_boundary_points
from calibration.boundary.extractor import BoundaryExtractor
from calibration.kinds.base import CalibrationKind
from models import quaternion as Q
from models.geometry import fibonacci_sphere
from models.oracle import ConstraintOracle

__all__ = ["BallCalibration", "allowed_boundary_samples"]


class BallCalibration(CalibrationKind):
    """The ball joint's extraction and clinical reading."""

    name = "ball"
    angles = (0, 1, 2)
    unmeasured_words = "not measured by a ball joint"

    def extractor(self, spec, *, limb_axis, alpha_deg, max_vertices, by_swing, name) -> Any:
        return BoundaryExtractor(alpha_deg=alpha_deg, max_vertices=max_vertices,
                                 by_swing=by_swing, limb_axis=limb_axis, name=name,
                                 kind=self.name)

    def allowed_samples(self, constraint, step_deg: float) -> np.ndarray:
        return allowed_boundary_samples(constraint, step_deg)


def allowed_boundary_samples(constraint, step_deg: float = 0.25,
                             interior: int = 80_000) -> np.ndarray:
    """Orientations (N, 4) on the boundary of the set a ball or two-axis constraint allows —
    where every joint angle takes its extremes (a Cardan angle has no extreme inside the
    set): each limb direction along the swing boundary (``step_deg`` apart) at twists across
    its interval (``step_deg`` apart), and each direction inside the swing region (a
    Fibonacci grid of ``interior`` points on the sphere, ~0.8°) at its two twist limits
    (an unconstrained twist: at twists 2° apart along the boundary, 10° inside).
    Orientations are ``swing ⊗ twist``, the oracle's decomposition about the limb axis, so
    every one is allowed."""
    oracle = ConstraintOracle(constraint)
    axis = np.asarray(constraint.limb_axis, dtype=np.float64)
    step = math.radians(step_deg)
    grid = fibonacci_sphere(interior)
    inside = grid if constraint.swing is None else grid[oracle.swing_distance(grid) <= 0.0]
    edge = (np.zeros((0, 3)) if constraint.swing is None
            else swing_boundary_points(constraint.swing, step_deg)[0])
    # an unconstrained twist has no ends: every direction at twists 2° (edge) / 10° apart
    free = constraint.twist is None
    parts = []
    for d, tw_step in ((edge, math.radians(2.0) if free else step),
                       (inside, math.radians(10.0) if free else None)):
        if not len(d):
            continue
        lo, hi = (np.broadcast_to(x, (len(d),)) for x in oracle.twist_limits_at(d))
        m = 2 if tw_step is None else math.ceil(float((hi - lo).max()) / tw_step) + 1
        tw = lo[:, None] + (hi - lo)[:, None] * np.linspace(0.0, 1.0, m)[None, :]
        sw = Q.from_two_vectors(np.broadcast_to(axis, d.shape), d)
        parts.append(Q.multiply(np.repeat(sw, m, axis=0),
                                Q.from_axis_angle(axis, tw.ravel())))
    return np.concatenate(parts)
