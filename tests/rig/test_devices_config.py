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


# ------------------------------------------------------------------ a servo limb (issue 39)
def arm() -> dict:
    return yaml.safe_load("""
name: a
limb: arm
joint: {name: shoulder, side: right, parent: thorax, child: upper-arm}
servos:
  port: "sim://dynamixel?ids=1,2,3,4,5,6,7"
  joints:
    - name: shoulder
      chain: [{id: 1, axis: [0, 0, 1]}, {id: 2, axis: [0, 1, 0]}, {id: 3, axis: [1, 0, 0]}]
    - name: elbow
      kind: forearm
      chain: [{id: 4, axis: [0, 0, 1]}, {id: 5, axis: [1, 0, 0]}]
    - name: wrist
      chain: [{id: 6, axis: [0, 0, 1]}, {id: 7, axis: [0, 1, 0]}]
""")


def test_servo_limb_lists_its_joints_in_the_limbs_order():
    cfg = parse(arm())
    assert cfg.limb == "arm" and cfg.sensors is None
    s = cfg.servos
    assert s.joint_names == ("shoulder", "elbow", "wrist")
    assert [j.kind for j in s.joints] == ["ball", "forearm", "two-axis"]
    assert s.ids == tuple(range(1, 8)) and len(s.bus_servos()) == 7
    kin = s.limb_kinematics()
    assert kin.names == s.joint_names and kin.n == 7
    assert [kin.joint(k).n for k in range(3)] == [3, 2, 2]
    with pytest.raises(RigConfigError, match="limb kinematics"):
        s.kinematics()


def test_one_joint_rig_is_a_limb_of_one_joint_unchanged():
    s = load_rig_config("sim-shoulder").servos
    assert s.joints == () and s.joint_names == ("joint",)
    assert s.limb_kinematics().names == ("joint",)
    assert s.limb_kinematics("shoulder").names == ("shoulder",)


def test_shipped_servo_arms_load():
    for name in ("sim-servo-arm", "hardware-servo-arm-template"):
        cfg = load_rig_config(name)
        assert cfg.limb == "arm" and cfg.servos.ids == tuple(range(1, 8))
        assert [j.kind for j in cfg.servos.joints] == ["ball", "forearm", "two-axis"]


def _joints(d):
    return d["servos"]["joints"]


@pytest.mark.parametrize(("edit", "match"), [
    (lambda d: _joints(d)[1].update(knd="forearm"), r"joints\[1\]: unknown key 'knd'"),
    (lambda d: _joints(d)[2]["chain"][0].update(id=1), "servos.joints: duplicate ID 1"),
    (lambda d: _joints(d).reverse(), r"joints\[0\].name: the arm's joints are shoulder, "
                                     r"elbow, wrist, in that order; got 'wrist'"),
    (lambda d: _joints(d)[1].update(name="knee"), r"got 'knee' at position 2"),
    (lambda d: _joints(d).pop(), "the arm has 3 joints .* got 2"),
    (lambda d: _joints(d)[1].pop("kind"), r"joints\[1\].chain: a hinge has 1 servo, got 2"),
    (lambda d: _joints(d)[0]["chain"].pop(), r"joints\[0\].chain: a ball joint has 3 servos, "
                                             r"got 2"),
    (lambda d: _joints(d)[0].update(kind="hinge"), r"joints\[0\].kind: the shoulder cannot "
                                                   r"be a hinge"),
    (lambda d: _joints(d)[1].update(kind="elbowish"), r"joints\[1\].kind: expected one of"),
    (lambda d: d.pop("limb"), "a servo limb needs 'limb: arm'"),
    (lambda d: d["servos"].update(chain=[{"id": 1, "axis": [0, 0, 1]}]),
     "needs either 'chain' .* or 'joints'"),
])
def test_servo_limb_errors_name_what_is_wrong(edit, match):
    d = arm()
    edit(d)
    with pytest.raises(RigConfigError, match=match):
        parse(d)


def test_a_limb_rig_with_one_joints_chain_is_refused():
    d = arm()
    d["servos"].pop("joints")
    d["servos"]["chain"] = [{"id": 1, "axis": [0, 0, 1]}]
    with pytest.raises(RigConfigError, match="servos are listed per joint"):
        parse(d)
