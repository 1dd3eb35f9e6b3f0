"""The limb model: a whole limb's corrections in one ONNX graph, run by onnxruntime.

Contract (``jointlimits-limb-correction/1``)::

    orientations [N, J, 4] float32   joint orientations, child relative to parent, scalar-first,
                                     either sign, in the limb file's joint order
    corrections  [N, J, 4] float32   unit, w >= 0;  corrected_j = correction_j ⊗ orientation_j

Metadata (``metadata_props``): ``jointlimits.format``, ``jointlimits.limb`` (the limb file's
YAML), ``jointlimits.limb_sha256`` (:meth:`models.limb.Limb.content_hash`),
``jointlimits.joints`` (JSON list of the joint names, in order), ``jointlimits.method``,
``jointlimits.version``.

Method ``network`` (the default of ``rig train`` on a limb file): every coupled polygon swing
by its trained distance field (:mod:`models.nn.ndf`): ``f(d, τ)`` with ``τ`` the source's
corrected angle mapped to [-1, 1]; ``outside = f(d, τ) > 0``; ``b`` after the field's
projection steps ``d ← cos(αf⁺) d − sin(αf⁺) ĝ`` (``ĝ`` the unit tangent of the analytic input
gradient; step fractions ``α`` 0.25, 0.5, 0.5, 1, 1), all in the graph as matrix products
— the steps in the branch of an ``If`` node taken only when some direction is outside (a
direction inside takes no step, so a valid posture's single call skips them: issue 39);
the hinges, the twist clamps (intervals interpolated at ``τ``'s angle) and every uncoupled joint
exactly as below. Metadata ``jointlimits.training`` (JSON) holds the seed, the postures' count
(and the dataset's hash when trained from one), the network's size and the training time.

Method ``geometric``: the exact limb oracle (:mod:`models.oracle`) compiled into the
graph, in float32 — no table, no training; its size grows with the vertex count only.

The graph runs the joints in stages of the hierarchy (a joint after the joints its limits
depend on, as late as its dependents allow), and the joints of one kind in one stage as one
group — tensors (K, N, ·), a row per joint, per-joint constants — so the node count, which is
what one posture costs in onnxruntime (~0.3 µs a node), grows with the kinds rather than the
joints (a leg: 261 nodes). Per joint:

- **hinge**: the half-angle pair ``(w, a·v)`` of its orientation about the axis, clamped to the
  interval on the circle (the twist clamp of :mod:`models.field`: relative to the interval's
  middle, nearer end, a tie to ``max``); the projection is the pure rotation about the axis
  with the clamped angle (the geodesic correction: out-of-axis motion is removed too). Its
  corrected angle ``θ = 4 atan(s / (1 + c))`` (``(c, s)`` the clamped pair with ``c >= 0``)
  drives the joints coupled to it;
- **forearm**: the exact closed form of :mod:`models.kinds.forearm` on half-angle pairs
  (``u = (cos θ/2, sin θ/2)`` of the flexion, ``v`` of the axial rotation; no angle is taken
  but the output's): ``A_ij = <q, e_ij>`` by one ``MatMul`` with the four edges' free pairs;
  the free optimum as square roots of two complex products; the edges' free pairs clamped as
  a hinge's, the first largest ``|h|`` where the optimum is outside (:func:`_forearm_group`;
  the edges in an ``If`` branch taken only then: a single call within the intervals skips
  them, 102.5 → 94.8 µs median on held-out forearm arm 9200, interleaved, 2026-11-28).
  Its corrected flexion ``θ = 4 atan(s / (1 + c))`` drives the joints coupled to it, as a
  hinge's angle does;
- **swing** (ball, two-axis): limb direction ``d = R(q) a``; nearest boundary point ``b`` of a
  cone (closed form) or a polygon by the kernel of :class:`models.geometry.SphericalPolygon`
  over every edge (key = squared chord, lowest index on ties — ``ArgMin`` returns the first —,
  pseudo-normal sign; every edge's products with ``d`` in one ``MatMul``, the nearest edge's
  rows by a one-hot ``MatMul``); swing correction ``Δ`` = the minimal rotation ``d → b`` where
  outside; then the twist of ``Δ ⊗ q`` clamped as for a hinge about ``d`` (``τ``); correction
  ``Δ ⊗ τ``;
- **coupled** joints: keyframe interval ``k`` and fraction ``t`` of the source's corrected angle
  (clamped to the keyframes' range), intervals ``min``/``max`` linear in ``t``, cones by
  normalised interpolation of the centre and linear radius, polygons as the normalised mix of
  the keyframes' corresponding vertices (:func:`models.limb.corresponding_polygons`, padded to
  one vertex count by splitting edges — the same boundaries) gathered per sample.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import onnx
from onnx import TensorProto, helper

from models.fileio import write_owner_only
from models.kinds.forearm import basis as forearm_basis
from models.limb import Limb, oriented_vertices
from models.limits import ConeSwing, PolygonSwing
from models.onnx_io import (
    LIMB_CONTRACT,
    OPSET,
    Graph,
    bilinear,
    interval_clamp,
    package_version,
    product_tensor,
    rotation_tensor,
    twist_clamp,
    twist_rotation,
)

__all__ = ["FORMAT", "INPUT", "OUTPUT", "export_limb_model", "limb_to_onnx"]

#: The limb contract's format, input and output names (:data:`models.onnx_io.LIMB_CONTRACT`;
#: the file is opened by :func:`models.onnx_io.load_model`).
FORMAT, INPUT, OUTPUT = LIMB_CONTRACT.format, LIMB_CONTRACT.input, LIMB_CONTRACT.output

_PROD = product_tensor()
_I64 = np.int64


# ---------------------------------------------------------------------------------------------
# Graph pieces. Joints of one kind at one stage of the hierarchy run as one group: tensors
# (K, N, ·) with one row per joint and per-joint constants (K, 1, ·) or (K, ·, ·), so the node
# count (what a single call costs in onnxruntime) grows with the kinds, not the joints.
# ---------------------------------------------------------------------------------------------
_CROSS = np.zeros((3, 3, 3))
for _a, _b, _c in ((0, 1, 2), (1, 2, 0), (2, 0, 1)):
    _CROSS[_a, _b, _c], _CROSS[_b, _a, _c] = 1.0, -1.0


def _i(g: Graph, v) -> str:
    return g.const(np.asarray(v), dtype=_I64)


def _dot(g: Graph, a: str, b: str) -> str:
    return g.op("ReduceSum", [g.op("Mul", [a, b]), _i(g, [-1])], keepdims=1)


def _normalize(g: Graph, a: str) -> str:
    """Unit rows over the last axis (a zero row stays zero)."""
    return g.op("LpNormalization", [a], axis=-1, p=2)


def _cross(g: Graph, a: str, b: str) -> str:
    """a × b over the last axis (length 3)."""
    return bilinear(g, a, b, _CROSS, "cross")


def _first(g: Graph, a: str) -> str:
    """The first component over the last axis (…, 1)."""
    return g.op("Slice", [a, _i(g, [0]), _i(g, [1]), _i(g, [-1])])


def _canonical(g: Graph, q: str) -> str:
    """``q`` with ``w >= 0``."""
    return g.op("Mul", [q, g.op("Where", [g.op("Less", [_first(g, q), g.const(0.0)]),
                                         g.const(-1.0), g.const(1.0)])])


def _rows(g: Graph, group: str, k: int, size: int) -> str:
    """Row ``k`` (N, ·) of a group tensor (K, N, ·)."""
    one = group if size == 1 else g.op("Gather", [group, _i(g, [k])], axis=0)
    return g.op("Squeeze", [one, _i(g, [0])])


def _stack(g: Graph, parts: list[str]) -> str:
    """Rows (N, ·) stacked into a group tensor (K, N, ·)."""
    ups = [g.op("Unsqueeze", [p, _i(g, [0])]) for p in parts]
    return ups[0] if len(ups) == 1 else g.op("Concat", ups, axis=0)


class _Limits:
    """Per-joint intervals of a group (hinge angles or twists, radians): each a (lo, hi) pair
    of floats, None (no limit: the whole circle) or a tensor (N, 2) (coupled)."""

    def __init__(self, items: list):
        self.limited = any(x is not None for x in items)  #: any joint with a limit
        self.items = [(-math.pi, math.pi) if x is None else x for x in items]

    def clamp(self, g: Graph, t: str, target: bool) -> tuple[str, str | None]:
        """:func:`models.onnx_io.interval_clamp` of half-angle pairs ``t`` (K, N, 2), each row
        to its joint's interval (constants folded; per-sample ones stacked to (K, N, 2))."""
        if all(isinstance(x, tuple) for x in self.items):
            return interval_clamp(g, t, tuple(np.array(self.items, dtype=float).T), target)
        ref = next(x for x in self.items if isinstance(x, str))
        shape = g.op("Shape", [ref])
        return interval_clamp(g, t, _stack(g, [x if isinstance(x, str) else g.op("Expand", [
            g.const(np.array(x)[None]), shape]) for x in self.items]), target)


