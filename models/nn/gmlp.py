"""Generalised multi-layer perceptron (GMLP), stacked so that a whole population runs at once.

Structure (thesis ch. 2 and 4, "GMLP"): ``I`` inputs, up to ``H`` hidden nodes, ``O`` outputs;
every lower node may feed every higher node except within a layer — input→hidden,
input→output and hidden→output — and one bias node feeds every hidden and output node. A
boolean mask per connection switches links on and off (the evolved topology); a hidden node with
no enabled links is absent. Each hidden and output node has its own activation
(:mod:`models.nn.activations`).

With ``x̃ = [x, 1]`` (input plus bias, shape ``I + 1``) the forward pass of one network is::

    z_h = x̃ W1                       W1 : (I + 1, H)      masked by M1
    h   = f_h(z_h)                                         per-node activation
    z_o = [h, x̃] W2                  W2 : (H + I + 1, O)  masked by M2
    y   = f_o(z_o)

and for P networks the same with a leading population axis (``W1 : (P, I + 1, H)``) — one
``np.matmul`` per layer for the whole population. The gradient of ``SSE = Σ (y - t)²`` (RPROP
only uses its sign, so the factor 2 and the mean are dropped) is the usual back-propagation::

    δ_o = (y - t) f_o'(z_o)           ∂SSE/∂W2 = [h, x̃]ᵀ δ_o
    δ_h = (δ_o W2[:H]ᵀ) f_h'(z_h)      ∂SSE/∂W1 = x̃ᵀ δ_h

The deployed network (:class:`GMLP`) also owns its *input map* and normalises its output to a
unit quaternion; the ONNX export reproduces both. Input maps:

- ``"canonical"``: hemisphere canonicalisation ``q ← sign(q·r) q`` for a reference quaternion
  ``r`` (``sign(0) = +1``), so that ``q`` and ``-q`` give the same correction;
- ``"swing"``: the twist-free *swing* of ``q`` — the minimal rotation taking the limb axis X to
  the limb direction ``d = R(q) X`` (thesis eq. 60-62's ``Qi``). For ``q = (w, x, y, z)``::

      swing(q) ∝ (w² + x², 0, wy - xz, wz + xy)      (= (1 + d·X, X × d) / 2, normalised)

  homogeneous of degree 2, so sign- and scale-invariant. For a swing-only constraint the
  parent-frame correction depends on ``d`` alone, so a network trained on the thesis's
  twist-free patterns serves live orientations with any twist.

Centre frame (``frame = R_c``, thesis ch. 9's "reduced-coordinate encodings"). The swing map is
singular at ``d = -X`` and smooth everywhere else, while a corrective constraint is
discontinuous at the antipode of its boundary centre (the correctional discontinuity). With
``R_c`` the minimal rotation taking the limb axis to the boundary centre ``c`` the network works
in the centre frame::

    q' = R_c⁻¹ ⊗ q                      limb direction R_c⁻¹ d: the centre c maps to +X
    x  = swing(q')  (or sign(q·r) q')   input map as above, on q'
    c' = network(x)                      correction in the centre frame
    ĉ  = R_c ⊗ c' ⊗ R_c⁻¹                back to the parent frame, then normalised

so the input singularity (``d' = -X``, i.e. ``d = -c``) sits exactly on the discontinuity and
costs nothing, whatever the centre. Training targets are ``t' = R_c⁻¹ ⊗ t ⊗ R_c``, since
``R_c ⊗ (t' ⊗ q') = t ⊗ q``. Both fixed products are linear maps, ``q' = L(R_c⁻¹) q`` and
``ĉ = L(R_c) R(R_c⁻¹) c'`` (:func:`left_matrix`, :func:`right_matrix`; orthogonal, and the
conjugation keeps the scalar part ``w``), so the ONNX export folds them into the swing's
quadratic form, the first-layer weights and the output weights. ``frame = None`` is the
parent frame (the thesis's encoding).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from models.nn import activations as act


def activate(
    z: np.ndarray, kinds: np.ndarray, coef: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray]:
    """Apply per-node activations to stacked pre-activations.

    Parameters
    ----------
    z : (P, N, H) float
        Pre-activations.
    kinds : (P, H) int
        Activation index of every node of every network.
    coef : (P, T, K - 1, 4) float or None
        Spline template coefficients; needed only if a spline index occurs.

    Returns
    -------
    value, derivative : (P, N, H)
    """
    present = np.unique(kinds)
    if len(present) == 1 and present[0] < act.SPLINE0:
        return act.apply(int(present[0]), z)
    y = np.zeros_like(z)
    dy = np.zeros_like(z)
    plain = present[present < act.SPLINE0]
    for k in plain:
        m = (kinds == k)[:, None, :]
        yk, dk = act.apply(int(k), z)
        np.copyto(y, yk, where=m)
        np.copyto(dy, dk, where=m)
    if len(plain) < len(present):
        if coef is None:
            raise ValueError("spline activation without spline templates")
        m = (kinds >= act.SPLINE0)[:, None, :]
        yk, dk = act.spline_apply(z, coef.astype(z.dtype, copy=False), kinds - act.SPLINE0)
        np.copyto(y, yk, where=m)
        np.copyto(dy, dk, where=m)
    return y, dy


@dataclass
class PopulationSpec:
    """Topology of P networks padded to a common size.

    Attributes
    ----------
    mask1 : (P, I + 1, H) bool
        Enabled input→hidden links; the last row is the hidden biases.
    mask2 : (P, H + I + 1, O) bool
        Enabled hidden→output and input→output links; the last row is the output biases.
    act_hidden : (P, H) int
    act_out : (P, O) int
    spline : (P, T, K) float or None
        Control values of each network's spline templates.
    """

    mask1: np.ndarray
    mask2: np.ndarray
    act_hidden: np.ndarray
    act_out: np.ndarray
    spline: np.ndarray | None = None

    @property
    def shape(self) -> tuple[int, int, int, int]:
        """``(P, I, H, O)``."""
        p, i1, h = self.mask1.shape
        return p, i1 - 1, h, self.mask2.shape[2]

    @property
    def n_weights(self) -> int:
        _, i, h, o = self.shape
        return (i + 1) * h + (h + i + 1) * o

    def flat_mask(self) -> np.ndarray:
        """(P, n_weights) bool, the layout of the flat parameter vector."""
        p = self.shape[0]
        return np.concatenate((self.mask1.reshape(p, -1), self.mask2.reshape(p, -1)), axis=1)

    def coefficients(self) -> np.ndarray | None:
        return None if self.spline is None else act.spline_coefficients(self.spline)

    def subset(self, idx: np.ndarray) -> PopulationSpec:
        return PopulationSpec(
            self.mask1[idx], self.mask2[idx], self.act_hidden[idx], self.act_out[idx],
            None if self.spline is None else self.spline[idx],
        )


def split_params(theta: np.ndarray, i: int, h: int, o: int) -> tuple[np.ndarray, np.ndarray]:
    """Views ``W1 (P, I + 1, H)`` and ``W2 (P, H + I + 1, O)`` of flat parameters ``(P, n)``."""
    p = theta.shape[0]
    n1 = (i + 1) * h
    return theta[:, :n1].reshape(p, i + 1, h), theta[:, n1:].reshape(p, h + i + 1, o)


def init_params(spec: PopulationSpec, rng: np.random.Generator, dtype=np.float64) -> np.ndarray:
    """Random masked weights, uniform in ±1/√fan-in (fan-in counted over enabled links)."""
    p, i, h, o = spec.shape
    theta = rng.uniform(-1.0, 1.0, (p, spec.n_weights))
    w1, w2 = split_params(theta, i, h, o)
    fan1 = np.maximum(spec.mask1.sum(axis=1, keepdims=True), 1)
    fan2 = np.maximum(spec.mask2.sum(axis=1, keepdims=True), 1)
    w1 *= spec.mask1 / np.sqrt(fan1)
    w2 *= spec.mask2 / np.sqrt(fan2)
    return theta.astype(dtype)


def with_bias(x: np.ndarray) -> np.ndarray:
    """``[x, 1]``: (N, I) → (N, I + 1)."""
    return np.concatenate((x, np.ones((len(x), 1), dtype=x.dtype)), axis=1)


def forward(
    theta: np.ndarray, spec: PopulationSpec, xb: np.ndarray, coef: np.ndarray | None = None,
    *, need_grad: bool = True,
):
    """Stacked forward pass.

    Parameters
    ----------
    theta : (P, n_weights) float
        Flat parameters (masked entries are zero).
    spec : PopulationSpec
    xb : (N, I + 1) float
        Inputs with the bias column (:func:`with_bias`).
    coef : (P, T, K - 1, 4) or None
        Spline coefficients (computed from ``spec`` when None).

    Returns
    -------
    y : (P, N, O)
        Network outputs.
    cache : tuple
        What :func:`backward` needs (None if ``need_grad`` is False).
    """
    _, i, h, o = spec.shape
    if coef is None:
        coef = spec.coefficients()
    w1, w2 = split_params(theta, i, h, o)
    zh = np.matmul(xb, w1)  # (P, N, H)
    hh, dh = activate(zh, spec.act_hidden, coef)
    zo = np.matmul(hh, w2[:, :h])
    zo += np.matmul(xb, w2[:, h:])  # input→output shortcuts and output biases
    if not spec.act_out.any():  # all outputs linear (the usual case): no derivative needed
        y, dy = zo, None
    else:
        y, dy = activate(zo, spec.act_out, coef)
    return y, ((hh, dh, dy, w2) if need_grad else None)


def backward(err: np.ndarray, cache, spec: PopulationSpec, xb: np.ndarray) -> np.ndarray:
    """Gradient of ``Σ err²/2`` w.r.t. the flat parameters; ``err = y - t`` (P, N, O).

    Returns (P, n_weights); entries of disabled links are not zeroed (the trainer masks).
    """
    hh, dh, dy, w2 = cache
    p, _, h, _ = spec.shape
    do = err if dy is None else err * dy
    g2h = np.matmul(hh.transpose(0, 2, 1), do)  # (P, H, O)
    g2x = np.matmul(xb.T, do)  # (P, I + 1, O)
    dhid = np.matmul(do, w2[:, :h, :].transpose(0, 2, 1))  # (P, N, H)
    dhid *= dh
    g1 = np.matmul(xb.T, dhid)  # (P, I + 1, H)
    return np.concatenate((g1.reshape(p, -1), g2h.reshape(p, -1), g2x.reshape(p, -1)), axis=1)


def left_matrix(p: np.ndarray) -> np.ndarray:
    """4×4 matrix ``L(p)`` with ``p ⊗ q = L(p) q`` (Hamilton, scalar-first)."""
    w, x, y, z = np.asarray(p, dtype=np.float64)
    return np.array([[w, -x, -y, -z], [x, w, -z, y], [y, z, w, -x], [z, -y, x, w]])


def right_matrix(p: np.ndarray) -> np.ndarray:
    """4×4 matrix ``R(p)`` with ``q ⊗ p = R(p) q`` (Hamilton, scalar-first)."""
    w, x, y, z = np.asarray(p, dtype=np.float64)
    return np.array([[w, -x, -y, -z], [x, w, z, -y], [y, -z, w, x], [z, y, -x, w]])


def conjugate_of(p: np.ndarray) -> np.ndarray:
    """``p⁻¹`` of a unit quaternion ``p`` (4,)."""
    return np.asarray(p, dtype=np.float64) * np.array([1.0, -1.0, -1.0, -1.0])


def frame_matrices(frame: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Input and output maps of the centre frame ``R_c`` (module docstring).

    Parameters
    ----------
    frame : (4,) float, unit

    Returns
    -------
    into : (4, 4)
        ``L(R_c⁻¹)``: ``q' = into @ q``.
    back : (4, 4)
        ``L(R_c) R(R_c⁻¹)``: ``ĉ = back @ c'``.
    """
    inv = conjugate_of(frame)
    return left_matrix(inv), left_matrix(frame) @ right_matrix(inv)


