"""Fuzz the Protocol 2.0 decoder with random and mutated frames.

Feeds ``--frames`` inputs (default 1 000 000; half random bytes, half valid frames with bit
flips, truncations, insertions and header-like bytes) to :func:`decode_packet` and, as one long
stream in random-sized chunks, to :class:`StreamDecoder`. Prints how often each outcome
occurred and the rate. Exits non-zero if any exception other than a
``firmware_protocol.errors.ProtocolError`` subclass escapes, or if the stream decoder ever makes
a call that neither consumes input nor returns (which is how a hang would begin).

Run: ``python benchmarks/fuzz_dynamixel.py [--frames N] [--seed S]``.
"""

from __future__ import annotations

import argparse
import collections
import random
import sys
import time

import common  # noqa: F401  (first: one BLAS thread, this checkout on sys.path)

from firmware_protocol import fuzzing
from firmware_protocol.dynamixel import (
    StreamDecoder,
    decode_packet,
    encode_instruction,
    encode_status,
)
from firmware_protocol.errors import ProtocolError

INSTRUCTIONS = (0x01, 0x02, 0x03, 0x04, 0x05, 0x06, 0x08, 0x10, 0x82, 0x83, 0x8A, 0x92, 0x93,
                0x9A)


def valid_frame(rng: random.Random) -> bytes:
    params = rng.randbytes(rng.choice((0, 1, 2, 4, 6, 10, 30)))
    if rng.random() < 0.2:  # make stuffing happen
        params += b"\xff\xff\xfd" + rng.randbytes(2)
    if rng.random() < 0.5:
        return encode_status(rng.randrange(254), rng.randrange(256), params)
    return encode_instruction(rng.randrange(256), rng.choice(INSTRUCTIONS), params)


def mutate(frame: bytes, rng: random.Random) -> bytes:
    """:func:`firmware_protocol.fuzzing.mutate` with Protocol 2.0's header bytes and its length
    field (bytes 5-6)."""
    return fuzzing.mutate(frame, rng, special=b"\xff\xfd\x00", fields=((5, 2),))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=1_000_000)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    rng = random.Random(args.seed)
    outcomes: collections.Counter[str] = collections.Counter()
    stream_outcomes: collections.Counter[str] = collections.Counter()
    escaped: list[str] = []
    decoder = StreamDecoder()
    pending: list[bytes] = []
    t0, cpu0 = time.perf_counter(), time.process_time()
    for k in range(args.frames):
        data = rng.randbytes(rng.randrange(48)) if k % 2 else mutate(valid_frame(rng), rng)
        if k % 7 == 0:  # now and then an intact frame
            data = valid_frame(rng)
        try:
            decode_packet(data)
            outcomes["decoded"] += 1
        except ProtocolError as err:
            outcomes[type(err).__name__] += 1
        except Exception as err:
            escaped.append(f"decode_packet({data.hex()}): {type(err).__name__}: {err}")
        pending.append(data)
        if len(pending) >= 16:
            blob = b"".join(pending)
            pending.clear()
            pos = 0
            while pos < len(blob):
                step = rng.randint(1, 64)
                decoder.feed(blob[pos:pos + step])
                pos += step
                while True:
                    before = decoder.pending
                    try:
                        packet = decoder.next_packet()
                    except ProtocolError as err:
                        stream_outcomes[type(err).__name__] += 1
                        if decoder.pending >= before:
                            escaped.append("stream decoder raised without consuming input")
                        continue
                    except Exception as err:
                        escaped.append(f"StreamDecoder: {type(err).__name__}: {err}")
                        decoder.clear()
                        break
                    if packet is None:
                        if decoder.pending > before:
                            escaped.append("stream decoder grew its buffer without input")
                        break
                    stream_outcomes["decoded"] += 1
        if len(escaped) > 20:
            break
    elapsed, cpu = time.perf_counter() - t0, time.process_time() - cpu0
    total = sum(outcomes.values()) + len(escaped)
    print(f"decode_packet: {total} frames in {elapsed:.1f} s wall, {cpu:.1f} s CPU "
          f"({total / cpu:,.0f} frames per CPU-second; generation and stream decoding of the "
          f"same bytes included)")
    for name, count in outcomes.most_common():
        print(f"  {name:<14} {count:>9}")
    print("StreamDecoder over the same bytes (random chunking):")
    for name, count in stream_outcomes.most_common():
        print(f"  {name:<14} {count:>9}")
    print(f"  bytes dropped as garbage: {decoder.dropped}")
    if escaped:
        print(f"FAIL: {len(escaped)} unexpected outcomes, e.g.:")
        for line in escaped[:10]:
            print("  " + line)
        return 1
    print("OK: only ProtocolError subclasses escaped; every decoder call made progress")
    return 0


if __name__ == "__main__":
    sys.exit(main())
