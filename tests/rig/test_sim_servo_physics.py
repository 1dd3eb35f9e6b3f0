"""The simulated servo's frame and torque model, on plain SimServo calls (no wire).

Simulated time only (each servo integrates on the times the test gives it); no sleeps.
"""

from __future__ import annotations

import math

import pytest

from firmware_protocol.dynamixel import ErrorCode
from rig.sim.dynamixel import SimServo


def write(servo: SimServo, name: str, value: int, now: float = 0.0) -> int:
    item = servo.table[name]
    return servo.write(item.address, item.encode(value), now)


def present(servo: SimServo, name: str, now: float) -> int:
    item = servo.table[name]
    error, data = servo.read(item.address, item.size, now)
    assert error == 0
    return item.decode(data)


def servo_in(mode: int, position: float = 2048.0, **items: int) -> SimServo:
    servo = SimServo(1, "XM430-W350", position=position)
    servo.advance(0.0)
    assert write(servo, "Operating Mode", mode) == 0
    for name, value in items.items():
        assert write(servo, name.replace("_", " "), value) == 0
    assert write(servo, "Torque Enable", 1) == 0
    return servo


# ---------------------------------------------------------------------------- frame


def test_homing_offset_and_reverse_in_present_goal_and_velocity():
    servo = SimServo(1, position=1000.0)
    servo.advance(0.0)
    assert write(servo, "Operating Mode", 4) == 0
    assert write(servo, "Drive Mode", 1) == 0
    assert write(servo, "Homing Offset", 3000) == 0
    assert present(servo, "Present Position", 0.0) == -1000 + 3000
    assert write(servo, "Torque Enable", 1) == 0
    assert present(servo, "Goal Position", 0.0) == 2000  # torque on: goal := present
    assert write(servo, "Goal Position", 2500, 0.0) == 0
    assert present(servo, "Present Velocity", 0.05) > 0  # the frame's position increases ...
    assert servo.vel < 0  # ... while the shaft turns the other way
    assert present(servo, "Position Trajectory", 0.05) == 2500
    assert present(servo, "Present Position", 5.0) == 2500
    assert servo.pos == 500.0  # actual = -(2500 - 3000)


def test_present_position_comes_back_within_one_turn_as_the_e_manual_says():
    """e-Manual "Present Position(132)": multi-turn while torque is off or in extended
    position mode; back within one turn when the Operating Mode becomes Position Control
    Mode, when torque is turned on in it, and after REBOOT (Homing Offset still on top)."""
    servo = SimServo(1, position=2048.0)
    servo.advance(0.0)
    assert write(servo, "Homing Offset", 100) == 0
    servo.hand = 2048.0 + 2 * 4096 + 10  # turned by hand two turns further, torque off
    assert present(servo, "Present Position", 0.01) == 2048 + 8192 + 10 + 100
    servo.hand = None
    assert write(servo, "Torque Enable", 1, 0.02) == 0  # torque on in Position Control Mode
    assert present(servo, "Present Position", 0.03) == 2058 + 100
    assert write(servo, "Torque Enable", 0, 0.04) == 0
    assert write(servo, "Operating Mode", 4, 0.05) == 0
    servo.hand = 5000.0
    assert present(servo, "Present Position", 0.06) == 5100
    servo.hand = None
    assert write(servo, "Torque Enable", 1, 0.07) == 0  # extended position: no reset
    assert present(servo, "Present Position", 0.08) == 5100
    assert write(servo, "Torque Enable", 0, 0.09) == 0
    assert write(servo, "Operating Mode", 3, 0.1) == 0  # back to Position Control Mode
    assert present(servo, "Present Position", 0.11) == 5000 - 4096 + 100
    servo.hand = -300.0
    assert present(servo, "Present Position", 0.12) == -200
    servo.hand = None
    servo.reboot()
    assert present(servo, "Present Position", 0.5) == 4096 - 300 + 100
    p_series = SimServo(1, "PH54-200-S500", position=0.0)  # one turn is ±501,923 about 0
    p_series.advance(0.0)
    p_series.hand = -600_000.0
    p_series.advance(0.01)
    p_series.hand = None
    p_series.reboot()
    assert p_series.pos == pytest.approx(-600_000 + 1_003_846)


