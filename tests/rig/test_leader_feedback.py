"""The limit felt at the leader, wired into the loop (issue 41): the commanded posture mapped back
onto the leader's joints (mirrored back too), ``--leader-spring`` checked in one line, the sim
URL's impedance hand, and a manual-clock run where the leader's Goal Current is zero while the
leader is inside the limits and non-zero once it is pushed beyond them."""

from __future__ import annotations

import math

import numpy as np
import pytest
import yaml

from models.oracle import ConstraintOracle
from rig.demo.stages import shipped_config
from rig.devices.config import load_rig_config
from rig.devices.ports import open_port
from rig.errors import RigConfigError
from rig.loop import EnforcementLoop, LoopConfig, SupervisorConfig
from rig.loop.enforce import EnforceRequest
from rig.loop.leader import mirror_posture, open_leader, posture_to_leader
from rig.loop.leader_spring import SpringSettings
from rig.loop.runner import prepare_servo_limb
from rig.sim.patients import anatomical_limb
from rig.sim.urls import with_keys, without_keys
from tests.rig.rigs import LOADED_HOST_MS

MANUAL = {"clock": "manual", "process": "off", "wire_time": "off"}
PATIENT_KEYS = ("limb", "side", "chain", "seed", "excursion")
TICKS_PER_DEG = 4096 / 360.0


@pytest.fixture(scope="module")
def oracle():
    return ConstraintOracle(anatomical_limb(3, "arm", kinds={"elbow": "forearm"}))


def _leader_rig(tmp_path, *, patient: bool = True, side: str | None = None, **keys):
    """sim-leader-arm in this process on a manual clock; without its therapist (``patient``
    False) the servos stay where they are put."""
    cfg = shipped_config("sim-leader-arm")
    url = cfg["servos"]["port"]
    if not patient:
        url = without_keys(url, *PATIENT_KEYS)
    cfg["servos"]["port"] = with_keys(url, **MANUAL, **keys)
    if side is not None:
        cfg["joint"]["side"] = side
    path = tmp_path / "leader.yaml"
    path.write_text(yaml.safe_dump(cfg, sort_keys=False))
    return path


def _unit(rng, shape):
    q = rng.normal(size=(*shape, 4))
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


# --------------------------------------------------------------------------- mapping back
def test_the_commanded_posture_maps_back_onto_the_leaders_joints():
    rng = np.random.default_rng(41)
    c = _unit(rng, (2,))  # the follower: (elbow, shoulder); the leader: shoulder, elbow, wrist
    back = posture_to_leader(c, [1, 0], 3)
    np.testing.assert_array_equal(back[1], c[0])
    np.testing.assert_array_equal(back[0], c[1])
    assert np.isnan(back[2]).all()  # a leader joint the follower lacks stays free
    m = posture_to_leader(c, [1, 0], 3, mirror=True)
    np.testing.assert_array_equal(m[:2], mirror_posture(back[:2]))
    # forward then back is the identity, mirrored or not
    lead = _unit(rng, (3,))
    for mirror in (False, True):
        fwd = lead[[1, 0]]
        fwd = mirror_posture(fwd) if mirror else fwd
        np.testing.assert_array_equal(posture_to_leader(fwd, [1, 0], 3, mirror=mirror)[:2],
                                      lead[:2])


class _Spy:
    """A spring that records what :meth:`LeaderTargets.feedback` hands it."""

    armed = True

    def __init__(self, fail: bool = False):
        self.calls, self.fail, self.disarmed = [], fail, 0
        self.binding_ = np.array([True, False, False])

    def update(self, leader_q, admitted_q, ticks):
        if self.fail:
            raise OSError("leader bus gone")
        self.calls.append((np.array(leader_q), np.array(admitted_q), np.array(ticks)))
        return np.full(7, 12.0)

    def disarm(self):
        self.disarmed += 1
        self.armed = False


