"""Host driver for a multi-IMU board speaking the rig stream protocol (``firmware_protocol/imu``).

Start-up (each command answered by one ACK/NAK, SPEC §5): a 0x00 delimiter, ``STOP``,
``IDENTIFY`` (protocol major version and the sensors present are checked), ``SET_SENSORS``
(the wanted mask) and — on a 1.1 board — ``SET_FIELDS`` (RAW on with ``raw=True``, off
otherwise), ``SET_RATE``, ``START``. Then SAMPLE frames arrive at the rate; each becomes one
:class:`ImuSample` per sensor reading, with the raw readings in SI units when asked for.
``raw=True`` on a 1.0 board, or for more than 8 sensors, is a :class:`~rig.errors.RigConfigError`
at open.

* **Sequence gaps** (the device's u16 frame counter skipping) are counted in
  :attr:`StreamImu.dropped` — frames the host never saw (UART overrun, a full buffer, noise);
  garbled frames (CRC) in :attr:`StreamImu.corrupt`. Nothing is dropped silently.
* **Time**: the device's u32 µs timestamps are unwrapped (``TimestampUnwrapper``) into
  :attr:`ImuSample.device_t`; the host time of a sample is estimated as
  ``t = device_t + offset`` with ``offset`` the running minimum of ``t_received − device_t``
  (transport delay is never negative, and its minimum is the most faithful; the minimum may
  creep up by 100 ppm of elapsed time to follow clock drift).
* **Reconnect**: when the port fails (adapter replugged) or no sample arrives for
  ``silence_s``, the port is reopened and the start-up sequence repeated until
  ``reconnect_s`` has passed; then :class:`~rig.errors.RigConnectionError`.
"""

from __future__ import annotations

import time
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np
import serial

from firmware_protocol.errors import ProtocolError
from firmware_protocol.imu import stream as S
from rig.devices.base import Device, close_serial, open_serial
from rig.devices.ports import Port
from rig.errors import RigConfigError, RigConnectionError, RigProtocolError, RigTimeoutError

__all__ = ["ImuSample", "StreamImu"]

_CONNECTION_ERRORS = (OSError, serial.SerialException)


@dataclass(frozen=True)
class ImuSample:
    """One sensor's orientation at one instant.

    Attributes
    ----------
    t : float
        Host monotonic time of the reading (estimated from the device clock), s.
    device_t : float or None
        Device clock, s (unwrapped), None when the device has no clock (BNO055).
    sensor : int
        Sensor index on the device (or on the rig's list of BNO055 ports).
    q : (4,) float64
        Unit quaternion (w, x, y, z): sensor frame relative to the sensor's world frame.
    calibration : int
        BNO055 ``CALIB_STAT`` byte (``sys<<6 | gyr<<4 | acc<<2 | mag``).
    flags : int
        Stream-protocol reading flags (0 for a BNO055).
    raw : (9,) float64 or None
        Raw readings at the same instant, sensor frame: accelerometer (m/s², specific force),
        gyroscope (rad/s), magnetometer (µT); None unless the driver was opened with
        ``raw=True``.
    """

    t: float
    device_t: float | None
    sensor: int
    q: np.ndarray
    calibration: int
    flags: int = 0
    raw: np.ndarray | None = None


