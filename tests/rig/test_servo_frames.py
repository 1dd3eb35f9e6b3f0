"""Issue 40, item 3: the rig's servo code and the servos' own frame (Homing Offset, Drive Mode
reverse bit) and the goal read back through indirect addressing.

- the rig config's ``homing_offset`` / ``reverse`` per servo and ``servos.homing``;
- ``check`` refuses a servo whose registers differ (one line naming the servo, the register,
  both values and the two ways out; exit 2 at the CLI), ``write`` writes and reads back;
- ``rig scan`` shows each servo's Homing Offset and direction;
- the loop's read returns the goal each servo holds; a servo that does not hold the goal
  written lately (none of the last GOAL_HISTORY, two reads in a row) is
  ``Fault.GOAL_NOT_HELD`` and the safe state follows.

The simulated servos are changed as a bench would (``SimServo.set_item``); cheap: manual clock,
few cycles.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

import rig
from rig.devices.config import ServoFrame, load_rig_config, loads_rig_config
from rig.devices.dynamixel import DynamixelBus, scan
from rig.devices.ports import open_port
from rig.errors import RigConfigError, RigError
from rig.loop.runner import prepare_servo_limb
from rig.loop.telemetry import Fault

URL = "sim://dynamixel?ids=1,2,3&model=XM430-W350&return_delay_us=0"
RIG = load_rig_config("sim-shoulder")
SERVOS = dataclasses.replace(RIG.servos, port=URL)


def _config(chain_extra: str = "", servos_extra: str = "") -> str:
    return f"""name: t
joint: {{name: shoulder, side: right, parent: thorax, child: humerus}}
servos:
  port: "{URL}"
  {servos_extra}
  chain:
    - {{id: 1, axis: [0, 0, 1]}}
    - {{id: 2, axis: [0, 1, 0]{chain_extra}}}
    - {{id: 3, axis: [1, 0, 0]}}
