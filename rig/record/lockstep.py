"""Recording simulated rigs faster than real time: a manual clock driven in lockstep.

A simulator on a :class:`~rig.sim.clock.ManualClock` (``sim://imu-stream?...&clock=manual``)
produces samples only when its clock is advanced. :class:`LockstepClock` advances it from a
thread, by ``step_s`` simulated seconds at a time, never more than ``window_s`` simulated
seconds ahead of what the recorder has written (``written() -> samples``), so the device never
has more than a window of samples waiting for the host: any loss is the recorder's, and the
recording runs as fast as the host can take it. Until ``start()`` (the recorder has opened its
store and is about to read) the clock runs at real-time pace, so a driver that waits for the
first samples never sees a silent device.

:class:`CountingDisplay` is a display that only remembers how many samples have been written
(what the lockstep needs), optionally forwarding to another display.

Used by ``benchmarks/bench_record.py`` and the end-to-end accuracy test; nothing here is needed
on hardware.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

__all__ = ["CountingDisplay", "LockstepClock"]


class CountingDisplay:
    """A recorder display that counts the samples written (``samples``) and forwards every
    call to ``inner`` when given."""

    def __init__(self, inner=None) -> None:
        self.inner = inner
        self.samples = 0
        self.messages: list[str] = []

    def start(self) -> None:
        if self.inner is not None:
            self.inner.start()

    def stop(self) -> None:
        if self.inner is not None:
            self.inner.stop()

    def message(self, text: str) -> None:
        self.messages.append(text)
        if self.inner is not None:
            self.inner.message(text)

    def update(self, status, *, force: bool = False) -> None:
        self.samples = int(status.samples)
        if self.inner is not None:
            self.inner.update(status, force=force)


class LockstepClock:
    """Advance a manual clock in lockstep with a consumer (see the module docstring).

    Parameters
    ----------
    clock : ManualClock
        ``clock()`` (simulated seconds) and ``clock.advance(dt)``.
    written : callable() -> int
        Samples the recorder has written so far.
    samples_per_s : float
        Samples the device produces per simulated second (rate × sensors).
    step_s : float
        Simulated seconds per advance.
    window_s : float
        Most simulated seconds the clock may run ahead of ``written``.
    """

    def __init__(self, clock, written: Callable[[], int], samples_per_s: float, *,
                 step_s: float = 0.05, window_s: float = 0.5) -> None:
        if not (step_s > 0 and window_s >= step_s):
            raise ValueError("need 0 < step_s <= window_s")
        self.clock = clock
        self.written = written
        self.samples_per_s = float(samples_per_s)
        self.step_s = float(step_s)
        self.window_s = float(window_s)
        self._t0 = float(clock())
        self._go = threading.Event()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="rig-lockstep-clock", daemon=True)

    def __enter__(self) -> LockstepClock:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def start(self) -> None:
        """Leave real-time pace: from now on, as fast as the consumer writes."""
        self._go.set()

    def close(self) -> None:
        self._stop.set()
        if self._thread.ident is not None:
            self._thread.join()

    def _run(self) -> None:
        while not self._go.is_set() and not self._stop.is_set():
            self.clock.advance(self.step_s)
            time.sleep(self.step_s)
        ahead = self.window_s * self.samples_per_s
        while not self._stop.is_set():
            due = (float(self.clock()) - self._t0) * self.samples_per_s
            if due - self.written() < ahead:
                self.clock.advance(self.step_s)
            else:
                time.sleep(0.001)
