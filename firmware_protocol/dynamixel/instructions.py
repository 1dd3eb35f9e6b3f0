"""Parameters of each Protocol 2.0 instruction: builders and parsers.

Parameter layouts (little-endian; e-Manual "Instruction Details")::

    PING            (none)                     status: MODEL_L MODEL_H FW_VERSION
    READ            ADDR(2) LEN(2)             status: DATA * LEN
    WRITE           ADDR(2) DATA ...           status: (none)
    REG_WRITE       ADDR(2) DATA ...           status: (none)
    ACTION          (none)
    FACTORY_RESET   OPTION(1)  0xFF all, 0x01 all but ID, 0x02 all but ID and baud rate
    REBOOT          (none)
    CLEAR           0x01 0x44 0x58 0x4C 0x22   (clear multi-turn revolution count)
    SYNC_READ       ADDR(2) LEN(2) ID1 ID2 ...                  (ID 0xFE)
    FAST_SYNC_READ  same as SYNC_READ                           (ID 0xFE)
    SYNC_WRITE      ADDR(2) LEN(2) [ID DATA*LEN] ...            (ID 0xFE)
    BULK_READ       [ID ADDR(2) LEN(2)] ...                     (ID 0xFE)
    FAST_BULK_READ  same as BULK_READ                           (ID 0xFE)
    BULK_WRITE      [ID ADDR(2) LEN(2) DATA*LEN] ...            (ID 0xFE)

Fast sync/bulk read reply: one status packet from ID 0xFE whose parameter region is::

    ERR1 ID1 DATA1 CRC1(2) | ERR2 ID2 DATA2 CRC2(2) | ... | ERRn IDn DATAn | CRC(2)

where each CRCk is the running CRC of the packet up to and including DATAk, so the last one is
the packet's own CRC. The packet's first error byte sits where a normal status has its ERR.
"""

from __future__ import annotations

import struct
from collections.abc import Iterable, Mapping, Sequence

from firmware_protocol.dynamixel.framing import BROADCAST_ID, HEADER, MAX_ID, crc16
from firmware_protocol.dynamixel.packets import (
    STATUS,
    Instruction,
    InstructionPacket,
    StatusPacket,
)
from firmware_protocol.errors import PacketError

CLEAR_MULTI_TURN = bytes((0x01, 0x44, 0x58, 0x4C, 0x22))
"""Parameters of the CLEAR instruction that reset the multi-turn count."""


def _u16(value: int, what: str) -> bytes:
    if not 0 <= value <= 0xFFFF:
        raise ValueError(f"{what} must be 0..65535, got {value}")
    return struct.pack("<H", value)


def _id(value: int) -> int:
    if not 0 <= value <= MAX_ID:
        raise ValueError(f"device id must be 0..{MAX_ID}, got {value}")
    return value


def ping(dxl_id: int = BROADCAST_ID) -> InstructionPacket:
    """PING a device (or all, with the broadcast ID)."""
    return InstructionPacket(dxl_id, Instruction.PING)


def read(dxl_id: int, address: int, length: int) -> InstructionPacket:
    """READ ``length`` bytes from ``address``."""
    return InstructionPacket(dxl_id, Instruction.READ,
                             _u16(address, "address") + _u16(length, "length"))


def write(dxl_id: int, address: int, data: bytes) -> InstructionPacket:
    """WRITE ``data`` at ``address``."""
    return InstructionPacket(dxl_id, Instruction.WRITE, _u16(address, "address") + bytes(data))


def reg_write(dxl_id: int, address: int, data: bytes) -> InstructionPacket:
    """REG_WRITE: register ``data`` at ``address`` until ACTION."""
    return InstructionPacket(dxl_id, Instruction.REG_WRITE,
                             _u16(address, "address") + bytes(data))


def action(dxl_id: int = BROADCAST_ID) -> InstructionPacket:
    """ACTION: execute registered writes."""
    return InstructionPacket(dxl_id, Instruction.ACTION)


