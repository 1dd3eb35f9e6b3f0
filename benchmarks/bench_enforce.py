"""The live enforcement loop through the real ``dynamixel_sdk`` on a simulated servo bus: the
3-servo shoulder (``--rig sim-shoulder``, the default) or the 7-servo arm (``--rig
sim-servo-arm``: shoulder 3, forearm elbow 2, wrist 2, with a limb model and the exact limb
oracle).

Prints (figures, never assertions), and the machine's 10^7-additions loop time at the start and
the end; each section can be run alone (``--sections``):

``long``
    ``rig enforce --rig RIG`` itself (a child process, as a user runs it; its servo
    simulator in a process of its own with the U2D2 latency model, 1 ms) at 200 Hz on
    adversarial targets for ``--minutes`` (default 10): achieved rate, overruns (% and by
    cause), lateness p50/p99/max, the lateness distribution's tail (what the stale limit is
    chosen from), compute p50/p99, read faults, safe-state entries.
``runs``
    ``--runs`` (default 50) runs of ``rig enforce`` of ``--run-s`` (default 30) s each: safe-state
    entries with their reasons (no fault is injected: every entry is unexplained), overruns.
``sweep``
    Highest sustainable rate (< 0.1 % of cycles overrun and p99 lateness <= 0.5 ms, runs of
    ``--sweep-s``) of the supervised loop and of the raw SDK loop (fast sync read + sync write,
    no compute, paced by the same scheduler) on the same child-process bus, in the same run —
    without the latency model and with the 1 ms one — beside the physical bound of one sync read
    and one sync write per cycle at 1 Mbit/s.
``compute``
    Per-cycle compute (model + supervisor + IK + FK + final check) inside the 200 Hz loop
    (from the ``long`` section's telemetry, or a 20 s run) and each part alone.
``accuracy``
    The model's correction against the exact projection, per cycle.
``adversarial``
    ``--cycles`` (default 10,000) adversarial cycles on a manual clock (the bus is real, time
    is not): commanded orientations beyond the tolerance, counted with the batched oracle — with
    the model trained for the constraint and with a model trained for another one. For a limb:
    commanded postures beyond 1° per joint by the exact limb oracle, and the tracking of valid
    targets per joint (the angle between the target and the present posture once the target has
    been held ``--settle-s``, default 0.3 s; median and p95) — with the limb model and with the
    exact ``geometric`` graph; the simulated servos run on the loop's manual clock.

For a limb (``--rig sim-servo-arm``) the scripted targets are the rig's
(:class:`rig.loop.ScriptedTargets` with its kinematics: valid postures its servos reach) and the
``accuracy`` section is the one-joint model's only.

Run: ``python benchmarks/bench_enforce.py [--rig sim-servo-arm] [--minutes 10] [--runs 50]
[--sections long,sweep] [--busy-wait] [--realtime]``.
The model defaults to ``rig train`` on the rig's constraint, trained first: preset ``field`` for
a joint; for a limb, preset ``network`` on the limb file of the simulated patient's true arm
(:func:`rig.sim.patients.anatomical_limb` of the rig's seed, its elbow a forearm joint — the
limb the simulator's patient moves; ``--constraint LIMB.yaml``: another, e.g. one ``rig
boundary`` extracted from a recording of the arm).
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import json
import os
import subprocess
import sys
import tempfile
import time
import urllib.parse
from pathlib import Path

import common  # noqa: F401  (first: one BLAS thread, this checkout on sys.path)
import numpy as np
from common import additions_s, child_env, child_servos, raw_paced_loop

from models import quaternion as Q
from models.limb import dump_limb, load_limb
from models.onnx_io import load_model
from models.oracle import ConstraintOracle
from rig.devices.config import load_rig_config
from rig.devices.ports import open_port
from rig.errors import UnreachableError
from rig.loop import (
    EnforcementLoop,
    LoopConfig,
    ScriptedTargets,
    Supervisor,
    SupervisorConfig,
)
from rig.loop.limb_supervisor import LimbSupervisor
from rig.loop.runner import prepare_servo_limb
from rig.loop.targets import valid_targets
from rig.sim.clock import ManualClock
from rig.sim.patients import anatomical_limb

SIM_URL = "sim://dynamixel?ids=1,2,3&model=XM430-W350&return_delay_us=0"
SECTIONS = ("long", "runs", "sweep", "compute", "accuracy", "adversarial")
#: sustainable: fewer than this fraction of cycles overrun, and p99 lateness at most this (ms)
MAX_OVERRUN, MAX_P99_LATE_MS = 0.001, 0.5


def _train(constraint_path: Path, out: Path, preset: str | None = None) -> Path:
    subprocess.run([sys.executable, "-m", "rig", "train", "--constraint", str(constraint_path),
                    "--out", str(out), *(["--preset", preset] if preset else [])], check=True,
                   capture_output=True, env=child_env())
    return out


def _preset(model) -> str:
    """A model's training preset (a joint's) or method (a limb's: network, geometric)."""
    return str(model.network_info.get("preset")
               or model.metadata.get("jointlimits.method", "?"))




RIG = "sim-shoulder"  # --rig
CONSTRAINT: Path | None = None  # a limb's limb file, passed to rig enforce


def _scripted(name, oracle, rig, seed, **kw):
    """A scripted target source; for a limb, with the rig's kinematics (reachable postures)."""
    kin = rig.servos.limb_kinematics() if rig.limb else None
    return ScriptedTargets(name, oracle, seed=seed, kinematics=kin, **kw)


def _limb_sim_url(rig) -> str:
    """The rig's servos on an in-process simulator driven by the loop's manual clock (no
    patient: torque is on throughout)."""
    ids = ",".join(str(i) for i in rig.servos.ids)
    return f"sim://dynamixel?ids={ids}&model=XM430-W350&return_delay_us=0&clock=manual" \
           f"&wire_time=off"


BUSY_WAIT = False  # --busy-wait: every supervised loop spins between cycles
WARM_UP = True  # --no-warm-up: the supervised loops without their warm-up (LoopConfig.warm_up)
REALTIME = False  # --realtime: every supervised loop's thread under SCHED_FIFO when permitted


def run_loop(servos, oracle, model, targets, *, rate, duration=None, cycles=None, clock=None):
    """One supervised loop; ``clock``: a ManualClock, or ``"sim"`` — the simulator's own
    (manual) clock, so the servos move in the loop's time."""
    cfg = LoopConfig(rate_hz=rate, duration_s=duration,
                     watchdog_ms=1000 if clock is not None else None, busy_wait=BUSY_WAIT,
                     warm_up=WARM_UP)
    with open_port(servos.port, baud=servos.baud) as port:
        if clock == "sim":
            clock = port.simulator.clock
        kw = {} if clock is None else {"clock": clock, "sleep": clock.sleep}
        limb = prepare_servo_limb(port, servos, oracle)
        try:
            loop = EnforcementLoop(limb, model, oracle, targets, cfg, **kw)
            loop.setup()
            from rig.loop import realtime

            restore, notes = realtime.apply(realtime=REALTIME, cpu=None)
            for note in notes:
                print(f"  note: {note}")
            try:
                summary = loop.run(max_cycles=cycles)
            finally:
                restore()
        finally:
            limb.close()
    return summary, loop.telemetry.table()


def rig_enforce(model_path: Path, out: Path, duration_s: float, *, seed: int,
                telemetry: bool = False, extra: tuple[str, ...] = ()) -> dict:
    """``rig enforce --rig RIG`` on adversarial targets in a child process; its summary JSON
    (and ``telemetry_csv``, the path of its telemetry, when asked)."""
    summary = out.with_suffix(".json")
    cmd = [sys.executable, "-m", "rig", "enforce", "--rig", RIG, "--model", str(model_path),
           *(["--constraint", str(CONSTRAINT)] if CONSTRAINT is not None else []),
           "--targets", f"script:adversarial?seed={seed}", "--duration",
           str(duration_s), "--summary-json", str(summary), "--quiet", *extra,
           *(["--busy-wait"] if BUSY_WAIT else []), *(["--realtime"] if REALTIME else []),
           *([] if WARM_UP else ["--no-warm-up"])]
    if telemetry:
        cmd += ["--telemetry", str(out.with_suffix(".csv"))]
    proc = subprocess.run(cmd, capture_output=True, text=True, env=child_env())
    if proc.returncode not in (0, 1):
        raise RuntimeError(f"rig enforce exited {proc.returncode}: {proc.stderr.strip()}")
    s = json.loads(summary.read_text())
    s["exit_status"] = proc.returncode
    if telemetry:
        s["telemetry_csv"] = str(out.with_suffix(".csv"))
    return s


def _columns(path: str, names: tuple[str, ...]) -> dict[str, np.ndarray]:
    with open(path, newline="") as fh:
        rows = list(csv.DictReader(fh))
    return {n: np.array([float(r[n]) for r in rows]) for n in names}


def _pct_over(s: dict) -> float:
    return 100.0 * s["overruns"] / max(1, s["cycles"])


def _rate_line(label, s, late):
    late = np.asarray(late)
    print(f"  {label:<34} {s['cycles']:7d} cycles {s['achieved_hz']:7.1f} Hz  late p50 "
          f"{np.median(late):.3f} p99 {np.percentile(late, 99):.3f} ms  overruns "
          f"{s['overruns']} ({_pct_over(s):.3f} %) {s.get('overruns_by_cause', '')}  faults "
          f"{s['faults'] or '{}'}")


def _sustained(cycles: int, overruns: int, late) -> bool:
    return overruns < MAX_OVERRUN * cycles and float(np.percentile(late, 99)) <= MAX_P99_LATE_MS


def _angle(a, b):
    return np.degrees(Q.angle(Q.multiply(a, Q.conjugate(b))))


def physical_bound_hz(latency_ms: float, baud: int = 1_000_000, n: int = 3) -> tuple:
    """One fast sync read (request + reply) and one sync write of ``n`` 4-byte positions per
    cycle on the wire at ``baud``, plus the adapter's latency timer once (a reply waits up to a
    full period of it); return delay 0. Returns (Hz, the parts in ms)."""
    byte_ms = 10.0 / baud * 1e3
    # request: header 4, id, length 2, instruction, address 2, data length 2, the ids, CRC 2
    req = 14 + n
    # fast sync read reply: header 4, id, length 2, instruction; per servo error, id, 4, CRC 2
    reply = 8 + 8 * n
    # sync write: header 4 .. data length 2 (12), per servo id + 4 bytes, CRC 2
    write = 12 + 5 * n + 2
    parts = {"request": req * byte_ms, "reply": reply * byte_ms, "usb latency": latency_ms,
             "write": write * byte_ms}
    return 1e3 / sum(parts.values()), parts


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--minutes", type=float, default=10.0)
    ap.add_argument("--runs", type=int, default=50)
    ap.add_argument("--run-s", type=float, default=30.0)
    ap.add_argument("--sweep-s", type=float, default=5.0)
    ap.add_argument("--cycles", type=int, default=10_000)
    ap.add_argument("--model", default=None)
    ap.add_argument("--rig", default="sim-shoulder",
                    help="sim-shoulder (default) or sim-servo-arm (a limb)")
    ap.add_argument("--constraint", default=None,
                    help="a limb's limb file (default: the simulated patient's true arm)")
    ap.add_argument("--settle-s", type=float, default=0.3,
                    help="the servos' settling time added to the time a goal needs to reach a "
                         "valid target before it counts in the tracking figures")
    ap.add_argument("--hold-s", type=float, default=2.0,
                    help="a limb's adversarial section: each target held this long (the "
                         "script's hold_s; its default 0.4 s is shorter than a large valid "
                         "jump takes at the supervisor's 120°/s)")
    ap.add_argument("--segment-s", type=float, default=4.0,
                    help="a limb's adversarial section: the script's segment_s")
    ap.add_argument("--busy-wait", action="store_true",
                    help="the supervised loops spin between cycles (rig enforce --busy-wait)")
    ap.add_argument("--no-warm-up", action="store_true",
                    help="the supervised loops without their warm-up before each deadline "
                         "(rig enforce --no-warm-up)")
    ap.add_argument("--realtime", action="store_true",
                    help="the supervised loops under SCHED_FIFO when permitted (rig enforce "
                         "--realtime)")
    ap.add_argument("--sections", default=",".join(SECTIONS),
                    help=f"comma-separated, of {', '.join(SECTIONS)}")
    args = ap.parse_args()
    global BUSY_WAIT, REALTIME, WARM_UP, RIG, CONSTRAINT
    BUSY_WAIT, REALTIME, WARM_UP = args.busy_wait, args.realtime, not args.no_warm_up
    RIG = args.rig
    sections = set(args.sections.split(","))
    unknown = sections - set(SECTIONS)
    if unknown:
        ap.error(f"unknown sections: {', '.join(sorted(unknown))}")

    t_add = additions_s()
    print(f"10^7 additions: {t_add:.2f} s (start)")
    rig = load_rig_config(RIG)
    tmp = Path(tempfile.mkdtemp(prefix="bench-enforce-"))
    geometric = None
    if rig.limb:
        if args.constraint is None:
            seed = int(urllib.parse.parse_qs(urllib.parse.urlsplit(rig.servos.port).query)
                       .get("seed", ["0"])[0])
            constraint = anatomical_limb(seed, rig.limb, kinds={"elbow": "forearm"})
            source = f"the simulated patient's true {rig.limb} (seed {seed})"
        else:
            constraint = load_limb(args.constraint)
            source = args.constraint
        CONSTRAINT = tmp / "limb.yaml"
        dump_limb(constraint, CONSTRAINT)
        oracle = ConstraintOracle(constraint)
        model_path = _train(CONSTRAINT, tmp / "m.onnx", "network") if args.model is None \
            else Path(args.model)
        model = load_model(model_path, limb=True)
        geometric = load_model(_train(CONSTRAINT, tmp / "g.onnx", "geometric"), limb=True)
    else:
        constraint = rig.load_constraint()
        source = "the rig's"
        oracle = ConstraintOracle(constraint)
        if args.model is None:
            cpath = tmp / "c.yaml"
            cpath.write_text(constraint.to_yaml())
            model_path = _train(cpath, tmp / "m.onnx")
        else:
            model_path = Path(args.model)
        model = load_model(model_path)
    print(f"rig {rig.name}: constraint {constraint.name!r} ({source}), model {model_path} "
          f"(preset {_preset(model)}); "
          f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores; supervised loops "
          f"{'busy-wait' if BUSY_WAIT else 'sleep'} between cycles"
          f"{', warm-up before each deadline' if WARM_UP else ', no warm-up'}"
          f"{', real-time priority' if REALTIME else ''}")
    compute_us = None

    if "long" in sections:
        print(f"\nlong: rig enforce --rig {RIG}, 200 Hz, adversarial targets, "
              f"{args.minutes:g} min (servo simulator in its own process, USB latency 1 ms)")
        s = rig_enforce(model_path, tmp / "long", 60.0 * args.minutes, seed=1, telemetry=True)
        t = _columns(s["telemetry_csv"], ("t_s", "late_ms", "compute_ms", "read_ms",
                                          "write_ms", "faults"))
        late = t["late_ms"]
        _rate_line("rig enforce", s, late)
        print(f"  late starts by cause {s['late_starts_by_cause']}; safe-state entries "
              f"{s['safe_state_entries']} ({s['safe_state_reason'] or 'none'})")
        tail = {q: float(np.percentile(late, q)) for q in (99.9, 99.99)}
        print(f"  lateness tail: p99.9 {tail[99.9]:.3f} ms, p99.99 {tail[99.99]:.3f} ms, max "
              f"{late.max():.3f} ms; read p99 {np.percentile(t['read_ms'], 99):.3f} ms, max "
              f"{t['read_ms'].max():.3f} ms")
        fresh = (t["faults"].astype(np.int64) & 8) == 0  # Fault.READ_FAILED
        gaps = np.diff(t["t_s"][fresh]) * 1e3 if fresh.sum() > 1 else np.array([0.0])
        print(f"  servo data age (gap between fresh reads): p99.99 "
              f"{np.percentile(gaps, 99.99):.2f} ms, max {gaps.max():.2f} ms; cycles without "
              f"a fresh read {int((~fresh).sum())} (the stale limit is chosen above this)")
        compute_us = 1e3 * t["compute_ms"]

    if "runs" in sections:
        print(f"\nruns: {args.runs} × rig enforce --rig {RIG}, {args.run_s:g} s each, no "
              f"fault injected")
        entries, reasons, pct = 0, [], []
        for r in range(args.runs):
            s = rig_enforce(model_path, tmp / f"run{r}", args.run_s, seed=100 + r)
            entries += s["safe_state_entries"]
            if s["safe_state_entries"]:
                reasons.append(s["safe_state_reason"])
            pct.append(_pct_over(s))
        print(f"  safe-state entries no fault caused: {entries} in {args.runs} runs "
              f"{reasons or ''}; overruns per run median {np.median(pct):.3f} %, max "
              f"{max(pct):.3f} %")

    if "sweep" in sections:
        print(f"\nsweep: highest sustainable rate ({args.sweep_s:g} s per rate; < "
              f"{100 * MAX_OVERRUN:g} % overruns and p99 lateness <= {MAX_P99_LATE_MS} ms), "
              f"supervised loop vs the raw SDK loop on the same bus")
        plans = ((0.0, (200, 300, 400, 500, 600, 700, 800, 1000)),
                 (1.0, (200, 300, 400, 450, 500, 550)))
        if rig.limb:  # 7 servos: a longer sync read and write; and lower rates too
            plans = tuple(((lat, (100, 150, *rates)) for lat, rates in plans))
        ids = rig.servos.ids
        url = SIM_URL if not rig.limb else rig.servos.port
        for latency_ms, rates in plans:
            bound, parts = physical_bound_hz(latency_ms, n=len(ids))
            print(f"  usb_latency_ms={latency_ms:g}: physical bound {bound:.0f} Hz ("
                  + ", ".join(f"{k} {v:.2f} ms" for k, v in parts.items()) + ")")
            best = {"supervised": None, "raw SDK": None, "raw SDK waiting": None}
            with child_servos(f"{url}&usb_latency_ms={latency_ms:g}") as path:
                servos = dataclasses.replace(rig.servos, port=path)
                for rate in rates:
                    s2, t2 = run_loop(servos, oracle, model,
                                      _scripted("adversarial", oracle, rig, 2),
                                      rate=float(rate), duration=args.sweep_s)
                    ok = _sustained(s2["cycles"], s2["overruns"], t2["late_ms"])
                    _rate_line(f"supervised {rate} Hz {'ok' if ok else 'not sustained'}", s2,
                               t2["late_ms"])
                    if ok:
                        best["supervised"] = rate
                    for name, waiting in (("raw SDK", False), ("raw SDK waiting", True)):
                        raw = raw_paced_loop(path, float(rate), args.sweep_s, waiting=waiting,
                                             ids=ids)
                        ok_raw = _sustained(raw["cycles"], raw["overruns"], raw["late_ms"])
                        label = f"{name} {rate} Hz {'ok' if ok_raw else 'not sustained'}"
                        print(f"  {label:<34} {raw['cycles']:7d} cycles  late p99 "
                              f"{np.percentile(raw['late_ms'], 99):.3f} ms  overruns "
                              f"{raw['overruns']} "
                              f"({100 * raw['overruns'] / raw['cycles']:.3f} %)  "
                              f"failed reads {raw['failed_reads']}")
                        if ok_raw:
                            best[name] = rate
            sup_best = best["supervised"]
            raws = [r for r in (best["raw SDK"], best["raw SDK waiting"]) if r]
            raw_best = max(raws) if raws else None
            ratio = (f"{100 * sup_best / raw_best:.0f} %" if sup_best and raw_best else "n/a")
            print(f"  => usb_latency_ms={latency_ms:g}: supervised {sup_best} Hz; raw SDK "
                  f"{best['raw SDK']} Hz, raw SDK waiting {best['raw SDK waiting']} Hz "
                  f"(supervised / best raw {ratio}); supervised / physical bound "
                  f"{100 * (sup_best or 0) / bound:.0f} %")

    if "compute" in sections:
        (limb_compute if rig.limb else compute)(args, rig, oracle, model, compute_us)
    if "accuracy" in sections:
        if rig.limb:
            print("\naccuracy: the one-joint model's only (a limb model's: "
                  "benchmarks/bench_limb.py)")
        else:
            accuracy(rig, oracle, model)
    if "adversarial" in sections:
        if rig.limb:
            limb_adversarial(args, rig, oracle, {"limb model": model, "geometric": geometric})
        else:
            adversarial(args, rig, oracle, model, tmp)
    print(f"\n10^7 additions: {additions_s():.2f} s (end; {t_add:.2f} s at the start)")


def compute(args, rig, oracle, model, compute_us) -> None:
    print("\ncompute: per cycle (model + supervisor + IK + FK + final check)")
    if compute_us is None:
        with child_servos(SIM_URL + "&usb_latency_ms=1") as path:
            servos = dataclasses.replace(rig.servos, port=path)
            _, t = run_loop(servos, oracle, model, ScriptedTargets("adversarial", oracle,
                                                                   seed=1),
                            rate=200.0, duration=20.0)
        compute_us = 1e3 * t["compute_ms"]
        where = "a 20 s 200 Hz loop"
    else:
        where = "the long run's 200 Hz loop"
    in_loop = float(np.median(compute_us))
    print(f"  in {where}: median {in_loop:.1f} µs, p99 {np.percentile(compute_us, 99):.1f} µs")
    qs_ = [tuple(q) for q in _usable_adversarial(rig, oracle)]
    kin = rig.servos.kinematics()
    sup = Supervisor(oracle, SupervisorConfig(), period_s=0.005)
    sup.reset(0.0, kin.forward(kin.zero_ticks))
    t_model, t_sup, t_ik = [], [], []
    ticks = kin.zero_ticks.astype(np.int64)
    pc = time.perf_counter
    for k, q in enumerate(qs_):
        tk = (k + 1) * 0.005
        a = pc()
        c = model.correct_one(q)
        b = pc()
        tq = sup.admit(tk, q, tk)
        goal = sup.step(tk, tq, c)
        cc = pc()
        try:
            gt = kin.inverse(goal, ticks)
            cq = kin.forward(gt)
            ticks = gt
        except Exception:
            cq = goal
        d = pc()
        sup.accept(cq)
        e = pc()
        t_model.append(b - a)
        t_sup.append((cc - b) + (e - d))
        t_ik.append(d - cc)
    for name, v in (("onnxruntime correct_one", t_model), ("supervisor step + accept", t_sup),
                    ("IK + FK", t_ik)):
        v = 1e6 * np.array(v)
        print(f"  {name:<28} median {np.median(v):7.1f} µs  p99 {np.percentile(v, 99):7.1f} µs")
    total = 1e6 * (np.array(t_model) + np.array(t_sup) + np.array(t_ik))
    alone = float(np.median(total))
    print(f"  {'sum (one thread, no bus)':<28} median {alone:7.1f} µs")
    print(f"  in the loop / alone: {in_loop / alone:.2f}")


def _usable_adversarial(rig, oracle, n: int = 4000) -> np.ndarray:
    src = ScriptedTargets("adversarial", oracle, seed=4)
    src.start(0.0)
    kin = rig.servos.kinematics()
    sup = Supervisor(oracle, SupervisorConfig(), period_s=0.005)
    sup.reset(0.0, kin.forward(kin.zero_ticks))
    # one joint's orientation (4,) of each (1, 4) posture the source returns
    targets = [np.asarray(src.latest(k * 0.005)[1], dtype=np.float64).reshape(-1, 4)[0]
               for k in range(1, n + 1)]
    return np.array([q for q in targets if sup.admit(0.0, q, 0.0) is not None])


def accuracy(rig, oracle, model) -> None:
    print("\naccuracy: the model's correction against the exact projection, per cycle")
    rng = np.random.default_rng(5)
    q_adv = _usable_adversarial(rig, oracle)
    q_rand = Q.random_quaternions(20000, rng)
    for label, q in (("adversarial targets (usable ones)", q_adv), ("uniform over SO(3)", q_rand)):
        corrected = model.corrected(q)
        exact = oracle.project(q)
        err = _angle(Q.canonical(corrected), Q.canonical(exact))
        outside = np.degrees(oracle.signed_distance(q)) > 0
        beyond = np.degrees(oracle.signed_distance(corrected)) > 1.0
        print(f"  {label:<34} n={len(q):6d}: |model − exact| median {np.median(err):.3f}° "
              f"p99 {np.percentile(err, 99):.3f}° max {err.max():.2f}°, > 1° on "
              f"{100 * (err > 1).mean():.2f} %; "
              f"model output > 1° outside on {100 * beyond.mean():.2f} % "
              f"({100 * beyond[outside].mean() if outside.any() else 0:.2f} % of outside "
              f"targets)")
    valid = q_rand[oracle.is_valid(q_rand)]
    ident = _angle(model.corrected(valid), valid)
    print(f"  identity error on {len(valid)} valid targets: median {np.median(ident):.4f}° "
          f"p99 {np.percentile(ident, 99):.3f}° max {ident.max():.3f}°")


def adversarial(args, rig, oracle, model, tmp: Path) -> None:
    from models.constraint import JointConstraint

    # a model trained for another constraint (what --force-model lets through)
    other = JointConstraint.cone((1, 0, 0), 70.0, twist=(-90, 90), name="cone70")
    (tmp / "o.yaml").write_text(other.to_yaml())
    wrong = load_model(_train(tmp / "o.yaml", tmp / "o.onnx"))
    servos_in = dataclasses.replace(rig.servos, port=SIM_URL)
    print(f"\nadversarial: {args.cycles} cycles on a manual clock (real bus, in-process sim)")
    for label, m in (("model for the constraint", model), ("model for another constraint",
                                                            wrong)):
        clk = ManualClock()
        src = ScriptedTargets("adversarial", oracle, seed=6)
        s5, t5 = run_loop(servos_in, oracle, m, src, rate=200.0, cycles=args.cycles, clock=clk)
        cmd = np.stack([t5[f"commanded_{c}"] for c in "wxyz"], 1)
        d = np.degrees(oracle.signed_distance(cmd))
        tgt = np.stack([t5[f"target_{c}"] for c in "wxyz"], 1)
        good = np.isfinite(tgt).all(1) & (np.abs(np.linalg.norm(tgt, axis=1) - 1) < 0.02)
        out = np.degrees(oracle.signed_distance(tgt[good])) > 1.0
        print(f"  {label:<30} cycles {s5['cycles']}: commanded beyond 1°: {(d > 1.0).sum()}; "
              f"max {d.max():.3f}°; within 0.5° of the boundary: {(d > -0.5).sum()}; "
              f"targets beyond 1°: {out.sum()}, NaN/zero/non-unit "
              f"{(~good).sum()}; interventions {s5['interventions']} "
              f"{s5['interventions_by_kind']}")


def _postures(table: dict, names, what: str) -> np.ndarray:
    """(N, J, 4) ``<joint>_<what>_w..z`` of a limb's telemetry."""
    return np.stack([np.stack([np.asarray(table[f"{n}_{what}_{c}"], dtype=np.float64)
                               for c in "wxyz"], axis=-1) for n in names], axis=1)


def limb_compute(args, rig, oracle, model, compute_us) -> None:
    """A limb's compute per cycle — model + limb supervisor + IK + FK of every joint + final
    check — inside the 200 Hz loop and the same work alone (same targets, a fresh supervisor,
    the rig's kinematics), medians."""
    print(f"\ncompute: per cycle (model + supervisor + IK + FK + final check, "
          f"{len(rig.servos.ids)} servos)")
    if compute_us is None:
        with child_servos(rig.servos.port + "&usb_latency_ms=1") as path:
            servos = dataclasses.replace(rig.servos, port=path)
            _, t = run_loop(servos, oracle, model, _scripted("adversarial", oracle, rig, 1),
                            rate=200.0, duration=20.0)
        compute_us = 1e3 * np.asarray(t["compute_ms"])
        where = "a 20 s 200 Hz loop"
    else:
        where = "the long run's 200 Hz loop"
    in_loop = float(np.median(compute_us))
    print(f"  in {where}: median {in_loop:.1f} µs, p99 {np.percentile(compute_us, 99):.1f} µs")
    kin = rig.servos.limb_kinematics().compile()
    src = _scripted("adversarial", oracle, rig, 4)
    src.start(0.0)
    n = 4000
    targets = [src.latest((k + 1) * 0.005) for k in range(n)]
    sup = LimbSupervisor(oracle, period_s=0.005, names=kin.names)
    start = kin.forward(kin.zero_ticks)
    sup.reset(0.0, start)
    ticks = kin.zero_ticks.astype(np.float64)
    commanded = [tuple(r) for r in start.tolist()]
    t_model, t_sup, t_ik = np.zeros(n), np.zeros(n), np.zeros(n)
    pc = time.perf_counter
    for k, (tt, q) in enumerate(targets):
        t = (k + 1) * 0.005
        a = pc()
        tq = sup.admit(t, q, tt)
        b = pc()
        corr = None
        if tq is not None:
            corr = np.asarray(model.correct_one(np.array(tq)), dtype=np.float64).reshape(-1, 4)
            corr = [tuple(r) for r in corr.tolist()]
        c = pc()
        goal = sup.step(t, tq, corr)
        d = pc()
        ok = False
        try:
            gt = np.concatenate([j.inverse(g, ticks[sl]) for j, g, sl in
                                 zip(kin.joints, goal, kin.slices, strict=True)])
            cand = [j.forward_one(gt[sl]) for j, sl in zip(kin.joints, kin.slices, strict=True)]
            ok = True
        except UnreachableError:
            cand = None
        e = pc()
        if ok and sup.accept(cand):
            ticks, commanded = gt.astype(np.float64), cand
        else:
            sup.revert(commanded)
        f = pc()
        t_model[k] = c - b
        t_sup[k] = (b - a) + (d - c) + (f - e)
        t_ik[k] = e - d
    for name, v in (("limb model correct_one", t_model), ("limb supervisor", t_sup),
                    ("IK + FK (7 servos)", t_ik)):
        v = 1e6 * v
        print(f"  {name:<28} median {np.median(v):7.1f} µs  p99 {np.percentile(v, 99):7.1f} µs")
    alone = float(np.median(1e6 * (t_model + t_sup + t_ik)))
    print(f"  {'the same work alone':<28} median {alone:7.1f} µs")
    print(f"  in the loop / alone (medians): {in_loop / alone:.2f}")


def _tracked_cycles(oracle, tgt, cmd, pres, intervention, settle: int,
                    vmax_deg_s: float = SupervisorConfig.max_velocity_deg_s,
                    amax_deg_s2: float = SupervisorConfig.max_accel_deg_s2) -> np.ndarray:
    """(N,) bool: the cycles whose target has been held long enough to be reached — valid by
    the exact oracle, fresh (no stale hold), the same since the hold began, and held at least
    the time the supervisor's velocity and acceleration limits need to turn the goal from
    where it was at the hold's start to the target (the joint that must turn most), plus
    ``settle`` cycles for the servos."""
    ok = valid_targets(oracle, tgt) & np.isfinite(pres).all(axis=(1, 2)) \
        & ((intervention.astype(np.int64) & 4) == 0)  # 4: Intervention.HOLD_STALE
    flat = np.nan_to_num(tgt).reshape(len(tgt), -1)
    new_hold = np.r_[True, (flat[1:] != flat[:-1]).any(axis=1)]
    starts = np.flatnonzero(new_hold)
    ends = np.r_[starts[1:], len(tgt)]
    vmax, ramp = vmax_deg_s, vmax_deg_s / amax_deg_s2
    out = np.zeros(len(tgt), dtype=bool)
    for a, b in zip(starts.tolist(), ends.tolist(), strict=True):
        if not ok[a]:
            continue
        prev = cmd[a - 1] if a > 0 else cmd[a]
        turn = float(_angle(tgt[a], prev).max()) if np.isfinite(prev).all() else 180.0
        need = a + int(np.ceil((turn / vmax + ramp) * 200.0)) + settle
        out[need:b] = ok[need:b]
    return out


def limb_adversarial(args, rig, oracle, models: dict) -> None:
    """``--cycles`` adversarial cycles on the simulator's manual clock, per model: commanded
    postures beyond 1° per joint (exact limb oracle); tracking of valid targets held long
    enough to be reached (:func:`_tracked_cycles`: angle between target and present, per
    joint)."""
    servos = dataclasses.replace(rig.servos, port=_limb_sim_url(rig))
    settle = max(1, round(args.settle_s * 200.0))
    print(f"\nadversarial: {args.cycles} cycles at 200 Hz on the simulator's manual clock "
          f"(real bus, in-process sim; valid targets the rig's servos reach; script:adversarial"
          f"?seed=6&hold_s={args.hold_s:g}&segment_s={args.segment_s:g}); tracking: valid "
          f"fresh targets held long enough for the goal's velocity and acceleration limits "
          f"plus {args.settle_s:g} s")
    names = rig.servos.joint_names
    for label, m in models.items():
        if m is None:
            continue
        src = _scripted("adversarial", oracle, rig, 6, hold_s=args.hold_s,
                        segment_s=args.segment_s)
        s5, t5 = run_loop(servos, oracle, m, src, rate=200.0, cycles=args.cycles, clock="sim")
        cmd = _postures(t5, names, "commanded")
        tgt = _postures(t5, names, "target")
        pres = _postures(t5, names, "present")
        finite = np.isfinite(cmd).all(axis=(1, 2))
        d = np.full(cmd.shape[:2], np.nan)
        d[finite] = np.degrees(oracle.signed_distance(cmd[finite]))
        tracked = _tracked_cycles(oracle, tgt, cmd, pres, np.asarray(t5["intervention"]),
                                  settle)
        ok = valid_targets(oracle, tgt)
        err = _angle(tgt[tracked], pres[tracked]) if tracked.any() else np.zeros((0, len(names)))
        print(f"  {label} ({_preset(m)}): cycles {s5['cycles']}, "
              f"safe states {s5['safe_state_entries']}, interventions "
              f"{s5['interventions_by_kind']}; invalid/NaN targets {int((~ok).sum())}")
        for j, n in enumerate(names):
            dj = d[:, j]
            e = err[:, j]
            track = (f"median {np.median(e):.2f}° p95 {np.percentile(e, 95):.2f}° over "
                     f"{len(e)} cycles" if len(e) else "no cycle")
            f = s5["joints"][n]
            ours = (f"; the summary's own: p50 {f['tracking_p50_deg']:.2f}° p95 "
                    f"{f['tracking_p95_deg']:.2f}° over {f['tracked_cycles']}"
                    if f.get("tracked_cycles") else "")
            print(f"    {n:<9} commanded beyond 1°: {int((dj > 1.0).sum())} (max "
                  f"{np.nanmax(dj):.3f}°); tracking of valid held targets {track}{ours}")


if __name__ == "__main__":
    main()
