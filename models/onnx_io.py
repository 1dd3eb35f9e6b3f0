"""ONNX export of trained GMLPs and the low-latency runtime the live loop uses.

The exported graph (opset 17, float32) is the whole correction, so callers feed raw sensor
quaternions::

    orientation [N, 4]  (w, x, y, z), either sign
      │  x = swing(orientation)  or  x = sign(orientation·r) orientation   input map (gmlp.py)
      │  for each activation kind k:  h_k = f_k(x W1[:, k] + b1[k])     hidden nodes grouped by kind
      │  y = Σ_k h_k W2[k] + x W_io + b_o;  y ← f_o(y)                  input→output shortcut links
      ▼  correction = y / max(|y|, 1e-12)                               unit quaternion
    correction [N, 4]   corrected = correction ⊗ orientation

A centre-frame network (``GMLP.frame = R_c``, :mod:`models.nn.gmlp`) costs no extra node: with
``F = L(R_c⁻¹)`` and ``G = L(R_c) R(R_c⁻¹)`` (both orthogonal, constant),

- swing map: ``swing(F q)`` is again a quadratic form of ``q``; its (16, 4) matrix becomes
  ``B'[(a,b), k] = Σ_ij F[i,a] F[j,b] B[(i,j), k]``;
- canonical map: ``sign(q·r)`` is frame-invariant and ``(F x)ᵀ W = xᵀ (Fᵀ W)``, so the input rows
  of ``W1`` and ``W_io`` are replaced by ``Fᵀ W``;
- output: ``G y`` — folded into every output weight (``W2 ← W2 Gᵀ``) when the outputs are linear,
  else one ``MatMul`` after the output activations; ``|G y| = |y|``, so the normalisation stays.

Spline activations are evaluated in-graph: ``u = clip((z - z₀)/h, 0, S - ε)``, segment
``Gather`` of the Catmull-Rom coefficient tables (:mod:`models.nn.activations`), Horner form.

Metadata (``metadata_props``): ``jointlimits.format``, ``jointlimits.constraint`` (the constraint
YAML), ``jointlimits.constraint_sha256``, ``jointlimits.training_data_sha256``,
``jointlimits.metrics`` (JSON), ``jointlimits.network`` (JSON summary), ``jointlimits.version``.

:class:`CorrectionModel` runs a one-joint model and a limb model (:mod:`models.limb_model`)
alike, what differs between their files in one :class:`Contract`. It refuses a file that is
not ONNX, has other input/output names or shapes, or whose constraint differs from the one the
caller expects (:class:`models.errors.ModelFileError`). No pickle anywhere.
"""

from __future__ import annotations

import hashlib
import json
import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from importlib.metadata import version
from pathlib import Path
from typing import Any

import numpy as np
import onnx
import yaml
from onnx import TensorProto, helper, numpy_helper

from models.constraint import loads_constraint
from models.errors import ModelFileError
from models.field import encode_bias, encode_matrix, index_weights
from models.fileio import write_owner_only
from models.limb import Limb, loads_limb
from models.metrics import current_metric_names
from models.nn import activations as act
from models.nn.gmlp import GMLP, frame_matrices
from models.quaternion import multiply
from models.yamlio import safe_load_yaml

FORMAT = "jointlimits-correction/1"
INPUT = "orientation"
OUTPUT = "correction"
OPSET = 17


def package_version() -> str:
    """Installed version of the ``jointlimits-rig`` distribution."""
    try:
        return version("jointlimits-rig")
    except Exception:  # not installed (source checkout)
        return "0.0.0+unknown"


def data_sha256(*arrays: np.ndarray) -> str:
    """SHA-256 of arrays as contiguous float64 (the training-data fingerprint)."""
    h = hashlib.sha256()
    for a in arrays:
        h.update(np.ascontiguousarray(a, dtype=np.float64).tobytes())
    return h.hexdigest()


class Graph:
    """An ONNX graph under construction: nodes and initialisers (constants) in the order they
    are added, each value named ``stem_k`` by a running counter (:meth:`name`). The one-joint
    graphs here and the limb graph (:mod:`models.limb_model`) are built with it."""

    def __init__(self):
        self.nodes: list = []
        self.inits: list = []
        self._n = [0]  # shared with the graph's branches (:meth:`branch`)

    def name(self, stem: str) -> str:
        """A fresh value name ``stem_k``."""
        self._n[0] += 1
        return f"{stem}_{self._n[0]}"

    def branch(self) -> Graph:
        """An empty graph for a branch of an ``If`` node of this one: its own nodes and
        initialisers, names from this graph's counter (unique in the model); its nodes may
        read this graph's values."""
        b = Graph()
        b._n = self._n
        return b

    def const(self, value, stem="c", dtype=np.float32) -> str:
        """An initialiser holding ``value`` as ``dtype``; returns its name."""
        n = self.name(stem)
        self.inits.append(numpy_helper.from_array(np.asarray(value, dtype=dtype), n))
        return n

    def op(self, op_type: str, inputs: list[str], stem: str | None = None, out=None, **attrs):
        """A node of one output (named ``out``, else fresh from ``stem``); returns its name."""
        out = out or self.name(stem or op_type.lower())
        self.nodes.append(helper.make_node(op_type, inputs, [out], **attrs))
        return out

    def ops(self, op_type: str, inputs: list[str], n: int, **attrs) -> list[str]:
        """A node of ``n`` outputs (``Split``)."""
        outs = [self.name(op_type.lower()) for _ in range(n)]
        self.nodes.append(helper.make_node(op_type, inputs, outs, **attrs))
        return outs


