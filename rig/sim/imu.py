"""Simulated IMUs on pseudo-terminals: a BNO055 on its UART, and a multi-IMU stream device.

Both serve real bytes on the master side of a pseudo-terminal; ``serial.Serial(sim.port)``
(pyserial, unchanged) opens the slave exactly as it opens a USB-UART. Thread, pty, error
policy and adapter unplug come from :class:`rig.sim.pty_server.PtyServer`; the stream device
also wakes at its sample deadlines (or when its :class:`~rig.sim.clock.ManualClock` is
advanced). Orientations come from a :class:`~rig.sim.limb.SimulatedLimb` (ground truth through
:attr:`limb`). Port strings: :func:`bno055_from_url` (``sim://bno055?...``) and
:func:`stream_from_url` (``sim://imu-stream?...``).

:class:`Bno055Simulator`
    Register reads and writes as the chip answers them (:mod:`firmware_protocol.imu.bno055`):
    CHIP_ID 0xA0, ``OPR_MODE`` rules (fusion data only in fusion modes, configuration registers
    writable only in CONFIG mode, otherwise ``EE 05``), invalid addresses ``EE 04``, bad start
    bytes ``EE 06``, a partial request left for ``char_timeout_s`` ``EE 0A``; calibration status
    rising while fusing; data registers refreshed at the fusion rate (100 Hz by default, like
    the chip): accelerometer (``ACC_DATA``), magnetometer (``MAG_DATA``) and gyroscope
    (``GYR_DATA``) in the modes that run those sensors, fusion outputs in the fusion modes;
    ``SYS_TRIGGER`` bit 5 resets; ``UNIT_SEL`` (acceleration, rate and Euler units) and axis
    remap honoured.
:class:`StreamImuSimulator`
    The rig stream protocol 1.1 (:mod:`firmware_protocol.imu.stream`, ``SPEC.md``; or a 1.0
    device): IDENTIFY, START, STOP, SET_RATE, SET_SENSORS, SET_FIELDS answered with ACK/NAK;
    SAMPLE frames at the set rate for the active sensors, timestamped on the exact sample grid
    of the device clock (µs since the simulator started), with the raw accelerometer,
    gyroscope and magnetometer readings when the RAW field is on.

Both are context managers with an idempotent :meth:`close`; ``close`` re-raises an exception
that stopped the server thread, so a test sees simulator bugs; :meth:`disconnect` /
:meth:`reconnect` unplug and replug the USB-UART.
"""

from __future__ import annotations

import math
import time
from collections import deque
from collections.abc import Callable

import numpy as np
from scipy.spatial.transform import Rotation

from firmware_protocol.errors import ChecksumError, FramingError, PacketError
from firmware_protocol.imu import bno055 as B
from firmware_protocol.imu import stream as S
from models import quaternion as Q
from rig.sim.clock import real_delay
from rig.sim.limb import Measurement, SimulatedJoint, SimulatedLimb
from rig.sim.patients import LIMB_KEYS, PATIENT_KEYS, limb_from_url, patient_from_url
from rig.sim.pty_server import PtyServer
from rig.sim.urls import SimUrl

__all__ = [
    "Bno055Simulator",
    "StreamImuSimulator",
    "bno055_from_url",
    "stream_from_url",
    "stream_patient",
    "stream_query",
]

# ---------------------------------------------------------------------------------------------
# BNO055

_READ_ONLY = frozenset(range(0x00, 0x07)) | frozenset(range(0x08, 0x3B))
_ANY_MODE = frozenset({B.Register.PAGE_ID, B.Register.OPR_MODE, B.Register.SYS_TRIGGER})
_LAST_PAGE0 = 0x6A
_GYRO_MODES = frozenset({B.OperationMode.GYROONLY, B.OperationMode.ACCGYRO,
                         B.OperationMode.MAGGYRO, B.OperationMode.AMG, B.OperationMode.IMU,
                         B.OperationMode.NDOF_FMC_OFF, B.OperationMode.NDOF})
_ACC_MODES = frozenset({B.OperationMode.ACCONLY, B.OperationMode.ACCMAG,
                        B.OperationMode.ACCGYRO, B.OperationMode.AMG, B.OperationMode.IMU,
                        B.OperationMode.COMPASS, B.OperationMode.M4G,
                        B.OperationMode.NDOF_FMC_OFF, B.OperationMode.NDOF})
_MAG_MODES = frozenset({B.OperationMode.MAGONLY, B.OperationMode.ACCMAG,
                        B.OperationMode.MAGGYRO, B.OperationMode.AMG, B.OperationMode.COMPASS,
                        B.OperationMode.M4G, B.OperationMode.NDOF_FMC_OFF,
                        B.OperationMode.NDOF})
_MG_PER_MS2 = 1000.0 / 9.80665
"""ACC_DATA LSB per m/s² with UNIT_SEL bit 0 set (1 LSB = 1 mg)."""


