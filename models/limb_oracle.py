"""The exact limb oracle: validity, corrections and distances of every joint of a limb.

The judge of everything learned about limbs (datasets, evaluation) and the check a live limb
supervisor makes. Input: orientations ``(N, J, 4)`` — joint ``j``'s child segment relative to its
parent, scalar-first, in the limb file's joint order — or ``(J, 4)`` for one posture.

Hierarchical correction (``models.limb``): joints are evaluated in :attr:`Limb.order`; a joint
without a coupling is answered by :class:`models.oracle.ConstraintOracle` (the single-joint
oracle, unchanged); a coupled joint by the same maths (its kind's
:meth:`~models.kinds.base.JointKind.evaluate_coupled`) with its limits interpolated at the
coupling angle of **the corrected** source joint — the hinge angle of the source's projected
orientation. So the corrected limb is valid in every joint (the source's correction does not
move again; the dependant is valid at that angle), and a valid limb is left as it is.

One implementation serves a batch and a single posture (a posture is a batch of one).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from models import quaternion as Q
from models.errors import QuaternionError
from models.kinds.base import OracleResult
from models.limb import InterpolatedLimits, Limb
from models.oracle import ConstraintOracle

__all__ = ["LimbOracle", "LimbResult", "check_postures", "end_points", "segment_directions"]


@dataclass(frozen=True)
class LimbResult:
    """The oracle's answers for a batch of postures (leading shape N; one posture: none).

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


class _CoupledJoint:
    """A coupled joint's oracle: limits interpolated at a coupling angle per sample (the
    maths of its kind: :meth:`models.kinds.base.JointKind.evaluate_coupled`)."""

    def __init__(self, limits: InterpolatedLimits, axis: np.ndarray):
        self.lim = limits
        self.axis = axis
        self.kind = limits.keyframes[0].joint_kind

    def evaluate(self, q: np.ndarray, angle: np.ndarray) -> OracleResult:
        k, t = self.lim.locate(angle)
        return self.kind.evaluate_coupled(q, self.axis, self.lim, k, t)


class LimbOracle:
    """Exact answers for one :class:`~models.limb.Limb`.

    Parameters
    ----------
    limb : Limb
    """

    def __init__(self, limb: Limb):
        self.limb = limb
        self.n_joints = len(limb.joints)
        self.axes = np.array([j.limb_axis for j in limb.joints])
        self._joint: list[ConstraintOracle | _CoupledJoint] = []
        for j in limb.joints:
            if j.coupling is None:
                self._joint.append(ConstraintOracle(j.constraint))
            else:
                self._joint.append(_CoupledJoint(j.coupling.limits, np.asarray(j.limb_axis)))
        self._source = [None if j.coupling is None else limb.index(j.coupling.by)
                        for j in limb.joints]
        self._coupling_axis = [(j.constraint or j.coupling.keyframes[0]).joint_kind.coupling_axis(
            j.constraint or j.coupling.keyframes[0]) for j in limb.joints]

    def evaluate(self, orientations, *, normalize: bool = False) -> LimbResult:
        """Validity, distance, projection and correction of every joint, hierarchically."""
        q = check_postures(orientations, self.n_joints, normalize=normalize)
        single = q.ndim == 2
        res = self._evaluate(q[None] if single else q, self.limb.order)
        if single:
            res = LimbResult(*(x[0] for x in (res.valid, res.distance, res.projected,
                                               res.correction, res.coupling_angle)))
        return res

    def joint_is_valid(self, orientations, joint: int, *, normalize: bool = False) -> np.ndarray:
        """``is_valid(orientations)[..., joint]``, evaluating only that joint and the joints
        its limits depend on (a coupled joint's source, hierarchically)."""
        q = check_postures(orientations, self.n_joints, normalize=normalize)
        single = q.ndim == 2
        needed, j = set(), joint
        while j is not None:
            needed.add(j)
            j = self._source[j]
        order = [j for j in self.limb.order if j in needed]
        valid = self._evaluate(q[None] if single else q, order).valid[:, joint]
        return valid[0] if single else valid

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
            oracle = self._joint[j]
            qj = np.ascontiguousarray(q3[:, j])
            if isinstance(oracle, ConstraintOracle):
                r = oracle.evaluate(qj)
            else:
                src = self._source[j]
                angle[:, j] = Q.twist_angle(proj[:, src], self._coupling_axis[src])
                r = oracle.evaluate(qj, angle[:, j])
            valid[:, j], dist[:, j] = r.valid, r.distance
            proj[:, j], corr[:, j] = r.projected, r.correction
        return LimbResult(valid, dist, proj, corr, angle)

    def correction(self, orientations, *, normalize: bool = False) -> np.ndarray:
        """Corrective quaternions ``(N, J, 4)``: ``corrected_j = correction_j ⊗ q_j``."""
        return self.evaluate(orientations, normalize=normalize).correction

    def project(self, orientations, *, normalize: bool = False) -> np.ndarray:
        """The nearest valid posture, joint by joint in the hierarchy's order."""
        return self.evaluate(orientations, normalize=normalize).projected

    def is_valid(self, orientations, *, normalize: bool = False) -> np.ndarray:
        """``(N, J)`` bool: each joint within its limits (a coupled joint at the corrected
        source's angle — for a valid source, its own angle)."""
        return self.evaluate(orientations, normalize=normalize).valid

    def end_points(self, orientations, *, normalize: bool = False) -> np.ndarray:
        """The limb's end point with unit segment lengths, ``(N, 3)`` (root segment's frame)."""
        q = check_postures(orientations, self.n_joints, normalize=normalize)
        single = q.ndim == 2
        p = end_points(q[None] if single else q, self.axes)
        return p[0] if single else p
