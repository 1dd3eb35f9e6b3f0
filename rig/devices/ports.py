"""Port strings choose the backend: hardware serial ports or simulators on pseudo-terminals.

The seam in the style of pyserial's URL handlers and python-can's interface table: a port string
is resolved once, here, and every driver above opens :attr:`Port.path` with the unchanged
``dynamixel_sdk`` / ``pyserial`` — no code above this module knows whether it has hardware.

Port strings
------------
``/dev/ttyUSB0``, ``/dev/ttyACM0``, ``/dev/serial/by-id/...``, ``COM3``
    Hardware: the path is used as is. On POSIX it is checked at once (exists, is a character
    device, is a terminal), so a wrong path fails in milliseconds, not after a long job.
``sim://dynamixel?ids=1,2,3&model=XM430-W350&baud=57600&return_delay_us=0&noise=0&seed=0``
    A simulated X-series chain (:mod:`rig.sim.dynamixel`). ``baud`` is the *servos'* rate; when
    absent the servos run at the rate the host asks for (``open_port(..., baud=B)``), so a URL
    with ``baud=57600`` opened at 1 Mbit/s is a bus where nobody answers, as on hardware.
    Extra keys handled here: ``patient=<shape name | constraint file>`` back-drives the servos
    (torque off) from a :class:`rig.sim.limb.SimulatedLimb` through the inverse kinematics of
    ``chain=<rig config name | file>`` (default ``sim-shoulder``), so a recording of the
    servo limb sees a patient's motion; ``speed`` scales that motion's frequencies,
    ``excursion`` its reach.
``sim://bno055?patient=original&seed=0&rate=100&sensor=1&noise=on|off``
    A simulated BNO055 on its UART (:func:`rig.sim.imu.bno055_from_url` lists the keys).
``sim://imu-stream?sensors=2&rate=200&patient=original&seed=1&flow=off`` (or ``sim://stream?...``)
    A simulated multi-IMU board speaking the rig stream protocol
    (:func:`rig.sim.imu.stream_from_url`). Sensor 0 is on the thorax, 1.. on the upper arm.

Unknown query keys are errors naming the key (one parser for every ``sim://`` string:
:class:`rig.sim.urls.SimUrl`; the simulated devices: :data:`rig.sim.urls.SIM_DEVICES`). A
simulator is started by :func:`open_port` and stopped by :meth:`Port.close`.

What code above the seam may ask of a simulated port
----------------------------------------------------
:attr:`Port.simulated_patient` is a :class:`SimulatedPatient` (None on hardware and on a
simulator nobody drives): the ground-truth limb, the patient's time for a host time, whether the
port back-drives servos (:meth:`SimulatedPatient.follow`), and having the patient start the
calibration protocol (:meth:`SimulatedPatient.start_protocol`). Nothing above this module looks
into a simulator object for these.
"""

from __future__ import annotations

import importlib
import os
import stat
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from rig.errors import RigConfigError, RigConnectionError

if TYPE_CHECKING:
    from rig.sim.limb import SimulatedLimb

__all__ = ["Port", "SimulatedPatient", "open_port"]


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
        What moves a servo chain with the patient (``follow(joint_q) -> (chain_q, missed)``).
    protocol_pinned : bool
        The port string says whether the patient performs the calibration protocol
        (``calibrate=on|off``): a recorder leaves that as it is.

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
                 backdrive: Any = None, protocol_pinned: bool = False) -> None:
        self.limb = limb
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
        """Whether the patient moves a servo chain (torque off) through its kinematics."""
        return self._backdrive is not None

    def follow(self, joint_q) -> tuple[np.ndarray, int]:
        """The orientations (N, 4) the back-driven chain takes, from its zero, while the
        patient moves through ``joint_q`` (N, 4), unquantised, and how many of them were out
        of the chain's reach.

        Raises
        ------
        ValueError
            The port does not back-drive servos (:attr:`back_drives`).
        """
        if self._backdrive is None:
            raise ValueError("this port's simulated patient back-drives no servo chain")
        return self._backdrive.follow(np.asarray(joint_q, dtype=np.float64).reshape(-1, 4))

    def start_protocol(self, protocol, lead_s: float = 2.0) -> None:
        """Have the patient perform ``protocol`` from ``lead_s`` seconds of patient time after
        now (the simulators sample the patient lazily: the change applies from their next
        sample on)."""
        self.limb.perform_protocol(protocol, start_s=max(0.0, self.now()) + float(lead_s))


_SIM_BACKEND = "rig.devices._sim_backends:open_sim_port"
"""Opens every ``sim://`` port (it builds :class:`Port` objects: imported by name, and only when
a simulator is asked for)."""


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
        The simulator serving :attr:`path` (fault injection in tests), None for hardware.
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
        return self.simulator is not None

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


def open_port(url: str, *, baud: int | None = None) -> Port:
    """Resolve a port string: check a hardware path, or start a simulator.

    Parameters
    ----------
    url : str
        See the module docstring.
    baud : int, optional
        The line speed the host will use (a simulated Dynamixel chain without ``baud=`` in its
        URL runs its servos at this rate).

    Returns
    -------
    Port
        Close it (or use it as a context manager) to stop a simulator.

    Raises
    ------
    RigConfigError
        Unknown ``sim://`` device, unknown key or bad value.
    RigConnectionError
        A hardware path that does not exist or is not a serial port.
    """
    if not isinstance(url, str) or not url.strip():
        raise RigConfigError(f"port {url!r}: expected a device path or a sim:// URL")
    url = url.strip()
    if "://" in url:
        from rig.sim.urls import SIM_DEVICES

        scheme = url.split("://", 1)[0]
        if scheme != "sim":
            hosts = ",".join(sorted(SIM_DEVICES))
            raise RigConfigError(f"port {url!r}: unknown scheme {scheme!r}; use a device path "
                                 f"(/dev/ttyUSB0, COM3) or sim://{{{hosts}}}")
        module, func = _SIM_BACKEND.split(":")
        return getattr(importlib.import_module(module), func)(url, baud=baud)
    check_hardware_path(url)
    return Port(url=url, path=url)


def check_hardware_path(path: str) -> None:
    """Fail fast on a hardware path that cannot be a serial port (POSIX; no-op elsewhere).

    Raises
    ------
    RigConnectionError
        Missing path, not a character device, or not a terminal (e.g. ``/dev/null``).
    """
    if os.name != "posix":
        return
    try:
        st = os.stat(path)
    except FileNotFoundError:
        raise RigConnectionError("no such port (is the adapter plugged in? list candidates with "
                                 "`ls /dev/serial/by-id/`)", port=path) from None
    except OSError as err:
        raise RigConnectionError(f"cannot access the port: {err.strerror}", port=path) from err
    if not stat.S_ISCHR(st.st_mode):
        raise RigConnectionError("not a serial port (not a character device)", port=path)
    try:
        fd = os.open(path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
    except PermissionError as err:
        raise RigConnectionError("permission denied (add yourself to the 'dialout' group: "
                                 "`sudo usermod -aG dialout $USER`, then log in again)",
                                 port=path) from err
    except OSError as err:
        raise RigConnectionError(f"cannot open the port: {err.strerror}", port=path) from err
    try:
        if not os.isatty(fd):
            raise RigConnectionError("not a serial port (not a terminal device)", port=path)
    finally:
        os.close(fd)


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
