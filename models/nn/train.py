"""End-to-end training of a corrective constraint: patterns → evolution → held-out metrics.

Pipeline for a :class:`models.constraint.JointConstraint`:

1. Patterns (thesis ch. 3-4, :func:`models.datasets.quaternion_dataset`): twist-free
   orientations ``Qi`` (rotation taking the limb axis to a direction ``V``, eq. 59-62) labelled
   by the exact oracle's correction (eq. 63-68 for a cone, nearest boundary point by
   limb-endpoint angle for a polygon). The ONNX training-data hash is the dataset's
   :meth:`~models.datasets.Dataset.content_hash`.
2. Hemisphere canonicalisation ``q ← sign(q·r) q`` with ``r`` = ``(1, 0, 0, 0)`` (``w-positive``)
   or the twist-free rotation to the boundary centre (``centre``; the hemisphere cut then lies
   opposite the valid region, away from the boundary — cf. thesis TABLE IV), applied identically
   to training data and, inside the exported graph, to live inputs.
   Centre frame (``network.frame: centre``, :mod:`models.nn.gmlp`): with ``R_c`` =
   :func:`centre_frame` the network sees ``q' = R_c⁻¹ ⊗ q`` (through the input map) and learns
   ``t' = canonical(R_c⁻¹ ⊗ t ⊗ R_c)``; the deployed network maps back,
   ``ĉ = R_c ⊗ c' ⊗ R_c⁻¹``. This puts the swing map's singularity (limb along ``-X`` in the
   frame, i.e. ``d = -centre``) on the correctional discontinuity.
3. Evolution (:func:`models.nn.evolution.evolve`) on train/validation splits.
4. Metrics (:func:`models.metrics.evaluate`) on a fresh test set from the same generator.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from models import metrics as M
from models import quaternion as quat
from models.datasets import quaternion_dataset
from models.evaluation import evaluate_model
from models.field import FieldModel
from models.geometry import fibonacci_sphere
from models.nn.evolution import EvolutionResult, GenerationStats, evolve
from models.nn.gmlp import GMLP, swing_of
from models.oracle import ConstraintOracle

#: Directions searched for a polygon's centre frame (:func:`centre_frame`).
FRAME_GRID = 20_000

#: (x, y, z) → (z, x, −y): the Fibonacci spiral from +X to −X, turning as the search always did.
_SPIRAL_ABOUT_X = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])



def _centre_direction(constraint) -> np.ndarray:
    sw = constraint.swing
    if sw is None:
        return np.asarray(constraint.limb_axis, dtype=np.float64)
    if hasattr(sw, "centre"):
        return np.asarray(sw.centre, dtype=np.float64)
    return np.asarray(sw.interior, dtype=np.float64)


def canonical_reference(constraint, mode: str) -> np.ndarray | None:
    """Reference quaternion ``r`` (4,) of the canonicalisation ``mode``.

    None for ``none`` and ``swing`` (the swing map needs no reference).
    """
    if mode in ("none", "swing"):
        return None
    if mode == "w-positive":
        return quat.IDENTITY.copy()
    axis = np.asarray(constraint.limb_axis, dtype=np.float64)
    return quat.from_two_vectors(axis, quat.check_vectors(_centre_direction(constraint)))


def canonicalise(q: np.ndarray, ref: np.ndarray | None) -> np.ndarray:
    """``sign(q·r) q`` (``sign(0) = +1``) for (N, 4) ``q``; unchanged if ``ref`` is None."""
    if ref is None:
        return q
    return q * np.where(q @ ref >= 0.0, 1.0, -1.0)[:, None]


def centre_frame(constraint, oracle=None, n_grid: int = FRAME_GRID) -> np.ndarray:
    """Centre-frame rotation ``R_c`` (4,): the minimal rotation limb axis → constraint centre.

    The swing map's singularity lands on ``-centre``, so the best centre is the one whose
    antipode lies deepest in the invalid region (where the correction flips). For a cone that is
    its centre, used exactly. For a polygon it is the antipode of the limb direction farthest
    outside the boundary (largest ``oracle.signed_distance``) on a deterministic Fibonacci grid
    of ``n_grid`` directions (~1.4° spacing for 20 000) — measured on the five thesis shapes,
    3 seeds: mean 3-D error 2.32 % vs 2.32 % for the normalised vertex mean and 2.35 % for the
    parent frame, MSE 8.9e-4 vs 9.3e-4 / 9.8e-4 (all within seed noise: the shapes are centred
    near +X already). The limb axis itself (``R_c`` = identity) without a swing limit.

    Parameters
    ----------
    constraint : JointConstraint
    oracle : ConstraintOracle, optional
        Reused if given.
    n_grid : int
        Grid size for polygons.

    Returns
    -------
    (4,) float64, unit quaternion.
    """
    axis = np.asarray(constraint.limb_axis, dtype=np.float64)
    sw = constraint.swing
    if sw is None or hasattr(sw, "centre"):
        return quat.from_two_vectors(axis, quat.check_vectors(_centre_direction(constraint)))
    oracle = oracle or ConstraintOracle(constraint)
    g = fibonacci_sphere(n_grid) @ _SPIRAL_ABOUT_X  # the spiral about +X, as it always was
    d = oracle.signed_distance(quat.from_two_vectors(np.broadcast_to(axis, g.shape), g))
    return quat.from_two_vectors(axis, -g[int(np.argmax(d))])


def to_frame(q: np.ndarray, frame: np.ndarray | None) -> np.ndarray:
    """``R_c⁻¹ ⊗ q`` for (N, 4) ``q``; unchanged if ``frame`` is None."""
    if frame is None:
        return q
    return quat.multiply(np.broadcast_to(quat.conjugate(frame), q.shape), q)


def target_to_frame(t: np.ndarray, frame: np.ndarray | None) -> np.ndarray:
    """Corrections in the centre frame, ``canonical(R_c⁻¹ ⊗ t ⊗ R_c)``, (N, 4)."""
    if frame is None:
        return t
    f = np.broadcast_to(frame, t.shape)
    return quat.canonical(quat.multiply(quat.multiply(quat.conjugate(f), t), f))


def training_patterns(constraint, n: int, rng: np.random.Generator, *,
                      distribution: str = "even", order: str = "valid-first",
                      hemisphere: str = "w-positive", twist: bool = False,
                      oracle=None) -> tuple[np.ndarray, np.ndarray]:
    """``n`` patterns (inputs (n, 4), exact corrections (n, 4), ``w ≥ 0``) of a constraint.

    A thin wrapper of :func:`models.datasets.quaternion_dataset`: ``hemisphere`` is its input
    sign rule (``ambiguous``, ``centre``, ``w-positive``); ``twist=True`` draws full 3-DOF
    orientations (random twist about the limb axis) — what a live sensor delivers. ``oracle``
    is accepted for compatibility and unused (the dataset labels with the exact oracle).
    """
    return _patterns(constraint, n, rng, distribution=distribution, order=order,
                     hemisphere=hemisphere, twist=twist)[:2]


def _patterns(constraint, n, rng, **kw) -> tuple[np.ndarray, np.ndarray, str]:

    ds = quaternion_dataset(constraint, n, rng, **kw)
    return (np.asarray(ds.inputs, np.float64), quat.canonical(np.asarray(ds.targets)),
            ds.content_hash())


@dataclass
class TrainedModel:
    """A trained correction network with its provenance and held-out metrics."""

    network: GMLP | Any  #: a GMLP, or a models.field.FieldModel (preset field)
    result: EvolutionResult | None  #: None for the field model
    metrics: dict[str, float]
    data_sha256: str
    config: dict[str, Any]
    extra: dict[str, Any] = field(default_factory=dict)


def overshoot(targets: np.ndarray, margin_deg: float) -> np.ndarray:
    """Lengthen non-identity corrections by ``margin_deg`` about their own axis.

    A learned correction that falls a little short leaves the limb just outside the boundary;
    training on corrections that go ``margin`` further trades a little accuracy (and a jump of
    ``margin`` at the boundary, which the network smooths) for fewer violations. (N, 4) → (N, 4).
    """
    if margin_deg <= 0.0:
        return targets
    ang = quat.angle(targets)
    moving = ang > 1e-9
    axis = np.zeros((len(targets), 3))
    axis[moving] = targets[moving, 1:] / np.linalg.norm(targets[moving, 1:], axis=1,
                                                        keepdims=True)
    new = quat.from_axis_angle(axis, ang + math.radians(margin_deg))
    return np.where(moving[:, None], new, targets)


def split(q, t, sizes, rng):
    """Train/validation split of a pattern set, keeping the pattern order within each part."""
    n_tr = sizes[0]
    idx = rng.permutation(len(q))
    tr, va = np.sort(idx[:n_tr]), np.sort(idx[n_tr:n_tr + sizes[1]])
    return q[tr], t[tr], q[va], t[va]


def _train_field(constraint, config: dict, rng, oracle, patterns) -> TrainedModel:
    import time

    t0 = time.perf_counter()
    f = FieldModel.from_constraint(constraint, grid=config["model"]["grid"], oracle=oracle)
    build_s = time.perf_counter() - t0
    seed = int(rng.integers(2**31))
    metrics = evaluate_model(f, constraint, n=config["data"]["test"], seed=seed, oracle=oracle)
    metrics["build_s"] = build_s
    data_hash = f.content_hash()
    extra = {"table_sha256": data_hash}
    if patterns is not None:  # a dataset: the field samples its constraint; scored on it too
        q, _, data_hash = patterns
        on = evaluate_model(f, constraint, q=q, oracle=oracle)
        metrics.update({f"dataset_{k}": v for k, v in on.items()
                        if k in ("mean_3d_error_pct", "frac_invalid_violating_1deg",
                                 "mean_identity_error_deg", "n")})
        extra["data_use"] = ("the table samples the dataset's constraint with the exact "
                             "oracle; dataset_* metrics are measured on its patterns")
    f.info.update(extra)
    return TrainedModel(f, None, metrics, data_hash, config, extra)


def train_correction(constraint, config: dict, rng: np.random.Generator,
                     progress: Callable[[GenerationStats], None] | None = None,
                     oracle=None, patterns=None) -> TrainedModel:
    """Train a corrective-constraint model for ``constraint`` with a validated ``config``.

    Parameters
    ----------
    constraint : JointConstraint
    config : dict
        :func:`models.nn.config.get_config`; ``model.method`` chooses a GMLP (thesis, best,
        compact, fixed presets) or the swing-field model (:mod:`models.field`, preset field).
    rng : Generator
    progress : callable, optional
        Called with :class:`GenerationStats` after each generation (GMLP only).
    oracle : ConstraintOracle, optional
    patterns : (inputs (N, 4), targets (N, 4), sha256 str), optional
        Training patterns from a dataset file (``rig train --data``) instead of freshly
        generated ones; split into train / validation in the configured proportion, and the
        model records their hash.
    """
    oracle = oracle or ConstraintOracle(constraint)
    if config.get("model", {}).get("method") == "field":
        return _train_field(constraint, config, rng, oracle, patterns)
    mode = config["network"]["canonicalise"]
    if mode == "swing" and getattr(constraint, "twist", None) is not None:
        # the swing map discards the twist, which a twist limit needs: learn from twisted
        # patterns with the centre hemisphere rule instead
        config = {**config, "network": {**config["network"], "canonicalise": "centre"},
                  "data": {**config["data"], "twist": True}}
        mode = "centre"
    dc = config["data"]
    ref = canonical_reference(constraint, mode)
    frame = (centre_frame(constraint, oracle) if config["network"]["frame"] == "centre"
             else None)
    n = dc["train"] + dc["validation"]
    if patterns is None:
        q, t, data_hash = _patterns(constraint, n, rng, distribution=dc["distribution"],
                                    order=dc["order"], hemisphere=dc["hemisphere"],
                                    twist=dc["twist"])
        sizes = (dc["train"], dc["validation"])
    else:
        q, t, data_hash = patterns
        q = np.asarray(q, np.float64)
        t = quat.canonical(np.asarray(t, np.float64))
        if len(q) < 3:
            raise ValueError(f"patterns: need at least 3 patterns, got {len(q)}")
        n_tr = min(max(1, round(len(q) * dc["train"] / n)), len(q) - 1)
        sizes = (n_tr, len(q) - n_tr)
    x = swing_of(to_frame(q, frame)) if mode == "swing" else to_frame(canonicalise(q, ref), frame)
    t = target_to_frame(overshoot(t, dc["overshoot_deg"]), frame)
    xtr, ttr, xva, tva = split(x, t, sizes, rng)
    res = evolve(config, xtr, ttr, xva, tva, rng, progress, canonical_ref=ref)
    res.network.input_map = "swing" if mode == "swing" else "canonical"
    res.network.frame = frame
    res.network.info["input_map"] = res.network.input_map
    res.network.info["frame"] = config["network"]["frame"]
    # raw sensor quaternions come with either sign; without in-graph canonicalisation the
    # network only knows the training data's hemisphere rule, so test with that rule
    test_hemi = dc["hemisphere"] if mode == "none" else "ambiguous"
    qt, _ = training_patterns(constraint, dc["test"], rng, distribution=dc["distribution"],
                              order="random", hemisphere=test_hemi, twist=dc["twist"],
                              oracle=oracle)
    metrics = M.evaluate(res.network.predict, oracle, qt)
    metrics.update({"hidden": res.network.n_hidden, "links": res.network.n_links,
                    "val_mse": res.val_mse, "train_mse": res.train_mse,
                    "evolution_s": res.elapsed_s})
    return TrainedModel(res.network, res, metrics, data_hash, config)
