"""SVM binary constraints: numpy decision function equals scikit-learn, pickle-free I/O."""

from __future__ import annotations

import numpy as np
import pytest

from models import quaternion as quat
from models.constraint import JointConstraint
from models.errors import ModelFileError
from models.oracle import ConstraintOracle
from models.svm import BinaryConstraintSVM, features


@pytest.fixture(scope="module")
def data():
    rng = np.random.default_rng(0)
    oracle = ConstraintOracle(JointConstraint.cone([0, 1, 0], 60))
    q = quat.random_quaternions(600, rng)
    qt = quat.random_quaternions(500, rng)
    return oracle, q, oracle.is_valid(q), qt


@pytest.mark.parametrize("kernel", ["linear", "poly", "rbf", "sigmoid"])
@pytest.mark.parametrize("feature", ["quaternion", "direction"])
def test_numpy_decision_equals_sklearn(data, kernel, feature, tmp_path):
    _, q, valid, qt = data
    m = BinaryConstraintSVM(kernel, feature=feature).fit(q, valid)
    ref = m.sklearn_.decision_function(features(qt, feature))
    np.testing.assert_allclose(m.decision_function(qt), ref, atol=1e-9)
    npz, meta = m.save(tmp_path / "svm", constraint_yaml="name: c\n")
    assert npz.suffix == ".npz" and meta.suffix == ".json"
    loaded = BinaryConstraintSVM.load(tmp_path / "svm")
    np.testing.assert_allclose(loaded.decision_function(qt), ref, atol=1e-9)
    assert loaded.constraint_yaml == "name: c\n"


def test_rbf_classifies_a_cone_well(data):
    oracle, q, valid, qt = data
    m = BinaryConstraintSVM("rbf").fit(q, valid)
    assert np.mean(m.predict(qt) == oracle.is_valid(qt)) > 0.95
    assert np.all(m.predict(qt) == m.predict(-qt))


def test_load_refuses_garbage(tmp_path):
    (tmp_path / "x.json").write_text("{}")
    np.savez(tmp_path / "x.npz", support_vectors=np.zeros((1, 4)), dual_coef=np.zeros(1))
    with pytest.raises(ModelFileError, match="format"):
        BinaryConstraintSVM.load(tmp_path / "x")
    with pytest.raises(ModelFileError):
        BinaryConstraintSVM.load(tmp_path / "missing")


def test_bad_kernel():
    with pytest.raises(ValueError, match="kernel"):
        BinaryConstraintSVM("cubic")
