"""Regular-boundary (cone) patterns exactly as thesis eq. 59-68, plus their exact oracle.

This is the self-contained reference generator of the thesis's *regular* experiments; it lets
:mod:`models.nn` be trained, tested and benchmarked without the general constraint machinery
(:mod:`models.constraint`, :mod:`models.oracle`, :mod:`models.datasets`), which the CLI and the
reproduction harness use when present.

Maths (limb axis ``X = (1, 0, 0)``, boundary centre ``C`` (unit), radius ``r``)::

    V ~ chosen on S²                                     (eq. 59)
    Qi = rotation taking X to V, axis X × V, w ≥ 0       (eq. 60-62, twist-free input)
    θ = angle(V, C)                                      (eq. 63)
    θ ≤ r   →  Qo = (1, 0, 0, 0)                         (eq. 64, valid: identity)
    θ > r   →  Δθ = θ - r,  a = (V × C)/|V × C|,
               Qo = (cos Δθ/2, a sin Δθ/2)               (eq. 65-67)
    corrected = Qo ⊗ Qi                                   (eq. 68)

For an orientation with twist the same rule acts on its limb direction ``V = rotate(q, X)``,
so :class:`ConeOracle` is defined on all of SO(3); ``signed_distance = θ - r`` (radians).

Distributions (thesis Fig. 34): ``"even"`` draws equal counts from four zones — inner valid
``[0, r - b]``, valid band ``[r - b, r]``, invalid band ``[r, r + b]``, outer invalid
``[r + b, π]`` with ``b = min(10°, r/2, (π - r)/2)`` — each zone area-uniform (``cos θ``
uniform, azimuth uniform); ``"clustered"`` packs half the patterns within 5° of the boundary;
``"uniform"`` draws ``V`` uniformly on S².
"""

from __future__ import annotations

import math

import numpy as np

from models import quaternion as quat


class ConeOracle:
    """Exact corrective constraint of a circular (cone) swing boundary.

    Parameters
    ----------
    centre : (3,) float
        Boundary centre direction in the parent frame (normalised).
    radius_deg : float
        Cone half-angle in degrees, in (0, 180).
    """

    def __init__(self, centre, radius_deg: float):
        self.centre = quat.check_vectors(centre, name="centre")
        self.radius = math.radians(float(radius_deg))

    def _theta(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        d = quat.limb_direction(q)
        return d, quat.angle_between(d, self.centre)

    def signed_distance(self, q: np.ndarray) -> np.ndarray:
        """(N,) radians: ``θ - r`` (negative inside, positive = correction angle outside)."""
        _, th = self._theta(np.asarray(q, dtype=np.float64))
        return th - self.radius

    def is_valid(self, q: np.ndarray) -> np.ndarray:
        """(N,) bool."""
        return self.signed_distance(q) <= 0.0

    def correction(self, q: np.ndarray) -> np.ndarray:
        """(N, 4) corrective quaternion, ``w ≥ 0``, identity when valid (eq. 64-67)."""
        q = np.asarray(q, dtype=np.float64).reshape(-1, 4)
        d, th = self._theta(q)
        dtheta = np.maximum(th - self.radius, 0.0)
        axis = np.cross(d, self.centre)
        n = np.linalg.norm(axis, axis=1, keepdims=True)
        perp = quat._perpendicular(np.broadcast_to(self.centre, d.shape))
        axis = np.where(n > 1e-12, axis / np.maximum(n, 1e-300), perp)
        return quat.from_axis_angle(axis, dtheta)

    def project(self, q: np.ndarray) -> np.ndarray:
        """(N, 4) nearest valid orientation, ``correction(q) ⊗ q``."""
        q = np.asarray(q, dtype=np.float64).reshape(-1, 4)
        return quat.multiply(self.correction(q), q)


def _directions_in_zone(n, centre, lo, hi, rng):
    """``n`` unit vectors with angle to ``centre`` in [lo, hi], area-uniform."""
    c = rng.uniform(math.cos(hi), math.cos(lo), n)
    phi = rng.uniform(0.0, 2.0 * math.pi, n)
    s = np.sqrt(np.clip(1.0 - c * c, 0.0, None))
    e1 = quat._perpendicular(centre)
    e2 = np.cross(centre, e1)
    return (c[:, None] * centre + s[:, None] * (np.cos(phi)[:, None] * e1
                                                + np.sin(phi)[:, None] * e2))


def cone_patterns(
    n: int,
    centre,
    radius_deg: float,
    rng: np.random.Generator,
    *,
    distribution: str = "even",
    order: str = "valid-first",
) -> tuple[np.ndarray, np.ndarray]:
    """Training patterns of a regular boundary (eq. 59-68).

    Parameters
    ----------
    n : int
        Number of patterns.
    centre : (3,) float
        Boundary centre (normalised).
    radius_deg : float
        Boundary radius, degrees.
    rng : numpy Generator
    distribution : {"even", "clustered", "uniform"}
    order : {"valid-first", "random", "reversed"}
        Pattern order (thesis TABLE X); irrelevant to batch RPROP except through the GA's
        train/validation split, which callers take as contiguous blocks.

    Returns
    -------
    inputs : (n, 4) float64
        Twist-free orientations ``Qi`` (w ≥ 0).
    targets : (n, 4) float64
        Corrective quaternions ``Qo``.
    """
    c = quat.check_vectors(centre, name="centre")
    r = math.radians(radius_deg)
    if distribution == "uniform":
        v = quat.random_unit_vectors(n, rng)
    elif distribution in ("even", "clustered"):
        b = min(math.radians(10.0), r / 2, (math.pi - r) / 2)
        if distribution == "even":
            zones = [(0.0, r - b), (r - b, r), (r, r + b), (r + b, math.pi)]
            counts = [n // 4 + (1 if k < n % 4 else 0) for k in range(4)]
        else:
            b5 = min(math.radians(5.0), r / 2, (math.pi - r) / 2)
            zones = [(0.0, r - b5), (r - b5, r), (r, r + b5), (r + b5, math.pi)]
            near = n // 4
            counts = [n // 4 - n // 8, near, near, 0]
            counts[3] = n - sum(counts)
        v = np.concatenate([_directions_in_zone(k, c, lo, hi, rng)
                            for k, (lo, hi) in zip(counts, zones, strict=True)])
    else:
        raise ValueError(f"distribution must be even, clustered or uniform, got {distribution!r}")
    qi = quat.from_two_vectors(np.broadcast_to(quat.LIMB_AXIS, v.shape), v)
    oracle = ConeOracle(c, radius_deg)
    qo = oracle.correction(qi)
    valid = oracle.is_valid(qi)
    if order == "valid-first":
        idx = np.concatenate((np.flatnonzero(valid), np.flatnonzero(~valid)))
        idx = np.concatenate((rng.permutation(idx[: valid.sum()]),
                              rng.permutation(idx[valid.sum():])))
    elif order == "random":
        idx = rng.permutation(n)
    elif order == "reversed":
        idx = np.concatenate((rng.permutation(np.flatnonzero(~valid)),
                              rng.permutation(np.flatnonzero(valid))))
    else:
        raise ValueError(f"order must be valid-first, random or reversed, got {order!r}")
    return qi[idx], qo[idx]
