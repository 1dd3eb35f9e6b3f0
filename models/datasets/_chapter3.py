r"""Chapter 3 vector-field datasets: 1-D interval, 2-D/3-D ball, circle on the unit sphere.

Maths (thesis § 3.1.1)
----------------------
*1-D, Euler-angle interval* (eq. 45-47). ``P`` uniform on ``span`` (default [-1, 1])::

    P valid  iff  lower < P < upper                               (eq. 45)
    C = lower - P          if P <= lower                          (eq. 46)
    C = upper - P          if P >= upper    (additive convention)
    C = P - upper          if P >= upper    (convention="thesis", eq. 47 as printed)

The thesis prints eq. 47 as ``C = P − upper``, a positive magnitude, while eq. 46 (``lower − P``,
also positive) and eq. 49 below are *additive* corrections (``P + C`` is the corrected value).
The default ``convention="additive"`` makes both cases additive, so ``P + C`` is always the
nearer bound; ``convention="thesis"`` reproduces the printed equations (``|C|`` is the same).

*2-D / 3-D ball* (eq. 48-49). Components of ``V`` uniform in [-1, 1]::

    V invalid  iff  |V| > R                                       (eq. 48)
    C = -V (1 - R/|V|)      (so V + C = R V/|V|, on the sphere)   (eq. 49)

*Circle on the unit sphere* (eq. 50-56). ``V`` uniform on S², ``C`` the circle's centre (the
thesis uses +X), ``θ = ∠(V, C)``; valid iff ``θ <= θmax``; otherwise ``V`` is rotated towards
``C`` by ``Δθ = θ − θmax`` about ``V × C``::

    Qo = [cos(Δθ/2), (V × C)/|V × C| sin(Δθ/2)]                  (eq. 52-55)
    O  = V' - V,   V' = Qo V Qo*      (vector correction, additive like eq. 49; eq. 56)

:func:`sphere_vector_dataset` outputs ``O``, :func:`sphere_quaternion_dataset` outputs ``Qo``
(``w >= 0``, identity when valid). Both are computed by the exact oracle
(:class:`models.oracle.ConstraintOracle` of a cone constraint), which implements the same
closed form.

Region labels (thesis Fig. 34) use the signed distance: ``max(lower − P, P − upper)`` in 1-D,
``|V| − R`` for the ball, ``θ − θmax`` (radians) on the sphere.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from models import quaternion as Q
from models.constraint import JointConstraint
from models.datasets._common import (
    check_choice,
    check_n,
    check_number,
    label_regions,
    make_rng,
)
from models.datasets._dataset import Dataset, dataset_meta
from models.errors import ConstraintError, DatasetError
from models.oracle import ConstraintOracle

__all__ = [
    "ball_dataset",
    "cone_constraint",
    "interval_dataset",
    "sphere_quaternion_dataset",
    "sphere_vector_dataset",
]


def interval_dataset(
    n: int,
    rng: np.random.Generator | int,
    lower: float = -0.5,
    upper: float = 0.5,
    *,
    span: tuple[float, float] = (-1.0, 1.0),
    band: float | None = None,
    convention: str = "additive",
) -> Dataset:
    """1-D interval constraint patterns (thesis eq. 45-47).

    Parameters
    ----------
    n : int
        Number of patterns, > 0.
    rng : numpy Generator or int seed
    lower, upper : float
        Bounds of the valid interval, ``lower < upper``, both inside ``span``.
    span : (float, float)
        ``P`` is drawn uniformly from this interval.
    band : float, optional
        Width of the near-boundary regions for the labels; default ``min(0.1, (upper -
        lower)/4)``.
    convention : {"additive", "thesis"}
        Sign of the correction above ``upper`` (see the module docstring).

    Returns
    -------
    Dataset
        ``inputs`` (n, 1) P; ``targets`` (n, 1) C; ``regions`` labelled.
    """
    n = check_n(n)
    convention = check_choice(convention, "convention", ("additive", "thesis"))
    try:
        s0, s1 = (float(x) for x in span)
    except (TypeError, ValueError) as err:
        raise DatasetError(f"span: expected two numbers (low, high), got {span!r}") from err
    if not (math.isfinite(s0) and math.isfinite(s1) and s0 < s1):
        raise DatasetError(f"span: expected low < high, got {span!r}")
    lower = check_number(lower, "lower", s0, s1, closed=True)
    upper = check_number(upper, "upper", s0, s1, closed=True)
    if not lower < upper:
        raise DatasetError(f"lower: must be less than upper, got lower={lower:g} upper={upper:g}")
    band = min(0.1, (upper - lower) / 4) if band is None else check_number(band, "band", 0, s1 - s0)
    rng, rng_meta = make_rng(rng)
    p = rng.uniform(s0, s1, n)
    valid = (p > lower) & (p < upper)  # eq. 45
    below = p <= lower
    above = p >= upper
    c = np.zeros(n)
    c[below] = lower - p[below]  # eq. 46
    c[above] = (upper - p[above]) if convention == "additive" else (p[above] - upper)  # eq. 47
    dist = np.maximum(lower - p, p - upper)
    regions = label_regions(valid, dist, band)
    gen = {
        "n": n,
        "lower": lower,
        "upper": upper,
        "span": [s0, s1],
        "band": band,
        "convention": convention,
    }
    return Dataset(p[:, None], c[:, None], dataset_meta("interval", gen, rng_meta), regions)


def ball_dataset(
    n: int,
    rng: np.random.Generator | int,
    dim: int = 2,
    radius: float = 0.5,
    *,
    band: float | None = None,
) -> Dataset:
    """2-D disc or 3-D ball constraint patterns (thesis eq. 48-49).

    Parameters
    ----------
    n : int
        Number of patterns, > 0.
    rng : numpy Generator or int seed
    dim : {2, 3}
    radius : float
        ``R``, in ``(0, √dim)`` (the cube [-1, 1]^dim must have both valid and invalid points;
        the thesis's chapter 5 3-D case uses 0.125).
    band : float, optional
        Near-boundary width for the labels; default ``min(0.1, R/2)``.

    Returns
    -------
    Dataset
        ``inputs`` (n, dim) V; ``targets`` (n, dim) C (zero when valid); ``regions``.
    """
    n = check_n(n)
    if dim not in (2, 3) or isinstance(dim, bool):
        raise DatasetError(f"dim: must be 2 or 3, got {dim!r}")
    radius = check_number(radius, "radius", 0.0, math.sqrt(dim))
    band = min(0.1, radius / 2) if band is None else check_number(band, "band", 0.0, 2.0)
    rng, rng_meta = make_rng(rng)
    v = rng.uniform(-1.0, 1.0, (n, dim))
    norm = np.linalg.norm(v, axis=1)
    invalid = norm > radius  # eq. 48
    c = np.zeros_like(v)
    c[invalid] = -v[invalid] * (1.0 - radius / norm[invalid])[:, None]  # eq. 49
    regions = label_regions(~invalid, norm - radius, band)
    gen = {"n": n, "dim": dim, "radius": radius, "band": band}
    return Dataset(v, c, dataset_meta(f"ball{dim}", gen, rng_meta), regions)


def cone_constraint(centre: Any = (1.0, 0.0, 0.0), radius_deg: float = 45.0) -> JointConstraint:
    """A cone (regular boundary) constraint, with :class:`DatasetError` for bad arguments.

    Parameters
    ----------
    centre : (3,) array_like
        Boundary centre, parent frame (normalised).
    radius_deg : float
        Cone radius in degrees, in (0, 180) (the thesis uses 5-150).
    """
    radius_deg = check_number(radius_deg, "radius_deg", 0.0, 180.0)
    try:
        c = np.asarray(centre, dtype=np.float64)
    except (TypeError, ValueError) as err:
        raise DatasetError(f"centre: expected a 3-vector, got {centre!r}") from err
    if c.shape != (3,) or not np.isfinite(c).all() or np.linalg.norm(c) < 1e-12:
        raise DatasetError(f"centre: expected a non-zero finite 3-vector, got {centre!r}")
    try:
        return JointConstraint.cone(c.tolist(), radius_deg, name=f"cone-{radius_deg:g}deg")
    except ConstraintError as err:  # pragma: no cover - arguments checked above
        raise DatasetError(str(err)) from err


def _sphere(
    kind: str, n: int, rng: Any, centre: Any, radius_deg: float, band_deg: float | None
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict]:
    n = check_n(n)
    constraint = cone_constraint(centre, radius_deg)
    r = math.radians(radius_deg)
    if band_deg is None:
        band = min(math.radians(10.0), r / 2, (math.pi - r) / 2)
    else:
        band = math.radians(check_number(band_deg, "band_deg", 0.0, 90.0))
    rng, rng_meta = make_rng(rng)
    oracle = ConstraintOracle(constraint)
    v = Q.random_unit_vectors(n, rng)  # eq. 50: random unit V
    dist = oracle.swing_distance(v)  # θ - θmax
    b = oracle.nearest_swing_point(v)  # V rotated towards C by Δθ (eq. 52-55); V when valid
    regions = label_regions(dist <= 0.0, dist, band)
    gen = {
        "n": n,
        "centre": constraint.swing.centre.tolist(),  # type: ignore[union-attr]
        "radius_deg": float(radius_deg),
        "band_deg": math.degrees(band),
    }
    meta = dataset_meta(
        kind, gen, rng_meta, constraint=constraint.to_yaml(), constraint_name=constraint.name
    )
    return v, b, dist, regions, meta


def sphere_vector_dataset(
    n: int,
    rng: np.random.Generator | int,
    centre: Any = (1.0, 0.0, 0.0),
    radius_deg: float = 45.0,
    *,
    band_deg: float | None = None,
) -> Dataset:
    """Circle-on-the-sphere patterns with a vector correction (thesis eq. 50-56, Fig. 5a).

    Parameters
    ----------
    n : int
    rng : numpy Generator or int seed
    centre : (3,) array_like
        Circle centre ``C`` (thesis: +X).
    radius_deg : float
        ``θmax`` in degrees, (0, 180).
    band_deg : float, optional
        Near-boundary width for the labels; default ``min(10°, θmax/2, (180° − θmax)/2)``.

    Returns
    -------
    Dataset
        ``inputs`` (n, 3) unit V; ``targets`` (n, 3) ``O = V' − V`` (zero when valid).
    """
    v, b, dist, regions, meta = _sphere("sphere-vector", n, rng, centre, radius_deg, band_deg)
    return Dataset(v, np.where((dist > 0.0)[:, None], b - v, 0.0), meta, regions)  # eq. 56


def sphere_quaternion_dataset(
    n: int,
    rng: np.random.Generator | int,
    centre: Any = (1.0, 0.0, 0.0),
    radius_deg: float = 45.0,
    *,
    band_deg: float | None = None,
) -> Dataset:
    """Circle-on-the-sphere patterns with a corrective quaternion (eq. 50-55, Fig. 5b).

    Parameters are those of :func:`sphere_vector_dataset`.

    Returns
    -------
    Dataset
        ``inputs`` (n, 3) unit V; ``targets`` (n, 4) ``Qo`` scalar-first, parent frame,
        ``w >= 0``, identity when valid; ``rotate(Qo, V)`` lies on the circle.
    """
    v, b, dist, regions, meta = _sphere("sphere-quaternion", n, rng, centre, radius_deg, band_deg)
    qo = np.where((dist > 0.0)[:, None], Q.from_two_vectors(v, b), Q.IDENTITY)  # exact identity
    return Dataset(v, qo, meta, regions)
