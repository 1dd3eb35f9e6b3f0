"""Swing-twist factored correction: a tabulated swing-correction field and an exact twist clamp.

The corrective constraint (thesis ch. 4) is discontinuous in quaternion space — at the
boundary, at the correctional discontinuity and inside concave notches — which is what a smooth
network cannot learn (``docs/learned-constraints.md``). This model factors it the way the exact
oracle (:mod:`models.oracle`) defines it and keeps only the swing part as data:

1. limb direction ``d = R(q) a`` (``a`` the limb axis; a quadratic form of ``q``, sign-free);
2. **swing**: the swing correction ``Δ(d)`` — the minimal rotation taking ``d`` to its nearest
   point ``b`` on the swing region (identity inside) — read from a table sampled from the exact
   oracle at the nodes of a grid on S², at the node nearest to ``d``. The grid is a pair of
   *octahedral diamonds* (one per hemisphere ``z ≥ 0`` / ``z < 0``): ``p = d / |d|₁``, node
   ``(round(G(p_x+1)/2), round(G(p_y+1)/2))``; node spacing about ``3.5 / G`` rad (0.5° for
   ``G = 400``). Using the correction of a node at angle ``ε`` from ``d`` leaves the corrected
   limb within about ``ε`` of the exact one, *whatever the shape*: no smoothness is assumed, so
   concave notches and the correctional discontinuity cost nothing but the node spacing.
   Inside nodes hold the identity, so a valid orientation is returned unchanged unless its
   nearest node lies outside (within half a node spacing of the boundary);
3. **twist**: ``q' = Δ ⊗ q``; its twist ``φ`` about ``a`` (the half-angle pair ``t = (w', a·v')``
   normalised, taken relative to the middle ``m`` of the allowed interval: ``u = t e^{-i m/2}``)
   is clamped exactly: valid iff ``|u_x| ≤ sin(r/2)`` (``r`` the half-width); otherwise the
   target is ``(cos r/2, ± sin r/2)`` on the side of ``sign(u_w u_x)`` (a twist exactly opposite
   the interval goes to ``max``, the oracle's tie rule). The clamp is the rotation
   ``e = t_target t̄`` about the limb, ``τ = (e_w, e_x d)`` in the parent frame;
   with swing-dependent limits (``twist.by_swing``, contract 3 of :mod:`models.constraint`) the
   interval is the Gaussian-kernel interpolation at the *corrected* direction ``b = R(q') a``;
4. ``correction = Δ ⊗ τ`` (``corrected = correction ⊗ q``; unit by construction).

Everything is exported as one ONNX graph (:func:`models.onnx_io.export_onnx`), ~35 nodes for a
constant twist range; :meth:`FieldModel.predict` is the same computation in numpy (float64).
The table is the model's "training data": its SHA-256 is the training-data hash.
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from models import quaternion as quat
from models.oracle import ConstraintOracle

#: Default grid resolution (nodes per diamond side): node spacing ~0.5°.
DEFAULT_GRID = 400



def grid_directions(grid: int) -> np.ndarray:
    """Unit directions (2 (G+1)², 3) of the table nodes, upper diamond first.

    Node ``(h, i, j)`` has ``p = (2i/G − 1, 2j/G − 1, ±(1 − |p_x| − |p_y|))`` (sign + for
    ``h = 0``); nodes outside the diamond ``|p_x| + |p_y| ≤ 1`` (never the nearest node of a
    direction, kept to make the index arithmetic a plain product) are pulled onto its rim.
    """
    g = grid
    c = 2.0 * np.arange(g + 1) / g - 1.0
    px, py = np.meshgrid(c, c, indexing="ij")
    px, py = px.ravel(), py.ravel()
    l1 = np.abs(px) + np.abs(py)
    over = l1 > 1.0
    px = np.where(over, px / np.where(over, l1, 1.0), px)
    py = np.where(over, py / np.where(over, l1, 1.0), py)
    pz = np.maximum(1.0 - np.abs(px) - np.abs(py), 0.0)
    up = np.stack((px, py, pz), axis=1)
    down = np.stack((px, py, -pz), axis=1)
    p = np.concatenate((up, down))
    return p / np.linalg.norm(p, axis=1, keepdims=True)


def node_index(d: np.ndarray, grid: int) -> np.ndarray:
    """Index (N,) int64 of the table node nearest (in the diamond map) to unit directions (N, 3).

    The same arithmetic as the graph: ``p = d/|d|₁``, ``i = ⌊G p_x/2 + G/2 + ½⌋``,
    ``j = ⌊G p_y/2 + G/2 + ½⌋``, ``h = ⌊1 − p_z/2⌋`` (0 for ``p_z > 0``, 1 for ``p_z ≤ 0`` —
    on the equator both diamonds hold the same directions), index ``h (G+1)² + i (G+1) + j``.
    """
    d = np.asarray(d, dtype=np.float64)
    p = d / np.abs(d).sum(axis=1, keepdims=True)
    x = np.floor(p @ encode_matrix(grid) + encode_bias(grid))
    return (x @ index_weights(grid)).astype(np.int64)


def encode_matrix(grid: int) -> np.ndarray:
    """(3, 3) ``M`` of :func:`node_index`'s ``⌊p M + c⌋`` (rows ``i``, ``j``, ``h``)."""
    return np.array([[grid / 2, 0.0, 0.0], [0.0, grid / 2, 0.0], [0.0, 0.0, -0.5]])


