"""Rig IMU stream protocol: SPEC.md test vectors, COBS, CRC, resync, sequence gaps, fuzz."""

from __future__ import annotations

import re
import struct
from pathlib import Path

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
    assert S.decode_frame(wire) == frame
    assert S.decode_body(body) == frame


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


def test_forward_compatible_extensions():
    # a 1.x SAMPLE with 13-byte records and a trailing payload field decodes as 1.0
    rec = struct.pack("<BBBhhhh", 2, 0xFF, 0, 16384, 0, 0, 0) + b"\xaa\xbb"
    payload = struct.pack("<IBB", 77, 1, 13) + rec + b"\x01\x02"
    frame = S.decode_frame(S.encode_frame(S.FrameType.SAMPLE, 3, payload))
    assert frame == S.Sample(3, 77, (S.SensorReading(2, 0xFF, 0, (1.0, 0.0, 0.0, 0.0)),))
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
