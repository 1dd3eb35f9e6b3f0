"""The rig's multi-IMU stream protocol, version 1.1 (normative text: ``SPEC.md`` beside this file).

A microcontroller reads up to 16 orientation sensors and streams their quaternions (and, on
request, their raw accelerometer, gyroscope and magnetometer readings) to the host; the host
starts, stops and configures the stream with commands that the device acknowledges.

Frame on the wire::

    COBS(body) 0x00                          (0x00 delimits frames; COBS removes it from the body)

    body:  +---------+------+---------+-------------------+-----------------+
           | version | type | seq     | payload           | crc32           |
           | u8      | u8   | u16 LE  | 0..MAX_PAYLOAD    | u32 LE          |
           +---------+------+---------+-------------------+-----------------+
           offset 0    1      2         4                   len - 4

* ``version`` is the protocol *major* version (1). The first 4 bytes and the CRC trailer keep
  this layout in every version.
* ``crc32`` is CRC-32/ISO-HDLC (poly 0x04C11DB7, init 0xFFFFFFFF, reflected in and out,
  xorout 0xFFFFFFFF, check("123456789") = 0xCBF43926; :func:`zlib.crc32`) over bytes
  ``0 .. len-4``.
* ``seq`` counts the sender's frames modulo 2**16; host and device count independently. An ACK or
  NAK echoes the ``seq`` of the command it answers in its payload.

Frame types and payloads (little-endian)::

    0x01 SAMPLE  device→host  u32 timestamp_us, u8 count, u8 record_size (11, or 29 with the
                              RAW field set), count records:
                              u8 sensor_id, u8 calib (sys<<6|gyr<<4|acc<<2|mag), u8 flags,
                              i16 w, i16 x, i16 y, i16 z   (1 LSB = 2**-14, scalar first)
                              [RAW, 1.1: i16 acc x,y,z (100 LSB = 1 m/s²), i16 gyr x,y,z
                              (16 LSB = 1 °/s), i16 mag x,y,z (16 LSB = 1 µT), sensor frame]
    0x02 ACK     device→host  u16 command_seq, u8 command_type, reply data (IDENTIFY: Identity)
    0x03 NAK     device→host  u16 command_seq, u8 command_type, u8 error
    0x80 IDENTIFY host→device  (empty)
    0x81 START    host→device  (empty)
    0x82 STOP     host→device  (empty)
    0x83 SET_RATE host→device  u16 rate_hz
    0x84 SET_SENSORS host→device u16 sensor_mask
    0x85 SET_FIELDS  host→device u8 field_mask (bit 0 RAW)              [1.1]

Decoding checks the frame size and the CRC before reading any field. The streaming
:class:`StreamDecoder` splits at 0x00, so garbage costs at most the frame it lands in, and it
reports sequence gaps.
"""

from __future__ import annotations

import enum
import math
import struct
import zlib
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

from firmware_protocol.errors import ChecksumError, FramingError, PacketError
from firmware_protocol.imu import cobs
from firmware_protocol.imu.bno055 import CalibrationStatus

__all__ = [
    "ACC_SCALE",
    "CRC_CHECK",
    "GYR_SCALE",
    "HEADER_SIZE",
    "MAG_SCALE",
    "MAX_BODY",
    "MAX_ENCODED",
    "MAX_RAW_SENSORS",
    "MAX_SENSORS",
    "PROTOCOL_MAJOR",
    "PROTOCOL_MINOR",
    "QUATERNION_SCALE",
    "RAW_RECORD_SIZE",
    "RECORD_SIZE",
    "TIMESTAMP_MODULUS",
    "Ack",
    "Command",
    "CommandType",
    "ErrorCode",
    "FieldFlag",
    "FrameContentError",
    "FrameType",
    "Gap",
    "Identity",
    "Nak",
    "ReadingFlag",
    "Sample",
    "SensorReading",
    "StreamDecoder",
    "TimestampUnwrapper",
    "UnknownFrame",
    "crc32",
    "decode_body",
    "decode_frame",
    "encode_ack",
    "encode_command",
    "encode_frame",
    "encode_identity",
    "encode_nak",
    "encode_sample",
    "quantize_quaternion",
    "quantize_raw",
]

