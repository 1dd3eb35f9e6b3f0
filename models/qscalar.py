"""Scalar quaternion kernels for one orientation at a time (tuples of floats, ``w x y z``).

The single-orientation twins of :mod:`models.quaternion`, used wherever one orientation per
call must be cheap: the exact oracle's single path, servo-chain kinematics and the control
loop's supervisor. Same conventions (scalar-first, Hamilton, ``p ⊗ q`` rotates by ``q``
first), written on plain floats because one orientation through numpy costs more in call
overhead than in arithmetic. ``tests/models/test_qscalar.py`` checks every kernel against its
:mod:`models.quaternion` counterpart.

Maths
-----
- product: ``(p ⊗ q)_w = p_w q_w − p·q``, ``(p ⊗ q)_v = p_w q_v + q_w p_v + p_v × q_v``;
- rotation of a vector: ``v' = v + w t + u × t`` with ``t = 2 u × v`` (``q = (w, u)``);
- shortest rotation from unit ``a`` to unit ``b``: ``normalize(1 + a·b, a × b)``; antiparallel
  vectors rotate by π about :func:`models.quaternion.perpendicular` of ``a``;
- relative rotation from ``a`` to ``b`` (parent frame): ``r = b ⊗ a⁻¹``, sign chosen so that
  ``r_w ≥ 0`` (the shorter way round);
- rotation vector: ``log(r) = θ u`` with ``θ = 2 atan2(|r_v|, r_w)``, ``u = r_v / |r_v|``;
  ``exp(θ u) = (cos θ/2, u sin θ/2)``.
"""

from __future__ import annotations

import math

from models.quaternion import perpendicular

Quat = tuple[float, float, float, float]
Vec = tuple[float, float, float]

IDENTITY: Quat = (1.0, 0.0, 0.0, 0.0)

__all__ = [
    "IDENTITY",
    "angle",
    "angle_between",
    "axis_angle",
    "conj",
    "exp_vec",
    "from_two_vectors",
    "log_vec",
    "mul",
    "norm",
    "normalize",
    "relative",
    "rotate",
]


def mul(p: Quat, q: Quat) -> Quat:
    """Hamilton product ``p ⊗ q``."""
    pw, px, py, pz = p
    qw, qx, qy, qz = q
    return (
        pw * qw - px * qx - py * qy - pz * qz,
        pw * qx + px * qw + py * qz - pz * qy,
        pw * qy - px * qz + py * qw + pz * qx,
        pw * qz + px * qy - py * qx + pz * qw,
    )


def rotate(q, v) -> Vec:
    """Vector ``v`` rotated by the unit quaternion ``q``."""
    w, x, y, z = q
    tx = 2.0 * (y * v[2] - z * v[1])
    ty = 2.0 * (z * v[0] - x * v[2])
    tz = 2.0 * (x * v[1] - y * v[0])
    return (
        v[0] + w * tx + (y * tz - z * ty),
        v[1] + w * ty + (z * tx - x * tz),
        v[2] + w * tz + (x * ty - y * tx),
    )


def axis_angle(axis, theta: float) -> Quat:
    """Rotation by ``theta`` radians about the unit ``axis``."""
    s = math.sin(0.5 * theta)
    return (math.cos(0.5 * theta), s * axis[0], s * axis[1], s * axis[2])


def from_two_vectors(a, b) -> Quat:
    """Shortest rotation taking unit ``a`` to unit ``b`` (antiparallel: the rule of
    :func:`models.quaternion.from_two_vectors`)."""
    w = 1.0 + a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
    if w < 1e-12:
        p = perpendicular(a)
        return (0.0, float(p[0]), float(p[1]), float(p[2]))
    q = (w, a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])
    n = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    return (q[0] / n, q[1] / n, q[2] / n, q[3] / n)


def conj(q: Quat) -> Quat:
    """Conjugate (the inverse of a unit quaternion)."""
    return (q[0], -q[1], -q[2], -q[3])


def norm(q) -> float:
    """Euclidean norm; NaN if any component is NaN."""
    return math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])


def normalize(q) -> Quat:
    """``q / |q|`` (caller guarantees a finite, non-zero norm)."""
    n = norm(q)
    return (q[0] / n, q[1] / n, q[2] / n, q[3] / n)


def relative(a: Quat, b: Quat) -> Quat:
    """Rotation ``b ⊗ a⁻¹`` taking ``a`` to ``b`` (parent frame), with ``w ≥ 0``."""
    r = mul(b, conj(a))
    if r[0] < 0.0:
        return (-r[0], -r[1], -r[2], -r[3])
    return r


def angle(q: Quat) -> float:
    """Rotation angle of a unit quaternion, radians in [0, π] (either sign of ``q``)."""
    return 2.0 * math.atan2(math.sqrt(q[1] * q[1] + q[2] * q[2] + q[3] * q[3]), abs(q[0]))


def angle_between(a: Quat, b: Quat) -> float:
    """Angle of the rotation taking ``a`` to ``b``, radians in [0, π]."""
    return angle(mul(b, conj(a)))


def log_vec(r: Quat) -> Vec:
    """Rotation vector ``θ u`` of a unit quaternion with ``w ≥ 0`` (radians)."""
    s = math.sqrt(r[1] * r[1] + r[2] * r[2] + r[3] * r[3])
    if s < 1e-15:
        return (0.0, 0.0, 0.0)
    k = 2.0 * math.atan2(s, r[0]) / s
    return (r[1] * k, r[2] * k, r[3] * k)


def exp_vec(v: Vec) -> Quat:
    """Unit quaternion of the rotation vector ``v`` (radians)."""
    th = math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
    if th < 1e-15:
        return IDENTITY
    s = math.sin(0.5 * th) / th
    return (math.cos(0.5 * th), v[0] * s, v[1] * s, v[2] * s)
