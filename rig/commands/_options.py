"""Checks of option values shared by several commands (click callbacks), and a file's segment
columns as ``rig boundary`` and ``rig rom`` take them (:func:`file_columns`)."""

from __future__ import annotations

import math

import click

__all__ = ["file_columns", "finite_seconds"]


def finite_seconds(ctx, param, value):
    """A ``--duration``: None (no limit) or a finite number; ``inf`` / ``nan`` are refused in
    one line naming what to give instead (a positive duration is checked by the command's
    library function)."""
    if value is not None and not math.isfinite(value):
        raise click.BadParameter(f"{value}: a duration must be a finite number of seconds; "
                                 "leave --duration out to run until Ctrl-C")
    return value


def file_columns(parent: str | None, child: str | None, reference: str | None,
                 limb: str | None) -> tuple[str | None, str | None, str | None]:
    """A file's segment columns and a whole limb, as ``(parent, child, limb)``, from the
    options ``--parent COLUMN``, ``--child COLUMN`` and ``--limb arm|leg`` (a whole limb, and
    nothing else). The old spellings still work, each announced in one line on stderr:
    ``--reference COLUMN`` is ``--parent``, and ``--limb VALUE`` whose value is not a limb name
    is ``--child VALUE``. An old and a new spelling of the same column together are refused
    in one line."""
    from calibration.joints import LIMB_CHAINS  # lazy: the CLI's start-up time
    from rig.errors import RigConfigError  # lazy: the CLI's start-up time

    if reference is not None:
        click.echo("rig: note: --reference is now --parent", err=True)
        if parent is not None:
            raise RigConfigError("give --parent once (--reference is its old spelling)")
        parent = reference
    if limb is not None and limb not in LIMB_CHAINS:
        click.echo("rig: note: --limb COLUMN is now --child COLUMN", err=True)
        if child is not None:
            raise RigConfigError("give --child once (--limb COLUMN is its old spelling)")
        child, limb = limb, None
    return parent, child, limb
