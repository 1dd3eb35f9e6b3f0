"""Protocol 2.0 codec: published byte vectors, stuffing, CRC, stream resync, fuzzing.

Vectors are the examples of the ROBOTIS e-Manual "DYNAMIXEL Protocol 2.0" page; each was
re-checked by recomputing its CRC (a mis-remembered byte would fail that check).
"""

from __future__ import annotations

import random

import pytest
from dynamixel_sdk import Protocol2PacketHandler
from hypothesis import given, settings
from hypothesis import strategies as st

from firmware_protocol.dynamixel import (
    ErrorCode,
    Instruction,
    InstructionPacket,
    StatusPacket,
    StreamDecoder,
    crc16,
    decode_packet,
    encode_instruction,
    encode_status,
    instructions,
    stuff,
    unstuff,
)
from firmware_protocol.dynamixel.framing import CRC_TABLE
from firmware_protocol.errors import ChecksumError, FramingError, PacketError, ProtocolError
from firmware_protocol.fuzzing import mutate


def h(text: str) -> bytes:
    return bytes.fromhex(text)


# (e-Manual section, packet bytes, expected decoded packet)
PUBLISHED = [
    ("ping", "FF FF FD 00 01 03 00 01 19 4E", InstructionPacket(1, Instruction.PING)),
    ("ping status", "FF FF FD 00 01 07 00 55 00 06 04 26 65 5D",
     StatusPacket(1, 0, h("06 04 26"))),
    ("broadcast ping", "FF FF FD 00 FE 03 00 01 31 42", InstructionPacket(0xFE, 1)),
    ("broadcast ping status id 2", "FF FF FD 00 02 07 00 55 00 06 04 26 6F 6D",
     StatusPacket(2, 0, h("06 04 26"))),
    ("read", "FF FF FD 00 01 07 00 02 84 00 04 00 1D 15",
     InstructionPacket(1, Instruction.READ, h("84 00 04 00"))),
    ("read status", "FF FF FD 00 01 08 00 55 00 A6 00 00 00 8C C0",
     StatusPacket(1, 0, h("A6 00 00 00"))),
    ("write", "FF FF FD 00 01 09 00 03 74 00 00 02 00 00 CA 89",
     InstructionPacket(1, Instruction.WRITE, h("74 00 00 02 00 00"))),
    ("write status", "FF FF FD 00 01 04 00 55 00 A1 0C", StatusPacket(1, 0, b"")),
    ("reg write", "FF FF FD 00 01 09 00 04 68 00 C8 00 00 00 AE 8E",
     InstructionPacket(1, Instruction.REG_WRITE, h("68 00 C8 00 00 00"))),
    ("action", "FF FF FD 00 01 03 00 05 02 CE", InstructionPacket(1, Instruction.ACTION)),
    ("factory reset", "FF FF FD 00 01 04 00 06 01 A1 E6",
     InstructionPacket(1, Instruction.FACTORY_RESET, h("01"))),
    ("reboot", "FF FF FD 00 01 03 00 08 2F 4E", InstructionPacket(1, Instruction.REBOOT)),
    ("clear", "FF FF FD 00 01 08 00 10 01 44 58 4C 22 B1 DC",
     InstructionPacket(1, Instruction.CLEAR, h("01 44 58 4C 22"))),
    ("sync read", "FF FF FD 00 FE 09 00 82 84 00 04 00 01 02 CE FA",
     InstructionPacket(0xFE, Instruction.SYNC_READ, h("84 00 04 00 01 02"))),
    ("sync read status id 2", "FF FF FD 00 02 08 00 55 00 1F 08 00 00 BA BE",
     StatusPacket(2, 0, h("1F 08 00 00"))),
    ("sync write", "FF FF FD 00 FE 11 00 83 74 00 04 00 01 96 00 00 00 02 AA 00 00 00 82 87",
     InstructionPacket(0xFE, Instruction.SYNC_WRITE,
                       h("74 00 04 00 01 96 00 00 00 02 AA 00 00 00"))),
    ("bulk read status id 1", "FF FF FD 00 01 06 00 55 00 77 00 C3 69",
     StatusPacket(1, 0, h("77 00"))),
    ("bulk write", "FF FF FD 00 FE 10 00 93 01 20 00 02 00 A0 00 02 1F 00 01 00 50 B7 68",
     InstructionPacket(0xFE, Instruction.BULK_WRITE, h("01 20 00 02 00 A0 00 02 1F 00 01 00 50"))),
]


