"""Protocol 1.0 packets and the mixed-protocol stream decoder, on the e-Manual's byte vectors
(emanual.robotis.com/docs/en/dxl/protocol1/, "Instruction Details" examples)."""

from __future__ import annotations

import pytest

from firmware_protocol.dynamixel import instructions as ins2
from firmware_protocol.dynamixel import protocol1 as p1
from firmware_protocol.dynamixel.packets import InstructionPacket, StatusPacket
from firmware_protocol.errors import ChecksumError, FramingError, PacketError

PING_1 = bytes.fromhex("FF FF 01 02 01 FB")
PING_1_STATUS = bytes.fromhex("FF FF 01 02 00 FC")
READ_TEMP = bytes.fromhex("FF FF 01 04 02 2B 01 CC")
READ_TEMP_STATUS = bytes.fromhex("FF FF 01 03 00 20 DB")  # 32 °C
WRITE_ID = bytes.fromhex("FF FF FE 04 03 03 01 F6")  # broadcast: set ID 1
SYNC_WRITE = bytes.fromhex("FF FF FE 18 83 1E 04 00 10 00 50 01 01 20 02 60 03 02 30 00 70 01"
                           " 03 20 02 80 03 12")
BULK_READ = bytes.fromhex("FF FF FE 09 92 00 02 01 1E 02 02 24 1D")


def test_e_manual_vectors_encode():
    assert p1.encode_instruction(1, p1.Instruction1.PING) == PING_1
    assert p1.encode_status(1, 0) == PING_1_STATUS
    assert p1.encode_instruction(1, p1.Instruction1.READ, bytes((43, 1))) == READ_TEMP
    assert p1.encode_status(1, 0, bytes((32,))) == READ_TEMP_STATUS
    assert p1.encode_instruction(0xFE, p1.Instruction1.WRITE, bytes((3, 1))) == WRITE_ID
    params = p1.sync_write_params(30, 4, {0: bytes.fromhex("10 00 50 01"),
                                         1: bytes.fromhex("20 02 60 03"),
                                         2: bytes.fromhex("30 00 70 01"),
                                         3: bytes.fromhex("20 02 80 03")})
    assert p1.encode_instruction(0xFE, p1.Instruction1.SYNC_WRITE, params) == SYNC_WRITE
    assert p1.encode_instruction(0xFE, p1.Instruction1.BULK_READ,
                                 p1.bulk_read_params([(1, 30, 2), (2, 36, 2)])) == BULK_READ


def test_decode_and_parameters():
    pkt = p1.decode_instruction(READ_TEMP)
    assert (pkt.id, pkt.instruction, p1.parse_read(pkt.params)) == (1, 2, (43, 1))
    st = p1.decode_status(READ_TEMP_STATUS)
    assert st.ok and st.params == b"\x20"
    address, length, data = p1.parse_sync_write(p1.decode_instruction(SYNC_WRITE).params)
    assert (address, length, sorted(data)) == (30, 4, [0, 1, 2, 3])
    assert data[1] == bytes.fromhex("20 02 60 03")
    assert p1.parse_bulk_read(p1.decode_instruction(BULK_READ).params) == [(1, 30, 2),
                                                                           (2, 36, 2)]
    assert p1.parse_write(bytes((3, 1))) == (3, b"\x01")
    with pytest.raises(PacketError):
        p1.parse_read(b"\x01")
    with pytest.raises(PacketError):
        p1.parse_sync_write(bytes((30, 2, 1, 0)))
    with pytest.raises(p1.Checksum1Error) as err:
        p1.decode_instruction(PING_1[:-1] + b"\x00")
    assert err.value.packet_id == 1
    with pytest.raises(FramingError):
        p1.decode_status(PING_1_STATUS + b"\x00")


def test_error_bits_are_named():
    assert p1.error_names(0x22) == ("angle_limit", "overload")
    assert p1.Error1.CHECKSUM == 0x10 and p1.Error1.INSTRUCTION == 0x40
    with pytest.raises(ValueError):
        p1.encode_status(1, 0x80)


def test_mixed_stream_tags_each_protocol_and_resyncs():
    v2 = ins2.ping(1).encode()
    d = p1.MixedStreamDecoder()
    bad = bytearray(PING_1)
    bad[-1] ^= 1
    d.feed(b"\x00\x13" + PING_1 + v2 + bytes(bad) + READ_TEMP[:5])
    first = d.next_packet()
    assert isinstance(first, p1.InstructionPacket1) and p1.packet_protocol(first) == 1.0
    second = d.next_packet()
    assert isinstance(second, InstructionPacket) and p1.packet_protocol(second) == 2.0
    with pytest.raises(ChecksumError):
        d.next_packet()
    assert d.next_packet() is None  # half a READ
    d.feed(READ_TEMP[5:])
    assert d.next_packet() == p1.InstructionPacket1(1, 2, bytes((43, 1)))
    host = p1.MixedStreamDecoder("status")
    host.feed(b"\xff" + READ_TEMP_STATUS)  # FF FF FF: the header starts one byte later
    assert list(host) == [p1.StatusPacket1(1, 0, b"\x20")]
    host.feed(StatusPacket(3, 0, b"\x01\x02").encode())
    assert isinstance(host.next_packet(), StatusPacket)


def test_id_253_is_a_1_0_packet_not_a_2_0_header():
    pkt = p1.encode_instruction(0xFD, p1.Instruction1.PING)  # FF FF FD 02 ...
    d = p1.MixedStreamDecoder()
    d.feed(pkt)
    assert d.next_packet() == p1.InstructionPacket1(0xFD, 1, b"")
