"""The limb loop's compute per cycle (supervisor + IK + FK, optionally a limb model), 7 servos:
inside the loop against the same work alone, same run.

A 7-servo arm (shoulder Z-Y'-X'', elbow hinge Z, wrist Z-Y'-X'') on ``sim://dynamixel`` driven by
a manual clock (the simulator advances exactly one period per cycle, so the figures are the
compute's, not the scheduler's), enforcing a held-out arm limb file whose shoulder is coupled to
the elbow (:func:`models.limb_evaluation.random_limb`), targets from its held-out postures:
``jumps`` (default) holds each (valid and invalid) 30 cycles; ``smooth`` joins the valid ones
joint by joint, 2 s apart (tracking). *Inside*: the telemetry's ``compute_ms`` (target → supervisor
→ IK → FK → final check). *Alone*: the same targets through a fresh
:class:`~rig.loop.limb_supervisor.LimbSupervisor` and the same kinematics in a tight loop.
Prints the machine's 10⁷-additions loop time beside the figures.

Run: ``python benchmarks/bench_loop_limb.py [--cycles 4000] [--targets jumps|smooth]
[--model LIMB.onnx]``. Figures,
never assertions.
"""

from __future__ import annotations

import argparse
import time

import common  # noqa: F401  (first: one BLAS thread, this checkout on sys.path)
import numpy as np
from common import additions_s

from models.limb_evaluation import held_out_postures, random_limb
from models.onnx_io import load_model
from models.oracle import ConstraintOracle
from rig.devices.dynamixel import DynamixelBus
from rig.devices.kinematics import JointKinematics, LimbKinematics, ServoAxis
from rig.devices.ports import open_port
from rig.devices.servo_limb import ServoLimb
from rig.errors import UnreachableError
from rig.loop import EnforcementLoop, LoopConfig
from rig.loop.limb_supervisor import LimbSupervisor
from rig.loop.targets import TargetSource

URL = "sim://dynamixel?ids=1-7&model=XM430-W350&return_delay_us=0&clock=manual&wire_time=off"


def kinematics() -> LimbKinematics:
    z, y, x = (0, 0, 1), (0, 1, 0), (1, 0, 0)

    def ax(i, a):
        return ServoAxis(id=i, axis=a, zero_ticks=2048, direction=1, min_ticks=0,
                         max_ticks=4095)
    return LimbKinematics([JointKinematics([ax(1, z), ax(2, y), ax(3, x)]),
                           JointKinematics([ax(4, z)]),
                           JointKinematics([ax(5, z), ax(6, y), ax(7, x)])],
                          names=("shoulder", "elbow", "wrist"))


class Postures(TargetSource):
    """``jumps``: the pool's postures (valid and invalid) held ``hold`` cycles each. ``smooth``:
    the pool's valid postures joined joint by joint along the shortest rotation, ``hold``
    cycles from one to the next (the rate limits can follow: tracking)."""

    def __init__(self, pool, hold=30, period=0.005, smooth=False):
        self.pool, self.hold, self.period, self.smooth = pool, hold, period, smooth

    def at(self, k):
        i, r = divmod(k, self.hold)
        a = self.pool[i % len(self.pool)]
        if not self.smooth:
            return a
        b = self.pool[(i + 1) % len(self.pool)]
        return slerp(a, b, r / self.hold)

    def latest(self, t):
        return t, self.at(round((t - self.t0) / self.period))


def slerp(a: np.ndarray, b: np.ndarray, f: float) -> np.ndarray:
    """Row-wise shortest-path interpolation of unit quaternions (J, 4)."""
    dot = np.einsum("ij,ij->i", a, b)
    b = np.where(dot[:, None] < 0, -b, b)
    th = np.arccos(np.clip(np.abs(dot), 0.0, 1.0))[:, None]
    s = np.sin(th)
    small = s[:, 0] < 1e-9
    w0 = np.where(small[:, None], 1.0 - f, np.sin((1.0 - f) * th) / np.where(small[:, None], 1, s))
    w1 = np.where(small[:, None], f, np.sin(f * th) / np.where(small[:, None], 1, s))
    q = w0 * a + w1 * b
    return q / np.linalg.norm(q, axis=1, keepdims=True)




