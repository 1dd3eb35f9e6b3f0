"""Rig IMU stream protocol: SPEC.md test vectors, COBS, CRC, resync, sequence gaps, fuzz."""

from __future__ import annotations

import math
import re
import struct
import subprocess
import sys
import types
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from firmware_protocol.errors import ChecksumError, FramingError, PacketError, ProtocolError
from firmware_protocol.imu import cobs
from firmware_protocol.imu import stream as S

SPEC = Path(S.__file__).with_name("SPEC.md")


def spec_vectors() -> dict[str, tuple[bytes, bytes]]:
    """``name -> (body, wire)`` from the ```vector blocks of SPEC.md §10."""
    text = SPEC.read_text(encoding="utf-8")
    out = {}
    for block in re.findall(r"```vector\n(.*?)```", text, flags=re.S):
        fields = dict(re.findall(r"^(vector|body|wire):\s*(.*)$", block, flags=re.M))
        out[fields["vector"].split()[0]] = (bytes.fromhex(fields["body"]),
                                            bytes.fromhex(fields["wire"]))
    return out


#: sensor 0 of the sample_raw vector: acc m/s², gyr rad/s (1 and -2 °/s), mag µT
RAW0 = (0.12, -0.5, 9.81, math.radians(1), math.radians(-2), 0.0, 20.0, -5.5, -43.0)
IDENTITY = S.Identity(1, 0, 0x0100, 0x51570001, 16, False, 0x000F, 0x0005, 200, 10, 400)

#: name -> (encoded by the Python encoder, decoded frame)
EXPECTED = {
    "identify": (S.encode_command(0, S.CommandType.IDENTIFY),
                 S.Command(0, S.CommandType.IDENTIFY)),
    "start": (S.encode_command(1, S.CommandType.START), S.Command(1, S.CommandType.START)),
    "stop": (S.encode_command(0x0102, S.CommandType.STOP),
             S.Command(0x0102, S.CommandType.STOP)),
    "set_rate": (S.encode_command(2, S.CommandType.SET_RATE, 200),
                 S.Command(2, S.CommandType.SET_RATE, 200)),
    "set_sensors": (S.encode_command(3, S.CommandType.SET_SENSORS, 5),
                    S.Command(3, S.CommandType.SET_SENSORS, 5)),
    "ack_start": (S.encode_ack(0x10, 1, S.CommandType.START), S.Ack(0x10, 1, 0x81)),
    "nak_rate": (S.encode_nak(0x11, 2, S.CommandType.SET_RATE, S.ErrorCode.BAD_ARGUMENT),
                 S.Nak(0x11, 2, 0x83, 3)),
    "ack_identify": (S.encode_ack(0x12, 0, S.CommandType.IDENTIFY, S.encode_identity(IDENTITY)),
                     S.Ack(0x12, 0, 0x80, S.encode_identity(IDENTITY))),
    "sample": (
        S.encode_sample(0x1234, 0x89ABCDEF, [(0, 0xFF, 0, (1, 0, 0, 0)),
                                             (2, 0x3F, 1, (0.5, -0.5, 0.5, -0.5))]),
        S.Sample(0x1234, 0x89ABCDEF, (S.SensorReading(0, 0xFF, 0, (1.0, 0.0, 0.0, 0.0)),
                                      S.SensorReading(2, 0x3F, 1, (0.5, -0.5, 0.5, -0.5)))),
    ),
    "sample_wrap": (
        S.encode_sample(0xFFFF, 0xFFFFFF00, [(1, 0xC0, 0, (0.7071, 0, 0.7071, 0))]),
        S.Sample(0xFFFF, 0xFFFFFF00,
                 (S.SensorReading(1, 0xC0, 0, (11585 / 16384, 0.0, 11585 / 16384, 0.0)),)),
    ),
    "sample_empty": (S.encode_sample(0, 0, []), S.Sample(0, 0, ())),
    "sample_fault": (S.encode_sample(5, 1000, [(3, 0, 2, (0, 0, 0, 0))]),
                     S.Sample(5, 1000, (S.SensorReading(3, 0, 2, (0.0, 0.0, 0.0, 0.0)),))),
    "set_fields": (S.encode_command(4, S.CommandType.SET_FIELDS, S.FieldFlag.RAW),
                   S.Command(4, S.CommandType.SET_FIELDS, 1)),
    "nak_fields": (S.encode_nak(0x13, 4, S.CommandType.SET_FIELDS, S.ErrorCode.UNKNOWN_COMMAND),
                   S.Nak(0x13, 4, 0x85, 1)),
    "sample_raw": (
        S.encode_sample(0x0100, 2_000_000, [
            (0, 0xFF, 0, (1, 0, 0, 0), RAW0),
            (1, 0, 2, (0, 0, 0, 0), (0.0,) * 9)]),
        S.Sample(0x0100, 2_000_000, (
            S.SensorReading(0, 0xFF, 0, (1.0, 0.0, 0.0, 0.0),
                            (0.12, -0.5, 9.81, math.pi / 180, -2 * math.pi / 180, 0.0,
                             20.0, -5.5, -43.0)),
            S.SensorReading(1, 0, 2, (0.0, 0.0, 0.0, 0.0), (0.0,) * 9))),
    ),
}


