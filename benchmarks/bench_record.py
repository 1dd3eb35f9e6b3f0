"""Recording benchmarks: sustained throughput without loss, and end-to-end accuracy.

``throughput``
    2 sensors at 400 Hz for 10 simulated minutes through the whole recording path — stream IMU
    simulator on a pty (manual clock) → ``rig.devices`` stream driver → reader thread →
    bounded queue → store (SQLite, WAL) — faster than real time. The manual clock is advanced
    in lockstep with what the recorder has written (never more than ``--window`` simulated
    seconds ahead), so the simulator never skips a sample because the host is slow: any loss
    would be the recorder's. Prints samples, sequence gaps, queue overflow, real time and the
    speed-up over real time; medians over ``--repeats`` runs.
``accuracy``
    Seeded simulated patients on the ``sim-shoulder`` configuration (back-driven servo limb,
    patient time scaled): record → boundary extraction (``calibration.boundary``) → mean
    distance of the extracted boundary to the patient's true one. NOT YET: the IMU path through
    calibration (the simulated patient does not perform the calibration protocol yet), twist
    range and peak clinical angles (the shipped patient shapes have no twist limits).

The machine these figures come from may be shared: the script says how many CPUs it sees and
the figures are medians; treat them as lower bounds of what an idle machine does.

Usage::

    .venv/bin/python benchmarks/bench_record.py throughput [--minutes 10] [--repeats 3]
    .venv/bin/python benchmarks/bench_record.py accuracy [--seeds 1 2 3]
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import io
import statistics
import sys
import tempfile
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from rig.record import PlainDisplay, RecordOptions, record_session
from rig.record.rigio import load_config, open_rig


class _Lockstep(PlainDisplay):
    """A display that also tells the clock driver how many samples have been written."""

    def __init__(self) -> None:
        super().__init__(io.StringIO(), interval_s=3600.0)
        self.samples = 0

    def update(self, st, *, force: bool = False) -> None:
        self.samples = st.samples


def _drive(clock, sim, display: _Lockstep, n_sensors: int, stop: threading.Event,
           recording: threading.Event, step_s: float, window_s: float, rate: int) -> None:
    """Advance the manual clock: at real-time pace until the recording starts (the driver
    must not see a silent board while the store opens), then in lockstep with the writer
    (at most ``window_s`` simulated seconds ahead)."""
    ahead = int(window_s * rate * n_sensors)
    while not recording.is_set() and not stop.is_set():
        clock.advance(step_s)
        time.sleep(step_s)
    while not stop.is_set():
        due = clock() * rate * n_sensors  # samples the board has produced (started at 0)
        if due - display.samples < ahead:
            clock.advance(step_s)
        else:
            time.sleep(0.0005)


def throughput(minutes: float, rate: int, repeats: int, window_s: float) -> None:
    results = []
    for rep in range(repeats):
        with tempfile.TemporaryDirectory() as tmp:
            port = (f"sim://imu-stream?sensors=2&rate={rate}&patient=original&seed={rep + 1}"
                    f"&clock=manual&max_lag=none&flow=off")
            cfg_path = Path(tmp) / "rig.yaml"
            cfg_path.write_text(
                f"name: bench-imu\njoint: {{name: shoulder, side: right, parent: thorax, "
                f"child: humerus}}\nsensors:\n  port: \"{port}\"\n  protocol: stream\n"
                f"  rate_hz: {rate}\n  segments: {{thorax: 0, humerus: 1}}\n")
            config = load_config(str(cfg_path))
            rig = open_rig(config)
            sim = rig.simulators[0]
            clock = sim.clock
            display = _Lockstep()
            stop = threading.Event()
            recording = threading.Event()
            driver = threading.Thread(target=_drive, args=(clock, sim, display, 2, stop,
                                                           recording, 0.005, window_s, rate),
                                      daemon=True)
            opts = RecordOptions(rig=str(cfg_path), db=str(Path(tmp) / "bench.db"),
                                 patient="BENCH", duration_s=minutes * 60.0, calibrate=False,
                                 queue_batches=256)
            t0 = time.perf_counter()
            driver.start()
            try:
                res = record_session(
                    opts, display=display, rig=rig,
                    on_event=lambda name, info, ev=recording: name == "recording" and ev.set())
            finally:
                stop.set()
                driver.join()
            wall = time.perf_counter() - t0
            results.append((res, wall))
            print(f"run {rep + 1}: {res.samples} samples over {res.span_s:.1f} simulated s, "
                  f"sequence gaps {res.gaps}, queue overflow {res.overflow}, "
                  f"real {wall:.1f} s ({res.span_s / wall:.1f}x real time, "
                  f"{res.samples / wall:.0f} samples/s)", flush=True)
    walls = [w for _, w in results]
    spans = [r.span_s for r, _ in results]
    print(f"\nthroughput: 2 sensors x {rate} Hz, {minutes:g} simulated min, {repeats} runs, "
          f"{os.cpu_count()} CPUs (shared machine: contended figures)")
    print(f"  dropped (gaps + overflow), every run: {[r.dropped for r, _ in results]}")
    print(f"  median real time {statistics.median(walls):.1f} s, median speed-up "
          f"{statistics.median(s / w for s, w in zip(spans, walls, strict=True)):.1f}x, "
          f"median {statistics.median(r.samples / w for r, w in results):.0f} samples/s")


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="what", required=True)
    t = sub.add_parser("throughput")
    t.add_argument("--minutes", type=float, default=10.0)
    t.add_argument("--rate", type=int, default=400)
    t.add_argument("--repeats", type=int, default=3)
    t.add_argument("--window", type=float, default=0.1,
                   help="simulated seconds the clock may run ahead of the writer")
    a = sub.add_parser("accuracy")
    a.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    a.add_argument("--seconds", type=float, default=40.0, help="real seconds per recording")
    a.add_argument("--time-scale", type=float, default=10.0)
    args = ap.parse_args(argv)
    if args.what == "throughput":
        throughput(args.minutes, args.rate, args.repeats, args.window)
    else:
        accuracy(args.seeds, args.seconds, args.time_scale)


def accuracy(seeds, seconds: float, time_scale: float) -> None:
    """Servo path only (see the module docstring for what is missing): the back-driven
    ``sim-shoulder`` limb recorded for ``seconds`` real seconds with the patient's time running
    ``time_scale`` times faster, the boundary extracted from the stored joint orientations
    and compared with the patient's truth (``calibration.boundary.boundary_distance``)."""
    from importlib import resources

    from calibration.boundary import BoundaryExtractor, boundary_distance
    from rig.store import open_store

    base = load_config("sim-shoulder")
    text = resources.files("rig").joinpath("configs", "sim-shoulder.yaml").read_text()
    rows = []
    for seed in seeds:
        url = base.servos.port.replace("seed=1", f"seed={seed}") + f"&time_scale={time_scale:g}"
        with tempfile.TemporaryDirectory() as tmp:
            cfg = Path(tmp) / "rig.yaml"
            cfg.write_text(text.replace(base.servos.port, url))
            stop = threading.Event()
            timer = threading.Timer(seconds, stop.set)
            timer.start()
            try:
                res = record_session(RecordOptions(rig=str(cfg), db=str(Path(tmp) / "a.db"),
                                                   patient=f"S{seed}", calibrate=False),
                                     display=PlainDisplay(io.StringIO()), stop=stop)
            finally:
                timer.cancel()
                timer.join()
            with open_store(Path(tmp) / "a.db") as store:
                q = store.samples(res.session_id)["q"]
            truth = load_config(str(cfg)).load_constraint()
            est = BoundaryExtractor().fit(q).constraint_
            dist = boundary_distance(est, truth)
            rows.append(dist["mean_deg"])
            print(f"seed {seed}: {res.status}, {res.samples} samples, boundary mean distance "
                  f"{dist['mean_deg']:.2f}° (Hausdorff {dist['hausdorff_deg']:.1f}°)", flush=True)
    print(f"\naccuracy (sim-shoulder, servo path): median boundary mean distance "
          f"{statistics.median(rows):.2f}° over seeds {list(seeds)}; {os.cpu_count()} CPUs, "
          f"shared machine")


if __name__ == "__main__":
    main()
