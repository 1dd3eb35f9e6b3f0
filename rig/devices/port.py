"""An opened port string (:class:`Port`) and what code above the seam may ask of a simulated
port's patient (:class:`SimulatedPatient`). Ports are made by :func:`rig.devices.ports.open_port`
(hardware paths) and the ``sim://`` backends (:mod:`rig.devices._sim_backends`)."""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from rig.sim.limb import SimulatedLimb

__all__ = ["Port", "SimulatedPatient"]


class SimulatedPatient:
    """A simulated port's patient, as code above the seam may see it.

    Parameters
    ----------
    limb : rig.sim.limb.SimulatedLimb
        The patient (ground truth).
    clock : callable
        The simulator's clock (seconds).
    clock_t0 : float
        The reading of ``clock`` at patient time 0.
    t0 : float
        Host time at patient time 0 (:attr:`t0`).
    scale : float
        Patient seconds per host second.
    device_t0 : float
        Device time (s) at patient time 0 of a device that timestamps its samples with the
        patient's time (the stream board); 0 otherwise.
    backdrive : object, optional
        What moves servos with the patient (``follow(joint_q) -> (servo_q, missed)``).
    protocol_pinned : bool
        The port string says whether the patient performs the calibration protocol
        (``calibrate=on|off``): a recorder leaves that as it is.
    on_protocol : callable, optional
        ``on_protocol(protocol, start_s)`` after :meth:`start_protocol` changed ``limb``: a
        board served by another process has the same patient perform it there (``limb`` is
        then this process's copy of that patient, its ground truth).

    Attributes
    ----------
    limb : rig.sim.limb.SimulatedLimb
    t0 : float
        When the patient's motion time was 0. On the real clock (the default) and a
        ``time_scale=`` one: host monotonic time, ``limb.joint((t - t0) * scale)`` is the truth
        at host time ``t`` (:meth:`time_at`). On a ``clock=manual`` simulator host time does not
        move the patient: it is the simulator clock's reading, and :meth:`now` is the
        patient's time.
    scale : float
    device_t0 : float
    protocol_pinned : bool
    """

    def __init__(self, limb: SimulatedLimb, *, clock: Callable[[], float], clock_t0: float,
                 t0: float, scale: float = 1.0, device_t0: float = 0.0,
                 backdrive: Any = None, protocol_pinned: bool = False,
                 on_protocol: Callable[[Any, float], None] | None = None) -> None:
        self.limb = limb
        self._on_protocol = on_protocol
        self.t0 = float(t0)
        self.scale = float(scale)
        self.device_t0 = float(device_t0)
        self.protocol_pinned = bool(protocol_pinned)
        self._clock = clock
        self._clock_t0 = float(clock_t0)
        self._backdrive = backdrive

    def time_at(self, host_t) -> np.ndarray:
        """The patient's time (s) at host monotonic times ``host_t`` (N,)."""
        return (np.asarray(host_t, dtype=np.float64) - self.t0) * self.scale

    def now(self) -> float:
        """The patient's time now (s), on the simulator's clock."""
        return float(self._clock()) - self._clock_t0

    @property
    def back_drives(self) -> bool:
        """Whether the patient moves servos (torque off) through its kinematics."""
        return self._backdrive is not None

    def follow(self, joint_q) -> tuple[np.ndarray, int]:
        """The orientations the back-driven servos take, from their zero, while the patient
        moves through ``joint_q`` — (N, 4) for a joint, (N, J, 4) postures for a limb; the
        result the same shape — unquantised, and at how many instants a joint was out of
        reach.

        Raises
        ------
        ValueError
            The port does not back-drive servos (:attr:`back_drives`).
        """
        if self._backdrive is None:
            raise ValueError("this port's simulated patient back-drives no servo chain")
        q = np.asarray(joint_q, dtype=np.float64)
        out, missed = self._backdrive.follow(q.reshape(len(q), -1, 4))
        return out.reshape(q.shape), missed

    def start_protocol(self, protocol, lead_s: float = 2.0) -> None:
        """Have the patient perform ``protocol`` from ``lead_s`` seconds of patient time after
        now (the simulators sample the patient lazily: the change applies from their next
        sample on)."""
        start_s = max(0.0, self.now()) + float(lead_s)
        self.limb.perform_protocol(protocol, start_s=start_s)
        if self._on_protocol is not None:
            self._on_protocol(protocol, start_s)


@dataclass
class Port:
    """An opened port string.

    Attributes
    ----------
    url : str
        The port string as given.
    path : str
        What ``dynamixel_sdk.PortHandler`` / ``serial.Serial`` open (``/dev/ttyUSB0`` or the
        simulator's ``/dev/pts/N``).
    simulator : object or None
        The simulator serving :attr:`path` in this process (fault injection in tests); None
        for hardware and for a simulator in a process of its own (``process=on``).
    kind : str
        ``"hardware"``, ``"sim-dynamixel"``, ``"sim-bno055"`` or ``"sim-imu-stream"``.
    simulated_patient : SimulatedPatient or None
        The simulated patient driving the simulator, if any (what code above the seam may ask
        of it).
    """

    url: str
    path: str
    simulator: Any = None
    kind: str = "hardware"
    simulated_patient: SimulatedPatient | None = None
    _closers: list[Callable[[], None]] = field(default_factory=list, repr=False)
    _closed: bool = field(default=False, repr=False)

    @property
    def patient(self) -> SimulatedLimb | None:
        """The :class:`rig.sim.limb.SimulatedLimb` driving the simulator (ground truth), or
        None: ``simulated_patient.limb``."""
        sp = self.simulated_patient
        return None if sp is None else sp.limb

    @property
    def patient_t0(self) -> float:
        """When the patient's motion time was 0 (:attr:`SimulatedPatient.t0`); 0 without a
        patient."""
        sp = self.simulated_patient
        return 0.0 if sp is None else sp.t0

    def add_closer(self, fn: Callable[[], None]) -> None:
        """Run ``fn`` (once) when the port is closed; closers run in reverse order."""
        self._closers.append(_Once(fn))

    @property
    def is_simulated(self) -> bool:
        """A simulator serves the port (in this process or another one)."""
        return self.kind != "hardware"

    @property
    def closed(self) -> bool:
        return self._closed

    def current_path(self) -> str:
        """The path to (re)open now: a simulator's adapter replug opens a new pty."""
        sim_port = getattr(self.simulator, "port", None)
        return sim_port if isinstance(sim_port, str) and sim_port else self.path

    def close(self) -> None:
        """Stop the simulator (if any); idempotent."""
        if self._closed:
            return
        self._closed = True
        errors = []
        for fn in reversed(self._closers):
            try:
                fn()
            except Exception as err:  # keep closing the rest
                errors.append(err)
        self._closers.clear()
        if errors:
            raise errors[0]

    def __enter__(self) -> Port:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __str__(self) -> str:
        return self.url


class _Once:
    """A callable that runs ``fn`` once (thread-safe)."""

    def __init__(self, fn: Callable[[], None]) -> None:
        self._fn: Callable[[], None] | None = fn
        self._lock = threading.Lock()

    def __call__(self) -> None:
        with self._lock:
            fn, self._fn = self._fn, None
        if fn is not None:
            fn()
