"""The live loop over a limb: a 7-servo arm (shoulder 3, elbow 1, wrist 3) on the simulated bus
(real ``dynamixel_sdk`` on a pty, manual clock), enforcing a held-out arm limb file whose
shoulder is coupled to the elbow, judged by the exact limb oracle on the telemetry's commanded
columns."""

from __future__ import annotations

import math

import numpy as np
import pytest

from models import quaternion as Q
from models.limb_evaluation import held_out_postures, random_limb
from models.limb_model import export_limb_model
from models.onnx_io import load_model
from models.oracle import ConstraintOracle
from rig.devices.config import load_rig_config
from rig.devices.dynamixel import DynamixelBus
from rig.devices.kinematics import JointKinematics, LimbKinematics, ServoAxis
from rig.devices.ports import open_port
from rig.devices.servo_limb import ServoLimb
from rig.errors import UnreachableError
from rig.loop import EnforcementLoop, Intervention, LoopConfig, SupervisorConfig
from rig.loop.backstop import position_limits_from_limb
from rig.loop.limb_supervisor import LimbSupervisor
from rig.loop.targets import ScriptedTargets, TargetSource
from rig.loop.telemetry import telemetry_columns
from rig.sim.patients import anatomical_limb

URL = "sim://dynamixel?ids=1-7&model=XM430-W350&return_delay_us=0&clock=manual&wire_time=off"
NAMES = ("shoulder", "elbow", "wrist")


def _axis(i, axis, lo=0, hi=4095):
    return ServoAxis(id=i, axis=axis, zero_ticks=2048, direction=1, min_ticks=lo, max_ticks=hi)


def _kinematics() -> LimbKinematics:
    z, y, x = (0, 0, 1), (0, 1, 0), (1, 0, 0)
    return LimbKinematics([
        JointKinematics([_axis(1, z), _axis(2, y), _axis(3, x)]),
        JointKinematics([_axis(4, z)]),
        JointKinematics([_axis(5, z), _axis(6, y), _axis(7, x)]),
    ], names=NAMES)


@pytest.fixture(scope="module")
def arm():
    limb = random_limb(20261128, "arm")
    assert limb.joint_names == NAMES and limb.coupled == (0,)
    return limb, ConstraintOracle(limb).prepare()


class PostureTargets(TargetSource):
    """A posture (J, 4) per cycle from ``fn(k)``; ``fn`` may return ``(age_s, posture)``."""

    def __init__(self, fn, n_joints=3, period=0.005):
        self.fn, self.n_joints, self.period = fn, n_joints, period

    def latest(self, t):
        k = round((t - self.t0) / self.period)
        out = self.fn(k)
        age = 0.0
        if isinstance(out, tuple):
            age, out = out
        return t - age, out


def _place(posture):
    """A ``before`` that leaves the (torque-off) arm at ``posture``."""
    kin = _kinematics()
    ticks = kin.inverse(posture, kin.zero_ticks)

    def place(sim):
        for i, t in zip(kin.ids, ticks, strict=True):
            sim.set_hand(i, float(t))
    return place


def _valid(oracle, pool):
    return pool[int(np.flatnonzero(oracle.is_valid(pool).all(axis=1))[0])]


def _run(oracle, targets, cycles, *, before=None, model=None, **cfg):
    loop_cfg = LoopConfig(rate_hz=200.0, watchdog_ms=1000, **cfg)
    with open_port(URL, baud=1_000_000) as port:
        sim = port.simulator
        clk = sim.clock
        if before is not None:
            before(sim)
            clk.advance(0.01)
        kin = _kinematics()
        limb = ServoLimb(DynamixelBus(port, list(kin.ids)), kin)
        try:
            limb.set_position_limits(kin.min_ticks, kin.max_ticks)
            limb.bus.configure()
            loop = EnforcementLoop(limb, model, oracle, targets, loop_cfg, clock=clk,
                                   sleep=clk.sleep)
            loop.setup()
            summary = loop.run(max_cycles=cycles)
        finally:
            limb.close()
    return summary, loop.telemetry.table(), loop


def _posture(table, what):
    return np.stack([np.stack([table[f"{n}_{what}_{c}"] for c in "wxyz"], axis=-1)
                     for n in NAMES], axis=1)


