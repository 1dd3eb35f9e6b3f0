"""Devices: port strings, drivers, the rig configuration and orientation sources.

Above :mod:`rig.devices.ports`, code asks a :class:`Port` for its path and, on a simulator, for
its :attr:`Port.simulated_patient` (ground truth, patient time, back-driving, the calibration
protocol); it never looks into a simulator for these. The simulator object itself
(``Port.simulator``) is for tests and benchmarks (fault injection, a manual clock).

Public API
----------
:func:`open_port`, :class:`Port`, :class:`SimulatedPatient`
    Port strings (``/dev/ttyUSB0``, ``sim://dynamixel?...``) -> an opened port; what code
    above the seam may ask of a simulated port's patient.
:class:`Device`
    Base class of the drivers (template method, retries, typed errors).
:class:`ServoBus`, :class:`Servo`
    The servo bus base class: named servos, ticks, torque, alerts, watchdog (no kinematics).
:class:`DynamixelBus`, :func:`scan`
    X-series servos over ``dynamixel_sdk``.
:class:`JointKinematics`, :class:`LimbKinematics`, :class:`ServoAxis`
    A joint's 1-3 servos' ticks ↔ its orientation (forward / closed-form inverse); a limb's
    joints in order: the bus's tick vector ↔ (J, 4) joint orientations.
:class:`ServoLimb`
    A servo bus with its limb's kinematics above it.
:class:`Bno055`, :class:`StreamImu`, :class:`ImuSample`
    IMU drivers.
:func:`load_rig_config`, :class:`RigConfig`
    Validated rig configuration files (``rig/configs/*.yaml`` by name).
:class:`OrientationSample`, :class:`ServoLimbSource`, :class:`ImuSetSource`,
:func:`open_source`
    The orientation-source interface recording and the live loop consume.
"""

from rig.devices.base import Device
from rig.devices.bno055 import Bno055
from rig.devices.bus import ServoBus
from rig.devices.config import RigConfig, ServosConfig, load_rig_config, rig_config_names
from rig.devices.dynamixel import DynamixelBus, ServoInfo, scan
from rig.devices.kinematics import JointKinematics, LimbKinematics, ServoAxis
from rig.devices.ports import Port, SimulatedPatient, open_port
from rig.devices.servo import Servo
from rig.devices.servo_limb import ServoLimb
from rig.devices.sources import (
    ImuSetSource,
    OrientationSample,
    OrientationSource,
    ServoLimbSource,
    open_source,
)
from rig.devices.stream_imu import ImuSample, StreamImu

__all__ = [
    "Bno055",
    "Device",
    "DynamixelBus",
    "ImuSample",
    "ImuSetSource",
    "JointKinematics",
    "LimbKinematics",
    "OrientationSample",
    "OrientationSource",
    "Port",
    "RigConfig",
    "Servo",
    "ServoAxis",
    "ServoBus",
    "ServoInfo",
    "ServoLimb",
    "ServoLimbSource",
    "ServosConfig",
    "SimulatedPatient",
    "StreamImu",
    "load_rig_config",
    "open_port",
    "open_source",
    "rig_config_names",
    "scan",
]
