"""What an irregular boundary takes: held-out accuracy against network capacity.

Trains preset ``best`` with the given hidden nodes, training patterns and epochs on one of the
shipped shapes and prints the held-out metrics (fresh test orientations, exact oracle as the
reference). Prints figures; asserts nothing.

Run: python benchmarks/bench_capacity.py original 160 4000 3000 [--overshoot 0] [--seed 0]
"""

from __future__ import annotations

import argparse
import json
import time

import common  # noqa: F401  (first: one BLAS thread, this checkout on sys.path)
import numpy as np

from models.nn.config import get_config
from models.nn.train import train_correction
from models.shapes import SHAPES, load_shape


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("shape", choices=SHAPES)
    ap.add_argument("hidden", type=int)
    ap.add_argument("patterns", type=int)
    ap.add_argument("epochs", type=int)
    ap.add_argument("--overshoot", type=float, default=0.0, help="data.overshoot_deg")
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args()
    cfg = get_config(
        "best",
        {
            "network": {"max_hidden": a.hidden},
            "training": {"max_epochs": a.epochs, "min_epochs": a.epochs},
            "data": {"train": a.patterns, "overshoot_deg": a.overshoot},
        },
    )
    t = time.perf_counter()
    m = train_correction(load_shape(a.shape), cfg, np.random.default_rng(a.seed))
    keys = ("mse", "mean_3d_error_pct", "frac_invalid_violating_1deg", "hidden", "links")
    shown = {k: m.metrics[k] for k in keys if k in m.metrics}
    print(
        f"{a.shape}: hidden {a.hidden}, patterns {a.patterns}, epochs {a.epochs}, overshoot "
        f"{a.overshoot}°, trained in {time.perf_counter() - t:.1f} s: {json.dumps(shown)}"
    )


if __name__ == "__main__":
    main()
