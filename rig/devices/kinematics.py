"""Joint and limb kinematics: servo ticks ↔ joint orientations, above the servo bus.

Vocabulary (``docs/architecture.md``): the *servo bus* (:mod:`rig.devices.bus`) knows servos by
ID, name and register — ticks, torque, alerts, watchdog — and no kinematics. Above it,
:class:`JointKinematics` maps the ticks of one joint's 1-3 servos to the joint's orientation and
back (FK/IK, tick limits), and :class:`LimbKinematics` holds the joints of a limb in order, each
with its kinematics, mapping the bus's whole tick vector to ``(J, 4)`` joint orientations (a
one-joint rig is a limb of one joint).

Model of one joint
------------------
Servo ``i`` of a joint (parent → child order) turns about a fixed unit axis ``a_i`` expressed in
the frame of the link before it (servo 1: the parent segment, e.g. the thorax). Its angle is

    θ_i = direction_i · (ticks_i − zero_i) · 2π / T_i

with ``T_i`` servo ``i``'s ticks per revolution (:attr:`ServoAxis.ticks_per_rev`, its model's
``units.ticks_per_rev``: X series 4096; AX-12A, AX-18A and XL-320 1228.8, 1024 ticks over
300°; P-series e.g. PH54-200-S500 1,003,846, ±501,923 over ±180°; see
:func:`rig.devices.config.servo_position_defaults`)

and the limb orientation relative to the parent (scalar-first Hamilton quaternion, limb long
axis +X) is the product of axis-angle rotations parent → child (intrinsic composition)

    q = exp(θ_1 a_1 / 2) ⊗ exp(θ_2 a_2 / 2) ⊗ exp(θ_3 a_3 / 2).

Inverse kinematics (closed form; Paden-Kahan subproblems, Murray, Li & Sastry, *A Mathematical
Introduction to Robotic Manipulation*, 1994, §3.3)
-------------------------------------------------------------------------------------------------
* **Subproblem 1** — the angle θ about ``ω`` taking ``p`` to ``q``: project both on the plane
  ⟂ ω (``p' = p − ω(ω·p)``), ``θ = atan2(ω·(p'×q'), p'·q')``; it exists iff ``ω·p = ω·q``.
* **1 servo** — ``θ_1 = 2 atan2(v·a_1, w)`` for ``q = (w, v)``.
* **2 servos** — ``R_1 R_2 a_2 = R_1 a_2 = R a_2`` gives θ_1 by subproblem 1, then
  ``q_2 = q_1* ⊗ q`` must be a rotation about ``a_2``. For a target off the servos' surface
  the same closed form (θ_1 turning ``a_2`` nearest ``R a_2``, then the twist about ``a_2``)
  gives the **nearest** orientation they reach (checked against the top singular pair of
  ``M = [[w, v·a_2], [v·a_1, −(a_1·a_2) w + v·(a_1×a_2)]]``, where
  ``⟨exp(θ_1 a_1/2) ⊗ exp(θ_2 a_2/2), q⟩ = u_1ᵀ M u_2``, ``u_i = (cos θ_i/2, sin θ_i/2)``: the
  same residual to 1e-9°), as one servo's ``2 atan2(v·a_1, w)`` is.
* **3 servos** — ``R_1 R_2 a_3 = R a_3`` is **subproblem 2**: ``c = R_2 a_3 = R_1ᵀ R a_3``
  satisfies ``a_1·c = a_1·R a_3`` and ``a_2·c = a_2·a_3``, so with ``k = a_1·a_2``
  ``c = α a_1 + β a_2 ± γ (a_1 × a_2)``, ``α = (a_1·Ra_3 − k a_2·a_3)/(1−k²)``,
  ``β = (a_2·a_3 − k a_1·Ra_3)/(1−k²)``, ``γ² = (1 − α² − β² − 2αβk)/|a_1×a_2|²``: two solutions
  (one when γ = 0, none when γ² < 0). θ_2 and θ_1 by subproblem 1, then θ_3 from
  ``q_3 = (q_1 ⊗ q_2)* ⊗ q``. For three orthogonal-consecutive axes this is the Euler-angle
  decomposition (e.g. Z-Y'-X''); at its gimbal lock (``R a_3 ∥ a_1``) θ_1 is free and is kept at
  the present position's value.

Each θ is then moved by whole turns (``T_i`` ticks each) to the tick value nearest the present
position inside ``[min_ticks, max_ticks]`` (an angle less than half a tick beyond a limit is
the limit: the tick it rounds to; a servo whose range is less than a turn, an AX's 300°, may
have no such value: the angle is then unreachable, never a tick outside its range), and of the
(up to two) solutions the one nearest the present position (least squared tick distance) is
returned. If no solution lies within the tick limits, or the target is off the joint's
reachable set by more than ``tolerance_deg`` (joints of 1-2
servos reach only a subset of SO(3)), :class:`~rig.errors.UnreachableError` names the servo,
the value and the limits — goals are never clipped. A rig's joint of 1-2 servos has the
tolerance :data:`NEAREST_TOLERANCE_DEG` by default (:func:`default_tolerance_deg`): any target
becomes the nearest orientation its axes reach (within its tick limits), and the loop's
supervisor judges the forward kinematics of those ticks, not the target.

The per-sample paths (:meth:`JointKinematics.forward`, :meth:`JointKinematics.inverse`) run
in kernels compiled by numba (``_forward_kernel``, ``_ik_kernel``: about 1 µs and 2 µs, where
the same maths in plain Python took 5 µs and 34 µs on this project's 2-core machine); they are
the live loop's per-cycle kinematics. The kernels compile on first use (about a second, cached
on disk after that): :meth:`JointKinematics.compile` does it before a loop starts.
:meth:`JointKinematics.forward_batch` is vectorised for recorded tick series.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from models import qkernels as qk
from models import quaternion as Q
from models.jit import njit
from models.quaternion import normalize_rows
from rig.errors import RigConfigError, UnreachableError

__all__ = ["EXACT_TOLERANCE_DEG", "NEAREST_TOLERANCE_DEG", "RAD_PER_TICK", "TICKS_PER_REV",
           "JointKinematics", "LimbKinematics", "ServoAxis", "default_tolerance_deg",
           "rad_per_tick"]

TICKS_PER_REV = 4096
"""Encoder ticks per revolution of an X-series servo (0.088° per tick): the default of
:attr:`ServoAxis.ticks_per_rev`; each axis converts with its own."""
RAD_PER_TICK = 2.0 * math.pi / TICKS_PER_REV
"""Radians per tick at :data:`TICKS_PER_REV`; :func:`rad_per_tick` of each axis's own
resolution is computed the same way (``2π / T``), so an X-series axis gives exactly this."""
EXACT_TOLERANCE_DEG = 0.1
"""The IK tolerance of a joint of 3 servos (its residual is round-off): a target is reached."""
NEAREST_TOLERANCE_DEG = 180.0
"""The IK tolerance that accepts any orientation: the goal is the nearest one the axes reach."""


def rad_per_tick(ticks_per_rev):
    """Radians per tick of a resolution (scalar or array): ``2π / ticks_per_rev``, computed as
    :data:`RAD_PER_TICK` is, so that 4096 gives exactly that float.

    Parameters
    ----------
    ticks_per_rev : float or (n,) array_like of float
        Ticks per revolution (X series 4096, AX-12A 1228.8, PH54-200-S500 1,003,846).
    """
    if np.ndim(ticks_per_rev) == 0:
        return 2.0 * math.pi / float(ticks_per_rev)
    return 2.0 * math.pi / np.asarray(ticks_per_rev, dtype=np.float64)


def default_tolerance_deg(n_servos: int) -> float:
    """The IK tolerance a rig's joint gets by default: :data:`EXACT_TOLERANCE_DEG` for 3
    servos, :data:`NEAREST_TOLERANCE_DEG` for 1-2 (they reach a 1-2-D subset of SO(3): a
    target off it becomes the nearest orientation they reach).

    Parameters
    ----------
    n_servos : int
        The joint's servos, 1 to 3.
    """
    return EXACT_TOLERANCE_DEG if n_servos >= 3 else NEAREST_TOLERANCE_DEG

_FREE = 1e-7  # |projection| below which a subproblem-1 angle is free (gimbal lock)
_HALF_TICK = 0.5  # an angle less than this beyond a tick limit rounds onto it

Vec = tuple[float, float, float]
Quat = tuple[float, float, float, float]


@dataclass(frozen=True)
class ServoAxis:
    """One servo of a joint: its ID, the axis it turns the joint about, zero, direction, limits.

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
    ticks_per_rev : float
        The servo's position resolution, ticks per revolution (X series 4096, the default;
        AX-12A / AX-18A / XL-320 1228.8; P-series e.g. 1,003,846): its model's
        ``units.ticks_per_rev`` (:func:`firmware_protocol.dynamixel.load_control_table`).
    """

    id: int
    axis: tuple[float, float, float]
    zero_ticks: int = 2048
    direction: int = 1
    min_ticks: int = 0
    max_ticks: int = 4095
    name: str | None = None
    ticks_per_rev: float = float(TICKS_PER_REV)

    def angle(self, ticks: float) -> float:
        """Joint angle (rad) at ``ticks``."""
        return self.direction * (ticks - self.zero_ticks) * rad_per_tick(self.ticks_per_rev)


_FREE2 = _FREE * _FREE


@njit(inline="always")
def _axis_angle(axes, i, theta):
    """Rotation by ``theta`` about ``axes[i]``."""
    return qk.axis_angle(axes[i, 0], axes[i, 1], axes[i, 2], theta)


@njit(inline="always")
def _subproblem1(w0, w1, w2, p0, p1, p2, q0, q1, q2):
    """Angle about unit ``w`` taking ``p`` to ``q`` (their projections ⟂ w); NaN if free."""
    dp = w0 * p0 + w1 * p1 + w2 * p2
    dq = w0 * q0 + w1 * q1 + w2 * q2
    a0, a1, a2 = p0 - w0 * dp, p1 - w1 * dp, p2 - w2 * dp
    b0, b1, b2 = q0 - w0 * dq, q1 - w1 * dq, q2 - w2 * dq
    if a0 * a0 + a1 * a1 + a2 * a2 < _FREE2 or b0 * b0 + b1 * b1 + b2 * b2 < _FREE2:
        return math.nan
    c0, c1, c2 = a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0
    return math.atan2(w0 * c0 + w1 * c1 + w2 * c2, a0 * b0 + a1 * b1 + a2 * b2)


@njit(inline="always")
def _twist_about(w, x, y, z, axes, i):
    """Angle of the rotation about ``axes[i]`` closest to ``q``: 2 atan2(v·a, w)."""
    return 2.0 * math.atan2(x * axes[i, 0] + y * axes[i, 1] + z * axes[i, 2], w)


@njit
def _forward_kernel(axes, zero, direction, rpt, n, ticks):
    """Limb orientation (w, x, y, z), ``w ≥ 0``, of ``ticks`` (n,); ``rpt`` (n,) radians per
    tick."""
    w, x, y, z = 1.0, 0.0, 0.0, 0.0
    for i in range(n):
        theta = direction[i] * (float(ticks[i]) - zero[i]) * rpt[i]
        a0, a1, a2, a3 = _axis_angle(axes, i, theta)
        w, x, y, z = qk.mul(w, x, y, z, a0, a1, a2, a3)
    if w < 0.0:
        return -w, -x, -y, -z
    return w, x, y, z


@njit
def _solutions_kernel(axes, n, w, x, y, z, near1, near2):
    """The (up to two) joint-angle solutions for unit ``q``: ``(count, θ (2, 3))``; joints
    beyond ``n`` are 0. ``near1``, ``near2``: the present angles of joints 1 and 2 (kept at a
    gimbal lock)."""
    out = np.zeros((2, 3))
    if n == 1:
        out[0, 0] = _twist_about(w, x, y, z, axes, 0)
        return 1, out
    if n == 2:
        r0, r1, r2 = qk.rotate(w, x, y, z, axes[1, 0], axes[1, 1], axes[1, 2])
        t1 = _subproblem1(axes[0, 0], axes[0, 1], axes[0, 2],
                          axes[1, 0], axes[1, 1], axes[1, 2], r0, r1, r2)
        if math.isnan(t1):
            t1 = near1
        c0, c1, c2, c3 = _axis_angle(axes, 0, t1)
        v0, v1, v2, v3 = qk.mul(c0, -c1, -c2, -c3, w, x, y, z)
        out[0, 0] = t1
        out[0, 1] = _twist_about(v0, v1, v2, v3, axes, 1)
        return 1, out
    a10, a11, a12 = axes[0, 0], axes[0, 1], axes[0, 2]
    a20, a21, a22 = axes[1, 0], axes[1, 1], axes[1, 2]
    a30, a31, a32 = axes[2, 0], axes[2, 1], axes[2, 2]
    g0, g1, g2 = qk.rotate(w, x, y, z, a30, a31, a32)  # R a3
    k = a10 * a20 + a11 * a21 + a12 * a22
    cr0, cr1, cr2 = a11 * a22 - a12 * a21, a12 * a20 - a10 * a22, a10 * a21 - a11 * a20
    crn = cr0 * cr0 + cr1 * cr1 + cr2 * cr2
    big_a = a10 * g0 + a11 * g1 + a12 * g2
    big_b = a20 * a30 + a21 * a31 + a22 * a32
    alpha = (big_a - k * big_b) / (1.0 - k * k)
    beta = (big_b - k * big_a) / (1.0 - k * k)
    gg = (1.0 - alpha * alpha - beta * beta - 2.0 * alpha * beta * k) / crn
    if gg < -1e-9:
        return 0, out
    gam = math.sqrt(max(gg, 0.0))
    count = 2 if gam > 1e-9 else 1
    for j in range(count):
        s = 1.0 if j == 0 else -1.0
        c0 = alpha * a10 + beta * a20 + s * gam * cr0
        c1 = alpha * a11 + beta * a21 + s * gam * cr1
        c2 = alpha * a12 + beta * a22 + s * gam * cr2
        t1 = _subproblem1(a10, a11, a12, c0, c1, c2, g0, g1, g2)
        if math.isnan(t1):  # gimbal lock: R a3 along a1, θ1 free -> keep the present value
            t1 = near1
            q0, q1, q2, q3 = _axis_angle(axes, 0, t1)
            h0, h1, h2 = qk.rotate(q0, -q1, -q2, -q3, g0, g1, g2)
            t2 = _subproblem1(a20, a21, a22, a30, a31, a32, h0, h1, h2)
        else:
            t2 = _subproblem1(a20, a21, a22, a30, a31, a32, c0, c1, c2)
        if math.isnan(t2):
            t2 = near2
        p0, p1, p2, p3 = _axis_angle(axes, 0, t1)
        e0, e1, e2, e3 = _axis_angle(axes, 1, t2)
        m0, m1, m2, m3 = qk.mul(p0, p1, p2, p3, e0, e1, e2, e3)
        v0, v1, v2, v3 = qk.mul(m0, -m1, -m2, -m3, w, x, y, z)
        out[j, 0] = t1
        out[j, 1] = t2
        out[j, 2] = _twist_about(v0, v1, v2, v3, axes, 2)
    return count, out


@njit
def _placed_kernel(zero, direction, rpt, tpr, lo, hi, n, theta, near, ticks):
    """Joint angles ``theta`` placed nearest ``near`` within the tick limits, written to
    ``ticks``: ``(-1, cost)``, or ``(i, 0)`` with ``i`` the first joint that cannot reach its
    angle. ``rpt``, ``tpr`` (n,): each servo's radians per tick and ticks per turn."""
    cost = 0.0
    for i in range(n):
        base = zero[i] + direction[i] * theta[i] / rpt[i]
        # within half a tick of a limit is the limit (what rounding to a tick gives); the
        # whole turns k that land inside [lo, hi] (none: a servo whose range is less than a
        # turn, an AX's 300°, cannot take this angle)
        k_lo = math.ceil((lo[i] - _HALF_TICK - base) / tpr[i] - 1e-9)
        k_hi = math.floor((hi[i] + _HALF_TICK - base) / tpr[i] + 1e-9)
        if k_lo > k_hi:
            return i, 0.0
        k = min(max(round((near[i] - base) / tpr[i]), k_lo), k_hi)
        tick = min(max(base + k * tpr[i], lo[i]), hi[i])
        ticks[i] = tick
        cost += (tick - near[i]) ** 2
    return -1, cost