@pytest.mark.parametrize(("name", "wire", "packet"), PUBLISHED, ids=[p[0] for p in PUBLISHED])
def test_published_vectors_decode_and_encode(name, wire, packet):
    data = h(wire)
    assert decode_packet(data) == packet
    assert packet.encode() == data


def test_builders_match_published_vectors():
    assert instructions.ping(1).encode() == h("FF FF FD 00 01 03 00 01 19 4E")
    assert instructions.read(1, 132, 4).encode() == h("FF FF FD 00 01 07 00 02 84 00 04 00 1D 15")
    assert instructions.write(1, 116, h("00 02 00 00")).encode() == h(
        "FF FF FD 00 01 09 00 03 74 00 00 02 00 00 CA 89")
    assert instructions.reg_write(1, 104, (200).to_bytes(4, "little")).encode() == h(
        "FF FF FD 00 01 09 00 04 68 00 C8 00 00 00 AE 8E")
    assert instructions.action(1).encode() == h("FF FF FD 00 01 03 00 05 02 CE")
    assert instructions.factory_reset(1, 0x01).encode() == h("FF FF FD 00 01 04 00 06 01 A1 E6")
    assert instructions.reboot(1).encode() == h("FF FF FD 00 01 03 00 08 2F 4E")
    assert instructions.clear(1).encode() == h("FF FF FD 00 01 08 00 10 01 44 58 4C 22 B1 DC")
    assert instructions.sync_read(132, 4, [1, 2]).encode() == h(
        "FF FF FD 00 FE 09 00 82 84 00 04 00 01 02 CE FA")
    assert instructions.sync_write(116, 4, {1: (150).to_bytes(4, "little"),
                                            2: (170).to_bytes(4, "little")}).encode() == h(
        "FF FF FD 00 FE 11 00 83 74 00 04 00 01 96 00 00 00 02 AA 00 00 00 82 87")
    assert instructions.bulk_write([(1, 32, h("A0 00")), (2, 31, h("50"))]).encode() == h(
        "FF FF FD 00 FE 10 00 93 01 20 00 02 00 A0 00 02 1F 00 01 00 50 B7 68")
    status = encode_status(1, 0, instructions.ping_status_params(1030, 0x26))
    assert status == h("FF FF FD 00 01 07 00 55 00 06 04 26 65 5D")


def test_parsers_roundtrip():
    assert instructions.parse_read(h("84 00 04 00")) == (132, 4)
    assert instructions.parse_sync_read(h("84 00 04 00 01 02")) == (132, 4, [1, 2])
    assert instructions.parse_sync_write(h("74 00 04 00 01 96 00 00 00 02 AA 00 00 00")) == (
        116, 4, {1: h("96 00 00 00"), 2: h("AA 00 00 00")})
    assert instructions.parse_bulk_write(h("01 20 00 02 00 A0 00 02 1F 00 01 00 50")) == [
        (1, 32, h("A0 00")), (2, 31, h("50"))]
    pkt = instructions.bulk_read([(1, 144, 2), (2, 146, 1)])
    assert instructions.parse_bulk_read(pkt.params) == [(1, 144, 2), (2, 146, 1)]
    assert instructions.parse_ping_status(StatusPacket(1, 0, h("06 04 26"))) == (1030, 0x26)


@pytest.mark.parametrize(("parser", "params"), [
    (instructions.parse_read, h("84 00 04")),
    (instructions.parse_sync_read, h("84 00 04 00")),
    (instructions.parse_sync_write, h("74 00 04 00 01 96 00")),
    (instructions.parse_bulk_read, h("01 84 00 04")),
    (instructions.parse_bulk_write, h("01 20 00 02 00 A0")),
])
def test_parsers_reject_bad_lengths_with_actual_and_expected(parser, params):
    with pytest.raises(PacketError) as info:
        parser(params)
    assert info.value.actual is not None and info.value.expected is not None


def test_crc_table_is_the_sdk_table():
    sdk = Protocol2PacketHandler()
    for i in range(256):
        assert crc16(bytes([i])) == sdk.updateCRC(0, [i], 1)
    assert CRC_TABLE[1] == 0x8005
    # CRC-16/BUYPASS check value
    assert crc16(b"123456789") == 0xFEE8


