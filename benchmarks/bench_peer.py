"""The analytic peer: van den Bergen's swing-twist clamp with a fitted ellipse.

    python benchmarks/bench_peer.py [--n 10000] [--random 20]

Implemented from its published description — G. van den Bergen, "Rotational Joint Limits in
Quaternion Space", GDC 2016 talk and *Game Engine Gems 3* (CRC 2016, ch. "Rotational Joint
Limits in Quaternion Space", doi:10.1201/b21177-14):

- decompose ``q = swing ⊗ twist`` about the limb axis ``a``; the swing quaternion of a
  rotation taking ``a`` (here: the boundary's rest direction) to ``d`` has no component along
  ``a``: ``(cos θ/2, sin θ/2 n)``, ``n ⊥ a``, so its two remaining vector components ``(y, z)``
  lie in the unit disc and parametrise the swing without singularity short of 180°;
- the swing limit is an **ellipse** ``(y, z)ᵀ A (y, z) ≤ 1`` in that plane; an out-of-range
  swing is clamped to the **closest point of the ellipse** (Euclidean in ``(y, z)``, found by a
  one-dimensional root search), and ``w = √(1 − y² − z²)``;
- the twist is clamped to its interval.

Adaptations needed to score it on our constraints: the rest direction is the cone's centre or
the polygon's ``interior`` point (our boundaries sit at varied centres; the ellipse is centred
on the rest direction, as in the talk), the ellipse is a least-squares fit of
``y²A₁₁ + 2yzA₁₂ + z²A₂₂ = 1`` to 2000 points sampled along the boundary, and the twist is
clamped the way the constraint defines it (the twist of ``Δ ⊗ q`` after the swing correction
``Δ``), so that only the swing
model differs from the exact oracle. Run alone it prints the peer's metrics on the held-out
boundary sets (:mod:`models.evaluation`); ``bench_accuracy.py`` scores it beside our models on
the same orientations.
"""

from __future__ import annotations

import argparse

import common  # noqa: F401  (first: one BLAS thread, this checkout on sys.path)
from peers import VanDenBergenClamp


def main() -> None:
    from models.evaluation import (
        TARGET_METRICS,
        evaluate_model,
        irregular_boundaries,
        regular_boundaries,
        summarise,
    )

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=10_000)
    ap.add_argument("--random", type=int, default=20)
    args = ap.parse_args()
    for label, cs in (("irregular", irregular_boundaries(args.random)),
                      ("regular", regular_boundaries())):
        rows = []
        for name, c in cs.items():
            rows.append(evaluate_model(VanDenBergenClamp(c).predict, c, n=args.n))
            print(f"{name:26s} " + "  ".join(f"{rows[-1][k]:.3f}" for k, _ in TARGET_METRICS),
                  flush=True)
        s = summarise(rows)
        print(f"{label}: " + ", ".join(f"{lab} {s[k]:.3f}" for k, lab in TARGET_METRICS))


if __name__ == "__main__":
    main()
