"""Host driver for a Bosch BNO055 on a USB-UART (its UART register protocol, no custom firmware).

The same class drives real hardware (``/dev/ttyUSB0``) and the simulator (``sim://bno055``).
Every transaction is one request and one response with a monotonic deadline (the
:class:`~rig.devices.base.Device` template): a timeout, a garbled response and the chip's
transient ``BUS_OVER_RUN_ERROR`` (datasheet 4.7: the host should retry) are retried a bounded
number of times, then raised as :class:`~rig.errors.RigTimeoutError` /
:class:`~rig.errors.RigProtocolError`. Opening reads CHIP_ID, so a wrong port or a silent chip
fails at once.

:meth:`Bno055.sample` reads quaternion (0x20-0x27) through CALIB_STAT (0x35) in one 22-byte
transaction; with ``raw=True`` it reads ACC_DATA (0x08) through CALIB_STAT in one 46-byte
transaction (accelerometer, magnetometer, gyroscope, Euler angles, quaternion, ..., status) and
returns the raw readings in SI units, converted with the chip's ``UNIT_SEL`` (read at open).
"""

from __future__ import annotations

import time

import numpy as np
import serial

from firmware_protocol.errors import ProtocolError
from firmware_protocol.imu import bno055 as B
from rig.devices.base import Device, close_serial, open_serial
from rig.devices.ports import Port
from rig.devices.stream_imu import ImuSample
from rig.errors import RigConnectionError, RigError, RigProtocolError, RigTimeoutError

__all__ = ["Bno055"]

_CONNECTION_ERRORS = (OSError, serial.SerialException)


