"""One pseudo-terminal server for every simulator: the pty, the server thread, one error policy.

A simulator is a device on the master side of a pseudo-terminal; the host opens the slave
(:attr:`PtyServer.port`, ``/dev/pts/N``) with pyserial or ``dynamixel_sdk`` exactly as it opens
``/dev/ttyUSB0``. This module owns everything that is not the device's protocol:

Thread
    One daemon thread waits on the pty master and a wake-up pipe — ``select`` while every fd
    number is below ``FD_SETSIZE`` (microsecond timeouts: Dynamixel return delays are tens of
    µs), ``poll`` beyond it (``select`` cannot take fd >= 1024) — until bytes arrive, the
    device's next deadline (:meth:`PtyServer._deadline`) passes, the output can move again, or
    a :class:`~rig.sim.clock.ManualClock` it subscribed to is advanced. No busy sleeps.
Output
    :meth:`PtyServer._send` queues bytes and writes what the pty takes. Without flow control
    (a UART) what does not fit is lost and counted in :attr:`PtyServer.bytes_dropped`; with
    ``flow_control`` (a USB CDC device) it waits for the host to read.
Error policy (one for all simulators)
    An exception raised by the device code (a simulator bug) stops the server thread — the
    device goes silent, as a crashed device does — and is kept in :attr:`PtyServer.server_error`;
    :meth:`PtyServer.close` re-raises it once as ``RuntimeError`` (chained), so no test and no
    benchmark can miss it. Errors of the *host* (garbage, bad CRCs, a vanished client) are
    protocol events the device answers or ignores, never exceptions.
Lifecycle
    Context manager; :meth:`PtyServer.close` idempotent; :meth:`PtyServer.disconnect` /
    :meth:`PtyServer.reconnect` unplug and replug the USB adapter (the pty goes away: the
    host's port fails with EIO; a new pty, so a new :attr:`PtyServer.port`, comes back).
Observation
    :meth:`PtyServer.wait_for` blocks until a condition on the simulator holds (re-checked
    after every server iteration): tests synchronise on device state, never on sleeps.
"""

from __future__ import annotations

import contextlib
import math
import os
import select
import termios
import threading
import time
import tty
from collections.abc import Callable
from typing import TypeVar

from rig.sim.clock import Clock

__all__ = ["SPEEDS", "PtyServer"]

_FD_SETSIZE = 1024  # glibc's select() limit on fd numbers
_READ_CHUNK = 4096

SPEEDS: dict[int, int] = {getattr(termios, n): int(n[1:]) for n in dir(termios)
                          if n.startswith("B") and n[1:].isdigit()}
"""termios speed constant -> bit/s."""

_S = TypeVar("_S", bound="PtyServer")