"""


# ------------------------------------------------------------------------------- the config
def test_config_reads_each_servos_frame_and_the_homing_mode():
    cfg = loads_rig_config(_config(", homing_offset: -1024, reverse: true", "homing: write"))
    s = cfg.servos
    assert s.homing == "write"
    assert [s.frame(k) for k in range(3)] == [ServoFrame(), ServoFrame(-1024, True), ServoFrame()]
    plain = loads_rig_config(_config()).servos
    assert plain.frames == () and plain.homing == "check" and plain.frame(1) == ServoFrame()


def test_shipped_servo_rigs_keep_the_factory_frame():
    for name in ("sim-shoulder", "sim-servo-arm"):
        s = load_rig_config(name).servos
        assert s.frames == () and s.homing == "check"


@pytest.mark.parametrize(("chain", "servos", "match"), [
    (", homing_offset: 1.5", "", "servos.chain[1].homing_offset: expected a whole number"),
    (", homing_offset: 2000000", "", "servos.chain[1].homing_offset: 2000000 is out of range"),
    (", reverse: yes-please", "", "servos.chain[1].reverse: expected true or false"),
    (", reverse: 1", "", "servos.chain[1].reverse: expected true or false"),
    ("", "homing: overwrite", "servos.homing: expected check or write"),
    (", homing: write", "", "servos.chain[1]: unknown key 'homing'"),
    ("", "homing_offset: 3", "servos: unknown key 'homing_offset'"),
])
def test_config_mistakes_are_one_line_naming_the_key(chain, servos, match):
    with pytest.raises(RigConfigError) as exc:
        loads_rig_config(_config(chain, servos), "rig.yaml")
    assert match in str(exc.value) and "\n" not in str(exc.value)


# ------------------------------------------------------------------------------- check / write
def _changed(**items):
    """A manual-clock simulated bus whose servo 2 holds ``items`` (set as a bench would)."""
    port = open_port(URL + "&clock=manual&wire_time=off", baud=SERVOS.baud)
    for name, value in items.items():
        port.simulator.servo(2).set_item(name.replace("_", " "), value)
    return port


@pytest.mark.parametrize(("items", "register", "holds", "says"), [
    ({"Homing_Offset": 512}, "Homing Offset", "512", "0"),
    ({"Drive_Mode": 0x05}, "reverse bit (Drive Mode bit 0)", "true", "false"),
])
def test_check_refuses_a_servo_calibrated_by_another_tool(items, register, holds, says):
    with _changed(**items) as port, pytest.raises(RigConfigError) as exc:
        prepare_servo_limb(port, SERVOS)
    msg = str(exc.value)
    assert "\n" not in msg and "ID 2" in msg and "servo elevation" in msg
    assert f"{register} holds {holds}, the rig config says {says}" in msg
    assert "in the config" in msg and "servos.homing: write" in msg
    assert port.simulator.servo(2).get("Torque Enable") == 0  # nothing was switched on


def test_check_accepts_a_servo_holding_the_configured_frame():
    servos = dataclasses.replace(SERVOS, frames=(ServoFrame(), ServoFrame(300, True),
                                                 ServoFrame()))
    with _changed(Homing_Offset=300, Drive_Mode=0x05) as port:
        bus = DynamixelBus(port, servos)
        try:
            bus.configure()
            assert bus.read_frames()[2] == (300, 0x05)
        finally:
            bus.close()


def test_write_writes_the_configured_frame_keeping_other_drive_mode_bits():
    servos = dataclasses.replace(SERVOS, homing="write",
                                 frames=(ServoFrame(), ServoFrame(-700, True), ServoFrame(5)))
    with _changed(Homing_Offset=512, Drive_Mode=0x04) as port:
        limb = prepare_servo_limb(port, servos)
        try:
            sim = port.simulator
            assert sim.servo(2).get("Homing Offset") == -700
            assert sim.servo(2).get("Drive Mode") == 0x05  # reverse set, time-based profile kept
            assert sim.servo(3).get("Homing Offset") == 5
            assert sim.servo(1).get("Homing Offset") == 0 and sim.servo(1).get("Drive Mode") == 0
            assert limb.bus.read_frames() == {1: (0, 0), 2: (-700, 5), 3: (5, 0)}
        finally:
            limb.close()


def test_write_refuses_to_change_eeprom_while_torque_is_on():
    servos = dataclasses.replace(SERVOS, homing="write",
                                 frames=(ServoFrame(), ServoFrame(100), ServoFrame()))
    with _changed(Torque_Enable=1) as port, pytest.raises(RigError) as exc:
        DynamixelBus(port, servos)
    assert "'Homing Offset' must change" in str(exc.value) and "torque is on" in str(exc.value)
    assert port.simulator.servo(2).get("Homing Offset") == 0


def test_a_bus_of_bare_ids_does_not_check_the_frame():
    with _changed(Homing_Offset=512) as port:
        bus = DynamixelBus(port, [1, 2, 3])
        try:
            assert bus.homing is None and bus.read_frames()[2] == (512, 0)
        finally:
            bus.close()


def test_record_on_a_rig_whose_servo_disagrees_exits_2_with_one_line(tmp_path, rig_cli):
    """The shipped sim-shoulder with a Homing Offset on its servo 2 that the simulated servo
    (factory 0) does not hold."""
    path = tmp_path / "r.yaml"
    src = (Path(rig.__file__).parent / "configs" / "sim-shoulder.yaml").read_text()
    path.write_text(src.replace("name: elevation}", "name: elevation, homing_offset: 256}"))
    code, out, err = rig_cli(["record", "--rig", str(path), "--db", str(tmp_path / "x.db"),
                              "--patient", "P-1", "--duration", "1"])
    assert code == 2, (out, err)
    assert err.startswith("rig: error: ") and err.count("\n") == 1
    assert "ID 2" in err and "Homing Offset holds 0, the rig config says 256" in err


# ------------------------------------------------------------------------------- rig scan
def test_scan_reads_each_servos_homing_offset_and_direction():
    with _changed(Homing_Offset=-300, Drive_Mode=0x01) as port:
        found = {s.id: s for s in scan(port, [SERVOS.baud], [1, 2, 3])}
    assert (found[2].homing_offset, found[2].reverse) == (-300, True)
    assert (found[1].homing_offset, found[1].reverse) == (0, False)


def test_scan_shows_a_dash_for_a_model_without_the_items(rig_cli):
    code, out, err = rig_cli(["scan", "sim://dynamixel?ids=4&model=XL320", "--baud", "1000000",
                              "--ids", "4"])
    assert code == 0, err
    row = out.splitlines()[1].split()
    assert row[:2] == ["4", "XL320"] and row[-2:] == ["-", "-"]


# ------------------------------------------------------------------------------- goal not held
def _loop_run(on_cycle, *, cycles=120, watchdog_ms=1000):
    """The loop on the simulated shoulder (manual clock, no model: the supervisor alone),
    ``cycles`` cycles of sweeping targets; (summary, telemetry table, bus)."""
    from models.constraint import JointConstraint
    from models.oracle import ConstraintOracle
    from rig.loop import EnforcementLoop, LoopConfig, ScriptedTargets

    oracle = ConstraintOracle(JointConstraint.cone((1, 0, 0), 50.0, twist=(-40, 40)))
    cfg = LoopConfig(rate_hz=200.0, watchdog_ms=watchdog_ms)
    with open_port(URL + "&clock=manual&wire_time=off", baud=SERVOS.baud) as port:
        sim = port.simulator
        limb = prepare_servo_limb(port, SERVOS, oracle)
        try:
            assert limb.bus.read_back  # the simulated X-series honour indirect addressing
            loop = EnforcementLoop(limb, None, oracle, ScriptedTargets("sweep", oracle), cfg,
                                   clock=sim.clock, sleep=sim.clock.sleep,
                                   on_cycle=lambda lp, k: on_cycle(sim, lp, k))
            loop.setup()
            summary = loop.run(max_cycles=cycles)
        finally:
            limb.close()
    return summary, loop.telemetry.table(), limb.bus


def test_the_read_returns_the_goals_written_and_no_fault_without_one():
    held, sent = [], []

    def on_cycle(sim, loop, k):  # at cycle k: the read of cycle k - 1, the write of k - 1
        if k >= 1:
            held.append(loop.bus.held_goals.copy())
            sent.append(loop.last_sent.copy())

    summary, table, _ = _loop_run(on_cycle, cycles=60)
    assert summary["safe_state_entries"] == 0 and summary["cycles"] == 60
    assert not (table["faults"] & Fault.GOAL_NOT_HELD).any()
    # the read of cycle k returns the goal written at the end of cycle k - 1
    assert all((h == s).all() for h, s in zip(held[1:], sent[:-1], strict=True))
    assert len({tuple(s) for s in sent}) > 10  # the goals did change


def test_a_servo_refusing_goals_after_its_watchdog_fired_is_goal_not_held():
    """Servo 1's Bus Watchdog flagged (as when it alone heard nothing for too long: a flaky
    cable to it), the host's own gap measure sees nothing: the first goal it refuses (the sweep
    moves servo 1 a tick every few cycles) is seen once the goal it holds has left the window
    of goals recently written (late replies may show those); the safe state follows."""
    def on_cycle(sim, loop, k):
        if k == 50:
            sim.servo(1).set_item("Bus Watchdog", 0xFF)

    summary, table, _ = _loop_run(on_cycle)
    assert summary["safe_state_entries"] == 1
    from rig.loop.runner import GOAL_HISTORY, GOAL_NOT_HELD_CYCLES

    assert 51 <= summary["safe_state_cycle"] <= 50 + GOAL_HISTORY + GOAL_NOT_HELD_CYCLES + 5
    reason = summary["safe_state_reason"]
    assert "servo ID 1 holds goal" in reason and "none of the last" in reason
    bits = table["faults"]
    assert bits[-1] & Fault.GOAL_NOT_HELD and not (bits[:-1] & Fault.GOAL_NOT_HELD).any()
    assert table["safe_state"][-1] == 1 and summary["faults"].get("goal_not_held") == 1



# ------------------------------------------------------------------------------- the same arm
def test_a_reversed_servo_with_a_homing_offset_reads_the_same_joint():
    """The back-driven simulated shoulder seen twice at the same patient time: through servos in
    the factory frame, and with servo 2 reversed and offset by 300 ticks (written at start-up by
    ``homing: write``, the chain's zero, direction and limits stated in that frame). The ticks
    differ (Present = −actual + 300); the joint orientations are the same."""
    back = "&patient=original&chain=sim-shoulder&seed=1&wire_time=off&clock=manual"
    plain_cfg = RIG.servos
    axes = list(plain_cfg.axes)
    # θ = −(present − zero'): zero' = −2048 + 300, limits mirrored and offset
    axes[1] = dataclasses.replace(axes[1], zero_ticks=-2048 + 300, direction=-1,
                                  min_ticks=-3072 + 300, max_ticks=-1024 + 300)
    turned_cfg = dataclasses.replace(plain_cfg, axes=tuple(axes), homing="write",
                                     frames=(ServoFrame(), ServoFrame(300, True), ServoFrame()))
    seen = {}
    for name, cfg in (("plain", plain_cfg), ("turned", turned_cfg)):
        with open_port(URL + back, baud=cfg.baud) as port:
            clock = port.simulator.clock
            bus = DynamixelBus(port, cfg)
            try:
                ticks, quats = [], []
                for t in (0.5, 1.0, 1.5):
                    clock.advance(t - clock.t)
                    tk = bus.read_ticks()
                    ticks.append(tk)
                    quats.append(cfg.kinematics().forward(tk))
                seen[name] = (np.array(ticks), np.array(quats))
            finally:
                bus.close()
    (t0, q0), (t1, q1) = seen["plain"], seen["turned"]
    assert (t1[:, 1] == -t0[:, 1] + 300).all() and (t1[:, [0, 2]] == t0[:, [0, 2]]).all()
    assert np.allclose(q0, q1, atol=1e-12)
    assert np.degrees(2 * np.arccos(np.clip(np.abs(q0[:, 0]), 0, 1))).max() > 5  # it moved
