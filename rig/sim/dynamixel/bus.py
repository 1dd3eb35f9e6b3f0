"""The simulated bus: servos behind a simulated USB adapter (U2D2), served on a pty.

:class:`DynamixelBus` stands on :class:`rig.sim.pty_server.PtyServer` (thread, pty, error
policy, adapter unplug) and adds Protocol 2.0 (:mod:`firmware_protocol.dynamixel`): it decodes
instruction packets, lets the addressed :class:`~rig.sim.dynamixel.servo.SimServo` objects
execute them, and schedules their status packets at the times the wire would deliver them.

Wire time: a reply starts ``instruction bytes × 10 / baud`` after the instruction arrived plus
the servo's Return Delay Time, and occupies ``bytes × 10 / baud``; sync/bulk read replies follow
one another in request order (an absent servo is skipped). A new instruction cancels replies
not yet sent. A half-received packet is abandoned after :data:`PACKET_TIMEOUT` without bytes.
Packets with a bad CRC are ignored — no status, no effect, no watchdog reset (see
``docs/sim.md`` for the evidence).

USB latency (``usb_latency_s`` > 0): the adapter's USB-serial chip (the U2D2's FT232H) holds
the bytes it receives from the servos until its latency timer expires; the host sees them only
then. Modelled as a free-running timer started with the bus: a status packet whose last byte is
on the wire at ``t`` reaches the host at the first timer tick at or after ``t`` (packets that
complete within one period arrive together). A U2D2 on Linux with its latency timer set to
1 ms (``/sys/bus/usb-serial/devices/ttyUSBn/latency_timer``, what the Dynamixel SDK
recommends) is ``usb_latency_s=0.001``, the default of ``sim://dynamixel`` with wire time on.
Host-to-servo bytes are not delayed (a bulk OUT transfer leaves within the USB frame), and a
packet is never split by the chip's 64-byte buffer (every status packet of a few servos is
shorter).
"""

from __future__ import annotations

import math
import random
import time
from collections.abc import Callable, Iterable, Sequence

from firmware_protocol.dynamixel import instructions as ins
from firmware_protocol.dynamixel.control_table import load_control_table
from firmware_protocol.dynamixel.framing import BROADCAST_ID
from firmware_protocol.dynamixel.packets import (
    ErrorCode,
    Instruction,
    InstructionPacket,
    encode_status,
)
from firmware_protocol.dynamixel.protocol1 import InstructionPacket1, MixedStreamDecoder
from firmware_protocol.errors import ChecksumError, ProtocolError
from rig.errors import RigConfigError
from rig.sim.clock import Clock
from rig.sim.dynamixel import protocol1 as proto1
from rig.sim.dynamixel.faults import FaultInjection, Faults
from rig.sim.dynamixel.servo import SimServo
from rig.sim.dynamixel.servo_legacy import LegacyServo, is_legacy_table
from rig.sim.pty_server import PtyServer

__all__ = ["PACKET_TIMEOUT", "DynamixelBus", "latency_timer_tick", "start_servo_bus"]

PACKET_TIMEOUT = 0.02
"""Inter-byte timeout after which a servo abandons a half-received packet, s (modelling
choice: the e-Manual does not publish the firmware's value)."""

_READS = frozenset({Instruction.READ, Instruction.SYNC_READ, Instruction.BULK_READ,
                    Instruction.FAST_SYNC_READ, Instruction.FAST_BULK_READ})
_GROUP_READS = frozenset({Instruction.SYNC_READ, Instruction.FAST_SYNC_READ,
                          Instruction.BULK_READ, Instruction.FAST_BULK_READ})


def latency_timer_tick(t: float, epoch: float, period: float) -> float:
    """When bytes on the wire by ``t`` reach the host through a USB adapter whose latency timer
    (``period`` s, free-running since ``epoch``) sends what it holds at each tick: the first
    tick at or after ``t`` (``t`` itself when ``period`` is 0). A billionth of a period of
    slack keeps a packet that ends on a tick (up to float rounding) on that tick."""
    if period <= 0.0:
        return t
    return epoch + math.ceil((t - epoch) / period - 1e-9) * period


