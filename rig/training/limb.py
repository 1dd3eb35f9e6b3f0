"""``rig constraint check``, ``rig train`` and ``rig evaluate`` on limb files (issue 20): the
limb model (one joint's steps are :mod:`rig.training.joint`; :mod:`rig.training.kinds` chooses
between them).

``rig train --constraint LIMB.yaml`` (or ``--data`` with a limb dataset from ``rig dataset
make --constraint LIMB.yaml``) trains a distance field per coupled polygon swing
(:mod:`models.nn.ndf`, preset ``network``, the default for limbs) or compiles the exact limb
oracle (preset ``geometric``), exports the limb model (:mod:`models.limb_model`) and scores it
through onnxruntime on held-out postures (:func:`models.limb_evaluation.held_out_postures`,
a seed the training never drew). ``rig evaluate --constraint LIMB.yaml`` scores an exported
limb model the same way.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from models import quaternion as Q
from models.datasets import field_joints
from models.errors import ModelFileError
from models.evaluation import evaluate_model
from models.limb_model import export_limb_model
from models.nn.ndf import FieldSpec, fit_limb_fields
from models.onnx_io import load_model
from models.oracle import ConstraintOracle
from rig.training.metrics import labelled_lines

__all__ = ["LIMB_METRIC_LABELS", "LIMB_PRESETS", "LimbTrained", "describe_limb",
           "evaluate_limb", "limb_metric_lines", "train_limb"]

#: ``--preset`` values for limb files; the first is the default.
LIMB_PRESETS = ("network", "geometric")

#: A limb model's held-out metrics for people, metric → label (the lines ``rig train`` prints;
#: a missed target's words, :func:`rig.training.verdict.missed_targets`).
LIMB_METRIC_LABELS = {
    "end_mean_3d_error_pct": "end-point mean 3-D error (% of limb length)",
    "end_p99_direction_error_deg": "99th pct end-point direction error (deg)",
    "frac_invalid_violating_1deg": "invalid postures left > 1 deg outside",
    "valid_moved_deg": "valid postures moved (mean deg)",
    "mean_violation_deg": "mean violation (deg)",
    "max_violation_deg": "max violation (deg)",
}

#: Held-out postures scored after training.
HELD_OUT_N = 6000


@dataclass
class LimbTrained:
    """What ``rig train`` made of a limb file: the held-out ``metrics`` and the training facts."""

    metrics: dict
    facts: dict


def limb_metric_lines(metrics: dict, joints) -> list[str]:
    """The limb metrics for people, one labelled line each (fractions in %), then each
    joint's mean direction error."""

    out = labelled_lines(metrics, LIMB_METRIC_LABELS, 44)
    for name, err in zip(joints, metrics.get("joint_mean_direction_error_deg", ()),
                         strict=False):
        out.append(f"  {'mean direction error, ' + name + ' (deg)':<44} {err:.6g}")
    return out


def describe_limb(path: str, limb, samples: int, seed: int) -> str:
    """``rig constraint check`` of a limb file: its joints, couplings, and the fraction of
    random postures each swing joint allows (a coupled joint judged at its source's corrected
    angle; ``samples`` uniform postures drawn with ``seed``)."""

    oracle = ConstraintOracle(limb)
    n = len(limb.joints)
    rng = np.random.default_rng(seed)
    q = Q.random_quaternions(samples * n, rng).reshape(samples, n, 4)
    valid = oracle.is_valid(q)
    parts = []
    for j, joint in enumerate(limb.joints):
        if joint.joint_kind.single_axis:
            lo = joint.loosest().hinge
            parts.append(f"{joint.name} hinge {lo.min_deg:g}..{lo.max_deg:g} deg")
        elif not joint.joint_kind.swing_twist and joint.constraint is not None:
            # a forearm: two intervals (a surface in SO(3): 0 % of all orientations)
            c = joint.constraint
            lo, hi = (math.degrees(x) for x in c.joint_kind.coupling_range(c))
            parts.append(f"{joint.name} {c.kind} flexion {lo:.4g}..{hi:.4g} deg")
        else:
            parts.append(f"{joint.name} {100 * float(valid[:, j].mean()):.2f} %")
    return "\n".join([f"{path}: OK", limb.summary(),
                      f"  valid       {'; '.join(parts)} of all orientations "
                      f"({samples} uniform postures)"])


def _score(model, limb, n: int, seed: int) -> dict:

    return evaluate_model(model, limb, n=n, seed=seed)


def train_limb(limb, out: str | Path, *, preset: str | None, seed: int,
               postures=None, data: dict[str, Any] | None = None,
               echo: Callable[[str], None]) -> tuple[LimbTrained, Path]:
    """Train (``network``) or compile (``geometric``) and export a limb model; ``postures``
    from a limb dataset (``data``: its file and content hash) replace the drawn ones."""

    preset = preset or LIMB_PRESETS[0]
    if preset not in LIMB_PRESETS:
        raise ModelFileError(f"--preset {preset}: a single-joint preset; for a limb file use "
                             f"{' or '.join(LIMB_PRESETS)}")
    t0 = time.perf_counter()
    fields = facts = None
    names = field_joints(limb)
    if preset == "network" and names:
        spec = FieldSpec()
        n = len(postures) if postures is not None else spec.samples
        echo(f"training {limb.name!r}: preset network, a distance field for "
             f"{', '.join(names)} ({spec.features} Fourier features, 2×{spec.hidden} tanh, "
             f"{spec.epochs} epochs on {n} postures{' of ' + data['file'] if data else ''})")
        fields, facts = fit_limb_fields(
            limb, seed, spec, postures=postures,
            progress=lambda name, s: echo(f"  {name}: trained in {s:.1f} s"))
        if data:
            facts.update({"data_file": data["file"], "data_sha256": data["sha256"]})
    else:
        why = ("no coupled polygon swing to learn; " if preset == "network" else "")
        echo(f"building {limb.name!r}: {why}the exact limb oracle compiled (geometric)")
    path = export_limb_model(limb, out, fields, facts)
    model = load_model(path, limb)
    metrics = _score(model, limb, HELD_OUT_N, seed + 1_000_003)
    seconds = time.perf_counter() - t0
    echo(f"wrote {path} ({model.metadata['jointlimits.method']}, "
         f"{model.size_bytes / 1e3:.0f} kB) in {seconds:.1f} s; held-out metrics "
         f"({HELD_OUT_N} postures):")
    for line in limb_metric_lines(metrics, limb.joint_names):
        echo(line)
    return LimbTrained(metrics, facts or {}), path


def evaluate_limb(model_path: str, limb, n: int, seed: int) -> tuple[dict, str]:
    """Score an exported limb model on ``n`` fresh held-out postures: ``(metrics, what)``."""

    model = load_model(model_path, limb)
    metrics = _score(model, limb, n, seed)
    return metrics, (f"{model_path}: limb model ({model.metadata['jointlimits.method']}), {n} "
                     f"held-out postures of {limb.name!r} (a third uniform, a third near a "
                     f"boundary, a third valid)")
