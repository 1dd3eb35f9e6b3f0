"""One table of model targets, one verdict (issue 38): a single joint's and a limb's
evaluation judged by :func:`rig.training.verdict.evaluation_verdict` in their own words, and a
metric stored under its old spelling read as today's."""

from __future__ import annotations

from models.metrics import RENAMED_METRICS, current_metric_names
from rig.training.verdict import (
    MODEL_TARGETS,
    evaluation_record,
    evaluation_verdict,
    missed_targets,
    stored_evaluation,
    targets_for,
)

JOINT = {"mean_3d_error_pct": 0.3, "frac_invalid_violating_1deg": 0.0,
         "mean_identity_error_deg": 0.01, "p99_angular_error_deg": 1.0}
LIMB = {"end_mean_3d_error_pct": 0.2, "frac_invalid_violating_1deg": 0.0,
        "valid_moved_deg": 0.01, "end_p99_direction_error_deg": 1.0,
        "joint_mean_direction_error_deg": [0.1, 0.0]}


def test_one_table_one_spelling_each_kind_in_its_order():
    assert list(targets_for(limb=False)) == ["mean_3d_error_pct", "frac_invalid_violating_1deg",
                                             "mean_identity_error_deg", "p99_angular_error_deg"]
    assert list(targets_for(limb=True)) == ["end_mean_3d_error_pct",
                                            "frac_invalid_violating_1deg", "valid_moved_deg",
                                            "end_p99_direction_error_deg"]
    assert not set(RENAMED_METRICS) & set(MODEL_TARGETS)


def test_the_verdicts_words_for_a_joint_and_a_limb():
    assert evaluation_verdict(JOINT) == (True, (
        "ok: within targets (mean 3-D error ≤ 0.8 %, invalid inputs left > 1° outside ≤ 1 %, "
        "identity error ≤ 0.2°, p99 direction error ≤ 5°)"))
    assert evaluation_verdict(LIMB)[1].startswith("ok: within the limb model's targets")
    assert evaluation_verdict({**JOINT, "frac_invalid_violating_1deg": 0.02,
                               "p99_angular_error_deg": 5.3}) == (False, (
        "warning: misses targets: invalid inputs left > 1° outside 2.00 % > 1 %; "
        "p99 direction error 5.3° > 5°"))
    assert missed_targets({**LIMB, "frac_invalid_violating_1deg": 0.025}) == [
        "invalid postures left > 1 deg outside is 2.5 %, above the target 1 %"]


def test_an_old_spelling_is_read_as_todays():
    old = {("frac_invalid_left_1deg" if k == "frac_invalid_violating_1deg" else k):
           (0.5 if k == "frac_invalid_violating_1deg" else v) for k, v in LIMB.items()}
    assert list(current_metric_names(old)) == list(LIMB)  # in the same place
    assert current_metric_names(LIMB) is LIMB
    ok, verdict = evaluation_verdict(old)
    assert not ok and "invalid postures left > 1 deg outside is 50 %" in verdict
    metrics, which = stored_evaluation({"metrics": evaluation_record(old, n=6, seed=1, by="x")})
    assert metrics["frac_invalid_violating_1deg"] == 0.5 and "frac_invalid_left_1deg" not in metrics
    assert which == {"n": 6, "seed": 1, "by": "x"}
