"""Checks of option values shared by several commands (click callbacks)."""

from __future__ import annotations

import math

import click

__all__ = ["finite_seconds"]


def finite_seconds(ctx, param, value):
    """A ``--duration``: None (no limit) or a finite number; ``inf`` / ``nan`` are refused in
    one line naming what to give instead (a positive duration is checked by the command's
    library function)."""
    if value is not None and not math.isfinite(value):
        raise click.BadParameter(f"{value}: a duration must be a finite number of seconds; "
                                 "leave --duration out to run until Ctrl-C")
    return value