class PtyServer:
    """Base class: a simulated device served on a pseudo-terminal by one thread.

    Subclasses set their state, call ``super().__init__(...)``, then :meth:`_start`, and
    implement :meth:`_on_bytes` and, if they have timed behaviour, :meth:`_deadline` /
    :meth:`_on_timer`. All hooks run on the server thread with :attr:`lock` held.

    Parameters
    ----------
    clock : callable, optional
        The device's simulated clock; a :class:`~rig.sim.clock.ManualClock` is subscribed to
        so that advancing it wakes the server.
    line_speed : int, optional
        Initial line speed of the pty in bit/s (what the host reads back before setting one).
    flow_control : bool
        Keep output the host has not read yet (True) or drop it like a UART (False).

    Attributes
    ----------
    port : str
        Path of the pty slave (``/dev/pts/N``); changes after :meth:`reconnect`.
    clock : callable or None
    bytes_dropped : int
        Output bytes lost because the host did not read them (no flow control) or because the
        adapter was disconnected.
    lock : threading.RLock
        Held by the server thread while the device runs; take it to read consistent state.
    """

    thread_name = "sim"

    def __init__(self, *, clock: Clock | None = None, line_speed: int | None = None,
                 flow_control: bool = False) -> None:
        self.lock = threading.RLock()
        self._cv = threading.Condition(self.lock)
        self.clock = clock
        self.flow_control = bool(flow_control)
        self.bytes_dropped = 0
        self.port = ""
        self._line_speed = line_speed
        self._master = self._slave = -1
        self._txq = bytearray()
        self._closed = False
        self._stopping = False
        self._error: BaseException | None = None
        self._error_reported = False
        self._iterations = 0
        self._wake_r, self._wake_w = os.pipe()
        os.set_blocking(self._wake_r, False)
        os.set_blocking(self._wake_w, False)
        try:
            self._open_pty()
        except BaseException:
            os.close(self._wake_r)
            os.close(self._wake_w)
            raise
        subscribe = getattr(clock, "subscribe", None)
        self._unsubscribe = subscribe(self._wake) if callable(subscribe) else None
        self._thread = threading.Thread(target=self._serve, daemon=True,
                                        name=f"{self.thread_name} {self.port}")

    def _start(self) -> None:
        """Start serving (subclasses call it once their state is complete)."""
        self._thread.start()

    # ------------------------------------------------------------------ pty
    def _open_pty(self) -> None:
        master, slave = os.openpty()
        try:
            tty.setraw(slave)  # no echo, no line discipline: bytes pass verbatim
            if self._line_speed is not None:
                attrs = termios.tcgetattr(slave)
                speed = next((k for k, v in SPEEDS.items() if v == self._line_speed), attrs[4])
                attrs[4] = attrs[5] = speed
                termios.tcsetattr(slave, termios.TCSANOW, attrs)
            os.set_blocking(master, False)
            self.port = os.ttyname(slave)
        except BaseException:
            os.close(master)
            os.close(slave)
            raise
        self._master, self._slave = master, slave

    def _close_pty(self) -> None:
        for fd in (self._master, self._slave):
            if fd >= 0:
                with contextlib.suppress(OSError):
                    os.close(fd)
        self._master = self._slave = -1

    @property
    def line_speed(self) -> int | None:
        """The line speed the host set on the port, bit/s (None if unknown or unplugged)."""
        if self._master < 0:
            return None
        try:
            return SPEEDS.get(termios.tcgetattr(self._slave)[5])
        except (termios.error, OSError):
            return None

    def fileno(self) -> int:
        """File descriptor of the pty master (-1 while disconnected)."""
        return self._master

    @property
    def connected(self) -> bool:
        """False between :meth:`disconnect` and :meth:`reconnect`."""
        return self._master >= 0

    def disconnect(self) -> None:
        """Unplug the USB adapter: the pty's master goes away, so the host's port fails with
        EIO and opening its path again fails too (a driver trying to reconnect keeps trying).

        The slave end stays open here until :meth:`reconnect` or :meth:`close`: the kernel
        does not give the pty's number to another pty meanwhile, so a driver reopening the old
        path never reaches somebody else's simulator (another process's, under a parallel
        test run).
        """
        with self.lock:
            if self._master >= 0:
                with contextlib.suppress(OSError):
                    os.close(self._master)
                self._master = -1
            self.bytes_dropped += len(self._txq)
            self._txq.clear()
            self._on_disconnect()
        self._wake()

    def reconnect(self) -> str:
        """Plug the adapter back in: a new pty is opened; returns (and stores) its path."""
        with self.lock:
            if self._master < 0 and not self._closed:
                old_slave = self._slave
                self._open_pty()  # first: the old number is not free for it to take
                with contextlib.suppress(OSError):
                    os.close(old_slave)
        self._wake()
        return self.port

    # ------------------------------------------------------------------ lifecycle
    def __enter__(self: _S) -> _S:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __del__(self) -> None:  # pragma: no cover - safety net only
        if not getattr(self, "_closed", True):
            with contextlib.suppress(Exception):
                self.close()

    @property
    def closed(self) -> bool:
        """True once :meth:`close` has been called."""
        return self._closed

    @property
    def server_error(self) -> BaseException | None:
        """The exception that stopped the server thread (a simulator bug), or None."""
        return self._error

    def close(self) -> None:
        """Stop the server thread and release the pty; safe to call more than once.

        Raises
        ------
        RuntimeError
            The server thread died of an exception (chained to it); raised by the first
            ``close`` after the failure only.
        """
        with self.lock:
            first = not self._closed
            self._closed = True
            self._stopping = True
        if first:
            if self._unsubscribe is not None:
                self._unsubscribe()
            self._wake()
            if self._thread.ident is not None and self._thread is not threading.current_thread():
                self._thread.join()
            with self.lock:
                self._close_pty()
                for fd in (self._wake_r, self._wake_w):
                    with contextlib.suppress(OSError):
                        os.close(fd)
                self._wake_r = self._wake_w = -1
        if self._error is not None and not self._error_reported:
            self._error_reported = True
            raise RuntimeError(f"simulator on {self.port} stopped: {self._error!r}") \
                from self._error

    shutdown = close

    def wait_for(self, predicate: Callable[[], bool], timeout: float = 5.0) -> bool:
        """Block until ``predicate()`` is true; False if ``timeout`` real seconds pass first.

        ``predicate`` is evaluated with :attr:`lock` held, after every server iteration (any
        byte received or sent, deadline, clock advance), so it sees consistent state. Returns
        at once (with the predicate's value) once the server has stopped.
        """
        deadline = time.monotonic() + timeout
        with self._cv:
            while not predicate():
                remaining = deadline - time.monotonic()
                if remaining <= 0 or self._stopping or self._error is not None:
                    return bool(predicate())
                self._cv.wait(remaining)
            return True

    # ------------------------------------------------------------------ output
    @property
    def tx_backlog(self) -> int:
        """Bytes queued for the host and not yet taken by the pty (flow control only)."""
        return len(self._txq)

    def _send(self, data: bytes) -> None:
        """Queue ``data`` for the host and write what the pty takes now."""
        if self._master < 0:
            self.bytes_dropped += len(data)
            return
        self._txq += data
        self._flush()

    def _flush(self) -> None:
        while self._txq and self._master >= 0:
            try:
                n = os.write(self._master, self._txq)
            except BlockingIOError:
                if not self.flow_control:  # a UART: what the FIFO cannot take is lost
                    self.bytes_dropped += len(self._txq)
                    self._txq.clear()
                return
            except OSError:  # the pty went away under us
                self.bytes_dropped += len(self._txq)
                self._txq.clear()
                return
            del self._txq[:n]

    def _wake(self) -> None:
        with contextlib.suppress(OSError):
            os.write(self._wake_w, b"\0")

    # ------------------------------------------------------------------ server thread
    def _serve(self) -> None:
        try:
            while True:
                with self.lock:
                    if self._stopping:
                        return
                    master = self._master
                    deadline = self._deadline()
                    want_write = master >= 0 and bool(self._txq)
                timeout = None if deadline is None else max(0.0, deadline - time.monotonic())
                rfds = [self._wake_r] + ([master] if master >= 0 else [])
                wfds = [master] if want_write else []
                try:
                    readable, _ = _wait(rfds, wfds, timeout)
                except OSError:  # an fd closed under us by disconnect(): re-read the state
                    continue
                if self._wake_r in readable:
                    with contextlib.suppress(OSError):
                        os.read(self._wake_r, 4096)
                with self.lock:
                    if self._stopping:
                        return
                    if master in readable and master == self._master:
                        try:
                            data = os.read(master, _READ_CHUNK)
                        except OSError:  # BlockingIOError, or EIO while nobody holds the slave
                            data = b""
                        if data:
                            self._on_bytes(data, time.monotonic())
                    self._flush()
                    self._on_timer(time.monotonic())
                    self._flush()
                    self._iterations += 1
                    self._cv.notify_all()
        except BaseException as err:  # the one error policy: stop, keep, re-raise in close()
            self._error = err
        finally:
            with self._cv:
                self._cv.notify_all()

    # ------------------------------------------------------------------ hooks
    def _on_bytes(self, data: bytes, t_rx: float) -> None:
        """Bytes from the host; ``t_rx`` is ``time.monotonic()`` at reception."""
        raise NotImplementedError

    def _deadline(self) -> float | None:
        """``time.monotonic()`` value at which :meth:`_on_timer` must run next (None: never)."""
        return None

    def _on_timer(self, now: float) -> None:
        """Called after every wake-up (``now`` = ``time.monotonic()``); do what is due."""
        return None

    def _on_disconnect(self) -> None:
        """The adapter was unplugged: forget half-received input and pending replies."""
        return None


def _wait(rfds: list[int], wfds: list[int], timeout: float | None) -> tuple[set[int], set[int]]:
    """fds of ``rfds`` readable and of ``wfds`` writable within ``timeout`` seconds.

    ``select`` for its microsecond timeout; ``poll`` (1 ms resolution, rounded up) when an fd
    number reaches ``FD_SETSIZE``, which ``select`` refuses.
    """
    if max(rfds + wfds) < _FD_SETSIZE:
        r, w, _ = select.select(rfds, wfds, [], timeout)
        return set(r), set(w)
    poller = select.poll()
    for fd in set(rfds + wfds):
        poller.register(fd, (select.POLLIN if fd in rfds else 0)
                        | (select.POLLOUT if fd in wfds else 0))
    ms = None if timeout is None else math.ceil(timeout * 1000.0)
    r: set[int] = set()
    w: set[int] = set()
    for fd, events in poller.poll(ms):
        if events & (select.POLLIN | select.POLLHUP | select.POLLERR | select.POLLNVAL):
            r.add(fd)
        if events & select.POLLOUT:
            w.add(fd)
    return r, w
