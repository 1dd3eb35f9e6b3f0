"""``rig constraint check`` as a library: validate a constraint or limb file and describe it."""

from __future__ import annotations

import math

import numpy as np

from models import quaternion as Q
from models.limb import Limb, load_limits
from models.oracle import ConstraintOracle

__all__ = ["summarise"]


def summarise(path: str, samples: int = 200_000, seed: int = 0) -> str:
    """Validate ``path`` and describe it: limits, and the fraction of orientations it allows."""

    c = load_limits(path)  # read and parsed once, either kind
    if isinstance(c, Limb):
        return _summarise_limb(path, c, samples, seed)
    if c.hinge is not None:  # a curve in SO(3): no fraction of orientations to sample
        return "\n".join([f"{path}: OK", c.summary(),
                          f"  valid       the rotations about the axis within "
                          f"{c.hinge.max_deg - c.hinge.min_deg:g} deg (a curve: 0 % of all "
                          f"orientations; the oracle corrects every other one onto it)"])
    oracle = ConstraintOracle(c)
    rng = np.random.default_rng(seed)
    q = Q.random_quaternions(samples, rng)
    valid = oracle.is_valid(q)
    frac = float(valid.mean())
    # binomial standard error of the Monte-Carlo estimate
    se = math.sqrt(max(frac * (1 - frac), 1e-12) / samples)
    lines = [f"{path}: OK", c.summary()]
    lines.append(
        f"  valid       {100 * frac:.2f} % ± {100 * se:.2f} % of all orientations "
        f"({samples} uniform samples)"
    )
    return "\n".join(lines)


def _summarise_limb(path: str, limb, samples: int, seed: int) -> str:
    """A limb file: its joints, couplings, and the fraction of random postures each swing
    joint allows (a coupled joint judged at its source's corrected angle)."""

    oracle = ConstraintOracle(limb)
    n = len(limb.joints)
    rng = np.random.default_rng(seed)
    q = Q.random_quaternions(samples * n, rng).reshape(samples, n, 4)
    valid = oracle.is_valid(q)
    parts = []
    for j, joint in enumerate(limb.joints):
        if joint.joint_kind.single_axis:
            lo = joint.loosest().hinge
            parts.append(f"{joint.name} hinge {lo.min_deg:g}..{lo.max_deg:g} deg")
        else:
            parts.append(f"{joint.name} {100 * float(valid[:, j].mean()):.2f} %")
    return "\n".join([f"{path}: OK", limb.summary(),
                      f"  valid       {'; '.join(parts)} of all orientations "
                      f"({samples} uniform postures)"])
