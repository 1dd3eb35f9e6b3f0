"""Rig configuration files: which joint, which sensors and servos on which ports.

YAML read with :func:`models.yamlio.safe_load_yaml` (safe, no anchors or aliases) and
validated field by field; **unknown keys are rejected at every level, naming the key** (a
misspelt safety setting must never be silently ignored).
Named configurations ship in ``rig/configs/<name>.yaml`` and are found by name
(``--rig sim-shoulder``); anything else is a file path. Reference::

    name: sim-imu                          # required, str
    description: "..."                     # optional, str
    joint:                                 # required
      name: shoulder                       #   str
      side: right                          #   left | right
      parent: thorax                       #   segment names (str)
      child: humerus
    limb: arm                              # optional: arm | leg — the sensors are worn on the
                                           #   whole limb (sensors.segments maps its four
                                           #   segments; joint is its proximal joint), or the
                                           #   servos drive it (servos.joints: its joints)
    constraint: original                   # optional: shipped shape name or constraint file
                                           #   (relative to this file); the patient / default
    sensors:                               # optional (IMU rigs)
      port: "sim://imu-stream?sensors=2&rate=200&patient=original&seed=1"
                                           #   str; for protocol bno055 a list, one per sensor
      protocol: stream                     #   stream | bno055
      rate_hz: 200                         #   int > 0 (default 100)
      baud: 921600                         #   int (default: stream 921600, bno055 115200)
      segments: {thorax: 0, humerus: 1}    #   segment -> sensor index (port index for bno055);
                                           #   must name joint.parent and joint.child
      raw: false                           #   true | false (default false): also record raw
                                           #   accelerometer/gyroscope/magnetometer samples
                                           #   (stream protocol 1.1, at most 8 sensors)
    servos:                                # optional (servo rigs)
      port: "sim://dynamixel?ids=1,2,3&return_delay_us=0"
      baud: 1000000                        #   int, an X-series rate (default 1000000)
      model: XM430-W350                    #   optional: every servo must report this model;
                                           #   its e-Manual table gives each servo's default
                                           #   ticks_per_rev, min/max_ticks and zero_ticks
      return_delay_us: 0                   #   0..508, even (default 0), EEPROM
      status_return_level: 2               #   0..2 (default 2)
      watchdog_ms: 100                     #   0 (off) or 20..2540 (default 100)
      ik_tolerance_deg: 0.1                #   > 0 (default: 0.1 for a joint of 3 servos,
                                           #   180 — the nearest reachable — for 1-2)
      latency_ms: null                     #   SDK packet-timeout latency; default: detected
      protocol: 2.0                        #   1.0 | 2.0 (default 2.0): the servos' wire
                                           #   protocol (AX, MX on 1.0 firmware, X series on
                                           #   Protocol Type 1: 1.0); a sim:// port serving
                                           #   the other one is refused
      calibration: arm-cal.yaml            #   optional: a `rig calibrate` file (relative to
                                           #   this file): its zero and ranges override the
                                           #   servos' below, its directions must equal
                                           #   theirs, and the bus checks the arm against it
                                           #   at start-up (docs/devices.md)
      homing: check                        #   check | write (default check): the servos'
                                           #   Homing Offset / Drive Mode reverse bit must
                                           #   hold each servo's homing_offset / reverse
                                           #   (check refuses a servo that differs; write
                                           #   writes them, torque off only)
      chain:                               #   the joint's servos, parent -> child, 1..3
        - {id: 1, axis: [0, 0, 1], zero_ticks: 2048, direction: 1, min_ticks: 0,
           max_ticks: 4095, name: j1}      #   zero/direction/min/max/name optional
                                           #   (defaults: the model's position range and its
                                           #   centre, X series 0..4095 and 2048, AX 0..1023
                                           #   and 512, P-series ±its range and 0)
        - {id: 3, axis: [1, 0, 0], ticks_per_rev: 4096}
                                           #   ticks_per_rev: optional, the model's (X 4096,
                                           #   AX-12A 1228.8, PH54-200-S500 1003846); one
                                           #   that differs from servos.model's is an error
        - {id: 2, axis: [0, 1, 0], homing_offset: -1024, reverse: true}
                                           #   homing_offset: int ticks, ±1,044,479
                                           #   (default 0); reverse: true | false (default
                                           #   false): the frame the servo's own registers
                                           #   hold, in which zero/direction/min/max were
                                           #   measured
      joints:                              #   instead of chain, with limb: a servo limb —
        - name: shoulder                   #   every joint of the limb, in its order
          kind: ball                       #   optional: default the joint's (calibration.
          chain: [...]                     #   joints); e.g. forearm for an elbow with
        - {name: elbow, kind: forearm, chain: [...]}  # pronation; servos as many as the
        - {name: wrist, chain: [...]}      #   kind's servo_axes (ball 3, forearm 2, ...)

The ``servos`` section describes a servo bus (port, baud, model, registers) and the
kinematics of the rig's joints above it: ``chain`` lists the one joint's servos (read as
:class:`~rig.devices.kinematics.ServoAxis`, kept under that key so existing files read
unchanged); ``joints`` (a rig with ``limb:``) lists each joint of the limb with its servos,
the bus's tick vector being the joints' servos concatenated in that order
(:class:`~rig.devices.kinematics.LimbKinematics`). A servo limb needs no sensors: ``limb``
then checks ``servos.joints`` against the limb's joints instead of ``sensors.segments``.

Each servo's ``homing_offset`` and ``reverse`` (:class:`ServoFrame`) are the values of its
Homing Offset (20) and Drive Mode bit 0 (reverse direction) items, e-Manual "Homing Offset" /
"Drive Mode" of the X series: Present Position = (reverse ? −1 : 1) × actual + Homing Offset.
The rig's ticks (``zero_ticks``, ``min_ticks``, ...) are in that frame, so a servo calibrated by
another tool (its own offset, a reversed direction) would move the joint elsewhere; the bus
refuses it at open (``homing: check``) or writes the configured values (``homing: write``),
see :class:`rig.devices.dynamixel.DynamixelBus`.

Each servo's resolution (``ticks_per_rev``) and the defaults of its tick range and zero come
from the control table of ``servos.model`` (:func:`servo_position_defaults`; no model: the X
series' 4096 ticks per turn, 0..4095, 2048). :func:`resolution_mismatch` compares a config's
resolutions with the models a bus found.

At least one of ``sensors`` / ``servos`` is required.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from importlib import resources
from pathlib import Path
from typing import Any
from urllib.parse import parse_qs, urlsplit

import yaml

from calibration.arm import ArmCalibration, ExpectedServo, load_arm_calibration
from calibration.errors import CalibrationError
from calibration.joints import JOINTS, LIMB_CHAINS, columns_mismatch, joint_mismatch
from firmware_protocol.dynamixel import load_control_table, tables_protocol1
from firmware_protocol.imu.stream import MAX_RAW_SENSORS
from models.constraint import load_constraint
from models.errors import ModelsError
from models.kinds import KINDS, get_kind
from models.shapes import SHAPES, load_shape
from models.yamlio import safe_load_yaml
from rig.devices.kinematics import (
    JointKinematics,
    LimbKinematics,
    ServoAxis,
    default_tolerance_deg,
)
from rig.devices.servo import Servo
from rig.errors import RigConfigError

__all__ = [
    "HOMING_MODES",
    "HOMING_OFFSET_RANGE",
    "PROTOCOLS",
    "JointInfo",
    "RigConfig",
    "SensorsConfig",
    "ServoFrame",
    "ServoJoint",
    "ServoPositionDefaults",
    "ServosConfig",
    "load_rig_config",
    "loads_rig_config",
    "resolution_mismatch",
    "rig_config_names",
    "servo_position_defaults",
]

_X_BAUDS = (9600, 57600, 115200, 1_000_000, 2_000_000, 3_000_000, 4_000_000, 4_500_000)

HOMING_MODES = ("check", "write")
"""``servos.homing``: refuse servos whose Homing Offset / reverse bit differ, or write them."""

PROTOCOLS = (1.0, 2.0)
"""``servos.protocol``: DYNAMIXEL Protocol 1.0 or 2.0 (e-Manual "Protocol 1.0" / "Protocol 2.0")."""

HOMING_OFFSET_RANGE = (-1_044_479, 1_044_479)
"""Homing Offset's range, ticks (X-series e-Manual, control table item 20)."""


