"""The exact oracle of a joint or a limb: validity, nearest valid orientation, correction, distance.

One class, :class:`ConstraintOracle`, for a joint's constraint and for a whole limb (a
:class:`models.limb.Limb`: joints in order, with couplings). A one-joint constraint file is a limb
of one joint: its oracle keeps the one joint's contract — orientations ``(N, 4)`` or ``(4,)`` in,
answers of the same leading shape out, and a single-orientation path in plain floats for the
control loop (:meth:`ConstraintOracle.distance_projected_one`) — while a limb's takes postures
``(N, J, 4)`` or ``(J, 4)``: joint ``j``'s child segment relative to its parent, scalar-first, in
the limb file's joint order.

What differs between kinds of joint is in the kinds' modules (:mod:`models.kinds`): each joint is
answered by the exact oracle of its kind (:meth:`models.kinds.base.JointKind.oracle`; the maths
of each kind is in its module, :mod:`models.kinds.ball`, :mod:`models.kinds.hinge`, ...; the ball
joint's below), a coupled joint by its kind's :meth:`~models.kinds.base.JointKind.evaluate_coupled`.
What is the limb's — the couplings and their hierarchy — is here (below). One vectorised
implementation, used for dataset generation, model evaluation and the live supervisor, plus a
scalar path for one orientation per control cycle that gives the same answers.

Hierarchical correction of a limb
---------------------------------
Joints are evaluated in :attr:`models.limb.Limb.order` (every coupling's source before its
dependant). A joint without a coupling is answered by its kind's oracle, as one joint's
constraint is; a coupled joint by the same maths with its limits interpolated at the coupling
angle of **the corrected** source joint — the source's angle (its kind's
:meth:`~models.kinds.base.JointKind.coupling_angle`: a hinge's angle about its axis, a forearm's
flexion) in its projected orientation. So the corrected
limb is valid in every joint (the source's correction does not move again; the dependant is valid
at that angle), and a valid limb is left as it is. One implementation serves a batch and a single
posture (a posture is a batch of one).

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
took 9-14 µs); a hinge's and a forearm's are plain Python.
:meth:`ConstraintOracle.distance_projected_one` is the control loop's query (plain floats in and
out), a joint's only.

A limb's joints are queried one at a time by :meth:`ConstraintOracle.joint_query`. A coupled
joint's single-orientation path is its kind's
(:meth:`~models.kinds.base.JointKind.coupled_one`): for a ball or two-axis joint one compiled
kernel (:func:`models.kinds.ball._coupled_ball_kernel`) locates the angle among the keyframes,
interpolates the cone, or the corresponding vertices of the polygon (every edge tried, as the
batched path's :func:`models.geometry.nearest_on_polygons` does: O(vertices), no array built),
and the twist interval, then runs the uncoupled kernel's maths; a hinge's is plain Python. Same
answers as the batched path (to about 1e-15); about 2.5 µs a query for a 45-vertex polygon on
the project's 2-core machine where the batched evaluation of one took 260-375 µs. The source's
angle has a scalar twin too (:meth:`~models.kinds.base.JointKind.coupling_angle_one`).
"""


from __future__ import annotations

import math
from dataclasses import dataclass
from functools import partial

import numpy as np

from models import quaternion as Q
from models.constraint import JointConstraint
from models.errors import QuaternionError
from models.geometry import boundary_distance, polygon_area
from models.kinds.base import BOUNDARY_TOLERANCE, KindOracle, OracleResult
from models.limb import InterpolatedLimits, Limb
from models.limits import PolygonSwing

__all__ = [
    "ConstraintOracle",
    "LimbResult",
    "check_postures",
    "end_points",
    "polygon_area_sr",
    "polygon_boundary_distance",
    "segment_directions",
]


@dataclass(frozen=True)
class LimbResult:
    """A limb oracle's answers for a batch of postures (leading shape N; one posture: none).

    One joint's constraint answers with :class:`models.kinds.base.OracleResult` (arrays of
    length N).

    Attributes
    ----------
    valid : (N, J) bool
    distance : (N, J) radians; > 0 outside (the joint's correction angle), <= 0 inside
    projected : (N, J, 4) the corrected orientations (same sign as the input)
    correction : (N, J, 4) ``projected ⊗ q⁻¹``, ``w >= 0``; identity where valid
    coupling_angle : (N, J) radians: the corrected source's angle a coupled joint was judged
        at; NaN for joints without a coupling
    """

    valid: np.ndarray
    distance: np.ndarray
    projected: np.ndarray
    correction: np.ndarray
    coupling_angle: np.ndarray

    @property
    def limb_valid(self) -> np.ndarray:
        """(N,) bool: every joint valid."""
        return self.valid.all(axis=-1)


