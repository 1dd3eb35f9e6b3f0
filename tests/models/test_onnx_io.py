"""ONNX export: parity with numpy, in-graph canonicalisation, metadata, refusals."""

from __future__ import annotations

import json

import numpy as np
import onnx
import pytest
from onnx import TensorProto, helper

from models import quaternion as quat
from models.errors import ModelFileError
from models.nn.gmlp import GMLP, PopulationSpec, init_params
from models.onnx_io import export_onnx, load_model, one_sample, to_onnx

CONSTRAINT = "name: c45\nswing:\n  cone: {centre: [1, 0, 0], radius_deg: 45}\n"


def _net(rng, kinds, out_kinds, h=7, ref=(1.0, 0.0, 0.0, 0.0), scale=2.0, input_map="canonical",
         frame=None):
    spec = PopulationSpec(rng.random((1, 5, h)) < 0.8, rng.random((1, h + 5, 4)) < 0.8,
                          rng.choice(kinds, (1, h)), rng.choice(out_kinds, (1, 4)),
                          rng.uniform(-1, 1, (1, 4, 9)))
    spec.mask2[:, -1] = True
    theta = init_params(spec, rng) * scale
    return GMLP.from_population(theta, spec, 0, input_map=input_map,
                                canonical_ref=None if ref is None else np.asarray(ref),
                                frame=None if frame is None else np.asarray(frame))


_FRAME = tuple(quat.from_two_vectors(quat.LIMB_AXIS, np.array([0.3, -0.8, 0.52])))


@pytest.mark.parametrize(("kinds", "out_kinds", "ref", "input_map", "frame"), [
    ([2], [0], (1.0, 0.0, 0.0, 0.0), "canonical", None),
    ([0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11], [0, 1, 2, 8, 9], (0.5, 0.5, -0.5, 0.5), "canonical",
     None),
    ([6], [0], None, "canonical", None),
    ([6], [0], None, "swing", None),
    ([6], [0], None, "swing", _FRAME),
    ([6], [0], _FRAME, "canonical", _FRAME),
    ([1, 2, 8], [0, 2, 8], (0.5, 0.5, -0.5, 0.5), "canonical", _FRAME),
    ([1, 6], [1, 0], None, "swing", _FRAME),
])
def test_parity_with_numpy_on_10k(tmp_path, kinds, out_kinds, ref, input_map, frame):
    rng = np.random.default_rng(len(kinds))
    net = _net(rng, kinds, out_kinds, ref=ref, input_map=input_map, frame=frame)
    path = export_onnx(net, tmp_path / "m.onnx", constraint_yaml=CONSTRAINT,
                       training_data_sha256="ab" * 32, metrics={"mse": 1e-4})
    model = load_model(path, expected_constraint=CONSTRAINT)
    q = quat.random_quaternions(10_000, rng)
    got = model.correction(q)
    assert got.dtype == np.float32 and got.shape == (10_000, 4)
    np.testing.assert_allclose(got, net.predict(q), atol=1e-5)
    if ref is not None or input_map == "swing":
        np.testing.assert_allclose(model.correction(-q), got, atol=1e-6)
    assert model.network_info["input_map"] == input_map
    assert (model.network_info["frame"] is None) == (frame is None)
    np.testing.assert_allclose(model.correct_one(q[3]), got[3], atol=1e-6)
    np.testing.assert_allclose(model.correction(q[3]), got[3], atol=1e-6)


