"""``sim://`` backends of :func:`rig.devices.ports.open_port` (imported only when used).

:func:`open_sim_port` starts the simulator a port string names (:data:`rig.sim.urls.SIM_DEVICES`)
on a pseudo-terminal and returns a :class:`~rig.devices.ports.Port` whose ``close`` stops it,
with the :class:`~rig.devices.ports.SimulatedPatient` view of its patient. The query is parsed
once, by :class:`rig.sim.urls.SimUrl`; the simulated patient (``patient=`` and the other patient
keys) is resolved by :func:`rig.sim.patients.patient_from_url`, for the IMU simulators and the
back-driven servo chain alike.

Back-driving (``sim://dynamixel?...&patient=...``): each servo's hand position is a function of
the simulator's clock, ``ticks_i(t) = IK(limb.joint(t - t0))_i`` with the chain's closed-form
inverse kinematics (:class:`rig.devices.kinematics.ChainKinematics`), evaluated once per
millisecond of simulated time and shared by the servos; the IK solution nearest the previous one
keeps the joint angles continuous. While torque is off, Present Position follows it
(:meth:`rig.sim.dynamixel.DynamixelBus.set_hand`), as a clinician moving a back-drivable limb.
"""

from __future__ import annotations

import threading
from typing import Any

import numpy as np

from rig.devices.port import Port, SimulatedPatient
from rig.errors import RigConfigError, UnreachableError

BACKDRIVE_KEYS = ("patient", "chain", "speed", "excursion")
"""The keys a ``sim://dynamixel`` URL takes besides the bus's: the back-driving patient's
(``seed`` is the bus's, shared)."""


def open_sim_port(url: str, *, baud: int | None = None) -> Port:
    """The port of the simulator ``url`` names (``baud``: the host's line speed, which a
    simulated Dynamixel chain without ``baud=`` runs at)."""
    from rig.sim.urls import sim_device_of

    device = sim_device_of(url)
    if device.name == "dynamixel":
        return _open_dynamixel(url, baud, device.kind)
    return _open_imu(url, device.start(url), device.kind)


def _patient(limb: Any, clock: Any, clock_t0: float, **kwargs: Any) -> SimulatedPatient:
    """The view of a patient whose motion time is 0 when the simulator's ``clock`` reads
    ``clock_t0``: :attr:`~rig.devices.ports.SimulatedPatient.t0` is host monotonic time on the
    real clock and on a :class:`~rig.sim.clock.ScaledClock` (its ``host_time``), the clock's own
    reading on a :class:`~rig.sim.clock.ManualClock` (whose time no host time corresponds to)."""
    from rig.sim.clock import ScaledClock

    if isinstance(clock, ScaledClock):
        t0, scale = float(clock.host_time(clock_t0)), clock.scale
    else:
        t0, scale = float(clock_t0), 1.0
    return SimulatedPatient(limb, clock=clock, clock_t0=clock_t0, t0=t0, scale=scale, **kwargs)


class _BackDrive:
    """Joint ticks of a simulated patient through the chain's IK, cached per millisecond."""

    def __init__(self, limb: Any, kinematics: Any, t0: float) -> None:
        self.limb = limb
        self.kin = kinematics
        self.t0 = t0
        self._lock = threading.Lock()
        self._key: int | None = None
        self._ticks = kinematics.zero_ticks.astype(np.float64)
        self.unreachable = 0

    def ticks(self, now: float) -> np.ndarray:
        key = int(now * 1000.0)
        with self._lock:
            if key != self._key:
                self._key = key
                q = self.limb.joint(max(0.0, key / 1000.0 - self.t0))[0]
                self._ticks, reached = self._step(q, self._ticks)
                self.unreachable += not reached
            return self._ticks

    def _step(self, q: np.ndarray, ticks: np.ndarray) -> tuple[np.ndarray, bool]:
        """The chain's ticks for limb orientation ``q``: the IK solution nearest ``ticks``, or
        ``ticks`` unchanged where ``q`` is out of reach (the servo limb cannot follow: it stays
        put). Also says whether ``q`` was reached."""
        try:
            return self.kin.inverse_float(q, ticks), True
        except UnreachableError:
            return ticks, False

    def follow(self, joint_q: np.ndarray) -> tuple[np.ndarray, int]:
        """The orientations (N, 4) the chain takes, from its zero, while the patient moves
        through ``joint_q`` (N, 4), unquantised, and how many of them were out of reach."""
        ticks = self.kin.zero_ticks.astype(np.float64)
        out = np.empty((len(joint_q), len(ticks)))
        missed = 0
        for i, q in enumerate(joint_q):
            ticks, reached = self._step(q, ticks)
            missed += not reached
            out[i] = ticks
        return self.kin.forward_batch(out), missed

    def hand(self, index: int):
        return lambda now: float(self.ticks(now)[index])


