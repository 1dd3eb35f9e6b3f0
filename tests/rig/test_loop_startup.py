"""A follower that never jumps (issue 41 item 3): start-up from the present posture at the
velocity limits (or refused), resume after a stale-target hold by a ramp, a hand-over between
target sources without a step, and the slide to the rest pose at the end — on the simulated
7-servo arm's kinematics (sim-servo-arm: shoulder 3, elbow 2, wrist 2) on a manual-clock bus,
the real ``dynamixel_sdk`` on a pty. The goal ticks are observed as they are written."""

from __future__ import annotations

import math

import numpy as np
import pytest

from models.limb_model import export_limb_model
from models.oracle import ConstraintOracle
from rig.devices.config import load_rig_config
from rig.devices.dynamixel import DynamixelBus
from rig.devices.ports import open_port
from rig.devices.servo_limb import ServoLimb
from rig.errors import RigConfigError
from rig.loop import EnforcementLoop, Intervention, LoopConfig, SupervisorConfig
from rig.loop.runner import whole_ticks_within
from rig.loop.targets import ScriptedTargets, TargetSource
from rig.sim.patients import anatomical_limb
from tests.rig.rigs import LOADED_HOST_MS

URL = "sim://dynamixel?ids=1-7&model=XM430-W350&return_delay_us=0&clock=manual&wire_time=off"
PERIOD = 0.005
VMAX = 120.0  # the default joint velocity limit, °/s
TICK_DEG = 360.0 / 4096


@pytest.fixture(scope="module")
def arm():
    """The servo arm's patient, its kinematics, a valid start posture's ticks and a valid
    target 90° away in two joints (the shoulder's plane servo and the elbow's flexion servo
    each turned a quarter turn)."""
    limb = anatomical_limb(3, "arm", kinds={"elbow": "forearm"})
    oracle = ConstraintOracle(limb).prepare()
    kin = load_rig_config("sim-servo-arm").servos.limb_kinematics()
    hold = ScriptedTargets("hold", oracle, kinematics=kin)
    hold.start(0.0)
    start = kin.inverse(hold.latest(0.0)[1], kin.zero_ticks)
    far = start.copy()
    far[0] += 1024
    far[3] += 1024
    assert oracle.is_valid(kin.forward(far)[None]).all()
    return limb, oracle, kin, start, far


class Posture(TargetSource):
    """``fn(k)`` per cycle: a posture, or ``(age_s, posture)``."""

    n_joints = 3

    def __init__(self, fn):
        self.fn = fn

    def latest(self, t):
        out = self.fn(round((t - self.t0) / PERIOD))
        age = 0.0
        if isinstance(out, tuple):
            age, out = out
        return t - age, out


def _run(arm, targets, cycles, *, on_cycle=None, **cfg):
    _limb, oracle, kin, start, _far = arm
    logs: list[str] = []
    sent: list[np.ndarray] = []
    with open_port(URL, baud=1_000_000) as port:
        sim = port.simulator
        clk = sim.clock
        for i, t in zip(kin.ids, start, strict=True):
            sim.set_hand(i, float(t))
        clk.advance(0.01)
        sl = ServoLimb(DynamixelBus(port, list(kin.ids)), kin)
        sl.bus.set_latency(LOADED_HOST_MS)
        write = sl.bus.write_goal_ticks

        def observed(ticks):
            sent.append(np.array(ticks, dtype=np.int64))
            return write(ticks)

        sl.bus.write_goal_ticks = observed
        try:
            sl.set_position_limits(kin.min_ticks, kin.max_ticks)
            sl.bus.configure()
            loop = EnforcementLoop(sl, None, oracle, targets,
                                   LoopConfig(rate_hz=1 / PERIOD, watchdog_ms=1000, **cfg),
                                   clock=clk, sleep=clk.sleep, on_cycle=on_cycle,
                                   log=logs.append)
            loop.setup()
            error = None
            try:
                loop.run(max_cycles=cycles)
            except RigConfigError as err:
                error = err
            present = np.array([sim.servo(i).pos for i in kin.ids])
        finally:
            sl.close()
    return loop, np.array(sent), logs, error, present


def _steps(kin, start, sent):
    """Per cycle: each servo's tick step, each joint's angle step (degrees)."""
    ticks = np.vstack([start, sent])
    q = np.array([kin.forward(t) for t in ticks])
    dot = np.abs(np.einsum("kjc,kjc->kj", q[1:], q[:-1]))
    return np.abs(np.diff(ticks, axis=0)), np.degrees(2 * np.arccos(np.clip(dot, 0, 1)))


