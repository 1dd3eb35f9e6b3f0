"""A forearm elbow in a limb (issue 39): a limb file's joint of kind ``forearm`` (flexion plus
pronation–supination), a coupling driven by its flexion, the hierarchical limb oracle and the
limb model's graph on it."""

from __future__ import annotations

import math

import numpy as np
import pytest
import yaml

from models import quaternion as Q
from models.errors import ConstraintError
from models.evaluation import evaluate_model
from models.kinds.forearm import decompose
from models.limb import dump_limb, load_limb, loads_limb
from models.limb_evaluation import (
    HELD_OUT_FOREARM_SEED,
    held_out_forearm_arms,
    held_out_postures,
    random_limb,
)
from models.limb_model import export_limb_model
from models.onnx_io import load_model
from models.oracle import ConstraintOracle

X = np.array([1.0, 0.0, 0.0])
Z = np.array([0.0, 0.0, 1.0])


def _cone(centre, radius, twist):
    return {"swing": {"cone": {"centre": centre, "radius_deg": radius}},
            "twist": {"min_deg": twist[0], "max_deg": twist[1]}}


def arm_doc(axis=(0, 0, 1), limb_axis=None):
    """An arm: the shoulder's cone and twist at three keyframes of the elbow's flexion, a
    forearm elbow (flexion 0..140, rotation −80..70), a two-axis wrist."""
    elbow = {"kind": "forearm", "forearm": {
        "flexion": {"axis": list(axis), "min_deg": 0, "max_deg": 140},
        "rotation": {"min_deg": -80, "max_deg": 70}}}
    if limb_axis is not None:
        elbow["limb_axis"] = list(limb_axis)
    return {"name": "forearm-arm", "limb": "arm", "side": "left", "joints": [
        {"name": "shoulder", "parent": "thorax", "child": "upper-arm", "coupled": {
            "by": "elbow", "keyframes": [
                {"at_deg": 0, "constraint": _cone([1, 0, 0], 40, (-30, 40))},
                {"at_deg": 70, "constraint": _cone([0.8, 0.6, 0], 60, (-40, 50))},
                {"at_deg": 140, "constraint": _cone([0.5, 0.8, 0.3], 75, (-50, 60))}]}},
        {"name": "elbow", "parent": "upper-arm", "child": "forearm", "constraint": elbow},
        {"name": "wrist", "parent": "forearm", "child": "hand", "constraint": {
            "kind": "two-axis", "swing": {"cone": {"centre": [1, 0, 0.2], "radius_deg": 35}},
            "twist": {"min_deg": -5, "max_deg": 5}}}]}


def _postures(n, seed=0, joints=3):
    return Q.random_quaternions(n * joints, np.random.default_rng(seed)).reshape(n, joints, 4)


def test_a_forearm_elbow_round_trips(tmp_path):
    limb = loads_limb(yaml.safe_dump(arm_doc()))
    assert limb.joints[1].kind == "forearm" and limb.joints[0].coupling.by == "elbow"
    again = loads_limb(limb.to_yaml())
    assert again.to_dict() == limb.to_dict()
    assert again.content_hash() == limb.content_hash()
    dump_limb(limb, tmp_path / "arm.yaml")
    assert load_limb(tmp_path / "arm.yaml").to_dict() == limb.to_dict()
    assert "forearm" in limb.summary()


@pytest.mark.parametrize(("mutate", "message"), [
    (lambda d: d["joints"][1]["constraint"]["forearm"]["flexion"].update(axsi=[0, 0, 1]),
     "joints[1].constraint.forearm.flexion.axsi: unknown key 'axsi' (did you mean 'axis'?)"),
    (lambda d: d["joints"][1]["constraint"]["forearm"].update(rotaton={}),
     "joints[1].constraint.forearm.rotaton: unknown key 'rotaton' (did you mean 'rotation'?)"),
    (lambda d: d["joints"][1]["constraint"].update(twist={"min_deg": 0, "max_deg": 1}),
     "joints[1].constraint.twist: a forearm joint has no swing or twist limits"),
    (lambda d: d["joints"][0]["coupled"].update(by="wrist"),
     "a coupling follows a hinge's angle or a forearm's flexion; 'wrist' is a two-axis joint"),
])
def test_bad_forearm_limbs_name_the_field(mutate, message):
    doc = arm_doc()
    mutate(doc)
    with pytest.raises(ConstraintError) as err:
        loads_limb(yaml.safe_dump(doc), source="arm.yaml")
    assert message in str(err.value) and "\n" not in str(err.value)