def test_spec_lists_every_vector():
    assert set(spec_vectors()) == set(EXPECTED)


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_spec_vectors(name):
    body, wire = spec_vectors()[name]
    encoded, frame = EXPECTED[name]
    assert encoded.hex(" ") == wire.hex(" ")
    assert cobs.encode(body) + b"\x00" == wire
    assert cobs.decode(wire[:-1]) == body
    assert S.crc32(body[:-4]) == struct.unpack("<I", body[-4:])[0]
    assert _close(S.decode_frame(wire), frame)
    assert _close(S.decode_body(body), frame)


def _close(a, b) -> bool:
    """Frames equal, the float fields to 1e-12 (raw values are decoded by multiplying)."""
    if isinstance(a, S.Sample) and isinstance(b, S.Sample):
        return (a.seq, a.timestamp_us, len(a.readings)) == (b.seq, b.timestamp_us,
                                                            len(b.readings)) and all(
            (x.sensor_id, x.calibration, x.flags, x.quaternion, x.raw is None)
            == (y.sensor_id, y.calibration, y.flags, y.quaternion, y.raw is None)
            and (x.raw is None or np.allclose(x.raw, y.raw, rtol=0, atol=1e-12))
            for x, y in zip(a.readings, b.readings, strict=True))
    return a == b


def test_identity_roundtrip():
    ack = S.decode_frame(EXPECTED["ack_identify"][0])
    assert ack.identity == IDENTITY
    with pytest.raises(PacketError):
        _ = S.Ack(0, 0, S.CommandType.START).identity
    with pytest.raises(PacketError):
        _ = S.Ack(0, 0, S.CommandType.IDENTIFY, b"\x01").identity


def test_spec_wrap_example():
    dec = S.StreamDecoder()
    dec.feed(spec_vectors()["sample_wrap"][1] + S.encode_sample(0, 0x100, []))
    a, b = dec.drain()
    assert (a.seq, b.seq) == (0xFFFF, 0) and dec.gaps == 0
    unwrap = S.TimestampUnwrapper()
    assert unwrap(a.timestamp_us) == 0xFFFFFF00
    assert unwrap(b.timestamp_us) - 0xFFFFFF00 == 512


def test_crc_parameters():
    assert S.crc32(b"123456789") == S.CRC_CHECK == 0xCBF43926


COBS_EXAMPLES = [
    ("", "01"), ("00", "01 01"), ("00 00", "01 01 01"), ("11 22 00 33", "03 11 22 02 33"),
    ("11 22 33 44", "05 11 22 33 44"), ("11 00 00 00", "02 11 01 01 01"),
]


@pytest.mark.parametrize(("raw", "enc"), COBS_EXAMPLES)
def test_cobs_published_examples(raw, enc):
    assert cobs.encode(bytes.fromhex(raw)) == bytes.fromhex(enc)
    if raw:
        assert cobs.decode(bytes.fromhex(enc)) == bytes.fromhex(raw)


