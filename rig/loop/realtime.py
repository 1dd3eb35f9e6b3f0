"""Optional real-time scheduling and CPU affinity for the loop's thread (Linux).

:func:`check_cpu` refuses a CPU the process may not run on before anything starts (a user
mistake: one line). :func:`apply` then asks the kernel, for the calling thread only (the loop's;
the telemetry writer and the store keep normal priority):

- ``realtime``: ``SCHED_FIFO`` at :data:`RT_PRIORITY` — the loop's thread then runs as soon
  as its sleep ends, ahead of every normal thread. It needs ``CAP_SYS_NICE`` or an
  ``rtprio`` limit (``ulimit -r``, ``/etc/security/limits.conf``); without it the loop runs
  at normal priority and :func:`apply` returns one line saying so (never an error: the loop
  is correct either way, only its jitter differs).
- ``realtime`` also asks for a CPU wake-up latency of 0 µs for as long as the loop runs (the
  kernel's PM QoS interface, ``/dev/cpu_dma_latency``, as ``cyclictest`` does): idle CPUs then
  poll instead of halting. Measured on this project's 2-core virtual machine, the loop's work
  right after a 4 ms sleep took 275 µs against 56 µs back to back — a halted CPU comes back
  slow — and 68 µs with the request held (``docs/loop.md``). It costs an idle core's power,
  which is why it comes with ``--realtime`` only. Needs write access to the device (root);
  without it one line says so.
- ``cpu``: pin the thread to that CPU (``sched_setaffinity``); on a 2-core machine the other
  core is left to the simulator's process, the telemetry writer and the rest.

Both are undone by the function :func:`apply` returns.
"""

from __future__ import annotations

import os
import struct
from collections.abc import Callable

from rig.errors import RigConfigError

__all__ = ["CPU_LATENCY_DEVICE", "RT_PRIORITY", "apply", "check_cpu", "hold_cpu_latency"]

#: SCHED_FIFO priority of the loop's thread: above the kernel's default threaded IRQ
#: handlers' 50 would starve the serial driver, so below it.
RT_PRIORITY = 40

#: The kernel's PM QoS CPU latency request: held while the file stays open.
CPU_LATENCY_DEVICE = "/dev/cpu_dma_latency"


def check_cpu(cpu: int | None) -> None:
    """Raise :class:`RigConfigError` unless ``cpu`` is None or a CPU this process may use."""
    if cpu is None:
        return
    if not hasattr(os, "sched_getaffinity"):
        raise RigConfigError("--cpu: CPU affinity is not available on this system")
    allowed = sorted(os.sched_getaffinity(0))
    if cpu not in allowed:
        raise RigConfigError(f"--cpu {cpu}: not a CPU this process may run on; allowed: "
                             f"{', '.join(map(str, allowed))}")


def apply(*, realtime: bool, cpu: int | None) -> tuple[Callable[[], None], list[str]]:
    """Real-time scheduling and / or CPU affinity for the calling thread.

    Returns
    -------
    restore : callable
        Puts the thread's policy and affinity back.
    notes : list of str
        One line per request the system did not grant (and what the loop does instead).
    """
    notes: list[str] = []
    undo: list[Callable[[], None]] = []
    if cpu is not None:
        check_cpu(cpu)
        old_cpus = os.sched_getaffinity(0)
        os.sched_setaffinity(0, {cpu})
        undo.append(lambda: os.sched_setaffinity(0, old_cpus))
    if realtime:
        if not hasattr(os, "SCHED_FIFO"):
            notes.append("--realtime: real-time scheduling is not available on this system; "
                         "the loop runs at normal priority")
        else:
            old_policy = os.sched_getscheduler(0)
            old_param = os.sched_getparam(0)
            try:
                os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(RT_PRIORITY))
                undo.append(lambda: os.sched_setscheduler(0, old_policy, old_param))
            except PermissionError:
                notes.append("--realtime: real-time scheduling not permitted (needs "
                             "CAP_SYS_NICE or an rtprio limit, see `ulimit -r`); the loop runs "
                             "at normal priority")
            except OSError as err:
                notes.append(f"--realtime: real-time scheduling refused ({err.strerror}); the "
                             f"loop runs at normal priority")

        release, note = hold_cpu_latency(0)
        if note:
            notes.append(note)
        else:
            undo.append(release)

    def restore() -> None:
        for fn in reversed(undo):
            try:
                fn()
            except OSError:  # best effort: the loop has ended
                pass
    return restore, notes


def hold_cpu_latency(microseconds: int, device: str = CPU_LATENCY_DEVICE
                     ) -> tuple[Callable[[], None], str | None]:
    """Ask the kernel to keep every CPU's wake-up latency at or below ``microseconds``.

    Returns ``(release, None)`` — the request holds until ``release()`` closes the file — or
    ``(no-op, note)`` with one line saying why the system did not grant it.
    """
    try:
        fd = os.open(device, os.O_WRONLY)
    except FileNotFoundError:
        return (lambda: None), (f"--realtime: {device} does not exist (no PM QoS on this "
                                f"system); idle CPUs may wake slowly")
    except PermissionError:
        return (lambda: None), (f"--realtime: no write access to {device} (needs root); "
                                f"idle CPUs may wake slowly")
    except OSError as err:
        return (lambda: None), f"--realtime: {device}: {err.strerror}; idle CPUs may wake slowly"
    try:
        os.write(fd, struct.pack("=i", int(microseconds)))
    except OSError as err:
        os.close(fd)
        return (lambda: None), f"--realtime: {device} refused the request ({err.strerror})"
    return (lambda: os.close(fd)), None
