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

Targets: one table (:data:`MODEL_TARGETS`), one spelling per metric, for a single joint's
model (issue 9) and a limb model (issue 20) alike: each target says whose evaluation gives its
metric (``invalid inputs left > 1° outside``, ``frac_invalid_violating_1deg``, is both's). ``rig
train``'s enforcement warning (:func:`rig.training.train.enforcement_warnings`) reads two of
them. A stored evaluation that spells a metric the old way (a limb's
``frac_invalid_left_1deg`` before issue 38) is read as today's
(:func:`models.metrics.current_metric_names`).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, NamedTuple

from models.metrics import current_metric_names
from rig.training.limb import LIMB_METRIC_LABELS

__all__ = ["EVALUATION_KEY", "MODEL_TARGETS", "Target", "evaluation_record",
           "evaluation_verdict", "missed_targets", "stored_evaluation", "targets_for"]


class Target(NamedTuple):
    """A target of a model's held-out metric: met when the metric is ``≤ limit``; ``label``
    and ``unit`` are a single joint's verdict's words (a limb's are the lines ``rig train``
    prints, :data:`rig.training.limb.LIMB_METRIC_LABELS`); ``of`` says whose evaluation gives
    the metric: ``"joint"``, ``"limb"`` or ``"joint limb"``."""

    limit: float
    label: str
    unit: str
    of: str


#: Every target of a model's held-out metrics, metric → :class:`Target`: a single joint's
#: (issue 9) and a limb's (issue 20), each in its verdict's order.
MODEL_TARGETS: dict[str, Target] = {
    "mean_3d_error_pct": Target(0.8, "mean 3-D error", "%", "joint"),
    "end_mean_3d_error_pct": Target(0.5, "end-point mean 3-D error (% of limb length)", "",
                                    "limb"),
    "frac_invalid_violating_1deg": Target(0.01, "invalid inputs left > 1° outside", "",
                                          "joint limb"),
    "mean_identity_error_deg": Target(0.2, "mean identity error on valid inputs", "°", "joint"),
    "valid_moved_deg": Target(0.1, "valid postures moved (mean deg)", "", "limb"),
    "p99_angular_error_deg": Target(5.0, "p99 direction error", "°", "joint"),
    "end_p99_direction_error_deg": Target(3.0, "99th pct end-point direction error (deg)", "",
                                          "limb"),
}

_WITHIN = {
    "joint": ("ok: within targets (mean 3-D error ≤ 0.8 %, invalid inputs left > 1° "
              "outside ≤ 1 %, identity error ≤ 0.2°, p99 direction error ≤ 5°)"),
    "limb": ("ok: within the limb model's targets (end-point mean 3-D error ≤ 0.5 % of "
             "the limb's length, invalid inputs left > 1° outside ≤ 1 %, valid inputs "
             "moved ≤ 0.1° mean, p99 end-point direction error ≤ 3°)"),
}


def targets_for(limb: bool) -> dict[str, Target]:
    """The targets judging a limb model's evaluation (``limb``) or a single joint's, in
    their verdict's order."""
    whose = "limb" if limb else "joint"
    return {k: t for k, t in MODEL_TARGETS.items() if whose in t.of.split()}


def _is_limb(metrics: Mapping[str, Any]) -> bool:
    """Are these a limb model's metrics rather than a single joint's (a metric only a limb's
    evaluation gives, none only a joint's)?"""
    only = {w: [k for k, t in MODEL_TARGETS.items() if t.of == w] for w in ("joint", "limb")}
    return (any(k in metrics for k in only["limb"])
            and not any(k in metrics for k in only["joint"]))


def missed_targets(metrics: Mapping[str, Any], *, limb: bool | None = None) -> list[str]:
    """The targets one evaluation's metrics miss, one phrase each (empty when it meets them;
    a metric absent is not judged): a single joint's or a limb's (``limb`` None: told by the
    metrics), in its verdict's words."""
    metrics = current_metric_names(dict(metrics))
    limb = _is_limb(metrics) if limb is None else limb
    out = []
    for key, (limit, label, unit, _) in targets_for(limb).items():
        v = metrics.get(key)
        if v is None or not v > limit:
            continue
        pct = key.startswith("frac_")
        if limb:  # the words `rig train` prints for a limb
            got, want, u = (100 * v, 100 * limit, " %") if pct else (v, limit, "")
            out.append(f"{LIMB_METRIC_LABELS[key]} is {got:.3g}{u}, above the target "
                       f"{want:g}{u}")
        elif pct:
            out.append(f"{label} {100 * v:.2f} % > {100 * limit:g} %")
        else:
            out.append(f"{label} {v:.3g}{unit} > {limit:g}{unit}")
    return out


def evaluation_verdict(metrics: Mapping[str, Any], *,
                       limb: bool | None = None) -> tuple[bool, str]:
    """(all targets met, one-line verdict) of one evaluation's metrics, a single joint's or a
    limb's (``limb`` None: told by the metrics) against :data:`MODEL_TARGETS`: the verdict
    every place that shows the evaluation shows."""
    metrics = current_metric_names(dict(metrics))
    limb = _is_limb(metrics) if limb is None else limb
    missed = missed_targets(metrics, limb=limb)
    if missed:
        return False, "warning: misses targets: " + "; ".join(missed)
    return True, _WITHIN["limb" if limb else "joint"]


#: The key of a registered model's metrics (``store.models.add``) that says which
#: evaluation they are: ``{"n", "seed", "by"}``.
EVALUATION_KEY = "evaluation"


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
    metrics = current_metric_names(dict(row.get("metrics") or {}))
    which = metrics.pop(EVALUATION_KEY, None)
    if not isinstance(which, Mapping) or "n" not in which or "seed" not in which:
        return None
    return metrics, dict(which)
