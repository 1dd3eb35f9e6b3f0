"""The rig's Dynamixel bus on Protocol 1.0 (``servos.protocol: 1.0``): MX-28 on its 1.0 firmware
(BULK_READ, 2-byte goals, angle limits for the position limits, no watchdog, no read-back) and
AX-12A (no BULK_READ: one READ per servo), against the simulator on a pty driven by the
unmodified ``dynamixel_sdk``; the rig configuration's key and its one-line mistakes; and the
rig's servo paths (scan, record, boundary, train, enforce) on the shipped ``sim-shoulder-mx28``.
"""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from rig.devices.config import ServoFrame, load_rig_config, loads_rig_config
from rig.devices.dynamixel import DynamixelBus
from rig.devices.ports import open_port
from rig.devices.servo import Servo
from rig.errors import RigConfigError, RigProtocolError, UnreachableError

MX28 = "sim://dynamixel?ids=1,2,3&model=MX-28&protocol=1&return_delay_us=0&wire_time=off"
AX12 = "sim://dynamixel?ids=1,2&model=AX-12A&return_delay_us=0&wire_time=off"


def _servos(ids, lo=1024, hi=3072):
    return [Servo(i, None, lo, hi) for i in ids]


# -- the bus -----------------------------------------------------------------------------------
def test_mx28_on_protocol_1_bulk_reads_writes_2_byte_goals_and_has_no_watchdog():
    with open_port(MX28) as port, \
            DynamixelBus(port, _servos([1, 2, 3]), protocol=1.0, latency_ms=4.0) as bus:
        sim = port.simulator
        assert [(s.model, s.protocol) for s in bus.found.values()] == [("MX-28", 1.0)] * 3
        assert bus.read_what == "bulk read of Present Position" and not bus.fast
        assert bus.read_ticks().tolist() == [2048, 2048, 2048]  # MX power-on: mid-turn
        bus.configure()
        # Min/Max Position Limit are the MX's CW/CCW Angle Limit (6/8), EEPROM, read back
        assert [bus.read_register(1, n) for n in ("CW Angle Limit", "CCW Angle Limit")] == [
            1024, 3072]
        assert bus.read_register(2, "Status Return Level") == 2
        assert bus.held_goals is None and any("no indirect addressing" in a for a in bus.advice)
        assert bus.arm_watchdog(100) == 0  # no Bus Watchdog on the MX-28 (1.0)
        bus.set_torque(True)
        bus.write_goal_ticks([2100, 2000, 2300])  # SYNC_WRITE of 2-byte Goal Position (30)
        assert sim.wait_for(lambda: [sim.servo(i).target for i in (1, 2, 3)] == [2100, 2000,
                                                                                 2300])
        bus.begin_read()
        assert bus.finish_read().shape == (3,)
        assert bus.bulk_read({1: (30, 2), 3: (30, 2)}) == {1: (2100).to_bytes(2, "little"),
                                                           3: (2300).to_bytes(2, "little")}
        with pytest.raises(UnreachableError):
            bus.write_goal_ticks([2100, 3500, 2300])
        # the 1.0 error byte, named: a goal outside the angle limits is refused by the servo
        with pytest.raises(RigProtocolError, match="angle limit error"):
            bus.write_register(1, "Goal Position", 4000)
        # a hardware bit marks the servo (the read still ran); the poll names it
        assert bus.poll_alerts() == []
        sim.raise_hardware_error(2, "overload")
        bus.read_ticks()
        assert bus.alert_pending
        alerts = bus.poll_alerts()
        assert [(a.dxl_id, a.names, a.torque) for a in alerts] == [(2, ("overload",), False)]


def test_ax12_has_no_bulk_read_one_read_per_servo_and_a_one_turn_joint_mode():
    with open_port(AX12) as port, \
            DynamixelBus(port, _servos([1, 2], 200, 800), protocol=1.0, latency_ms=4.0) as bus:
        assert bus.read_what == "read of Present Position"
        assert bus.read_ticks().tolist() == [512, 512]  # 150° of 300°
        bus.begin_read()  # the first servo's READ; the second's in the finish
        assert bus.finish_read().tolist() == [512, 512]
        bus.configure()
        assert bus.read_register(2, "Max Position Limit") == 800
        bus.set_torque(True)
        bus.write_goal_ticks([300, 700])
        sim = port.simulator
        assert sim.wait_for(lambda: [sim.servo(i).target for i in (1, 2)] == [300, 700])
        bus.set_position_limits([0, 0], [1023, 4095])
        with pytest.raises(RigConfigError, match=r"max_ticks 0..4095 beyond its joint mode's "
                                                 r"0..1023"):
            bus.configure()


def test_an_x_series_on_protocol_type_1_keeps_its_watchdog_and_4_byte_goals():
    url = "sim://dynamixel?ids=1,2&model=XM430-W350&protocol=1&return_delay_us=0&wire_time=off"
    with open_port(url) as port, \
            DynamixelBus(port, _servos([1, 2]), protocol=1.0, latency_ms=4.0) as bus:
        sim = port.simulator
        assert [s.protocol for s in bus.found.values()] == [1.0, 1.0]
        assert bus.read_what == "bulk read of Present Position"
        bus.configure()
        assert bus.held_goals is None and any("Protocol 1.0" in a for a in bus.advice)
        assert bus.arm_watchdog(100) == 100  # Bus Watchdog (98) answers on 1.0 too
        bus.set_torque(True)
        bus.write_goal_ticks([1500, 2500])  # SYNC_WRITE of 4-byte Goal Position (116)
        assert sim.wait_for(lambda: [sim.servo(i).target for i in (1, 2)] == [1500, 2500])
        assert bus.poll_alerts() == []