def test_a_forearm_is_not_a_keyframe():
    doc = arm_doc()
    elbow = doc["joints"][1]["constraint"]
    doc["joints"][1] = {"name": "elbow", "parent": "upper-arm", "child": "forearm",
                        "coupled": {"by": "shoulder", "keyframes": [
                            {"at_deg": 0, "constraint": elbow},
                            {"at_deg": 10, "constraint": elbow}]}}
    with pytest.raises(ConstraintError):
        loads_limb(yaml.safe_dump(doc))


@pytest.mark.parametrize("theta_deg", [-170.0, -30.0, 0.0, 45.0, 139.0, 179.0])
def test_the_flexion_is_the_twist_about_the_axis_when_perpendicular(theta_deg):
    rng = np.random.default_rng(3)
    phi = rng.uniform(-math.pi + 1e-3, math.pi - 1e-3, 200)
    q = Q.multiply(Q.from_axis_angle(Z, np.full(200, math.radians(theta_deg))),
                   Q.from_axis_angle(X, phi))
    assert np.allclose(Q.twist_angle(q, Z), math.radians(theta_deg), atol=1e-12)
    limb = loads_limb(yaml.safe_dump(arm_doc()))
    kind = limb.joints[1].joint_kind
    assert np.allclose(kind.coupling_angle(limb.joints[1].constraint, q),
                       math.radians(theta_deg), atol=1e-12)
    # a flexion axis not perpendicular to the limb axis: the twist about it is not θ, the
    # kind's coupling angle still is
    tilted = loads_limb(yaml.safe_dump(arm_doc(axis=(0.3, 0, 1))))
    c = tilted.joints[1].constraint
    n = np.asarray(c.limits.axis)
    q2 = Q.multiply(Q.from_axis_angle(n, np.full(200, math.radians(theta_deg))),
                    Q.from_axis_angle(X, phi))
    assert np.allclose(Q.wrap_angle(c.joint_kind.coupling_angle(c, q2)
                                    - math.radians(theta_deg)), 0.0, atol=1e-9)
    if theta_deg != 0.0:
        assert not np.allclose(Q.twist_angle(q2, n), math.radians(theta_deg), atol=1e-3)


@pytest.mark.parametrize("axis", [(0, 0, 1), (0.3, 0, 1)])
def test_the_oracle_is_the_forearms_and_the_hierarchy(axis):
    limb = loads_limb(yaml.safe_dump(arm_doc(axis=axis)))
    oracle = ConstraintOracle(limb)
    q = _postures(3000, seed=5)
    r = oracle.evaluate(q)
    # the elbow: the single-joint forearm oracle (to the limb's second rounding to unit)
    single = ConstraintOracle(limb.joints[1].constraint).evaluate(q[:, 1])
    assert np.allclose(r.correction[:, 1], single.correction, atol=1e-12)
    assert np.array_equal(r.valid[:, 1], single.valid)
    # the shoulder judged at the corrected elbow's flexion
    c = limb.joints[1].constraint
    theta = decompose(r.projected[:, 1], c.limits.axis, c.limb_axis)[0]
    assert np.array_equal(r.coupling_angle[:, 0], theta)
    lo, hi = c.limits.flexion
    assert (theta >= lo - 1e-9).all() and (theta <= hi + 1e-9).all()
    cp = limb.joints[0].coupling
    for i in range(0, 3000, 150):
        at = ConstraintOracle(cp.at(math.degrees(theta[i]))).evaluate(q[i, 0])
        assert np.allclose(r.correction[i, 0], at.correction, atol=1e-9)
        assert r.valid[i, 0] == at.valid
    # corrected: valid in every joint, and correcting again changes nothing
    again = oracle.evaluate(r.projected)
    assert again.valid.all()
    assert np.allclose(np.abs(again.correction[..., 0]), 1.0, atol=1e-12)


def test_a_valid_arm_is_left_alone():
    limb = random_limb(HELD_OUT_FOREARM_SEED - 1, "arm", forearm=True)  # a tuning seed
    oracle = ConstraintOracle(limb)
    q = held_out_postures(limb, 600, 2, oracle=oracle)
    valid = oracle.evaluate(q).valid.all(axis=1)
    assert valid.sum() >= 200
    assert np.allclose(oracle.correction(q[valid])[..., 0], 1.0, atol=0)


