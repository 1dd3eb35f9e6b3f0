"""Fuzz the IMU parsers with random and mutated frames; print counts and rates.

For each parser — BNO055 request decoder (chip side), BNO055 response decoder (host side), rig
stream decoder — feeds ``--frames`` inputs (default 1 000 000) through the streaming decoder in
random-sized pieces and through the one-shot decoder. The inputs are valid frames with random
mutations (bit flips, byte replacements, truncation, inserted garbage, duplicated bytes, stray
delimiters) and random byte strings; for the stream protocol a third are mutants whose CRC is
recomputed, so that the field checks behind the CRC are exercised too. It proves that

* only :class:`firmware_protocol.errors.ProtocolError` subclasses escape (anything else is
  printed and the script exits with status 1), and
* nothing hangs: every ``next()`` call consumes input or reports that it needs more, so the
  calls per chunk are bounded by the bytes in it (checked), and the slowest chunk is reported.

Usage: ``python benchmarks/fuzz_imu.py [--frames N] [--seed S]``. Figures are printed, never
asserted as timings.
"""

from __future__ import annotations

import argparse
import random
import sys
import time
from collections import Counter
from collections.abc import Callable

import common  # noqa: F401  (first: one BLAS thread, this checkout on sys.path)

from firmware_protocol.errors import ProtocolError
from firmware_protocol.fuzzing import mutate
from firmware_protocol.imu import bno055 as B
from firmware_protocol.imu import cobs
from firmware_protocol.imu import stream as S

CHUNK_FRAMES = 500  # inputs concatenated per streaming chunk


def _valid_bno055_requests(rng: random.Random, n: int) -> list[bytes]:
    out = []
    for _ in range(n):
        reg = rng.randrange(256)
        if rng.random() < 0.5:
            out.append(B.encode_read(reg, rng.randint(1, 128)))
        else:
            out.append(B.encode_write(reg, rng.randbytes(rng.randint(1, 24))))
    return out


def _valid_bno055_responses(rng: random.Random, n: int) -> list[bytes]:
    out = []
    for _ in range(n):
        if rng.random() < 0.5:
            out.append(B.encode_status(rng.randint(1, 10)))
        else:
            out.append(B.encode_read_response(rng.randbytes(rng.randint(1, 24))))
    return out


def _valid_stream_frames(rng: random.Random, n: int) -> list[bytes]:
    out = []
    for _ in range(n):
        kind = rng.random()
        seq = rng.randrange(1 << 16)
        if kind < 0.6:
            ids = sorted(rng.sample(range(16), rng.randint(0, 16)))
            readings = [(i, rng.randrange(256), rng.randrange(4),
                         [rng.uniform(-1, 1) for _ in range(4)]) for i in ids]
            out.append(S.encode_sample(seq, rng.randrange(1 << 32), readings))
        elif kind < 0.75:
            out.append(S.encode_ack(seq, rng.randrange(1 << 16), rng.choice(list(S.CommandType)),
                                    rng.randbytes(rng.choice((0, 20)))))
        elif kind < 0.85:
            out.append(S.encode_nak(seq, rng.randrange(1 << 16), 0x83, rng.randint(1, 6)))
        else:
            cmd = rng.choice(list(S.CommandType))
            value = rng.randrange(1 << 16) if cmd in (S.CommandType.SET_RATE,
                                                      S.CommandType.SET_SENSORS) else None
            out.append(S.encode_command(seq, cmd, value))
    return out


def _recrc(rng: random.Random, wire: bytes) -> bytes:
    """Mutate a stream frame's body, then fix its CRC: reaches the field checks behind it."""
    body = bytearray(cobs.decode(wire[:-1]))
    payload = mutate(bytes(body[1:-4]), rng)
    body = bytearray([body[0] if rng.random() < 0.9 else rng.randrange(256)]) + payload
    body += S.crc32(body).to_bytes(4, "little")
    return cobs.encode(bytes(body)) + b"\x00"


