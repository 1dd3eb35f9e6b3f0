"""``rig constraint ...``: validate and inspect joint-constraint files (click code over
:func:`rig.training.constraints.summarise`)."""

from __future__ import annotations

import click

from rig.training.constraints import summarise


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