def _activation(g: Graph, kind: int, z: str, templates: np.ndarray | None = None,
                coef: np.ndarray | None = None) -> str:
    if kind == 0:
        return z
    if kind == 1:
        return g.op("Sigmoid", [z])
    if kind == 2:
        return g.op("Tanh", [z])
    if kind == 3:
        return g.op("Exp", [g.op("Neg", [g.op("Mul", [z, z])])])
    if kind == 4:
        return g.op("Sin", [z])
    if kind == 5:
        return g.op("Relu", [z])
    if kind == 6:
        return g.op("LeakyRelu", [z], alpha=act.LEAKY_SLOPE)
    if kind == 7:
        return g.op("Clip", [z, g.const(-1.0), g.const(1.0)])
    # spline: templates (n,) per node, coef (T, S, 4)
    t_, s_, _ = coef.shape
    lo, hi = act.SENSITIVITY
    h = (hi - lo) / s_
    u = g.op("Add", [g.op("Mul", [z, g.const(1.0 / h)]), g.const(-lo / h)])
    u = g.op("Clip", [u, g.const(0.0), g.const(s_ - act.SEG_EPS)])
    seg = g.op("Floor", [u])
    t = g.op("Sub", [u, seg])
    idx = g.op("Add", [g.op("Cast", [seg], to=TensorProto.INT64),
                       g.const((templates * s_)[None, :], dtype=np.int64)])
    flat = coef.reshape(t_ * s_, 4)
    a, b, c, d = (g.op("Gather", [g.const(flat[:, j]), idx]) for j in range(4))
    y = g.op("Add", [g.op("Mul", [a, t]), b])
    y = g.op("Add", [g.op("Mul", [y, t]), c])
    return g.op("Add", [g.op("Mul", [y, t]), d])


def product_tensor() -> np.ndarray:
    """(4, 4, 4): ``(e_i ⊗ e_j)_k`` — the Hamilton product as a bilinear form."""
    eye = np.eye(4)
    return np.stack([np.stack([multiply(eye[i], eye[j]) for j in range(4)]) for i in range(4)])


def rotation_tensor(axis: np.ndarray) -> np.ndarray:
    """(4, 4, 3): ``R(q) a`` as a quadratic form of (not necessarily unit) ``q``."""
    def f(q):
        w, u = q[0], q[1:]
        return (w * w - u @ u) * axis + 2.0 * (u @ axis) * u + 2.0 * w * np.cross(u, axis)

    eye = np.eye(4)
    t = np.zeros((4, 4, 3))
    for i in range(4):
        t[i, i] = f(eye[i])
        for j in range(i + 1, 4):
            t[i, j] = t[j, i] = 0.5 * (f(eye[i] + eye[j]) - f(eye[i]) - f(eye[j]))
    return t


def bilinear(g: Graph, p: str, q: str, t: np.ndarray, stem: str = "bilinear") -> str:
    """``out_k = Σ_ij p_i q_j t[i, j, k]`` over the last axis: 4 nodes, zero pairs pruned.

    ``t`` (I, J, O) for inputs (..., I), (..., J); or (K, I, J, O), one form per row of a
    leading axis of K (inputs (K, N, I), (K, N, J): a group of joints, one tensor each)."""
    ts = t[None] if t.ndim == 3 else t
    if p == q:  # a quadratic form: fold t[j, i] into t[i, j] (i < j)
        sym = 0.5 * (ts + np.swapaxes(ts, 1, 2))
        ts = np.moveaxis(np.triu(np.moveaxis(sym, (1, 2), (-2, -1)), 0), (-2, -1), (1, 2))
        ts = ts + np.moveaxis(np.triu(np.moveaxis(ts, (1, 2), (-2, -1)), 1), (-2, -1), (1, 2))
    _, ni, nj, _ = ts.shape
    pairs = [(i, j) for i in range(ni) for j in range(nj) if np.any(ts[:, i, j] != 0.0)]
    a = np.zeros((ni, len(pairs)))
    b = np.zeros((nj, len(pairs)))
    s = np.stack([ts[:, i, j] for i, j in pairs], axis=1)  # (K, P, O)
    for n, (i, j) in enumerate(pairs):
        a[i, n] = b[j, n] = 1.0
    prod = g.op("Mul", [g.op("MatMul", [p, g.const(a)]), g.op("MatMul", [q, g.const(b)])])
    return g.op("MatMul", [prod, g.const(s[0] if t.ndim == 3 else s)], stem=stem)


