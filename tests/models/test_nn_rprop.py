"""Population RPROP: determinism, masks, stopping, both variants."""

from __future__ import annotations

import numpy as np
import pytest

from models.constraint import JointConstraint
from models.datasets import quaternion_dataset
from models.nn.gmlp import PopulationSpec, forward, init_params, with_bias
from models.nn.rprop import train_population


@pytest.fixture(scope="module")
def problem():
    rng = np.random.default_rng(0)
    ds = quaternion_dataset(JointConstraint.cone([1, 0, 0], 45), 200, rng, hemisphere="w-positive")
    x, t = ds.inputs, ds.targets
    p, i, h, o = 6, 4, 8, 4
    spec = PopulationSpec(rng.random((p, i + 1, h)) < 0.7, rng.random((p, h + i + 1, o)) < 0.7,
                          np.full((p, h), 2), np.zeros((p, o), int))
    spec.mask2[:, -1, :] = True
    return x, t, spec, init_params(spec, rng)


@pytest.mark.parametrize("variant", ["irprop-", "irprop+"])
def test_training_reduces_error_and_respects_masks(problem, variant):
    x, t, spec, theta = problem
    y0, _ = forward(theta, spec, with_bias(x), need_grad=False)
    mse0 = np.mean((y0 - t) ** 2, axis=(1, 2))
    r = train_population(theta, spec, x, t, max_epochs=150, stop_mse=1e-9, variant=variant,
                         dtype=np.float64)
    assert np.all(r.mse < 0.5 * mse0)
    assert np.all(r.theta[~spec.flat_mask()] == 0.0)
    assert np.all(r.epochs == 150)
    y, _ = forward(r.theta, spec, with_bias(x), need_grad=False)
    np.testing.assert_allclose(np.mean((y - t) ** 2, axis=(1, 2)), r.mse, rtol=1e-9)


def test_deterministic(problem):
    x, t, spec, theta = problem
    a = train_population(theta, spec, x, t, max_epochs=60, stop_mse=1e-9)
    b = train_population(theta, spec, x, t, max_epochs=60, stop_mse=1e-9)
    np.testing.assert_array_equal(a.theta, b.theta)


def test_each_network_stops_on_its_own(problem):
    x, t, spec, theta = problem
    budget = np.array([0, 5, 10, 200, 200, 200])
    r = train_population(theta, spec, x, t, max_epochs=budget, stop_mse=1e-9)
    assert list(r.epochs) == [0, 5, 10, 200, 200, 200]
    np.testing.assert_allclose(r.theta[0], theta[0], atol=1e-7)  # float32 round trip
    r = train_population(theta, spec, x, t, max_epochs=500, stop_mse=0.01)
    early = r.epochs < 500
    assert early.any() and np.all(r.mse[early] <= 0.01)


def test_bad_variant():
    with pytest.raises(ValueError, match="variant"):
        train_population(np.zeros((1, 1)), None, np.zeros((1, 4)), np.zeros((1, 4)),
                         max_epochs=1, stop_mse=0.1, variant="rprop")


def test_huber_clips_residuals_in_the_gradient(problem):
    x, t, spec, theta = problem
    a = train_population(theta, spec, x, t, max_epochs=30, stop_mse=1e-9)
    b = train_population(theta, spec, x, t, max_epochs=30, stop_mse=1e-9, huber=1e-3)
    c = train_population(theta, spec, x, t, max_epochs=30, stop_mse=1e-9, huber=1e3)
    np.testing.assert_array_equal(a.theta, c.theta)  # threshold above every residual: SSE
    assert not np.array_equal(a.theta, b.theta)