def _inputs(rng: random.Random, pool: list[bytes], n: int, deep: Callable | None = None):
    """n inputs: mutated valid frames, random byte strings and (``deep``) CRC-fixed mutants."""
    kinds = 3 if deep is not None else 2
    for k in range(n):
        kind = k % kinds
        if kind == 0:
            yield mutate(rng.choice(pool), rng)
        elif kind == 1:
            yield rng.randbytes(rng.randint(1, 80))
        else:
            yield deep(rng, rng.choice(pool))


def _drain(dec, stats: Counter, budget: int) -> None:
    calls = 0
    while True:
        calls += 1
        if calls > budget:
            raise AssertionError(f"decoder made no progress after {budget} calls")
        try:
            item = dec.next()
        except ProtocolError as err:
            stats[type(err).__name__] += 1
            continue
        if item is None:
            return
        stats[type(item).__name__] += 1


def fuzz(name: str, decoder_factory: Callable, one_shot: Callable, pool: list[bytes], n: int,
         rng: random.Random, deep: Callable | None = None) -> bool:
    """Fuzz one parser; print its figures; return False if a non-protocol error escaped."""
    stats: Counter = Counter()
    shot: Counter = Counter()
    dec = decoder_factory()
    fed = nbytes = 0
    slowest = 0.0
    ok = True
    t0 = time.perf_counter()
    try:
        batch: list[bytes] = []
        for data in _inputs(rng, pool, n, deep):
            batch.append(data)
            try:
                one_shot(data)
                shot["ok"] += 1
            except ProtocolError as err:
                shot[type(err).__name__] += 1
            if len(batch) == CHUNK_FRAMES:
                fed += len(batch)
                blob = b"".join(batch)
                nbytes += len(blob)
                batch.clear()
                c0 = time.perf_counter()
                pos = 0
                while pos < len(blob):  # random-sized pieces: partial input everywhere
                    step = rng.randint(1, 300)
                    dec.feed(blob[pos:pos + step])
                    _drain(dec, stats, budget=step + 64)
                    pos += step
                slowest = max(slowest, time.perf_counter() - c0)
        if batch:
            fed += len(batch)
            blob = b"".join(batch)
            nbytes += len(blob)
            dec.feed(blob)
            _drain(dec, stats, budget=len(blob) + 64)
    except Exception as err:  # anything but ProtocolError is a bug
        ok = False
        print(f"  !! {name}: {type(err).__name__} escaped: {err!r}", file=sys.stderr)
    dt = time.perf_counter() - t0
    print(f"{name}: {fed:,} inputs ({nbytes / 1e6:.1f} MB) in {dt:.1f} s = {fed / dt:,.0f} "
          f"inputs/s, {nbytes / dt / 1e6:.2f} MB/s; slowest {CHUNK_FRAMES}-input chunk "
          f"{slowest * 1e3:.1f} ms")
    print(f"  streaming decoder: {dict(sorted(stats.items()))}")
    print(f"  one-shot decoder:  {dict(sorted(shot.items()))}")
    return ok


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=1_000_000,
                        help="inputs per parser (default 1 000 000)")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    rng = random.Random(args.seed)
    results = [
        fuzz("bno055 requests (chip side)", B.RequestDecoder, B.decode_request,
             _valid_bno055_requests(rng, 2000), args.frames, rng),
        fuzz("bno055 responses (host side)", B.ResponseDecoder, B.decode_response,
             _valid_bno055_responses(rng, 2000), args.frames, rng),
        fuzz("rig stream frames", lambda: S.StreamDecoder(track_sequence=True), S.decode_frame,
             _valid_stream_frames(rng, 2000), args.frames, rng, deep=_recrc),
    ]
    if all(results):
        print("only ProtocolError subclasses escaped; every decoder made progress on every call")
        return 0
    return 1


if __name__ == "__main__":
    sys.exit(main())
