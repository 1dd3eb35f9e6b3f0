"""Exceptions (and the hardware-alert event) of :mod:`rig`.

Hierarchy::

    RigError
     +-- RigConfigError (ValueError)        a configuration file or option is invalid
     +-- RigConnectionError (OSError)       a port is missing, busy, not a serial port, went
     |                                      away, or the device on it stopped answering
     +-- RigTimeoutError (TimeoutError)     a device did not answer in time (after retries)
     +-- RigProtocolError                   answers arrived but stayed garbled (after retries)
     +-- UnreachableError (ValueError)      an orientation / goal the servo chain cannot reach
     +-- HardwareAlertError                 a servo's hardware alert, raised on the safe-state
     |                                      path (carries the :class:`HardwareAlert`)
     +-- SafetyError                        the supervisor refused a command or stopped motion

    HardwareAlert                           an *event* (dataclass), not an exception: a
                                            Dynamixel's alert bit / Hardware Error Status; the
                                            instruction that reported it still ran

Every error may carry ``port``, ``dxl_id``, ``actual`` and ``expected`` (keyword arguments);
those given are named in the message (``"sim://dynamixel?ids=1: ID 2: no answer (got ...,
expected ...)"``), the style of dynamixel2-rs's error type.

The other packages keep their own roots, as libraries usable alone must:
:class:`models.errors.ModelsError` (constraints, quaternions, datasets, model files),
:class:`calibration.errors.CalibrationError` (calibration and extraction data that cannot
determine a result) and :class:`firmware_protocol.errors.ProtocolError` (bytes that are not a
frame). :func:`user_errors` names them all, with the file errors a user's path causes: the
one mapping the CLI (:func:`rig.cli.main`: one line ``rig: error: ...``, exit status 2, no
traceback) and the application's own "did the user give something wrong?" checks use.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Any

__all__ = [
    "HardwareAlert",
    "HardwareAlertError",
    "RigConfigError",
    "RigConnectionError",
    "RigError",
    "RigProtocolError",
    "RigTimeoutError",
    "SafetyError",
    "UnreachableError",
    "user_errors",
]

_UNSET: Any = object()


class RigError(Exception):
    """Base class of every error raised by :mod:`rig`.

    Parameters
    ----------
    message : str
        What went wrong (and, where it helps, what to do).
    port : str, optional
        The port string the device was opened with; prefixed to the message.
    dxl_id : int, optional
        Servo ID; named after the port.
    actual, expected : optional
        The value found and the value wanted; appended as ``(got ..., expected ...)``.
    """

    def __init__(self, message: str = "", *, port: str | None = None, dxl_id: int | None = None,
                 actual: Any = _UNSET, expected: Any = _UNSET) -> None:
        self.port = port
        self.dxl_id = dxl_id
        self.actual = None if actual is _UNSET else actual
        self.expected = None if expected is _UNSET else expected
        self.detail = message
        prefix = ""
        if port is not None and not str(message).startswith(str(port)):
            prefix += f"{port}: "
        if dxl_id is not None:
            prefix += f"ID {dxl_id}: "
        text = prefix + str(message)
        parts = []
        if actual is not _UNSET:
            parts.append(f"got {actual!r}" if not isinstance(actual, str) else f"got {actual}")
        if expected is not _UNSET:
            parts.append(f"expected {expected!r}" if not isinstance(expected, str)
                         else f"expected {expected}")
        if parts:
            text += f" ({', '.join(parts)})"
        super().__init__(text)

    def __reduce__(self):  # picklable across processes despite keyword-only arguments
        return (_rebuild, (type(self), str(self), self.port, self.dxl_id, self.actual,
                           self.expected))


def _rebuild(cls, text, port, dxl_id, actual, expected):
    err = cls.__new__(cls)
    Exception.__init__(err, text)
    err.port, err.dxl_id, err.actual, err.expected = port, dxl_id, actual, expected
    err.detail = text
    return err


class RigConfigError(RigError, ValueError):
    """A configuration file, port string or command-line option is invalid."""


class RigConnectionError(RigError, OSError):
    """A port is missing, busy, not a serial port or disconnected; or its device went silent."""

    def __str__(self) -> str:  # OSError would format (errno, strerror) pairs otherwise
        return str(self.args[0]) if self.args else ""


class RigTimeoutError(RigError, TimeoutError):
    """A device did not answer before the deadline (retries included)."""

    def __str__(self) -> str:
        return str(self.args[0]) if self.args else ""


class RigProtocolError(RigError):
    """A device answered, but with garbled or unexpected bytes, every time it was asked."""


class UnreachableError(RigError, ValueError):
    """An orientation or goal the servo chain cannot reach (IK has no solution within the
    configured tick limits). Never silently clipped."""


class SafetyError(RigError):
    """The safety supervisor refused a command or stopped motion."""


@dataclass(frozen=True)
class HardwareAlert:
    """A servo reported a hardware error: an event, not an exception.

    Attributes
    ----------
    port : str
        Port string of the bus.
    dxl_id : int
        Servo ID.
    t : float
        Host monotonic time of the poll that read it, s.
    error_status : int
        Hardware Error Status (address 70) bits; 0 when only the Bus Watchdog fired.
    names : tuple of str
        Decoded bits (``"overload"``, ``"overheating"``, ``"input_voltage"``, ``"encoder"``,
        ``"electrical_shock"``, ``"bus_watchdog"``).
    torque : bool or None
        Torque Enable as the servo reports it (None if it could not be read).
    """

    port: str
    dxl_id: int
    t: float
    error_status: int
    names: tuple[str, ...]
    torque: bool | None

    @property
    def message(self) -> str:
        torque = {True: "on", False: "off", None: "unknown"}[self.torque]
        return (f"{self.port}: ID {self.dxl_id}: hardware alert {', '.join(self.names) or '?'} "
                f"(Hardware Error Status 0x{self.error_status:02X}); torque {torque}")


class HardwareAlertError(RigError):
    """Raised where a :class:`HardwareAlert` must stop the caller (the safe-state path).

    Attributes
    ----------
    alert : HardwareAlert
    """

    def __init__(self, alert: HardwareAlert) -> None:
        self.alert = alert
        super().__init__(alert.message)



@functools.cache
def user_errors() -> tuple[type[BaseException], ...]:
    """Exceptions that mean "the user gave something wrong" — a file, an option, a port, a
    recording that cannot give the answer asked of it: shown as one line, never a traceback.
    (The packages' roots are imported on the first call: ``rig --help`` stays fast.)"""
    # lazy: importing these runs the packages' __init__ (numpy, scipy and their native BLAS
    # threads); `rig sim` imports this module and must block its stop signals before any
    # thread exists (rig.commands.sim.serve), or a SIGINT can land on a BLAS thread
    from calibration.errors import CalibrationError
    from firmware_protocol.errors import ProtocolError
    from models.errors import ModelsError

    return (RigError, ModelsError, CalibrationError, ProtocolError,
            FileNotFoundError, PermissionError, IsADirectoryError, NotADirectoryError)
