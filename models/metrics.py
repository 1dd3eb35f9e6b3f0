"""Accuracy metrics of learned corrective constraints.

For orientations ``q`` (N, 4), the exact correction ``c*`` (oracle) and a learned correction
``ĉ`` (unit), with the limb axis ``X`` (:data:`models.quaternion.LIMB_AXIS`):

- **MSE** — mean over patterns and the 4 components of ``(ĉ - c*)²`` (thesis's output MSE).
- **3-D error** (thesis's "Pythagorean" error) — ``e = |R(c* ⊗ q) X - R(ĉ ⊗ q) X|``, the distance
  between the unit-limb endpoints corrected by the ideal and the learned correction; its maximum
  is 2, so it is reported as ``100 e / 2`` percent. The thesis also counts the patterns above 2 %
  and above 7.5 %.
- **Angular error** — angle (degrees) between the learned corrected limb direction and the limb
  direction of the exact projection (``oracle.project``); equals the 3-D error in angle form.
- **Violation** — how far outside the boundary the learned corrected orientation lies,
  ``max(0, oracle.signed_distance(ĉ ⊗ q))`` in degrees (thesis 9.2.2's proposed
  distance-to-boundary metric, which is fair at the correctional discontinuities).
- **Identity error** — rotation angle (degrees) of ``ĉ`` on valid inputs, where the exact
  correction is the identity.

A limb's postures ``q`` (N, J, 4) (joint orientations, child relative to parent, in the limb
file's order; a limb oracle, :class:`models.oracle.ConstraintOracle`): with the exact corrected
posture ``p*`` (the oracle's projection) and the model's ``p̂`` (``ĉ_j ⊗ q_j``), unit segment
lengths, the end point ``E(p) = Σ_j (p_0 ⊗ … ⊗ p_j) · a_j``:

- ``end_mean_3d_error_pct``: mean ``|E(p̂) − E(p*)|`` in % of the limb's length ``J``;
- ``end_p99_direction_error_deg``: 99th percentile of the angle between ``E(p̂)`` and ``E(p*)``;
- ``joint_mean_direction_error_deg`` (per joint): mean angle between each segment's direction
  in its parent's frame after the model's and the exact correction;
- ``frac_invalid_violating_1deg``: postures invalid in some joint whose model-corrected posture
  is more than 1° outside in any joint (the limb oracle's distance; a one joint's metric of the
  same name, spelt ``frac_invalid_left_1deg`` for a limb before issue 38:
  :data:`RENAMED_METRICS`);
- ``mean_violation_deg`` / ``max_violation_deg``: that distance over all postures and joints;
- ``valid_moved_deg``: mean, over valid postures, of the largest rotation the model applies to
  any joint (0 for an exact model).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from models import quaternion as quat
from models.oracle import end_points

#: Metric names renamed, old → today's: one spelling per metric, a one joint's and a limb's
#: (issue 38). A stored evaluation (an ONNX file's metadata, a registered model's metrics) is
#: read through :func:`current_metric_names`.
RENAMED_METRICS = {"frac_invalid_left_1deg": "frac_invalid_violating_1deg"}


def current_metric_names(metrics: dict) -> dict:
    """``metrics`` with every old name of :data:`RENAMED_METRICS` read as today's (a value
    under both names keeps today's); the same dict when none is old."""
    if not any(k in metrics for k in RENAMED_METRICS):
        return metrics
    out = {}
    for k, v in metrics.items():
        new = RENAMED_METRICS.get(k)
        if new is None:
            out[k] = v
        elif new not in metrics:
            out[new] = v
    return out


def mse(pred: np.ndarray, target: np.ndarray) -> float:
    """Mean squared error over all entries of (N, 4) arrays."""
    d = np.asarray(pred, dtype=np.float64) - np.asarray(target, dtype=np.float64)
    return float(np.mean(d * d))


def endpoint_error(q: np.ndarray, ideal: np.ndarray, learned: np.ndarray) -> np.ndarray:
    """(N,) distance in [0, 2] between unit-limb endpoints corrected by ``ideal`` / ``learned``."""
    a = quat.limb_direction(quat.multiply(ideal, q))
    b = quat.limb_direction(quat.multiply(learned, q))
    return np.linalg.norm(a - b, axis=-1)


def three_d_error_percent(q: np.ndarray, ideal: np.ndarray, learned: np.ndarray) -> np.ndarray:
    """(N,) thesis 3-D error in percent of its maximum 2.0."""
    return 50.0 * endpoint_error(q, ideal, learned)


def angular_error_deg(q: np.ndarray, learned: np.ndarray, projected: np.ndarray) -> np.ndarray:
    """(N,) degrees between the learned corrected limb and the exactly projected limb."""
    a = quat.limb_direction(quat.multiply(learned, q))
    b = quat.limb_direction(projected)
    return np.degrees(quat.angle_between(a, b))


def violation_deg(oracle, corrected: np.ndarray) -> np.ndarray:
    """(N,) degrees by which ``corrected`` orientations lie outside the boundary (0 inside)."""
    return np.degrees(np.maximum(oracle.signed_distance(corrected), 0.0))


def identity_error_deg(learned: np.ndarray) -> np.ndarray:
    """(N,) rotation angle in degrees of corrections that should be the identity."""
    return np.degrees(quat.angle(learned))


