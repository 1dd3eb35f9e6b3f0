"""A bus of Dynamixel servos (Protocol 2.0, or 1.0) over the official ``dynamixel_sdk``.

:class:`DynamixelBus` is a :class:`~rig.devices.bus.ServoBus`: servos by ID and register, no
kinematics (those sit above it, :mod:`rig.devices.kinematics`).

Instruction packets are built and parsed by the SDK's ``PacketHandler`` (protocol 2.0); this
module keeps what the SDK's group classes throw away — the **error byte of every status
packet**, whose bit 7 is the *alert* bit (a hardware error is latched; the instruction still
ran) — and turns SDK result codes into typed errors (:mod:`rig.errors`).

Per cycle (:meth:`DynamixelBus.read_ticks` / :meth:`DynamixelBus.write_goal_ticks`): one
SYNC READ of Present Position (132, 4 bytes) — FAST SYNC READ (one status packet for all
servos) when every servo's firmware supports it (X-series firmware ≥ 45, e-Manual
"Fast Sync Read") — and one SYNC WRITE of Goal Position (116, 4 bytes, no reply). The read
splits into its request (:meth:`DynamixelBus.begin_read`: the SDK's ``syncReadTx``, which starts
the reply's packet timeout) and its reply (:meth:`DynamixelBus.finish_read`: ``fastSyncReadRx``
or ``readRx`` per servo, then the error bytes); ``read_ticks`` is the two in a row.

Start-up (:meth:`DynamixelBus.configure`): Operating Mode (11) = position, Return Delay
Time (9, 2 µs units), Min/Max Position Limit (52/48) from the servos' tick limits — EEPROM, so
written only while torque is off (refused otherwise) and only when they differ (EEPROM has a
limited write life) — then Status Return Level (68, RAM). :meth:`DynamixelBus.arm_watchdog`
writes Bus Watchdog (98, 20 ms units): with torque on, a servo that hears nothing from the host
for that long stops and flags ``Bus Watchdog = -1`` (255) until 0 is written.

Frame (:meth:`DynamixelBus.apply_homing`): a bus opened from a rig config's ``servos`` section
reads every servo's Homing Offset (20) and Drive Mode (10) before anything reads a position:
Present Position = (Drive Mode bit 0 ? −1 : 1) × actual + Homing Offset (X-series e-Manual,
"Homing Offset" and "Drive Mode"), so a servo whose values differ from the config's
``homing_offset`` / ``reverse`` reports ticks in another frame than the one its zero and limits
were measured in. ``servos.homing: check`` refuses it (:class:`~rig.errors.RigConfigError`
naming the servo, the register, both values and the two ways out); ``write`` writes the
config's values (EEPROM: torque off only; the other Drive Mode bits kept) and reads them back.
:meth:`DynamixelBus.configure` does the same first, and reads back every register it writes.

Read-back of the goal (:meth:`DynamixelBus.map_read_back`, called by ``configure``): on servos
with indirect addressing (e-Manual "Indirect Address / Indirect Data": Indirect Address k at
168 + 2(k−1) holds the address whose byte Indirect Data k at 224 + (k−1) stands for), Indirect
Address 1-4 are set to Present Position (132-135) and 5-8 to Goal Position (116-119); the
cycle's one sync read then reads Indirect Data 1-8 (8 bytes per servo): the present position
and the goal each servo holds (:attr:`~rig.devices.bus.ServoBus.held_goals`). Servos without
it keep the 4-byte read of Present Position (``held_goals`` None, a line of advice).

Hardware errors are events: a status packet with the alert bit marks its servo;
:meth:`DynamixelBus.poll_alerts` reads Torque Enable (64), Hardware Error Status (70) and Bus
Watchdog (98) and returns :class:`~rig.errors.HardwareAlert` records with the torque state as
the servo reports it.

Timeouts: the SDK's packet timeout is ``tx_time × bytes + 2 × LATENCY_TIMER + 2 ms`` with a
module constant ``LATENCY_TIMER = 16`` measured on ``time.time()``; the port class here uses the
same formula with a per-bus latency (the adapter's detected USB latency timer, see
:mod:`rig.devices.latency`) and the monotonic clock.

Protocol 1.0 (``servos.protocol: 1.0``; AX, MX on 1.0 firmware, X series on Protocol Type 1;
e-Manual "DYNAMIXEL Protocol 1.0", emanual.robotis.com/docs/en/dxl/protocol1/): what differs on
the wire is behind one small strategy chosen at open (:class:`_Wire2` / :class:`_Wire1`); every
address and size comes from each model's control table through ``table.resolve`` (AX / MX "CW
Angle Limit" for Min Position Limit, ...). Open: a 1.0 PING of every servo, then a READ of its
Model Number (0) and Firmware Version (1.0 has no model in its PING status). The cycle: one
BULK_READ of Present Position (``0x92``, "available only on MX / X series" — the SDK's
``bulkReadTx``; the request through ``PacketHandler`` directly, as the SDK's
``GroupBulkRead`` passes ``bulkReadTx`` one argument too many on 1.0) when no servo is an AX,
else one READ per servo; goals by one SYNC_WRITE of each table's Goal Position (2 bytes on AX and
MX). The status error byte has no alert bit: its hardware bits (input voltage 0x01, overheating
0x04, overload 0x20) mark the servo (the instruction still ran) and :meth:`poll_alerts` reports
them with Torque Enable; the others (angle limit 0x02, range 0x08, checksum 0x10, instruction
0x40) are errors, named. No Bus Watchdog on AX / MX (:meth:`arm_watchdog` returns 0: servos
whose host stops hold their last goal), no indirect addressing (no goal read-back), Homing
Offset / Drive Mode only where the table has them (MX-106's Drive Mode; a rig config asking for
a frame on a servo without the item is refused).

Receiving: the SDK's receive loops (``rxPacket``, ``fastSyncRead``, ``broadcastPing``) call
``PortHandler.readPort`` on a port opened with ``timeout=0`` until the packet is complete or
its deadline passes — a busy loop that takes a whole core (and, with a simulator in the same
process, the GIL) while a reply is on its way. The port class here keeps the SDK as the protocol
engine and changes only that extension point: when no byte is waiting, ``readPort`` waits in
``select`` for the first byte or the packet's deadline, whichever comes first, then returns what
arrived (POSIX; elsewhere the SDK's own loop runs unchanged).
"""

from __future__ import annotations

import errno
import math
import os
import select
import termios
import time
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass

import dynamixel_sdk as sdk
import numpy as np
import serial

from firmware_protocol.dynamixel.control_table import (
    BAUD_RATES,
    ControlItem,
    ControlTable,
    load_control_table,
)
from firmware_protocol.dynamixel.protocol1 import error_names as error_names1
from firmware_protocol.dynamixel.tables_protocol1 import PROTOCOL1_ONLY
from rig.devices.base import describe_open_error
from rig.devices.bus import ServoBus
from rig.devices.config import (
    HOMING_MODES,
    PROTOCOLS,
    ServoFrame,
    ServosConfig,
    resolution_mismatch,
)
from rig.devices.latency import SDK_LATENCY_MS, latency_advice, usb_latency_timer_ms
from rig.devices.ports import Port, open_port
from rig.devices.servo import Servo
from rig.errors import (
    HardwareAlert,
    RigConfigError,
    RigConnectionError,
    RigError,
    RigProtocolError,
    RigTimeoutError,
)

__all__ = ["FAST_SYNC_READ_FIRMWARE", "REVERSE_BIT", "SCAN_BAUDS", "DynamixelBus", "ServoInfo",
           "find_servos", "scan"]

ALERT_BIT = 0x80
FAST_SYNC_READ_FIRMWARE = 45
"""X-series firmware from which FAST SYNC READ / FAST BULK READ are supported (e-Manual)."""

SCAN_BAUDS = tuple(b for b in BAUD_RATES.values() if b != 4_500_000)
"""X-series rates ``dynamixel_sdk`` can set (its rate list lacks 4.5 Mbit/s)."""

_HW_BITS = {0x01: "input_voltage", 0x04: "overheating", 0x08: "encoder",
            0x10: "electrical_shock", 0x20: "overload"}