def _keyframe_lerp(g: Graph, kt, values: np.ndarray) -> str:
    """(N, C) per-sample rows linear between keyframes' rows ``values`` (K, C) (intervals
    (lo, hi), cone centres, radii) at the located interval and fraction ``kt``."""
    k, t = kt
    lo = g.op("Squeeze", [g.op("Gather", [g.const(values[:-1]), k], axis=0), _i(g, [1])])
    hi = g.op("Squeeze", [g.op("Gather", [g.const(values[1:]), k], axis=0), _i(g, [1])])
    return g.op("Add", [lo, g.op("Mul", [g.op("Sub", [hi, lo]), t])])


def _locate(g: Graph, angle: str, at: np.ndarray) -> tuple[str, str]:
    """Keyframe interval (N, 1) int64 and fraction (N, 1) of coupling angles (N, 1)."""
    n = len(at)
    if n > 2:
        ge = g.op("Cast", [g.op("GreaterOrEqual", [angle, g.const(at[1:-1][None, :])])],
                  to=TensorProto.FLOAT)
        k = g.op("Cast", [g.op("ReduceSum", [ge, _i(g, [1])], keepdims=1)], to=TensorProto.INT64)
    else:
        k = g.op("Cast", [g.op("Mul", [angle, g.const(0.0)])], to=TensorProto.INT64)
    a0 = g.op("Gather", [g.const(at[:-1]), k], axis=0)  # (N, 1)
    span = g.op("Gather", [g.const(np.diff(at)), k], axis=0)
    t = g.op("Div", [g.op("Sub", [angle, a0]), span])
    t = g.op("Clip", [t, g.const(0.0), g.const(1.0)])
    return k, t