class DynamixelBus(FaultInjection, PtyServer):
    """A bus of simulated servos served on a pseudo-terminal.

    Parameters
    ----------
    servos : sequence of SimServo
        The servos on the bus (distinct IDs).
    clock : callable, default time.monotonic
        Simulated clock in seconds; motion and the Bus Watchdog run on it (a
        :class:`~rig.sim.clock.ManualClock` makes them exact in tests).
    model_wire_time : bool, default True
        Delay replies by the time the bytes take on the wire at the servo's baud rate.
    usb_latency_s : float, default 0
        The USB adapter's latency timer, s (see the module docstring); 0: bytes reach the host
        as soon as they are on the wire.

    Attributes
    ----------
    port : str
        Path of the pty slave to open with ``PortHandler`` / pyserial.
    servos : dict of int to SimServo
        By ID at creation (IDs written later keep their original key).
    instructions_seen, replies_sent, crc_errors : int
        Instruction packets decoded, status packets written, instruction packets ignored for a
        bad CRC.
    packet_timeout : float
        Real seconds without bytes after which a half-received packet is abandoned (default
        :data:`PACKET_TIMEOUT`; a test that floods the bus from a loaded machine may raise it).

    Examples
    --------
    >>> with start_servo_bus([1, 2, 3]) as bus:  # doctest: +SKIP
    ...     port = dynamixel_sdk.PortHandler(bus.port)
    """

    thread_name = "dxl-sim"

    def __init__(self, servos: Sequence[SimServo], *, clock: Clock = time.monotonic,
                 model_wire_time: bool = True, usb_latency_s: float = 0.0):
        ids = [s.id for s in servos]
        if not (math.isfinite(usb_latency_s) and usb_latency_s >= 0.0):
            raise ValueError(f"usb latency must be a finite number >= 0 s, got {usb_latency_s}")
        if not ids:
            raise ValueError("a servo bus needs at least one servo")
        if len(set(ids)) != len(ids):
            raise ValueError(f"servo ids must be distinct, got {ids}")
        self.servos: dict[int, SimServo] = {s.id: s for s in servos}
        self.model_wire_time = model_wire_time
        self.usb_latency_s = float(usb_latency_s)
        self._usb_epoch = time.monotonic()  # the adapter's free-running latency timer
        self._faults = Faults()
        self._decoder = MixedStreamDecoder()  # Protocol 2.0 and 1.0 share the wire
        self._last_rx = 0.0
        self._outbox: list[tuple[float, bytes]] = []
        self.replies_sent = 0
        self.instructions_seen = 0
        self.crc_errors = 0
        self.packet_timeout = PACKET_TIMEOUT
        # the line starts at the servos' rate, as an adapter left configured for them
        super().__init__(clock=clock, line_speed=servos[0].baud_rate)
        now = clock()
        for servo in servos:
            servo.power_on(now)  # a servo created with boot=True starts booting now
        self._start()

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
                 position: float | Callable[[float], float] | None,
                 stiffness: float | None = None, damping: float | None = None) -> None:
        """Move the limb by hand: rigidly (torque off, the shaft follows ``position`` exactly),
        or through an impedance (a person pushing through the spring of their arm).

        Parameters
        ----------
        dxl_id : int
            Servo ID.
        position : float, callable or None
            ACTUAL shaft ticks (the physical world: Present Position is this through Homing
            Offset and Drive Mode); or a function of the simulated time (s) returning them, for a
            continuous
            movement (a clinician sweeping the limb while it records); ``None`` lets go (the
            shaft stays where it is).
        stiffness : float or None
            None (default): the rigid hand above, acting with torque off only. A number,
            N·m/rad: the hand is an impedance acting as a push ``K (θ_hand − θ) − B θ'`` on the
            shaft, torque on or off (:meth:`SimServo.set_hand
            <rig.sim.dynamixel.servo.SimServo.set_hand>`); it keeps holding when torque is
            turned on.
        damping : float or None
            N·m·s/rad, with a stiffness only (None: 0).

        Raises
        ------
        ValueError
            An impedance on a servo without the torque model (Protocol 1.0 / XL-320
            tables), or a stiffness / damping :meth:`SimServo.set_hand` refuses.
        """
        with self.lock:
            servo = self.servo(dxl_id)
            if stiffness is not None and isinstance(servo, LegacyServo):
                raise ValueError(f"servo {dxl_id} ({servo.table.display_name}) has no torque "
                                 f"model: an impedance hand needs an X-series-style servo")
            servo.advance(self.clock())
            servo.set_hand(position, stiffness, damping)

    def push(self, dxl_id: int, torque: float | Callable[[float], float] | None) -> None:
        """Push the shaft with an external torque (a hand or a patient), torque on or off.

        Parameters
        ----------
        dxl_id : int
            Servo ID.
        torque : float, callable or None
            N·m at the output shaft, in the ACTUAL (physical) frame: positive pushes towards
            increasing encoder ticks whatever the servo's Drive Mode; or a function of the
            simulated time (s) returning N·m; ``None`` lets go. See
            :mod:`rig.sim.dynamixel.servo` for the torque model it acts on.
        """
        with self.lock:
            servo = self.servo(dxl_id)
            servo.advance(self.clock())
            servo.push = torque if torque is None or callable(torque) else float(torque)

    def position(self, dxl_id: int) -> float:
        """True (noise-free) shaft position in ACTUAL ticks (the encoder, before Homing Offset
        and Drive Mode), advanced to now (watchdog included)."""
        with self.lock:
            servo = self.servo(dxl_id)
            servo.advance(self.clock())
            return servo.pos

    def watchdog_tripped(self, dxl_id: int) -> bool:
        """True while servo ``dxl_id`` has its Bus Watchdog error flagged (advanced to now)."""
        with self.lock:
            servo = self.servo(dxl_id)
            servo.advance(self.clock())
            return servo.watchdog_error

    def restore_defaults(self) -> None:
        """Every servo back to its state at creation (ID, baud rate, table, position, no
        errors); pending faults and half-received input are forgotten."""
        with self.lock:
            for servo in self.servos.values():
                servo.restore()
            self._faults = Faults()
            self._decoder.clear()
            self._outbox.clear()

    # ------------------------------------------------------------------ server hooks
    def _deadline(self) -> float | None:
        due = self._outbox[0][0] if self._outbox else None
        if self._decoder.pending:  # a partial frame: give up on it after a while
            stale = self._last_rx + self.packet_timeout
            due = stale if due is None else min(due, stale)
        return due

    def _on_timer(self, now: float) -> None:
        if self._decoder.pending and now - self._last_rx >= self.packet_timeout:
            self._decoder.skip_frame()
            self._last_rx = now
            self._drain(now)
        while self._outbox and self._outbox[0][0] <= now:
            _, data = self._outbox.pop(0)
            if data and self.connected:
                self._send(data)
                self.replies_sent += 1

    def _on_bytes(self, data: bytes, t_rx: float) -> None:
        self._last_rx = t_rx
        self._decoder.feed(data)
        self._drain(t_rx)

    def _on_disconnect(self) -> None:
        self._outbox.clear()
        self._decoder.clear()

    def _drain(self, t_rx: float) -> None:
        while True:
            try:
                packet = self._decoder.next_packet()
            except ChecksumError:  # 1.0 checksum too (docs/sim.md)
                self.crc_errors += 1  # a servo cannot trust any field: it stays silent
                continue
            except ProtocolError:
                continue  # framing: resynchronise on the next header
            if packet is None:
                return
            if isinstance(packet, InstructionPacket | InstructionPacket1):
                if self._faults.spoil_instruction():
                    self.crc_errors += 1
                    continue
                self._outbox.clear()  # a new instruction pre-empts unsent replies
                self.instructions_seen += 1
                self._faults.heard(self.instructions_seen, self.clock())
                if isinstance(packet, InstructionPacket1):
                    proto1.dispatch(self, packet, t_rx)
                else:
                    self._dispatch(packet, t_rx)

    # ------------------------------------------------------------------ instruction handling
    def _listeners(self, now: float, protocol: float = 2.0) -> list[SimServo]:
        """Servos that hear the host, speak ``protocol`` (:func:`proto1.speaks`) and are not
        booting at ``now``. A UART hears a host whose rate is within ±3 % of its own (a 1.0
        servo at 57,142 bit/s, a host at 57,600)."""
        if self._faults.cable_out(now):
            return []
        client = self.line_speed
        return [s for s in self.servos.values()
                if s.plugged and proto1.speaks(s) == protocol
                and (client is None or abs(client - s.baud_rate) <= 0.03 * s.baud_rate)
                and s.listening(now)]

    def _schedule(self, servo: SimServo, packet: bytes, start_after: float) -> float:
        """Queue ``packet`` to be sent; returns the time its last byte is on the wire."""
        byte_time = 10.0 / servo.baud_rate if self.model_wire_time else 0.0
        begin = start_after + servo.return_delay
        end = begin + len(packet) * byte_time
        out, extra = self._faults.outgoing(packet)
        if out is not None:
            self._outbox.append((self._usb_delivery(end + extra), out))
            self._outbox.sort(key=lambda e: e[0])
        return end

    def _usb_delivery(self, t: float) -> float:
        return latency_timer_tick(t, self._usb_epoch, self.usb_latency_s)

    def _dispatch(self, pkt: InstructionPacket, t_rx: float) -> None:
        now = self.clock()
        listeners = self._listeners(now)
        if not listeners:
            return
        size = 10 + len(pkt.params)  # header, id, length, instruction, CRC (stuffing ignored)
        wire = size * 10.0 / listeners[0].baud_rate if self.model_wire_time else 0.0
        t = t_rx + wire
        inst = pkt.instruction
        if inst in _GROUP_READS:
            if pkt.id == BROADCAST_ID:
                self._group_read(pkt, listeners, now, t)
            return
        if inst in (Instruction.SYNC_WRITE, Instruction.BULK_WRITE):
            if pkt.id == BROADCAST_ID:
                self._group_write(pkt, listeners, now)
            return
        if pkt.id == BROADCAST_ID:
            targets = {s: True for s in listeners}
        else:  # its ID, or its Secondary ID (executed without a status packet)
            targets = {s: hit[1] for s in listeners if (hit := s.addressed(pkt.id))[0]}
        for servo in targets:
            servo.note_instruction(now)
        for servo in sorted(targets, key=lambda s: s.id):
            # the level in force when the instruction arrived decides (a write that changes
            # Status Return Level is still acknowledged under the old level)
            answer = targets[servo] and (inst == Instruction.PING or (
                pkt.id != BROADCAST_ID and self._srl_allows(servo, inst)))
            error, params, after = self._execute(servo, pkt, now,
                                                 ram_only=not targets[servo])
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

    def _execute(self, servo: SimServo, pkt: InstructionPacket, now: float, *,
                 ram_only: bool = False) -> tuple[int, bytes, Callable[[], None] | None]:
        """Run a unicast/broadcast instruction on one servo: (error, reply params, after);
        ``ram_only``: sent to its Secondary ID (EEPROM refused)."""
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
                return servo.write(address, data, now, ram_only=ram_only), b"", None
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
                return servo.write(address, data, now, ram_only=ram_only), b"", None
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
                return servo.clear_multi_turn(now), b"", None
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
        for dxl_id in {r[0] for r in requests}:
            if dxl_id in by_id:
                by_id[dxl_id].note_instruction(now)
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
        for dxl_id in {w[0] for w in writes}:
            if dxl_id in by_id:
                by_id[dxl_id].note_instruction(now)
        for dxl_id, address, data in writes:
            servo = by_id.get(dxl_id)
            if servo is not None:
                servo.write(address, data, now)