_ERROR_NAMES = {1: "result fail", 2: "instruction error", 3: "CRC error", 4: "data range error",
                5: "data length error", 6: "data limit error", 7: "access error"}
_CONNECTION_ERRORS = (OSError, serial.SerialException, termios.error)
_HW1_MASK = 0x01 | 0x04 | 0x20
"""Protocol 1.0 error-byte bits that are hardware errors (input voltage, overheating, overload;
the same bit values as the X series' Hardware Error Status)."""

REVERSE_BIT = 0x01
"""Drive Mode bit 0: reverse direction (X-series e-Manual, "Drive Mode (10)")."""

# X-series item names (resolved in, and checked against, the control table of every model
# found): a 2.0 bus needs them all; a 1.0 bus the first (_ITEMS1), the others where every servo
# has them alike (AX / MX on 1.0 have no Operating Mode, Hardware Error Status, Bus Watchdog)
_ITEMS1 = ("Return Delay Time", "Max Position Limit", "Min Position Limit", "Torque Enable",
           "Status Return Level", "Goal Position", "Present Position", "Firmware Version")
_ITEMS = (*_ITEMS1, "Operating Mode", "Hardware Error Status", "Bus Watchdog")


@dataclass(frozen=True)
class ServoInfo:
    """What a PING found: ID, model number and name, firmware version, baud rate, and the
    protocol it answered (2.0, or 1.0: AX, MX on 1.0 firmware, X series on Protocol Type 1);
    what :func:`scan` read after it: Homing Offset (ticks) and the Drive Mode reverse bit
    (None: the model has no such item, or it was not read)."""

    id: int
    model_number: int
    model: str
    firmware: int
    baud: int
    protocol: float = 2.0
    homing_offset: int | None = None
    reverse: bool | None = None

    def __repr__(self) -> str:  # the protocol shown only when it is not the default 2.0
        extra = f", protocol={self.protocol}" if self.protocol != 2.0 else ""
        return (f"ServoInfo(id={self.id}, model_number={self.model_number}, "
                f"model={self.model!r}, firmware={self.firmware}, baud={self.baud}{extra})")


class _SdkPort(sdk.PortHandler):
    """``PortHandler`` with the SDK's timeout formula on a per-port latency and the monotonic
    clock (the SDK's own uses a module constant and ``time.time()``)."""

    def __init__(self, port_name: str, latency_ms: float) -> None:
        super().__init__(port_name)
        self.latency_ms = float(latency_ms)

    def setPacketTimeout(self, packet_length):
        self.packet_start_time = self.getCurrentTime()
        self.packet_timeout = self.tx_time_per_byte * packet_length + self.latency_ms * 2.0 + 2.0

    def getCurrentTime(self):
        return time.monotonic() * 1000.0

    def readPort(self, length):
        """Up to ``length`` bytes; when none is waiting, first wait (``select``, the GIL
        released) for one to arrive or for the packet's deadline (see the module docstring).

        POSIX: one ``select`` and one ``read`` on the port's (non-blocking) descriptor —
        pyserial's ``read`` adds an ``ioctl`` and a ``select`` or two per call, and the SDK
        calls this twice or more per status packet. Its errors as pyserial's: a descriptor
        that is ready but reads nothing is a disconnected device.
        """
        ser = self.ser
        if not _CAN_SELECT:
            return ser.read(length)
        fd = ser.fd
        remaining_ms = self.packet_timeout - self.getTimeSinceStart()
        try:
            ready, _, _ = select.select((fd,), (), (), max(remaining_ms, 0.0) / 1000.0)
            if not ready:
                return b""
            buf = os.read(fd, length)
        except OSError as err:
            if err.errno in _RETRY_ERRNOS:
                return b""
            raise serial.SerialException(f"read failed: {err}") from err
        if not buf:
            raise serial.SerialException("device reports readiness to read but returned no "
                                         "data (device disconnected?)")
        return buf


#: ``select`` works on serial file descriptors (POSIX); elsewhere the SDK's busy loop stays.
_CAN_SELECT = os.name == "posix"
#: ``read`` errors that mean "nothing now" (as pyserial treats them).
_RETRY_ERRNOS = (errno.EAGAIN, errno.EALREADY, errno.EWOULDBLOCK, errno.EINPROGRESS,
                 errno.EINTR)


def _model_name(model_number: int) -> str:
    try:
        return load_control_table(model_number).display_name
    except (ValueError, FileNotFoundError):
        return f"model {model_number}"


def _model_name1(model_number: int) -> str:
    try:
        return load_control_table(model_number, protocol=1.0).display_name
    except (ValueError, FileNotFoundError):
        return f"model {model_number}"


def _ping1(port: _SdkPort, ph1, dxl_id: int) -> tuple[int, int, int] | None:
    """Protocol 1.0 PING (no model in its status): then READ of Model Number (0, 2 bytes) and
    of the model's Firmware Version; (model number, firmware, error byte) or None."""
    tx = [0] * 6  # FF FF ID LEN INST CHK (the SDK's PKT_* constants are 2.0's offsets)
    tx[2], tx[3], tx[4] = dxl_id, 2, sdk.INST_PING
    port.is_using = False
    _, result, error = ph1.txRxPacket(port, tx)
    if result != sdk.COMM_SUCCESS:
        return None
    port.is_using = False
    model, result, _ = ph1.read2ByteTxRx(port, dxl_id, 0)
    if result != sdk.COMM_SUCCESS:
        return None
    firmware = 0
    try:
        item = load_control_table(model, protocol=1.0).resolve("Firmware Version")
    except (ValueError, FileNotFoundError):
        item = None
    if item is not None:
        port.is_using = False
        fw, result, _ = ph1.read1ByteTxRx(port, dxl_id, item.address)
        firmware = fw if result == sdk.COMM_SUCCESS else 0
    return model, firmware, error


def _open_sdk(path: str, url: str, baud: int, latency_ms: float,
              protocol: float = 2.0) -> tuple[_SdkPort, object]:
    port = _SdkPort(path, latency_ms)
    try:
        ok = port.setBaudRate(baud)
    except _CONNECTION_ERRORS as err:
        raise RigConnectionError(f"cannot open the servo port: {describe_open_error(err)}",
                                 port=url) from err
    if not ok:
        raise RigConfigError(f"dynamixel_sdk cannot set {baud} bit/s", port=url,
                             expected=", ".join(map(str, SCAN_BAUDS)))
    return port, sdk.PacketHandler(protocol)


def _default_latency(port: Port) -> float:
    if port.is_simulated:
        # a pty has no USB latency, but a simulator thread on a loaded machine can be late:
        # a generous margin (timeouts ~0.1 s) only costs time when a reply is really lost
        return 50.0
    timer = usb_latency_timer_ms(port.path)
    return float(max(timer, 1)) if timer is not None else float(SDK_LATENCY_MS)


def _ping(port: _SdkPort, ph, dxl_id: int) -> tuple[int, int, int] | None:
    """(model number, firmware, error byte) or None when nobody answered."""
    tx = [0] * 10
    tx[sdk.PKT_ID] = dxl_id
    tx[sdk.PKT_LENGTH_L] = 3
    tx[sdk.PKT_INSTRUCTION] = sdk.INST_PING
    port.is_using = False
    rx, result, error = ph.txRxPacket(port, tx)
    if result != sdk.COMM_SUCCESS:
        return None
    p0 = sdk.PKT_PARAMETER0 + 1  # status parameters follow the error byte
    return rx[p0] | rx[p0 + 1] << 8, rx[p0 + 2], error


def _read_frame(port: _SdkPort, ph, dxl_id: int, model_number: int,
                protocol: float | None = None) -> tuple[int | None, bool | None]:
    """Homing Offset (ticks) and the Drive Mode reverse bit of one servo that answered a PING;
    None for an item its model lacks (or a read that got no clean answer)."""
    try:
        table = load_control_table(model_number, protocol)
    except (ValueError, FileNotFoundError):
        return None, None
    out: list[int | None] = []
    for name in ("Homing Offset", "Drive Mode"):
        item = table.resolve(name)
        if item is None:
            out.append(None)
            continue
        port.is_using = False
        data, result, err = ph.readTxRx(port, dxl_id, item.address, item.size)
        out.append(item.decode(bytes(data)) if result == sdk.COMM_SUCCESS and not err & 0x7F
                   else None)
    offset, mode = out
    return offset, None if mode is None else bool(mode & REVERSE_BIT)