def _hinge_group(g: Graph, q: str, axes: np.ndarray, lims: _Limits) -> tuple[str, str]:
    """Corrections (K, N, 4) and corrected angles (K, N, 1) of hinges ``q`` (K, N, 4) about
    ``axes`` (K, 3): the half-angle pair ``(w, a·v)`` clamped, the pure rotation about the axis
    with the clamped angle (the geodesic correction: out-of-axis motion is removed too)."""
    tmap = np.zeros((len(axes), 4, 2))
    tmap[:, 0, 0] = 1.0
    tmap[:, 1:, 1] = axes
    _, target = lims.clamp(g, g.op("MatMul", [q, g.const(tmap)]), True)
    target = _canonical(g, target)
    c, s = g.ops("Split", [target], 2, axis=-1)
    angle = g.op("Mul", [g.op("Atan", [g.op("Div", [s, g.op("Add", [c, g.const(1.0)])])]),
                         g.const(4.0)])
    hmap = np.zeros((len(axes), 2, 4))
    hmap[:, 0, 0] = 1.0
    hmap[:, 1, 1:] = axes
    h = g.op("MatMul", [target, g.const(hmap)])  # (c, s a); correction = h ⊗ q⁻¹
    qinv = g.op("Mul", [q, g.const([1.0, -1.0, -1.0, -1.0])])
    corr = bilinear(g, h, qinv, _PROD, "hinge_correction")
    return _canonical(g, _normalize(g, corr)), angle


def _half_pairs(angles: np.ndarray) -> np.ndarray:
    """Half-angle pairs ``(cos θ/2, sin θ/2)`` (..., 2) of angles (radians)."""
    return np.stack([np.cos(0.5 * angles), np.sin(0.5 * angles)], axis=-1)


def _clamp_pairs(g: Graph, t: str, lo: np.ndarray, hi: np.ndarray) -> str:
    """Half-angle pairs ``t`` (..., 2) clamped to intervals ``[lo, hi]`` (radians, constants
    broadcast to ``t``'s leading shape, one per pair): the hinge's rule on the circle
    (:func:`models.onnx_io.twist_clamp`: relative to the middle, nearer end, a tie to ``max``).
    Returns the clamped pairs, unit (the input's own where inside)."""
    mid, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
    cm, sm = np.cos(0.5 * mid)[..., None], np.sin(0.5 * mid)[..., None]
    tn = _normalize(g, t)
    swap = g.op("MatMul", [tn, g.const([[0.0, 1.0], [1.0, 0.0]])])  # (x, w)
    u = g.op("Add", [g.op("Mul", [tn, g.const(np.concatenate([cm, cm], -1))]),
                     g.op("Mul", [swap, g.const(np.concatenate([sm, -sm], -1))])])  # t e^{-i mid/2}
    e = twist_clamp(g, u, g.const(np.cos(0.5 * half)[..., None]),
                    g.const(np.sin(0.5 * half)[..., None]))
    e_w, e_x = g.ops("Split", [e], 2, axis=-1)  # e ⊗ t̂ (complex product)
    return g.op("Add", [g.op("Mul", [tn, e_w]), g.op("Mul", [
        g.op("MatMul", [tn, g.const([[0.0, 1.0], [-1.0, 0.0]])]), e_x])])