def test_crc_can_continue_over_chunks():
    data = bytes(range(50))
    assert crc16(data[20:], crc16(data[:20])) == crc16(data)


def test_stuffing_examples():
    assert stuff(h("03 FF FF FD 01")) == h("03 FF FF FD FD 01")
    assert stuff(h("FF FF FD FF FF FD")) == h("FF FF FD FD FF FF FD FD")
    assert stuff(h("FF FD FF")) == h("FF FD FF")
    assert unstuff(h("03 FF FF FD FD 01")) == h("03 FF FF FD 01")
    # a packet whose data contains the header: LEN counts the stuffed byte
    wire = encode_instruction(1, Instruction.WRITE, h("74 00 FF FF FD 00"))
    assert wire[5] == 10  # 1 inst + 6 params + 1 stuffing + 2 CRC
    assert b"\xff\xff\xfd\xfd" in wire[7:]
    assert decode_packet(wire) == InstructionPacket(1, 3, h("74 00 FF FF FD 00"))


def _sdk_encode(packet_id: int, instruction: int, params: bytes) -> bytes:
    """Encode with the SDK's own txPacket code path (reference implementation)."""

    class _Port:
        is_using = False
        written = b""

        def clearPort(self):
            pass

        def writePort(self, packet):
            _Port.written = bytes(packet)
            return len(packet)

    length = len(params) + 3
    tx = [0] * (length + 7)  # the SDK sends the whole list: it must be exactly sized
    tx[4], tx[5], tx[6], tx[7] = packet_id, length & 0xFF, length >> 8, instruction
    tx[8:8 + len(params)] = list(params)
    port = _Port()
    assert Protocol2PacketHandler().txPacket(port, tx) == 0
    total = (port.written[5] | port.written[6] << 8) + 7
    return port.written[:total]


@settings(max_examples=300, deadline=None)
@given(st.integers(0, 0xFE),
       # 0x55 is the Status instruction: such a frame is a status packet, not an instruction
       st.integers(0, 0xFF).filter(lambda i: i != 0x55),
       st.lists(st.sampled_from([0x00, 0xFD, 0xFF, 0x55, 0x01]), max_size=40).map(bytes))
def test_encoder_matches_sdk_txpacket(packet_id, instruction, params):
    ours = encode_instruction(packet_id, instruction, params)
    sdk = _sdk_encode(packet_id, instruction, params)
    region = bytes((instruction,)) + params
    if b"\xff\xff\xfd" in region:
        # dynamixel-sdk 4.1.0 pitfall: txPacket ignores addStuffing's return value, so the
        # Python SDK never stuffs. Our decoder still reads its packets (lenient unstuffing),
        # except data holding FF FF FD FD, which any receiver must take as stuffed.
        if b"\xff\xff\xfd\xfd" not in region:
            assert decode_packet(sdk) == InstructionPacket(packet_id, instruction, params)
    else:
        assert ours == sdk


def test_sdk_does_not_stuff_and_we_still_decode_it():
    params = h("74 00 FF FF FD 00")
    sdk = _sdk_encode(1, Instruction.WRITE, params)
    assert sdk == h("FF FF FD 00 01 09 00 03 74 00 FF FF FD 00 C9 07")  # unstuffed
    assert decode_packet(sdk) == InstructionPacket(1, Instruction.WRITE, params)


@settings(max_examples=300, deadline=None)
@given(st.integers(0, 0xFE), st.integers(0, 0xFF), st.binary(max_size=60))
def test_roundtrip(packet_id, error, params):
    status = StatusPacket(packet_id, error, params)
    assert decode_packet(status.encode()) == status
    inst = InstructionPacket(packet_id, 0x03, params)
    assert decode_packet(inst.encode()) == inst


def test_status_error_byte_alert_is_a_flag():
    status = decode_packet(encode_status(3, 0x80 | ErrorCode.ACCESS))
    assert status.alert and status.error_code is ErrorCode.ACCESS and not status.ok
    status = decode_packet(encode_status(3, 0x80))
    assert status.alert and status.ok and status.error_code is ErrorCode.NONE
    for code in range(1, 8):
        assert decode_packet(encode_status(1, code)).error_code == code


