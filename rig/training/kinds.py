"""The training kinds: what ``rig constraint check``, ``rig dataset make``, ``rig train`` and
``rig evaluate`` do differently for one joint's constraint file and for a limb file, behind one
object chosen in one place (:func:`training_kind`), so that the modules running those commands
never ask "one joint or a whole limb?".

A joint is a limb of one joint, but the two models still differ in what they compute: one
joint's is an ``[N, 4]`` orientation model (:data:`models.onnx_io.JOINT_CONTRACT`) built from
the thesis's quaternion datasets by the ``field`` preset or a GMLP preset
(:mod:`rig.training.joint`); a limb's is an ``[N, J, 4]`` posture model
(:data:`models.onnx_io.LIMB_CONTRACT`) with a distance field per coupled polygon swing or the
exact limb oracle compiled (:mod:`rig.training.limb`). Each kind carries its steps
(:class:`TrainingKind`):

:meth:`~TrainingKind.describe`
    one joint: its limits and the % of all orientations it allows; a limb: its joints and the %
    each swing joint allows.
:meth:`~TrainingKind.dataset_kind`
    one joint: ``quaternion`` (``--kind limb`` refused); a limb: ``limb``.
:meth:`~TrainingKind.train`
    one joint: preset ``field`` or a GMLP, and its enforcement warnings; a limb: preset
    ``network`` or ``geometric``, and the targets it misses.
:meth:`~TrainingKind.evaluate`
    one joint: held-out orientations or a thesis distribution; a limb: held-out postures only.
"""

from __future__ import annotations

import time
from abc import ABC, abstractmethod
from collections.abc import Callable
from pathlib import Path
from typing import Any

from models.constraint import JointConstraint
from models.datasets import limb_postures
from models.errors import DatasetError, ModelFileError
from models.limb import Limb
from rig.training.joint import (
    describe_joint,
    enforcement_warnings,
    evaluate_joint,
    train_joint,
)
from rig.training.limb import describe_limb, evaluate_limb, limb_metric_lines, train_limb
from rig.training.verdict import missed_targets

__all__ = ["JOINT_TRAINING", "LIMB_TRAINING", "JointTraining", "LimbTraining", "TrainingKind",
           "training_kind"]


class TrainingKind(ABC):
    """The steps of ``rig constraint check``, ``rig dataset make``, ``rig train`` and ``rig
    evaluate`` that differ between one joint's constraint file and a limb file; ``limits`` is
    what :func:`models.limb.load_limits` read (None without a file where one is optional)."""

    #: ``"joint"`` or ``"limb"``.
    name: str

    @abstractmethod
    def describe(self, path: str, limits, samples: int, seed: int) -> str:
        """What ``rig constraint check`` prints of ``limits`` read from ``path``."""

    @abstractmethod
    def dataset_kind(self, asked: str, path: str) -> str:
        """The ``--kind`` of dataset ``rig dataset make`` makes from this file (``asked``: the
        ``--kind`` given, ``quaternion`` or ``limb``); :class:`DatasetError` when it cannot."""

    @abstractmethod
    def train(self, request, limits, dataset, echo: Callable[[str], None]
              ) -> tuple[Any, Path, float, list[str]]:
        """Train or build the model ``request`` (a :class:`rig.training.TrainRequest`) asks for
        from ``limits`` and/or ``dataset`` (a loaded ``--data``, None without one), export it;
        ``(model, path written, seconds, warnings)``."""

    @abstractmethod
    def evaluate(self, request, limits) -> tuple[dict, str, list[str]]:
        """Score the model ``request`` (a :class:`rig.training.EvaluateRequest`) names against
        ``limits``: ``(metrics, description, metric lines)``."""


class JointTraining(TrainingKind):
    """One joint's constraint file (:mod:`rig.training.joint`)."""

    name = "joint"

    def describe(self, path: str, limits, samples: int, seed: int) -> str:
        return describe_joint(path, limits, samples, seed)

    def dataset_kind(self, asked: str, path: str) -> str:
        if asked == "limb":
            raise DatasetError(f"--kind limb: {path} is a single-joint constraint file, "
                               "not a limb file")
        return asked

    def train(self, request, limits, dataset, echo):
        if dataset is not None and training_kind(limits) is not self:
            raise DatasetError(f"--data: {request.data} is not a limb dataset (make one "
                               f"with `rig dataset make --constraint {request.constraint}`)")
        model, path, seconds = train_joint(request, limits, dataset, echo)
        return model, path, seconds, enforcement_warnings(model.metrics)

    def evaluate(self, request, limits):
        return evaluate_joint(request, limits)


class LimbTraining(TrainingKind):
    """A limb file, or a limb dataset (:mod:`rig.training.limb`)."""

    name = "limb"

    def describe(self, path: str, limits, samples: int, seed: int) -> str:
        return describe_limb(path, limits, samples, seed)

    def dataset_kind(self, asked: str, path: str) -> str:
        return "limb"  # --kind quaternion or limb: a limb file makes a limb dataset

    def train(self, request, limits, dataset, echo):
        limb, postures, data = limits, None, None
        if dataset is not None:
            limb, postures = limb_postures(dataset)
            if limits is not None and (training_kind(limits) is not self
                                       or limits.content_hash() != limb.content_hash()):
                raise DatasetError(f"--data: {request.data} was made for limb {limb.name!r}, "
                                   f"which differs from --constraint {request.constraint}")
            data = {"file": str(request.data), "sha256": dataset.content_hash()}
        if request.config is not None:
            raise ModelFileError("--config: for single-joint presets; a limb model takes none")
        t0 = time.perf_counter()
        trained, path = train_limb(limb, request.out, preset=request.preset,
                                   seed=request.seed, postures=postures, data=data, echo=echo)
        return (trained, path, time.perf_counter() - t0,
                missed_targets(trained.metrics, limb=True))

    def evaluate(self, request, limits):
        if request.distribution != "held-out" or request.twist:
            raise DatasetError("--distribution/--twist: a limb model is evaluated on held-out "
                               "postures only")
        metrics, what = evaluate_limb(request.model, limits, request.n, request.seed)
        return metrics, what, limb_metric_lines(metrics, limits.joint_names)


#: One joint's constraint file.
JOINT_TRAINING = JointTraining()
#: A limb file.
LIMB_TRAINING = LimbTraining()

#: The kind of what :func:`models.limb.load_limits` reads, by its class.
_BY_LIMITS: dict[type, TrainingKind] = {JointConstraint: JOINT_TRAINING, Limb: LIMB_TRAINING}
#: The kind of a dataset, by its ``kind`` metadata (``rig dataset make --kind``); any other
#: dataset is one joint's (a quaternion dataset; the others are refused by its training).
_BY_DATASET: dict[str, TrainingKind] = {"limb": LIMB_TRAINING}


def training_kind(limits, dataset=None) -> TrainingKind:
    """The one place that chooses the training kind: ``dataset``'s (a loaded ``--data``) when
    one is given, else that of ``limits`` (what :func:`models.limb.load_limits` read: a
    :class:`~models.limb.Limb` or a :class:`~models.constraint.JointConstraint`); one joint's
    without either (its steps then ask for ``--constraint``)."""
    if dataset is not None:
        return _BY_DATASET.get(dataset.meta.get("kind"), JOINT_TRAINING)
    return _BY_LIMITS.get(type(limits), JOINT_TRAINING)