def test_position_limits_are_in_the_servo_frame():
    servo = SimServo(1, position=500.0)
    servo.advance(0.0)
    assert write(servo, "Drive Mode", 1) == 0
    assert write(servo, "Homing Offset", 1024) == 0  # joint mode accepts up to ±1,024
    assert write(servo, "Max Position Limit", 1000) == 0
    assert present(servo, "Present Position", 0.0) == 524
    assert write(servo, "Torque Enable", 1) == 0
    assert write(servo, "Goal Position", 3000) == 0  # X series: clamped to the limit
    assert present(servo, "Present Position", 5.0) == 1000
    assert servo.pos == 24.0


def test_joint_mode_ignores_a_homing_offset_beyond_1024():
    servo = SimServo(1)
    servo.advance(0.0)
    assert write(servo, "Homing Offset", 2000) == 0
    assert present(servo, "Present Position", 0.0) == 2048  # mode 3: ignored
    assert write(servo, "Operating Mode", 4) == 0
    assert present(servo, "Present Position", 0.0) == 4048


def test_torque_on_by_goal_update():
    servo = SimServo(1)
    servo.advance(0.0)
    assert write(servo, "Goal Position", 2100) == 0
    assert not servo.torque
    assert write(servo, "Drive Mode", 0x08) == 0
    assert write(servo, "Goal Position", 2200) == 0
    assert servo.torque and servo.target == 2200.0


# ---------------------------------------------------------------------------- torque model


def test_position_mode_without_push_keeps_the_exact_profile_and_reports_its_current():
    servo = servo_in(3, Profile_Acceleration=20, Profile_Velocity=100)
    assert write(servo, "Goal Position", 3048, 0.0) == 0
    servo.advance(0.05)  # accelerating: positive current
    assert servo.current > 0 and not servo._off_profile
    assert present(servo, "Present Position", 10.0) == 3048
    assert servo.pos == 3048.0 and present(servo, "Present Current", 10.0) == 0


def test_position_mode_resists_a_push_then_yields_at_current_limit():
    servo = servo_in(3)
    servo.push = 1.0  # N·m
    servo.advance(1.0)
    stiffness = servo.table.units.stall_torque_nm * (800 / 128) / servo.table.units.pwm_max
    assert servo.pos - 2048 == pytest.approx(1.0 / stiffness, rel=0.02)  # ticks of deflection
    unit = servo.table.units.current_ma / 1000
    assert present(servo, "Present Current", 1.0) == pytest.approx(-1.0 / servo.kt / unit,
                                                                   abs=2)
    servo.push = None  # let go: back on the goal, the exact profile again
    servo.advance(3.0)
    assert servo.pos == 2048.0 and not servo._off_profile
    servo.push = 6.0  # beyond the motor's stall torque: it yields, current at its limit
    servo.advance(4.0)
    assert servo.pos > 2048 + 1000
    assert present(servo, "Present Current", 4.0) == -servo.get("Current Limit")


def test_current_based_position_goal_current_bounds_the_resistance():
    servo = servo_in(5, Goal_Current=200)
    held = 0.8 * 200 * servo.table.units.current_ma / 1000 * servo.kt  # N·m
    servo.push = -held
    servo.advance(1.0)
    assert abs(servo.pos - 2048) < 100 and abs(servo.vel) < 1.0
    servo.push = -1.5 * held / 0.8
    servo.advance(2.0)
    assert servo.pos < 2048 - 1000  # beyond Goal Current's torque: yields
    assert present(servo, "Present Current", 2.0) == 200


@pytest.mark.parametrize("push", [0.0, -0.5, -1.2, 0.4])
def test_current_mode_reaches_the_analytic_equilibrium(push):
    servo = servo_in(0, Goal_Current=250)
    servo.push = push
    servo.advance(4.0)  # ~10 mechanical time constants of the friction
    w, i = servo.current_mode_equilibrium(push)
    assert servo.vel * 2 * math.pi / 4096 == pytest.approx(w, rel=0.01, abs=0.01)
    assert servo.current == pytest.approx(i, rel=0.01, abs=0.002)