def _commanded_distance_deg(oracle, table):
    return np.degrees(oracle.signed_distance(_posture(table, "commanded")))


def _qangle(a, b):
    return 2.0 * math.acos(min(1.0, abs(float(np.dot(a, b)))))


def _hinge(deg):
    return Q.from_axis_angle(np.array([0.0, 0.0, 1.0]), math.radians(deg))


def test_telemetry_names_one_joint_unchanged_limb_prefixed():
    from rig.loop.telemetry import COLUMNS
    assert telemetry_columns(None) == COLUMNS == telemetry_columns(["shoulder"])
    cols = telemetry_columns(NAMES)
    assert cols[:3] == ("cycle", "t_s", "shoulder_target_w")
    for c in ("elbow_commanded_z", "wrist_present_w", "elbow_violation_deg",
              "elbow_intervention", "cycle_ms", "late_ms", "faults", "safe_state"):
        assert c in cols
    assert len(set(cols)) == len(cols)


def test_joint_query_answers_as_the_limb_oracle(arm):
    limb, oracle = arm
    p = held_out_postures(limb, 60, 3, oracle=oracle)
    r = oracle.evaluate(p)
    for j in range(3):
        query = oracle.joint_query(j)
        src = oracle.joint_source(j)
        for n in range(len(p)):
            a = math.nan if src is None else oracle.coupling_angle_one(src, *r.projected[n, src])
            d, proj = query(*p[n, j], a)
            assert d == pytest.approx(r.distance[n, j], abs=1e-12)
            np.testing.assert_allclose(proj, r.projected[n, j], atol=1e-12)