def twist_clamp(g: Graph, u: str, cr: str, sr: str) -> str:
    """The twist clamp on half-angle pairs: ``u`` (N, 2) unit, taken relative to the middle of
    the interval; ``cr``, ``sr`` the cosine and sine of its half-width / 2 (scalars or (N, 1)).
    Returns ``e`` (N, 2), the half-angle pair of the clamping rotation: ``(1, 0)`` inside,
    else ``target · ū`` with target ``(cr, ±sr)`` on the side of ``sign(u_w u_x)`` (a twist
    exactly opposite the interval goes to ``max``, the oracle's tie rule)."""
    ab = g.op("Abs", [u])
    valid = g.op("LessOrEqual", [g.op("MatMul", [ab, g.const([[0.0], [1.0]])]), sr])
    swapped = g.op("MatMul", [ab, g.const([[0.0, 1.0], [1.0, 0.0]])])
    mr = g.op("Add", [g.op("Mul", [ab, g.op("Mul", [cr, g.const([[1.0, -1.0]])])]),
                      g.op("Mul", [swapped, sr])])
    side = g.op("GreaterOrEqual", [g.op("ReduceProd", [u], axes=[-1], keepdims=1),
                                   g.const(0.0)])
    ms = g.op("Where", [side, mr, g.op("Mul", [mr, g.const([[1.0, -1.0]])])])
    return g.op("Where", [valid, g.const([[1.0, 0.0]]), ms], stem="twist_clamp")


_ROT90 = np.array([[0.0, -1.0], [1.0, 0.0]])  # (w, x) @ _ROT90 = (x, -w)


def interval_clamp(g: Graph, t: str, lims, target: bool = False) -> tuple[str, str | None]:
    """Clamp half-angle pairs ``t`` (..., 2) (the angle ``φ/2`` of a rotation about an axis) to
    intervals on the circle: relative to each interval's middle, nearer end, a tie to ``max``
    (:func:`twist_clamp`, the oracle's rule).

    ``lims``: radians, either ``(lo, hi)`` constants — floats, or arrays (K,) for inputs
    (K, N, 2), one interval per row of the leading axis — or a tensor (..., 2) per sample.
    Returns ``e`` (..., 2), the half-angle pair of the clamping rotation (``(1, 0)`` inside),
    and with ``target`` the clamped pair itself (``e ⊗ t̂``), else None."""
    tn = g.op("LpNormalization", [t], axis=-1, p=2)
    if isinstance(lims, str):
        mh = g.op("MatMul", [lims, g.const([[0.25, -0.25], [0.25, 0.25]])])  # mid/2, half/2
        cm, cr = g.ops("Split", [g.op("Cos", [mh])], 2, axis=-1)
        sm, sr = g.ops("Split", [g.op("Sin", [mh])], 2, axis=-1)
        u = g.op("Add", [g.op("Mul", [tn, cm]),
                         g.op("Mul", [g.op("MatMul", [tn, g.const(_ROT90)]), sm])])
    else:
        lo, hi = (np.asarray(x, dtype=float) for x in lims)
        mid, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
        cm, sm = np.cos(mid / 2), np.sin(mid / 2)
        turn = np.stack([np.stack([cm, -sm], -1), np.stack([sm, cm], -1)], -2)
        u = g.op("MatMul", [tn, g.const(turn)])  # t e^{-i mid/2}
        if np.ndim(half):  # (K,) → (K, 1, 1): one per row of the leading axis
            half = half[:, None, None]
        cr, sr = g.const(np.cos(half / 2)), g.const(np.sin(half / 2))
    e = twist_clamp(g, u, cr, sr)
    if not target:
        return e, None
    e_w, e_x = g.ops("Split", [e], 2, axis=-1)  # e ⊗ t̂ (complex product)
    return e, g.op("Add", [g.op("Mul", [tn, e_w]),
                           g.op("Mul", [g.op("MatMul", [tn, g.const(_ROT90.T)]), e_x])])


def twist_rotation(g: Graph, d: str, e: str, rank: int = 2) -> str:
    """The rotation of half-angle pair ``e`` (..., 2) about the unit direction ``d`` (..., 3):
    ``(1, d) ⊙ (e_w, e_x, e_x, e_x)`` (..., 4); ``rank`` of the inputs."""
    pads = [0] * (2 * rank)
    pads[rank - 1] = 1  # one leading component on the last axis
    d1 = g.op("Pad", [d, g.const(pads, dtype=np.int64), g.const(1.0)])
    return g.op("Mul", [d1, g.op("MatMul", [e, g.const([[1.0, 0, 0, 0], [0, 1.0, 1.0, 1.0]])])],
                stem="twist_rotation")


