"""The limit felt at the leader: a therapist pushes a leader joint past the patient's limit.

A simulated leader of one joint — one XL330-M288 (current control available) turning about
z, zero at 2048 — on ``sim://dynamixel`` with a manual clock, driven through the rig's bus
(:class:`~rig.devices.dynamixel.DynamixelBus`, the real ``dynamixel_sdk`` on the pty). The
patient's admitted range is ±30°: each cycle the admitted pose is the leader's angle clamped
to it (what the follower is allowed to do). A simulated therapist holds the leader through an
impedance hand (``bus.set_hand(1, f(t), stiffness=K, damping=B)``) moving 0 → 60° in 1 s,
then holding 60°: at the limit the hand pushes with ``K × 30°``.

Spring off: the leader's servos are as today (torque off), the hand takes the leader to 60°
(30° beyond the limit). Spring on (:class:`~rig.loop.leader_spring.LeaderSpring`, a few gains
and caps): the leader's deviation beyond the limit and the current drawn. Steady state: the
last cycle's deviation (3 s simulated); peak: the largest over the run. The analytic
equilibrium, ``K (60° − θ) = kt · min(g (θ − 30° − 0), I_max)`` in consistent units, is
printed beside it.

``--arm``: the whole arm through ``rig enforce`` (:func:`rig.loop.run_enforce`): the follower
``sim-servo-arm`` with the exact limb model of its patient (arm 3), ``--targets
leader:<sim-leader-arm whose therapist holds it through an impedance hand, hand_stiffness=K>``,
``--duration 20``, at 200 Hz on manual clocks (the simulators in this process, their time
advanced a period a cycle: the figure does not depend on a loaded host), the spring off and on
(``--leader-spring``). Per joint, how far the leader is beyond the patient's limits (the angle
from its pose to the nearest valid posture: the exact oracle's correction): p95 and largest over
the cycles where that joint is beyond, the mean over all cycles, after the first 2 s (the
start-up ramp); and the run's ``leader.spring`` summary.

Figures only, never assertions. Run: ``.venv/bin/python benchmarks/bench_leader_spring.py
[--arm [--seconds S] [--stiffness K] [--spring GAIN,MAX,DEAD_BAND]]``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from models import quaternion as Q
from rig.devices.dynamixel import DynamixelBus
from rig.devices.kinematics import JointKinematics, ServoAxis
from rig.devices.servo import Servo
from rig.loop.leader_spring import LeaderSpring, SpringSettings

URL = "sim://dynamixel?ids=1&model=XL330-M288&clock=manual&return_delay_us=0"
LIMIT_DEG = 30.0
TARGET_DEG = 60.0
TICKS_PER_DEG = 4096 / 360.0
Z = np.array([0.0, 0.0, 1.0])
KINEMATICS = JointKinematics([ServoAxis(1, (0.0, 0.0, 1.0), 2048, 1, 0, 4095)])


@dataclass(frozen=True)
class Push:
    """One run: the leader's deviation beyond the limit (deg) and the spring's current (mA)."""

    final_deg: float
    peak_deg: float
    current_ma: float


def therapist_push(settings: SpringSettings | None, *, stiffness: float = 0.2,
                   damping: float = 0.002, seconds: float = 3.0, period: float = 0.005,
                   ramp_s: float = 1.0) -> Push:
    """Run the scenario of the module docstring; ``settings`` None: the spring off.

    Parameters
    ----------
    settings : SpringSettings or None
    stiffness, damping : float
        The therapist's hand, N·m/rad and N·m·s/rad.
    seconds, period : float
        Simulated length and the cycle's period, s.
    ramp_s : float
        Time the hand takes from 0 to 60°, s.
    """
    with DynamixelBus(URL, [Servo(1)]) as dxl:
        sim = dxl.port.simulator
        clock = sim.clock
        spring = LeaderSpring(dxl, KINEMATICS, settings) if settings is not None else None
        if spring is not None:
            spring.arm()
        start = clock()

        def hand(t: float) -> float:
            return 2048.0 + TICKS_PER_DEG * TARGET_DEG * min(1.0, (t - start) / ramp_s)

        sim.set_hand(1, hand, stiffness=stiffness, damping=damping)
        peak = deviation = current = 0.0
        for _ in range(round(seconds / period)):
            ticks = dxl.read_ticks()
            angle = (float(ticks[0]) - 2048.0) / TICKS_PER_DEG
            if spring is not None:
                admitted = max(-LIMIT_DEG, min(LIMIT_DEG, angle))
                aq = Q.from_axis_angle(Z, math.radians(admitted))[None]
                current = float(spring.update(KINEMATICS.forward(ticks)[None], aq, ticks)[0])
            deviation = max(0.0, abs(angle) - LIMIT_DEG)
            peak = max(peak, deviation)
            clock.advance(period)
        if spring is not None:
            spring.disarm()
        return Push(deviation, peak, current)


def equilibrium_deg(settings: SpringSettings | None, stiffness: float,
                    kt: float = 0.52 / 1.47) -> float:
    """Analytic steady deviation beyond the limit (deg): the hand's torque against the
    spring's ``kt × current`` (the servo's loop saturated at Goal Current), by bisection."""
    span = TARGET_DEG - LIMIT_DEG
    if settings is None:
        return span
    k_deg = stiffness * math.pi / 180.0

    def net(x: float) -> float:
        amps = min(settings.gain_ma_per_deg * x, settings.max_current_ma) / 1000.0
        return k_deg * (span - x) - kt * amps

    lo, hi = 0.0, span
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if net(mid) > 0 else (lo, mid)
    return 0.5 * (lo + hi)


#: ``--arm``: seconds left out of the figure at the start (the follower's start-up ramp).
SETTLE_S = 2.0


def arm_run(spring: str | None, *, stiffness: float, seconds: float, workdir) -> dict:
    """One ``rig enforce`` run of the ``--arm`` section; per joint ``{p95, max, cycles}`` of
    the leader's deviation beyond the commanded posture where the limit binds, deg, and the
    run's ``leader.spring``."""
    from pathlib import Path

    import yaml

    from models.limb import dump_limb
    from models.limb_model import export_limb_model
    from models.oracle import ConstraintOracle
    from rig.demo.stages import shipped_config
    from rig.loop import EnforceHooks, EnforceRequest, run_enforce
    from rig.sim.patients import anatomical_limb
    from rig.sim.urls import with_keys

    d = Path(workdir)
    limb = anatomical_limb(3, "arm", kinds={"elbow": "forearm"})
    model = d / "arm.onnx"
    if not model.exists():
        dump_limb(limb, d / "arm.yaml")
        export_limb_model(limb, model)  # the exact geometric graph
    cfg = shipped_config("sim-leader-arm")
    manual = {"clock": "manual", "process": "off", "wire_time": "off"}
    cfg["servos"]["port"] = with_keys(cfg["servos"]["port"], hand_stiffness=f"{stiffness:g}",
                                      **manual)
    rig = d / "leader.yaml"
    rig.write_text(yaml.safe_dump(cfg, sort_keys=False))
    from rig.devices.config import load_rig_config
    from rig.devices.ports import open_port

    f_url = load_rig_config("sim-servo-arm").servos.port
    port = open_port(with_keys(f_url, **manual), baud=1_000_000)
    period = 1.0 / 200.0

    def on_cycle(loop, k):  # the leader's simulated time keeps pace with the loop's
        if k == 0:
            loop.targets.bus.set_latency(50.0)
        loop.targets.port.simulator.clock.advance(period)

    try:
        res = run_enforce(EnforceRequest(rig="sim-servo-arm", model=str(model),
                                         targets=f"leader:{rig}", duration_s=seconds,
                                         stale_servo_ms=1000.0, watchdog_ms=0,
                                         leader_spring=spring),
                          hooks=EnforceHooks(keep_telemetry=True, clock=port.simulator.clock,
                                             ports={f_url: port}, on_cycle=on_cycle))
    finally:
        port.close()
    table = res.telemetry.table()
    oracle = ConstraintOracle(limb)
    names = limb.joint_names

    def posture(what):
        return np.stack([np.stack([table[f"{n}_{what}_{c}"] for c in "wxyz"], axis=-1)
                         for n in names], axis=1)

    tq = posture("target")
    ok = np.isfinite(tq).all(axis=(1, 2))
    out: dict = {"cycles": len(tq), "leader": res.summary.get("leader", {}).get("spring"),
                 "exit": res.exit_status}
    ok &= np.asarray(table["t_s"]) >= SETTLE_S  # past the start-up ramp
    bind = np.zeros(tq.shape[:2], dtype=bool)
    bind[ok] = ~oracle.is_valid(tq[ok])
    # how far the leader is beyond the patient's limits: each joint's angle to the nearest valid
    # posture (the exact oracle's correction of the leader's pose)
    beyond = np.zeros(tq.shape[:2])
    if ok.any():
        corr = np.asarray(oracle.correction(tq[ok], normalize=True))
        beyond[ok] = np.degrees(2.0 * np.arccos(np.clip(np.abs(corr[..., 0]), 0.0, 1.0)))
    for j, n in enumerate(names):
        e = beyond[bind[:, j], j]
        out[n] = {"cycles": len(e),
                  "p95": None if not len(e) else float(np.percentile(e, 95)),
                  "max": None if not len(e) else float(e.max()),
                  "mean_all": float(beyond[ok, j].mean()) if ok.any() else None}
    return out


