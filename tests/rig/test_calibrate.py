"""``rig calibrate`` (issue 41): the guided calibration of the simulated 7-servo arm (in this
process, manual clock: the back-driven patient performs the protocol by itself), its file, the
rig configuration naming it, and the start-up check of the arm against it."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

from calibration.arm import load_arm_calibration
from calibration.errors import CalibrationError
from calibration.protocol import LimbCalibrationProtocol
from rig.devices.config import load_rig_config
from rig.devices.dynamixel import DynamixelBus
from rig.devices.ports import open_port
from rig.errors import RigConfigError
from rig.record.arm_calibration import CalibrateRequest, run_calibrate

pytestmark = pytest.mark.xdist_group("calibrate")

ARM = load_rig_config("sim-servo-arm")
SHIPPED = Path(ARM.source) if Path(str(ARM.source)).is_file() else None
PORT = ARM.servos.port.replace("process=on", "process=off") + "&clock=manual&wire_time=off"
PROTOCOL = LimbCalibrationProtocol("arm", static_s=2.0, movement_s=4.0, period_s=4.0)


def _calibrate(config, out: Path):
    lines: list[str] = []
    with open_port(PORT, baud=config.servos.baud) as port:
        result = run_calibrate(CalibrateRequest(config, out, rate_hz=20, ranges_s=4.0,
                                                lead_s=0.5, protocol=PROTOCOL),
                               echo=lines.append, port=port, wait=port.simulator.clock.advance)
    return result, lines


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
    # each joint's flexion turns its first servo: those directions are confirmed by the move
    assert [s.direction_confirmed for s in cal.servos] == [True, False, False, True, False,
                                                          True, False]
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


def test_a_servo_that_turns_the_other_way_is_refused_naming_it(tmp_path):
    """The rig says the elbow's flexion servo turns the other way; the patient's elbow flexion
    turns it positively: refused in one line naming it."""
    axes = list(ARM.servos.axes)
    axes[3] = dataclasses.replace(axes[3], direction=-1, min_ticks=0, max_ticks=4095)
    joints = list(ARM.servos.joints)
    joints[1] = dataclasses.replace(joints[1], axes=(axes[3], axes[4]))
    config = dataclasses.replace(ARM, servos=dataclasses.replace(
        ARM.servos, axes=tuple(axes), joints=tuple(joints)))
    with pytest.raises(CalibrationError) as err:
        _calibrate(config, tmp_path / "x.yaml")
    msg = str(err.value)
    assert msg.startswith("servo ID 4 (elbow-flexion) turned the other way during the elbow "
                          "move: direction 1 measured, -1 in rig 'sim-servo-arm'"), msg
    assert not (tmp_path / "x.yaml").exists()


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