PROTOCOL_MAJOR = 1
"""Major version, byte 0 of every frame. A receiver rejects frames of another major version."""
PROTOCOL_MINOR = 1
"""Minor version, reported by IDENTIFY. Minor versions only append (see SPEC.md); 1.1 added
SET_FIELDS and the raw fields of a SAMPLE record."""

HEADER_SIZE = 4
"""version, type, seq."""
CRC_SIZE = 4
MAX_SENSORS = 16
"""Sensor ids are 0..15; masks are 16 bits."""
RECORD_SIZE = 11
"""Bytes of one sensor record in a version-1.0 SAMPLE (the fields every 1.x record starts with)."""
RAW_RECORD_SIZE = 29
"""Bytes of one sensor record with the RAW fields (1.1): the 11 of 1.0, then 9 int16."""
MAX_RAW_SENSORS = 8
"""Most sensors one SAMPLE can carry with the RAW fields: 6 + 8·29 = 238 payload bytes fit
the 248 a frame allows, 9 sensors do not."""
MAX_BODY = 256
"""Largest frame body (header + payload + CRC) before COBS."""
MAX_ENCODED = cobs.max_encoded_length(MAX_BODY)
"""Largest COBS-encoded frame, without its delimiter (258)."""
QUATERNION_SCALE = 1 << 14
"""Quaternion LSB per unit, as the BNO055 outputs it."""
TIMESTAMP_MODULUS = 1 << 32
"""Timestamps are microseconds modulo 2**32 (wrap every 4294.967296 s ≈ 71.6 min)."""
ACC_SCALE = 100.0
"""Accelerometer LSB per m/s² in a RAW record (the BNO055's ACC_DATA in m/s² units)."""
GYR_SCALE = 16.0
"""Gyroscope LSB per °/s in a RAW record (the BNO055's GYR_DATA in dps units)."""
MAG_SCALE = 16.0
"""Magnetometer LSB per µT in a RAW record (the BNO055's MAG_DATA)."""
CRC_CHECK = 0xCBF43926
"""CRC-32/ISO-HDLC of b"123456789"."""

_SEQ_MOD = 1 << 16


class FrameType(enum.IntEnum):
    """Byte 1 of a frame. 0x01-0x7F device→host, 0x80-0xFF host→device."""

    SAMPLE = 0x01
    ACK = 0x02
    NAK = 0x03


class CommandType(enum.IntEnum):
    """Host → device frame types."""

    IDENTIFY = 0x80
    START = 0x81
    STOP = 0x82
    SET_RATE = 0x83
    SET_SENSORS = 0x84
    SET_FIELDS = 0x85
    """Version 1.1: u8 mask of the optional record fields (:class:`FieldFlag`)."""


class FieldFlag(enum.IntFlag):
    """Argument of SET_FIELDS: optional fields of each SAMPLE record (1.1). Bits 1-7 are
    reserved: a device refuses a mask naming them (NAK BAD_ARGUMENT)."""

    NONE = 0
    RAW = 0x01
    """Raw accelerometer, gyroscope and magnetometer (record_size 29)."""


class ErrorCode(enum.IntEnum):
    """NAK error byte."""

    UNKNOWN_COMMAND = 0x01
    BAD_LENGTH = 0x02
    BAD_ARGUMENT = 0x03
    BAD_STATE = 0x04
    UNSUPPORTED_VERSION = 0x05
    SENSOR_FAULT = 0x06


class ReadingFlag(enum.IntFlag):
    """Per-sensor ``flags`` byte of a SAMPLE record (bits 2-7 reserved, sent as 0, ignored)."""

    NONE = 0
    STALE = 0x01
    """The sensor had no new value; the previous one is repeated."""
    FAULT = 0x02
    """The sensor did not answer; the quaternion is all zeros."""


