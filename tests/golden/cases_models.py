"""Golden cases: exact oracles, ONNX models, evaluation metrics and verdicts (joint and limb)."""

from __future__ import annotations

import numpy as np
import yaml

from models.constraint import JointConstraint
from models.evaluation import evaluate_model, held_out_orientations
from models.field import FieldModel
from models.limb import loads_limb
from models.limb_evaluation import held_out_postures, random_limb
from models.limb_model import export_limb_model
from models.metrics import RENAMED_METRICS, current_metric_names
from models.onnx_io import export_onnx, load_model
from models.oracle import ConstraintOracle
from models.shapes import SHAPES, load_shape
from rig.sim.patients import anatomical_limb
from rig.training.joint import enforcement_warnings
from rig.training.limb import limb_metric_lines
from rig.training.verdict import evaluation_verdict, missed_targets, targets_for
from tests.golden.harness import case, normalise, tmpdir
from tests.golden.util import jtext, onnx_bytes, prefixed, quats

N_BATCH = 2000
N_SINGLE = 50

#: The joint constraints of the oracle cases: every joint kind and the thesis shapes.
BY_SWING = {
    "name": "bs", "swing": {"cone": {"centre": [1, 0, 0], "radius_deg": 70}},
    "twist": {"min_deg": -80, "max_deg": 90, "by_swing": {"bandwidth_deg": 25, "points": [
        {"direction": [1, 0, 0], "min_deg": -40, "max_deg": 60},
        {"direction": [0, 1, 0], "min_deg": -80, "max_deg": 10},
        {"direction": [0, 0, 1], "min_deg": 0, "max_deg": 90}]}}}


def _constraints() -> dict[str, JointConstraint]:
    out = {
        "cone_twist": JointConstraint.cone([0.3, 0.8, 0.2], 55.0, twist=(-60.0, 80.0)),
        "cone_only": JointConstraint.cone([1, 0, 0], 45.0),
        "twist_wraps": JointConstraint.cone([0, 0, 1], 100.0, twist=(170.0, 180.0)),
        "by_swing": JointConstraint.from_dict(BY_SWING),
        "hinge": JointConstraint.hinge_joint((0, 0, 1), -5.0, 140.0),
        "hinge_wraps": JointConstraint.hinge_joint((0, 1, 0), -180.0, 90.0),
        "two_axis": JointConstraint.from_dict({
            "name": "wrist", "kind": "two-axis",
            "swing": {"cone": {"centre": [1, 0.5, 0], "radius_deg": 45}},
            "twist": {"min_deg": -6, "max_deg": 8}}),
    }
    for name in SHAPES:
        s = load_shape(name)
        out[f"shape_{name}"] = s
        out[f"shape_{name}_twist"] = JointConstraint.polygon(
            s.swing.vertices, s.swing.interior, twist=(-45.0, 70.0), name=name)
    return out


def _oracle_outputs(oracle: ConstraintOracle, seed: int) -> dict:
    q = quats(N_BATCH, seed)
    r = oracle.evaluate(q)
    out = {f"batch_{k}": np.asarray(v) for k, v in r.__dict__.items()}
    out["is_valid"] = oracle.is_valid(q)
    one = q[:N_SINGLE]
    singles = [oracle.evaluate(x) for x in one]
    for k in r.__dict__:
        out[f"single_{k}"] = np.stack([np.asarray(getattr(s, k)) for s in singles])
    dp = [oracle.distance_projected_one(*map(float, x)) for x in one]
    out["one_distance"] = np.array([d for d, _ in dp])
    out["one_projected"] = np.array([p for _, p in dp])
    return out


