"""Bosch BNO055 UART register protocol (datasheet BST-BNO055-DS000, section 4.7).

With ``PS1 = 1, PS0 = 0`` the BNO055 speaks a register protocol on its UART (115200 8N1). The
host starts every transaction; the chip answers each one.

Host → chip::

    write   +------+------+-----+-----+--------------+
            | 0xAA | 0x00 | reg | len | data[0..len) |        1 <= len <= 128
            +------+------+-----+-----+--------------+
    read    +------+------+-----+-----+
            | 0xAA | 0x01 | reg | len |                      1 <= len <= 128
            +------+------+-----+-----+

Chip → host::

    status  +------+--------+           answer to every write (0x01 = WRITE_SUCCESS),
            | 0xEE | status |           and to a read that failed
            +------+--------+
    data    +------+-----+--------------+
            | 0xBB | len | data[0..len) |   answer to a read that succeeded
            +------+-----+--------------+

``reg`` addresses the register page selected by ``PAGE_ID`` (0x07). A read or write of ``len``
bytes covers registers ``reg .. reg + len - 1`` (auto-increment).

Register map (page 0, the subset the rig uses)::

    0x00 CHIP_ID (0xA0)   0x08-0x0D ACC x,y,z      0x35 CALIB_STAT  sys|gyr|acc|mag, 2 bits each
    0x07 PAGE_ID          0x0E-0x13 MAG x,y,z      0x39 SYS_STATUS  0x3A SYS_ERR  0x3B UNIT_SEL
                          0x14-0x19 GYR x,y,z      0x3D OPR_MODE    0x3E PWR_MODE 0x3F SYS_TRIGGER
                          0x1A-0x1F EUL h,r,p      0x41 AXIS_MAP_CONFIG  0x42 AXIS_MAP_SIGN
                          0x20-0x27 QUA w,x,y,z

Multi-byte values are little-endian signed 16-bit. Quaternion: 1 LSB = 2**-14; Euler angles:
16 LSB/° (900 LSB/rad with UNIT_SEL bit 2); angular rate: 16 LSB/(°/s) (900 LSB/(rad/s) with
UNIT_SEL bit 1); acceleration: 100 LSB/(m/s²) (1 LSB/mg with UNIT_SEL bit 0); magnetic field:
16 LSB/µT. Fusion data are valid only in the fusion modes (``OPR_MODE`` 0x08-0x0C); the
configuration registers can be written only in CONFIG mode (0x00).

Everything here is pure: bytes in, bytes out. Encoders build requests and responses; the two
streaming decoders (:class:`RequestDecoder` on the chip side, :class:`ResponseDecoder` on the
host side) accept input in arbitrary pieces, skip garbage, and raise only
:mod:`firmware_protocol.errors` types.
"""

from __future__ import annotations

import enum
import math
import struct
from collections.abc import Sequence
from dataclasses import dataclass

from firmware_protocol.errors import FramingError, PacketError

__all__ = [
    "CHIP_ID_VALUE",
    "FUSION_MODES",
    "MAX_LENGTH",
    "QUATERNION_SCALE",
    "READ",
    "READ_RESPONSE",
    "START",
    "STATUS_RESPONSE",
    "WRITE",
    "Bno055FramingError",
    "CalibrationStatus",
    "OperationMode",
    "ReadRequest",
    "ReadResponse",
    "Register",
    "RequestDecoder",
    "ResponseDecoder",
    "Status",
    "StatusResponse",
    "WriteRequest",
    "decode_quaternion",
    "decode_request",
    "decode_response",
    "decode_vector",
    "encode_quaternion",
    "encode_read",
    "encode_read_response",
    "encode_status",
    "encode_vector",
    "encode_write",
]

START = 0xAA
"""First byte of every host request."""
WRITE = 0x00
"""Request type: register write."""
READ = 0x01
"""Request type: register read."""
READ_RESPONSE = 0xBB
"""First byte of a successful read response."""
STATUS_RESPONSE = 0xEE
"""First byte of a status response (write acknowledgement or failure)."""
MAX_LENGTH = 128
"""Largest ``len`` of one request (datasheet table 4-8)."""

CHIP_ID_VALUE = 0xA0
"""Content of ``CHIP_ID`` (0x00) on every BNO055."""

QUATERNION_SCALE = 1 << 14
"""Quaternion LSB per unit: 1 LSB = 1/16384."""


class Status(enum.IntEnum):
    """Status byte of a ``0xEE`` response (datasheet table 4-8)."""

    WRITE_SUCCESS = 0x01
    READ_FAIL = 0x02
    WRITE_FAIL = 0x03
    REGMAP_INVALID_ADDRESS = 0x04
    REGMAP_WRITE_DISABLED = 0x05
    WRONG_START_BYTE = 0x06
    BUS_OVER_RUN_ERROR = 0x07
    MAX_LENGTH_ERROR = 0x08
    MIN_LENGTH_ERROR = 0x09
    RECEIVE_CHARACTER_TIMEOUT = 0x0A