_COMMAND_ARG = {
    CommandType.IDENTIFY: 0,
    CommandType.START: 0,
    CommandType.STOP: 0,
    CommandType.SET_RATE: 2,
    CommandType.SET_SENSORS: 2,
    CommandType.SET_FIELDS: 1,
}


def crc32(data: bytes | bytearray | memoryview) -> int:
    """CRC-32/ISO-HDLC (``zlib.crc32``) of ``data``; ``crc32(b"123456789") == 0xCBF43926``."""
    return zlib.crc32(data) & 0xFFFFFFFF


# --------------------------------------------------------------------------------------------
# messages


@dataclass(frozen=True, slots=True)
class SensorReading:
    """One sensor's quaternion in a SAMPLE.

    Attributes
    ----------
    sensor_id : int
        0..15, the sensor's position on the device.
    calibration : int
        BNO055 ``CALIB_STAT`` byte (``sys<<6 | gyr<<4 | acc<<2 | mag``).
    flags : int
        :class:`ReadingFlag` bits.
    quaternion : tuple of 4 float
        Scalar-first ``(w, x, y, z)``, sensor frame relative to the sensor's world frame,
        quantised to 2**-14 (not renormalised; all zeros when ``FAULT``).
    raw : tuple of 9 float or None
        Version 1.1, RAW field set: accelerometer (m/s², specific force), gyroscope (rad/s),
        magnetometer (µT), sensor frame, in that order, at the record's resolution
        (0.01 m/s², 1/16 °/s, 1/16 µT); None in a record without the RAW fields (11 bytes).
    """

    sensor_id: int
    calibration: int
    flags: int
    quaternion: tuple[float, float, float, float]
    raw: tuple[float, ...] | None = None

    @property
    def calibration_status(self) -> CalibrationStatus:
        return CalibrationStatus.from_byte(self.calibration)


@dataclass(frozen=True, slots=True)
class Sample:
    """Device → host: the quaternions of the active sensors at one instant.

    Attributes
    ----------
    seq : int
        Device frame counter (mod 2**16).
    timestamp_us : int
        Device clock at the reading, microseconds modulo 2**32.
    readings : tuple of SensorReading
        Active sensors in increasing ``sensor_id``.
    """

    seq: int
    timestamp_us: int
    readings: tuple[SensorReading, ...]


@dataclass(frozen=True, slots=True)
class Command:
    """Host → device command; ``value`` is the argument of SET_RATE / SET_SENSORS / SET_FIELDS,
    else None."""

    seq: int
    command: CommandType
    value: int | None = None


@dataclass(frozen=True, slots=True)
class Identity:
    """Reply data of IDENTIFY (20 bytes in version 1.0)."""

    protocol_major: int
    protocol_minor: int
    firmware_version: int
    serial: int
    max_sensors: int
    streaming: bool
    present_mask: int
    active_mask: int
    rate_hz: int
    min_rate_hz: int
    max_rate_hz: int

    _FORMAT = struct.Struct("<BBHIBBHHHHH")


@dataclass(frozen=True, slots=True)
class Ack:
    """Device → host: the command with ``command_seq`` was carried out."""

    seq: int
    command_seq: int
    command: int
    data: bytes = b""

    @property
    def identity(self) -> Identity:
        """Parse ``data`` as the IDENTIFY reply.

        Raises
        ------
        PacketError
            Not an IDENTIFY acknowledgement, or reply data shorter than 20 bytes.
        """
        if self.command != CommandType.IDENTIFY:
            raise PacketError("ACK does not answer IDENTIFY", actual=self.command,
                              expected=int(CommandType.IDENTIFY))
        fmt = Identity._FORMAT
        if len(self.data) < fmt.size:
            raise PacketError("IDENTIFY reply length", actual=len(self.data),
                              expected=f">= {fmt.size}")
        f = fmt.unpack_from(self.data)
        return Identity(f[0], f[1], f[2], f[3], f[4], bool(f[5] & 1), *f[6:])


