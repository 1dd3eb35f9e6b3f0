"""What the benchmark scripts share. Each imports it first (``import common``): Python puts a
script's own folder on ``sys.path``, so scripts reach shared code through this module, never
through each other or a path edit of their own.

On import:

- one BLAS / OpenMP thread, set before numpy loads (figures per core, comparable between
  machines; child processes inherit it);
- :data:`ROOT`, the checkout this file is in, first on ``sys.path``: a script measures the code
  beside it, not another installed copy. :func:`child_env` passes it to child processes.

Shared pieces: :func:`single_latencies_ns` (one ONNX call at a time), :func:`raw_sync_loop`
and :func:`raw_paced_loop` (the raw ``dynamixel_sdk`` control cycle, back to back or at a fixed
rate: the peer figure of the driver and live-loop benchmarks) and :func:`child_servos` (a
simulated chain in its own process, as hardware is).
"""

from __future__ import annotations

import contextlib
import os
import sys
import time
from collections.abc import Iterator
from pathlib import Path

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path[:1]:
    sys.path.insert(0, str(ROOT))

__all__ = ["IDS", "ROOT", "child_env", "child_servos", "raw_paced_loop", "raw_sync_loop",
           "single_latencies_ns"]

#: The driver benchmarks' bus: 3 servos, return delay 0, an instantaneous USB adapter (their
#: figures compare drivers, not adapters; ``bench_enforce.py`` adds the latency timer).
CHILD_URL = "sim://dynamixel?ids=1,2,3&return_delay_us=0&usb_latency_ms=0"

#: Servo IDs of the simulated 3-servo chain the loop benchmarks drive.
IDS = (1, 2, 3)
_TORQUE, _GOAL_POS, _PRESENT_POS = 64, 116, 132


def additions_s() -> float:
    """How fast the machine runs that day: seconds a Python loop of 10⁷ additions takes (in a
    function; every speed figure is printed beside it)."""
    t = time.perf_counter()
    s = 0
    for i in range(10**7):
        s += i
    return time.perf_counter() - t


def child_env() -> dict[str, str]:
    """The environment for a child process that must import this checkout."""
    return dict(os.environ, PYTHONPATH=str(ROOT))


@contextlib.contextmanager
def child_servos(url: str = CHILD_URL) -> Iterator[str]:
    """A simulated chain served from a process of its own for the duration (the product's
    ``process=on`` port, as ``rig enforce`` opens it); yields its pty path. The default bus
    has no USB latency (:data:`CHILD_URL`)."""
    from rig.devices.ports import open_port

    with open_port(url, separate_process=True) as port:
        yield port.path


def single_latencies_ns(model, qs, warmup: int = 2000) -> list[int]:
    """Per-call latency (ns) of ``model.correct_one`` over the orientations ``qs`` (N, 4)."""
    rows = [tuple(map(float, r)) for r in qs]
    for r in rows[:warmup]:
        model.correct_one(r)
    lat = []
    for r in rows:
        t0 = time.perf_counter_ns()
        model.correct_one(r)
        lat.append(time.perf_counter_ns() - t0)
    return lat


@contextlib.contextmanager
def _raw_bus(port_name: str, waiting: bool = False, ids=IDS) -> Iterator[tuple]:
    """The raw SDK on ``port_name``: torque on for ``ids`` (default :data:`IDS`); yields
    (reader, writer) — a
    GroupSyncRead of Present Position and a GroupSyncWrite of Goal Position. ``waiting``: the
    SDK on the driver's ``PortHandler`` subclass, which waits in ``select`` for a reply instead
    of polling (everything else the stock SDK)."""
    from dynamixel_sdk import (
        COMM_SUCCESS,
        GroupSyncRead,
        GroupSyncWrite,
        PacketHandler,
        PortHandler,
    )

    assert COMM_SUCCESS == _COMM_SUCCESS
    if waiting:
        from rig.devices.dynamixel import _SdkPort  # the driver's port: the SDK's own, waiting

        port = _SdkPort(port_name, latency_ms=4.0)
    else:
        port = PortHandler(port_name)
    if not port.openPort():
        raise RuntimeError(f"cannot open {port_name}")
    try:
        ph = PacketHandler(2.0)
        for i in ids:
            result, error = ph.write1ByteTxRx(port, i, _TORQUE, 1)
            if result != COMM_SUCCESS or error:
                raise RuntimeError(f"torque on id {i}: {ph.getTxRxResult(result)} error {error}")
        reader = GroupSyncRead(port, ph, _PRESENT_POS, 4)
        writer = GroupSyncWrite(port, ph, _GOAL_POS, 4)
        for i in ids:
            reader.addParam(i)
            writer.addParam(i, [0, 8, 0, 0])
        yield reader, writer
    finally:
        port.closePort()


#: ``dynamixel_sdk.COMM_SUCCESS`` (the SDK is imported only when a raw loop runs)
_COMM_SUCCESS = 0


def _raw_cycle(reader, writer, k: int, fast: bool, ids=IDS) -> bool:
    """One raw control cycle (read, then write a goal); False when the read failed."""
    result = reader.fastSyncRead() if fast else reader.txRxPacket()
    positions = [reader.getData(i, _PRESENT_POS, 4) for i in ids]
    goal = 2048 + (k % 200) - 100
    for i, _ in zip(ids, positions, strict=True):
        writer.changeParam(i, list(goal.to_bytes(4, "little")))
    writer.txPacket()
    return result == _COMM_SUCCESS


def raw_sync_loop(port_name: str, cycles: int, fast: bool) -> list[float]:
    """The raw SDK control cycle on ``port_name``: GroupSyncRead of Present Position (fast
    sync read when ``fast``) + GroupSyncWrite of Goal Position for :data:`IDS`, no other work,
    back to back; cycle times in seconds. Raises if torque cannot be enabled."""
    with _raw_bus(port_name) as (reader, writer):
        times = []
        failures = 0
        for k in range(cycles):
            t0 = time.perf_counter()
            failures += not _raw_cycle(reader, writer, k, fast)
            times.append(time.perf_counter() - t0)
        if failures:
            print(f"    ({failures} failed reads)")
        return times


def raw_paced_loop(port_name: str, rate_hz: float, duration_s: float,
                   fast: bool = True, waiting: bool = False, ids=IDS) -> dict:
    """The raw SDK control cycle (as :func:`raw_sync_loop`) paced at ``rate_hz`` for
    ``duration_s`` by the live loop's own scheduler (absolute deadlines, no catch-up): the peer
    of the supervised loop at the same rate. Returns cycles, overruns, failed reads and the
    lateness (ms) of every cycle. ``waiting``: see :func:`_raw_bus`; ``ids``: the servos
    (default :data:`IDS`)."""
    from rig.loop.scheduler import Scheduler

    with _raw_bus(port_name, waiting, ids) as (reader, writer):
        sched = Scheduler(rate_hz)
        t0 = sched.start()
        late = []
        failures = 0
        k = 0
        while True:
            k, due, start = sched.wait()
            late.append(1e3 * (start - due))
            failures += not _raw_cycle(reader, writer, k, fast, ids)
            sched.finish()
            if start - t0 + sched.period > duration_s - 1e-9:  # as the supervised loop ends
                break
        return {"cycles": len(late), "overruns": sched.overruns, "failed_reads": failures,
                "late_ms": late}
