"""``rig evaluate`` as a library: a model's metrics through onnxruntime on fresh held-out
orientations (:func:`run_evaluate`: :class:`EvaluateRequest` → :class:`EvaluateResult`).

``held-out`` (the default) is :func:`models.evaluation.held_out_orientations`: half uniform on
SO(3), half within 20° of the boundary; the others are the thesis's pattern distributions
(:func:`models.nn.train.training_patterns`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from models.errors import DatasetError
from models.limb import load_limits
from rig.training.kinds import training_kind

__all__ = ["DISTRIBUTIONS", "EvaluateRequest", "EvaluateResult", "run_evaluate"]

#: ``--distribution`` values.
DISTRIBUTIONS = ("held-out", "even", "uniform", "clustered")


@dataclass(frozen=True)
class EvaluateRequest:
    """The ONNX model, the constraint it must match, how many orientations from which
    distribution (``twist``: thesis distributions with a random twist) and the seed."""

    model: str
    constraint: str
    n: int = 10_000
    distribution: str = "held-out"
    twist: bool = False
    seed: int = 12345


@dataclass
class EvaluateResult:
    """The metrics (:func:`models.evaluation.evaluate_model`, a joint's or a limb's) and what
    they were measured on, for people (``description``, then ``lines``)."""

    metrics: dict
    description: str
    lines: list[str] = field(default_factory=list)


def run_evaluate(request: EvaluateRequest) -> EvaluateResult:
    """Load the model (refused when made for another constraint), draw the orientations, run
    the model through onnxruntime and compare with the exact oracle — one joint's
    (:func:`rig.training.joint.evaluate_joint`) or a limb's held-out postures
    (:func:`rig.training.limb.evaluate_limb`), as the file's training kind says
    (:func:`rig.training.kinds.training_kind`)."""

    if request.distribution not in DISTRIBUTIONS:
        raise DatasetError(f"--distribution {request.distribution!r}: expected one of "
                           f"{', '.join(DISTRIBUTIONS)}")
    constraint = load_limits(request.constraint)
    return EvaluateResult(*training_kind(constraint).evaluate(request, constraint))