def check_postures(q, n_joints: int, *, normalize: bool = False) -> np.ndarray:
    """Validate postures ``(N, J, 4)`` or ``(J, 4)``; float64, unit (see
    :func:`models.quaternion.check_quaternions`)."""
    arr = np.asarray(q, dtype=np.float64) if not isinstance(q, np.ndarray) else q
    if arr.ndim not in (2, 3) or arr.shape[-2:] != (n_joints, 4):
        raise QuaternionError(f"postures: expected shape (N, {n_joints}, 4) or ({n_joints}, 4) "
                              f"(one scalar-first quaternion per joint), got {arr.shape}")
    flat = Q.check_quaternions(arr.reshape(-1, 4), normalize=normalize, name="postures")
    return flat.reshape(arr.shape)


def segment_directions(q: np.ndarray, axes: np.ndarray) -> np.ndarray:
    """Each segment's long axis in the root segment's frame, ``(N, J, 3)``: segment ``j``
    (joint ``j``'s child) points along ``(q_0 ⊗ … ⊗ q_j) · axes[j]``."""
    n, j = q.shape[:2]
    out = np.empty((n, j, 3))
    acc = q[:, 0]
    out[:, 0] = Q.rotate(acc, axes[0])
    for k in range(1, j):
        acc = Q.multiply(acc, q[:, k])
        out[:, k] = Q.rotate(acc, axes[k])
    return out


def end_points(q: np.ndarray, axes: np.ndarray) -> np.ndarray:
    """The limb's end point (hand, foot) ``(N, 3)`` with unit segment lengths, root frame."""
    return segment_directions(q, axes).sum(axis=1)


#: Answers a coupled joint's :meth:`ConstraintOracle.joint_query` remembers (oldest dropped).
_QUERY_CACHE = 8


class _CoupledJoint:
    """A coupled joint's oracle: limits interpolated at a coupling angle per sample (the
    maths of its kind: :meth:`models.kinds.base.JointKind.evaluate_coupled`)."""

    def __init__(self, limits: InterpolatedLimits, axis: np.ndarray):
        self.lim = limits
        self.axis = axis
        self.kind = limits.keyframes[0].joint_kind
        self._one = None  # the kind's single-orientation path, built by prepare()
        self._prepared = False

    def prepare(self) -> None:
        """Build the kind's single-orientation path (compiled or loaded now)."""
        if not self._prepared:
            self._one = self.kind.coupled_one(self.axis, self.lim)
            self._prepared = True

    def evaluate(self, q: np.ndarray, angle: np.ndarray) -> OracleResult:
        k, t = self.lim.locate(angle)
        return self.kind.evaluate_coupled(q, self.axis, self.lim, k, t)

    def one(self):
        """``one(w, x, y, z, angle) -> (valid, distance, projected, correction)`` of one unit
        orientation: the kind's single path (:meth:`models.kinds.base.JointKind.coupled_one`),
        else :meth:`evaluate` on a batch of one."""
        self.prepare()
        if self._one is not None:
            return self._one
        evaluate = self.evaluate

        def batch_of_one(w, x, y, z, angle):
            r = evaluate(np.array([[w, x, y, z]]), np.array([float(angle)]))
            p, c = r.projected[0], r.correction[0]
            return (bool(r.valid[0]), float(r.distance[0]),
                    (float(p[0]), float(p[1]), float(p[2]), float(p[3])),
                    (float(c[0]), float(c[1]), float(c[2]), float(c[3])))
        return batch_of_one


