"""Topology, activation and spline evolution of GMLPs (NetGEN / NetJEN, thesis 4.2, 5.1.8-10).

Genome (direct encoding, a "Modified Miller Matrix" linearised row by row; integer genes)::

    [ epochs | Δ₀ | Δmax | spline templates T×K |
      hidden row j = (marker, activation, in-links from the I inputs)          j = 1 … H
      output row k = (activation, in-links from the I inputs, from the H hidden) k = 1 … O ]

Rows are the sub-diagonal part of the lower-triangular connection matrix of the node order
inputs < hidden < outputs (no intra-layer links); the activation index is the diagonal entry and
the marker switches a hidden node (and with it its links, which become introns) on or off. The
bias node feeds every present hidden and output node (not evolved). Gene alphabets: link and
marker bits {0, 1}; activation genes index the configured candidate list; epochs, Δ₀, Δmax take
16 levels (``min_epochs … max_epochs``; ``Δ₀ = lr·2^((g-8)/4)``; ``Δmax = 10^(g/5 - 1)``); spline
control values 256 levels over the activation interval [-1, 1] (TABLE IX).

Genetic algorithm (simple GA, thesis 4.2): binary tournament selection, two-point crossover on
the whole linearised genome with probability ``crossover_rate``, per-gene mutation with
probability ``mutation_rate`` (bit flip / new random allele), whole-generation replacement
(``elitism`` copies the best k unchanged; 0 in the thesis preset). Every generation's P networks
are trained *at once* by :func:`models.nn.rprop.train_population`.

Fitness (thesis eq. 57-58; the OCR garbles them, this is our reading)::

    F = α₁ / (1 + SSE_val) - α₂ · L / L_max,     α₁ = 1 - α₂

with ``SSE_val`` the validation sum of squared errors, ``L`` the enabled links of present nodes
(biases excluded) and ``L_max`` the links of the full GMLP. A network with an output that no
input reaches gets ``F = -1`` (lowest), untrained.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from models.nn import activations as act
from models.nn.gmlp import GMLP, PopulationSpec, forward, init_params, with_bias
from models.nn.rprop import train_population

LEVELS = 16
SPLINE_LEVELS = 256
LOWEST_FITNESS = -1.0


@dataclass
class Layout:
    """Positions of the gene groups in the linearised genome."""

    n_in: int
    n_hidden: int
    n_out: int
    n_templates: int
    n_control: int
    n_hidden_acts: int
    n_out_acts: int

    @property
    def spline_start(self) -> int:
        return 3

    @property
    def hidden_start(self) -> int:
        return 3 + self.n_templates * self.n_control

    @property
    def hidden_row(self) -> int:
        return 2 + self.n_in

    @property
    def out_start(self) -> int:
        return self.hidden_start + self.n_hidden * self.hidden_row

    @property
    def out_row(self) -> int:
        return 1 + self.n_in + self.n_hidden

    @property
    def length(self) -> int:
        return self.out_start + self.n_out * self.out_row

    def alleles(self) -> np.ndarray:
        """(length,) number of values each gene can take."""
        a = np.full(self.length, 2, dtype=np.int64)
        a[:3] = LEVELS
        a[self.spline_start:self.hidden_start] = SPLINE_LEVELS
        hid = a[self.hidden_start:self.out_start].reshape(self.n_hidden, self.hidden_row)
        hid[:, 1] = self.n_hidden_acts
        out = a[self.out_start:].reshape(self.n_out, self.out_row)
        out[:, 0] = self.n_out_acts
        return a


@dataclass
class Decoded:
    """A population's genomes decoded into trainable form."""

    spec: PopulationSpec
    epochs: np.ndarray
    delta0: np.ndarray
    delta_max: np.ndarray
    feasible: np.ndarray
    links: np.ndarray


@dataclass
class GenerationStats:
    generation: int
    best_fitness: float
    mean_fitness: float
    best_val_mse: float
    best_hidden: int
    best_links: int
    elapsed_s: float
    run: int = 1  #: which of the ``repeats`` evolutions (1-based)
    runs: int = 1


