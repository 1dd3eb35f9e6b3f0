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

Unknown query keys are errors naming the key. A simulator is started by :func:`open_port` and
stopped by :meth:`Port.close`.
"""

from __future__ import annotations

import contextlib
import importlib
import os
import stat
import threading
import urllib.parse
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from rig.errors import RigConfigError, RigConnectionError

__all__ = ["BACKENDS", "Port", "open_port", "parse_sim_url"]


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
    patient : object or None
        The :class:`rig.sim.limb.SimulatedLimb` driving a simulator (ground truth), if any.
    patient_t0 : float
        When the patient's motion time was 0. On the real clock (the default) and a
        ``time_scale=`` one: host monotonic time, ``limb.joint((t - patient_t0) * scale)`` is
        the truth at host time ``t`` (``scale``: the simulator clock's, 1 on real time). On a
        ``clock=manual`` simulator host time does not move the patient: it is the simulator
        clock's reading, ``limb.joint(simulator.clock() - patient_t0)`` is the truth now.
    """

    url: str
    path: str
    simulator: Any = None
    kind: str = "hardware"
    patient: Any = None
    patient_t0: float = 0.0
    _closers: list[Callable[[], None]] = field(default_factory=list, repr=False)
    _closed: bool = field(default=False, repr=False)

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


#: scheme netloc -> (module, function) opening that simulator; imported only when used.
BACKENDS: dict[str, tuple[str, str]] = {
    "dynamixel": ("rig.devices._sim_backends", "open_sim_dynamixel"),
    "dxl": ("rig.devices._sim_backends", "open_sim_dynamixel"),
    "bno055": ("rig.devices._sim_backends", "open_sim_bno055"),
    "imu-stream": ("rig.devices._sim_backends", "open_sim_imu_stream"),
    "stream": ("rig.devices._sim_backends", "open_sim_imu_stream"),  # short form
}


def parse_sim_url(url: str, known: set[str] | frozenset[str]) -> dict[str, str]:
    """Query of a ``sim://`` URL as ``{key: last value}``; unknown keys are errors naming them."""
    parts = urllib.parse.urlsplit(url)
    try:
        query = urllib.parse.parse_qs(parts.query, keep_blank_values=True, strict_parsing=False)
    except ValueError as err:
        raise RigConfigError(f"port {url!r}: bad query ({err})") from err
    unknown = sorted(set(query) - set(known))
    if unknown:
        raise RigConfigError(f"port {url!r}: unknown key {unknown[0]!r}; known keys: "
                             f"{', '.join(sorted(known))}")
    return {k: v[-1] for k, v in query.items()}


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
        scheme, rest = url.split("://", 1)
        if scheme != "sim":
            raise RigConfigError(f"port {url!r}: unknown scheme {scheme!r}; use a device path "
                                 f"(/dev/ttyUSB0, COM3) or sim://{{{','.join(sorted(BACKENDS))}}}")
        device = rest.split("?", 1)[0].strip("/")
        if device not in BACKENDS:
            raise RigConfigError(f"port {url!r}: unknown simulated device {device!r}; known: "
                                 f"{', '.join(sorted(BACKENDS))}")
        module, attr = BACKENDS[device]
        opener = getattr(importlib.import_module(module), attr)
        return opener(url, baud=baud)
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


def _closing(obj: Any) -> Callable[[], None]:
    def close() -> None:
        with contextlib.suppress(AttributeError):
            obj.close()
    return _Once(close)
