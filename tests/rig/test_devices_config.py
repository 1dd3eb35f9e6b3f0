"""Rig configuration files: shipped configs load; every level rejects unknown keys by name."""

from __future__ import annotations

import pytest
import yaml

from rig.devices.config import load_rig_config, loads_rig_config, rig_config_names
from rig.errors import RigConfigError


def test_shipped_configs_load():
    assert {"sim-shoulder", "sim-imu", "hardware-template"} <= set(rig_config_names())
    shoulder = load_rig_config("sim-shoulder")
    assert shoulder.servos.ids == (1, 2, 3) and shoulder.sensors is None
    assert shoulder.load_constraint().name == "original"
    assert shoulder.servos.kinematics().n == 3
    imu = load_rig_config("sim-imu")
    assert imu.sensors.segments == {"thorax": 0, "humerus": 1} and imu.sensors.rate_hz == 200
    hw = load_rig_config("hardware-template")
    assert hw.servos.port.startswith("/dev/") and hw.sensors.protocol == "stream"


def base() -> dict:
    return yaml.safe_load("""
name: t
joint: {name: shoulder, side: right, parent: thorax, child: humerus}
sensors:
  port: "sim://imu-stream?sensors=2"
  segments: {thorax: 0, humerus: 1}
servos:
  port: "sim://dynamixel?ids=1,2"
  chain:
    - {id: 1, axis: [0, 0, 1]}
    - {id: 2, axis: [0, 1, 0]}
""")


def parse(d):
    return loads_rig_config(yaml.safe_dump(d), "t.yaml")


def test_minimal_config_gets_defaults():
    cfg = parse(base())
    assert cfg.servos.baud == 1_000_000 and cfg.servos.watchdog_ms == 100
    assert cfg.servos.axes[0].zero_ticks == 2048 and cfg.sensors.protocol == "stream"
    assert cfg.sensors.raw is False


def test_sensors_raw_is_a_boolean():
    d = base()
    d["sensors"]["raw"] = True
    assert parse(d).sensors.raw is True
    assert load_rig_config("sim-imu").sensors.raw is True


@pytest.mark.parametrize(("edit", "match"), [
    (lambda d: d.update(servo={}), "top level: unknown key 'servo'"),
    (lambda d: d["joint"].update(sid="left"), "joint: unknown key 'sid'"),
    (lambda d: d["sensors"].update(rate=100), "sensors: unknown key 'rate'"),
    (lambda d: d["servos"].update(watchdog=1), "servos: unknown key 'watchdog'"),
    (lambda d: d["servos"]["chain"][1].update(zero=0), r"servos.chain\[1\]: unknown key 'zero'"),
    (lambda d: d["servos"]["chain"][1].update(id=1), "duplicate ID 1"),
    (lambda d: d["servos"]["chain"][1].update(axis=[0, 0, 3]), "parallel"),
    (lambda d: d["servos"].update(baud=12345), "not an X-series rate"),
    (lambda d: d["servos"].update(return_delay_us=3), "even"),
    (lambda d: d["joint"].update(side="up"), "joint.side"),
    (lambda d: d["sensors"].update(segments={"thorax": 0}), "no sensor for segment 'humerus'"),
    (lambda d: d["sensors"].update(segments={"thorax": 0, "humerus": 0}), "share"),
    (lambda d: d.pop("joint"), "missing required key 'joint'"),
    (lambda d: (d.pop("sensors"), d.pop("servos")), "needs 'sensors' or 'servos'"),
    (lambda d: d.update(constraint="nowhere.yaml"), "constraint"),
    (lambda d: d["servos"]["chain"][0].update(id=True), "whole number"),
    (lambda d: d["sensors"].update(raw="on"), "sensors.raw: expected true or false, got 'on'"),
    (lambda d: d["sensors"].update(raw=1), "sensors.raw: expected true or false"),
    (lambda d: d["sensors"].update(raws=True), "sensors: unknown key 'raws'"),
    (lambda d: d["sensors"].update(raw=True, segments={f"s{i}": i for i in range(7)}
                                   | {"thorax": 7, "humerus": 8}), "at most 8 sensors"),
])
def test_invalid_configs_name_the_field(edit, match):
    d = base()
    edit(d)
    with pytest.raises(RigConfigError, match=match) as info:
        parse(d)
    assert str(info.value).startswith("t.yaml: ")


def test_unknown_name_lists_the_shipped_configs(tmp_path):
    with pytest.raises(RigConfigError, match=r"shipped: .*sim-imu"):
        load_rig_config("sim-elbow")
    with pytest.raises(RigConfigError, match="no such rig config file"):
        load_rig_config(tmp_path / "missing.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: [unclosed\n")
    with pytest.raises(RigConfigError, match="not valid YAML"):
        load_rig_config(bad)


def test_the_constraint_must_be_one_the_rigs_joint_can_have(tmp_path):
    """Issue 37, case 2: a leg rig took a shoulder file or an arm limb file as ``constraint``."""
    files = {
        "knee.yaml": "name: k\nkind: hinge\njoint: knee\nhinge: {axis: [0, 0, -1], min_deg: 0, "
                     "max_deg: 140}\n",
        "hinge.yaml": "name: h\nkind: hinge\nhinge: {axis: [0, 0, 1], min_deg: 0, "
                      "max_deg: 140}\n",
        "left.yaml": "name: l\nside: left\nswing: {cone: {centre: [1, 0, 0], radius_deg: 40}}\n",
        "arm.yaml": "name: a\nlimb: arm\njoints:\n- {name: shoulder, parent: thorax, child: "
                    "upper-arm, constraint: {swing: {cone: {centre: [1, 0, 0], "
                    "radius_deg: 40}}}}\n",
        "fine.yaml": "name: s\njoint: shoulder\nside: right\nswing: {cone: {centre: [1, 0, 0], "
                     "radius_deg: 40}}\n",
    }
    for name, text in files.items():
        (tmp_path / name).write_text(text)
    for name, match in (("knee.yaml", "is for the knee, not the shoulder"),
                        ("hinge.yaml", "holds hinge limits, but the shoulder is a ball joint"),
                        ("left.yaml", "is for the left side, not the right"),
                        ("arm.yaml", "a limb file .*not one joint's constraint file")):
        d = base()
        d["constraint"] = str(tmp_path / name)
        with pytest.raises(RigConfigError, match=match) as info:
            parse(d)
        assert str(info.value).startswith("t.yaml: constraint: ")
    d = base()
    d["constraint"] = str(tmp_path / "fine.yaml")
    assert parse(d).constraint == str(tmp_path / "fine.yaml")
    d = base()
    d["joint"].update(name="knee", parent="thigh", child="shank")
    d["sensors"]["segments"] = {"thigh": 0, "shank": 1}
    d["constraint"] = "original"  # a shipped shape is a ball joint's swing region
    with pytest.raises(RigConfigError, match="the knee is a hinge joint"):
        parse(d)


@pytest.mark.parametrize(("edit", "match"), [
    ({"parent": "pelvis", "child": "femur_r"},
     "joint: segment 'pelvis' is a pelvis, not the thorax of the right shoulder"),
    ({"child": "humerus_l"},
     "joint: segment 'humerus_l' is a left segment, but the right side is asked"),
])
def test_joint_segments_named_for_another_joint_or_side_are_refused(edit, match):
    d = base()
    d["joint"].update(edit)
    d["sensors"]["segments"] = {d["joint"]["parent"]: 0, d["joint"]["child"]: 1}
    with pytest.raises(RigConfigError, match=match):
        parse(d)