@dataclass(frozen=True, slots=True)
class Nak:
    """Device → host: the command with ``command_seq`` was refused with ``error``."""

    seq: int
    command_seq: int
    command: int
    error: int


@dataclass(frozen=True, slots=True)
class UnknownFrame:
    """A valid frame of a type this version does not know (newer minor version): skip it."""

    seq: int
    type: int
    payload: bytes


class FrameContentError(PacketError):
    """A frame with a good CRC whose content is wrong; the header fields are trustworthy.

    Attributes
    ----------
    seq, frame_type : int
        From the frame header: a device answers ``NAK(seq, frame_type, code)``.
    code : ErrorCode
        The NAK error that fits (BAD_LENGTH, or UNSUPPORTED_VERSION).
    """

    def __init__(self, message: str, *, seq: int, frame_type: int, code: ErrorCode,
                 actual=None, expected=None):
        self.seq = seq
        self.frame_type = frame_type
        self.code = code
        super().__init__(message, actual=actual, expected=expected)


@dataclass(frozen=True, slots=True)
class Gap:
    """Emitted by :class:`StreamDecoder` before a frame whose ``seq`` is not the expected one.

    ``lost = (received - expected) mod 2**16`` frames were lost; values >= 2**15 mean the device
    restarted its counter (links do not reorder), not that that many frames were lost.
    """

    expected: int
    received: int
    lost: int


Frame = Sample | Ack | Nak | Command | UnknownFrame

# --------------------------------------------------------------------------------------------
# encoders


def _check_u16(value: int, name: str) -> int:
    if not (isinstance(value, int) and 0 <= value < _SEQ_MOD):
        raise ValueError(f"{name} must be an int in 0..65535, got {value!r}")
    return value


def encode_frame(frame_type: int, seq: int, payload: bytes = b"") -> bytes:
    """Build a complete wire frame: ``COBS(version type seq payload crc32) 00``.

    Raises
    ------
    ValueError
        ``frame_type`` not a byte, ``seq`` not u16, or body longer than :data:`MAX_BODY`.
    """
    if not (isinstance(frame_type, int) and 0 <= frame_type <= 0xFF):
        raise ValueError(f"frame type must be one byte, got {frame_type!r}")
    _check_u16(seq, "seq")
    body = struct.pack("<BBH", PROTOCOL_MAJOR, frame_type, seq) + bytes(payload)
    if len(body) + CRC_SIZE > MAX_BODY:
        raise ValueError(f"frame body of {len(body) + CRC_SIZE} bytes exceeds {MAX_BODY}")
    body += struct.pack("<I", crc32(body))
    return cobs.encode(body) + b"\x00"


def quantize_quaternion(q: Sequence[float]) -> tuple[int, int, int, int]:
    """int16 components of a scalar-first quaternion at 2**-14 per LSB.

    Rounded to nearest with ties away from zero (as the C encoder), then saturated.
    """
    if len(q) != 4:
        raise ValueError(f"a quaternion has 4 components (w, x, y, z), got {len(q)}")
    out = []
    for c in q:
        c = float(c)
        if c != c:
            raise ValueError("cannot encode a NaN quaternion component")
        out.append(_round_saturate(c * QUATERNION_SCALE))
    return (out[0], out[1], out[2], out[3])


def _round_saturate(scaled: float) -> int:
    raw = math.floor(scaled + 0.5) if scaled >= 0 else -math.floor(-scaled + 0.5)
    return max(-32768, min(32767, raw))