@dataclass(frozen=True)
class ServoFrame:
    """The frame a servo's own registers must hold: its Homing Offset (item 20, ticks) and
    Drive Mode bit 0 (reverse direction), X-series e-Manual. Defaults: the factory's (0, normal).
    """

    homing_offset: int = 0
    reverse: bool = False


@dataclass(frozen=True)
class JointInfo:
    name: str
    side: str
    parent: str
    child: str


@dataclass(frozen=True)
class SensorsConfig:
    """IMU set: ``ports`` (one for ``stream``, one per sensor for ``bno055``)."""

    ports: tuple[str, ...]
    protocol: str
    rate_hz: int
    baud: int
    segments: dict[str, int]
    raw: bool = False
    """Ask the sensors for raw accelerometer, gyroscope and magnetometer readings too."""

    @property
    def port(self) -> str:
        return self.ports[0]


@dataclass(frozen=True)
class ServoJoint:
    """One joint of a servo limb (an entry of ``servos.joints``).

    Attributes
    ----------
    name : str
        The joint's name in the limb (``shoulder``, ``elbow``, ...).
    kind : str
        Its kind (:mod:`models.kinds`), e.g. ``forearm`` for an elbow with pronation.
    axes : tuple of ServoAxis
        Its servos, parent → child (YAML key ``chain``).
    """

    name: str
    kind: str
    axes: tuple[ServoAxis, ...]