def _check_ramped(arm, sent, vmax=VMAX):
    """No step beyond the velocity limit × period — the rounded goal ticks' too, not only the
    supervisor's unrounded goal — and no goal outside the servos' limits or the patient's
    (beyond tolerance)."""
    _limb, oracle, kin, start, _far = arm
    ticks, angles = _steps(kin, start, sent)
    limit_ticks = vmax * PERIOD / TICK_DEG
    assert ticks.max() <= math.floor(limit_ticks), ticks.max(axis=0)
    assert angles.max() <= vmax * PERIOD + 1e-9, angles.max(axis=0)
    assert ((sent >= kin.min_ticks) & (sent <= kin.max_ticks)).all()
    d = np.degrees(oracle.signed_distance(np.array([kin.forward(t) for t in sent])))
    assert d.max() <= 1.0
    return ticks, angles


def test_start_90_degrees_away_in_two_joints_ramps_at_the_velocity_limit(arm):
    _limb, _oracle, kin, start, far = arm
    target = kin.forward(far)
    loop, sent, logs, error, _ = _run(arm, Posture(lambda k: target), 220)
    assert error is None and loop.safe_state_entries == 0
    ticks, angles = _check_ramped(arm, sent)
    # the first goal is where the limb is; the shoulder and elbow ramp, the wrist never moves
    assert (sent[0] == start).all()
    assert ticks[:, [1, 2, 4, 5, 6]].max() == 0
    # at the limit, not slower: the largest whole number of ticks within 120°/s × 5 ms (6.83)
    fastest = math.floor(VMAX * PERIOD / TICK_DEG) * TICK_DEG
    assert angles[:, 0].max() >= fastest - 1e-9 and angles[:, 1].max() >= fastest - 1e-9
    assert (sent[-1] == far).all()  # reached: 90° at 6 ticks a cycle (120°/s, 1200°/s²) in 0.9 s
    assert loop.start_mismatch == pytest.approx({"shoulder": 90.0, "elbow": 90.0,
                                                 "wrist": 0.0}, abs=0.2)
    assert any("ramping" in m and "shoulder 90.0°, elbow 90.0°" in m for m in logs), logs


def test_a_per_servo_velocity_limit_caps_every_servos_step(arm):
    _limb, _oracle, kin, _start, far = arm
    target = kin.forward(far)
    _loop, sent, _, error, _ = _run(arm, Posture(lambda k: target), 80,
                                    servo_max_velocity_deg_s=45.0)
    assert error is None
    ticks, _ = _check_ramped(arm, sent)
    assert ticks.max() == int(math.radians(45.0) * PERIOD / (2 * math.pi / 4096))


def test_whole_ticks_within_the_step_stay_within_the_servos_limits():
    """Steps held within the velocity limit at whole ticks, near the servos' tick limits (an
    IK angle less than half a tick beyond a limit is the limit: its ceiling would be a tick
    outside — a goal the bus refuses, which ended a 60 s leader run in the safe state): every
    candidate within the limits and within the step (seeded, 400 cases on each joint)."""
    kin = load_rig_config("sim-servo-arm").servos.limb_kinematics()
    rng = np.random.default_rng(41)
    for kj in kin.joints:
        lo, hi = kj.min_ticks, kj.max_ticks
        for _ in range(400):
            edge = np.where(rng.random(len(lo)) < 0.5, lo, hi)
            near = np.clip(edge + rng.integers(-8, 9, len(lo)), lo, hi)
            want = np.clip(near + rng.normal(0, 6, len(lo)), lo - 0.45, hi + 0.45)
            goal, prev = kj.forward_one(want), kj.forward_one(near)
            step = 2 * math.acos(min(1.0, abs(float(np.dot(goal, prev)))))
            cap = step * rng.uniform(0.5, 0.99)
            ticks, q = whole_ticks_within(kj, goal, near, prev, cap)
            assert ((ticks >= lo) & (ticks <= hi)).all(), (near, want, ticks)
            got = 2 * math.acos(min(1.0, abs(float(np.dot(q, prev)))))
            assert got <= cap + 1e-12
            np.testing.assert_allclose(q, kj.forward_one(ticks))


def test_refused_start_moves_nothing(arm):
    _limb, _oracle, kin, start, far = arm
    target = kin.forward(far)
    # the target appears at cycle 5 (a leader read late): the limb holds until then
    _loop, sent, _logs, error, present = _run(
        arm, Posture(lambda k: target if k >= 5 else (1.0, target)), 50,
        on_start_mismatch="refuse")
    assert isinstance(error, RigConfigError)
    msg = str(error)
    assert "\n" not in msg and "--start-mismatch-deg 20" in msg and "nothing moved" in msg
    assert "shoulder 90.0°" in msg and "elbow 90.0°" in msg and "wrist" not in msg
    assert len(sent) == 5 and (sent == start).all()
    assert np.abs(present - start).max() < 1.0
    # under the threshold, refuse changes nothing
    near = start.copy()
    near[3] += 100  # 8.8°
    _, sent, _, error, _ = _run(arm, Posture(lambda k: kin.forward(near)), 80,
                                on_start_mismatch="refuse")
    assert error is None and (sent[-1] == near).all()


