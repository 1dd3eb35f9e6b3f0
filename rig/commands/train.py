"""``rig train`` and ``rig evaluate``: learn a corrective constraint, export it, check it.

``rig train (--constraint FILE | --data FILE.npz) --out MODEL.onnx [--config YAML]
[--preset field|best|compact|thesis|fixed] [--seed N]`` builds the model (preset ``field``, the
default: :mod:`models.field`; the others evolve and train a GMLP, :mod:`models.nn`, printing one
progress line per generation) and writes an ONNX model whose metadata holds the constraint, the
training-data hash and the held-out metrics. ``--data`` takes a dataset written by
``rig dataset make`` (its constraint comes from the file; the model records the dataset's
content hash — the one ``rig dataset info`` prints); a GMLP preset trains on its patterns.

``rig evaluate --model MODEL.onnx --constraint FILE`` runs the model through onnxruntime on fresh
held-out orientations (:func:`models.evaluation.held_out_orientations`: half uniform on SO(3),
half within 20° of the boundary; or a thesis-style distribution) and prints the metrics.
"""

from __future__ import annotations

import time

import click

PRESET_NAMES = ["field", "best", "compact", "thesis", "fixed"]

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


def _print_metrics(metrics: dict, echo=click.echo) -> None:
    for key, label in _LABELS.items():
        if key in metrics:
            v = metrics[key]
            text = f"{100 * v:.3f} %" if key.startswith("frac_") else f"{v:.6g}"
            echo(f"  {label:<42} {text}")


@click.command()
@click.option("--constraint", "constraint_path", type=click.Path(dir_okay=False), default=None,
              help="Constraint YAML file (optional with --data: the dataset names its own).")
@click.option("--data", "data_path", type=click.Path(dir_okay=False), default=None,
              help="Dataset .npz written by `rig dataset make` to train on.")
@click.option("--out", "out_path", required=True, type=click.Path(dir_okay=False),
              help="Where to write the ONNX model.")
@click.option("--config", "config_path", type=click.Path(dir_okay=False), default=None,
              help="YAML overriding fields of the preset.")
@click.option("--preset", type=click.Choice(PRESET_NAMES), default="field", show_default=True,
              help="Starting configuration (models.nn.config).")
@click.option("--seed", type=int, default=0, show_default=True, help="Random seed.")
def train(constraint_path, data_path, out_path, config_path, preset, seed) -> None:
    """Train a corrective-constraint model and export it to ONNX."""
    run_train(constraint_path, out_path, config_path=config_path, preset=preset, seed=seed,
              data_path=data_path)


def _load_data(data_path, constraint_path):
    """(constraint, (inputs, targets, content hash)) of a dataset file; checks the constraint."""
    from models.constraint import load_constraint
    from models.datasets import load_dataset
    from models.errors import DatasetError

    ds = load_dataset(data_path)
    c = ds.constraint()
    if c is None or ds.inputs.shape[1:] != (4,) or ds.targets.shape[1:] != (4,):
        raise DatasetError(f"--data: {data_path} is not a quaternion dataset with a constraint "
                           "(make one with `rig dataset make --kind quaternion`)")
    if constraint_path is not None and load_constraint(constraint_path) != c:
        raise DatasetError(f"--data: {data_path} was made for constraint {c.name!r}, which "
                           f"differs from --constraint {constraint_path}")
    return c, (ds.inputs, ds.targets, ds.content_hash())


def run_train(constraint_path, out_path, *, config_path=None, preset="field", seed=0,
              echo=click.echo, data_path=None):
    """What ``rig train`` does; returns the :class:`models.nn.train.TrainedModel`."""
    import numpy as np

    from models.constraint import load_constraint
    from models.errors import ConstraintError
    from models.nn.config import get_config, load_config
    from models.nn.train import train_correction
    from models.onnx_io import export_onnx

    cfg = load_config(config_path, preset) if config_path else get_config(preset)
    patterns = None
    if data_path is not None:
        constraint, patterns = _load_data(data_path, constraint_path)
    elif constraint_path is None:
        raise ConstraintError("--constraint: required (or --data with a dataset file)")
    else:
        constraint = load_constraint(constraint_path)
    field = cfg["model"]["method"] == "field"
    gens = cfg["evolution"]["generations"]
    src = f" on {len(patterns[0])} patterns of {data_path}" if patterns is not None else ""
    if field:
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
    model = train_correction(constraint, cfg, np.random.default_rng(seed), progress,
                             patterns=patterns)
    extra = {"preset": preset, "seed": seed, "config": cfg}
    if data_path is not None:
        extra["data_file"] = str(data_path)
    path = export_onnx(model.network, out_path, constraint_yaml=constraint.to_yaml(),
                       training_data_sha256=model.data_sha256, metrics=model.metrics,
                       extra=extra)
    what = ("swing field" if field else
            f"{model.network.n_hidden} hidden nodes, {model.network.n_links} links")
    echo(f"wrote {path} ({what}) in {time.perf_counter() - t0:.1f} s; training-data sha256 "
         f"{model.data_sha256[:16]}…; held-out metrics:")
    _print_metrics(model.metrics, echo)
    for w in enforcement_warnings(model.metrics):
        echo(f"warning: {w}")
    return model