def _forearm_group(g: Graph, q: str, ns: np.ndarray, xs: np.ndarray, flex: np.ndarray,
                   rot: np.ndarray) -> tuple[str, str]:
    """Corrections (K, N, 4) and corrected flexion angles (K, N, 1) of forearm joints ``q``
    (K, N, 4) with flexion axes ``ns`` and limb axes ``xs`` (K, 3), intervals ``flex`` and
    ``rot`` (K, 2) radians: the exact closed form of :mod:`models.kinds.forearm` on half-angle
    pairs ``u = (cos θ/2, sin θ/2)``, ``v = (cos φ/2, sin φ/2)`` (no angle is taken but the
    output's flexion). ``A_ij = <q, e_ij>``; ``z1 = ½(A00 + A11) + ½i(A10 − A01)`` and
    ``z2 = ½(A00 − A11) + ½i(A01 + A10)``; the free optimum ``u0 = √(z1 z2)``,
    ``v0 = √(z2 z̄1)`` (either square root: a pair and its negative are one rotation); on an
    edge (one angle fixed at an end, pair ``c``) the free pair is ``w = Aᵀc`` or ``A c``,
    clamped to its interval, with ``h = w · clamped``; the first largest ``|h|`` of the four
    edges where ``(u0, v0)`` is outside either interval. Projection ``Σ u_i v_j e_ij``."""
    k = len(ns)
    bases = np.stack([forearm_basis(n, x) for n, x in zip(ns, xs, strict=True)])  # (K, 4, 4)
    zmap = np.array([[0.5, 0.0, 0.5, 0.0], [0.0, -0.5, 0.0, 0.5],
                     [0.0, 0.5, 0.0, 0.5], [0.5, 0.0, -0.5, 0.0]])  # A → (x1, y1, x2, y2)
    ends = np.concatenate([_half_pairs(flex), _half_pairs(rot)], axis=1)  # (K, 4, 2)
    emap = np.zeros((k, 4, 8))  # A → the four edges' free pairs
    for e in range(4):
        c0, c1 = ends[:, e, 0], ends[:, e, 1]
        if e < 2:  # θ fixed: w = Aᵀu = (A00 cu + A10 su, A01 cu + A11 su)
            emap[:, 0, 2 * e], emap[:, 2, 2 * e] = c0, c1
            emap[:, 1, 2 * e + 1], emap[:, 3, 2 * e + 1] = c0, c1
        else:  # φ fixed: w = A v = (A00 cv + A01 sv, A10 cv + A11 sv)
            emap[:, 0, 2 * e], emap[:, 1, 2 * e] = c0, c1
            emap[:, 2, 2 * e + 1], emap[:, 3, 2 * e + 1] = c0, c1
    amap = np.swapaxes(bases, 1, 2)  # q → A
    lin = g.op("MatMul", [q, g.const(np.concatenate([amap @ zmap, amap @ emap], axis=2))])
    z, free = g.ops("Split", [lin, _i(g, [4, 8])], 2, axis=-1)
    # free optimum: (z1 z2, z2 z̄1) as one quadratic form, then a square root of each
    sq = np.zeros((4, 4, 4))
    sq[0, 2, 0], sq[1, 3, 0], sq[0, 3, 1], sq[1, 2, 1] = 1.0, -1.0, 1.0, 1.0
    sq[0, 2, 2], sq[1, 3, 2], sq[0, 3, 3], sq[1, 2, 3] = 1.0, 1.0, 1.0, -1.0
    w = g.op("Reshape", [bilinear(g, z, z, sq, "forearm_optimum"), _i(g, [0, 0, 2, 2])])
    r = g.op("ReduceL2", [w], axes=[-1], keepdims=1)
    right = g.op("Add", [w, g.op("Mul", [r, g.const([1.0, 0.0])])])  # (r + x, y)
    right = g.op("Add", [right, g.const([1e-18, 0.0])])  # r = 0 (no unique optimum): (1, 0)
    left = g.op("Add", [g.op("MatMul", [w, g.const([[0.0, -1.0], [1.0, 0.0]])]),
                        g.op("Mul", [r, g.const([0.0, 1.0])])])  # (y, r − x)
    opt = _normalize(g, g.op("Where", [g.op("Less", [_first(g, w), g.const(0.0)]), left,
                                       right]))  # (K, N, 2, 2): u0, v0
    lims = np.stack([flex, rot], axis=1)  # (K, 2, 2): per pair (lo, hi)
    mid, half = lims.mean(axis=2), 0.5 * (lims[..., 1] - lims[..., 0])
    rel_x = g.op("ReduceSum", [g.op("Mul", [opt, g.const(np.stack([
        -np.sin(0.5 * mid), np.cos(0.5 * mid)], -1)[:, None])]), _i(g, [-1])], keepdims=0)
    worst = g.op("ReduceMax", [g.op("Sub", [g.op("Abs", [rel_x]), g.const(
        np.sin(0.5 * half)[:, None])])], axes=[-1], keepdims=1)
    inside = g.op("LessOrEqual", [worst, g.const(0.0)])  # (K, N, 1)
    opt4 = g.op("Reshape", [opt, _i(g, [0, 0, 4])])
    # the edges (θ = lo, hi with φ free; φ = lo, hi with θ free) in the branch of an If taken
    # only when some optimum is outside: a posture within the intervals skips them
    br = g.branch()
    free = br.op("Reshape", [free, _i(br, [0, 0, 4, 2])])
    e_lo = np.stack([rot[:, 0], rot[:, 0], flex[:, 0], flex[:, 0]], 1)
    e_hi = np.stack([rot[:, 1], rot[:, 1], flex[:, 1], flex[:, 1]], 1)
    clamped = _clamp_pairs(br, free, e_lo[:, None], e_hi[:, None])  # (K, N, 4, 2)
    h = br.op("Abs", [br.op("ReduceSum", [br.op("Mul", [free, clamped]), _i(br, [-1])],
                            keepdims=0)])
    best = br.op("ArgMax", [h], axis=-1, keepdims=1)  # the first largest (K, N, 1)
    fixed = br.const(ends[:, None])  # (K, 1, 4, 2)
    theta_edge = br.const(np.array([True, True, False, False])[:, None], dtype=np.bool_)
    cand = br.op("Concat", [br.op("Where", [theta_edge, fixed, clamped]),
                            br.op("Where", [theta_edge, clamped, fixed])], axis=-1)
    at = br.op("Tile", [br.op("Unsqueeze", [best, _i(br, [-1])]), _i(br, [1, 1, 1, 4])])
    edge = br.op("Squeeze", [br.op("GatherElements", [cand, at], axis=2), _i(br, [2])])
    chosen = br.op("Where", [inside, opt4, edge])
    same = g.branch()
    kept = same.op("Identity", [opt4])
    anyone = g.op("Not", [g.op("Cast", [g.op("ReduceMin", [g.op("Cast", [
        inside], to=TensorProto.FLOAT)], keepdims=0)], to=TensorProto.BOOL)])
    uv = g.op("If", [anyone], then_branch=helper.make_graph(
        br.nodes, g.name("edges"), [], [helper.make_tensor_value_info(
            chosen, TensorProto.FLOAT, None)], br.inits), else_branch=helper.make_graph(
        same.nodes, g.name("within"), [], [helper.make_tensor_value_info(
            kept, TensorProto.FLOAT, None)], same.inits))
    u, v = g.ops("Split", [uv], 2, axis=-1)
    proj = bilinear(g, u, v, bases.reshape(k, 2, 2, 4), "forearm_projection")
    qinv = g.op("Mul", [q, g.const([1.0, -1.0, -1.0, -1.0])])
    corr = bilinear(g, proj, qinv, _PROD, "forearm_correction")
    c, s_ = g.ops("Split", [_canonical(g, u)], 2, axis=-1)
    angle = g.op("Mul", [g.op("Atan", [g.op("Div", [s_, g.op("Add", [c, g.const(1.0)])])]),
                         g.const(4.0)])
    return _canonical(g, _normalize(g, corr)), angle