class _Wire2:
    """What Protocol 2.0 does on a :class:`DynamixelBus` (see the module docstring): PING with
    the model in its status, SYNC READ (FAST SYNC READ when every firmware supports it), the
    alert bit (7) of the error byte and its error codes, Hardware Error Status and Bus Watchdog
    for the alerts. Chosen once, at open; holds no state but the bus's."""

    protocol = 2.0
    needs = "the bus needs X-series servos"
    items = _ITEMS

    def __init__(self, bus: DynamixelBus) -> None:
        self.bus = bus

    _ping = staticmethod(_ping)
    _model_name = staticmethod(_model_name)

    def ping(self, dxl_id: int) -> ServoInfo | None:
        bus = self.bus
        got = self._ping(bus._sdk_port, bus._ph, dxl_id)
        if got is None:
            return None
        return ServoInfo(dxl_id, got[0], self._model_name(got[0]), got[1], bus.baud,
                         self.protocol)

    def table(self, info: ServoInfo) -> ControlTable:
        return load_control_table(info.model_number)

    def setup(self, found: Mapping[int, ServoInfo]) -> None:
        """The read the cycle uses, once the servos are known."""
        bus = self.bus
        supported = all(s.firmware >= FAST_SYNC_READ_FIRMWARE for s in found.values())
        bus.fast = supported if bus._fast_wanted is None else bool(bus._fast_wanted)

    def status_error(self, dxl_id: int, error: int, what: str) -> None:
        bus = self.bus
        if error & ALERT_BIT:
            bus._alert_ids.add(dxl_id)
            bus.alert_pending = True
        code = error & 0x7F
        if code:
            raise RigProtocolError(f"{what}: servo answered {_ERROR_NAMES.get(code, code)}",
                                   port=str(bus.port), dxl_id=dxl_id, actual=code)

    def read_tx(self, address: int, length: int, ids: list[int]) -> None:
        """Send a (fast) sync read request; the SDK starts the reply's packet timeout."""
        bus = self.bus
        port, ph = bus._sdk_port, bus._ph
        port.is_using = False
        fast = bus.fast
        result = bus._guard(lambda: ph.syncReadTx(port, address, length, ids, len(ids), fast))
        bus._result(result, "fast sync read" if fast else "sync read")

    def read_rx(self, address: int, length: int, ids: list[int]) -> dict[int, bytes]:
        """Collect the replies of :meth:`read_tx`: ``{id: bytes}``."""
        bus = self.bus
        port, ph = bus._sdk_port, bus._ph
        out: dict[int, bytes] = {}
        if bus.fast:
            raw, result, _ = bus._guard(
                lambda: ph.fastSyncReadRx(port, sdk.BROADCAST_ID, (length + 4) * len(ids)))
            bus._result(result, "fast sync read")
            off = 0
            for _ in ids:
                if off + 2 + length > len(raw):
                    break
                err, dxl_id = raw[off], raw[off + 1]
                out[dxl_id] = bytes(raw[off + 2:off + 2 + length])
                self.status_error(dxl_id, err, "fast sync read")
                off += length + 4
            missing = [i for i in ids if i not in out]
            if missing:
                raise RigTimeoutError("fast sync read: no data", port=str(bus.port),
                                      dxl_id=missing[0])
            return out
        for dxl_id in ids:
            data, result, err = bus._guard(lambda i=dxl_id: ph.readRx(port, i, length))
            bus._result(result, "sync read", dxl_id)
            self.status_error(dxl_id, err, "sync read")
            out[dxl_id] = bytes(data)
        return out

    def bulk_tx(self, requests: Mapping[int, tuple[int, int]]) -> None:
        """A BULK READ request: ``ID ADDR_L ADDR_H LEN_L LEN_H`` per servo."""
        bus = self.bus
        port = bus._sdk_port
        port.is_using = False
        param: list[int] = []
        for dxl_id, (address, length) in requests.items():
            param += (dxl_id, address & 0xFF, address >> 8, length & 0xFF, length >> 8)
        result = bus._guard(lambda: bus._ph.bulkReadTx(port, param, len(param), False))
        bus._result(result, "bulk read")

    def poll_alerts(self) -> list[HardwareAlert]:
        """Torque Enable .. Bus Watchdog of every servo in one sync read."""
        bus = self.bus
        t = bus.table
        a0 = t["Torque Enable"].address
        a_hw, a_wd = t["Hardware Error Status"].address, t["Bus Watchdog"].address
        length = a_wd + 1 - a0
        data = bus.transact(lambda d: bus.group_read(a0, length), "alert poll")
        now = time.monotonic()
        alerts = []
        for dxl_id in bus.ids:
            b = data[dxl_id]
            hw, wd = b[a_hw - a0], b[a_wd - a0]
            names = tuple(n for bit, n in _HW_BITS.items() if hw & bit)
            if wd == 0xFF:
                names += ("bus_watchdog",)
            if names or dxl_id in bus._alert_ids:
                alerts.append(HardwareAlert(str(bus.port), dxl_id, now, hw, names,
                                            bool(b[0])))
        bus._alert_ids.clear()
        return alerts

    def reboot(self, dxl_id: int) -> None:
        bus = self.bus
        port = bus._sdk_port
        port.is_using = False
        result, _ = bus._guard(lambda: bus._ph.reboot(port, dxl_id))
        bus._result(result, "reboot", dxl_id)