def _page0_defaults() -> bytearray:
    regs = bytearray(0x80)
    regs[B.Register.CHIP_ID] = B.CHIP_ID_VALUE
    regs[B.Register.ACC_ID] = 0xFB
    regs[B.Register.MAG_ID] = 0x32
    regs[B.Register.GYR_ID] = 0x0F
    regs[B.Register.SW_REV_ID_LSB] = 0x11
    regs[B.Register.SW_REV_ID_MSB] = 0x03
    regs[B.Register.BL_REV_ID] = 0x15
    regs[B.Register.TEMP] = 25
    regs[B.Register.ST_RESULT] = 0x0F
    regs[B.Register.UNIT_SEL] = 0x80
    regs[B.Register.AXIS_MAP_CONFIG] = 0x24
    regs[B.Register.AXIS_MAP_SIGN] = 0x00
    return regs


def _axis_remap(config: int, sign: int) -> np.ndarray | None:
    """Matrix ``M`` with ``v_remapped = M v`` for AXIS_MAP_CONFIG/SIGN; None if invalid."""
    src = [(config >> (2 * k)) & 3 for k in range(3)]  # remapped X, Y, Z take these axes
    if sorted(src) != [0, 1, 2]:
        return None
    m = np.zeros((3, 3))
    for k, s in enumerate(src):
        m[k, s] = -1.0 if sign & (4 >> k) else 1.0
    return m


