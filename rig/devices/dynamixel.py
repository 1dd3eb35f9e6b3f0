"""A bus of Dynamixel X-series servos (Protocol 2.0) over the official ``dynamixel_sdk``.

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
from dataclasses import dataclass, field

import dynamixel_sdk as sdk
import numpy as np
import serial

from firmware_protocol.dynamixel.control_table import (
    BAUD_RATES,
    ControlTable,
    load_control_table,
)
from rig.devices.base import describe_open_error
from rig.devices.bus import ServoBus
from rig.devices.config import HOMING_MODES, ServoFrame, ServosConfig
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

REVERSE_BIT = 0x01
"""Drive Mode bit 0: reverse direction (X-series e-Manual, "Drive Mode (10)")."""

# X-series addresses (checked against the control table of every model found)
_ITEMS = ("Return Delay Time", "Operating Mode", "Max Position Limit", "Min Position Limit",
          "Torque Enable", "Status Return Level", "Hardware Error Status", "Bus Watchdog",
          "Goal Position", "Present Position", "Firmware Version")


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


def _open_sdk(path: str, url: str, baud: int, latency_ms: float) -> tuple[_SdkPort, object]:
    port = _SdkPort(path, latency_ms)
    try:
        ok = port.setBaudRate(baud)
    except _CONNECTION_ERRORS as err:
        raise RigConnectionError(f"cannot open the servo port: {describe_open_error(err)}",
                                 port=url) from err
    if not ok:
        raise RigConfigError(f"dynamixel_sdk cannot set {baud} bit/s", port=url,
                             expected=", ".join(map(str, SCAN_BAUDS)))
    return port, sdk.PacketHandler(2.0)


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


class DynamixelBus(ServoBus):
    """X-series servos on one bus: open, check, read, write, registers, alerts, watchdog.

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
                 fast: bool | None = None, homing: str | None = None) -> None:
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
        self._sdk_port, self._ph = _open_sdk(self.path, url, self.baud, latency)
        try:
            self._check_servos()
            self._plain_read()
            if self.homing is not None:
                self.apply_homing()
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
                got = self._guard(lambda i=dxl_id: _ping(self._sdk_port, self._ph, i))
                if got is not None:
                    model, fw, _err = got
                    found[dxl_id] = ServoInfo(dxl_id, model, _model_name(model), fw, self.baud)
            if len(found) == len(self.ids):
                break
        if not found:
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
        tables = {i: load_control_table(s.model_number) for i, s in found.items()}
        first = next(iter(tables.values()))
        for dxl_id, table in tables.items():
            for item in _ITEMS:
                if item not in table or (table[item].address, table[item].size) != \
                        (first[item].address, first[item].size):
                    raise RigConfigError(f"control table of {table.display_name} lacks or moves "
                                         f"{item!r}; the bus needs X-series servos",
                                         port=url, dxl_id=dxl_id)
        self.found = found
        self.table: ControlTable = first
        t = first
        self._a_present, self._a_goal = t["Present Position"].address, t["Goal Position"].address
        supported = all(s.firmware >= FAST_SYNC_READ_FIRMWARE for s in found.values())
        self.fast = supported if self._fast_wanted is None else bool(self._fast_wanted)
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
        if error & ALERT_BIT:
            self._alert_ids.add(dxl_id)
            self.alert_pending = True
        code = error & 0x7F
        if code:
            raise RigProtocolError(f"{what}: servo answered {_ERROR_NAMES.get(code, code)}",
                                   port=str(self.port), dxl_id=dxl_id, actual=code)

    # -- the cycle ------------------------------------------------------------------------
    def _read_ticks(self, deadline: float) -> np.ndarray:
        self._begin_read()
        return self._finish_read()

    def _begin_read(self) -> None:
        """The sync read request of Present Position (its packet timeout starts now), and of
        the goal held when :meth:`map_read_back` mapped both into the indirect data."""
        self._sync_read_tx(self._read_at, self._read_len, self._id_param)

    def _finish_read(self) -> np.ndarray:
        """The reply of :meth:`_begin_read` as ticks, (n,) int64 (and :attr:`held_goals`)."""
        data = self._sync_read_rx(self._read_len, self._id_param)
        v = np.frombuffer(b"".join([data[i] for i in self.ids]), dtype="<i4").astype(np.int64)
        if self._read_len == 8:
            self.held_goals = v[1::2]
            return v[0::2]
        return v

    def sync_read(self, address: int, length: int,
                  ids: Sequence[int] | None = None) -> dict[int, bytes]:
        """One SYNC READ (FAST SYNC READ when in use): ``{id: bytes}``; no retries.

        Status error bytes are checked (alert bit noted, error codes raised).
        """
        ids = self._id_param if ids is None else list(ids)
        self._sync_read_tx(address, length, ids)
        return self._sync_read_rx(length, ids)

    def _sync_read_tx(self, address: int, length: int, ids: list[int]) -> None:
        """Send a (fast) sync read request; the SDK starts the reply's packet timeout."""
        port, ph = self._sdk_port, self._ph
        port.is_using = False
        fast = self.fast
        result = self._guard(lambda: ph.syncReadTx(port, address, length, ids, len(ids), fast))
        self._result(result, "fast sync read" if fast else "sync read")

    def _sync_read_rx(self, length: int, ids: list[int]) -> dict[int, bytes]:
        """Collect the replies of :meth:`_sync_read_tx`: ``{id: bytes}``."""
        port, ph = self._sdk_port, self._ph
        out: dict[int, bytes] = {}
        if self.fast:
            raw, result, _ = self._guard(
                lambda: ph.fastSyncReadRx(port, sdk.BROADCAST_ID, (length + 4) * len(ids)))
            self._result(result, "fast sync read")
            off = 0
            for _ in ids:
                if off + 2 + length > len(raw):
                    break
                err, dxl_id = raw[off], raw[off + 1]
                out[dxl_id] = bytes(raw[off + 2:off + 2 + length])
                self._status_error(dxl_id, err, "fast sync read")
                off += length + 4
            missing = [i for i in ids if i not in out]
            if missing:
                raise RigTimeoutError("fast sync read: no data", port=str(self.port),
                                      dxl_id=missing[0])
            return out
        for dxl_id in ids:
            data, result, err = self._guard(lambda i=dxl_id: ph.readRx(port, i, length))
            self._result(result, "sync read", dxl_id)
            self._status_error(dxl_id, err, "sync read")
            out[dxl_id] = bytes(data)
        return out

    def _write_goal_ticks(self, ticks: list[int]) -> None:
        """Goal Position of every servo by one SYNC WRITE (no reply, no retry)."""
        param: list[int] = []
        for dxl_id, t in zip(self.ids, ticks, strict=True):
            v = int(t) & 0xFFFFFFFF
            param += (dxl_id, v & 0xFF, v >> 8 & 0xFF, v >> 16 & 0xFF, v >> 24 & 0xFF)
        port = self._sdk_port
        port.is_using = False
        result = self._guard(lambda: self._ph.syncWriteTxOnly(port, self._a_goal, 4, param,
                                                              len(param)))
        self._result(result, "sync write of Goal Position")

    # -- register access ------------------------------------------------------------------
    def read_register(self, dxl_id: int, name: str) -> int:
        """One control-table item of one servo (retried)."""
        item = self.table[name]

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
        item = self.table[name]
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
        """One BULK READ: ``{id: (address, length)}`` → ``{id: bytes}`` (retried)."""
        def once(deadline: float) -> dict[int, bytes]:
            port = self._sdk_port
            port.is_using = False
            param: list[int] = []
            for dxl_id, (address, length) in requests.items():
                param += (dxl_id, address & 0xFF, address >> 8, length & 0xFF, length >> 8)
            result = self._guard(lambda: self._ph.bulkReadTx(port, param, len(param), False))
            self._result(result, "bulk read")
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
        got = self._guard(lambda: _ping(self._sdk_port, self._ph, dxl_id))
        if got is None:
            return None
        return ServoInfo(dxl_id, got[0], _model_name(got[0]), got[1], self.baud)

    # -- torque, configuration, watchdog --------------------------------------------------
    def _read_torque(self) -> np.ndarray:
        """Torque Enable as each servo reports it, (n,) bool."""
        a = self.table["Torque Enable"].address
        data = self.transact(lambda d: self.sync_read(a, 1), "sync read of Torque Enable")
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
        multi_turn = bool((lo < 0).any() or (hi > 4095).any())
        for k, dxl_id in enumerate(self.ids):
            want = {"Operating Mode": 4 if multi_turn else 3,
                    "Return Delay Time": self.return_delay_us // 2}
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

    def _plain_read(self) -> None:
        """The cycle reads Present Position alone (no goal read back)."""
        self._read_at, self._read_len = self._a_present, 4
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
        if len(blocks) != 1 or block is None or block.count < 8 \
                or "Goal Position" not in t or "Present Position" not in t:
            no = [i for i, tb in zip(self.ids, tables, strict=True) if not tb.indirect]
            why = (f"servo ID {no[0]} ({self.found[no[0]].model}) has no indirect addressing"
                   if no else "the servos' indirect blocks differ")
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
        before = self.transact(lambda d: self.sync_read(a_p, 4), "sync read of Present Position")
        mapped = self.transact(lambda d: self.sync_read(block.data_start, 8),
                               "sync read of Indirect Data")
        after = self.transact(lambda d: self.sync_read(a_p, 4), "sync read of Present Position")
        goals = self.transact(lambda d: self.sync_read(a_g, 4), "sync read of Goal Position")
        for dxl_id in self.ids:
            p0, p1 = (int.from_bytes(x[dxl_id], "little", signed=True) for x in (before, after))
            p = int.from_bytes(mapped[dxl_id][:4], "little", signed=True)
            if mapped[dxl_id][4:] != goals[dxl_id] or not min(p0, p1) - 2 <= p <= max(p0, p1) + 2:
                self.advice.append(
                    f"servo ID {dxl_id} does not honour its indirect addressing (Indirect Data "
                    f"reads {p} for Present Position {p0}): the loop reads Present Position "
                    f"only and does not check that each servo holds the goal written")
                return False
        self._read_at, self._read_len = block.data_start, 8
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
        a watchdog error); the ms set."""
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
        t = self.table
        a0 = t["Torque Enable"].address
        a_hw, a_wd = t["Hardware Error Status"].address, t["Bus Watchdog"].address
        length = a_wd + 1 - a0
        data = self.transact(lambda d: self.sync_read(a0, length), "alert poll")
        now = time.monotonic()
        alerts = []
        for dxl_id in self.ids:
            b = data[dxl_id]
            hw, wd = b[a_hw - a0], b[a_wd - a0]
            names = tuple(n for bit, n in _HW_BITS.items() if hw & bit)
            if wd == 0xFF:
                names += ("bus_watchdog",)
            if names or dxl_id in self._alert_ids:
                alerts.append(HardwareAlert(str(self.port), dxl_id, now, hw, names,
                                            bool(b[0])))
        self._alert_ids.clear()
        return alerts

    def reboot(self, dxl_id: int) -> None:
        """REBOOT one servo (clears its hardware error; torque comes back off)."""
        port = self._sdk_port
        port.is_using = False
        result, _ = self._guard(lambda: self._ph.reboot(port, dxl_id))
        self._result(result, "reboot", dxl_id)
        self._alert_ids.discard(dxl_id)


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