def _swing_group(g: Graph, q: str, axes: np.ndarray, nearests: list, lims: _Limits) -> str:
    """Corrections (K, N, 4) of ball / two-axis joints ``q`` (K, N, 4) with limb axes ``axes``
    (K, 3): limb direction ``d``; per joint ``nearest(d (N, 3)) -> (outside (N, 1), b (N, 3))``
    or None; swing correction ``Δ`` = the minimal rotation ``d → b`` where outside; the twist of
    ``Δ ⊗ q`` about ``d`` clamped (``τ``; none when no joint of the group has a twist limit);
    correction ``Δ ⊗ τ``."""
    k = len(axes)
    d = _normalize(g, bilinear(g, q, q, np.stack([rotation_tensor(a) for a in axes]),
                                "limb_direction"))
    delta = None
    if any(n is not None for n in nearests):
        outs, bs = [], []
        for j, nearest in enumerate(nearests):
            dj = _rows(g, d, j, k)
            if nearest is None:
                outs.append(g.op("Greater", [_first(g, dj), g.const(2.0)]))  # never
                bs.append(dj)
            else:
                o, b = nearest(dj)
                outs.append(o)
                bs.append(b)
        outside, b = _stack(g, outs), _stack(g, bs)
        cosb1 = g.op("Add", [_dot(g, d, b), g.const(1.0)])
        raw = g.op("Concat", [cosb1, _cross(g, d, b)], axis=-1)
        # d exactly opposite b: half a turn about any axis perpendicular to d
        ref = g.op("Where", [g.op("Less", [g.op("Abs", [_first(g, d)]), g.const(0.9)]),
                             g.const([1.0, 0.0, 0.0]), g.const([0.0, 1.0, 0.0])])
        flip = g.op("Concat", [g.op("Mul", [cosb1, g.const(0.0)]),
                               _normalize(g, _cross(g, d, ref))], axis=-1)
        raw = g.op("Where", [g.op("Less", [cosb1, g.const(1e-7)]), flip, raw])
        delta = g.op("Where", [outside, _normalize(g, raw), g.const([1.0, 0.0, 0.0, 0.0])])
    if not lims.limited:
        if delta is None:
            return g.op("Add", [g.op("Mul", [q, g.const(0.0)]), g.const([1.0, 0, 0, 0])])
        return delta
    tmap = np.stack([np.concatenate((_PROD[..., :1], (_PROD[..., 1:] @ a)[..., None]), axis=-1)
                     for a in axes])  # (K, 4, 4, 2): twist pair of p ⊗ q about a
    if delta is None:
        t = g.op("MatMul", [q, g.const(tmap[:, 0])])
    else:
        t = bilinear(g, delta, q, tmap, "twist_pair")
    e, _ = lims.clamp(g, t, False)
    tau = twist_rotation(g, d, e, rank=3)
    if delta is None:
        return _canonical(g, tau)
    return _canonical(g, _normalize(g, bilinear(g, delta, tau, _PROD, "swing_twist")))


def _polygon_tables(v: np.ndarray) -> dict[str, np.ndarray]:
    """Per-edge tables of an oriented polygon (region on the side of ``v_i × v_{i+1}``)."""
    v1 = np.roll(v, -1, axis=0)
    gn = np.cross(v, v1)
    gn /= np.linalg.norm(gn, axis=1, keepdims=True)
    return {"v0": v, "v1": v1, "g": gn, "t0": np.cross(gn, v), "t1": np.cross(v1, gn),
            "vn": gn + np.roll(gn, 1, axis=0)}


def _pad(a: np.ndarray, b: np.ndarray, m: int) -> tuple[np.ndarray, np.ndarray]:
    """Split the longest edges (of ``a``) of two corresponding polygons until they have ``m``
    vertices; a split point lies on its edge, so both boundaries are unchanged."""
    a, b = a.copy(), b.copy()
    while len(a) < m:
        na = np.roll(a, -1, axis=0)
        i = int(np.argmax(np.linalg.norm(na - a, axis=1)))
        ma = a[i] + na[i]
        mb = b[i] + np.roll(b, -1, axis=0)[i]
        a = np.insert(a, i + 1, ma / np.linalg.norm(ma), axis=0)
        b = np.insert(b, i + 1, mb / np.linalg.norm(mb), axis=0)
    return a, b


_DOTS = ("g", "t0", "t1", "v0", "v1")  # the columns of a polygon's dot table, in order
_ROWS = ("g", "v0", "v1", "vn", "vn1")  # the columns of its row table


def _nearest_polygon(g: Graph, d: str, dots: str, rows: str, m: int) -> tuple[str, str]:
    """Kernel of :class:`models.geometry.SphericalPolygon` over all ``m`` edges. ``d`` (N, 3);
    ``dots`` (1|N, 3, 5m) the tables :data:`_DOTS` side by side (one product gives every
    edge's plane side, arc coordinates and end cosines); ``rows`` (1|N, m, 15) the tables
    :data:`_ROWS` (``vn1`` the next edge's ``vn``): the nearest edge's rows by one one-hot
    product. Key = squared chord of the nearest point of each edge (lowest index on ties —
    ``ArgMin`` returns the first —), pseudo-normal sign. Returns ``(outside (N, 1), b)``."""
    p = g.op("MatMul", [g.op("Unsqueeze", [d, _i(g, [1])]), dots])  # (N, 1, 5m)
    s, a0, a1, c0, c1 = g.ops("Split", [p], 5, axis=-1)
    s2 = g.op("Mul", [s, s])
    in_arc = g.op("And", [g.op("And", [g.op("GreaterOrEqual", [a0, g.const(0.0)]),
                                       g.op("GreaterOrEqual", [a1, g.const(0.0)])]),
                          g.op("Less", [s2, g.const(1.0 - 1e-6)])])
    key_in = g.op("Div", [g.op("Mul", [s2, g.const(2.0)]), g.op("Add", [
        g.const(1.0), g.op("Sqrt", [g.op("Max", [g.op("Sub", [g.const(1.0), s2]),
                                                 g.const(0.0)])])])])
    key_end = g.op("Sub", [g.const(2.0), g.op("Mul", [g.op("Max", [c0, c1]), g.const(2.0)])])
    best = g.op("ArgMin", [g.op("Where", [in_arc, key_in, key_end])], axis=-1, keepdims=1)
    onehot = g.op("Cast", [g.op("Equal", [best, _i(g, np.arange(m))])], to=TensorProto.FLOAT)
    gb, v0, v1, vn0, vn1 = g.ops("Split", [g.op("Squeeze", [
        g.op("MatMul", [onehot, rows]), _i(g, [1])])], 5, axis=-1)
    at = g.op("Add", [best, _i(g, [0, 3 * m, 4 * m])])  # s, c0, c1 of the nearest edge
    sb, cb0, cb1 = g.ops("Split", [g.op("Squeeze", [
        g.op("GatherElements", [p, at], axis=-1), _i(g, [1])])], 3, axis=-1)
    arc = g.op("Squeeze", [g.op("GatherElements", [in_arc, best], axis=-1), _i(g, [1])])
    end1 = g.op("Greater", [cb1, cb0])  # the edge's end nearer than its start
    vn = g.op("Where", [end1, vn1, vn0])
    side = g.op("Where", [arc, sb, _dot(g, d, vn)])
    foot = _normalize(g, g.op("Sub", [d, g.op("Mul", [sb, gb])]))
    return g.op("Less", [side, g.const(0.0)]), g.op("Where", [arc, foot, g.op("Where", [
        end1, v1, v0])])


