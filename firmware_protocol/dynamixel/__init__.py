"""ROBOTIS Dynamixel Protocol 2.0: pure encode/decode, no I/O.

Packet layout::

    FF FF FD 00 | ID | LEN_L LEN_H | INST | PARAM ... | CRC_L CRC_H
    (status packets: INST = 0x55 and the first parameter is the error byte)

Modules
-------
framing
    Header, byte stuffing, CRC-16 (poly 0x8005).
packets
    :class:`InstructionPacket`, :class:`StatusPacket`, encode/decode, :class:`StreamDecoder`.
instructions
    Builders and parsers of each instruction's parameters (sync/bulk/fast reads included).
control_table
    X-series control tables loaded from the ``dynamixel-sdk`` wheel's ``.model`` files.
"""

from firmware_protocol.dynamixel import instructions
from firmware_protocol.dynamixel.control_table import (
    ControlItem,
    ControlTable,
    available_models,
    load_control_table,
)
from firmware_protocol.dynamixel.framing import BROADCAST_ID, HEADER, crc16, stuff, unstuff
from firmware_protocol.dynamixel.packets import (
    ALERT,
    ErrorCode,
    Instruction,
    InstructionPacket,
    Packet,
    StatusPacket,
    StreamDecoder,
    decode_packet,
    encode_instruction,
    encode_status,
)

__all__ = [
    "ALERT",
    "BROADCAST_ID",
    "HEADER",
    "ControlItem",
    "ControlTable",
    "ErrorCode",
    "Instruction",
    "InstructionPacket",
    "Packet",
    "StatusPacket",
    "StreamDecoder",
    "available_models",
    "crc16",
    "decode_packet",
    "encode_instruction",
    "encode_status",
    "instructions",
    "load_control_table",
    "stuff",
    "unstuff",
]