@case("joint")
def case_oracle_joint_kinds() -> dict:
    """ConstraintOracle on 2000 seeded quaternions (batched) and 50 (single path), for every
    joint kind and the five thesis shapes with and without a twist limit."""
    out: dict = {}
    for i, (name, c) in enumerate(_constraints().items()):
        oracle = ConstraintOracle(c)
        out.update(prefixed(name.replace("-", "_"), _oracle_outputs(oracle, 100 + i)))
        if c.hinge is None:
            d = quats(200, 900 + i)[:, 1:]
            d /= np.linalg.norm(d, axis=1, keepdims=True)
            out[f"{name.replace('-', '_')}_swing_distance"] = oracle.swing_distance(d)
            out[f"{name.replace('-', '_')}_nearest_swing_point"] = oracle.nearest_swing_point(d)
            lo, hi = oracle.twist_limits_at(d)
            out[f"{name.replace('-', '_')}_twist_lo"] = np.asarray(lo, dtype=np.float64)
            out[f"{name.replace('-', '_')}_twist_hi"] = np.asarray(hi, dtype=np.float64)
    return out


#: The limb files of the limb cases: the shipped anatomical arm and leg (couplings), a left
#: arm, the four-joint test arm with coupled cones and hinges.
ARM4 = {"name": "cone-arm", "joints": [
    {"name": "shoulder", "parent": "thorax", "child": "upper-arm", "constraint": {
        "swing": {"cone": {"centre": [1, 0, 0], "radius_deg": 70}},
        "twist": {"min_deg": -60, "max_deg": 80}}},
    {"name": "elbow", "parent": "upper-arm", "child": "forearm", "constraint": {
        "kind": "hinge", "hinge": {"axis": [0, 0, 1], "min_deg": 0, "max_deg": 145}}},
    {"name": "wrist", "parent": "forearm", "child": "hand", "coupled": {
        "by": "elbow", "keyframes": [
            {"at_deg": 0, "constraint": {"kind": "two-axis", "swing": {"cone": {
                "centre": [1, 0, 0], "radius_deg": 30}}, "twist": {"min_deg": -4,
                                                                   "max_deg": 4}}},
            {"at_deg": 70, "constraint": {"kind": "two-axis", "swing": {"cone": {
                "centre": [1, 0.5, 0], "radius_deg": 45}}, "twist": {"min_deg": -6,
                                                                     "max_deg": 8}}},
            {"at_deg": 140, "constraint": {"kind": "two-axis", "swing": {"cone": {
                "centre": [1, 1, 0], "radius_deg": 50}}, "twist": {"min_deg": -8,
                                                                   "max_deg": 12}}}]}},
    {"name": "finger", "parent": "hand", "child": "finger", "coupled": {
        "by": "elbow", "keyframes": [
            {"at_deg": 0, "constraint": {"kind": "hinge", "hinge": {
                "axis": [0, 0, 1], "min_deg": 0, "max_deg": 60}}},
            {"at_deg": 100, "constraint": {"kind": "hinge", "hinge": {
                "axis": [0, 0, 1], "min_deg": 20, "max_deg": 100}}}]}}]}


def _limbs() -> dict:
    return {"arm": anatomical_limb(7, "arm"), "leg": anatomical_limb(11, "leg"),
            "left_arm": anatomical_limb(5, "arm", "left"),
            "cone_arm": loads_limb(yaml.safe_dump(ARM4))}


@case("limb")
def case_oracle_limbs() -> dict:
    """ConstraintOracle on seeded postures [N, J, 4] of the anatomical arm and leg (couplings), a
    left arm and the four-joint coupled test arm: every field, per-joint validity, end points;
    the limb files' text."""
    out: dict = {}
    for i, (name, limb) in enumerate(_limbs().items()):
        oracle = ConstraintOracle(limb)
        jn = len(limb.joints)
        q = quats(1000 * jn, 300 + i).reshape(1000, jn, 4)
        r = oracle.evaluate(q)
        for k, v in r.__dict__.items():
            out[f"{name}_{k}"] = np.asarray(v)
        out[f"{name}_limb_valid"] = r.limb_valid
        out[f"{name}_is_valid"] = oracle.is_valid(q)
        out[f"{name}_end_points"] = oracle.end_points(q)
        for j in range(jn):
            out[f"{name}_joint{j}_is_valid"] = oracle.joint_is_valid(q, j)
        one = oracle.evaluate(q[0])
        for k, v in one.__dict__.items():
            out[f"{name}_one_{k}"] = np.asarray(v)
        out[f"{name}_yaml"] = limb.to_yaml()
    return out