@njit
def _residual_kernel(axes, n, theta, w, x, y, z):
    """Angle between unit ``q`` and what the joint angles ``theta`` reach, rad."""
    r0, r1, r2, r3 = 1.0, 0.0, 0.0, 0.0
    for i in range(n):
        a0, a1, a2, a3 = _axis_angle(axes, i, theta[i])
        r0, r1, r2, r3 = qk.mul(r0, r1, r2, r3, a0, a1, a2, a3)
    d = abs(r0 * w + r1 * x + r2 * y + r3 * z)
    return 2.0 * math.acos(min(1.0, d))


@njit
def _ik_kernel(axes, zero, direction, rpt, tpr, lo, hi, n, w, x, y, z, near, tol, ticks):
    """Closed-form IK of unit ``q`` nearest ``near`` (ticks, n): the cheapest solution within
    the limits whose residual is at most ``tol``, the first on ties, written to ``ticks``;
    True if there is one."""
    near1 = direction[0] * (near[0] - zero[0]) * rpt[0]
    near2 = direction[1] * (near[1] - zero[1]) * rpt[1] if n > 1 else 0.0
    count, sols = _solutions_kernel(axes, n, w, x, y, z, near1, near2)
    placed = np.empty((2, 3))
    costs = np.full(2, np.inf)
    for j in range(count):
        i, c = _placed_kernel(zero, direction, rpt, tpr, lo, hi, n, sols[j], near, placed[j])
        if i < 0:
            costs[j] = c
    first = 1 if costs[1] < costs[0] else 0  # the cheaper first, the first on ties
    for j in (first, 1 - first):
        if costs[j] < np.inf and _residual_kernel(axes, n, sols[j], w, x, y, z) <= tol:
            for i in range(n):
                ticks[i] = placed[j, i]
            return True
    return False