def quantize_raw(raw: Sequence[float]) -> tuple[int, ...]:
    """The 9 int16 RAW fields of a record from SI values.

    ``raw`` is accelerometer (m/s²), gyroscope (rad/s), magnetometer (µT), sensor frame; each
    is scaled to its LSB (:data:`ACC_SCALE` per m/s², :data:`GYR_SCALE` per °/s,
    :data:`MAG_SCALE` per µT), rounded to nearest with ties away from zero and saturated.
    """
    if len(raw) != 9:
        raise ValueError(f"raw readings are 9 values (acc, gyr, mag x/y/z), got {len(raw)}")
    vals = [float(v) for v in raw]
    if any(v != v for v in vals):
        raise ValueError("cannot encode a NaN raw reading")
    scales = (ACC_SCALE,) * 3 + (GYR_SCALE * 180.0 / math.pi,) * 3 + (MAG_SCALE,) * 3
    return tuple(_round_saturate(v * k) for v, k in zip(vals, scales, strict=True))


_RECORD = struct.Struct("<BBBhhhh")
_RAW = struct.Struct("<9h")
_SAMPLE_HEAD = struct.Struct("<IBB")
_RAW_UNIT = (1.0 / ACC_SCALE,) * 3 + (math.pi / (180.0 * GYR_SCALE),) * 3 + (1.0 / MAG_SCALE,) * 3


def encode_sample(
    seq: int,
    timestamp_us: int,
    readings: Iterable[SensorReading | tuple],
    *,
    raw: bool | None = None,
) -> bytes:
    """Encode a SAMPLE frame.

    Parameters
    ----------
    seq : int
        Device frame counter, 0..65535.
    timestamp_us : int
        Microseconds; reduced modulo 2**32 here, so a running 64-bit clock may be passed.
    readings : iterable of SensorReading or (sensor_id, calibration, flags, quaternion[, raw])
        At most 16 (8 with raw fields), in strictly increasing ``sensor_id``; quaternion
        scalar-first; ``raw`` 9 SI values as :attr:`SensorReading.raw`, or None.
    raw : bool, optional
        Records with the RAW fields (``record_size`` 29, version 1.1) or without (11). Default:
        with them when every reading has ``raw``, without when none has. With ``raw=True`` every
        reading needs its raw values (a FAULT record sends zeros); with ``raw=False`` they are
        left out.
    """
    items = []
    for r in readings:
        if isinstance(r, tuple):
            sid, calib, flags, q, *rest = r
            values = rest[0] if rest else None
        else:
            sid, calib, flags, q, values = (r.sensor_id, r.calibration, r.flags, r.quaternion,
                                            r.raw)
        items.append((sid, calib, flags, q, values))
    has_raw = [v is not None for _, _, _, _, v in items]
    if raw is None:
        if any(has_raw) and not all(has_raw):
            raise ValueError("either every reading of a SAMPLE has raw values or none has")
        raw = bool(items) and all(has_raw)
    elif raw and not all(has_raw):
        raise ValueError("raw=True needs raw values for every reading (zeros for a FAULT)")
    recs = bytearray()
    last_id = -1
    for sid, calib, flags, q, values in items:
        if not (0 <= sid < MAX_SENSORS) or sid <= last_id:
            raise ValueError(
                f"sensor ids must be strictly increasing in 0..{MAX_SENSORS - 1}, got {sid}")
        if not (0 <= calib <= 0xFF and 0 <= flags <= 0xFF):
            raise ValueError("calibration and flags are single bytes")
        last_id = sid
        recs += _RECORD.pack(sid, calib, flags, *quantize_quaternion(q))
        if raw:
            recs += _RAW.pack(*quantize_raw(values))
    if raw and len(items) > MAX_RAW_SENSORS:
        raise ValueError(f"a SAMPLE with raw fields carries at most {MAX_RAW_SENSORS} sensors, "
                         f"got {len(items)}")
    if not isinstance(timestamp_us, int) or timestamp_us < 0:
        raise ValueError(f"timestamp_us must be a non-negative int, got {timestamp_us!r}")
    size = RAW_RECORD_SIZE if raw else RECORD_SIZE
    payload = _SAMPLE_HEAD.pack(timestamp_us % TIMESTAMP_MODULUS, len(items), size) + recs
    return encode_frame(FrameType.SAMPLE, seq, payload)