# -- models ----------------------------------------------------------------------------------
def _field_model(constraint: JointConstraint, grid: int = 60) -> dict:
    f = FieldModel.from_constraint(constraint, grid=grid)
    with tmpdir() as d:
        p = export_onnx(f, d / "f.onnx", constraint_yaml=constraint.to_yaml(),
                        training_data_sha256=f.content_hash(), metrics={"x": 1.0})
        raw = onnx_bytes(p, d)
        m = load_model(p, expected_constraint=constraint)
        q = quats(2000, 8)
        out = {"onnx": raw, "predict": f.predict(q[:500]), "correction": m.correction(q),
               "correction_neg": m.correction(-q),
               "correct_one": np.stack([m.correct_one(tuple(map(float, x))) for x in q[:20]]),
               "corrected": m.corrected(q[:200]),
               "metadata": normalise(jtext(dict(sorted(m.metadata.items()))), d),
               "metrics": jtext(m.metrics), "network_info": normalise(jtext(m.network_info), d),
               "constraint_yaml": m.constraint_yaml, "content_hash": f.content_hash()}
        ev = evaluate_model(m, constraint, n=2000, seed=5)
        out["evaluation"] = jtext(ev)
        out["verdict"] = jtext(evaluation_verdict(ev))
    return out


@case("joint")
def case_model_field_cone() -> dict:
    """A field model of a cone with a twist limit, exported to ONNX, loaded as a
    CorrectionModel: the file's bytes, outputs, metadata, its held-out evaluation."""
    return _field_model(JointConstraint.cone([0, 0, 1], 35.0, twist=(-45.0, 70.0)))


@case("joint")
def case_model_field_polygon() -> dict:
    """A field model of the c-shape polygon with a swing-dependent twist table."""
    s = load_shape("c-shape").swing
    return _field_model(JointConstraint.polygon(s.vertices, s.interior, twist=(-20.0, 110.0),
                                                name="c-shape"))


def _limb_model(limb) -> dict:
    oracle = ConstraintOracle(limb)
    with tmpdir() as d:
        p = export_limb_model(limb, d / "limb.onnx")
        raw = onnx_bytes(p, d)
        m = load_model(p, limb)
        q = held_out_postures(limb, 1000, 11, oracle=oracle)
        out = {"onnx": raw, "postures": q, "correction": m.correction(q),
               "correct_one": np.stack([m.correct_one(x) for x in q[:20]]),
               "metadata": normalise(jtext(dict(sorted(m.metadata.items()))), d),
               "joints": jtext(m.joints)}
        ev = evaluate_model(m, limb, q=q, oracle=oracle)
        out["evaluation"] = jtext(_recorded_names(ev))
        out["verdict"] = jtext(evaluation_verdict(ev))
        out["metric_lines"] = "\n".join(limb_metric_lines(ev, m.joints))
    return out


@case("limb")
def case_model_limb_leg() -> dict:
    """The geometric limb model of the anatomical leg (couplings): ONNX bytes, corrections of
    held-out postures, metadata, evaluation and verdict."""
    return _limb_model(anatomical_limb(11, "leg"))


@case("limb")
def case_model_limb_random_arm() -> dict:
    """The geometric limb model of a random evaluation arm (models.limb_evaluation)."""
    return _limb_model(random_limb(9_099, "arm"))


@case("joint")
def case_held_out_orientations() -> dict:
    """Held-out orientations of a polygon constraint and the evaluation of the exact oracle as
    a model on them."""
    c = load_shape("original")
    q = held_out_orientations(c, 1000, 3)
    oracle = ConstraintOracle(c)
    ev = evaluate_model(oracle.correction, c, q=q)
    return {"q": q, "evaluation": jtext(ev), "verdict": jtext(evaluation_verdict(ev))}


