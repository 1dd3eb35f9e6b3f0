"""Sparse arcs: stretches of the boundary the patient reached rarely or never (step 7).

Points every 0.5° along the final boundary
(:func:`calibration.boundary.compare.boundary_points`) with fewer than ``min_samples`` kept
samples within ``sparse_deg`` are grouped into arcs (:func:`sparse_arcs`) and reported: there
the boundary is an interpolation, and the clinician should record more. Arcs shorter than 1°
are not reported.

Documented in docs/calibration.md, "Boundary extraction", step 7.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from calibration.boundary.compare import boundary_points

__all__ = ["SparseArc", "sparse_arcs"]


@dataclass(frozen=True)
class SparseArc:
    """A stretch of the extracted boundary with few samples nearby.

    Attributes
    ----------
    start, end : (3,) float64, unit directions (parent frame) where the arc begins and ends
    length_deg : float, arc length along the boundary, degrees
    """

    start: np.ndarray
    end: np.ndarray
    length_deg: float

    def to_dict(self) -> dict[str, Any]:
        return {
            "from": [round(float(v), 6) for v in self.start],
            "to": [round(float(v), 6) for v in self.end],
            "length_deg": round(float(self.length_deg), 2),
        }


def sparse_arcs(vertices: np.ndarray, d: np.ndarray, sparse_deg: float,
                min_samples: int) -> list[SparseArc]:
    """Arcs of the spherical polygon ``vertices`` (M, 3, unit, boundary order) with fewer than
    ``min_samples`` of the directions ``d`` (N, 3, unit) within ``sparse_deg`` degrees."""
    from scipy.spatial import cKDTree

    pts, seg_len = boundary_points(vertices, step_deg=0.5)
    tree = cKDTree(d)
    chord = 2.0 * math.sin(math.radians(sparse_deg) / 2.0)
    counts = tree.query_ball_point(pts, chord, return_length=True)
    sparse = counts < min_samples
    arcs: list[SparseArc] = []
    if not sparse.any():
        return arcs
    n = len(pts)
    if sparse.all():
        return [SparseArc(pts[0], pts[-1], float(seg_len.sum()))]
    # rotate so that the sequence starts on a non-sparse point, then group runs
    start = int(np.argmin(sparse))
    order = (np.arange(n) + start) % n
    run: list[int] = []
    for k in [*list(order), order[0]]:
        if sparse[k]:
            run.append(int(k))
        elif run:
            length = float(seg_len[run].sum())
            if length >= 1.0:
                arcs.append(SparseArc(pts[run[0]], pts[run[-1]], length))
            run = []
    return arcs