def _field_graph(g: Graph, model) -> None:
    """The swing-field + twist-clamp graph of :class:`models.field.FieldModel` (its docstring)."""
    axis = model.axis
    prod = product_tensor()
    d = bilinear(g, INPUT, INPUT, rotation_tensor(axis), "limb_direction")
    delta = None
    if model.table is not None:  # nearest table node in the two octahedral diamonds
        p = g.op("Div", [d, g.op("ReduceL1", [d], axes=[1], keepdims=1)])
        x = g.op("Floor", [g.op("Gemm", [p, g.const(encode_matrix(model.grid)),
                                           g.const(encode_bias(model.grid))])])
        flat = g.op("ReduceSum", [g.op("Mul", [x, g.const(index_weights(model.grid))]),
                                  g.const([1], dtype=np.int64)], keepdims=0)
        idx = g.op("Cast", [flat], to=TensorProto.INT64)
        delta = g.op("Gather", [g.const(model.table), idx], stem="swing_correction")
    tw = model.constraint.twist
    if tw is None:
        if delta is None:  # nothing constrained: identity for every row
            delta = g.op("Add", [g.op("Mul", [INPUT, g.const(0.0)]),
                                 g.const([[1.0, 0.0, 0.0, 0.0]])])
        g.op("Identity", [delta], out=OUTPUT)
        return
    # twist half-angle pair t = (w', a·v') of q' = Δ ⊗ q
    tmap = np.concatenate((prod[..., :1], (prod[..., 1:] @ axis)[..., None]), axis=-1)
    by_swing = getattr(tw, "by_swing", None)
    if by_swing is None:
        t = (g.op("MatMul", [INPUT, g.const(tmap[0])]) if delta is None
             else bilinear(g, delta, INPUT, tmap, "twist"))
        e, _ = interval_clamp(g, t, (tw.min, tw.max))
    else:  # limits interpolated at the corrected direction b = R(q') a (contract 3)
        qp = INPUT if delta is None else bilinear(g, delta, INPUT, prod, "corrected")
        b = bilinear(g, qp, qp, rotation_tensor(axis), "corrected_direction")
        kappa = float(by_swing.kappa)
        z = g.op("MatMul", [b, g.const(kappa * np.asarray(by_swing.directions).T)])
        w = g.op("Exp", [g.op("Sub", [z, g.op("ReduceMax", [z], axes=[1], keepdims=1)])])
        lims = g.op("Div", [g.op("MatMul", [w, g.const(np.radians(np.stack(
            (by_swing.min_deg, by_swing.max_deg), axis=1)))]),
            g.op("ReduceSum", [w, g.const([1], dtype=np.int64)], keepdims=1)])
        e, _ = interval_clamp(g, g.op("MatMul", [qp, g.const(tmap[0])]), lims)
    # τ: the twist clamp about the limb
    tau = twist_rotation(g, d, e)
    if delta is None:
        g.op("Identity", [tau], out=OUTPUT)
        return
    g.op("Identity", [bilinear(g, delta, tau, prod)], out=OUTPUT)  # Δ ⊗ τ


def _finish(g: Graph, meta: dict[str, str]) -> onnx.ModelProto:
    graph = helper.make_graph(
        g.nodes, "jointlimits_correction",
        [helper.make_tensor_value_info(INPUT, TensorProto.FLOAT, ["N", 4])],
        [helper.make_tensor_value_info(OUTPUT, TensorProto.FLOAT, ["N", 4])],
        g.inits,
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", OPSET)],
                              producer_name="jointlimits-rig", producer_version=package_version())
    model.ir_version = 8
    model.doc_string = ("Corrective joint constraint: corrected = correction ⊗ orientation "
                        "(scalar-first w, x, y, z; Hamilton product).")
    onnx.helper.set_model_props(model, meta)
    onnx.checker.check_model(model)
    return model


def _meta(constraint_yaml, training_data_sha256, metrics, network: dict) -> dict[str, str]:
    return {
        "jointlimits.format": FORMAT,
        "jointlimits.constraint": constraint_yaml,
        "jointlimits.constraint_sha256": hashlib.sha256(constraint_yaml.encode()).hexdigest(),
        "jointlimits.training_data_sha256": training_data_sha256,
        "jointlimits.metrics": json.dumps(metrics or {}, sort_keys=True),
        "jointlimits.network": json.dumps(network, sort_keys=True, default=str),
        "jointlimits.version": package_version(),
    }


