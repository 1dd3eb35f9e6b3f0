"""Experiment: fire the network a second time on its own corrected output.

A smooth network undershoots next to the boundary discontinuity, leaving corrected limbs a
little outside. Applying the same network again to ``c1 ⊗ q`` (only where the first correction
is larger than ``tau``, so valid inputs keep one pass) trades 3-D error for fewer violations.
Not wired into the ONNX export; this script measures the trade. Prints figures, asserts nothing.

Run: python benchmarks/bench_refine.py [--taus 0,1,2,4]
"""

from __future__ import annotations

import argparse

import common  # noqa: F401  (first: one BLAS thread, this checkout on sys.path)
import numpy as np

from models import metrics as M
from models import quaternion as Q
from models.constraint import JointConstraint
from models.nn.config import get_config
from models.nn.train import train_correction, training_patterns
from models.oracle import ConstraintOracle
from models.shapes import load_shape

KEYS = ("mse", "mean_3d_error_pct", "frac_invalid_violating_1deg", "mean_identity_error_deg")


def refined(net, tau_deg: float | None):
    """Correction function: one pass, or a second pass where the first exceeds ``tau_deg``."""

    def predict(x):
        c1 = net.predict(x)
        c1 /= np.linalg.norm(c1, axis=1, keepdims=True)
        if tau_deg is None:
            return c1
        c2 = net.predict(Q.multiply(c1, x))
        c2 /= np.linalg.norm(c2, axis=1, keepdims=True)
        big = Q.angle(c1) > np.radians(tau_deg)
        return np.where(big[:, None], Q.multiply(c2, c1), c1)

    return predict


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--taus", default="0,1,2,4", help="gate thresholds, degrees")
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args()
    taus = [float(t) for t in a.taus.split(",")]
    for c in (JointConstraint.cone([0, 1, 0], 45, name="cone Y 45°"), load_shape("original")):
        model = train_correction(c, get_config("best"), np.random.default_rng(a.seed))
        oracle = ConstraintOracle(c)
        q, _ = training_patterns(
            c, 3000, np.random.default_rng(a.seed + 5), distribution="even", order="random"
        )
        for tau in (None, *taus):
            r = M.evaluate(refined(model.network, tau), oracle, q)
            label = "one pass" if tau is None else f"second pass where > {tau:g}°"
            print(f"{c.name:12s} {label:28s} " + "  ".join(f"{k} {r[k]:.4g}" for k in KEYS))


if __name__ == "__main__":
    main()
