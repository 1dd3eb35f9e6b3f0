"""``rig train`` and ``rig evaluate``: learn a corrective constraint, export it, check it.

``rig train --constraint FILE --out MODEL.onnx [--config YAML]
[--preset best|compact|thesis|fixed] [--seed N]`` evolves and trains a GMLP (:mod:`models.nn`)
on patterns of the constraint, prints one progress line per generation, and writes an ONNX
model whose metadata holds the constraint, the training-data hash and the held-out metrics.

``rig evaluate --model MODEL.onnx --constraint FILE`` runs the model through onnxruntime on
fresh held-out orientations and prints the metrics of :func:`models.metrics.evaluate`.
"""

from __future__ import annotations

import time

import click

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


def _print_metrics(metrics: dict) -> None:
    for key, label in _LABELS.items():
        if key in metrics:
            v = metrics[key]
            text = f"{100 * v:.3f} %" if key.startswith("frac_") else f"{v:.6g}"
            click.echo(f"  {label:<42} {text}")


@click.command()
@click.option("--constraint", "constraint_path", required=True,
              type=click.Path(dir_okay=False), help="Constraint YAML file.")
@click.option("--out", "out_path", required=True, type=click.Path(dir_okay=False),
              help="Where to write the ONNX model.")
@click.option("--config", "config_path", type=click.Path(dir_okay=False), default=None,
              help="YAML overriding fields of the preset.")
@click.option("--preset", type=click.Choice(["best", "compact", "thesis", "fixed"]),
              default="best", show_default=True,
              help="Starting configuration (models.nn.config).")
@click.option("--seed", type=int, default=0, show_default=True, help="Random seed.")
def train(constraint_path, out_path, config_path, preset, seed) -> None:
    """Train a corrective-constraint network and export it to ONNX."""
    run_train(constraint_path, out_path, config_path=config_path, preset=preset, seed=seed)


def run_train(constraint_path, out_path, *, config_path=None, preset="best", seed=0,
              echo=click.echo):
    """What ``rig train`` does; returns the :class:`models.nn.train.TrainedModel`."""
    import numpy as np

    from models.constraint import load_constraint
    from models.nn.config import get_config, load_config
    from models.nn.train import train_correction
    from models.onnx_io import export_onnx

    constraint = load_constraint(constraint_path)
    cfg = load_config(config_path, preset) if config_path else get_config(preset)
    gens = cfg["evolution"]["generations"]
    echo(f"training {constraint.name!r}: preset {preset}, population "
         f"{cfg['evolution']['population']}, {gens} generations, ≤ "
         f"{cfg['training']['max_epochs']} epochs, {cfg['evolution']['repeats']} run(s)")

    def progress(st):
        echo(f"  generation {st.generation:3d}/{gens}  best fitness {st.best_fitness:.6f}  "
             f"val MSE {st.best_val_mse:.3e}  hidden {st.best_hidden:2d}  "
             f"elapsed {st.elapsed_s:6.1f} s")

    t0 = time.perf_counter()
    model = train_correction(constraint, cfg, np.random.default_rng(seed), progress)
    path = export_onnx(model.network, out_path, constraint_yaml=constraint.to_yaml(),
                       training_data_sha256=model.data_sha256, metrics=model.metrics,
                       extra={"preset": preset, "seed": seed, "config": cfg})
    echo(f"wrote {path} ({model.network.n_hidden} hidden nodes, {model.network.n_links} links) "
         f"in {time.perf_counter() - t0:.1f} s; held-out metrics:")
    _print_metrics(model.metrics)
    return model


@click.command()
@click.option("--model", "model_path", required=True, type=click.Path(dir_okay=False),
              help="ONNX model written by `rig train`.")
@click.option("--constraint", "constraint_path", required=True,
              type=click.Path(dir_okay=False), help="Constraint YAML the model must match.")
@click.option("--n", "n", type=click.IntRange(min=10), default=3000, show_default=True,
              help="Number of held-out orientations.")
@click.option("--distribution", type=click.Choice(["even", "uniform", "clustered"]),
              default="even", show_default=True, help="Held-out pattern distribution.")
@click.option("--twist/--no-twist", default=False, show_default=True,
              help="Add a random twist about the limb axis (as live sensor data has).")
@click.option("--seed", type=int, default=12345, show_default=True, help="Random seed.")
def evaluate(model_path, constraint_path, n, distribution, twist, seed) -> None:
    """Print a model's accuracy metrics on fresh held-out orientations."""
    run_evaluate(model_path, constraint_path, n=n, distribution=distribution, twist=twist,
                 seed=seed)


def run_evaluate(model_path, constraint_path, *, n=3000, distribution="even", twist=False,
                 seed=12345, echo=click.echo) -> dict:
    """What ``rig evaluate`` does; returns the metrics."""
    import numpy as np

    from models import metrics as M
    from models.constraint import load_constraint
    from models.nn.train import _oracle, training_patterns
    from models.onnx_io import load_model

    constraint = load_constraint(constraint_path)
    model = load_model(model_path, expected_constraint=constraint)
    oracle = _oracle(constraint)
    q, _ = training_patterns(constraint, n, np.random.default_rng(seed),
                             distribution=distribution, order="random", hemisphere="ambiguous",
                             twist=twist, oracle=oracle)
    metrics = M.evaluate(model.correction, oracle, q)
    info = model.network_info
    echo(f"{model_path}: {info.get('hidden', '?')} hidden nodes, {info.get('links', '?')} links, "
         f"{len(q)} held-out {distribution} orientations{' with twist' if twist else ''} of "
         f"{constraint.name!r}")
    _print_metrics(metrics)
    return metrics