@njit
def _nearest_batch_kernel(axes, zero, direction, rpt, tpr, lo, hi, n, q, near, out):
    """Per row of unit ``q`` (N, 4): the orientation of the IK solution nearest it (any
    residual) within the tick limits, ``w ≥ 0``, written to ``out`` (NaN: none)."""
    ticks = np.empty(n)
    for r in range(q.shape[0]):
        if _ik_kernel(axes, zero, direction, rpt, tpr, lo, hi, n, q[r, 0], q[r, 1], q[r, 2],
                      q[r, 3], near, math.pi + 1e-9, ticks):
            w, x, y, z = _forward_kernel(axes, zero, direction, rpt, n, ticks)
            out[r, 0], out[r, 1], out[r, 2], out[r, 3] = w, x, y, z
        else:
            out[r, :] = math.nan


def _kernel_array(values) -> np.ndarray:
    """``values`` as the kernels take them: a contiguous int64 array as it is (the drivers'
    ticks), anything else as contiguous float64 — two compiled signatures in all, both built
    by :meth:`JointKinematics.compile`, so no call inside a control loop compiles."""
    if (isinstance(values, np.ndarray) and values.dtype in (np.int64, np.float64)
            and values.flags.c_contiguous):
        return values
    return np.ascontiguousarray(values, dtype=np.float64)