def evaluate(
    predict: Callable[[np.ndarray], np.ndarray], oracle, q: np.ndarray
) -> dict[str, float]:
    """All metrics of a learned correction on orientations ``q`` of one joint, or on postures
    of a limb (the module docstring).

    Parameters
    ----------
    predict : callable
        ``(N, 4) raw orientations → (N, 4) unit corrections`` (network, ONNX session, …); a
        limb's: ``(N, J, 4) → (N, J, 4)``.
    oracle : object
        Exact constraint with ``correction``, ``project``, ``signed_distance``, ``is_valid``
        (:class:`models.oracle.ConstraintOracle`); a limb's (the same class, built from the
        limb): with ``evaluate`` and ``axes``.
    q : (N, 4) or (N, J, 4) float
        Held-out orientations (unit, either sign), or a limb's postures.

    Returns
    -------
    dict of float
        ``mse``, ``mean_3d_error_pct``, ``max_3d_error_pct``, ``frac_above_2pct``,
        ``frac_above_7_5pct``, ``mean_angular_error_deg``, ``p99_angular_error_deg``,
        ``frac_invalid_violating_1deg`` (invalid inputs whose corrected limb is > 1° outside),
        ``mean_violation_deg``, ``max_violation_deg``, ``mean_identity_error_deg``,
        ``max_identity_error_deg``, ``n``; a limb's: ``n``, ``valid_fraction``,
        ``end_mean_3d_error_pct``, ``end_max_3d_error_pct``, ``end_p99_direction_error_deg``,
        ``joint_mean_direction_error_deg`` (a list, per joint),
        ``frac_invalid_violating_1deg``, ``mean_violation_deg``, ``max_violation_deg``,
        ``valid_moved_deg``.
    """
    q = np.asarray(q, dtype=np.float64)
    if q.ndim == 3:  # a limb's postures
        return _evaluate_limb(predict, oracle, q)
    ideal = quat.canonical(oracle.correction(q))
    learned = np.asarray(predict(q), dtype=np.float64)
    learned = learned / np.linalg.norm(learned, axis=1, keepdims=True)
    valid = np.asarray(oracle.is_valid(q), dtype=bool)
    e3 = three_d_error_percent(q, ideal, learned)
    ang = angular_error_deg(q, learned, oracle.project(q))
    corrected = quat.multiply(learned, q)
    viol = violation_deg(oracle, corrected)
    ident = identity_error_deg(learned[valid]) if valid.any() else np.zeros(1)
    inv = ~valid
    return {
        "n": float(len(q)),
        "mse": mse(quat.canonical(learned), ideal),
        "mean_3d_error_pct": float(e3.mean()),
        "max_3d_error_pct": float(e3.max()),
        "frac_above_2pct": float(np.mean(e3 > 2.0)),
        "frac_above_7_5pct": float(np.mean(e3 > 7.5)),
        "mean_angular_error_deg": float(ang.mean()),
        "p99_angular_error_deg": float(np.percentile(ang, 99)),
        "frac_invalid_violating_1deg": float(np.mean(viol[inv] > 1.0)) if inv.any() else 0.0,
        "mean_violation_deg": float(viol.mean()),
        "max_violation_deg": float(viol.max()),
        "mean_identity_error_deg": float(ident.mean()),
        "max_identity_error_deg": float(ident.max()),
    }


def _evaluate_limb(predict: Callable[[np.ndarray], np.ndarray], oracle,
                   q: np.ndarray) -> dict[str, float | list[float]]:
    """The limb metrics of the module docstring on postures ``q`` (N, J, 4) float64."""
    n, jn = q.shape[:2]
    exact = oracle.evaluate(q)
    learned = np.asarray(predict(q), dtype=np.float64).reshape(n, jn, 4)
    learned = learned / np.linalg.norm(learned, axis=2, keepdims=True)
    fixed = quat.multiply(learned.reshape(-1, 4), q.reshape(-1, 4)).reshape(n, jn, 4)
    axes = oracle.axes
    e_model = end_points(fixed, axes)
    e_exact = end_points(exact.projected, axes)
    err = np.linalg.norm(e_model - e_exact, axis=1)
    dir_err = np.degrees(quat.angle_between(e_model, e_exact))
    seg_err = np.stack([np.degrees(quat.angle_between(
        quat.rotate(fixed[:, j], axes[j]), quat.rotate(exact.projected[:, j], axes[j])))
        for j in range(jn)], axis=1)
    after = oracle.evaluate(fixed)
    viol = np.degrees(np.maximum(after.distance, 0.0))
    invalid = ~exact.limb_valid
    moved = np.degrees(quat.angle(learned.reshape(-1, 4))).reshape(n, jn).max(axis=1)
    return {
        "n": float(n),
        "valid_fraction": float(exact.limb_valid.mean()),
        "end_mean_3d_error_pct": float(100.0 * err.mean() / jn),
        "end_max_3d_error_pct": float(100.0 * err.max() / jn),
        "end_p99_direction_error_deg": float(np.percentile(dir_err, 99)),
        "joint_mean_direction_error_deg": [float(x) for x in seg_err.mean(axis=0)],
        "frac_invalid_violating_1deg": (float((viol[invalid] > 1.0).any(axis=1).mean())
                                        if invalid.any() else 0.0),
        "mean_violation_deg": float(viol.mean()),
        "max_violation_deg": float(viol.max()),
        "valid_moved_deg": (float(moved[exact.limb_valid].mean())
                            if exact.limb_valid.any() else 0.0),
    }
