r"""Chapter 4 quaternion datasets: orientation quaternion → corrective quaternion.

Maths (thesis § 4.1, eq. 59-68, generalised by the exact oracle)
----------------------------------------------------------------
A limb direction ``V`` (unit, parent frame) is drawn on S²; the twist-free orientation is the
minimal rotation taking the limb axis ``X`` to ``V`` (eq. 59-61)::

    Qi = [cos(α/2), (X × V)/|X × V| sin(α/2)],  α = acos(V·X)     (w >= 0, zero twist)

and with ``twist=True`` a twist ``φ`` about the limb axis is added, ``Qi = swing ⊗ [cos φ/2,
X sin φ/2]``. The target is the corrective quaternion of :class:`models.oracle.ConstraintOracle`
(cone: eq. 63-67; polygon: rotation to the nearest boundary point measured on the unit limb
endpoint; twist clamped to its limits)::

    Qo = project(Qi) ⊗ Qi⁻¹   (parent frame, w >= 0, identity when valid)
    corrected = Qo ⊗ Qi                                                 (eq. 68)

``Qo`` is a rotation, so ``Qi`` and ``−Qi`` have the same target; every target is returned with
``w >= 0``, whatever the sign chosen for its input.

Distributions (thesis § 5.1.5, Fig. 34)
---------------------------------------
Patterns fall in four regions by the oracle's signed distance ``s`` (radians; > 0 outside =
the correction angle, <= 0 inside = minus the margin) and a band width ``b``: inner valid
(``s <= −b``), valid near boundary (``−b < s <= 0``), invalid near boundary (``0 < s <= b``),
outer invalid (``s > b``).

- ``"even"``: the same number of patterns (``n/4``) in each region whatever the constraint's
  size, with ``b = min(10°, depth_in/2, depth_out/2)``; ``depth_in`` is the deepest point
  inside (cone: ``r``), ``depth_out`` the farthest point outside (cone: ``180° − r``), so for a
  cone ``b = min(10°, r/2, (180° − r)/2)``.
- ``"clustered"``: the same four equal regions but with ``b = min(5°, ...)``, i.e. half the
  patterns packed in a dense band within 5° of the boundary.
- ``"uniform"``: limb directions uniform on S² (with ``twist=True``, orientations uniform on
  SO(3)); regions labelled with the ``"even"`` band.

``band_deg`` overrides the 10° / 5° default. Within a region, samples are drawn by construction
where possible and accepted by the oracle otherwise: candidate directions are area-uniform in
the annulus ``θ ∈ [θmin + s_lo, θmax + s_hi]`` around the constraint centre ``c`` (the cone
centre or the polygon's interior point; ``θmin``/``θmax`` = nearest/farthest boundary point from
``c``, which bounds where a point at signed distance ``s`` can lie), then kept if the oracle puts
them in the region. For a cone this is exact (no rejection). Batches are vectorised.

Twist (``twist=True``): without twist limits ``φ`` is uniform on (−π, π]; with limits
``[lo, hi]`` half of each candidate batch draws ``φ`` uniformly from ``[lo − w, hi + w]``
(``w = max(2b, (hi − lo)/4)``), the other half from (−π, π] (for the invalid regions with the
limb direction inside the swing region), so twist-invalid patterns are represented too.

Hemisphere (thesis § 4.2.1-4.2.2, TABLE IV)
-------------------------------------------
- ``"ambiguous"``: each input is ``q`` or ``−q`` with probability 1/2 (recorded data covers
  both halves of S³).
- ``"centre"``: every input's sign is chosen so that ``q · q_c >= 0``, where the centre
  rotation ``q_c = from_two_vectors(X, c) ⊗ [cos(m/2), X sin(m/2)]`` (``m`` = mid-twist of the
  limits with ``twist=True``, else 0). Valid points and the boundary they are corrected to are
  then on the centre's side of S³ (the thesis's fix for irregular data). For a cone centred on
  +X without twist this equals ``"w-positive"``.
- ``"w-positive"``: every input has ``w >= 0`` (:func:`models.quaternion.canonical`); the thesis
  found forcing this hurt large constraints (TABLE IV).

Orders (TABLE X): ``"valid-first"`` (valid patterns, then invalid; the thesis's best),
``"random"``, ``"reversed"`` (invalid first). Rows are shuffled within each block.
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
    equal_counts,
    label_regions,
    make_rng,
    order_index,
)
from models.datasets._dataset import REGION_NAMES, Dataset, created_by
from models.errors import DatasetError
from models.geometry import fibonacci_sphere
from models.limits import ConeSwing, PolygonSwing
from models.oracle import ConstraintOracle

__all__ = [
    "CLUSTERED_BAND_DEG",
    "DISTRIBUTIONS",
    "EVEN_BAND_DEG",
    "HEMISPHERES",
    "ORDERS",
    "common_test_set",
    "quaternion_dataset",
]

DISTRIBUTIONS: tuple[str, ...] = ("even", "clustered", "uniform")
ORDERS: tuple[str, ...] = ("valid-first", "random", "reversed")
HEMISPHERES: tuple[str, ...] = ("ambiguous", "centre", "w-positive")
#: Default near-boundary band widths (degrees) of the "even" and "clustered" distributions.
EVEN_BAND_DEG = 10.0
CLUSTERED_BAND_DEG = 5.0

_MAX_ROUNDS = 60
_MAX_BATCH = 400_000
_GIVE_UP = 2_000_000  # candidates tried without a single hit: the region is empty
_X = np.array([1.0, 0.0, 0.0])


def _wrap(x: np.ndarray) -> np.ndarray:
    return np.mod(x + math.pi, 2.0 * math.pi) - math.pi


class _Sampler:
    """Region-by-region sampling of one constraint (see the module docstring)."""

    def __init__(self, constraint: JointConstraint, twist: bool, rng: np.random.Generator):
        self.oracle = ConstraintOracle(constraint)
        self.axis = self.oracle.axis
        self.twist = twist
        self.rng = rng
        swing = constraint.swing
        tw = constraint.twist
        self.limits = (tw.min, tw.max) if tw is not None else None
        if isinstance(swing, ConeSwing):
            self.centre = np.asarray(swing.centre, dtype=np.float64)
            r = swing.radius
            self.theta_min = self.theta_max = r
            depth_in, depth_out = r, math.pi - r
        elif isinstance(swing, PolygonSwing):
            self.centre = np.asarray(swing.interior, dtype=np.float64)
            self.theta_min = float(-self.oracle.swing_distance(self.centre))
            v0 = swing.vertices
            v1 = np.roll(v0, -1, axis=0)
            t = np.linspace(0.0, 1.0, 33)[:, None, None]
            pts = ((1.0 - t) * v0 + t * v1).reshape(-1, 3)
            pts /= np.linalg.norm(pts, axis=1, keepdims=True)
            edge = float(Q.angle_between(v0, v1).max())
            self.theta_max = float(Q.angle_between(pts, self.centre).max()) + edge / 32 + 1e-9
            # the spiral turning the other way (y mirrored), as this generator always used
            grid = np.concatenate((fibonacci_sphere(4000) * (1.0, -1.0, 1.0),
                                   [self.centre, -self.centre]))
            s = self.oracle.swing_distance(grid)
            depth_in, depth_out = float(-s.min()), float(s.max())
        else:  # twist-only constraint: limb directions are unconstrained
            self.centre = self.axis.copy()
            self.theta_min, self.theta_max = 0.0, math.pi
            depth_in, depth_out = math.inf, 0.0
        if self.limits is not None:
            lo, hi = self.limits
            if twist:
                depth_in = min(depth_in, (hi - lo) / 2)
                depth_out = max(depth_out, math.pi - (hi - lo) / 2)
            else:  # twist-free inputs have φ = 0: its margin caps the depth inside
                depth_in = min(depth_in, -lo, hi)
        self.depth_in, self.depth_out = depth_in, depth_out
        mid = 0.5 * (self.limits[0] + self.limits[1]) if (self.limits and twist) else 0.0
        self.centre_rotation = Q.multiply(
            Q.from_two_vectors(self.axis, self.centre), Q.from_axis_angle(self.axis, mid)
        )
        self._to_centre = Q.from_two_vectors(_X, self.centre)

    # -- proposals ------------------------------------------------------------------------
    def _annulus(self, m: int, lo: float, hi: float) -> np.ndarray:
        """``m`` directions area-uniform with angle in [lo, hi] from the centre."""
        lo, hi = max(lo, 0.0), min(hi, math.pi)
        cos_t = self.rng.uniform(math.cos(hi), math.cos(lo), m)
        az = self.rng.uniform(-math.pi, math.pi, m)
        sin_t = np.sqrt(np.clip(1.0 - cos_t * cos_t, 0.0, None))
        d = np.stack((cos_t, sin_t * np.cos(az), sin_t * np.sin(az)), axis=1)
        return Q.rotate(self._to_centre, d)

    def _twists(self, m: int, broad: bool, band: float) -> np.ndarray:
        if not self.twist:
            return np.zeros(m)
        if self.limits is None or broad:
            return self.rng.uniform(-math.pi, math.pi, m)
        lo, hi = self.limits
        w = max(2.0 * band, (hi - lo) / 4)
        if hi - lo + 2 * w >= 2 * math.pi:
            return self.rng.uniform(-math.pi, math.pi, m)
        return _wrap(self.rng.uniform(lo - w, hi + w, m))

    def orientations(self, d: np.ndarray, phi: np.ndarray) -> np.ndarray:
        """``from_two_vectors(axis, d) ⊗ twist(φ)`` (eq. 59-61, plus the twist)."""
        swing = Q.from_two_vectors(np.broadcast_to(self.axis, d.shape), d)
        if not self.twist:
            return swing
        return Q.multiply(swing, Q.from_axis_angle(self.axis, phi))

    def _propose(self, k: int, m: int, band: float) -> np.ndarray:
        s_lo = (-math.inf, -band, 0.0, band)[k]
        s_hi = (-band, 0.0, band, math.inf)[k]
        lo, hi = self.theta_min + s_lo, self.theta_max + s_hi
        if self.twist and self.limits is not None:
            m_b = m // 2
            m_a = m - m_b
            d = np.concatenate(
                (
                    self._annulus(m_a, lo, hi),
                    self._annulus(m_b, lo, hi)
                    if k < 2
                    else self._annulus(m_b, 0.0, self.theta_max),
                )
            )
            phi = np.concatenate((self._twists(m_a, False, band), self._twists(m_b, True, band)))
        else:
            d = self._annulus(m, lo, hi)
            phi = self._twists(m, False, band)
        return self.orientations(d, phi)

    def region(self, k: int, count: int, band: float) -> np.ndarray:
        """``count`` orientations whose oracle region is ``k`` (rejection by batches)."""
        parts: list[np.ndarray] = []
        have, rate, tried = 0, 1.0, 0
        for _ in range(_MAX_ROUNDS):
            if have >= count or (have == 0 and tried >= _GIVE_UP):
                break
            need = count - have
            m = int(min(_MAX_BATCH, max(64, math.ceil(1.25 * need / max(rate, 1e-4)))))
            q = self._propose(k, m, band)
            tried += m
            res = self.oracle.evaluate(q)
            hit = q[label_regions(res.valid, res.distance, band) == k]
            rate = max(len(hit), 0.5) / m
            parts.append(hit[:need])
            have += len(parts[-1])
        if have < count:
            raise DatasetError(
                f"distribution: cannot fill region {REGION_NAMES[k]!r} of this constraint "
                f"({have} of {count} patterns found); the region is empty or too thin"
            )
        return np.concatenate(parts)


def quaternion_dataset(
    constraint: JointConstraint,
    n: int,
    rng: np.random.Generator | int,
    *,
    distribution: str = "even",
    order: str = "valid-first",
    hemisphere: str = "ambiguous",
    twist: bool = False,
    band_deg: float | None = None,
) -> Dataset:
    """Orientation → corrective-quaternion patterns of a joint constraint (thesis ch. 4).

    Parameters
    ----------
    constraint : JointConstraint
        Regular boundary (cone, e.g. :func:`cone_constraint`) or irregular (polygon, e.g.
        :func:`models.shapes.load_shape`), optionally with twist limits.
    n : int
        Number of patterns, > 0.
    rng : numpy Generator or int seed
        The same seed (or generator state) gives identical arrays.
    distribution : {"even", "clustered", "uniform"}
    order : {"valid-first", "random", "reversed"}
    hemisphere : {"ambiguous", "centre", "w-positive"}
    twist : bool
        False: twist-free inputs as in the thesis (``w >= 0`` before the hemisphere rule, zero
        twist). True: full 3-DOF inputs with a random twist.
    band_deg : float, optional
        Near-boundary band width in degrees, (0, 90); default 10 ("even", "uniform") or 5
        ("clustered"), capped at half the constraint's inside and outside depths.

    Returns
    -------
    Dataset
        ``inputs`` (n, 4) orientation quaternions (scalar-first, limb relative to parent);
        ``targets`` (n, 4) corrective quaternions (parent frame, ``w >= 0``, identity when
        valid); ``regions`` (n,) labels; ``meta`` with the constraint YAML and parameters.

    Raises
    ------
    DatasetError
        Bad ``n``, unknown option, ``band_deg`` out of range, not a constraint, or a region
        that cannot be filled (e.g. twist limits that exclude zero with ``twist=False``).
    """
    if not isinstance(constraint, JointConstraint):
        raise DatasetError(
            f"constraint: expected a JointConstraint, got {type(constraint).__name__}"
        )
    n = check_n(n)
    distribution = check_choice(distribution, "distribution", DISTRIBUTIONS)
    order = check_choice(order, "order", ORDERS)
    hemisphere = check_choice(hemisphere, "hemisphere", HEMISPHERES)
    if not isinstance(twist, (bool, np.bool_)):
        raise DatasetError(f"twist: expected True or False, got {twist!r}")
    default_band = CLUSTERED_BAND_DEG if distribution == "clustered" else EVEN_BAND_DEG
    requested = default_band if band_deg is None else check_number(band_deg, "band_deg", 0, 90)
    rng, rng_meta = make_rng(rng)
    sampler = _Sampler(constraint, bool(twist), rng)
    if not sampler.depth_in > 1e-6:
        raise DatasetError(
            "constraint: no orientation of the requested kind is valid "
            "(twist limits exclude zero twist? use twist=True)"
        )
    if not sampler.depth_out > 1e-6:
        raise DatasetError(
            "constraint: no orientation of the requested kind is invalid "
            "(a twist-only constraint needs twist=True)"
        )
    band = min(math.radians(requested), sampler.depth_in / 2, sampler.depth_out / 2)
    if distribution == "uniform":
        if twist:
            q = Q.random_quaternions(n, rng)
        else:
            q = sampler.orientations(Q.random_unit_vectors(n, rng), np.zeros(n))
    else:
        q = np.concatenate(
            [sampler.region(k, c, band) for k, c in enumerate(equal_counts(n, 4)) if c]
        )
    # hemisphere rule (inputs only: the correction is a rotation, the same for q and -q)
    if hemisphere == "ambiguous":
        q = q * rng.choice(np.array([-1.0, 1.0]), size=n)[:, None]
    elif hemisphere == "centre":
        q = np.where((q @ sampler.centre_rotation < 0.0)[:, None], -q, q)
    else:
        q = Q.canonical(q)
    res = sampler.oracle.evaluate(q)
    regions = label_regions(res.valid, res.distance, band)
    idx = order_index(res.valid, order, rng)
    meta = {
        "kind": "quaternion",
        "constraint": constraint.to_yaml(),
        "constraint_name": constraint.name,
        "generator": {
            "n": n,
            "distribution": distribution,
            "order": order,
            "hemisphere": hemisphere,
            "twist": bool(twist),
            "band_deg": math.degrees(band),
            "band_deg_requested": requested,
        },
        **rng_meta,
        "created_by": created_by(),
        "region_names": list(REGION_NAMES),
        "centre_rotation": sampler.centre_rotation.tolist(),
        "inputs": "orientation quaternion (w, x, y, z), limb relative to parent",
        "targets": "corrective quaternion (w, x, y, z), parent frame, w >= 0; "
        "corrected = target ⊗ input",
    }
    return Dataset(q[idx], res.correction[idx], meta, regions[idx])


def common_test_set(
    constraint: JointConstraint,
    rng: np.random.Generator | int,
    n: int = 3000,
    **kwargs: Any,
) -> Dataset:
    """The thesis's common test set: ``n`` (3000) unseen patterns of ``constraint``.

    Keyword arguments go to :func:`quaternion_dataset` (default: even distribution, the
    default order and hemisphere). Use a seed different from the training data's.
    ``meta["role"]`` is ``"common-test"``.
    """
    ds = quaternion_dataset(constraint, n, rng, **kwargs)
    ds.meta["role"] = "common-test"
    return ds