class Bno055Simulator(PtyServer):
    """One BNO055 in UART mode, on a pseudo-terminal.

    Parameters
    ----------
    limb : SimulatedLimb, optional
        Motion source; default ``SimulatedJoint(sensors=2, seed=seed)``.
    sensor : int, optional
        Which of the limb's sensors this chip is (default 1, the upper-arm sensor, or 0 if the
        limb has one sensor).
    rate_hz : float
        Fusion output rate: data registers change at this rate (the chip's is 100 Hz).
    char_timeout_s : float
        Inter-character timeout (real seconds, whatever ``clock`` is) after which a partial
        request is answered ``EE 0A``.
    clock : callable
        Monotonic seconds; tests may pass a manual clock to make time-dependent answers
        (calibration progress, motion) deterministic.
    seed : int, optional
        Seed of the default limb.

    Attributes
    ----------
    port : str
        The ``/dev/pts/N`` to open with pyserial.
    limb : SimulatedLimb
    last : Measurement or None
        The measurement behind the data registers last read (ground truth in ``last.truth``).
    """

    thread_name = "bno055-sim"

    def __init__(
        self,
        limb: SimulatedLimb | None = None,
        *,
        sensor: int | None = None,
        rate_hz: float = 100.0,
        char_timeout_s: float = 0.1,
        clock: Callable[[], float] = time.monotonic,
        seed: int | None = 0,
    ) -> None:
        # no motion source given: the default patient of the seed (not a joint-or-limb question)
        self.limb = limb if limb is not None else SimulatedJoint(sensors=2, seed=seed)
        self.sensor = sensor if sensor is not None else min(1, self.limb.n_sensors - 1)
        if not 0 <= self.sensor < self.limb.n_sensors:
            raise ValueError(
                f"sensor {self.sensor} not on the limb ({self.limb.n_sensors} sensors)")
        if not rate_hz > 0:
            raise ValueError(f"rate_hz must be > 0, got {rate_hz}")
        self.rate_hz = float(rate_hz)
        self.char_timeout_s = float(char_timeout_s)
        super().__init__(clock=clock)
        self.clock: Callable[[], float] = clock
        self._t0 = clock()
        self._decoder = B.RequestDecoder()
        self._last_rx = time.monotonic()
        self._page1 = bytearray(0x80)
        self._reset(self._t0)
        self.last: Measurement | None = None
        self._last_index = -1
        self._start()

    # state --------------------------------------------------------------------------------
    def _reset(self, now: float) -> None:
        self._regs = _page0_defaults()
        self._page1[:] = bytes(0x80)
        self._page1[B.Register.PAGE_ID] = 1
        self._fusing_since: float | None = None
        self._fused = 0.0  # seconds spent in fusion modes before _fusing_since

    @property
    def started_at(self) -> float:
        """Reading of :attr:`clock` when the simulator started: device time 0 and patient
        time 0."""
        return self._t0

    @property
    def mode(self) -> B.OperationMode:
        """Current operation mode."""
        return B.OperationMode(self._regs[B.Register.OPR_MODE] & 0x0F)

    def _fusion_elapsed(self, now: float) -> float:
        extra = 0.0 if self._fusing_since is None else now - self._fusing_since
        return self._fused + extra

    def _refresh(self, now: float) -> None:
        regs = self._regs
        mode = self.mode
        index = math.floor((now - self._t0) * self.rate_hz)
        if index != self._last_index:
            self._last_index = index
            self.last = self.limb.measure(index / self.rate_hz,
                                          calibration_elapsed_s=self._fusion_elapsed(now))
        m = self.last
        assert m is not None
        q = m.quaternions[self.sensor]
        gyro, accel, field_ = m.gyro[self.sensor], m.accel[self.sensor], m.mag[self.sensor]
        remap = _axis_remap(regs[B.Register.AXIS_MAP_CONFIG], regs[B.Register.AXIS_MAP_SIGN])
        if remap is not None:
            gyro, accel, field_ = remap @ gyro, remap @ accel, remap @ field_
            if np.linalg.det(remap) > 0:  # a proper rotation: the sensor axes are re-labelled
                # v_remapped = M v, so q_world_remapped = q_world_sensor ⊗ quat(Mᵀ)
                q = Q.multiply(q, Q.from_rotation(Rotation.from_matrix(remap.T)))
        unit = regs[B.Register.UNIT_SEL]
        zero6, zero8 = bytes(6), bytes(8)
        regs[0x08:0x0E] = (B.encode_vector(accel, _MG_PER_MS2 if unit & 0x01 else 100.0)
                           if mode in _ACC_MODES else zero6)
        regs[0x0E:0x14] = B.encode_vector(field_, 16.0) if mode in _MAG_MODES else zero6
        if mode in _GYRO_MODES:
            if unit & 0x02:
                regs[0x14:0x1A] = B.encode_vector(gyro, 900.0)
            else:
                regs[0x14:0x1A] = B.encode_vector(np.degrees(gyro), 16.0)
        else:
            regs[0x14:0x1A] = zero6
        if mode in B.FUSION_MODES:
            regs[0x20:0x28] = B.encode_quaternion(q)
            regs[0x1A:0x20] = B.encode_vector(_euler(q, radians=bool(unit & 0x04)),
                                              900.0 if unit & 0x04 else 16.0)
            regs[B.Register.CALIB_STAT] = int(m.calibration[self.sensor])
            regs[B.Register.SYS_STATUS] = 5
        else:
            regs[0x20:0x28] = zero8
            regs[0x1A:0x20] = zero6
            regs[B.Register.CALIB_STAT] = 0
            regs[B.Register.SYS_STATUS] = 0 if mode == B.OperationMode.CONFIG else 6

    # protocol -----------------------------------------------------------------------------
    def _on_bytes(self, data: bytes, t_rx: float) -> None:
        self._last_rx = t_rx
        now = self.clock()
        self._decoder.feed(data)
        while True:
            try:
                req = self._decoder.next()
            except B.Bno055FramingError as err:
                self._send(B.encode_status(err.status))
                continue
            if req is None:
                return
            if isinstance(req, B.ReadRequest):
                self._send(self._read(req, now))
            else:
                self._send(self._write(req, now))

    def _deadline(self) -> float | None:
        # the inter-character timeout is a link timer: real time, whatever the clock
        return self._last_rx + self.char_timeout_s if self._decoder.buffered else None

    def _on_timer(self, now: float) -> None:
        if self._decoder.buffered and now >= self._last_rx + self.char_timeout_s:
            self._decoder.expire()
            self._send(B.encode_status(B.Status.RECEIVE_CHARACTER_TIMEOUT))

    def _page(self) -> bytearray:
        return self._page1 if self._regs[B.Register.PAGE_ID] == 1 else self._regs

    def _read(self, req: B.ReadRequest, now: float) -> bytes:
        end = req.register + req.length
        if end > 0x80:
            return B.encode_status(B.Status.REGMAP_INVALID_ADDRESS)
        page = self._page()
        if page is self._regs and req.register < 0x3B and end > 0x08:
            self._refresh(now)
        return B.encode_read_response(page[req.register:end])

    def _write(self, req: B.WriteRequest, now: float) -> bytes:
        regs = self._regs
        config = self.mode == B.OperationMode.CONFIG
        end = req.register + len(req.data)
        if self._page() is self._page1:
            if end > 0x80:
                return B.encode_status(B.Status.REGMAP_INVALID_ADDRESS)
            if any(a != B.Register.PAGE_ID for a in range(req.register, end)) and not config:
                return B.encode_status(B.Status.REGMAP_WRITE_DISABLED)
            for a, v in zip(range(req.register, end), req.data, strict=True):
                if a == B.Register.PAGE_ID:
                    if v > 1:
                        return B.encode_status(B.Status.WRITE_FAIL)
                    regs[a] = v
                else:
                    self._page1[a] = v
            return B.encode_status(B.Status.WRITE_SUCCESS)
        if end - 1 > _LAST_PAGE0:
            return B.encode_status(B.Status.REGMAP_INVALID_ADDRESS)
        for a, v in zip(range(req.register, end), req.data, strict=True):
            if a in _READ_ONLY or a == 0x3C:
                return B.encode_status(B.Status.REGMAP_WRITE_DISABLED)
            if a not in _ANY_MODE and not config:
                return B.encode_status(B.Status.REGMAP_WRITE_DISABLED)
            if a == B.Register.OPR_MODE and (v & 0x0F) > B.OperationMode.NDOF:
                return B.encode_status(B.Status.WRITE_FAIL)
            if a == B.Register.PAGE_ID and v > 1:
                return B.encode_status(B.Status.WRITE_FAIL)
        reset = False
        for a, v in zip(range(req.register, end), req.data, strict=True):
            if a == B.Register.OPR_MODE:
                self._set_mode(v & 0x0F, now)
            elif a == B.Register.SYS_TRIGGER:
                reset = bool(v & 0x20)
                regs[a] = v & 0x80  # self-test and interrupt-reset bits read back as 0
            else:
                regs[a] = v
        if reset:
            self._reset(now)
        return B.encode_status(B.Status.WRITE_SUCCESS)

    def _set_mode(self, mode: int, now: float) -> None:
        fusing = mode in B.FUSION_MODES
        if self._fusing_since is not None and not fusing:
            self._fused += now - self._fusing_since
            self._fusing_since = None
        elif self._fusing_since is None and fusing:
            self._fusing_since = now
        self._regs[B.Register.OPR_MODE] = mode
        self._last_index = -1  # the next read samples afresh


