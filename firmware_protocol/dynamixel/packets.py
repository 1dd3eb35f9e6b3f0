"""Dynamixel Protocol 2.0 instruction and status packets, and a streaming decoder.

Packet layout (see :mod:`.framing` for stuffing and CRC)::

    instruction:  FF FF FD 00 | ID | LEN_L LEN_H | INST | PARAM ...          | CRC_L CRC_H
    status:       FF FF FD 00 | ID | LEN_L LEN_H | 0x55 | ERR | PARAM ...    | CRC_L CRC_H

Status error byte (ERR)::

    bit 7      alert: the device has a hardware error (see its Hardware Error Status item).
               Not a failure of *this* instruction: it still ran.
    bits 0-6   result: 0 ok, 1 result fail, 2 instruction error, 3 CRC error, 4 data range,
               5 data length, 6 data limit, 7 access error

The decoder checks the header, the length and then the CRC *before* reading any other field.
"""

from __future__ import annotations

import enum
from collections.abc import Iterator
from dataclasses import dataclass

from firmware_protocol.dynamixel.framing import HEADER, crc16, frame, unstuff
from firmware_protocol.errors import ChecksumError, FramingError, PacketError

STATUS = 0x55
"""Instruction byte of a status packet."""

MAX_LENGTH = 0x0400 * 4
"""Largest LEN field the decoder accepts; longer frames are treated as framing errors
(the SDK's own receive buffer is 1024 bytes)."""


class Instruction(enum.IntEnum):
    """Protocol 2.0 instruction codes (e-Manual, "Instruction")."""

    PING = 0x01
    READ = 0x02
    WRITE = 0x03
    REG_WRITE = 0x04
    ACTION = 0x05
    FACTORY_RESET = 0x06
    REBOOT = 0x08
    CLEAR = 0x10
    STATUS = 0x55
    SYNC_READ = 0x82
    SYNC_WRITE = 0x83
    FAST_SYNC_READ = 0x8A
    BULK_READ = 0x92
    BULK_WRITE = 0x93
    FAST_BULK_READ = 0x9A


class ErrorCode(enum.IntEnum):
    """Low 7 bits of a status packet's error byte."""

    NONE = 0
    RESULT_FAIL = 1
    INSTRUCTION = 2
    CRC = 3
    DATA_RANGE = 4
    DATA_LENGTH = 5
    DATA_LIMIT = 6
    ACCESS = 7


ALERT = 0x80
"""Alert bit of the status error byte."""


@dataclass(frozen=True, slots=True)
class InstructionPacket:
    """A decoded (unstuffed) instruction packet.

    Attributes
    ----------
    id : int
        Target device ID (0xFE broadcast).
    instruction : int
        Instruction code; a plain ``int`` so unknown codes survive decoding.
    params : bytes
        Parameters, unstuffed.
    """

    id: int
    instruction: int
    params: bytes = b""

    def encode(self) -> bytes:
        """Bytes on the wire, with stuffing and CRC."""
        return encode_instruction(self.id, self.instruction, self.params)


@dataclass(frozen=True, slots=True)
class StatusPacket:
    """A decoded (unstuffed) status packet.

    Attributes
    ----------
    id : int
        ID of the answering device (0xFE for fast sync/bulk read replies).
    error : int
        Raw error byte: alert bit 7, result code in bits 0-6.
    params : bytes
        Parameters after the error byte.
    """

    id: int
    error: int = 0
    params: bytes = b""

    @property
    def alert(self) -> bool:
        """True when the device reports a hardware error (the instruction still ran)."""
        return bool(self.error & ALERT)

    @property
    def error_code(self) -> ErrorCode | int:
        """Result code (bits 0-6); an :class:`ErrorCode` when it is a known one."""
        code = self.error & 0x7F
        try:
            return ErrorCode(code)
        except ValueError:
            return code

    @property
    def ok(self) -> bool:
        """True when the result code is 0 (the alert bit is ignored)."""
        return not self.error & 0x7F

    def encode(self, *, stuffing: bool = True) -> bytes:
        """Bytes on the wire, with stuffing and CRC."""
        return encode_status(self.id, self.error, self.params, stuffing=stuffing)


Packet = InstructionPacket | StatusPacket


def encode_instruction(packet_id: int, instruction: int, params: bytes = b"") -> bytes:
    """Encode an instruction packet.

    Parameters
    ----------
    packet_id : int
        Target ID, 0..252 or 0xFE broadcast.
    instruction : int
        Instruction code (:class:`Instruction`).
    params : bytes
        Parameters, unstuffed.

    Returns
    -------
    bytes
        The complete packet.
    """
    if not 0 <= instruction <= 0xFF:
        raise ValueError(f"instruction must be 0..255, got {instruction}")
    return frame(packet_id, bytes((instruction,)) + bytes(params))


def encode_status(packet_id: int, error: int = 0, params: bytes = b"", *,
                  stuffing: bool = True) -> bytes:
    """Encode a status packet.

    Parameters
    ----------
    packet_id : int
        ID of the answering device.
    error : int
        Error byte (alert bit 7 | result code).
    params : bytes
        Parameters after the error byte, unstuffed.
    stuffing : bool, default True
        Apply byte stuffing.

    Returns
    -------
    bytes
        The complete packet.
    """
    if not 0 <= error <= 0xFF:
        raise ValueError(f"error byte must be 0..255, got {error}")
    return frame(packet_id, bytes((STATUS, error)) + bytes(params), stuffing=stuffing)


