"""Orientation sources: the one interface recording and the live loop consume.

A source is a context manager and an iterator of batches of :class:`OrientationSample`:

* ``read(timeout) -> list[OrientationSample]`` — what arrived (possibly empty) within
  ``timeout`` seconds;
* ``dropped`` — samples lost (sequence gaps) so far; ``names`` — what it reports;
* ``iter(source)`` — ``read`` in a loop, yielding non-empty batches until the source is closed.

A device that vanishes makes ``read`` raise :class:`~rig.errors.RigConnectionError` (a servo
bus that stops answering too: its timeouts are turned into a connection error there).

Implementations
---------------
:class:`ServoLimbSource`
    Limb kinematics of one read of the servo bus per period: one ``kind="joint"`` sample per
    joint, ``name`` the joint's (a rig config's joint name); periods on a drift-free monotonic
    schedule at ``rate_hz``.
:class:`ImuSetSource`
    A stream-protocol board, or one BNO055 per segment: ``kind="sensor"``, ``name`` the
    segment the sensor is strapped to (the rig config's ``segments``), ``q`` the sensor
    relative to its world frame, ``raw`` the raw readings when the devices were opened with
    ``raw=True`` (rig config ``sensors.raw``).

:func:`open_source` builds either from a :class:`~rig.devices.config.RigConfig`.
"""

from __future__ import annotations

import time
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from firmware_protocol.imu import bno055 as B
from rig.devices.bno055 import Bno055
from rig.devices.config import RigConfig
from rig.devices.dynamixel import DynamixelBus
from rig.devices.ports import Port
from rig.devices.servo_limb import ServoLimb
from rig.devices.stream_imu import StreamImu
from rig.errors import RigConfigError, RigConnectionError, RigProtocolError, RigTimeoutError

__all__ = [
    "ImuSetSource",
    "OrientationSample",
    "OrientationSource",
    "ServoLimbSource",
    "open_source",
]


@dataclass(frozen=True)
class OrientationSample:
    """One timestamped orientation.

    Attributes
    ----------
    t : float
        Host monotonic time, s.
    device_t : float or None
        Device timestamp, s (None if the device has none).
    name : str
        Segment name (``kind="sensor"``) or joint name (``kind="joint"``).
    kind : str
        ``"sensor"``: IMU orientation in its world frame; ``"joint"``: limb relative to parent.
    q : (4,) float64
        Unit quaternion (w, x, y, z).
    status : int
        Calibration status byte (IMU) or 0.
    raw : (9,) float64 or None
        The IMU's raw readings at the same instant, sensor frame: accelerometer (m/s², specific
        force, +g up at rest), gyroscope (rad/s), magnetometer (µT), in that order; None when
        the device does not deliver them (``sensors.raw`` off, or a joint sample).
    """

    t: float
    device_t: float | None
    name: str
    kind: str
    q: np.ndarray
    status: int
    raw: np.ndarray | None = None


@runtime_checkable
class OrientationSource(Protocol):
    """What recording and the live loop consume (see the module docstring)."""

    names: tuple[str, ...]

    @property
    def dropped(self) -> int: ...  # pragma: no cover - protocol

    def read(self, timeout: float) -> list[OrientationSample]: ...  # pragma: no cover

    def close(self) -> None: ...  # pragma: no cover

    def __enter__(self): ...  # pragma: no cover

    def __exit__(self, *exc: object) -> None: ...  # pragma: no cover

    def __iter__(self) -> Iterator[list[OrientationSample]]: ...  # pragma: no cover


class _SourceBase:
    names: tuple[str, ...] = ()
    _closed = False

    def __enter__(self):
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        self._closed = True

    @property
    def closed(self) -> bool:
        return self._closed

    def read(self, timeout: float) -> list[OrientationSample]:  # pragma: no cover
        raise NotImplementedError

    def __iter__(self) -> Iterator[list[OrientationSample]]:
        while not self._closed:
            batch = self.read(0.5)
            if batch:
                yield batch