def encode_command(seq: int, command: CommandType | int, value: int | None = None) -> bytes:
    """Encode a host command; ``value`` is required for SET_RATE, SET_SENSORS (u16) and
    SET_FIELDS (u8) only."""
    command = CommandType(command)
    size = _COMMAND_ARG[command]
    if size:
        if value is None:
            raise ValueError(f"{command.name} needs a value")
        if size == 1:
            if not (isinstance(value, int) and 0 <= value <= 0xFF):
                raise ValueError(f"{command.name} value must be an int in 0..255, got {value!r}")
            payload = bytes([value])
        else:
            payload = struct.pack("<H", _check_u16(value, f"{command.name} value"))
    else:
        if value is not None:
            raise ValueError(f"{command.name} takes no value")
        payload = b""
    return encode_frame(command, seq, payload)


def encode_ack(seq: int, command_seq: int, command: int, data: bytes = b"") -> bytes:
    """Encode an ACK for the command ``command_seq`` of type ``command``, with reply ``data``."""
    _check_u16(command_seq, "command_seq")
    return encode_frame(FrameType.ACK, seq, struct.pack("<HB", command_seq, command) + data)


def encode_nak(seq: int, command_seq: int, command: int, error: ErrorCode | int) -> bytes:
    """Encode a NAK refusing the command ``command_seq`` with ``error``."""
    _check_u16(command_seq, "command_seq")
    return encode_frame(FrameType.NAK, seq, struct.pack("<HBB", command_seq, command, int(error)))


def encode_identity(identity: Identity) -> bytes:
    """The 20 reply-data bytes of an IDENTIFY ACK."""
    i = identity
    return Identity._FORMAT.pack(
        i.protocol_major, i.protocol_minor, i.firmware_version, i.serial, i.max_sensors,
        1 if i.streaming else 0, i.present_mask, i.active_mask, i.rate_hz, i.min_rate_hz,
        i.max_rate_hz,
    )


# --------------------------------------------------------------------------------------------
# decoders

_HEAD = struct.Struct("<BBH")
_U32 = struct.Struct("<I")
_ACK_HEAD = struct.Struct("<HB")
_NAK = struct.Struct("<HBB")


def decode_body(body: bytes) -> Frame:
    """Decode a frame body (COBS already removed): size, CRC, version, then fields.

    Raises
    ------
    FramingError
        Shorter than 8 bytes or longer than :data:`MAX_BODY`.
    ChecksumError
        CRC mismatch.
    FrameContentError (a PacketError)
        Other major version, or a payload inconsistent with its type.
    """
    n = len(body)
    if n < HEADER_SIZE + CRC_SIZE:
        raise FramingError(f"frame body of {n} bytes is shorter than the 8-byte minimum")
    if n > MAX_BODY:
        raise FramingError(f"frame body of {n} bytes exceeds {MAX_BODY}")
    (received,) = _U32.unpack_from(body, n - CRC_SIZE)
    computed = zlib.crc32(memoryview(body)[: n - CRC_SIZE]) & 0xFFFFFFFF
    if received != computed:
        raise ChecksumError(received, computed, what="CRC-32")
    version, ftype, seq = _HEAD.unpack_from(body)
    if version != PROTOCOL_MAJOR:
        raise FrameContentError("unsupported protocol major version", seq=seq,
                                frame_type=ftype, code=ErrorCode.UNSUPPORTED_VERSION,
                                actual=version, expected=PROTOCOL_MAJOR)
    payload = body[HEADER_SIZE : n - CRC_SIZE]
    if ftype == FrameType.SAMPLE:
        return _decode_sample(seq, payload)
    if ftype == FrameType.ACK:
        if len(payload) < _ACK_HEAD.size:
            raise FrameContentError("ACK payload length", seq=seq, frame_type=ftype,
                                    code=ErrorCode.BAD_LENGTH, actual=len(payload),
                                    expected=">= 3")
        cseq, cmd = _ACK_HEAD.unpack_from(payload)
        return Ack(seq, cseq, cmd, bytes(payload[_ACK_HEAD.size :]))
    if ftype == FrameType.NAK:
        if len(payload) < _NAK.size:
            raise FrameContentError("NAK payload length", seq=seq, frame_type=ftype,
                                    code=ErrorCode.BAD_LENGTH, actual=len(payload),
                                    expected=">= 4")
        cseq, cmd, err = _NAK.unpack_from(payload)
        return Nak(seq, cseq, cmd, err)
    if ftype in _COMMAND_ARG_BY_INT:
        command = CommandType(ftype)
        size = _COMMAND_ARG_BY_INT[ftype]
        # exact length: a device must refuse arguments it does not understand (BAD_LENGTH)
        if len(payload) != size:
            raise FrameContentError(f"{command.name} payload length", seq=seq, frame_type=ftype,
                                    code=ErrorCode.BAD_LENGTH, actual=len(payload),
                                    expected=size)
        value = int.from_bytes(payload, "little") if size else None
        return Command(seq, command, value)
    return UnknownFrame(seq, ftype, bytes(payload))