def swing_of(q: np.ndarray) -> np.ndarray:
    """Twist-free swing ``(w² + x², 0, wy - xz, wz + xy)`` normalised, (N, 4) → (N, 4).

    The minimal rotation taking +X to the limb direction of ``q`` (``w ≥ 0``); for the limb
    pointing exactly along -X (``w² + x² = 0`` and the rest zero) it returns zeros.
    """
    q = np.asarray(q, dtype=np.float64)
    w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    s = np.stack((w * w + x * x, np.zeros_like(w), w * y - x * z, w * z + x * y), axis=1)
    return s / np.maximum(np.linalg.norm(s, axis=1, keepdims=True), 1e-12)


@dataclass
class GMLP:
    """One trained network, ready to correct orientations.

    Attributes
    ----------
    w1 : (I + 1, H) float64
        Input(+bias)→hidden weights, disabled links zero; only enabled hidden nodes are kept.
    w2 : (H + I + 1, O) float64
        Hidden, input(+bias)→output weights.
    act_hidden : (H,) int
    act_out : (O,) int
    spline : (T, K) float64 or None
        Spline template control values.
    canonical_ref : (4,) float64 or None
        Reference quaternion ``r`` of the input hemisphere canonicalisation ``q ← sign(q·r) q``
        (``sign(0) = +1``); None disables it. Ignored when ``input_map == "swing"``.
    input_map : {"canonical", "swing"}
        How raw orientations become network inputs (module docstring).
    frame : (4,) float64 or None
        Centre-frame rotation ``R_c`` (module docstring); None for the parent frame.
    info : dict
        Provenance (preset, genome summary, epochs, …), JSON-serialisable.
    """

    w1: np.ndarray
    w2: np.ndarray
    act_hidden: np.ndarray
    act_out: np.ndarray
    spline: np.ndarray | None = None
    canonical_ref: np.ndarray | None = None
    info: dict = field(default_factory=dict)
    input_map: str = "canonical"
    frame: np.ndarray | None = None

    @property
    def n_inputs(self) -> int:
        return self.w1.shape[0] - 1

    @property
    def n_hidden(self) -> int:
        return self.w1.shape[1]

    @property
    def n_links(self) -> int:
        """Enabled connections, biases included (non-zero weights)."""
        return int(np.count_nonzero(self.w1) + np.count_nonzero(self.w2))

    @classmethod
    def from_population(cls, theta: np.ndarray, spec: PopulationSpec, k: int, **kw) -> GMLP:
        """Extract network ``k``, dropping hidden nodes that have no enabled link."""
        _, i, h, o = spec.shape
        w1, w2 = split_params(np.asarray(theta, dtype=np.float64), i, h, o)
        w1 = w1[k] * spec.mask1[k]
        w2 = w2[k] * spec.mask2[k]
        used = spec.mask1[k][:i].any(axis=0) & spec.mask2[k][:h].any(axis=1)
        keep = np.flatnonzero(used)
        w2_new = np.concatenate((w2[keep], w2[h:]), axis=0)
        spline = None if spec.spline is None else np.asarray(spec.spline[k], dtype=np.float64)
        return cls(
            w1=w1[:, keep].copy(), w2=w2_new, act_hidden=spec.act_hidden[k][keep].copy(),
            act_out=spec.act_out[k].copy(), spline=spline, **kw,
        )

    def canonicalise(self, q: np.ndarray) -> np.ndarray:
        """The input map applied to raw quaternions (N, 4) → (N, 4).

        ``canonical_ref`` is a parent-frame reference: ``sign(q·r) = sign(q'·r')`` with
        ``r' = R_c⁻¹ ⊗ r`` because ``L(R_c⁻¹)`` is orthogonal.
        """
        q = np.asarray(q, dtype=np.float64)
        if self.input_map != "swing" and self.canonical_ref is not None:
            q = q * np.where(q @ self.canonical_ref >= 0.0, 1.0, -1.0)[:, None]
        if self.frame is not None:
            q = q @ frame_matrices(self.frame)[0].T
        return swing_of(q) if self.input_map == "swing" else q

    def forward(self, x: np.ndarray) -> np.ndarray:
        """Raw network output (N, O) for already canonicalised inputs (N, I), float64."""
        x = np.asarray(x, dtype=np.float64)
        coef = None if self.spline is None else act.spline_coefficients(self.spline)[None]
        spec = PopulationSpec(
            np.ones((1, *self.w1.shape), bool), np.ones((1, *self.w2.shape), bool),
            self.act_hidden[None], self.act_out[None], None,
        )
        theta = np.concatenate((self.w1.reshape(1, -1), self.w2.reshape(1, -1)), axis=1)
        y, _ = forward(theta, spec, with_bias(x), coef, need_grad=False)
        return y[0]

    def predict(self, orientation: np.ndarray) -> np.ndarray:
        """Unit corrective quaternions for raw orientations.

        Parameters
        ----------
        orientation : (N, 4) or (4,) float, scalar-first, either sign

        Returns
        -------
        (N, 4) or (4,) float64, unit; ``corrected = multiply(correction, orientation)``.
        """
        q = np.asarray(orientation, dtype=np.float64)
        single = q.ndim == 1
        q = q.reshape(-1, 4)
        y = self.forward(self.canonicalise(q))
        if self.frame is not None:
            y = y @ frame_matrices(self.frame)[1].T
        y = y / np.maximum(np.linalg.norm(y, axis=1, keepdims=True), 1e-12)
        return y[0] if single else y
