"""The limit felt at the leader: the simulator's impedance hand and :class:`LeaderSpring`."""

from __future__ import annotations

import math

import numpy as np
import pytest

from benchmarks.bench_leader_spring import KINEMATICS, therapist_push
from rig.devices.dynamixel import DynamixelBus
from rig.devices.kinematics import JointKinematics, ServoAxis
from rig.devices.servo import Servo
from rig.errors import RigConfigError
from rig.loop.leader_spring import LeaderSpring, SpringSettings
from rig.sim.dynamixel import start_servo_bus
from rig.sim.dynamixel.servo import SimServo


def _write(servo: SimServo, name: str, value: int, now: float = 0.0) -> None:
    item = servo.table[name]
    assert servo.write(item.address, item.encode(value), now) == 0


def _settle(servo: SimServo, seconds: float = 3.0) -> None:
    t0 = servo.last_t
    for k in range(1, 31):
        servo.advance(t0 + seconds * k / 30)


# -- the impedance hand on a plain SimServo ---------------------------------------------------
def test_impedance_hand_balances_a_current_mode_servo_analytically():
    """Current Control Mode holding Goal Current I against a hand of stiffness K at 2048:
    at rest ``kt I + K (θ_hand − θ) = 0``, so θ = θ_hand + kt I / K."""
    servo = SimServo(1, "XL330-M288")
    servo.advance(0.0)
    servo.set_item("Operating Mode", 0)
    _write(servo, "Goal Current", 200)  # 1 mA units: 0.2 A
    _write(servo, "Torque Enable", 1)
    stiffness = 0.5
    servo.set_hand(2048.0, stiffness=stiffness, damping=0.005)
    _settle(servo)
    expected = 2048.0 + servo.kt * 0.2 / stiffness / (2 * math.pi / 4096)
    assert servo.pos == pytest.approx(expected, abs=0.01)
    assert abs(servo.hand_torque(servo.last_t) + servo.kt * 0.2) < 1e-5


def test_impedance_hand_moves_a_free_current_based_position_servo_and_a_torque_off_one():
    """Mode 5 with Goal Current 0 exerts no torque: the hand takes the shaft where it holds;
    and with torque off the hand is a torque too (the shaft's inertia and friction)."""
    free = SimServo(1, "XL330-M288")
    free.advance(0.0)
    free.set_item("Operating Mode", 5)
    _write(free, "Goal Current", 0)
    _write(free, "Torque Enable", 1)
    free.set_hand(3000.0, stiffness=0.5, damping=0.005)
    _write(free, "Torque Enable", 0)
    _write(free, "Torque Enable", 1)  # an impedance hand keeps holding through torque-on
    off = SimServo(2, "XL330-M288")
    off.advance(0.0)
    off.set_hand(3000.0, stiffness=0.5, damping=0.005)
    free.advance(0.02)
    off.advance(0.02)
    assert 2048.0 < off.pos < 2900.0  # no jump: it accelerates under the hand's torque
    _settle(free)
    _settle(off)
    assert free.pos == pytest.approx(3000.0, abs=0.01) and free.current == 0.0
    assert off.pos == pytest.approx(3000.0, abs=0.01)


def test_rigid_hand_unchanged_and_impedance_arguments_checked():
    servo = SimServo(1, "XL330-M288")
    servo.advance(0.0)
    servo.set_hand(2100.0)
    servo.advance(0.01)
    assert servo.pos == 2100.0 and servo.hand_stiffness is None
    with pytest.raises(ValueError, match="damping needs a stiffness"):
        servo.set_hand(2100.0, damping=0.1)
    with pytest.raises(ValueError, match="too stiff"):
        servo.set_hand(2100.0, stiffness=1e6)
    with start_servo_bus([1], "AX-12A") as bus, pytest.raises(ValueError,
                                                              match="no torque model"):
        bus.set_hand(1, 500.0, stiffness=0.5)


# -- LeaderSpring ------------------------------------------------------------------------------
def test_spring_reduces_the_leaders_deviation_beyond_the_limit():
    off = therapist_push(None, seconds=1.5, period=0.01, ramp_s=0.5)
    on = therapist_push(SpringSettings(True, 20.0, 300.0, 1.0), seconds=1.5, period=0.01,
                        ramp_s=0.5)
    assert on.final_deg < off.final_deg