def _euler(q: np.ndarray, radians: bool) -> tuple[float, float, float]:
    """(heading, roll, pitch) as the register order; heading clockwise from north in [0, 360)
    (or [0, 2π)), roll and pitch from the intrinsic Z-Y-X decomposition."""
    yaw, pitch, roll = Q.to_rotation(q).as_euler("ZYX")
    heading = (-yaw) % (2.0 * math.pi)
    if radians:
        return (heading, roll, pitch)
    return (math.degrees(heading), math.degrees(roll), math.degrees(pitch))


# ---------------------------------------------------------------------------------------------
# stream protocol


class StreamImuSimulator(PtyServer):
    """A microcontroller streaming several IMUs with the rig stream protocol, on a pty.

    Parameters
    ----------
    limb : SimulatedLimb (SimulatedJoint or SimulatedWholeLimb), optional
        Motion source; default ``SimulatedJoint(sensors=sensors, seed=seed)``. Sensor ``i`` of
        the protocol is ``limb.mounts[i]`` (anything with ``n_sensors``, ``mounts``,
        ``measure_many`` and ``truth``: a :class:`~rig.sim.limb.SimulatedWholeLimb` too).
    sensors : int
        Sensors present when ``limb`` is not given (1..16).
    rate_hz : int
        Initial sample rate (settable with SET_RATE within ``min_rate_hz..max_rate_hz``).
    min_rate_hz, max_rate_hz : int
        Rates the device accepts; others are refused with NAK BAD_ARGUMENT.
    serial : int
        Device serial number reported by IDENTIFY.
    timestamp_offset_us : int
        Device clock at simulator start, microseconds: ``2**32 - 10**6`` makes the u32
        timestamps wrap one second in. Ground truth of a SAMPLE is
        ``limb.truth((unwrapped_timestamp_us - timestamp_offset_us) / 1e6)``.
    clock : callable
        Monotonic seconds; the device clock is ``clock() - clock_at_start`` in microseconds.
        With a :class:`~rig.sim.clock.ManualClock` every ``advance`` emits at once the samples
        whose time has come (simulated time as fast as the host reads).
    seed : int, optional
    max_lag_s : float or None
        None (default): every sample of the grid is sent, late if the simulator's thread was
        starved (firmware on its own MCU does not fall behind; a loaded test machine does).
        A number models starved firmware: falling more than this behind its grid, the device
        skips the missed samples (SPEC §8), counting them in ``samples_skipped``.
    flow_control : bool
        False: a UART — bytes the host does not read in time are lost (``bytes_dropped``).
        True: a USB CDC device — the device waits for the host, nothing is lost; with
        ``max_lag_s=None`` and a manual or scaled clock, zero samples are lost however fast
        simulated time runs.
    initial_seq : int
        Sequence number of the first frame after power-up (0..65535), e.g. to test wrapping.
    protocol_minor : int
        Minor protocol version the device speaks: 1 (default, SET_FIELDS and raw records) or
        0 (a 1.0 device: IDENTIFY reports 0, SET_FIELDS is an unknown command).

    Attributes
    ----------
    port : str
    clock : callable
    limb : SimulatedLimb
        Ground truth: ``limb.truth(timestamp_us / 1e6)`` for a SAMPLE's timestamp.
    samples_sent, samples_skipped : int
        Samples streamed, and samples skipped because the device fell more than ``max_lag_s``
        behind.
    fields : int
        The SET_FIELDS mask in force (:class:`~firmware_protocol.imu.stream.FieldFlag`);
        with RAW each record carries ``limb``'s accelerometer, gyroscope and magnetometer.
    """

    thread_name = "stream-imu-sim"
    FIRMWARE_VERSION = 0x0100

    def __init__(
        self,
        limb: SimulatedLimb | None = None,
        *,
        sensors: int = 4,
        rate_hz: int = 100,
        min_rate_hz: int = 10,
        max_rate_hz: int = 400,
        serial: int = 0x5157_0001,
        timestamp_offset_us: int = 0,
        clock: Callable[[], float] = time.monotonic,
        seed: int | None = 0,
        max_lag_s: float | None = None,
        flow_control: bool = False,
        initial_seq: int = 0,
        protocol_minor: int = S.PROTOCOL_MINOR,
    ) -> None:
        if protocol_minor not in (0, 1):
            raise ValueError(f"protocol_minor must be 0 or 1, got {protocol_minor!r}")
        if max_lag_s is not None and not max_lag_s > 0:
            raise ValueError(f"max_lag_s must be > 0 or None, got {max_lag_s!r}")
        if not 0 <= initial_seq <= 0xFFFF:
            raise ValueError(f"initial_seq must be 0..65535, got {initial_seq}")
        if limb is None:  # no motion source given: the default patient of sensors and seed
            if not 1 <= sensors <= S.MAX_SENSORS:
                raise ValueError(f"sensors must be 1..{S.MAX_SENSORS}, got {sensors}")
            limb = SimulatedJoint(sensors=sensors, seed=seed)
        if limb.n_sensors > S.MAX_SENSORS:
            raise ValueError(f"the stream protocol carries at most {S.MAX_SENSORS} sensors")
        if not 1 <= min_rate_hz <= rate_hz <= max_rate_hz <= 0xFFFF:
            raise ValueError(
                f"need 1 <= min_rate_hz <= rate_hz <= max_rate_hz <= 65535, got "
                f"{min_rate_hz}, {rate_hz}, {max_rate_hz}")
        self.limb = limb
        self.min_rate_hz, self.max_rate_hz = int(min_rate_hz), int(max_rate_hz)
        self.rate_hz = int(rate_hz)
        self.serial = int(serial)
        self.timestamp_offset_us = int(timestamp_offset_us)
        self.present_mask = (1 << limb.n_sensors) - 1
        self.active_mask = self.present_mask
        self.protocol_minor = int(protocol_minor)
        self.fields = 0
        self.streaming = False
        self.samples_sent = 0
        self.samples_skipped = 0
        self.commands_received = 0
        self.frames_rejected = 0
        self.max_lag_s = max_lag_s
        super().__init__(clock=clock, flow_control=flow_control)
        self.clock: Callable[[], float] = clock
        self._t0 = clock()
        self._decoder = S.StreamDecoder(track_sequence=False)
        self._tx_seq = int(initial_seq)
        self._send(b"\x00")  # SPEC §3.1: a delimiter after power-up
        self._next_sample: float | None = None  # device time (s) of the next sample to send
        self._grid_base = 0.0  # device time of slot 0 of the current rate
        self._grid_k = 0  # the next slot to measure
        # the sensors' FIFO: (device time, Measurement) measured ahead of their slot
        self._fifo: deque[tuple[float, Measurement]] = deque()
        self._measured_to: float | None = None  # device time of the last slot measured
        self._ahead = 0 if hasattr(clock, "subscribe") else max(
            1, math.ceil(self.AHEAD_S * self.rate_hz))
        self._start()

    @property
    def started_at(self) -> float:
        """Reading of :attr:`clock` when the simulator started: device time 0 and patient
        time 0."""
        return self._t0

    def device_time_us(self, now: float | None = None) -> int:
        """The device clock in microseconds, not wrapped (SAMPLEs carry it modulo 2**32)."""
        t = (self.clock() if now is None else now) - self._t0
        return round(t * 1e6) + self.timestamp_offset_us

    def _seq(self) -> int:
        seq = self._tx_seq
        self._tx_seq = (seq + 1) & 0xFFFF
        return seq

    def identity(self) -> S.Identity:
        """What IDENTIFY reports now."""
        return S.Identity(
            protocol_major=S.PROTOCOL_MAJOR, protocol_minor=self.protocol_minor,
            firmware_version=self.FIRMWARE_VERSION, serial=self.serial,
            max_sensors=S.MAX_SENSORS, streaming=self.streaming,
            present_mask=self.present_mask, active_mask=self.active_mask,
            rate_hz=self.rate_hz, min_rate_hz=self.min_rate_hz, max_rate_hz=self.max_rate_hz,
        )

    # protocol -----------------------------------------------------------------------------
    def _on_bytes(self, data: bytes, t_rx: float) -> None:
        now = self.clock()
        self._decoder.feed(data)
        while True:
            try:
                frame = self._decoder.next()
            except PacketError as err:
                # CRC was good, so the header is trustworthy: refuse by name
                self.frames_rejected += 1
                seq, ftype = getattr(err, "seq", None), getattr(err, "frame_type", None)
                if seq is not None and ftype is not None:
                    code = getattr(err, "code", S.ErrorCode.BAD_LENGTH)
                    self._send(S.encode_nak(self._seq(), seq, ftype, code))
                continue
            except (FramingError, ChecksumError):
                self.frames_rejected += 1  # nothing trustworthy to answer to
                continue
            if frame is None:
                return
            self.commands_received += 1
            self._command(frame, now)

    def _command(self, frame, now: float) -> None:
        if not isinstance(frame, S.Command) or (frame.command == S.CommandType.SET_FIELDS
                                                and self.protocol_minor < 1):
            ftype = frame.type if isinstance(frame, S.UnknownFrame) else _frame_type(frame)
            self._send(S.encode_nak(self._seq(), frame.seq, ftype, S.ErrorCode.UNKNOWN_COMMAND))
            return
        cmd, value = frame.command, frame.value
        nak = None
        data = b""
        if cmd == S.CommandType.IDENTIFY:
            data = S.encode_identity(self.identity())
        elif cmd == S.CommandType.START:
            if not self.streaming:
                self.streaming = True
                base = now - self._t0
                if self._measured_to is not None and base <= self._measured_to:
                    base = self._measured_to + 1e-6  # the patient is measured that far already
                self._grid_base, self._grid_k = base, 0
                self._next_sample = self._grid_base
        elif cmd == S.CommandType.STOP:
            self.streaming = False
            self._fifo.clear()  # what was measured ahead is never sent
            self._next_sample = None
        elif cmd == S.CommandType.SET_RATE:
            assert value is not None
            if self.min_rate_hz <= value <= self.max_rate_hz:
                if self._next_sample is not None:  # from the first slot not yet measured
                    self._grid_base = self._grid_base + self._grid_k / self.rate_hz
                    self._grid_k = 0
                self.rate_hz = value
                if self._ahead:
                    self._ahead = max(1, math.ceil(self.AHEAD_S * value))
            else:
                nak = S.ErrorCode.BAD_ARGUMENT
        elif cmd == S.CommandType.SET_SENSORS:
            assert value is not None
            if value == 0 or value & ~self.present_mask or (
                    self.fields & S.FieldFlag.RAW and value.bit_count() > S.MAX_RAW_SENSORS):
                nak = S.ErrorCode.BAD_ARGUMENT
            else:
                self.active_mask = value
        elif cmd == S.CommandType.SET_FIELDS:
            assert value is not None
            if value & ~int(S.FieldFlag.RAW) or (
                    value & S.FieldFlag.RAW and self.active_mask.bit_count() > S.MAX_RAW_SENSORS):
                nak = S.ErrorCode.BAD_ARGUMENT
            else:
                self.fields = value
        if nak is None:
            self._send(S.encode_ack(self._seq(), frame.seq, cmd, data))
        else:
            self._send(S.encode_nak(self._seq(), frame.seq, cmd, nak))

    _BACKLOG = 8192
    """With flow control, stop producing samples while this many bytes wait for the host."""
    _BATCH = 64
    """Most samples measured, and most sent, in one go: the server reads the host's commands
    between two batches, so a device catching up on its grid still answers at once."""
    AHEAD_S = 0.1
    """On a running clock (real or ``time_scale``), the patient is measured this far ahead of
    the slot that is due, in one vectorised call, and the measurements wait in a FIFO for their
    slot — as an IMU's sensors fill a FIFO the firmware empties. One ``measure_many`` per
    0.1 s instead of one per sample: a four-segment chain costs ~0.8 ms per call, which at
    200 Hz took a fifth of a core and starved on a loaded host. A manual clock measures only
    what is due (its samples are as before). The patient's own changes
    (:meth:`~rig.devices.ports.SimulatedPatient.start_protocol`) come 2 s ahead, beyond it;
    SET_RATE applies from the first slot not yet measured; STOP empties the FIFO."""

    def _sync_next(self) -> None:
        """:attr:`_next_sample`: the oldest measured sample, else the next slot of the grid."""
        self._next_sample = (self._fifo[0][0] if self._fifo
                             else self._grid_base + self._grid_k / self.rate_hz)

    def _deadline(self) -> float | None:
        if self._next_sample is None:
            return None
        if self.flow_control and self.tx_backlog >= self._BACKLOG:
            return None  # wait for the host to read (the base waits for POLLOUT)
        delay = real_delay(self.clock, self._t0 + self._next_sample - self.clock())
        if delay is None:  # manual clock: due now, or when it is advanced (it wakes us)
            return time.monotonic() if self.clock() - self._t0 >= self._next_sample else None
        return time.monotonic() + delay

    def _on_timer(self, now: float) -> None:
        """Send what is due, one batch at most (the server loop comes back at once if more is
        due, reading the host's commands first)."""
        if self._next_sample is None:
            return
        t_now = self.clock() - self._t0
        rate = self.rate_hz
        lag = t_now - self._next_sample
        if self.max_lag_s is not None and lag > self.max_lag_s:
            # fell far behind (SPEC §8): skip the missed slots, as firmware would
            missed = int(lag * rate)
            self.samples_skipped += missed
            while missed and self._fifo:
                self._fifo.popleft()
                missed -= 1
            self._grid_k += missed
            self._sync_next()
        if self._next_sample > t_now:
            return
        if not self._fifo:  # the due slots (and, on a running clock, those just ahead)
            due = math.floor((t_now - self._grid_base) * rate + 1e-9) - self._grid_k + 1
            batch = max(1, min(due + self._ahead, self._BATCH))
            ks = self._grid_k + np.arange(batch)
            times = self._grid_base + ks / rate
            self._fifo.extend(zip(times.tolist(), self.limb.measure_many(times), strict=True))
            self._grid_k += batch
            self._measured_to = float(times[-1])
        active = [i for i in range(self.limb.n_sensors) if self.active_mask >> i & 1]
        raw = bool(self.fields & S.FieldFlag.RAW)
        out = bytearray()
        sent = 0
        fifo = self._fifo
        while fifo and fifo[0][0] <= t_now and sent < self._BATCH:
            if self.flow_control and self._BACKLOG - self.tx_backlog - len(out) <= 0:
                break  # the rest when the host has read
            t, m = fifo.popleft()
            if raw:
                values = np.hstack([m.accel, m.gyro, m.mag]).tolist()
                readings = [(i, int(m.calibration[i]), 0, m.quaternions[i].tolist(),
                             values[i]) for i in active]
            else:
                readings = [(i, int(m.calibration[i]), 0, m.quaternions[i].tolist())
                            for i in active]
            ts = round(t * 1e6) + self.timestamp_offset_us
            out += S.encode_sample(self._seq(), ts, readings, raw=raw)
            sent += 1
        self.samples_sent += sent
        self._sync_next()
        if out:
            self._send(bytes(out))