def test_held_out_forearm_arms_are_their_own_family():
    arms = held_out_forearm_arms(2)
    assert list(arms) == [f"forearm-arm-{HELD_OUT_FOREARM_SEED}",
                          f"forearm-arm-{HELD_OUT_FOREARM_SEED + 1}"]
    for limb in arms.values():
        assert [j.kind for j in limb.joints] == ["ball", "forearm", "two-axis"]
        assert limb.joints[0].coupling.by == "elbow"
    # the same draws as the hinge arm of the seed: the shoulder's limits are that arm's
    hinge = random_limb(HELD_OUT_FOREARM_SEED, "arm")
    forearm = arms[f"forearm-arm-{HELD_OUT_FOREARM_SEED}"]
    assert forearm.joints[0].to_dict() == hinge.joints[0].to_dict()
    with pytest.raises(ValueError):
        random_limb(1, "leg", forearm=True)


def _angles(a, b):
    return np.degrees(Q.angle(Q.multiply(a.reshape(-1, 4), Q.conjugate(b.reshape(-1, 4)))))


@pytest.mark.parametrize("axis", [(0, 0, 1), (0.3, 0, 1)])
def test_the_graph_gives_the_oracles_corrections(axis, tmp_path):
    limb = loads_limb(yaml.safe_dump(arm_doc(axis=axis)))
    oracle = ConstraintOracle(limb)
    model = load_model(export_limb_model(limb, tmp_path / "arm.onnx"), limb)
    q = held_out_postures(limb, 3000, 7, oracle=oracle)  # uniform, near boundaries, valid
    exact = oracle.correction(q)
    got = model.correction(q).astype(np.float64)
    diff = _angles(got, exact).reshape(-1, 3)
    assert np.percentile(diff, 99, axis=0).max() < 0.01
    # near a corner two edges tie to float32 precision: both nearly as near (the corrections'
    # angles agree), the projections a little apart
    assert diff.max() < 0.5
    dist = np.degrees(Q.angle(got.reshape(-1, 4))) - np.degrees(Q.angle(exact.reshape(-1, 4)))
    assert np.abs(dist).max() < 0.01
    assert (got[..., 0] >= 0).all()
    r = evaluate_model(model, limb, q=q, oracle=oracle)
    assert r["frac_invalid_violating_1deg"] == 0.0 and r["max_violation_deg"] < 0.05
    assert r["valid_moved_deg"] < 0.01 and r["end_mean_3d_error_pct"] < 0.005
    # one posture a call (the edges skipped where the elbow's optimum is within its
    # intervals): the batch's answers
    one = np.stack([model.correct_one(p) for p in q[:300]]).astype(np.float64)
    assert _angles(one, got[:300]).max() < 1e-3


@pytest.mark.parametrize("limits", [((0, 140), (-80, 70)), ((-180, 180), (-90, 90)),
                                    ((-170, 170), (-180, 180)), ((30, 30), (0, 0)),
                                    ((-120, 120), (-10, 10))])
def test_the_graph_of_one_forearm_joint_near_its_boundary(limits, tmp_path):
    (f_lo, f_hi), (r_lo, r_hi) = limits
    doc = {"name": "elbow-only", "joints": [
        {"name": "elbow", "parent": "upper-arm", "child": "forearm", "constraint": {
            "kind": "forearm", "forearm": {
                "flexion": {"axis": [0, 0, 1], "min_deg": f_lo, "max_deg": f_hi},
                "rotation": {"min_deg": r_lo, "max_deg": r_hi}}}}]}
    limb = loads_limb(yaml.safe_dump(doc))
    oracle = ConstraintOracle(limb)
    model = load_model(export_limb_model(limb, tmp_path / "elbow.onnx"), limb)
    rng = np.random.default_rng(11)
    n = 4000
    # on and near the set, angles near the ends; and uniform orientations
    th = np.radians(rng.choice([f_lo, f_hi], n) + rng.normal(0, 3, n))
    ph = np.radians(rng.choice([r_lo, r_hi], n) + rng.normal(0, 3, n))
    near = Q.multiply(Q.from_axis_angle(Z, th), Q.from_axis_angle(X, ph))
    off = Q.from_axis_angle(Q.random_unit_vectors(n, rng), np.radians(rng.uniform(0, 3, n)))
    near = np.where((rng.random(n) < 0.5)[:, None], near, Q.multiply(off, near))
    q = np.concatenate([near, Q.random_quaternions(n, rng)])[:, None, :]
    exact = oracle.correction(q)
    got = model.correction(q).astype(np.float64)
    diff = _angles(got, exact)
    assert np.percentile(diff, 99) < 0.01
    dist = np.degrees(Q.angle(got.reshape(-1, 4))) - np.degrees(Q.angle(exact.reshape(-1, 4)))
    assert np.abs(dist).max() < 0.01
    assert np.isfinite(got).all()
