"""Frame mutations for fuzzing the decoders: valid frames, slightly broken.

One mutator for every protocol (:func:`mutate`), used by the test suite's seeded fuzz tests and
by the long fuzz runs in ``benchmarks/fuzz_*.py``. A decoder fed its output must raise only its
:class:`~firmware_protocol.errors.ProtocolError` subclasses, never another exception, and a
streaming decoder must keep making progress.
"""

from __future__ import annotations

import random
from collections.abc import Sequence

__all__ = ["mutate"]


def mutate(frame: bytes, rng: random.Random, *, special: bytes = b"\x00",
           fields: Sequence[tuple[int, int]] = ()) -> bytes:
    """``frame`` with one to three random edits.

    The edits: a bit flipped, a byte replaced, the tail cut off, random bytes inserted, a few
    bytes repeated, one of the protocol's ``special`` bytes (header, delimiter) written over a
    byte or inserted, and, for each ``(offset, size)`` in ``fields`` (e.g. a length field), its
    bytes overwritten.
    """
    buf = bytearray(frame)
    kinds = 7 + bool(fields)
    for _ in range(rng.randint(1, 3)):
        op = rng.randrange(kinds)
        pos = rng.randrange(len(buf)) if buf else 0
        if op == 0 and buf:
            buf[pos] ^= 1 << rng.randrange(8)
        elif op == 1 and buf:
            buf[pos] = rng.randrange(256)
        elif op == 2:
            del buf[pos:]
        elif op == 3:
            buf[pos:pos] = rng.randbytes(rng.randint(1, 8))
        elif op == 4 and buf:
            buf[pos:pos] = buf[pos:pos + rng.randint(1, 4)]
        elif op == 5 and buf:
            buf[pos] = rng.choice(special)
        elif op == 6:
            buf[pos:pos] = bytes([rng.choice(special)])
        elif op == 7:
            offset, size = rng.choice(list(fields))
            for k in range(offset, min(offset + size, len(buf))):
                buf[k] = rng.randrange(256)
    return bytes(buf)
