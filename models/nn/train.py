"""End-to-end training of a corrective constraint: patterns → evolution → held-out metrics.

Pipeline for a :class:`models.constraint.JointConstraint`:

1. Patterns (thesis ch. 3-4): twist-free orientations ``Qi`` (rotation taking the limb axis to a
   direction ``V``, eq. 59-62) labelled by the exact oracle's correction (eq. 63-68 for a cone,
   nearest boundary point by limb-endpoint angle for a polygon). :mod:`models.datasets` is used
   when installed; otherwise a built-in sampler with the thesis's *even* distribution (four
   equally filled zones by signed distance: inner valid, 10° valid band, 10° invalid band, outer
   invalid) — exact zone sampling for cones (:mod:`models.nn.thesis_data`), rejection sampling
   for polygons.
2. Hemisphere canonicalisation ``q ← sign(q·r) q`` with ``r`` = ``(1, 0, 0, 0)`` (``w-positive``)
   or the twist-free rotation to the boundary centre (``centre``; the hemisphere cut then lies
   opposite the valid region, away from the boundary — cf. thesis TABLE IV), applied identically
   to training data and, inside the exported graph, to live inputs.
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
from models.nn.evolution import EvolutionResult, GenerationStats, evolve
from models.nn.gmlp import GMLP, swing_of
from models.nn.thesis_data import cone_patterns

BAND_DEG = 10.0


def _oracle(constraint):
    from models.oracle import ConstraintOracle

    return ConstraintOracle(constraint)


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


def _zone_sample(constraint, oracle, n, rng, distribution) -> np.ndarray:
    axis = np.asarray(constraint.limb_axis, dtype=np.float64)
    if distribution == "uniform":
        v = quat.random_unit_vectors(n, rng)
        return quat.from_two_vectors(np.broadcast_to(axis, v.shape), v)
    band = math.radians(BAND_DEG if distribution == "even" else 5.0)
    quota = [n // 4 + (1 if k < n % 4 else 0) for k in range(4)]
    if distribution == "clustered":
        quota = [n // 8, n // 4 + n // 8, n // 4 + n // 8, 0]
        quota[3] = n - sum(quota)
    got: list[list[np.ndarray]] = [[], [], [], []]
    have = [0, 0, 0, 0]
    for _ in range(200):
        v = quat.random_unit_vectors(max(4 * n, 4096), rng)
        q = quat.from_two_vectors(np.broadcast_to(axis, v.shape), v)
        d = oracle.signed_distance(q)
        zone = np.select([d < -band, d <= 0.0, d <= band], [0, 1, 2], 3)
        for k in range(4):
            need = quota[k] - have[k]
            if need > 0:
                sel = q[zone == k][:need]
                got[k].append(sel)
                have[k] += len(sel)
        if all(h >= qk for h, qk in zip(have, quota, strict=True)):
            break
    return np.concatenate([np.concatenate(g) if g else np.zeros((0, 4)) for g in got])


def training_patterns(constraint, n: int, rng: np.random.Generator, *,
                      distribution: str = "even", order: str = "valid-first",
                      hemisphere: str = "w-positive", twist: bool = False,
                      oracle=None) -> tuple[np.ndarray, np.ndarray]:
    """``n`` patterns (inputs (n, 4), exact corrections (n, 4), ``w ≥ 0``) of a constraint.

    ``hemisphere`` is the input sign rule of :func:`models.datasets.quaternion_dataset`
    (``ambiguous``, ``centre``, ``w-positive``); the built-in fallback sampler supports
    ``w-positive`` only (its inputs are twist-free with ``w ≥ 0``). ``twist=True`` draws full
    3-DOF orientations (random twist about the limb axis; needs :mod:`models.datasets`) — what
    a live sensor delivers; a network trained twist-free is meaningless on twisted inputs.
    """
    try:
        from models.datasets import quaternion_dataset
    except ImportError:
        quaternion_dataset = None
    if quaternion_dataset is not None:
        ds = quaternion_dataset(constraint, n, rng, distribution=distribution, order=order,
                                hemisphere=hemisphere, twist=twist)
        return np.asarray(ds.inputs, np.float64), quat.canonical(np.asarray(ds.targets))
    if twist:
        from models.errors import DatasetError

        raise DatasetError("twist=True patterns need models.datasets")
    oracle = oracle or _oracle(constraint)
    sw = constraint.swing
    if hasattr(sw, "radius_deg") and constraint.twist is None and np.allclose(
            constraint.limb_axis, quat.LIMB_AXIS):
        return cone_patterns(n, sw.centre, sw.radius_deg, rng, distribution=distribution,
                             order=order)
    q = _zone_sample(constraint, oracle, n, rng, distribution)
    valid = oracle.is_valid(q)
    if order == "valid-first":
        idx = np.concatenate((rng.permutation(np.flatnonzero(valid)),
                              rng.permutation(np.flatnonzero(~valid))))
    elif order == "reversed":
        idx = np.concatenate((rng.permutation(np.flatnonzero(~valid)),
                              rng.permutation(np.flatnonzero(valid))))
    else:
        idx = rng.permutation(len(q))
    q = q[idx]
    return q, quat.canonical(oracle.correction(q))


@dataclass
class TrainedModel:
    """A trained correction network with its provenance and held-out metrics."""

    network: GMLP
    result: EvolutionResult
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


def train_correction(constraint, config: dict, rng: np.random.Generator,
                     progress: Callable[[GenerationStats], None] | None = None,
                     oracle=None) -> TrainedModel:
    """Train a correction network for ``constraint`` with a validated ``config``."""
    from models.onnx_io import data_sha256

    oracle = oracle or _oracle(constraint)
    mode = config["network"]["canonicalise"]
    if mode == "swing" and getattr(constraint, "twist", None) is not None:
        # the swing map discards the twist, which a twist limit needs: learn from twisted
        # patterns with the centre hemisphere rule instead
        config = {**config, "network": {**config["network"], "canonicalise": "centre"},
                  "data": {**config["data"], "twist": True}}
        mode = "centre"
    dc = config["data"]
    ref = canonical_reference(constraint, mode)
    n = dc["train"] + dc["validation"]
    q, t = training_patterns(constraint, n, rng, distribution=dc["distribution"],
                             order=dc["order"], hemisphere=dc["hemisphere"],
                             twist=dc["twist"], oracle=oracle)
    x = swing_of(q) if mode == "swing" else canonicalise(q, ref)
    t = overshoot(t, dc["overshoot_deg"])
    xtr, ttr, xva, tva = split(x, t, (dc["train"], dc["validation"]), rng)
    res = evolve(config, xtr, ttr, xva, tva, rng, progress, canonical_ref=ref)
    res.network.input_map = "swing" if mode == "swing" else "canonical"
    res.network.info["input_map"] = res.network.input_map
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
    return TrainedModel(res.network, res, metrics, data_sha256(xtr, ttr), config)
