"""The quaternion primitives of :mod:`models.qscalar`, compiled, for use inside other kernels.

:mod:`models.qscalar` serves plain Python (one orientation at a time); code compiled by
:func:`models.jit.njit` (the oracle's single-orientation kernel, the servo chain's IK and FK)
calls these instead. Each is inlined where it is called, works on floats passed one by one (no
tuples or arrays to build) and computes the same expressions in the same order as its
:mod:`models.qscalar` twin, so the results are the same to the last bit.
"""

from __future__ import annotations

import math

from models.jit import njit

__all__ = ["axis_angle", "mul", "rotate"]


@njit(inline="always")
def mul(p0, p1, p2, p3, q0, q1, q2, q3):
    """Hamilton product ``p ⊗ q`` (:func:`models.qscalar.mul`)."""
    return (p0 * q0 - p1 * q1 - p2 * q2 - p3 * q3, p0 * q1 + p1 * q0 + p2 * q3 - p3 * q2,
            p0 * q2 - p1 * q3 + p2 * q0 + p3 * q1, p0 * q3 + p1 * q2 - p2 * q1 + p3 * q0)


@njit(inline="always")
def rotate(w, x, y, z, v0, v1, v2):
    """``v`` rotated by the unit quaternion ``q`` (:func:`models.qscalar.rotate`)."""
    tx = 2.0 * (y * v2 - z * v1)
    ty = 2.0 * (z * v0 - x * v2)
    tz = 2.0 * (x * v1 - y * v0)
    return (v0 + w * tx + (y * tz - z * ty), v1 + w * ty + (z * tx - x * tz),
            v2 + w * tz + (x * ty - y * tx))


@njit(inline="always")
def axis_angle(a0, a1, a2, theta):
    """Rotation by ``theta`` radians about unit ``a`` (:func:`models.qscalar.axis_angle`)."""
    s = math.sin(0.5 * theta)
    return math.cos(0.5 * theta), s * a0, s * a1, s * a2