@pytest.mark.parametrize("mirrored", [False, True])
def test_feedback_hands_the_leaders_spring_the_mapped_back_posture(tmp_path, mirrored):
    """A mirrored leader (a left arm leading the right) gets the follower's posture reflected
    back; the spring is given the ticks the cycle's read returned; a spring that fails is
    counted, disarmed and said once, and the target still comes."""
    follower = load_rig_config("sim-servo-arm")
    rig = _leader_rig(tmp_path, side="left" if mirrored else None)
    names = ("elbow", "shoulder")
    lines = []
    with open_leader(f"leader:{rig}", names=names, side="right", rig=follower,
                     separate_process=False, spring=SpringSettings(enabled=True),
                     log=lines.append) as lead:
        assert lead.mirror is mirrored
        spy = lead.spring = _Spy()
        lead.spring_armed = True
        lead.bus.set_latency(LOADED_HOST_MS)
        lead.port.simulator.clock.advance(0.5)
        _, q = lead.latest(0.5)
        ticks = np.asarray(lead.bus.read_ticks())
        commanded = _unit(np.random.default_rng(3), (2,))
        lead.feedback(0.5, [tuple(r) for r in commanded])
        (lq, aq, tk), = spy.calls
        want = mirror_posture(commanded) if mirrored else commanded
        np.testing.assert_allclose(aq[1], want[0])
        np.testing.assert_allclose(aq[0], want[1])
        assert np.isnan(aq[2]).all()
        # the leader's own (unmirrored) posture, which the target is made from
        back = posture_to_leader(q, [1, 0], 3, mirror=mirrored)
        np.testing.assert_allclose(lq[:2], back[:2], atol=1e-12)
        np.testing.assert_array_equal(tk, ticks)
        spy.fail = True
        lead.feedback(0.5, commanded)
        lead.feedback(0.5, commanded)  # disarmed: not called again
        assert lead.spring_failures == 1 and spy.disarmed == 1 and len(lines) == 1
        assert "leader spring off" in lines[0] and "\n" not in lines[0]
        assert lead.latest(0.5)[1] is not None
        fig = lead.summary()["spring"]
        assert fig == {"armed": True, "binding_cycles": 1,
                       "current_ma": {"p95": 12.0, "max": 12.0}, "failures": 1}


# --------------------------------------------------------------------------- options
def test_leader_spring_option_parsed_and_checked():
    s = SpringSettings.from_option("20,100,2")
    assert (s.enabled, s.gain_ma_per_deg, s.max_current_ma, s.dead_band_deg) == \
        (True, 20.0, 100.0, 2.0)
    assert SpringSettings.from_option("5").max_current_ma == SpringSettings().max_current_ma
    for bad in ("", "a", "1,2,3,4", "-1", "1,,2", "1,0"):
        with pytest.raises(RigConfigError) as err:
            SpringSettings.from_option(bad)
        assert str(err.value).startswith("--leader-spring") and "\n" not in str(err.value)
    req = EnforceRequest(rig="sim-servo-arm", model="m.onnx", targets="script:slow",
                         leader_spring="10")
    with pytest.raises(RigConfigError, match="needs --targets leader"):
        req.loop_config()


def test_leader_spring_without_a_leader_is_one_line(tmp_path, rig_cli):
    code, out, err = rig_cli(["enforce", "--rig", "sim-servo-arm", "--model",
                              tmp_path / "m.onnx", "--targets", "script:slow",
                              "--leader-spring", "10,150", "--duration", "1"])
    assert code == 2, (out, err)
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and "--leader-spring 10,150: needs --targets leader" in lines[0]


def test_leader_without_current_control_is_refused_before_anything_moves(tmp_path):
    rig = _leader_rig(tmp_path, patient=False, model="XL430-W250")
    cfg = yaml.safe_load(rig.read_text())
    cfg["servos"]["model"] = "XL430-W250"
    rig.write_text(yaml.safe_dump(cfg, sort_keys=False))
    with pytest.raises(RigConfigError) as err:
        open_leader(f"leader:{rig}", names=("shoulder", "elbow", "wrist"), side="right",
                    rig=load_rig_config("sim-servo-arm"), separate_process=False,
                    spring=SpringSettings(enabled=True))
    msg = str(err.value)
    assert "\n" not in msg and "has no current control" in msg and "servo ID 1" in msg


