"""Where a servo cycle's time goes: the sync read's request, the wait for its reply, the reply's
parsing, the sync write — on a simulated bus served from a process of its own, as ``rig enforce``
opens it.

Prints (figures, never assertions). For each part: wall time (p50 / p99, µs) and this thread's
CPU time (``time.thread_time``: the Python work a slower machine multiplies), then the
arithmetic of a slow day: every CPU part × ``--slow`` (default 4) against the period, with the
compute per cycle given by ``--compute-us`` (the telemetry's ``compute_ms`` p50 of a run) —
in a row (compute, then the read) and overlapped (the request, the compute while the reply
travels, the rest of the reply).

``--rig NAME`` takes the servos (IDs, model, protocol) of a rig configuration instead of
``--servos`` X-series ones: ``--rig sim-shoulder-mx28`` measures the Protocol 1.0 cycle (one
BULK_READ, one SYNC_WRITE of 2-byte goals) beside ``--rig sim-shoulder``'s 2.0 one.

Run: ``python benchmarks/bench_cycle_parts.py [--servos 7 | --rig NAME] [--cycles 2000]
[--usb-latency-ms 1]``
"""

from __future__ import annotations

import argparse
import os
import time

import common  # noqa: F401  (first: one BLAS thread, this checkout on sys.path)
import numpy as np
from common import additions_s, child_servos

from rig.devices.config import load_rig_config
from rig.devices.dynamixel import DynamixelBus
from rig.errors import RigProtocolError, RigTimeoutError


def _stats(ns) -> str:
    a = np.asarray(ns, dtype=np.float64) / 1e3
    return f"p50 {np.median(a):7.1f}  p99 {np.percentile(a, 99):7.1f} µs"


def _finish(bus: DynamixelBus) -> bool:
    """The reply of the read begun; False when it timed out (or came garbled)."""
    try:
        bus.finish_read()
    except (RigTimeoutError, RigProtocolError):
        return False
    return True


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--servos", type=int, default=7)
    ap.add_argument("--rig", default=None,
                    help="the servos (IDs, model, protocol) of this rig configuration instead "
                         "of --servos XM430-W350 on Protocol 2.0")
    ap.add_argument("--cycles", type=int, default=2000)
    ap.add_argument("--rate", type=float, default=200.0)
    ap.add_argument("--usb-latency-ms", type=float, default=1.0)
    ap.add_argument("--compute-us", type=float, default=220.0)
    ap.add_argument("--slow", type=float, default=4.0)
    ap.add_argument("--read-back", action="store_true",
                    help="configure() the servos first, as the loop does: on servos with "
                         "indirect addressing the read then also returns the goal each holds "
                         "(8 bytes per servo instead of 4)")
    ap.add_argument("--no-wire-time", action="store_true",
                    help="the simulator answers at once (no wire time, no USB latency): the "
                         "reply's flight is then the simulator's own work and the pty")
    args = ap.parse_args()
    ids, model, protocol = list(range(1, args.servos + 1)), "XM430-W350", 2.0
    if args.rig is not None:
        servos = load_rig_config(args.rig).servos
        ids, model, protocol = list(servos.ids), servos.model or model, servos.protocol
        args.servos = len(ids)
    url = (f"sim://dynamixel?ids={','.join(map(str, ids))}&model={model}&protocol="
           f"{protocol:g}&return_delay_us=0"
           + ("&wire_time=off" if args.no_wire_time
              else f"&usb_latency_ms={args.usb_latency_ms:g}"))
    add_s = additions_s()
    print(f"{args.servos} {model} on Protocol {protocol:.1f}"
          f"{f' (rig {args.rig})' if args.rig else ''}, "
          f"{'no wire time' if args.no_wire_time else f'USB latency {args.usb_latency_ms:g} ms'}"
          f", {args.cycles} cycles at "
          f"{args.rate:g} Hz; 10^7 additions {add_s:.2f} s; load average "
          f"{os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    wall = {k: [] for k in ("request", "reply wait", "reply parse", "write", "read in a row")}
    cpu = {k: [] for k in wall}
    period = 1.0 / args.rate
    pc, tt = time.perf_counter_ns, time.thread_time_ns
    lost = 0
    with child_servos(url) as path:
        bus = DynamixelBus(path, ids, latency_ms=4.0, protocol=protocol)
        try:
            if args.read_back:
                bus.configure()
                print(f"  read-back of the goal: {'on' if bus.read_back else 'off'}")
            print(f"  the read: {'fast ' if bus.fast else ''}{bus.read_what}")
            goal = bus.read_ticks()
            nxt = time.monotonic()
            for k in range(args.cycles):
                nxt += period
                time.sleep(max(0.0, nxt - time.monotonic()))
                if k % 2:
                    # the request, then (3 ms later: the reply is in) its parsing alone
                    w0, c0 = pc(), tt()
                    bus.begin_read()
                    w1, c1 = pc(), tt()
                    time.sleep(0.003)
                    w2, c2 = pc(), tt()
                    if not _finish(bus):
                        lost += 1
                        continue
                    w3, c3 = pc(), tt()
                    wall["request"].append(w1 - w0)
                    cpu["request"].append(c1 - c0)
                    wall["reply parse"].append(w3 - w2)
                    cpu["reply parse"].append(c3 - c2)
                else:
                    # the plain read: request, wait, reply
                    w0, c0 = pc(), tt()
                    bus.begin_read()
                    w1 = pc()
                    if not _finish(bus):
                        lost += 1
                        continue
                    w3, c3 = pc(), tt()
                    wall["read in a row"].append(w3 - w0)
                    cpu["read in a row"].append(c3 - c0)
                    wall["reply wait"].append(w3 - w1)
                    cpu["reply wait"].append(0)
                w4, c4 = pc(), tt()
                bus.write_goal_ticks(goal)
                wall["write"].append(pc() - w4)
                cpu["write"].append(tt() - c4)
        finally:
            bus.close()
    print(f"  replies lost (a timeout on a loaded host; not counted above): {lost}")
    print(f"  {'part':<16}{'wall':>32}   {'CPU (this thread)':>32}")
    for k in wall:
        if wall[k]:
            print(f"  {k:<16}{_stats(wall[k]):>32}   {_stats(cpu[k]):>32}")
    med = {k: float(np.median(v)) / 1e3 for k, v in cpu.items() if v}
    wmed = {k: float(np.median(v)) / 1e3 for k, v in wall.items() if v}
    py = med["request"] + med["reply parse"] + med["write"]
    reply_flight = wmed["read in a row"] - med["request"] - med["reply parse"]
    f, p_us = args.slow, 1e6 * period
    row = f * (args.compute_us + py) + reply_flight
    over = f * med["request"] + max(f * args.compute_us, reply_flight) \
        + f * (med["reply parse"] + med["write"])
    print(f"  Python per cycle on the bus (request + parse + write, CPU p50): {py:.0f} µs; the "
          f"reply's flight (read in a row − its CPU parts): {reply_flight:.0f} µs")
    print(f"  slow day (every CPU part × {f:g}, compute {args.compute_us:g} µs × {f:g}; the "
          f"flight unchanged): in a row {row:.0f} µs, overlapped {over:.0f} µs of a "
          f"{p_us:.0f} µs period (slack {p_us - row:.0f} / {p_us - over:.0f} µs)")


if __name__ == "__main__":
    main()
