"""Rotation conventions, in one place. Every other module imports from here.

Conventions (the whole project, every file, API and model)
----------------------------------------------------------
- Quaternions are **scalar-first** ``(w, x, y, z)``, stored as float arrays of shape ``(4,)`` or
  ``(N, 4)``.
- Products are **Hamilton** products: ``i*j = k``; ``multiply(p, q)`` rotates by ``q`` first,
  then by ``p`` (for vectors, ``rotate(multiply(p, q), v) == rotate(p, rotate(q, v))``).
- An **orientation** is the limb frame relative to its reference (parent) segment: ``rotate(q, v)``
  maps a vector expressed in the limb frame into the parent frame.
- The limb's long axis is **+X** in the limb frame (``LIMB_AXIS``), so the limb direction in the
  parent frame is ``rotate(q, [1, 0, 0])``.
- A **correction** is expressed in the parent frame and applied on the left:
  ``corrected = multiply(correction, orientation)``.
- **Swing-twist** about the limb axis ``a``: ``q = swing ⊗ twist``, where ``twist`` is a rotation
  about ``a`` (limb frame) and ``swing`` is the minimal rotation taking ``a`` to the limb direction.
- ``q`` and ``-q`` are the same rotation. Functions that return a rotation "as a rotation"
  (:func:`canonical`) pick ``w >= 0``; functions that transform an orientation keep its sign.
- **Angles wrap to (-π, π]** (:func:`wrap_angle`, scalar twin :func:`wrap_angle1`): a twist of
  exactly half a turn is ``+π`` for ``q`` and ``-q`` alike, on every path. Differences about a
  centre, where the end of the interval does not matter, may use the plain modulo formula
  (:func:`wrap_angle_mod`, to [-π, π)).

scipy's :class:`scipy.spatial.transform.Rotation` is used for conversions (it is scalar-last by
default: always go through :func:`to_rotation` / :func:`from_rotation`, which pass
``scalar_first=True``). Hot paths are hand-vectorised numpy over ``(N, 4)`` arrays.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial.transform import Rotation

from models.errors import QuaternionError

LIMB_AXIS = np.array([1.0, 0.0, 0.0])
IDENTITY = np.array([1.0, 0.0, 0.0, 0.0])

#: Orientations whose norm differs from 1 by more than this are rejected unless the caller asks
#: for normalisation. Float32 sensor data rounds to ~1e-7, so this is generous but not lax.
UNIT_TOLERANCE = 1e-5

__all__ = [
    "IDENTITY",
    "LIMB_AXIS",
    "UNIT_TOLERANCE",
    "angle",
    "angle_between",
    "canonical",
    "check_quaternions",
    "check_vectors",
    "conjugate",
    "cross",
    "from_axis_angle",
    "from_rotation",
    "from_two_vectors",
    "limb_direction",
    "multiply",
    "normalize_rows",
    "perpendicular",
    "random_quaternions",
    "random_unit_vectors",
    "rotate",
    "swing_twist",
    "tangent_basis",
    "to_rotation",
    "twist_angle",
    "twist_angle1",
    "wrap_angle",
    "wrap_angle1",
    "wrap_angle_mod",
]

_PI = math.pi
_TWO_PI = 2.0 * math.pi


def check_quaternions(q, *, normalize: bool = False, name: str = "orientation") -> np.ndarray:
    """Validate quaternions and return them as float64.

    Parameters
    ----------
    q : array_like, shape (4,) or (N, 4)
        Scalar-first quaternions (w, x, y, z).
    normalize : bool
        If True, any finite non-zero quaternion is scaled to unit norm. If False (default), a
        quaternion whose norm is off by more than :data:`UNIT_TOLERANCE` is an error; smaller
        rounding deviations are removed.
    name : str
        What the array is, for error messages.

    Returns
    -------
    ndarray, float64, same shape as ``q``, unit norm.

    Raises
    ------
    QuaternionError
        Wrong shape, non-finite entries, zero norm, or (with ``normalize=False``) non-unit norm.
        The message names the first offending row.
    """
    try:
        arr = np.asarray(q, dtype=np.float64)
    except (TypeError, ValueError) as err:
        raise QuaternionError(f"{name}: not a numeric array ({err})") from err
    if arr.ndim not in (1, 2) or arr.shape[-1] != 4:
        raise QuaternionError(
            f"{name}: expected shape (4,) or (N, 4) scalar-first (w, x, y, z), got {arr.shape}"
        )
    flat = arr.reshape(-1, 4)
    finite = np.isfinite(flat).all(axis=1)
    if not finite.all():
        i = int(np.argmin(finite))
        raise QuaternionError(f"{name}[{i}] has a NaN or infinite component: {flat[i].tolist()}")
    unit, norm = normalize_rows(flat)
    bad = norm < 1e-12
    if bad.any():
        i = int(np.argmax(bad))
        raise QuaternionError(f"{name}[{i}] has zero norm and is not a rotation")
    if not normalize:
        off = np.abs(norm - 1.0) > UNIT_TOLERANCE
        if off.any():
            i = int(np.argmax(off))
            raise QuaternionError(
                f"{name}[{i}] is not a unit quaternion (norm {norm[i]:.6g}); "
                "normalise it or pass normalize=True"
            )
    return unit.reshape(arr.shape)


def check_vectors(v, *, name: str = "vector", normalize: bool = True) -> np.ndarray:
    """Validate 3-vectors (shape (3,) or (N, 3)); optionally normalise them to unit length."""
    try:
        arr = np.asarray(v, dtype=np.float64)
    except (TypeError, ValueError) as err:
        raise QuaternionError(f"{name}: not a numeric array ({err})") from err
    if arr.ndim not in (1, 2) or arr.shape[-1] != 3:
        raise QuaternionError(f"{name}: expected shape (3,) or (N, 3), got {arr.shape}")
    flat = arr.reshape(-1, 3)
    if not np.isfinite(flat).all():
        raise QuaternionError(f"{name} has a NaN or infinite component")
    if normalize:
        flat, norm = normalize_rows(flat)
        if (norm < 1e-12).any():
            raise QuaternionError(f"{name} has zero length")
    return flat.reshape(arr.shape)


def normalize_rows(flat: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rows of finite ``flat`` (N, k) scaled to unit length, and their lengths (``inf`` where
    the length itself exceeds the float range). A row whose squares overflow
    (``[0, 0, 1e308]``) is first divided by its largest component, so it keeps its direction
    instead of collapsing to zeros."""
    with np.errstate(over="ignore"):
        norm = np.sqrt(np.einsum("ij,ij->i", flat, flat))
    with np.errstate(divide="ignore", invalid="ignore"):
        unit = flat / norm[:, None]
    big = ~np.isfinite(norm)
    if big.any():
        rows = flat[big]
        scaled = rows / np.abs(rows).max(axis=1)[:, None]
        unit[big] = scaled / np.sqrt(np.einsum("ij,ij->i", scaled, scaled))[:, None]
    return unit, norm