def to_onnx(
    network,
    *,
    constraint_yaml: str,
    training_data_sha256: str = "",
    metrics: dict[str, Any] | None = None,
    extra: dict[str, Any] | None = None,
) -> onnx.ModelProto:
    """Build the ONNX model of a trained network or field model (module docstring).

    ``network`` is a :class:`~models.nn.gmlp.GMLP` or a :class:`models.field.FieldModel`.
    """
    g = Graph()
    if not isinstance(network, GMLP):  # a FieldModel
        _field_graph(g, network)
        info = {**network.info, **(extra or {})}
        return _finish(g, _meta(constraint_yaml, training_data_sha256, metrics, info))
    i, h = network.n_inputs, network.n_hidden
    w1, w2 = network.w1.copy(), network.w2.copy()
    fold_out = None
    into = None
    if network.frame is not None:
        into, back = frame_matrices(network.frame)
        if (network.act_out == 0).all():
            w2 = w2 @ back.T  # linear outputs: y Gᵀ folded into every output weight
        else:
            fold_out = back.T
    x = INPUT
    if network.input_map == "swing":
        # swing components are quadratic forms of q: (q qᵀ) flattened (N, 16) times B (16, 4)
        b = np.zeros((16, 4))
        b[0, 0] = b[5, 0] = 1.0  # w² + x²
        b[2, 2], b[7, 2] = 1.0, -1.0  # wy - xz
        b[3, 3] = b[6, 3] = 1.0  # wz + xy
        if into is not None:  # swing(F q): B'[(a,b),k] = Σ_ij F[i,a] F[j,b] B[(i,j),k]
            b = np.einsum("ia,jb,ijk->abk", into, into, b.reshape(4, 4, 4)).reshape(16, 4)
        col = g.op("Unsqueeze", [INPUT, g.const([2], dtype=np.int64)])
        row = g.op("Unsqueeze", [INPUT, g.const([1], dtype=np.int64)])
        outer = g.op("Reshape", [g.op("Mul", [col, row]), g.const([-1, 16], dtype=np.int64)])
        s = g.op("MatMul", [outer, g.const(b)])
        sn = g.op("Max", [g.op("ReduceL2", [s], axes=[1], keepdims=1), g.const(1e-12)])
        x = g.op("Div", [s, sn], stem="swing")
    elif network.canonical_ref is not None:
        d = g.op("MatMul", [INPUT, g.const(np.asarray(network.canonical_ref).reshape(4, 1))])
        s = g.op("Where", [g.op("GreaterOrEqual", [d, g.const(0.0)]), g.const(1.0),
                           g.const(-1.0)])
        x = g.op("Mul", [INPUT, s], stem="canonical")
    if into is not None and network.input_map != "swing":  # (F x)ᵀ W = xᵀ (Fᵀ W)
        w1[:i] = into.T @ w1[:i]
        w2[h:h + i] = into.T @ w2[h:h + i]
    coef = None if network.spline is None else act.spline_coefficients(network.spline)
    terms = [g.op("Gemm", [x, g.const(w2[h:h + i]), g.const(w2[h + i])], stem="shortcut")]
    kinds = network.act_hidden
    plain = sorted({int(k) for k in kinds if k < act.SPLINE0})
    groups = [(k, np.flatnonzero(kinds == k)) for k in plain]
    if (kinds >= act.SPLINE0).any():
        groups.append((act.SPLINE0, np.flatnonzero(kinds >= act.SPLINE0)))
    for k, cols in groups:
        z = g.op("Gemm", [x, g.const(w1[:i, cols]), g.const(w1[i, cols])], stem="hidden")
        hk = _activation(g, k, z, kinds[cols] - act.SPLINE0, coef)
        terms.append(g.op("MatMul", [hk, g.const(w2[cols])]))
    y = terms[0] if len(terms) == 1 else g.op("Sum", terms, stem="output")
    outk = network.act_out
    if (outk != 0).any():
        parts = []
        for k in sorted({int(v) for v in outk}):
            sel = (outk == k) if k < act.SPLINE0 else (outk >= act.SPLINE0)
            if k >= act.SPLINE0 and any(p[0] >= act.SPLINE0 for p in parts):
                continue
            fk = _activation(g, k, y, np.where(outk >= act.SPLINE0, outk - act.SPLINE0, 0),
                             coef)
            parts.append((k, g.op("Mul", [fk, g.const(sel.astype(np.float32)[None, :])])))
        y = g.op("Sum", [p[1] for p in parts]) if len(parts) > 1 else parts[0][1]
    if fold_out is not None:
        y = g.op("MatMul", [y, g.const(fold_out)], stem="parent_frame")
    n = g.op("ReduceL2", [y], axes=[1], keepdims=1)
    n = g.op("Max", [n, g.const(1e-12)])
    g.op("Div", [y, n], out=OUTPUT)
    info = {**network.info, "input_map": network.input_map,
            "frame": None if network.frame is None else [float(v) for v in network.frame],
            **(extra or {})}
    return _finish(g, _meta(constraint_yaml, training_data_sha256, metrics, info))


def export_onnx(network: GMLP, path: str | Path, **kw) -> Path:
    """Write :func:`to_onnx` to ``path`` (parents created); returns the path."""
    path = Path(path)
    model = to_onnx(network, **kw)
    path.parent.mkdir(parents=True, exist_ok=True)
    # atomic and owner-only: the metadata embeds the constraint, patient pseudonym included
    return write_owner_only(path, model.SerializeToString())


def _as_constraint_dict(c) -> Any:
    if c is None:
        return None
    if hasattr(c, "to_yaml"):
        return safe_load_yaml(c.to_yaml())
    if isinstance(c, str):
        return safe_load_yaml(c)
    return c


def read_onnx(path: Path) -> tuple[bytes, onnx.ModelProto]:
    """A model file's bytes and its checked ONNX graph (:class:`ModelFileError` in one line
    when it cannot be read or is not ONNX)."""
    try:
        raw = path.read_bytes()
    except OSError as err:
        raise ModelFileError(f"{path}: cannot read model file ({err.strerror})") from None
    try:
        model = onnx.load_model_from_string(raw)
        onnx.checker.check_model(model)
    except Exception as err:  # protobuf raises various types
        raise ModelFileError(f"{path}: not an ONNX model ({type(err).__name__})") from None
    return raw, model