def _nearest_cone(g: Graph, d: str, c: str, r: str) -> tuple[str, str]:
    """Cone(s) of centre ``c`` and radius ``r`` (constants or (N, 3) / (N, 1))."""
    cos_t = _dot(g, d, c)
    tang = g.op("Sub", [d, g.op("Mul", [cos_t, c])])
    dm = g.op("Sub", [d, c])
    dp = g.op("Add", [d, c])
    theta = g.op("Mul", [g.op("Atan", [g.op("Div", [
        g.op("Sqrt", [_dot(g, dm, dm)]), g.op("Sqrt", [_dot(g, dp, dp)])])]), g.const(2.0)])
    b = g.op("Add", [g.op("Mul", [g.op("Cos", [r]), c]),
                     g.op("Mul", [g.op("Sin", [r]), _normalize(g, tang)])])
    return g.op("Greater", [theta, r]), b


def _constant_polygon(g: Graph, swing: PolygonSwing):
    tab = _polygon_tables(oriented_vertices(swing))
    tab["vn1"] = np.roll(tab["vn"], -1, axis=0)
    m = len(tab["v0"])
    dots = g.const(np.concatenate([tab[k].T for k in _DOTS], axis=1)[None])
    rows = g.const(np.concatenate([tab[k] for k in _ROWS], axis=1)[None])
    return lambda d: _nearest_polygon(g, d, dots, rows, m)


def _coupled_polygon(g: Graph, pairs, kt):
    m = max(len(a) for a, _ in pairs)
    padded = [_pad(a, b, m) for a, b in pairs]
    a_st = np.stack([a for a, _ in padded])
    b_st = np.stack([b for _, b in padded])
    k, t = kt
    t3 = g.op("Unsqueeze", [t, _i(g, [2])])  # (N, 1, 1)
    ga = g.op("Squeeze", [g.op("Gather", [g.const(a_st), k], axis=0), _i(g, [1])])
    gb = g.op("Squeeze", [g.op("Gather", [g.const(b_st), k], axis=0), _i(g, [1])])
    v0 = _normalize(g, g.op("Add", [ga, g.op("Mul", [g.op("Sub", [gb, ga]), t3])]))  # (N, m, 3)

    def roll(x: str, by: int) -> str:
        return g.op("Gather", [x, _i(g, np.roll(np.arange(m), -by))], axis=1)

    v1 = roll(v0, 1)
    gn = _normalize(g, _cross(g, v0, v1))
    vn = g.op("Add", [gn, roll(gn, -1)])
    tab = {"v0": v0, "v1": v1, "g": gn, "t0": _cross(g, gn, v0), "t1": _cross(g, v1, gn),
           "vn": vn, "vn1": roll(vn, 1)}
    dots = g.op("Transpose", [g.op("Concat", [tab[k_] for k_ in _DOTS], axis=1)],
                perm=[0, 2, 1])
    rows = g.op("Concat", [tab[k_] for k_ in _ROWS], axis=2)
    return lambda d: _nearest_polygon(g, d, dots, rows, m)


