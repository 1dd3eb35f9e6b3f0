"""The live loop on the simulated servo bus (real ``dynamixel_sdk`` on a pty), driven by a
manual clock: correctness by counts and telemetry content, never by wall time.

Faults are injected through the simulator's public fault-injection API. The Bus Watchdog is
armed at 1 s in these tests (not the rig's 100 ms) so a loaded test machine cannot trip it
between two cycles; ``test_bus_watchdog_is_armed`` checks the rig's own value.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from models import quaternion as Q
from models.constraint import JointConstraint, dump_constraint
from models.onnx_io import load_model
from models.oracle import ConstraintOracle
from models.shapes import load_shape
from rig.cli import main
from rig.devices.config import load_rig_config
from rig.devices.ports import open_port
from rig.loop import (
    EnforcementLoop,
    Fault,
    Intervention,
    LoopConfig,
    ScriptedTargets,
    SupervisorConfig,
)
from rig.loop.runner import prepare_servo_limb
from rig.loop.supervisor import SAFETY_FLAGS
from rig.sim.clock import ManualClock
from tests.rig.rigs import LOADED_HOST_MS

URL = "sim://dynamixel?ids=1,2,3&model=XM430-W350&return_delay_us=0"
RIG = load_rig_config("sim-shoulder")
SERVOS = dataclasses.replace(RIG.servos, port=URL)
TOL = math.radians(1.0)


def _train(constraint_path, out):
    with pytest.raises(SystemExit) as exc:
        main(["train", "--constraint", str(constraint_path), "--out", str(out)])
    assert exc.value.code == 0
    return out


@pytest.fixture(scope="module")
def models(tmp_path_factory):
    d = tmp_path_factory.mktemp("loop-models")
    orig = load_shape("original")
    notch = JointConstraint.polygon(orig.swing.vertices, orig.swing.interior, twist=(-45, 70),
                                    name="original+twist")
    cone = JointConstraint.cone((1, 0, 0), 50.0, twist=(-40, 40), name="cone50")
    out = {}
    for c in (notch, cone):
        path = d / f"{c.name}.yaml"
        dump_constraint(c, path)
        out[c.name] = (c, load_model(_train(path, d / f"{c.name}.onnx")))
    return out


def _run(constraint, model, targets, *, cycles, on_cycle=None, watchdog_ms=1000,
         safe_state="hold", before=None, warm_up=True, faults=False, **sup):
    """Open the simulated servos, run ``cycles`` cycles on a manual clock, close everything;
    ``faults``: the test injects faults that time reads out (the SDK's own packet timeout).

    Returns (summary, telemetry table, bus, loop).
    """
    oracle = ConstraintOracle(constraint)
    cfg = LoopConfig(rate_hz=200.0, watchdog_ms=watchdog_ms, safe_state=safe_state,
                     supervisor=SupervisorConfig(**sup), warm_up=warm_up)
    # the loop and the servos share one simulated clock: the limb moves exactly as far per
    # cycle as the loop's time says, however fast or loaded the test machine is
    with open_port(URL + "&clock=manual&wire_time=off", baud=SERVOS.baud) as port:
        bus = port.simulator
        clk = bus.clock
        if before is not None:
            before(bus)
            clk.advance(0.01)  # let what ``before`` did to the limb take effect
        limb = prepare_servo_limb(port, SERVOS, oracle)
        if not faults:
            limb.bus.set_latency(LOADED_HOST_MS)
        try:
            loop = EnforcementLoop(limb, model, oracle, targets, cfg, clock=clk,
                                   sleep=clk.sleep, on_cycle=on_cycle)
            loop.setup()
            summary = loop.run(max_cycles=cycles)
            state = {i: (bus.servo(i).torque, bus.servo(i).get("Goal Position"),
                         bus.position(i)) for i in SERVOS.ids}
        finally:
            limb.close()
    return summary, loop.telemetry.table(), state, loop


def _col(table, name):
    return np.stack([table[f"{name}_{c}"] for c in "wxyz"], axis=1)


def _distance(oracle, q):
    return oracle.signed_distance(q)


# --------------------------------------------------------------------------- safety
@pytest.mark.parametrize("which", ["original+twist", "wrong-model"])
def test_adversarial_targets_never_commanded_beyond_tolerance(models, which):
    constraint, model = models["original+twist"]
    if which == "wrong-model":  # a model trained for another constraint (as --force-model)
        model = models["cone50"][1]
    oracle = ConstraintOracle(constraint)
    # every kind of segment once (8 × 0.5 s), each target held long enough to reach the
    # boundary (at whole ticks within 120°/s: 0.55-0.60° a cycle on this 3-servo shoulder)
    src = ScriptedTargets("adversarial", oracle, seed=7, segment_s=0.5, hold_s=0.35)
    summary, table, _, _ = _run(constraint, model, src, cycles=800)
    assert summary["cycles"] == 800 and summary["end_reason"] == "completed"
    commanded = _col(table, "commanded")
    d = _distance(oracle, commanded)
    assert (d <= TOL).all(), f"{(d > TOL).sum()} commanded orientations beyond 1°"
    if which != "wrong-model":  # the goal did press on the boundary
        assert (d > -math.radians(0.5)).sum() > 50
    assert summary["max_violation_deg"] <= 1.0
    # the telemetry's own distance column agrees with the oracle
    np.testing.assert_allclose(table["distance_deg"], np.degrees(d), atol=1e-6)
    target = _col(table, "target")
    ok = np.isfinite(target).all(1) & (np.abs(np.linalg.norm(target, axis=1) - 1) < 0.02)
    assert (_distance(oracle, target[ok]) > TOL).sum() > 200  # plenty of targets were outside
    bits = table["intervention"]
    assert (bits & Intervention.HOLD_INVALID).sum() > 25
    assert (bits & Intervention.HOLD_STALE).sum() > 25
    assert summary["interventions"] > 0 and summary["safe_state_entries"] == 0
    # the breakdown adds up to the total, and both agree with the telemetry's own bits
    assert sum(summary["interventions_by_kind"].values()) == summary["interventions"]
    assert summary["interventions"] == int((bits & SAFETY_FLAGS != 0).sum())
    assert summary["rate_limited"] == int((bits & Intervention.RATE_LIMITED != 0).sum())
    if which == "wrong-model":
        assert (bits & (Intervention.PROJECTED | Intervention.REPROJECTED)).sum() > 50


def test_the_warm_up_changes_nothing_that_is_sent(models):
    """The warm-up before each deadline runs the compute on copies and throws the result away:
    with and without it, the same targets give the same corrections, commands and
    interventions, cycle by cycle. (Not the limb's motion to the last bit: when the simulated
    servos take a goal relative to the manual clock's next step depends on their thread.)"""
    constraint, model = models["original+twist"]
    oracle = ConstraintOracle(constraint)
    runs = []
    for warm_up in (True, False):
        src = ScriptedTargets("adversarial", oracle, seed=3, segment_s=0.5, hold_s=0.25)
        runs.append(_run(constraint, model, src, cycles=400, warm_up=warm_up))
    (_, warm, _, loop), (_, cold, _, cold_loop) = runs
    assert loop.warm_ups > 250 and cold_loop.warm_ups == 0  # each cycle after a usable target
    for name in ("commanded", "correction", "target"):
        np.testing.assert_array_equal(_col(warm, name), _col(cold, name), err_msg=name)
    for name in ("intervention", "faults", "distance_deg", "t_s"):
        np.testing.assert_array_equal(warm[name], cold[name], err_msg=name)


def test_slow_valid_path_is_tracked(models):
    constraint, model = models["cone50"]
    oracle = ConstraintOracle(constraint)
    src = ScriptedTargets("slow", oracle, period_s=3.0)
    summary, table, _, _ = _run(constraint, model, src, cycles=800)
    target, present = _col(table, "target"), _col(table, "present")
    err = np.degrees(Q.angle(Q.multiply(present, Q.conjugate(target))))
    settled = table["t_s"] > 1.0  # after the goal has caught up with the path
    assert np.median(err[settled]) <= 1.5
    bits = table["intervention"][settled]
    assert not (bits & (Intervention.PROJECTED | Intervention.REPROJECTED)).any()
    assert summary["max_violation_deg"] == 0.0


def test_limb_starting_outside_is_brought_back(models):
    constraint, model = models["cone50"]
    oracle = ConstraintOracle(constraint)
    kin = SERVOS.kinematics()
    start = Q.from_two_vectors(Q.LIMB_AXIS, np.array([0.0, math.sin(1.4), math.cos(1.4)]))
    ticks = kin.inverse(start, kin.zero_ticks)  # ~80° from the axis: 30° outside the cone

    def place(bus):  # torque off: the limb rests where the hand left it
        for i, t in zip(SERVOS.ids, ticks, strict=True):
            bus.set_hand(i, float(t))

    src = ScriptedTargets("adversarial", oracle, seed=1, segment_s=0.1, hold_s=0.05)
    _, table, _, _ = _run(constraint, model, src, cycles=600, before=place)
    d = np.degrees(_distance(oracle, _col(table, "commanded")))
    assert d[0] > 25.0
    back = np.flatnonzero(d <= 1.0)
    assert len(back) and back[0] < 200  # < 1 s at 120°/s
    # monotone: never further out than any earlier command
    assert (np.diff(d[: back[0] + 1]) <= 1e-9).all()
    assert (d[back[0]:] <= 1.0).all()
    steered = Intervention.RECOVERY | Intervention.HOLD_INVALID | Intervention.HOLD_STALE
    assert (table["intervention"][: back[0]] & steered).all()
    assert (table["intervention"][: back[0]] & Intervention.RECOVERY).sum() > back[0] // 2


# --------------------------------------------------------------------------- faults
def test_one_percent_dropped_and_corrupted_packets(models):
    constraint, model = models["cone50"]
    oracle = ConstraintOracle(constraint)
    bus_ref = {}

    def on_cycle(loop, k):
        if k == 0:
            bus_ref["bus"].set_fault_rates(drop=0.01, corrupt=0.01)

    def keep(bus):
        bus_ref["bus"] = bus

    src = ScriptedTargets("slow", oracle)
    summary, table, _, _ = _run(constraint, model, src, cycles=1000, on_cycle=on_cycle,
                                before=keep, faults=True)
    assert summary["cycles"] == 1000 and summary["safe_state_entries"] == 0
    faults = summary["faults"]
    assert faults.get("read_timeout", 0) > 0 and faults.get("read_corrupt", 0) > 0
    assert faults.get("read_retry", 0) > 0
    injected = bus_ref["bus"].fault_counts
    assert injected["dropped"] > 0 and injected["corrupted"] > 0
    # each failed attempt is one injected fault (or a genuine timeout of a loaded machine)
    bits = table["faults"]
    assert ((bits & Fault.READ_CORRUPT) > 0).sum() <= injected["corrupted"]
    assert (_distance(oracle, _col(table, "commanded")) <= TOL).all()


def test_unplugged_adapter_reaches_the_safe_state_within_two_cycles(models):
    constraint, model = models["cone50"]
    oracle = ConstraintOracle(constraint)
    bus_ref = {}

    def on_cycle(loop, k):
        if k == 100:
            bus_ref["bus"].unplug(adapter=True)

    summary, table, _, _ = _run(constraint, model, ScriptedTargets("slow", oracle),
                                cycles=200, on_cycle=on_cycle, faults=True,
                                before=lambda b: bus_ref.setdefault("bus", b))
    assert summary["safe_state_entries"] == 1
    assert 100 <= summary["safe_state_cycle"] <= 102
    assert "adapter" in summary["safe_state_reason"]
    assert table["safe_state"][-1] == 1 and table["cycle"][-1] == summary["safe_state_cycle"]
    assert table["faults"][-1] & Fault.CONNECTION_LOST
    assert summary["end_reason"].startswith("safe state")
    # nothing could be written: the note says the servos' Bus Watchdog takes over
    assert "Bus Watchdog" in summary["safe_state_note"]


@pytest.mark.parametrize("safe_state", ["hold", "torque-off"])
def test_hardware_error_on_one_servo_puts_the_limb_in_the_safe_state(models, safe_state):
    constraint, model = models["cone50"]
    oracle = ConstraintOracle(constraint)
    bus_ref = {}

    def on_cycle(loop, k):
        if k == 80:
            bus_ref["bus"].raise_hardware_error(2, "overload")

    summary, table, state, _ = _run(constraint, model, ScriptedTargets("sweep", oracle),
                                    cycles=200, on_cycle=on_cycle, safe_state=safe_state,
                                    before=lambda b: bus_ref.setdefault("bus", b))
    assert summary["safe_state_entries"] == 1
    assert 80 <= summary["safe_state_cycle"] <= 82
    assert "overload" in summary["safe_state_reason"] and "ID 2" in summary["safe_state_reason"]
    assert table["faults"][-1] & Fault.HARDWARE_ALERT
    assert state[2][0] is False or state[2][0] == 0  # overload is in Shutdown: torque off
    if safe_state == "hold":
        for i in (1, 3):  # the others hold where they are, torque on
            torque, goal, pos = state[i]
            assert torque and abs(goal - pos) <= 3
    else:
        assert not any(state[i][0] for i in SERVOS.ids)


def test_stale_servo_data_trips_the_watchdog(models):
    constraint, model = models["cone50"]
    oracle = ConstraintOracle(constraint)
    bus_ref = {}

    def on_cycle(loop, k):
        if k == 50:
            bus_ref["bus"].unplug()  # the bus cable: nobody answers, the port stays open

    summary, table, _, _ = _run(constraint, model, ScriptedTargets("slow", oracle),
                                cycles=200, on_cycle=on_cycle, stale_present_s=0.03,
                                faults=True, before=lambda b: bus_ref.setdefault("bus", b))
    assert summary["safe_state_entries"] == 1
    assert "stale" in summary["safe_state_reason"]
    # 30 ms at 5 ms per cycle: the 7th cycle without fresh data
    assert 50 + 5 <= summary["safe_state_cycle"] <= 50 + 6
    failed = (table["faults"] & Fault.READ_FAILED) > 0
    assert failed[50:].all() and not failed[:50].any()


def test_a_loop_stalled_past_the_bus_watchdog_enters_the_safe_state(models):
    """A host that stalls the loop longer than the servos' Bus Watchdog: they stopped and refuse
    goals, so the loop must not go on as if it commanded them — safe state, named."""
    constraint, model = models["cone50"]
    oracle = ConstraintOracle(constraint)

    def on_cycle(loop, k):
        if k == 60:
            loop.clock.advance(0.25)  # the whole host frozen for 250 ms (watchdog 100 ms)

    summary, table, _, _ = _run(constraint, model, ScriptedTargets("slow", oracle),
                                cycles=200, on_cycle=on_cycle, watchdog_ms=100)
    assert summary["safe_state_entries"] == 1 and summary["safe_state_cycle"] == 60
    assert "Bus Watchdog" in summary["safe_state_reason"]
    gap = (table["faults"] & Fault.WATCHDOG_GAP) > 0
    assert gap[60] and not gap[:60].any()


def test_a_slow_start_does_not_leave_the_servos_stopped_by_their_watchdog(models):
    """Between setup (torque on, watchdog armed) and the first cycle the host may take longer
    than the watchdog (a first run loading compiled kernels): the loop arms it again before its
    first cycle, so the servos follow the goals sent."""
    constraint, model = models["cone50"]
    oracle = ConstraintOracle(constraint)
    with open_port(URL + "&clock=manual&wire_time=off", baud=SERVOS.baud) as port:
        bus = port.simulator
        clk = bus.clock
        limb = prepare_servo_limb(port, SERVOS, oracle)
        limb.bus.set_latency(LOADED_HOST_MS)
        try:
            cfg = LoopConfig(rate_hz=200.0, watchdog_ms=100)
            loop = EnforcementLoop(limb, model, oracle, ScriptedTargets("adversarial", oracle), cfg,
                                   clock=clk, sleep=clk.sleep)
            loop.setup()
            clk.advance(0.5)  # nothing on the bus for 500 ms: every servo's watchdog fires
            assert all(bus.watchdog_tripped(i) for i in SERVOS.ids)
            summary = loop.run(max_cycles=400)
            assert not any(bus.watchdog_tripped(i) for i in SERVOS.ids)
        finally:
            limb.close()
    table = loop.telemetry.table()
    assert summary["safe_state_entries"] == 0
    # the limb follows its goals: each cycle's present is the last cycle's command
    present, commanded = _col(table, "present"), _col(table, "commanded")
    # rotation angles between orientations (either sign); Q.angle_between is for 3-vectors: on
    # quaternions it read one fresh CI run's present posture as 90° off the last goal
    spread = np.degrees(Q.angle(Q.multiply(Q.conjugate(commanded[:1]), commanded))).max()
    lag = np.degrees(Q.angle(Q.multiply(Q.conjugate(present[1:]), commanded[:-1])))
    assert spread > 5.0 and lag.max() < 3.0


def test_stop_request_leaves_the_limb_held(models):
    constraint, model = models["cone50"]
    oracle = ConstraintOracle(constraint)

    def on_cycle(loop, k):
        if k == 120:
            loop.request_stop("SIGTERM")

    summary, _, state, loop = _run(constraint, model, ScriptedTargets("sweep", oracle),
                                   cycles=200, on_cycle=on_cycle)
    assert summary["safe_state_cycle"] == 120 and loop.stop_reason == "SIGTERM"
    assert "SIGTERM" in summary["safe_state_reason"]
    for torque, goal, pos in state.values():
        assert torque and abs(goal - pos) <= 3


def test_bus_watchdog_is_armed_and_backstop_written(models):
    constraint, model = models["original+twist"]
    oracle = ConstraintOracle(constraint)
    clk = ManualClock()
    with open_port(URL, baud=SERVOS.baud) as port:
        bus = port.simulator
        limb = prepare_servo_limb(port, SERVOS, oracle)
        try:
            loop = EnforcementLoop(limb, model, oracle, ScriptedTargets("hold", oracle),
                                   LoopConfig(), clock=clk, sleep=clk.sleep)
            loop.setup()
            lo, hi = limb.backstop
            for k, i in enumerate(SERVOS.ids):
                s = bus.servo(i)
                assert s.get("Bus Watchdog") == 5  # the rig's 100 ms in 20 ms units
                assert s.get("Min Position Limit") == lo[k]
                assert s.get("Max Position Limit") == hi[k]
                assert SERVOS.axes[k].min_ticks <= lo[k] < hi[k] <= SERVOS.axes[k].max_ticks
            # the box holds every valid orientation's IK solution (sampled)
            q = Q.random_quaternions(3000, np.random.default_rng(0))
            valid = q[oracle.is_valid(q)]
            ticks = np.array([limb.kinematics.joint(0).inverse_float(v, loop._present_ticks)
                              for v in valid[:300]])
            assert (ticks >= lo - 1).all() and (ticks <= hi + 1).all()
            summary = loop.run(max_cycles=20)
        finally:
            limb.close()
    assert summary["watchdog_ms"] == 100 and summary["cycles"] == 20
    assert summary["backstop_ticks"]["1"] == [int(lo[0]), int(hi[0])]


_NO_COMPILE_SCRIPT = """
import dataclasses, json
from models import geometry
from models.kinds import ball as O
from models.oracle import ConstraintOracle
from models.shapes import load_shape
from models.constraint import JointConstraint
from rig.devices import kinematics as K
from rig.devices.config import load_rig_config
from rig.devices.ports import open_port
from rig.loop import EnforcementLoop, LoopConfig
from rig.loop.runner import prepare_servo_limb
from rig.loop.targets import CsvTrajectory

KERNELS = [(O, "_ball_kernel"), (geometry, "nearest_in_cell"), (geometry, "rank_one"),
           (K, "_forward_kernel"), (K, "_ik_kernel"), (K, "_solutions_kernel"),
           (K, "_placed_kernel"), (K, "_residual_kernel")]
def counts():
    return {name: len(getattr(mod, name).signatures) for mod, name in KERNELS}
orig = load_shape("original")
c = JointConstraint.polygon(orig.swing.vertices, orig.swing.interior, twist=(-45, 70),
                            name="original+twist")
oracle = ConstraintOracle(c)
servos = dataclasses.replace(load_rig_config("sim-shoulder").servos,
                             port="%s&clock=manual&wire_time=off")
targets = CsvTrajectory(%r)  # read from a file: nothing queries the oracle before the loop
with open_port(servos.port, baud=servos.baud) as port:
    clk = port.simulator.clock
    limb = prepare_servo_limb(port, servos)  # no backstop: nothing asks the oracle before the loop
    try:
        loop = EnforcementLoop(limb, None, oracle, targets,
                               LoopConfig(rate_hz=200.0, watchdog_ms=1000), clock=clk,
                               sleep=clk.sleep)
        before = counts()
        loop.setup()
        summary = loop.run(max_cycles=600)
        after = counts()
    finally:
        limb.close()
print(json.dumps([before, after, dict(summary["interventions_by_kind"])]))
"""


def test_no_kernel_compiles_inside_a_running_loop(tmp_path):
    """The compiled kernels a cycle calls (the oracle's query, a polygon's nearest edge, IK,
    FK, an unreachable goal's message) are all built when the loop is, so a machine's first
    run pays for compiling before its first deadline, never inside a cycle. In a fresh
    interpreter (no kernel loaded yet), their compiled signatures after 600 adversarial
    cycles — projections, rate limits, unreachable goals — are those they had before the
    first. The targets come from a file, so that only the loop itself could have built them."""
    import json
    import subprocess
    import sys
    from pathlib import Path

    orig = load_shape("original")
    oracle = ConstraintOracle(JointConstraint.polygon(orig.swing.vertices, orig.swing.interior,
                                                      twist=(-45, 70)))
    src = ScriptedTargets("adversarial", oracle, seed=3)
    src.start(0.0)
    rows = [(k * 0.005, *src.latest(k * 0.005)[1][0].tolist()) for k in range(1, 601)]
    rows = [r for r in rows if np.isfinite(r).all() and abs(np.linalg.norm(r[1:]) - 1) < 1e-6]
    path = tmp_path / "targets.csv"
    path.write_text("t_s,w,x,y,z\n" + "".join(",".join(f"{v!r}" for v in r) + "\n"
                                            for r in rows))
    root = Path(__file__).resolve().parents[2]
    out = subprocess.run([sys.executable, "-c", _NO_COMPILE_SCRIPT % (URL, str(path))], cwd=root,
                         capture_output=True, text=True, timeout=110)
    assert out.returncode == 0, out.stderr
    before, after, kinds = json.loads(out.stdout.strip().splitlines()[-1])
    assert after == before
    # every kernel the cycle reaches was built (a polygon's ranking inside its cell lookup)
    assert all(n >= 1 for name, n in before.items() if name != "rank_one"), before
    assert kinds.get("projected", 0) + kinds.get("reprojected", 0) > 0, kinds


def test_hold_keeps_a_servo_standing_past_its_limit_at_that_limit(models):
    """A servo can read a tick or two past its position limit (its noise, a push): the hold
    written on a fault must be a goal the bus accepts — the present position brought within
    the same limits the backstop wrote — not a refused write that leaves the limb to the
    watchdog (issue 37: "goal outside tick limits (got 2259, expected 1024..2258)")."""
    constraint, model = models["cone50"]
    oracle = ConstraintOracle(constraint)
    with open_port(URL + "&clock=manual&wire_time=off", baud=SERVOS.baud) as port:
        bus = port.simulator
        clk = bus.clock
        bus.set_hand(SERVOS.ids[1], 2300.0)  # the limb starts raised (torque off)
        clk.advance(0.01)
        limb = prepare_servo_limb(port, SERVOS, oracle)
        limits = {}

        def on_cycle(loop, k):
            if k == 3:  # the limits now end 3 ticks short of where servo 2 stands; then a stop
                present = np.asarray(limb.read_ticks(), dtype=np.int64)
                lo, hi = limb.kinematics.min_ticks.copy(), limb.kinematics.max_ticks.copy()
                assert present[1] > 2250
                hi[1] = present[1] - 3
                limb.set_position_limits(lo, hi)
                loop.kin = limb.kinematics.joint(0)
                limits["hi"] = int(hi[1])
                loop.request_stop("SIGTERM")

        try:
            loop = EnforcementLoop(limb, model, oracle, ScriptedTargets("hold", oracle),
                                   LoopConfig(watchdog_ms=1000), clock=clk, sleep=clk.sleep,
                                   on_cycle=on_cycle)
            loop.setup()
            summary = loop.run(max_cycles=20)
            limb.read_ticks()  # a round trip: the simulator has handled the hold's write
            goal = bus.servo(SERVOS.ids[1]).get("Goal Position")
        finally:
            limb.close()
    assert summary["safe_state_cycle"] == 3
    assert loop.safe_state_note is None  # the hold was written, not left to the watchdog
    assert goal == limits["hi"]