class ConstraintOracle:
    """Exact answers for one joint's :class:`~models.constraint.JointConstraint` or for a whole
    :class:`~models.limb.Limb` (hierarchically over its couplings: the module docstring).

    Parameters
    ----------
    limits : JointConstraint or Limb
        One joint's constraint: every method takes orientations ``q`` of shape ``(4,)`` or
        ``(N, 4)`` and answers with the matching leading shape. A limb: every method takes
        postures ``(N, J, 4)`` or ``(J, 4)`` (a limb of one joint read from a limb file too:
        ``(N, 1, 4)``) and answers per joint ``(N, J, ...)``; the methods marked "one joint's"
        are refused with :class:`TypeError`.

    Inputs are scalar-first, unit norm, either sign (validated by
    :func:`models.quaternion.check_quaternions`; ``normalize=True`` scales any finite non-zero
    quaternion). A joint's answers are those of its kind's oracle
    (:meth:`models.kinds.base.JointKind.oracle`).

    Attributes
    ----------
    constraint : JointConstraint or None
        One joint's constraint (None for a limb).
    limb : Limb or None
        The limb (None for one joint's constraint).
    n_joints : int
        The joints answered (1 for one joint's constraint).
    axes : (n_joints, 3) float64
        Each joint's limb axis (its child segment's long axis, child frame).
    axis : (3,) float64 or None
        One joint's limb axis (None for a limb).
    """

    def __init__(self, limits: JointConstraint | Limb):
        self._joints: list[KindOracle | _CoupledJoint] = []
        if isinstance(limits, Limb):
            self.limb: Limb | None = limits
            self.constraint: JointConstraint | None = None
            self.axis: np.ndarray | None = None
            self.axes = np.array([j.limb_axis for j in limits.joints])
            for j in limits.joints:
                if j.coupling is None:
                    self._joints.append(j.constraint.joint_kind.oracle(j.constraint))
                else:
                    self._joints.append(_CoupledJoint(j.coupling.limits,
                                                      np.asarray(j.limb_axis)))
            self._source = [None if j.coupling is None else limits.index(j.coupling.by)
                            for j in limits.joints]
            # each joint's coupling angle of (N, 4) orientations: its kind's (a hinge's angle,
            # a forearm's flexion)
            self._coupling_angle = [
                partial((j.constraint or j.coupling.keyframes[0]).joint_kind.coupling_angle,
                        j.constraint or j.coupling.keyframes[0]) for j in limits.joints]
            # its scalar twin, built for the sources only (a control loop's per-cycle query)
            sources = {s for s in self._source if s is not None}
            self._coupling_angle_one = [
                (j.constraint or j.coupling.keyframes[0]).joint_kind.coupling_angle_one(
                    j.constraint or j.coupling.keyframes[0]) if i in sources else None
                for i, j in enumerate(limits.joints)]
            self._kind: KindOracle | None = None
            self._swing = None
        else:
            self.limb = None
            self.constraint = limits
            self.axis = np.asarray(limits.limb_axis, dtype=np.float64)
            self.axes = self.axis[None]
            self._kind = limits.joint_kind.oracle(limits)
            self._swing = self._kind.swing
            self._joints.append(self._kind)
        self.n_joints = len(self._joints)

    # -- both: one joint's orientations (N, 4), a limb's postures (N, J, 4) ------------------
    def prepare(self) -> ConstraintOracle:
        """Build now what the single-orientation path needs (a polygon's grid, the compiled
        kernel loaded or compiled: seconds on a machine's first run), otherwise built by the
        first query that pays for them, so that no query of a control loop waits for it; for a
        limb, its joints' kinds prepare theirs. Returns self."""
        if self._kind is None:
            for oracle in self._joints:
                oracle.prepare()
            # every kernel a control loop's cycle calls, compiled or loaded now: each joint's
            # query (a coupled one inside its coupling range) and each source's angle
            for j in range(self.n_joints):
                rng = self.coupling_range(j)
                angle = 0.0 if rng is None else 0.5 * (rng[0] + rng[1])
                self.joint_query(j)(1.0, 0.0, 0.0, 0.0, angle)
                src = self.joint_source(j)
                if src is not None:
                    self.coupling_angle_one(src, 1.0, 0.0, 0.0, 0.0)
            return self
        self._kind.prepare()
        self.distance_projected_one(1.0, 0.0, 0.0, 0.0)
        return self

    def evaluate(self, q, *, normalize: bool = False) -> OracleResult | LimbResult:
        """Validity, distance, projection and correction in one pass.

        One joint's: an :class:`~models.kinds.base.OracleResult`; a single orientation (shape
        ``(4,)``) takes a scalar path (plain floats, one small numpy gather for a polygon)
        built for the control loop, giving the same answers as the batched path. A limb's: a
        :class:`LimbResult`, every joint hierarchically.
        """
        if self._kind is None:
            return self._evaluate_postures(q, normalize)
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
        """True where the orientation satisfies the constraint (within tolerance); a limb's:
        ``(N, J)``, each joint within its limits (a coupled joint at the corrected source's
        angle — for a valid source, its own angle)."""
        if self._kind is None:
            return self._evaluate_postures(q, normalize).valid
        if isinstance(q, np.ndarray) and q.shape == (4,) and q.dtype.kind in "fiu":
            return self._evaluate_one(q, normalize).valid
        q2, single = self._prep(q, normalize)
        valid = self._kind.is_valid(q2)
        return valid[0] if single else valid

    def project(self, q, *, normalize: bool = False) -> np.ndarray:
        """Nearest valid orientation (same quaternion sign as the input); a limb's: the nearest
        valid posture, joint by joint in the hierarchy's order."""
        return self.evaluate(q, normalize=normalize).projected

    def correction(self, q, *, normalize: bool = False) -> np.ndarray:
        """Corrective quaternion ``project(q) ⊗ q⁻¹`` (``w >= 0``, identity when valid); a
        limb's ``(N, J, 4)``: ``corrected_j = correction_j ⊗ q_j``."""
        return self.evaluate(q, normalize=normalize).correction

    def signed_distance(self, q, *, normalize: bool = False) -> np.ndarray:
        """Signed angular distance to the boundary, radians (> 0 outside, <= 0 inside); a
        limb's per joint ``(N, J)``."""
        return self.evaluate(q, normalize=normalize).distance

    def joint_is_valid(self, q, joint: int, *, normalize: bool = False) -> np.ndarray:
        """``is_valid(q)[..., joint]``, evaluating only that joint and the joints its limits
        depend on (a coupled joint's source, hierarchically); one joint's constraint: joint 0,
        :meth:`is_valid`."""
        if self._kind is not None:
            if joint != 0:
                raise IndexError(f"joint {joint}: one joint's constraint has joint 0 only")
            return self.is_valid(q, normalize=normalize)
        q = check_postures(q, self.n_joints, normalize=normalize)
        single = q.ndim == 2
        needed, j = set(), joint
        while j is not None:
            needed.add(j)
            j = self._source[j]
        order = [j for j in self.limb.order if j in needed]
        valid = self._evaluate(q[None] if single else q, order).valid[:, joint]
        return valid[0] if single else valid

    def end_points(self, q, *, normalize: bool = False) -> np.ndarray:
        """The limb's end point with unit segment lengths, ``(N, 3)`` (root segment's frame);
        one joint's: its child segment's direction (parent frame)."""
        if self._kind is not None:
            q = Q.check_quaternions(q, normalize=normalize)
            p = end_points(q.reshape(-1, 1, 4), self.axes)
            return p[0] if q.ndim == 1 else p
        q = check_postures(q, self.n_joints, normalize=normalize)
        single = q.ndim == 2
        p = end_points(q[None] if single else q, self.axes)
        return p[0] if single else p

    # -- one joint's -------------------------------------------------------------------------
    def swing_distance(self, directions) -> np.ndarray:
        """Signed angular distance (radians) of limb directions (N, 3) to the swing boundary
        (one joint's)."""
        self._one_joint("swing_distance")
        d = Q.check_vectors(directions, name="direction")
        single = d.ndim == 1
        out = self._swing_dist(d.reshape(-1, 3))
        return out[0] if single else out

    def nearest_swing_point(self, directions) -> np.ndarray:
        """Nearest point of the swing region (N, 3): the direction itself when inside (one
        joint's)."""
        self._one_joint("nearest_swing_point")
        d = Q.check_vectors(directions, name="direction")
        single = d.ndim == 1
        d2 = d.reshape(-1, 3)
        if self._swing is None:
            return d
        dist, b = self._swing.nearest(d2)
        out = np.where((dist > BOUNDARY_TOLERANCE)[:, None], b, d2)
        return out[0] if single else out

    def twist_limits_at(self, directions) -> tuple[np.ndarray, np.ndarray]:
        """Twist limits (radians) at limb directions (N, 3) or (3,), unit, parent frame (one
        joint's).

        ``(lo, hi)`` arrays (N,) — floats for one direction — from the constraint's ``by_swing``
        table, else its constant interval; ``(−π, π)`` when twist is unconstrained. The oracle
        clamps the twist to these limits at the corrected limb direction.
        """
        self._one_joint("twist_limits_at")
        d = Q.check_vectors(directions, name="direction")
        return self.constraint.twist_limits_at(d)

    def distance_projected_one(self, w: float, x: float, y: float, z: float):
        """The control loop's query: ``(D(q), projection of q)`` for one orientation given as
        four floats (normalised here; non-finite or zero raises as :meth:`evaluate` does), in
        plain floats — :meth:`evaluate`'s answers without building its arrays (one joint's)."""
        if self._kind is None:
            self._one_joint("distance_projected_one")
        nrm = math.sqrt(w * w + x * x + y * y + z * z)
        if not math.isfinite(nrm) or nrm < 1e-12:
            Q.check_quaternions(np.array([w, x, y, z]), normalize=True)  # raises
        return self._kind.distance_projected_one((w / nrm, x / nrm, y / nrm, z / nrm))

    # -- a limb's joints, one at a time (the control loop's per-joint queries) --------------
    @property
    def order(self) -> tuple[int, ...]:
        """The joints' evaluation order (:attr:`models.limb.Limb.order`: every coupling's
        source before its dependant); ``(0,)`` for one joint's constraint."""
        return (0,) if self._kind is not None else tuple(self.limb.order)

    def joint_source(self, joint: int) -> int | None:
        """The index of the joint whose angle ``joint``'s limits depend on (its coupling's
        source), None for a joint with limits of its own (and for one joint's constraint)."""
        if self._kind is not None:
            return None
        return self._source[joint]

    def coupling_angle_one(self, joint: int, w: float, x: float, y: float, z: float) -> float:
        """The coupling angle (radians) of orientation ``(w, x, y, z)`` of source joint
        ``joint``: its twist about its kind's coupling axis — what a joint coupled to it is
        judged at (:meth:`evaluate` takes it from the corrected source orientation)."""
        if self._kind is not None:
            raise TypeError("coupling_angle_one: a limb's query")
        # its kind's coupling angle (a hinge's twist about its axis, a forearm's flexion), in
        # plain floats (JointKind.coupling_angle_one: the batched formulas' scalar twin)
        one = self._coupling_angle_one[joint]
        if one is None:
            return float(self._coupling_angle[joint](np.array([[w, x, y, z]]))[0])
        return one(w, x, y, z)

    def coupling_range(self, joint: int) -> tuple[float, float] | None:
        """The coupling angles (radians) over which joint ``joint``'s limits change — its first
        and last keyframe's (beyond them the limits are those keyframes') — None for a joint
        with limits of its own."""
        if self._kind is not None or self._source[joint] is None:
            return None
        at = self._joints[joint].lim.at
        return float(at[0]), float(at[-1])

    def evaluate_joint(self, joint: int, q, angle=None) -> OracleResult:
        """One joint of a limb on its own orientations ``q`` (N, 4): its kind's oracle, a
        coupled joint's limits at the coupling angles ``angle`` (N,) (radians; required for a
        coupled joint, ignored otherwise) — :meth:`evaluate`'s answers for that joint when its
        source is at those angles. One joint's constraint: joint 0, :meth:`evaluate`."""
        if self._kind is not None:
            if joint != 0:
                raise IndexError(f"joint {joint}: one joint's constraint has joint 0 only")
            return self.evaluate(np.asarray(q, dtype=np.float64).reshape(-1, 4))
        q2 = Q.check_quaternions(np.asarray(q, dtype=np.float64).reshape(-1, 4))
        oracle = self._joints[joint]
        if isinstance(oracle, KindOracle):
            return oracle.evaluate(q2)
        if angle is None:
            raise ValueError(f"joint {joint} is coupled: its limits need the coupling angle")
        a = np.broadcast_to(np.asarray(angle, dtype=np.float64), (len(q2),))
        return oracle.evaluate(q2, a)

    def joint_query(self, joint: int):
        """A fast single-orientation query of one joint of a limb: a callable
        ``query(w, x, y, z, angle) -> (D, projection)`` in plain floats, ``D`` the joint's
        signed distance (radians) and ``projection`` its corrected orientation (4-tuple) — the
        answers of :meth:`evaluate` for that joint when its coupling's source is at ``angle``
        (radians; the corrected source's :meth:`coupling_angle_one`). ``angle`` is ignored for a
        joint with limits of its own, answered by its kind's single-orientation path
        (:meth:`distance_projected_one`'s); a coupled joint by its kind's
        (:meth:`~models.kinds.base.JointKind.coupled_one`: compiled for a ball or two-axis
        joint), or, for a kind without one, its coupled evaluation on a batch of one (the last
        :data:`_QUERY_CACHE` answers are remembered: a held goal, judged at its source's goal
        angle and at its commanded angle, costs nothing). Built here, not by the first query.
        One joint's constraint: joint 0, :meth:`distance_projected_one`."""
        if self._kind is not None:
            if joint != 0:
                raise IndexError(f"joint {joint}: one joint's constraint has joint 0 only")
            dpo = self.distance_projected_one

            def query_own(w, x, y, z, angle=math.nan):
                return dpo(w, x, y, z)
            return query_own
        oracle = self._joints[joint]
        if isinstance(oracle, KindOracle):
            kind_one = oracle.distance_projected_one

            def query_kind(w, x, y, z, angle=math.nan):
                nrm = math.sqrt(w * w + x * x + y * y + z * z)
                if not math.isfinite(nrm) or nrm < 1e-12:
                    Q.check_quaternions(np.array([w, x, y, z]), normalize=True)  # raises
                return kind_one((w / nrm, x / nrm, y / nrm, z / nrm))
            return query_kind
        cache: dict = {}
        one = oracle.one()

        def query_coupled(w, x, y, z, angle):
            key = (w, x, y, z, angle)
            out = cache.get(key)
            if out is not None:
                return out
            nrm = math.sqrt(w * w + x * x + y * y + z * z)
            if not math.isfinite(nrm) or nrm < 1e-12:
                Q.check_quaternions(np.array([w, x, y, z]), normalize=True)  # raises
            r = one(w / nrm, x / nrm, y / nrm, z / nrm, angle)
            out = (r[1], r[2])
            if len(cache) >= _QUERY_CACHE:
                del cache[next(iter(cache))]  # the oldest
            cache[key] = out
            return out
        return query_coupled

    # -- internals -------------------------------------------------------------------------
    def _one_joint(self, what: str) -> None:
        if self._kind is None:
            raise TypeError(f"{what}: one joint's query; a limb's oracle answers postures "
                            f"(N, {self.n_joints}, 4) — ask the oracle of the joint's constraint")

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

    def _prep(self, q, normalize):
        q = Q.check_quaternions(q, normalize=normalize)
        return q.reshape(-1, 4), q.ndim == 1

    def _swing_dist(self, d: np.ndarray) -> np.ndarray:
        if self._swing is None:
            return np.full(len(d), -np.inf)
        return self._swing.nearest(d, need_point=False)[0]

    def _evaluate_postures(self, q, normalize: bool) -> LimbResult:
        """A limb's :meth:`evaluate`: every joint, hierarchically."""
        q = check_postures(q, self.n_joints, normalize=normalize)
        single = q.ndim == 2
        res = self._evaluate(q[None] if single else q, self.limb.order)
        if single:
            res = LimbResult(*(x[0] for x in (res.valid, res.distance, res.projected,
                                               res.correction, res.coupling_angle)))
        return res

    def _evaluate(self, q3: np.ndarray, order) -> LimbResult:
        """The joints in ``order`` (the hierarchy's, each after its source) of postures
        ``(N, J, 4)``; the other joints' entries are left unset."""
        n, jn = q3.shape[:2]
        valid = np.empty((n, jn), dtype=bool)
        dist = np.empty((n, jn))
        proj = np.empty((n, jn, 4))
        corr = np.empty((n, jn, 4))
        angle = np.full((n, jn), np.nan)
        for j in order:
            oracle = self._joints[j]
            qj = np.ascontiguousarray(q3[:, j])
            if isinstance(oracle, KindOracle):
                # checked again as one joint's orientations are (this second rounding to unit
                # is the limb's answers' since the limb oracle began: kept, bit for bit)
                r = oracle.evaluate(Q.check_quaternions(qj))
            else:
                src = self._source[j]
                angle[:, j] = self._coupling_angle[src](proj[:, src])
                r = oracle.evaluate(qj, angle[:, j])
            valid[:, j], dist[:, j] = r.valid, r.distance
            proj[:, j], corr[:, j] = r.projected, r.correction
        return LimbResult(valid, dist, proj, corr, angle)


# ---------------------------------------------------------------------------------------------
# Helpers kept for callers of the former API (the geometry now lives in models.geometry)
# ---------------------------------------------------------------------------------------------
def polygon_boundary_distance(vertices: np.ndarray, point: np.ndarray) -> float:
    """Unsigned angular distance (radians) from ``point`` to a polygon's boundary (brute force)."""
    return boundary_distance(vertices, point)


def polygon_area_sr(swing: PolygonSwing) -> float:
    """Solid angle (steradians) of a polygon swing's valid region."""
    return polygon_area(swing.vertices, swing.interior)
