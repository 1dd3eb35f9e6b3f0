"""``rig sim ...``: start a simulator that speaks a real wire protocol on a pseudo-terminal.

Each simulator prints its port path as the first line on stdout, then runs until SIGINT/SIGTERM.
"""

from __future__ import annotations

import click

from rig.commands._lazy import lazy_group_class

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


@click.group(cls=lazy_group_class(_SIMS, "Simulators"))
def sim() -> None:
    """Run a simulated device on a pseudo-terminal (no hardware needed)."""