def latency_session(raw: bytes, *, single: bool = False, prepack: bool = True,
                    profile: str | None = None):
    """An onnxruntime session tuned for latency: one thread, sequential, no spinning;
    ``single``: for one sample a call (no memory-reuse planning); ``prepack``: False leaves
    the products' constant matrices as they are (onnxruntime's ``session.disable_prepacking``:
    see :func:`large_products`); ``profile``: onnxruntime's profiler on, its JSON file named
    from this prefix (``end_profiling`` returns the path)."""
    import onnxruntime as ort  # lazily: exporting a model needs no runtime (models/__init__)

    opts = ort.SessionOptions()
    opts.intra_op_num_threads = 1
    opts.inter_op_num_threads = 1
    opts.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
    opts.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
    opts.add_session_config_entry("session.intra_op.allow_spinning", "0")
    # one sample: no memory-reuse planning — a single call of a small graph is per-node
    # overhead, and the planner's buffer sharing is part of it: a limb model's single call
    # 11 % faster (network 132 → 117 µs, geometric 95.5 → 85.3 µs, interleaved, 2026-11-28,
    # this 2-core VM, a Python loop of 10⁷ additions 0.46 s), the same numbers; batches keep
    # it (their buffers are large)
    opts.enable_mem_reuse = not single
    if not prepack:
        opts.add_session_config_entry("session.disable_prepacking", "1")
    if profile is not None:
        opts.enable_profiling = True
        opts.profile_file_prefix = profile
    return ort.InferenceSession(raw, sess_options=opts, providers=["CPUExecutionProvider"])


#: a constant matrix of at least this many numbers makes a model's products "large"
LARGE_PRODUCT = 4096


def large_products(model: onnx.ModelProto) -> bool:
    """Whether a ``MatMul`` or ``Gemm`` of ``model`` (its ``If`` branches included) multiplies
    by a constant of at least :data:`LARGE_PRODUCT` numbers (a limb network's field: 195 × 128,
    128 × 128, …).

    One sample a call, such a model runs faster with its matrices as they are than prepacked
    for onnxruntime's blocked products (``session.disable_prepacking``): a held-out arm's
    network single call 137.3 → 122.9 µs where its field's projection steps run (forearm arm
    9200: 147.4 → 132.5 µs), while a model of small matrices loses 1.5-2 % (``geometric``
    84.2 → 85.8 µs); interleaved, 2026-11-28, this 2-core VM. So :class:`CorrectionModel`'s
    single-call session leaves them unpacked only when they are large."""
    sizes: dict[str, int] = {}
    factors: set[str] = set()

    def walk(graph) -> None:
        sizes.update((t.name, int(np.prod(t.dims))) for t in graph.initializer)
        for node in graph.node:
            if node.op_type in ("MatMul", "Gemm"):
                factors.add(node.input[1])
            for a in node.attribute:
                if a.type == onnx.AttributeProto.GRAPH:
                    walk(a.g)

    walk(model.graph)
    return any(sizes.get(f, 0) >= LARGE_PRODUCT for f in factors)


def one_sample(model: onnx.ModelProto) -> bytes:
    """``model`` with the batch axis of its inputs and outputs fixed to one sample (the graph
    unchanged): the session of :meth:`CorrectionModel.correct_one` knows every shape when it
    is built, so onnxruntime folds the shape arithmetic (``Shape``, ``Expand``) and plans each
    node's output once — 1-5 % off a limb model's single call (network 153.5 → 145.6 µs,
    geometric 91.7 → 90.4 µs, leg network 78.1 → 77.3 µs; interleaved, 2026-11-28, this 2-core
    VM beside a benchmark), the same answers bit for bit."""
    fixed = onnx.ModelProto()
    fixed.CopyFrom(model)
    for v in (*fixed.graph.input, *fixed.graph.output):
        dims = v.type.tensor_type.shape.dim
        if dims:
            dims[0].Clear()
            dims[0].dim_value = 1
    return fixed.SerializeToString()


@dataclass(frozen=True)
class Contract:
    """What a model file's contract fixes, the one place a one-joint model and a limb model
    differ: ``format`` (metadata ``jointlimits.format``), the input and output names, and
    whether a sample is a posture ``[J, 4]`` (a limb's joints) or one orientation ``[4]``.
    A batch over ``chunk`` samples runs in chunks of ``chunk`` on worker threads (None: in one
    call)."""

    format: str
    input: str
    output: str
    per_joint: bool
    chunk: int | None = None


#: A one-joint model: ``orientation [N, 4] → correction [N, 4]`` (module docstring).
JOINT_CONTRACT = Contract(FORMAT, INPUT, OUTPUT, per_joint=False)
#: A limb model: ``orientations [N, J, 4] → corrections [N, J, 4]`` (:mod:`models.limb_model`).
LIMB_CONTRACT = Contract("jointlimits-limb-correction/1", "orientations", "corrections",
                         per_joint=True, chunk=1024)