def multiply(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Hamilton product ``p ⊗ q`` (apply ``q`` first, then ``p``); broadcasts over leading axes."""
    p = np.asarray(p, dtype=np.float64)
    q = np.asarray(q, dtype=np.float64)
    pw, px, py, pz = p[..., 0], p[..., 1], p[..., 2], p[..., 3]
    qw, qx, qy, qz = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return np.stack(
        (
            pw * qw - px * qx - py * qy - pz * qz,
            pw * qx + px * qw + py * qz - pz * qy,
            pw * qy - px * qz + py * qw + pz * qx,
            pw * qz + px * qy - py * qx + pz * qw,
        ),
        axis=-1,
    )


def conjugate(q: np.ndarray) -> np.ndarray:
    """Conjugate ``(w, -x, -y, -z)``; the inverse of a unit quaternion."""
    q = np.asarray(q, dtype=np.float64)
    out = -q
    out[..., 0] = q[..., 0]
    return out


def rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate 3-vectors ``v`` by unit quaternions ``q`` (``q v q*``); broadcasts.

    ``v`` is in the rotated (limb) frame, the result in the reference (parent) frame.
    """
    q = np.asarray(q, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    w = q[..., :1]
    u = q[..., 1:]
    t = 2.0 * cross(u, v)
    return v + w * t + cross(u, t)


def cross(a, b) -> np.ndarray:
    """``np.cross`` of 3-vectors along the last axis (broadcasting) — the same arithmetic in the
    same order, so the same bits — without its axis bookkeeping, which costs 3-6 times the
    arithmetic on the batches the oracle and the boundary code pass (10-10,000 rows)."""
    a, b = np.asarray(a), np.asarray(b)
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    out = np.empty(np.broadcast_shapes(a.shape, b.shape), dtype=np.result_type(a, b))
    out[..., 0] = a1 * b2 - a2 * b1
    out[..., 1] = a2 * b0 - a0 * b2
    out[..., 2] = a0 * b1 - a1 * b0
    return out



def limb_direction(q: np.ndarray, axis: np.ndarray = LIMB_AXIS) -> np.ndarray:
    """Unit direction of the limb's long axis in the parent frame, ``rotate(q, axis)``."""
    return rotate(q, axis)


def canonical(q: np.ndarray) -> np.ndarray:
    """The representative with ``w >= 0`` (on ``w == 0`` the first non-zero component > 0)."""
    q = np.asarray(q, dtype=np.float64)
    flat = q.reshape(-1, 4)
    # sign of the first non-zero component, scanning w, x, y, z
    nz = flat != 0.0
    first = np.argmax(nz, axis=1)
    lead = flat[np.arange(len(flat)), first]
    sign = np.where(lead < 0.0, -1.0, 1.0)
    return (flat * sign[:, None]).reshape(q.shape)


def angle(q: np.ndarray) -> np.ndarray:
    """Rotation angle in radians, in [0, π], of unit quaternions (sign-independent)."""
    q = np.asarray(q, dtype=np.float64)
    vec = np.linalg.norm(q[..., 1:], axis=-1)
    return 2.0 * np.arctan2(vec, np.abs(q[..., 0]))


def angle_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angle in radians between unit 3-vectors, accurate near 0 and π (atan2 form)."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    return np.arctan2(np.linalg.norm(cross(a, b), axis=-1), np.sum(a * b, axis=-1))


def from_axis_angle(axis: np.ndarray, angle_rad: np.ndarray) -> np.ndarray:
    """Quaternion for a rotation of ``angle_rad`` about unit ``axis`` (right-hand rule)."""
    axis = np.asarray(axis, dtype=np.float64)
    half = 0.5 * np.asarray(angle_rad, dtype=np.float64)
    return np.concatenate((np.cos(half)[..., None], axis * np.sin(half)[..., None]), axis=-1)


def perpendicular(v: np.ndarray) -> np.ndarray:
    """A unit vector perpendicular to each unit ``v``, chosen deterministically.

    Uses the cross product with the basis axis least aligned with ``v`` (ties: lowest index).
    """
    v = np.asarray(v, dtype=np.float64)
    flat = v.reshape(-1, 3)
    basis = np.eye(3)[np.argmin(np.abs(flat), axis=1)]
    p = np.cross(flat, basis)
    p /= np.linalg.norm(p, axis=1, keepdims=True)
    return p.reshape(v.shape)


def tangent_basis(c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """An orthonormal basis ``(u, v)`` of the plane tangent to the sphere at one unit ``c``.

    ``u`` is ``c`` crossed with the basis axis least aligned with it (as in
    :func:`perpendicular`; ties: lowest index), normalised; ``v = c × u``, so ``(u, v, c)`` is
    right-handed. Deterministic: the azimuth ``atan2(d·v, d·u)`` of a direction ``d`` about
    ``c`` is the same on every call.

    Parameters
    ----------
    c : (3,) float64, unit

    Returns
    -------
    u, v : (3,) float64, unit, perpendicular to ``c`` and to each other
    """
    u = np.cross(c, np.eye(3)[int(np.argmin(np.abs(c)))])
    u /= np.linalg.norm(u)
    return u, np.cross(c, u)


def from_two_vectors(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Minimal rotation taking unit vectors ``a`` to ``b`` (axis ``a × b``), ``w >= 0``.

    For antiparallel vectors the rotation is by π about :func:`perpendicular` of ``a`` — a
    deterministic choice, documented because every such choice is arbitrary.
    """
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    a, b = np.broadcast_arrays(a, b)
    # q = (1 + a·b, a × b) normalised: the half-way formula, stable except near antiparallel
    w = 1.0 + np.sum(a * b, axis=-1)
    xyz = np.cross(a, b)
    q = np.concatenate((w[..., None], xyz), axis=-1)
    anti = w < 1e-12
    if np.any(anti):
        q = q.copy()
        perp = perpendicular(a[anti] if a.ndim > 1 else a)
        q[anti] = np.concatenate((np.zeros((*perp.shape[:-1], 1)), perp), axis=-1)
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def twist_angle(q: np.ndarray, axis: np.ndarray = LIMB_AXIS) -> np.ndarray:
    """Twist of ``q`` about the limb ``axis`` (limb frame), radians in (-π, π].

    With ``q = swing ⊗ twist`` the twist is ``(w, (v·a) a)`` normalised, and its signed angle is
    ``2 atan2(v·a, w)``, evaluated on the representative with ``w >= 0`` so that ``q`` and ``-q``
    give bit-identical angles; half a turn (``w = 0``) is ``+π``.
    """
    q = np.asarray(q, dtype=np.float64)
    axis = np.asarray(axis, dtype=np.float64)
    proj = q[..., 1:] @ axis
    w = q[..., 0]
    neg = w < 0.0
    phi = 2.0 * np.arctan2(np.where(neg, -proj, proj), np.abs(w))
    return np.where(phi <= -_PI, _PI, phi)


def twist_angle1(q, axis) -> float:
    """Scalar twin of :func:`twist_angle` for one quaternion and axis (tuples of floats)."""
    p = q[1] * axis[0] + q[2] * axis[1] + q[3] * axis[2]
    w = q[0]
    phi = 2.0 * math.atan2(-p, -w) if w < 0.0 else 2.0 * math.atan2(p, abs(w))  # abs: w = -0.0
    return _PI if phi <= -_PI else phi


def wrap_angle(phi) -> np.ndarray:
    """Wrap angles (radians) to (-π, π]; angles already inside are returned unchanged."""
    phi = np.asarray(phi, dtype=np.float64)
    out = np.mod(phi + _PI, _TWO_PI) - _PI
    out = np.where(out == -_PI, _PI, out)
    return np.where((phi > -_PI) & (phi <= _PI), phi, out)


def wrap_angle1(phi: float) -> float:
    """Scalar twin of :func:`wrap_angle` (same results, bit for bit)."""
    if -_PI < phi <= _PI:
        return phi
    out = (phi + _PI) % _TWO_PI - _PI
    return _PI if out == -_PI else out


def wrap_angle_mod(phi) -> np.ndarray:
    """Wrap angles (radians) to [-π, π) by the modulo formula ``(φ + π) mod 2π − π``.

    Every value goes through the formula (one inside may move by an ulp), and ``π`` maps to
    ``-π``: for angles about a centre (twist about its circular mean, residuals), where the end
    of the interval does not matter. Orientation angles follow :func:`wrap_angle`, (-π, π].
    """
    return (np.asarray(phi, dtype=np.float64) + _PI) % _TWO_PI - _PI


def swing_twist(q: np.ndarray, axis: np.ndarray = LIMB_AXIS) -> tuple[np.ndarray, np.ndarray]:
    """Decompose ``q = swing ⊗ twist`` about the limb ``axis``.

    Returns
    -------
    swing : ndarray (..., 4)
        Minimal rotation (no component about ``axis``) taking ``axis`` to the limb direction.
    twist : ndarray (..., 4)
        Rotation about ``axis``; ``twist_angle(q)`` is its signed angle.

    The signs follow ``q``: ``multiply(swing, twist) == q`` exactly (not only up to sign).
    When the limb points exactly opposite ``axis`` the twist is undefined; the swing is then
    taken about :func:`perpendicular` of ``axis`` (deterministic).
    """
    q = np.asarray(q, dtype=np.float64)
    axis = np.asarray(axis, dtype=np.float64)
    proj = q[..., 1:] @ axis
    twist = np.concatenate((q[..., :1], proj[..., None] * axis), axis=-1)
    n = np.linalg.norm(twist, axis=-1, keepdims=True)
    degenerate = n[..., 0] < 1e-12
    if np.any(degenerate):
        twist = np.where(degenerate[..., None], IDENTITY, twist)
        n = np.where(degenerate[..., None], 1.0, n)
    twist = twist / n
    swing = multiply(q, conjugate(twist))
    return swing, twist


def to_rotation(q: np.ndarray) -> Rotation:
    """scipy :class:`Rotation` from scalar-first quaternions."""
    return Rotation.from_quat(np.asarray(q, dtype=np.float64), scalar_first=True)


def from_rotation(r: Rotation) -> np.ndarray:
    """Scalar-first quaternions from a scipy :class:`Rotation` (sign as scipy returns it)."""
    return r.as_quat(scalar_first=True)


def random_quaternions(n: int, rng: np.random.Generator) -> np.ndarray:
    """``n`` rotations uniform on SO(3) (normalised 4-D Gaussians), both hemispheres."""
    q = rng.standard_normal((n, 4))
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def random_unit_vectors(n: int, rng: np.random.Generator) -> np.ndarray:
    """``n`` unit vectors uniform on the sphere S²."""
    v = rng.standard_normal((n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)
