"""A simulated bus of Dynamixel X-series servos behind a simulated USB adapter (U2D2).

The bus is served on a pseudo-terminal: :attr:`DynamixelBus.port` (``/dev/pts/N``) is opened by
``dynamixel_sdk.PortHandler`` (or plain pyserial) exactly like ``/dev/ttyUSB0``; also reachable
as a port string, ``sim://dynamixel?ids=1,2,3`` (:func:`bus_from_url`). ``docs/sim.md`` says
what is modelled, with sources.

Modules
-------
servo
    :class:`SimServo` — control table per model (from the SDK's ``.model`` files), access
    rules and error codes, motion profiles, Homing Offset and Drive Mode (reverse, time-based
    profile, torque on by goal update), current / current-based position / PWM control with a
    torque model and an external push, indirect addressing, Secondary ID, boot time,
    back-driving, encoder noise, hardware errors, REBOOT / FACTORY_RESET, the Bus Watchdog.
bus
    :class:`DynamixelBus` on :class:`rig.sim.pty_server.PtyServer` — Protocol 2.0 decoding,
    unicast / broadcast / sync / bulk / fast instructions, Status Return Level, baud-rate
    matching, wire timing; :func:`start_servo_bus`.
faults
    :class:`FaultInjection` — dropped, corrupted, truncated, late replies; corrupted
    instructions; random fault rates; hardware errors; unplugged servos, bus and adapter.
url
    :func:`bus_from_url` — the ``sim://dynamixel`` port string.

Not modelled: Protocol 1.0 (see ``servo_legacy`` when present), the control-table backup
instruction, Feedforward gains, the velocity loop's gains (velocity mode follows its profile
exactly), an external push in velocity mode.
"""

from rig.sim.dynamixel.bus import PACKET_TIMEOUT, DynamixelBus, start_servo_bus
from rig.sim.dynamixel.faults import FaultInjection
from rig.sim.dynamixel.servo import (
    ACCEL_UNIT,
    BOOT_TIME_S,
    HARDWARE_ERRORS,
    TICKS_PER_REV,
    VELOCITY_UNIT,
    WATCHDOG_ERROR,
    WATCHDOG_UNIT_S,
    SimServo,
)
from rig.sim.dynamixel.url import bus_from_url

__all__ = [
    "ACCEL_UNIT",
    "BOOT_TIME_S",
    "HARDWARE_ERRORS",
    "PACKET_TIMEOUT",
    "TICKS_PER_REV",
    "VELOCITY_UNIT",
    "WATCHDOG_ERROR",
    "WATCHDOG_UNIT_S",
    "DynamixelBus",
    "FaultInjection",
    "SimServo",
    "bus_from_url",
    "start_servo_bus",
]