def _contract_of(path: Path, metadata: dict[str, str], limb: bool | None) -> Contract:
    """The contract a file claims (a ``jointlimits-limb-`` format is a limb's, anything else is
    judged as a one joint's), refused in one line when it is not the one ``limb`` asks for."""
    got = metadata.get("jointlimits.format")
    is_limb = str(got or "").startswith("jointlimits-limb-")
    if limb is False and is_limb:
        raise ModelFileError(f"{path}: a limb model (corrections of a whole limb's joints, "
                             "[N, J, 4]), not one joint's: give a model trained on a "
                             "single joint's constraint file")
    if (limb or is_limb) and got != LIMB_CONTRACT.format:
        raise ModelFileError(f"{path}: not a limb model (metadata jointlimits.format is "
                             f"{got!r}, expected {LIMB_CONTRACT.format!r})")
    return LIMB_CONTRACT if is_limb else JOINT_CONTRACT


class CorrectionModel:
    """An exported correction model run by onnxruntime, tuned for latency: one joint's
    (``[N, 4] → [N, 4]``, :func:`export_onnx`) or a whole limb's (``[N, J, 4] → [N, J, 4]``,
    :func:`models.limb_model.export_limb_model`) — a one-joint model is the limb of one joint
    whose file keeps its ``[N, 4]`` contract (:class:`Contract`).

    One sample (:meth:`correct_one`) runs on the calling thread (one onnxruntime thread, no
    spinning) through a preallocated input buffer, in a session of its own without
    memory-reuse planning (:func:`latency_session`) whose shapes are fixed to one sample
    (:func:`one_sample`), large constant matrices not prepacked (:func:`large_products`); a
    limb's batch of more than :attr:`Contract.chunk` postures in chunks on one worker thread
    per core for the call (the session is shared; onnxruntime releases the GIL while it runs,
    and chunks of this size stay in the cache).

    Parameters
    ----------
    path : str or Path
        ``.onnx`` file written by :func:`export_onnx` or
        :func:`models.limb_model.export_limb_model`.
    expected_constraint : JointConstraint, YAML str, dict, Limb or None
        If given, the model's embedded constraint must equal it (a :class:`models.limb.Limb`:
        a limb model with the same limits, content hash; anything else: a one-joint model).
    limb : bool or None
        True: refuse a one-joint model; False: refuse a limb model; None (the default) takes
        either, unless ``expected_constraint`` tells which.

    Attributes
    ----------
    contract : Contract
    metadata : dict of str
    constraint_yaml : str
        The embedded constraint file (a limb model: its limb file).
    limb : Limb or None
        A limb model's limb (None for a one-joint model).
    joints : tuple of str
        A limb model's joint names, in order (empty for a one-joint model).

    Raises
    ------
    ModelFileError
        Missing file, not ONNX, wrong input/output names or shapes, not one of ours, the other
        contract than asked for, or a different constraint.
    """

    def __init__(self, path: str | Path, expected_constraint=None, *, limb: bool | None = None):
        self.path = Path(path)
        raw, model = read_onnx(self.path)
        self.metadata = {p.key: p.value for p in model.metadata_props}
        if expected_constraint is not None and limb is None:
            limb = isinstance(expected_constraint, Limb)
        self.contract = _contract_of(path, self.metadata, limb)
        self.limb: Limb | None = None
        self.joints: tuple[str, ...] = ()
        if self.contract.per_joint:
            self.constraint_yaml = self.metadata.get("jointlimits.limb", "")
            self.limb = loads_limb(self.constraint_yaml, source=f"{path} (embedded)")
            self.joints = tuple(json.loads(self.metadata.get("jointlimits.joints", "[]")))
            self._check_limb_io(model)
            sample: tuple[int, ...] = (len(self.joints), 4)
        else:
            self._check_io(model)
            if self.metadata.get("jointlimits.format") != FORMAT:
                got = self.metadata.get("jointlimits.format")
                raise ModelFileError(f"{path}: not a jointlimits correction model (metadata "
                                     f"jointlimits.format is {got!r}, expected {FORMAT!r})")
            self.constraint_yaml = self.metadata.get("jointlimits.constraint", "")
            sample = (4,)
        if expected_constraint is not None:
            self.check_constraint(expected_constraint)
        self.session = latency_session(raw)
        self._single = latency_session(one_sample(model), single=True,  # correct_one's
                                       prepack=not large_products(model))
        self._sample = sample
        self._one = np.zeros((1, *sample), dtype=np.float32)
        self._outs = [self.contract.output]
        self._feed = {self.contract.input: self._one}
        # session.run, the public path: its Python-side checks cost ~0.1 µs a call
        self._ro = _run_options()

    def _check_io(self, model: onnx.ModelProto) -> None:
        def describe(vs):
            out = []
            for v in vs:
                dims = [d.dim_param or d.dim_value for d in v.type.tensor_type.shape.dim]
                out.append((v.name, v.type.tensor_type.elem_type, dims))
            return out

        ins = [v for v in model.graph.input
               if v.name not in {i.name for i in model.graph.initializer}]
        got_in, got_out = describe(ins), describe(model.graph.output)
        ok = (len(got_in) == 1 and len(got_out) == 1
              and got_in[0][0] == INPUT and got_out[0][0] == OUTPUT
              and got_in[0][1] == TensorProto.FLOAT and got_out[0][1] == TensorProto.FLOAT
              and len(got_in[0][2]) == 2 and got_in[0][2][1] == 4
              and len(got_out[0][2]) == 2 and got_out[0][2][1] == 4)
        if not ok:
            raise ModelFileError(
                f"{self.path}: expected input '{INPUT}' float32 [N, 4] and output '{OUTPUT}' "
                f"float32 [N, 4], got inputs {[(n, d) for n, _, d in got_in]} and outputs "
                f"{[(n, d) for n, _, d in got_out]}")

    def _check_limb_io(self, model: onnx.ModelProto) -> None:
        c = self.contract
        ins = [v for v in model.graph.input
               if v.name not in {i.name for i in model.graph.initializer}]
        if len(ins) != 1 or ins[0].name != c.input or [o.name for o in model.graph.output] != [
                c.output]:
            raise ModelFileError(f"{self.path}: expected input '{c.input}' and output "
                                 f"'{c.output}'")

    def check_constraint(self, expected) -> None:
        """Raise :class:`ModelFileError` unless the embedded constraint equals ``expected``
        (a :class:`models.limb.Limb`: the same limits, by content hash)."""
        if self.contract.per_joint:
            if expected.content_hash() != self.limb.content_hash():
                raise ModelFileError(f"{self.path}: the model was made for other limits (limb "
                                     f"{self.limb.name!r}); export one for this limb file")
            return
        try:
            mine = safe_load_yaml(self.constraint_yaml)
        except yaml.YAMLError:
            mine = None
        if hasattr(expected, "to_yaml"):  # a JointConstraint: compare limits, ignore the name
            try:
                embedded = loads_constraint(self.constraint_yaml)
                same = embedded == expected
            except Exception:  # unparsable embedded constraint: not the same
                embedded, same = None, False
            for what in ("joint", "side", "patient"):  # the same limits, another joint's
                a, b = getattr(embedded, what, None), getattr(expected, what, None)
                if a is not None and b is not None and a != b:
                    raise ModelFileError(f"{self.path}: model was trained for {what} {a!r}, "
                                         f"the constraint is for {what} {b!r}")
        else:
            same = mine == _as_constraint_dict(expected)
        if not same:
            name = (mine or {}).get("name", "?") if isinstance(mine, dict) else "?"
            raise ModelFileError(
                f"{self.path}: model was trained for a different constraint (embedded "
                f"constraint {name!r} differs from the expected one); retrain with "
                "`rig train` for this constraint file")

    @property
    def metrics(self) -> dict[str, Any]:
        """The held-out metrics stored at export (a one-joint model's; a limb model stores
        none), an old metric name read as today's (:func:`current_metric_names`)."""
        return current_metric_names(json.loads(self.metadata.get("jointlimits.metrics", "{}")))

    @property
    def network_info(self) -> dict[str, Any]:
        """The network's summary stored at export (``jointlimits.network``)."""
        return json.loads(self.metadata.get("jointlimits.network", "{}"))

    @property
    def size_bytes(self) -> int:
        """The model file's size."""
        return self.path.stat().st_size

    def correction(self, orientation: np.ndarray) -> np.ndarray:
        """Batched corrections.

        Parameters
        ----------
        orientation : (N, 4) or (4,) float for a one-joint model, (N, J, 4) or (J, 4) for a
            limb model: raw scalar-first quaternions (either sign), a limb's joints in its
            file's order

        Returns
        -------
        float32 array of the input's shape: unit corrective quaternions.
        """
        q = np.ascontiguousarray(orientation, dtype=np.float32)
        single = q.ndim == len(self._sample)
        q = q.reshape(-1, *self._sample)
        c = self.contract
        workers = min(os.cpu_count() or 1, 8)
        if c.chunk is None or len(q) <= c.chunk or workers == 1:
            out = self.session.run(self._outs, {c.input: q}, self._ro)[0]
            return out[0] if single else out
        out = np.empty(q.shape, dtype=np.float32)

        def chunk(k: int) -> None:
            out[k:k + c.chunk] = self.session.run(self._outs, {c.input: q[k:k + c.chunk]},
                                                  self._ro)[0]
        starts = range(0, len(q), c.chunk)
        with ThreadPoolExecutor(min(workers, len(starts)), thread_name_prefix="limb-model") as pool:
            list(pool.map(chunk, starts))
        return out

    def correct_one(self, orientation) -> np.ndarray:
        """The cheap single-sample path: the correction of one orientation (4,) (a limb model:
        one posture (J, 4)), float32, through one preallocated input buffer; the returned
        array is fresh."""
        self._one[0] = orientation
        return self._single.run(self._outs, self._feed, self._ro)[0][0]

    def corrected(self, orientation: np.ndarray) -> np.ndarray:
        """``correction ⊗ orientation`` float64 of the input's shape, keeping its sign."""
        q = np.asarray(orientation, dtype=np.float64)
        return multiply(self.correction(q).astype(np.float64), q)


def _run_options():
    """The ``RunOptions`` every call passes."""
    import onnxruntime as ort  # lazily, as in latency_session

    return ort.RunOptions()


def load_model(path: str | Path, expected_constraint=None, *,
               limb: bool | None = None) -> CorrectionModel:
    """Open an exported model, one joint's or a limb's (see :class:`CorrectionModel`)."""
    return CorrectionModel(path, expected_constraint, limb=limb)
