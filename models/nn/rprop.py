"""Resilient back-propagation (RPROP) for a whole population of GMLPs at once.

Variant: **iRprop−** by default (Igel & Hüsken 2000), **iRprop+** on request; the thesis used
Riedmiller & Braun's RPROP (thesis Fig. 8: RPROP beat plain back-propagation). Full batch.
For every weight ``w`` with gradient ``g_t = ∂SSE/∂w`` and step size ``Δ``::

    if g_t g_{t-1} > 0:  Δ ← min(η⁺ Δ, Δmax)
    if g_t g_{t-1} < 0:  Δ ← max(η⁻ Δ, Δmin);  g_t ← 0
                         (iRprop+ only: undo the last step if this network's error rose)
    w ← w - sign(g_t) Δ

with ``η⁺ = 1.2``, ``η⁻ = 0.5``, ``Δmin = 1e-6``; ``Δ₀`` (the thesis's "learning rate" 0.1) and
``Δmax`` are per network, because the genetic algorithm evolves them together with the epoch
budget. Each network stops on its own when its training MSE ≤ ``stop_mse`` or it has used its
epochs; stopped networks leave the stacked arrays, so the remaining ones run faster. Entirely
deterministic for a given initial ``theta`` (no randomness inside).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from models.nn.gmlp import PopulationSpec, backward, forward, with_bias

ETA_PLUS = 1.2
ETA_MINUS = 0.5
DELTA_MIN = 1e-6


@dataclass
class TrainResult:
    """Outcome of :func:`train_population`.

    Attributes
    ----------
    theta : (P, n_weights) float64
        Trained flat parameters.
    mse : (P,) float64
        Final training MSE (mean over patterns and outputs).
    epochs : (P,) int
        Epochs used by each network.
    """

    theta: np.ndarray
    mse: np.ndarray
    epochs: np.ndarray


def train_population(
    theta: np.ndarray,
    spec: PopulationSpec,
    x: np.ndarray,
    t: np.ndarray,
    *,
    max_epochs: np.ndarray | int,
    stop_mse: float,
    delta0: np.ndarray | float = 0.1,
    delta_max: np.ndarray | float = 50.0,
    variant: str = "irprop-",
    dtype=np.float32,
    huber: float = 0.0,
) -> TrainResult:
    """Train P networks at once with batch RPROP.

    Parameters
    ----------
    theta : (P, n_weights) float
        Initial flat parameters (masked entries zero), e.g. :func:`models.nn.gmlp.init_params`.
    spec : PopulationSpec
    x : (N, I) float
        Training inputs (canonicalised quaternions).
    t : (N, O) float
        Targets (corrective quaternions).
    max_epochs : int or (P,) int
        Epoch budget per network.
    stop_mse : float
        A network stops once its training MSE is at or below this.
    delta0, delta_max : float or (P,) float
        Initial and maximum RPROP step sizes.
    variant : {"irprop-", "irprop+"}
    dtype : numpy float dtype
        Arithmetic precision (float32 is about twice as fast; see benchmarks/bench_evolution.py).
    huber : float
        If > 0, descend the Huber loss with this threshold instead of the SSE: residuals are
        clipped to ±huber in the gradient, so the few patterns at a discontinuity the network
        cannot fit (thesis's correctional discontinuity) stop dominating the weight updates.
        Stopping still uses the MSE.

    Returns
    -------
    TrainResult
    """
    if variant not in ("irprop-", "irprop+"):
        raise ValueError(f"variant must be 'irprop-' or 'irprop+', got {variant!r}")
    p = theta.shape[0]
    max_epochs = np.broadcast_to(np.asarray(max_epochs, dtype=np.int64), (p,))
    delta0 = np.broadcast_to(np.asarray(delta0, dtype=np.float64), (p,))
    delta_max = np.broadcast_to(np.asarray(delta_max, dtype=np.float64), (p,)).astype(dtype)
    xb = with_bias(np.asarray(x, dtype=dtype))
    t = np.asarray(t, dtype=dtype)
    norm = 1.0 / (t.shape[0] * t.shape[1])

    out_theta = np.asarray(theta, dtype=np.float64).copy()
    out_mse = np.full(p, np.inf)
    out_epochs = np.zeros(p, dtype=np.int64)

    active = np.arange(p)
    sub = spec
    coef = sub.coefficients()
    coef = None if coef is None else coef.astype(dtype)
    mask = sub.flat_mask().astype(dtype)
    th = np.asarray(theta, dtype=dtype) * mask
    step = np.broadcast_to(np.minimum(delta0, delta_max)[:, None], th.shape).astype(dtype)
    gprev = np.zeros_like(th)
    dw = np.zeros_like(th)
    eprev = np.full(p, np.inf)
    dmax = delta_max[:, None]
    plus = variant == "irprop+"

    epoch = 0
    while True:
        y, cache = forward(th, sub, xb, coef)
        err = y - t
        mse = np.einsum("pno,pno->p", err, err) * norm
        done = (mse <= stop_mse) | (epoch >= max_epochs[active]) | ~np.isfinite(mse)
        if done.any():
            ids = active[done]
            out_theta[ids] = th[done]
            out_mse[ids] = mse[done]
            out_epochs[ids] = epoch
            keep = ~done
            if not keep.any():
                break
            active = active[keep]
            sub = sub.subset(keep)
            coef = None if coef is None else coef[keep]
            mask, th, step, gprev, dw = (a[keep] for a in (mask, th, step, gprev, dw))
            eprev, dmax, mse = eprev[keep], dmax[keep], mse[keep]
            y, cache = forward(th, sub, xb, coef)
            err = y - t
        if huber > 0.0:
            np.clip(err, -huber, huber, out=err)
        g = backward(err, cache, sub, xb)
        g *= mask
        s = g * gprev
        pos = s > 0
        neg = s < 0
        step *= np.where(pos, ETA_PLUS, np.where(neg, ETA_MINUS, 1.0)).astype(dtype)
        np.clip(step, DELTA_MIN, dmax, out=step)  # Δ₀ ≤ Δmax, so only changed steps clip
        if plus:
            rose = (mse > eprev)[:, None] & neg
            th += np.where(rose, dw, 0.0)  # undo the previous step (weight backtracking)
        g[neg] = 0.0
        dw = np.sign(g)
        dw *= step
        np.negative(dw, out=dw)
        th += dw
        gprev = g
        eprev = mse
        epoch += 1
    return TrainResult(out_theta, out_mse, out_epochs)