class JointKinematics:
    """Forward and inverse kinematics of one joint moved by 1-3 servos (see the module
    docstring).

    Parameters
    ----------
    servos : sequence of ServoAxis
        Parent → child order, 1 to 3 servos, distinct IDs, no two consecutive axes parallel.
    tolerance_deg : float
        Largest distance from the reachable set accepted by :meth:`inverse` (the residual of a
        3-servo joint with independent axes is round-off).

    Attributes
    ----------
    servos : tuple of ServoAxis
    n : int
        Number of servos.
    ids : tuple of int
    axes : (n, 3) float64
    zero_ticks, min_ticks, max_ticks : (n,) int64
    direction : (n,) float64
    ticks_per_rev : (n,) float64
        Each servo's resolution (:attr:`ServoAxis.ticks_per_rev`).
    rad_per_tick : (n,) float64
        ``2π / ticks_per_rev`` (:func:`rad_per_tick`).
    """

    def __init__(self, servos: Sequence[ServoAxis], *, tolerance_deg: float = 0.1) -> None:
        servos = tuple(servos)
        if not 1 <= len(servos) <= 3:
            raise RigConfigError(f"a joint has 1 to 3 servos, got {len(servos)}")
        ids = [j.id for j in servos]
        if len(set(ids)) != len(ids):
            dup = next(i for i in ids if ids.count(i) > 1)
            raise RigConfigError(f"joint kinematics: duplicate ID {dup}", actual=ids)
        axes = []
        for j in servos:
            a = np.asarray(j.axis, dtype=np.float64).reshape(1, -1)
            unit, n = normalize_rows(a) if a.shape == (1, 3) and np.isfinite(a).all() \
                else (a, [0.0])
            if n[0] < 1e-9:
                raise RigConfigError(f"joint kinematics: ID {j.id}: axis must be a non-zero "
                                     f"3-vector", actual=list(j.axis))
            axes.append(unit[0])
            if j.direction not in (1, -1):
                raise RigConfigError(f"joint kinematics: ID {j.id}: direction must be 1 or -1",
                                     actual=j.direction)
            if not (math.isfinite(j.ticks_per_rev) and j.ticks_per_rev > 0):
                raise RigConfigError(f"joint kinematics: ID {j.id}: ticks_per_rev must be a "
                                     f"positive number", actual=j.ticks_per_rev)
            if not j.min_ticks <= j.zero_ticks <= j.max_ticks:
                raise RigConfigError(f"joint kinematics: ID {j.id}: zero_ticks outside "
                                     f"[min_ticks, max_ticks]", actual=j.zero_ticks,
                                     expected=f"{j.min_ticks}..{j.max_ticks}")
        for k in range(1, len(axes)):
            if abs(float(axes[k] @ axes[k - 1])) > 1.0 - 1e-6:
                raise RigConfigError(f"joint kinematics: axes of IDs {servos[k - 1].id} and "
                                     f"{servos[k].id} are parallel (no closed-form IK)")
        self.servos = servos
        self.tolerance_deg = tolerance_deg
        self.n = len(servos)
        self.ids = tuple(ids)
        self.axes = np.array(axes)
        self.zero_ticks = np.array([j.zero_ticks for j in servos], dtype=np.int64)
        self.min_ticks = np.array([j.min_ticks for j in servos], dtype=np.int64)
        self.max_ticks = np.array([j.max_ticks for j in servos], dtype=np.int64)
        self.direction = np.array([j.direction for j in servos], dtype=np.float64)
        self.ticks_per_rev = np.array([j.ticks_per_rev for j in servos], dtype=np.float64)
        self.rad_per_tick = rad_per_tick(self.ticks_per_rev)
        self._rpt = tuple(float(r) for r in self.rad_per_tick)
        self._zero = tuple(float(j.zero_ticks) for j in servos)
        self._dir = tuple(float(j.direction) for j in servos)
        self._lo = tuple(float(j.min_ticks) for j in servos)
        self._hi = tuple(float(j.max_ticks) for j in servos)
        self.tolerance = math.radians(tolerance_deg)
        # the compiled kernels' view: contiguous float64 arrays
        self._zero_c = np.array(self._zero)
        self._lo_c = np.array(self._lo)
        self._hi_c = np.array(self._hi)

    def with_limits(self, min_ticks: Sequence[int], max_ticks: Sequence[int]) -> JointKinematics:
        """The same joint with other tick limits (validated as at construction).

        Parameters
        ----------
        min_ticks, max_ticks : (n,) array_like of int
            Per servo, parent → child.

        Raises
        ------
        ValueError
            Not ``n`` values each.
        RigConfigError
            A zero outside its new limits.
        """
        lo, hi = np.asarray(min_ticks), np.asarray(max_ticks)
        if lo.shape != (self.n,) or hi.shape != (self.n,):
            raise ValueError(f"need {self.n} min and max ticks, got {lo.shape}, {hi.shape}")
        servos = tuple(dataclasses.replace(s, min_ticks=int(a), max_ticks=int(b))
                       for s, a, b in zip(self.servos, lo, hi, strict=True))
        return JointKinematics(servos, tolerance_deg=self.tolerance_deg)

    # -- forward --------------------------------------------------------------------------
    def angles(self, ticks: Sequence[float]) -> tuple[float, ...]:
        """Joint angles (rad) of ``ticks`` (n,)."""
        return tuple(d * (float(t) - z) * r
                     for t, z, d, r in zip(ticks, self._zero, self._dir, self._rpt, strict=True))

    def forward(self, ticks: Sequence[float]) -> np.ndarray:
        """Joint orientation (child segment relative to the parent), (4,) float64 (w, x, y, z),
        ``w ≥ 0``.

        Parameters
        ----------
        ticks : (n,) array_like
            Present Position of each servo, parent → child.
        """
        return np.array(self.forward_one(ticks))

    def forward_one(self, ticks: Sequence[float]) -> Quat:
        """:meth:`forward` as a tuple of floats (the live loop's per-cycle form)."""
        t = _kernel_array(ticks)
        if t.shape != (self.n,):
            raise ValueError(f"ticks must have {self.n} values, got shape {t.shape}")
        return _forward_kernel(self.axes, self._zero_c, self.direction, self.rad_per_tick,
                               self.n, t)

    def compile(self) -> JointKinematics:
        """Compile (or load from numba's on-disk cache) the per-sample kernels now, so the
        first :meth:`forward` or :meth:`inverse` of a running loop does not pay for it."""
        self.forward_one(self._zero_c)
        q = self.forward(self.zero_ticks)
        self.inverse_float(q, self.zero_ticks)
        self.inverse_float(q, self._zero_c)
        try:  # the kernels behind an unreachable goal's message, called from Python
            self._unreachable(tuple(q), self._zero_c)
        except UnreachableError:
            pass
        return self

    def forward_batch(self, ticks: np.ndarray) -> np.ndarray:
        """Vectorised :meth:`forward`: ticks (N, n) → orientations (N, 4), ``w ≥ 0``."""
        t = np.asarray(ticks, dtype=np.float64)
        if t.ndim != 2 or t.shape[1] != self.n:
            raise ValueError(f"ticks must have shape (N, {self.n}), got {t.shape}")
        theta = self.direction * (t - self.zero_ticks) * self.rad_per_tick
        q = np.tile(np.array([1.0, 0.0, 0.0, 0.0]), (len(t), 1))
        for k in range(self.n):
            q = Q.multiply(q, Q.from_axis_angle(self.axes[k], theta[:, k]))
        return np.where(q[:, :1] < 0, -q, q)

    # -- inverse --------------------------------------------------------------------------
    def inverse_float(self, q: Sequence[float], near_ticks: Sequence[float]) -> np.ndarray:
        """Like :meth:`inverse` but returns unrounded ticks (n,) float64."""
        w, x, y, z = float(q[0]), float(q[1]), float(q[2]), float(q[3])
        norm = math.sqrt(w * w + x * x + y * y + z * z)
        if not norm > 0.5 or not math.isfinite(norm):
            raise UnreachableError("IK target is not a unit quaternion", actual=[w, x, y, z])
        w, x, y, z = w / norm, x / norm, y / norm, z / norm
        near = _kernel_array(near_ticks)
        if near.shape != (self.n,):
            raise ValueError(f"near_ticks must have {self.n} values, got {near.size}")
        ticks = np.empty(self.n)
        if _ik_kernel(self.axes, self._zero_c, self.direction, self.rad_per_tick,
                      self.ticks_per_rev, self._lo_c, self._hi_c, self.n, w, x, y, z, near,
                      self.tolerance, ticks):
            return ticks
        return self._unreachable((w, x, y, z), near)

    def _unreachable(self, qq, near) -> np.ndarray:
        """Raise the :class:`UnreachableError` that says why no solution serves ``qq``."""
        near = np.asarray(near, dtype=np.float64)
        nt = self.angles(near)
        count, sols = _solutions_kernel(self.axes, self.n, *qq, nt[0],
                                        nt[1] if self.n > 1 else 0.0)
        why = "the chain's axes cannot reach it"  # wording kept: CLI output unchanged
        residual_deg = None
        scratch = np.empty(self.n)
        for theta in sols[:count]:
            res = _residual_kernel(self.axes, self.n, theta, *qq)
            if res > self.tolerance:
                residual_deg = math.degrees(res)
                continue
            i, _ = _placed_kernel(self._zero_c, self.direction, self.rad_per_tick,
                                  self.ticks_per_rev, self._lo_c, self._hi_c, self.n, theta,
                                  near, scratch)
            if i >= 0:
                base = self._zero[i] + self._dir[i] * theta[i] / self._rpt[i]
                turn = float(self.ticks_per_rev[i])
                why = (f"ID {self.ids[i]} would need {base % turn:.0f} ticks "
                       f"(mod {turn:g}), outside its limits {self._lo[i]:.0f}..{self._hi[i]:.0f}")
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
            the joint's reachable set; never clipped.
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


    def nearest_batch(self, q: np.ndarray, near_ticks: Sequence[float] | None = None
                      ) -> np.ndarray:
        """The orientations the servos reach nearest each target, whatever the tolerance.

        Parameters
        ----------
        q : (N, 4) array_like
            Targets (either sign); rows not finite or not of unit norm (within 0.5) give NaN.
        near_ticks : (n,) array_like, optional
            Chooses among solutions and whole-turn branches (default: the servos' zeros).

        Returns
        -------
        (N, 4) float64
            Forward kinematics of the (unrounded) IK solution nearest each target within the
            tick limits, ``w ≥ 0``; NaN rows where the tick limits leave none. A 3-servo
            joint's is the target itself (up to round-off).
        """
        q = np.asarray(q, dtype=np.float64).reshape(-1, 4)
        norm = np.linalg.norm(q, axis=1, keepdims=True)
        ok = np.isfinite(norm[:, 0]) & (norm[:, 0] > 0.5)
        unit = np.where(ok[:, None], q / np.where(ok[:, None], norm, 1.0), 1.0)
        unit = np.ascontiguousarray(unit)
        near = self._zero_c if near_ticks is None else _kernel_array(near_ticks)
        out = np.empty((len(q), 4))
        _nearest_batch_kernel(self.axes, self._zero_c, self.direction, self.rad_per_tick,
                              self.ticks_per_rev, self._lo_c, self._hi_c, self.n, unit, near, out)
        out[~ok] = np.nan
        return out


