"""The trained limb model: the distance-field network (models.nn.ndf) and its ONNX graph."""

from __future__ import annotations

import numpy as np
import pytest

from models import quaternion as Q
from models.datasets import field_joints, field_samples, training_postures
from models.evaluation import evaluate_model
from models.kinds.ball import evaluate_ball
from models.limb_evaluation import held_out_postures, random_limb
from models.limb_model import export_limb_model, limb_to_onnx
from models.nn.ndf import DistanceField, FieldSpec, fit_limb_fields
from models.onnx_io import load_model
from models.oracle import ConstraintOracle

SMALL = FieldSpec(features=64, hidden=64, samples=20000, epochs=8, batch=512)
DEV_SEED = 321  # a development limb, below the held-out seeds


@pytest.fixture(scope="module")
def leg():
    return random_limb(DEV_SEED, "leg")


@pytest.fixture(scope="module")
def trained(leg):
    return fit_limb_fields(leg, seed=3, spec=SMALL)


def _float64(net: DistanceField) -> DistanceField:
    for k in ("b", "c", "w1", "b1", "w2", "b2", "w3", "b3"):
        setattr(net, k, getattr(net, k).astype(np.float64))
    return net


def _problem(seed=0, n=12):
    rng = np.random.default_rng(seed)
    d = Q.random_unit_vectors(n, rng)
    z = np.c_[d, rng.uniform(-1, 1, n)]
    g = Q.random_unit_vectors(n, rng)
    g -= (g * d).sum(1, keepdims=True) * d
    return rng, z, rng.normal(size=n), g


def test_training_gradients_match_finite_differences():
    rng, z, s, g = _problem()
    net = _float64(DistanceField.initial(FieldSpec(features=6, hidden=5), 0.0, 1.0, rng))
    w = rng.uniform(0.5, 2.0, len(z))
    analytic = net.gradients(z, s, g, 0.7, w)
    for name, ga in zip(("w1", "b1", "w2", "b2", "w3", "b3"), analytic, strict=True):
        a = getattr(net, name)
        num = np.zeros_like(a)
        for i in np.ndindex(a.shape):
            old = a[i]
            a[i] = old + 1e-6
            up = net.loss(z, s, g, 0.7, w)
            a[i] = old - 1e-6
            down = net.loss(z, s, g, 0.7, w)
            a[i] = old
            num[i] = (up - down) / 2e-6
        np.testing.assert_allclose(ga, num, atol=1e-7, err_msg=name)


def test_input_gradient_matches_finite_differences():
    rng, z, _, _ = _problem(1)
    net = _float64(DistanceField.initial(FieldSpec(features=6, hidden=5), 0.0, 1.0, rng))
    d, tau = z[:, :3], z[:, 3]
    _, grad = net.value_and_gradient(d, tau)
    for k in range(3):
        e = np.zeros(3)
        e[k] = 1e-6
        num = (net.value(d + e, tau) - net.value(d - e, tau)) / 2e-6
        np.testing.assert_allclose(grad[:, k], num, atol=1e-7)


def test_field_samples_are_the_limb_oracles_distances(leg):
    rng = np.random.default_rng(0)
    q = training_postures(leg, 500, rng)
    (name,) = field_joints(leg)
    d, angle, s, g = field_samples(leg, name, q)  # the oracle's answers computed inside
    res = ConstraintOracle(leg).evaluate(q)
    assert [np.array_equal(a, b) for a, b in zip(
        field_samples(leg, name, q, res), (d, angle, s, g), strict=True)] == [True] * 4
    j = leg.index(name)
    # outside, the distance is how far the oracle moves the limb direction (twist aside)
    moved = Q.angle_between(d, Q.rotate(res.projected[:, j], np.asarray(leg.joints[j].limb_axis)))
    np.testing.assert_allclose(np.maximum(s, 0.0), moved, atol=1e-9)
    np.testing.assert_allclose(angle, res.coupling_angle[:, j])
    # the gradient is a unit tangent pointing away from the boundary outside
    np.testing.assert_allclose(np.linalg.norm(g, axis=1), 1.0, atol=1e-9)
    np.testing.assert_allclose((g * d).sum(1), 0.0, atol=1e-9)
    # the source hinge is on its axis inside its interval: its corrected angle is its own
    src = leg.index(leg.joints[j].coupling.by)
    assert res.valid[:, src].all()
    # half the directions lie within 40° of the boundary
    assert 0.4 < float((np.abs(s) < np.radians(40.5)).mean()) < 0.9