def _field_nearest(g: Graph, tau: str, net):
    """``nearest(d) -> (outside, b)`` of a coupled swing by its trained distance field
    (:class:`models.nn.ndf.DistanceField`): ``outside`` where ``f(d, τ) > 0``, ``b`` after the
    field's projection steps (the same computation as :meth:`DistanceField.project`)."""
    nf = net.b.shape[1]
    f32 = np.float32
    bd = g.const(net.b[:3].astype(f32))
    w1_fd = g.const(net.w1[:nf + 3].astype(f32))           # rows of sin(u) and d
    w2, w3 = g.const(net.w2.astype(f32)), g.const(net.w3[:, None].astype(f32))
    w1_ft = g.const(net.w1[:nf].T.astype(f32).copy())       # (H, F)
    w1_dt = g.const(net.w1[nf:nf + 3].T.astype(f32).copy())  # (H, 3)
    w2t, w3r = g.const(net.w2.T.astype(f32).copy()), g.const(net.w3[None].astype(f32))
    bdt = g.const(net.b[:3].T.astype(f32).copy())            # (F, 3)
    b2, b3 = g.const(net.b2[None].astype(f32)), g.const(net.b3[None].astype(f32))
    one = g.const(1.0)
    # the terms of τ are the same at every step
    u_t = g.op("Add", [g.op("Mul", [tau, g.const(net.b[3:4].astype(f32))]),
                       g.const(net.c[None].astype(f32))])
    a1_t = g.op("Add", [g.op("Mul", [tau, g.const(net.w1[nf + 3:nf + 4].astype(f32))]),
                        g.const(net.b1[None].astype(f32))])

    def forward(g: Graph, x: str) -> tuple[str, tuple[str, str, str]]:
        u = g.op("Add", [g.op("MatMul", [x, bd]), u_t])
        h1 = g.op("Tanh", [g.op("Add", [g.op("MatMul", [
            g.op("Concat", [g.op("Sin", [u]), x], axis=1), w1_fd]), a1_t])])
        h2 = g.op("Tanh", [g.op("Add", [g.op("MatMul", [h1, w2]), b2])])
        return g.op("Add", [g.op("MatMul", [h2, w3]), b3]), (u, h1, h2)

    def gradient(g: Graph, u: str, h1: str, h2: str) -> str:
        g2 = g.op("Mul", [g.op("Sub", [one, g.op("Mul", [h2, h2])]), w3r])
        g1 = g.op("Mul", [g.op("Sub", [one, g.op("Mul", [h1, h1])]), g.op("MatMul", [g2, w2t])])
        return g.op("Add", [g.op("MatMul", [g.op("Mul", [g.op("MatMul", [g1, w1_ft]),
                                                         g.op("Cos", [u])]), bdt]),
                            g.op("MatMul", [g1, w1_dt])])

    def nearest(d: str) -> tuple[str, str]:
        f, inner = forward(g, d)
        outside = g.op("Greater", [f, g.const(0.0)])
        # the steps only where some direction is outside: a valid posture's single call
        # skips them (a direction inside takes no step: Relu(f) = 0)
        anyone = g.op("Greater", [g.op("ReduceMax", [g.op("Cast", [outside], to=TensorProto.FLOAT)],
                                       keepdims=0), g.const(0.0)])
        br = g.branch()
        x = d
        for k, frac in enumerate(net.steps):
            if k:
                f, inner = forward(br, x)
            grad = gradient(br, *inner)
            tang = _normalize(br, br.op("Sub", [grad, br.op("Mul", [_dot(br, grad, x), x])]))
            step = br.op("Mul", [br.op("Relu", [f]), br.const(float(frac))])
            x = _normalize(br, br.op("Sub", [br.op("Mul", [br.op("Cos", [step]), x]),
                                             br.op("Mul", [br.op("Sin", [step]), tang])]))
        same = g.branch()
        kept = same.op("Identity", [d])
        b = g.op("If", [anyone], then_branch=helper.make_graph(
            br.nodes, g.name("steps"), [], [helper.make_tensor_value_info(
                x, TensorProto.FLOAT, None)], br.inits), else_branch=helper.make_graph(
            same.nodes, g.name("inside"), [], [helper.make_tensor_value_info(
                kept, TensorProto.FLOAT, None)], same.inits))
        return outside, b
    return nearest


def _levels(limb: Limb) -> list[int]:
    """Each joint's stage: after the joints its limits depend on, as late as the joints that
    depend on it allow (a joint nothing depends on joins the last stage, so joints of one kind
    share a group where the hierarchy allows)."""
    n = len(limb.joints)
    src = [None if j.coupling is None else limb.index(j.coupling.by) for j in limb.joints]
    early = [0] * n
    for j in limb.order:
        if src[j] is not None:
            early[j] = early[src[j]] + 1
    late = [max(early)] * n
    for j in reversed(limb.order):
        if src[j] is not None:
            late[src[j]] = min(late[src[j]], late[j] - 1)
    return late


def _graph_class(joint) -> int:
    """Which group graph answers the joint: 0 an axis and an interval (the hinge graph), 1 a
    swing region and a twist (the swing-twist graph), 2 a flexion and an axial rotation (the
    forearm graph)."""
    kind = joint.joint_kind
    return 0 if kind.single_axis else 2 if kind.flexion_rotation else 1


def _limb_graph(g: Graph, limb: Limb, fields: dict) -> None:
    """Every joint's correction into ``OUTPUT``: the groups of :func:`_levels` × kind in the
    hierarchy's order; a coupled joint reads its source's corrected angle."""
    level = _levels(limb)
    groups: dict[tuple[int, int], list[int]] = {}
    for j in sorted(range(len(limb.joints)), key=lambda j: level[j]):
        groups.setdefault((level[j], _graph_class(limb.joints[j])), []).append(j)
    qt = g.op("Transpose", [INPUT], perm=[1, 0, 2])  # (J, N, 4)
    angles: dict[int, tuple[str, int, int]] = {}  # source → (its group's angles, row, size)
    cache: dict[int, str] = {}

    def angle_of(j: int) -> str:
        if j not in cache:
            cache[j] = _rows(g, *angles[j])
        return cache[j]

    outputs, order = [], []
    for (_, cls), js in sorted(groups.items()):
        same = js == list(range(len(limb.joints)))
        q = _normalize(g, qt if same else g.op("Gather", [qt, _i(g, js)], axis=0))
        items, axes, nearests = [], [], []
        for j in js:
            joint = limb.joints[j]
            c, cp = joint.constraint, joint.coupling
            kt = src = None
            if cp is not None:
                src = angle_of(limb.index(cp.by))
                kt = _locate(g, src, np.radians(np.asarray(cp.at_deg)))
                c = cp.keyframes[0]
            if cls == 2:  # a forearm (never coupled: its keyframes are refused)
                f = c.limits
                axes.append((f.axis, c.limb_axis))
                items.append((f.flexion, f.rotation))
                continue
            if cls == 0:
                axes.append(c.hinge.axis)
                items.append((c.hinge.min, c.hinge.max) if cp is None else _keyframe_lerp(
                    g, kt, np.array([[k.hinge.min, k.hinge.max] for k in cp.keyframes])))
                continue
            axes.append(c.limb_axis)
            nearests.append(_swing_nearest(g, joint, kt, src, fields.get(joint.name)))
            items.append(None if c.twist is None else (c.twist.min, c.twist.max) if cp is None
                         else _keyframe_lerp(g, kt, np.array([[k.twist.min, k.twist.max]
                                                               for k in cp.keyframes])))
        axes = np.asarray(axes, dtype=float)
        if cls == 2:
            lims = np.asarray(items, dtype=float)  # (K, 2, 2): flexion, rotation
            corr, ang = _forearm_group(g, q, axes[:, 0], axes[:, 1], lims[:, 0], lims[:, 1])
            for r, j in enumerate(js):
                angles[j] = (ang, r, len(js))
        elif cls == 0:
            corr, ang = _hinge_group(g, q, axes, _Limits(items))
            for r, j in enumerate(js):
                angles[j] = (ang, r, len(js))
        else:
            corr = _swing_group(g, q, axes, nearests, _Limits(items))
        outputs.append(corr)
        order.extend(js)
    out = outputs[0] if len(outputs) == 1 else g.op("Concat", outputs, axis=0)
    if order != sorted(order):
        out = g.op("Gather", [out, _i(g, np.argsort(order))], axis=0)
    g.op("Transpose", [out], perm=[1, 0, 2], out=OUTPUT)


