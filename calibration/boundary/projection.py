"""Directions on the sphere ↔ the plane the swing region is built in (step 3).

The centre ``c`` is the normalised mean of the directions, re-centred on the 95 % nearest it
(:func:`centre_of`). Directions are mapped to the plane by the *azimuthal-equidistant*
projection about ``c`` (Snyder 1987, *Map projections — a working manual*, USGS PP 1395, §25):
``p = θ (cos α, sin α)`` with ``θ = ∠(d, c)`` in degrees and ``α`` the azimuth in the tangent
basis ``(u, v)`` at ``c`` (:func:`models.quaternion.tangent_basis`). Distances from ``c`` are
exact; other distances are stretched by ``θ / sin θ`` across the radial direction (5 % at 30°,
21 % at 60°), which matters for the alpha radius only: vertices are mapped back exactly
(:meth:`Projection.inverse`).

Documented in docs/calibration.md, "Boundary extraction", step 3.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calibration.errors import CalibrationError
from models import quaternion as Q

__all__ = ["Projection", "centre_of"]


def centre_of(d: np.ndarray) -> np.ndarray:
    """Projection centre of unit directions ``d`` (N, 3): their normalised mean, re-centred on
    the 95 % nearest it. Returns (3,) unit.

    Raises
    ------
    CalibrationError
        The directions have no clear centre (the mean's norm is below 0.2).
    """
    m = d.mean(axis=0)
    if np.linalg.norm(m) < 0.2:
        raise CalibrationError(
            "recorded directions have no clear centre (spread over the whole sphere)"
        )
    c = m / np.linalg.norm(m)
    ang = Q.angle_between(d, c)
    near = ang <= np.quantile(ang, 0.95)
    m = d[near].mean(axis=0)
    return m / np.linalg.norm(m)


@dataclass(frozen=True)
class Projection:
    """Azimuthal-equidistant projection about ``centre`` (plane coordinates in degrees).

    Attributes
    ----------
    centre : (3,) float64, unit, parent frame
    u, v : (3,) float64, unit, the tangent basis at ``centre`` (plane axes 0 and 1)
    """

    centre: np.ndarray
    u: np.ndarray
    v: np.ndarray

    @classmethod
    def about(cls, centre: np.ndarray) -> Projection:
        """The projection about unit ``centre`` in its :func:`~models.quaternion.tangent_basis`."""
        u, v = Q.tangent_basis(centre)
        return cls(centre, u, v)

    def forward(self, d: np.ndarray) -> np.ndarray:
        """Plane coordinates (N, 2), degrees, of unit directions ``d`` (N, 3)."""
        x = d @ self.u
        y = d @ self.v
        s = np.hypot(x, y)
        theta = np.degrees(np.arctan2(s, d @ self.centre))
        safe = np.where(s > 1e-15, s, 1.0)
        return np.column_stack((theta * x / safe, theta * y / safe))

    def inverse(self, p: np.ndarray) -> np.ndarray:
        """Unit directions (N, 3) of plane coordinates ``p`` (N, 2), degrees."""
        theta = np.hypot(p[:, 0], p[:, 1])
        safe = np.where(theta > 1e-12, theta, 1.0)
        t = np.radians(theta)
        tang = (p[:, :1] / safe[:, None]) * self.u + (p[:, 1:] / safe[:, None]) * self.v
        return np.cos(t)[:, None] * self.centre + np.sin(t)[:, None] * tang
