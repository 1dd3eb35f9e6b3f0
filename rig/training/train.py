"""``rig train`` as a library: a corrective-constraint model from a constraint or a dataset,
exported to ONNX with its metadata (:func:`run_train`: :class:`TrainRequest` →
:class:`TrainResult`).

The default preset ``field`` builds :mod:`models.field` (a swing field on a grid + the exact
twist clamp); the others evolve and train a GMLP (:mod:`models.nn`), reporting one progress
line per generation. The ONNX file's metadata holds the constraint, the training-data hash and
the held-out metrics (:func:`models.onnx_io.export_onnx`). ``data`` takes a dataset written by
``rig dataset make`` (its constraint comes from the file; the model records the dataset's
content hash, the one ``rig dataset info`` prints).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from models.datasets import limb_postures, load_dataset
from models.errors import ConstraintError, DatasetError, ModelFileError
from models.fileio import check_output
from models.limb import Limb, load_limits
from models.nn.config import get_config, load_config
from models.nn.train import train_correction
from models.onnx_io import export_onnx
from rig.training.limb import LIMB_PRESETS, train_limb
from rig.training.metrics import labelled_lines
from rig.training.verdict import MODEL_TARGETS, missed_targets

__all__ = ["PRESET_NAMES", "TrainRequest", "TrainResult",
           "enforcement_warnings", "metric_lines", "run_train"]

#: ``--preset`` values (:mod:`models.nn.config`); ``field`` is the default.
PRESET_NAMES = ("field", "best", "compact", "thesis", "fixed")

_LABELS = {
    "mse": "MSE (correction quaternion)",
    "mean_3d_error_pct": "mean 3-D error (% of 2.0)",
    "max_3d_error_pct": "max 3-D error (% of 2.0)",
    "frac_above_2pct": "patterns > 2 % error",
    "frac_above_7_5pct": "patterns > 7.5 % error",
    "mean_angular_error_deg": "mean angular error (deg)",
    "p99_angular_error_deg": "99th pct angular error (deg)",
    "frac_invalid_violating_1deg": "invalid inputs left > 1 deg outside",
    "mean_violation_deg": "mean violation (deg)",
    "max_violation_deg": "max violation (deg)",
    "mean_identity_error_deg": "mean identity error, valid inputs (deg)",
    "max_identity_error_deg": "max identity error, valid inputs (deg)",
}


def _silent(_: str) -> None:
    pass


def metric_lines(metrics: dict) -> list[str]:
    """Held-out metrics for people, one labelled line each (fractions in %)."""

    return labelled_lines(metrics, _LABELS, 42)


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
    """The trained model (:class:`models.nn.train.TrainedModel`), the ONNX file written, how
    long it took and why it should not be trusted to enforce limits (empty when it meets the
    targets: :func:`enforcement_warnings`; a limb's,
    :func:`rig.training.verdict.missed_targets`)."""

    model: Any
    path: Path
    seconds: float
    warnings: list[str] = field(default_factory=list)

    @property
    def metrics(self) -> dict:
        return self.model.metrics


def _load_data(ds, data_path, given, constraint_path):
    """(constraint, (inputs, targets, content hash)) of a loaded quaternion dataset ``ds``;
    checks it against ``given``, the constraint file's content (None without one)."""

    c = ds.constraint()
    if c is None or ds.inputs.shape[1:] != (4,) or ds.targets.shape[1:] != (4,):
        raise DatasetError(f"--data: {data_path} is not a quaternion dataset with a constraint "
                           "(make one with `rig dataset make --kind quaternion`)")
    if given is not None and given != c:
        raise DatasetError(f"--data: {data_path} was made for constraint {c.name!r}, which "
                           f"differs from --constraint {constraint_path}")
    return c, (ds.inputs, ds.targets, ds.content_hash())


def _limb_source(request: TrainRequest):
    """``(limb, postures, data)`` when the request is about a limb (a limb file, or a limb
    dataset — postures and ``{"file", "sha256"}``); else ``(None, constraint or None, dataset
    or None)``: each file read once."""

    limits = load_limits(request.constraint) if request.constraint is not None else None
    if request.data is not None:
        ds = load_dataset(request.data)
        if ds.meta.get("kind") != "limb":
            if isinstance(limits, Limb):
                raise DatasetError(f"--data: {request.data} is not a limb dataset (make one "
                                   f"with `rig dataset make --constraint {request.constraint}`)")
            return None, limits, ds
        limb, postures = limb_postures(ds)
        if limits is not None and (not isinstance(limits, Limb)
                                   or limits.content_hash() != limb.content_hash()):
            raise DatasetError(f"--data: {request.data} was made for limb {limb.name!r}, "
                               f"which differs from --constraint {request.constraint}")
        data = {"file": str(request.data), "sha256": ds.content_hash()}
    elif isinstance(limits, Limb):
        limb, postures, data = limits, None, None
    else:
        return None, limits, None
    if request.config is not None:
        raise ModelFileError("--config: for single-joint presets; a limb model takes none")
    return limb, postures, data