def _swing_nearest(g: Graph, joint, kt, src: str | None, field):
    """``nearest(d)`` of a ball / two-axis joint's swing (None: no swing limit); a coupled one
    at keyframe interval and fraction ``kt`` of its source's corrected angle ``src``."""
    cp = joint.coupling
    if cp is None:
        sw = joint.constraint.swing
        if isinstance(sw, ConeSwing):
            return lambda d: _nearest_cone(g, d, g.const(sw.centre[None, :]), g.const(sw.radius))
        if isinstance(sw, PolygonSwing):
            return _constant_polygon(g, sw)
        return None
    kf = cp.keyframes
    if isinstance(kf[0].swing, ConeSwing):
        centre = _normalize(g, _keyframe_lerp(g, kt, np.array([k.swing.centre for k in kf])))
        radius = _keyframe_lerp(g, kt, np.array([[k.swing.radius] for k in kf]))
        return lambda d: _nearest_cone(g, d, centre, radius)
    if isinstance(kf[0].swing, PolygonSwing):
        if field is None:
            return _coupled_polygon(g, cp.limits.polygons, kt)
        span = field.at1 - field.at0  # τ = 2 (θ − at0) / (at1 − at0) − 1, clamped
        tau = g.op("Clip", [g.op("Add", [
            g.op("Mul", [src, g.const(2.0 / span)]),
            g.const(-1.0 - 2.0 * field.at0 / span)]), g.const(-1.0), g.const(1.0)])
        return _field_nearest(g, tau, field)
    return None


def _inputs(nodes) -> set[str]:
    """The value names ``nodes`` read, their branches' (``If``) included."""
    out = set()
    for node in nodes:
        out.update(node.input)
        for attr in node.attribute:
            if attr.type == onnx.AttributeProto.GRAPH:
                out |= _inputs(attr.g.node)
    return out


def limb_to_onnx(limb: Limb, fields: dict | None = None,
                 training: dict | None = None) -> onnx.ModelProto:
    """The limb model of ``limb`` (module docstring): method ``geometric`` without ``fields``;
    method ``network`` with ``fields`` (joint name → :class:`models.nn.ndf.DistanceField`, one
    per coupled polygon swing, :func:`models.nn.ndf.fit_limb_fields`), ``training`` its facts
    (seed, samples, seconds; stored as ``jointlimits.training``)."""
    fields = fields or {}
    need = {j.name for j in limb.joints if j.coupling is not None and isinstance(
        j.coupling.keyframes[0].swing, PolygonSwing)}
    if fields and set(fields) != need:
        raise ValueError(f"fields: expected one per coupled polygon swing {sorted(need)}, "
                         f"got {sorted(fields)}")
    g = Graph()
    jn = len(limb.joints)
    _limb_graph(g, limb, fields)
    used = _inputs(g.nodes)
    g.inits = [t for t in g.inits if t.name in used]
    graph = helper.make_graph(
        g.nodes, "jointlimits_limb_correction",
        [helper.make_tensor_value_info(INPUT, TensorProto.FLOAT, ["N", jn, 4])],
        [helper.make_tensor_value_info(OUTPUT, TensorProto.FLOAT, ["N", jn, 4])],
        g.inits)
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", OPSET)],
                              producer_name="jointlimits-rig", producer_version=package_version())
    model.ir_version = 8
    model.doc_string = ("Corrective limb constraint: corrected_j = correction_j ⊗ orientation_j "
                        "(scalar-first w, x, y, z; Hamilton product; joints in the limb's order).")
    limb_yaml = limb.to_yaml()
    onnx.helper.set_model_props(model, {
        "jointlimits.format": FORMAT,
        "jointlimits.limb": limb_yaml,
        "jointlimits.limb_sha256": limb.content_hash(),
        "jointlimits.joints": json.dumps(list(limb.joint_names)),
        "jointlimits.method": "network" if fields else "geometric",
        "jointlimits.version": package_version(),
        **({"jointlimits.training": json.dumps(training or {}, sort_keys=True)}
           if fields else {}),
    })
    onnx.checker.check_model(model)
    return model


def export_limb_model(limb: Limb, path: str | Path, fields: dict | None = None,
                      training: dict | None = None) -> Path:
    """Write the limb model to ``path`` (owner-only: it embeds the patient's limits);
    ``fields``/``training`` as :func:`limb_to_onnx`."""
    path = Path(path)
    write_owner_only(path, limb_to_onnx(limb, fields, training).SerializeToString())
    return path