class _Wire1(_Wire2):
    """What Protocol 1.0 does on a :class:`DynamixelBus` (see the module docstring): PING then
    a READ of Model Number and Firmware Version, BULK_READ (MX / X series) or one READ per
    servo (AX), the error byte's bits (hardware bits mark the servo, the others are errors)."""

    protocol = 1.0
    needs = "the bus needs servos whose control tables agree on it"
    items = _ITEMS1

    def __init__(self, bus: DynamixelBus) -> None:
        super().__init__(bus)
        self.bulk = True

    _ping = staticmethod(_ping1)
    _model_name = staticmethod(_model_name1)

    def table(self, info: ServoInfo) -> ControlTable:
        return load_control_table(info.model_number, 1.0)

    def setup(self, found: Mapping[int, ServoInfo]) -> None:
        bus = self.bus
        bus.fast = False
        self.bulk = all(s.model_number not in PROTOCOL1_ONLY for s in found.values())
        bus.read_what = ("bulk read" if self.bulk else "read") + " of Present Position"

    def status_error(self, dxl_id: int, error: int, what: str) -> None:
        bus = self.bus
        hw = error & _HW1_MASK
        if hw:
            bus._hw_bits[dxl_id] = hw
            bus._alert_ids.add(dxl_id)
            bus.alert_pending = True
        else:
            bus._hw_bits.pop(dxl_id, None)
        code = error & 0x7F & ~_HW1_MASK
        if code:
            names = ", ".join(n.replace("_", " ") for n in error_names1(code))
            raise RigProtocolError(f"{what}: servo answered {names} error", port=str(bus.port),
                                   dxl_id=dxl_id, actual=code)

    def read_tx(self, address: int, length: int, ids: list[int]) -> None:
        """One BULK_READ request (every servo's status follows the one before it), or the READ
        of the first servo (an AX ignores BULK_READ)."""
        bus = self.bus
        if self.bulk:
            self.bulk_tx({i: (address, length) for i in ids})
            return
        port = bus._sdk_port
        port.is_using = False
        result = bus._guard(lambda: bus._ph.readTx(port, ids[0], address, length))
        bus._result(result, "read", ids[0])

    def read_rx(self, address: int, length: int, ids: list[int]) -> dict[int, bytes]:
        bus = self.bus
        port, ph = bus._sdk_port, bus._ph
        what = "bulk read" if self.bulk else "read"
        out: dict[int, bytes] = {}
        for k, dxl_id in enumerate(ids):
            if self.bulk or k == 0:
                data, result, err = bus._guard(lambda i=dxl_id: ph.readRx(port, i, length))
            else:
                port.is_using = False
                data, result, err = bus._guard(
                    lambda i=dxl_id: ph.readTxRx(port, i, address, length))
            bus._result(result, what, dxl_id)
            self.status_error(dxl_id, err, what)
            out[dxl_id] = bytes(data)
        return out

    def bulk_tx(self, requests: Mapping[int, tuple[int, int]]) -> None:
        """A 1.0 BULK_READ request: ``0x00 [LEN ID ADDR] ...`` (the SDK adds the 0x00)."""
        bus = self.bus
        if not self.bulk:
            raise RigProtocolError("an AX servo does not answer BULK_READ (MX / X series only)",
                                   port=str(bus.port))
        port = bus._sdk_port
        port.is_using = False
        param: list[int] = []
        for dxl_id, (address, length) in requests.items():
            param += (length, dxl_id, address)
        result = bus._guard(lambda: bus._ph.bulkReadTx(port, param, len(param)))
        bus._result(result, "bulk read")

    def poll_alerts(self) -> list[HardwareAlert]:
        """Torque Enable of every servo; the hardware bits are those of its status (and Bus
        Watchdog where the table has one: an X series on Protocol Type 1)."""
        bus = self.bus
        a_te = bus._item("Torque Enable").address
        torque = bus.transact(lambda d: bus.group_read(a_te, 1), "alert poll")
        wd_item = bus.table.resolve("Bus Watchdog")
        wd = None if wd_item is None else \
            bus.transact(lambda d: bus.group_read(wd_item.address, 1), "alert poll")
        now = time.monotonic()
        alerts = []
        for dxl_id in bus.ids:
            hw = bus._hw_bits.get(dxl_id, 0)
            names = tuple(n for bit, n in _HW_BITS.items() if hw & bit)
            if wd is not None and wd[dxl_id][0] == 0xFF:
                names += ("bus_watchdog",)
            if names or dxl_id in bus._alert_ids:
                alerts.append(HardwareAlert(str(bus.port), dxl_id, now, hw, names,
                                            bool(torque[dxl_id][0])))
        bus._alert_ids.clear()
        return alerts

    def reboot(self, dxl_id: int) -> None:
        """REBOOT (0x08; the SDK's 1.0 ``reboot`` says "not available", the servos have it)."""
        bus = self.bus
        port = bus._sdk_port
        tx = [0] * 6  # FF FF ID LEN INST CHK
        tx[2], tx[3], tx[4] = dxl_id, 2, sdk.INST_REBOOT
        port.is_using = False
        _, result, _ = bus._guard(lambda: bus._ph.txRxPacket(port, tx))
        bus._result(result, "reboot", dxl_id)


REBOOT_WAIT_S = 2.0
"""How long :meth:`DynamixelBus.reboot` waits for a rebooted servo to answer again, s."""


