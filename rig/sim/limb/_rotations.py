"""Small rotation helpers shared by the simulated patient's parts (scalar-first, Hamilton)."""

from __future__ import annotations

import numpy as np

from models import quaternion as Q


def exp_map(rotvec: np.ndarray) -> np.ndarray:
    """Quaternion of rotation vectors ``(..., 3)`` (radians, axis × angle)."""
    rotvec = np.asarray(rotvec, dtype=np.float64)
    theta = np.linalg.norm(rotvec, axis=-1, keepdims=True)
    half = 0.5 * theta
    # sin(θ/2)/θ, with its limit 1/2 at θ = 0
    k = np.where(theta > 1e-12, np.sin(half) / np.where(theta > 1e-12, theta, 1.0), 0.5)
    return np.concatenate((np.cos(half), k * rotvec), axis=-1)


def slerp(a: np.ndarray, b: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Spherical interpolation ``a ⊗ exp(w log(a* ⊗ b))`` (N, 4), shortest arc, ``w`` (N,)."""
    rel = Q.multiply(Q.conjugate(a), b)
    rel *= np.where(rel[:, :1] < 0, -1.0, 1.0)
    vn = np.linalg.norm(rel[:, 1:], axis=1)
    ang = 2.0 * np.arctan2(vn, rel[:, 0])  # rotation angle of a* b, [0, π]
    axis = rel[:, 1:] / np.where(vn > 1e-15, vn, 1.0)[:, None]
    return Q.multiply(a, exp_map(axis * (w * ang)[:, None]))


def smoothstep(x: np.ndarray) -> np.ndarray:
    """``x² (3 - 2x)`` of ``x`` in [0, 1]: 0 and 1 with zero slope at both ends (C¹ blends)."""
    return x * x * (3.0 - 2.0 * x)
