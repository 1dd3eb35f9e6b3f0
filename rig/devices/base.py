"""The device base class (template method, after python-can's ``BusABC``).

:class:`Device` owns the life cycle and the error policy; subclasses implement hooks:

* ``_open()`` — open :attr:`Device.path` and check the device is there (called by
  ``__init__``; on failure ``_close()`` runs and the port, and a simulator behind it, are
  closed again);
* ``_close()`` — release the device (called once by :meth:`Device.close`, idempotent);
* transactions go through :meth:`Device.transact`, which gives each attempt a monotonic
  deadline, retries :class:`~rig.errors.RigTimeoutError` and :class:`~rig.errors.RigProtocolError`
  a bounded number of times, and never retries :class:`~rig.errors.RigConnectionError` (an
  adapter that went away does not come back by asking again). After the last attempt the error
  is re-raised with the attempt count in its message.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import TypeVar

import serial

from rig.devices.ports import Port, open_port
from rig.errors import RigConnectionError, RigError, RigProtocolError, RigTimeoutError

__all__ = ["Device", "describe_open_error", "open_serial"]

T = TypeVar("T")


def describe_open_error(err: BaseException) -> str:
    """What went wrong opening a port, in the user's terms (``/dev/null`` → "not a serial
    port" rather than the OS's "Inappropriate ioctl for device")."""
    msg = getattr(err, "strerror", None) or str(err)
    return "not a serial port" if "Inappropriate ioctl" in msg else msg


def open_serial(path: str, baud: int, *, what: str, url: str):
    """A non-blocking :class:`serial.Serial` on ``path``, or :class:`RigConnectionError`
    naming ``what`` ("the BNO055 port") and the port string ``url``."""
    try:
        return serial.Serial(path, baudrate=baud, timeout=0)
    except (serial.SerialException, OSError) as err:
        raise RigConnectionError(f"cannot open {what}: {describe_open_error(err)}",
                                 port=url) from err


def close_serial(ser) -> None:
    """Close ``ser`` (a :class:`serial.Serial` or None), ignoring a port that is already gone
    (an unplugged adapter raises on close)."""
    if ser is not None:
        try:
            ser.close()
        except (OSError, serial.SerialException):
            pass


class Device:
    """Base class of every device driver.

    Parameters
    ----------
    port : str or Port
        A port string (opened here and closed with the device) or an already opened
        :class:`~rig.devices.ports.Port` (left open by :meth:`close`: its owner closes it).
    baud : int, optional
        Line speed.
    timeout : float, optional
        Seconds allowed per attempt (default :attr:`default_timeout`).
    retries : int, optional
        Extra attempts after a timeout or a garbled answer (default :attr:`default_retries`).

    Attributes
    ----------
    port : Port
        ``str(port)`` is the port string, used in every error message.
    retried : int
        Attempts repeated so far (a health figure for telemetry).
    """

    default_timeout: float = 0.2
    default_retries: int = 2
    kind: str = "device"

    def __init__(self, port: str | Port, *, baud: int | None = None,
                 timeout: float | None = None, retries: int | None = None) -> None:
        self.timeout = float(self.default_timeout if timeout is None else timeout)
        self.retries = int(self.default_retries if retries is None else retries)
        if self.timeout <= 0 or self.retries < 0:
            raise ValueError("timeout must be > 0 and retries >= 0")
        self.baud = baud
        self.retried = 0
        self._closed = False
        if isinstance(port, Port):
            self.port, self._owns_port = port, False
        else:
            self.port, self._owns_port = open_port(port, baud=baud), True
        try:
            self._open()
        except BaseException:
            self._closed = True
            try:
                self._close()  # whatever _open got as far as opening
            except Exception:
                pass
            finally:
                self._release_port()
            raise

    # -- template hooks -------------------------------------------------------------------
    def _open(self) -> None:
        raise NotImplementedError

    def _close(self) -> None:
        return None

    # -- life cycle -----------------------------------------------------------------------
    @property
    def path(self) -> str:
        """What pyserial / dynamixel_sdk open (the simulator's pty for ``sim://``)."""
        return self.port.current_path()

    @property
    def closed(self) -> bool:
        return self._closed

    def close(self) -> None:
        """Release the device and (if this device opened it) the port; idempotent."""
        if self._closed:
            return
        self._closed = True
        try:
            self._close()
        finally:
            self._release_port()

    def _release_port(self) -> None:
        if self._owns_port:
            self.port.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __del__(self) -> None:  # pragma: no cover - safety net only
        if not getattr(self, "_closed", True):
            try:
                self.close()
            except Exception:
                pass

    def _check_open(self) -> None:
        if self._closed:
            raise RigConnectionError(f"{self.kind} is closed", port=str(self.port))

    # -- transactions ---------------------------------------------------------------------
    def deadline(self, seconds: float | None = None) -> float:
        """Monotonic time ``seconds`` (default :attr:`timeout`) from now."""
        return time.monotonic() + (self.timeout if seconds is None else seconds)

    def transact(self, attempt: Callable[[float], T], what: str, *,
                 dxl_id: int | None = None) -> T:
        """Run ``attempt(deadline)`` with bounded retries (see the module docstring).

        Raises
        ------
        RigTimeoutError, RigProtocolError
            Every attempt failed; the message says ``what`` and how many attempts.
        RigConnectionError
            At once, without retrying.
        """
        self._check_open()
        last: RigError | None = None
        for k in range(self.retries + 1):
            if k:
                self.retried += 1
            try:
                return attempt(self.deadline())
            except (RigTimeoutError, RigProtocolError) as err:
                last = err
        assert last is not None
        n = self.retries + 1
        cls = type(last)
        raise cls(f"{what}: {last.detail} ({n} attempt{'s' if n > 1 else ''})",
                  port=str(self.port), dxl_id=last.dxl_id if dxl_id is None else dxl_id) \
            from last
