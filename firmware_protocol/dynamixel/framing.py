"""Dynamixel Protocol 2.0 framing: header, byte stuffing and CRC-16.

Packet layout (ROBOTIS e-Manual, "DYNAMIXEL Protocol 2.0")::

    +------+------+------+------+----+-------+-------+-------+---------------+-------+-------+
    | 0xFF | 0xFF | 0xFD | 0x00 | ID | LEN_L | LEN_H | INST  | PARAM 1 .. N  | CRC_L | CRC_H |
    +------+------+------+------+----+-------+-------+-------+---------------+-------+-------+
     header (3 bytes) + reserved     length = len(INST + PARAMs after stuffing) + 2 (CRC)

* A status packet is an instruction packet with ``INST = 0x55`` whose first parameter is the
  error byte.
* **Byte stuffing**: in the INST + PARAM region, every ``FF FF FD`` is sent as ``FF FF FD FD`` so
  that the header never appears inside a packet. LEN counts the stuffed bytes.
* **CRC-16**: polynomial 0x8005 (x^16 + x^15 + x^2 + 1), initial value 0, no reflection, no final
  XOR ("CRC-16/BUYPASS"), computed over every byte from the first 0xFF up to the last parameter
  *after* stuffing, sent little-endian. The table is generated here rather than retyped and is
  bit-for-bit the ``crc_table`` of ``dynamixel_sdk.Protocol2PacketHandler.updateCRC``.
"""

from __future__ import annotations

HEADER = b"\xff\xff\xfd\x00"
"""Header plus reserved byte that opens every Protocol 2.0 packet."""

BROADCAST_ID = 0xFE
"""ID addressing every device; devices never answer broadcasts except ping and reads."""

MAX_ID = 0xFC
"""Largest ID a device may have (252)."""

_STUFF_FROM = b"\xff\xff\xfd"
_STUFF_TO = b"\xff\xff\xfd\xfd"

CRC_POLY = 0x8005


def _make_table(poly: int = CRC_POLY) -> tuple[int, ...]:
    table = []
    for i in range(256):
        crc = i << 8
        for _ in range(8):
            crc = ((crc << 1) ^ poly) if crc & 0x8000 else (crc << 1)
        table.append(crc & 0xFFFF)
    return tuple(table)


CRC_TABLE: tuple[int, ...] = _make_table()


def crc16(data: bytes | bytearray | memoryview, crc: int = 0) -> int:
    """CRC-16 of ``data`` as Protocol 2.0 computes it.

    Parameters
    ----------
    data : bytes-like
        Bytes from the header's first 0xFF to the end of the (stuffed) parameters.
    crc : int, default 0
        Running value, to continue a CRC over several chunks.

    Returns
    -------
    int
        16-bit CRC; sent on the wire low byte first.
    """
    table = CRC_TABLE
    for byte in data:
        crc = ((crc << 8) ^ table[((crc >> 8) ^ byte) & 0xFF]) & 0xFFFF
    return crc


def stuff(region: bytes) -> bytes:
    """Insert stuffing: every ``FF FF FD`` in ``region`` becomes ``FF FF FD FD``.

    ``region`` is the INST + PARAM part of a packet. Occurrences cannot overlap (0xFD is not
    0xFF), so a plain replace matches the SDK's byte-by-byte scan.
    """
    return region.replace(_STUFF_FROM, _STUFF_TO) if _STUFF_FROM in region else region


def unstuff(region: bytes) -> bytes:
    """Remove stuffing: every ``FF FF FD FD`` in ``region`` becomes ``FF FF FD``.

    Lenient like the SDK: an unstuffed ``FF FF FD`` (as some devices send in fast-read replies)
    is left as it is.
    """
    return region.replace(_STUFF_TO, _STUFF_FROM) if _STUFF_TO in region else region


def frame(packet_id: int, region: bytes, *, stuffing: bool = True) -> bytes:
    """Wrap an INST + PARAM region into a complete packet (header, ID, length, CRC).

    Parameters
    ----------
    packet_id : int
        Device ID, 0..253, or :data:`BROADCAST_ID`.
    region : bytes
        Instruction byte followed by the parameters, not yet stuffed.
    stuffing : bool, default True
        Apply byte stuffing (off only to imitate devices that do not stuff).

    Returns
    -------
    bytes
        The packet as sent on the wire.
    """
    if not 0 <= packet_id <= 0xFF:
        raise ValueError(f"packet id must be 0..255, got {packet_id}")
    body = stuff(region) if stuffing else region
    length = len(body) + 2
    if length > 0xFFFF:
        raise ValueError(f"packet too long: length field {length} > 65535")
    head = HEADER + bytes((packet_id, length & 0xFF, length >> 8))
    crc = crc16(body, crc16(head))
    return head + body + bytes((crc & 0xFF, crc >> 8))