def _frame_type(frame) -> int:
    if isinstance(frame, S.Command):
        return int(frame.command)
    if isinstance(frame, S.Sample):
        return S.FrameType.SAMPLE
    if isinstance(frame, S.Ack):
        return S.FrameType.ACK
    return S.FrameType.NAK


# ---------------------------------------------------------------------------------------------
# port strings

BNO055_EXAMPLE = "sim://bno055?seed=1&rate=100&patient=original"
STREAM_EXAMPLE = "sim://imu-stream?sensors=2&rate=200&patient=original&seed=1"


def bno055_from_url(url: str, **overrides: object) -> Bno055Simulator:
    """Start a simulated BNO055 described by a port string.

    ``sim://bno055?seed=1&rate=100&patient=original`` — every key optional (the patient
    keys are read by :func:`rig.sim.patients.patient_from_url`, for every simulator alike):

    ================  ===========================================================  ==========
    key               meaning                                                      default
    ================  ===========================================================  ==========
    ``patient``       range of motion: a shape of :mod:`models.shapes` or a        60° cone
                      constraint YAML path
    ``sensor``        which sensor of the patient this chip is: 0 thorax, 1 arm    1
    ``rate``          fusion output rate, Hz (the chip: 100)                       100
    ``seed``          seed of motion, noise and mounting                           0
    ``noise``         sensor errors (white noise, drift, magnetic disturbances,   on
                      calibration) on / off
    ``misplace_deg``  each strap turned this far off its nominal mounting          5
    ``excursion``     RMS of the motion relative to the range (> 0, <= 3)          1
    ``speed``         multiplies the motion's frequencies (> 0, <= 20)             1
    ``calibrate``     the patient performs the guided calibration protocol          off
                      (:class:`calibration.protocol.CalibrationProtocol`: neutral
                      pose from 2 s, flexion/extension, then free motion) on / off
    ``neutral``       the patient returns to the neutral pose every this many      0 (never)
                      seconds after the calibration (or from 0 s): 1.5 s into it,
                      held 2 s, 1.5 s out (``SimulatedJoint(neutral_every_s=)``);
                      0 (never) or >= 6
    ``neutral_sd``    the patient's repeatability of the neutral pose: std of its  2
                      axial rotation, degrees (0..10; swing: half of it)
    ``clock``,        simulated time (:mod:`rig.sim.urls`): ``clock=manual``       real time
    ``time_scale``    gives ``sim.clock`` a :class:`~rig.sim.clock.ManualClock`
    ================  ===========================================================  ==========

    Parameters
    ----------
    url : str
    **overrides
        Keyword arguments of :class:`Bno055Simulator` that win over the URL (``clock``,
        ``limb``, ``char_timeout_s``, ...).

    Raises
    ------
    RigConfigError
        Not ``sim://bno055``, unknown key, bad value (the message names the key).
    """
    q = SimUrl(url, ("bno055",), (*PATIENT_KEYS, "sensor", "rate"), BNO055_EXAMPLE)
    kwargs: dict[str, object] = {
        "sensor": q.integer("sensor", 1, 0, 1),
        "rate_hz": q.number("rate", 100.0, 0.0, 1000.0, open_lo=True),
        "clock": q.clock(),
    }
    if "limb" not in overrides:
        kwargs["limb"] = patient_from_url(q, sensors=2)
    kwargs.update(overrides)
    return Bno055Simulator(**kwargs)  # type: ignore[arg-type]


