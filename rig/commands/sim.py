"""``rig sim ...``: start a simulator that speaks a real wire protocol on a pseudo-terminal.

Each simulator prints its port path as the first line on stdout, then runs until SIGINT/SIGTERM.
"""

from __future__ import annotations

import importlib

import click

_SIMS = {
    "servos": (
        "rig.commands.sim_servos",
        "servos",
        "Simulated Dynamixel Protocol 2.0 servo chain.",
    ),
    "imu": (
        "rig.commands.sim_imu",
        "imu",
        "Simulated IMU (BNO055 UART or the rig stream protocol).",
    ),
}


class _SimGroup(click.Group):
    def list_commands(self, ctx):
        return sorted(_SIMS)

    def get_command(self, ctx, name):
        if name not in _SIMS:
            return None
        module, attr, _ = _SIMS[name]
        return getattr(importlib.import_module(module), attr)

    def format_commands(self, ctx, formatter):
        with formatter.section("Simulators"):
            formatter.write_dl([(n, _SIMS[n][2]) for n in self.list_commands(ctx)])


@click.group(cls=_SimGroup)
def sim() -> None:
    """Run a simulated device on a pseudo-terminal (no hardware needed)."""
