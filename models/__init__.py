"""Learned, patient-specific joint limits: the public API.

A joint constraint (a swing region on the sphere and a twist interval, constant or
swing-dependent) is read from YAML, answered exactly by an oracle, and approximated by a learned
corrective model exported to ONNX::

    import models

    c = models.load_constraint("right-shoulder.yaml")     # JointConstraint
    oracle = models.ConstraintOracle(c)   # or of a models.Limb: postures (N, J, 4)
    corrected = models.quaternion.multiply(oracle.correction(q), q)   # q: (N, 4) w, x, y, z
    model = models.load_model("model.onnx", expected_constraint=c)   # onnxruntime, lazily
    corrected = models.quaternion.multiply(model.correction(q), q)

Conventions (:mod:`models.quaternion`): quaternions scalar-first ``(w, x, y, z)``, Hamilton
products, ``corrected = correction ⊗ orientation``, the limb's long axis +X, angles wrapped to
(-π, π].

Everything here is imported on first use (PEP 562 ``__getattr__``), so ``import models`` loads
no numerical library and never onnxruntime; the submodules stay importable directly
(``from models.oracle import ConstraintOracle``).
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

#: public name -> (module, attribute or None for the module itself)
_EXPORTS: dict[str, tuple[str, str | None]] = {
    # constraint files
    "JointConstraint": ("models.constraint", "JointConstraint"),
    "ConeSwing": ("models.limits", "ConeSwing"),
    "PolygonSwing": ("models.limits", "PolygonSwing"),
    "TwistLimits": ("models.limits", "TwistLimits"),
    "SwingTwistTable": ("models.limits", "SwingTwistTable"),
    "load_constraint": ("models.constraint", "load_constraint"),
    "loads_constraint": ("models.constraint", "loads_constraint"),
    "dump_constraint": ("models.constraint", "dump_constraint"),
    # limb files (chains of joints, couplings)
    "Limb": ("models.limb", "Limb"),
    "load_limb": ("models.limb", "load_limb"),
    "loads_limb": ("models.limb", "loads_limb"),
    "dump_limb": ("models.limb", "dump_limb"),
    # exact answers
    "ConstraintOracle": ("models.oracle", "ConstraintOracle"),
    "OracleResult": ("models.kinds.base", "OracleResult"),
    "BOUNDARY_TOLERANCE": ("models.kinds.base", "BOUNDARY_TOLERANCE"),
    "SphericalPolygon": ("models.geometry", "SphericalPolygon"),
    "LimbResult": ("models.oracle", "LimbResult"),
    # shipped example boundaries
    "SHAPES": ("models.shapes", "SHAPES"),
    "load_shape": ("models.shapes", "load_shape"),
    # learned models (onnxruntime is imported only when these are used)
    "load_model": ("models.onnx_io", "load_model"),
    "CorrectionModel": ("models.onnx_io", "CorrectionModel"),
    "FieldModel": ("models.field", "FieldModel"),
    "export_onnx": ("models.onnx_io", "export_onnx"),
    "evaluate_model": ("models.evaluation", "evaluate_model"),
    "held_out_orientations": ("models.evaluation", "held_out_orientations"),
    # errors
    "ModelsError": ("models.errors", "ModelsError"),
    "ConstraintError": ("models.errors", "ConstraintError"),
    "GeometryError": ("models.errors", "GeometryError"),
    "QuaternionError": ("models.errors", "QuaternionError"),
    "DatasetError": ("models.errors", "DatasetError"),
    "ModelFileError": ("models.errors", "ModelFileError"),
    # submodules
    "quaternion": ("models.quaternion", None),
    "geometry": ("models.geometry", None),
    "evaluation": ("models.evaluation", None),
}

__all__ = [
    "BOUNDARY_TOLERANCE",
    "SHAPES",
    "ConeSwing",
    "ConstraintError",
    "ConstraintOracle",
    "CorrectionModel",
    "DatasetError",
    "FieldModel",
    "GeometryError",
    "JointConstraint",
    "Limb",
    "LimbResult",
    "ModelFileError",
    "ModelsError",
    "OracleResult",
    "PolygonSwing",
    "QuaternionError",
    "SphericalPolygon",
    "SwingTwistTable",
    "TwistLimits",
    "dump_constraint",
    "dump_limb",
    "evaluate_model",
    "evaluation",
    "export_onnx",
    "geometry",
    "held_out_orientations",
    "load_constraint",
    "load_limb",
    "load_model",
    "load_shape",
    "loads_constraint",
    "loads_limb",
    "quaternion",
]


def __getattr__(name: str) -> Any:
    try:
        module, attr = _EXPORTS[name]
    except KeyError:
        raise AttributeError(f"module 'models' has no attribute {name!r}") from None
    mod = importlib.import_module(module)
    value = mod if attr is None else getattr(mod, attr)
    globals()[name] = value  # later look-ups skip __getattr__
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_EXPORTS))


if TYPE_CHECKING:  # pragma: no cover - for type checkers and IDEs only
    from models import evaluation, geometry, quaternion
    from models.constraint import (
        JointConstraint,
        dump_constraint,
        load_constraint,
        loads_constraint,
    )
    from models.errors import (
        ConstraintError,
        DatasetError,
        GeometryError,
        ModelFileError,
        ModelsError,
        QuaternionError,
    )
    from models.evaluation import evaluate_model, held_out_orientations
    from models.field import FieldModel
    from models.geometry import SphericalPolygon
    from models.kinds.base import BOUNDARY_TOLERANCE, OracleResult
    from models.limb import Limb, dump_limb, load_limb, loads_limb
    from models.limits import ConeSwing, PolygonSwing, SwingTwistTable, TwistLimits
    from models.onnx_io import CorrectionModel, export_onnx, load_model
    from models.oracle import ConstraintOracle, LimbResult
    from models.shapes import SHAPES, load_shape