def test_cobs_long_runs_canonical():
    run = bytes(range(1, 255))  # 254 non-zero bytes
    assert cobs.encode(run) == b"\xff" + run
    assert cobs.encode(run + b"\x00") == b"\xff" + run + b"\x01\x01"
    assert cobs.encode(b"\x00" + run) == b"\x01\xff" + run
    assert cobs.encode(run + b"\x01") == b"\xff" + run + b"\x02\x01"
    for data in (run, run + b"\x00", bytes(range(256)) * 3):
        assert cobs.decode(cobs.encode(data)) == data
        assert len(cobs.encode(data)) <= cobs.max_encoded_length(len(data))


@given(st.binary(max_size=1200))
def test_cobs_roundtrip(data):
    enc = cobs.encode(data)
    assert 0 not in enc
    assert cobs.decode(enc) == data


@given(st.binary(max_size=600))
def test_cobs_matches_the_cobs_package(data):
    ref = pytest.importorskip("cobs.cobs")
    assert cobs.encode(data) == ref.encode(data)


@pytest.mark.parametrize("bad", ["", "00", "05 11 22", "03 11 00"])
def test_cobs_decode_errors(bad):
    with pytest.raises(FramingError):
        cobs.decode(bytes.fromhex(bad))


def _sample(seq: int, ts: int = 0) -> bytes:
    return S.encode_sample(seq, ts, [(0, 0xFF, 0, (1, 0, 0, 0))])


def test_resync_after_garbage():
    frames = [_sample(i, 1000 * i) for i in range(5)]
    stream = b"\x17\x42\x99" + frames[0] + b"\xde\xad\x00" + frames[1] + frames[2]
    # garbage *inside* frame 3 corrupts only it; frame 4 arrives intact
    stream += frames[3][:5] + b"\x00\x33" + frames[3][5:] + frames[4]
    dec = S.StreamDecoder(track_sequence=False)
    got, errors = [], []
    for i in range(0, len(stream), 7):
        dec.feed(stream[i:i + 7])
        while True:
            try:
                item = dec.next()
            except ProtocolError as err:
                errors.append(type(err))
                continue
            if item is None:
                break
            got.append(item.seq)
    # frame 0 is glued to leading garbage (no delimiter before it): lost, as SPEC §3.1 says
    assert got == [1, 2, 4]
    assert len(errors) == dec.errors >= 3
    assert all(issubclass(e, ProtocolError) for e in errors)


def test_leading_delimiter_protects_first_frame():
    dec = S.StreamDecoder()
    dec.feed(b"\x17\x42\x00" + _sample(7))
    with pytest.raises(ProtocolError):
        dec.next()
    assert dec.next().seq == 7


def test_sequence_gaps_and_wraparound():
    dec = S.StreamDecoder()
    for seq in (0xFFFE, 0xFFFF, 0x0000, 0x0001, 0x0004, 0x0005):
        dec.feed(_sample(seq))
    items = dec.drain()
    gaps = [i for i in items if isinstance(i, S.Gap)]
    assert gaps == [S.Gap(expected=2, received=4, lost=2)]
    assert [i.seq for i in items if isinstance(i, S.Sample)] == [0xFFFE, 0xFFFF, 0, 1, 4, 5]
    assert (dec.gaps, dec.lost, dec.frames) == (1, 2, 6)
    # a restarted counter is a gap of >= 2**15, not counted as lost frames
    dec.feed(_sample(0))
    (gap, frame) = dec.drain()
    assert gap.lost == 0x10000 - 6 and dec.lost == 2 and frame.seq == 0
    dec.reset_sequence()
    dec.feed(_sample(100))
    assert [type(i) for i in dec.drain()] == [S.Sample]


def test_timestamp_unwrapper():
    u = S.TimestampUnwrapper()
    assert u(0xFFFFFFF0) == 0xFFFFFFF0
    assert u(0x00000010) == 0x1_00000010
    assert u(0x00000020) == 0x1_00000020
    assert u(0x00000018) == 0x1_00000018  # an older timestamp steps back


def test_version_mismatch_is_reported_with_header():
    body = bytearray(spec_vectors()["start"][0])
    body[0] = 2
    body[-4:] = struct.pack("<I", S.crc32(body[:-4]))
    with pytest.raises(S.FrameContentError) as info:
        S.decode_frame(cobs.encode(bytes(body)) + b"\x00")
    err = info.value
    assert (err.seq, err.frame_type, err.code) == (1, 0x81, S.ErrorCode.UNSUPPORTED_VERSION)
    assert (err.actual, err.expected) == (2, 1)