def arm_main(seconds: float, stiffness: float, spring: str) -> None:
    import tempfile

    print(f"sim-servo-arm led by sim-leader-arm (7 XL330-M288), therapist hand_stiffness="
          f"{stiffness:g} N·m/rad, {seconds:g} s at 200 Hz; how far the leader is beyond the "
          f"patient's limits (each joint's angle to its nearest valid posture, deg): p95 and "
          f"max over the cycles beyond, mean over all")
    with tempfile.TemporaryDirectory() as d:
        for label, opt in (("off", None), (f"on {spring}", spring)):
            r = arm_run(opt, stiffness=stiffness, seconds=seconds, workdir=d)
            joints = "; ".join(
                f"{n} p95 {r[n]['p95']:.1f} max {r[n]['max']:.1f} ({r[n]['cycles']} cycles, "
                f"mean {r[n]['mean_all']:.2f})"
                if r[n]["p95"] is not None else f"{n}: never binding"
                for n in ("shoulder", "elbow", "wrist"))
            print(f"spring {label:>14}: {joints}; cycles {r['cycles']}, exit {r['exit']}")
            if r["leader"] is not None:
                print(f"{'':>22}leader.spring {r['leader']}")


def main() -> None:
    import argparse

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--arm", action="store_true", help="the whole arm through rig enforce")
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--stiffness", type=float, default=0.2, help="hand, N·m/rad")
    ap.add_argument("--spring", default="10,150,1", help="GAIN,MAX_MA,DEAD_BAND_DEG")
    args = ap.parse_args()
    if args.arm:
        arm_main(args.seconds, args.stiffness, args.spring)
        return
    stiffness = 0.2
    print(f"XL330-M288 leader, admitted ±{LIMIT_DEG:g}°, therapist hand {stiffness} N·m/rad "
          f"towards {TARGET_DEG:g}° (pushes {stiffness * math.radians(30):.3f} N·m at the "
          f"limit); 200 Hz, 3 s simulated")
    print(f"{'spring':>28} | {'beyond limit, steady':>20} | {'peak':>6} | {'analytic':>8} "
          f"| {'current':>8}")
    cases: list[SpringSettings | None] = [None]
    cases += [SpringSettings(True, g, m, 1.0) for g, m in
              ((5.0, 300.0), (10.0, 300.0), (20.0, 300.0), (40.0, 300.0), (40.0, 100.0),
               (80.0, 600.0))]
    for s in cases:
        r = therapist_push(s, stiffness=stiffness)
        name = "off" if s is None else f"{s.gain_ma_per_deg:g} mA/° ≤ {s.max_current_ma:g} mA"
        print(f"{name:>28} | {r.final_deg:19.2f}° | {r.peak_deg:5.2f}° | "
              f"{equilibrium_deg(s, stiffness):7.2f}° | {r.current_ma:5.0f} mA")


if __name__ == "__main__":
    main()