def test_the_compiled_coupled_query_leaves_the_limb_cycle_unchanged(arm, monkeypatch):
    """The coupled shoulder's compiled single path (and the elbow's scalar coupling angle)
    against its kind's batched evaluation on a batch of one (what the loop used before): 600
    cycles of held-out (valid and invalid) postures through the supervisor, IK, FK and the final
    check give the same goal ticks and flags, the goals equal to 1e-12."""
    from models.kinds.ball import BallKind
    from models.kinds.base import JointKind
    limb, _ = arm
    pool = held_out_postures(limb, 40, np.random.default_rng(9))

    def run():
        oracle = ConstraintOracle(limb).prepare()
        kin = _kinematics()
        sup = LimbSupervisor(oracle, names=NAMES)
        start = pool[oracle.is_valid(pool).all(axis=1)][0]
        sup.reset(0.0, start)
        ticks = kin.inverse(start, kin.zero_ticks)
        commanded = list(map(tuple, start))
        goals, out = [], []
        for k in range(600):
            t = 0.005 * (k + 1)
            goal = sup.step(t, sup.admit(t, pool[(k // 15) % len(pool)], t))
            try:
                gt = kin.inverse(np.array(goal), ticks)
                cand = [tuple(q) for q in kin.forward(gt)]
                if sup.accept(cand):
                    ticks, commanded = gt, cand
                else:
                    sup.revert(commanded)
            except UnreachableError:
                sup.revert(commanded)
            goals.append(np.ravel(goal))
            out.append((*ticks.tolist(), *sup.joint_flags))
        return np.array(goals), out

    fast = run()
    monkeypatch.setattr(BallKind, "coupled_one", lambda self, axis, limits: None)
    monkeypatch.setattr(JointKind, "coupling_angle_one", lambda self, constraint: None)
    slow = run()
    assert fast[1] == slow[1]
    np.testing.assert_allclose(fast[0], slow[0], rtol=0, atol=1e-12)


def test_adversarial_limb_targets_never_commanded_beyond_tolerance(arm):
    limb, oracle = arm
    rng = np.random.default_rng(7)
    pool = held_out_postures(limb, 40, rng, oracle=oracle)  # valid and invalid postures
    at = limb.joints[0].coupling.at_deg
    lo, hi = at[0], at[-1]
    bent, straight = _hinge(hi - 5.0), _hinge(lo + 5.0)
    reach = None
    for p in pool:
        a = np.array([p[0], bent, p[2]])
        b = np.array([p[0], straight, p[2]])
        if oracle.is_valid(a)[0] and not oracle.is_valid(b)[0]:
            reach = p[0]
            break
    nan = np.full((3, 4), np.nan)

    def fn(k):
        seg, i = divmod(k, 30)
        if seg % 7 == 3:  # the elbow straightens under a held shoulder reach
            if reach is None:
                return pool[seg % len(pool)]
            f = min(1.0, i / 20)
            return np.array([reach, _hinge((1 - f) * (hi - 5.0) + f * (lo + 5.0)), pool[0][2]])
        if seg % 7 == 5 and i < 10:
            return nan
        if seg % 7 == 6 and i < 10:
            return (0.5, pool[seg % len(pool)])  # stale
        return pool[seg % len(pool)]

    summary, table, _loop = _run(oracle, PostureTargets(fn), 700,
                                before=_place(_valid(oracle, pool)))
    assert summary["cycles"] == 700 and summary["safe_state_entries"] == 0
    d = _commanded_distance_deg(oracle, table)
    assert d.max() <= 1.0 + 1e-9
    assert summary["max_violation_deg"] <= 1.0
    for n in NAMES:
        assert (table[f"{n}_violation_deg"] <= 1.0).all()
    bits = table["intervention"]
    assert (bits & Intervention.HOLD_INVALID).any() and (bits & Intervention.HOLD_STALE).any()
    assert (table["shoulder_intervention"] & (Intervention.PROJECTED
                                              | Intervention.REPROJECTED)).any()
    # the whole limb's flags are the joints' OR
    ored = table["shoulder_intervention"] | table["elbow_intervention"] \
        | table["wrist_intervention"]
    assert (ored == bits).all()
    j = summary["joints"]
    assert set(j) == set(NAMES) and j["shoulder"]["max_violation_deg"] <= 1.0
    # tracking counts valid targets held still long enough to be reached (settled_rows, tested
    # in test_loop_parts); this script's valid targets are not held that long
    for n in NAMES:
        assert (j[n]["tracking_p50_deg"] is None) == (j[n]["tracked_cycles"] == 0)


def test_elbow_moves_and_the_shoulder_follows(arm):
    limb, oracle = arm
    rng = np.random.default_rng(11)
    pool = held_out_postures(limb, 400, rng, oracle=oracle)
    lo, hi = (limb.joints[0].coupling.at_deg[0], limb.joints[0].coupling.at_deg[-1])
    bent, straight = _hinge(hi), _hinge(lo)
    wrist = _valid(oracle, pool)[2]
    # shoulder reaches on the boundary with the elbow bent, > 3° outside with it straight
    n = len(pool)
    at_bent = oracle.project(np.stack([pool[:, 0], np.tile(bent, (n, 1)),
                                       np.tile(wrist, (n, 1))], axis=1))
    straight_d = oracle.signed_distance(np.stack([at_bent[:, 0], np.tile(straight, (n, 1)),
                                                  np.tile(wrist, (n, 1))], axis=1))[:, 0]
    i = int(np.argmax(straight_d))
    reach = at_bent[i, 0] if straight_d[i] > math.radians(3.0) else None
    assert reach is not None

    def fn(k):
        if k < 200:
            return np.array([reach, bent, wrist])
        f = min(1.0, (k - 200) / 200)
        return np.array([reach, _hinge((1 - f) * hi + f * lo), wrist])

    _summary, table, _ = _run(oracle, PostureTargets(fn), 600,
                             before=_place(np.array([reach, bent, wrist])))
    d = _commanded_distance_deg(oracle, table)
    assert d.max() <= 1.0 + 1e-9
    cmd = _posture(table, "commanded")
    # the elbow reached straight, and the shoulder left the reach that became invalid
    assert _qangle(cmd[-1, 1], straight) < math.radians(1.0)
    assert math.degrees(_qangle(cmd[-1, 0], reach)) > 1.0
    assert (table["shoulder_intervention"][400:] & (Intervention.PROJECTED
                                                    | Intervention.REPROJECTED)).any()


def test_a_shoulder_outside_is_brought_back_while_the_elbow_holds(arm):
    limb, oracle = arm
    kin = _kinematics()
    rng = np.random.default_rng(5)
    pool = held_out_postures(limb, 400, rng, oracle=oracle)
    r = oracle.evaluate(pool)
    far = next(i for i in range(len(pool))
               if r.distance[i, 0] > math.radians(15) and r.valid[i, 1:].all())
    start = pool[far]
    ticks = kin.inverse(start, kin.zero_ticks)

    def place(sim):
        for i, t in zip(kin.ids, ticks, strict=True):
            sim.set_hand(i, float(t))

    target = pool[next(i for i in range(len(pool)) if r.valid[i].all())]
    other_elbow = _hinge(math.degrees(Q.twist_angle(start[1][None],
                                                   np.array([0, 0, 1.0]))[0]) + 40.0)

    def fn(k):
        return np.array([target[0], other_elbow, target[2]])

    _summary, table, _ = _run(oracle, PostureTargets(fn), 500, before=place)
    d = np.degrees(oracle.signed_distance(_posture(table, "commanded"))[:, 0])
    assert d[0] > 10.0
    back = np.flatnonzero(d <= 1.0)
    assert len(back) and back[0] < 400
    assert (np.diff(d[: back[0] + 1]) <= 1e-9).all()  # monotone
    assert (d[back[0]:] <= 1.0 + 1e-9).all()
    held = table["elbow_intervention"][: back[0] - 1]
    assert (held & Intervention.HELD_FOR_COUPLED).all()
    elbow = _posture(table, "commanded")[:, 1]
    assert np.allclose(np.abs(np.einsum("ij,j->i", elbow[: back[0] - 1], elbow[0])), 1.0)


def test_one_joint_limb_supervisor_is_the_one_joint_supervisor():
    from models.constraint import JointConstraint
    from rig.loop.supervisor import Supervisor
    c = JointConstraint.cone((1, 0, 0), 40.0, twist=(-30, 30))
    o = ConstraintOracle(c)
    a, b = Supervisor(o), LimbSupervisor(o)
    rng = np.random.default_rng(2)
    a.reset(0.0, (1.0, 0, 0, 0))
    b.reset(0.0, np.array([[1.0, 0, 0, 0]]))
    for k, q in enumerate(Q.random_quaternions(50, rng)):
        t = 0.005 * (k + 1)
        ga = a.step(t, a.admit(t, q, t))
        tb = b.admit(t, q[None], t)
        gb = b.step(t, tb)
        assert ga == gb[0] and a.flags == b.flags


def test_the_backstop_of_a_limb_contains_every_valid_posture(arm):
    limb, oracle = arm
    kin = _kinematics()
    lo, hi = position_limits_from_limb(kin, oracle, kin.zero_ticks, n=1500)
    assert lo.shape == hi.shape == (7,) and (lo <= kin.zero_ticks).all() \
        and (kin.zero_ticks <= hi).all()
    assert (hi - lo < 4095).any()  # the elbow's hinge at least is a real limit
    pool = held_out_postures(limb, 200, np.random.default_rng(4), oracle=oracle)
    ok = oracle.is_valid(pool).all(axis=1)
    for p in pool[ok]:
        t = kin.inverse(p, kin.zero_ticks)
        assert ((lo <= t) & (t <= hi)).all()


def test_per_servo_velocity_limit_and_per_joint_tolerance(arm):
    limb, oracle = arm
    pool = held_out_postures(limb, 40, np.random.default_rng(9), oracle=oracle)
    start = _valid(oracle, pool)
    far = pool[np.flatnonzero(oracle.is_valid(pool).all(axis=1))[-1]]
    wide = SupervisorConfig(tolerance_deg=2.0, quantum_deg=0.25)
    summary, table, _ = _run(oracle, PostureTargets(lambda k: far), 120, before=_place(start),
                             servo_max_velocity_deg_s=30.0,
                             joint_supervisors={"wrist": wide})
    kin = _kinematics()
    cmd = _posture(table, "commanded")
    ticks = np.array([kin.inverse(c, kin.zero_ticks) for c in cmd])
    step = np.abs(np.diff(ticks, axis=0)).max()
    assert step <= int(math.radians(30.0) * 0.005 / (2 * math.pi / 4096))
    assert (table["intervention"] & Intervention.RATE_LIMITED).any()
    assert summary["joints"]["wrist"]["tolerance_deg"] == 2.0
    assert summary["joints"]["elbow"]["tolerance_deg"] == 1.0
    assert _commanded_distance_deg(oracle, table).max() <= 2.0
    with pytest.raises(ValueError, match="unknown joint"):
        LimbSupervisor(oracle, joint_configs={"knee": wide}, names=NAMES)


def test_the_limb_model_in_the_loop(arm, tmp_path):
    limb, oracle = arm
    model = load_model(export_limb_model(limb, tmp_path / "arm.onnx"), limb)
    pool = held_out_postures(limb, 30, np.random.default_rng(21), oracle=oracle)
    summary, table, _loop = _run(oracle, PostureTargets(lambda k: pool[(k // 20) % len(pool)]),
                                200, before=_place(_valid(oracle, pool)), model=model)
    assert summary["safe_state_entries"] == 0
    assert _commanded_distance_deg(oracle, table).max() <= 1.0 + 1e-9
    corr = _posture(table, "correction")
    assert np.isfinite(corr).all()
    # the exact graph's corrections: the corrected targets are valid (to float32 rounding)
    fixed = Q.multiply(corr.reshape(-1, 4), _posture(table, "target").reshape(-1, 4))
    fixed /= np.linalg.norm(fixed, axis=1, keepdims=True)
    d = oracle.signed_distance(fixed.reshape(-1, 3, 4))
    assert np.degrees(d).max() < 0.05
    assert not (table["intervention"] & Intervention.MODEL_INVALID).any()
    assert table["shoulder_correction_deg"].max() > 1.0


def test_a_target_two_servos_cannot_reach_becomes_the_nearest_they_reach():
    """The servo arm (sim-servo-arm's joints: a forearm elbow and a wrist of two servos each):
    a valid posture whose wrist is twisted 4° about its long axis — which its flexion and
    deviation servos cannot turn — is driven to the nearest orientation they reach, never
    flagged unreachable; every commanded posture stays within tolerance."""
    limb = anatomical_limb(3, "arm", kinds={"elbow": "forearm"})
    oracle = ConstraintOracle(limb).prepare()
    kin = load_rig_config("sim-servo-arm").servos.limb_kinematics()
    hold = ScriptedTargets("hold", oracle, kinematics=kin)
    hold.start(0.0)
    start = hold.latest(0.0)[1]
    target = start.copy()
    target[2] = Q.multiply(start[2], Q.from_axis_angle(np.array([1.0, 0, 0]), math.radians(4)))
    nearest = kin.nearest_batch(target[None])[0]
    assert _qangle(nearest[2], target[2]) > math.radians(0.5)  # off the wrist's surface
    assert oracle.is_valid(nearest[None]).all()
    with pytest.raises(UnreachableError):  # what the exact tolerance said of it
        JointKinematics(kin.joint(2).servos).inverse(target[2], kin.joint(2).zero_ticks)
    with open_port(URL, baud=1_000_000) as port:
        sim = port.simulator
        for i, t in zip(kin.ids, kin.inverse(start, kin.zero_ticks), strict=True):
            sim.set_hand(i, float(t))
        sim.clock.advance(0.01)
        sl = ServoLimb(DynamixelBus(port, list(kin.ids)), kin)
        try:
            sl.bus.configure()
            loop = EnforcementLoop(sl, None, oracle, PostureTargets(lambda k: target),
                                   LoopConfig(rate_hz=200.0, watchdog_ms=1000),
                                   clock=sim.clock, sleep=sim.clock.sleep)
            loop.setup()
            loop.run(max_cycles=200)
        finally:
            sl.close()
    table = loop.telemetry.table()
    for n in NAMES:
        assert not (table[f"{n}_intervention"] & Intervention.UNREACHABLE).any()
    assert _commanded_distance_deg(oracle, table).max() <= 1.0 + 1e-9
    cmd = _posture(table, "commanded")
    assert _qangle(cmd[-1, 2], nearest[2]) < math.radians(0.2)
    assert _qangle(_posture(table, "present")[-1, 2], nearest[2]) < math.radians(0.3)
