"""GMLP forward/backward, activations and spline templates."""

from __future__ import annotations

import numpy as np
import pytest

from models.nn import activations as act
from models.nn.gmlp import GMLP, PopulationSpec, backward, forward, init_params, with_bias


def _spec(rng, p=3, i=4, h=5, o=4, kinds=None, out_kinds=None):
    m1 = rng.random((p, i + 1, h)) < 0.8
    m2 = rng.random((p, h + i + 1, o)) < 0.8
    kinds = rng.choice(kinds or [0, 1, 2, 3, 4, 6, 8, 9], (p, h))
    ok = rng.choice(out_kinds or [0, 2, 8], (p, o))
    spline = rng.uniform(-1, 1, (p, 2, 7))
    return PopulationSpec(m1, m2, kinds, ok, spline)


def test_backward_matches_finite_differences():
    rng = np.random.default_rng(0)
    spec = _spec(rng)
    theta = init_params(spec, rng) * 3.0
    x = rng.standard_normal((7, 4))
    t = rng.standard_normal((7, 4))
    xb = with_bias(x)
    y, cache = forward(theta, spec, xb)
    g = backward(y - t, cache, spec, xb)

    def loss(th):
        yy, _ = forward(th, spec, xb, need_grad=False)
        return 0.5 * np.sum((yy - t) ** 2, axis=(1, 2))

    eps = 1e-6
    for k in rng.choice(theta.shape[1], 25, replace=False):
        d = np.zeros_like(theta)
        d[:, k] = eps
        num = (loss(theta + d) - loss(theta - d)) / (2 * eps)
        np.testing.assert_allclose(g[:, k], num, rtol=1e-4, atol=1e-6)


def test_extracted_network_matches_population_forward():
    rng = np.random.default_rng(1)
    spec = _spec(rng)
    theta = init_params(spec, rng)
    x = rng.standard_normal((11, 4))
    y, _ = forward(theta, spec, with_bias(x), need_grad=False)
    for k in range(3):
        net = GMLP.from_population(theta, spec, k)
        assert net.n_hidden <= 5
        np.testing.assert_allclose(net.forward(x), y[k], atol=1e-12)


def test_predict_is_sign_invariant_and_unit():
    rng = np.random.default_rng(2)
    spec = _spec(rng, p=1)
    net = GMLP.from_population(init_params(spec, rng), spec, 0,
                               canonical_ref=np.array([0.6, 0.8, 0.0, 0.0]))
    q = rng.standard_normal((50, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    a, b = net.predict(q), net.predict(-q)
    np.testing.assert_allclose(a, b, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(a, axis=1), 1.0, atol=1e-12)
    assert net.predict(q[0]).shape == (4,)


def test_spline_interpolates_control_points_and_is_c1():
    rng = np.random.default_rng(3)
    ctrl = rng.uniform(-1, 1, (1, 1, 9))
    coef = act.spline_coefficients(ctrl)
    knots = np.linspace(-5, 5, 9)
    z = knots[None, :, None]
    y, _ = act.spline_apply(z, coef, np.zeros((1, 1), int))
    np.testing.assert_allclose(y[0, :, 0], ctrl[0, 0], atol=1e-4)  # last knot: clip epsilon
    # C1 at inner knots: left and right derivatives agree
    zl, zr = knots[1:-1] - 1e-7, knots[1:-1] + 1e-7
    _, dl = act.spline_apply(zl[None, :, None], coef, np.zeros((1, 1), int))
    _, dr = act.spline_apply(zr[None, :, None], coef, np.zeros((1, 1), int))
    np.testing.assert_allclose(dl, dr, atol=1e-5)
    # flat outside the sensitivity interval
    y_out, d_out = act.spline_apply(np.array([[[-9.0], [9.0]]]), coef, np.zeros((1, 1), int))
    np.testing.assert_allclose(y_out[0, :, 0], ctrl[0, 0, [0, -1]], atol=1e-4)
    assert np.all(d_out == 0)


@pytest.mark.parametrize("name", [*act.NAMES, "spline3"])
def test_activation_names_round_trip(name):
    assert act.name_of(act.index_of(name)) == name


def test_unknown_activation_is_rejected():
    with pytest.raises(ValueError, match="unknown activation"):
        act.index_of("swish")


def test_swing_map_is_the_twist_free_rotation_to_the_limb_direction():
    from models import quaternion as quat
    from models.nn.gmlp import swing_of

    rng = np.random.default_rng(4)
    q = quat.random_quaternions(200, rng)
    s = swing_of(q)
    d = quat.limb_direction(q)
    np.testing.assert_allclose(s, quat.from_two_vectors(np.broadcast_to(quat.LIMB_AXIS, d.shape),
                                                        d), atol=1e-12)
    np.testing.assert_allclose(swing_of(-3.0 * q), s, atol=1e-12)  # sign and scale
    twist = quat.from_axis_angle(np.array([1.0, 0.0, 0.0]), rng.uniform(-np.pi, np.pi, 200))
    np.testing.assert_allclose(swing_of(quat.multiply(q, twist)), s, atol=1e-12)


def test_swing_input_map_makes_predictions_twist_invariant():
    from models import quaternion as quat

    rng = np.random.default_rng(5)
    spec = _spec(rng, p=1)
    net = GMLP.from_population(init_params(spec, rng), spec, 0, input_map="swing")
    q = quat.random_quaternions(50, rng)
    twist = quat.from_axis_angle(np.array([1.0, 0.0, 0.0]), rng.uniform(-np.pi, np.pi, 50))
    np.testing.assert_allclose(net.predict(quat.multiply(q, twist)), net.predict(q), atol=1e-12)
