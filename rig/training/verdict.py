"""One evaluation, one verdict: the targets a model's held-out metrics are judged against, the
one function that judges them (:func:`evaluation_verdict`), and the evaluation stored with a
registered model (:func:`evaluation_record`, :func:`stored_evaluation`).

Wherever a model's accuracy is shown — ``rig demo``'s evaluate stage, the shoulder's and the
limb's report — the figures are one evaluation's (the held-out set drawn from ``n`` and
``seed``) and the verdict is :func:`evaluation_verdict` of them. The demo registers its
evaluation with the model in the store; a report on that model shows the stored evaluation
rather than drawing another held-out set (two sets gave two verdicts near a target: the arm
demo's evaluate stage WARN at a p99 end-point direction error of 3.08°, its report "met" at
2.78° on another set).

Targets: a single joint's model, issue 9 (:data:`MODEL_TARGETS`); a limb model, issue 20
(:data:`rig.training.limb.LIMB_TARGETS`). ``rig train``'s enforcement warning uses two of issue
9's (:data:`rig.training.train.ENFORCEMENT_TARGETS`, taken from :data:`MODEL_TARGETS`).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

__all__ = ["EVALUATION_KEY", "MODEL_TARGETS", "evaluation_record", "evaluation_verdict",
           "is_limb_evaluation", "model_verdict", "stored_evaluation"]

#: Targets of a single joint's learned model (issue 9), metric → (limit, label, unit).
MODEL_TARGETS: dict[str, tuple[float, str, str]] = {
    "mean_3d_error_pct": (0.8, "mean 3-D error", "%"),
    "frac_invalid_violating_1deg": (0.01, "invalid inputs left > 1° outside", ""),
    "mean_identity_error_deg": (0.2, "mean identity error on valid inputs", "°"),
    "p99_angular_error_deg": (5.0, "p99 direction error", "°"),
}

#: The key of a registered model's metrics (``store.models.add``) that says which
#: evaluation they are: ``{"n", "seed", "by"}``.
EVALUATION_KEY = "evaluation"


def model_verdict(metrics: Mapping[str, float]) -> tuple[bool, str]:
    """(all targets met, one-line verdict) of a single joint's held-out metrics against
    :data:`MODEL_TARGETS`; a metric absent is not judged."""
    missed = []
    for key, (limit, label, unit) in MODEL_TARGETS.items():
        v = metrics.get(key)
        if v is None:
            continue
        if key.startswith("frac_"):
            if v > limit:
                missed.append(f"{label} {100 * v:.2f} % > {100 * limit:g} %")
        elif v > limit:
            missed.append(f"{label} {v:.3g}{unit} > {limit:g}{unit}")
    if missed:
        return False, "warning: misses targets: " + "; ".join(missed)
    return True, ("ok: within targets (mean 3-D error ≤ 0.8 %, invalid inputs left > 1° "
                  "outside ≤ 1 %, identity error ≤ 0.2°, p99 direction error ≤ 5°)")


def is_limb_evaluation(metrics: Mapping[str, Any]) -> bool:
    """Are these a limb model's metrics (:func:`models.limb_evaluation.evaluate_limb_model`)
    rather than a single joint's (:func:`models.evaluation.evaluate_model`)?"""
    from rig.training.limb import LIMB_TARGETS

    return any(k in metrics for k in LIMB_TARGETS) and not any(k in metrics
                                                               for k in MODEL_TARGETS)


def evaluation_verdict(metrics: Mapping[str, Any], *,
                       limb: bool | None = None) -> tuple[bool, str]:
    """(all targets met, one-line verdict) of one evaluation's metrics, a single joint's
    (:func:`model_verdict`) or a limb's (:data:`rig.training.limb.LIMB_TARGETS`; ``limb``
    None: told by the metrics, :func:`is_limb_evaluation`): the verdict every place that shows
    the evaluation shows."""
    if not (is_limb_evaluation(metrics) if limb is None else limb):
        return model_verdict(metrics)
    from rig.training.limb import LIMB_TARGETS, limb_warnings

    misses = limb_warnings({k: v for k, v in metrics.items() if k in LIMB_TARGETS})
    if misses:
        return False, "warning: misses targets: " + "; ".join(misses)
    return True, ("ok: within the limb model's targets (end-point mean 3-D error ≤ 0.5 % of "
                  "the limb's length, invalid inputs left > 1° outside ≤ 1 %, valid inputs "
                  "moved ≤ 0.1° mean, p99 end-point direction error ≤ 3°)")


def evaluation_record(metrics: Mapping[str, Any], *, n: int, seed: int, by: str) -> dict:
    """The metrics to register with a model (``store.models.add``): the
    evaluation's own, and under :data:`EVALUATION_KEY` which one it was (``n`` held-out inputs
    drawn with ``seed``, computed ``by``)."""
    return {**metrics, EVALUATION_KEY: {"n": int(n), "seed": int(seed), "by": str(by)}}


def stored_evaluation(row: Mapping[str, Any] | None) -> tuple[dict, dict] | None:
    """``(metrics, which)`` of the evaluation stored with a registered model (a row of
    ``store.models.list``), None when it holds none (a model registered with its
    training's metrics only)."""
    if row is None:
        return None
    metrics = dict(row.get("metrics") or {})
    which = metrics.pop(EVALUATION_KEY, None)
    if not isinstance(which, Mapping) or "n" not in which or "seed" not in which:
        return None
    return metrics, dict(which)