def test_current_mode_balance_holds_still():
    servo = servo_in(0, Goal_Current=250)
    servo.push = -servo.kt * 250 * servo.table.units.current_ma / 1000
    servo.advance(1.0)
    assert abs(servo.pos - 2048) < 1e-6
    assert present(servo, "Present Current", 1.0) == 250


def test_pwm_mode_runs_at_the_speed_the_duty_allows():
    servo = servo_in(16, Goal_PWM=442)
    servo.advance(2.0)
    u = servo.table.units
    duty = 442 / u.pwm_max
    w = u.stall_torque_nm * duty / (u.stall_torque_nm / servo.no_load_w + servo.friction)
    assert servo.vel * 2 * math.pi / 4096 == pytest.approx(w, rel=0.01)
    assert present(servo, "Present PWM", 2.0) == 442


def test_reversed_current_mode_turns_the_other_way():
    servo = servo_in(0, Drive_Mode=1, Goal_Current=100)
    servo.advance(0.01)  # still below the speed where the PWM bounds the current
    assert servo.vel < 0 and present(servo, "Present Velocity", 0.01) > 0
    assert present(servo, "Present Current", 0.01) == 100 and servo.current < 0


def test_goal_current_and_pwm_beyond_their_limits_are_data_limit_errors():
    servo = SimServo(1)
    servo.advance(0.0)
    assert write(servo, "Current Limit", 500) == 0
    assert write(servo, "PWM Limit", 300) == 0
    assert write(servo, "Goal Current", 501) == ErrorCode.DATA_LIMIT
    assert write(servo, "Goal Current", -501) == ErrorCode.DATA_LIMIT
    assert write(servo, "Goal PWM", 301) == ErrorCode.DATA_LIMIT
    assert write(servo, "Goal PWM", -300) == 0


def test_p_series_refuses_a_goal_beyond_its_position_limits():
    servo = SimServo(1, "PH54-200-S500", position=0.0)
    servo.advance(0.0)
    servo.set_item("Max Position Limit", 100_000)
    servo.set_item("Min Position Limit", 0)
    assert write(servo, "Torque Enable", 1) == 0
    assert write(servo, "Goal Position", 150_000) == ErrorCode.DATA_LIMIT
    assert write(servo, "Goal Position", 90_000) == 0


def test_units_come_from_the_table():
    servo = SimServo(1, "XM430-W350")
    u = servo.table.units
    assert servo.velocity_unit == u.velocity_rpm * u.ticks_per_rev / 60.0
    assert servo.kt == pytest.approx(u.stall_torque_nm / u.stall_current_a)
    assert servo.pos == u.ticks_per_rev / 2


def test_p_series_goal_range_per_mode_and_its_quarter_turn_homing_rule():
    """PH54-200-S500 (ph54-200-s500-r page and its Goal Position include): Position Control
    Mode refuses a goal beyond Min/Max Position Limit (Data Limit Error), Extended Position
    Control Mode takes the int32 range; a Homing Offset beyond ±90° (a quarter turn, 250,961
    pulses) is ignored in Position Control Mode only."""
    servo = SimServo(1, "PH54-200-S500")
    servo.advance(0.0)
    assert write(servo, "Homing Offset", 300_000) == 0
    assert present(servo, "Present Position", 0.0) == 0  # ignored in position mode
    assert write(servo, "Homing Offset", 200_000) == 0
    assert present(servo, "Present Position", 0.0) == 200_000
    assert write(servo, "Homing Offset", 0) == 0
    assert write(servo, "Torque Enable", 1) == 0
    assert write(servo, "Goal Position", 501_434) == ErrorCode.DATA_LIMIT  # limit 501,433
    assert write(servo, "Goal Position", 1_048_575) == ErrorCode.DATA_LIMIT
    assert write(servo, "Torque Enable", 0) == 0
    assert write(servo, "Operating Mode", 4) == 0
    assert write(servo, "Homing Offset", 300_000) == 0
    assert present(servo, "Present Position", 0.0) == 300_000  # honoured in extended mode
    assert write(servo, "Torque Enable", 1) == 0
    assert write(servo, "Goal Position", 1_048_575 + 300_000) == 0
    assert present(servo, "Present Position", 60.0) == 1_048_575 + 300_000