@dataclass(frozen=True)
class ServosConfig:
    """A rig config's ``servos`` section: the servo bus and its joints' servos.

    Attributes
    ----------
    port : str
    axes : tuple of ServoAxis
        Every servo in tick-vector order: the one joint's, parent → child (YAML key
        ``chain``), or the limb's joints' concatenated in the limb's order.
    baud, model, return_delay_us, status_return_level, watchdog_ms, latency_ms
        The bus's settings (see the module docstring).
    ik_tolerance_deg : float or None
        The joint kinematics' IK tolerance; None: each joint's
        :func:`~rig.devices.kinematics.default_tolerance_deg` (exact for 3 servos, the nearest
        reachable orientation for 1-2).
    joints : tuple of ServoJoint
        A servo limb's joints (YAML key ``joints``); empty for a rig of one joint (``chain``).
    frames : tuple of ServoFrame
        Each servo's Homing Offset / reverse, in tick-vector order (empty: every servo the
        factory's 0 / normal).
    homing : {"check", "write"}
        What opening the bus does when a servo's registers differ from :attr:`frames`.
    protocol : float
        The wire protocol the bus speaks, 1.0 or 2.0 (:data:`PROTOCOLS`).
    calibration : calibration.arm.ArmCalibration or None
        ``servos.calibration``: its zeros and ranges are already in :attr:`axes`; the bus
        checks the arm against it at open (:meth:`rig.devices.dynamixel.DynamixelBus.
        check_calibration`).
    configured_axes : tuple of ServoAxis
        With a calibration: the servos as the rig file gives them (empty without).
    """

    port: str
    axes: tuple[ServoAxis, ...]
    baud: int = 1_000_000
    model: str | None = None
    return_delay_us: int = 0
    status_return_level: int = 2
    watchdog_ms: int = 100
    ik_tolerance_deg: float | None = None
    latency_ms: float | None = None
    joints: tuple[ServoJoint, ...] = ()
    frames: tuple[ServoFrame, ...] = ()
    homing: str = "check"
    protocol: float = 2.0
    calibration: ArmCalibration | None = None
    configured_axes: tuple[ServoAxis, ...] = ()

    def without_calibration(self) -> ServosConfig:
        """This section with the rig file's own zeros and ranges (no ``calibration``): what
        ``rig calibrate`` measures against."""
        if self.calibration is None:
            return self
        return _with_axes(replace(self, calibration=None, configured_axes=()),
                          self.configured_axes)

    def frame(self, k: int) -> ServoFrame:
        """The frame of the ``k``-th servo in tick-vector order."""
        return self.frames[k] if self.frames else ServoFrame()

    @property
    def joint_names(self) -> tuple[str, ...]:
        """The joints' names, proximal → distal (``("joint",)`` for a rig of one joint)."""
        return tuple(j.name for j in self.joints) or ("joint",)

    @property
    def ids(self) -> tuple[int, ...]:
        """The servos' IDs, in tick-vector order."""
        return tuple(j.id for j in self.axes)

    def bus_servos(self) -> tuple[Servo, ...]:
        """The servos as the bus knows them: ID, name, goal range (no kinematics)."""
        return tuple(Servo(a.id, a.name, a.min_ticks, a.max_ticks) for a in self.axes)

    def kinematics(self) -> JointKinematics:
        """The one joint's kinematics (its servos' ticks ↔ its orientation).

        Raises
        ------
        RigConfigError
            A servo limb of more than one joint (use :meth:`limb_kinematics`).
        """
        if len(self.joints) > 1:
            raise RigConfigError(f"a servo limb of {len(self.joints)} joints "
                                 f"({', '.join(self.joint_names)}) has no single joint's "
                                 f"kinematics: use its limb kinematics")
        return JointKinematics(self.axes, tolerance_deg=self.tolerance_deg(len(self.axes)))

    def tolerance_deg(self, n_servos: int) -> float:
        """The IK tolerance of a joint of ``n_servos`` servos: ``ik_tolerance_deg`` when set,
        else :func:`~rig.devices.kinematics.default_tolerance_deg`."""
        if self.ik_tolerance_deg is not None:
            return self.ik_tolerance_deg
        return default_tolerance_deg(n_servos)

    def limb_kinematics(self, joint: str | None = None) -> LimbKinematics:
        """Every joint's kinematics: the bus's tick vector ↔ (J, 4) joint orientations.

        Parameters
        ----------
        joint : str, optional
            The name of a rig of one joint (``chain``; default ``"joint"``); a servo limb's
            joints are named by ``servos.joints``.
        """
        if not self.joints:
            return LimbKinematics([self.kinematics()], [joint or "joint"])
        return LimbKinematics([JointKinematics(j.axes,
                                               tolerance_deg=self.tolerance_deg(len(j.axes)))
                               for j in self.joints], self.joint_names)


@dataclass(frozen=True)
class RigConfig:
    name: str
    joint: JointInfo
    constraint: str | None = None
    sensors: SensorsConfig | None = None
    servos: ServosConfig | None = None
    description: str = ""
    source: str | None = field(default=None, compare=False)
    limb: str | None = None  # "arm" | "leg": IMUs or servos on the whole limb

    def load_constraint(self):
        """The constraint (:class:`models.constraint.JointConstraint`) or None."""
        return None if self.constraint is None else _load_constraint(self.constraint)


def _load_constraint(constraint: str):
    """A shipped shape by name, else a constraint file."""
    return load_shape(constraint) if constraint in SHAPES else load_constraint(constraint)


# ---------------------------------------------------------------------------------- helpers
class _Ctx:
    def __init__(self, source: str) -> None:
        self.source = source

    def fail(self, where: str, what: str) -> RigConfigError:
        return RigConfigError(f"{self.source}: {where}: {what}")

    def mapping(self, value: Any, where: str, required: set[str], optional: set[str]) -> dict:
        if not isinstance(value, Mapping):
            raise self.fail(where, f"expected a mapping, got {type(value).__name__}")
        for key in value:
            if key not in required | optional:
                raise self.fail(where, f"unknown key {key!r} (known: "
                                       f"{', '.join(sorted(required | optional))})")
        for key in sorted(required):
            if key not in value:
                raise self.fail(where, f"missing required key {key!r}")
        return dict(value)

    def string(self, value: Any, where: str) -> str:
        if not isinstance(value, str) or not value.strip():
            raise self.fail(where, f"expected a non-empty string, got {value!r}")
        return value.strip()

    def integer(self, value: Any, where: str, lo: int | None = None, hi: int | None = None) -> int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.fail(where, f"expected a whole number, got {value!r}")
        if (lo is not None and value < lo) or (hi is not None and value > hi):
            raise self.fail(where, f"{value} is out of range {lo}..{hi}")
        return value

    def number(self, value: Any, where: str, lo: float | None = None) -> float:
        if isinstance(value, bool) or not isinstance(value, (int, float)) \
                or not math.isfinite(value):
            raise self.fail(where, f"expected a number, got {value!r}")
        if lo is not None and not value > lo:
            raise self.fail(where, f"must be > {lo}, got {value}")
        return float(value)


