"""The safety supervisor (pure): projection, holds, rate limits, the monotone recovery rule."""

from __future__ import annotations

import math

import numpy as np
import pytest

from models import qscalar as qs
from models import quaternion as Q
from models.constraint import JointConstraint
from models.oracle import ConstraintOracle
from models.shapes import load_shape
from rig.loop.supervisor import Intervention, Supervisor, SupervisorConfig
from rig.loop.targets import ScriptedTargets

DT = 0.005


def _oracles():
    cone = JointConstraint.cone((1, 0, 0), 40.0, twist=(-30, 50), name="cone40")
    notch = load_shape("original")
    notch_tw = JointConstraint.polygon(notch.swing.vertices, notch.swing.interior,
                                       twist=(-45, 70), name="original+twist")
    twist_only = JointConstraint(name="twist-only", swing=None,
                                 twist=JointConstraint.cone(twist=(-20, 20)).twist)
    return {c.name: ConstraintOracle(c) for c in (cone, notch_tw, twist_only)}


ORACLES = _oracles()


def _tup(q):
    return tuple(float(v) for v in q)


def _start(oracle, q0=None, **cfg):
    sup = Supervisor(oracle, SupervisorConfig(**cfg), period_s=DT)
    if q0 is None:
        src = ScriptedTargets("hold", oracle)
        q0 = src.latest(0.0)[1][0]  # one joint's posture (1, 4): its orientation
    sup.reset(0.0, q0)
    return sup


def _cycle(sup, t, target, target_t=None, correction=None):
    tq = sup.admit(t, target, t if target_t is None else target_t)
    goal = sup.step(t, tq, correction)
    assert sup.accept(goal)
    return goal


# --------------------------------------------------------------------------- target handling
@pytest.mark.parametrize("bad", [
    (math.nan, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 0.0), (math.inf, 0.0, 0.0, 0.0),
    (2.0, 0.0, 0.0, 0.0), (0.5, 0.5, 0.5, 0.4), (1.0, math.nan, 0.0, 0.0),
])
def test_invalid_targets_hold_the_last_safe_goal(bad):
    oracle = ORACLES["cone40"]
    sup = _start(oracle)
    g_prev = sup.goal
    goal = _cycle(sup, DT, bad)
    assert goal == g_prev
    assert sup.flags & Intervention.HOLD_INVALID
    assert sup.velocity == (0.0, 0.0, 0.0)


def test_stale_and_missing_targets_hold():
    oracle = ORACLES["cone40"]
    sup = _start(oracle)
    valid = _tup(Q.from_axis_angle(np.array([0, 0, 1.0]), 0.3))
    g0 = sup.goal
    assert _cycle(sup, 1.0, valid, target_t=1.0 - 0.5) == g0
    assert sup.flags & Intervention.HOLD_STALE
    assert sup.step(1.005, sup.admit(1.005, None, None)) == g0
    assert sup.flags & Intervention.HOLD_STALE
    # fresh again: it moves
    assert _cycle(sup, 1.01, valid) != g0
    assert not sup.flags & (Intervention.HOLD_STALE | Intervention.HOLD_INVALID)


def test_invalid_model_output_falls_back_to_the_target():
    oracle = ORACLES["cone40"]
    sup = _start(oracle, qs.IDENTITY, max_velocity_deg_s=1e4, max_accel_deg_s2=1e7)
    target = _tup(Q.from_axis_angle(np.array([0, 0, 1.0]), 0.001))
    goal = _cycle(sup, DT, target, correction=(math.nan, 0, 0, 0))
    assert sup.flags & Intervention.MODEL_INVALID
    assert qs.angle_between(goal, target) < 1e-9


def test_model_correction_is_applied_on_the_left():
    oracle = ORACLES["cone40"]
    sup = _start(oracle, qs.IDENTITY, max_velocity_deg_s=1e4, max_accel_deg_s2=1e7)
    target = _tup(Q.from_axis_angle(np.array([0, 0, 1.0]), 0.1))
    corr = _tup(Q.from_axis_angle(np.array([0, 1.0, 0]), 0.05))
    goal = _cycle(sup, DT, target, correction=corr)
    want = Q.multiply(corr, target)
    assert qs.angle_between(goal, _tup(want)) < 1e-9
    assert math.degrees(sup.last_correction_angle) == pytest.approx(math.degrees(0.05))


# --------------------------------------------------------------------------- the boundary
@pytest.mark.parametrize("name", sorted(ORACLES))
def test_far_outside_targets_are_projected_never_sent(name):
    oracle = ORACLES[name]
    sup = _start(oracle)
    rng = np.random.default_rng(1)
    q = Q.random_quaternions(3000, rng)
    far = q[oracle.signed_distance(q) > math.radians(20)]
    assert len(far) > 100
    tol = math.radians(sup.config.tolerance_deg)
    projected = 0
    t = 0.0
    for target in far[:400]:
        for _ in range(3):
            t += DT
            goal = _cycle(sup, t, _tup(target))
            assert oracle.signed_distance(np.array(goal)) <= tol
            projected += bool(sup.flags & Intervention.PROJECTED)
    assert projected == 1200  # every one of them


def test_valid_target_is_reached_exactly():
    oracle = ORACLES["original+twist"]
    sup = _start(oracle)
    rng = np.random.default_rng(2)
    q = Q.random_quaternions(2000, rng)
    valid = q[oracle.signed_distance(q) < -math.radians(3)]
    t = 0.0
    for target in valid[:5]:
        for _ in range(400):  # 2 s: enough for any 180° move at 120°/s
            t += DT
            goal = _cycle(sup, t, _tup(target))
        assert qs.angle_between(goal, _tup(target)) < 1e-9
        assert not sup.flags & Intervention.RATE_LIMITED


