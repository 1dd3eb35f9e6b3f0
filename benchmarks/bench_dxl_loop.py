"""Control-loop cycle time through the real ``dynamixel_sdk`` against the simulated chain.

One cycle = GroupSyncRead of Present Position (3 servos, 4 bytes) + GroupSyncWrite of Goal
Position, as a position-control loop does. Prints median / p99 cycle time and the achievable
rate for several configurations:

* ``thread``  - simulator in this process (a background thread: shares the GIL with the SDK's
  busy-polling receive loop);
* ``process`` - simulator in a child process (``rig sim servos``), as in real use;

each with the e-Manual default Return Delay Time (500 µs) and with 0, and with normal vs fast
sync read. Wire time at the bus baud rate is modelled. Figures, never assertions.

Run: ``python benchmarks/bench_dxl_loop.py [--cycles 1000] [--runs 3]``.
"""

from __future__ import annotations

import argparse
import statistics

from common import IDS, child_servos
from common import raw_sync_loop as run_loop

from rig.sim.dynamixel import start_servo_bus


def summarise(label: str, runs: list[list[float]]) -> None:
    medians = [statistics.median(r) for r in runs]
    p99s = [sorted(r)[int(0.99 * (len(r) - 1))] for r in runs]
    med = statistics.median(medians)
    print(f"{label:<44} median {med * 1e3:6.3f} ms  p99 {statistics.median(p99s) * 1e3:6.3f} ms"
          f"  -> {1.0 / med:7.0f} Hz   (run medians: "
          f"{', '.join(f'{m * 1e3:.3f}' for m in medians)} ms)")


def in_thread(cycles: int, runs: int, delay_us: int, fast: bool) -> list[list[float]]:
    out = []
    for _ in range(runs):
        with start_servo_bus(IDS, return_delay_us=delay_us) as bus:
            out.append(run_loop(bus.port, cycles, fast))
    return out


def in_process(cycles: int, runs: int, delay_us: int, fast: bool) -> list[list[float]]:
    out = []
    for _ in range(runs):
        url = f"sim://dynamixel?ids=1,2,3&return_delay_us={delay_us}&usb_latency_ms=0"
        with child_servos(url) as port_name:
            out.append(run_loop(port_name, cycles, fast))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cycles", type=int, default=1000)
    parser.add_argument("--runs", type=int, default=3)
    args = parser.parse_args()
    print(f"3-servo sync read (Present Position) + sync write (Goal Position), 1 Mbps, "
          f"{args.cycles} cycles x {args.runs} runs")
    for where, fn in (("process", in_process), ("thread", in_thread)):
        for delay in (0, 500):
            for fast in (False, True):
                kind = "fast" if fast else "normal"
                label = f"{where}, return delay {delay} us, {kind} sync read"
                summarise(label, fn(args.cycles, args.runs, delay, fast))


if __name__ == "__main__":
    main()
