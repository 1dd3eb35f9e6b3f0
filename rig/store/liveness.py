"""Is the process writing a ``running`` session still alive?

A session records who writes it (``writer_host``, ``writer_pid``, ``writer_start``) and, at
every commit of its writer, a heartbeat (``heartbeat_at``, Unix time). A ``kill -9`` or a power
cut leaves the status ``running``; :func:`judge` tells such a session from a live one:

* **writer on this host** (same host name): the process must exist, not be a zombie, and have
  the recorded start (``writer_start``: ``<boot id>/<start in clock ticks since boot>`` from
  ``/proc`` on Linux). A missing process, a reused pid (another start) or a reboot (another
  boot id) means *interrupted*. The heartbeat is not consulted: a live process is live even
  while its device is silent.
* **writer on another host**: its process cannot be seen from here; the session is
  *interrupted* when its last heartbeat (or its start, before the first commit) is older than
  ``stale_after_s`` (default :data:`STALE_AFTER_S`). Both hosts' clocks must agree to well
  within that threshold (NTP).
* **writer unknown** (a session started before schema version 3): *unknown*.

Every input is injectable (host, now, process probe), so the rule is tested without clocks or
real processes.
"""

from __future__ import annotations

import os
import socket
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

#: Default age (s) of the last heartbeat after which a session written on another host is
#: judged interrupted. The writer commits (and beats) at least every second while samples
#: flow and every :data:`IDLE_HEARTBEAT_S` seconds when idle.
STALE_AFTER_S = 60.0

#: A writer with nothing to commit still refreshes the heartbeat this often (s).
IDLE_HEARTBEAT_S = 2.0

#: ``(alive, start)`` of a pid: ``alive`` False for no such process (or a zombie); ``start``
#: the process's start token, None when the platform does not tell.
Probe = Callable[[int], tuple[bool, str | None]]


@dataclass(frozen=True)
class Writer:
    """Who writes a session: host name, pid and the process's start token."""

    host: str
    pid: int
    start: str | None


@dataclass(frozen=True)
class Liveness:
    """``state``: ``live``, ``interrupted``, ``unknown`` (running sessions) or ``ended``;
    ``reason``: one phrase saying why."""

    state: str
    reason: str

    def as_dict(self) -> dict[str, str]:
        return {"state": self.state, "reason": self.reason}


def _boot_id() -> str | None:
    try:
        with open("/proc/sys/kernel/random/boot_id") as fh:
            return fh.read().strip() or None
    except OSError:
        return None


_BOOT_ID = _boot_id()


def probe_process(pid: int) -> tuple[bool, str | None]:
    """``(alive, start)`` of process ``pid`` on this host.

    On Linux ``start`` is ``"<boot id>/<start time in clock ticks since boot>"`` (field 22 of
    ``/proc/PID/stat``): with the pid it names one process of one boot (a pid reused later
    starts later), and it does not move when the wall clock is set. A zombie (killed, not yet
    reaped) counts as gone. Elsewhere the pid's existence is checked with signal 0 and
    ``start`` is None.
    """
    pid = int(pid)
    if pid <= 0:
        return False, None
    try:
        with open(f"/proc/{pid}/stat") as fh:
            stat = fh.read()
    except FileNotFoundError:
        return False, None
    except OSError:
        stat = None
    if stat is not None:
        fields = stat.rsplit(")", 1)[1].split()  # after "pid (comm)", comm may hold spaces
        if fields[0] in ("Z", "X"):  # zombie / dead
            return False, None
        return True, f"{_BOOT_ID}/{fields[19]}" if _BOOT_ID else None
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False, None
    except PermissionError:  # exists, belongs to someone else
        return True, None
    return True, None


def this_writer() -> Writer:
    """The calling process as a session's writer."""
    pid = os.getpid()
    return Writer(socket.gethostname(), pid, probe_process(pid)[1])


def judge(
    row: Mapping[str, Any],
    *,
    host: str | None = None,
    now: float | None = None,
    stale_after_s: float = STALE_AFTER_S,
    probe: Probe = probe_process,
) -> Liveness:
    """Liveness of a session row (``status``, ``started_at``, ``writer_host``, ``writer_pid``,
    ``writer_start``, ``heartbeat_at``); see the module docstring for the rule.

    ``host`` defaults to this host's name, ``now`` to ``time.time()``, ``probe`` to
    :func:`probe_process`.
    """
    if row.get("status") != "running":
        return Liveness("ended", f"ended as {row.get('status')}")
    whost, wpid = row.get("writer_host"), row.get("writer_pid")
    if not whost or wpid is None:
        return Liveness("unknown", "the writer was not recorded (session older than schema 3)")
    host = socket.gethostname() if host is None else host
    if whost == host:
        alive, start = probe(int(wpid))
        if not alive:
            return Liveness("interrupted", f"writer pid {wpid} on {whost} is gone")
        recorded = row.get("writer_start")
        if recorded and start and start != recorded:
            if recorded.split("/")[0] != start.split("/")[0]:
                return Liveness("interrupted",
                                f"{whost} has restarted since writer pid {wpid} started")
            return Liveness("interrupted",
                            f"writer pid {wpid} on {whost} is gone (pid reused by another "
                            "process)")
        return Liveness("live", f"writer pid {wpid} on {whost} is running")
    now = time.time() if now is None else float(now)
    beat = row.get("heartbeat_at")
    last = float(beat if beat is not None else row["started_at"])
    age = now - last
    what = "heartbeat" if beat is not None else "heartbeat (none since the start)"
    if age > stale_after_s:
        return Liveness("interrupted", f"writer pid {wpid} on {whost}: last {what} "
                                       f"{age:.0f} s ago (> {stale_after_s:g} s)")
    return Liveness("live", f"writer pid {wpid} on {whost}: last {what} {max(age, 0.0):.0f} s "
                            f"ago (<= {stale_after_s:g} s)")
