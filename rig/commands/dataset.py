"""``rig dataset ...``: generate and inspect the thesis's vector-field datasets (ch. 3-4); click
code over :mod:`rig.training.datasets`."""

from __future__ import annotations

from typing import Any

import click

from rig.training.datasets import KINDS, dataset_info, make_dataset


@click.group()
def dataset() -> None:
    """Generate and inspect training datasets (thesis ch. 3-4)."""


@dataset.command("make")
@click.option("--kind", default="quaternion", show_default=True, help=" | ".join(KINDS))
@click.option("--constraint", "constraint", metavar="FILE", help="Constraint YAML file.")
@click.option("--shape", metavar="NAME", help="A shipped irregular shape (models.shapes).")
@click.option("--cone-centre", default="1,0,0", show_default=True, metavar="X,Y,Z")
@click.option("--cone-radius", metavar="DEG", help="Cone (regular boundary) radius, degrees.")
@click.option("--n", "n", metavar="N", help="Number of patterns.")
@click.option("--distribution", help="even (default) | clustered | uniform")
@click.option("--order", help="valid-first (default) | random | reversed")
@click.option("--hemisphere", help="ambiguous (default) | centre | w-positive")
@click.option("--twist", is_flag=True, help="Full 3-DOF inputs with a random twist.")
@click.option("--band-deg", metavar="DEG", help="Near-boundary band (default 10, clustered 5).")
@click.option("--lower", metavar="X", help="interval: lower bound (default -0.5).")
@click.option("--upper", metavar="X", help="interval: upper bound (default 0.5).")
@click.option("--radius", metavar="R", help="ball2/ball3: radius (default 0.5).")
@click.option("--seed", metavar="S", help="Random seed (default 0).")
@click.option(
    "--split", metavar="F,F,F", help="Write train/validation/test parts, e.g. 0.7,0.15,0.15."
)
@click.option("--out", metavar="FILE.npz", help="Output file.")
def make(**opts: Any) -> None:
    """Generate a dataset and write it as .npz."""
    for path, ds in make_dataset(**opts):
        click.echo(ds.summary())
        click.echo(f"wrote {path}")


@dataset.command("info")
@click.argument("file", metavar="FILE.npz")
def info(file: str) -> None:
    """Summarise a dataset file (regions, generator, constraint, PCA of the inputs)."""
    click.echo(dataset_info(file))