def test_command_with_wrong_length_is_bad_length():
    wire = S.encode_frame(S.CommandType.START, 9, b"\x01")
    with pytest.raises(S.FrameContentError) as info:
        S.decode_frame(wire)
    assert info.value.code == S.ErrorCode.BAD_LENGTH and info.value.seq == 9


def test_checksum_error_carries_values():
    wire = bytearray(spec_vectors()["stop"][1])
    wire[3] ^= 0x40
    with pytest.raises(ChecksumError) as info:
        S.decode_frame(bytes(wire))
    assert info.value.received != info.value.computed


def test_raw_fields_round_trip_at_their_resolution():
    rng = np.random.default_rng(11)
    acc = rng.uniform(-150, 150, (8, 3))  # BNO055 ranges: ±16 g, ±2000 °/s, ±1300 µT
    gyr = np.radians(rng.uniform(-2000, 2000, (8, 3)))
    mag = rng.uniform(-1300, 1300, (8, 3))
    raws = np.hstack([acc, gyr, mag])
    readings = [(i, 0xFF, 0, (1, 0, 0, 0), tuple(r)) for i, r in enumerate(raws)]
    wire = S.encode_sample(9, 10, readings)
    body = cobs.decode(wire[:-1])
    assert body[9] == S.RAW_RECORD_SIZE and len(body) == 14 + 29 * 8 <= S.MAX_BODY
    got = np.array([r.raw for r in S.decode_frame(wire).readings])
    half_lsb = np.array([0.5 / S.ACC_SCALE] * 3 + [math.radians(0.5 / S.GYR_SCALE)] * 3
                        + [0.5 / S.MAG_SCALE] * 3)
    assert np.all(np.abs(got - raws) <= half_lsb + 1e-12)
    # saturation, ties away from zero
    assert S.quantize_raw((400, -400, 0.005, math.radians(3000), 0, 0, -3000, 1 / 32, 0)) == (
        32767, -32768, 1, 32767, 0, 0, -32768, 1, 0)


def test_raw_sample_arguments():
    q = (1, 0, 0, 0)
    with pytest.raises(ValueError, match="every reading"):
        S.encode_sample(0, 0, [(0, 0, 0, q, (0.0,) * 9), (1, 0, 0, q)])
    with pytest.raises(ValueError, match="raw=True"):
        S.encode_sample(0, 0, [(0, 0, 0, q)], raw=True)
    with pytest.raises(ValueError, match="at most 8"):
        S.encode_sample(0, 0, [(i, 0, 0, q, (0.0,) * 9) for i in range(9)])
    with pytest.raises(ValueError, match="9 values"):
        S.quantize_raw((1.0, 2.0))
    with pytest.raises(ValueError, match="NaN"):
        S.quantize_raw((math.nan,) + (0.0,) * 8)
    with pytest.raises(ValueError, match=r"0\.\.255"):
        S.encode_command(0, S.CommandType.SET_FIELDS, 256)
    # raw=False leaves the raw values out; an empty raw SAMPLE says record_size 29
    plain = S.decode_frame(S.encode_sample(0, 0, [(0, 0, 0, q, (1.0,) * 9)], raw=False))
    assert plain.readings[0].raw is None
    assert cobs.decode(S.encode_sample(0, 0, [], raw=True)[:-1])[9] == 29
    wire = S.encode_frame(S.CommandType.SET_FIELDS, 2, b"\x01\x00")
    with pytest.raises(S.FrameContentError) as info:
        S.decode_frame(wire)
    assert info.value.code == S.ErrorCode.BAD_LENGTH


def _decoder_of_version_1_0() -> types.ModuleType:
    """The host decoder as released with protocol 1.0 (commit 9fdf835), from git history."""
    try:
        source = subprocess.run(
            ["git", "show", "9fdf835:firmware_protocol/imu/stream.py"], cwd=SPEC.parent,
            capture_output=True, text=True, check=True, timeout=30).stdout
    except (OSError, subprocess.CalledProcessError) as err:
        pytest.skip(f"the 1.0 decoder is not in this checkout's git history ({err})")
    module = types.ModuleType("stream_1_0")
    sys.modules[module.__name__] = module  # dataclasses look their module up while defining
    try:
        exec(compile(source, "stream_1_0.py", "exec"), module.__dict__)
    finally:
        del sys.modules[module.__name__]
    assert module.PROTOCOL_MINOR == 0 and module.RECORD_SIZE == 11
    return module