def test_centre_frame_maps():
    """``predict`` of a centre-frame net is the parent-frame net conjugated by ``R_c``."""
    rng = np.random.default_rng(5)
    net = _net(rng, [6], [0], ref=None, input_map="swing", frame=_FRAME)
    q = quat.random_quaternions(500, rng)
    r = np.asarray(_FRAME)
    qp = quat.multiply(np.broadcast_to(quat.conjugate(r), q.shape), q)
    y = net.forward(GMLP.canonicalise(net, q))
    np.testing.assert_allclose(y, net.forward(quat.from_two_vectors(
        np.broadcast_to(quat.LIMB_AXIS, (500, 3)), quat.limb_direction(qp))), atol=1e-9)
    y = y / np.linalg.norm(y, axis=1, keepdims=True)
    back = quat.multiply(quat.multiply(np.broadcast_to(r, y.shape), y),
                         np.broadcast_to(quat.conjugate(r), y.shape))
    np.testing.assert_allclose(net.predict(q), back, atol=1e-12)


def test_metadata(tmp_path):
    net = _net(np.random.default_rng(0), [2], [0])
    net.info["hidden"] = net.n_hidden
    path = export_onnx(net, tmp_path / "sub" / "m.onnx", constraint_yaml=CONSTRAINT,
                       training_data_sha256="cd" * 32, metrics={"mse": 2e-5})
    m = load_model(path)
    assert m.constraint_yaml == CONSTRAINT
    assert m.metrics == {"mse": 2e-5}
    assert m.network_info["hidden"] == net.n_hidden
    assert m.metadata["jointlimits.training_data_sha256"] == "cd" * 32
    assert m.metadata["jointlimits.version"]
    corrected = m.corrected(quat.random_quaternions(5, np.random.default_rng(1)))
    np.testing.assert_allclose(np.linalg.norm(corrected, axis=1), 1.0, atol=1e-6)


def test_the_single_call_session_knows_its_shapes_and_gives_the_batchs_answers(tmp_path):
    net = _net(np.random.default_rng(0), [2], [0])
    path = export_onnx(net, tmp_path / "m.onnx", constraint_yaml=CONSTRAINT)
    model = onnx.load(str(path))
    fixed = onnx.load_model_from_string(one_sample(model))
    for v in (*fixed.graph.input, *fixed.graph.output):
        assert [d.dim_value for d in v.type.tensor_type.shape.dim] == [1, 4]
    assert fixed.graph.node == model.graph.node  # the graph itself unchanged
    assert model.graph.input[0].type.tensor_type.shape.dim[0].dim_param  # the copy's, not it
    m = load_model(path)
    q = quat.random_quaternions(20, np.random.default_rng(2))
    batch = m.correction(q)
    for i in range(len(q)):
        np.testing.assert_allclose(m.correct_one(q[i]), batch[i], atol=1e-6)


def test_refuses_non_onnx(tmp_path):
    p = tmp_path / "x.onnx"
    p.write_text("name: not a model\n")
    with pytest.raises(ModelFileError, match="not an ONNX model"):
        load_model(p)
    with pytest.raises(ModelFileError, match="cannot read"):
        load_model(tmp_path / "missing.onnx")


def test_refuses_other_io(tmp_path):
    graph = helper.make_graph(
        [helper.make_node("Identity", ["q"], ["out"])], "g",
        [helper.make_tensor_value_info("q", TensorProto.FLOAT, ["N", 4])],
        [helper.make_tensor_value_info("out", TensorProto.FLOAT, ["N", 4])])
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    p = tmp_path / "other.onnx"
    onnx.save(model, p)
    with pytest.raises(ModelFileError, match="expected input 'orientation'"):
        load_model(p)
    graph = helper.make_graph(
        [helper.make_node("Identity", ["orientation"], ["correction"])], "g",
        [helper.make_tensor_value_info("orientation", TensorProto.FLOAT, ["N", 3])],
        [helper.make_tensor_value_info("correction", TensorProto.FLOAT, ["N", 3])])
    onnx.save(helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)]), p)
    with pytest.raises(ModelFileError, match=r"\[N, 4\]"):
        load_model(p)
    graph = helper.make_graph(
        [helper.make_node("Identity", ["orientation"], ["correction"])], "g",
        [helper.make_tensor_value_info("orientation", TensorProto.FLOAT, ["N", 4])],
        [helper.make_tensor_value_info("correction", TensorProto.FLOAT, ["N", 4])])
    onnx.save(helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)]), p)
    with pytest.raises(ModelFileError, match="not a jointlimits correction model"):
        load_model(p)


