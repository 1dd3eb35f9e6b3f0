"""A simulated chain of Dynamixel X-series servos behind a simulated USB adapter (U2D2).

The bus is served on a pseudo-terminal: :attr:`DynamixelBus.port` (``/dev/pts/N``) is opened by
``dynamixel_sdk.PortHandler`` (or plain pyserial) exactly like ``/dev/ttyUSB0``. Bytes are
Protocol 2.0 (see :mod:`firmware_protocol.dynamixel`); one background thread waits on the pty
master and a wake-up pipe with ``select`` (``poll`` if fd numbers pass FD_SETSIZE) and answers
instruction packets. Also reachable as a port string: ``sim://dynamixel?ids=1,2,3``
(:func:`bus_from_url`).

What is modelled
----------------
* Control table per model, from the SDK's ``.model`` files; EEPROM (< 64) writable only with
  torque off, read-only items, value ranges and goal limits -> the e-Manual error codes.
* Baud rate: each servo answers only when the client's line speed (read back from the pty's
  termios) equals its Baud Rate item; unknown speeds (custom ``BOTHER`` rates) are accepted.
  Wire time is modelled: a reply starts ``instruction bytes x 10 / baud`` after the
  instruction arrived plus the servo's Return Delay Time (address 9, 2 µs units), and each
  reply occupies ``bytes x 10 / baud``; sync/bulk read replies follow one another in request
  order. The USB adapter's own latency (FTDI latency timer) is not modelled.
* Status Return Level (68): 0 answers only PING, 1 PING and reads, 2 everything (unicast).
* Motion in position modes (3, 4, 5): trapezoidal velocity profile from Profile Velocity
  (0.229 rev/min units) and Profile Acceleration (214.577 rev/min² units), 0 meaning
  "unlimited" (Velocity Limit / instantaneous); mode 3 clamps the goal to the Min/Max Position
  Limit. Velocity mode (1) ramps to Goal Velocity. Integrated lazily on a clock that defaults
  to ``time.monotonic``. Drive Mode bit 2 selects the time-based profile (Profile Velocity =
  move time, Profile Acceleration = ramp time, both ms).
* Torque off: the limb is back-drivable; Present Position follows :meth:`DynamixelBus.set_hand`.
  Torque on: Goal Position is set to Present Position first (so the limb holds still).
* Encoder noise: Gaussian, ``noise_ticks`` standard deviation, seeded.
* Hardware errors (Hardware Error Status, 70): bits in Shutdown (63) drop torque and refuse
  torque-on; every status packet carries the alert bit; REBOOT clears them. Overheating is
  raised when the temperature set by :meth:`DynamixelBus.set_temperature` exceeds the
  Temperature Limit.
* REBOOT answers first, then clears RAM to defaults and the hardware errors (a servo that
  overheated is taken to have cooled down). FACTORY_RESET (refused with torque on) restores
  EEPROM defaults too, so option 0xFF moves the servo to ID 1 at 57600 bps as hardware does.
* Errors: undefined address or beyond the table / read-only item / EEPROM with torque on ->
  access (7); a write covering part of an item or of length 0 -> data length (5); a value out of
  the item's range -> data range (4); Goal Velocity/PWM/Current beyond its limit item -> data
  limit (6); unknown instruction or ACTION without REG_WRITE -> instruction (2).
* Packets with a bad CRC are ignored (no reply). A new instruction cancels replies not yet sent.
  A half-received packet is abandoned after :data:`PACKET_TIMEOUT` without bytes.

Not modelled: Protocol 1.0, indirect address mapping (the indirect block is plain RAM),
Secondary ID, Bus Watchdog, reverse direction (Drive Mode bit 0), Homing Offset, current and
PWM control (the shaft stays put), the control-table backup instruction. In a sync/bulk read
an absent servo is skipped and the next one answers straight after the previous reply.

Fault injection
---------------
:meth:`~DynamixelBus.drop_responses`, :meth:`~DynamixelBus.corrupt_responses`,
:meth:`~DynamixelBus.delay_responses`, :meth:`~DynamixelBus.truncate_responses`,
:meth:`~DynamixelBus.raise_hardware_error`, :meth:`~DynamixelBus.unplug` /
:meth:`~DynamixelBus.replug` (servos stop answering, adapter present) and
:meth:`~DynamixelBus.disconnect` / :meth:`~DynamixelBus.reconnect`, also
``unplug(adapter=True)`` / ``replug(adapter=True)`` (the adapter itself goes
away: the pty master is closed, the client's port fails with an I/O error; reconnecting opens a
new pty, so :attr:`~DynamixelBus.port` changes).
"""

from __future__ import annotations

import contextlib
import math
import os
import random
import select
import termios
import threading
import time
import tty
import urllib.parse
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass

from firmware_protocol.dynamixel import instructions as ins
from firmware_protocol.dynamixel.control_table import (
    BAUD_RATES,
    OPERATING_MODES,
    ControlTable,
    load_control_table,
)
from firmware_protocol.dynamixel.framing import BROADCAST_ID
from firmware_protocol.dynamixel.packets import (
    ALERT,
    ErrorCode,
    Instruction,
    InstructionPacket,
    StreamDecoder,
    encode_status,
)
from firmware_protocol.errors import ProtocolError
from rig.errors import RigConfigError

__all__ = ["HARDWARE_ERRORS", "DynamixelBus", "SimServo", "bus_from_url", "start_servo_bus"]

