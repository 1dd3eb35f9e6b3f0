"""Host driver for a Bosch BNO055 on a USB-UART (its UART register protocol, no custom firmware).

The same class drives real hardware (``/dev/ttyUSB0``) and :class:`rig.sim.imu.Bno055Simulator`
(its ``/dev/pts/N``). Every transaction is one request and one response with a monotonic
deadline; the chip's transient ``BUS_OVER_RUN_ERROR`` answer (datasheet 4.7: the host should
retry) is retried a bounded number of times.
"""

from __future__ import annotations

import time

import numpy as np
import serial

from firmware_protocol.errors import ProtocolError
from firmware_protocol.imu import bno055 as B
from rig.errors import RigConnectionError, RigError, RigTimeoutError


class Bno055:
    """A BNO055 in UART mode.

    Parameters
    ----------
    port : str
        Serial port (``/dev/ttyUSB0``, or a simulator's pty).
    baudrate : int
        The chip's UART runs at 115200 bit/s.
    timeout : float
        Seconds to wait for each response.
    retries : int
        Extra attempts after a ``BUS_OVER_RUN_ERROR`` or a garbled response.
    """

    def __init__(
        self, port: str, *, baudrate: int = 115200, timeout: float = 0.2, retries: int = 3
    ):
        self.port = port
        self.timeout = timeout
        self.retries = retries
        try:
            self._serial = serial.Serial(port, baudrate=baudrate, timeout=0)
        except (serial.SerialException, OSError) as err:
            raise RigConnectionError(f"{port}: cannot open the BNO055 port ({err})") from err
        self._decoder = B.ResponseDecoder()

    # -- lifecycle --------------------------------------------------------------------------
    def close(self) -> None:
        """Close the port (idempotent)."""
        if self._serial.is_open:
            self._serial.close()

    def __enter__(self) -> Bno055:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # -- transactions -------------------------------------------------------------------------
    def _transact(self, request: bytes, expected_length: int | None):
        last: Exception | None = None
        for _ in range(self.retries + 1):
            self._serial.reset_input_buffer()
            self._decoder = B.ResponseDecoder()
            self._serial.write(request)
            deadline = time.monotonic() + self.timeout
            try:
                resp = self._receive(deadline)
            except ProtocolError as err:  # garbled answer: ask again
                last = err
                continue
            if isinstance(resp, B.StatusResponse) and resp.status == B.Status.BUS_OVER_RUN_ERROR:
                last = RigError(f"{self.port}: BNO055 bus over-run")
                continue
            if (
                expected_length is not None
                and isinstance(resp, B.ReadResponse)
                and len(resp.data) != expected_length
            ):
                last = RigError(
                    f"{self.port}: BNO055 answered {len(resp.data)} bytes, "
                    f"expected {expected_length}"
                )
                continue
            return resp
        if isinstance(last, RigTimeoutError):
            raise last
        raise RigError(
            f"{self.port}: BNO055 transaction failed after {self.retries + 1} attempts: {last}"
        )

    def _receive(self, deadline: float):
        while True:
            resp = self._decoder.next()
            if resp is not None:
                return resp
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise RigTimeoutError(
                    f"{self.port}: no answer from the BNO055 within {self.timeout * 1e3:.0f} ms"
                )
            self._serial.timeout = remaining
            chunk = self._serial.read(max(1, self._serial.in_waiting))
            if chunk:
                self._decoder.feed(chunk)

    def read(self, register: int, length: int) -> bytes:
        """Read ``length`` bytes from ``register`` (page 0)."""
        resp = self._transact(B.encode_read(register, length), length)
        if isinstance(resp, B.StatusResponse):
            raise RigError(
                f"{self.port}: BNO055 refused to read 0x{register:02X}: {_status_name(resp.status)}"
            )
        return resp.data

    def write(self, register: int, data: bytes) -> None:
        """Write ``data`` to ``register``; raises unless the chip answers WRITE_SUCCESS."""
        resp = self._transact(B.encode_write(register, data), None)
        if not (isinstance(resp, B.StatusResponse) and resp.status == B.Status.WRITE_SUCCESS):
            what = _status_name(resp.status) if isinstance(resp, B.StatusResponse) else resp
            raise RigError(f"{self.port}: BNO055 write to 0x{register:02X} failed: {what}")

    # -- conveniences -------------------------------------------------------------------------
    def chip_id(self) -> int:
        return self.read(B.Register.CHIP_ID, 1)[0]

    def set_mode(self, mode: B.OperationMode) -> None:
        """Switch operation mode (through CONFIG, as the datasheet requires)."""
        self.write(B.Register.OPR_MODE, bytes([B.OperationMode.CONFIG]))
        if mode != B.OperationMode.CONFIG:
            self.write(B.Register.OPR_MODE, bytes([int(mode)]))

    def quaternion(self) -> np.ndarray:
        """Fused orientation, scalar-first (w, x, y, z), sensor relative to the chip's world
        frame, normalised (the registers carry 1/16384 resolution)."""
        q = np.array(B.decode_quaternion(self.read(B.Register.QUA_DATA, 8)))
        n = float(np.linalg.norm(q))
        if n < 0.5:
            raise RigError(
                f"{self.port}: BNO055 quaternion registers read {q.tolist()} "
                "(not in a fusion mode?)"
            )
        return q / n

    def calibration(self) -> B.CalibrationStatus:
        return B.CalibrationStatus.from_byte(self.read(B.Register.CALIB_STAT, 1)[0])


def _status_name(code: int) -> str:
    try:
        return B.Status(code).name
    except ValueError:
        return f"status 0x{code:02X}"