def test_refuses_other_constraint(tmp_path):
    net = _net(np.random.default_rng(0), [2], [0])
    p = export_onnx(net, tmp_path / "m.onnx", constraint_yaml=CONSTRAINT)
    other = CONSTRAINT.replace("45", "50")
    with pytest.raises(ModelFileError, match="different constraint"):
        load_model(p, expected_constraint=other)
    load_model(p, expected_constraint={"name": "c45", "swing": {"cone": {
        "centre": [1, 0, 0], "radius_deg": 45}}})


def test_constraint_objects_compare_by_limits(tmp_path):
    from models.constraint import JointConstraint

    c = JointConstraint.cone([1, 0, 0], 45, name="a")
    net = _net(np.random.default_rng(0), [2], [0])
    p = export_onnx(net, tmp_path / "m.onnx", constraint_yaml=c.to_yaml())
    load_model(p, expected_constraint=JointConstraint.cone([1, 0, 0], 45, name="b"))
    with pytest.raises(ModelFileError, match="different constraint"):
        load_model(p, expected_constraint=JointConstraint.cone([0, 1, 0], 45))


def test_graph_is_valid_onnx_without_pickle():
    net = _net(np.random.default_rng(5), [8, 9], [0])
    model = to_onnx(net, constraint_yaml=CONSTRAINT, metrics={"a": 1.0})
    onnx.checker.check_model(model, full_check=True)
    props = {p.key: p.value for p in model.metadata_props}
    assert json.loads(props["jointlimits.metrics"]) == {"a": 1.0}


# -- the field model's graph (models.field) ---------------------------------------------------
def _field_case(constraint, tmp_path, grid=120):
    from models.field import FieldModel

    f = FieldModel.from_constraint(constraint, grid=grid)
    p = export_onnx(f, tmp_path / "f.onnx", constraint_yaml=constraint.to_yaml(),
                    training_data_sha256=f.content_hash(), metrics={"x": 1.0})
    return f, load_model(p, expected_constraint=constraint)


def _rotation_deg(a, b):
    from models import quaternion as quat

    return np.degrees(quat.angle(quat.multiply(a, quat.conjugate(b))))


@pytest.mark.parametrize("twist", [None, (-45.0, 70.0)])
@pytest.mark.parametrize("swing", ["polygon", "cone", "none"])
def test_field_graph_matches_its_numpy_reference(tmp_path, swing, twist):
    from models import quaternion as quat
    from models.constraint import JointConstraint
    from models.shapes import load_shape

    if swing == "polygon":
        s = load_shape("c-shape").swing
        c = JointConstraint.polygon(s.vertices, s.interior, twist=twist)
    elif swing == "cone":
        c = JointConstraint.cone([0, 0, 1], 35, twist=twist)
    elif twist is None:
        pytest.skip("a constraint needs a swing or a twist limit")
    else:
        c = JointConstraint.from_dict({"name": "t", "twist": {"min_deg": twist[0],
                                                              "max_deg": twist[1]}})
    f, m = _field_case(c, tmp_path)
    q = quat.random_quaternions(5000, np.random.default_rng(8))
    got = m.correction(q).astype(np.float64)
    np.testing.assert_allclose(np.linalg.norm(got, axis=1), 1.0, atol=1e-5)
    err = _rotation_deg(got, f.predict(q))
    # float32 may pick a neighbouring node for a handful of directions
    assert np.mean(err > 1e-2) < 0.005 and err.max() < 3.0
    np.testing.assert_allclose(m.correction(-q), got, atol=1e-5)  # sign-free
    assert m.metadata["jointlimits.training_data_sha256"] == f.content_hash()
    assert m.network_info["method"] == "field" and m.metrics == {"x": 1.0}
    one = m.correct_one(tuple(map(float, q[0])))
    np.testing.assert_allclose(one, got[0], atol=1e-6)