def start_servo_bus(ids: Iterable[int] | Sequence[tuple] = (1,),
                    model: str = "XM430-W350", *, protocol: float | None = None,
                    baud_rate: int = 1_000_000,
                    return_delay_us: int | None = None, noise_ticks: float = 0.0,
                    seed: int = 0, positions: Sequence[float] | None = None,
                    clock: Clock = time.monotonic,
                    model_wire_time: bool = True,
                    usb_latency_ms: float = 0.0, boot: bool = False) -> DynamixelBus:
    """Start a simulated servo bus on a new pty.

    Parameters
    ----------
    ids : iterable of int, or of (id, model) or (id, model, protocol)
        Servo IDs (all of ``model``), or ``(id, model[, protocol])`` for a mixed bus.
    model : str
        e-Manual model name, e.g. ``"XM430-W350"``, ``"XL430-W250"``, ``"XC330-M288"``,
        ``"AX-12A"`` (a Protocol 1.0 servo, :class:`LegacyServo`).
    protocol : float, optional
        1.0: models with a Protocol 1.0 table of their own (MX-28 on 1.0 firmware) get it;
        others (X series) are switched to 1.0 by their Protocol Type item. None: each model's
        factory protocol (AX: 1.0, X series and MX: 2.0).
    baud_rate : int
        Line speed of every servo, bit/s.
    return_delay_us : int or None
        Return Delay Time of every servo in µs; None keeps the default 500 µs.
    noise_ticks : float
        Encoder noise standard deviation, ticks.
    seed : int
        Seed of the encoder noise (servo ``k`` uses ``seed + id``).
    positions : sequence of float, optional
        Initial ACTUAL shaft positions in ticks (default: each model's power-on position,
        2048 on the X series).
    clock : callable
        Simulated clock, seconds.
    model_wire_time : bool
        Model the time bytes take on the wire.
    usb_latency_ms : float
        The USB adapter's latency timer, ms (0: none; see :class:`DynamixelBus`).
    boot : bool
        Power the servos on booting (silent for their boot time) instead of already booted.

    Returns
    -------
    DynamixelBus
        Already serving; use it as a context manager or call ``close()``.

    Raises
    ------
    RigConfigError
        Unknown model, bad ID, duplicate IDs or unsupported baud rate.
    """
    specs = [(i, model, protocol) if isinstance(i, int)
             else (int(i[0]), str(i[1]), i[2] if len(i) > 2 else protocol) for i in ids]
    if not specs:
        raise RigConfigError("a servo bus needs at least one servo id")
    try:
        servos = [make_servo(i, m, protocol=p, baud_rate=baud_rate,
                             return_delay_us=return_delay_us,
                             position=positions[k] if positions is not None else None,
                             noise_ticks=noise_ticks, rng=random.Random(seed + i), boot=boot)
                  for k, (i, m, p) in enumerate(specs)]
        return DynamixelBus(servos, clock=clock, model_wire_time=model_wire_time,
                            usb_latency_s=float(usb_latency_ms) / 1e3)
    except ValueError as err:
        raise RigConfigError(str(err)) from err


