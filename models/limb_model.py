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
gradient; step fractions ``α`` 0.5, 0.5, 0.5, 1, 1), all in the graph as matrix products;
the hinges, the twist clamps (intervals interpolated at ``τ``'s angle) and every uncoupled joint
exactly as below. Metadata ``jointlimits.training`` (JSON) holds the seed, the postures' count
(and the dataset's hash when trained from one), the network's size and the training time.

Method ``geometric``: the exact limb oracle (:mod:`models.limb_oracle`) compiled into the
graph, in float32 — no table, no training; its size grows with the vertex count only.
Per joint, in the hierarchy's order:

- **hinge**: the half-angle pair ``(w, a·v)`` of its orientation about the axis, clamped to the
  interval on the circle (the twist clamp of :mod:`models.field`: relative to the interval's
  middle, nearer end, a tie to ``max``); the projection is the pure rotation about the axis
  with the clamped angle (the geodesic correction: out-of-axis motion is removed too). Its
  corrected angle ``θ = 4 atan(s / (1 + c))`` (``(c, s)`` the clamped pair with ``c >= 0``)
  drives the joints coupled to it;
- **swing** (ball, two-axis): limb direction ``d = R(q) a``; nearest boundary point ``b`` of a
  cone (closed form) or a polygon by the kernel of :class:`models.geometry.SphericalPolygon`
  over every edge (key = squared chord, lowest index on ties — ``ArgMin`` returns the first —,
  pseudo-normal sign); swing correction ``Δ`` = the minimal rotation ``d → b`` where outside;
  then the twist of ``Δ ⊗ q`` clamped as for a hinge about ``d`` (``τ``); correction ``Δ ⊗ τ``;
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

from models.constraint import ConeSwing, JointConstraint, PolygonSwing
from models.errors import ModelFileError
from models.fileio import write_owner_only
from models.limb import Limb, loads_limb, oriented_vertices
from models.onnx_io import (
    OPSET,
    _bilinear,
    _Graph,
    _product_tensor,
    _rotation_tensor,
    latency_session,
    package_version,
    read_onnx,
    twist_clamp,
)

__all__ = ["FORMAT", "INPUT", "OUTPUT", "LimbModel", "export_limb_model", "limb_to_onnx",
           "load_limb_model"]

FORMAT = "jointlimits-limb-correction/1"
INPUT = "orientations"
OUTPUT = "corrections"

_PROD = _product_tensor()
_I64 = np.int64


# ---------------------------------------------------------------------------------------------
# Graph pieces
# ---------------------------------------------------------------------------------------------
def _i(g: _Graph, v) -> str:
    return g.const(np.asarray(v), dtype=_I64)


def _dot(g: _Graph, a: str, b: str, axis: int = -1) -> str:
    return g.op("ReduceSum", [g.op("Mul", [a, b]), _i(g, [axis])], keepdims=1)


def _normalize(g: _Graph, a: str, axis: int = -1) -> str:
    n = g.op("Sqrt", [_dot(g, a, a, axis)])
    return g.op("Div", [a, g.op("Max", [n, g.const(1e-30)])])


def _cross(g: _Graph, a: str, b: str) -> str:
    """a × b over the last axis (length 3)."""
    yzx, zxy = _i(g, [1, 2, 0]), _i(g, [2, 0, 1])
    a1, a2 = g.op("Gather", [a, yzx], axis=-1), g.op("Gather", [a, zxy], axis=-1)
    b1, b2 = g.op("Gather", [b, yzx], axis=-1), g.op("Gather", [b, zxy], axis=-1)
    return g.op("Sub", [g.op("Mul", [a1, b2]), g.op("Mul", [a2, b1])])


def _canonical(g: _Graph, q: str) -> str:
    """``q`` with ``w >= 0`` (N, 4)."""
    w = g.op("Slice", [q, _i(g, [0]), _i(g, [1]), _i(g, [1])])
    return g.op("Mul", [q, g.op("Where", [g.op("Less", [w, g.const(0.0)]), g.const(-1.0),
                                          g.const(1.0)])])


def _clamp_pair(g: _Graph, t: str, lims) -> tuple[str, str]:
    """Clamp the half-angle pair ``t`` (N, 2) (its angle ``φ/2``) to ``[lo, hi]`` on the circle.

    ``lims``: a (lo, hi) pair of floats (radians) or a tensor (N, 2). Returns ``(e, u_full)``:
    ``e`` (N, 2) the half-angle pair of the clamping rotation (``(1, 0)`` inside), and the
    clamped target pair (N, 2) in absolute terms (``t`` normalised where inside).
    """
    rot90 = np.array([[0.0, -1.0], [1.0, 0.0]])
    tn = _normalize(g, t)
    if isinstance(lims, tuple):
        lo, hi = lims
        mid, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
        cm, sm = math.cos(mid / 2), math.sin(mid / 2)
        u = g.op("MatMul", [tn, g.const([[cm, -sm], [sm, cm]])])  # t e^{-i mid/2}
        cr, sr = g.const(math.cos(half / 2)), g.const(math.sin(half / 2))
    else:
        mh = g.op("MatMul", [lims, g.const([[0.25, -0.25], [0.25, 0.25]])])  # (mid/2, half/2)
        cmr, smr = g.op("Cos", [mh]), g.op("Sin", [mh])
        first, second = g.const([[1.0], [0.0]]), g.const([[0.0], [1.0]])
        cm_, cr = g.op("MatMul", [cmr, first]), g.op("MatMul", [cmr, second])
        sm_, sr = g.op("MatMul", [smr, first]), g.op("MatMul", [smr, second])
        u = g.op("Add", [g.op("Mul", [tn, cm_]),
                         g.op("Mul", [g.op("MatMul", [tn, g.const(rot90)]), sm_])])
    e = twist_clamp(g, u, cr, sr)
    # the clamped pair itself: e ⊗ tn (complex product)
    e_w = g.op("MatMul", [e, g.const([[1.0], [0.0]])])
    e_x = g.op("MatMul", [e, g.const([[0.0], [1.0]])])
    target = g.op("Add", [g.op("Mul", [tn, e_w]),
                          g.op("Mul", [g.op("MatMul", [tn, g.const(rot90.T)]), e_x])])
    return e, target


def _keyframe_lerp(g: _Graph, kt, values: np.ndarray) -> str:
    """(N, C) per-sample rows linear between keyframes' rows ``values`` (K, C) (intervals
    (lo, hi), cone centres, radii) at the located interval and fraction ``kt``."""
    k, t = kt
    lo = g.op("Squeeze", [g.op("Gather", [g.const(values[:-1]), k], axis=0), _i(g, [1])])
    hi = g.op("Squeeze", [g.op("Gather", [g.const(values[1:]), k], axis=0), _i(g, [1])])
    return g.op("Add", [lo, g.op("Mul", [g.op("Sub", [hi, lo]), t])])


def _locate(g: _Graph, angle: str, at: np.ndarray) -> tuple[str, str]:
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


def _hinge(g: _Graph, q: str, axis: np.ndarray, lims) -> tuple[str, str]:
    """Correction (N, 4) and corrected angle (N, 1) of a hinge joint."""
    tmap = np.zeros((4, 2))
    tmap[0, 0] = 1.0
    tmap[1:, 1] = axis
    t = g.op("MatMul", [q, g.const(tmap)])
    _, target = _clamp_pair(g, t, lims)
    target = g.op("Mul", [target, g.op("Where", [
        g.op("Less", [g.op("MatMul", [target, g.const([[1.0], [0.0]])]), g.const(0.0)]),
        g.const(-1.0), g.const(1.0)])])
    c = g.op("MatMul", [target, g.const([[1.0], [0.0]])])
    s = g.op("MatMul", [target, g.const([[0.0], [1.0]])])
    angle = g.op("Mul", [g.op("Atan", [g.op("Div", [s, g.op("Add", [c, g.const(1.0)])])]),
                         g.const(4.0)])
    # h = (c, s a); correction = h ⊗ q⁻¹
    h = g.op("MatMul", [target, g.const(np.array([[1.0, 0, 0, 0], [0, *axis]]))])
    qinv = g.op("Mul", [q, g.const([[1.0, -1.0, -1.0, -1.0]])])
    corr = _bilinear(g, h, qinv, _PROD, "hinge_correction")
    return _canonical(g, _normalize(g, corr)), angle


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


def _nearest_polygon(g: _Graph, d: str, tab: dict[str, str], m: int) -> tuple[str, str, str]:
    """Kernel of SphericalPolygon over all edges. ``d`` (N, 3); tables (1 or N, M, 3).

    Returns ``(outside (N, 1) bool, b (N, 3), dist_sign_inside (N,1) bool)``."""
    d3 = g.op("Unsqueeze", [d, _i(g, [1])])  # (N, 1, 3)
    s = g.op("ReduceSum", [g.op("Mul", [tab["g"], d3]), _i(g, [2])], keepdims=0)  # (N, M)
    a0 = g.op("ReduceSum", [g.op("Mul", [tab["t0"], d3]), _i(g, [2])], keepdims=0)
    a1 = g.op("ReduceSum", [g.op("Mul", [tab["t1"], d3]), _i(g, [2])], keepdims=0)
    s2 = g.op("Mul", [s, s])
    in_arc = g.op("And", [g.op("And", [g.op("GreaterOrEqual", [a0, g.const(0.0)]),
                                       g.op("GreaterOrEqual", [a1, g.const(0.0)])]),
                          g.op("Less", [s2, g.const(1.0 - 1e-6)])])
    key_in = g.op("Div", [g.op("Mul", [s2, g.const(2.0)]), g.op("Add", [
        g.const(1.0), g.op("Sqrt", [g.op("Max", [g.op("Sub", [g.const(1.0), s2]),
                                                 g.const(0.0)])])])])
    e0 = g.op("Sub", [tab["v0"], d3])
    e1 = g.op("Sub", [tab["v1"], d3])
    k0 = g.op("ReduceSum", [g.op("Mul", [e0, e0]), _i(g, [2])], keepdims=0)
    k1 = g.op("ReduceSum", [g.op("Mul", [e1, e1]), _i(g, [2])], keepdims=0)
    key = g.op("Where", [in_arc, key_in, g.op("Min", [k0, k1])])
    best = g.op("ArgMin", [key], axis=1, keepdims=1, select_last_index=0)  # (N, 1)
    sb = g.op("GatherElements", [s, best], axis=1)
    arc_b = g.op("GatherElements", [in_arc, best], axis=1)
    end1 = g.op("Less", [g.op("GatherElements", [k1, best], axis=1),
                         g.op("GatherElements", [k0, best], axis=1)])
    nxt = g.op("Mod", [g.op("Add", [best, _i(g, [[1]])]), _i(g, [[m]])])
    vidx = g.op("Where", [end1, nxt, best])

    def rows(table: str, idx: str) -> str:  # table (1|N, M, 3) at idx (N, 1) -> (N, 3)
        shape = g.op("Shape", [d])  # (N, 3)
        full = g.op("Expand", [table, g.op("Concat", [
            g.op("Slice", [shape, _i(g, [0]), _i(g, [1])]), _i(g, [m, 3])], axis=0)])
        ix = g.op("Expand", [g.op("Unsqueeze", [idx, _i(g, [2])]), g.op("Concat", [
            g.op("Slice", [shape, _i(g, [0]), _i(g, [1])]), _i(g, [1, 3])], axis=0)])
        return g.op("Squeeze", [g.op("GatherElements", [full, ix], axis=1), _i(g, [1])])

    gb = rows(tab["g"], best)
    vn = rows(tab["vn"], vidx)
    vv = rows(tab["v0"], vidx)
    inside = g.op("Or", [
        g.op("And", [arc_b, g.op("GreaterOrEqual", [sb, g.const(0.0)])]),
        g.op("And", [g.op("Not", [arc_b]),
                     g.op("GreaterOrEqual", [_dot(g, d, vn), g.const(0.0)])])])
    foot = _normalize(g, g.op("Sub", [d, g.op("Mul", [sb, gb])]))
    b = g.op("Where", [arc_b, foot, vv])
    return g.op("Not", [inside]), b


def _nearest_cone(g: _Graph, d: str, c: str, r: str) -> tuple[str, str]:
    """Cone(s) of centre ``c`` and radius ``r`` (constants or (N, 3) / (N, 1))."""
    cos_t = _dot(g, d, c)
    tang = g.op("Sub", [d, g.op("Mul", [cos_t, c])])
    sin_t = g.op("Sqrt", [_dot(g, tang, tang)])
    dm = g.op("Sub", [d, c])
    dp = g.op("Add", [d, c])
    theta = g.op("Mul", [g.op("Atan", [g.op("Div", [
        g.op("Sqrt", [_dot(g, dm, dm)]), g.op("Sqrt", [_dot(g, dp, dp)])])]), g.const(2.0)])
    outside = g.op("Greater", [theta, r])
    u = g.op("Div", [tang, g.op("Max", [sin_t, g.const(1e-30)])])
    b = g.op("Add", [g.op("Mul", [g.op("Cos", [r]), c]), g.op("Mul", [g.op("Sin", [r]), u])])
    return outside, b


def _swing_joint(g: _Graph, q: str, axis: np.ndarray, nearest, lims) -> str:
    """Correction (N, 4) of a ball / two-axis joint: ``nearest(d) -> (outside, b)`` or None,
    twist ``lims``: None, (lo, hi) floats or an (N, 2) tensor."""
    d = _bilinear(g, q, q, _rotation_tensor(axis), "limb_direction")
    d = _normalize(g, d)
    delta = None
    if nearest is not None:
        outside, b = nearest(d)
        cosb = _dot(g, d, b)
        axis_v = _cross(g, d, b)
        raw = g.op("Concat", [g.op("Add", [cosb, g.const(1.0)]), axis_v], axis=1)
        # d exactly opposite b: half a turn about any axis perpendicular to d
        perp = _normalize(g, _cross(g, d, g.op("Where", [
            g.op("Less", [g.op("Abs", [g.op("MatMul", [d, g.const([[1.0], [0.0], [0.0]])])]),
                          g.const(0.9)]), g.const([[1.0, 0.0, 0.0]]), g.const([[0.0, 1.0, 0.0]])])))
        flip = g.op("Concat", [g.op("Mul", [cosb, g.const(0.0)]), perp], axis=1)
        raw = g.op("Where", [g.op("Less", [g.op("Add", [cosb, g.const(1.0)]), g.const(1e-7)]),
                             flip, raw])
        delta = g.op("Where", [outside, _normalize(g, raw), g.const([[1.0, 0.0, 0.0, 0.0]])])
    if lims is None:
        if delta is None:
            return g.op("Add", [g.op("Mul", [q, g.const(0.0)]), g.const([[1.0, 0, 0, 0]])])
        return delta
    tmap = np.concatenate((_PROD[..., :1], (_PROD[..., 1:] @ axis)[..., None]), axis=-1)
    if delta is None:
        t = g.op("MatMul", [q, g.const(tmap[0])])
    else:
        t = _bilinear(g, delta, q, tmap, "twist_pair")
    e, _ = _clamp_pair(g, t, lims)
    d1 = g.op("Concat", [g.op("Add", [g.op("Mul", [g.op("MatMul", [
        d, g.const([[1.0], [0.0], [0.0]])]), g.const(0.0)]), g.const(1.0)]), d], axis=1)
    tau = g.op("Mul", [d1, g.op("MatMul", [e, g.const([[1.0, 0, 0, 0], [0, 1.0, 1.0, 1.0]])])])
    if delta is None:
        return _canonical(g, tau)
    return _canonical(g, _normalize(g, _bilinear(g, delta, tau, _PROD, "swing_twist")))


def _constant_polygon(g: _Graph, swing: PolygonSwing):
    tabs = _polygon_tables(oriented_vertices(swing))
    m = len(tabs["v0"])
    names = {k: g.const(v[None]) for k, v in tabs.items()}
    return lambda d: _nearest_polygon(g, d, names, m)


def _coupled_polygon(g: _Graph, pairs, kt):
    m = max(len(a) for a, _ in pairs)
    padded = [_pad(a, b, m) for a, b in pairs]
    a_st = np.stack([a for a, _ in padded])
    b_st = np.stack([b for _, b in padded])
    k, t = kt

    def mix(arr_a, arr_b) -> str:
        ga = g.op("Squeeze", [g.op("Gather", [g.const(arr_a), k], axis=0), _i(g, [1])])
        gb = g.op("Squeeze", [g.op("Gather", [g.const(arr_b), k], axis=0), _i(g, [1])])
        t3 = g.op("Unsqueeze", [t, _i(g, [2])])  # (N, 1, 1)
        return _normalize(g, g.op("Add", [ga, g.op("Mul", [g.op("Sub", [gb, ga]), t3])]))

    v0 = mix(a_st, b_st)
    v1 = mix(np.roll(a_st, -1, axis=1), np.roll(b_st, -1, axis=1))
    gn = _normalize(g, _cross(g, v0, v1))
    prev = mix(np.roll(a_st, 1, axis=1), np.roll(b_st, 1, axis=1))
    gprev = _normalize(g, _cross(g, prev, v0))
    tabs = {"v0": v0, "v1": v1, "g": gn, "t0": _cross(g, gn, v0), "t1": _cross(g, v1, gn),
            "vn": g.op("Add", [gn, gprev])}
    return lambda d: _nearest_polygon(g, d, tabs, m)


def _field_nearest(g: _Graph, tau: str, net):
    """``nearest(d) -> (outside, b)`` of a coupled swing by its trained distance field
    (:class:`models.nn.ndf.DistanceField`): ``outside`` where ``f(d, τ) > 0``, ``b`` after the
    field's projection steps (the same computation as :meth:`DistanceField.project`)."""
    nf = net.b.shape[1]
    f32 = np.float32
    bd, bt = g.const(net.b[:3].astype(f32)), g.const(net.b[3:4].astype(f32))
    w1_fd = g.const(net.w1[:nf + 3].astype(f32))           # rows of sin(u) and d
    w2, w3 = g.const(net.w2.astype(f32)), g.const(net.w3[:, None].astype(f32))
    w1_ft = g.const(net.w1[:nf].T.astype(f32).copy())       # (H, F)
    w1_dt = g.const(net.w1[nf:nf + 3].T.astype(f32).copy())  # (H, 3)
    w2t, w3r = g.const(net.w2.T.astype(f32).copy()), g.const(net.w3[None].astype(f32))
    bdt = g.const(net.b[:3].T.astype(f32).copy())            # (F, 3)
    one = g.const(1.0)
    # the terms of τ are the same at every step
    u_t = g.op("Add", [g.op("Mul", [tau, bt]), g.const(net.c[None].astype(f32))])
    a1_t = g.op("Add", [g.op("Mul", [tau, g.const(net.w1[nf + 3:nf + 4].astype(f32))]),
                        g.const(net.b1[None].astype(f32))])

    def evaluate(x: str) -> tuple[str, str]:
        u = g.op("Add", [g.op("MatMul", [x, bd]), u_t])
        h1 = g.op("Tanh", [g.op("Add", [g.op("MatMul", [
            g.op("Concat", [g.op("Sin", [u]), x], axis=1), w1_fd]), a1_t])])
        h2 = g.op("Tanh", [g.op("Add", [g.op("MatMul", [h1, w2]),
                                        g.const(net.b2[None].astype(f32))])])
        f = g.op("Add", [g.op("MatMul", [h2, w3]), g.const(net.b3[None].astype(f32))])
        g2 = g.op("Mul", [g.op("Sub", [one, g.op("Mul", [h2, h2])]), w3r])
        g1 = g.op("Mul", [g.op("Sub", [one, g.op("Mul", [h1, h1])]), g.op("MatMul", [g2, w2t])])
        grad = g.op("Add", [g.op("MatMul", [g.op("Mul", [g.op("MatMul", [g1, w1_ft]),
                                                         g.op("Cos", [u])]), bdt]),
                            g.op("MatMul", [g1, w1_dt])])
        return f, grad

    def nearest(d: str) -> tuple[str, str]:
        x = d
        outside = None
        for frac in net.steps:
            f, grad = evaluate(x)
            if outside is None:
                outside = g.op("Greater", [f, g.const(0.0)])
            tang = _normalize(g, g.op("Sub", [grad, g.op("Mul", [_dot(g, grad, x), x])]))
            step = g.op("Mul", [g.op("Relu", [f]), g.const(float(frac))])
            x = _normalize(g, g.op("Sub", [g.op("Mul", [g.op("Cos", [step]), x]),
                                           g.op("Mul", [g.op("Sin", [step]), tang])]))
        return outside, x
    return nearest


def _joint_graph(g: _Graph, q: str, c: JointConstraint | None, coupling, kt, field=None,
                 tau=None):
    """Correction (and the corrected angle for a hinge) of one joint; ``field``: the trained
    distance field of a coupled polygon swing (method ``network``) and ``tau`` its input."""
    if coupling is None:
        if c.kind == "hinge":
            return _hinge(g, q, np.asarray(c.hinge.axis), (c.hinge.min, c.hinge.max))
        sw = c.swing
        if isinstance(sw, ConeSwing):
            def nearest(d):
                return _nearest_cone(g, d, g.const(sw.centre[None, :]), g.const(sw.radius))
        elif isinstance(sw, PolygonSwing):
            nearest = _constant_polygon(g, sw)
        else:
            nearest = None
        lims = None if c.twist is None else (c.twist.min, c.twist.max)
        return _swing_joint(g, q, np.asarray(c.limb_axis), nearest, lims), None
    kf = coupling.keyframes
    if coupling.limits.kind == "hinge":
        vals = np.array([[k.hinge.min, k.hinge.max] for k in kf])
        return _hinge(g, q, np.asarray(kf[0].hinge.axis), _keyframe_lerp(g, kt, vals))
    first = kf[0]
    if isinstance(first.swing, ConeSwing):
        centre = _normalize(g, _keyframe_lerp(g, kt, np.array([k.swing.centre for k in kf])))
        radius = _keyframe_lerp(g, kt, np.array([[k.swing.radius] for k in kf]))

        def nearest(d):
            return _nearest_cone(g, d, centre, radius)
    elif isinstance(first.swing, PolygonSwing):
        nearest = (_coupled_polygon(g, coupling.limits.polygons, kt) if field is None else
                   _field_nearest(g, tau, field))
    else:
        nearest = None
    lims = None
    if first.twist is not None:
        vals = np.array([[k.twist.min, k.twist.max] for k in kf])
        lims = _keyframe_lerp(g, kt, vals)
    return _swing_joint(g, q, np.asarray(first.limb_axis), nearest, lims), None


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
    g = _Graph()
    jn = len(limb.joints)
    corr: dict[int, str] = {}
    angle: dict[int, str] = {}
    for j in limb.order:
        joint = limb.joints[j]
        q = g.op("Squeeze", [g.op("Gather", [INPUT, _i(g, [j])], axis=1), _i(g, [1])],
                 stem=f"q_{joint.name}")
        q = _normalize(g, q)
        kt = tau = None
        field = fields.get(joint.name)
        if joint.coupling is not None:
            src = limb.index(joint.coupling.by)
            kt = _locate(g, angle[src], np.radians(np.asarray(joint.coupling.at_deg)))
            if field is not None:  # τ = 2 (θ − at0) / (at1 − at0) − 1, clamped
                span = field.at1 - field.at0
                tau = g.op("Clip", [g.op("Add", [g.op("Mul", [angle[src], g.const(2.0 / span)]),
                                                 g.const(-1.0 - 2.0 * field.at0 / span)]),
                                    g.const(-1.0), g.const(1.0)])
        c, a = _joint_graph(g, q, joint.constraint, joint.coupling, kt, field, tau)
        corr[j] = c
        if a is not None:
            angle[j] = a
    stacked = g.op("Concat", [g.op("Unsqueeze", [corr[j], _i(g, [1])]) for j in range(jn)],
                   axis=1)
    g.op("Identity", [stacked], out=OUTPUT)
    used = {name for node in g.nodes for name in node.input}
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


class LimbModel:
    """An exported limb model run by onnxruntime (one thread, no spinning).

    Parameters
    ----------
    path : str or Path
    expected_limb : Limb, optional
        The model's embedded limb must have the same limits (content hash).

    Raises
    ------
    ModelFileError
        Missing or unreadable file, not ONNX, not a limb model, wrong inputs/outputs, or
        another limb's limits.
    """

    def __init__(self, path: str | Path, expected_limb: Limb | None = None):
        self.path = Path(path)
        raw, model = read_onnx(self.path)
        self.metadata = {p.key: p.value for p in model.metadata_props}
        if self.metadata.get("jointlimits.format") != FORMAT:
            got = self.metadata.get("jointlimits.format")
            raise ModelFileError(f"{path}: not a limb model (metadata jointlimits.format is "
                                 f"{got!r}, expected {FORMAT!r})")
        self.limb = loads_limb(self.metadata.get("jointlimits.limb", ""), source=f"{path} "
                                                                                  f"(embedded)")
        self.joints = tuple(json.loads(self.metadata.get("jointlimits.joints", "[]")))
        ins = [v for v in model.graph.input
               if v.name not in {i.name for i in model.graph.initializer}]
        if len(ins) != 1 or ins[0].name != INPUT or [o.name for o in model.graph.output] != [
                OUTPUT]:
            raise ModelFileError(f"{path}: expected input '{INPUT}' and output '{OUTPUT}'")
        if expected_limb is not None and expected_limb.content_hash() != self.limb.content_hash():
            raise ModelFileError(f"{path}: the model was made for other limits (limb "
                                 f"{self.limb.name!r}); export one for this limb file")
        self.session = latency_session(raw)
        self._run = self.session._sess.run
        self.n_joints = len(self.joints)
        self._one = np.zeros((1, self.n_joints, 4), dtype=np.float32)
        self._feed = {INPUT: self._one}

    @property
    def size_bytes(self) -> int:
        return self.path.stat().st_size

    def correction(self, postures: np.ndarray) -> np.ndarray:
        """Corrections (N, J, 4) float32 of postures (N, J, 4) (or (J, 4) → (J, 4))."""
        q = np.ascontiguousarray(postures, dtype=np.float32)
        single = q.ndim == 2
        out = self._run([OUTPUT], {INPUT: q.reshape(-1, self.n_joints, 4)}, None)[0]
        return out[0] if single else out

    def correct_one(self, posture) -> np.ndarray:
        """One posture (J, 4) through a preallocated input buffer: (J, 4) float32."""
        self._one[0] = posture
        return self._run([OUTPUT], self._feed, None)[0][0]


def load_limb_model(path: str | Path, expected_limb: Limb | None = None) -> LimbModel:
    """Open an exported limb model (:class:`LimbModel`)."""
    return LimbModel(path, expected_limb)

