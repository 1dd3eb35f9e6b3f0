"""The limb model (issue 20, part 4): a whole limb's exact corrections compiled into one ONNX
graph — input orientations [N, J, 4], output corrections [N, J, 4] — run by onnxruntime."""

from __future__ import annotations

import os
import stat

import numpy as np
import pytest
import yaml

from models import quaternion as Q
from models.errors import ModelFileError
from models.evaluation import evaluate_model
from models.limb import loads_limb
from models.limb_evaluation import (
    HELD_OUT_LIMB_SEED,
    held_out_postures,
    random_limb,
)
from models.limb_model import FORMAT, export_limb_model
from models.onnx_io import load_model
from models.oracle import ConstraintOracle

ARM = {"name": "cone-arm", "joints": [  # no "limb: arm": the arm has no finger joint
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


@pytest.fixture(scope="module")
def leg_model(tmp_path_factory):
    limb = random_limb(HELD_OUT_LIMB_SEED - 1, "leg")  # a tuning seed
    path = export_limb_model(limb, tmp_path_factory.mktemp("m") / "leg.onnx")
    return limb, ConstraintOracle(limb), load_model(path, limb)


def test_the_graph_gives_the_oracles_corrections_to_float32_precision(leg_model):
    limb, oracle, model = leg_model
    q = held_out_postures(limb, 3000, 11, oracle=oracle)
    r = evaluate_model(model, limb, q=q, oracle=oracle)
    assert r["end_mean_3d_error_pct"] < 0.005
    assert r["end_p99_direction_error_deg"] < 0.02
    assert r["frac_invalid_violating_1deg"] == 0.0 and r["max_violation_deg"] < 0.05
    assert r["valid_moved_deg"] < 0.01
    exact = oracle.correction(q)
    got = model.correction(q).astype(np.float64)
    angle = np.degrees(Q.angle(Q.multiply(got.reshape(-1, 4),
                                          Q.conjugate(exact.reshape(-1, 4)))))
    assert np.percentile(angle, 99) < 0.01
    assert (got[..., 0] >= 0).all()


def test_coupled_cones_and_hinges_and_four_joints(tmp_path):
    limb = loads_limb(yaml.safe_dump(ARM))
    oracle = ConstraintOracle(limb)
    model = load_model(export_limb_model(limb, tmp_path / "arm.onnx"), limb)
    rng = np.random.default_rng(12)
    q = Q.random_quaternions(4 * 4000, rng).reshape(4000, 4, 4)
    # hinges near their axes, bent anywhere from -40° to 180°
    for j in (1, 3):
        q[:, j] = Q.from_axis_angle(np.array([0.0, 0, 1]), np.radians(rng.uniform(-40, 180,
                                                                                   4000)))
    r = evaluate_model(model, limb, q=q, oracle=oracle)
    assert r["end_mean_3d_error_pct"] < 0.005 and r["frac_invalid_violating_1deg"] == 0.0
    assert max(r["joint_mean_direction_error_deg"]) < 0.01


def test_one_posture_metadata_and_file_mode(leg_model, tmp_path):
    limb, oracle, model = leg_model
    q = held_out_postures(limb, 20, 13, oracle=oracle)
    batch = model.correction(q)
    for i in range(5):  # the same graph; float32 kernels may round a batch differently
        np.testing.assert_allclose(model.correct_one(q[i]), batch[i], atol=1e-6)
        np.testing.assert_allclose(model.correction(q[i]), batch[i], atol=1e-6)
    # a batch larger than a chunk runs in chunks on worker threads: the same corrections,
    # in order, as one call on the whole batch
    big = held_out_postures(limb, 2 * model.contract.chunk + 37, 14,
                            oracle=oracle).astype(np.float32)
    whole = model.session.run(None, {"orientations": big})[0]
    np.testing.assert_allclose(model.correction(big), whole, atol=1e-6)
    assert model.metadata["jointlimits.format"] == FORMAT
    assert model.joints == ("hip", "knee", "ankle")
    assert model.metadata["jointlimits.method"] == "geometric"
    assert model.limb.content_hash() == limb.content_hash()
    assert model.size_bytes < 2_000_000
    assert stat.S_IMODE(os.stat(model.path).st_mode) == 0o600


def test_the_wrong_file_is_refused_in_one_line(leg_model, tmp_path):
    _, _, model = leg_model
    other = random_limb(HELD_OUT_LIMB_SEED - 2, "arm")
    with pytest.raises(ModelFileError, match="the model was made for other limits"):
        load_model(model.path, other)
    junk = tmp_path / "junk.onnx"
    junk.write_bytes(b"not a model")
    with pytest.raises(ModelFileError, match="not an ONNX model"):
        load_model(junk)
    with pytest.raises(ModelFileError, match="cannot read model file"):
        load_model(tmp_path / "missing.onnx")
    from models.constraint import JointConstraint
    from models.field import FieldModel
    from models.onnx_io import to_onnx

    c = JointConstraint.cone([1, 0, 0], 40)
    single = tmp_path / "single.onnx"
    single.write_bytes(to_onnx(FieldModel.from_constraint(c, grid=20), constraint_yaml=c.to_yaml())
                       .SerializeToString())
    with pytest.raises(ModelFileError, match="not a limb model"):
        load_model(single, limb=True)