def make_servo(dxl_id: int, model: str | int, *, protocol: float | None = None,
               position: float | None = None, **kwargs) -> SimServo:
    """One simulated servo of ``model``: a :class:`LegacyServo` for a Protocol 1.0 or
    angle-limit table (AX, MX on 1.0, XL-320), else a :class:`SimServo`; ``protocol=1.0`` on
    a model without a 1.0 table of its own sets its Protocol Type item to 1. ``position``
    None: mid-range (2048 on the X series). Other keywords go to the servo class.

    Raises
    ------
    ValueError
        Unknown model, bad ID, baud rate not one of the model's.
    """
    table = load_control_table(model, protocol)
    if protocol is not None and float(protocol) == 2.0 and table.protocol == 1.0:
        raise ValueError(f"{table.display_name} speaks only Protocol 1.0")
    if is_legacy_table(table):
        return LegacyServo(dxl_id, table, position=position, **kwargs)
    servo = SimServo(dxl_id, model, position=position, **kwargs)  # None: the table's home
    if protocol is not None and float(protocol) == 1.0:
        if "Protocol Type" not in servo.table:
            raise ValueError(f"{servo.table.display_name} has no Protocol Type item: it "
                             f"cannot speak Protocol 1.0")
        servo.set_item("Protocol Type", 1)
        if hasattr(servo, "_creation"):  # restore() brings the servo back to this state
            servo._creation = (bytes(servo.mem), *servo._creation[1:])
    return servo