def stream_from_url(url: str, **overrides: object) -> StreamImuSimulator:
    """Start a simulated stream-protocol IMU board described by a port string.

    ``sim://imu-stream?sensors=2&rate=200&patient=original&seed=1`` — every key optional; the
    patient keys of :func:`bno055_from_url` (``patient``, ``seed``, ``noise``,
    ``misplace_deg``, ``excursion``, ``speed``, ``calibrate``, ``neutral``, ``neutral_sd``,
    ``clock``, ``time_scale``) and:

    ============  ==================================================================  ========
    key           meaning                                                             default
    ============  ==================================================================  ========
    ``sensors``   sensors on the board (1..16): 0 on the thorax, the others on the    2
                  arm
    ``rate``      initial sample rate, Hz (SET_RATE may change it within 10..max(400,  100
                  rate))
    ``max_lag``   seconds behind its sample grid after which the device skips         none
                  samples (starved firmware); ``none``: never skip
    ``flow``      flow control: ``on`` the device waits for the host (nothing lost),  off
                  ``off`` unread bytes are lost like on a UART
    ``protocol``  stream protocol version the board speaks: ``1.1`` (raw samples on   1.1
                  request) or ``1.0`` (an older firmware: no SET_FIELDS)
    ``limb``      ``arm`` or ``leg``: the board is worn by a whole arm or leg, one    (none)
                  sensor per segment (:class:`~rig.sim.limb.SimulatedWholeLimb`,
                  :func:`rig.sim.patients.anatomical_limb` of ``seed``); ``sensors``
                  must then be 4 (its default); ``calibrate=on`` performs the limb
                  calibration protocol. ``patient=`` a limb file does the same with
                  the file's limits. Absent: the shoulder patient
    ``side``      ``right`` or ``left``, with ``limb``                                right
    ============  ==================================================================  ========

    A benchmark that must not lose a sample at any speed:
    ``sim://imu-stream?sensors=2&rate=400&clock=manual&flow=on`` and advance ``sim.clock``.

    Raises
    ------
    RigConfigError
        Not ``sim://imu-stream``, unknown key, bad value (the message names the key).
    """
    q = stream_query(url)
    rate = q.integer("rate", 100, 1, 0xFFFF)
    kwargs: dict[str, object] = {
        "rate_hz": rate,
        "min_rate_hz": min(10, rate),
        "max_rate_hz": max(400, rate),
        "max_lag_s": q.number("max_lag", None, 0.0, none_ok=True, open_lo=True),
        "flow_control": q.flag("flow", False),
        "protocol_minor": int(q.choice("protocol", "1.1", ("1.0", "1.1"))[-1]),
        "clock": q.clock(),
    }
    if "limb" not in overrides:
        kwargs["limb"] = stream_patient(q)
    kwargs.update(overrides)
    return StreamImuSimulator(**kwargs)  # type: ignore[arg-type]


def stream_query(url: str, extra_keys: tuple[str, ...] = ()) -> SimUrl:
    """The checked query of a ``sim://imu-stream`` port string (``extra_keys``: a port
    backend's own, such as ``process``)."""
    return SimUrl(url, ("imu-stream", "stream"),
                  (*PATIENT_KEYS, *LIMB_KEYS, "sensors", "rate", "max_lag", "flow", "protocol",
                   *extra_keys), STREAM_EXAMPLE)


def stream_patient(q: SimUrl):
    """The patient a ``sim://imu-stream`` query describes — the simulator's :attr:`limb`: a
    :class:`~rig.sim.limb.SimulatedWholeLimb` (``limb=`` or a limb file) or a
    :class:`~rig.sim.limb.SimulatedLimb`. Deterministic in the query, so a process that does
    not serve the board builds the same patient (its ground truth) from the same string."""
    sensors = q.integer("sensors", 2, 1, S.MAX_SENSORS)
    # limb_from_url is the one place that reads the user's limb= / patient= limb file
    chain = limb_from_url(q, sensors=sensors if "sensors" in q else None)
    return chain if chain is not None else patient_from_url(q, sensors=sensors)
