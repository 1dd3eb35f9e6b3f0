"""Driver-layer control cycle against the raw ``dynamixel_sdk`` loop, same run, same simulator.

One *driver* cycle = ``DynamixelBus.read_ticks()`` (one fast sync read of Present Position,
3 servos) → forward kinematics → closed-form inverse kinematics (solution nearest the present
position) → ``write_goal_ticks()`` (one sync write), on ``sim://dynamixel`` at Return Delay
Time 0. The *raw* cycle is ``benchmarks/bench_dxl_loop.py``'s ``run_loop`` (GroupSyncRead +
GroupSyncWrite, no kinematics). Runs alternate raw / driver so both see the same machine load;
figures are medians of run medians. FK+IK is timed inside the driver cycle (median µs).

Placements: ``thread`` — the simulator in this process (``sim://``, shares the GIL with the
SDK's busy-polling receive loop); ``process`` — the simulator in a child process
(``rig sim servos``), its pty path opened like a hardware port.

Run: ``python benchmarks/bench_driver_loop.py [--cycles 1000] [--runs 3]``. Figures, never
assertions.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

import common  # noqa: F401  (first: one BLAS thread, this checkout on sys.path)
import numpy as np
from common import child_servos
from common import raw_sync_loop as run_loop

from rig.devices import DynamixelBus, load_rig_config

URL = "sim://dynamixel?ids=1,2,3&model=XM430-W350&return_delay_us=0&usb_latency_ms=0"


def driver_loop(port: str, cycles: int) -> tuple[list[float], list[float]]:
    """(cycle times, FK+IK times) in seconds."""
    servos = load_rig_config("sim-shoulder").servos
    kin = servos.kinematics()
    with DynamixelBus(port, servos.bus_servos()) as bus:
        bus.set_torque(False)  # EEPROM (limits) only with torque off
        bus.configure()
        bus.set_torque(True)
        times, kin_times = [], []
        for k in range(cycles):
            t0 = time.perf_counter()
            ticks = bus.read_ticks()
            t1 = time.perf_counter()
            q = kin.forward(ticks)
            # a slowly moving target: present orientation turned a little about the limb axis
            goal = kin.inverse(q, ticks)
            goal[2] = 2048 + (k % 200) - 100
            t2 = time.perf_counter()
            bus.write_goal_ticks(goal)
            times.append(time.perf_counter() - t0)
            kin_times.append(t2 - t1)
        return times, kin_times


def med(xs):
    return statistics.median(xs)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cycles", type=int, default=1000)
    parser.add_argument("--runs", type=int, default=3)
    args = parser.parse_args()
    print(f"3 servos, 1 Mbit/s, return delay 0, {args.cycles} cycles x {args.runs} runs "
          f"(alternating raw / driver); load average {os.getloadavg()[0]:.1f} on "
          f"{os.cpu_count()} cores")
    for where in ("thread", "process"):
        raw_meds, drv_meds, kin_meds = [], [], []
        for _ in range(args.runs):
            if where == "thread":
                from rig.devices import open_port

                with open_port(URL) as port:
                    raw = run_loop(port.path, args.cycles, True)
                with open_port(URL) as port:
                    drv, kin = driver_loop(port, args.cycles)
            else:
                with child_servos() as path:
                    raw = run_loop(path, args.cycles, True)
                    drv, kin = driver_loop(path, args.cycles)
            raw_meds.append(med(raw))
            drv_meds.append(med(drv))
            kin_meds.append(med(kin))
        r, d = med(raw_meds), med(drv_meds)
        print(f"{where:<8} raw SDK fast-sync loop   median {r * 1e3:6.3f} ms -> {1 / r:6.0f} Hz"
              f"   (runs: {', '.join(f'{1 / x:.0f}' for x in raw_meds)} Hz)")
        print(f"{where:<8} driver read-FK-IK-write  median {d * 1e3:6.3f} ms -> {1 / d:6.0f} Hz"
              f"   (runs: {', '.join(f'{1 / x:.0f}' for x in drv_meds)} Hz)")
        print(f"{where:<8} driver / raw rate {r / d * 100:5.1f} %;  FK+IK per cycle median "
              f"{med(kin_meds) * 1e6:5.1f} µs")
    # the kinematics alone, no bus
    kin = load_rig_config("sim-shoulder").servos.kinematics()
    ticks = np.array([2100, 1990, 2300])
    q = kin.forward(ticks)
    samples = []
    for _ in range(5):
        t0 = time.perf_counter()
        for _ in range(2000):
            kin.inverse(kin.forward(ticks), ticks)
        samples.append((time.perf_counter() - t0) / 2000)
    back = kin.forward(kin.inverse(q, ticks))
    err = np.degrees(2 * np.arccos(min(1.0, abs(float(q @ back)))))
    print(f"FK+IK alone (no bus): median {med(samples) * 1e6:.1f} µs per call pair; "
          f"round trip {err:.3f}° after rounding to ticks")


if __name__ == "__main__":
    main()
