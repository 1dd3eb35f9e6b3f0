"""The exact joint-constraint oracle: validity, nearest valid orientation, correction, distance.

:class:`ConstraintOracle` validates its input and hands it to the exact oracle of the
constraint's kind (:meth:`models.kinds.base.JointKind.oracle`: the maths of each kind is in its
module, :mod:`models.kinds.ball`, :mod:`models.kinds.hinge`, ...; the ball joint's below). One
vectorised implementation, used for dataset generation, model evaluation and the live
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
:class:`models.limits.SwingTwistTable` (``by_swing``). After the swing correction the twist
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
(:func:`models.kinds.ball._ball_kernel`: the swing, the twist, a ``by_swing`` table's weights
and the projection, about 2-3 µs a query on the project's 2-core machine, where plain Python
took 9-14 µs); a hinge's is plain Python. :meth:`ConstraintOracle.distance_projected_one` is the
control loop's query (plain floats in and out).
"""

from __future__ import annotations

import math

import numpy as np

from models import quaternion as Q
from models.constraint import JointConstraint
from models.geometry import boundary_distance, polygon_area
from models.kinds.base import BOUNDARY_TOLERANCE, OracleResult
from models.limits import PolygonSwing

__all__ = [
    "ConstraintOracle",
    "polygon_area_sr",
    "polygon_boundary_distance",
]


class ConstraintOracle:
    """Exact answers for one :class:`~models.constraint.JointConstraint`.

    Parameters
    ----------
    constraint : JointConstraint

    All methods accept ``q`` of shape ``(4,)`` or ``(N, 4)`` (scalar-first, unit norm, either
    sign; validated by :func:`models.quaternion.check_quaternions`) and return arrays with the
    matching leading shape. The answers are those of the constraint's kind's oracle
    (:meth:`models.kinds.base.JointKind.oracle`).
    """

    def __init__(self, constraint: JointConstraint):
        self.constraint = constraint
        self.axis = np.asarray(constraint.limb_axis, dtype=np.float64)
        self._kind = constraint.joint_kind.oracle(constraint)
        self._swing = self._kind.swing

    # -- public API ------------------------------------------------------------------------
    def prepare(self) -> ConstraintOracle:
        """Build now what the single-orientation path needs (a polygon's grid, the compiled
        kernel loaded or compiled: seconds on a machine's first run), otherwise built by the
        first query that pays for them, so that no query of a control loop waits for it.
        Returns self."""
        self._kind.prepare()
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
        res = self._kind.evaluate(q2)
        if single:
            res = OracleResult(*(np.asarray(x)[0] for x in res.__dict__.values()))
        return res

    def is_valid(self, q, *, normalize: bool = False) -> np.ndarray:
        """True where the orientation satisfies the constraint (within tolerance)."""
        if isinstance(q, np.ndarray) and q.shape == (4,) and q.dtype.kind in "fiu":
            return self._evaluate_one(q, normalize).valid
        q2, single = self._prep(q, normalize)
        valid = self._kind.is_valid(q2)
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

    # -- internals -------------------------------------------------------------------------
    def _evaluate_one(self, q: np.ndarray, normalize: bool) -> OracleResult:
        """Scalar twin of the batched path for one orientation (same maths, same tie rules)."""
        w, x, y, z = q.tolist()
        nrm = math.sqrt(w * w + x * x + y * y + z * z)
        if (
            not math.isfinite(nrm)
            or nrm < 1e-12
            or (not normalize and abs(nrm - 1.0) > Q.UNIT_TOLERANCE)
        ):
            Q.check_quaternions(q, normalize=normalize)  # raises with the precise message
        return self._kind.evaluate_one((w / nrm, x / nrm, y / nrm, z / nrm))

    def distance_projected_one(self, w: float, x: float, y: float, z: float):
        """The control loop's query: ``(D(q), projection of q)`` for one orientation given as
        four floats (normalised here; non-finite or zero raises as :meth:`evaluate` does), in
        plain floats — :meth:`evaluate`'s answers without building its arrays."""
        nrm = math.sqrt(w * w + x * x + y * y + z * z)
        if not math.isfinite(nrm) or nrm < 1e-12:
            Q.check_quaternions(np.array([w, x, y, z]), normalize=True)  # raises
        return self._kind.distance_projected_one((w / nrm, x / nrm, y / nrm, z / nrm))

    def _prep(self, q, normalize):
        q = Q.check_quaternions(q, normalize=normalize)
        return q.reshape(-1, 4), q.ndim == 1

    def _swing_dist(self, d: np.ndarray) -> np.ndarray:
        if self._swing is None:
            return np.full(len(d), -np.inf)
        return self._swing.nearest(d, need_point=False)[0]


# ---------------------------------------------------------------------------------------------
# Helpers kept for callers of the former API (the geometry now lives in models.geometry)
# ---------------------------------------------------------------------------------------------
def polygon_boundary_distance(vertices: np.ndarray, point: np.ndarray) -> float:
    """Unsigned angular distance (radians) from ``point`` to a polygon's boundary (brute force)."""
    return boundary_distance(vertices, point)


def polygon_area_sr(swing: PolygonSwing) -> float:
    """Solid angle (steradians) of a polygon swing's valid region."""
    return polygon_area(swing.vertices, swing.interior)