def test_onnx_graph_computes_the_fields_projection(leg, trained, tmp_path):
    fields, facts = trained
    model = load_model(export_limb_model(leg, tmp_path / "leg.onnx", fields, facts), leg)
    assert model.metadata["jointlimits.method"] == "network"
    assert '"joints": ["hip"]' in model.metadata["jointlimits.training"]
    q = held_out_postures(leg, 900, 7)
    got = model.correction(q).astype(np.float64)
    # the numpy computation: the limb oracle with the coupled joint's nearest point replaced
    oracle = ConstraintOracle(leg)
    (name,) = fields
    j = leg.index(name)
    net = fields[name]
    res = oracle.evaluate(q)
    lim = leg.joints[j].coupling.limits
    k, t = lim.locate(res.coupling_angle[:, j])
    lo, hi = lim.interval(k, t)

    def nearest(d):
        out, b = net.project(d, res.coupling_angle[:, j])
        return np.where(out, 1.0, -1.0), b
    axis = np.asarray(leg.joints[j].limb_axis)
    want = evaluate_ball(np.ascontiguousarray(q[:, j]), axis, nearest,
                         lambda e: (lo, hi)).correction
    err = np.degrees(Q.angle(Q.multiply(got[:, j], Q.conjugate(want))))
    assert np.percentile(err, 99) < 0.05  # float32 graph against float64 numpy
    # every other joint is exact
    for other in range(len(leg.joints)):
        if other != j:
            e = np.degrees(Q.angle(Q.multiply(got[:, other], Q.conjugate(res.correction[:,
                                                                                         other]))))
            assert e.max() < 0.01
    # one posture a call (the projection steps skipped where its direction is inside): the
    # batch's answers, to float32 rounding — the single call's products run on the field's
    # matrices unpacked (onnx_io.large_products), the batch's prepacked, and five steps carry
    # a last-bit difference to a few thousandths of a degree on one posture of 300
    one = np.stack([model.correct_one(p) for p in q[:300]]).astype(np.float64)
    assert not res.valid[:300, j].all() and res.valid[:300, j].any()
    e = np.degrees(Q.angle(Q.multiply(one.reshape(-1, 4), Q.conjugate(got[:300].reshape(-1, 4)))))
    assert e.max() < 0.01
    assert np.median(e) < 1e-4


def test_small_network_corrects_a_development_limb(leg, trained):
    fields, facts = trained
    model_bytes = limb_to_onnx(leg, fields, facts).SerializeToString()
    import onnxruntime as ort

    sess = ort.InferenceSession(model_bytes, providers=["CPUExecutionProvider"])
    oracle = ConstraintOracle(leg)
    q = held_out_postures(leg, 1500, 11, oracle=oracle)

    def predict(x):
        return sess.run(None, {"orientations": x.astype(np.float32)})[0]
    m = evaluate_model(predict, leg, q=q, oracle=oracle)
    # a 64-wide network trained for 8 epochs: far from the shipped one (bench_limb.py)
    assert m["end_mean_3d_error_pct"] < 3.0
    assert m["valid_moved_deg"] < 0.5
    assert m["joint_mean_direction_error_deg"][1] < 1e-3  # the hinge is exact


def test_fields_must_match_the_limbs_coupled_swings(leg, trained):
    fields, _ = trained
    with pytest.raises(ValueError, match="one per coupled polygon swing"):
        limb_to_onnx(leg, {"knee": next(iter(fields.values()))})


def test_fields_train_side_by_side_as_they_do_one_after_another():
    """Two coupled swings (the anatomical leg's hip and ankle): each field has its own
    generator, so training them on two threads gives the weights of training them in turn."""
    from rig.sim.patients import anatomical_limb

    leg2 = anatomical_limb(0, "leg", "right")
    assert field_joints(leg2) == ["hip", "ankle"]
    tiny = FieldSpec(features=16, hidden=16, samples=3000, epochs=2, batch=256)
    seen = []
    one, facts1 = fit_limb_fields(leg2, seed=5, spec=tiny, workers=1)
    two, facts2 = fit_limb_fields(leg2, seed=5, spec=tiny, workers=2,
                                  progress=lambda name, s: seen.append(name))
    assert (facts1["workers"], facts2["workers"]) == (1, 2)
    assert seen == ["hip", "ankle"]
    for name in ("hip", "ankle"):
        for k in ("b", "w1", "b1", "w2", "b2", "w3", "b3"):
            np.testing.assert_array_equal(getattr(one[name], k), getattr(two[name], k))
    assert not np.allclose(one["hip"].w1, one["ankle"].w1)


def test_a_batch_computed_in_parts_on_helper_threads_gives_the_same_weights():
    """A field alone on several cores computes each batch's gradient in parts on helper
    threads; the parts are summed in order, so the weights are those of the same parts on one
    thread, bit for bit — and the parts' sum is the whole batch's gradient."""
    from concurrent.futures import ThreadPoolExecutor

    from models.nn.ndf import fit_coupled_field
    from rig.sim.patients import anatomical_limb

    arm = anatomical_limb(0, "arm", "right")
    limits = arm.joints[arm.index("shoulder")].coupling.limits
    tiny = FieldSpec(features=16, hidden=16, samples=3000, epochs=2, batch=256)
    q = training_postures(arm, tiny.samples, np.random.default_rng(7), tiny.uniform)
    samples = field_samples(arm, "shoulder", q, ConstraintOracle(arm).evaluate(q))
    alone = fit_coupled_field(limits, np.random.default_rng(1), tiny, samples, parts=3)
    with ThreadPoolExecutor(2) as helpers:
        helped = fit_coupled_field(limits, np.random.default_rng(1), tiny, samples, helpers, 3)
    for k in ("b", "w1", "b1", "w2", "b2", "w3", "b3"):
        np.testing.assert_array_equal(getattr(alone, k), getattr(helped, k))
    # the parts add up to the whole batch's gradient
    net = DistanceField.initial(tiny, limits.at[0], limits.at[-1], np.random.default_rng(2))
    d, angle, s_, g = samples
    z = np.concatenate((d, net.tau(angle)[:, None]), axis=1).astype(np.float32)[:256]
    lam, w = np.float32(0.05), np.ones(256, np.float32)
    whole = net.gradients(z, s_[:256].astype(np.float32), g[:256].astype(np.float32), lam, w)
    parts = net._batch_gradients(z, s_[:256].astype(np.float32), g[:256].astype(np.float32),
                                 lam, w, 3, None)
    for a, b in zip(whole, parts, strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-4, atol=1e-6)
