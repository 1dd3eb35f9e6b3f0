"""The servo bus: servos by ID, name and register — ticks, torque, alerts, watchdog.

A servo bus knows no kinematics. It holds named servos, each with the goal range its
position-limit registers allow, reads their present positions and writes their goals as one
tick vector (the servos' order), turns torque on and off, reports hardware alerts and arms the
servos' watchdog. What turns a joint's ticks into its orientation sits above it
(:mod:`rig.devices.kinematics`); :class:`rig.devices.servo_limb.ServoLimb` composes the two.

Template methods (after python-can's ``BusABC``): the public methods here own argument checks,
the retries (:meth:`rig.devices.base.Device.transact`) and the alert flag; a backend implements
the hooks below. Hooks a backend cannot offer have defaults, so a caller never asks a bus
whether it has a method:

=========================  ============================================  =====================
hook                       called by                                     default
=========================  ============================================  =====================
``_read_ticks(deadline)``  :meth:`ServoBus.read_ticks` (retried)          required
``_begin_read()``          :meth:`ServoBus.begin_read`                   nothing sent
``_finish_read()``         :meth:`ServoBus.finish_read`                  ``_read_ticks``
``_write_goal_ticks(t)``   :meth:`ServoBus.write_goal_ticks` (checked)    required
``_read_torque()``         :meth:`ServoBus.torque`                        required
``_write_torque(on)``      :meth:`ServoBus.set_torque`                    required
``_poll_alerts()``         :meth:`ServoBus.poll_alerts`                   no alerts
``_arm_watchdog(ms)``      :meth:`ServoBus.arm_watchdog` / ``disarm``     no watchdog (0 ms)
``configure()``            start-up registers                            nothing to write
``feed_watchdog()``        a loop with nothing else to send               nothing (every
                                                                         transaction feeds it)
=========================  ============================================  =====================

A backend whose read also returns the Goal Position each servo holds (the Dynamixel bus with
indirect addressing) sets :attr:`ServoBus.held_goals` in its read; the others leave it None (the
loop then cannot check that its goals landed).

A split read (:meth:`ServoBus.begin_read` sends the request, :meth:`ServoBus.finish_read`
collects the reply) lets a caller work while the reply is on its way (the loop computes its
goal then); a backend that sends and collects in one step inherits the defaults (nothing sent at
the begin, the whole read at the finish). A backend with a real split makes its
``_read_ticks`` the begin and the finish in a row, so both paths are one mechanism.

Every bus is a context manager with an idempotent :meth:`~rig.devices.base.Device.close`
(alias :meth:`ServoBus.shutdown`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from rig.devices.base import Device
from rig.devices.ports import Port
from rig.devices.servo import Servo
from rig.errors import (
    HardwareAlert,
    HardwareAlertError,
    RigConfigError,
    RigProtocolError,
    UnreachableError,
)

__all__ = ["ServoBus"]


def _as_servo(item: Servo | int) -> Servo:
    if isinstance(item, Servo):
        return item
    if isinstance(item, (int, np.integer)) and not isinstance(item, bool):
        return Servo(int(item))
    raise TypeError(f"a servo is a Servo or an ID, got {item!r}")


class ServoBus(Device):
    """Base class of servo buses (see the module docstring).

    Parameters
    ----------
    port : str or Port
        As :class:`~rig.devices.base.Device`.
    servos : sequence of Servo or int
        The servos, in tick-vector order; distinct IDs.
    baud, timeout, retries
        As :class:`~rig.devices.base.Device`.
    watchdog_ms : int
        The watchdog :meth:`arm_watchdog` arms when asked for no value (0: off).

    Attributes
    ----------
    servos : tuple of Servo
    ids : tuple of int
    alert_pending : bool
        A reply carried an alert since the last :meth:`poll_alerts` (a backend without alert
        flags leaves it False).
    watchdog_ms : int
    advice : list of str
        One-line hints found at open (e.g. the adapter's USB latency timer).
    held_goals : (n,) int64 ndarray or None
        The goal each servo held at the last successful read of present positions (tick-vector
        order), as the servos report it; None when the backend does not read it back.
    """

    kind = "servo bus"
    read_what = "read of present positions"
    """How a failed :meth:`read_ticks` is described in its error."""

    def __init__(self, port: str | Port, servos: Sequence[Servo | int], *,
                 baud: int | None = None, timeout: float | None = None,
                 retries: int | None = None, watchdog_ms: int = 0) -> None:
        servos = tuple(_as_servo(s) for s in servos)
        ids = [s.id for s in servos]
        if not servos or len(set(ids)) != len(ids):
            raise RigConfigError("a servo bus needs servos with distinct IDs", actual=ids)
        self._set_servos(servos)
        self.watchdog_ms = int(watchdog_ms)
        self.alert_pending = False
        self.advice: list[str] = []
        self.held_goals: np.ndarray | None = None
        self._reading = False
        super().__init__(port, baud=baud, timeout=timeout, retries=retries)

    def _set_servos(self, servos: tuple[Servo, ...]) -> None:
        self.servos = servos
        self.ids = tuple(s.id for s in servos)
        self._lo = [s.min_ticks for s in servos]
        self._hi = [s.max_ticks for s in servos]

    # -- names ----------------------------------------------------------------------------
    @property
    def names(self) -> tuple[str, ...]:
        """Each servo's name (its ID as text when it has none), in tick-vector order."""
        return tuple(s.name if s.name else str(s.id) for s in self.servos)

    def index(self, key: int | str) -> int:
        """Position in the tick vector of the servo with ID ``key`` (int) or name ``key``."""
        where = self.ids if isinstance(key, int) else self.names
        try:
            return where.index(key)
        except ValueError:
            raise KeyError(f"no servo {key!r} on the bus (IDs {list(self.ids)}, names "
                           f"{list(self.names)})") from None

    @property
    def min_ticks(self) -> np.ndarray:
        """Each servo's lowest allowed goal, (n,) int64."""
        return np.array(self._lo, dtype=np.int64)

    @property
    def max_ticks(self) -> np.ndarray:
        """Each servo's highest allowed goal, (n,) int64."""
        return np.array(self._hi, dtype=np.int64)

    def shutdown(self) -> None:
        """:meth:`close` (python-can's name); idempotent."""
        self.close()

    # -- the cycle ------------------------------------------------------------------------
    def read_ticks(self) -> np.ndarray:
        """Present position of every servo, (n,) int64 ticks, in one transaction.

        Raises
        ------
        RigTimeoutError, RigProtocolError
            After the retries.
        RigConnectionError
            The adapter is gone.
        """
        return self.transact(self._read_ticks, self.read_what)

    def _read_ticks(self, deadline: float) -> np.ndarray:
        raise NotImplementedError

    def begin_read(self) -> None:
        """Send the request of a read of present positions and return at once (no reply
        awaited, no retry); :meth:`finish_read` collects the reply. Nothing else may use the
        bus in between.

        Raises
        ------
        RigConnectionError
            The adapter is gone (or the request could not be sent).
        """
        self._check_open()
        self._begin_read()
        self._reading = True

    def finish_read(self) -> np.ndarray:
        """The reply of the read :meth:`begin_read` sent: present position of every servo,
        (n,) int64 ticks. One attempt (a caller retries with :meth:`read_ticks`); its timeout
        counts from the request.

        Raises
        ------
        RigTimeoutError, RigProtocolError
            No reply / a garbled one.
        RigConnectionError
            The adapter is gone.
        RuntimeError
            No read was begun.
        """
        self._check_open()
        if not self._reading:
            raise RuntimeError("finish_read() without begin_read()")
        self._reading = False
        return self._finish_read()

    def _begin_read(self) -> None:
        return None

    def _finish_read(self) -> np.ndarray:
        return self._read_ticks(self.deadline())

    def check_goal(self, ticks: Sequence[int]) -> None:
        """Raise :class:`UnreachableError` if a goal is outside its servo's tick limits."""
        if len(ticks) != len(self.ids):
            raise ValueError(f"expected {len(self.ids)} goal ticks, got {len(ticks)}")
        for k, t in enumerate(ticks):
            if not self._lo[k] <= t <= self._hi[k]:
                raise UnreachableError("goal outside the joint's tick limits", port=str(self.port),
                                       dxl_id=self.ids[k], actual=int(t),
                                       expected=f"{self._lo[k]}..{self._hi[k]}")

    def write_goal_ticks(self, ticks: Sequence[int]) -> None:
        """Goal position of every servo (no reply awaited, no retry).

        Raises
        ------
        UnreachableError
            A goal outside its servo's ``[min_ticks, max_ticks]``: nothing is sent.
        RigConnectionError
            The adapter is gone.
        """
        self._check_open()
        ticks = [int(t) for t in ticks]
        self.check_goal(ticks)
        self._write_goal_ticks(ticks)

    def _write_goal_ticks(self, ticks: list[int]) -> None:
        raise NotImplementedError

    def set_position_limits(self, min_ticks: Sequence[int], max_ticks: Sequence[int]) -> None:
        """Replace every servo's goal range (no bus traffic): :meth:`write_goal_ticks` checks
        goals against it and the next :meth:`configure` writes it.

        Raises
        ------
        ValueError
            Not one min and one max per servo.
        """
        lo, hi = np.asarray(min_ticks), np.asarray(max_ticks)
        if lo.shape != (len(self.ids),) or hi.shape != (len(self.ids),):
            raise ValueError(f"need {len(self.ids)} min and max ticks, got {lo.shape}, "
                             f"{hi.shape}")
        self._set_servos(tuple(Servo(s.id, s.name, int(a), int(b))
                               for s, a, b in zip(self.servos, lo, hi, strict=True)))

    # -- torque ---------------------------------------------------------------------------
    def torque(self) -> np.ndarray:
        """Torque as each servo reports it, (n,) bool."""
        return np.asarray(self._read_torque(), dtype=bool)

    def _read_torque(self) -> Sequence[bool]:
        raise NotImplementedError

    def set_torque(self, on: bool) -> np.ndarray:
        """Torque on/off on every servo; returns the state the servos then report.

        Raises
        ------
        HardwareAlertError
            Torque on was asked but a servo in hardware-error shutdown stays off.
        RigProtocolError
            Torque on was asked but a servo stays off with no alert to say why.
        """
        self._write_torque(bool(on))
        state = self.torque()
        if on and not state.all():
            alerts = {a.dxl_id: a for a in self.poll_alerts()}
            off = [i for i, s in zip(self.ids, state, strict=True) if not s]
            if off[0] in alerts:
                raise HardwareAlertError(alerts[off[0]])
            raise RigProtocolError("torque did not come on", port=str(self.port),
                                   dxl_id=off[0])
        return state

    def _write_torque(self, on: bool) -> None:
        raise NotImplementedError

    def configure(self) -> None:
        """Write the start-up registers a control loop depends on (default: none)."""
        return None

    # -- alerts and watchdog --------------------------------------------------------------
    def poll_alerts(self) -> list[HardwareAlert]:
        """Current hardware alerts, one per servo in error (default: none). Clears
        :attr:`alert_pending`."""
        alerts = self._poll_alerts()
        self.alert_pending = False
        return alerts

    def _poll_alerts(self) -> list[HardwareAlert]:
        return []

    def arm_watchdog(self, ms: int | None = None) -> int:
        """Arm the servos' watchdog: with torque on, a servo that hears nothing from the host
        for ``ms`` stops. ``ms`` default :attr:`watchdog_ms`; 0 disarms (and clears a fired
        watchdog). Returns the ms set (0 on a bus without a watchdog)."""
        return self._arm_watchdog(self.watchdog_ms if ms is None else int(ms))

    def _arm_watchdog(self, ms: int) -> int:
        return 0

    def disarm_watchdog(self) -> None:
        """:meth:`arm_watchdog` with 0."""
        self.arm_watchdog(0)

    def feed_watchdog(self) -> None:
        """Tell the servos the host is alive without moving them (default: nothing — on a bus
        whose every transaction feeds the watchdog, the cycle's own read does)."""
        return None
