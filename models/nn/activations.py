"""Node activation functions of the GMLP, with derivatives, for stacked populations.

Candidates (index → name):

====  ============  ==========================================  =========================
idx   name          f(z)                                        source
====  ============  ==========================================  =========================
0     linear        z                                           thesis 5.1.8
1     sigmoid       1 / (1 + e^-z)                              thesis 5.1.8
2     tanh          tanh z                                      thesis 5.1.8
3     gaussian      exp(-z^2)                                   thesis 5.1.8
4     sine          sin z                                       thesis 5.1.8
5     relu          max(z, 0)                                   modern, piecewise linear
6     leaky_relu    max(z, 0.1 z)                               modern, piecewise linear
7     hardtanh      clip(z, -1, 1)                              modern, piecewise linear
8+t   spline[t]     template cubic spline t (see below)         thesis 5.1.10, TABLE IX
====  ============  ==========================================  =========================

Template cubic-spline activations (thesis 5.1.10): a template is ``K`` control values
``c_0 … c_{K-1}`` in the *activation interval* [-1, 1] placed at equally spaced knots over the
*sensitivity interval* [-5, 5] (TABLE IX). Between knots the curve is the Catmull-Rom cubic
(C¹, interpolating); the end values are held constant outside the sensitivity interval, like a
squashing function. With knot spacing ``h``, ``u = (z - z_0) / h``, segment ``i = ⌊u⌋`` and
``t = u - i``::

    f(z) = a_i t³ + b_i t² + c_i t + d_i,   f'(z) = (3 a_i t² + 2 b_i t + c_i) / h

where ``(a, b, c, d)`` come from the Catmull-Rom basis on ``(c_{i-1}, c_i, c_{i+1}, c_{i+2})``
(ends padded by repetition). The OCR lost the thesis's control-point and template counts; we use
``K = 9`` control points and ``T = 4`` templates per network (configurable), enough for one
bump or a sigmoid-like step with a spare template for the output layer.

All functions work on any shape; ``spline`` arrays are stacked per network so that a whole
population trains at once.
"""

from __future__ import annotations

import numpy as np

NAMES: tuple[str, ...] = (
    "linear",
    "sigmoid",
    "tanh",
    "gaussian",
    "sine",
    "relu",
    "leaky_relu",
    "hardtanh",
)
#: Index of the first spline template; template ``t`` has activation index ``SPLINE0 + t``.
SPLINE0 = len(NAMES)
LEAKY_SLOPE = 0.1
SENSITIVITY = (-5.0, 5.0)  # thesis TABLE IX
ACTIVATION_RANGE = (-1.0, 1.0)  # thesis TABLE IX
#: Keeps the last segment index in range (float32-representable below any segment count).
SEG_EPS = 1e-5


def index_of(name: str) -> int:
    """Activation index of a name (``"spline0"`` … for templates); ``ValueError`` if unknown."""
    if name in NAMES:
        return NAMES.index(name)
    if name.startswith("spline") and name[6:].isdigit():
        return SPLINE0 + int(name[6:])
    raise ValueError(f"unknown activation {name!r}; expected one of {[*NAMES, 'spline<t>']}")


def name_of(idx: int) -> str:
    """Name of an activation index."""
    return NAMES[idx] if idx < SPLINE0 else f"spline{idx - SPLINE0}"


def apply(kind: int, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Value and derivative of a non-spline activation ``kind`` at ``z`` (same shape/dtype)."""
    if kind == 0:
        return z, np.ones_like(z)
    if kind == 1:
        y = np.multiply(z, 0.5)
        np.tanh(y, out=y)  # overflow-free sigmoid: (1 + tanh(z/2)) / 2
        y *= 0.5
        y += 0.5
        dy = np.subtract(1.0, y)
        dy *= y
        return y, dy
    if kind == 2:
        y = np.tanh(z)
        dy = np.multiply(y, y)
        np.subtract(1.0, dy, out=dy)
        return y, dy
    if kind == 3:
        y = np.exp(-z * z)
        return y, -2.0 * z * y
    if kind == 4:
        return np.sin(z), np.cos(z)
    if kind == 5:
        return np.maximum(z, 0.0), (z > 0).astype(z.dtype)
    if kind == 6:
        return np.maximum(z, LEAKY_SLOPE * z), np.where(z > 0, 1.0, LEAKY_SLOPE).astype(z.dtype)
    if kind == 7:
        return np.clip(z, -1.0, 1.0), (np.abs(z) < 1.0).astype(z.dtype)
    raise ValueError(f"activation index {kind} is a spline template; use spline_apply")


def spline_coefficients(control: np.ndarray) -> np.ndarray:
    """Catmull-Rom segment coefficients of templates.

    Parameters
    ----------
    control : (..., K) float
        Control values at equally spaced knots over :data:`SENSITIVITY`.

    Returns
    -------
    (..., K - 1, 4) float
        ``(a, b, c, d)`` per segment, for ``f = ((a t + b) t + c) t + d`` with ``t`` in [0, 1].
    """
    p = np.concatenate((control[..., :1], control, control[..., -1:]), axis=-1)
    p0, p1, p2, p3 = p[..., :-3], p[..., 1:-2], p[..., 2:-1], p[..., 3:]
    a = 0.5 * (-p0 + 3 * p1 - 3 * p2 + p3)
    b = 0.5 * (2 * p0 - 5 * p1 + 4 * p2 - p3)
    c = 0.5 * (-p0 + p2)
    return np.stack((a, b, c, p1), axis=-1)


def spline_apply(
    z: np.ndarray, coef: np.ndarray, template: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Value and derivative of spline activations.

    Parameters
    ----------
    z : (P, N, H) float
        Pre-activations of P networks, N patterns, H nodes.
    coef : (P, T, K - 1, 4) float
        Per-network template coefficients (:func:`spline_coefficients`).
    template : (P, H) int
        Template index of every node (clipped to [0, T)).

    Returns
    -------
    value, derivative : (P, N, H)
    """
    p_, t_, s_, _ = coef.shape
    lo, hi = SENSITIVITY
    h = (hi - lo) / s_
    u = (z - lo) * (1.0 / h)
    inside = (u >= 0) & (u < s_)
    u = np.clip(u, 0.0, s_ - SEG_EPS)
    seg = u.astype(np.int64)
    t = (u - seg).astype(z.dtype)
    flat = coef.reshape(p_ * t_ * s_, 4)
    base = (np.arange(p_)[:, None] * t_ + np.clip(template, 0, t_ - 1)) * s_  # (P, H)
    idx = seg + base[:, None, :]
    a, b, c, d = (flat[:, j][idx] for j in range(4))
    y = ((a * t + b) * t + c) * t + d
    dy = np.where(inside, (3 * a * t + 2 * b) * t + c, 0.0) * (1.0 / h)
    return y.astype(z.dtype), dy.astype(z.dtype)