TICKS_PER_REV = 4096
VELOCITY_UNIT = 0.229 * TICKS_PER_REV / 60.0  # ticks/s per Profile/Present Velocity unit
ACCEL_UNIT = 214.577 * TICKS_PER_REV / 3600.0  # ticks/s² per Profile Acceleration unit
_STEP = 0.001  # integration step, s
PACKET_TIMEOUT = 0.02
"""Inter-byte timeout after which a servo abandons a half-received packet, s (modelling
choice: the e-Manual does not publish the firmware's value)."""

HARDWARE_ERRORS = {
    "input_voltage": 0x01,
    "overheating": 0x04,
    "encoder": 0x08,
    "electrical_shock": 0x10,
    "overload": 0x20,
}
"""Hardware Error Status (address 70) bits by name (X-series e-Manual)."""

_READS = frozenset({Instruction.READ, Instruction.SYNC_READ, Instruction.BULK_READ,
                    Instruction.FAST_SYNC_READ, Instruction.FAST_BULK_READ})

_FD_SETSIZE = 1024  # glibc's select() limit on fd numbers

_SPEEDS = {getattr(termios, n): int(n[1:]) for n in dir(termios)
           if n.startswith("B") and n[1:].isdigit()}


class SimServo:
    """State and behaviour of one simulated servo (not thread-safe: the bus locks around it).

    Parameters
    ----------
    dxl_id : int
        ID, 0..252.
    model : str or int
        e-Manual name, file stem or model number (see
        :func:`firmware_protocol.dynamixel.control_table.load_control_table`).
    baud_rate : int
        Initial Baud Rate in bit/s (must be one of the X-series rates).
    return_delay_us : int or None
        Initial Return Delay Time in µs (even, 0..508); None keeps the e-Manual default 500 µs.
    position : float
        Initial shaft position, ticks.
    noise_ticks : float
        Standard deviation of the encoder noise added to Present Position, ticks.
    rng : random.Random
        Source of the encoder noise.
    """

    def __init__(self, dxl_id: int, model: str | int = "XM430-W350", *,
                 baud_rate: int = 1_000_000, return_delay_us: int | None = None,
                 position: float = 2048.0, noise_ticks: float = 0.0,
                 rng: random.Random | None = None):
        if not 0 <= dxl_id <= 252:
            raise ValueError(f"servo id must be 0..252, got {dxl_id}")
        self.table: ControlTable = load_control_table(model)
        # name -> (first byte, one past last, signed, size): the hot path of get/_set
        self._fields = {n: (it.address, it.end, it.signed, it.size)
                        for n, it in self.table.items.items()}
        self.mem = self.table.default_memory()
        self._baud_index = _baud_index(baud_rate)
        self._set("ID", dxl_id)
        self._set("Baud Rate", self._baud_index)
        if return_delay_us is not None:
            if not 0 <= return_delay_us <= 508:
                raise ValueError(f"return delay must be 0..508 µs, got {return_delay_us}")
            self._set("Return Delay Time", return_delay_us // 2)
        self._eeprom_boot = bytes(self.mem[:64])
        self.noise_ticks = float(noise_ticks)
        self.rng = rng or random.Random(dxl_id)
        self.pos = float(position)
        self.vel = 0.0  # ticks/s
        self.target = float(position)
        self.hand: float | Callable[[float], float] | None = None
        self.hardware_error = 0
        self.temperature = float(self.get("Present Temperature"))
        self.registered: tuple[int, bytes] | None = None
        self._time_profile: tuple[float, float] | None = None
        self.plugged = True
        self.last_t: float | None = None
        self.boot_t = 0.0

    # ------------------------------------------------------------------ memory helpers
    def get(self, name: str) -> int:
        """Current value of control-table item ``name``."""
        start, end, signed, _ = self._fields[name]
        return int.from_bytes(self.mem[start:end], "little", signed=signed)

    def _set(self, name: str, value: int) -> None:
        field = self._fields.get(name)
        if field is not None:
            start, end, _, size = field
            self.mem[start:end] = (int(value) & ((1 << (8 * size)) - 1)).to_bytes(size, "little")

    @property
    def id(self) -> int:
        """Current ID (address 7)."""
        return self.mem[self.table["ID"].address]

    @property
    def baud_rate(self) -> int:
        """Current line speed in bit/s, from the Baud Rate item."""
        return BAUD_RATES.get(self.get("Baud Rate"), 57600)

    @property
    def return_delay(self) -> float:
        """Return Delay Time in seconds."""
        return self.get("Return Delay Time") * 2e-6

    @property
    def torque(self) -> bool:
        """Torque Enable."""
        return bool(self.get("Torque Enable"))

    # ------------------------------------------------------------------ physics
    def _limits(self) -> tuple[float, float]:
        return float(self.get("Min Position Limit")), float(self.get("Max Position Limit"))

    def _profile(self) -> tuple[float, float]:
        """(max velocity ticks/s, acceleration ticks/s²) of the current move."""
        if self._time_profile is not None:
            return self._time_profile
        pv = self.get("Profile Velocity")
        pa = self.get("Profile Acceleration")
        vlim = self.get("Velocity Limit") or 1023
        vmax = (pv if pv else vlim) * VELOCITY_UNIT
        amax = pa * ACCEL_UNIT if pa else math.inf
        return vmax, amax

    def advance(self, now: float) -> None:
        """Integrate the motion up to simulated time ``now`` (seconds)."""
        if self.last_t is None:
            self.last_t = now
            self.boot_t = now
            return
        dt = now - self.last_t
        if dt <= 0:
            return
        self.last_t = now
        if not self.torque:
            if self.hand is not None:
                hand = float(self.hand(now)) if callable(self.hand) else self.hand
                self.vel = (hand - self.pos) / dt if dt > 1e-4 else 0.0
                self.pos = hand
            else:
                self.vel = 0.0
            return
        mode = self.get("Operating Mode")
        vmax, amax = self._profile()
        if mode == 1:  # velocity control
            goal_v = self.get("Goal Velocity") * VELOCITY_UNIT
            while dt > 0:
                h = min(dt, _STEP)
                dv = goal_v - self.vel
                if math.isfinite(amax):
                    dv = max(-amax * h, min(amax * h, dv))
                self.vel += dv
                self.pos += self.vel * h
                dt -= h
                if self.vel == goal_v and goal_v == 0:
                    break
            return
        if mode not in (3, 4, 5):  # current / PWM control: not modelled, the shaft stays
            self.vel = 0.0
            return
        target = self.target
        while dt > 0:
            err = target - self.pos
            if abs(err) < 1e-6 and abs(self.vel) < 1e-6:
                self.pos, self.vel = target, 0.0
                break
            h = min(dt, _STEP)
            dt -= h
            direction = 1.0 if err > 0 else -1.0
            # the fastest speed from which we can still stop at the target (trapezoid ramp-down)
            v_stop = math.sqrt(2.0 * amax * abs(err)) if math.isfinite(amax) else math.inf
            v_des = direction * min(vmax, v_stop, abs(err) / h)
            dv = v_des - self.vel
            if math.isfinite(amax):
                dv = max(-amax * h, min(amax * h, dv))
            self.vel += dv
            self.pos += self.vel * h
            if (target - self.pos) * err <= 0:  # reached or crossed the target
                self.pos, self.vel = target, 0.0
                break

    def refresh(self, now: float) -> None:
        """Advance to ``now`` and write the present values into the control table."""
        self.advance(now)
        noise = self.rng.gauss(0.0, self.noise_ticks) if self.noise_ticks > 0 else 0.0
        present = round(self.pos + noise)
        self._set("Present Position", present)
        self._set("Present Velocity", round(self.vel / VELOCITY_UNIT))
        self._set("Position Trajectory", round(self.target))
        self._set("Velocity Trajectory", round(self.vel / VELOCITY_UNIT))
        moving = abs(self.vel) > 0 or (self.torque and abs(self.target - self.pos) >
                                       self.get("Moving Threshold"))
        self._set("Moving", int(moving))
        in_position = abs(self.target - self.pos) <= self.get("Moving Threshold")
        self._set("Moving Status", (1 if in_position else 0) | (2 if moving else 0))
        self._set("Realtime Tick", int((now - self.boot_t) * 1000) % 32768)
        self._set("Present Temperature", round(self.temperature))
        self._set("Hardware Error Status", self.hardware_error)
        self._set("Registered Instruction", int(self.registered is not None))

    def raise_error(self, bits: int) -> None:
        """Set Hardware Error Status bits; bits in Shutdown (63) drop the torque."""
        self.hardware_error |= bits
        if self.hardware_error & self.get("Shutdown"):
            self._set("Torque Enable", 0)

    def set_temperature(self, celsius: float) -> None:
        """Set the winding temperature; above the Temperature Limit raises overheating."""
        self.temperature = float(celsius)
        if celsius > self.get("Temperature Limit"):
            self.raise_error(HARDWARE_ERRORS["overheating"])

    @property
    def error_byte(self) -> int:
        """Alert bit to put on every status packet."""
        return ALERT if self.hardware_error else 0

    # ------------------------------------------------------------------ instructions
    def read(self, address: int, length: int, now: float) -> tuple[int, bytes]:
        """READ: ``(error code, data)``; data is zero-filled on error (as hardware does)."""
        if length == 0:
            return ErrorCode.DATA_LENGTH, b""
        if address + length > self.table.size:
            return ErrorCode.ACCESS, bytes(length)
        self.refresh(now)
        return ErrorCode.NONE, bytes(self.mem[address:address + length])

    def write(self, address: int, data: bytes, now: float) -> int:
        """WRITE: apply ``data`` at ``address`` all-or-nothing; returns the error code."""
        table = self.table
        end = address + len(data)
        if not data:
            return ErrorCode.DATA_LENGTH
        if end > table.size:
            return ErrorCode.ACCESS
        plain_from = table["Indirect Address 1"].address if "Indirect Address 1" in table \
            else table.size
        touched = []
        a = address
        while a < end:
            item = table.item_covering(a)
            if item is None:
                if a >= plain_from:
                    touched.append(None)
                a += 1
                continue
            if item.address < address or item.end > end:
                return ErrorCode.DATA_LENGTH
            touched.append(item)
            a = item.end
        if not touched:
            return ErrorCode.ACCESS
        items = [it for it in touched if it is not None]
        for item in items:
            if not item.writable or (item.eeprom and self.torque):
                return ErrorCode.ACCESS
        values = {it.name: it.decode(data[it.address - address:it.end - address]) for it in items}
        for name, value in values.items():
            lo_hi = table.ranges.get(name)
            if lo_hi and not lo_hi[0] <= value <= lo_hi[1]:
                return ErrorCode.DATA_RANGE
            if name == "Operating Mode" and value not in OPERATING_MODES:
                return ErrorCode.DATA_RANGE
        limits = {"Goal Velocity": "Velocity Limit", "Goal PWM": "PWM Limit",
                  "Goal Current": "Current Limit"}
        for name, limit in limits.items():
            if name in values and limit in table:
                lim = values.get(limit, self.get(limit))
                if abs(values[name]) > lim:
                    return ErrorCode.DATA_LIMIT
        self.advance(now)
        was_torque = self.torque
        self.mem[address:end] = data
        if "Torque Enable" in values:
            if values["Torque Enable"] and self.hardware_error & self.get("Shutdown"):
                self._set("Torque Enable", 0)  # shut down until reboot
            elif values["Torque Enable"] and not was_torque:
                self.vel = 0.0
                self.hand = None
                self._set("Goal Position", round(self.pos))
                self.target = self.pos
        if "Goal Position" in values or "Torque Enable" in values or any(
                n in values for n in ("Min Position Limit", "Max Position Limit")):
            self._update_target()
        return ErrorCode.NONE

    def _update_target(self) -> None:
        goal = float(self.get("Goal Position"))
        if self.get("Operating Mode") == 3:
            lo, hi = self._limits()
            goal = min(max(goal, lo), hi)
        self.target = goal
        self._time_profile = None
        if self.get("Drive Mode") & 0x04:
            # time-based profile (Drive Mode bit 2): Profile Velocity is the time to reach the
            # goal and Profile Acceleration the ramp time, both ms; the ramp is at most half
            total = self.get("Profile Velocity") / 1000.0
            ramp = min(self.get("Profile Acceleration") / 1000.0, total / 2.0)
            if total > 0:
                v = abs(goal - self.pos) / (total - ramp)
                self._time_profile = (v, v / ramp if ramp > 0 else math.inf)

    def reboot(self) -> None:
        """REBOOT: RAM back to defaults, hardware errors cleared, torque off."""
        keep = bytes(self.mem[:64])
        self.mem = self.table.default_memory()
        self.mem[:64] = keep
        self.hardware_error = 0
        self.registered = None
        self.vel = 0.0
        self.target = self.pos
        if self.temperature > self.get("Temperature Limit"):
            self.temperature = float(self.table.defaults.get("Present Temperature", 30))
        self.boot_t = self.last_t or 0.0

    def factory_reset(self, option: int) -> None:
        """FACTORY_RESET: 0xFF all, 0x01 all but ID, 0x02 all but ID and baud rate."""
        dxl_id, baud = self.id, self.get("Baud Rate")
        self.mem = self.table.default_memory()
        self._set("Baud Rate", 1)  # e-Manual factory default 57600 bps
        if option in (0x01, 0x02):
            self._set("ID", dxl_id)
        if option == 0x02:
            self._set("Baud Rate", baud)
        self.reboot()


def _wait_readable(fds: list[int], timeout: float | None) -> list[int]:
    """The fds of ``fds`` that are readable within ``timeout`` seconds (None: no limit).

    ``select`` for its microsecond timeout (return delays are tens of µs); ``poll`` (1 ms
    resolution, rounded up) when an fd number is beyond ``FD_SETSIZE``, which select refuses.
    """
    if max(fds) < _FD_SETSIZE:
        return select.select(fds, [], [], timeout)[0]
    poller = select.poll()
    for fd in fds:
        poller.register(fd, select.POLLIN)
    ms = None if timeout is None else math.ceil(timeout * 1000.0)
    return [fd for fd, events in poller.poll(ms) if events & (select.POLLIN | select.POLLHUP)]


def _baud_index(baud_rate: int) -> int:
    for index, rate in BAUD_RATES.items():
        if rate == baud_rate:
            return index
    raise ValueError(f"baud rate {baud_rate} is not an X-series rate; use one of "
                     f"{', '.join(str(b) for b in BAUD_RATES.values())}")


@dataclass
class _Faults:
    drop: int = 0
    corrupt: int = 0
    delay: float = 0.0
    delay_count: int = 0
    truncate: int = 0
    truncate_keep: int = 0
    bus_unplugged: bool = False


class DynamixelBus:
    """A chain of simulated servos served on a pseudo-terminal.

    Parameters
    ----------
    servos : sequence of SimServo
        The servos on the bus (distinct IDs).
    clock : callable, default time.monotonic
        Simulated clock in seconds; motion is integrated against it.
    model_wire_time : bool, default True
        Delay replies by the time the bytes take on the wire at the servo's baud rate.

    Attributes
    ----------
    port : str
        Path of the pty slave to open with ``PortHandler`` / pyserial.
    servos : dict of int to SimServo
        By ID at creation (IDs written later keep their original key).
    instructions_seen, replies_sent : int
        Counters of decoded instruction packets and of status packets written.
    internal_errors : list of str
        Exceptions raised while handling an instruction (simulator bugs; the packet is then
        unanswered and the bus keeps serving). Empty in a healthy run.

    Examples
    --------
    >>> with start_servo_bus([1, 2, 3]) as bus:  # doctest: +SKIP
    ...     port = dynamixel_sdk.PortHandler(bus.port)
    """

    def __init__(self, servos: Sequence[SimServo], *, clock: Callable[[], float] = time.monotonic,
                 model_wire_time: bool = True):
        ids = [s.id for s in servos]
        if not ids:
            raise ValueError("a servo bus needs at least one servo")
        if len(set(ids)) != len(ids):
            raise ValueError(f"servo ids must be distinct, got {ids}")
        self.servos: dict[int, SimServo] = {s.id: s for s in servos}
        self.clock = clock
        self.model_wire_time = model_wire_time
        self._lock = threading.RLock()
        self._faults = _Faults()
        self._decoder = StreamDecoder()
        self._last_rx = 0.0
        self._outbox: list[tuple[float, bytes]] = []
        self._closed = False
        self._stop = False
        self._master = -1
        self._slave = -1
        self._wake_r, self._wake_w = os.pipe()
        os.set_blocking(self._wake_w, False)
        self.port = ""
        self.replies_sent = 0
        self.instructions_seen = 0
        self.internal_errors: list[str] = []
        try:
            self._open_pty()
        except BaseException:
            os.close(self._wake_r)
            os.close(self._wake_w)
            raise
        self._thread = threading.Thread(target=self._serve, name=f"dxl-sim {self.port}",
                                        daemon=True)
        self._thread.start()

    # ------------------------------------------------------------------ lifecycle
    def _open_pty(self) -> None:
        master, slave = os.openpty()
        try:
            tty.setraw(slave)
            # start the line at the servos' rate, as an adapter left configured for them
            baud = next(iter(self.servos.values())).baud_rate
            attrs = termios.tcgetattr(slave)
            speed = next((k for k, v in _SPEEDS.items() if v == baud), attrs[4])
            attrs[4] = attrs[5] = speed
            termios.tcsetattr(slave, termios.TCSANOW, attrs)
            os.set_blocking(master, False)
            self.port = os.ttyname(slave)
        except BaseException:
            os.close(master)
            os.close(slave)
            raise
        self._master, self._slave = master, slave

    def _close_pty(self) -> None:
        for fd in (self._master, self._slave):
            if fd >= 0:
                with contextlib.suppress(OSError):
                    os.close(fd)
        self._master = self._slave = -1

    def _wake(self) -> None:
        with contextlib.suppress(BlockingIOError, OSError):
            os.write(self._wake_w, b"\0")

    def close(self) -> None:
        """Stop serving and release the pty; safe to call more than once."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
            self._stop = True
        self._wake()
        if self._thread is not threading.current_thread():
            self._thread.join()
        with self._lock:
            self._close_pty()
            for fd in (self._wake_r, self._wake_w):
                with contextlib.suppress(OSError):
                    os.close(fd)

    shutdown = close

    @property
    def closed(self) -> bool:
        """True once :meth:`close` has been called."""
        return self._closed

    def __enter__(self) -> DynamixelBus:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __del__(self) -> None:  # pragma: no cover - safety net only
        if not getattr(self, "_closed", True):
            with contextlib.suppress(Exception):
                self.close()

    # ------------------------------------------------------------------ python API
    def servo(self, dxl_id: int) -> SimServo:
        """The simulated servo whose ID is now ``dxl_id`` (or, failing that, was at creation)."""
        for servo in self.servos.values():
            if servo.id == dxl_id:
                return servo
        try:
            return self.servos[dxl_id]
        except KeyError:
            raise KeyError(f"no simulated servo with id {dxl_id}; ids: {sorted(self.servos)}") \
                from None

    def set_hand(self, dxl_id: int,
                 position: float | Callable[[float], float] | None) -> None:
        """Move the limb by hand: with torque off, Present Position follows ``position``.

        Parameters
        ----------
        dxl_id : int
            Servo ID.
        position : float, callable or None
            Ticks; or a function of the simulated time (s) returning ticks, for a continuous
            movement (a clinician sweeping the limb while it records); ``None`` lets go (the
            shaft stays where it is).
        """
        with self._lock:
            servo = self.servo(dxl_id)
            servo.advance(self.clock())
            servo.hand = position if position is None or callable(position) else float(position)

    def position(self, dxl_id: int) -> float:
        """True (noise-free) shaft position in ticks, advanced to now."""
        with self._lock:
            servo = self.servo(dxl_id)
            servo.advance(self.clock())
            return servo.pos

    def set_temperature(self, dxl_id: int, celsius: float) -> None:
        """Set a servo's temperature; above its Temperature Limit it reports overheating."""
        with self._lock:
            self.servo(dxl_id).set_temperature(celsius)

    def raise_hardware_error(self, dxl_id: int, kind: str | int = "overload") -> None:
        """Raise a hardware error (a :data:`HARDWARE_ERRORS` name or raw bits)."""
        bits = HARDWARE_ERRORS[kind] if isinstance(kind, str) else int(kind)
        with self._lock:
            self.servo(dxl_id).raise_error(bits)

    def drop_responses(self, count: int = 1) -> None:
        """Do not send the next ``count`` status packets (the client times out)."""
        with self._lock:
            self._faults.drop += count

    def corrupt_responses(self, count: int = 1) -> None:
        """Flip the CRC of the next ``count`` status packets."""
        with self._lock:
            self._faults.corrupt += count

    def delay_responses(self, seconds: float, count: int = 1) -> None:
        """Send the next ``count`` status packets ``seconds`` late."""
        with self._lock:
            self._faults.delay, self._faults.delay_count = float(seconds), count

    def truncate_responses(self, keep: int = 9, count: int = 1) -> None:
        """Send only the first ``keep`` bytes of the next ``count`` status packets."""
        with self._lock:
            self._faults.truncate, self._faults.truncate_keep = count, keep

    def unplug(self, ids: Iterable[int] | None = None, *, adapter: bool = False) -> None:
        """Unplug something; the client sees what it would see on hardware.

        Parameters
        ----------
        ids : iterable of int, optional
            Servos whose cable is pulled: they stop answering. ``None``: the bus cable between
            adapter and chain, so nobody answers (timeouts, the port stays open).
        adapter : bool, default False
            Unplug the USB adapter itself instead (:meth:`disconnect`): the pty goes away.
        """
        if adapter:
            self.disconnect()
            return
        with self._lock:
            if ids is None:
                self._faults.bus_unplugged = True
            else:
                for i in ids:
                    self.servo(i).plugged = False

    def replug(self, ids: Iterable[int] | None = None, *, adapter: bool = False) -> str:
        """Undo :meth:`unplug` (``ids`` None: the bus cable and every servo).

        With ``adapter=True`` the adapter is plugged back (:meth:`reconnect`): a new pty.
        Returns the port path, which changes only after an adapter replug.
        """
        if adapter:
            return self.reconnect()
        with self._lock:
            if ids is None:
                self._faults.bus_unplugged = False
                ids = list(self.servos)
            for i in ids:
                self.servo(i).plugged = True
            return self.port

    def disconnect(self) -> None:
        """Unplug the USB adapter: the pty goes away and the client's port fails with EIO."""
        with self._lock:
            self._close_pty()
            self._outbox.clear()
            self._decoder.clear()
        self._wake()

    def reconnect(self) -> str:
        """Plug the adapter back in: a new pty is opened; returns (and stores) its path."""
        with self._lock:
            if self._master < 0:
                self._open_pty()
        self._wake()
        return self.port

    # ------------------------------------------------------------------ serving thread
    def _client_baud(self) -> int | None:
        try:
            return _SPEEDS.get(termios.tcgetattr(self._slave)[5])
        except (termios.error, OSError):
            return None

    def _serve(self) -> None:
        while True:
            with self._lock:
                if self._stop:
                    return
                master = self._master
                due = self._outbox[0][0] if self._outbox else None
                if self._decoder.pending:  # a partial frame: give up on it after a while
                    stale = self._last_rx + PACKET_TIMEOUT
                    due = stale if due is None else min(due, stale)
            timeout = None if due is None else max(0.0, due - time.monotonic())
            fds = [self._wake_r] + ([master] if master >= 0 else [])
            try:
                ready = _wait_readable(fds, timeout)
            except OSError:  # fd closed under us by disconnect(): re-read the state
                continue
            if self._wake_r in ready:
                with contextlib.suppress(OSError):
                    os.read(self._wake_r, 4096)
            if master in ready:
                try:
                    data = os.read(master, 4096)
                except (BlockingIOError, InterruptedError):
                    data = b""
                except OSError:
                    data = b""
                if data:
                    self._on_bytes(data, time.monotonic())
            self._flush_outbox()
            self._expire_partial()

    def _expire_partial(self) -> None:
        with self._lock:
            if self._decoder.pending and time.monotonic() - self._last_rx >= PACKET_TIMEOUT:
                self._decoder.skip_frame()
                self._last_rx = time.monotonic()
                self._drain(self._last_rx)

    def _flush_outbox(self) -> None:
        with self._lock:
            now = time.monotonic()
            while self._outbox and self._outbox[0][0] <= now:
                _, data = self._outbox.pop(0)
                if self._master >= 0 and data:
                    with contextlib.suppress(OSError):
                        os.write(self._master, data)
                    self.replies_sent += 1

    def _on_bytes(self, data: bytes, t_rx: float) -> None:
        with self._lock:
            self._last_rx = t_rx
            self._decoder.feed(data)
            self._drain(t_rx)

    def _drain(self, t_rx: float) -> None:
        with self._lock:
            while True:
                try:
                    packet = self._decoder.next_packet()
                except ProtocolError:
                    continue  # bad CRC / framing: a servo ignores it
                if packet is None:
                    return
                if isinstance(packet, InstructionPacket):
                    self._outbox.clear()  # a new instruction pre-empts unsent replies
                    self.instructions_seen += 1
                    try:
                        self._dispatch(packet, t_rx)
                    except Exception as err:  # a simulator bug must not kill the bus
                        self.internal_errors.append(f"{packet!r}: {type(err).__name__}: {err}")

    # ------------------------------------------------------------------ instruction handling
    def _listeners(self) -> list[SimServo]:
        if self._faults.bus_unplugged:
            return []
        client = self._client_baud()
        return [s for s in self.servos.values()
                if s.plugged and (client is None or client == s.baud_rate)]

    def _schedule(self, servo: SimServo, packet: bytes, start_after: float) -> float:
        """Queue ``packet`` to be sent; returns the time its last byte is on the wire."""
        f = self._faults
        byte_time = 10.0 / servo.baud_rate if self.model_wire_time else 0.0
        begin = start_after + servo.return_delay
        end = begin + len(packet) * byte_time
        if f.drop:
            f.drop -= 1
            return end
        if f.corrupt:
            f.corrupt -= 1
            packet = packet[:-2] + bytes((packet[-2] ^ 0xFF, packet[-1] ^ 0x5A))
        if f.truncate:
            f.truncate -= 1
            packet = packet[:f.truncate_keep]
        due = end
        if f.delay_count:
            f.delay_count -= 1
            due += f.delay
        self._outbox.append((due, packet))
        self._outbox.sort(key=lambda e: e[0])
        return end

    def _dispatch(self, pkt: InstructionPacket, t_rx: float) -> None:
        now = self.clock()
        listeners = self._listeners()
        if not listeners:
            return
        size = 10 + len(pkt.params)  # header, id, length, instruction, CRC (stuffing ignored)
        wire = size * 10.0 / listeners[0].baud_rate if self.model_wire_time else 0.0
        t = t_rx + wire
        inst = pkt.instruction
        if inst in (Instruction.SYNC_READ, Instruction.FAST_SYNC_READ, Instruction.BULK_READ,
                    Instruction.FAST_BULK_READ):
            if pkt.id == BROADCAST_ID:
                self._group_read(pkt, listeners, now, t)
            return
        if inst in (Instruction.SYNC_WRITE, Instruction.BULK_WRITE):
            if pkt.id == BROADCAST_ID:
                self._group_write(pkt, listeners, now)
            return
        targets = listeners if pkt.id == BROADCAST_ID else [s for s in listeners
                                                             if s.id == pkt.id]
        for servo in sorted(targets, key=lambda s: s.id):
            # the level in force when the instruction arrived decides (a write that changes
            # Status Return Level is still acknowledged under the old level)
            answer = inst == Instruction.PING or (pkt.id != BROADCAST_ID
                                                  and self._srl_allows(servo, inst))
            error, params, after = self._execute(servo, pkt, now)
            # a broadcast PING is answered by every servo, one after another in ID order
            if answer:
                status = encode_status(servo.id, error | servo.error_byte, params)
                t = self._schedule(servo, status, t)
            if after is not None:
                after()

    @staticmethod
    def _srl_allows(servo: SimServo, inst: int) -> bool:
        level = servo.get("Status Return Level")
        if inst == Instruction.PING:
            return True
        if inst in _READS:
            return level >= 1
        return level >= 2

    def _execute(self, servo: SimServo, pkt: InstructionPacket,
                 now: float) -> tuple[int, bytes, Callable[[], None] | None]:
        """Run a unicast/broadcast instruction on one servo: (error, reply params, after)."""
        inst = pkt.instruction
        try:
            if inst == Instruction.PING:
                return 0, ins.ping_status_params(servo.table.model_number,
                                                 servo.get("Firmware Version")), None
            if inst == Instruction.READ:
                address, length = ins.parse_read(pkt.params)
                error, data = servo.read(address, length, now)
                return error, data, None
            if inst == Instruction.WRITE:
                address, data = ins.parse_write(pkt.params)
                return servo.write(address, data, now), b"", None
            if inst == Instruction.REG_WRITE:
                address, data = ins.parse_write(pkt.params)
                if address + len(data) > servo.table.size or not data:
                    return ErrorCode.ACCESS if data else ErrorCode.DATA_LENGTH, b"", None
                servo.registered = (address, data)
                return 0, b"", None
            if inst == Instruction.ACTION:
                if servo.registered is None:
                    return ErrorCode.INSTRUCTION, b"", None
                address, data = servo.registered
                servo.registered = None
                return servo.write(address, data, now), b"", None
            if inst == Instruction.REBOOT:
                return 0, b"", servo.reboot
            if inst == Instruction.FACTORY_RESET:
                if len(pkt.params) != 1 or pkt.params[0] not in (0xFF, 0x01, 0x02):
                    return ErrorCode.DATA_RANGE, b"", None
                if servo.torque:
                    return ErrorCode.ACCESS, b"", None
                option = pkt.params[0]
                return 0, b"", lambda: servo.factory_reset(option)
            if inst == Instruction.CLEAR:
                if pkt.params != ins.CLEAR_MULTI_TURN:
                    return ErrorCode.DATA_RANGE, b"", None
                servo.advance(now)
                if servo.vel != 0:
                    return ErrorCode.RESULT_FAIL, b"", None
                servo.pos %= TICKS_PER_REV
                servo.target = servo.pos
                return 0, b"", None
        except ProtocolError:
            return ErrorCode.DATA_LENGTH, b"", None
        return ErrorCode.INSTRUCTION, b"", None

    def _group_read(self, pkt: InstructionPacket, listeners: list[SimServo], now: float,
                    t: float) -> None:
        by_id = {s.id: s for s in listeners}
        try:
            if pkt.instruction in (Instruction.SYNC_READ, Instruction.FAST_SYNC_READ):
                address, length, ids = ins.parse_sync_read(pkt.params)
                requests = [(i, address, length) for i in ids]
            else:
                requests = ins.parse_bulk_read(pkt.params)
        except ProtocolError:
            return
        fast = pkt.instruction in (Instruction.FAST_SYNC_READ, Instruction.FAST_BULK_READ)
        entries: list[tuple[int, int, bytes]] = []
        last: SimServo | None = None
        for dxl_id, address, length in requests:
            servo = by_id.get(dxl_id)
            if servo is None or not self._srl_allows(servo, pkt.instruction):
                continue  # absent servo: the next one answers after its own delay
            error, data = servo.read(address, length, now)
            error |= servo.error_byte
            if fast:
                entries.append((error, servo.id, data))
                last = servo
            else:
                t = self._schedule(servo, encode_status(servo.id, error, data), t)
        if fast and entries and last is not None:
            delay = sum(by_id[e[1]].return_delay for e in entries[:-1])
            self._schedule(last, ins.encode_fast_status(entries), t + delay)

    def _group_write(self, pkt: InstructionPacket, listeners: list[SimServo], now: float) -> None:
        by_id = {s.id: s for s in listeners}
        try:
            if pkt.instruction == Instruction.SYNC_WRITE:
                address, _, data = ins.parse_sync_write(pkt.params)
                writes = [(i, address, d) for i, d in data.items()]
            else:
                writes = ins.parse_bulk_write(pkt.params)
        except ProtocolError:
            return
        for dxl_id, address, data in writes:
            servo = by_id.get(dxl_id)
            if servo is not None:
                servo.write(address, data, now)


def start_servo_bus(ids: Iterable[int] | Sequence[tuple[int, str]] = (1,),
                    model: str = "XM430-W350", *, baud_rate: int = 1_000_000,
                    return_delay_us: int | None = None, noise_ticks: float = 0.0,
                    seed: int = 0, positions: Sequence[float] | None = None,
                    clock: Callable[[], float] = time.monotonic,
                    model_wire_time: bool = True) -> DynamixelBus:
    """Start a simulated servo chain on a new pty.

    Parameters
    ----------
    ids : iterable of int, or of (id, model)
        Servo IDs (all of ``model``), or ``(id, model)`` pairs for a mixed chain.
    model : str
        e-Manual model name, e.g. ``"XM430-W350"``, ``"XL430-W250"``, ``"XC330-M288"``.
    baud_rate : int
        Line speed of every servo, bit/s.
    return_delay_us : int or None
        Return Delay Time of every servo in µs; None keeps the default 500 µs.
    noise_ticks : float
        Encoder noise standard deviation, ticks.
    seed : int
        Seed of the encoder noise (servo ``k`` uses ``seed + id``).
    positions : sequence of float, optional
        Initial shaft positions in ticks (default 2048, mid-range).
    clock : callable
        Simulated clock, seconds.
    model_wire_time : bool
        Model the time bytes take on the wire.

    Returns
    -------
    DynamixelBus
        Already serving; use it as a context manager or call ``close()``.

    Raises
    ------
    RigConfigError
        Unknown model, bad ID, duplicate IDs or unsupported baud rate.
    """
    specs = [(i, model) if isinstance(i, int) else (int(i[0]), str(i[1])) for i in ids]
    if not specs:
        raise RigConfigError("a servo bus needs at least one servo id")
    try:
        servos = [SimServo(i, m, baud_rate=baud_rate, return_delay_us=return_delay_us,
                           position=positions[k] if positions is not None else 2048.0,
                           noise_ticks=noise_ticks, rng=random.Random(seed + i))
                  for k, (i, m) in enumerate(specs)]
        return DynamixelBus(servos, clock=clock, model_wire_time=model_wire_time)
    except ValueError as err:
        raise RigConfigError(str(err)) from err


def bus_from_url(url: str, **overrides: object) -> DynamixelBus:
    """Start a simulated chain described by a port string.

    ``sim://dynamixel?ids=1,2,3&model=XM430-W350&baud=1000000&return_delay_us=0&noise=0.5&seed=1``
    (every query key optional: one XM430-W350 with ID 1 at 1 Mbps). This is the seam where a
    port string chooses the simulator instead of ``/dev/ttyUSB0``.

    Parameters
    ----------
    url : str
        ``sim://dynamixel`` URL.
    **overrides
        Keyword arguments of :func:`start_servo_bus` that win over the URL (e.g. ``clock``).

    Raises
    ------
    RigConfigError
        Not a ``sim://dynamixel`` URL, unknown key or bad value.
    """
    parts = urllib.parse.urlsplit(url)
    if parts.scheme != "sim" or parts.netloc not in ("dynamixel", "dxl"):
        raise RigConfigError(f"{url!r} is not a simulated servo bus URL "
                             f"(expected sim://dynamixel?ids=1,2,3&model=XM430-W350)")
    query = urllib.parse.parse_qs(parts.query, keep_blank_values=True)
    known = {"ids", "model", "baud", "return_delay_us", "noise", "seed"}
    unknown = set(query) - known
    if unknown:
        raise RigConfigError(f"{url!r}: unknown key(s) {', '.join(sorted(unknown))}; "
                             f"known: {', '.join(sorted(known))}")
    one = {k: v[-1] for k, v in query.items()}
    try:
        kwargs: dict[str, object] = {
            "ids": [int(i) for i in one.get("ids", "1").split(",")],
            "model": one.get("model", "XM430-W350"),
            "baud_rate": int(one.get("baud", "1000000")),
            "return_delay_us": int(one["return_delay_us"]) if "return_delay_us" in one else None,
            "noise_ticks": float(one.get("noise", "0")),
            "seed": int(one.get("seed", "0")),
        }
    except ValueError as err:
        raise RigConfigError(f"{url!r}: {err}") from err
    kwargs.update(overrides)
    return start_servo_bus(**kwargs)  # type: ignore[arg-type]