_COMMAND_ARG_BY_INT = {int(k): v for k, v in _COMMAND_ARG.items()}


def _decode_sample(seq: int, payload: bytes) -> Sample:
    if len(payload) < _SAMPLE_HEAD.size:
        raise _sample_error(seq, "SAMPLE payload length", actual=len(payload), expected=">= 6")
    ts, count, rsize = _SAMPLE_HEAD.unpack_from(payload)
    if count > MAX_SENSORS:
        raise _sample_error(seq, "SAMPLE sensor count", actual=count, expected=f"<= {MAX_SENSORS}")
    if rsize < RECORD_SIZE:
        raise _sample_error(seq, "SAMPLE record size", actual=rsize, expected=f">= {RECORD_SIZE}")
    need = _SAMPLE_HEAD.size + count * rsize
    if len(payload) < need:
        raise _sample_error(seq, "SAMPLE payload length", actual=len(payload),
                            expected=f">= {need}")
    readings = []
    last = -1
    off = _SAMPLE_HEAD.size
    scale = 1.0 / QUATERNION_SCALE
    for _ in range(count):
        sid, calib, flags, w, x, y, z = _RECORD.unpack_from(payload, off)
        if sid >= MAX_SENSORS or sid <= last:
            raise _sample_error(seq, "SAMPLE sensor ids must increase within 0..15",
                                actual=sid, expected=f"> {last}")
        last = sid
        raw = None
        if rsize >= RAW_RECORD_SIZE:
            raw = tuple(v * k for v, k in zip(_RAW.unpack_from(payload, off + RECORD_SIZE),
                                               _RAW_UNIT, strict=True))
        readings.append(SensorReading(sid, calib, flags, (w * scale, x * scale, y * scale,
                                                          z * scale), raw))
        off += rsize
    return Sample(seq, ts, tuple(readings))


def _sample_error(seq: int, message: str, actual=None, expected=None) -> FrameContentError:
    return FrameContentError(message, seq=seq, frame_type=FrameType.SAMPLE,
                             code=ErrorCode.BAD_LENGTH, actual=actual, expected=expected)


def decode_frame(data: bytes) -> Frame:
    """Decode one wire frame: COBS bytes with or without the trailing 0x00 delimiter."""
    buf = bytes(data)
    if buf.endswith(b"\x00"):
        buf = buf[:-1]
    if len(buf) > MAX_ENCODED:
        raise FramingError(f"encoded frame of {len(buf)} bytes exceeds {MAX_ENCODED}")
    return decode_body(cobs.decode(buf))


