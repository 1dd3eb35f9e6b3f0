"""ROBOTIS Dynamixel Protocol 1.0: pure encode/decode, no I/O.

Source: e-Manual "DYNAMIXEL Protocol 1.0" (emanual.robotis.com/docs/en/dxl/protocol1/).

Packet layout::

    instruction:  FF FF | ID | LEN | INST | PARAM 1 .. N | CHK
    status:       FF FF | ID | LEN | ERR  | PARAM 1 .. N | CHK

    LEN = N + 2 (INST or ERR, the parameters, CHK)
    CHK = ~(ID + LEN + INST/ERR + PARAM 1 + ... + PARAM N) & 0xFF

No byte stuffing, no reserved byte; an instruction and a status packet look alike on the wire
(only the direction tells them apart). ID 0xFE is the broadcast ID; a status packet never
carries it.

Instructions (e-Manual "Instruction Details")::

    PING 0x01         (none)                                   status: (none)
    READ 0x02         ADDR LEN                                 status: DATA * LEN
    WRITE 0x03        ADDR DATA ...
    REG_WRITE 0x04    ADDR DATA ...
    ACTION 0x05       (none)
    RESET 0x06        (none)         factory reset, ID and baud rate included
    REBOOT 0x08       (none)
    SYNC_WRITE 0x83   ADDR LEN [ID DATA * LEN] ...              (ID 0xFE, no status)
    BULK_READ 0x92    0x00 [LEN ID ADDR] ...                    (ID 0xFE, MX series)

Addresses and lengths are one byte. A BULK_READ is answered by each servo in the order of the
request, each after the status packet of the one before it.

Status error byte (bit 7 unused)::

    bit 0  input voltage   bit 1  angle limit   bit 2  overheating   bit 3  range
    bit 4  checksum        bit 5  overload      bit 6  instruction

Mixed buses: a Protocol 2.0 packet opens with ``FF FF FD 00`` (:mod:`.framing`); a 1.0 packet
with ``FF FF ID LEN``. :class:`MixedStreamDecoder` splits a byte stream that carries both and
yields packets tagged by protocol.
"""

from __future__ import annotations

import enum
from collections.abc import Iterator
from dataclasses import dataclass

from firmware_protocol.dynamixel import packets as p2
from firmware_protocol.dynamixel.framing import HEADER as HEADER2
from firmware_protocol.errors import ChecksumError, FramingError, PacketError

__all__ = [
    "BROADCAST_ID",
    "ERROR_BITS",
    "HEADER",
    "MAX_ID",
    "Checksum1Error",
    "Error1",
    "Instruction1",
    "InstructionPacket1",
    "MixedStreamDecoder",
    "StatusPacket1",
    "bulk_read_params",
    "checksum",
    "decode_instruction",
    "decode_status",
    "encode_instruction",
    "encode_status",
    "error_names",
    "packet_protocol",
    "parse_bulk_read",
    "parse_read",
    "parse_sync_write",
    "parse_write",
    "sync_write_params",
]

HEADER = b"\xff\xff"
"""The two bytes that open every Protocol 1.0 packet."""

BROADCAST_ID = 0xFE
MAX_ID = 0xFD
"""Largest ID a Protocol 1.0 device may have (253)."""


class Instruction1(enum.IntEnum):
    """Protocol 1.0 instruction codes."""

    PING = 0x01
    READ = 0x02
    WRITE = 0x03
    REG_WRITE = 0x04
    ACTION = 0x05
    RESET = 0x06
    REBOOT = 0x08
    SYNC_WRITE = 0x83
    BULK_READ = 0x92


class Error1(enum.IntFlag):
    """Bits of the Protocol 1.0 status error byte."""

    INPUT_VOLTAGE = 0x01
    ANGLE_LIMIT = 0x02
    OVERHEATING = 0x04
    RANGE = 0x08
    CHECKSUM = 0x10
    OVERLOAD = 0x20
    INSTRUCTION = 0x40


ERROR_BITS = {int(e): e.name.lower() for e in Error1}
"""Error byte bit -> name (``"angle_limit"``, ...)."""


def error_names(error: int) -> tuple[str, ...]:
    """Names of the bits set in a status error byte, lowest bit first."""
    return tuple(name for bit, name in ERROR_BITS.items() if error & bit)


class Checksum1Error(ChecksumError):
    """A Protocol 1.0 frame whose checksum does not match; ``packet_id`` is its ID field (which
    a device cannot trust, but the e-Manual's checksum error bit is reported to it)."""

    def __init__(self, received: int, computed: int, packet_id: int):
        self.packet_id = packet_id
        super().__init__(received, computed, what="checksum")


@dataclass(frozen=True, slots=True)
class InstructionPacket1:
    """A decoded Protocol 1.0 instruction packet."""

    id: int
    instruction: int
    params: bytes = b""
    protocol = 1.0

    def encode(self) -> bytes:
        """Bytes on the wire."""
        return encode_instruction(self.id, self.instruction, self.params)