def _open_dynamixel(url: str, baud: int | None, kind: str) -> Port:
    from rig.sim.dynamixel.url import DEVICES, EXAMPLE, KEYS, bus_from_query
    from rig.sim.urls import SimUrl

    overrides: dict[str, Any] = {}
    try:
        q = SimUrl(url, DEVICES, (*KEYS, *BACKDRIVE_KEYS), EXAMPLE)
        if "baud" not in q and baud is not None:
            overrides["baud_rate"] = int(baud)
        bus = bus_from_query(q, **overrides)
    except RigConfigError as err:  # every message names the URL
        raise RigConfigError(str(err) if url in str(err) else f"{url}: {err}") from err
    port = Port(url=url, path=bus.port, simulator=bus, kind=kind)
    port.add_closer(bus.close)
    own = [k for k in BACKDRIVE_KEYS if k in q]
    if "patient" not in q:
        if own:
            port.close()
            raise RigConfigError(f"{url}: {', '.join(sorted(own))} need patient=")
        return port
    try:
        port.simulated_patient = _back_driving_patient(q, bus)
    except BaseException:
        port.close()
        raise
    return port


def _back_driving_patient(q: Any, bus: Any) -> SimulatedPatient:
    """The patient of ``q`` moving ``bus``'s servos through the ``chain=`` kinematics."""
    from rig.devices.config import load_rig_config
    from rig.sim.patients import patient_from_url

    url = q.url
    chain_name = q.text("chain", "sim-shoulder")
    cfg = load_rig_config(chain_name)
    if cfg.servos is None:
        raise RigConfigError(f"{url}: chain={chain_name!r} has no servo chain")
    kin = cfg.servos.kinematics()
    missing = [i for i in kin.ids if i not in bus.servos]
    if missing:
        raise RigConfigError(f"{url}: chain {chain_name!r} needs servo IDs {list(kin.ids)}, "
                             f"the simulated bus has no ID {missing[0]}")
    # a servo limb wears no IMU: the default straps (the motion does not depend on them)
    limb = patient_from_url(q, sensors=2, misplaced_straps=False)
    t0 = bus.clock()
    drive = _BackDrive(limb, kin, t0)
    for k, dxl_id in enumerate(kin.ids):
        bus.set_hand(dxl_id, drive.hand(k))
    return _patient(limb, bus.clock, t0, backdrive=drive)


def _open_imu(url: str, sim: Any, kind: str) -> Port:
    from rig.sim.imu import StreamImuSimulator
    from rig.sim.urls import query_keys

    port = Port(url=url, path=sim.port, simulator=sim, kind=kind)
    port.add_closer(sim.close)
    try:
        # the simulator samples its patient at clock() - started_at (its device time); a
        # stream board's samples carry that time, from its timestamp offset
        device_t0 = (sim.timestamp_offset_us / 1e6 if isinstance(sim, StreamImuSimulator)
                     else 0.0)
        port.simulated_patient = _patient(sim.limb, sim.clock, sim.started_at,
                                          device_t0=device_t0,
                                          protocol_pinned="calibrate" in query_keys(url))
    except BaseException:
        port.close()
        raise
    return port
