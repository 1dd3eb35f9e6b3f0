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

    def patient_time(self, batch) -> np.ndarray:
        """The simulated patient's own time (s) at each sample of ``batch`` (N,).

        A stream IMU simulator timestamps samples with the patient's time (its device clock
        starts with the patient), so ``device_t`` is used where present; otherwise host time
        minus the port's ``patient_t0``.
        """
        if not self.ports:
            raise ValueError("patient_time: not a simulated rig")
        if self.kind == "imu" and not np.isnan(batch.device_t).any():
            return batch.device_t - self.device_t0
        return batch.t - float(getattr(self.ports[0], "patient_t0", 0.0))

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


def open_rig(config, **source_options) -> OpenRig:
    """Open the rig's devices and its orientation source.

    Raises whatever the devices raise for a wrong port or a silent device
    (:class:`rig.errors.RigConnectionError`, :class:`rig.errors.RigTimeoutError`), before any
    sample is recorded.
    """
    from rig.devices import sources as S

    stack = contextlib.ExitStack()
    try:
        if getattr(config, "sensors", None) is not None:
            sc = config.sensors
            source = stack.enter_context(S.ImuSetSource.from_config(config, **source_options))
            sensors = [SensorInfo(name, segment=name, kind="sensor", port=str(sc.port))
                       for name in source.names]
            kind = "imu"
        elif getattr(config, "servos", None) is not None:
            source = stack.enter_context(S.ServoChainSource.from_config(config, **source_options))
            sensors = [SensorInfo(name, segment=config.joint.child, kind="joint",
                                  port=str(config.servos.port)) for name in source.names]
            kind = "servo"
        else:  # load_rig_config refuses this; a config built by hand might not
            from rig.errors import RigConfigError

            raise RigConfigError(f"rig {config.name!r} has neither sensors nor servos")
        sims = list(getattr(source, "simulators", []) or [])
        return OpenRig(config, source, sensors, sims, kind, stack)
    except BaseException:
        stack.close()
        raise