def run_train(request: TrainRequest, *, echo: Callable[[str], None] = _silent) -> TrainResult:
    """Build or train the model, export it; ``echo`` receives the progress lines and the
    summary (what ``rig train`` prints)."""
    import numpy as np

    request.check()
    limb, source, data = _limb_source(request)  # a joint's: (None, constraint, dataset)
    if limb is not None:
        t0 = time.perf_counter()
        trained, path = train_limb(limb, request.out, preset=request.preset,
                                   seed=request.seed, postures=source, data=data, echo=echo)
        result = TrainResult(trained, path, time.perf_counter() - t0,
                             missed_targets(trained.metrics, limb=True))
        for w in result.warnings:
            echo(f"warning: {w}")
        return result
    preset = request.preset or PRESET_NAMES[0]
    if preset not in PRESET_NAMES:
        raise ModelFileError(f"--preset {preset}: for a limb file only; for a single joint use "
                             f"{', '.join(PRESET_NAMES)}")
    cfg = load_config(request.config, preset) if request.config else get_config(preset)
    patterns = None
    if request.data is not None:
        constraint, patterns = _load_data(data, request.data, source, request.constraint)
    elif request.constraint is None:
        raise ConstraintError("--constraint: required (or --data with a dataset file)")
    else:
        constraint = source
    constraint.require_swing_twist("rig train")
    is_field = cfg["model"]["method"] == "field"
    gens = cfg["evolution"]["generations"]
    src = f" on {len(patterns[0])} patterns of {request.data}" if patterns is not None else ""
    if is_field:
        echo(f"building {constraint.name!r}: preset {preset}, swing field on a "
             f"{cfg['model']['grid']}-node grid + exact twist clamp{src}")
    else:
        echo(f"training {constraint.name!r}: preset {preset}, population "
             f"{cfg['evolution']['population']}, {gens} generations, ≤ "
             f"{cfg['training']['max_epochs']} epochs, {cfg['evolution']['repeats']} run(s){src}")

    def progress(st):
        run = f"run {st.run}/{st.runs}  " if st.runs > 1 else ""
        echo(f"  {run}generation {st.generation:3d}/{gens}  best fitness {st.best_fitness:.6f}"
             f"  val MSE {st.best_val_mse:.3e}  hidden {st.best_hidden:2d}  "
             f"elapsed {st.elapsed_s:6.1f} s")

    t0 = time.perf_counter()
    model = train_correction(constraint, cfg, np.random.default_rng(request.seed), progress,
                             patterns=patterns)
    extra = {"preset": preset, "seed": request.seed, "config": cfg}
    if request.data is not None:
        extra["data_file"] = str(request.data)
    path = export_onnx(model.network, request.out, constraint_yaml=constraint.to_yaml(),
                       training_data_sha256=model.data_sha256, metrics=model.metrics,
                       extra=extra)
    seconds = time.perf_counter() - t0
    what = ("swing field" if is_field else
            f"{model.network.n_hidden} hidden nodes, {model.network.n_links} links")
    echo(f"wrote {path} ({what}) in {seconds:.1f} s; training-data sha256 "
         f"{model.data_sha256[:16]}…; held-out metrics:")
    for line in metric_lines(model.metrics):
        echo(line)
    result = TrainResult(model, Path(path), seconds, enforcement_warnings(model.metrics))
    for w in result.warnings:
        echo(f"warning: {w}")
    return result


def enforcement_warnings(metrics: dict) -> list[str]:
    """Why a freshly trained model should not be trusted to enforce limits (empty when it
    meets two of the targets every verdict uses, :data:`rig.training.verdict.MODEL_TARGETS`:
    invalid inputs left > 1° outside, mean 3-D error): the live supervisor still projects
    every goal, but the model's corrections would be overridden on every such input."""
    out = []
    frac = metrics.get("frac_invalid_violating_1deg")
    if frac is not None and frac > MODEL_TARGETS["frac_invalid_violating_1deg"].limit:
        worst = metrics.get("max_violation_deg")
        out.append(f"this model leaves {100 * frac:.1f} % of the held-out invalid "
                   "orientations more than 1° outside the constraint"
                   + (f" (worst {worst:.0f}°)" if worst is not None else "")
                   + "; for enforcement use the default preset 'field', which does not")
    err = metrics.get("mean_3d_error_pct")
    limit = MODEL_TARGETS["mean_3d_error_pct"].limit
    if err is not None and err > limit and not out:
        out.append(f"this model's mean 3-D error is {err:.2f} % (the target for enforcement "
                   f"is {limit:g} %); for enforcement use "
                   "the default preset 'field'")
    return out