def test_arm_update_disarm_on_the_wire():
    url = "sim://dynamixel?ids=1&model=XL330-M288&clock=manual&return_delay_us=0"
    with DynamixelBus(url, [Servo(1)]) as dxl:
        sim = dxl.port.simulator.servo(1)
        spring = LeaderSpring(dxl, KINEMATICS, SpringSettings(True, 10.0, 100.0, 1.0))
        with spring:
            assert sim.get("Operating Mode") == 5 and sim.torque
            assert sim.get("Goal Current") == 0
            ticks = dxl.read_ticks()
            lq = KINEMATICS.forward(ticks)[None]
            current = spring.update(lq, lq, ticks)  # within the dead band: free
            assert not current.any() and sim.get("Goal Current") == 0
            admitted = KINEMATICS.forward([2048 + 4096 * 5 / 360])[None]  # 5° away
            current = spring.update(lq, admitted, ticks)
            dxl.read_ticks()  # a round trip: the sync writes (no reply) were served before it
            assert current[0] == pytest.approx(50.0, abs=1.0)
            assert sim.get("Goal Current") == round(current[0])
            assert abs(sim.get("Goal Position") - (2048 + 4096 * 5 / 360)) <= 1
            far = KINEMATICS.forward([2048 + 4096 * 40 / 360])[None]
            assert spring.update(lq, far, ticks)[0] == 100.0  # capped
            assert spring.binding_.tolist() == [True]
        assert sim.get("Operating Mode") == 3 and not sim.torque
        assert sim.get("Goal Current") == 0


def test_a_leader_turned_through_the_wrap_is_pulled_the_short_way():
    """In Current-based Position Control Mode a whole-turn axis reads multi-turn (a hand that
    took it through 4095 → 0 reads 4146, not 50): the spring's goal is the admitted pose in
    that turn — 5° on, not 355° back to its equivalent inside 0..4095."""
    url = "sim://dynamixel?ids=1&model=XL330-M288&clock=manual&return_delay_us=0"
    kin = JointKinematics([ServoAxis(1, (0.0, 0.0, 1.0), 2048, 1, 0, 4095)])
    with DynamixelBus(url, [Servo(1)]) as dxl:
        spring = LeaderSpring(dxl, kin, SpringSettings(True, 10.0, 100.0, 1.0))
        with spring:
            ticks = np.array([4096 + 50])  # 4.4° past the wrap, one turn up
            lq = kin.forward(ticks)[None]
            admitted = kin.forward([4096 + 50 + 4096 * 5 / 360])[None]  # 5° further on
            current = spring.update(lq, admitted, ticks)
            dxl.read_ticks()
            goal = dxl.port.simulator.servo(1).get("Goal Position")
            assert abs(goal - (4096 + 50 + 4096 * 5 / 360)) <= 1, goal
            assert current[0] == pytest.approx(50.0, abs=1.0)  # 5°, not 355°


def test_spring_on_a_leader_without_current_control_is_one_line():
    url = "sim://dynamixel?ids=1&model=XL430-W250"
    with DynamixelBus(url, [Servo(1)]) as dxl:
        kin = JointKinematics([ServoAxis(1, (0.0, 0.0, 1.0))])
        with pytest.raises(RigConfigError) as err:
            LeaderSpring(dxl, kin)
    msg = str(err.value)
    assert "\n" not in msg and "ID 1" in msg and "XL430-W250" in msg
    assert "current control" in msg


def test_settings_off_by_default_and_checked():
    assert SpringSettings().enabled is False
    assert SpringSettings.from_mapping({"enabled": True, "gain_ma_per_deg": 5}).enabled
    with pytest.raises(RigConfigError, match="unknown key 'gian'"):
        SpringSettings.from_mapping({"gian": 5})
    with pytest.raises(RigConfigError, match="max_current_ma"):
        SpringSettings(True, 5.0, -1.0)
    assert np.isfinite(SpringSettings().dead_band_deg)
