"""BNO055 UART register protocol: published byte vectors, codecs, streaming decoders, fuzz."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from firmware_protocol.errors import FramingError, PacketError, ProtocolError
from firmware_protocol.imu import bno055 as B

# Datasheet BST-BNO055-DS000, section 4.7 (UART protocol) and table 4-8 (status codes): the
# CHIP_ID read and the OPR_MODE write are the datasheet's own examples; the others apply the
# same published layouts to the registers the rig uses.
PUBLISHED = [
    # (what, host bytes, chip bytes, decoded response)
    ("read CHIP_ID", "AA 01 00 01", "BB 01 A0", B.ReadResponse(b"\xa0")),
    ("write OPR_MODE = NDOF", "AA 00 3D 01 0C", "EE 01", B.StatusResponse(0x01)),
    ("write OPR_MODE = CONFIG", "AA 00 3D 01 00", "EE 01", B.StatusResponse(0x01)),
    ("read CALIB_STAT", "AA 01 35 01", "BB 01 FF", B.ReadResponse(b"\xff")),
    ("read QUA_DATA, identity", "AA 01 20 08", "BB 08 00 40 00 00 00 00 00 00",
     B.ReadResponse(b"\x00\x40" + bytes(6))),
    ("write to a read-only register", "AA 00 00 01 00", "EE 05", B.StatusResponse(0x05)),
]


@pytest.mark.parametrize(("what", "host", "chip", "response"), PUBLISHED,
                         ids=[p[0] for p in PUBLISHED])
def test_published_vectors(what, host, chip, response):
    host_b, chip_b = bytes.fromhex(host), bytes.fromhex(chip)
    req = B.decode_request(host_b)
    if isinstance(req, B.ReadRequest):
        assert B.encode_read(req.register, req.length) == host_b
    else:
        assert B.encode_write(req.register, req.data) == host_b
    assert B.decode_response(chip_b) == response
    if isinstance(response, B.ReadResponse):
        assert B.encode_read_response(response.data) == chip_b
    else:
        assert B.encode_status(response.status) == chip_b


def test_status_codes_match_datasheet_table():
    assert {s.name: s.value for s in B.Status} == {
        "WRITE_SUCCESS": 0x01, "READ_FAIL": 0x02, "WRITE_FAIL": 0x03,
        "REGMAP_INVALID_ADDRESS": 0x04, "REGMAP_WRITE_DISABLED": 0x05,
        "WRONG_START_BYTE": 0x06, "BUS_OVER_RUN_ERROR": 0x07, "MAX_LENGTH_ERROR": 0x08,
        "MIN_LENGTH_ERROR": 0x09, "RECEIVE_CHARACTER_TIMEOUT": 0x0A,
    }
    for status in B.Status:
        resp = B.decode_response(bytes((0xEE, status)))
        assert resp.status == status and resp.ok == (status == B.Status.WRITE_SUCCESS)


def test_register_map_subset():
    assert B.Register.CHIP_ID == 0x00 and B.Register.PAGE_ID == 0x07
    assert B.Register.QUA_DATA == 0x20 and B.Register.EUL_DATA == 0x1A
    assert B.Register.GYR_DATA == 0x14 and B.Register.CALIB_STAT == 0x35
    assert (B.Register.SYS_STATUS, B.Register.SYS_ERR, B.Register.UNIT_SEL) == (0x39, 0x3A, 0x3B)
    assert (B.Register.OPR_MODE, B.Register.PWR_MODE, B.Register.SYS_TRIGGER) == (0x3D, 0x3E, 0x3F)
    assert (B.Register.AXIS_MAP_CONFIG, B.Register.AXIS_MAP_SIGN) == (0x41, 0x42)
    assert B.OperationMode.CONFIG == 0 and B.OperationMode.NDOF == 0x0C
    assert B.OperationMode.NDOF in B.FUSION_MODES
    assert B.OperationMode.AMG not in B.FUSION_MODES


@pytest.mark.parametrize(
    ("data", "status"),
    [("55", B.Status.WRONG_START_BYTE), ("AA 02 00 01", B.Status.WRONG_START_BYTE),
     ("AA 01 00 00", B.Status.MIN_LENGTH_ERROR), ("AA 00 00 81", B.Status.MAX_LENGTH_ERROR),
     ("AA 00 3D 02 0C", B.Status.RECEIVE_CHARACTER_TIMEOUT),
     ("AA 01 00 01 00", B.Status.BUS_OVER_RUN_ERROR)],
)
def test_bad_requests_carry_the_chip_status(data, status):
    with pytest.raises(B.Bno055FramingError) as info:
        B.decode_request(bytes.fromhex(data))
    assert info.value.status == status
    assert isinstance(info.value, FramingError)


def test_request_decoder_handles_pieces_and_garbage():
    stream = (b"\x13\x37" + B.encode_read(0x20, 8) + B.encode_write(0x3D, [0x0C])
              + b"\xaa\x05" + B.encode_read(0x35, 1))
    dec = B.RequestDecoder()
    got, errors = [], []
    for byte in stream:  # one byte at a time: partial input everywhere
        dec.feed(bytes([byte]))
        while True:
            try:
                item = dec.next()
            except B.Bno055FramingError as err:
                errors.append(err.status)
                continue
            if item is None:
                break
            got.append(item)
    assert got == [B.ReadRequest(0x20, 8), B.WriteRequest(0x3D, b"\x0c"), B.ReadRequest(0x35, 1)]
    assert errors == [B.Status.WRONG_START_BYTE] * 3
    assert dec.buffered == 0


def test_request_decoder_expire_drops_partial_request():
    dec = B.RequestDecoder()
    dec.feed(b"\xaa\x00\x3d")
    assert dec.next() is None
    assert dec.expire() is True
    assert dec.expire() is False
    dec.feed(B.encode_read(0, 1))
    assert dec.next() == B.ReadRequest(0, 1)


def test_response_decoder_skips_garbage_runs():
    dec = B.ResponseDecoder()
    dec.feed(b"\x01\x02\x03" + B.encode_read_response(b"\xa0") + b"\xbb")
    with pytest.raises(FramingError, match="3 byte"):
        dec.next()
    assert dec.next() == B.ReadResponse(b"\xa0")
    assert dec.next() is None  # a lone 0xBB waits for its length
    dec.feed(b"\x00")
    with pytest.raises(FramingError, match="length 0"):
        dec.next()


def test_decode_response_checks_expected_length():
    with pytest.raises(PacketError) as info:
        B.decode_response(bytes.fromhex("BB 01 A0"), expected_length=8)
    assert (info.value.actual, info.value.expected) == (1, 8)
    with pytest.raises(FramingError):
        B.decode_response(bytes.fromhex("BB 08 00"))


def test_encoders_reject_bad_arguments():
    with pytest.raises(ValueError):
        B.encode_read(0x100, 1)
    with pytest.raises(ValueError):
        B.encode_read(0, 0)
    with pytest.raises(ValueError):
        B.encode_write(0, b"")
    with pytest.raises(ValueError):
        B.encode_write(0, bytes(129))
    with pytest.raises(ValueError):
        B.encode_vector([float("nan"), 0, 0], 16.0)


def test_quaternion_codec():
    assert B.encode_quaternion((1, 0, 0, 0)) == bytes.fromhex("0040000000000000")
    assert B.decode_quaternion(bytes.fromhex("0040000000000000")) == (1.0, 0.0, 0.0, 0.0)
    assert B.decode_quaternion(bytes.fromhex("00C0000000000000"))[0] == -1.0
    # 1 LSB = 2**-14, little-endian int16, saturating
    assert B.encode_quaternion((0.5, -0.5, 2**-14, 3.0)) == bytes.fromhex("0020 00E0 0100 FF7F")
    with pytest.raises(PacketError):
        B.decode_quaternion(b"\x00" * 7)


def test_vector_units():
    # Euler and angular rate default units: 16 LSB per degree (per degree per second)
    assert B.encode_vector((360.0, -90.0, 1 / 16), 16.0) == bytes.fromhex("8016 60FA 0100")
    assert B.decode_vector(bytes.fromhex("801660FA0100"), 16.0) == (360.0, -90.0, 1 / 16)


def test_calibration_status_packing():
    cs = B.CalibrationStatus(system=3, gyroscope=2, accelerometer=1, magnetometer=0)
    assert cs.to_byte() == 0b11_10_01_00
    assert B.CalibrationStatus.from_byte(0b11_10_01_00) == cs
    assert B.CalibrationStatus.from_byte(0xFF).fully_calibrated
    with pytest.raises(ValueError):
        B.CalibrationStatus(4, 0, 0, 0)


@given(st.integers(0, 255), st.binary(min_size=1, max_size=128))
def test_write_roundtrip(register, data):
    assert B.decode_request(B.encode_write(register, data)) == B.WriteRequest(register, data)


@given(st.lists(st.floats(-1.0, 1.0), min_size=4, max_size=4))
def test_quaternion_roundtrip_within_half_lsb(q):
    back = B.decode_quaternion(B.encode_quaternion(q))
    assert all(abs(a - b) <= 0.5 / 16384 + 1e-12 for a, b in zip(q, back, strict=True))


def _drain(dec) -> int:
    """Run a decoder to exhaustion; only ProtocolError may escape ``next``. Returns the calls."""
    calls = 0
    while True:
        calls += 1
        assert calls < 10_000, "decoder made no progress"
        try:
            if dec.next() is None:
                return calls
        except ProtocolError:
            continue


@settings(max_examples=300)
@given(st.binary(max_size=600))
def test_fuzz_random_bytes_raise_only_protocol_errors(data):
    for cls in (B.RequestDecoder, B.ResponseDecoder):
        dec = cls()
        dec.feed(data)
        assert _drain(dec) <= len(data) + 1
    for fn in (B.decode_request, B.decode_response):
        try:
            fn(data)
        except ProtocolError:
            pass


@settings(max_examples=300)
@given(st.integers(0, 255), st.binary(min_size=1, max_size=40), st.integers(0, 44),
       st.integers(0, 255))
def test_fuzz_mutated_requests(register, data, pos, value):
    frame = bytearray(B.encode_write(register, data))
    frame[pos % len(frame)] = value
    try:
        B.decode_request(bytes(frame))
    except ProtocolError:
        pass
    dec = B.RequestDecoder()
    dec.feed(bytes(frame) + B.encode_read(0, 1))
    _drain(dec)