class Register(enum.IntEnum):
    """Page-0 register addresses used by the rig."""

    CHIP_ID = 0x00
    ACC_ID = 0x01
    MAG_ID = 0x02
    GYR_ID = 0x03
    SW_REV_ID_LSB = 0x04
    SW_REV_ID_MSB = 0x05
    BL_REV_ID = 0x06
    PAGE_ID = 0x07
    ACC_DATA = 0x08
    MAG_DATA = 0x0E
    GYR_DATA = 0x14
    EUL_DATA = 0x1A
    QUA_DATA = 0x20
    LIA_DATA = 0x28
    GRV_DATA = 0x2E
    TEMP = 0x34
    CALIB_STAT = 0x35
    ST_RESULT = 0x36
    INT_STA = 0x37
    SYS_CLK_STATUS = 0x38
    SYS_STATUS = 0x39
    SYS_ERR = 0x3A
    UNIT_SEL = 0x3B
    OPR_MODE = 0x3D
    PWR_MODE = 0x3E
    SYS_TRIGGER = 0x3F
    TEMP_SOURCE = 0x40
    AXIS_MAP_CONFIG = 0x41
    AXIS_MAP_SIGN = 0x42


class OperationMode(enum.IntEnum):
    """``OPR_MODE`` values (datasheet table 3-5)."""

    CONFIG = 0x00
    ACCONLY = 0x01
    MAGONLY = 0x02
    GYROONLY = 0x03
    ACCMAG = 0x04
    ACCGYRO = 0x05
    MAGGYRO = 0x06
    AMG = 0x07
    IMU = 0x08
    COMPASS = 0x09
    M4G = 0x0A
    NDOF_FMC_OFF = 0x0B
    NDOF = 0x0C


FUSION_MODES = frozenset(
    {
        OperationMode.IMU,
        OperationMode.COMPASS,
        OperationMode.M4G,
        OperationMode.NDOF_FMC_OFF,
        OperationMode.NDOF,
    }
)
"""Modes in which the fusion outputs (quaternion, Euler angles) are valid."""


class Bno055FramingError(FramingError):
    """A request the chip cannot parse; ``status`` is what a BNO055 answers (``0xEE status``)."""

    def __init__(self, message: str, status: Status):
        self.status = status
        super().__init__(f"{message} [{status.name}]")


@dataclass(frozen=True)
class WriteRequest:
    """Host → chip: write ``data`` to ``register`` and the following addresses."""

    register: int
    data: bytes


@dataclass(frozen=True)
class ReadRequest:
    """Host → chip: read ``length`` bytes from ``register`` onwards."""

    register: int
    length: int


@dataclass(frozen=True)
class StatusResponse:
    """Chip → host: ``0xEE status``. ``ok`` is True only for ``WRITE_SUCCESS``."""

    status: int

    @property
    def ok(self) -> bool:
        return self.status == Status.WRITE_SUCCESS


@dataclass(frozen=True)
class ReadResponse:
    """Chip → host: ``0xBB len data``."""

    data: bytes


@dataclass(frozen=True)
class CalibrationStatus:
    """``CALIB_STAT`` fields, each 0 (uncalibrated) to 3 (fully calibrated)."""

    system: int
    gyroscope: int
    accelerometer: int
    magnetometer: int

    def __post_init__(self) -> None:
        for name in ("system", "gyroscope", "accelerometer", "magnetometer"):
            value = getattr(self, name)
            if not (isinstance(value, int) and 0 <= value <= 3):
                raise ValueError(f"calibration {name} must be an int in 0..3, got {value!r}")

    def to_byte(self) -> int:
        """Pack as ``sys<<6 | gyr<<4 | acc<<2 | mag``."""
        return (
            (self.system << 6) | (self.gyroscope << 4) | (self.accelerometer << 2)
            | self.magnetometer
        )

    @classmethod
    def from_byte(cls, value: int) -> CalibrationStatus:
        """Unpack a ``CALIB_STAT`` byte."""
        if not 0 <= value <= 0xFF:
            raise PacketError("CALIB_STAT is one byte", actual=value, expected="0..255")
        return cls((value >> 6) & 3, (value >> 4) & 3, (value >> 2) & 3, value & 3)

    @property
    def fully_calibrated(self) -> bool:
        return self.to_byte() == 0xFF


# --------------------------------------------------------------------------------------------
# encoders


def _check_register(register: int) -> None:
    if not (isinstance(register, int) and 0 <= register <= 0xFF):
        raise ValueError(f"register address must be an int in 0x00..0xFF, got {register!r}")