class Bno055(Device):
    """A BNO055 in UART mode.

    Parameters
    ----------
    port : str or Port
        ``/dev/ttyUSB0``, ``sim://bno055?...``, or an opened Port.
    baud : int
        The chip's UART runs at 115200 bit/s.
    timeout : float
        Seconds to wait for each response.
    retries : int
        Extra attempts after a timeout, a garbled response or ``BUS_OVER_RUN_ERROR``.
    sensor : int
        Index reported in :class:`~rig.devices.stream_imu.ImuSample.sensor`.
    raw : bool
        :meth:`sample` also returns the raw accelerometer, gyroscope and magnetometer readings
        (:attr:`~rig.devices.stream_imu.ImuSample.raw`: m/s², rad/s, µT, sensor frame).
    """

    kind = "BNO055"
    default_timeout = 0.2
    default_retries = 3

    def __init__(self, port: str | Port, *, baud: int = 115200, timeout: float | None = None,
                 retries: int | None = None, sensor: int = 0, raw: bool = False) -> None:
        self.sensor = sensor
        self.raw = bool(raw)
        self._units = 0x80
        self._serial: serial.Serial | None = None
        super().__init__(port, baud=baud, timeout=timeout, retries=retries)

    def _open(self) -> None:
        url = str(self.port)
        self._serial = open_serial(self.path, self.baud, what="the BNO055 port", url=url)
        self._decoder = B.ResponseDecoder()
        chip = self.chip_id()
        if chip != B.CHIP_ID_VALUE:
            raise RigProtocolError("this is not a BNO055 (CHIP_ID)", port=url,
                                   actual=f"0x{chip:02X}", expected=f"0x{B.CHIP_ID_VALUE:02X}")
        if self.raw:
            self._units = self.read(B.Register.UNIT_SEL, 1)[0]

    def _close(self) -> None:
        ser, self._serial = self._serial, None
        close_serial(ser)

    # -- transactions ---------------------------------------------------------------------
    def _attempt(self, request: bytes, expected_length: int | None, deadline: float):
        ser = self._serial
        assert ser is not None
        try:
            ser.reset_input_buffer()
            self._decoder = B.ResponseDecoder()
            ser.write(request)
            resp = self._receive(deadline)
        except RigError:  # RigTimeoutError is an OSError too: not a connection failure
            raise
        except _CONNECTION_ERRORS as err:
            raise RigConnectionError(f"the BNO055 port failed ({err})",
                                     port=str(self.port)) from err
        if isinstance(resp, B.StatusResponse) and resp.status == B.Status.BUS_OVER_RUN_ERROR:
            raise RigProtocolError("BNO055 bus over-run", port=str(self.port))
        if (expected_length is not None and isinstance(resp, B.ReadResponse)
                and len(resp.data) != expected_length):
            raise RigProtocolError("BNO055 answered the wrong number of bytes",
                                   port=str(self.port), actual=len(resp.data),
                                   expected=expected_length)
        return resp

    def _receive(self, deadline: float):
        ser = self._serial
        assert ser is not None
        while True:
            try:
                resp = self._decoder.next()
            except ProtocolError as err:  # garbled answer: the attempt failed, ask again
                raise RigProtocolError(f"garbled BNO055 answer ({err})",
                                       port=str(self.port)) from err
            if resp is not None:
                return resp
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise RigTimeoutError(f"no answer from the BNO055 within "
                                      f"{self.timeout * 1e3:.0f} ms", port=str(self.port))
            ser.timeout = remaining
            chunk = ser.read(max(1, ser.in_waiting))
            if chunk:
                self._decoder.feed(chunk)

    def _transact(self, request: bytes, expected_length: int | None, what: str):
        return self.transact(lambda d: self._attempt(request, expected_length, d), what)

    def read(self, register: int, length: int) -> bytes:
        """Read ``length`` bytes from ``register`` (current page)."""
        resp = self._transact(B.encode_read(register, length), length,
                              f"read of 0x{register:02X}")
        if isinstance(resp, B.StatusResponse):
            raise RigError(f"BNO055 refused to read 0x{register:02X}: "
                           f"{_status_name(resp.status)}", port=str(self.port))
        return resp.data

    def write(self, register: int, data: bytes) -> None:
        """Write ``data`` to ``register``; raises unless the chip answers WRITE_SUCCESS."""
        resp = self._transact(B.encode_write(register, data), None,
                              f"write to 0x{register:02X}")
        if not (isinstance(resp, B.StatusResponse) and resp.status == B.Status.WRITE_SUCCESS):
            what = _status_name(resp.status) if isinstance(resp, B.StatusResponse) else resp
            raise RigError(f"BNO055 write to 0x{register:02X} failed: {what}",
                           port=str(self.port))
        unit_sel = int(B.Register.UNIT_SEL) - register
        if 0 <= unit_sel < len(data):
            self._units = data[unit_sel]  # raw readings are converted with the units in force

    # -- conveniences ---------------------------------------------------------------------
    def chip_id(self) -> int:
        return self.read(B.Register.CHIP_ID, 1)[0]

    def set_mode(self, mode: B.OperationMode) -> None:
        """Switch operation mode (through CONFIG, as the datasheet requires)."""
        self.write(B.Register.OPR_MODE, bytes([B.OperationMode.CONFIG]))
        if mode != B.OperationMode.CONFIG:
            self.write(B.Register.OPR_MODE, bytes([int(mode)]))

    @staticmethod
    def _unit(q: np.ndarray, port: str) -> np.ndarray:
        n = float(np.linalg.norm(q))
        if n < 0.5:
            raise RigError(f"BNO055 quaternion registers read {q.tolist()} "
                           "(not in a fusion mode?)", port=port)
        return q / n

    def quaternion(self) -> np.ndarray:
        """Fused orientation (4,) float64, scalar-first (w, x, y, z), sensor relative to the
        chip's world frame, normalised (the registers carry 1/16384 resolution)."""
        q = np.array(B.decode_quaternion(self.read(B.Register.QUA_DATA, 8)))
        return self._unit(q, str(self.port))

    def calibration(self) -> B.CalibrationStatus:
        return B.CalibrationStatus.from_byte(self.read(B.Register.CALIB_STAT, 1)[0])

    def sample(self) -> ImuSample:
        """Quaternion and calibration status (and with ``raw`` the raw readings) in one
        transaction, host-timestamped (the time half-way through the transaction; the chip has
        no clock to report)."""
        t0 = time.monotonic()
        first = int(B.Register.ACC_DATA if self.raw else B.Register.QUA_DATA)
        data = self.read(first, int(B.Register.CALIB_STAT) - first + 1)
        t = 0.5 * (t0 + time.monotonic())
        q_at = int(B.Register.QUA_DATA) - first
        q = self._unit(np.array(B.decode_quaternion(data[q_at:q_at + 8])), str(self.port))
        raw = self._raw(data[:18]) if self.raw else None
        return ImuSample(t, None, self.sensor, q, data[-1], raw=raw)

    def _raw(self, data: bytes) -> np.ndarray:
        """ACC_DATA, MAG_DATA, GYR_DATA (18 bytes from 0x08) → (acc m/s², gyr rad/s, mag µT)
        with the UNIT_SEL in force: acceleration 100 LSB/(m/s²) or 1 LSB/mg (bit 0), rate
        16 LSB/(°/s) or 900 LSB/(rad/s) (bit 1), magnetic field 16 LSB/µT."""
        acc = np.array(B.decode_vector(data[0:6], 1.0))
        acc *= 9.80665e-3 if self._units & 0x01 else 0.01
        mag = np.array(B.decode_vector(data[6:12], 16.0))
        if self._units & 0x02:
            gyr = np.array(B.decode_vector(data[12:18], 900.0))
        else:
            gyr = np.radians(B.decode_vector(data[12:18], 16.0))
        return np.concatenate([acc, gyr, mag])


def _status_name(code: int) -> str:
    try:
        return B.Status(code).name
    except ValueError:
        return f"status 0x{code:02X}"
