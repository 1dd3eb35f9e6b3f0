"""``rig constraint check``, ``rig train`` and ``rig evaluate`` on one joint's constraint file:
the corrective model of a single joint (the limb model's steps are :mod:`rig.training.limb`;
:mod:`rig.training.kinds` chooses between them).

The default preset ``field`` builds :mod:`models.field` (a swing field on a grid + the exact
twist clamp); the others evolve and train a GMLP (:mod:`models.nn`), reporting one progress
line per generation. The ONNX file's metadata holds the constraint, the training-data hash and
the held-out metrics (:func:`models.onnx_io.export_onnx`). A quaternion dataset written by
``rig dataset make`` may replace the drawn patterns (its constraint comes from the file; the
model records the dataset's content hash, the one ``rig dataset info`` prints).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from models import quaternion as Q
from models.errors import ConstraintError, DatasetError, ModelFileError
from models.evaluation import evaluate_model, held_out_orientations
from models.nn.config import get_config, load_config
from models.nn.train import train_correction, training_patterns
from models.onnx_io import export_onnx, load_model
from models.oracle import ConstraintOracle
from rig.training.metrics import labelled_lines
from rig.training.verdict import MODEL_TARGETS

__all__ = ["PRESET_NAMES", "describe_joint", "enforcement_warnings", "evaluate_joint",
           "metric_lines", "train_joint"]

#: ``--preset`` values for one joint's constraint file (:mod:`models.nn.config`); the first,
#: ``field``, is the default.
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


def metric_lines(metrics: dict) -> list[str]:
    """Held-out metrics for people, one labelled line each (fractions in %)."""

    return labelled_lines(metrics, _LABELS, 42)


def describe_joint(path: str, c, samples: int, seed: int) -> str:
    """``rig constraint check`` of one joint's constraint ``c`` read from ``path``: its limits
    and the fraction of all orientations it allows (``samples`` uniform, drawn with ``seed``)."""

    if c.hinge is not None:  # a curve in SO(3): no fraction of orientations to sample
        return "\n".join([f"{path}: OK", c.summary(),
                          f"  valid       the rotations about the axis within "
                          f"{c.hinge.max_deg - c.hinge.min_deg:g} deg (a curve: 0 % of all "
                          f"orientations; the oracle corrects every other one onto it)"])
    oracle = ConstraintOracle(c)
    rng = np.random.default_rng(seed)
    q = Q.random_quaternions(samples, rng)
    valid = oracle.is_valid(q)
    frac = float(valid.mean())
    # binomial standard error of the Monte-Carlo estimate
    se = math.sqrt(max(frac * (1 - frac), 1e-12) / samples)
    lines = [f"{path}: OK", c.summary()]
    lines.append(
        f"  valid       {100 * frac:.2f} % ± {100 * se:.2f} % of all orientations "
        f"({samples} uniform samples)"
    )
    return "\n".join(lines)


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


def train_joint(request, given, ds, echo: Callable[[str], None]) -> tuple[Any, Path, float]:
    """Build or train one joint's model for ``request`` (a :class:`rig.training.TrainRequest`)
    from ``given``, the constraint file's content (None without one), and/or ``ds``, the
    quaternion dataset (None without one), export it; ``echo`` receives the progress lines and
    the summary. Returns ``(model, path, seconds)``."""

    preset = request.preset or PRESET_NAMES[0]
    if preset not in PRESET_NAMES:
        raise ModelFileError(f"--preset {preset}: for a limb file only; for a single joint use "
                             f"{', '.join(PRESET_NAMES)}")
    cfg = load_config(request.config, preset) if request.config else get_config(preset)
    patterns = None
    if request.data is not None:
        constraint, patterns = _load_data(ds, request.data, given, request.constraint)
    elif request.constraint is None:
        raise ConstraintError("--constraint: required (or --data with a dataset file)")
    else:
        constraint = given
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
    return model, Path(path), seconds


def evaluate_joint(request, constraint) -> tuple[dict, str, list[str]]:
    """``rig evaluate`` of one joint's model for ``request`` (a
    :class:`rig.training.EvaluateRequest`) against its ``constraint``: the model (refused when
    made for another constraint) run through onnxruntime on fresh orientations of the
    requested distribution, compared with the exact oracle. Returns ``(metrics, description,
    lines)``."""
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
    return metrics, (f"{request.model}: {what}, {len(q)} held-out {kind}{twist} "
                     f"of {constraint.name!r}"), metric_lines(metrics)


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