def _check_length(length: int) -> None:
    if not (isinstance(length, int) and 1 <= length <= MAX_LENGTH):
        raise ValueError(f"length must be an int in 1..{MAX_LENGTH}, got {length!r}")


def encode_write(register: int, data: bytes | Sequence[int]) -> bytes:
    """Host write request ``AA 00 reg len data...``.

    Raises
    ------
    ValueError
        Register outside 0..255 or ``len(data)`` outside 1..128.
    """
    _check_register(register)
    payload = bytes(data)
    _check_length(len(payload))
    return bytes((START, WRITE, register, len(payload))) + payload


def encode_read(register: int, length: int) -> bytes:
    """Host read request ``AA 01 reg len``."""
    _check_register(register)
    _check_length(length)
    return bytes((START, READ, register, length))


def encode_status(status: int) -> bytes:
    """Chip status response ``EE status``."""
    if not 0 <= int(status) <= 0xFF:
        raise ValueError(f"status must be one byte, got {status!r}")
    return bytes((STATUS_RESPONSE, int(status)))


def encode_read_response(data: bytes | Sequence[int]) -> bytes:
    """Chip read response ``BB len data...``."""
    payload = bytes(data)
    _check_length(len(payload))
    return bytes((READ_RESPONSE, len(payload))) + payload


# --------------------------------------------------------------------------------------------
# value codecs


def encode_quaternion(q: Sequence[float]) -> bytes:
    """Quaternion register bytes (8, ``QUA_DATA``) from a scalar-first ``(w, x, y, z)``.

    Components are rounded to 1/16384 and saturated to the int16 range.
    """
    return encode_vector(q, QUATERNION_SCALE, count=4)


def decode_quaternion(data: bytes) -> tuple[float, float, float, float]:
    """Scalar-first ``(w, x, y, z)`` from the 8 ``QUA_DATA`` bytes (not renormalised)."""
    w, x, y, z = decode_vector(data, QUATERNION_SCALE, count=4)
    return (w, x, y, z)


def encode_vector(values: Sequence[float], lsb_per_unit: float, count: int = 3) -> bytes:
    """Little-endian int16 register bytes for ``count`` values scaled by ``lsb_per_unit``.

    Used for Euler angles (16 LSB/°), angular rate (16 LSB/(°/s)) and the quaternion
    (16384 LSB/unit). Values saturate at the int16 limits; NaN is a ``ValueError``.
    """
    vals = [float(v) for v in values]
    if len(vals) != count:
        raise ValueError(f"expected {count} values, got {len(vals)}")
    raw = []
    for v in vals:
        if math.isnan(v):
            raise ValueError("cannot encode NaN")
        raw.append(max(-32768, min(32767, round(v * lsb_per_unit))))
    return struct.pack(f"<{count}h", *raw)


def decode_vector(data: bytes, lsb_per_unit: float, count: int = 3) -> tuple[float, ...]:
    """Values from ``2 * count`` little-endian int16 register bytes divided by ``lsb_per_unit``.

    Raises
    ------
    PacketError
        ``data`` is not exactly ``2 * count`` bytes.
    """
    if len(data) != 2 * count:
        raise PacketError("wrong register data length", actual=len(data), expected=2 * count)
    return tuple(v / lsb_per_unit for v in struct.unpack(f"<{count}h", bytes(data)))


# --------------------------------------------------------------------------------------------
# single-message decoders


def decode_request(data: bytes) -> WriteRequest | ReadRequest:
    """Decode exactly one host request (no trailing bytes).

    Raises
    ------
    Bno055FramingError
        Wrong start byte, unknown request type, ``len`` 0 or > 128, truncated or over-long input;
        ``status`` tells what the chip answers.
    """
    dec = RequestDecoder()
    dec.feed(data)
    req = dec.next()
    if req is None:
        raise Bno055FramingError(
            f"incomplete request ({len(data)} bytes)", Status.RECEIVE_CHARACTER_TIMEOUT
        )
    if dec.buffered:
        raise Bno055FramingError(
            f"{dec.buffered} bytes after the request", Status.BUS_OVER_RUN_ERROR
        )
    return req


def decode_response(
    data: bytes, expected_length: int | None = None
) -> ReadResponse | StatusResponse:
    """Decode exactly one chip response.

    Parameters
    ----------
    data : bytes
        ``EE status`` or ``BB len data``.
    expected_length : int, optional
        For a read: the ``len`` that was requested; a data response of another length is a
        :class:`PacketError`.
    """
    dec = ResponseDecoder()
    dec.feed(data)
    resp = dec.next()
    if resp is None:
        raise FramingError(f"incomplete response ({len(data)} bytes): {bytes(data).hex(' ')}")
    if dec.buffered:
        raise FramingError(f"{dec.buffered} bytes after the response")
    if (
        expected_length is not None
        and isinstance(resp, ReadResponse)
        and len(resp.data) != expected_length
    ):
        raise PacketError("read response length", actual=len(resp.data), expected=expected_length)
    return resp


