"""The small public API of the models package (models/__init__.py)."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

import models


def test_import_is_light():
    """``import models`` loads neither onnxruntime nor onnx nor scipy (everything is lazy)."""
    code = (
        "import sys, models\n"
        "names = ('onnxruntime', 'onnx', 'scipy', 'models.oracle')\n"
        "heavy = [m for m in names if m in sys.modules]\n"
        "print(','.join(heavy))\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=60
    )
    assert out.stdout.strip() == ""


@pytest.mark.parametrize("name", models.__all__)
def test_every_exported_name_resolves(name):
    assert getattr(models, name) is not None
    assert name in dir(models)


def test_unknown_names_raise_attribute_error():
    with pytest.raises(AttributeError, match="no attribute 'nope'"):
        models.nope  # noqa: B018


def test_a_user_round_trip_through_the_public_names(tmp_path):
    c = models.JointConstraint.cone([1, 0, 0], 40, twist=(-30, 30), joint="shoulder")
    path = tmp_path / "c.yaml"
    models.dump_constraint(c, path)
    again = models.load_constraint(path)
    assert again == c and again.joint == "shoulder"
    oracle = models.ConstraintOracle(again)
    q = models.quaternion.from_axis_angle(np.array([0.0, 0.0, 1.0]), np.radians(70.0))
    corrected = models.quaternion.multiply(oracle.correction(q), q)
    assert oracle.is_valid(corrected)
    assert models.ConstraintOracle is models.oracle.ConstraintOracle
    assert issubclass(models.ConstraintError, models.ModelsError)
    with pytest.raises(models.ConstraintError, match="twsit"):
        models.loads_constraint("twsit: {min_deg: -1, max_deg: 1}")