#: What a model must reach on held-out orientations to be used for enforcement as is (the
#: targets the report's verdict uses, :data:`rig.report.session.MODEL_TARGETS`).
ENFORCEMENT_TARGETS = {"frac_invalid_violating_1deg": 0.01, "mean_3d_error_pct": 0.8}


def enforcement_warnings(metrics: dict) -> list[str]:
    """Why a freshly trained model should not be trusted to enforce limits (empty when it
    meets :data:`ENFORCEMENT_TARGETS`): the live supervisor still projects every goal, but the
    model's corrections would be overridden on every such input."""
    out = []
    frac = metrics.get("frac_invalid_violating_1deg")
    if frac is not None and frac > ENFORCEMENT_TARGETS["frac_invalid_violating_1deg"]:
        worst = metrics.get("max_violation_deg")
        out.append(f"this model leaves {100 * frac:.1f} % of the held-out invalid "
                   "orientations more than 1° outside the constraint"
                   + (f" (worst {worst:.0f}°)" if worst is not None else "")
                   + "; for enforcement use the default preset 'field', which does not")
    err = metrics.get("mean_3d_error_pct")
    if err is not None and err > ENFORCEMENT_TARGETS["mean_3d_error_pct"] and not out:
        out.append(f"this model's mean 3-D error is {err:.2f} % (the target for enforcement "
                   "is 0.8 %); for enforcement use the default preset 'field'")
    return out


@click.command()
@click.option("--model", "model_path", required=True, type=click.Path(dir_okay=False),
              help="ONNX model written by `rig train`.")
@click.option("--constraint", "constraint_path", required=True,
              type=click.Path(dir_okay=False), help="Constraint YAML the model must match.")
@click.option("--n", "n", type=click.IntRange(min=10), default=10000, show_default=True,
              help="Number of held-out orientations.")
@click.option("--distribution", type=click.Choice(["held-out", "even", "uniform", "clustered"]),
              default="held-out", show_default=True,
              help="held-out: half uniform on SO(3), half within 20° of the boundary; the "
                   "others are the thesis's pattern distributions.")
@click.option("--twist/--no-twist", default=False, show_default=True,
              help="Thesis distributions: add a random twist about the limb axis.")
@click.option("--seed", type=int, default=12345, show_default=True, help="Random seed.")
def evaluate(model_path, constraint_path, n, distribution, twist, seed) -> None:
    """Print a model's accuracy metrics on fresh held-out orientations."""
    run_evaluate(model_path, constraint_path, n=n, distribution=distribution, twist=twist,
                 seed=seed)


def run_evaluate(model_path, constraint_path, *, n=10000, distribution="held-out", twist=False,
                 seed=12345, echo=click.echo) -> dict:
    """What ``rig evaluate`` does (:func:`models.evaluation.evaluate_model`); returns metrics."""
    import numpy as np

    from models.constraint import load_constraint
    from models.evaluation import evaluate_model, held_out_orientations
    from models.nn.train import _oracle, training_patterns
    from models.onnx_io import load_model

    constraint = load_constraint(constraint_path)
    model = load_model(model_path, expected_constraint=constraint)
    oracle = _oracle(constraint)
    if distribution == "held-out":
        q = held_out_orientations(constraint, n, seed, oracle=oracle)
    else:
        q, _ = training_patterns(constraint, n, np.random.default_rng(seed),
                                 distribution=distribution, order="random",
                                 hemisphere="ambiguous", twist=twist, oracle=oracle)
    metrics = evaluate_model(model, constraint, q=q, oracle=oracle)
    info = model.network_info
    what = (f"swing field, grid {info.get('grid')}" if info.get("method") == "field" else
            f"{info.get('hidden', '?')} hidden nodes, {info.get('links', '?')} links")
    kind = ("orientations (half uniform, half within 20° of the boundary)"
            if distribution == "held-out" else f"{distribution} orientations")
    echo(f"{model_path}: {what}, {len(q)} held-out {kind}"
         f"{' with twist' if twist and distribution != 'held-out' else ''} of "
         f"{constraint.name!r}")
    _print_metrics(metrics, echo)
    return metrics