class StreamImu(Device):
    """A stream-protocol IMU board.

    Parameters
    ----------
    port : str or Port
    sensors : iterable of int, optional
        Sensor indices to stream (default: all present).
    rate_hz : int
        Sample rate asked of the device.
    baud : int
        UART rate (ignored by USB-CDC boards and ptys).
    silence_s : float
        No sample for this long while streaming triggers a reconnect.
    reconnect_s : float
        How long a reconnect may take before :class:`RigConnectionError`.
    raw : bool
        Ask the board for the raw accelerometer, gyroscope and magnetometer readings
        (protocol 1.1, at most 8 sensors); they arrive in :attr:`ImuSample.raw`.

    Attributes
    ----------
    identity : firmware_protocol.imu.stream.Identity
    dropped : int
        Frames lost (sequence gaps).
    corrupt : int
        Frames dropped for a bad CRC / framing.
    reconnects : int
    """

    kind = "stream IMU"
    default_timeout = 0.25
    default_retries = 3

    def __init__(self, port: str | Port, *, sensors: Iterable[int] | None = None,
                 rate_hz: int = 100, baud: int = 921600, timeout: float | None = None,
                 retries: int | None = None, silence_s: float = 0.5,
                 reconnect_s: float = 2.0, raw: bool = False) -> None:
        self.rate_hz = int(rate_hz)
        self.raw = bool(raw)
        self.wanted = None if sensors is None else sorted(set(int(s) for s in sensors))
        self.silence_s = float(silence_s)
        self.reconnect_s = float(reconnect_s)
        self.dropped = 0
        self.corrupt = 0
        self.reconnects = 0
        self._serial: serial.Serial | None = None
        self._cmd_seq = 0
        self._queue: list[ImuSample] = []
        super().__init__(port, baud=baud, timeout=timeout, retries=retries)

    # -- open / close ---------------------------------------------------------------------
    def _open(self) -> None:
        self._connect()

    def _connect(self) -> None:
        url = str(self.port)
        if self._serial is not None:
            self._drop_serial()
        self._serial = open_serial(self.path, self.baud, what="the IMU board port", url=url)
        self._decoder = S.StreamDecoder(track_sequence=True)
        self._unwrap = S.TimestampUnwrapper()
        self._offset: float | None = None
        self._last_sample = time.monotonic()
        self._write(b"\x00")
        self._command(S.CommandType.STOP)  # a board left streaming by a crashed host
        ack = self._command(S.CommandType.IDENTIFY)
        ident = ack.identity
        if ident.protocol_major != S.PROTOCOL_MAJOR:
            raise RigProtocolError("unsupported stream protocol version", port=url,
                                   actual=ident.protocol_major, expected=S.PROTOCOL_MAJOR)
        present = [i for i in range(16) if ident.present_mask >> i & 1]
        wanted = present if self.wanted is None else self.wanted
        absent = [i for i in wanted if i not in present]
        if absent:
            raise RigConfigError(f"sensor {absent[0]} is not present on the board", port=url,
                                 actual=present, expected=wanted)
        if not ident.min_rate_hz <= self.rate_hz <= ident.max_rate_hz:
            raise RigConfigError("sample rate not supported by the board", port=url,
                                 actual=self.rate_hz,
                                 expected=f"{ident.min_rate_hz}..{ident.max_rate_hz} Hz")
        if self.raw and ident.protocol_minor < 1:
            raise RigConfigError(f"the IMU board speaks stream protocol {ident.protocol_major}."
                                 f"{ident.protocol_minor}; raw samples need 1.1 (set "
                                 f"sensors.raw: false, or update its firmware)", port=url)
        if self.raw and len(wanted) > S.MAX_RAW_SENSORS:
            raise RigConfigError(f"raw samples carry at most {S.MAX_RAW_SENSORS} sensors per "
                                 f"board", port=url, actual=len(wanted))
        self.identity = ident
        self.sensors = wanted
        mask = sum(1 << i for i in wanted)
        # a board keeps its fields: RAW off before a mask of more than 8 sensors, on after
        if ident.protocol_minor >= 1 and not self.raw:
            self._command(S.CommandType.SET_FIELDS, S.FieldFlag.NONE)
        self._command(S.CommandType.SET_SENSORS, mask)
        if self.raw:
            self._command(S.CommandType.SET_FIELDS, S.FieldFlag.RAW)
        self._command(S.CommandType.SET_RATE, self.rate_hz)
        self._command(S.CommandType.START)
        self._decoder.reset_sequence()
        self._last_sample = time.monotonic()

    def _drop_serial(self) -> None:
        ser, self._serial = self._serial, None
        close_serial(ser)

    def _close(self) -> None:
        if self._serial is not None:
            try:
                self._write(S.encode_command(self._next_seq(), S.CommandType.STOP))
            except (RigConnectionError, *_CONNECTION_ERRORS):
                pass
            self._drop_serial()

    # -- wire -----------------------------------------------------------------------------
    def _next_seq(self) -> int:
        seq = self._cmd_seq
        self._cmd_seq = (seq + 1) & 0xFFFF
        return seq

    def _write(self, data: bytes) -> None:
        try:
            assert self._serial is not None
            self._serial.write(data)
        except _CONNECTION_ERRORS as err:
            raise RigConnectionError(f"the IMU board port failed ({err})",
                                     port=str(self.port)) from err

    def _read_bytes(self, wait: float) -> bytes:
        ser = self._serial
        assert ser is not None
        try:
            ser.timeout = max(0.0, wait)
            data = ser.read(max(1, ser.in_waiting))
            if data and ser.in_waiting:
                data += ser.read(ser.in_waiting)
            return data
        except _CONNECTION_ERRORS as err:
            raise RigConnectionError(f"the IMU board port failed ({err})",
                                     port=str(self.port)) from err

    def _frames(self, t_rx: float) -> list[S.Ack | S.Nak]:
        """Decode what is buffered: samples go to the queue, ACK/NAKs are returned."""
        replies = []
        while True:
            try:
                item = self._decoder.next()
            except ProtocolError:
                self.corrupt += 1
                continue
            if item is None:
                return replies
            if isinstance(item, S.Gap):
                if item.lost < 1 << 15:
                    self.dropped += item.lost
                continue
            if isinstance(item, S.Sample):
                self._on_sample(item, t_rx)
            elif isinstance(item, (S.Ack, S.Nak)):
                replies.append(item)

    def _on_sample(self, s: S.Sample, t_rx: float) -> None:
        device_t = self._unwrap(s.timestamp_us) * 1e-6
        lag = t_rx - device_t
        if self._offset is None or lag < self._offset:
            self._offset = lag
        else:
            self._offset += 1e-4 * max(0.0, t_rx - self._last_sample)
        self._last_sample = t_rx
        t = device_t + self._offset
        for r in s.readings:
            q = np.array(r.quaternion, dtype=np.float64)
            n = float(np.linalg.norm(q))
            if n < 0.5:  # FAULT flag / all zeros: not an orientation
                continue
            raw = np.array(r.raw) if self.raw and r.raw is not None else None
            self._queue.append(ImuSample(t, device_t, r.sensor_id, q / n, r.calibration,
                                         r.flags, raw))

    def _command(self, command: S.CommandType, value: int | None = None) -> S.Ack:
        name = command.name

        def once(deadline: float) -> S.Ack:
            seq = self._next_seq()
            self._write(S.encode_command(seq, command, value))
            while True:
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    raise RigTimeoutError(f"no answer to {name}", port=str(self.port))
                data = self._read_bytes(remaining)
                if data:
                    self._decoder.feed(data)
                for reply in self._frames(time.monotonic()):
                    if reply.command_seq != seq:
                        continue
                    if isinstance(reply, S.Nak):
                        code = _nak_name(reply.error)
                        raise RigConfigError(f"the board refused {name}"
                                             f"{'' if value is None else f' {value}'}: {code}",
                                             port=str(self.port))
                    return reply

        return self.transact(once, f"{name} command")

    # -- samples --------------------------------------------------------------------------
    def read(self, timeout: float) -> list[ImuSample]:
        """Samples received since the last call; waits up to ``timeout`` s for the first.

        Raises
        ------
        RigConnectionError
            The board is gone and did not come back within ``reconnect_s``.
        """
        self._check_open()
        deadline = time.monotonic() + max(0.0, timeout)
        while not self._queue:
            try:
                data = self._read_bytes(max(0.0, min(deadline - time.monotonic(),
                                                     self.silence_s)))
            except RigConnectionError as err:
                self._reconnect(err)
                continue
            now = time.monotonic()
            if data:
                self._decoder.feed(data)
                self._frames(now)
            elif now - self._last_sample > self.silence_s:
                self._reconnect(RigTimeoutError(f"no sample for {self.silence_s:.2f} s",
                                                port=str(self.port)))
            if now >= deadline:
                break
        out, self._queue = self._queue, []
        return out

    def _reconnect(self, cause: Exception) -> None:
        end = time.monotonic() + self.reconnect_s
        last: Exception = cause
        while time.monotonic() < end and not self._closed:
            try:
                self._connect()
                self.reconnects += 1
                return
            except (RigConnectionError, RigTimeoutError, RigProtocolError) as err:
                last = err
                time.sleep(0.05)
        self._drop_serial()
        raise RigConnectionError(f"the IMU board stopped answering ({last}); reconnecting "
                                 f"failed for {self.reconnect_s:.1f} s",
                                 port=str(self.port)) from cause


def _nak_name(code: int) -> str:
    try:
        return S.ErrorCode(code).name
    except ValueError:
        return f"error {code}"
