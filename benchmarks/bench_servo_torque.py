"""The simulated servo's torque model under a simulated hand (figures, never assertions).

Two tables, on simulated time (plain :class:`~rig.sim.dynamixel.servo.SimServo`, no wire):

1. A Current Control Mode servo (XM430-W350, and XL330-M288 when its table has current
   sensing) holding Goal Current while a hand pushes against it with a slow torque ramp
   (0 → −2 × the motor's torque at Goal Current over 20 s): the simulated Present Current and
   shaft speed beside the model's analytic steady state
   (:meth:`~rig.sim.dynamixel.servo.SimServo.current_mode_equilibrium`), and the position.
2. A Position Control Mode servo holding 2048 while the hand's torque ramps 0 → 1.5 × stall
   torque: deflection and Present Current grow with the push until the current reaches what
   the PWM and Current Limit allow, then the servo yields.

Run: ``.venv/bin/python benchmarks/bench_servo_torque.py``.
"""

from __future__ import annotations

import math

from rig.sim.dynamixel.servo import SimServo


def _write(servo: SimServo, name: str, value: int) -> None:
    item = servo.table[name]
    error = servo.write(item.address, item.encode(value), servo.last_t or 0.0)
    if error:
        raise RuntimeError(f"{name}={value}: error {error}")


def _read(servo: SimServo, name: str, now: float) -> int:
    item = servo.table[name]
    _, data = servo.read(item.address, item.size, now)
    return item.decode(data)


def current_mode(model: str, goal_current: int = 200, ramp_s: float = 20.0) -> None:
    servo = SimServo(1, model)
    if servo.table.units.current_ma is None or "Goal Current" not in servo.table:
        print(f"{model}: no current sensing in its table, skipped")
        return
    servo.advance(0.0)
    _write(servo, "Operating Mode", 0)
    _write(servo, "Goal Current", goal_current)
    _write(servo, "Torque Enable", 1)
    unit = servo.table.units.current_ma / 1000.0
    motor = servo.kt * goal_current * unit
    rate = 2.0 * motor / ramp_s
    servo.push = lambda t: -rate * t
    rad = 2.0 * math.pi / servo.ticks_per_rev
    print(f"\n{model} current mode, Goal Current {goal_current} ({goal_current * unit:.3f} A, "
          f"{motor:.3f} N·m), hand ramp {-rate:.3f} N·m/s")
    print(f"{'t s':>5} {'hand N·m':>9} {'I mA':>8} {'I eq mA':>8} {'w rad/s':>9} "
          f"{'w eq':>9} {'position':>10}")
    for t in (1, 4, 8, 10, 12, 16, 20):
        current = _read(servo, "Present Current", float(t)) * unit * 1e3
        w_eq, i_eq = servo.current_mode_equilibrium(-rate * t)
        print(f"{t:5.0f} {-rate * t:9.3f} {current:8.0f} {i_eq * 1e3:8.0f} "
              f"{servo.vel * rad:9.3f} {w_eq:9.3f} {_read(servo, 'Present Position', t):10d}")


def position_mode(model: str = "XM430-W350", ramp_s: float = 10.0) -> None:
    servo = SimServo(1, model)
    servo.advance(0.0)
    _write(servo, "Torque Enable", 1)
    stall = servo.table.units.stall_torque_nm
    rate = 1.5 * stall / ramp_s
    servo.push = lambda t: rate * t
    unit = servo.table.units.current_ma / 1000.0
    limit = servo.get("Current Limit") * unit
    print(f"\n{model} position mode holding 2048; hand ramp {rate:.3f} N·m/s; stall "
          f"{stall} N·m, Current Limit {limit:.2f} A")
    print(f"{'t s':>5} {'hand N·m':>9} {'I mA':>8} {'hand/kt mA':>10} {'deflection':>11}")
    for t in (1, 2, 4, 6, 6.5, 7, 8, 10):
        current = _read(servo, "Present Current", float(t)) * unit * 1e3
        print(f"{t:5.1f} {rate * t:9.3f} {current:8.0f} {-rate * t / servo.kt * 1e3:10.0f} "
              f"{servo.pos - 2048:11.1f}")


def main() -> None:
    current_mode("XM430-W350")
    current_mode("XL330-M288")
    position_mode()


if __name__ == "__main__":
    main()
