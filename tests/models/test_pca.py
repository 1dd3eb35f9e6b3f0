"""PCA of quaternion datasets (models.pca, thesis TABLES III-V)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from models import quaternion as Q
from models.datasets import cone_constraint, quaternion_dataset
from models.errors import DatasetError
from models.pca import ambiguity_removal_effect, pca_difference, quaternion_pca


def _random_orthonormal(rng):
    m, _ = np.linalg.qr(rng.standard_normal((4, 4)))
    return m


def test_known_gaussian_recovers_variances_and_axes():
    rng = np.random.default_rng(1)
    basis = _random_orthonormal(rng)  # columns: the true axes
    sd = np.array([2.0, 1.4, 1.0, 0.5])
    x = (rng.standard_normal((40000, 4)) * sd) @ basis.T + np.array([0.3, 0.0, -0.2, 1.0])
    p = quaternion_pca(x)
    np.testing.assert_allclose(p.eigenvalues, sd**2, rtol=0.05)
    assert np.all(np.diff(p.eigenvalues) <= 0)
    np.testing.assert_allclose(p.explained.sum(), 1.0)
    np.testing.assert_allclose(np.linalg.norm(p.axes, axis=1), 1.0)
    for k in range(4):
        assert abs(p.axes[k] @ basis[:, k]) > 0.99
    assert np.all(p.axes[:, 0] >= 0.0)  # canonical sign
    np.testing.assert_allclose(p.mean, [0.3, 0.0, -0.2, 1.0], atol=0.05)


def test_angle_to_identity_and_contribution_variance():
    rng = np.random.default_rng(2)
    along_w = np.zeros((500, 4))
    along_w[:, 0] = rng.standard_normal(500)
    p = quaternion_pca(along_w)
    assert p.angle_to_identity_deg[0] == pytest.approx(0.0, abs=1e-6)
    assert p.contribution_variance == pytest.approx(1875.0)  # all variance in one component
    along_x = np.zeros((500, 4))
    along_x[:, 1] = rng.standard_normal(500)
    assert quaternion_pca(along_x).angle_to_identity_deg[0] == pytest.approx(90.0)
    iso = quaternion_pca(rng.standard_normal((50000, 4)))
    assert iso.contribution_variance < 2.0  # hyper-spherical
    np.testing.assert_allclose(iso.contributions.sum(), 100.0)


def test_pca_difference():
    a = np.eye(4)
    assert pca_difference(a, a) == 0.0
    assert pca_difference(a, -a) == 0.0  # eigenvector signs are arbitrary
    assert pca_difference(a, -a, align_signs=False) == pytest.approx(2.0)
    th = math.radians(40.0)
    b = np.eye(4)
    b[0, :2] = [math.cos(th), math.sin(th)]
    b[1, :2] = [-math.sin(th), math.cos(th)]
    # two axes each moved by a chord of 2 sin(θ/2), two unchanged: mean = sin(θ/2)
    assert pca_difference(a, b) == pytest.approx(math.sin(th / 2))
    assert pca_difference(a, b, components=2) == pytest.approx(2 * math.sin(th / 2))
    with pytest.raises(DatasetError, match="components"):
        pca_difference(a, b, components=5)


def test_ambiguity_removal_on_generated_datasets():
    c = cone_constraint((1, 0, 0), 60)
    centred = quaternion_dataset(c, 800, 3, hemisphere="centre")
    e = ambiguity_removal_effect(centred.inputs)
    assert e.moved_fraction == 0.0 and e.difference == 0.0  # +X centre: already w >= 0
    amb = quaternion_dataset(c, 800, 3, hemisphere="ambiguous")
    e = ambiguity_removal_effect(amb.inputs)
    assert 0.4 < e.moved_fraction < 0.6
    assert e.difference > 0.0
    # twist-free inputs have x = 0: a zero fourth eigenvalue (thesis: "ignored")
    assert e.after.eigenvalues[3] < 1e-12
    np.testing.assert_allclose(np.abs(e.after.axes[3]), [0, 1, 0, 0], atol=1e-9)
    assert Q.canonical(amb.inputs).shape == amb.inputs.shape


def test_bad_input():
    with pytest.raises(DatasetError, match=r"\(N, 4\)"):
        quaternion_pca(np.zeros((10, 3)))
    with pytest.raises(DatasetError, match="at least 2"):
        quaternion_pca(np.zeros((1, 4)))
    with pytest.raises(DatasetError, match="NaN"):
        quaternion_pca(np.full((3, 4), np.nan))
