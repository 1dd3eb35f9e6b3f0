"""Simulated devices that speak the real wire protocols on pseudo-terminals.

Each simulator is a backend, not a test double: the official client libraries (``dynamixel_sdk``,
``pyserial``) open its ``port`` exactly as they open a USB adapter. ``docs/sim.md`` lists what
is modelled, with sources, and the fault-injection API.

Modules
-------
pty_server
    :class:`~rig.sim.pty_server.PtyServer`, the base of every simulator (pty, thread, one
    error policy, adapter unplug, ``wait_for``).
clock
    :class:`~rig.sim.clock.ManualClock` / :class:`~rig.sim.clock.ScaledClock`: simulated time
    faster than real time.
urls
    ``sim://`` port-string parsing shared by the simulators.
dynamixel
    A chain of Dynamixel X-series servos (Protocol 2.0) behind a simulated U2D2.
imu
    Simulated IMUs (BNO055 UART and the rig stream protocol).
limb
    The simulated patient: shoulder motion inside a constraint, sensor placement and errors.
patients
    The factory of simulated patients with a known range (seeded star polygons, misplaced
    straps, the calibration protocol) and offline IMU / servo recordings of them.

:func:`from_url` starts the simulator a ``sim://`` port string names.
"""

from __future__ import annotations

import urllib.parse

from rig.errors import RigConfigError

__all__ = ["SIM_DEVICES", "from_url"]

SIM_DEVICES = {
    "dynamixel": "rig.sim.dynamixel:bus_from_url",
    "dxl": "rig.sim.dynamixel:bus_from_url",
    "bno055": "rig.sim.imu:bno055_from_url",
    "imu-stream": "rig.sim.imu:stream_from_url",
    "stream": "rig.sim.imu:stream_from_url",
}
"""``sim://<device>`` -> the entry point that starts it (imported lazily)."""


def from_url(url: str, **overrides: object):
    """Start the simulator named by ``url`` (``sim://dynamixel?...``, ``sim://bno055?...``,
    ``sim://imu-stream?...``); ``overrides`` are passed to its entry point (e.g. ``clock``).

    Returns
    -------
    PtyServer
        The running simulator; its ``port`` is what pyserial / ``dynamixel_sdk`` open.

    Raises
    ------
    RigConfigError
        Not a ``sim://`` URL of a known device, or a bad key or value (named).
    """
    import importlib

    parts = urllib.parse.urlsplit(url)
    target = SIM_DEVICES.get(parts.netloc) if parts.scheme == "sim" else None
    if target is None:
        raise RigConfigError(f"{url!r} names no simulator; known: "
                             f"{', '.join(f'sim://{k}' for k in SIM_DEVICES)}")
    module, func = target.split(":")
    return getattr(importlib.import_module(module), func)(url, **overrides)
