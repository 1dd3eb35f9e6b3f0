"""Servo position limits derived from the boundary: the hardware backstop.

The servos' own Min/Max Position Limit registers (EEPROM 52/48 on X-series; in position mode a
goal beyond them is clamped by the servo firmware) are set so that even a host that sends a
wild goal cannot drive a joint beyond the range the valid region needs.

Method: sample the valid set densely — orientations uniform over SO(3) that the oracle accepts,
plus exact projections of rejected ones (so the boundary itself is covered) — solve the inverse
kinematics of each on the branch nearest the start posture, and take per joint the smallest
tick interval containing them, widened by ``margin_deg`` and by the start posture itself (a limb
starting outside must be able to come back), then intersected with the configured
``min_ticks..max_ticks``. The result is a box in joint space containing the valid region: a
coarse outer bound (a 3-DOF region is not a box), never the primary limit — the supervisor is.
An interval that would cover the whole turn is left at the configured limits. Margins and whole
turns are in each servo's own ticks (:attr:`~rig.devices.kinematics.ServoAxis.ticks_per_rev`:
X series 4096, AX-12A 1228.8, P-series e.g. 1,003,846).
"""

from __future__ import annotations

import numpy as np

from models import quaternion as Q
from rig.errors import UnreachableError

__all__ = ["position_limits_from_boundary", "position_limits_from_limb"]


def position_limits_from_boundary(kinematics, oracle, near_ticks, *, n: int = 6000,
                                  margin_deg: float = 5.0, seed: int = 0
                                  ) -> tuple[np.ndarray, np.ndarray]:
    """Per-joint tick limits containing the valid region (see the module docstring).

    Parameters
    ----------
    kinematics : rig.devices.kinematics.JointKinematics
    oracle : models.oracle.ConstraintOracle
    near_ticks : (n_joints,) array_like
        Start posture (present position), chooses the IK branch and is always inside.
    n : int
        Random orientations drawn.
    margin_deg : float
        Widening on each side.

    Returns
    -------
    min_ticks, max_ticks : (n_joints,) int64
    """
    rng = np.random.default_rng(seed)
    q = Q.random_quaternions(n, rng)
    res = oracle.evaluate(q)
    samples = np.concatenate([q[res.valid], res.projected[~res.valid]])
    near = np.asarray(near_ticks, dtype=np.float64)
    ticks = []
    for qi in samples:
        try:
            ticks.append(kinematics.inverse_float(qi, near))
        except UnreachableError:
            continue
    lo_cfg = kinematics.min_ticks.astype(np.int64)
    hi_cfg = kinematics.max_ticks.astype(np.int64)
    if not ticks:
        return lo_cfg.copy(), hi_cfg.copy()
    t = np.array(ticks)
    turn = np.asarray(kinematics.ticks_per_rev, dtype=np.float64)  # per servo
    margin = margin_deg / 360.0 * turn
    lo = np.floor(np.minimum(t.min(0), near) - margin).astype(np.int64)
    hi = np.ceil(np.maximum(t.max(0), near) + margin).astype(np.int64)
    whole = (hi - lo) >= turn - 1
    lo = np.where(whole, lo_cfg, np.maximum(lo, lo_cfg))
    hi = np.where(whole, hi_cfg, np.minimum(hi, hi_cfg))
    return lo, hi


class _JointEnvelope:
    """One joint of a limb oracle answering ``evaluate(q)`` over its whole envelope: a coupled
    joint's limits at a coupling angle drawn uniformly over its keyframes' range per sample
    (beyond that range its limits do not change), so the valid samples and projections cover
    every region the joint can be allowed."""

    def __init__(self, oracle, joint: int, seed: int):
        self.oracle, self.joint = oracle, joint
        self.range = oracle.coupling_range(joint)
        self.rng = np.random.default_rng(seed)

    def evaluate(self, q):
        angle = None if self.range is None else self.rng.uniform(*self.range, len(q))
        return self.oracle.evaluate_joint(self.joint, q, angle)


def position_limits_from_limb(kinematics, oracle, near_ticks, *, n: int = 6000,
                              margin_deg: float = 5.0, seed: int = 0
                              ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`position_limits_from_boundary` for every joint of a limb, each from the joint's
    envelope (a coupled joint's limits over all its coupling angles).

    Parameters
    ----------
    kinematics : rig.devices.kinematics.LimbKinematics
    oracle : models.oracle.ConstraintOracle
        A limb's (or one joint's: a limb of one joint).
    near_ticks : (n_servos,) array_like
        Start posture, tick-vector order.

    Returns
    -------
    min_ticks, max_ticks : (n_servos,) int64, tick-vector order
    """
    near = np.asarray(near_ticks, dtype=np.float64)
    los, his = [], []
    for j, (kin, sl) in enumerate(zip(kinematics.joints, kinematics.slices, strict=True)):
        env = _JointEnvelope(oracle, j, seed + 1 + j)
        lo, hi = position_limits_from_boundary(kin, env, near[sl], n=n, margin_deg=margin_deg,
                                               seed=seed + j)
        los.append(np.minimum(lo, kin.zero_ticks))
        his.append(np.maximum(hi, kin.zero_ticks))
    return np.concatenate(los), np.concatenate(his)


def describe_limits(kinematics, lo, hi) -> str:
    """``"ID 1 1024..3072 (180.0°), ..."`` for logs."""
    parts = []
    for i, a, b, turn in zip(kinematics.ids, lo, hi, kinematics.ticks_per_rev, strict=True):
        parts.append(f"ID {i} {int(a)}..{int(b)} ({(int(b) - int(a)) * 360 / turn:.1f}°)")
    return ", ".join(parts)


