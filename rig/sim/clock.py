"""Simulated time: the one manual clock of the project, and a scaled clock.

A *clock* is any zero-argument callable returning seconds; the real one is ``time.monotonic``
(the default of every simulator and of the live loop, which then calls it directly: no
wrapper on the real-time path). Two richer clocks let tests and benchmarks run time at their
own pace:

:class:`ManualClock`
    Moves only when the caller says (:meth:`ManualClock.advance`, or :meth:`ManualClock.sleep`
    for a loop that sleeps on it). Simulators subscribe to it, so an ``advance`` wakes their
    server threads at once: a stream IMU then emits every sample whose time has come — as fast
    as the host reads, far faster than real time — and nothing spins while the clock stands
    still. The live loop (:class:`rig.loop.scheduler.Scheduler`,
    :class:`rig.loop.runner.EnforcementLoop`) runs on it with ``clock=clk, sleep=clk.sleep``;
    sharing one with a simulated servo bus (``sim://dynamixel?...&clock=manual``) keeps the
    loop and the limb on one time.
:class:`ScaledClock`
    ``t = start + scale × (monotonic() − monotonic_at_creation)``: simulated time running
    ``scale`` times faster than real time (``sim://...&time_scale=20``); :meth:`ScaledClock.at`
    and :meth:`ScaledClock.host_time` convert between its readings and host monotonic time.

:func:`real_delay` converts a simulated interval into the real seconds a server thread should
wait for it (``None``: only an ``advance`` can bring it).
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable

__all__ = ["Clock", "ManualClock", "ScaledClock", "real_delay"]

Clock = Callable[[], float]
"""A zero-argument callable returning simulated seconds (monotonic, never going back)."""


class ManualClock:
    """Simulated seconds that move only when the caller advances them.

    Parameters
    ----------
    start : float
        Initial reading, seconds.

    Examples
    --------
    >>> clock = ManualClock()
    >>> clock.advance(0.5)
    >>> clock()
    0.5
    >>> clock.t += 0.25          # same as advance(0.25)
    >>> clock()
    0.75
    >>> clock.sleep(0.25)        # a loop sleeping on it: advances, never blocks
    >>> clock.sleep(-1.0)        # a deadline already passed: nothing to wait for
    >>> clock()
    1.0
    """

    def __init__(self, start: float = 0.0) -> None:
        if not math.isfinite(start):
            raise ValueError(f"start must be finite, got {start!r}")
        self._t = float(start)
        self._lock = threading.Lock()
        self._listeners: list[Callable[[], None]] = []

    def __call__(self) -> float:
        return self._t

    @property
    def t(self) -> float:
        """The current reading, seconds; assigning it is :meth:`set`."""
        return self._t

    @t.setter
    def t(self, value: float) -> None:
        self.set(value)

    def advance(self, dt: float) -> None:
        """Move the clock ``dt >= 0`` seconds forward and wake every subscribed simulator."""
        if not dt >= 0.0:
            raise ValueError(f"a clock only moves forward: dt={dt!r}")
        self.set(self._t + float(dt))

    def sleep(self, seconds: float) -> None:
        """Wait ``seconds`` on this clock: advance it (never blocks); ``<= 0`` does nothing.

        The ``sleep`` of a loop running on manual time
        (``Scheduler(rate, clock=clk, sleep=clk.sleep)``).
        """
        if seconds > 0.0:
            self.advance(seconds)

    def set(self, t: float) -> None:
        """Set the reading to ``t`` (not earlier than now) and wake the subscribers."""
        t = float(t)
        with self._lock:
            if not t >= self._t:
                raise ValueError(f"a clock only moves forward: {t!r} < {self._t!r}")
            self._t = t
            listeners = list(self._listeners)
        for wake in listeners:
            wake()

    def subscribe(self, wake: Callable[[], None]) -> Callable[[], None]:
        """Call ``wake()`` after every change; returns the function that unsubscribes."""
        with self._lock:
            self._listeners.append(wake)

        def unsubscribe() -> None:
            with self._lock:
                if wake in self._listeners:
                    self._listeners.remove(wake)

        return unsubscribe


class ScaledClock:
    """Simulated seconds running ``scale`` times as fast as ``time.monotonic``.

    Parameters
    ----------
    scale : float
        Simulated seconds per real second, > 0.
    start : float
        Reading at creation, seconds.
    """

    def __init__(self, scale: float, start: float = 0.0) -> None:
        if not (math.isfinite(scale) and scale > 0.0):
            raise ValueError(f"scale must be > 0, got {scale!r}")
        self.scale = float(scale)
        self._start = float(start)
        self._real0 = time.monotonic()

    def __call__(self) -> float:
        return self._start + self.scale * (time.monotonic() - self._real0)

    def at(self, host_t: float) -> float:
        """The reading at host monotonic time ``host_t``."""
        return self._start + self.scale * (float(host_t) - self._real0)

    def host_time(self, t: float) -> float:
        """The host monotonic time at which the clock reads ``t`` (inverse of :meth:`at`)."""
        return self._real0 + (float(t) - self._start) / self.scale


def real_delay(clock: Clock, sim_dt: float) -> float | None:
    """Real seconds until ``sim_dt`` simulated seconds of ``clock`` have passed.

    Returns ``None`` for a clock with ``subscribe`` (a :class:`ManualClock`): only an
    ``advance`` moves it, and the subscription wakes the waiter.
    """
    if hasattr(clock, "subscribe"):
        return None
    return max(0.0, sim_dt) / float(getattr(clock, "scale", 1.0))
