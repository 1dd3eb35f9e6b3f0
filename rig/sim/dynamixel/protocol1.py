"""Protocol 1.0 on the simulated bus: which servo speaks what, and the 1.0 instructions.

:class:`~rig.sim.dynamixel.bus.DynamixelBus` decodes both protocols
(:class:`firmware_protocol.dynamixel.protocol1.MixedStreamDecoder`) and hands each 1.0
instruction packet to :func:`dispatch`. Rules (e-Manual "DYNAMIXEL Protocol 1.0",
emanual.robotis.com/docs/en/dxl/protocol1/, and the "Status Return Level" and "Protocol Type"
items of the control-table pages):

* A servo answers only the protocol it speaks (:func:`speaks`): AX and MX on 1.0 firmware
  always 1.0; a servo with a Protocol Type item (X series, MX 2.0: address 13) what it holds,
  1 or 2 — with the same control table, its addresses limited to one byte.
* Broadcast (ID 0xFE): executed by every servo, answered by none (PING included).
* Status Return Level: 0 only PING is answered, 1 PING and READ, 2 everything.
* SYNC_WRITE: no status. BULK_READ (``0x00 [LEN ID ADDR]...``, MX series and X series on
  1.0; an AX ignores it): each servo answers after the status packet of the one before it in
  the request; one that stays silent (absent, an AX) leaves the ones after it waiting, so they
  stay silent too.
* RESET (0x06): every item back to its factory value, ID and baud rate included. REBOOT (0x08).
* Error byte: the instruction's outcome (range 0x08 for out-of-range / read-only / length
  errors, angle limit 0x02, instruction 0x40 for an unknown instruction or an ACTION without a
  REG_WRITE) ORed with the servo's hardware errors (input voltage 0x01, overheating 0x04,
  overload 0x20). A packet with a bad checksum is ignored — no status, no effect — as a 2.0
  packet with a bad CRC (``docs/sim.md`` gives the evidence and why the e-Manual's Checksum
  Error bit 0x10 is not sent: the ID of such a packet cannot be trusted).
* Wire time and Return Delay Time as for 2.0 (:class:`DynamixelBus`).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol

from firmware_protocol.dynamixel import protocol1 as p1
from firmware_protocol.dynamixel.packets import ErrorCode
from firmware_protocol.dynamixel.tables_protocol1 import PROTOCOL1_ONLY
from firmware_protocol.errors import ProtocolError
from rig.sim.dynamixel.servo import SimServo


class DynamixelBus(Protocol):
    """What a 1.0 instruction needs of :class:`rig.sim.dynamixel.bus.DynamixelBus` (which
    imports this module: the bus is described here, not imported)."""

    model_wire_time: bool

    def clock(self) -> float: ...

    def _listeners(self, now: float, protocol: float = 2.0) -> list[SimServo]: ...

    def _schedule(self, servo: SimServo, packet: bytes, start_after: float) -> float: ...

__all__ = ["dispatch", "error1_of", "hardware_bits", "speaks"]

_HW_TO_1 = p1.Error1.INPUT_VOLTAGE | p1.Error1.OVERHEATING | p1.Error1.OVERLOAD
I = p1.Instruction1


def speaks(servo: SimServo) -> float:
    """The protocol ``servo`` answers now: its own (a 1.0 table), else its Protocol Type."""
    own = getattr(servo, "speaks", None)
    if own is not None:
        return float(own)
    if "Protocol Type" in servo.table and servo.get("Protocol Type") == 1:
        return 1.0
    return 2.0


def error1_of(servo: SimServo, code: int) -> int:
    """Protocol 1.0 error bits for a 2.0-style result code of ``servo.read``/``write``."""
    own = getattr(servo, "error1_of", None)
    if own is not None:
        return own(code)
    if code in (ErrorCode.INSTRUCTION, ErrorCode.RESULT_FAIL):
        return p1.Error1.INSTRUCTION
    return p1.Error1.RANGE if code else 0


def hardware_bits(servo: SimServo) -> int:
    """The hardware-error bits every 1.0 status of ``servo`` carries."""
    return servo.hardware_error & _HW_TO_1


def _bulk_read_capable(servo: SimServo) -> bool:
    return servo.table.model_number not in PROTOCOL1_ONLY  # AX: no BULK_READ


def _answers(servo: SimServo, inst: int) -> bool:
    level = servo.get("Status Return Level")
    if inst == I.PING:
        return True
    if inst == I.READ:
        return level >= 1
    return level >= 2


def dispatch(bus: DynamixelBus, pkt: p1.InstructionPacket1, t_rx: float) -> None:
    """Run one 1.0 instruction packet on the servos that hear it and speak 1.0."""
    now = bus.clock()
    listeners = bus._listeners(now, 1.0)
    if not listeners:
        return
    size = 6 + len(pkt.params)
    wire = size * 10.0 / listeners[0].baud_rate if bus.model_wire_time else 0.0
    t = t_rx + wire
    inst = pkt.instruction
    if inst == I.BULK_READ:
        if pkt.id == p1.BROADCAST_ID:
            _bulk_read(bus, pkt, listeners, now, t)
        return
    if inst == I.SYNC_WRITE:
        if pkt.id == p1.BROADCAST_ID:
            _sync_write(pkt, listeners, now)
        return
    targets = listeners if pkt.id == p1.BROADCAST_ID else [s for s in listeners
                                                           if s.id == pkt.id]
    for servo in targets:
        servo.note_instruction(now)
    for servo in targets:
        answer = pkt.id != p1.BROADCAST_ID and _answers(servo, inst)
        error, params, after = _execute(servo, pkt, now)
        if answer:
            status = p1.encode_status(servo.id, error | hardware_bits(servo), params)
            bus._schedule(servo, status, t)
        if after is not None:
            after()


def _execute(servo: SimServo, pkt: p1.InstructionPacket1,
             now: float) -> tuple[int, bytes, Callable[[], None] | None]:
    """(1.0 error bits, status parameters, what to do once the status is queued)."""
    inst = pkt.instruction
    try:
        if inst == I.PING:
            return 0, b"", None
        if inst == I.READ:
            address, length = p1.parse_read(pkt.params)
            code, data = servo.read(address, length, now)
            return error1_of(servo, code), data, None
        if inst == I.WRITE:
            address, data = p1.parse_write(pkt.params)
            return error1_of(servo, servo.write(address, data, now)), b"", None
        if inst == I.REG_WRITE:
            address, data = p1.parse_write(pkt.params)
            if address + len(data) > servo.table.size:
                return p1.Error1.RANGE, b"", None
            servo.registered = (address, data)
            return 0, b"", None
        if inst == I.ACTION:
            if servo.registered is None:
                return p1.Error1.INSTRUCTION, b"", None
            address, data = servo.registered
            servo.registered = None
            return error1_of(servo, servo.write(address, data, now)), b"", None
        if inst == I.REBOOT:
            return 0, b"", servo.reboot
        if inst == I.RESET:
            return 0, b"", lambda: servo.factory_reset(0xFF)
    except ProtocolError:
        return p1.Error1.RANGE, b"", None
    return p1.Error1.INSTRUCTION, b"", None


def _sync_write(pkt: p1.InstructionPacket1, listeners: list, now: float) -> None:
    try:
        address, _, data = p1.parse_sync_write(pkt.params)
    except ProtocolError:
        return
    by_id = {s.id: s for s in listeners}
    for dxl_id, chunk in data.items():
        servo = by_id.get(dxl_id)
        if servo is not None:
            servo.note_instruction(now)
            servo.write(address, chunk, now)


def _bulk_read(bus: DynamixelBus, pkt: p1.InstructionPacket1, listeners: list, now: float,
               t: float) -> None:
    try:
        requests = p1.parse_bulk_read(pkt.params)
    except ProtocolError:
        return
    by_id = {s.id: s for s in listeners}
    for dxl_id, _, _ in requests:
        if dxl_id in by_id:
            by_id[dxl_id].note_instruction(now)
    for dxl_id, address, length in requests:
        servo = by_id.get(dxl_id)
        if servo is None or not _bulk_read_capable(servo) or not _answers(servo, I.READ):
            return  # the ones after it wait for a status packet that never comes
        code, data = servo.read(address, length, now)
        error = error1_of(servo, code) | hardware_bits(servo)
        t = bus._schedule(servo, p1.encode_status(servo.id, error, data), t)
