"""``rig evaluate`` as a library: a model's metrics through onnxruntime on fresh held-out
orientations (:func:`run_evaluate`: :class:`EvaluateRequest` → :class:`EvaluateResult`).

``held-out`` (the default) is :func:`models.evaluation.held_out_orientations`: half uniform on
SO(3), half within 20° of the boundary; the others are the thesis's pattern distributions
(:func:`models.nn.train.training_patterns`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from models.errors import DatasetError
from models.evaluation import evaluate_model, held_out_orientations
from models.limb import Limb, load_limits
from models.nn.train import training_patterns
from models.onnx_io import load_model
from models.oracle import ConstraintOracle
from rig.training.limb import evaluate_limb, limb_metric_lines
from rig.training.train import metric_lines

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
    the model through onnxruntime and compare with the exact oracle."""
    import numpy as np

    if request.distribution not in DISTRIBUTIONS:
        raise DatasetError(f"--distribution {request.distribution!r}: expected one of "
                           f"{', '.join(DISTRIBUTIONS)}")
    constraint = load_limits(request.constraint)
    if isinstance(constraint, Limb):
        if request.distribution != "held-out" or request.twist:
            raise DatasetError("--distribution/--twist: a limb model is evaluated on held-out "
                               "postures only")
        metrics, what = evaluate_limb(request.model, constraint, request.n, request.seed)
        return EvaluateResult(metrics, what, limb_metric_lines(metrics, constraint.joint_names))
    constraint.require_swing_twist("rig evaluate")
    model = load_model(request.model, expected_constraint=constraint)
    oracle = ConstraintOracle(constraint)
    n, seed, distribution = request.n, request.seed, request.distribution
    if distribution == "held-out":
        q = held_out_orientations(constraint, n, seed, oracle=oracle)
    else:
        q, _ = training_patterns(constraint, n, np.random.default_rng(seed),
                                 distribution=distribution, order="random",
                                 hemisphere="ambiguous", twist=request.twist, oracle=oracle)
    metrics = evaluate_model(model, constraint, q=q, oracle=oracle)
    info = model.network_info
    what = (f"swing field, grid {info.get('grid')}" if info.get("method") == "field" else
            f"{info.get('hidden', '?')} hidden nodes, {info.get('links', '?')} links")
    kind = ("orientations (half uniform, half within 20° of the boundary)"
            if distribution == "held-out" else f"{distribution} orientations")
    twist = " with twist" if request.twist and distribution != "held-out" else ""
    return EvaluateResult(metrics, f"{request.model}: {what}, {len(q)} held-out {kind}{twist} "
                                   f"of {constraint.name!r}", metric_lines(metrics))
