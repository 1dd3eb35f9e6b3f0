"""Held-out evaluation of corrective constraints: test orientations, boundary sets, metrics.

One function for every caller (``rig evaluate``, ``benchmarks/``, the demo), a joint's model
or a limb's (a one-joint constraint is a limb of one joint): :func:`evaluate_model` scores a
model — a :class:`models.onnx_io.CorrectionModel` or any ``(N, 4) → (N, 4)`` callable (a
limb's: ``(N, J, 4) → (N, J, 4)``) — on :func:`held_out_orientations` (a limb's:
:func:`models.limb_evaluation.held_out_postures`) with the metrics of
:func:`models.metrics.evaluate` (3-D error, violations, identity error, p99 direction error; a
limb's at its end point).

Held-out orientations (issue 9's protocol)
------------------------------------------
Half uniform over SO(3) with both quaternion signs (:func:`models.quaternion.random_quaternions`);
half within ``band_deg`` (20°) of the boundary, ``|oracle.signed_distance(q)| ≤ band`` — the
oracle's signed distance combines swing and twist (correction angle outside, −min(swing margin,
twist margin) inside) — drawn by rejection from uniform orientations, with random signs.

Held-out boundaries
-------------------
:func:`irregular_boundaries`: the five thesis shapes (:mod:`models.shapes`) with twist limits
added, and seeded random concave star-shaped spherical polygons (:func:`random_star_polygon`)
around random centres, with twist intervals of random width and centre. :func:`regular_boundaries`:
cones of radius 5-150° about +X, +Y, +Z without twist (the thesis's regular set). Neither set is
used to choose any parameter of a method: methods are tuned on other seeds.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from models import metrics as M
from models import quaternion as quat
from models.constraint import JointConstraint
from models.limb import Limb
from models.limb_evaluation import held_out_postures
from models.oracle import ConstraintOracle
from models.shapes import SHAPES, load_shape

__all__ = [
    "RADII_DEG",
    "SHAPE_TWISTS_DEG",
    "evaluate_model",
    "held_out_orientations",
    "irregular_boundaries",
    "random_star_polygon",
    "regular_boundaries",
    "summarise",
]

#: Cone radii of the regular set (thesis ch. 5).
RADII_DEG = (5, 20, 45, 90, 135, 150)
#: Twist limits (degrees) added to the five thesis shapes in the irregular set.
SHAPE_TWISTS_DEG = {"original": (-45.0, 70.0), "small": (-30.0, 30.0), "large": (-90.0, 60.0),
                    "c-shape": (-20.0, 110.0), "highly-irregular": (-120.0, 10.0)}
#: Default seed of the random star polygons (held out: no method is tuned on it).
HELD_OUT_SEED = 9_000



def held_out_orientations(constraint, n: int, rng: np.random.Generator | int, *,
                          band_deg: float = 20.0, oracle=None) -> np.ndarray:
    """Test orientations (n, 4): half uniform on SO(3), half within ``band_deg`` of the boundary.

    Parameters
    ----------
    constraint : JointConstraint
    n : int, >= 2
    rng : Generator or int seed
    band_deg : float
        Half-width of the near-boundary band, degrees (|signed distance| ≤ band).
    oracle : ConstraintOracle, optional

    Returns
    -------
    (n, 4) float64, unit, scalar-first, both signs, shuffled.
    """
    rng = np.random.default_rng(rng)
    oracle = oracle or ConstraintOracle(constraint)
    n_uni = n // 2
    n_near = n - n_uni
    uni = quat.random_quaternions(n_uni, rng)
    band = math.radians(band_deg)
    near: list[np.ndarray] = []
    have = 0
    for _ in range(1000):
        c = quat.random_quaternions(max(4 * n_near, 4096), rng)
        keep = c[np.abs(oracle.signed_distance(c)) <= band]
        near.append(keep)
        have += len(keep)
        if have >= n_near:
            break
    else:
        raise ValueError(f"band_deg: too few orientations within {band_deg}° of the boundary")
    q = np.concatenate([uni, np.concatenate(near)[:n_near]])
    return q[rng.permutation(len(q))]


def random_star_polygon(rng: np.random.Generator | int, *, name: str = "star",
                        twist: bool = True):
    """A seeded random concave star-shaped swing polygon, optionally with a twist interval.

    ``K`` ∈ [10, 28] vertices at increasing azimuth ``φ_k`` (jittered) about a random centre
    ``c``; radius ``ρ(φ)`` = base 25-65° plus two or three lobes and 1-2 notches (depth
    25-60 % of the base, width 20-50°), clipped to [8°, 110°]; the polygon is star-shaped about
    ``c``, hence simple, and concave wherever a notch is. Twist: centre ∈ [−80°, 80°], half-width
    ∈ [20°, 100°] (within ±180°).

    Returns
    -------
    JointConstraint
    """

    rng = np.random.default_rng(rng)
    k = int(rng.integers(10, 29))
    phi = np.sort((np.arange(k) + rng.uniform(-0.3, 0.3, k)) * 2 * np.pi / k)
    base = rng.uniform(25, 65)
    rho = np.full(k, base)
    for _ in range(int(rng.integers(2, 4))):
        rho += base * rng.uniform(0.05, 0.25) * np.cos(int(rng.integers(1, 5)) * phi
                                                       + rng.uniform(0, 2 * np.pi))
    for _ in range(int(rng.integers(1, 3))):
        at, width = rng.uniform(0, 2 * np.pi), math.radians(rng.uniform(20, 50))
        dphi = np.angle(np.exp(1j * (phi - at)))
        rho -= base * rng.uniform(0.25, 0.6) * np.exp(-0.5 * (dphi / (0.5 * width)) ** 2)
    rho = np.radians(np.clip(rho, 8, 110))
    c = quat.random_unit_vectors(1, rng)[0]
    e1 = quat.perpendicular(c)
    e2 = quat.cross(c, e1)
    verts = (np.cos(rho)[:, None] * c
             + np.sin(rho)[:, None] * (np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2))
    tw = None
    if twist:
        mid, half = rng.uniform(-80, 80), rng.uniform(20, 100)
        tw = (max(mid - half, -180.0), min(mid + half, 180.0))
    return JointConstraint.polygon(verts, c, twist=tw, name=name)


def irregular_boundaries(n_random: int = 20, seed: int = HELD_OUT_SEED) -> dict[str, Any]:
    """The irregular held-out set: five thesis shapes with twist plus ``n_random`` stars.

    Returns
    -------
    dict name → JointConstraint (insertion-ordered: shapes first).
    """

    out: dict[str, Any] = {}
    for s in SHAPES:
        c = load_shape(s)
        out[f"{s} +twist"] = JointConstraint.polygon(c.swing.vertices, c.swing.interior,
                                                     twist=SHAPE_TWISTS_DEG[s],
                                                     name=f"{s}-twist", limb_axis=c.limb_axis)
    for i in range(n_random):
        out[f"star {seed + i}"] = random_star_polygon(seed + i, name=f"star-{seed + i}")
    return out


def regular_boundaries(radii=RADII_DEG) -> dict[str, Any]:
    """Cones about +X, +Y, +Z of the given radii (degrees), no twist: dict name → constraint."""

    return {f"cone {ax} {r}°": JointConstraint.cone(v, r, name=f"cone-{ax}-{r}")
            for ax, v in (("X", [1, 0, 0]), ("Y", [0, 1, 0]), ("Z", [0, 0, 1]))
            for r in radii}


def _predictor(model) -> Callable[[np.ndarray], np.ndarray]:
    if hasattr(model, "correction"):
        return model.correction
    if hasattr(model, "predict"):
        return model.predict
    if callable(model):
        return model
    raise TypeError(f"model: expected a CorrectionModel (models.onnx_io.load_model), an object "
                    f"with predict or a callable, got {model!r}")


def evaluate_model(model, constraint, *, n: int = 10_000, seed: int = 12_345,
                   q: np.ndarray | None = None, band_deg: float = 20.0,
                   oracle=None) -> dict[str, Any]:
    """Metrics of a model on held-out orientations of ``constraint`` (a limb's postures).

    Parameters
    ----------
    model : CorrectionModel, object with ``predict`` or callable
        An ONNX model opened with :func:`models.onnx_io.load_model` runs through onnxruntime.
    constraint : JointConstraint or Limb
    n, seed, band_deg
        :func:`held_out_orientations` parameters (a limb's:
        :func:`models.limb_evaluation.held_out_postures`; ignored when ``q`` is given).
    q : (N, 4) array, optional
        Orientations to use instead (e.g. the same set for several models); a limb's postures
        (N, J, 4).
    oracle : ConstraintOracle, optional
        The exact oracle of ``constraint`` (built when not given).

    Returns
    -------
    dict: :func:`models.metrics.evaluate`'s metrics, a joint's plus ``valid_fraction``.
    """
    oracle = oracle or ConstraintOracle(constraint)
    if isinstance(constraint, Limb):
        if q is None:
            q = held_out_postures(constraint, n, seed, band_deg=band_deg, oracle=oracle)
        return M.evaluate(_predictor(model), oracle, q)
    if q is None:
        q = held_out_orientations(constraint, n, seed, band_deg=band_deg, oracle=oracle)
    out = M.evaluate(_predictor(model), oracle, q)
    out["valid_fraction"] = float(np.mean(oracle.is_valid(q)))
    return out


#: Metric keys of the issue's target table, in order, with labels.
TARGET_METRICS = (
    ("mean_3d_error_pct", "mean 3-D error %"),
    ("frac_invalid_violating_1deg", "invalid > 1° out"),
    ("mean_identity_error_deg", "identity err °"),
    ("p99_angular_error_deg", "p99 dir err °"),
)


def summarise(rows: list[dict[str, float]]) -> dict[str, float]:
    """Mean of each metric over boundaries, plus the worst ``max_violation_deg``."""
    keys = set().union(*rows) if rows else set()
    out = {k: float(np.mean([r[k] for r in rows if k in r])) for k in keys}
    if rows and "max_violation_deg" in keys:
        out["max_violation_deg"] = float(max(r["max_violation_deg"] for r in rows))
    return out
