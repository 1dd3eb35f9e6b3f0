"""Servo-chain zero and direction calibration from a known pose sequence.

Model (the rig's chain kinematics, :mod:`rig.devices.kinematics`): a chain of ``n`` (1-3)
revolute joints, parent → child, joint ``k`` turning about the unit axis ``a_k`` (expressed in
its parent link's frame) by ``θ_k = s_k (t_k − z_k) · 2π / T`` (``t_k`` the Present Position in
ticks, ``z_k`` the zero offset, ``s_k = ±1`` the direction, ``T`` ticks per turn — 4096 for
X-series, 1228.8 for AX-12A / XL-320, 1,003,846 for a PH54-200-S500; per joint ``T_k`` when the
chain mixes models), and the limb orientation is ``q = R(a_1, θ_1) ⊗ … ⊗ R(a_n, θ_n)``.

Calibration: the limb is put in ``K`` known orientations ``q_j`` (a jig, or poses measured by
another instrument) and the ticks ``t_jk`` are read. Each ``q_j`` is decomposed into joint angles
by the Davenport decomposition about the chain's axes (Shuster & Markley 2003, *J Astronaut
Sci* 51:123; :meth:`scipy.spatial.transform.Rotation.as_davenport`, intrinsic; consecutive axes
must be orthogonal; a chain of fewer than three joints is padded with orthogonal axes whose
angles should come out zero). Then, per joint and for each direction ``s ∈ {+1, −1}``, the zero
is the circular mean of ``t_jk − s θ_jk T / 2π`` over the poses and the residual the RMS of the
wrapped angle misfit; the direction with the smaller residual wins. The joint must move by at
least ``min_span_deg`` across the poses, or its direction is undetermined. The reported
``residual_deg_`` is the RMS angle between the calibrated forward kinematics and the known
poses.
"""

from __future__ import annotations

import math

import numpy as np

from calibration.errors import CalibrationError
from models import quaternion as Q

__all__ = ["ServoChainCalibration", "chain_forward"]


def _resolution(ticks_per_rev, n: int):
    """``ticks_per_rev`` as given (a scalar) or (n,) float64 per joint; ValueError if not
    positive or of another length."""
    if np.ndim(ticks_per_rev) == 0:
        out = ticks_per_rev
    else:
        out = np.asarray(ticks_per_rev, dtype=np.float64).reshape(-1)
        if len(out) != n:
            raise ValueError(f"ticks_per_rev: one per joint ({n}), got {len(out)}")
    if not np.all(np.isfinite(out)) or not np.all(np.asarray(out) > 0):
        raise ValueError(f"ticks_per_rev must be positive, got {ticks_per_rev!r}")
    return out


def chain_forward(axes, ticks, zero_ticks, direction, ticks_per_rev=4096) -> np.ndarray:
    """Forward kinematics (N, 4) of a chain (see module doc); ``ticks`` (N, n);
    ``ticks_per_rev`` a scalar or one per joint (n,)."""
    axes = Q.check_vectors(axes, name="axes").reshape(-1, 3)
    t = np.atleast_2d(np.asarray(ticks, dtype=np.float64))
    tpr = _resolution(ticks_per_rev, len(axes))
    theta = (np.asarray(direction, float) * (t - np.asarray(zero_ticks, float))
             * 2.0 * math.pi / tpr)
    q = np.tile(Q.IDENTITY, (len(t), 1))
    for k in range(len(axes)):
        q = Q.multiply(q, Q.from_axis_angle(axes[k], theta[:, k]))
    return q