@dataclass(frozen=True, slots=True)
class StatusPacket1:
    """A decoded Protocol 1.0 status packet; ``error`` holds the :class:`Error1` bits."""

    id: int
    error: int = 0
    params: bytes = b""
    protocol = 1.0

    @property
    def ok(self) -> bool:
        """True when no error bit is set."""
        return not self.error

    def encode(self) -> bytes:
        """Bytes on the wire."""
        return encode_status(self.id, self.error, self.params)


def checksum(body: bytes | bytearray | memoryview) -> int:
    """``~(sum of ID, LEN, INST/ERR and parameters) & 0xFF``."""
    return ~sum(body) & 0xFF


def _frame(packet_id: int, first: int, params: bytes) -> bytes:
    if not 0 <= packet_id <= BROADCAST_ID:
        raise ValueError(f"packet id must be 0..254, got {packet_id}")
    if not 0 <= first <= 0xFF:
        raise ValueError(f"instruction / error byte must be 0..255, got {first}")
    length = len(params) + 2
    if length > 0xFF:
        raise ValueError(f"packet too long: length field {length} > 255")
    body = bytes((packet_id, length, first)) + bytes(params)
    return HEADER + body + bytes((checksum(body),))


def encode_instruction(packet_id: int, instruction: int, params: bytes = b"") -> bytes:
    """Encode a Protocol 1.0 instruction packet (ID 0..253 or 0xFE broadcast)."""
    return _frame(packet_id, instruction, params)


def encode_status(packet_id: int, error: int = 0, params: bytes = b"") -> bytes:
    """Encode a Protocol 1.0 status packet (``error``: :class:`Error1` bits, bit 7 clear)."""
    if packet_id > MAX_ID:
        raise ValueError(f"a status packet's id must be 0..{MAX_ID}, got {packet_id}")
    if error & 0x80:
        raise ValueError(f"bit 7 of a Protocol 1.0 error byte is unused, got 0x{error:02X}")
    return _frame(packet_id, error, params)


def _check(data: bytes) -> tuple[int, int, bytes]:
    if len(data) < 6 or data[:2] != HEADER:
        raise FramingError(f"not a Protocol 1.0 packet: {data[:6].hex(' ')}")
    length = data[3]
    if length < 2:
        raise FramingError(f"length field {length} is below the minimum 2")
    if len(data) != 4 + length:
        raise FramingError(f"packet of {len(data)} bytes, its length field says {4 + length}")
    computed = checksum(data[2:-1])
    if data[-1] != computed:
        raise Checksum1Error(data[-1], computed, data[2])
    return data[2], data[4], data[5:-1]


def decode_instruction(data: bytes | bytearray) -> InstructionPacket1:
    """Decode exactly one instruction packet (header to checksum).

    Raises
    ------
    FramingError, Checksum1Error
    """
    packet_id, inst, params = _check(bytes(data))
    return InstructionPacket1(packet_id, inst, params)


def decode_status(data: bytes | bytearray) -> StatusPacket1:
    """Decode exactly one status packet (header to checksum).

    Raises
    ------
    FramingError, Checksum1Error
    """
    packet_id, err, params = _check(bytes(data))
    return StatusPacket1(packet_id, err, params)


# -- parameters ---------------------------------------------------------------------------
def parse_read(params: bytes) -> tuple[int, int]:
    """READ parameters -> ``(address, length)``."""
    if len(params) != 2:
        raise PacketError("READ takes ADDR LEN", actual=len(params), expected=2)
    return params[0], params[1]


def parse_write(params: bytes) -> tuple[int, bytes]:
    """WRITE / REG_WRITE parameters -> ``(address, data)``."""
    if len(params) < 2:
        raise PacketError("WRITE takes ADDR and at least one data byte", actual=len(params),
                          expected=">= 2")
    return params[0], bytes(params[1:])


def sync_write_params(address: int, length: int, data: dict[int, bytes]) -> bytes:
    """SYNC_WRITE parameters: ``ADDR LEN [ID DATA * LEN] ...``."""
    out = bytearray((address, length))
    for dxl_id, chunk in data.items():
        if len(chunk) != length:
            raise ValueError(f"id {dxl_id}: {len(chunk)} data bytes, expected {length}")
        out.append(dxl_id)
        out += chunk
    return bytes(out)


def parse_sync_write(params: bytes) -> tuple[int, int, dict[int, bytes]]:
    """SYNC_WRITE parameters -> ``(address, length, {id: data})``."""
    if len(params) < 2:
        raise PacketError("SYNC_WRITE without ADDR LEN", actual=len(params), expected=">= 2")
    address, length = params[0], params[1]
    rest = params[2:]
    if length == 0 or len(rest) % (length + 1):
        raise PacketError("SYNC_WRITE data is not whole [ID DATA] groups", actual=len(rest),
                          expected=f"a multiple of {length + 1}")
    step = length + 1
    return address, length, {rest[k]: bytes(rest[k + 1:k + step])
                             for k in range(0, len(rest), step)}