def encode_bias(grid: int) -> np.ndarray:
    """(3,) ``c`` of :func:`node_index`'s ``⌊p M + c⌋``."""
    return np.array([grid / 2 + 0.5, grid / 2 + 0.5, 1.0])


def index_weights(grid: int) -> np.ndarray:
    """(3,) weights of ``(i, j, h)`` in the flat node index ``h (G+1)² + i (G+1) + j``."""
    return np.array([grid + 1.0, 1.0, float((grid + 1) ** 2)])


@dataclass
class FieldModel:
    """A corrective constraint as a tabulated swing field plus an exact twist clamp.

    Complete at construction: build one with :meth:`from_constraint`.

    Attributes
    ----------
    constraint : JointConstraint
    grid : int
        Nodes per diamond side ``G``.
    table : (2 (G+1)², 4) float32 or None
        Swing correction quaternion (``w ≥ 0``) at every node; None without a swing limit.
    info : dict
        Summary for the ONNX metadata (method, grid, node spacing, build time).
    """

    constraint: Any
    grid: int
    table: np.ndarray | None
    info: dict[str, Any] = field(default_factory=dict)

    @classmethod
    def from_constraint(cls, constraint, *, grid: int = DEFAULT_GRID, oracle=None) -> FieldModel:
        """Sample the exact oracle's swing correction at the grid nodes.

        Parameters
        ----------
        constraint : JointConstraint
        grid : int, >= 8
            Nodes per diamond side; time and table size grow as ``G²``
            (``2 (G+1)² × 16`` bytes: 5.2 MB for ``G = 400``).
        oracle : ConstraintOracle, optional
            Reused if given.
        """
        import time

        if isinstance(grid, bool) or not isinstance(grid, int) or grid < 8:
            raise ValueError(f"grid: expected an integer >= 8, got {grid!r}")
        t0 = time.perf_counter()
        table = None
        if constraint.swing is not None:
            oracle = oracle or ConstraintOracle(constraint)
            n = grid_directions(grid)
            b = oracle.nearest_swing_point(n)
            table = quat.from_two_vectors(n, b)  # identity where b == n (inside)
            inside = np.all(b == n, axis=1)
            table[inside] = quat.IDENTITY
            table = table.astype(np.float32)
        spacing = math.degrees(math.sqrt(4.0 * math.pi) / grid)
        info = {"method": "field", "grid": grid, "node_spacing_deg": round(spacing, 4),
                "build_s": round(time.perf_counter() - t0, 3),
                "twist": ("none" if constraint.twist is None else
                          "by_swing" if getattr(constraint.twist, "by_swing", None) is not None
                          else "constant")}
        return cls(constraint, grid, table, info)

    # -- properties used by the exporter ------------------------------------------------------
    @property
    def axis(self) -> np.ndarray:
        """Limb axis ``a`` (3,), limb frame."""
        return np.asarray(self.constraint.limb_axis, dtype=np.float64)

    def content_hash(self) -> str:
        """SHA-256 of the table (the model's training data) and its grid size."""
        h = hashlib.sha256(f"jointlimits-field/1 grid={self.grid}".encode())
        if self.table is not None:
            h.update(np.ascontiguousarray(self.table, dtype="<f4").tobytes())
        return h.hexdigest()

    # -- numpy reference of the exported graph ------------------------------------------------
    def swing_correction(self, d: np.ndarray) -> np.ndarray:
        """Table swing correction ``Δ`` (N, 4) at unit limb directions ``d`` (N, 3)."""
        if self.table is None:
            return np.tile(quat.IDENTITY, (len(d), 1))
        return self.table[node_index(d, self.grid)].astype(np.float64)

    def predict(self, q: np.ndarray) -> np.ndarray:
        """Corrections (N, 4) of orientations ``q`` (N, 4) (unit, either sign), float64.

        The computation of the ONNX graph (module docstring), in float64.
        """
        q = np.asarray(q, dtype=np.float64).reshape(-1, 4)
        a = self.axis
        d = quat.rotate(q, a)
        delta = self.swing_correction(d)
        tw = self.constraint.twist
        if tw is None:
            return delta
        qp = quat.multiply(delta, q)
        t = np.stack((qp[:, 0], qp[:, 1:] @ a), axis=1)
        t /= np.maximum(np.linalg.norm(t, axis=1, keepdims=True), 1e-12)
        if getattr(tw, "by_swing", None) is not None:
            lo, hi = tw.by_swing.limits_at(quat.rotate(qp, a))
        else:
            lo, hi = np.full(len(q), tw.min), np.full(len(q), tw.max)
        mid, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
        cm, sm = np.cos(mid / 2), np.sin(mid / 2)
        u = np.stack((t[:, 0] * cm + t[:, 1] * sm, t[:, 1] * cm - t[:, 0] * sm), axis=1)
        cr, sr = np.cos(half / 2), np.sin(half / 2)
        ab = np.abs(u)
        valid = ab[:, 1] <= sr
        sg = np.where(u[:, 0] * u[:, 1] >= 0.0, 1.0, -1.0)
        ew = cr * ab[:, 0] + sr * ab[:, 1]
        ex = sg * (sr * ab[:, 0] - cr * ab[:, 1])
        e = np.where(valid[:, None], [1.0, 0.0], np.stack((ew, ex), axis=1))
        tau = np.concatenate((e[:, :1], e[:, 1:] * d), axis=1)
        return quat.multiply(delta, tau)