class DynamixelBus(ServoBus):
    """Dynamixel servos on one bus: open, check, read, write, registers, alerts, watchdog.

    Parameters
    ----------
    port : str, Port or None
        Port string (``/dev/ttyUSB0``, ``sim://dynamixel?...``) or an opened
        :class:`~rig.devices.ports.Port`; None takes ``servos.port`` (a :class:`ServosConfig`).
    servos : ServosConfig or sequence of Servo or int
        The servos in tick-vector order: a rig config's ``servos`` section (its joint's
        servos, with the bus settings below) or :class:`~rig.devices.bus.Servo` s / IDs
        (the settings' defaults).
    baud : int, optional
        Line speed (default ``servos.baud`` or 1 Mbit/s).
    timeout : float, optional
        Seconds per attempt of a transaction (on top of the SDK's packet timeout).
    retries : int
        Extra attempts after a timeout / garbled reply.
    latency_ms : float, optional
        Latency in the SDK's packet-timeout formula; default: the adapter's USB latency timer
        (≥ 1 ms) on hardware, 50 ms on a simulator's pty (a loaded machine).
    fast : bool, optional
        Force FAST SYNC READ on/off; default: when every servo's firmware supports it.
    homing : {"check", "write"}, optional
        What :meth:`apply_homing` does at open and in :meth:`configure`; default
        ``servos.homing`` of a rig config, None (no frame check) for a bus of bare servos.
    protocol : {2.0, 1.0}, optional
        The wire protocol; default ``servos.protocol`` of a rig config, 2.0 for bare servos.

    Attributes
    ----------
    config : ServosConfig or None
        The rig config section it was opened from.
    found : dict of int to ServoInfo
        What each servo reported at open.
    fast : bool
        FAST SYNC READ in use.
    model : str or None
        The model every servo must report (``servos.model``).
    return_delay_us, status_return_level : int
        What :meth:`configure` writes.
    homing : str or None
    frames : tuple of ServoFrame
        Each servo's Homing Offset / reverse bit the bus requires (tick-vector order).
    read_back : bool
        The cycle's read also reads the goal each servo holds (:meth:`map_read_back`).
    protocol : float
        2.0 or 1.0.

    Raises
    ------
    RigConnectionError
        Port missing / not a serial port; nobody answering (wrong baud?); IDs missing.
    RigConfigError
        Unsupported baud, a servo of another model than ``model``.
    """

    kind = "Dynamixel bus"
    read_what = "sync read of Present Position"
    default_timeout = 0.1
    default_retries = 2

    def __init__(self, port: str | Port | None, servos: ServosConfig | Sequence[Servo | int], *,
                 baud: int | None = None, timeout: float | None = None,
                 retries: int | None = None, latency_ms: float | None = None,
                 fast: bool | None = None, homing: str | None = None,
                 protocol: float | None = None) -> None:
        config = servos if isinstance(servos, ServosConfig) else None
        settings = config if config is not None else ServosConfig  # its defaults
        self.config = config
        if port is None:
            if config is None:
                raise RigConfigError("a servo bus needs a port")
            port = config.port
        self.model = settings.model
        self.return_delay_us = settings.return_delay_us
        self.status_return_level = settings.status_return_level
        self._latency = latency_ms if latency_ms is not None else settings.latency_ms
        self._fast_wanted = fast
        baud = int(baud if baud is not None else settings.baud)
        self._alert_ids: set[int] = set()
        self._hw_bits: dict[int, int] = {}  # 1.0: each servo's hardware bits, last status
        protocol = settings.protocol if protocol is None else protocol
        if protocol not in PROTOCOLS:
            raise RigConfigError(f"protocol must be 1.0 or 2.0, got {protocol!r}")
        self.protocol = float(protocol)
        if homing is None and config is not None:
            homing = config.homing
        if homing is not None and homing not in HOMING_MODES:
            raise RigConfigError(f"homing must be {' or '.join(HOMING_MODES)}, got {homing!r}")
        self.homing = homing
        n = len(config.axes) if config is not None else len(servos)
        self.frames: tuple[ServoFrame, ...] = tuple(
            config.frame(k) if config is not None else ServoFrame() for k in range(n))
        super().__init__(port, config.bus_servos() if config is not None else servos,
                         baud=baud, timeout=timeout, retries=retries,
                         watchdog_ms=settings.watchdog_ms)

    @classmethod
    def from_config(cls, config: ServosConfig, **kwargs) -> DynamixelBus:
        """Open the bus a rig config's ``servos`` section describes."""
        return cls(None, config, **kwargs)

    # -- open / close ---------------------------------------------------------------------
    def _open(self) -> None:
        url = str(self.port)
        latency = self._latency if self._latency is not None else _default_latency(self.port)
        self._wire = (_Wire1 if self.protocol == 1.0 else _Wire2)(self)
        self._sdk_port, self._ph = _open_sdk(self.path, url, self.baud, latency, self.protocol)
        try:
            self._check_servos()
            self._plain_read()
            calibrated = self.config is not None and self.config.calibration is not None
            if calibrated and self.homing != "write":
                self.check_calibration()
            if self.homing is not None:
                self.apply_homing()
            if calibrated and self.homing == "write":
                self.check_calibration()
        except BaseException:
            self._close()
            raise
        if not self.port.is_simulated:
            tip = latency_advice(self.port.path)
            if tip:
                self.advice.append(tip)

    def _close(self) -> None:
        port = getattr(self, "_sdk_port", None)
        if port is not None and port.is_open:
            try:
                port.closePort()
            except _CONNECTION_ERRORS:
                pass

    def _check_servos(self) -> None:
        url = str(self.port)
        found: dict[int, ServoInfo] = {}
        # a silent bus gets two passes; once anyone answers, a missing ID gets three tries
        for attempt in range(3):
            if attempt == 2 and not found:
                break
            for dxl_id in self.ids:
                if dxl_id in found:
                    continue
                got = self._guard(lambda i=dxl_id: self._wire.ping(i))
                if got is not None:
                    found[dxl_id] = got
            if len(found) == len(self.ids):
                break
        if not found:
            self._other_protocol(url)
            raise RigConnectionError(
                f"no servo answered at {self.baud} bit/s (wrong baud rate or port? try "
                f"`rig scan {url}`)", port=url, actual=[], expected=list(self.ids))
        missing = [i for i in self.ids if i not in found]
        if missing:
            raise RigConnectionError(f"servo ID {missing[0]} did not answer at {self.baud} bit/s",
                                     port=url, actual=sorted(found), expected=list(self.ids))
        want = self.model
        if want is not None:
            for info in found.values():
                if info.model.upper() != want.upper():
                    raise RigConfigError("servo model differs from the rig config", port=url,
                                         dxl_id=info.id, actual=info.model, expected=want)
        wire = self._wire
        tables = {i: wire.table(s) for i, s in found.items()}
        first = next(iter(tables.values()))

        def where(table: ControlTable, name: str) -> tuple[int, int] | None:
            item = table.resolve(name)
            return None if item is None else (item.address, item.size)

        for dxl_id, table in tables.items():
            for item in _ITEMS:
                at = where(table, item)
                if (at is None and item in wire.items) or at != where(first, item):
                    raise RigConfigError(f"control table of {table.display_name} lacks or moves "
                                         f"{item!r}; {wire.needs}", port=url, dxl_id=dxl_id)
        if self.config is not None:
            why = resolution_mismatch(self.config, found)
            if why:
                raise RigConfigError(why, port=url)
        self.found = found
        self.table: ControlTable = first
        self._present_item = self._item("Present Position")
        self._goal_item = self._item("Goal Position")
        wire.setup(found)
        self._id_param = list(self.ids)
        self._id_index = {i: k for k, i in enumerate(self.ids)}

    # -- helpers --------------------------------------------------------------------------
    def _guard(self, fn):
        """Run an SDK call; OS-level failures (adapter gone) -> RigConnectionError."""
        try:
            return fn()
        except _CONNECTION_ERRORS as err:
            self._sdk_port.is_using = False
            msg = getattr(err, "strerror", None) or str(err) or type(err).__name__
            raise RigConnectionError(f"the servo adapter stopped working ({msg}); unplugged?",
                                     port=str(self.port)) from err

    def _result(self, result: int, what: str, dxl_id: int | None = None) -> None:
        if result == sdk.COMM_SUCCESS:
            return
        url = str(self.port)
        if result == sdk.COMM_RX_TIMEOUT:
            raise RigTimeoutError(f"{what}: no answer", port=url, dxl_id=dxl_id)
        if result in (sdk.COMM_RX_CORRUPT, sdk.COMM_RX_FAIL):
            raise RigProtocolError(f"{what}: garbled answer", port=url, dxl_id=dxl_id)
        if result == sdk.COMM_TX_FAIL:
            raise RigConnectionError(f"{what}: could not send", port=url)
        raise RigProtocolError(f"{what}: {self._ph.getTxRxResult(result)}", port=url,
                               dxl_id=dxl_id)

    def _status_error(self, dxl_id: int, error: int, what: str) -> None:
        """A status packet's error byte: alerts noted, errors raised (per protocol)."""
        self._wire.status_error(dxl_id, error, what)

    def _item(self, name: str) -> ControlItem:
        """The item playing X-series item ``name``'s role in the servos' table."""
        item = self.table.resolve(name)
        if item is None:
            raise RigConfigError(f"{self.table.display_name} has no {name!r} item",
                                 port=str(self.port))
        return item

    def _other_protocol(self, url: str) -> None:
        """Nobody answered: if the first servo answers the other protocol, say so (one line)."""
        other = 1.0 if self.protocol == 2.0 else 2.0
        ping = _ping1 if other == 1.0 else _ping
        got = self._guard(lambda: ping(self._sdk_port, sdk.PacketHandler(other), self.ids[0]))
        if got is not None:
            raise RigConfigError(f"servo ID {self.ids[0]} answers Protocol {other:.1f}, the rig "
                                 f"config says {self.protocol:.1f}: set servos.protocol: "
                                 f"{other:.1f}", port=url)

    # -- the cycle ------------------------------------------------------------------------
    def _read_ticks(self, deadline: float) -> np.ndarray:
        self._begin_read()
        return self._finish_read()

    def _begin_read(self) -> None:
        """The read request of Present Position (its packet timeout starts now), and of the
        goal held when :meth:`map_read_back` mapped both into the indirect data."""
        self._wire.read_tx(self._read_at, self._read_len, self._id_param)

    def _finish_read(self) -> np.ndarray:
        """The reply of :meth:`_begin_read` as ticks, (n,) int64 (and :attr:`held_goals`)."""
        data = self._wire.read_rx(self._read_at, self._read_len, self._id_param)
        v = np.frombuffer(b"".join([data[i] for i in self.ids]),
                          dtype=self._read_dtype).astype(np.int64)
        if self._read_len == 8:
            self.held_goals = v[1::2]
            return v[0::2]
        return v

    def group_read(self, address: int, length: int,
                   ids: Sequence[int] | None = None) -> dict[int, bytes]:
        """``length`` bytes at ``address`` of every servo in one exchange: ``{id: bytes}``; no
        retries. Protocol 2.0: one SYNC READ (FAST SYNC READ when in use); 1.0: one BULK_READ,
        or one READ per servo on a bus with an AX.

        Status error bytes are checked (alerts noted, errors raised).
        """
        ids = self._id_param if ids is None else list(ids)
        self._wire.read_tx(address, length, ids)
        return self._wire.read_rx(address, length, ids)

    def _write_goal_ticks(self, ticks: list[int]) -> None:
        """Goal Position of every servo by one SYNC WRITE (no reply, no retry), its table's
        size (4 bytes on the X series, 2 on AX / MX on 1.0)."""
        self._sync_write(self._goal_item, ticks, "Goal Position")

    def write_items(self, name: str, values: Sequence[int]) -> None:
        """One control-table item of every servo by one SYNC WRITE (no reply, no retry).

        Parameters
        ----------
        name : str
            An X-series item name or the model's own (resolved in the servos' table), e.g.
            ``"Goal Current"``.
        values : (n,) sequence of int
            Raw item values in tick-vector order (the item's own units).

        Raises
        ------
        RigConfigError
            The servos' table has no such item.
        ValueError
            Not one value per servo.
        """
        self._check_open()
        if len(values) != len(self.ids):
            raise ValueError(f"write_items({name!r}): need {len(self.ids)} values, got "
                             f"{len(values)}")
        self._sync_write(self._item(name), values, name)

    def _sync_write(self, item: ControlItem, values: Sequence[int], what: str) -> None:
        param: list[int] = []
        for dxl_id, v in zip(self.ids, values, strict=True):
            param += (dxl_id, *item.encode(int(v)))
        port = self._sdk_port
        port.is_using = False
        result = self._guard(lambda: self._ph.syncWriteTxOnly(port, item.address, item.size,
                                                              param, len(param)))
        self._result(result, f"sync write of {what}")

    # -- register access ------------------------------------------------------------------
    def read_register(self, dxl_id: int, name: str) -> int:
        """One control-table item of one servo (retried); ``name`` an X-series name or the
        model's own (resolved in its table)."""
        item = self._item(name)

        def once(deadline: float) -> int:
            port = self._sdk_port
            port.is_using = False
            data, result, err = self._guard(
                lambda: self._ph.readTxRx(port, dxl_id, item.address, item.size))
            self._result(result, f"read of {name}", dxl_id)
            self._status_error(dxl_id, err, f"read of {name}")
            return item.decode(bytes(data))

        return self.transact(once, f"read of {name}", dxl_id=dxl_id)

    def write_register(self, dxl_id: int, name: str, value: int) -> None:
        """Write one control-table item of one servo (acknowledged when Status Return Level is
        2, then retried; otherwise sent once)."""
        item = self._item(name)
        data = list(item.encode(int(value)))
        acked = getattr(self, "_srl", 2) >= 2

        def once(deadline: float) -> None:
            port = self._sdk_port
            port.is_using = False
            if not acked:
                result = self._guard(lambda: self._ph.writeTxOnly(port, dxl_id, item.address,
                                                                  item.size, data))
                self._result(result, f"write of {name}", dxl_id)
                return
            result, err = self._guard(lambda: self._ph.writeTxRx(port, dxl_id, item.address,
                                                                 item.size, data))
            self._result(result, f"write of {name}", dxl_id)
            self._status_error(dxl_id, err, f"write of {name} = {value}")

        self.transact(once, f"write of {name}", dxl_id=dxl_id)

    def bulk_read(self, requests: Mapping[int, tuple[int, int]]) -> dict[int, bytes]:
        """One BULK READ: ``{id: (address, length)}`` → ``{id: bytes}`` (retried; on 1.0 not
        with AX servos)."""
        def once(deadline: float) -> dict[int, bytes]:
            port = self._sdk_port
            self._wire.bulk_tx(requests)
            out = {}
            for dxl_id, (_, length) in requests.items():
                data, result, err = self._guard(lambda i=dxl_id, n=length:
                                                self._ph.readRx(port, i, n))
                self._result(result, "bulk read", dxl_id)
                self._status_error(dxl_id, err, "bulk read")
                out[dxl_id] = bytes(data)
            return out

        return self.transact(once, "bulk read")

    def ping(self, dxl_id: int) -> ServoInfo | None:
        """PING one ID: what answered, or None."""
        self._check_open()
        return self._guard(lambda: self._wire.ping(dxl_id))

    # -- torque, configuration, watchdog --------------------------------------------------
    def _read_torque(self) -> np.ndarray:
        """Torque Enable as each servo reports it, (n,) bool."""
        a = self._item("Torque Enable").address
        data = self.transact(lambda d: self.group_read(a, 1),
                             self.read_what.replace("Present Position", "Torque Enable"))
        return np.array([bool(data[i][0]) for i in self.ids])

    def _write_torque(self, on: bool) -> None:
        for dxl_id in self.ids:
            self.write_register(dxl_id, "Torque Enable", 1 if on else 0)

    def set_latency(self, latency_ms: float) -> None:
        """Adapter latency (ms) the SDK's packet timeout is computed from, from now on."""
        self._latency = float(latency_ms)
        self._sdk_port.latency_ms = float(latency_ms)

    def configure(self) -> None:
        """Set the registers the loop depends on (see the module docstring).

        First the servos' frame (:meth:`apply_homing`, when :attr:`homing` is set); every
        register written is read back (a value the servo did not keep is an error naming it);
        last the read-back of the goal (:meth:`map_read_back`).

        Raises
        ------
        RigError
            An EEPROM value must change while a servo's torque is on (turn torque off first;
            this method never does that by itself: the limb could fall).
        RigConfigError
            ``homing: check`` and a servo's Homing Offset / reverse bit differ from the config.
        RigProtocolError
            A servo did not keep a value written.
        """
        if self.homing is not None:
            self.apply_homing()
        lo, hi = self.min_ticks, self.max_ticks
        # beyond what the position-limit items can hold (X 0..4095, P-series ±501,923):
        # extended position mode, no limits written
        limit_lo, limit_hi = self.table.ranges.get(self._item("Max Position Limit").name,
                                                   (0, 4095))
        multi_turn = bool((lo < limit_lo).any() or (hi > limit_hi).any())
        has_mode = self.table.resolve("Operating Mode") is not None
        if not has_mode:  # AX / MX on 1.0: joint mode by the angle limits, within one turn
            top = self.table.ranges.get(self._goal_item.name, (0, 4095))[1]
            bad = [k for k in range(len(self.ids)) if lo[k] < 0 or hi[k] > top]
            if bad:
                k = bad[0]
                raise RigConfigError(
                    f"servo {self.names[k]} ({self.found[self.ids[k]].model}): min_ticks/"
                    f"max_ticks {lo[k]}..{hi[k]} beyond its joint mode's 0..{top}",
                    port=str(self.port), dxl_id=self.ids[k])
            multi_turn = False
        for k, dxl_id in enumerate(self.ids):
            want = {"Return Delay Time": self.return_delay_us // 2}
            if has_mode:
                want = {"Operating Mode": 4 if multi_turn else 3, **want}
            if not multi_turn:
                want["Min Position Limit"] = int(lo[k])
                want["Max Position Limit"] = int(hi[k])
            have = {name: self.read_register(dxl_id, name) for name in want}
            change = {n: v for n, v in want.items() if have[n] != v}
            if change and self.read_register(dxl_id, "Torque Enable"):
                n, v = next(iter(change.items()))
                raise RigError(f"EEPROM item {n!r} must change but torque is on; turn torque "
                               f"off first (set_torque(False))", port=str(self.port),
                               dxl_id=dxl_id, actual=have[n], expected=v)
            for name, value in change.items():
                self._write_verified(dxl_id, name, value)
        for dxl_id in self.ids:
            if self.status_return_level >= 1:  # 0: no status to a READ (only PING answers)
                self._write_verified(dxl_id, "Status Return Level", self.status_return_level)
            else:
                self.write_register(dxl_id, "Status Return Level", self.status_return_level)
        self._srl = self.status_return_level
        if self.status_return_level >= 1:
            self.map_read_back()

    # -- frame (Homing Offset, Drive Mode) and the goal's read-back -------------------------
    def _table_of(self, dxl_id: int) -> ControlTable:
        """The control table of servo ``dxl_id``'s model."""
        info = self.found[dxl_id]
        protocol = getattr(info, "protocol", None)
        return load_control_table(info.model_number, protocol)

    def _write_verified(self, dxl_id: int, name: str, value: int) -> None:
        """Write ``name`` and read it back: the servo must hold ``value``."""
        self.write_register(dxl_id, name, value)
        held = self.read_register(dxl_id, name)
        if held != value:
            raise RigProtocolError(f"{name} was written but the servo did not keep it",
                                   port=str(self.port), dxl_id=dxl_id, actual=held,
                                   expected=value)

    def read_frames(self) -> dict[int, tuple[int | None, int | None]]:
        """Each servo's Homing Offset (ticks) and Drive Mode byte; None where its model has no
        such item."""
        out: dict[int, tuple[int | None, int | None]] = {}
        for dxl_id in self.ids:
            table = self._table_of(dxl_id)
            off = self.read_register(dxl_id, "Homing Offset") \
                if table.resolve("Homing Offset") is not None else None
            mode = self.read_register(dxl_id, "Drive Mode") \
                if table.resolve("Drive Mode") is not None else None
            out[dxl_id] = (off, mode)
        return out

    def apply_homing(self) -> None:
        """Every servo's Homing Offset and reverse bit as :attr:`frames` says: checked
        (``homing = "check"``) or written and read back (``"write"``; EEPROM, so torque off
        only; the other Drive Mode bits kept).

        Raises
        ------
        RigConfigError
            ``check``: a servo's value differs (the message names the servo, the register, what
            it holds, what the config says and the two ways out); or the config asks for a
            frame on a model without the item.
        RigError
            ``write``: a value must change while the servo's torque is on.
        RigProtocolError
            ``write``: the servo did not keep a value written.
        """
        url = str(self.port)
        write = self.homing == "write"
        for (dxl_id, (off, mode)), want in zip(self.read_frames().items(), self.frames,
                                               strict=True):
            name = self.names[self.index(dxl_id)]
            change: dict[str, int] = {}
            for item, have, need, key, shown in (
                    ("Homing Offset", off, want.homing_offset, "homing_offset",
                     lambda v: str(v)),
                    ("Drive Mode", None if mode is None else bool(mode & REVERSE_BIT),
                     want.reverse, "reverse", lambda v: "true" if v else "false")):
                if have is None:
                    if need != type(need)():
                        raise RigConfigError(
                            f"servo {name} ({self.found[dxl_id].model}) has no {item} item: "
                            f"the rig config's {key}: {shown(need)} cannot hold; remove it",
                            port=url, dxl_id=dxl_id)
                    continue
                if have == need:
                    continue
                what = "reverse bit (Drive Mode bit 0)" if key == "reverse" else item
                if not write:
                    raise RigConfigError(
                        f"servo {name}: {what} holds {shown(have)}, the rig config says "
                        f"{shown(need)}; if the servo was calibrated so on purpose put "
                        f"'{key}: {shown(have)}' on servo {name} in the config, otherwise set "
                        f"'servos.homing: write' to write the config's value",
                        port=url, dxl_id=dxl_id)
                change[item] = need if key == "homing_offset" else \
                    (mode & ~REVERSE_BIT) | (REVERSE_BIT if need else 0)
            if not change:
                continue
            if self.read_register(dxl_id, "Torque Enable"):
                item, value = next(iter(change.items()))
                raise RigError(f"EEPROM item {item!r} must change (servos.homing: write) but "
                               f"torque is on; turn torque off first (set_torque(False))",
                               port=url, dxl_id=dxl_id, expected=value)
            for item, value in change.items():
                self._write_verified(dxl_id, item, value)

    def check_calibration(self) -> None:
        """The arm still matches ``servos.calibration`` (:class:`calibration.arm.ArmCalibration`):
        each servo's model as found, its Homing Offset / reverse bit as stored, its Present
        Position within the calibrated range ± the file's margin. Called at open (before
        :meth:`apply_homing` with ``homing: check``, after it with ``write``).

        Raises
        ------
        RigConfigError
            One line naming the first servo that differs.
        """
        cal = self.config.calibration
        frames = {i: (off, None if mode is None else bool(mode & REVERSE_BIT))
                  for i, (off, mode) in self.read_frames().items()}
        ticks = {i: self.read_register(i, "Present Position") for i in self.ids}
        why = cal.startup_mismatch({i: s.model for i, s in self.found.items()}, frames, ticks,
                                   {a.id: a.ticks_per_rev for a in self.config.axes})
        if why:
            raise RigConfigError(why, port=str(self.port))

    def _plain_read(self) -> None:
        """The cycle reads Present Position alone (no goal read back)."""
        item = self._present_item
        self._read_at, self._read_len = item.address, item.size
        self._read_dtype = f"<{'i' if item.signed else 'u'}{item.size}"
        self.read_back = False
        self.held_goals = None

    def map_read_back(self) -> bool:
        """Map Present Position, then Goal Position, into the first indirect data block of
        every servo (8 bytes; e-Manual "Indirect Address") so that the cycle's one sync read
        also returns the goal each servo holds (:attr:`held_goals`). Indirect Address items
        already holding the mapping are not written again; those written are read back. Before
        it is used, one read of the indirect data is checked against direct reads of Goal
        Position (equal) and Present Position (between two reads around it).

        Returns
        -------
        bool
            True when the cycle reads back the goal; False (and a line in :attr:`advice`) when
            a servo has no indirect addressing, refuses the mapping or does not honour it: the
            cycle then reads Present Position alone.
        """
        self._plain_read()
        tables = [self._table_of(i) for i in self.ids]
        blocks = {t.indirect[0] if t.indirect and t.protocol == 2.0 else None for t in tables}
        block = next(iter(blocks))
        t = self.table
        if len(blocks) != 1 or block is None or block.count < 8 or self.protocol != 2.0 \
                or "Goal Position" not in t or "Present Position" not in t:
            no = [i for i, tb in zip(self.ids, tables, strict=True) if not tb.indirect]
            why = (f"servo ID {no[0]} ({self.found[no[0]].model}) has no indirect addressing"
                   if no else "the servos' indirect blocks differ" if self.protocol == 2.0
                   else "the bus speaks Protocol 1.0 (the goal's read-back is 2.0's)")
            self.advice.append(f"{why}: the loop reads Present Position only and does not "
                               f"check that each servo holds the goal written")
            return False
        a_p, a_g = t["Present Position"].address, t["Goal Position"].address
        want = [a_p + j for j in range(4)] + [a_g + j for j in range(4)]
        raw = b"".join(a.to_bytes(2, "little") for a in want)
        url = str(self.port)
        try:
            for dxl_id in self.ids:
                if self._read_raw(dxl_id, block.address_start, len(raw)) == raw:
                    continue
                self._write_raw(dxl_id, block.address_start, raw)
                held = self._read_raw(dxl_id, block.address_start, len(raw))
                if held != raw:
                    raise RigProtocolError("Indirect Address 1-8 were written but the servo "
                                           "did not keep them", port=url, dxl_id=dxl_id,
                                           actual=held.hex(), expected=raw.hex())
        except RigProtocolError as err:
            if "did not keep" in str(err):
                raise
            self.advice.append(f"{err}: the loop reads Present Position only and does not "
                               f"check that each servo holds the goal written")
            return False
        before = self.transact(lambda d: self.group_read(a_p, 4), "sync read of Present Position")
        mapped = self.transact(lambda d: self.group_read(block.data_start, 8),
                               "sync read of Indirect Data")
        after = self.transact(lambda d: self.group_read(a_p, 4), "sync read of Present Position")
        goals = self.transact(lambda d: self.group_read(a_g, 4), "sync read of Goal Position")
        for dxl_id in self.ids:
            p0, p1 = (int.from_bytes(x[dxl_id], "little", signed=True) for x in (before, after))
            p = int.from_bytes(mapped[dxl_id][:4], "little", signed=True)
            if mapped[dxl_id][4:] != goals[dxl_id] or not min(p0, p1) - 2 <= p <= max(p0, p1) + 2:
                self.advice.append(
                    f"servo ID {dxl_id} does not honour its indirect addressing (Indirect Data "
                    f"reads {p} for Present Position {p0}): the loop reads Present Position "
                    f"only and does not check that each servo holds the goal written")
                return False
        self._read_at, self._read_len, self._read_dtype = block.data_start, 8, "<i4"
        self.read_back = True
        return True

    def _read_raw(self, dxl_id: int, address: int, length: int) -> bytes:
        """``length`` bytes of one servo from ``address`` (retried)."""
        def once(deadline: float) -> bytes:
            port = self._sdk_port
            port.is_using = False
            data, result, err = self._guard(
                lambda: self._ph.readTxRx(port, dxl_id, address, length))
            self._result(result, f"read of {length} bytes at {address}", dxl_id)
            self._status_error(dxl_id, err, f"read of {length} bytes at {address}")
            return bytes(data)

        return self.transact(once, f"read at {address}", dxl_id=dxl_id)

    def _write_raw(self, dxl_id: int, address: int, data: bytes) -> None:
        """Write ``data`` to one servo at ``address`` (acknowledged, retried)."""
        def once(deadline: float) -> None:
            port = self._sdk_port
            port.is_using = False
            result, err = self._guard(lambda: self._ph.writeTxRx(port, dxl_id, address,
                                                                 len(data), list(data)))
            self._result(result, f"write of {len(data)} bytes at {address}", dxl_id)
            self._status_error(dxl_id, err, f"write of {len(data)} bytes at {address}")

        self.transact(once, f"write at {address}", dxl_id=dxl_id)

    def _arm_watchdog(self, ms: int) -> int:
        """Bus Watchdog on every servo, ``ms`` rounded up to 20 ms units (0 disarms and clears
        a watchdog error); the ms set: 0 on servos without one (AX, MX on 1.0: they hold their
        last goal when the host stops)."""
        if self.table.resolve("Bus Watchdog") is None:
            return 0
        if ms < 0 or ms > 2540:
            raise RigConfigError("Bus Watchdog must be 0..2540 ms", port=str(self.port),
                                 actual=ms)
        units = 0 if ms == 0 else max(1, math.ceil(ms / 20))
        for dxl_id in self.ids:
            if units:  # a latched watchdog error (-1) must be cleared with 0 first
                self.write_register(dxl_id, "Bus Watchdog", 0)
            self.write_register(dxl_id, "Bus Watchdog", units)
        return units * 20

    def _poll_alerts(self) -> list[HardwareAlert]:
        """Current hardware alerts (one per servo in error), torque as the servo reports it.

        Level-triggered: a servo in error is reported at every poll until it is rebooted
        (hardware error) or its watchdog is cleared.
        """
        return self._wire.poll_alerts()

    def reboot(self, dxl_id: int, *, wait_s: float = REBOOT_WAIT_S) -> None:
        """REBOOT one servo (clears its hardware error; torque comes back off) and wait until
        it answers a PING again: a servo is silent while it boots (an XC330 ~0.4 s), and a
        packet sent to it meanwhile is lost.

        Raises
        ------
        RigTimeoutError
            It did not answer within ``wait_s`` seconds.
        """
        self._wire.reboot(dxl_id)
        self._alert_ids.discard(dxl_id)
        self._hw_bits.pop(dxl_id, None)
        deadline = time.monotonic() + wait_s
        while self._guard(lambda: self._wire.ping(dxl_id)) is None:
            if time.monotonic() >= deadline:
                raise RigTimeoutError(f"servo did not answer within {wait_s:g} s of its reboot",
                                      port=str(self.port), dxl_id=dxl_id)


#: Above this many IDs to try at one baud rate, :func:`scan` sends one broadcast PING first and
#: then pings only the IDs that answered it.
BROADCAST_SCAN_ABOVE = 24


def scan(port: str | Port, bauds: Iterable[int] | None = None,
         ids: Iterable[int] = range(253), *, latency_ms: float | None = None,
         on_found=None, protocols: Sequence[float] | None = None) -> list[ServoInfo]:
    """PING every ID at every baud rate, in each protocol: what answers, with each
    servo's Homing Offset and reverse bit read after its PING (:class:`ServoInfo`).

    A few IDs: per-ID pings with the SDK's timeout formula at ``latency_ms`` (default: the
    adapter's detected latency timer, 50 ms on a simulator). More than
    :data:`BROADCAST_SCAN_ABOVE` IDs: one ``broadcastPing`` per baud rate (it always waits
    ~0.8 s, 4.4 s at 9600 bit/s, but a silent ID costs nothing more), then per-ID pings of the
    IDs that answered, for their model and firmware.

    Parameters
    ----------
    port : str or Port
    bauds : iterable of int, optional
        Default: every X-series rate the SDK can set (:data:`SCAN_BAUDS`), fastest first.
    ids : iterable of int
    on_found : callable, optional
        Called with each :class:`ServoInfo` as it is found.
    protocols : sequence of float, optional
        At each rate, 2.0 PINGs then 1.0 PINGs of the IDs still silent (one bus carries
        both). Protocol 1.0 has no broadcast PING, so each silent ID costs a timeout: default
        ``(2.0, 1.0)`` for at most :data:`BROADCAST_SCAN_ABOVE` IDs, ``(2.0,)`` above.

    Raises
    ------
    RigConnectionError
        The port cannot be opened.
    """
    bauds = list(bauds) if bauds is not None else sorted(SCAN_BAUDS, reverse=True)
    ids = list(ids)
    if protocols is None:
        protocols = (2.0, 1.0) if len(ids) <= BROADCAST_SCAN_ABOVE else (2.0,)
    own = not isinstance(port, Port)
    p = open_port(port, baud=bauds[0]) if own else port
    try:
        latency = latency_ms if latency_ms is not None else _default_latency(p)
        found: list[ServoInfo] = []
        sdk_port = None
        try:
            for baud in bauds:
                if sdk_port is None:
                    sdk_port, ph = _open_sdk(p.current_path(), str(p), baud, latency)
                elif not sdk_port.setBaudRate(baud):
                    raise RigConfigError(f"dynamixel_sdk cannot set {baud} bit/s", port=str(p))
                seen = {s.id for s in found}
                todo = [i for i in ids if i not in seen]
                if 2.0 not in protocols:
                    todo = []
                elif len(todo) > BROADCAST_SCAN_ABOVE:
                    # one broadcast PING (~0.8 s at 1 Mbit/s, whatever answers) instead of a
                    # timeout per silent ID (253 x ~34 ms with the SDK's default latency)
                    try:
                        answers, _ = ph.broadcastPing(sdk_port)
                    except _CONNECTION_ERRORS as err:
                        raise RigConnectionError(f"the adapter stopped working ({err})",
                                                 port=str(p)) from err
                    todo = sorted(i for i in answers if i in set(todo))
                for dxl_id in todo:
                    try:
                        got = _ping(sdk_port, ph, dxl_id)
                    except _CONNECTION_ERRORS as err:
                        raise RigConnectionError(f"the adapter stopped working ({err})",
                                                 port=str(p)) from err
                    if got is not None:
                        try:
                            frame = _read_frame(sdk_port, ph, dxl_id, got[0])
                        except _CONNECTION_ERRORS as err:
                            raise RigConnectionError(f"the adapter stopped working ({err})",
                                                     port=str(p)) from err
                        info = ServoInfo(dxl_id, got[0], _model_name(got[0]), got[1], baud,
                                         2.0, *frame)
                        found.append(info)
                        if on_found is not None:
                            on_found(info)
                if 1.0 in protocols:
                    seen = {s.id for s in found}
                    ph1 = sdk.PacketHandler(1.0)
                    for dxl_id in (i for i in ids if i not in seen and i <= 253):
                        try:
                            got = _ping1(sdk_port, ph1, dxl_id)
                        except _CONNECTION_ERRORS as err:
                            raise RigConnectionError(f"the adapter stopped working ({err})",
                                                     port=str(p)) from err
                        if got is not None:
                            try:
                                frame = _read_frame(sdk_port, ph1, dxl_id, got[0], 1.0)
                            except _CONNECTION_ERRORS as err:
                                raise RigConnectionError(f"the adapter stopped working "
                                                         f"({err})", port=str(p)) from err
                            info = ServoInfo(dxl_id, got[0], _model_name1(got[0]), got[1],
                                             baud, 1.0, *frame)
                            found.append(info)
                            if on_found is not None:
                                on_found(info)
        finally:
            if sdk_port is not None and sdk_port.is_open:
                try:
                    sdk_port.closePort()
                except _CONNECTION_ERRORS:
                    pass
        return found
    finally:
        if own:
            p.close()


def find_servos(port: str, *, baud: int | None = None, ids: Sequence[int] = range(253),
                latency_ms: float | None = None, on_found=None,
                on_note=None, protocols: Sequence[float] | None = None) -> list[ServoInfo]:
    """``rig scan`` as a library: :func:`scan` of ``port`` at ``baud`` (default: every rate of
    :data:`SCAN_BAUDS`, fastest first), with the adapter's latency advice passed to
    ``on_note`` (hardware only) and an error when nothing answers; ``protocols`` as
    :func:`scan`.

    Raises
    ------
    RigConfigError
        ``baud`` is not a rate the SDK can set.
    RigConnectionError
        The port cannot be opened, or no servo answered (the IDs and rates tried named).
    """
    if baud is not None and baud not in SCAN_BAUDS:
        raise RigConfigError(f"--baud {baud}: not an X-series rate dynamixel_sdk can set "
                             f"({', '.join(map(str, SCAN_BAUDS))})")
    bauds = [baud] if baud is not None else sorted(SCAN_BAUDS, reverse=True)
    ids = list(ids)
    with open_port(port, baud=bauds[0]) as p:
        if not p.is_simulated and on_note is not None:
            tip = latency_advice(p.path)
            if tip:
                on_note(tip)
        found = scan(p, bauds, ids, latency_ms=latency_ms, on_found=on_found,
                     protocols=protocols)
    if not found:
        raise RigConnectionError(f"no servo answered (IDs {ids[0]}..{ids[-1]} at "
                                 f"{', '.join(map(str, bauds))} bit/s); check power, wiring "
                                 f"and the port", port=port)
    return found
