"""The recorder's one seam to the devices: rig configuration → opened orientation source.

Everything :mod:`rig.record` needs of :mod:`rig.devices` goes through :func:`open_rig`, so the
session logic never knows whether it reads a USB adapter or a simulator (port strings choose,
contract of :mod:`rig.devices.ports`).
"""

from __future__ import annotations

import contextlib
from dataclasses import dataclass, field

import numpy as np

from calibration.joints import LIMB_CHAINS
from rig.devices.config import load_rig_config
from rig.devices.ports import open_port
from rig.devices.sources import open_source
from rig.record.procedures import procedure_for

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
        Simulator objects behind ``sim://`` ports served in this process (empty on hardware
        and for a simulator in a process of its own).
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
        """Every device is a simulator (calibration steps then advance by themselves), in
        this process or served from one of its own (``process=on``)."""
        if self.simulators:
            return True
        return bool(self.ports) and all(p.is_simulated and p.simulated_patient is not None
                                        for p in self.ports)

    @property
    def simulated_patients(self) -> list:
        """The :class:`rig.devices.ports.SimulatedPatient` views of the ports' patients."""
        return [p.simulated_patient for p in self.ports if p.simulated_patient is not None]

    @property
    def patients(self) -> list:
        """The simulated patients (:class:`rig.sim.limb.SimulatedLimb`) behind the ports."""
        return [sp.limb for sp in self.simulated_patients]

    @property
    def protocol(self):
        """The calibration protocol the simulated patient performs, or None."""
        pats = self.patients
        return pats[0].calibration_protocol if pats else None

    @property
    def protocol_start_s(self) -> float:
        """Patient time (s) at which the simulated patient starts the protocol (0 if none)."""
        pats = self.patients
        return float(pats[0].protocol_start_s) if pats else 0.0

    def patient_time(self, batch) -> np.ndarray:
        """The simulated patient's own time (s) at each sample of ``batch`` (N,).

        A stream IMU simulator timestamps samples with the patient's time (its device clock
        starts with the patient), so ``device_t`` is used where present; otherwise host time
        through the port's :meth:`~rig.devices.ports.SimulatedPatient.time_at` (a
        ``time_scale=`` simulator runs the patient faster than the host's clock).
        """
        pats = self.simulated_patients
        if not pats:
            raise ValueError("patient_time: not a simulated rig")
        if self.kind == "imu" and not np.isnan(batch.device_t).any():
            return batch.device_t - self.device_t0
        return pats[0].time_at(batch.t)

    def close(self) -> None:
        """Close the source and its ports (idempotent)."""
        self.stack.close()

    def __enter__(self) -> OpenRig:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def load_config(name_or_path: str):
    """The rig configuration (``rig.devices.config.load_rig_config``)."""

    return load_rig_config(name_or_path)


def open_rig(config, *, which: str | None = None, rate_hz: float | None = None,
             calibrate: bool = False) -> OpenRig:
    """Open the rig's ports, devices and orientation source.

    ``calibrate``: a simulated patient performs the guided calibration protocol
    (:class:`calibration.protocol.CalibrationProtocol`) before moving freely, starting 2 s
    (patient time) after opening (:meth:`rig.devices.ports.SimulatedPatient.start_protocol`),
    unless its port string says whether it does (``calibrate=on|off`` of the IMU simulators).
    Without it a simulated patient moves freely from the start (hardware: no effect).

    The ports are opened here (:func:`rig.devices.ports.open_port`) and handed to
    :func:`rig.devices.sources.open_source`, so the simulators behind ``sim://`` ports stay
    reachable (:attr:`OpenRig.simulators`: the patient's clock, fault injection).

    Raises whatever the devices raise for a wrong port or a silent device
    (:class:`rig.errors.RigConnectionError`, :class:`rig.errors.RigTimeoutError`), before any
    sample is recorded.
    """

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
            ports[url] = stack.enter_context(open_port(url, baud=baud))
        if calibrate:
            for port in ports.values():
                _patient_performs_protocol(port, config.limb)
        source = open_source(config, which, rate_hz=rate_hz, ports=ports)
        stack.callback(source.close)  # LIFO: the source closes before its ports
        if which == "sensors":
            sensors = [SensorInfo(name, segment=name, kind="sensor", port=ports[urls[0]].url)
                       for name in source.names]
            kind = "imu"
        else:
            child = {name: c for name, _, c in LIMB_CHAINS.get(config.limb, ())}
            sensors = [SensorInfo(name, segment=child.get(name, config.joint.child),
                                  kind="joint", port=ports[urls[0]].url)
                       for name in source.names]  # a servo limb's joints: each its segment
            kind = "servo"
        port_list = list(ports.values())
        sims = [p.simulator for p in port_list if p.simulator is not None]
        if sims and len(sims) != len(port_list):
            sims = []  # a mixed rig counts as hardware: the clinician is prompted
        device_t0 = 0.0
        first = port_list[0].simulated_patient
        if kind == "imu" and all(p.simulated_patient is not None for p in port_list):
            device_t0 = first.device_t0
        return OpenRig(config, source, sensors, sims, kind, stack, port_list, device_t0)
    except BaseException:
        stack.close()
        raise


def _patient_performs_protocol(port, limb: str | None = None) -> None:
    """The simulated patient behind ``port`` (if any) performs the calibration protocol (the
    joint's, or the whole ``limb``'s), starting 2 s of patient time from now (the simulators
    sample it lazily, so the change takes effect from their next sample on) — unless it
    already does, or the port string says whether it does."""
    sp = port.simulated_patient
    if sp is None or sp.protocol_pinned or sp.limb.calibration_protocol is not None:
        return

    sp.start_protocol(procedure_for(limb).default_protocol(), lead_s=2.0)