def test_a_bus_of_the_other_protocol_is_one_line_naming_both():
    with open_port("sim://dynamixel?ids=1&model=MX-28&protocol=1&wire_time=off") as port:
        with pytest.raises(RigConfigError, match=r"servo ID 1 answers Protocol 1.0, the rig "
                                                 r"config says 2.0"):
            DynamixelBus(port, [1], latency_ms=2.0)


def test_a_frame_on_an_mx28_on_protocol_1_is_one_line():
    frames = (ServoFrame(), ServoFrame(homing_offset=100), ServoFrame())
    cfg = replace(load_rig_config("sim-shoulder-mx28").servos, port=MX28, frames=frames)
    with open_port(MX28) as port, pytest.raises(
            RigConfigError, match=r"servo elevation \(MX-28\) has no Homing Offset item: the "
                                  r"rig config's homing_offset: 100 cannot hold"):
        DynamixelBus(port, cfg, latency_ms=4.0)


# -- the rig configuration ---------------------------------------------------------------------
def _rig(port: str, protocol: object) -> str:
    return f"""
name: t
joint: {{name: shoulder, side: right, parent: thorax, child: humerus}}
servos:
  port: "{port}"
  protocol: {protocol}
  chain:
    - {{id: 1, axis: [0, 0, 1]}}
"""


@pytest.mark.parametrize(("port", "protocol", "message"), [
    ("/dev/ttyUSB0", "1.5", "servos.protocol: expected 1.0 or 2.0, got 1.5"),
    ("/dev/ttyUSB0", "'one'", "servos.protocol: expected 1.0 or 2.0, got 'one'"),
    ("sim://dynamixel?ids=1&model=MX-28&protocol=1", "2.0",
     "servos.protocol: 2.0, but the port 'sim://dynamixel?ids=1&model=MX-28&protocol=1' serves "
     "MX-28 on Protocol 1.0"),
    ("sim://dynamixel?ids=1&model=AX-12A", "2", "serves AX-12A on Protocol 1.0"),
    ("sim://dynamixel?ids=1&model=XM430-W350", "1.0", "serves XM430-W350 on Protocol 2.0"),
    ("sim://dynamixel?ids=1:AX-12A,2:XM430-W350", "1.0", "serves XM430-W350 (ID 2) on "
                                                         "Protocol 2.0"),
])
def test_servos_protocol_mistakes_are_one_line(port, protocol, message):
    with pytest.raises(RigConfigError) as info:
        loads_rig_config(_rig(port, protocol), "rig.yaml")
    text = str(info.value)
    assert "\n" not in text and text.startswith("rig.yaml: ") and message in text, text


def test_servos_protocol_reads():
    assert loads_rig_config(_rig("/dev/ttyUSB0", 1)).servos.protocol == 1.0
    assert loads_rig_config(_rig("sim://dynamixel?model=AX-12A", "1.0")).servos.protocol == 1.0
    assert loads_rig_config(_rig("sim://dxl?model=MX-28", 2)).servos.protocol == 2.0
    assert load_rig_config("sim-shoulder").servos.protocol == 2.0  # the default


# -- the rig's servo paths on sim-shoulder-mx28 ------------------------------------------------
@pytest.fixture(scope="module")
def mx28_path(tmp_path_factory):
    """The steps of a user's path on the shipped rig, short: scan, record (1.5 s), boundary,
    train, enforce (1 s, on the recorded session's boundary)."""
    from rig.cli import main

    d = tmp_path_factory.mktemp("mx28")
    db = d / "mx28.db"
    steps = {
        "scan": ["scan", "sim://dynamixel?ids=1,2,3&model=MX-28&protocol=1&wire_time=off",
                 "--ids", "1-4", "--baud", "1000000"],
        "record": ["record", "--rig", "sim-shoulder-mx28", "--duration", "1.5", "--db", db,
                   "--patient", "P-MX28", "--display", "plain", "--no-calibration", "--no-rom"],
        "boundary": ["boundary", "--db", db, "--session", "1", "--out", d / "b.yaml"],
        "train": ["train", "--constraint", d / "b.yaml", "--out", d / "b.onnx"],
        "enforce": ["enforce", "--rig", "sim-shoulder-mx28", "--model", d / "b.onnx",
                    "--db", db, "--session", "1", "--duration", "1", "--targets",
                    "script:adversarial", "--stale-servo-ms", "1000", "--watchdog-ms", "1000",
                    "--summary-json", d / "s.json"],
    }
    return d, steps, main


def test_scan_record_boundary_train_enforce_on_the_mx28_shoulder(mx28_path, rig_cli):
    d, steps, _ = mx28_path
    out = {}
    for name, argv in steps.items():
        code, stdout, err = rig_cli(argv)
        assert code == 0 and "Traceback" not in err, (name, stdout, err)
        out[name] = stdout + err
    rows = [ln.split() for ln in out["scan"].splitlines() if ln.strip()[:1].isdigit()]
    assert [(r[0], r[1], r[4]) for r in rows] == [(str(i), "MX-28", "1.0") for i in (1, 2, 3)]
    assert "session 1: completed" in out["record"] and "dropped 0" in out["record"]
    assert "no Bus Watchdog" in out["enforce"] and "hold their last goal" in out["enforce"]
    s = json.loads((d / "s.json").read_text())
    assert s["cycles"] > 100 and s["safe_state_entries"] == 0, s.get("safe_state_reason")
    assert s["watchdog_ms"] == 0
    assert np.isfinite(s["max_violation_deg"])