#: A servo chain that answers nothing for this long is lost (``RigConnectionError``); a shorter
#: silence — a USB adapter's hiccup, a host stalled by other work — costs the readings it
#: spans only (:attr:`ServoLimbSource.missed`), not the recording.
LOST_AFTER_S = 0.5


class ServoLimbSource(_SourceBase):
    """Joint orientations of a servo limb by its kinematics, at ``rate_hz``.

    Parameters
    ----------
    limb : ServoLimb
        Opened; closed with the source when ``own`` is true. Its joints' names name the
        samples.
    rate_hz : float
        Reads per second, on a drift-free schedule (a late read is not made up for).
    own : bool
        Close the limb with the source.

    Attributes
    ----------
    ticks : (n,) int64 or None
        The last ticks read.
    missed : int
        Readings that failed (every attempt timed out or came garbled) within
        :data:`LOST_AFTER_S` of the last good one: no sample for them, the recording goes on.
    """

    def __init__(self, limb: ServoLimb, *, rate_hz: float = 100.0, own: bool = True) -> None:
        if not rate_hz > 0:
            raise RigConfigError(f"rate_hz must be > 0, got {rate_hz}")
        self.limb = limb
        self.names = tuple(limb.kinematics.names)
        self.period = 1.0 / float(rate_hz)
        self._own = own
        self._next = time.monotonic()
        self._last_ok = self._next
        self.missed = 0
        self.ticks: np.ndarray | None = None

    @property
    def dropped(self) -> int:
        return 0  # each read is a request: nothing can be lost in between

    def read(self, timeout: float) -> list[OrientationSample]:
        """One reading (a sample per joint) if the next period starts within ``timeout`` s,
        else []."""
        nxt = _pace(self._next, self.period, timeout)
        if nxt is None:
            return []
        self._next = nxt
        bus = self.limb.bus
        try:
            ticks = bus.read_ticks()
        except (RigTimeoutError, RigProtocolError) as err:
            if time.monotonic() - self._last_ok < LOST_AFTER_S:
                self.missed += 1
                return []
            # the message's wording is kept (CLI output unchanged)
            raise RigConnectionError(f"the servo chain stopped answering ({err})",
                                     port=str(bus.port)) from err
        t = time.monotonic()
        self._last_ok = t
        self.ticks = ticks
        kin = self.limb.kinematics
        return [OrientationSample(t, None, name, "joint", joint.forward(part), 0)
                for name, joint, part in zip(self.names, kin.joints, kin.split(ticks),
                                             strict=True)]

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            if self._own:
                self.limb.close()


class ImuSetSource(_SourceBase):
    """Sensor orientations of an IMU set, named by segment.

    Parameters
    ----------
    devices : StreamImu, or sequence of Bno055
        One stream board, or one BNO055 per sensor index.
    segments : mapping of str to int
        Segment name -> sensor index (index into ``devices`` for BNO055s).
    rate_hz : float
        Poll rate for BNO055s (a stream board sets its own).
    own : bool
        Close the devices with the source.
    """

    def __init__(self, devices: StreamImu | Sequence[Bno055], segments: Mapping[str, int], *,
                 rate_hz: float = 100.0, own: bool = True) -> None:
        self._stream = devices if isinstance(devices, StreamImu) else None
        self._chips = [] if self._stream is not None else list(devices)  # type: ignore[arg-type]
        self._by_index = {int(i): str(s) for s, i in segments.items()}
        self.names = tuple(segments)
        self.period = 1.0 / float(rate_hz)
        self._next = time.monotonic()
        self._own = own
        if self._stream is None:
            for s, i in segments.items():
                if not 0 <= i < len(self._chips):
                    raise RigConfigError(f"segment {s!r}: sensor {i} but only "
                                         f"{len(self._chips)} BNO055 ports")

    @property
    def dropped(self) -> int:
        return self._stream.dropped if self._stream is not None else 0

    def read(self, timeout: float) -> list[OrientationSample]:
        if self._stream is not None:
            samples = self._stream.read(timeout)
            return [OrientationSample(s.t, s.device_t, self._by_index[s.sensor], "sensor", s.q,
                                      s.calibration, s.raw)
                    for s in samples if s.sensor in self._by_index]
        nxt = _pace(self._next, self.period, timeout)
        if nxt is None:
            return []
        self._next = nxt
        out = []
        for index, name in self._by_index.items():
            chip = self._chips[index]
            try:
                s = chip.sample()
            except (RigTimeoutError, RigProtocolError) as err:
                raise RigConnectionError(f"the BNO055 of {name!r} stopped answering ({err})",
                                         port=str(chip.port)) from err
            out.append(OrientationSample(s.t, None, name, "sensor", s.q, s.calibration, s.raw))
        return out

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        if self._own:
            devices = [self._stream] if self._stream is not None else self._chips
            errors = []
            for d in devices:
                try:
                    d.close()
                except Exception as err:
                    errors.append(err)
            if errors:
                raise errors[0]


