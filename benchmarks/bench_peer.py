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

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_v] = "1"

import argparse

import numpy as np

from models import quaternion as quat


def boundary_points(constraint, n: int = 2000) -> np.ndarray:
    """(n, 3) unit points spread along the swing boundary (by arc length)."""
    sw = constraint.swing
    if hasattr(sw, "centre"):
        c = np.asarray(sw.centre, float)
        e1 = quat.perpendicular(c)
        e2 = np.cross(c, e1)
        t = np.linspace(0, 2 * np.pi, n, endpoint=False)
        r = sw.radius
        return (np.cos(r) * c + np.sin(r) * (np.cos(t)[:, None] * e1 + np.sin(t)[:, None] * e2))
    v = np.asarray(sw.vertices, float)
    w = np.roll(v, -1, axis=0)
    ang = quat.angle_between(v, w)
    s = np.linspace(0, ang.sum(), n, endpoint=False)
    k = np.searchsorted(np.cumsum(ang), s, side="right")
    f = (s - np.concatenate(([0], np.cumsum(ang)))[k]) / ang[k]
    # slerp along edge k
    a, b, th = v[k], w[k], ang[k]
    p = (np.sin((1 - f) * th)[:, None] * a + np.sin(f * th)[:, None] * b) / np.sin(th)[:, None]
    return p / np.linalg.norm(p, axis=1, keepdims=True)


class VanDenBergenClamp:
    """Swing-twist clamp with an ellipse fitted to ``constraint``'s swing boundary.

    ``predict(q)`` (N, 4) → corrections (N, 4), ``corrected = correction ⊗ q``.
    """

    def __init__(self, constraint):
        self.constraint = constraint
        self.axis = np.asarray(constraint.limb_axis, float)
        self.A = None
        if constraint.swing is not None:
            pts = boundary_points(constraint)
            sw = constraint.swing
            rest = np.asarray(sw.centre if hasattr(sw, "centre") else sw.interior, float)
            self.rest = quat.from_two_vectors(self.axis, rest)  # rest frame: a → centroid
            yz = self._yz(pts)
            m = np.stack((yz[:, 0] ** 2, 2 * yz[:, 0] * yz[:, 1], yz[:, 1] ** 2), axis=1)
            a11, a12, a22 = np.linalg.lstsq(m, np.ones(len(m)), rcond=None)[0]
            lam, vec = np.linalg.eigh(np.array([[a11, a12], [a12, a22]]))
            lam = np.maximum(lam, 1e-6)  # a non-elliptic fit degenerates to a wide ellipse
            self.A, self.axes, self.rot = np.array([[a11, a12], [a12, a22]]), 1 / np.sqrt(lam), vec

    def _basis(self):
        e1 = quat.perpendicular(self.axis)
        return e1, np.cross(self.axis, e1)

    def _yz(self, d: np.ndarray) -> np.ndarray:
        """Swing-quaternion components (y, z) (N, 2) of directions in the rest frame."""
        dl = quat.rotate(np.broadcast_to(quat.conjugate(self.rest), (len(d), 4)), d)
        s = quat.from_two_vectors(np.broadcast_to(self.axis, dl.shape), dl)
        e1, e2 = self._basis()
        return np.stack((s[:, 1:] @ e1, s[:, 1:] @ e2), axis=1)

    def _clamp_ellipse(self, yz: np.ndarray) -> np.ndarray:
        p = yz @ self.rot  # principal axes
        a, b = self.axes
        out = np.einsum("ni,ij,nj->n", p, np.diag(1 / self.axes ** 2), p) > 1.0
        x0, y0 = np.abs(p[out, 0]), np.abs(p[out, 1])
        lo = np.zeros(len(x0))
        hi = np.maximum(a, b) * np.hypot(x0, y0) + 1e-12
        for _ in range(80):  # F(t) = (a x0/(t+a²))² + (b y0/(t+b²))² − 1, decreasing in t
            t = 0.5 * (lo + hi)
            f = (a * x0 / (t + a * a)) ** 2 + (b * y0 / (t + b * b)) ** 2 - 1.0
            lo = np.where(f > 0, t, lo)
            hi = np.where(f > 0, hi, t)
        t = 0.5 * (lo + hi)
        q = p.copy()
        q[out, 0] = np.sign(p[out, 0]) * a * a * x0 / (t + a * a)
        q[out, 1] = np.sign(p[out, 1]) * b * b * y0 / (t + b * b)
        return q @ self.rot.T

    def predict(self, q: np.ndarray) -> np.ndarray:
        q = np.asarray(q, float).reshape(-1, 4)
        d = quat.rotate(q, self.axis)
        proj = q.copy()
        if self.A is not None:
            yz = self._clamp_ellipse(self._yz(d))
            e1, e2 = self._basis()
            v = yz[:, :1] * e1 + yz[:, 1:] * e2
            s = np.concatenate((np.sqrt(np.maximum(1 - (yz ** 2).sum(1), 0))[:, None], v), 1)
            dn = quat.rotate(np.broadcast_to(self.rest, s.shape),
                             quat.rotate(s, np.broadcast_to(self.axis, (len(s), 3))))
            proj = quat.multiply(quat.from_two_vectors(d, dn), q)
        tw = self.constraint.twist
        if tw is not None:
            phi = quat.twist_angle(proj, self.axis)
            lo, hi = tw.min, tw.max
            bad = (phi < lo) | (phi > hi)
            wrap = lambda x: np.mod(x + np.pi, 2 * np.pi) - np.pi  # noqa: E731
            target = np.where(np.abs(wrap(phi - lo)) < np.abs(wrap(phi - hi)), lo, hi)
            delta = np.where(bad, wrap(target - phi), 0.0)
            proj = quat.multiply(proj, quat.from_axis_angle(self.axis, delta))
        return quat.canonical(quat.multiply(proj, quat.conjugate(q)))


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