@pytest.mark.parametrize("name", sorted(ORACLES))
def test_rate_limits_on_goals(name):
    oracle = ORACLES[name]
    cfg = SupervisorConfig()
    sup = _start(oracle)
    rng = np.random.default_rng(3)
    q = Q.random_quaternions(200, rng)
    vmax, amax = math.radians(cfg.max_velocity_deg_s), math.radians(cfg.max_accel_deg_s2)
    prev_goal, prev_v = sup.goal, (0.0, 0.0, 0.0)
    t = 0.0
    checked = 0
    for i in range(2000):
        t += DT
        goal = _cycle(sup, t, _tup(q[i // 10]))
        step = qs.log_vec(qs.relative(prev_goal, goal))
        v = tuple(s / DT for s in step)
        if not sup.flags & Intervention.REPROJECTED:
            assert math.dist(v, (0, 0, 0)) <= vmax * (1 + 1e-9)
            assert math.dist(v, prev_v) <= amax * DT * (1 + 1e-6) + 1e-9
            checked += 1
        prev_goal, prev_v = goal, sup.velocity
    assert checked > 1500


def test_concave_notch_crossing_stays_inside():
    """Jump between the two lips of the notch of 'original': the straight path crosses it."""
    oracle = ORACLES["original+twist"]
    sup = _start(oracle)
    v = oracle.constraint.swing.vertices
    # vertices either side of the deepest notch point (index of the min |x| on the -Y side)
    lips = [_tup(Q.from_two_vectors(Q.LIMB_AXIS, v[i])) for i in (16, 22)]
    tol = math.radians(sup.config.tolerance_deg)
    reproj = 0
    t = 0.0
    for k in range(600):
        t += DT
        goal = _cycle(sup, t, lips[(k // 100) % 2])
        assert oracle.signed_distance(np.array(goal)) <= tol
        reproj += bool(sup.flags & Intervention.REPROJECTED)
    assert reproj > 0  # the straight path did leave the region and was pulled back


# --------------------------------------------------------------------------- recovery
@pytest.mark.parametrize("name", sorted(ORACLES))
def test_limb_starting_outside_is_brought_back_monotonically(name):
    oracle = ORACLES[name]
    rng = np.random.default_rng(4)
    q = Q.random_quaternions(2000, rng)
    d = oracle.signed_distance(q)
    starts = q[(d > math.radians(25)) & (d < math.radians(60))][:4]
    assert len(starts)
    cfg = SupervisorConfig()
    for q0 in starts:
        sup = _start(oracle, _tup(q0))
        d_start = sup.goal_distance
        last = sup.ceiling
        t = 0.0
        # adversarial targets all along: far outside in the other direction
        for k in range(1000):
            t += DT
            target = _tup(q[(k * 7) % len(q)])
            goal = _cycle(sup, t, target)
            dg = float(oracle.signed_distance(np.array(goal)))
            assert dg <= max(math.radians(cfg.tolerance_deg), last) + 1e-12
            assert sup.ceiling <= last + 1e-15  # never rises
            last = sup.ceiling
            if not sup.recovering:
                break
        else:
            pytest.fail("never got back inside")
        # at most the time a 120°/s move with a 1200°/s² ramp takes, plus slack
        assert k * DT < (math.degrees(d_start) / cfg.max_velocity_deg_s + 0.2) * 1.5


def test_recovery_while_targets_are_nan_holds_outside_without_growing():
    oracle = ORACLES["cone40"]
    q0 = _tup(Q.from_two_vectors(Q.LIMB_AXIS, np.array([0.0, 1.0, 0.0])))  # 90° out: 50° over
    sup = _start(oracle, q0)
    c0, g0 = sup.ceiling, sup.goal
    assert qs.angle_between(g0, q0) < 1e-12
    for k in range(50):
        goal = _cycle(sup, (k + 1) * DT, (math.nan,) * 4)
        assert goal == g0 and sup.ceiling == c0


def test_guard_refuses_a_command_beyond_the_ceiling():
    oracle = ORACLES["cone40"]
    sup = _start(oracle)
    outside = _tup(Q.from_two_vectors(Q.LIMB_AXIS, np.array([0.0, 1.0, 0.0])))
    assert not sup.accept(outside)
    assert sup.flags & Intervention.GUARD_HOLD
    slightly = _tup(Q.from_two_vectors(Q.LIMB_AXIS, np.array(
        [math.cos(math.radians(40.5)), math.sin(math.radians(40.5)), 0.0])))
    assert sup.accept(slightly)  # 0.5° outside: within tolerance


def test_config_is_validated():
    with pytest.raises(ValueError, match="quantum_deg"):
        SupervisorConfig(tolerance_deg=1.0, quantum_deg=1.0)
    with pytest.raises(ValueError, match="max_velocity_deg_s"):
        SupervisorConfig(max_velocity_deg_s=0)


def test_present_watchdog():
    sup = _start(ORACLES["cone40"])
    assert not sup.present_stale(1.0, 0.99)
    assert sup.present_stale(1.0, 0.85)
    assert sup.present_stale(1.0, None)


def test_adversarial_script_never_commands_beyond_tolerance():
    for name, oracle in ORACLES.items():
        src = ScriptedTargets("adversarial", oracle, seed=5, segment_s=0.05)
        src.start(0.0)
        sup = _start(oracle)
        tol = math.radians(sup.config.tolerance_deg)
        kinds = set()
        for k in range(1, 1200):
            t = k * DT
            tt, posture = src.latest(t)
            target = posture[0]
            kinds.add(src.segment(t))
            goal = _cycle(sup, t, target, target_t=tt)
            assert oracle.signed_distance(np.array(goal)) <= tol, (name, k, src.segment(t))
        assert {"far", "twist", "invalid", "stale", "valid_jump"} <= kinds
