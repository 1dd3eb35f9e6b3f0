"""The recorder's one seam to the devices: rig configuration → opened orientation source.

Everything :mod:`rig.record` needs of :mod:`rig.devices` goes through :func:`open_rig`, so the
session logic never knows whether it reads a USB adapter or a simulator (port strings choose,
contract of :mod:`rig.devices.ports`).
"""

from __future__ import annotations

import contextlib
from dataclasses import dataclass, field

import numpy as np

__all__ = ["OpenRig", "SensorInfo", "load_config", "open_rig"]


@dataclass(frozen=True)
class SensorInfo:
    """One stream of samples the session records (a row of the store's sensor table)."""

    name: str
    segment: str
    kind: str  # "sensor" or "joint"
    port: str


@dataclass
class OpenRig:
    """An opened rig: the orientation source plus what describes it.

    Attributes
    ----------
    config : RigConfig
    source : OrientationSource
        Entered (its context is held by :attr:`stack`).
    sensors : list of SensorInfo
    simulators : list
        Simulator objects behind ``sim://`` ports (empty on hardware).
    kind : str
        ``"imu"`` or ``"servo"``.
    """

    config: object
    source: object
    sensors: list[SensorInfo]
    simulators: list = field(default_factory=list)
    kind: str = "imu"
    stack: contextlib.ExitStack = field(default_factory=contextlib.ExitStack)
    ports: list = field(default_factory=list)
    """Opened :class:`rig.devices.ports.Port` objects behind the source."""
    device_t0: float = 0.0
    """Device time at which the simulated patient's time was 0."""

    @property
    def simulated(self) -> bool:
        """Every device is a simulator (calibration steps then advance by themselves)."""
        return bool(self.simulators)

    @property
    def patients(self) -> list:
        """The simulated patients (:class:`rig.sim.limb.SimulatedLimb`) behind the ports."""
        return [p.patient for p in self.ports if getattr(p, "patient", None) is not None]

    @property
    def protocol(self):
        """The calibration protocol the simulated patient performs, or None."""
        pats = self.patients
        return getattr(pats[0], "calibration_protocol", None) if pats else None

    @property
    def protocol_start_s(self) -> float:
        """Patient time (s) at which the simulated patient starts the protocol (0 if none)."""
        pats = self.patients
        return float(getattr(pats[0], "protocol_start_s", 0.0)) if pats else 0.0

    def patient_time(self, batch) -> np.ndarray:
        """The simulated patient's own time (s) at each sample of ``batch`` (N,).

        A stream IMU simulator timestamps samples with the patient's time (its device clock
        starts with the patient), so ``device_t`` is used where present; otherwise host time
        since the port's ``patient_t0``, times the simulator clock's ``scale`` (a
        ``time_scale=`` simulator runs the patient faster than the host's clock).
        """
        if not self.ports:
            raise ValueError("patient_time: not a simulated rig")
        if self.kind == "imu" and not np.isnan(batch.device_t).any():
            return batch.device_t - self.device_t0
        port = self.ports[0]
        scale = float(getattr(getattr(port.simulator, "clock", None), "scale", 1.0))
        return (batch.t - float(getattr(port, "patient_t0", 0.0))) * scale

    def close(self) -> None:
        """Close the source and its ports (idempotent)."""
        self.stack.close()

    def __enter__(self) -> OpenRig:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def load_config(name_or_path: str):
    """The rig configuration (``rig.devices.config.load_rig_config``)."""
    from rig.devices.config import load_rig_config

    return load_rig_config(name_or_path)


def open_rig(config, *, which: str | None = None, rate_hz: float | None = None,
             calibrate: bool = False) -> OpenRig:
    """Open the rig's ports, devices and orientation source.

    ``calibrate``: a simulated patient performs the guided calibration protocol
    (:class:`calibration.protocol.CalibrationProtocol`) before moving freely — IMU simulators
    get ``calibrate=on`` unless their port string says otherwise (``calibrate=off``); a
    back-driven servo limb's patient is given the protocol to start 2 s (patient time) after
    opening. Without it a simulated patient moves freely from the start (hardware: no effect).

    The ports are opened here (:func:`rig.devices.ports.open_port`) and handed to
    :func:`rig.devices.sources.open_source`, so the simulators behind ``sim://`` ports stay
    reachable (:attr:`OpenRig.simulators`: the patient's clock, fault injection).

    Raises whatever the devices raise for a wrong port or a silent device
    (:class:`rig.errors.RigConnectionError`, :class:`rig.errors.RigTimeoutError`), before any
    sample is recorded.
    """
    from rig.devices.ports import open_port
    from rig.devices.sources import open_source

    if which is None:
        which = "sensors" if getattr(config, "sensors", None) is not None else "servos"
    stack = contextlib.ExitStack()
    try:
        if which == "sensors":
            urls = list(config.sensors.ports)
            baud = config.sensors.baud
        else:
            urls = [config.servos.port]
            baud = config.servos.baud
        ports = {}
        for url in urls:
            ports[url] = stack.enter_context(open_port(_with_protocol(url, calibrate),
                                                       baud=baud))
        if calibrate and which != "sensors":
            for port in ports.values():
                _servo_patient_protocol(port)
        source = open_source(config, which, rate_hz=rate_hz, ports=ports)
        stack.callback(source.close)  # LIFO: the source closes before its ports
        if which == "sensors":
            sensors = [SensorInfo(name, segment=name, kind="sensor", port=ports[urls[0]].url)
                       for name in source.names]
            kind = "imu"
        else:
            sensors = [SensorInfo(name, segment=config.joint.child, kind="joint",
                                  port=ports[urls[0]].url)
                       for name in source.names]
            kind = "servo"
        port_list = list(ports.values())
        sims = [p.simulator for p in port_list if p.simulator is not None]
        if sims and len(sims) != len(port_list):
            sims = []  # a mixed rig counts as hardware: the clinician is prompted
        device_t0 = 0.0
        if kind == "imu" and sims:
            device_t0 = float(getattr(sims[0], "timestamp_offset_us", 0)) / 1e6
        return OpenRig(config, source, sensors, sims, kind, stack, port_list, device_t0)
    except BaseException:
        stack.close()
        raise


_PATIENT_SCHEMES = ("sim://imu-stream", "sim://stream", "sim://bno055")


def _with_protocol(url: str, calibrate: bool) -> str:
    """``url`` with ``calibrate=on`` added for a simulated IMU patient (unless it says)."""
    import urllib.parse

    if not calibrate or not url.startswith(_PATIENT_SCHEMES):
        return url
    query = urllib.parse.parse_qs(urllib.parse.urlsplit(url).query, keep_blank_values=True)
    if "calibrate" in query:
        return url
    return url + ("&" if "?" in url else "?") + "calibrate=on"


def _servo_patient_protocol(port) -> None:
    """The back-driving patient of a ``sim://dynamixel?...&patient=`` port performs the
    protocol, starting 2 s of patient time from now (it is sampled lazily, so the change
    takes effect from the next servo read on)."""
    limb = getattr(port, "patient", None)
    drive = getattr(port, "backdrive", None)
    sim = getattr(port, "simulator", None)
    if limb is None or drive is None or sim is None:
        return
    if getattr(limb, "calibration_protocol", None) is not None:
        return
    from calibration.protocol import CalibrationProtocol

    now = float(sim.clock()) - float(drive.t0)
    limb.perform_protocol(CalibrationProtocol(), start_s=max(0.0, now) + 2.0)