def factory_reset(dxl_id: int, option: int = 0xFF) -> InstructionPacket:
    """FACTORY_RESET with ``option`` 0xFF (all), 0x01 (keep ID) or 0x02 (keep ID and baud)."""
    if option not in (0xFF, 0x01, 0x02):
        raise ValueError(f"factory reset option must be 0xFF, 0x01 or 0x02, got 0x{option:02X}")
    return InstructionPacket(dxl_id, Instruction.FACTORY_RESET, bytes((option,)))


def reboot(dxl_id: int) -> InstructionPacket:
    """REBOOT a device (clears its hardware error)."""
    return InstructionPacket(dxl_id, Instruction.REBOOT)


def clear(dxl_id: int, params: bytes = CLEAR_MULTI_TURN) -> InstructionPacket:
    """CLEAR (by default the multi-turn revolution count)."""
    return InstructionPacket(dxl_id, Instruction.CLEAR, bytes(params))


def sync_read(address: int, length: int, ids: Iterable[int], *,
              fast: bool = False) -> InstructionPacket:
    """SYNC_READ (or FAST_SYNC_READ) the same ``address``/``length`` from several devices."""
    params = _u16(address, "address") + _u16(length, "length") + bytes(_id(i) for i in ids)
    inst = Instruction.FAST_SYNC_READ if fast else Instruction.SYNC_READ
    return InstructionPacket(BROADCAST_ID, inst, params)


def sync_write(address: int, length: int, data: Mapping[int, bytes]) -> InstructionPacket:
    """SYNC_WRITE ``length`` bytes at ``address`` on several devices; ``data`` maps id -> bytes."""
    parts = [_u16(address, "address"), _u16(length, "length")]
    for dxl_id, chunk in data.items():
        if len(chunk) != length:
            raise ValueError(f"sync write data for id {dxl_id} has {len(chunk)} bytes, "
                             f"expected {length}")
        parts.append(bytes((_id(dxl_id),)) + bytes(chunk))
    return InstructionPacket(BROADCAST_ID, Instruction.SYNC_WRITE, b"".join(parts))


def bulk_read(requests: Iterable[tuple[int, int, int]], *, fast: bool = False) -> InstructionPacket:
    """BULK_READ (or FAST_BULK_READ): ``requests`` are ``(id, address, length)`` triples."""
    params = b"".join(bytes((_id(i),)) + _u16(a, "address") + _u16(n, "length")
                      for i, a, n in requests)
    inst = Instruction.FAST_BULK_READ if fast else Instruction.BULK_READ
    return InstructionPacket(BROADCAST_ID, inst, params)


def bulk_write(writes: Iterable[tuple[int, int, bytes]]) -> InstructionPacket:
    """BULK_WRITE: ``writes`` are ``(id, address, data)`` triples."""
    params = b"".join(bytes((_id(i),)) + _u16(a, "address") + _u16(len(d), "length") + bytes(d)
                      for i, a, d in writes)
    return InstructionPacket(BROADCAST_ID, Instruction.BULK_WRITE, params)


# --------------------------------------------------------------------------- parsers


def _need(params: bytes, n: int, what: str, exact: bool = False) -> None:
    if (len(params) != n) if exact else (len(params) < n):
        raise PacketError(f"{what}: wrong parameter length", actual=len(params),
                          expected=n if exact else f">= {n}")


def parse_read(params: bytes) -> tuple[int, int]:
    """READ parameters -> ``(address, length)``."""
    _need(params, 4, "READ", exact=True)
    return struct.unpack("<HH", params)


def parse_write(params: bytes) -> tuple[int, bytes]:
    """WRITE / REG_WRITE parameters -> ``(address, data)``; data may be empty."""
    _need(params, 2, "WRITE")
    return params[0] | (params[1] << 8), bytes(params[2:])


def parse_sync_read(params: bytes) -> tuple[int, int, list[int]]:
    """SYNC_READ / FAST_SYNC_READ parameters -> ``(address, length, ids)``."""
    _need(params, 5, "SYNC_READ")
    address, length = struct.unpack_from("<HH", params)
    return address, length, list(params[4:])