def _joint(ctx: _Ctx, value: Any) -> JointInfo:
    d = ctx.mapping(value, "joint", {"name", "side", "parent", "child"}, set())
    side = ctx.string(d["side"], "joint.side")
    if side not in ("left", "right"):
        raise ctx.fail("joint.side", f"expected 'left' or 'right', got {side!r}")
    parent = ctx.string(d["parent"], "joint.parent")
    child = ctx.string(d["child"], "joint.child")
    if parent == child:
        raise ctx.fail("joint", f"parent and child are the same segment {parent!r}")
    name = ctx.string(d["name"], "joint.name")

    spec = JOINTS.get(name)
    why = columns_mismatch([parent, child], [None, None] if spec is None else
                           [spec.parent, spec.child], side=side, what="joint.parent/child")
    if why is not None:  # segments named for another joint or side (femur_l on a right hip)
        raise ctx.fail("joint", f"{why.replace('column', 'segment')} of the {side} {name}")
    return JointInfo(name, side, parent, child)


def _sensors(ctx: _Ctx, value: Any, joint: JointInfo) -> SensorsConfig:
    d = ctx.mapping(value, "sensors", {"port", "segments"},
                    {"protocol", "rate_hz", "baud", "raw"})
    protocol = ctx.string(d.get("protocol", "stream"), "sensors.protocol")
    if protocol not in ("stream", "bno055"):
        raise ctx.fail("sensors.protocol", f"expected 'stream' or 'bno055', got {protocol!r}")
    raw_ports = d["port"]
    if isinstance(raw_ports, list):
        if not raw_ports:
            raise ctx.fail("sensors.port", "empty list")
        ports = tuple(ctx.string(p, f"sensors.port[{i}]") for i, p in enumerate(raw_ports))
    else:
        ports = (ctx.string(raw_ports, "sensors.port"),)
    if protocol == "stream" and len(ports) != 1:
        raise ctx.fail("sensors.port", "the stream protocol uses one port (one board)")
    rate = ctx.integer(d.get("rate_hz", 100), "sensors.rate_hz", 1, 65535)
    baud = ctx.integer(d.get("baud", 921600 if protocol == "stream" else 115200),
                       "sensors.baud", 1)
    segs = d["segments"]
    if not isinstance(segs, Mapping) or not segs:
        raise ctx.fail("sensors.segments", "expected a mapping segment -> sensor index")
    segments: dict[str, int] = {}
    limit = 15 if protocol == "stream" else len(ports) - 1
    for name, index in segs.items():
        seg = ctx.string(name, "sensors.segments")
        segments[seg] = ctx.integer(index, f"sensors.segments.{seg}", 0, limit)
    if len(set(segments.values())) != len(segments):
        raise ctx.fail("sensors.segments", "two segments share one sensor index")
    for need in (joint.parent, joint.child):
        if need not in segments:
            raise ctx.fail("sensors.segments", f"no sensor for segment {need!r} "
                                               f"(joint {joint.parent} -> {joint.child})")
    raw = d.get("raw", False)
    if not isinstance(raw, bool):
        raise ctx.fail("sensors.raw", f"expected true or false, got {raw!r}")
    if raw and protocol == "stream" and len(segments) > MAX_RAW_SENSORS:
        raise ctx.fail("sensors.raw", f"raw samples carry at most {MAX_RAW_SENSORS} sensors "
                                      f"per board, {len(segments)} segments listed")
    return SensorsConfig(ports, protocol, rate, baud, segments, raw)


@dataclass(frozen=True)
class ServoPositionDefaults:
    """What a servo model gives each servo of a chain by default (:func:`servo_position_defaults`).

    Attributes
    ----------
    ticks_per_rev : float
        Position resolution, ticks per revolution.
    min_ticks, max_ticks : int
        The model's position range (its Min/Max Position Limit's, or the AX's CW/CCW Angle
        Limit's, valid values).
    zero_ticks : int
        Its centre, ``(min + max + 1) // 2``: X series 2048, AX 512, P-series 0.
    model : str or None
        The e-Manual name of the model (None: no ``servos.model``, the X series' values).
    """

    ticks_per_rev: float = 4096.0
    min_ticks: int = 0
    max_ticks: int = 4095
    zero_ticks: int = 2048
    model: str | None = None


