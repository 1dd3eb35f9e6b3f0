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
    ``sim://`` port strings: the table of simulators (:data:`~rig.sim.urls.SIM_DEVICES`) and
    the one parser of their query, shared by the simulators and the port backends.
dynamixel
    A bus of Dynamixel X-series servos (Protocol 2.0) behind a simulated U2D2.
imu
    Simulated IMUs (BNO055 UART and the rig stream protocol).
limb
    The simulated patient's limb (:class:`~rig.sim.limb.SimulatedLimb`): one joint inside a
    constraint (:class:`~rig.sim.limb.SimulatedJoint`) or a whole arm or leg
    (:class:`~rig.sim.limb.SimulatedWholeLimb`); their motion (``limb.motion``), what they do
    when (``limb.schedule``), sensor placement and errors (``limb.sensors``).
patients
    The factory of simulated patients with a known range (seeded star polygons, misplaced
    straps, the calibration protocol), the one resolver of a port string's patient keys, and
    offline IMU / servo recordings.

:func:`from_url` starts the simulator a ``sim://`` port string names.
"""

from __future__ import annotations

from rig.sim.urls import SIM_DEVICES, sim_device_of

__all__ = ["SIM_DEVICES", "from_url"]


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
    return sim_device_of(url).start(url, **overrides)