def test_a_1_0_decoder_steps_through_raw_records():
    """SPEC §9: a 1.0 receiver uses record_size, so it reads the quaternions of 29-byte records
    and skips the raw fields — checked with the 1.0 decoder itself."""
    old = _decoder_of_version_1_0()
    _, wire = spec_vectors()["sample_raw"]
    frame = old.decode_frame(wire)
    assert [(r.sensor_id, r.calibration, r.flags, r.quaternion) for r in frame.readings] == [
        (0, 0xFF, 0, (1.0, 0.0, 0.0, 0.0)), (1, 0, 2, (0.0, 0.0, 0.0, 0.0))]
    rng = np.random.default_rng(3)
    readings = [(i, 0x3F, 0, tuple(q / np.linalg.norm(q)), tuple(rng.normal(0, 20, 9)))
                for i, q in zip((0, 3, 7), rng.normal(size=(3, 4)), strict=True)]
    dec = old.StreamDecoder()
    dec.feed(S.encode_sample(1, 5, readings) + S.encode_sample(2, 6, [r[:4] for r in readings]))
    raw_frame, plain_frame = dec.drain()
    assert dec.errors == 0 and dec.gaps == 0
    assert [r.quaternion for r in raw_frame.readings] == \
        [r.quaternion for r in plain_frame.readings]
    assert [r.sensor_id for r in raw_frame.readings] == [0, 3, 7]


def test_forward_compatible_extensions():
    # a 1.x SAMPLE with 13-byte records and a trailing payload field decodes as 1.0
    rec = struct.pack("<BBBhhhh", 2, 0xFF, 0, 16384, 0, 0, 0) + b"\xaa\xbb"
    payload = struct.pack("<IBB", 77, 1, 13) + rec + b"\x01\x02"
    frame = S.decode_frame(S.encode_frame(S.FrameType.SAMPLE, 3, payload))
    assert frame == S.Sample(3, 77, (S.SensorReading(2, 0xFF, 0, (1.0, 0.0, 0.0, 0.0)),))
    # a later 1.x record with fields after the raw ones: raw read, the rest skipped
    raw = struct.pack("<9h", 100, 0, 981, 16, 0, 0, 16, 32, -48)
    rec = struct.pack("<BBBhhhh", 1, 0xFF, 0, 16384, 0, 0, 0) + raw + b"\xcc" * 4
    payload = struct.pack("<IBB", 5, 2, 33) + rec + rec.replace(b"\x01", b"\x04", 1)
    frame = S.decode_frame(S.encode_frame(S.FrameType.SAMPLE, 4, payload))
    assert [r.sensor_id for r in frame.readings] == [1, 4]
    np.testing.assert_allclose(frame.readings[1].raw, (
        1.0, 0.0, 9.81, math.radians(1), 0.0, 0.0, 1.0, 2.0, -3.0), rtol=0, atol=1e-12)
    unknown = S.decode_frame(S.encode_frame(0x10, 4, b"xyz"))
    assert unknown == S.UnknownFrame(4, 0x10, b"xyz")


@pytest.mark.parametrize(
    "payload",
    [b"\x00" * 5, struct.pack("<IBB", 0, 17, 11), struct.pack("<IBB", 0, 1, 10) + bytes(10),
     struct.pack("<IBB", 0, 2, 11) + bytes(11),
     struct.pack("<IBB", 0, 2, 11) + struct.pack("<BBBhhhh", 3, 0, 0, 0, 0, 0, 0) * 2,
     struct.pack("<IBB", 0, 1, 11) + struct.pack("<BBBhhhh", 16, 0, 0, 0, 0, 0, 0)],
)
def test_malformed_samples(payload):
    with pytest.raises(PacketError):
        S.decode_frame(S.encode_frame(S.FrameType.SAMPLE, 0, payload))