class StreamDecoder:
    """Streaming decoder: bytes in any pieces → frames, with resynchronisation at 0x00.

    Call :meth:`feed` with received bytes, then :meth:`next` until it returns None. ``next``
    returns a frame (or a :class:`Gap`), returns None when it needs more bytes, or raises a
    :class:`~firmware_protocol.errors.ProtocolError` for one bad frame — which it has already
    dropped, so the next call carries on with the following frame. Garbage therefore costs at
    most the frame it corrupts: decoding restarts after the next 0x00.

    Parameters
    ----------
    track_sequence : bool
        Emit a :class:`Gap` before a frame whose ``seq`` is not the previous one + 1 (mod 2**16).
        Meant for the host side, where one device's frames arrive in order.

    Attributes
    ----------
    frames, errors, gaps, lost : int
        Counts of frames decoded, bad frames dropped, gaps seen and frames lost in gaps.
    """

    def __init__(self, *, track_sequence: bool = True) -> None:
        self.track_sequence = track_sequence
        self._buf = bytearray()
        self._scan = 0  # bytes of _buf already known to hold no delimiter
        self._discarding = False
        self._expected: int | None = None
        self._pending: Frame | None = None
        self.frames = 0
        self.errors = 0
        self.gaps = 0
        self.lost = 0

    @property
    def buffered(self) -> int:
        """Bytes held that do not yet form a complete frame."""
        return len(self._buf)

    def feed(self, data: bytes | bytearray | memoryview) -> None:
        """Append received bytes."""
        self._buf += data

    def reset_sequence(self) -> None:
        """Forget the expected ``seq`` (e.g. after reopening the port)."""
        self._expected = None

    def next(self) -> Frame | Gap | None:
        """The next frame or gap, None if more bytes are needed; raises for one bad frame."""
        if self._pending is not None:
            frame, self._pending = self._pending, None
            return frame
        buf = self._buf
        while True:
            end = buf.find(0, self._scan)
            if end < 0:
                self._scan = len(buf)
                if len(buf) > MAX_ENCODED and not self._discarding:
                    del buf[:]
                    self._scan = 0
                    self._discarding = True
                    self.errors += 1
                    raise FramingError(
                        f"no 0x00 delimiter within {MAX_ENCODED} bytes; discarding to the next one"
                    )
                if self._discarding:
                    del buf[:]
                    self._scan = 0
                return None
            chunk = bytes(buf[:end])
            del buf[: end + 1]
            self._scan = 0
            if self._discarding:
                self._discarding = False
                continue
            if not chunk:
                continue  # empty frame: extra delimiters are allowed (SPEC §3)
            try:
                frame = decode_frame(chunk)
            except (FramingError, ChecksumError, PacketError):
                self.errors += 1
                raise
            self.frames += 1
            return self._sequence(frame)

    def _sequence(self, frame: Frame) -> Frame | Gap:
        if not self.track_sequence:
            return frame
        expected = self._expected
        self._expected = (frame.seq + 1) % _SEQ_MOD
        if expected is None or frame.seq == expected:
            return frame
        lost = (frame.seq - expected) % _SEQ_MOD
        self.gaps += 1
        if lost < _SEQ_MOD // 2:
            self.lost += lost
        self._pending = frame
        return Gap(expected, frame.seq, lost)

    def drain(self) -> list[Frame | Gap]:
        """All complete frames and gaps now available; bad frames are counted in ``errors``."""
        out: list[Frame | Gap] = []
        while True:
            try:
                item = self.next()
            except (FramingError, ChecksumError, PacketError):
                continue
            if item is None:
                return out
            out.append(item)


class TimestampUnwrapper:
    """Turn u32 microsecond timestamps into a monotonic int64 count.

    Consecutive timestamps are assumed less than 2**31 µs (≈ 35.8 min) apart, so the forward
    difference modulo 2**32 is the elapsed time. The first timestamp is returned unchanged.
    """

    def __init__(self) -> None:
        self._last_raw: int | None = None
        self._value = 0

    def __call__(self, timestamp_us: int) -> int:
        if self._last_raw is None:
            self._value = timestamp_us
        else:
            delta = (timestamp_us - self._last_raw) % TIMESTAMP_MODULUS
            if delta >= TIMESTAMP_MODULUS // 2:
                delta -= TIMESTAMP_MODULUS  # an older frame: step back, do not add 71 minutes
            self._value += delta
        self._last_raw = timestamp_us
        return self._value