def test_resume_after_a_stale_hold_is_a_ramp(arm):
    _limb, _oracle, kin, start, far = arm
    here, there = kin.forward(start), kin.forward(far)

    def fn(k):
        if k < 20:
            return here
        if k < 40:
            return (0.5, there)  # stale: the goal holds
        return there

    loop, sent, _, error, _ = _run(arm, Posture(fn), 120)
    assert error is None
    _check_ramped(arm, sent)
    assert (sent[20:40] == start).all()  # held
    bits = loop.telemetry.table()["intervention"]
    assert (bits[20:40] & Intervention.HOLD_STALE).all()
    assert (sent[40:] != start).any()
    with pytest.raises(ValueError, match="max_accel_deg_s2"):
        SupervisorConfig(max_accel_deg_s2=0.0)  # a limit of 0 (a step) is not a setting


def test_hand_over_between_sources_has_no_step(arm):
    _limb, _oracle, kin, start, far = arm
    there = kin.forward(far)
    mid = start.copy()
    mid[3] += 512
    # source A sweeps the elbow at 60°/s; at cycle 40 source B (90° away) takes over while
    # the goal moves; at cycle 120 the loop is handed to "hold" in full motion
    sweep = Posture(lambda k: kin.forward(start + np.array([0, 0, 0, min(k, 80) * 3, 0, 0, 0])))
    b = Posture(lambda k: there)

    def on_cycle(loop, k):
        if k == 40:
            loop.set_targets(b)
        elif k == 120:
            loop.set_targets(None)

    loop, sent, _, error, _ = _run(arm, sweep, 220, on_cycle=on_cycle)
    assert error is None and loop.handovers == 2
    _check_ramped(arm, sent)
    # after "hold" the goal brakes (at most v²/2a past where it was) and stops
    assert (sent[-1] == sent[-10]).all()
    at_switch = kin.forward(sent[119])
    end = kin.forward(sent[-1])
    dot = abs(float(np.dot(at_switch[0], end[0])))
    assert math.degrees(2 * math.acos(min(1.0, dot))) <= VMAX ** 2 / (2 * 1200.0) + 0.5
    with pytest.raises(ValueError, match="postures of 1 joint"):
        loop.set_targets(type("One", (TargetSource,), {"n_joints": 1})())


def test_at_end_rest_slides_to_the_rest_pose(arm):
    _limb, _oracle, kin, start, far = arm
    here = kin.forward(start)
    loop, sent, logs, error, _ = _run(arm, Posture(lambda k: here), 20, at_end="rest")
    assert error is None and loop.rest_reached is True
    assert loop.end_reason == "completed (at rest)"
    # the zero pose (valid for this patient; its elbow 1.3° inside the limit, where the
    # supervisor's reprojection stops the goal a few ticks short of it)
    assert np.abs(sent[-1] - kin.zero_ticks).max() <= 8 and loop.rest_error_deg < 1.0
    assert len(sent) > 20 and any("rest pose" in m for m in logs)
    _check_ramped(arm, sent)
    # a rest pose of one's own
    rest = start.copy()
    rest[6] += 200
    loop, sent, _, _, _ = _run(arm, Posture(lambda k: here), 5, at_end="rest",
                               rest_ticks=tuple(rest.tolist()))
    assert loop.rest_reached and (sent[-1] == rest).all()
    # hold (the default) ends at once
    loop, sent, _, _, _ = _run(arm, Posture(lambda k: kin.forward(far)), 20)
    assert len(sent) == 20 and loop.rest_reached is None and loop.end_reason == "completed"


@pytest.mark.parametrize(("kw", "message"), [
    ({"on_start_mismatch": "abort"}, "--on-start-mismatch"),
    ({"at_end": "home"}, "--at-end"),
    ({"start_mismatch_deg": 0.0}, "--start-mismatch-deg"),
])
def test_bad_settings_name_the_option(kw, message):
    with pytest.raises(ValueError, match=message):
        LoopConfig(**kw)


def test_the_cli_refuses_a_start_mismatch_in_one_line(tmp_path, rig_cli):
    limb = anatomical_limb(3, "arm", kinds={"elbow": "forearm"})
    model = export_limb_model(limb, tmp_path / "arm.onnx")
    base = ["enforce", "--rig", "sim-servo-arm", "--model", str(model), "--targets",
            "script:hold", "--stale-servo-ms", "1000", "--watchdog-ms", "1000",
            "--duration", "0.5"]
    code, out, err = rig_cli([*base, "--start-mismatch-deg", "0.01", "--on-start-mismatch",
                              "refuse"])
    assert code == 2, (out, err)
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("rig: error: start-up: "), err
    assert "nothing moved" in lines[0]
    code, out, err = rig_cli([*base, "--at-end", "nowhere"])
    assert code == 2 and "--at-end" in err
