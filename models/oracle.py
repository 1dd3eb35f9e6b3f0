"""The exact joint-constraint oracle: validity, nearest valid orientation, correction, distance.

One vectorised implementation, used for dataset generation, model evaluation and the live
supervisor, plus a scalar path for one orientation per control cycle that gives the same
answers.

Maths
-----
Let ``q`` be an orientation (limb relative to parent), ``a`` the limb axis (limb frame) and
``d = q a q*`` the limb direction (parent frame). Decompose ``q = swing ⊗ twist`` about ``a``
(:func:`models.quaternion.swing_twist`) and let ``φ ∈ (−π, π]`` be the twist angle
(:func:`models.quaternion.twist_angle`).

*Swing.* ``d`` must lie in the region ``S ⊂ S²`` (cone or spherical polygon,
:mod:`models.geometry`). If it does not, the limb endpoint moves along the geodesic to the
nearest boundary point ``b`` — nearness measured "by the effect on unit vectors" (thesis ch. 4),
i.e. by the angle between ``d`` and ``b``. The swing correction is the minimal rotation taking
``d`` to ``b``, expressed in the parent frame: ``Δ = [cos(θ/2), (d×b)/|d×b| sin(θ/2)]`` with
``θ = ∠(d, b)`` (thesis eq. 63-68 with the cone centre ``C``: ``b`` lies on the great circle
through ``d`` and ``C``, ``r`` from ``C``).

*Twist.* The limits ``[lo(e), hi(e)]`` are taken at the *corrected* limb direction ``e`` (``b``
when the swing was corrected, else ``d``): constant, or the kernel-weighted table of
:class:`models.constraint.SwingTwistTable` (``by_swing``). After the swing correction the twist
``φ'`` of ``Δ ⊗ q`` is clamped to them by a right-multiplied rotation about ``a`` (the limb
direction is unchanged), towards the nearer limit on the circle.

Twist intervals live on the circle: ``φ`` is inside ``[lo, hi]`` when ``φ``, ``φ − 2π`` or
``φ + 2π`` is (so a twist of exactly ``±π`` is inside ``[−π, …]`` and ``[…, π]`` alike).

So ``project(q) = Δ ⊗ q ⊗ τ`` and ``correction(q) = project(q) ⊗ q⁻¹`` (identity for a valid
``q``; returned with ``w ≥ 0``, the representative :func:`models.quaternion.canonical` picks).
For swing-only constraints the correction angle equals the angular distance ``θ`` from ``d`` to
the swing boundary. A correction of half a turn has ``w = 0`` only up to rounding, and the sign
rule then follows the rounding: the batched and the single-orientation path may return ``c``
and ``−c`` for it — the same rotation; compare corrections as rotations there.

Signed distance: for an invalid ``q``, the angle of its correction (> 0); for a valid one,
``−min(swing margin, twist margin)`` (≤ 0), where the swing margin is the angle from ``d`` to
the boundary and the twist margin ``min(φ − lo(d), hi(d) − φ)``.

Determinism at discontinuities (thesis's "correctional" and "concave-region" discontinuities)
--------------------------------------------------------------------------------------------
- Cone, ``d = −centre`` (every boundary point equidistant): ``b`` is reached by rotating about
  the axis ``centre × e`` where ``e`` is the basis vector least aligned with the centre (lowest
  index on ties) — the same rule as :func:`models.quaternion.from_two_vectors`.
- Polygon, several boundary points exactly equidistant: the edge with the lowest index wins
  (edge ``i`` joins vertices ``i`` and ``i+1``).
- Twist exactly half-way round from the allowed interval: clamped to ``max``.
- Limb within ~2e-6 rad of ``−a`` (:data:`TWIST_SINGULARITY`): the twist is undefined and not
  limited (no rotation about ``a`` could change it); such an orientation lies on the closure
  of the valid set whenever its direction is allowed.
- A point within :data:`BOUNDARY_TOLERANCE` outside counts as valid (its correction is identity).
- ``q`` and ``−q`` give the same validity, distance and correction; ``project`` keeps the sign
  of its input.

Speed
-----
A polygon's nearest edge is found through the cube-map candidate grid of
:class:`models.geometry.SphericalPolygon` (or its tree of bounding caps, where a cell's list
would be long: set-up and memory grow as M log M with the vertex count M); the
single-orientation path ranks the same candidates by the same keys as the batched one, so the
same edge wins. For a ball or two-axis joint that path is one kernel compiled by numba
(:func:`_ball_kernel`: the swing, the twist, a ``by_swing`` table's weights and the
projection, about 2-3 µs a query on the project's 2-core machine, where plain Python took
9-14 µs); a hinge's is plain Python. :meth:`ConstraintOracle.distance_projected_one` is the
control loop's query (plain floats in and out).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from models import qkernels as qk
from models import qscalar as qs
from models import quaternion as Q
from models.constraint import ConeSwing, JointConstraint, PolygonSwing, _table_limits_one
from models.geometry import (
    SphericalPolygon,
    _nearest_in_cell,
    _rank_one,
    boundary_distance,
    polygon_area,
)
from models.jit import njit

__all__ = [
    "BOUNDARY_TOLERANCE",
    "TWIST_SINGULARITY",
    "ConstraintOracle",
    "OracleResult",
    "evaluate_ball",
    "evaluate_hinge",
    "polygon_area_sr",
    "polygon_boundary_distance",
]

#: Orientations at most this far (radians) outside the boundary count as valid.
BOUNDARY_TOLERANCE = 1e-9

#: Where the twist part of ``q`` (``(w, (v·a) a)``) is shorter than this, the limb points within
#: about 2e-6 rad of ``−a`` (the swing-twist singularity): the twist is undefined there, no
#: rotation about ``a`` changes it, and the twist limit is not applied.
TWIST_SINGULARITY = 1e-6
_SING2 = TWIST_SINGULARITY**2


@dataclass(frozen=True)
class OracleResult:
    """Everything the oracle knows about a batch of orientations (arrays of length N).

    Attributes
    ----------
    valid : (N,) bool
    distance : (N,) float64, radians; > 0 outside (correction angle), <= 0 inside (-margin)
    projected : (N, 4) float64, nearest valid orientation, same sign as the input
    correction : (N, 4) float64, ``projected ⊗ q⁻¹`` with ``w >= 0``; identity when valid
        (a half-turn correction's sign is the rounding's: see the module docstring)
    swing_distance : (N,) float64, radians, signed distance of the limb direction to the swing
        boundary (negative inside; ``-inf`` when swing is unconstrained)
    twist : (N,) float64, radians, twist angle of the input about the limb axis
    """

    valid: np.ndarray
    distance: np.ndarray
    projected: np.ndarray
    correction: np.ndarray
    swing_distance: np.ndarray
    twist: np.ndarray


class ConstraintOracle:
    """Exact answers for one :class:`~models.constraint.JointConstraint`.

    Parameters
    ----------
    constraint : JointConstraint

    All methods accept ``q`` of shape ``(4,)`` or ``(N, 4)`` (scalar-first, unit norm, either
    sign; validated by :func:`models.quaternion.check_quaternions`) and return arrays with the
    matching leading shape.
    """

    def __init__(self, constraint: JointConstraint):
        self.constraint = constraint
        self.axis = np.asarray(constraint.limb_axis, dtype=np.float64)
        self._axis_t = tuple(self.axis.tolist())
        swing = constraint.swing
        if isinstance(swing, ConeSwing):
            self._swing: _ConeSolver | SphericalPolygon | None = _ConeSolver(swing)
        elif isinstance(swing, PolygonSwing):
            self._swing = SphericalPolygon(swing.vertices, swing.interior)
        else:
            self._swing = None
        tw = constraint.twist
        self._twist = (tw.min, tw.max) if tw is not None else None
        self._table = tw.by_swing if tw is not None else None
        self._kernel_args: tuple | None = None  # built by the first single-orientation query
        # can an interval reach the ±π seam (so the twist test must look across it)?
        self._wraps = tw is not None and _reaches_seam(tw.min, tw.max)
        h = constraint.hinge
        self._hinge = (None if h is None else
                       (tuple(float(v) for v in h.axis), h.min, h.max,
                        _reaches_seam(h.min, h.max)))

    # -- public API ------------------------------------------------------------------------
    def prepare(self) -> ConstraintOracle:
        """Build now what the single-orientation path needs (a polygon's grid, the compiled
        kernel loaded or compiled: seconds on a machine's first run), otherwise built by the
        first query that pays for them, so that no query of a control loop waits for it.
        Returns self."""
        if isinstance(self._swing, SphericalPolygon):
            self._swing.prepare()
        self.distance_projected_one(1.0, 0.0, 0.0, 0.0)
        return self

    def evaluate(self, q, *, normalize: bool = False) -> OracleResult:
        """Validity, distance, projection and correction in one pass.

        A single orientation (shape ``(4,)``) takes a scalar path (plain floats, one small
        numpy gather for a polygon) built for the control loop; it gives the same answers as
        the batched path.
        """
        if isinstance(q, np.ndarray) and q.shape == (4,) and q.dtype.kind in "fiu":
            return self._evaluate_one(q, normalize)
        q = Q.check_quaternions(q, normalize=normalize)
        single = q.ndim == 1
        q2 = q.reshape(-1, 4)
        res = self._evaluate(q2)
        if single:
            res = OracleResult(*(np.asarray(x)[0] for x in res.__dict__.values()))
        return res

    def is_valid(self, q, *, normalize: bool = False) -> np.ndarray:
        """True where the orientation satisfies the constraint (within tolerance)."""
        if isinstance(q, np.ndarray) and q.shape == (4,) and q.dtype.kind in "fiu":
            return self._evaluate_one(q, normalize).valid
        q2, single = self._prep(q, normalize)
        if self._hinge is not None:
            valid = self._evaluate_hinge(q2).valid
            return valid[0] if single else valid
        d = Q.rotate(q2, self.axis)
        if self._twist is None:
            valid = self._swing_dist(d) <= BOUNDARY_TOLERANCE
            return valid[0] if single else valid
        lo, hi = self._limits(d)
        valid = _twist_inside(Q.twist_angle(q2, self.axis), lo, hi, self._wraps)
        if not valid.all():
            valid |= _singular(q2, self.axis)
        # the swing's nearest-edge search (the costly part) only where the twist passes
        rows = np.flatnonzero(valid)
        if len(rows):
            valid[rows] = self._swing_dist(d[rows]) <= BOUNDARY_TOLERANCE
        return valid[0] if single else valid

    def project(self, q, *, normalize: bool = False) -> np.ndarray:
        """Nearest valid orientation (same quaternion sign as the input)."""
        return self.evaluate(q, normalize=normalize).projected

    def correction(self, q, *, normalize: bool = False) -> np.ndarray:
        """Corrective quaternion ``project(q) ⊗ q⁻¹`` (``w >= 0``, identity when valid)."""
        return self.evaluate(q, normalize=normalize).correction

    def signed_distance(self, q, *, normalize: bool = False) -> np.ndarray:
        """Signed angular distance to the boundary, radians (> 0 outside, <= 0 inside)."""
        return self.evaluate(q, normalize=normalize).distance

    def swing_distance(self, directions) -> np.ndarray:
        """Signed angular distance (radians) of limb directions (N, 3) to the swing boundary."""
        d = Q.check_vectors(directions, name="direction")
        single = d.ndim == 1
        out = self._swing_dist(d.reshape(-1, 3))
        return out[0] if single else out

    def nearest_swing_point(self, directions) -> np.ndarray:
        """Nearest point of the swing region (N, 3): the direction itself when inside."""
        d = Q.check_vectors(directions, name="direction")
        single = d.ndim == 1
        d2 = d.reshape(-1, 3)
        if self._swing is None:
            return d
        dist, b = self._swing.nearest(d2)
        out = np.where((dist > BOUNDARY_TOLERANCE)[:, None], b, d2)
        return out[0] if single else out

    def twist_limits_at(self, directions) -> tuple[np.ndarray, np.ndarray]:
        """Twist limits (radians) at limb directions (N, 3) or (3,), unit, parent frame.

        ``(lo, hi)`` arrays (N,) — floats for one direction — from the constraint's ``by_swing``
        table, else its constant interval; ``(−π, π)`` when twist is unconstrained. The oracle
        clamps the twist to these limits at the corrected limb direction.
        """
        d = Q.check_vectors(directions, name="direction")
        return self.constraint.twist_limits_at(d)

    def _limits(self, d: np.ndarray):
        """Twist limits at unit directions (N, 3): arrays for a table, floats otherwise."""
        if self._table is not None:
            return self._table.limits_at(d)
        return self._twist

    # -- internals -------------------------------------------------------------------------
    def _evaluate_one(self, q: np.ndarray, normalize: bool) -> OracleResult:
        """Scalar twin of :meth:`_evaluate` for one orientation (same maths, same tie rules)."""
        w, x, y, z = q.tolist()
        nrm = math.sqrt(w * w + x * x + y * y + z * z)
        if (
            not math.isfinite(nrm)
            or nrm < 1e-12
            or (not normalize and abs(nrm - 1.0) > Q.UNIT_TOLERANCE)
        ):
            Q.check_quaternions(q, normalize=normalize)  # raises with the precise message
        qt = (w / nrm, x / nrm, y / nrm, z / nrm)
        if self._hinge is not None:
            return self._evaluate_hinge_one(qt)
        r = self._ball_one(qt)
        return OracleResult(
            valid=np.bool_(not r[0]),
            distance=np.float64(r[1]),
            projected=np.array(r[2:6]),
            correction=np.array(r[6:10]),
            swing_distance=np.float64(r[10]),
            twist=np.float64(r[11]),
        )

    def distance_projected_one(self, w: float, x: float, y: float, z: float):
        """The control loop's query: ``(D(q), projection of q)`` for one orientation given as
        four floats (normalised here; non-finite or zero raises as :meth:`evaluate` does), in
        plain floats — :meth:`evaluate`'s answers without building its arrays."""
        nrm = math.sqrt(w * w + x * x + y * y + z * z)
        if not math.isfinite(nrm) or nrm < 1e-12:
            Q.check_quaternions(np.array([w, x, y, z]), normalize=True)  # raises
        qt = (w / nrm, x / nrm, y / nrm, z / nrm)
        if self._hinge is not None:
            r = self._evaluate_hinge_one(qt)
            p = r.projected
            return float(r.distance), (float(p[0]), float(p[1]), float(p[2]), float(p[3]))
        r = self._ball_one(qt)
        return r[1], (r[2], r[3], r[4], r[5])

    def _ball_one(self, qt):
        """The compiled ball-joint kernel (:func:`_ball_kernel`) on one unit orientation."""
        k = self._kernel_args
        if k is None:
            k = self._kernel_args = self._make_kernel_args()
        if k[1] == _SWING_CANDIDATES:  # a polygon answered by its cap tree: candidates first
            d = qs.rotate(qt, self._axis_t)
            cand = self._swing._tree.search(np.array([d]), 0.0)[1]
            k = (*k[:5], cand, *k[6:])
        return _ball_kernel(*qt, *k)

    def _make_kernel_args(self) -> tuple:
        """The kernel's view of this constraint: the swing's and twist's arrays (placeholders
        of the same types where a part is absent, so one compiled signature serves all)."""
        none_i = np.zeros(1, dtype=np.int64)
        cone = np.zeros(7)
        G, ptr, edges = 1, none_i, none_i
        table, v0, vn, orient = np.zeros((1, 5, 3)), np.zeros((1, 3)), np.zeros((1, 3)), 1.0
        sw = self._swing
        if sw is None:
            kind = _SWING_NONE
        elif isinstance(sw, _ConeSolver):
            kind = _SWING_CONE
            cone = np.array([*sw._c_t, sw.r, *sw._perp_t])
        else:
            table, v0, vn, orient = sw._table, sw.v0, sw.vertex_normal, float(sw.orient)
            if sw._lists:
                kind, G, ptr, edges = _SWING_CELLS, int(sw.G), sw.cell_ptr, sw.cell_edges
            else:
                kind = _SWING_CANDIDATES
        if self._twist is None:
            tkind, lo, hi = _TWIST_NONE, 0.0, 0.0
        else:
            tkind, (lo, hi) = _TWIST_CONSTANT, self._twist
        dirs_k, sums, kappa = np.zeros((1, 3)), np.zeros((3, 1)), 0.0
        if self._table is not None:
            tkind = _TWIST_TABLE
            dirs_k, sums, kappa = self._table._dirs_k, self._table._sums, self._table.kappa
        ax = np.array(self._axis_t)
        return (ax, kind, cone, G, ptr, edges, table, v0, vn, orient, tkind, float(lo),
                float(hi), bool(self._wraps), dirs_k, sums, float(kappa))

    def _prep(self, q, normalize):
        q = Q.check_quaternions(q, normalize=normalize)
        return q.reshape(-1, 4), q.ndim == 1

    def _swing_dist(self, d: np.ndarray) -> np.ndarray:
        if self._swing is None:
            return np.full(len(d), -np.inf)
        return self._swing.nearest(d, need_point=False)[0]

    # -- hinge joints -------------------------------------------------------------------------
    # The allowed set is the arc {h(θ) = (cos θ/2, sin θ/2 · a) : lo <= θ <= hi}. For a unit
    # q = (w, v), |<q, h(θ)>| = c |cos((θ − φ)/2)| with c = sqrt(w² + (v·a)²) and φ the twist of
    # q about a: the geodesic distance to h(θ) grows with |θ − φ| (wrapped), so the nearest
    # allowed rotation is h(φ) when φ is inside the interval and the nearer end otherwise (the
    # upper one on a tie). The off-axis part of q (its swing about a) is corrected with it.
    def _evaluate_hinge(self, q: np.ndarray) -> OracleResult:
        axis_t, lo, hi, wraps = self._hinge
        return evaluate_hinge(q, np.asarray(axis_t), lo, hi, wraps)

    def _evaluate_hinge_one(self, qt: tuple[float, float, float, float]) -> OracleResult:
        """Scalar twin of :meth:`_evaluate_hinge` (same maths, same tie rules)."""
        axis_t, lo, hi, wraps = self._hinge
        phi = _twist1(qt, axis_t)
        t = BOUNDARY_TOLERANCE
        inside = lo - t <= phi <= hi + t or (wraps and _across_seam1(phi, lo, hi))
        if inside:
            theta = phi
        else:
            theta = lo if abs(_wrap1(phi - lo)) < abs(_wrap1(phi - hi)) else hi
        ch, sh = math.cos(0.5 * theta), math.sin(0.5 * theta)
        h = (ch, sh * axis_t[0], sh * axis_t[1], sh * axis_t[2])
        if h[0] * qt[0] + h[1] * qt[1] + h[2] * qt[2] + h[3] * qt[3] < 0.0:
            h = (-h[0], -h[1], -h[2], -h[3])
        c, gap = _correction1(h, qt)
        invalid = gap > t
        if invalid:
            corr, proj, distance = c, h, gap
        else:
            corr, proj = (1.0, 0.0, 0.0, 0.0), qt
            distance = -max(min(phi - lo, hi - phi), 0.0)
        p = qt[1] * axis_t[0] + qt[2] * axis_t[1] + qt[3] * axis_t[2]
        r2 = qt[0] * qt[0] + p * p
        off = 2.0 * math.atan2(math.sqrt(max(1.0 - r2, 0.0)), math.sqrt(r2))
        return OracleResult(valid=np.bool_(not invalid), distance=np.float64(distance),
                            projected=np.array(proj), correction=np.array(corr),
                            swing_distance=np.float64(off), twist=np.float64(phi))

    def _evaluate(self, q: np.ndarray) -> OracleResult:
        if self._hinge is not None:
            return self._evaluate_hinge(q)
        return evaluate_ball(q, self.axis,
                             None if self._swing is None else self._swing.nearest,
                             None if self._twist is None else self._limits, self._wraps)


def evaluate_ball(q: np.ndarray, axis: np.ndarray, nearest, limits, wraps: bool = True
                  ) -> OracleResult:
    """The ball (and two-axis) joint oracle, batched, given its swing and twist as functions.

    Parameters
    ----------
    q : (N, 4) unit orientations
    axis : (3,) the limb axis
    nearest : callable or None
        ``nearest(d) -> (signed distance (N,), nearest boundary point (N, 3))`` for limb
        directions ``d`` (N, 3); None: the swing is unconstrained.
    limits : callable or None
        ``limits(e) -> (lo, hi)`` twist limits (radians, floats or (N,) arrays) at the corrected
        limb directions ``e``; None: the twist is unconstrained.
    wraps : bool
        An interval may reach the ±π seam (False only speeds the twist test up).
    """
    n = len(q)
    d = Q.rotate(q, axis)
    projected = q.copy()
    if nearest is not None:
        sdist, b = nearest(d)
        out = sdist > BOUNDARY_TOLERANCE
        if out.any():
            delta = Q.from_two_vectors(d[out], b[out])
            projected[out] = Q.multiply(delta, q[out])
    else:
        sdist = np.full(n, -np.inf)
        out = np.zeros(n, dtype=bool)
        b = d
    phi = Q.twist_angle(q, axis)
    margin = -sdist
    if limits is not None:
        any_out = bool(out.any())
        lo, hi = limits(np.where(out[:, None], b, d) if any_out else d)  # corrected direction
        lo = np.broadcast_to(lo, (n,))
        hi = np.broadcast_to(hi, (n,))
        phi_p = Q.twist_angle(projected, axis) if any_out else phi
        bad_tw = ~_twist_inside(phi_p, lo, hi, wraps)
        if bad_tw.any():
            bad_tw &= ~_singular(projected, axis)
        if bad_tw.any():
            f = phi_p[bad_tw]
            lo_b, hi_b = lo[bad_tw], hi[bad_tw]
            d_lo = np.abs(Q.wrap_angle(f - lo_b))
            d_hi = np.abs(Q.wrap_angle(f - hi_b))
            target = np.where(d_lo < d_hi, lo_b, hi_b)
            tau = Q.from_axis_angle(axis, Q.wrap_angle(target - f))
            projected[bad_tw] = Q.multiply(projected[bad_tw], tau)
        # the plain margin; across the seam a valid twist is within the tolerance of a
        # limit, and the distance clips the margin at 0 anyway
        margin = np.minimum(margin, np.minimum(phi - lo, hi - phi))
        tw_bad = ~_twist_inside(phi, lo, hi, wraps)
        if tw_bad.any():
            sing = _singular(q, axis)
            if sing.any():
                tw_bad &= ~sing
                margin = np.where(sing, np.minimum(margin, 0.0), margin)
        invalid = out | tw_bad
    else:
        invalid = out
    corr = np.tile(Q.IDENTITY, (n, 1))
    if invalid.any():
        c = Q.multiply(projected[invalid], Q.conjugate(q[invalid]))
        corr[invalid] = Q.canonical(c / np.linalg.norm(c, axis=1, keepdims=True))
        projected[invalid] /= np.linalg.norm(projected[invalid], axis=1, keepdims=True)
    distance = np.where(invalid, Q.angle(corr), -np.maximum(margin, 0.0))
    return OracleResult(
        valid=~invalid,
        distance=distance,
        projected=projected,
        correction=corr,
        swing_distance=sdist,
        twist=phi,
    )


def evaluate_hinge(q: np.ndarray, a: np.ndarray, lo, hi, wraps: bool = True) -> OracleResult:
    """The hinge oracle, batched: ``q`` (N, 4) unit, hinge axis ``a`` (3,), the interval
    ``[lo, hi]`` (radians, floats or (N,) arrays: one interval per orientation, as a coupled
    joint's are). See :class:`ConstraintOracle` for the maths."""
    phi = Q.twist_angle(q, a)
    inside = _twist_inside(phi, lo, hi, wraps)
    d_lo = np.abs(Q.wrap_angle(phi - lo))
    d_hi = np.abs(Q.wrap_angle(phi - hi))
    theta = np.where(inside, phi, np.where(d_lo < d_hi, lo, hi))
    h = Q.from_axis_angle(a, theta)
    dot = np.einsum("ij,ij->i", h, q)
    h = np.where((dot < 0.0)[:, None], -h, h)  # the input's sign
    c = Q.multiply(h, Q.conjugate(q))
    c = Q.canonical(c / np.linalg.norm(c, axis=1, keepdims=True))
    gap = Q.angle(c)
    invalid = gap > BOUNDARY_TOLERANCE
    n = len(q)
    corr = np.where(invalid[:, None], c, np.tile(Q.IDENTITY, (n, 1)))
    projected = np.where(invalid[:, None], h, q)
    margin = np.minimum(phi - lo, hi - phi)
    distance = np.where(invalid, gap, -np.maximum(margin, 0.0))
    p = q[:, 1:] @ a
    off = 2.0 * np.arctan2(np.sqrt(np.maximum(1.0 - (q[:, 0] ** 2 + p * p), 0.0)),
                           np.sqrt(q[:, 0] ** 2 + p * p))
    return OracleResult(valid=~invalid, distance=distance, projected=projected,
                        correction=corr, swing_distance=off, twist=phi)


# -- twist intervals on the circle (both paths) -------------------------------------------------
_TWO_PI = 2.0 * math.pi


def _reaches_seam(lo, hi) -> bool:
    """Can a twist across the ±π seam lie within the tolerance of ``[lo, hi]``?"""
    t = BOUNDARY_TOLERANCE
    return bool(np.min(lo) <= -math.pi + t or np.max(hi) >= math.pi - t)


def _twist_inside(phi, lo, hi, wraps: bool = True):
    """``φ`` (radians, (−π, π]) inside ``[lo, hi]`` on the circle, within the tolerance.

    ``φ − 2π`` and ``φ + 2π`` are tried too when ``wraps`` (an interval touching ±π)."""
    t = BOUNDARY_TOLERANCE
    inside = (phi >= lo - t) & (phi <= hi + t)
    if wraps:
        inside |= (phi - _TWO_PI >= lo - t) | (phi + _TWO_PI <= hi + t)
    return inside


def _singular(q: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """(N,) bool: the twist of ``q`` is undefined (limb within ~2e-6 rad of ``−axis``)."""
    p = q[:, 1:] @ axis
    return q[:, 0] * q[:, 0] + p * p < _SING2


def _across_seam1(phi: float, lo: float, hi: float) -> bool:
    t = BOUNDARY_TOLERANCE
    return phi - _TWO_PI >= lo - t or phi + _TWO_PI <= hi + t


# -- the hinge's single-orientation path, plain Python (tuples of floats, w x y z) -------------
_wrap1 = Q.wrap_angle1
_twist1 = Q.twist_angle1
_mul1 = qs.mul


def _correction1(proj, qt) -> tuple[tuple[float, float, float, float], float]:
    """The correction ``proj ⊗ qt⁻¹`` (unit, ``w >= 0``: :func:`models.quaternion.canonical`'s
    rule) and its angle, radians."""
    c = _mul1(proj, (qt[0], -qt[1], -qt[2], -qt[3]))
    cn = math.sqrt(c[0] * c[0] + c[1] * c[1] + c[2] * c[2] + c[3] * c[3])
    sign = -1.0 if c[0] < 0.0 or (c[0] == 0.0 and _first_nonzero_negative(c)) else 1.0
    c = (sign * c[0] / cn, sign * c[1] / cn, sign * c[2] / cn, sign * c[3] / cn)
    return c, 2.0 * math.atan2(math.sqrt(c[1] * c[1] + c[2] * c[2] + c[3] * c[3]), abs(c[0]))


def _first_nonzero_negative(c) -> bool:
    for v in c:
        if v != 0.0:
            return v < 0.0
    return False


# -- the compiled ball-joint kernel (the control loop's single-orientation path) -------------
_SWING_NONE, _SWING_CONE, _SWING_CELLS, _SWING_CANDIDATES = 0, 1, 2, 3
_TWIST_NONE, _TWIST_CONSTANT, _TWIST_TABLE = 0, 1, 2
_PI = math.pi


@njit(inline="always")
def _twist_k(w, x, y, z, ax):
    """:func:`models.quaternion.twist_angle1`."""
    p = x * ax[0] + y * ax[1] + z * ax[2]
    phi = 2.0 * math.atan2(-p, -w) if w < 0.0 else 2.0 * math.atan2(p, abs(w))
    return _PI if phi <= -_PI else phi


@njit(inline="always")
def _wrap_k(phi):
    """:func:`models.quaternion.wrap_angle1`."""
    if -_PI < phi <= _PI:
        return phi
    out = (phi + _PI) % _TWO_PI - _PI
    return _PI if out == -_PI else out


@njit(inline="always")
def _across_k(phi, lo, hi):
    t = BOUNDARY_TOLERANCE
    return phi - _TWO_PI >= lo - t or phi + _TWO_PI <= hi + t


@njit(inline="always")
def _two_vectors_k(a0, a1, a2, b0, b1, b2):
    """:func:`models.qscalar.from_two_vectors` (antiparallel: :func:`Q.perpendicular`)."""
    w = 1.0 + a0 * b0 + a1 * b1 + a2 * b2
    if w < 1e-12:
        m0, m1, m2 = abs(a0), abs(a1), abs(a2)
        k = 0 if m0 <= m1 and m0 <= m2 else (1 if m1 <= m2 else 2)
        e0, e1, e2 = (1.0 if k == 0 else 0.0), (1.0 if k == 1 else 0.0), (1.0 if k == 2 else 0.0)
        p0, p1, p2 = a1 * e2 - a2 * e1, a2 * e0 - a0 * e2, a0 * e1 - a1 * e0
        n = math.sqrt(p0 * p0 + p1 * p1 + p2 * p2)
        return 0.0, p0 / n, p1 / n, p2 / n
    q1, q2, q3 = a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0
    n = math.sqrt(w * w + q1 * q1 + q2 * q2 + q3 * q3)
    return w / n, q1 / n, q2 / n, q3 / n


@njit
def _ball_kernel(w, x, y, z, ax, swing_kind, cone, G, cell_ptr, cell_edges, table, v0, vn,
                 orient, twist_kind, lo, hi, wraps, dirs_k, sums, kappa):
    """:meth:`ConstraintOracle._evaluate` for one unit orientation of a ball (or two-axis)
    joint: the same maths and tie rules in compiled plain floats. Returns ``(invalid,
    distance, projected (4), correction (4), swing distance, twist)``."""
    d0, d1, d2 = qk.rotate(w, x, y, z, ax[0], ax[1], ax[2])  # the limb direction
    p0, p1, p2, p3 = w, x, y, z
    swing_out = False
    b0, b1, b2 = d0, d1, d2
    if swing_kind == _SWING_NONE:
        sdist = -math.inf
    else:
        if swing_kind == _SWING_CONE:  # _ConeSolver.nearest's closed form, one direction
            c0, c1, c2, r = cone[0], cone[1], cone[2], cone[3]
            cos_t = d0 * c0 + d1 * c1 + d2 * c2
            g0, g1, g2 = d0 - cos_t * c0, d1 - cos_t * c1, d2 - cos_t * c2
            sin_t = math.sqrt(g0 ** 2 + g1 ** 2 + g2 ** 2)
            sdist = math.atan2(sin_t, cos_t) - r
            if sin_t < 1e-15:
                u0, u1, u2 = cone[4], cone[5], cone[6]
            else:
                u0, u1, u2 = g0 / sin_t, g1 / sin_t, g2 / sin_t
            cr, sr = math.cos(r), math.sin(r)
            n0, n1, n2 = cr * c0 + sr * u0, cr * c1 + sr * u1, cr * c2 + sr * u2
        elif swing_kind == _SWING_CELLS:
            sdist, n0, n1, n2 = _nearest_in_cell(d0, d1, d2, G, cell_ptr, cell_edges, table,
                                                 v0, vn, orient)
        else:
            sdist, n0, n1, n2 = _rank_one(d0, d1, d2, cell_edges, table, v0, vn, orient)
        if sdist > BOUNDARY_TOLERANCE:
            swing_out = True
            b0, b1, b2 = n0, n1, n2
            e0, e1, e2, e3 = _two_vectors_k(d0, d1, d2, n0, n1, n2)
            p0, p1, p2, p3 = qk.mul(e0, e1, e2, e3, w, x, y, z)
    phi = _twist_k(w, x, y, z, ax)
    margin = -sdist
    invalid = swing_out
    if twist_kind != _TWIST_NONE:
        if twist_kind == _TWIST_TABLE:
            lo, hi = _table_limits_one(b0, b1, b2, dirs_k, sums, kappa)
        phi_p = _twist_k(p0, p1, p2, p3, ax) if swing_out else phi
        t = BOUNDARY_TOLERANCE
        if not lo - t <= phi_p <= hi + t and not (
            (wraps and _across_k(phi_p, lo, hi))
            or p0 * p0 + (p1 * ax[0] + p2 * ax[1] + p3 * ax[2]) ** 2 < _SING2
        ):
            d_lo = abs(_wrap_k(phi_p - lo))
            d_hi = abs(_wrap_k(phi_p - hi))
            half = 0.5 * _wrap_k((lo if d_lo < d_hi else hi) - phi_p)
            sh = math.sin(half)
            p0, p1, p2, p3 = qk.mul(p0, p1, p2, p3, math.cos(half), ax[0] * sh, ax[1] * sh,
                                    ax[2] * sh)
        if lo - t <= phi <= hi + t:
            margin = min(margin, phi - lo, hi - phi)
        elif (wraps and _across_k(phi, lo, hi)) or (
            w * w + (x * ax[0] + y * ax[1] + z * ax[2]) ** 2 < _SING2
        ):
            margin = min(margin, 0.0)  # at a limit across the seam, or twist undefined
        else:
            invalid = True
    if invalid:  # _correction1: proj ⊗ q⁻¹, w >= 0 (canonical's rule), and its angle
        k0, k1, k2, k3 = qk.mul(p0, p1, p2, p3, w, -x, -y, -z)
        cn = math.sqrt(k0 * k0 + k1 * k1 + k2 * k2 + k3 * k3)
        neg = k0 < 0.0
        if k0 == 0.0:
            for v in (k1, k2, k3):
                if v != 0.0:
                    neg = v < 0.0
                    break
        sign = -1.0 if neg else 1.0
        k0, k1, k2, k3 = sign * k0 / cn, sign * k1 / cn, sign * k2 / cn, sign * k3 / cn
        distance = 2.0 * math.atan2(math.sqrt(k1 * k1 + k2 * k2 + k3 * k3), abs(k0))
        pn = math.sqrt(p0 * p0 + p1 * p1 + p2 * p2 + p3 * p3)
        p0, p1, p2, p3 = p0 / pn, p1 / pn, p2 / pn, p3 / pn
    else:
        k0, k1, k2, k3 = 1.0, 0.0, 0.0, 0.0
        distance = -max(margin, 0.0)
    return invalid, distance, p0, p1, p2, p3, k0, k1, k2, k3, sdist, phi


# ---------------------------------------------------------------------------------------------
# Swing solvers: nearest(d) -> (signed distance (N,), nearest boundary point (N, 3))
# ---------------------------------------------------------------------------------------------
class _ConeSolver:
    """Closed form for a circular boundary (thesis eq. 59-68)."""

    def __init__(self, cone: ConeSwing):
        self.c = np.asarray(cone.centre, dtype=np.float64)
        self.r = cone.radius
        self._perp = Q.perpendicular(self.c)
        self._c_t = tuple(self.c.tolist())
        self._perp_t = tuple(self._perp.tolist())

    def nearest(self, d: np.ndarray, need_point: bool = True):
        c = self.c
        cos_t = d @ c
        tang = d - cos_t[:, None] * c  # component of d perpendicular to the centre
        sin_t = np.linalg.norm(tang, axis=1)
        theta = np.arctan2(sin_t, cos_t)  # eq. 61: angle between limb and centre
        dist = theta - self.r  # eq. 62-63: valid iff theta <= r
        if not need_point:
            return dist, None
        # boundary point on the great circle through c and d (rotating d towards c by dist)
        tiny = sin_t < 1e-15
        safe = np.where(tiny, 1.0, sin_t)[:, None]
        u = np.where(tiny[:, None], self._perp, tang / safe)
        b = math.cos(self.r) * c + math.sin(self.r) * u
        return dist, b


# ---------------------------------------------------------------------------------------------
# Helpers kept for callers of the former API (the geometry now lives in models.geometry)
# ---------------------------------------------------------------------------------------------
def polygon_boundary_distance(vertices: np.ndarray, point: np.ndarray) -> float:
    """Unsigned angular distance (radians) from ``point`` to a polygon's boundary (brute force)."""
    return boundary_distance(vertices, point)


def polygon_area_sr(swing: PolygonSwing) -> float:
    """Solid angle (steradians) of a polygon swing's valid region."""
    return polygon_area(swing.vertices, swing.interior)
