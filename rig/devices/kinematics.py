"""Forward and closed-form inverse kinematics of a 1-3 joint servo chain (a spherical joint).

Model
-----
Joint ``i`` (parent → child order) turns about a fixed unit axis ``a_i`` expressed in the frame
of the link before it (joint 1: the parent segment, e.g. the thorax). Its angle is

    θ_i = direction_i · (ticks_i − zero_i) · 2π / 4096                (X-series: 4096 ticks/rev)

and the limb orientation relative to the parent (scalar-first Hamilton quaternion, limb long
axis +X) is the product of axis-angle rotations parent → child (intrinsic composition)

    q = exp(θ_1 a_1 / 2) ⊗ exp(θ_2 a_2 / 2) ⊗ exp(θ_3 a_3 / 2).

Inverse kinematics (closed form; Paden-Kahan subproblems, Murray, Li & Sastry, *A Mathematical
Introduction to Robotic Manipulation*, 1994, §3.3)
-------------------------------------------------------------------------------------------------
* **Subproblem 1** — the angle θ about ``ω`` taking ``p`` to ``q``: project both on the plane
  ⟂ ω (``p' = p − ω(ω·p)``), ``θ = atan2(ω·(p'×q'), p'·q')``; it exists iff ``ω·p = ω·q``.
* **1 joint** — ``θ_1 = 2 atan2(v·a_1, w)`` for ``q = (w, v)``.
* **2 joints** — ``R_1 R_2 a_2 = R_1 a_2 = R a_2`` gives θ_1 by subproblem 1, then
  ``q_2 = q_1* ⊗ q`` must be a rotation about ``a_2``.
* **3 joints** — ``R_1 R_2 a_3 = R a_3`` is **subproblem 2**: ``c = R_2 a_3 = R_1ᵀ R a_3``
  satisfies ``a_1·c = a_1·R a_3`` and ``a_2·c = a_2·a_3``, so with ``k = a_1·a_2``
  ``c = α a_1 + β a_2 ± γ (a_1 × a_2)``, ``α = (a_1·Ra_3 − k a_2·a_3)/(1−k²)``,
  ``β = (a_2·a_3 − k a_1·Ra_3)/(1−k²)``, ``γ² = (1 − α² − β² − 2αβk)/|a_1×a_2|²``: two solutions
  (one when γ = 0, none when γ² < 0). θ_2 and θ_1 by subproblem 1, then θ_3 from
  ``q_3 = (q_1 ⊗ q_2)* ⊗ q``. For three orthogonal-consecutive axes this is the Euler-angle
  decomposition (e.g. Z-Y'-X''); at its gimbal lock (``R a_3 ∥ a_1``) θ_1 is free and is kept at
  the present position's value.

Each θ is then moved by whole turns to the tick value nearest the present position inside
``[min_ticks, max_ticks]``, and of the (up to two) solutions the one nearest the present position
(least squared tick distance) is returned. If no solution lies within the tick limits, or the
target is off the chain's reachable set by more than ``tolerance_deg`` (1-2 joint chains reach
only a subset of SO(3)), :class:`~rig.errors.UnreachableError` names the joint, the value and the
limits — goals are never clipped.

The per-sample paths (:meth:`ChainKinematics.forward`, :meth:`ChainKinematics.inverse`) use
plain floats (a few µs each); :meth:`ChainKinematics.forward_batch` is vectorised for recorded
tick series.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from models import qscalar as qs
from rig.errors import RigConfigError, UnreachableError

__all__ = ["RAD_PER_TICK", "TICKS_PER_REV", "ChainKinematics", "ServoJoint"]

TICKS_PER_REV = 4096
"""Encoder ticks per revolution of an X-series servo (0.088° per tick)."""
RAD_PER_TICK = 2.0 * math.pi / TICKS_PER_REV

_EPS = 1e-9
_FREE = 1e-7  # |projection| below which a subproblem-1 angle is free (gimbal lock)

Vec = tuple[float, float, float]
Quat = tuple[float, float, float, float]


@dataclass(frozen=True)
class ServoJoint:
    """One servo of a chain.

    Attributes
    ----------
    id : int
        Dynamixel ID, 0..252.
    axis : (3,) tuple of float
        Unit rotation axis in the frame of the previous link (joint 1: the parent segment).
    zero_ticks : int
        Present Position at which the joint angle is 0.
    direction : int
        +1 if increasing ticks turn positively (right hand) about ``axis``, −1 otherwise.
    min_ticks, max_ticks : int
        Allowed goal range, ticks (also written to the servo's position-limit registers).
    name : str or None
        Optional label (e.g. ``"elevation"``).
    """

    id: int
    axis: tuple[float, float, float]
    zero_ticks: int = 2048
    direction: int = 1
    min_ticks: int = 0
    max_ticks: int = 4095
    name: str | None = None

    def angle(self, ticks: float) -> float:
        """Joint angle (rad) at ``ticks``."""
        return self.direction * (ticks - self.zero_ticks) * RAD_PER_TICK


def _dot(a: Sequence[float], b: Sequence[float]) -> float:
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def _cross(a: Sequence[float], b: Sequence[float]) -> Vec:
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def _subproblem1(w: Sequence[float], p: Sequence[float], q: Sequence[float]) -> float | None:
    """Angle about unit ``w`` taking ``p`` to ``q`` (their projections ⟂ w); None if free."""
    dp, dq = _dot(w, p), _dot(w, q)
    pp = (p[0] - w[0] * dp, p[1] - w[1] * dp, p[2] - w[2] * dp)
    qq = (q[0] - w[0] * dq, q[1] - w[1] * dq, q[2] - w[2] * dq)
    if _dot(pp, pp) < _FREE**2 or _dot(qq, qq) < _FREE**2:
        return None
    return math.atan2(_dot(w, _cross(pp, qq)), _dot(pp, qq))


def _twist_about(q: Sequence[float], a: Sequence[float]) -> float:
    """Angle of the rotation about ``a`` closest to ``q``: 2 atan2(v·a, w)."""
    return 2.0 * math.atan2(q[1] * a[0] + q[2] * a[1] + q[3] * a[2], q[0])


def _angle_between(p: Sequence[float], q: Sequence[float]) -> float:
    d = abs(p[0] * q[0] + p[1] * q[1] + p[2] * q[2] + p[3] * q[3])
    return 2.0 * math.acos(min(1.0, d))


class ChainKinematics:
    """Forward and inverse kinematics of a 1-3 joint chain (see the module docstring).

    Parameters
    ----------
    joints : sequence of ServoJoint
        Parent → child order, 1 to 3 joints, distinct IDs, no two consecutive axes parallel.
    tolerance_deg : float
        Largest distance from the reachable set accepted by :meth:`inverse` (the residual of a
        3-joint chain with independent axes is round-off).

    Attributes
    ----------
    ids : tuple of int
    axes : (n, 3) float64
    zero_ticks, min_ticks, max_ticks : (n,) int64
    direction : (n,) float64
    """

    def __init__(self, joints: Sequence[ServoJoint], *, tolerance_deg: float = 0.1) -> None:
        joints = tuple(joints)
        if not 1 <= len(joints) <= 3:
            raise RigConfigError(f"a servo chain has 1 to 3 joints, got {len(joints)}")
        ids = [j.id for j in joints]
        if len(set(ids)) != len(ids):
            dup = next(i for i in ids if ids.count(i) > 1)
            raise RigConfigError(f"servo chain: duplicate ID {dup}", actual=ids)
        axes = []
        for j in joints:
            a = np.asarray(j.axis, dtype=np.float64)
            n = float(np.linalg.norm(a))
            if a.shape != (3,) or not np.all(np.isfinite(a)) or n < 1e-9:
                raise RigConfigError(f"servo chain: ID {j.id}: axis must be a non-zero 3-vector",
                                     actual=list(j.axis))
            axes.append(a / n)
            if j.direction not in (1, -1):
                raise RigConfigError(f"servo chain: ID {j.id}: direction must be 1 or -1",
                                     actual=j.direction)
            if not j.min_ticks <= j.zero_ticks <= j.max_ticks:
                raise RigConfigError(f"servo chain: ID {j.id}: zero_ticks outside "
                                     f"[min_ticks, max_ticks]", actual=j.zero_ticks,
                                     expected=f"{j.min_ticks}..{j.max_ticks}")
        for k in range(1, len(axes)):
            if abs(float(axes[k] @ axes[k - 1])) > 1.0 - 1e-6:
                raise RigConfigError(f"servo chain: axes of IDs {joints[k - 1].id} and "
                                     f"{joints[k].id} are parallel (no closed-form IK)")
        self.joints = joints
        self.n = len(joints)
        self.ids = tuple(ids)
        self.axes = np.array(axes)
        self._axes = tuple(tuple(float(x) for x in a) for a in axes)
        self.zero_ticks = np.array([j.zero_ticks for j in joints], dtype=np.int64)
        self.min_ticks = np.array([j.min_ticks for j in joints], dtype=np.int64)
        self.max_ticks = np.array([j.max_ticks for j in joints], dtype=np.int64)
        self.direction = np.array([j.direction for j in joints], dtype=np.float64)
        self._zero = tuple(float(j.zero_ticks) for j in joints)
        self._dir = tuple(float(j.direction) for j in joints)
        self._lo = tuple(float(j.min_ticks) for j in joints)
        self._hi = tuple(float(j.max_ticks) for j in joints)
        self.tolerance = math.radians(tolerance_deg)

    # -- forward --------------------------------------------------------------------------
    def angles(self, ticks: Sequence[float]) -> tuple[float, ...]:
        """Joint angles (rad) of ``ticks`` (n,)."""
        return tuple(d * (float(t) - z) * RAD_PER_TICK
                     for t, z, d in zip(ticks, self._zero, self._dir, strict=True))

    def forward(self, ticks: Sequence[float]) -> np.ndarray:
        """Limb orientation relative to the parent, (4,) float64 (w, x, y, z), ``w ≥ 0``.

        Parameters
        ----------
        ticks : (n,) array_like
            Present Position of each servo, parent → child.
        """
        q: Sequence[float] = (1.0, 0.0, 0.0, 0.0)
        for a, theta in zip(self._axes, self.angles(ticks), strict=True):
            q = qs.mul(q, qs.axis_angle(a, theta))
        out = np.array(q)
        return -out if out[0] < 0 else out

    def forward_batch(self, ticks: np.ndarray) -> np.ndarray:
        """Vectorised :meth:`forward`: ticks (N, n) → orientations (N, 4), ``w ≥ 0``."""
        from models import quaternion as Q

        t = np.asarray(ticks, dtype=np.float64)
        if t.ndim != 2 or t.shape[1] != self.n:
            raise ValueError(f"ticks must have shape (N, {self.n}), got {t.shape}")
        theta = self.direction * (t - self.zero_ticks) * RAD_PER_TICK
        q = np.tile(np.array([1.0, 0.0, 0.0, 0.0]), (len(t), 1))
        for k in range(self.n):
            q = Q.multiply(q, Q.from_axis_angle(self.axes[k], theta[:, k]))
        return np.where(q[:, :1] < 0, -q, q)

    # -- inverse --------------------------------------------------------------------------
    def _solutions(self, q: Quat, near_theta: Sequence[float]) -> list[tuple[float, ...]]:
        a = self._axes
        if self.n == 1:
            return [(_twist_about(q, a[0]),)]
        if self.n == 2:
            t1 = _subproblem1(a[0], a[1], qs.rotate(q, a[1]))
            if t1 is None:
                t1 = near_theta[0]
            q2 = qs.mul(qs.conj(qs.axis_angle(a[0], t1)), q)
            return [(t1, _twist_about(q2, a[1]))]
        a1, a2, a3 = a
        target = qs.rotate(q, a3)
        k = _dot(a1, a2)
        cr = _cross(a1, a2)
        cr2 = _dot(cr, cr)
        big_a, big_b = _dot(a1, target), _dot(a2, a3)
        alpha = (big_a - k * big_b) / (1.0 - k * k)
        beta = (big_b - k * big_a) / (1.0 - k * k)
        g2 = (1.0 - alpha * alpha - beta * beta - 2.0 * alpha * beta * k) / cr2
        if g2 < -1e-9:
            return []
        g = math.sqrt(max(g2, 0.0))
        out = []
        for s in ((1.0, -1.0) if g > 1e-9 else (1.0,)):
            c = tuple(alpha * a1[i] + beta * a2[i] + s * g * cr[i] for i in range(3))
            t1 = _subproblem1(a1, c, target)
            if t1 is None:  # gimbal lock: R a3 along a1, θ1 free -> keep the present value
                t1 = near_theta[0]
                q1 = qs.axis_angle(a1, t1)
                t2 = _subproblem1(a2, a3, qs.rotate(qs.conj(q1), target))
                if t2 is None:
                    t2 = near_theta[1]
            else:
                t2 = _subproblem1(a2, a3, c)
                if t2 is None:
                    t2 = near_theta[1]
            q12 = qs.mul(qs.axis_angle(a1, t1), qs.axis_angle(a2, t2))
            t3 = _twist_about(qs.mul(qs.conj(q12), q), a3)
            out.append((t1, t2, t3))
        return out

    def inverse_float(self, q: Sequence[float], near_ticks: Sequence[float]) -> np.ndarray:
        """Like :meth:`inverse` but returns unrounded ticks (n,) float64."""
        qq = (float(q[0]), float(q[1]), float(q[2]), float(q[3]))
        norm = math.sqrt(qq[0] ** 2 + qq[1] ** 2 + qq[2] ** 2 + qq[3] ** 2)
        if not norm > 0.5 or not math.isfinite(norm):
            raise UnreachableError("IK target is not a unit quaternion", actual=list(qq))
        qq = (qq[0] / norm, qq[1] / norm, qq[2] / norm, qq[3] / norm)
        near = tuple(float(t) for t in near_ticks)
        if len(near) != self.n:
            raise ValueError(f"near_ticks must have {self.n} values, got {len(near)}")
        near_theta = self.angles(near)
        # the cheap test first: each solution's ticks within the limits and their cost; then
        # the residual of the cheapest ones, in order, until one passes (the same answer as
        # checking every solution: the cheapest passing one, the first on ties)
        solutions = self._solutions(qq, near_theta)
        ranked = []
        for order, theta in enumerate(solutions):
            placed = self._placed(theta, near)
            if not isinstance(placed, int):
                ranked.append((placed[0], order, placed[1], theta))
        ranked.sort()
        for _, _, ticks, theta in ranked:
            if self._residual(theta, qq) <= self.tolerance:
                return np.array(ticks)
        return self._unreachable(qq, near, solutions)

    def _placed(self, theta, near) -> tuple[float, tuple[float, ...]] | int:
        """(cost, ticks) of joint angles ``theta`` placed nearest ``near`` within the tick
        limits, or the index of the first joint that cannot reach its angle."""
        ticks = []
        cost = 0.0
        for i, t in enumerate(theta):
            base = self._zero[i] + self._dir[i] * t / RAD_PER_TICK
            k_lo = math.ceil((self._lo[i] - base) / TICKS_PER_REV - 1e-9)
            k_hi = math.floor((self._hi[i] - base) / TICKS_PER_REV + 1e-9)
            if k_lo > k_hi:
                return i
            k = min(max(round((near[i] - base) / TICKS_PER_REV), k_lo), k_hi)
            tick = min(max(base + k * TICKS_PER_REV, self._lo[i]), self._hi[i])
            ticks.append(tick)
            cost += (tick - near[i]) ** 2
        return cost, tuple(ticks)

    def _residual(self, theta, qq) -> float:
        """Angle between the target and what the joint angles ``theta`` reach, rad."""
        r: Sequence[float] = (1.0, 0.0, 0.0, 0.0)
        for a, t in zip(self._axes, theta, strict=True):
            r = qs.mul(r, qs.axis_angle(a, t))
        return _angle_between(r, qq)

    def _unreachable(self, qq, near, solutions) -> np.ndarray:
        """Raise the :class:`UnreachableError` that says why no solution serves ``qq``."""
        why = "the chain's axes cannot reach it"
        residual_deg = None
        for theta in solutions:
            res = self._residual(theta, qq)
            if res > self.tolerance:
                residual_deg = math.degrees(res)
                continue
            i = self._placed(theta, near)
            if isinstance(i, int):
                base = self._zero[i] + self._dir[i] * theta[i] / RAD_PER_TICK
                why = (f"ID {self.ids[i]} would need {base % TICKS_PER_REV:.0f} ticks "
                       f"(mod 4096), outside its limits {self._lo[i]:.0f}..{self._hi[i]:.0f}")
        if residual_deg is not None and why.startswith("the chain"):
            why = f"{residual_deg:.2f}° from the nearest orientation the axes reach"
        raise UnreachableError(f"IK target {np.round(qq, 4).tolist()} unreachable: {why}")

    def inverse(self, q: Sequence[float], near_ticks: Sequence[float]) -> np.ndarray:
        """Goal ticks (n,) int64 for limb orientation ``q``, nearest ``near_ticks``.

        Parameters
        ----------
        q : (4,) array_like
            Limb relative to parent, (w, x, y, z); either sign.
        near_ticks : (n,) array_like
            Present Position (chooses among solutions and whole-turn branches).

        Raises
        ------
        UnreachableError
            No solution within the tick limits, or ``q`` farther than ``tolerance_deg`` from
            the chain's reachable set; never clipped.
        """
        return np.rint(self.inverse_float(q, near_ticks)).astype(np.int64)

    def inverse_batch(self, q: np.ndarray, near_ticks: Sequence[float]) -> np.ndarray:
        """Goal ticks (N, n) for a trajectory (N, 4), each solution nearest the previous one
        (the first nearest ``near_ticks``): a sequential choice, so a loop over samples."""
        q = np.asarray(q, dtype=np.float64).reshape(-1, 4)
        out = np.empty((len(q), self.n), dtype=np.int64)
        prev = np.asarray(near_ticks, dtype=np.float64)
        for i, qi in enumerate(q):
            prev = self.inverse_float(qi, prev)
            out[i] = np.rint(prev)
        return out
