"""Drift-free periodic scheduling on a monotonic clock.

Cycle ``k`` is due at the absolute deadline ``t₀ + k T`` (``T = 1 / rate``), never at "last
wake-up + T", so sleep inaccuracy does not accumulate. A cycle that ends after the next
deadline is an **overrun**; the scheduler then runs one late cycle for the deadline that passed
last and skips the earlier ones — no burst of catch-up cycles (which would hammer the bus with
stale commands). Each cycle reports its **lateness**: how long after its deadline it started.

Sleeping: ``time.sleep`` until ``spin_s`` before the deadline, then a short busy-wait (the
kernel's sleep granularity on a loaded machine is coarser than a 5 ms period tolerates).

Tests and benchmarks run it on simulated time: ``clock=clk, sleep=clk.sleep`` with a
:class:`rig.sim.clock.ManualClock` (``sleep`` advances it and never blocks), so a loop runs as
fast as the CPU allows with the same arithmetic and deterministic timestamps. The real clock
path calls ``time.monotonic`` / ``time.sleep`` directly.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable

__all__ = ["Scheduler"]


class Scheduler:
    """Absolute-deadline periodic scheduler.

    Parameters
    ----------
    rate_hz : float
        Cycle rate.
    clock : callable, default time.monotonic
        Returns seconds (a :class:`rig.sim.clock.ManualClock` for simulated time).
    sleep : callable, default time.sleep
        Waits that many seconds of ``clock`` (``ManualClock.sleep`` for simulated time).
    spin_s : float, default 0.0003
        Busy-wait this long before each deadline instead of sleeping (0 with a manual clock).

    Attributes
    ----------
    period : float
        ``1 / rate_hz``, s.
    t0 : float
        Clock time of cycle 0's deadline (set by :meth:`start`).
    cycle : int
        Index of the current cycle (its deadline is ``t0 + cycle * period``).
    overruns : int
        Cycles that ended after the next deadline.
    skipped : int
        Deadlines dropped after overruns (never caught up).
    """

    def __init__(self, rate_hz: float, *, clock: Callable[[], float] = time.monotonic,
                 sleep: Callable[[float], None] = time.sleep, spin_s: float = 0.0003):
        if not (isinstance(rate_hz, (int, float)) and math.isfinite(rate_hz) and rate_hz > 0):
            raise ValueError(f"rate: expected a positive number of Hz, got {rate_hz!r}")
        self.rate_hz = float(rate_hz)
        self.period = 1.0 / self.rate_hz
        self.clock = clock
        self._sleep = sleep
        self.spin_s = float(spin_s)
        self.t0 = 0.0
        self.cycle = -1
        self.overruns = 0
        self.skipped = 0
        self._next = 0

    def start(self, t0: float | None = None) -> float:
        """Set cycle 0's deadline (now by default); returns it."""
        self.t0 = self.clock() if t0 is None else float(t0)
        self.cycle = -1
        self._next = 0
        self.overruns = 0
        self.skipped = 0
        return self.t0

    def deadline(self, k: int) -> float:
        """Absolute deadline of cycle ``k``."""
        return self.t0 + k * self.period

    def wait(self, before=None, lead_s: float = 0.0) -> tuple[int, float, float]:
        """Block until the next cycle is due.

        Parameters
        ----------
        before : callable, optional
            Called once while waiting, ``lead_s`` before the deadline (not at all when less
            than that is left): work that must not delay the cycle (the loop warms its
            compute path with it).
        lead_s : float
            How long before the deadline ``before`` is called, s; 0 calls it at once (a manual
            clock: one advance per cycle, as without it).

        Returns
        -------
        cycle : int
            Its index.
        deadline : float
            Its absolute deadline (clock seconds).
        start : float
            Clock time at which it actually started (``start − deadline`` is its lateness).
        """
        k = self._next
        due = self.t0 + k * self.period
        now = self.clock()
        if before is not None and due - now > lead_s:
            if lead_s > 0.0:
                self._sleep(due - now - lead_s)
            before()
            now = self.clock()
        remaining = due - now
        if remaining > self.spin_s:
            self._sleep(remaining - self.spin_s)
            now = self.clock()
        while now < due:
            if self.spin_s <= 0.0:
                self._sleep(due - now)
            now = self.clock()
        self.cycle = k
        return k, due, now

    def finish(self) -> bool:
        """Mark the current cycle done; returns True if it overran its period.

        After an overrun the next cycle is the one whose deadline passed last: it runs at once
        (late), every earlier missed deadline is skipped.
        """
        k = self.cycle
        now = self.clock()
        nxt = k + 1
        over = now > self.t0 + nxt * self.period
        if over:
            self.overruns += 1
            latest_past = math.floor((now - self.t0) / self.period)
            self.skipped += max(0, latest_past - nxt)
            nxt = max(nxt, latest_past)
        self._next = nxt
        return over