@dataclass
class EvolutionResult:
    """Best network of a run and the per-generation history."""

    network: GMLP
    fitness: float
    val_mse: float
    train_mse: float
    epochs: int
    history: list[GenerationStats] = field(default_factory=list)
    elapsed_s: float = 0.0


class Evolver:
    """NetGEN-style evolution of GMLPs for one training problem.

    Parameters
    ----------
    config : dict
        Validated configuration (:func:`models.nn.config.get_config`).
    n_in, n_out : int
        Input and output sizes (4 and 4 for quaternion → correction).
    """

    def __init__(self, config: dict, n_in: int = 4, n_out: int = 4):
        self.cfg = config
        net, evo = config["network"], config["evolution"]
        self.hidden_acts = np.array([act.index_of(a) for a in net["hidden_activations"]])
        self.out_acts = np.array([act.index_of(a) for a in net["output_activations"]])
        self.layout = Layout(n_in, net["max_hidden"], n_out, net["spline_templates"],
                             net["spline_control_points"], len(self.hidden_acts),
                             len(self.out_acts))
        self.alleles = self.layout.alleles()
        lay = self.layout
        # genes the GA may change (the others keep their initial values)
        mut = np.zeros(lay.length, dtype=bool)
        mut[0] = evo["evolve_epochs"]
        mut[1:3] = evo["evolve_learning"]
        mut[lay.spline_start:lay.hidden_start] = evo["evolve_splines"]
        hid = mut[lay.hidden_start:lay.out_start].reshape(lay.n_hidden, lay.hidden_row)
        hid[:, 0] = evo["evolve_hidden"]
        hid[:, 1] = evo["evolve_activations"]
        hid[:, 2:] = evo["evolve_links"]
        out = mut[lay.out_start:].reshape(lay.n_out, lay.out_row)
        out[:, 0] = evo["evolve_activations"]
        out[:, 1:] = evo["evolve_links"]
        self.mutable = mut

    # -- genome ---------------------------------------------------------------------------
    def random_genomes(self, p: int, rng: np.random.Generator) -> np.ndarray:
        """(p, length) int genomes; non-evolved genes take their configured defaults."""
        lay, evo = self.layout, self.cfg["evolution"]
        g = (rng.random((p, lay.length)) * self.alleles).astype(np.int64)
        g[:, 0] = g[:, 0] if evo["evolve_epochs"] else LEVELS - 1
        if not evo["evolve_learning"]:
            g[:, 1] = 8  # Δ₀ = learning rate
            g[:, 2] = 0  # placeholder: Δmax comes from the configuration
        hid = g[:, lay.hidden_start:lay.out_start].reshape(p, lay.n_hidden, lay.hidden_row)
        out = g[:, lay.out_start:].reshape(p, lay.n_out, lay.out_row)
        hid[:, :, 0] = rng.random((p, lay.n_hidden)) < evo["hidden_probability"]
        hid[:, :, 2:] = rng.random(hid[:, :, 2:].shape) < evo["link_probability"]
        out[:, :, 1:] = rng.random(out[:, :, 1:].shape) < evo["link_probability"]
        if not evo["evolve_activations"]:
            hid[:, :, 1] = 0
            out[:, :, 0] = 0
        if not evo["evolve_splines"]:
            # default templates: sigmoid-like steps of different steepness, as a starting point
            x = np.linspace(-5.0, 5.0, lay.n_control)
            tmpl = np.stack([np.tanh(x * (k + 1) / 2.0) for k in range(lay.n_templates)])
            lv = np.round((tmpl + 1.0) / 2.0 * (SPLINE_LEVELS - 1)).astype(np.int64)
            g[:, lay.spline_start:lay.hidden_start] = lv.reshape(-1)
        return np.ascontiguousarray(g)

    def decode(self, g: np.ndarray) -> Decoded:
        lay, tr = self.layout, self.cfg["training"]
        p = len(g)
        i, h, o = lay.n_in, lay.n_hidden, lay.n_out
        hid = g[:, lay.hidden_start:lay.out_start].reshape(p, h, lay.hidden_row)
        out = g[:, lay.out_start:].reshape(p, o, lay.out_row)
        marker = hid[:, :, 0].astype(bool)
        in_h = hid[:, :, 2:].astype(bool).transpose(0, 2, 1) & marker[:, None, :]  # (P, I, H)
        in_o = out[:, :, 1:1 + i].astype(bool).transpose(0, 2, 1)  # (P, I, O)
        h_o = out[:, :, 1 + i:].astype(bool).transpose(0, 2, 1) & marker[:, :, None]  # (P, H, O)
        present = in_h.any(axis=1) & h_o.any(axis=2)  # hidden nodes with input and output
        in_h &= present[:, None, :]
        h_o &= present[:, :, None]
        mask1 = np.concatenate((in_h, present[:, None, :]), axis=1)
        mask2 = np.concatenate((h_o, in_o, np.ones((p, 1, o), bool)), axis=1)
        feasible = (in_o.any(axis=1) | h_o.any(axis=1)).all(axis=1)
        links = in_h.sum(axis=(1, 2)) + h_o.sum(axis=(1, 2)) + in_o.sum(axis=(1, 2))
        ah = self.hidden_acts[np.minimum(hid[:, :, 1], len(self.hidden_acts) - 1)]
        ao = self.out_acts[np.minimum(out[:, :, 0], len(self.out_acts) - 1)]
        spline = None
        if (ah >= act.SPLINE0).any() or (ao >= act.SPLINE0).any():
            sp = g[:, lay.spline_start:lay.hidden_start].reshape(p, lay.n_templates, lay.n_control)
            spline = -1.0 + 2.0 * sp / (SPLINE_LEVELS - 1)
        ev = self.cfg["evolution"]
        lo, hi = tr["min_epochs"], tr["max_epochs"]
        epochs = np.round(lo + g[:, 0] * (hi - lo) / (LEVELS - 1)).astype(np.int64)
        if ev["evolve_learning"]:
            delta0 = tr["learning_rate"] * 2.0 ** ((g[:, 1] - 8) / 4.0)
            dmax = 10.0 ** (g[:, 2] / 5.0 - 1.0)
        else:
            delta0 = np.full(p, tr["learning_rate"])
            dmax = np.full(p, tr["delta_max"])
        epochs = np.where(feasible, epochs, 0)
        return Decoded(PopulationSpec(mask1, mask2, ah, ao, spline), epochs, delta0, dmax,
                       feasible, links)

    # -- GA operators ---------------------------------------------------------------------
    def _select(self, fit: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
        k = self.cfg["evolution"]["tournament"]
        cand = rng.integers(0, len(fit), (n, k))
        return cand[np.arange(n), np.argmax(fit[cand], axis=1)]

    def _crossover(self, a: np.ndarray, b: np.ndarray, rng: np.random.Generator):
        n, length = a.shape
        c1, c2 = a.copy(), b.copy()
        do = rng.random(n) < self.cfg["evolution"]["crossover_rate"]
        cut = np.sort(rng.integers(0, length + 1, (n, 2)), axis=1)
        pos = np.arange(length)
        seg = (pos >= cut[:, :1]) & (pos < cut[:, 1:]) & do[:, None]
        c1[seg], c2[seg] = b[seg], a[seg]
        return c1, c2

    def _mutate(self, g: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        hit = (rng.random(g.shape) < self.cfg["evolution"]["mutation_rate"]) & self.mutable
        r, c = np.nonzero(hit)
        if len(r):
            al = self.alleles[c]
            # a different allele, uniformly (bit flip for binary genes)
            shift = 1 + (rng.random(len(r)) * np.maximum(al - 1, 1)).astype(np.int64)
            g[r, c] = (g[r, c] + shift) % al
        return g

    def next_generation(self, g: np.ndarray, fit: np.ndarray, rng: np.random.Generator):
        p = len(g)
        parents = self._select(fit, p + (p % 2), rng)
        a, b = g[parents[0::2]], g[parents[1::2]]
        c1, c2 = self._crossover(a, b, rng)
        kids = np.concatenate((c1, c2))[:p]
        kids = self._mutate(kids, rng)
        e = self.cfg["evolution"]["elitism"]
        if e:
            kids[:e] = g[np.argsort(-fit)[:e]]
        return kids

    # -- evaluation -----------------------------------------------------------------------
    def evaluate(self, g, x, t, xv, tv, rng):
        """Train every genome's network and score it; returns (fitness, decoded, result, sse)."""
        tr, ev = self.cfg["training"], self.cfg["evolution"]
        dec = self.decode(g)
        dtype = np.float32 if tr["dtype"] == "float32" else np.float64
        theta0 = init_params(dec.spec, rng)
        res = train_population(theta0, dec.spec, x, t, max_epochs=dec.epochs,
                               stop_mse=tr["stop_mse"], delta0=dec.delta0,
                               delta_max=dec.delta_max, variant=tr["variant"], dtype=dtype,
                               huber=tr["huber"])
        yv, _ = forward(res.theta, dec.spec, with_bias(np.asarray(xv, np.float64)),
                        need_grad=False)
        sse = np.einsum("pno,pno->p", yv - tv, yv - tv)
        lay = self.layout
        lmax = lay.n_in * lay.n_hidden + lay.n_hidden * lay.n_out + lay.n_in * lay.n_out
        a2 = ev["alpha2"]
        fit = (1.0 - a2) / (1.0 + sse) - a2 * dec.links / lmax
        bad = ~dec.feasible | ~np.isfinite(fit)
        fit = np.where(bad, LOWEST_FITNESS, fit)
        return fit, dec, res, np.where(bad, np.inf, sse)

    def run(self, x, t, xv, tv, rng: np.random.Generator,
            progress: Callable[[GenerationStats], None] | None = None,
            canonical_ref: np.ndarray | None = None, run: int = 1,
            runs: int = 1) -> EvolutionResult:
        """Evolve for the configured generations; returns the best network seen.

        Parameters
        ----------
        x, t : (N, I), (N, O) float
            Training inputs (canonicalised) and targets.
        xv, tv : (M, I), (M, O) float
            Validation set (fitness).
        rng : numpy Generator
            Sole source of randomness: the same seed gives the same network.
        progress : callable, optional
            Called with each generation's :class:`GenerationStats`.
        canonical_ref : (4,) float, optional
            Stored in the returned :class:`GMLP`.
        """
        evo = self.cfg["evolution"]
        start = time.perf_counter()
        g = self.random_genomes(evo["population"], rng)
        best = None
        history = []
        for gen in range(evo["generations"] + 1):
            fit, dec, res, sse = self.evaluate(g, x, t, xv, tv, rng)
            k = int(np.argmax(fit))
            if best is None or fit[k] > best[0]:
                net = GMLP.from_population(res.theta, dec.spec, k, canonical_ref=canonical_ref)
                best = (float(fit[k]), net, float(sse[k]) / tv.size, float(res.mse[k]),
                        int(res.epochs[k]))
            st = GenerationStats(gen, best[0], float(np.mean(fit)), best[2],
                                 best[1].n_hidden, best[1].n_links,
                                 time.perf_counter() - start, run, runs)
            history.append(st)
            if progress is not None:
                progress(st)
            if gen < evo["generations"]:
                g = self.next_generation(g, fit, rng)
        fitness, net, val_mse, train_mse, epochs = best
        net.info.update({"fitness": fitness, "val_mse": val_mse, "train_mse": train_mse,
                         "epochs": epochs, "hidden": net.n_hidden, "links": net.n_links,
                         "hidden_activations": [act.name_of(int(a)) for a in net.act_hidden],
                         "output_activations": [act.name_of(int(a)) for a in net.act_out]})
        return EvolutionResult(net, fitness, val_mse, train_mse, epochs, history,
                               time.perf_counter() - start)


def evolve(config: dict, x, t, xv, tv, rng: np.random.Generator, progress=None,
           canonical_ref=None) -> EvolutionResult:
    """Run ``config['evolution']['repeats']`` evolutions, return the best by fitness."""
    ev = Evolver(config, x.shape[1], t.shape[1])
    best = None
    runs = int(config["evolution"]["repeats"])
    for k in range(runs):
        r = ev.run(x, t, xv, tv, rng, progress, canonical_ref, run=k + 1, runs=runs)
        if best is None or r.fitness > best.fitness:
            best = r
    return best
