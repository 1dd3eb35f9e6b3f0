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
train``'s enforcement warning (:func:`rig.training.joint.enforcement_warnings`) reads two of
them. A stored evaluation that spells a metric the old way (a limb's
``frac_invalid_left_1deg`` before issue 38) is read as today's
(:func:`models.metrics.current_metric_names`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from types import MappingProxyType
from typing import Any, NamedTuple

from models.metrics import current_metric_names
from rig.training.limb import LIMB_METRIC_LABELS

__all__ = ["EVALUATION_KEY", "JOINT_JUDGING", "LIMB_JUDGING", "MODEL_TARGETS", "Judging",
           "Target", "evaluation_record", "evaluation_verdict", "judging", "missed_targets",
           "stored_evaluation", "targets_for"]


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


def _joint_miss(key: str, v: float, t: Target) -> str:
    """A single joint's missed target, in its verdict's words."""
    if key.startswith("frac_"):
        return f"{t.label} {100 * v:.2f} % > {100 * t.limit:g} %"
    return f"{t.label} {v:.3g}{t.unit} > {t.limit:g}{t.unit}"


def _limb_miss(key: str, v: float, t: Target) -> str:
    """A limb's missed target, in the words ``rig train`` prints for a limb."""
    got, want, u = (100 * v, 100 * t.limit, " %") if key.startswith("frac_") else (v, t.limit, "")
    return f"{LIMB_METRIC_LABELS[key]} is {got:.3g}{u}, above the target {want:g}{u}"


class Judging(NamedTuple):
    """What differs between judging a single joint's evaluation and a limb's: whose targets
    (``whose``, a :attr:`Target.of` word), how a missed one is phrased (``miss(metric, value,
    target)``) and the verdict when none is missed (``within``)."""

    whose: str
    miss: Callable[[str, float, Target], str]
    within: str

    def targets(self) -> dict[str, Target]:
        """The targets judging this evaluation, in its verdict's order."""
        return {k: t for k, t in MODEL_TARGETS.items() if self.whose in t.of.split()}

    def missed(self, metrics: Mapping[str, Any]) -> list[str]:
        """The targets ``metrics`` (today's names) miss, one phrase each; a metric absent is
        not judged."""
        return [self.miss(key, metrics[key], target) for key, target in self.targets().items()
                if metrics.get(key) is not None and metrics[key] > target.limit]


#: A single joint's model's evaluation (issue 9).
JOINT_JUDGING = Judging("joint", _joint_miss, (
    "ok: within targets (mean 3-D error ≤ 0.8 %, invalid inputs left > 1° outside ≤ 1 %, "
    "identity error ≤ 0.2°, p99 direction error ≤ 5°)"))
#: A limb model's evaluation (issue 20).
LIMB_JUDGING = Judging("limb", _limb_miss, (
    "ok: within the limb model's targets (end-point mean 3-D error ≤ 0.5 % of the limb's "
    "length, invalid inputs left > 1° outside ≤ 1 %, valid inputs moved ≤ 0.1° mean, p99 "
    "end-point direction error ≤ 3°)"))


def judging(metrics: Mapping[str, Any] = MappingProxyType({}), *,
            limb: bool | None = None) -> Judging:
    """The one place that decides whose targets judge an evaluation: a limb's when the caller
    says so (``limb`` True) or, when it does not say (``limb`` None), when the metrics hold a
    metric only a limb's evaluation gives and none only a single joint's; else a single
    joint's. ``limb`` is the caller's word (a report of a limb session, ``rig train`` on a limb
    file); asking it here, once, is what lets every function below judge without asking."""
    if limb is None:  # not said: told by the metrics (a stored evaluation, `rig evaluate`'s)
        only = {w: [k for k, t in MODEL_TARGETS.items() if t.of == w] for w in ("joint", "limb")}
        limb = (any(k in metrics for k in only["limb"])
                and not any(k in metrics for k in only["joint"]))
    return LIMB_JUDGING if limb else JOINT_JUDGING


def targets_for(limb: bool) -> dict[str, Target]:
    """The targets judging a limb model's evaluation (``limb``) or a single joint's, in
    their verdict's order."""
    return judging(limb=limb).targets()


def missed_targets(metrics: Mapping[str, Any], *, limb: bool | None = None) -> list[str]:
    """The targets one evaluation's metrics miss, one phrase each (empty when it meets them;
    a metric absent is not judged): a single joint's or a limb's (``limb`` None: told by the
    metrics, :func:`judging`), in its verdict's words."""
    metrics = current_metric_names(dict(metrics))
    return judging(metrics, limb=limb).missed(metrics)


def evaluation_verdict(metrics: Mapping[str, Any], *,
                       limb: bool | None = None) -> tuple[bool, str]:
    """(all targets met, one-line verdict) of one evaluation's metrics, a single joint's or a
    limb's (``limb`` None: told by the metrics, :func:`judging`) against
    :data:`MODEL_TARGETS`: the verdict every place that shows the evaluation shows."""
    metrics = current_metric_names(dict(metrics))
    judge = judging(metrics, limb=limb)
    missed = judge.missed(metrics)
    if missed:
        return False, "warning: misses targets: " + "; ".join(missed)
    return True, judge.within


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