def test_oversized_input_without_delimiter_is_dropped():
    dec = S.StreamDecoder()
    dec.feed(b"\x01" * (S.MAX_ENCODED + 10))
    with pytest.raises(FramingError, match="delimiter"):
        dec.next()
    dec.feed(b"\x01" * 50 + b"\x00" + _sample(3))
    assert dec.next().seq == 3


def test_encoder_argument_checks():
    with pytest.raises(ValueError):
        S.encode_frame(S.FrameType.ACK, 70000)
    with pytest.raises(ValueError):
        S.encode_frame(S.FrameType.ACK, 0, bytes(250))
    with pytest.raises(ValueError):
        S.encode_sample(0, 0, [(1, 0, 0, (1, 0, 0, 0)), (1, 0, 0, (1, 0, 0, 0))])
    with pytest.raises(ValueError):
        S.encode_command(0, S.CommandType.SET_RATE)
    with pytest.raises(ValueError):
        S.encode_command(0, S.CommandType.START, 5)
    with pytest.raises(ValueError):
        S.quantize_quaternion((float("nan"), 0, 0, 0))


def test_quantisation_rounds_half_away_from_zero_and_saturates():
    half = 0.5 / 16384
    assert S.quantize_quaternion((half, -half, 1.5 / 16384, 2.0)) == (1, -1, 2, 32767)


def test_largest_sample_fits():
    readings = [(i, 0xFF, 0, (0.5, 0.5, 0.5, 0.5)) for i in range(16)]
    wire = S.encode_sample(1, 2, readings)
    assert len(cobs.decode(wire[:-1])) == 14 + 11 * 16
    assert len(S.decode_frame(wire).readings) == 16


# -- fuzz ---------------------------------------------------------------------------------


def _drain_all(dec: S.StreamDecoder) -> list:
    out, calls = [], 0
    while True:
        calls += 1
        assert calls < 10_000, "decoder made no progress"
        try:
            item = dec.next()
        except ProtocolError:
            continue
        if item is None:
            return out
        out.append(item)


@settings(max_examples=300)
@given(st.binary(max_size=800))
def test_fuzz_random_bytes(data):
    try:
        S.decode_frame(data)
    except ProtocolError:
        pass
    dec = S.StreamDecoder()
    dec.feed(data)
    _drain_all(dec)
    # after any garbage, a delimiter and a good frame get through
    dec.feed(b"\x00" + _sample(42))
    assert any(getattr(i, "seq", None) == 42 for i in _drain_all(dec))


_frames = st.sampled_from([w for _, w in spec_vectors().values()])


@settings(max_examples=400)
@given(_frames, st.lists(st.tuples(st.integers(0, 300), st.integers(0, 255)), min_size=1,
                         max_size=4), st.booleans())
def test_fuzz_mutated_frames(wire, edits, truncate):
    buf = bytearray(wire)
    for pos, value in edits:
        buf[pos % len(buf)] = value
    if truncate:
        del buf[len(buf) // 2:]
    try:
        S.decode_frame(bytes(buf))
    except ProtocolError:
        pass
    dec = S.StreamDecoder()
    dec.feed(bytes(buf) + b"\x00" + _sample(9))
    items = _drain_all(dec)
    assert items and getattr(items[-1], "seq", None) == 9


@settings(max_examples=400)
@given(_frames, st.lists(st.tuples(st.integers(0, 300), st.integers(0, 255)), min_size=1,
                         max_size=3), st.integers(0, 40))
def test_fuzz_mutated_bodies_with_valid_crc(wire, edits, cut):
    """Behind a good CRC, every field check raises only PacketError (FrameContentError)."""
    body = bytearray(cobs.decode(wire[:-1])[:-4])
    for pos, value in edits:
        body[pos % len(body)] = value
    del body[len(body) - min(cut, len(body) - 1):]
    body += S.crc32(body).to_bytes(4, "little")
    try:
        frame = S.decode_body(bytes(body))
    except S.FrameContentError as err:
        assert err.seq == int.from_bytes(body[2:4], "little") or len(body) < 8
    except (FramingError, PacketError):
        pass
    else:
        assert frame.seq == int.from_bytes(body[2:4], "little")
