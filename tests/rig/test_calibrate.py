"""``rig calibrate`` (issue 41): the guided calibration of the simulated 7-servo arms (in this
process, manual clock: the back-driven patient performs the servo-move protocol by itself),
every servo's direction confirmed by its own move, its file, the rig configuration naming it,
and the start-up check of the arm against it."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

from calibration.arm import load_arm_calibration
from calibration.errors import CalibrationError
from rig.devices.config import load_rig_config
from rig.devices.dynamixel import DynamixelBus
from rig.devices.ports import open_port
from rig.errors import RigConfigError
from rig.record.arm_calibration import CalibrateRequest, run_calibrate, servo_move_protocol

pytestmark = pytest.mark.xdist_group("calibrate")

ARM = load_rig_config("sim-servo-arm")
LEADER = load_rig_config("sim-leader-arm")
PORT = ARM.servos.port.replace("process=on", "process=off") + "&clock=manual&wire_time=off"
STEPS = ("zero", "directions")  # enough where the calibration is to be refused


def _in_process(config) -> str:
    return config.servos.port.replace("process=on", "process=off") + \
        "&clock=manual&wire_time=off"


def _calibrate(config, out: Path, steps=("zero", "directions", "ranges")):
    """The calibration on a manual clock, a short protocol (0.5 s moves)."""
    lines: list[str] = []
    protocol = servo_move_protocol(config, static_s=1.5, move_s=0.5, hold_s=0.3, rest_s=0.3)
    with open_port(_in_process(config), baud=config.servos.baud) as port:
        result = run_calibrate(CalibrateRequest(config, out, steps, rate_hz=20, ranges_s=3.0,
                                                lead_s=0.5, protocol=protocol),
                               echo=lines.append, port=port, wait=port.simulator.clock.advance)
    return result, lines


def _with_axes(config, **changes):
    """``config`` with servo ``k``'s fields changed (``changes``: ``{"s3": {...}}`` by
    position), its joints rebuilt from the changed servos."""
    axes = list(config.servos.axes)
    for key, fields in changes.items():
        k = int(key[1:])
        axes[k] = dataclasses.replace(axes[k], **fields)
    joints, start = [], 0
    for j in config.servos.joints:
        joints.append(dataclasses.replace(j, axes=tuple(axes[start:start + len(j.axes)])))
        start += len(j.axes)
    return dataclasses.replace(config, servos=dataclasses.replace(
        config.servos, axes=tuple(axes), joints=tuple(joints)))


def _rig_file(folder: Path, calibration: str | None = "arm-cal.yaml") -> Path:
    """The shipped arm's rig file, served in this process on a manual clock, naming
    ``calibration``."""
    from importlib import resources
    text = resources.files("rig").joinpath("configs", "sim-servo-arm.yaml").read_text()
    text = text.replace(ARM.servos.port, PORT)
    if calibration:
        text = text.replace("  watchdog_ms: 100\n",
                            f"  watchdog_ms: 100\n  calibration: {calibration}\n")
    path = folder / "arm.yaml"
    path.write_text(text)
    return path


@pytest.fixture(scope="module")
def calibrated(tmp_path_factory):
    folder = tmp_path_factory.mktemp("cal")
    result, lines = _calibrate(ARM, folder / "arm-cal.yaml")
    return folder, result, lines


def test_calibrate_writes_a_file_the_rig_loads_and_the_bus_accepts(calibrated):
    folder, result, lines = calibrated
    cal = load_arm_calibration(folder / "arm-cal.yaml")
    assert cal == dataclasses.replace(result.calibration, source=cal.source)
    assert [s.id for s in cal.servos] == list(range(1, 8)) and cal.rig == "sim-servo-arm"
    # one move per servo: every direction confirmed by its own move
    assert all(s.direction_confirmed for s in cal.servos) and not result.unconfirmed
    for s in cal.servos:
        assert s.min_ticks <= s.zero_ticks <= s.max_ticks and s.model == "XM430-W350"
        assert abs(s.zero_ticks - 2048) <= 3  # the patient's neutral pose, through the arm's IK
    assert cal.servo(4).max_ticks - cal.servo(4).min_ticks > 500  # the elbow was bent
    assert any("zero pose" in line for line in lines)
    config = load_rig_config(_rig_file(folder))
    assert config.servos.calibration is not None
    assert [a.min_ticks for a in config.servos.axes] == [s.min_ticks for s in cal.servos]
    assert config.servos.without_calibration().axes == ARM.servos.axes
    assert config.servos.limb_kinematics().joint("elbow").servos[0].max_ticks == \
        cal.servo(4).max_ticks
    with open_port(PORT, baud=1_000_000) as port, DynamixelBus(port, config.servos) as bus:
        assert len(bus.read_ticks()) == 7


@pytest.mark.parametrize("edit, words", [
    (lambda t: t.replace("note: ''", "note: ''\nnotes: hi"), "unknown key 'notes'"),
    (lambda t: t.replace("{id: 2, name: shoulder-elevation, model: XM430-W350, zero_ticks: "
                         "2048, direction: 1", "{id: 2, name: shoulder-elevation, model: "
                         "XM430-W350, zero_ticks: 2048, direction: -1"),
     "servo ID 2 (shoulder-elevation): direction -1 in the calibration, 1 in rig "
     "'sim-servo-arm'"),
])
def test_a_hand_edited_file_is_refused_in_one_line(calibrated, tmp_path, edit, words):
    folder, _, _ = calibrated
    text = (folder / "arm-cal.yaml").read_text()
    edited = edit(text)
    assert edited != text
    (tmp_path / "arm-cal.yaml").write_text(edited)
    with pytest.raises(RigConfigError) as err:
        load_rig_config(_rig_file(tmp_path))
    msg = str(err.value)
    assert words in msg and "servos.calibration" in msg and "\n" not in msg


def test_a_flipped_direction_at_the_cli_is_one_line(calibrated, tmp_path, rig_cli):
    folder, _, _ = calibrated
    text = (folder / "arm-cal.yaml").read_text()
    i = text.index("{id: 6,")
    j = text.index("direction: 1", i)
    (tmp_path / "arm-cal.yaml").write_text(text[:j] + "direction: -1" + text[j + 12:])
    rig = _rig_file(tmp_path)
    code, out, err = rig_cli(["calibrate", "--rig", str(rig), "--out",
                              str(tmp_path / "again.yaml")])[:3]
    assert code == 2 and "Traceback" not in out + err
    (line,) = [x for x in (out + err).splitlines() if x.strip()]
    assert "servo ID 6 (wrist-flexion): direction -1 in the calibration, 1 in rig" in line


def test_every_servo_of_the_leader_is_confirmed_by_its_own_move(tmp_path):
    """sim-leader-arm (its elbow- and wrist-flexion servos mounted the other way): 7 moves, 7
    directions confirmed, each prompt naming the joint, the movement and the servo."""
    result, lines = _calibrate(LEADER, tmp_path / "leader.yaml", STEPS)
    cal = result.calibration
    assert [s.direction for s in cal.servos] == [1, 1, 1, -1, 1, -1, 1]
    assert all(s.direction_confirmed for s in cal.servos) and not result.unconfirmed
    assert load_arm_calibration(tmp_path / "leader.yaml").servos == cal.servos
    moves = [x for x in result.prompts if "alone" in x]
    assert len(moves) == 7 and [x for x in lines if "alone" in x] == moves  # said, in order
    assert moves[1].startswith("shoulder: raise the arm sideways (abduction) by about 25°, "
                               "turning servo ID 2 (leader-shoulder-elevation) alone")
    assert moves[3].startswith("elbow: bend the elbow (flexion)")
    assert all("confirmed by its move" in x for x in result.lines)
    assert result.guided_s == pytest.approx(1.5 + 7 * 1.6)


def test_a_servo_that_turns_the_other_way_is_refused_naming_it(tmp_path):
    """The rig says the elbow's flexion servo turns the other way; bending the elbow turns it
    positively: refused in one line naming it."""
    config = _with_axes(ARM, s3={"direction": -1, "min_ticks": 0, "max_ticks": 4095})
    with pytest.raises(CalibrationError) as err:
        _calibrate(config, tmp_path / "x.yaml", STEPS)
    msg = str(err.value)
    assert msg.startswith("servo ID 4 (elbow-flexion) turned the other way during its move "
                          "(bend the elbow (flexion)): direction 1 measured, -1 in rig "
                          "'sim-servo-arm'"), msg
    assert "\n" not in msg and not (tmp_path / "x.yaml").exists()


def test_two_servos_ids_swapped_are_refused_naming_both(tmp_path):
    """The leader's shoulder-plane and shoulder-elevation servos' IDs swapped in the rig: the
    plane's move turns the servo the rig calls elevation, and not its own."""
    config = _with_axes(LEADER, s0={"id": 2}, s1={"id": 1})
    with pytest.raises(CalibrationError) as err:
        _calibrate(config, tmp_path / "x.yaml", STEPS)
    msg = str(err.value)
    assert msg.startswith("servo ID 1 (leader-shoulder-elevation) turned 25° during the move "
                          "of servo ID 2 (leader-shoulder-plane), which did not follow it: "
                          "are the two servos' IDs or cables swapped?"), msg
    assert "\n" not in msg and not (tmp_path / "x.yaml").exists()


def test_start_up_refuses_an_arm_re_homed_since_its_calibration(calibrated):
    folder, _, _ = calibrated
    config = load_rig_config(_rig_file(folder))
    with open_port(PORT, baud=1_000_000) as port:
        with DynamixelBus(port, [1, 2, 3, 4, 5, 6, 7]) as bare:
            bare.write_register(3, "Homing Offset", 1024)
        with pytest.raises(RigConfigError) as err:
            DynamixelBus(port, config.servos).open()
    msg = str(err.value)
    assert "servo ID 3 (shoulder-axial): Homing Offset holds 1024, the calibration" in msg
    assert "\n" not in msg