class ServoChainCalibration:
    """Zero offsets and directions of a servo chain (scikit-learn style; see module doc).

    Parameters
    ----------
    axes : (n, 3) array_like
        Joint axes, parent → child (1 ≤ n ≤ 3); consecutive axes orthogonal.
    ticks_per_rev : float or (n,) array_like of float
        Encoder ticks per turn: 4096 for Dynamixel X-series (the default), 1228.8 for AX-12A /
        XL-320 (1024 over 300°); one per joint for a chain of mixed models (e.g. each
        :attr:`rig.devices.kinematics.ServoAxis.ticks_per_rev`).
    min_span_deg : float
        Each joint must move at least this much across the poses.

    Attributes
    ----------
    zero_ticks_ : (n,) float64, in [0, ticks_per_rev) (each joint's own)
    direction_ : (n,) int, ±1
    joint_residual_deg_ : (n,) float64, RMS angle misfit per joint
    residual_deg_ : float, RMS angle between calibrated FK and the known poses
    """

    def __init__(self, axes, *, ticks_per_rev=4096, min_span_deg: float = 10.0) -> None:
        self.axes = Q.check_vectors(axes, name="axes").reshape(-1, 3)
        if not 1 <= len(self.axes) <= 3:
            raise ValueError(f"a chain has 1-3 joints, got {len(self.axes)} axes")
        for k in range(len(self.axes) - 1):
            if abs(self.axes[k] @ self.axes[k + 1]) > 1e-6:
                raise ValueError(f"axes {k} and {k + 1} must be orthogonal")
        self.ticks_per_rev = _resolution(ticks_per_rev, len(self.axes))
        self.min_span_deg = float(min_span_deg)

    def _padded_axes(self) -> np.ndarray:
        a = list(self.axes)
        if len(a) == 1:
            b = Q.perpendicular(a[0])
            a += [b, Q.cross(a[0], b)]
        elif len(a) == 2:
            a.append(Q.cross(a[0], a[1]) / np.linalg.norm(Q.cross(a[0], a[1])))
        return np.array(a)

    def joint_angles(self, poses) -> np.ndarray:
        """Joint angles (K, n), radians, of known limb orientations (K, 4)."""
        q = Q.check_quaternions(poses, normalize=True, name="poses").reshape(-1, 4)
        axes = self._padded_axes()
        if len(self.axes) == 1:
            return Q.twist_angle(q, self.axes[0])[:, None]
        import warnings

        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # gimbal lock: still a solution
            ang = Q.to_rotation(q).as_davenport(axes, "intrinsic")
        return ang[:, : len(self.axes)]

    def fit(self, ticks, poses) -> ServoChainCalibration:
        """Calibrate from ticks (K, n) read at known limb orientations (K, 4).

        Returns
        -------
        self
        """
        t = np.atleast_2d(np.asarray(ticks, dtype=np.float64))
        n = len(self.axes)
        if t.shape[1] != n:
            raise CalibrationError(f"ticks: expected shape (K, {n}), got {t.shape}")
        q = Q.check_quaternions(poses, normalize=True, name="poses").reshape(-1, 4)
        if len(q) != len(t):
            raise CalibrationError(f"{len(t)} tick rows for {len(q)} poses")
        if len(q) < 2:
            raise CalibrationError("need at least 2 known poses")
        theta = self.joint_angles(q)
        turns = np.broadcast_to(np.asarray(self.ticks_per_rev), (n,)).tolist()
        zeros = np.empty(n)
        dirs = np.empty(n, dtype=np.int64)
        res = np.empty(n)
        for k in range(n):
            k_tick = 2.0 * math.pi / turns[k]
            span = np.ptp(np.angle(np.exp(1j * (theta[:, k] - theta[0, k]))))
            if math.degrees(span) < self.min_span_deg:
                raise CalibrationError(
                    f"joint {k}: the poses move it by {math.degrees(span):.1f} deg; at least "
                    f"{self.min_span_deg:g} deg is needed to tell its direction"
                )
            best = None
            for s in (1, -1):
                z_ang = t[:, k] * k_tick - s * theta[:, k]  # zero, as an angle
                z = float(np.angle(np.mean(np.exp(1j * z_ang))))
                mis = np.angle(np.exp(1j * (s * (t[:, k] * k_tick - z) - theta[:, k])))
                rms = float(np.sqrt(np.mean(mis**2)))
                if best is None or rms < best[0]:
                    best = (rms, s, z)
            rms, s, z = best
            zeros[k] = (z / k_tick) % turns[k]
            dirs[k] = s
            res[k] = math.degrees(rms)
        self.zero_ticks_ = zeros
        self.direction_ = dirs
        self.joint_residual_deg_ = res
        fk = chain_forward(self.axes, t, zeros, dirs, self.ticks_per_rev)
        err = np.degrees(Q.angle(Q.multiply(fk, Q.conjugate(q))))
        self.residual_deg_ = float(np.sqrt(np.mean(err**2)))
        return self

    def to_dict(self) -> dict:
        """Plain types for the store's calibration record (``ticks_per_rev`` per joint only when
        some joint's is not the X series' 4096: an X-series record reads as before)."""
        return {
            "kind": "servo-zero-direction",
            "axes": self.axes.tolist(),
            "zero_ticks": [float(z) for z in self.zero_ticks_],
            "direction": [int(d) for d in self.direction_],
            "joint_residual_deg": [float(r) for r in self.joint_residual_deg_],
            "residual_deg": float(self.residual_deg_),
            **({} if np.all(np.asarray(self.ticks_per_rev) == 4096) else
               {"ticks_per_rev": np.broadcast_to(np.asarray(self.ticks_per_rev, float),
                                                 (len(self.axes),)).tolist()}),
        }
