"""``rig constraint check`` as a library: validate a constraint file and describe it."""

from __future__ import annotations

import math

import numpy as np

__all__ = ["summarise"]


def summarise(path: str, samples: int = 200_000, seed: int = 0) -> str:
    """Validate ``path`` and describe it: limits, and the fraction of orientations it allows."""
    from models import quaternion as Q
    from models.constraint import load_constraint
    from models.oracle import ConstraintOracle

    c = load_constraint(path)
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