def _recorded_names(metrics: dict) -> dict:
    """``metrics`` in the spelling the golden data was recorded with: a limb's
    ``frac_invalid_violating_1deg`` was ``frac_invalid_left_1deg`` before issue 38 (an
    announced rename, :data:`models.metrics.RENAMED_METRICS`); the values are compared bit for
    bit, the key in its old place."""
    old = {new: old for old, new in RENAMED_METRICS.items()}
    return {old.get(k, k): v for k, v in metrics.items()}


# -- targets and verdicts --------------------------------------------------------------------
def _metric_sets() -> tuple[list[dict], list[dict]]:
    joint_ok = {"mean_3d_error_pct": 0.1, "frac_invalid_violating_1deg": 0.0,
                "mean_identity_error_deg": 0.01, "p99_angular_error_deg": 1.0,
                "max_violation_deg": 0.4}
    joint_bad = {"mean_3d_error_pct": 1.7, "frac_invalid_violating_1deg": 0.034,
                 "mean_identity_error_deg": 0.3, "p99_angular_error_deg": 7.25,
                 "max_violation_deg": 12.5}
    limb_ok = {"end_mean_3d_error_pct": 0.2, "frac_invalid_left_1deg": 0.0,
               "valid_moved_deg": 0.05, "end_p99_direction_error_deg": 2.0,
               "mean_violation_deg": 0.0, "max_violation_deg": 0.1}
    limb_bad = {"end_mean_3d_error_pct": 0.8, "frac_invalid_left_1deg": 0.02,
                "valid_moved_deg": 0.25, "end_p99_direction_error_deg": 3.08,
                "mean_violation_deg": 0.3, "max_violation_deg": 4.0}
    edge = {"mean_3d_error_pct": 0.8, "frac_invalid_violating_1deg": 0.01}
    return [joint_ok, joint_bad, edge, {"mean_3d_error_pct": 0.9}, {}], [limb_ok, limb_bad]


@case("joint")
def case_verdicts_joint() -> dict:
    """The single joint's target tables (MODEL_TARGETS, ENFORCEMENT_TARGETS) and verdicts
    (model_verdict, evaluation_verdict, enforcement_warnings) on fixed metric dicts.

    Issue 38: one table (``MODEL_TARGETS`` of :class:`rig.training.verdict.Target`) and one
    verdict; the recorded tables are its single joint's view, ``model_verdict`` is
    ``evaluation_verdict(limb=False)``."""
    joint_sets, _ = _metric_sets()
    joint = {k: (t.limit, t.label, t.unit) for k, t in targets_for(limb=False).items()}
    enforcement = {k: joint[k][0] for k in ("frac_invalid_violating_1deg", "mean_3d_error_pct")}
    rows = []
    for m in joint_sets:
        rows.append({"metrics": m, "model_verdict": evaluation_verdict(m, limb=False),
                     "evaluation_verdict": evaluation_verdict(m),
                     "evaluation_verdict_joint": evaluation_verdict(m, limb=False),
                     "enforcement_warnings": enforcement_warnings(m)})
    return {"MODEL_TARGETS": jtext(joint),
            "ENFORCEMENT_TARGETS": jtext(enforcement), "rows": jtext(rows)}


@case("limb")
def case_verdicts_limb() -> dict:
    """The limb model's target table (LIMB_TARGETS) and verdicts on fixed metric dicts (in
    the recorded, pre-issue-38 spelling: read as today's).

    Issue 38: the recorded table is the one table's limb view (in the recorded spelling),
    ``limb_warnings`` is ``missed_targets(limb=True)``."""
    _, limb_sets = _metric_sets()
    rows = []
    for m in limb_sets:
        rows.append({"metrics": m, "evaluation_verdict": evaluation_verdict(m),
                     "evaluation_verdict_limb": evaluation_verdict(m, limb=True),
                     "limb_warnings": missed_targets(m, limb=True),
                     "metric_lines": limb_metric_lines(current_metric_names(m),
                                                       ["a", "b", "c"])})
    limb = _recorded_names({k: t.limit for k, t in targets_for(limb=True).items()})
    return {"LIMB_TARGETS": jtext(limb), "rows": jtext(rows)}