def test_hand_stiffness_url_key(tmp_path):
    base = "sim://dynamixel?ids=1-7&model=XL330-M288&limb=arm&chain=sim-leader-arm&" \
           "clock=manual&process=off"
    with open_port(with_keys(base, hand_stiffness="0.2")) as port:
        servo = port.simulator.servo(4)
        assert servo.hand_stiffness == 0.2 and servo.hand_damping == pytest.approx(0.002)
    with open_port(base) as port:  # no key: the rigid hand, as before
        assert port.simulator.servo(4).hand_stiffness is None
    for keys, what in (({"hand_damping": "0.1"}, "hand_damping needs hand_stiffness"),
                       ({"hand_stiffness": "0"}, "hand_stiffness"),
                       ({"hand_stiffness": "1e9"}, "too stiff")):
        with pytest.raises(RigConfigError, match=what) as err:
            open_port(with_keys(base, **keys))
        assert "\n" not in str(err.value)


# --------------------------------------------------------------------------- the loop
def test_goal_current_zero_inside_the_limits_and_pulling_beyond(tmp_path, oracle):
    """Leader and follower start at the zero pose (inside the patient's limits): the spring
    sends no current. From cycle 40 a therapist's hand (an impedance) pushes the leader's
    elbow 30° into flexion, beyond the limit: the follower stops at the limit, and the leader's
    elbow servo gets a non-zero Goal Current (capped), pulling it back. Closing the leader lets
    it go (torque off)."""
    follower = load_rig_config("sim-servo-arm")
    period = 1.0 / 200.0
    push_at, cycles = 40, 160
    lead = open_leader(f"leader:{_leader_rig(tmp_path, patient=False)}",
                       names=oracle.limb.joint_names, side=oracle.limb.side, rig=follower,
                       separate_process=False,
                       spring=SpringSettings(True, 10.0, 120.0, 1.0))
    lsim = lead.port.simulator
    lead.bus.set_latency(LOADED_HOST_MS)
    elbow = lsim.servo(4)
    seen = {}

    def on_cycle(loop, k):
        lsim.clock.advance(period)
        if k == push_at - 1:
            seen["inside"] = int(elbow.get("Goal Current"))
            seen["inside_all"] = [int(lsim.servo(i).get("Goal Current")) for i in range(1, 8)]
            lsim.set_hand(4, 2048.0 + 30.0 * TICKS_PER_DEG, stiffness=0.3, damping=0.003)

    url = "sim://dynamixel?ids=1-7&model=XM430-W350&return_delay_us=0&" \
          "clock=manual&wire_time=off"
    cfg = LoopConfig(rate_hz=200.0, watchdog_ms=0, warm_up=False, supervisor=SupervisorConfig(
        stale_target_s=1.5 * period, stale_present_s=1.0))
    with lead, open_port(url, baud=1_000_000) as port:
        clk = port.simulator.clock
        limb = prepare_servo_limb(port, follower.servos, oracle)
        try:
            loop = EnforcementLoop(limb, None, oracle, lead, cfg, clock=clk, sleep=clk.sleep,
                                   on_cycle=on_cycle)
            loop.setup()
            lead.arm_spring()
            assert elbow.get("Operating Mode") == 5 and elbow.torque
            summary = loop.run(max_cycles=cycles)
        finally:
            limb.close()
        lead.bus.read_ticks()  # a round trip: the last sync writes were served
        pulled = int(elbow.get("Goal Current"))
        fig = lead.summary()["spring"]
    assert seen["inside_all"] == [0] * 7, seen
    assert 0 < pulled <= 120, pulled
    assert fig["armed"] and fig["failures"] == 0 and fig["binding_cycles"] > 0
    assert fig["current_ma"]["max"] == pytest.approx(120.0, abs=1.0)
    assert summary["safe_state_entries"] == 0
    assert math.degrees(loop.max_violation) <= 1.0
    assert not elbow.torque and not lead.spring.armed  # closed: the leader is free again
