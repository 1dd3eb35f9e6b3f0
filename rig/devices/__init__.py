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
:class:`DynamixelChain`, :func:`scan`
    X-series servo chains over ``dynamixel_sdk``.
:class:`ChainKinematics`, :class:`ServoJoint`
    Forward / closed-form inverse kinematics of 1-3 joint chains.
:class:`Bno055`, :class:`StreamImu`, :class:`ImuSample`
    IMU drivers.
:func:`load_rig_config`, :class:`RigConfig`
    Validated rig configuration files (``rig/configs/*.yaml`` by name).
:class:`OrientationSample`, :class:`ServoChainSource`, :class:`ImuSetSource`,
:func:`open_source`
    The orientation-source interface recording and the live loop consume.
"""

from rig.devices.base import Device
from rig.devices.bno055 import Bno055
from rig.devices.config import RigConfig, ServosConfig, load_rig_config, rig_config_names
from rig.devices.dynamixel import DynamixelChain, ServoInfo, scan
from rig.devices.kinematics import ChainKinematics, ServoJoint
from rig.devices.ports import Port, SimulatedPatient, open_port
from rig.devices.sources import (
    ImuSetSource,
    OrientationSample,
    OrientationSource,
    ServoChainSource,
    open_source,
)
from rig.devices.stream_imu import ImuSample, StreamImu

__all__ = [
    "Bno055",
    "ChainKinematics",
    "Device",
    "DynamixelChain",
    "ImuSample",
    "ImuSetSource",
    "OrientationSample",
    "OrientationSource",
    "Port",
    "RigConfig",
    "ServoChainSource",
    "ServoInfo",
    "ServoJoint",
    "ServosConfig",
    "SimulatedPatient",
    "StreamImu",
    "load_rig_config",
    "open_port",
    "open_source",
    "rig_config_names",
    "scan",
]