def parse_sync_write(params: bytes) -> tuple[int, int, dict[int, bytes]]:
    """SYNC_WRITE parameters -> ``(address, length, {id: data})``."""
    _need(params, 4, "SYNC_WRITE")
    address, length = struct.unpack_from("<HH", params)
    body = params[4:]
    step = length + 1
    if length == 0 or not body or len(body) % step:
        raise PacketError("SYNC_WRITE: data is not a whole number of [ID DATA] blocks",
                          actual=len(body), expected=f"a multiple of {step}")
    return address, length, {body[k]: bytes(body[k + 1:k + step])
                             for k in range(0, len(body), step)}


def parse_bulk_read(params: bytes) -> list[tuple[int, int, int]]:
    """BULK_READ / FAST_BULK_READ parameters -> ``[(id, address, length), ...]``."""
    if not params or len(params) % 5:
        raise PacketError("BULK_READ: parameters are not whole [ID ADDR LEN] blocks",
                          actual=len(params), expected="a multiple of 5")
    return [(params[k], *struct.unpack_from("<HH", params, k + 1))
            for k in range(0, len(params), 5)]


def parse_bulk_write(params: bytes) -> list[tuple[int, int, bytes]]:
    """BULK_WRITE parameters -> ``[(id, address, data), ...]``."""
    out = []
    k = 0
    while k < len(params):
        if len(params) - k < 5:
            raise PacketError("BULK_WRITE: truncated block header", actual=len(params) - k,
                              expected=">= 5")
        dxl_id = params[k]
        address, length = struct.unpack_from("<HH", params, k + 1)
        end = k + 5 + length
        if end > len(params):
            raise PacketError("BULK_WRITE: block data shorter than its length field",
                              actual=len(params) - k - 5, expected=length)
        out.append((dxl_id, address, bytes(params[k + 5:end])))
        k = end
    if not out:
        raise PacketError("BULK_WRITE: no blocks", actual=0, expected=">= 1")
    return out


def parse_ping_status(status: StatusPacket) -> tuple[int, int]:
    """PING status parameters -> ``(model_number, firmware_version)``."""
    _need(status.params, 3, "PING status", exact=True)
    return status.params[0] | (status.params[1] << 8), status.params[2]


def ping_status_params(model_number: int, firmware_version: int) -> bytes:
    """Parameters of a PING status: model number (2 bytes) then firmware version."""
    return _u16(model_number, "model number") + bytes((firmware_version & 0xFF,))


# --------------------------------------------------------------------------- fast reads


def encode_fast_status(entries: Sequence[tuple[int, int, bytes]]) -> bytes:
    """Encode the single status packet that answers FAST_SYNC_READ / FAST_BULK_READ.

    Parameters
    ----------
    entries : sequence of (error, id, data)
        One entry per answering device, in bus order.

    Returns
    -------
    bytes
        The complete packet (ID 0xFE, not byte-stuffed: the SDK does not unstuff fast replies).
    """
    if not entries:
        raise ValueError("a fast read reply needs at least one device")
    length = 1 + sum(len(d) + 4 for _, _, d in entries)
    out = bytearray(HEADER + bytes((BROADCAST_ID, length & 0xFF, length >> 8, STATUS)))
    for error, dxl_id, data in entries:
        out += bytes((error, dxl_id)) + bytes(data)
        crc = crc16(out)
        out += bytes((crc & 0xFF, crc >> 8))
    return bytes(out)


def parse_fast_status(status: StatusPacket,
                      lengths: Sequence[int]) -> list[tuple[int, int, bytes]]:
    """Split a fast-read reply into ``[(error, id, data), ...]``.

    Parameters
    ----------
    status : StatusPacket
        The decoded reply (its ``error`` is the first device's error byte).
    lengths : sequence of int
        Data length of each device, in reply order.
    """
    region = bytes((status.error,)) + status.params
    expected = sum(n + 4 for n in lengths) - 2
    if len(region) != expected:
        raise PacketError("fast read reply has the wrong size", actual=len(region),
                          expected=expected)
    out = []
    k = 0
    for n in lengths:
        out.append((region[k], region[k + 1], region[k + 2:k + 2 + n]))
        k += n + 4
    return out