def bulk_read_params(requests: list[tuple[int, int, int]]) -> bytes:
    """BULK_READ parameters from ``[(id, address, length)]``: ``0x00 [LEN ID ADDR] ...``."""
    out = bytearray((0,))
    for dxl_id, address, length in requests:
        out += bytes((length, dxl_id, address))
    return bytes(out)


def parse_bulk_read(params: bytes) -> list[tuple[int, int, int]]:
    """BULK_READ parameters -> ``[(id, address, length)]`` in request order."""
    if not params or params[0] != 0 or (len(params) - 1) % 3:
        raise PacketError("BULK_READ takes 0x00 then [LEN ID ADDR] groups",
                          actual=params[:1].hex(), expected="00 + 3*k bytes")
    return [(params[k + 1], params[k + 2], params[k]) for k in range(1, len(params), 3)]


# -- a stream that carries both protocols ------------------------------------------------
class MixedStreamDecoder(p2.ByteBuffer):
    """Incremental decoder of a bus on which Protocol 1.0 and 2.0 packets share the wire.

    Yields :class:`~firmware_protocol.dynamixel.packets.InstructionPacket` /
    ``StatusPacket`` for 2.0 frames (``FF FF FD 00``) and :class:`InstructionPacket1` /
    :class:`StatusPacket1` for 1.0 frames (``FF FF ID LEN``, ID <= 0xFE, LEN >= 2); each has a
    ``protocol`` (1.0, or 2.0 for those of :mod:`.packets`, read with
    :func:`packet_protocol`). Garbage before a header is dropped. A bad frame raises once
    (:class:`ChecksumError` — :class:`Checksum1Error` for 1.0, with its ID —, or
    :class:`FramingError`) after its header is discarded, so the next call resynchronises.

    Parameters
    ----------
    direction : {"instruction", "status"}
        What 1.0 frames are (a servo hears instructions, a host statuses); 2.0 frames say
        what they are themselves.
    max_length : int
        Largest 2.0 LEN field accepted.
    """

    def __init__(self, direction: str = "instruction", max_length: int = p2.MAX_LENGTH):
        if direction not in ("instruction", "status"):
            raise ValueError(f"direction must be 'instruction' or 'status', got {direction!r}")
        super().__init__()
        self.direction = direction
        self._v2 = p2.StreamDecoder(max_length)

    def _discard(self, n: int) -> None:
        del self._buf[:n]
        self.dropped += n

    def skip_frame(self) -> None:
        """Give up on the incomplete frame at the front (after an inter-byte timeout)."""
        start = self._buf.find(HEADER)
        self._discard(len(self._buf) if start < 0 else start + 2)

    def next_packet(self):
        """The next complete packet, or None when more bytes are needed.

        Raises
        ------
        FramingError, ChecksumError, PacketError
            The frame at the front was bad; it has been discarded.
        """
        buf = self._buf
        while True:
            start = buf.find(HEADER)
            if start < 0:
                self._discard(len(buf) - (1 if buf[-1:] == b"\xff" else 0))
                return None
            if start:
                self._discard(start)
            if len(buf) < 4:
                return None
            if buf[:4] == HEADER2:
                return self._next_v2()
            if buf[2] == 0xFF:  # FF FF FF ...: the header may start one byte later
                self._discard(1)
                continue
            # FF FF FD xx with xx != 00 is a 1.0 packet to ID 0xFD (253 is a valid 1.0 ID)
            length = buf[3]
            if length < 2:
                self._discard(2)
                raise FramingError(f"Protocol 1.0 length field {length} is below 2")
            total = 4 + length
            if len(buf) < total:
                return None
            frame = bytes(buf[:total])
            computed = checksum(frame[2:-1])
            if frame[-1] != computed:
                self._discard(2)
                raise Checksum1Error(frame[-1], computed, frame[2])
            del buf[:total]
            if self.direction == "instruction":
                return InstructionPacket1(frame[2], frame[4], frame[5:-1])
            return StatusPacket1(frame[2], frame[4], frame[5:-1])

    def _next_v2(self):
        buf = self._buf
        try:
            total = p2._check_frame(buf, 0, self._v2.max_length)
        except (FramingError, ChecksumError):
            self._discard(3)
            raise
        if total is None:
            return None
        data = bytes(buf[:total])
        del buf[:total]
        return p2._parse_checked(data)

    def __iter__(self) -> Iterator:
        """Yield packets until more bytes are needed; bad frames raise as in next_packet."""
        while (packet := self.next_packet()) is not None:
            yield packet


def packet_protocol(packet: object) -> float:
    """1.0 for the packets of this module, 2.0 for those of :mod:`.packets`."""
    return getattr(packet, "protocol", 2.0)

