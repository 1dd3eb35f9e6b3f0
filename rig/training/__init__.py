"""Models for the live loop, from constraint files: checking a constraint, making the thesis's
datasets, training a corrective model and exporting it to ONNX, evaluating it on held-out
orientations — the application's side of :mod:`models`.

Modules
-------
:mod:`~rig.training.train`
    :func:`run_train` (:class:`TrainRequest` → :class:`TrainResult`), ``rig train``.
:mod:`~rig.training.evaluate`
    :func:`run_evaluate` (:class:`EvaluateRequest` → :class:`EvaluateResult`), ``rig evaluate``.
:mod:`~rig.training.kinds`
    the training kinds: what the commands below do differently for one joint's constraint
    file and a limb file, chosen in one place (:func:`~rig.training.kinds.training_kind`).
:mod:`~rig.training.joint`
    one joint's steps: the model (``--preset field|best|compact|thesis|fixed``), its scores and
    enforcement warnings.
:mod:`~rig.training.limb`
    a limb file's steps: the limb model (``--preset network|geometric``) and its scores.
:mod:`~rig.training.metrics`
    the metrics as labelled lines.
:mod:`~rig.training.datasets`
    ``rig dataset make`` / ``info``.
:mod:`~rig.training.constraints`
    ``rig constraint check``.
"""

from rig.training.evaluate import EvaluateRequest, EvaluateResult, run_evaluate
from rig.training.joint import PRESET_NAMES, enforcement_warnings, metric_lines
from rig.training.train import TrainRequest, TrainResult, run_train

__all__ = ["PRESET_NAMES", "EvaluateRequest", "EvaluateResult",
           "TrainRequest", "TrainResult", "enforcement_warnings", "metric_lines",
           "run_evaluate", "run_train"]
