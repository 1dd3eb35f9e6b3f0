"""``rig train`` and ``rig evaluate``: click code over :mod:`rig.training`.

``rig train (--constraint FILE | --data FILE.npz) --out MODEL.onnx [--config YAML]
[--preset field|best|compact|thesis|fixed|network|geometric] [--seed N]`` builds the model and
writes an ONNX model whose metadata holds the constraint (or limb), the training-data hash and
the held-out metrics (:func:`rig.training.run_train`; limb files: :mod:`rig.training.limb`).
``rig evaluate --model MODEL.onnx --constraint FILE`` runs the model through onnxruntime on
fresh held-out orientations (limb postures for a limb file) and prints the metrics
(:func:`rig.training.run_evaluate`).
"""

from __future__ import annotations

import click

from rig.training.evaluate import DISTRIBUTIONS
from rig.training.joint import PRESET_NAMES
from rig.training.limb import LIMB_PRESETS


@click.command()
@click.option("--constraint", "constraint_path", type=click.Path(dir_okay=False), default=None,
              help="Constraint or limb YAML file (optional with --data: the dataset names its "
                   "own).")
@click.option("--data", "data_path", type=click.Path(dir_okay=False), default=None,
              help="Dataset .npz written by `rig dataset make` to train on.")
@click.option("--out", "out_path", required=True, type=click.Path(dir_okay=False),
              help="Where to write the ONNX model.")
@click.option("--config", "config_path", type=click.Path(dir_okay=False), default=None,
              help="YAML overriding fields of the preset.")
@click.option("--preset", type=click.Choice(PRESET_NAMES + LIMB_PRESETS), default=None,
              help="A joint: field (default), best, compact, thesis, fixed (models.nn.config). "
                   "A limb: network (default: a trained distance field per coupled swing) or "
                   "geometric (the exact limb oracle compiled).")
@click.option("--seed", type=int, default=0, show_default=True, help="Random seed.")
def train(constraint_path, data_path, out_path, config_path, preset, seed) -> None:
    """Train a corrective-constraint model and export it to ONNX."""
    from rig.training import TrainRequest, run_train

    run_train(TrainRequest(out_path, constraint=constraint_path, data=data_path,
                           config=config_path, preset=preset, seed=seed), echo=click.echo)


@click.command()
@click.option("--model", "model_path", required=True, type=click.Path(dir_okay=False),
              help="ONNX model written by `rig train`.")
@click.option("--constraint", "constraint_path", required=True,
              type=click.Path(dir_okay=False),
              help="Constraint or limb YAML the model must match.")
@click.option("--n", "n", type=click.IntRange(min=10), default=10000, show_default=True,
              help="Number of held-out orientations.")
@click.option("--distribution", type=click.Choice(DISTRIBUTIONS),
              default="held-out", show_default=True,
              help="held-out: half uniform on SO(3), half within 20° of the boundary; the "
                   "others are the thesis's pattern distributions.")
@click.option("--twist/--no-twist", default=False, show_default=True,
              help="Thesis distributions: add a random twist about the limb axis.")
@click.option("--seed", type=int, default=12345, show_default=True, help="Random seed.")
def evaluate(model_path, constraint_path, n, distribution, twist, seed) -> None:
    """Print a model's accuracy metrics on fresh held-out orientations (or limb postures)."""
    from rig.training import EvaluateRequest, run_evaluate

    result = run_evaluate(EvaluateRequest(model_path, constraint_path, n=n,
                                          distribution=distribution, twist=twist, seed=seed))
    click.echo(result.description)
    for line in result.lines:
        click.echo(line)