def _check_frame(buf: bytes | bytearray, start: int, max_length: int) -> int | None:
    """Validate the frame at ``buf[start:]``; return its total size or None if incomplete."""
    if len(buf) - start < 7:
        return None
    length = buf[start + 5] | (buf[start + 6] << 8)
    if length < 3:
        raise FramingError(f"length field {length} is below the minimum 3 (INST + CRC)")
    if length > max_length:
        raise FramingError(f"length field {length} exceeds the maximum {max_length}")
    total = 7 + length
    if len(buf) - start < total:
        return None
    end = start + total
    received = buf[end - 2] | (buf[end - 1] << 8)
    computed = crc16(memoryview(buf)[start:end - 2])
    if received != computed:
        raise ChecksumError(received, computed)
    return total


def _parse_checked(data: bytes) -> Packet:
    """Build a packet from a frame whose header, length and CRC are already verified."""
    region = unstuff(bytes(data[7:-2]))
    packet_id = data[4]
    instruction = region[0]
    if instruction == STATUS:
        if len(region) < 2:
            raise PacketError("status packet without an error byte", actual=len(region) - 1,
                              expected=">= 1 parameter")
        return StatusPacket(packet_id, region[1], region[2:])
    return InstructionPacket(packet_id, instruction, region[1:])


def decode_packet(data: bytes | bytearray, *, max_length: int = MAX_LENGTH) -> Packet:
    """Decode exactly one complete packet.

    Parameters
    ----------
    data : bytes-like
        One packet, from its header to its CRC, nothing before or after.
    max_length : int
        Largest LEN field accepted.

    Returns
    -------
    InstructionPacket or StatusPacket

    Raises
    ------
    FramingError
        Bad header, length field, truncated or trailing bytes.
    ChecksumError
        CRC mismatch.
    PacketError
        A status packet without its error byte.
    """
    data = bytes(data)
    if data[:4] != HEADER:
        raise FramingError(f"bad header {data[:4].hex(' ')}, expected {HEADER.hex(' ')}")
    total = _check_frame(data, 0, max_length)
    if total is None:
        raise FramingError(f"truncated packet: {len(data)} bytes")
    if total != len(data):
        raise FramingError(f"{len(data) - total} trailing bytes after the packet")
    return _parse_checked(data)


class ByteBuffer:
    """The received bytes an incremental decoder holds (:class:`StreamDecoder`, and the mixed
    1.0/2.0 decoder of :mod:`firmware_protocol.dynamixel.protocol1`).

    Attributes
    ----------
    dropped : int
        Number of bytes discarded so far as garbage or as parts of bad frames.
    """

    def __init__(self) -> None:
        self._buf = bytearray()
        self.dropped = 0

    def feed(self, data: bytes | bytearray | memoryview) -> None:
        """Append received bytes."""
        self._buf += data

    @property
    def pending(self) -> int:
        """Number of buffered bytes not yet decoded."""
        return len(self._buf)

    def clear(self) -> None:
        """Forget buffered bytes (e.g. after a port flush)."""
        self.dropped += len(self._buf)
        self._buf.clear()


class StreamDecoder(ByteBuffer):
    """Incremental decoder for a byte stream (a serial port in either direction).

    Feed it bytes as they arrive; take packets out with :meth:`next_packet` or by iterating.
    Leading garbage is dropped up to the next header. A bad frame raises once (framing or
    checksum error) after its header has been discarded, so the next call resynchronises on
    whatever follows. Only :mod:`firmware_protocol.errors` types are raised, and every call
    consumes input or returns, so it cannot hang.

    Parameters
    ----------
    max_length : int
        Largest LEN field accepted; longer headers are taken as corruption.

    Attributes
    ----------
    dropped : int
        Number of bytes discarded so far as garbage or as parts of bad frames.
    """

    def __init__(self, max_length: int = MAX_LENGTH):
        super().__init__()
        self.max_length = max_length

    def skip_frame(self) -> None:
        """Give up on the incomplete frame at the front and resynchronise on the next header.

        A receiver calls this after an inter-byte timeout: a corrupted length field would
        otherwise make it wait for bytes that never come.
        """
        start = self._buf.find(HEADER)
        self._discard(len(self._buf) if start < 0 else start + 3)

    def _discard(self, n: int) -> None:
        del self._buf[:n]
        self.dropped += n

    def next_packet(self) -> Packet | None:
        """Decode the next complete packet, or return None when more bytes are needed.

        Raises
        ------
        FramingError, ChecksumError, PacketError
            The frame at the front of the buffer is bad; it has been discarded.
        """
        buf = self._buf
        start = buf.find(HEADER)
        if start < 0:
            # keep a possible partial header at the end
            keep = 0
            for k in (3, 2, 1):
                if len(buf) >= k and buf[-k:] == HEADER[:k]:
                    keep = k
                    break
            self._discard(len(buf) - keep)
            return None
        if start:
            self._discard(start)
        try:
            total = _check_frame(buf, 0, self.max_length)
        except (FramingError, ChecksumError):
            self._discard(3)  # drop the header, resync on what follows
            raise
        if total is None:
            return None
        data = bytes(buf[:total])
        del buf[:total]
        return _parse_checked(data)

    def __iter__(self) -> Iterator[Packet]:
        """Yield packets until more bytes are needed; bad frames raise as in next_packet."""
        while (packet := self.next_packet()) is not None:
            yield packet