def test_field_graph_with_swing_dependent_twist_limits(tmp_path):
    """A hand-built by_swing table (contract 3): graph = numpy reference = oracle's limits."""
    from models import quaternion as quat
    from models.constraint import JointConstraint
    from models.oracle import ConstraintOracle

    c = JointConstraint.from_dict({
        "name": "bs", "swing": {"cone": {"centre": [1, 0, 0], "radius_deg": 70}},
        "twist": {"min_deg": -80, "max_deg": 90, "by_swing": {"bandwidth_deg": 25, "points": [
            {"direction": [1, 0, 0], "min_deg": -40, "max_deg": 60},
            {"direction": [0, 1, 0], "min_deg": -80, "max_deg": 10},
            {"direction": [0, 0, 1], "min_deg": 0, "max_deg": 90}]}}})
    f, m = _field_case(c, tmp_path)
    assert m.network_info["twist"] == "by_swing"
    q = quat.random_quaternions(4000, np.random.default_rng(9))
    got = m.correction(q).astype(np.float64)
    err = _rotation_deg(got, f.predict(q))
    assert np.mean(err > 1e-2) < 0.005
    out = quat.multiply(got, q)
    o = ConstraintOracle(c)
    lo, hi = c.twist.limits_at(quat.limb_direction(out))
    phi = quat.twist_angle(out)
    tol = np.radians(0.05)
    assert np.all((phi >= lo - tol) & (phi <= hi + tol))
    # valid inputs well inside stay put
    deep = o.is_valid(q) & (o.signed_distance(q) < -np.radians(5))
    assert np.degrees(quat.angle(got[deep])).max() < 1e-3


def test_a_limb_model_given_for_one_joint_says_so(tmp_path):
    """Issue 37, case 11: a limb model given to a single-joint command got an ONNX
    tensor-shape message."""
    from models.limb import loads_limb
    from models.limb_model import export_limb_model

    limb = loads_limb("name: arm\nlimb: arm\njoints:\n"
                      "- {name: shoulder, parent: thorax, child: upper-arm, constraint: "
                      "{swing: {cone: {centre: [1, 0, 0], radius_deg: 60}}}}\n"
                      "- {name: elbow, parent: upper-arm, child: forearm, constraint: "
                      "{kind: hinge, hinge: {axis: [0, 0, 1], min_deg: 0, max_deg: 140}}}\n")
    path = export_limb_model(limb, tmp_path / "arm.onnx")
    assert load_model(path).joints == ("shoulder", "elbow")  # one loader opens both
    with pytest.raises(ModelFileError, match=r"a limb model .*not one joint's") as err:
        load_model(path, limb=False)
    assert "tensor" not in str(err.value) and "[N, 4]" not in str(err.value)


def test_the_same_limits_bound_to_another_joint_are_another_constraint(tmp_path):
    """Issue 37: a shoulder model evaluated against a hip file with the same limits passed."""
    from models.constraint import JointConstraint

    sh = JointConstraint.cone((1, 0, 0), 45.0, name="c45", joint="shoulder", side="right",
                              patient="P-1")
    net = _net(np.random.default_rng(0), [2], [0])
    p = export_onnx(net, tmp_path / "m.onnx", constraint_yaml=sh.to_yaml())
    load_model(p, expected_constraint=JointConstraint.cone((1, 0, 0), 45.0))  # unbound: fine
    for kw, match in (({"joint": "hip"}, "trained for joint 'shoulder', the constraint is for "
                                         "joint 'hip'"),
                      ({"side": "left"}, "side 'right'"),
                      ({"patient": "P-2"}, "patient 'P-1'")):
        with pytest.raises(ModelFileError, match=match):
            load_model(p, expected_constraint=JointConstraint.cone((1, 0, 0), 45.0, **kw))