# --------------------------------------------------------------------------------------------
# streaming decoders


class _StreamBuffer:
    """Byte buffer with a read cursor; compacts lazily so feeding stays O(n)."""

    def __init__(self) -> None:
        self._buf = bytearray()
        self._pos = 0

    def feed(self, data: bytes | bytearray | memoryview) -> None:
        if self._pos and self._pos >= len(self._buf) // 2:
            del self._buf[: self._pos]
            self._pos = 0
        self._buf += data

    @property
    def buffered(self) -> int:
        return len(self._buf) - self._pos

    def clear(self) -> None:
        self._buf.clear()
        self._pos = 0


class RequestDecoder(_StreamBuffer):
    """Chip-side streaming decoder of host requests.

    Feed bytes as they arrive with :meth:`feed`, then call :meth:`next` until it returns None.
    Each call either returns one request, returns None (more bytes needed), or consumes one bad
    unit and raises :class:`Bno055FramingError` carrying the status a BNO055 answers; the next
    call carries on after it. A run of bytes other than 0xAA where a request should start is
    one bad unit (``WRONG_START_BYTE``; one reply per run, not per byte). A request left
    incomplete is dropped by :meth:`expire` (the chip's ``RECEIVE_CHARACTER_TIMEOUT``).
    """

    def next(self) -> WriteRequest | ReadRequest | None:
        buf, pos = self._buf, self._pos
        avail = len(buf) - pos
        if avail == 0:
            return None
        if buf[pos] != START:
            # one error per run of garbage, not per byte: a noisy line must not flood replies
            end = buf.find(START, pos + 1)
            end = len(buf) if end < 0 else end
            self._pos = end
            raise Bno055FramingError(
                f"expected start byte 0xAA, got 0x{buf[pos]:02X} ({end - pos} byte(s) skipped)",
                Status.WRONG_START_BYTE,
            )
        if avail < 2:
            return None
        kind = buf[pos + 1]
        if kind not in (READ, WRITE):
            self._pos = pos + 2
            raise Bno055FramingError(
                f"unknown request type 0x{kind:02X} (0x00 write, 0x01 read)",
                Status.WRONG_START_BYTE,
            )
        if avail < 4:
            return None
        register, length = buf[pos + 2], buf[pos + 3]
        if length == 0:
            self._pos = pos + 4
            raise Bno055FramingError("request length 0", Status.MIN_LENGTH_ERROR)
        if length > MAX_LENGTH:
            self._pos = pos + 4
            raise Bno055FramingError(
                f"request length {length} > {MAX_LENGTH}", Status.MAX_LENGTH_ERROR
            )
        if kind == READ:
            self._pos = pos + 4
            return ReadRequest(register, length)
        if avail < 4 + length:
            return None
        self._pos = pos + 4 + length
        return WriteRequest(register, bytes(buf[pos + 4 : pos + 4 + length]))

    def expire(self) -> bool:
        """Drop a partly received request after the inter-character timeout.

        Returns True if bytes were dropped (the chip then answers ``EE 0A``).
        """
        dropped = self.buffered > 0
        self.clear()
        return dropped


class ResponseDecoder(_StreamBuffer):
    """Host-side streaming decoder of chip responses.

    Same calling pattern as :class:`RequestDecoder`: :meth:`feed`, then :meth:`next` until None.
    A byte that cannot start a response (neither 0xEE nor 0xBB) is skipped with a
    :class:`FramingError`; a ``BB 00`` header (read responses carry 1..128 bytes) likewise.
    """

    def next(self) -> ReadResponse | StatusResponse | None:
        buf, pos = self._buf, self._pos
        avail = len(buf) - pos
        if avail == 0:
            return None
        head = buf[pos]
        if head not in (STATUS_RESPONSE, READ_RESPONSE):
            # skip the whole run of garbage at once: one error per run, not per byte
            end = pos + 1
            while end < len(buf) and buf[end] not in (STATUS_RESPONSE, READ_RESPONSE):
                end += 1
            self._pos = end
            raise FramingError(
                f"{end - pos} byte(s) that start no response (0xEE or 0xBB) skipped, "
                f"first 0x{head:02X}"
            )
        if avail < 2:
            return None
        second = buf[pos + 1]
        if head == STATUS_RESPONSE:
            self._pos = pos + 2
            return StatusResponse(second)
        if second == 0 or second > MAX_LENGTH:
            self._pos = pos + 2
            raise FramingError(f"read response length {second} outside 1..{MAX_LENGTH}")
        if avail < 2 + second:
            return None
        self._pos = pos + 2 + second
        return ReadResponse(bytes(buf[pos + 2 : pos + 2 + second]))
