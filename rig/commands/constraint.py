"""``rig constraint ...``: validate and inspect joint-constraint files."""

from __future__ import annotations

import math

import click
import numpy as np


@click.group()
def constraint() -> None:
    """Validate and inspect joint-constraint files (YAML)."""


@constraint.command("check")
@click.argument("files", nargs=-1, required=True, type=click.Path(dir_okay=False))
@click.option(
    "--samples",
    default=200_000,
    show_default=True,
    type=click.IntRange(min=1000),
    help="Random orientations used to estimate the valid fraction.",
)
def check(files: tuple[str, ...], samples: int) -> None:
    """Validate constraint FILES and print a summary of each.

    Exits with status 2 at the first invalid file, naming the file and the field.
    """
    for path in files:
        click.echo(summarise(path, samples=samples))


def summarise(path: str, samples: int = 200_000, seed: int = 0) -> str:
    """Validate ``path`` and describe it: limits, and the fraction of orientations it allows."""
    from models import quaternion as Q
    from models.constraint import load_constraint
    from models.oracle import ConstraintOracle

    c = load_constraint(path)
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
