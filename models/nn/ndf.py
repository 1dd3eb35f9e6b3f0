"""A neural distance field for a coupled swing boundary (issue 20: the trained limb model).

A coupled ball or two-axis joint's swing region depends on another joint's angle ``θ`` (the
hip's on the knee's). A table over direction × angle at the field's 0.5° would need ~10⁸
nodes; this network learns the signed geodesic distance ``s(d, θ)`` of a limb direction
``d ∈ S²`` to the boundary interpolated at ``θ`` (radians, > 0 outside), from the exact oracle
(:func:`models.geometry.nearest_on_polygons` on :meth:`models.limb.InterpolatedLimits.polygon_at`).

Network (``f: S² × [-1, 1] → ℝ``)::

    z  = (d, τ)                         τ = the coupling angle mapped to [-1, 1] over the
                                          keyframes (clamped, as the limits are)
    γ  = (sin(z B + c), z)              fixed Fourier features (B: F random frequencies)
    h₁ = tanh(γ W₁ + b₁),  h₂ = tanh(h₁ W₂ + b₂),  f = h₂ w₃ + b₃

Fourier features let a small MLP follow a boundary's corners and notches (a plain MLP on
``d`` rounds them: 1.4 % mean error on one shoulder, ``docs/learned-constraints.md``). The
input gradient is analytic (:meth:`DistanceField.value_and_gradient`), so the projection runs
in ONNX as matrix products. Training (Sobolev): minibatch Adam on the squared error of the
value plus ``λ`` times that of the tangent gradient against the exact one, weighted by
``1 + 3|s|`` (a gradient error ``δ`` at distance ``s`` lands ``s·δ`` along the boundary), float32,
one thread per field (a limb's fields side by side; a field alone on two cores takes both,
each on half of every batch), a cosine-decayed rate; directions 70 % uniform on the sphere,
the rest within 40° of the boundary (:func:`models.datasets.training_postures`).

Projection (:meth:`DistanceField.project`): geodesic steps ``d ← cos(αf⁺) d − sin(αf⁺) ĝ``
(``ĝ`` the unit tangent gradient, ``f⁺ = max(f, 0)``) with fractions ``α`` = 0.25, 0.5, 0.5, 1,
1: the short steps re-read the gradient nearer the boundary, where it is learnt best (on
development limbs, seeds below the held-out ones, half steps first halved the far postures'
error against three full steps, and a quarter step first instead of a half lowered the mean
and p99 end-point errors on every development limb tried, at the same cost); a direction the
network judges valid takes no step.
"""

from __future__ import annotations

import itertools
import math
import os
import time
from dataclasses import dataclass, field

import numpy as np

from models.datasets._limb import (
    UNIFORM,
    coupled_directions,
    coupled_targets,
    field_joints,
    field_samples,
    training_postures,
)
from models.limb import InterpolatedLimits, oriented_vertices
from models.oracle import ConstraintOracle

__all__ = ["DistanceField", "FieldSpec", "fit_coupled_field", "fit_limb_fields", "fit_swing_field"]


@dataclass(frozen=True)
class FieldSpec:
    """Size and training of a :class:`DistanceField` (the defaults are the shipped model's)."""

    features: int = 192         #: Fourier features F
    hidden: int = 128           #: width of both tanh layers
    sigma_d: float = 4.0        #: frequency scale on the direction
    sigma_t: float = 1.5        #: frequency scale on the coupling coordinate τ
    samples: int = 120_000      #: training directions × angles
    epochs: int = 120
    batch: int = 1024
    lr: float = 2e-3
    steps: tuple[float, ...] = (0.25, 0.5, 0.5, 1.0, 1.0)  #: projection step fractions
    grad_weight: float = 0.05   #: λ, weight of the gradient term (Sobolev training)
    uniform: float = UNIFORM    #: fraction of training directions uniform on the sphere
    far_weight: float = 3.0     #: gradient term weighted by (1 + far_weight·|s|)


