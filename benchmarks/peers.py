"""Peer methods scored beside ours by the benchmarks (``bench_peer.py``, ``bench_accuracy.py``).

:class:`VanDenBergenClamp` — the analytic peer: van den Bergen's swing-twist clamp with a fitted
ellipse. Implemented from its published description — G. van den Bergen, "Rotational Joint
Limits in Quaternion Space", GDC 2016 talk and *Game Engine Gems 3* (CRC 2016, ch. "Rotational
Joint Limits in Quaternion Space", doi:10.1201/b21177-14); ``bench_peer.py``'s docstring gives
the method and the adaptations needed to score it on our constraints.
"""

from __future__ import annotations

import numpy as np

from models import quaternion as quat

__all__ = ["VanDenBergenClamp", "boundary_points"]


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
