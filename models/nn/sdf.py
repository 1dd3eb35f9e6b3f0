"""Method (b) of issue 9: a network for the signed geodesic distance to the swing boundary.

Pose-NDF / NRDF style: a small MLP ``f: S² → ℝ`` regresses the exact signed distance
``s(d)`` of a limb direction to the swing boundary
(:meth:`models.oracle.ConstraintOracle.swing_distance`, radians, > 0 outside); an invalid
direction is projected by ``K`` geodesic gradient steps

    ``d ← cos(f⁺) d − sin(f⁺) ĝ``,  ``ĝ = P_d ∇f / |P_d ∇f|``
    (``P_d = I − d dᵀ``, ``f⁺ = max(f, 0)``)

so a valid direction (``f ≤ 0``) takes no step. The swing correction is the minimal rotation
``d₀ → d_K``; the twist is clamped exactly as in :mod:`models.field` (same code path).

Network: ``d (3) → tanh(W₁d + b₁) (H) → tanh(W₂h + b₂) (H) → w₃·h + b₃``; its input gradient is
analytic (``∇f = W₁ᵀ((1−h₁²) ⊙ W₂ᵀ((1−h₂²) ⊙ w₃))``), i.e. two extra matrix products per step,
exactly reproducible in ONNX. Trained by full-batch Adam on exact distances (plain
supervision; the eikonal term was not needed for the measurement). This module exists for
the side-by-side measurement in ``docs/learned-constraints.md``; it is evaluated in numpy and
not exported (the tabulated field, :mod:`models.field`, won).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from models import quaternion as quat
from models.field import FieldModel
from models.oracle import ConstraintOracle


@dataclass
class DistanceMLP:
    """Two-layer tanh MLP on S² with its analytic input gradient (fitted by :meth:`fit`)."""

    hidden: int = 64
    epochs: int = 3000
    lr: float = 3e-3

    def _init(self, rng):
        h = self.hidden
        self.w1 = rng.standard_normal((3, h)) * 1.5
        self.b1 = rng.standard_normal(h) * 0.5
        self.w2 = rng.standard_normal((h, h)) / math.sqrt(h)
        self.b2 = np.zeros(h)
        self.w3 = rng.standard_normal(h) / math.sqrt(h)
        self.b3 = np.zeros(1)

    def _params(self):
        return [self.w1, self.b1, self.w2, self.b2, self.w3, self.b3]

    def forward(self, d):
        h1 = np.tanh(d @ self.w1 + self.b1)
        h2 = np.tanh(h1 @ self.w2 + self.b2)
        return h2 @ self.w3 + self.b3[0], (h1, h2)

    def gradient(self, d):
        """(N,) values and (N, 3) input gradients."""
        f, (h1, h2) = self.forward(d)
        g2 = (1 - h2 * h2) * self.w3
        g1 = (1 - h1 * h1) * (g2 @ self.w2.T)
        return f, g1 @ self.w1.T

    def fit(self, d, s, rng):
        """Full-batch Adam on ``mean((f(d) − s)²)``; ``d`` (N, 3), ``s`` (N,) radians."""
        self._init(rng)
        ps = self._params()
        m = [np.zeros_like(p) for p in ps]
        v = [np.zeros_like(p) for p in ps]
        n = len(d)
        for it in range(1, self.epochs + 1):
            f, (h1, h2) = self.forward(d)
            e = 2 * (f - s) / n
            gw3 = h2.T @ e
            gb3 = np.array([e.sum()])
            d2 = np.outer(e, self.w3) * (1 - h2 * h2)
            gw2 = h1.T @ d2
            gb2 = d2.sum(0)
            d1 = (d2 @ self.w2.T) * (1 - h1 * h1)
            gw1 = d.T @ d1
            gb1 = d1.sum(0)
            lr = self.lr * (0.1 ** (it / self.epochs))
            for p, g, mm, vv in zip(ps, [gw1, gb1, gw2, gb2, gw3, gb3], m, v, strict=True):
                mm *= 0.9
                mm += 0.1 * g
                vv *= 0.999
                vv += 0.001 * g * g
                p -= lr * (mm / (1 - 0.9 ** it)) / (np.sqrt(vv / (1 - 0.999 ** it)) + 1e-8)
        return self


class DistanceNetModel(FieldModel):
    """Method (b): learned distance + ``steps`` projection steps; twist as :class:`FieldModel`."""

    net: DistanceMLP
    steps: int

    @classmethod
    def fit_constraint(cls, constraint, rng, *, n: int = 20_000, hidden: int = 64,
                       epochs: int = 3000, steps: int = 3, oracle=None) -> DistanceNetModel:
        """Fit the distance network on ``n`` directions (half uniform, half within 20°)."""

        oracle = oracle or ConstraintOracle(constraint)
        t0 = time.perf_counter()
        d = quat.random_unit_vectors(4 * n, rng)
        s = oracle.swing_distance(d)
        near = np.abs(s) < math.radians(20)
        pick = np.concatenate((np.flatnonzero(~near)[: n // 2], np.flatnonzero(near)[: n // 2]))
        net = DistanceMLP(hidden, epochs).fit(d[pick], s[pick], rng)
        self = cls(constraint, 0, None, {"method": "distance-net", "hidden": hidden,
                                         "steps": steps})
        self.net, self.steps = net, steps
        self.info["build_s"] = time.perf_counter() - t0
        return self

    def swing_correction(self, d: np.ndarray) -> np.ndarray:
        x = d.copy()
        for _ in range(self.steps):
            f, g = self.net.gradient(x)
            g = g - (g * x).sum(1, keepdims=True) * x
            g /= np.maximum(np.linalg.norm(g, axis=1, keepdims=True), 1e-12)
            step = np.maximum(f, 0.0)[:, None]
            x = np.cos(step) * x - np.sin(step) * g
            x /= np.linalg.norm(x, axis=1, keepdims=True)
        return quat.from_two_vectors(d, x)
