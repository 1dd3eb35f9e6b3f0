"""The live enforcement loop through the real ``dynamixel_sdk`` on the simulated 3-servo bus.

Prints (figures, never assertions):

1. **Sustained rate** — ``rig enforce``'s loop at 200 Hz for ``--duration`` s (default 60) on
   the ``sim-shoulder`` chain served by a simulator in a child process (``rig sim servos``,
   as a real bus is outside the host process), return delay 0, adversarial targets: achieved
   rate, cycle time p50/p99, lateness (start − deadline) p50/p99 — the "cycle overrun" — and
   the overrun count. The same for a few seconds with the simulator in this process (what
   ``rig enforce --rig sim-shoulder`` does).
2. **Highest sustainable rate** — short runs at increasing rates; sustainable = < 1 % of cycles
   overrun and p99 lateness ≤ 1 ms.
3. **Per-cycle compute** (model + supervisor + IK + FK + final check) — median µs from the
   loop's telemetry, and each part alone on the same targets (single-sample onnxruntime call,
   supervisor step + accept, IK + FK).
4. **Model vs exact projection** — per cycle of adversarial and valid targets: the angle between
   ``correction ⊗ target`` and the exact projection; how often the model's output was beyond
   the tolerance (the supervisor then projects); identity error on valid targets.
5. **≥ 10,000 adversarial cycles** on a manual clock (the bus is real, time is not): commanded
   orientations beyond the tolerance, counted with the batched oracle from telemetry — with the
   model trained for the constraint and with a model trained for another one.

Run: ``python benchmarks/bench_enforce.py [--duration 60] [--cycles 10000] [--model M.onnx]``.
The model defaults to ``rig train`` (preset ``field``) on the rig's constraint, trained first.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import common  # noqa: F401  (first: one BLAS thread, this checkout on sys.path)
import numpy as np
from common import child_env, child_servos

from models import quaternion as Q
from models.onnx_io import load_model
from models.oracle import ConstraintOracle
from rig.devices.config import load_rig_config
from rig.devices.ports import open_port
from rig.loop import (
    EnforcementLoop,
    LoopConfig,
    ScriptedTargets,
    Supervisor,
    SupervisorConfig,
)
from rig.loop.runner import prepare_chain
from rig.sim.clock import ManualClock

SIM_URL = "sim://dynamixel?ids=1,2,3&model=XM430-W350&return_delay_us=0"


def _train(constraint_path: Path, out: Path) -> Path:
    subprocess.run([sys.executable, "-m", "rig", "train", "--constraint", str(constraint_path),
                    "--out", str(out)], check=True, capture_output=True,
                   env=child_env())
    return out


def run_loop(servos, oracle, model, targets, *, rate, duration=None, cycles=None, clock=None):
    cfg = LoopConfig(rate_hz=rate, duration_s=duration,
                     watchdog_ms=1000 if clock is not None else None)
    kw = {} if clock is None else {"clock": clock, "sleep": clock.sleep}
    with open_port(servos.port, baud=servos.baud) as port:
        chain = prepare_chain(port, servos, oracle)
        try:
            loop = EnforcementLoop(chain, model, oracle, targets, cfg, **kw)
            loop.setup()
            summary = loop.run(max_cycles=cycles)
        finally:
            chain.close()
    return summary, loop.telemetry.table()


def _rate_line(label, s, table):
    late = table["late_ms"]
    print(f"  {label:<38} {s['cycles']:6d} cycles  {s['achieved_hz']:7.1f} Hz  cycle p50 "
          f"{s['p50_cycle_ms']:.3f} ms p99 {s['p99_cycle_ms']:.3f} ms  late p50 "
          f"{np.median(late):.3f} ms p99 {np.percentile(late, 99):.3f} ms  overruns "
          f"{s['overruns']} ({100 * s['overruns'] / max(1, s['cycles']):.2f} %)  faults "
          f"{s['faults'] or '{}'}")


def _angle(a, b):
    return np.degrees(Q.angle(Q.multiply(a, Q.conjugate(b))))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=60.0)
    ap.add_argument("--cycles", type=int, default=10_000)
    ap.add_argument("--model", default=None)
    ap.add_argument("--rig", default="sim-shoulder")
    args = ap.parse_args()

    rig = load_rig_config(args.rig)
    constraint = rig.load_constraint()
    oracle = ConstraintOracle(constraint)
    tmp = Path(tempfile.mkdtemp(prefix="bench-enforce-"))
    if args.model is None:
        cpath = tmp / "c.yaml"
        cpath.write_text(constraint.to_yaml())
        model_path = _train(cpath, tmp / "m.onnx")
    else:
        model_path = Path(args.model)
    model = load_model(model_path)
    # a model trained for another constraint (what --force-model lets through)
    from models.constraint import JointConstraint

    other = JointConstraint.cone((1, 0, 0), 70.0, twist=(-90, 90), name="cone70")
    (tmp / "o.yaml").write_text(other.to_yaml())
    wrong = load_model(_train(tmp / "o.yaml", tmp / "o.onnx"))
    print(f"rig {rig.name}: constraint {constraint.name!r}, model {model_path} "
          f"(preset {model.network_info.get('preset', '?')}); "
          f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")

    # 1. sustained rate ----------------------------------------------------------------------
    print(f"\n1. sustained 200 Hz, 3 servos, adversarial targets, {args.duration:g} s")
    with child_servos() as child_port:
        servos = dataclasses.replace(rig.servos, port=child_port)
        s, t = run_loop(servos, oracle, model, ScriptedTargets("adversarial", oracle, seed=1),
                        rate=200.0, duration=args.duration)
        _rate_line("simulator in a child process", s, t)
        compute_us = 1e3 * t["compute_ms"]
        # 2. highest sustainable rate ---------------------------------------------------------
        print("\n2. highest sustainable rate (5 s each; < 1 % overruns and p99 late <= 1 ms)")
        best = None
        for rate in (200, 300, 400, 500, 700, 1000):
            s2, t2 = run_loop(servos, oracle, model,
                              ScriptedTargets("adversarial", oracle, seed=2), rate=float(rate),
                              duration=5.0)
            ok = s2["overruns"] < 0.01 * s2["cycles"] and np.percentile(t2["late_ms"], 99) <= 1
            _rate_line(f"{rate} Hz {'(sustained)' if ok else '(not sustained)'}", s2, t2)
            if ok:
                best = rate
        print(f"  highest sustainable: {best} Hz; the median cycle ({s['p50_cycle_ms']:.3f} ms "
              f"at 200 Hz) alone would allow {1e3 / s['p50_cycle_ms']:.0f} Hz")
    servos_in = dataclasses.replace(rig.servos, port=SIM_URL)
    s3, t3 = run_loop(servos_in, oracle, model, ScriptedTargets("adversarial", oracle, seed=3),
                      rate=200.0, duration=min(10.0, args.duration))
    _rate_line("simulator in this process (10 s)", s3, t3)

    # 3. per-cycle compute --------------------------------------------------------------------
    print("\n3. per-cycle compute (model + supervisor + IK + FK + final check)")
    print(f"  in the 200 Hz loop: median {np.median(compute_us):.1f} µs, p99 "
          f"{np.percentile(compute_us, 99):.1f} µs")
    src = ScriptedTargets("adversarial", oracle, seed=4)
    src.start(0.0)
    kin = rig.servos.kinematics()
    sup = Supervisor(oracle, SupervisorConfig(), period_s=0.005)
    sup.reset(0.0, kin.forward(kin.zero_ticks))
    targets = [src.latest(k * 0.005) for k in range(1, 4001)]
    usable = [(tt, q) for tt, q in targets if sup.admit(0.0, q, 0.0) is not None]
    qs_ = [q for _, q in usable]
    t_model, t_sup, t_ik = [], [], []
    ticks = kin.zero_ticks.astype(np.int64)
    pc = time.perf_counter
    for k, q in enumerate(qs_):
        tk = (k + 1) * 0.005
        a = pc()
        c = model.correct_one(*q)
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
    print(f"  {'sum (one thread, no bus)':<28} median {np.median(total):7.1f} µs")

    # 4. model vs exact projection ------------------------------------------------------------
    print("\n4. the model's correction against the exact projection, per cycle")
    rng = np.random.default_rng(5)
    q_adv = np.array(qs_)
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
    tq = t["target_w"]
    ok = np.isfinite(tq)
    bits = t["intervention"][ok]
    print(f"  in the 60 s loop: model output projected by the supervisor on "
          f"{100 * ((bits & 1) > 0).mean():.2f} % of cycles with a usable target, "
          f"re-projected after rate limiting on {100 * ((bits & 16) > 0).mean():.2f} %")

    # 5. >= 10,000 adversarial cycles ----------------------------------------------------------
    print(f"\n5. {args.cycles} adversarial cycles on a manual clock (real bus, in-process sim)")
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


if __name__ == "__main__":
    main()
