"""``rig train`` as a library: a corrective-constraint model from a constraint or limb file
and/or a dataset, exported to ONNX with its metadata (:func:`run_train`: :class:`TrainRequest`
→ :class:`TrainResult`).

What is trained is the training kind's (:func:`rig.training.kinds.training_kind`, chosen from
the dataset when ``data`` is given, else from the file): one joint's model
(:func:`rig.training.joint.train_joint`: the default preset ``field`` builds
:mod:`models.field`, a swing field on a grid + the exact twist clamp; the others evolve and
train a GMLP, :mod:`models.nn`, reporting one progress line per generation; the ONNX file's
metadata holds the constraint, the training-data hash and the held-out metrics) or a limb's
(:func:`rig.training.limb.train_limb`). ``data`` takes a dataset written by ``rig dataset
make`` (its constraint comes from the file; the model records the dataset's content hash, the
one ``rig dataset info`` prints).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from models.datasets import load_dataset
from models.errors import ModelFileError
from models.fileio import check_output
from models.limb import load_limits
from rig.training.joint import PRESET_NAMES
from rig.training.kinds import training_kind
from rig.training.limb import LIMB_PRESETS

__all__ = ["TrainRequest", "TrainResult", "run_train"]


def _silent(_: str) -> None:
    pass


@dataclass(frozen=True)
class TrainRequest:
    """What ``rig train`` is asked: a constraint or limb file and/or a dataset (``data``; then
    the file is optional and must match the dataset's), the ONNX file to write, the preset
    (None: ``field`` for a joint, ``network`` for a limb), an optional YAML overriding a
    single-joint preset's fields (``config``) and the seed."""

    out: str | Path
    constraint: str | None = None
    data: str | None = None
    config: str | None = None
    preset: str | None = None
    seed: int = 0

    def check(self) -> None:
        """Before any training (a GMLP preset runs for minutes): the output can be written in
        an existing folder (it is never created: a misspelled folder is a mistake), the preset
        is known."""

        check_output(self.out, "--out")

        if self.preset is not None and self.preset not in PRESET_NAMES + LIMB_PRESETS:
            raise ModelFileError(f"--preset {self.preset!r}: expected one of "
                                 f"{', '.join(PRESET_NAMES + LIMB_PRESETS)}")


@dataclass
class TrainResult:
    """The trained model (:class:`models.nn.train.TrainedModel`; a limb's,
    :class:`rig.training.limb.LimbTrained`), the ONNX file written, how long it took and why
    it should not be trusted to enforce limits (empty when it meets the targets: one joint's,
    :func:`rig.training.joint.enforcement_warnings`; a limb's,
    :func:`rig.training.verdict.missed_targets`)."""

    model: Any
    path: Path
    seconds: float
    warnings: list[str] = field(default_factory=list)

    @property
    def metrics(self) -> dict:
        return self.model.metrics


def run_train(request: TrainRequest, *, echo: Callable[[str], None] = _silent) -> TrainResult:
    """Build or train the model, export it; ``echo`` receives the progress lines and the
    summary (what ``rig train`` prints)."""

    request.check()
    limits = load_limits(request.constraint) if request.constraint is not None else None
    dataset = load_dataset(request.data) if request.data is not None else None
    kind = training_kind(limits, dataset)  # each file read once
    result = TrainResult(*kind.train(request, limits, dataset, echo))
    for w in result.warnings:
        echo(f"warning: {w}")
    return result