class LimbKinematics:
    """The joints of a limb in order, each with its :class:`JointKinematics`: the servo bus's
    whole tick vector ↔ ``(J, 4)`` joint orientations.

    The bus's servos are the joints' servos concatenated, parent → child (joint 1's servos
    first); joint ``j`` owns the slice :attr:`slices` ``[j]`` of the tick vector. Each joint's
    orientation is its child segment relative to its parent segment, as its own kinematics
    gives it: the maths of each joint is :class:`JointKinematics`' unchanged. A one-joint rig is
    a limb of one joint.

    Parameters
    ----------
    joints : sequence of JointKinematics
        Proximal → distal; no servo ID in two joints.
    names : sequence of str, optional
        The joints' names (e.g. ``("shoulder", "elbow")``); default ``joint1``, ``joint2``, ...

    Attributes
    ----------
    joints : tuple of JointKinematics
    names : tuple of str
    ids : tuple of int
        Every servo, in tick-vector order.
    n : int
        Number of servos.
    slices : tuple of slice
        Each joint's part of the tick vector.
    min_ticks, max_ticks, zero_ticks : (n,) int64
        Concatenated over the joints.
    ticks_per_rev, rad_per_tick : (n,) float64
        Each servo's resolution and ``2π / ticks_per_rev``, tick-vector order.

    Raises
    ------
    RigConfigError
        No joint, a servo ID in two joints, names not one per joint or repeated.
    """

    def __init__(self, joints: Sequence[JointKinematics],
                 names: Sequence[str] | None = None) -> None:
        joints = tuple(joints)
        if not joints:
            raise RigConfigError("a limb has at least one joint")
        names = tuple(f"joint{k + 1}" for k in range(len(joints))) if names is None \
            else tuple(str(n) for n in names)
        if len(names) != len(joints) or len(set(names)) != len(names):
            raise RigConfigError("limb kinematics: one distinct name per joint", actual=names)
        ids = [i for j in joints for i in j.ids]
        if len(set(ids)) != len(ids):
            dup = next(i for i in ids if ids.count(i) > 1)
            raise RigConfigError(f"limb kinematics: servo ID {dup} in two joints", actual=ids)
        self.joints = joints
        self.names = names
        self.ids = tuple(ids)
        self.n = len(ids)
        starts = np.cumsum([0] + [j.n for j in joints]).tolist()
        self.slices = tuple(slice(a, b) for a, b in itertools.pairwise(starts))
        self.min_ticks = np.concatenate([j.min_ticks for j in joints])
        self.max_ticks = np.concatenate([j.max_ticks for j in joints])
        self.zero_ticks = np.concatenate([j.zero_ticks for j in joints])
        self.ticks_per_rev = np.concatenate([j.ticks_per_rev for j in joints])
        self.rad_per_tick = np.concatenate([j.rad_per_tick for j in joints])

    def __len__(self) -> int:
        return len(self.joints)

    def joint(self, key: int | str) -> JointKinematics:
        """One joint's kinematics, by position or name."""
        return self.joints[self.names.index(key) if isinstance(key, str) else key]

    def split(self, ticks: Sequence[float]) -> list[np.ndarray]:
        """The tick vector (n,) — or a series (N, n) — cut into each joint's part."""
        t = np.asarray(ticks)
        if t.shape[-1] != self.n:
            raise ValueError(f"ticks must have {self.n} values per row, got shape {t.shape}")
        return [t[..., s] for s in self.slices]

    def with_limits(self, min_ticks: Sequence[int], max_ticks: Sequence[int]) -> LimbKinematics:
        """The same limb with other tick limits, (n,) each in tick-vector order
        (:meth:`JointKinematics.with_limits` per joint)."""
        lo, hi = np.asarray(min_ticks), np.asarray(max_ticks)
        if lo.shape != (self.n,) or hi.shape != (self.n,):
            raise ValueError(f"need {self.n} min and max ticks, got {lo.shape}, {hi.shape}")
        return LimbKinematics([j.with_limits(lo[s], hi[s]) for j, s in
                               zip(self.joints, self.slices, strict=True)], self.names)

    def compile(self) -> LimbKinematics:
        """:meth:`JointKinematics.compile` of every joint."""
        for j in self.joints:
            j.compile()
        return self

    def forward(self, ticks: Sequence[float]) -> np.ndarray:
        """Joint orientations, (J, 4) float64, each joint's child relative to its parent.

        Parameters
        ----------
        ticks : (n,) array_like
            Present Position of every servo, in tick-vector order.
        """
        parts = self.split(ticks)
        return np.stack([j.forward(t) for j, t in zip(self.joints, parts, strict=True)])

    def forward_batch(self, ticks: np.ndarray) -> np.ndarray:
        """Vectorised :meth:`forward`: ticks (N, n) → orientations (N, J, 4)."""
        t = np.asarray(ticks, dtype=np.float64)
        if t.ndim != 2:
            raise ValueError(f"ticks must have shape (N, {self.n}), got {t.shape}")
        parts = self.split(t)
        return np.stack([j.forward_batch(p) for j, p in zip(self.joints, parts, strict=True)],
                        axis=1)

    def nearest_batch(self, postures: np.ndarray) -> np.ndarray:
        """Postures (N, J, 4) → the postures the servos reach nearest them (N, J, 4): each
        joint's :meth:`JointKinematics.nearest_batch` (NaN where its tick limits leave none)."""
        p = np.asarray(postures, dtype=np.float64).reshape(-1, len(self.joints), 4)
        return np.stack([j.nearest_batch(p[:, k]) for k, j in enumerate(self.joints)], axis=1)

    def inverse(self, q: np.ndarray, near_ticks: Sequence[float]) -> np.ndarray:
        """Goal ticks (n,) int64 for joint orientations ``q`` (J, 4), each joint's solution
        nearest its part of ``near_ticks`` (:meth:`JointKinematics.inverse`).

        Raises
        ------
        UnreachableError
            A joint's target out of its reach or tick limits; never clipped.
        """
        q = np.asarray(q, dtype=np.float64).reshape(len(self.joints), 4)
        near = self.split(np.asarray(near_ticks, dtype=np.float64))
        return np.concatenate([j.inverse(qj, nj) for j, qj, nj in
                               zip(self.joints, q, near, strict=True)])