@dataclass
class DistanceField:
    """The network's weights (float32) and its coupling range.

    ``at0``/``at1``: the keyframes' first and last angle (radians); ``τ = 2(θ−at0)/(at1−at0) − 1``
    clamped to [-1, 1].
    """

    b: np.ndarray           # (4, F)
    c: np.ndarray           # (F,)
    w1: np.ndarray          # (F + 4, H)
    b1: np.ndarray          # (H,)
    w2: np.ndarray          # (H, H)
    b2: np.ndarray          # (H,)
    w3: np.ndarray          # (H,)
    b3: np.ndarray          # (1,)
    at0: float
    at1: float
    steps: tuple[float, ...]  #: projection step fractions (:attr:`FieldSpec.steps`)
    info: dict = field(default_factory=dict)

    @classmethod
    def initial(cls, spec: FieldSpec, at0: float, at1: float,
                rng: np.random.Generator) -> DistanceField:
        f, h = spec.features, spec.hidden
        scale = np.array([spec.sigma_d] * 3 + [spec.sigma_t])[:, None]
        f32 = np.float32
        return cls(
            b=(rng.standard_normal((4, f)) * scale).astype(f32),
            c=rng.uniform(0, 2 * np.pi, f).astype(f32),
            w1=(rng.standard_normal((f + 4, h)) / math.sqrt(f + 4)).astype(f32),
            b1=np.zeros(h, f32),
            w2=(rng.standard_normal((h, h)) / math.sqrt(h)).astype(f32),
            b2=np.zeros(h, f32),
            w3=(rng.standard_normal(h) / math.sqrt(h)).astype(f32),
            b3=np.zeros(1, f32),
            at0=float(at0), at1=float(at1), steps=spec.steps)

    # -- evaluation ------------------------------------------------------------------------
    def tau(self, angle) -> np.ndarray:
        """The coupling coordinate τ (N,) of coupling angles (radians)."""
        a = np.asarray(angle, dtype=np.float64)
        return np.clip(2.0 * (a - self.at0) / (self.at1 - self.at0) - 1.0, -1.0, 1.0)

    def _forward(self, z: np.ndarray):
        u = z @ self.b + self.c
        feats = np.concatenate((np.sin(u), z), axis=1)
        h1 = np.tanh(feats @ self.w1 + self.b1)
        h2 = np.tanh(h1 @ self.w2 + self.b2)
        return h2 @ self.w3 + self.b3[0], (u, feats, h1, h2)

    def value(self, d: np.ndarray, tau: np.ndarray) -> np.ndarray:
        """Predicted signed distance (N,) radians."""
        z = np.concatenate((d, np.asarray(tau)[:, None]), axis=1).astype(self.w1.dtype)
        return self._forward(z)[0]

    def _input_gradient(self, u, h1, h2):
        """The input gradient's chain: ``(g2, p1, g1, ∂f/∂d (N, 3))``."""
        g2 = (1 - h2 * h2) * self.w3
        p1 = g2 @ self.w2.T
        g1 = (1 - h1 * h1) * p1
        gf = g1 @ self.w1.T
        nf = self.b.shape[1]
        return g2, p1, g1, (gf[:, :nf] * np.cos(u)) @ self.b[:3].T + gf[:, nf:nf + 3]

    def value_and_gradient(self, d: np.ndarray, tau: np.ndarray):
        """Values (N,) and gradients (N, 3) with respect to the direction."""
        z = np.concatenate((d, np.asarray(tau)[:, None]), axis=1).astype(self.w1.dtype)
        f, (u, _, h1, h2) = self._forward(z)
        return f, self._input_gradient(u, h1, h2)[3]

    def project(self, d: np.ndarray, angle) -> tuple[np.ndarray, np.ndarray]:
        """``(outside (N,) bool, projected direction (N, 3))`` — the graph's computation."""
        tau = self.tau(angle)
        x = np.asarray(d, dtype=np.float64)
        outside = self.value(x, tau) > 0
        for frac in self.steps:
            f, g = self.value_and_gradient(x, tau)
            g = g - (g * x).sum(1, keepdims=True) * x
            g /= np.maximum(np.linalg.norm(g, axis=1, keepdims=True), 1e-12)
            step = frac * np.maximum(f, 0.0)[:, None]
            x = np.cos(step) * x - np.sin(step) * g
            x /= np.linalg.norm(x, axis=1, keepdims=True)
        return outside, x

    # -- training --------------------------------------------------------------------------
    def _params(self) -> list[np.ndarray]:
        return [self.w1, self.b1, self.w2, self.b2, self.w3, self.b3]

    def fit(self, z: np.ndarray, s: np.ndarray, g: np.ndarray, spec: FieldSpec,
            rng: np.random.Generator, *, helpers=None, parts: int = 1) -> DistanceField:
        """Minibatch Adam on ``mean((f − s)²) + λ mean(|P_d ∇f − g|²)`` (Sobolev training).

        ``z`` (N, 4) = (d, τ), ``s`` (N,) radians, ``g`` (N, 3) the exact distance's unit
        tangent gradient at ``d`` (pointing away from the nearest boundary point outside,
        towards it inside). The gradient term is what the projection steps follow: a
        direction error ``δ`` at distance ``s`` lands ``s·δ`` along the boundary.

        Each batch's gradient is the sum, in order, of its ``parts`` equal parts' (each
        normalised by the whole batch's size). ``helpers`` (a
        :class:`concurrent.futures.Executor`, optional) computes parts 1, 2, ... while this
        thread computes part 0; the sum is the same either way, so for a given ``parts`` the
        weights do not depend on it (with BLAS held to one thread, as
        :func:`fit_limb_fields` holds it). Parts pay only on threads of their own: one after
        the other, two parts of 512 took 12.3 ms a step against 9.7 ms for the whole batch of
        1,024, and 6.7 ms on two threads (this workplace's 2-core VM, 2026-11-28).
        """
        z = np.ascontiguousarray(z, dtype=np.float32)
        s = np.ascontiguousarray(s, dtype=np.float32)
        g = np.ascontiguousarray(g, dtype=np.float32)
        lam = np.float32(spec.grad_weight)
        w = (1 + spec.far_weight * np.abs(s)).astype(np.float32)
        ps = self._params()
        m = [np.zeros_like(p) for p in ps]
        v = [np.zeros_like(p) for p in ps]
        n = len(z)
        per_epoch = max(1, n // spec.batch)
        total = spec.epochs * per_epoch
        it = 0
        parts = max(1, min(int(parts), spec.batch))
        for _ in range(spec.epochs):
            order = rng.permutation(n)
            for k in range(per_epoch):
                idx = order[k * spec.batch:(k + 1) * spec.batch]
                grads = self._batch_gradients(z[idx], s[idx], g[idx], lam, w[idx], parts,
                                              helpers)
                it += 1
                lr = spec.lr * 0.5 * (1 + math.cos(math.pi * it / total)) + 1e-5
                c1, c2 = 1 - 0.9 ** it, 1 - 0.999 ** it
                for p, gr, mm, vv in zip(ps, grads, m, v, strict=True):
                    mm *= 0.9
                    mm += 0.1 * gr
                    vv *= 0.999
                    vv += 0.001 * gr * gr
                    p -= (lr * (mm / c1) / (np.sqrt(vv / c2) + 1e-8)).astype(np.float32)
        return self

    def _batch_gradients(self, zb, sb, gb, lam, wb, parts: int, helpers):
        """:meth:`gradients` of one batch as the in-order sum over ``parts`` equal parts."""
        if parts == 1:
            return self.gradients(zb, sb, gb, lam, wb)
        cut = np.linspace(0, len(zb), parts + 1).astype(np.int64)
        args = [(zb[a:b], sb[a:b], gb[a:b], lam, wb[a:b], len(zb))
                for a, b in itertools.pairwise(cut)]
        later = [helpers.submit(self.gradients, *a) for a in args[1:]] if helpers else []
        total = list(self.gradients(*args[0]))
        for k, a in enumerate(args[1:]):
            part = later[k].result() if later else self.gradients(*a)
            for t, p in zip(total, part, strict=True):
                t += p
        return tuple(total)

    def gradients(self, zb, sb, gb, lam, wb=None, n=None) -> tuple[np.ndarray, ...]:
        """The loss's gradients with respect to ``(w1, b1, w2, b2, w3, b3)`` on one batch (``n``:
        the size the loss's means divide by, default the batch's: a part of a batch passes
        the whole batch's)."""
        bd = self.b[:3]
        nb = zb.dtype.type(len(zb) if n is None else n)
        wb = np.ones(len(zb), zb.dtype) if wb is None else wb
        d = zb[:, :3]
        f, (u, feats, h1, h2) = self._forward(zb)
        s1, s2 = 1 - h1 * h1, 1 - h2 * h2
        cu = np.cos(u)
        g2, p1, g1, gd = self._input_gradient(u, h1, h2)  # tangent part below
        gt = gd - (gd * d).sum(1, keepdims=True) * d
        r = (2 * lam / nb) * (gt - gb) * wb[:, None]
        r -= (r * d).sum(1, keepdims=True) * d
        # back through the gradient's graph
        big_r = np.concatenate(((r @ bd) * cu, r, np.zeros((len(zb), 1), zb.dtype)),
                               axis=1)                         # dL/dgf (N, F+4)
        rw = big_r @ self.w1                                    # dL/dg1 (N, H)
        gw1 = big_r.T @ g1
        dp1 = rw * s1
        dh1 = -2 * h1 * (rw * p1)
        gw2 = dp1.T @ g2
        dg2 = dp1 @ self.w2
        gw3 = (dg2 * s2).sum(0)
        dh2 = -2 * h2 * (dg2 * self.w3)
        # the value term
        e = (2.0 / nb) * (f - sb)
        gw3 += h2.T @ e
        gb3 = np.array([e.sum()], zb.dtype)
        dh2 += np.outer(e, self.w3)
        da2 = dh2 * s2
        gw2 += h1.T @ da2
        gb2 = da2.sum(0)
        dh1 += da2 @ self.w2.T
        da1 = dh1 * s1
        gw1 += feats.T @ da1
        gb1 = da1.sum(0)
        return gw1, gb1, gw2, gb2, gw3, gb3

    def loss(self, z, s, g, grad_weight: float, w=None) -> float:
        """The training loss on ``(z, s, g)`` (float64; for tests of :meth:`fit`'s gradient)."""
        f, gd = self.value_and_gradient(z[:, :3], z[:, 3])
        d = z[:, :3]
        gt = gd - (gd * d).sum(1, keepdims=True) * d
        w = np.ones(len(z)) if w is None else w
        return float(((f - s) ** 2).mean() + grad_weight * (w * ((gt - g) ** 2).sum(1)).mean())


def fit_coupled_field(limits, rng: np.random.Generator, spec: FieldSpec = FieldSpec(),
                      samples=None, helpers=None, parts: int = 1) -> DistanceField:
    """Train a :class:`DistanceField` for a coupled polygon swing (``InterpolatedLimits``) on
    ``samples`` ``(d, angle, s, g)`` (default: :func:`coupled_directions` at uniform angles);
    ``helpers`` and ``parts`` as for :meth:`DistanceField.fit`."""
    t0 = time.perf_counter()
    net = DistanceField.initial(spec, limits.at[0], limits.at[-1], rng)
    if samples is None:
        angle = rng.uniform(limits.at[0], limits.at[-1], spec.samples)
        d = coupled_directions(limits, angle, rng, spec.uniform)
        samples = (d, angle, *coupled_targets(limits, angle, d))
    d, angle, s, g = samples
    z = np.concatenate((d, net.tau(angle)[:, None]), axis=1)
    net.fit(z, s, g, spec, rng, helpers=helpers, parts=parts)
    net.info = {"train_s": time.perf_counter() - t0, "samples": len(d),
                "epochs": spec.epochs, "features": spec.features, "hidden": spec.hidden}
    return net


def fit_limb_fields(limb, seed: int = 0, spec: FieldSpec = FieldSpec(), progress=None,
                    postures: np.ndarray | None = None,
                    workers: int | None = None) -> tuple[dict[str, DistanceField], dict]:
    """Train one field per :func:`field_joints` joint on ``postures`` (default:
    :func:`training_postures`, ``spec.samples`` of them); returns ``(fields, training
    facts)``. ``progress(name, seconds)`` is called after each, in the limb's joint order.

    Several fields train side by side, one thread each with BLAS held to one thread
    (``workers``, default: one per field up to the CPU count): on a 2-core machine two
    one-thread trainings take 1.2x one of them, while BLAS's own two threads make one
    training only 1.2x faster. A core left over (fewer fields than cores: an arm's one
    coupled shoulder on two cores) computes the second half of each batch's gradient beside
    the field's own thread (``parts`` 2 in the facts; :meth:`DistanceField.fit`): the arm
    demo's field trained in 96 s against 116 s with BLAS's two threads. The first field
    draws from the seed's generator after the postures, each further one from its own
    ``default_rng([seed, k])``, and a batch's parts are summed in order whoever computed
    them, so for a given number of parts a field's weights do not depend on how many fields
    train at once (tested bit for bit); the number of parts follows the cores left over.
    """
    from concurrent.futures import ThreadPoolExecutor

    from threadpoolctl import threadpool_limits

    rng = np.random.default_rng(seed)
    if postures is None:
        postures = training_postures(limb, spec.samples, rng, spec.uniform)
    result = ConstraintOracle(limb).evaluate(postures)  # once, for every field's source angles
    names = field_joints(limb)
    jobs = [(limb.joints[limb.index(name)].coupling.limits,
             rng if k == 0 else np.random.default_rng([seed, k]),
             field_samples(limb, name, postures, result)) for k, name in enumerate(names)]
    cpus = os.cpu_count() or 1
    workers = max(1, min(len(jobs), cpus) if workers is None else workers)
    # a helper thread per field when there are cores for it (not ``workers``: the number of
    # parts, which the weights depend on, follows the fields and the machine only)
    spare = 1 if jobs and cpus >= 2 * len(jobs) else 0
    fields: dict[str, DistanceField] = {}
    t0 = time.perf_counter()
    with threadpool_limits(limits=1, user_api="blas"), \
            ThreadPoolExecutor(max_workers=workers) as pool, \
            ThreadPoolExecutor(max_workers=max(1, spare * workers)) as helpers:
        running = [pool.submit(fit_coupled_field, limits, r, spec, samples,
                               helpers if spare else None, 1 + spare)
                   for limits, r, samples in jobs]
        for name, job in zip(names, running, strict=True):
            fields[name] = job.result()
            if progress is not None:
                progress(name, fields[name].info["train_s"])
    facts = {"seed": seed, "seconds": round(time.perf_counter() - t0, 3),
             "samples": len(postures), "epochs": spec.epochs, "features": spec.features,
             "hidden": spec.hidden, "steps": list(spec.steps), "joints": list(fields),
             "workers": workers, "parts": 1 + spare}
    return fields, facts


def fit_swing_field(constraint, rng: np.random.Generator,
                    spec: FieldSpec = FieldSpec()) -> DistanceField:
    """The same network on one joint's polygon swing (no coupling: τ is constant), for the
    measurement against the tabulated field (``benchmarks/bench_limb.py --single``)."""

    v = oriented_vertices(constraint.swing)
    limits = InterpolatedLimits(constraint.kind, np.array([0.0, 1.0]), (constraint, constraint),
                                ((v, v),))
    return fit_coupled_field(limits, rng, spec)