def open_source(config: RigConfig, which: str | None = None, *,
                rate_hz: float | None = None, ports: Mapping[str, Port] | None = None
                ) -> ServoLimbSource | ImuSetSource:
    """Open the orientation source a rig config describes.

    Parameters
    ----------
    config : RigConfig
    which : {"servos", "sensors"}, optional
        Needed when the config has both.
    rate_hz : float, optional
        Default: ``sensors.rate_hz``, or 100 Hz for servos.
    ports : mapping of str to Port, optional
        Already opened ports by port string (a test keeps the simulator for fault injection).

    Raises
    ------
    RigConfigError, RigConnectionError
        Before anything long starts: bad config, missing port, nobody answering.
    """
    if which is None:
        if config.servos is not None and config.sensors is not None:
            raise RigConfigError(f"rig config {config.name!r} has both servos and sensors: "
                                 f"say which to open")
        which = "servos" if config.servos is not None else "sensors"
    ports = dict(ports or {})
    if which == "servos":
        if config.servos is None:
            raise RigConfigError(f"rig config {config.name!r} has no servos")
        port = ports.get(config.servos.port, config.servos.port)
        kinematics = config.servos.limb_kinematics(config.joint.name)
        limb = ServoLimb(DynamixelBus(port, config.servos), kinematics)
        return ServoLimbSource(limb, rate_hz=rate_hz or 100.0)
    if which != "sensors":
        raise ValueError(f"which must be 'servos' or 'sensors', got {which!r}")
    sensors = config.sensors
    if sensors is None:
        raise RigConfigError(f"rig config {config.name!r} has no sensors")
    rate = rate_hz or sensors.rate_hz
    if sensors.protocol == "stream":
        board = StreamImu(ports.get(sensors.port, sensors.port),
                          sensors=sorted(set(sensors.segments.values())), rate_hz=int(rate),
                          baud=sensors.baud, raw=sensors.raw)
        return ImuSetSource(board, sensors.segments)
    chips: list[Bno055] = []
    try:
        for k, p in enumerate(sensors.ports):
            chips.append(Bno055(ports.get(p, p), baud=sensors.baud, sensor=k, raw=sensors.raw))

        for chip in chips:
            chip.set_mode(B.OperationMode.NDOF)
    except BaseException:
        for chip in chips:
            chip.close()
        raise
    return ImuSetSource(chips, sensors.segments, rate_hz=rate)


def _pace(due: float, period: float, timeout: float) -> float | None:
    """Wait for the reading due at monotonic time ``due`` if it falls within ``timeout`` s and
    return when the next one is due (skipping missed periods when behind); otherwise sleep
    ``timeout`` and return None."""
    wait = due - time.monotonic()
    if wait > timeout:
        time.sleep(max(0.0, timeout))
        return None
    if wait > 0:
        time.sleep(wait)
    due += period
    now = time.monotonic()
    return now + period if due < now else due