def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cycles", type=int, default=4000)
    ap.add_argument("--model", default=None, help="a limb model (.onnx) for the arm limb")
    ap.add_argument("--targets", choices=("jumps", "smooth"), default="jumps")
    ap.add_argument("--hold", type=int, default=None,
                    help="cycles per posture (default 30 for jumps, 400 for smooth)")
    args = ap.parse_args()
    limb = random_limb(20261128, "arm")
    oracle = ConstraintOracle(limb).prepare()
    pool = held_out_postures(limb, 60, np.random.default_rng(7), oracle=oracle)
    valid = pool[oracle.is_valid(pool).all(axis=1)]
    start = valid[0]
    smooth = args.targets == "smooth"
    src = Postures(valid if smooth else pool, args.hold or (400 if smooth else 30),
                   smooth=smooth)
    model = None if args.model is None else load_model(args.model, limb=True)
    kin = kinematics()
    t10 = additions_s()
    with open_port(URL, baud=1_000_000) as port:
        sim = port.simulator
        for i, t in zip(kin.ids, kin.inverse(start, kin.zero_ticks), strict=True):
            sim.set_hand(i, float(t))
        sim.clock.advance(0.01)
        sl = ServoLimb(DynamixelBus(port, list(kin.ids)), kin)
        try:
            sl.bus.configure()
            loop = EnforcementLoop(sl, model, oracle, src, LoopConfig(
                watchdog_ms=1000), clock=sim.clock, sleep=sim.clock.sleep)
            loop.setup()
            summary = loop.run(max_cycles=args.cycles)
        finally:
            sl.close()
    inside = loop.telemetry.compute_ms() * 1e3
    # the same work alone: the same targets, a fresh supervisor, the same kinematics
    sup = LimbSupervisor(oracle, period_s=0.005, names=kin.names)
    sup.reset(0.0, start)
    ticks = kin.inverse(start, kin.zero_ticks)
    commanded = list(map(tuple, start))
    alone = np.empty(args.cycles)
    for k in range(args.cycles):
        t0 = time.perf_counter()
        t = 0.005 * (k + 1)
        tq = sup.admit(t, src.at(k), t)
        corr = None
        if tq is not None and model is not None:
            corr = np.asarray(model.correct_one(np.array(tq)), dtype=np.float64)
        goal = sup.step(t, tq, corr)
        try:
            gt = np.concatenate([j.inverse(g, ticks[s]) for j, g, s in
                                 zip(kin.joints, goal, kin.slices, strict=True)])
            cand = [j.forward_one(gt[s]) for j, s in zip(kin.joints, kin.slices, strict=True)]
            if sup.accept(cand):
                ticks, commanded = gt, cand
            else:
                sup.revert(commanded)
        except UnreachableError:
            sup.revert(commanded)
        alone[k] = (time.perf_counter() - t0) * 1e6
    table = loop.telemetry.table()
    cmd = np.stack([np.stack([table[f"{n}_commanded_{c}"] for c in "wxyz"], axis=-1)
                    for n in kin.names], axis=1)
    d = np.degrees(oracle.signed_distance(cmd))
    p_in, p_al = float(np.median(inside)), float(np.median(alone))
    print(f"10^7 additions: {t10:.2f} s")
    print(f"cycles {summary['cycles']}, warm-ups {loop.warm_ups}, max violation "
          f"{summary['max_violation_deg']:.3f} deg, model {'yes' if model else 'no'}")
    for j, n in enumerate(kin.names):
        f = summary["joints"][n]
        print(f"  {n}: commanded beyond 1 deg (exact limb oracle) {int((d[:, j] > 1.0).sum())}"
              f", max {d[:, j].max():.3f} deg; interventions {f['interventions']}; tracking "
              f"of valid targets p50 {f['tracking_p50_deg']:.2f} p95 "
              f"{f['tracking_p95_deg']:.2f} deg over {f['tracked_cycles']} cycles")
    print(f"compute inside the loop: p50 {p_in:.0f} us, p99 {np.percentile(inside, 99):.0f} us")
    print(f"the same work alone:     p50 {p_al:.0f} us, p99 {np.percentile(alone, 99):.0f} us")
    print(f"ratio inside / alone (medians): {p_in / p_al:.2f}")


if __name__ == "__main__":
    main()
