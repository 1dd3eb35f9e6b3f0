"""Consistent Overhead Byte Stuffing (Cheshire & Baker, IEEE/ACM ToN 7(2), 1999).

COBS removes every 0x00 from a message so that 0x00 can delimit frames. The message is split at
its zeros into pieces; each piece is sent as a code byte ``len(piece) + 1`` followed by the piece,
and the zero that ended the piece is implied. A piece longer than 253 bytes is sent in blocks of
254 bytes with code 0xFF, which implies *no* zero. Canonical form (the one :func:`encode`
produces, and the one `SPEC.md` requires): when the message ends exactly after a 0xFF block, no
empty trailing block ``01`` is added. Overhead: at most ``1 + len // 254`` bytes.

Examples (from the COBS paper / Wikipedia)::

    00          -> 01 01
    00 00       -> 01 01 01
    11 22 00 33 -> 03 11 22 02 33
    01 .. FE    -> FF 01 .. FE      (254 non-zero bytes)
"""

from __future__ import annotations

from firmware_protocol.errors import FramingError

__all__ = ["decode", "encode", "max_encoded_length"]


def max_encoded_length(n: int) -> int:
    """Longest COBS encoding of an ``n``-byte message (without the 0x00 delimiter)."""
    return n + 1 + n // 254


def encode(data: bytes | bytearray | memoryview) -> bytes:
    """COBS-encode ``data`` (canonical form); the result contains no 0x00 and no delimiter."""
    out = bytearray()
    pieces = bytes(data).split(b"\x00")
    last = len(pieces) - 1
    for i, piece in enumerate(pieces):
        n = len(piece)
        start = 0
        while n - start >= 254:
            out.append(0xFF)
            out += piece[start : start + 254]
            start += 254
        if n - start > 0 or n == 0 or i != last:
            out.append(n - start + 1)
            out += piece[start:]
    return bytes(out)


def decode(data: bytes | bytearray | memoryview) -> bytes:
    """Decode one COBS block sequence (the bytes between two 0x00 delimiters).

    Raises
    ------
    FramingError
        Empty input, a 0x00 inside the input, or a code byte pointing past the end.
    """
    buf = bytes(data)
    n = len(buf)
    if n == 0:
        raise FramingError("empty COBS frame")
    if b"\x00" in buf:
        raise FramingError(f"0x00 inside a COBS frame at offset {buf.index(0)}")
    out = bytearray()
    i = 0
    while i < n:
        code = buf[i]
        end = i + code
        if end > n:
            raise FramingError(
                f"COBS code 0x{code:02X} at offset {i} runs past the end of the {n}-byte frame"
            )
        out += buf[i + 1 : end]
        i = end
        if code != 0xFF and i < n:
            out.append(0)
    return bytes(out)