def servo_position_defaults(model: str | int | None, protocol: float | None = None
                            ) -> ServoPositionDefaults:
    """A chain servo's defaults from its model's control table.

    Values: the table's ``units.ticks_per_rev`` and the valid range of its Max Position Limit
    item (e-Manual emanual.robotis.com/docs/en/dxl/x/xm430-w350/: 0..4095 over 360°;
    .../dxl/ax/ax-12a/: CW/CCW Angle Limit 0..1023 over 300°, so 1024 / 300 × 360 = 1228.8
    ticks per turn; .../dxl/p/ph54-200-s500-r/: resolution 1,003,846 pulse/rev, Min/Max
    Position Limit ±501,923), see
    :mod:`firmware_protocol.dynamixel.control_table` and
    :mod:`firmware_protocol.dynamixel.tables_protocol1`.

    Parameters
    ----------
    model : str, int or None
        ``servos.model`` (e-Manual name or model number); None: the X series' 4096, 0..4095,
        2048.
    protocol : float, optional
        1.0 for a model's Protocol 1.0 table (``servos.protocol``); None or 2.0 the SDK's.

    Raises
    ------
    ValueError
        Unknown model (the message lists the known ones).
    """
    if model is None:
        return ServoPositionDefaults()
    table = load_control_table(model, protocol)
    item = table.resolve("Max Position Limit")
    lo, hi = table.ranges.get(item.name, (0, 4095)) if item is not None else (0, 4095)
    return ServoPositionDefaults(float(table.units.ticks_per_rev), int(lo), int(hi),
                                 (int(lo) + int(hi) + 1) // 2, table.display_name)


def _same_resolution(a: float, b: float) -> bool:
    return math.isclose(a, b, rel_tol=1e-9, abs_tol=0.0)


def resolution_mismatch(servos: ServosConfig, found: Mapping[int, Any]) -> str | None:
    """Why the servos a bus found do not have the resolutions a config gives them, or None.

    For the check at bus open (:class:`rig.devices.dynamixel.DynamixelBus` knows each found
    servo's model): a config whose ``ticks_per_rev`` (given, or defaulted from
    ``servos.model``) differs from a found servo's model would turn every angle wrong.

    Parameters
    ----------
    servos : ServosConfig
        The rig config's servos.
    found : mapping of int to model
        Servo ID -> what was found: a :class:`rig.devices.dynamixel.ServoInfo` (its
        ``model_number`` and ``protocol``), a
        :class:`~firmware_protocol.dynamixel.control_table.ControlTable`, a model number or an
        e-Manual model name. IDs the config does not list, and configured IDs not found, are
        not this function's business.

    Returns
    -------
    str or None
        One line naming the first servo whose resolution differs, its model and both values.
    """
    for axis in servos.axes:
        if axis.id not in found:
            continue
        what = found[axis.id]
        if hasattr(what, "units") and hasattr(what, "display_name"):
            table = what
        else:
            protocol = getattr(what, "protocol", None)
            model = getattr(what, "model_number", what)
            try:
                table = load_control_table(model, protocol)
            except ValueError:
                continue  # a model without a table: the bus's model check names it
        have = float(table.units.ticks_per_rev)
        if not _same_resolution(have, float(axis.ticks_per_rev)):
            return (f"servo ID {axis.id} is an {table.display_name} ({have:g} ticks per "
                    f"revolution) but the rig config gives it {axis.ticks_per_rev:g}: set "
                    f"servos.model (or its ticks_per_rev) to the servos' model")
    return None


def _servo_axis(ctx: _Ctx, value: Any, where: str,
                defaults: ServoPositionDefaults = ServoPositionDefaults()
                ) -> tuple[ServoAxis, ServoFrame]:
    d = ctx.mapping(value, where, {"id", "axis"},
                    {"zero_ticks", "direction", "min_ticks", "max_ticks", "name",
                     "homing_offset", "reverse", "ticks_per_rev"})
    dxl_id = ctx.integer(d["id"], f"{where}.id", 0, 252)
    axis = d["axis"]
    if not isinstance(axis, list) or len(axis) != 3:
        raise ctx.fail(f"{where}.axis", f"expected [x, y, z], got {axis!r}")
    vec = tuple(ctx.number(a, f"{where}.axis") for a in axis)
    if math.hypot(*vec) < 1e-9:
        raise ctx.fail(f"{where}.axis", "must not be zero")
    direction = ctx.integer(d.get("direction", 1), f"{where}.direction")
    if direction not in (1, -1):
        raise ctx.fail(f"{where}.direction", f"expected 1 or -1, got {direction}")
    tpr = defaults.ticks_per_rev
    if "ticks_per_rev" in d:
        tpr = ctx.number(d["ticks_per_rev"], f"{where}.ticks_per_rev", 0.0)
        if defaults.model is not None and not _same_resolution(tpr, defaults.ticks_per_rev):
            raise ctx.fail(f"{where}.ticks_per_rev",
                           f"{tpr:g} differs from the {defaults.model}'s "
                           f"{defaults.ticks_per_rev:g} ticks per revolution (servos.model); "
                           f"leave it out or fix servos.model")
    lo = ctx.integer(d.get("min_ticks", defaults.min_ticks), f"{where}.min_ticks",
                     -1_048_575, 1_048_575)
    hi = ctx.integer(d.get("max_ticks", defaults.max_ticks), f"{where}.max_ticks",
                     -1_048_575, 1_048_575)
    zero = ctx.integer(d.get("zero_ticks", defaults.zero_ticks), f"{where}.zero_ticks",
                       -1_048_575, 1_048_575)
    if not lo <= zero <= hi:
        raise ctx.fail(where, f"need min_ticks <= zero_ticks <= max_ticks, got {lo}, {zero}, {hi}")
    name = ctx.string(d["name"], f"{where}.name") if "name" in d else None
    offset = ctx.integer(d.get("homing_offset", 0), f"{where}.homing_offset",
                         *HOMING_OFFSET_RANGE)
    reverse = d.get("reverse", False)
    if not isinstance(reverse, bool):
        raise ctx.fail(f"{where}.reverse", f"expected true or false, got {reverse!r}")
    return (ServoAxis(dxl_id, vec, zero, direction, lo, hi, name,  # type: ignore[arg-type]
                      float(tpr)),
            ServoFrame(offset, reverse))


def _chain(ctx: _Ctx, value: Any, where: str,
           defaults: ServoPositionDefaults = ServoPositionDefaults()
           ) -> tuple[tuple[ServoAxis, ...], tuple[ServoFrame, ...]]:
    """A chain's servos: their kinematics and their registers' frames (``defaults``: the
    model's resolution, range and centre)."""
    if not isinstance(value, list) or not 1 <= len(value) <= 3:
        raise ctx.fail(where, "expected a list of 1 to 3 servos (parent -> child)")
    pairs = [_servo_axis(ctx, j, f"{where}[{i}]", defaults) for i, j in enumerate(value)]
    return tuple(a for a, _ in pairs), tuple(f for _, f in pairs)


def _servo_joints(ctx: _Ctx, value: Any, limb: str, names: tuple[str, ...],
                  defaults: ServoPositionDefaults = ServoPositionDefaults()
                  ) -> tuple[tuple[ServoJoint, ...], tuple[ServoFrame, ...]]:
    """``servos.joints``: the ``limb``'s joints ``names`` in its order, each its kind's number
    of servos (none named: the file has no ``limb:`` to check them against); with every
    servo's frame, in tick-vector order."""
    if not names:
        raise ctx.fail("servos.joints", "a servo limb needs 'limb: arm' or 'limb: leg' "
                                        "(one joint: servos.chain)")
    if not isinstance(value, list) or not value:
        raise ctx.fail("servos.joints", f"expected a list of the {limb}'s joints "
                                        f"({', '.join(names)})")
    joints = []
    frames: list[ServoFrame] = []
    for i, raw in enumerate(value):
        where = f"servos.joints[{i}]"
        d = ctx.mapping(raw, where, {"name", "chain"}, {"kind"})
        name = ctx.string(d["name"], f"{where}.name")
        if i >= len(names) or name != names[i]:
            raise ctx.fail(f"{where}.name", f"the {limb}'s joints are {', '.join(names)}, in "
                                            f"that order; got {name!r} at position {i + 1}")
        own = get_kind(JOINTS[name].kind)
        kind_name = ctx.string(d.get("kind", own.name), f"{where}.kind")
        if kind_name not in KINDS:
            raise ctx.fail(f"{where}.kind", f"expected one of {', '.join(KINDS)}, "
                                            f"got {kind_name!r}")
        kind = get_kind(kind_name)
        if kind.swing_twist != own.swing_twist:
            raise ctx.fail(f"{where}.kind", f"the {name} cannot be a {kind.words} (it is a "
                                            f"{own.words})")
        axes, chain_frames = _chain(ctx, d["chain"], f"{where}.chain", defaults)
        frames.extend(chain_frames)
        if len(axes) != kind.servo_axes:
            raise ctx.fail(f"{where}.chain", f"a {kind.words} has {kind.servo_axes} servo"
                                             f"{'s' if kind.servo_axes > 1 else ''}, "
                                             f"got {len(axes)}")
        joints.append(ServoJoint(name, kind.name, axes))
    if len(joints) != len(names):
        raise ctx.fail("servos.joints", f"the {limb} has {len(names)} joints "
                                        f"({', '.join(names)}), got {len(joints)}")
    return tuple(joints), tuple(frames)


def _model_defaults(ctx: _Ctx, model: str | None, protocol: Any) -> ServoPositionDefaults:
    """The chain servos' defaults of ``servos.model`` (``protocol``: ``servos.protocol``'s raw
    value where the key exists; anything but 1 / 1.0 reads the model's factory table)."""
    proto = 1.0 if str(protocol).strip() in ("1", "1.0") else None
    try:
        return servo_position_defaults(model, proto)
    except ValueError as err:
        raise ctx.fail("servos.model", str(err)) from None


def _servos(ctx: _Ctx, value: Any, limb: str = "", name: str = "",
            base_dir: Path | None = None) -> ServosConfig:
    """``servos``; ``limb`` the file's ``limb:`` (empty: none), whose joints ``joints`` lists;
    ``name`` the rig's (a calibration must name it), ``base_dir`` the file's folder."""
    names = tuple(name for name, _, _ in LIMB_CHAINS.get(limb, ()))
    d = ctx.mapping(value, "servos", {"port"},
                    {"chain", "joints", "baud", "model", "return_delay_us",
                     "status_return_level", "watchdog_ms", "ik_tolerance_deg", "latency_ms",
                     "homing", "protocol", "calibration"})
    port = ctx.string(d["port"], "servos.port")
    protocol = _protocol(ctx, d.get("protocol", 2.0), port)
    baud = ctx.integer(d.get("baud", 1_000_000), "servos.baud")
    if baud not in _X_BAUDS:
        raise ctx.fail("servos.baud", f"{baud} is not an X-series rate "
                                      f"({', '.join(map(str, _X_BAUDS))})")
    if ("chain" in d) == ("joints" in d):
        raise ctx.fail("servos", "needs either 'chain' (one joint) or 'joints' (a limb)")
    model = ctx.string(d["model"], "servos.model") if d.get("model") is not None else None
    defaults = _model_defaults(ctx, model, d.get("protocol"))
    joints: tuple[ServoJoint, ...] = ()
    if "joints" in d:
        joints, frames = _servo_joints(ctx, d["joints"], limb, names, defaults)
        axes = tuple(a for j in joints for a in j.axes)
        where = "servos.joints"
    else:
        if names:
            raise ctx.fail("servos.chain", f"the {limb} rig's servos are listed per joint "
                                           f"(servos.joints)")
        axes, frames = _chain(ctx, d["chain"], "servos.chain", defaults)
        where = "servos.chain"
    ids = [j.id for j in axes]
    for i in ids:
        if ids.count(i) > 1:
            raise ctx.fail(where, f"duplicate ID {i}")
    rd = ctx.integer(d.get("return_delay_us", 0), "servos.return_delay_us", 0, 508)
    if rd % 2:
        raise ctx.fail("servos.return_delay_us", f"must be even (2 µs units), got {rd}")
    srl = ctx.integer(d.get("status_return_level", 2), "servos.status_return_level", 0, 2)
    wd = ctx.integer(d.get("watchdog_ms", 100), "servos.watchdog_ms", 0, 2540)
    if 0 < wd < 20:
        raise ctx.fail("servos.watchdog_ms", f"0 (off) or 20..2540 ms, got {wd}")
    tol = None if d.get("ik_tolerance_deg") is None else \
        ctx.number(d["ik_tolerance_deg"], "servos.ik_tolerance_deg", 0.0)
    lat = d.get("latency_ms")
    latency = None if lat is None else ctx.number(lat, "servos.latency_ms", 0.0)
    homing = ctx.string(d.get("homing", "check"), "servos.homing")
    if homing not in HOMING_MODES:
        raise ctx.fail("servos.homing", f"expected {' or '.join(HOMING_MODES)}, got {homing!r}")
    if all(f == ServoFrame() for f in frames):
        frames = ()  # every servo the factory's frame (as a config without the keys)
    cfg = ServosConfig(port, axes, baud, model, rd, srl, wd, tol, latency, joints, frames,
                       homing, protocol)
    if d.get("calibration") is not None:
        cfg = _calibrated(ctx, cfg, ctx.string(d["calibration"], "servos.calibration"), name,
                          base_dir)
    for j in joints or (None,):
        try:
            if j is None:
                cfg.kinematics()
            else:
                JointKinematics(j.axes, tolerance_deg=cfg.tolerance_deg(len(j.axes)))
        except RigConfigError as err:
            at = where if j is None else f"{where}[{cfg.joint_names.index(j.name)}].chain"
            raise ctx.fail(at, str(err).removeprefix("joint kinematics: ")) from None
    return cfg


def _with_axes(cfg: ServosConfig, axes: tuple[ServoAxis, ...]) -> ServosConfig:
    """``cfg`` with its servos (tick-vector order) replaced, its joints' too."""
    joints, k = [], 0
    for j in cfg.joints:
        joints.append(replace(j, axes=tuple(axes[k:k + len(j.axes)])))
        k += len(j.axes)
    return replace(cfg, axes=tuple(axes), joints=tuple(joints))


def _calibrated(ctx: _Ctx, cfg: ServosConfig, file: str, rig: str,
                base_dir: Path | None) -> ServosConfig:
    """``servos.calibration``: the file (relative to the rig file) checked against the servos
    (:meth:`calibration.arm.ArmCalibration.check`) and its zeros and ranges put in them."""
    path = Path(file)
    if not path.is_absolute() and base_dir is not None:
        path = base_dir / path
    try:
        cal = load_arm_calibration(path)
        expected = [ExpectedServo(a.id, a.direction, cfg.model, cfg.frame(k).homing_offset,
                                  cfg.frame(k).reverse, a.name)
                    for k, a in enumerate(cfg.axes)]

        def model_range(model: str) -> tuple[int, int]:
            d = servo_position_defaults(model, 1.0 if cfg.protocol == 1.0 else None)
            return d.min_ticks, d.max_ticks

        cal.check(rig, expected, model_range)
    except CalibrationError as err:
        raise ctx.fail("servos.calibration", str(err)) from None
    axes = []
    for a in cfg.axes:
        s = cal.servo(a.id)
        axes.append(replace(a, zero_ticks=s.zero_ticks, min_ticks=s.min_ticks,
                            max_ticks=s.max_ticks))
    return replace(_with_axes(cfg, tuple(axes)), calibration=cal, configured_axes=cfg.axes)


def _protocol(ctx: _Ctx, value: Any, port: str) -> float:
    """``servos.protocol`` (1.0 or 2.0); a ``sim://dynamixel`` port must serve it."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) \
            or float(value) not in PROTOCOLS:
        raise ctx.fail("servos.protocol", f"expected 1.0 or 2.0, got {value!r}")
    protocol = float(value)
    served = _sim_protocols(port)
    other = {p: who for p, who in served.items() if p != protocol}
    if other:
        p, who = next(iter(other.items()))
        raise ctx.fail("servos.protocol", f"{protocol:.1f}, but the port {port!r} serves "
                                          f"{who} on Protocol {p:.1f}; make the two agree")
    return protocol


def _sim_protocols(port: str) -> dict[float, str]:
    """The protocols a ``sim://dynamixel`` port's servos speak -> which servos (words), from its
    ``ids`` (``ID:MODEL[:PROTOCOL]``), ``model`` and ``protocol`` keys (see
    :mod:`rig.sim.dynamixel.url`); empty for any other port (hardware: found at open)."""
    parts = urlsplit(port)
    if parts.scheme != "sim" or parts.netloc not in ("dynamixel", "dxl"):
        return {}
    q = {k: v[-1] for k, v in parse_qs(parts.query).items()}

    def speaks(model: str, protocol: str | None) -> float:
        if protocol:
            try:
                return float(protocol)
            except ValueError:
                return 2.0  # not ours to judge: the simulator names the bad value
        table = tables_protocol1.load(model)  # a 1.0-only model (AX) speaks 1.0 by default
        return 1.0 if table is not None and table.model_number in \
            tables_protocol1.PROTOCOL1_ONLY else 2.0

    model, protocol = q.get("model", "XM430-W350"), q.get("protocol")
    out: dict[float, str] = {}
    entries = [e.strip().split(":") for e in q.get("ids", "1").split(",")]
    for e in entries:
        m = e[1] if len(e) > 1 and e[1] else model
        p = speaks(m, e[2] if len(e) > 2 else protocol)
        out.setdefault(p, f"{m} (ID {e[0]})" if len(entries) > 1 and len(e) > 1 else m)
    return out


def loads_rig_config(text: str, source: str = "<rig config>",
                     base_dir: Path | None = None) -> RigConfig:
    """Parse and validate rig-config YAML ``text`` (``source`` names it in errors)."""
    ctx = _Ctx(source)
    try:
        data = safe_load_yaml(text)
    except yaml.YAMLError as err:
        raise RigConfigError(f"{source}: not valid YAML: {str(err).splitlines()[0]}") from err
    d = ctx.mapping(data, "top level", {"name", "joint"},
                    {"description", "constraint", "sensors", "servos", "limb"})
    name = ctx.string(d["name"], "name")
    joint = _joint(ctx, d["joint"])
    limb = _limb(ctx, d["limb"], joint, d.get("sensors")) if d.get("limb") is not None else None
    constraint = None
    if d.get("constraint") is not None:
        constraint = ctx.string(d["constraint"], "constraint")

        if constraint not in SHAPES:
            path = Path(constraint)
            if not path.is_absolute() and base_dir is not None and (base_dir / path).exists():
                path = base_dir / path
            if not path.is_file():
                raise ctx.fail("constraint", f"{constraint!r} is neither a shape "
                                             f"({', '.join(SHAPES)}) nor an existing file")
            constraint = str(path)
        _check_constraint_joint(ctx, constraint, joint)
    sensors = _sensors(ctx, d["sensors"], joint) if d.get("sensors") is not None else None
    servos = _servos(ctx, d["servos"], limb or "", name, base_dir) \
        if d.get("servos") is not None else None
    if sensors is None and servos is None:
        raise ctx.fail("top level", "needs 'sensors' or 'servos' (or both)")
    desc = ctx.string(d["description"], "description") if d.get("description") else ""
    return RigConfig(name, joint, constraint, sensors, servos, desc, source, limb)


def _check_constraint_joint(ctx: _Ctx, constraint: str, joint: JointInfo) -> None:
    """``constraint`` must be limits the rig's joint can have (a shoulder rig refuses a knee's
    file, a hinge's, another side's, a limb file)."""
    try:
        c = _load_constraint(constraint)
    except ModelsError as err:
        raise ctx.fail("constraint", str(err)) from None
    why = joint_mismatch(c, for_joint=joint.name, for_side=joint.side)
    if why is not None:
        raise ctx.fail("constraint", f"{constraint} {why}: the rig's joint is the {joint.side} "
                                     f"{joint.name}")


def _limb(ctx: _Ctx, value: Any, joint: JointInfo, sensors: Any) -> str:
    """``limb``: arm | leg, its proximal joint the rig's ``joint``, one sensor per segment
    (sensors given; a servo limb's joints are checked by :func:`_servo_joints`)."""
    limb = ctx.string(value, "limb")
    if limb not in LIMB_CHAINS:
        raise ctx.fail("limb", f"expected one of {', '.join(LIMB_CHAINS)}, got {limb!r}")
    chain = LIMB_CHAINS[limb]
    if joint.name != chain[0][0] or (joint.parent, joint.child) != chain[0][1:]:
        raise ctx.fail("joint", f"the {limb} rig's joint must be its proximal one: name "
                                f"{chain[0][0]}, parent {chain[0][1]}, child {chain[0][2]}")
    if sensors is None:
        return limb
    segs = sensors.get("segments") if isinstance(sensors, Mapping) else None
    need = [chain[0][1], *(c for _, _, c in chain)]
    missing = [s for s in need if not isinstance(segs, Mapping) or s not in segs]
    if missing:
        raise ctx.fail("sensors.segments", f"the {limb} rig needs a sensor on each of "
                                           f"{', '.join(need)}; missing {', '.join(missing)}")
    return limb


def rig_config_names() -> list[str]:
    """Names of the shipped configurations (``rig/configs/*.yaml``)."""
    folder = resources.files("rig").joinpath("configs")
    return sorted(p.name[:-5] for p in folder.iterdir() if p.name.endswith(".yaml"))


def load_rig_config(name_or_path: str | Path) -> RigConfig:
    """A shipped configuration by name (``sim-shoulder``) or a YAML file by path.

    Raises
    ------
    RigConfigError
        Unknown name (the message lists the shipped ones), missing file, or invalid content
        (the message names the file, the field and what is wrong).
    """
    text_name = str(name_or_path)
    path = Path(text_name)
    looks_like_file = (isinstance(name_or_path, Path) or path.suffix in (".yaml", ".yml")
                       or "/" in text_name or "\\" in text_name)
    if not looks_like_file:
        names = rig_config_names()
        if text_name not in names:
            raise RigConfigError(f"--rig {text_name!r}: no such shipped rig config (shipped: "
                                 f"{', '.join(names)}) and not a file path")
        res = resources.files("rig").joinpath("configs", f"{text_name}.yaml")
        return loads_rig_config(res.read_text(encoding="utf-8"), f"{text_name}.yaml",
                                Path(str(res)).parent)
    if not path.is_file():
        raise RigConfigError(f"{path}: no such rig config file")
    return loads_rig_config(path.read_text(encoding="utf-8"), str(path), path.parent)