def test_decode_errors():
    good = h("FF FF FD 00 01 03 00 01 19 4E")
    with pytest.raises(ChecksumError) as info:
        decode_packet(good[:-1] + b"\x00")
    assert (info.value.received, info.value.computed) == (0x0019, 0x4E19)
    with pytest.raises(FramingError):
        decode_packet(good[:-1])
    with pytest.raises(FramingError):
        decode_packet(good + b"\x00")
    with pytest.raises(FramingError):
        decode_packet(b"\xff\xff\xfe\x00" + good[4:])
    with pytest.raises(FramingError):
        decode_packet(h("FF FF FD 00 01 02 00 01 00"))  # length below 3
    with pytest.raises(PacketError):
        decode_packet(encode_instruction(1, 0x55))  # status without its error byte


def test_stream_resyncs_after_garbage_and_partial_input():
    a = encode_status(1, 0, h("06 04 26"))
    b = encode_instruction(2, Instruction.READ, h("84 00 04 00"))
    stream = b"\x00\xff\xff\x13\xfd" + a + b"\xff\xff\xfd" + b"garbage" + b
    dec = StreamDecoder()
    got = []
    for k in range(len(stream)):  # one byte at a time
        dec.feed(stream[k:k + 1])
        got.extend(dec)
    assert got == [decode_packet(a), decode_packet(b)]
    assert dec.pending == 0
    assert dec.dropped == len(stream) - len(a) - len(b)


def test_stream_reports_bad_frame_then_continues():
    good = encode_status(1, 0, h("77 00"))
    bad = bytearray(encode_status(2, 0, h("24")))
    bad[-1] ^= 0x01
    dec = StreamDecoder()
    dec.feed(bytes(bad) + good)
    with pytest.raises(ChecksumError):
        dec.next_packet()
    assert list(dec) == [decode_packet(good)]


def test_stream_rejects_absurd_length_without_waiting_for_it():
    dec = StreamDecoder(max_length=1024)
    good = encode_status(1)
    dec.feed(h("FF FF FD 00 01 FF FF") + good)
    with pytest.raises(FramingError):
        dec.next_packet()
    assert list(dec) == [decode_packet(good)]


def test_fast_read_reply_layout():
    entries = [(0, 3, h("A6 00 00 00")), (0x80, 7, h("1F 08 00 00"))]
    wire = instructions.encode_fast_status(entries)
    status = decode_packet(wire)
    assert status.id == 0xFE and status.error == 0
    assert wire[5] | wire[6] << 8 == 1 + 2 * (4 + 4)
    # the first device's CRC is the CRC of everything before it
    first_end = 8 + 2 + 4
    assert wire[first_end] | wire[first_end + 1] << 8 == crc16(wire[:first_end])
    assert instructions.parse_fast_status(status, [4, 4]) == entries


@settings(max_examples=400, deadline=None)
@given(st.binary(max_size=80), st.randoms(use_true_random=False))
def test_fuzz_only_protocol_errors_escape(blob, rng):
    frame = encode_instruction(rng.randrange(256), rng.randrange(256), blob[:20])
    broken = mutate(frame, rng, special=b"\xff\xfd\x00", fields=((5, 2),))  # the length field
    for data in (blob, broken, b"\xff\xff\xfd\x00" + blob):
        try:
            decode_packet(data)
        except ProtocolError:
            pass
        dec = StreamDecoder()
        dec.feed(data)
        for _ in range(len(data) + 2):  # each call consumes input or stops
            try:
                if dec.next_packet() is None:
                    break
            except ProtocolError:
                pass
        else:
            pytest.fail("decoder did not converge")


def test_fuzz_seeded_mutations_are_detected():
    rng = random.Random(1234)
    detected = 0
    for _ in range(2000):
        frame = encode_instruction(rng.randrange(253), 0x03, rng.randbytes(rng.randrange(12)))
        data = bytearray(frame)
        data[rng.randrange(7, len(data))] ^= 1 << rng.randrange(8)  # one bit flip after header
        try:
            decode_packet(bytes(data))
        except ProtocolError:
            detected += 1
    assert detected == 2000  # CRC-16 catches every single-bit error


def test_stream_skip_frame_abandons_a_stalled_frame():
    dec = StreamDecoder()
    good = encode_instruction(1, Instruction.PING)
    dec.feed(h("FF FF FD 00 01 F4 01 03") + good)  # length 500: waits for more bytes
    assert dec.next_packet() is None
    dec.skip_frame()  # inter-byte timeout
    assert list(dec) == [decode_packet(good)]
