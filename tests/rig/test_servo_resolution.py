"""Each servo's own resolution: AX-12A (1228.8 ticks per turn over 0..1023), P-series
(PH54-200-S500: 1,003,846 per turn over ±501,923) and X series (4096) through the kinematics,
the rig configuration, the backstop, the calibration and the back-driven simulated patient."""

from __future__ import annotations

import math

import numpy as np
import pytest

from calibration.servo import ServoChainCalibration, chain_forward
from firmware_protocol.dynamixel import load_control_table
from models import quaternion as Q
from rig.devices.config import (
    ServoFrame,
    ServosConfig,
    resolution_mismatch,
    servo_position_defaults,
)
from rig.devices.kinematics import (
    NEAREST_TOLERANCE_DEG,
    RAD_PER_TICK,
    JointKinematics,
    LimbKinematics,
    ServoAxis,
    rad_per_tick,
)
from rig.errors import RigConfigError, UnreachableError
from rig.loop.backstop import describe_limits, position_limits_from_boundary

AXES = ((0.0, 0.0, 1.0), (0.0, 1.0, 0.0), (1.0, 0.0, 0.0))
AX = servo_position_defaults("AX-12A", 1.0)
PH = servo_position_defaults("PH54-200-S500")


def chain(d, n=3, **kw) -> JointKinematics:
    """A Z-Y-X chain of ``n`` servos with the model defaults ``d``."""
    return JointKinematics([ServoAxis(i + 1, AXES[i], d.zero_ticks, 1, d.min_ticks, d.max_ticks,
                                      ticks_per_rev=d.ticks_per_rev) for i in range(n)], **kw)


def test_model_defaults_come_from_the_control_tables():
    assert (AX.ticks_per_rev, AX.min_ticks, AX.max_ticks, AX.zero_ticks) == (1228.8, 0, 1023, 512)
    assert (PH.ticks_per_rev, PH.min_ticks, PH.max_ticks, PH.zero_ticks) == \
        (1_003_846.0, -501_923, 501_923, 0)
    x = servo_position_defaults("XM430-W350")
    assert (x.ticks_per_rev, x.min_ticks, x.max_ticks, x.zero_ticks) == (4096.0, 0, 4095, 2048)
    assert servo_position_defaults(None).ticks_per_rev == 4096.0
    # the X series' factor is exactly the old constant (bit for bit)
    assert rad_per_tick(4096.0) == RAD_PER_TICK and ServoAxis(1, AXES[0]).ticks_per_rev == 4096


@pytest.mark.parametrize("d, span_deg", [(AX, 140.0), (PH, 175.0)])
def test_fk_ik_round_trip_in_each_servos_own_ticks(d, span_deg):
    kin = chain(d).compile()
    rng = np.random.default_rng(40)
    theta = np.radians(rng.uniform(-span_deg, span_deg, (200, 3)))
    theta[:, 1] = np.radians(rng.uniform(-80.0, 80.0, 200))  # away from the gimbal lock
    ticks = d.zero_ticks + theta / rad_per_tick(d.ticks_per_rev)
    q = kin.forward_batch(ticks)
    for qi, ti in zip(q, ticks, strict=True):
        assert np.allclose(kin.forward(ti), qi, atol=1e-12)
        back = kin.inverse_float(qi, ti)
        assert np.allclose(back, ti, atol=1e-6 * d.ticks_per_rev / 4096)
        assert ((back >= d.min_ticks) & (back <= d.max_ticks)).all()
    # one tick is 2π / T of joint angle
    one = kin.forward([d.zero_ticks + 1, d.zero_ticks, d.zero_ticks])
    assert math.isclose(Q.angle(one[None])[0], 2 * math.pi / d.ticks_per_rev, rel_tol=1e-6)


def test_the_nearest_turn_never_leaves_an_ax_servos_300_degrees():
    kin = chain(AX, n=1, tolerance_deg=NEAREST_TOLERANCE_DEG)
    reach = math.degrees(AX.max_ticks + 0.5 - AX.zero_ticks) * 2 * math.pi / AX.ticks_per_rev
    for near in (0, 300, 512, 900, 1023):
        for deg in np.linspace(-179.5, 179.5, 72):
            q = Q.from_axis_angle(np.array(AXES[0]), math.radians(deg))
            if abs(deg) <= 149.0:
                t = kin.inverse_float(q, [near])[0]
                assert -0.5 <= t <= 1023.5  # within half a tick of the range
                assert math.isclose(t, AX.zero_ticks + math.radians(deg) / rad_per_tick(1228.8),
                                    abs_tol=1e-6)  # the only turn inside the range
            elif abs(deg) > reach:
                with pytest.raises(UnreachableError, match=r"mod 1228\.8\), outside its "
                                                           r"limits 0\.\.1023"):
                    kin.inverse(q, [near])
    # an X series' servo reaches the whole turn
    xs = JointKinematics([ServoAxis(1, AXES[0])], tolerance_deg=NEAREST_TOLERANCE_DEG)
    q = Q.from_axis_angle(np.array(AXES[0]), math.radians(170.0))
    assert xs.inverse(q, [2048])[0] == 2048 + round(170 / 360 * 4096)


def test_limb_kinematics_concatenates_the_resolutions():
    x = servo_position_defaults("XM430-W350")
    elbow = JointKinematics([ServoAxis(4, AXES[1], 512, 1, 0, 1023, ticks_per_rev=1228.8)])
    limb = LimbKinematics([chain(x), elbow], ["shoulder", "elbow"])
    assert limb.ticks_per_rev.tolist() == [4096.0, 4096.0, 4096.0, 1228.8]
    assert limb.rad_per_tick[0] == RAD_PER_TICK
    q = limb.forward([2048, 2048, 2048, 512 + 307.2])  # a quarter turn of the AX
    assert np.allclose(q[1], Q.from_axis_angle(np.array(AXES[1]), math.pi / 2), atol=1e-12)
    assert limb.with_limits(limb.min_ticks, limb.max_ticks).ticks_per_rev[3] == 1228.8


def _rig(tmp_path, chain_yaml: str, model: str | None = "AX-12A", extra: str = "") -> str:
    model_line = f"  model: {model}\n" if model else ""
    text = ("name: t\njoint: {name: shoulder, side: right, parent: thorax, child: humerus}\n"
            "servos:\n  port: \"sim://dynamixel?ids=1,2,3\"\n" + model_line + extra
            + "  chain:\n" + chain_yaml)
    path = tmp_path / "rig.yaml"
    path.write_text(text)
    return str(path)


CHAIN3 = ("    - {id: 1, axis: [0, 0, 1]}\n    - {id: 2, axis: [0, 1, 0]}\n"
          "    - {id: 3, axis: [1, 0, 0]}\n")


@pytest.mark.parametrize("model, want", [
    ("AX-12A", (1228.8, 0, 1023, 512)),
    ("PH54-200-S500", (1_003_846.0, -501_923, 501_923, 0)),
    ("XM430-W350", (4096.0, 0, 4095, 2048)),
    (None, (4096.0, 0, 4095, 2048)),
])
def test_config_defaults_each_servo_from_the_model(tmp_path, model, want):
    from rig.devices.config import load_rig_config

    cfg = load_rig_config(_rig(tmp_path, CHAIN3, model))
    for a in cfg.servos.axes:
        assert (a.ticks_per_rev, a.min_ticks, a.max_ticks, a.zero_ticks) == want
    assert cfg.servos.limb_kinematics().ticks_per_rev.tolist() == [want[0]] * 3


def test_config_ticks_per_rev_given_agrees_with_the_model_or_is_one_line(tmp_path):
    from rig.devices.config import load_rig_config

    ok = "    - {id: 1, axis: [0, 0, 1], ticks_per_rev: 1228.8}\n"
    assert load_rig_config(_rig(tmp_path, ok)).servos.axes[0].ticks_per_rev == 1228.8
    bad = "    - {id: 1, axis: [0, 0, 1], ticks_per_rev: 4096}\n"
    with pytest.raises(RigConfigError) as err:
        load_rig_config(_rig(tmp_path, bad))
    msg = str(err.value)
    assert "\n" not in msg and "servos.chain[0].ticks_per_rev: 4096 differs from the AX-12A's " \
                               "1228.8 ticks per revolution" in msg
    # without a model any positive resolution is the servo's own
    own = "    - {id: 1, axis: [0, 0, 1], ticks_per_rev: 1228.8, zero_ticks: 512}\n"
    assert load_rig_config(_rig(tmp_path, own, None)).servos.axes[0].ticks_per_rev == 1228.8
    for text, match in ((bad.replace("4096", "0"), "must be > 0"),
                        (bad.replace("4096", "fast"), "expected a number")):
        with pytest.raises(RigConfigError, match=match):
            load_rig_config(_rig(tmp_path, text, None))
    with pytest.raises(RigConfigError, match=r"servos\.model: unknown Dynamixel model 'AX-99'"):
        load_rig_config(_rig(tmp_path, CHAIN3, "AX-99"))


def test_resolution_mismatch_names_the_servo_and_both_values():
    axes = tuple(ServoAxis(i + 1, AXES[i], 512, 1, 0, 1023, ticks_per_rev=1228.8)
                 for i in range(3))
    servos = ServosConfig(port="", axes=axes, model="AX-12A")
    ax = load_control_table("AX-12A", 1.0)
    assert resolution_mismatch(servos, {1: ax, 2: ax.model_number, 3: "AX-18A"}) is None
    assert resolution_mismatch(servos, {}) is None  # missing servos: the bus's own check
    xm = load_control_table("XM430-W350")
    why = resolution_mismatch(servos, {1: ax, 2: xm})
    assert why == ("servo ID 2 is an XM430-W350 (4096 ticks per revolution) but the rig config "
                   "gives it 1228.8: set servos.model (or its ticks_per_rev) to the servos' "
                   "model")

    class Info:  # what DynamixelBus.found holds: a ServoInfo's model number and protocol
        model_number = ax.model_number
        protocol = 1.0

    assert resolution_mismatch(servos, {3: Info()}) is None


def test_backstop_margins_and_description_in_each_servos_ticks():
    kin = chain(AX, n=1, tolerance_deg=NEAREST_TOLERANCE_DEG)

    class Disc:  # a ±60° range about the zero
        def evaluate(self, q):
            from types import SimpleNamespace
            ang = Q.twist_angle(q, np.array(AXES[0]))
            valid = np.abs(ang) <= math.radians(60.0)
            proj = Q.from_axis_angle(np.array(AXES[0]), np.clip(ang, -math.radians(60.0),
                                                                math.radians(60.0)))
            return SimpleNamespace(valid=valid, projected=proj)

    lo, hi = position_limits_from_boundary(kin, Disc(), [512], n=400, margin_deg=5.0)
    per_deg = 1228.8 / 360.0
    assert abs(lo[0] - (512 - 65 * per_deg)) <= 2 and abs(hi[0] - (512 + 65 * per_deg)) <= 2
    assert describe_limits(kin, [0], [1023]) == "ID 1 0..1023 (299.7°)"


def test_calibration_with_each_joints_own_resolution():
    tpr = [1228.8, 4096.0]
    rng = np.random.default_rng(7)
    ticks = np.column_stack([rng.uniform(200, 800, 12), rng.uniform(1000, 3000, 12)])
    zero, direction = [500.0, 2100.0], [1, -1]
    poses = chain_forward(np.array(AXES[:2]), ticks, zero, direction, tpr)
    cal = ServoChainCalibration(np.array(AXES[:2]), ticks_per_rev=tpr).fit(ticks, poses)
    assert np.allclose(cal.zero_ticks_, zero, atol=1e-6) and cal.direction_.tolist() == direction
    assert cal.residual_deg_ < 1e-6 and cal.to_dict()["ticks_per_rev"] == tpr
    x_ticks = np.column_stack([rng.uniform(1000, 3000, 12), rng.uniform(1000, 3000, 12)])
    x_poses = chain_forward(np.array(AXES[:2]), x_ticks, [2048, 2048], [1, 1])
    x_cal = ServoChainCalibration(np.array(AXES[:2])).fit(x_ticks, x_poses)
    assert "ticks_per_rev" not in x_cal.to_dict()  # an X-series record reads as before
    with pytest.raises(ValueError, match="one per joint"):
        ServoChainCalibration(np.array(AXES[:2]), ticks_per_rev=[4096.0])


def test_offline_servo_recording_at_an_ax_resolution():
    from rig.sim.patients import record_servo, seeded_patient, star_constraint

    limb = seeded_patient(3, star_constraint(3))
    x = record_servo(limb, 4.0, 20.0)
    ax = record_servo(limb, 4.0, 20.0, ticks_per_rev=1228.8)
    err_x = np.degrees(Q.angle(Q.multiply(x.limb, Q.conjugate(x.truth))))
    err_ax = np.degrees(Q.angle(Q.multiply(ax.limb, Q.conjugate(ax.truth))))
    step_ax = 360.0 / 1228.8
    assert err_x.max() < 3 * 360.0 / 4096 and err_ax.max() < 3 * step_ax
    assert err_ax.max() > err_x.max()  # coarser encoders, coarser readings


def test_back_driven_patient_on_an_ax_chain_reads_the_joint(tmp_path):
    """An AX-12A chain (Protocol 1.0 servos) back-driven by the patient through its own
    kinematics: the shafts' ticks, read through that chain's forward kinematics, are the
    patient's joint to the AX's resolution."""
    from rig.devices.config import load_rig_config
    from rig.devices.ports import open_port

    path = _rig(tmp_path, CHAIN3)
    url = f"sim://dynamixel?ids=1,2,3&model=AX-12A&patient=original&chain={path}&seed=1"
    kin = load_rig_config(path).servos.kinematics()
    with open_port(url + "&clock=manual&wire_time=off") as port:
        bus, sp = port.simulator, port.simulated_patient
        seen = []
        for _ in range(6):
            bus.clock.advance(0.5)
            ticks = np.array([bus.position(i) for i in (1, 2, 3)])
            assert ((ticks >= 0) & (ticks <= 1023)).all()
            truth = sp.limb.joint(np.array([sp.now()]))[0]
            q = kin.forward(np.rint(ticks))
            seen.append(float(np.degrees(Q.angle(Q.multiply(q, Q.conjugate(truth))))))
        assert max(seen) < 3 * 360.0 / 1228.8  # three joints, half a tick each at most ×2


def test_the_hand_writes_actual_ticks_through_the_configured_frame(tmp_path):
    from rig.devices.config import load_rig_config
    from rig.devices.ports import open_port

    framed = ("    - {id: 1, axis: [0, 0, 1], homing_offset: 100, reverse: true, "
              "zero_ticks: 1500, min_ticks: -1000, max_ticks: 4000}\n"
              "    - {id: 2, axis: [0, 1, 0]}\n    - {id: 3, axis: [1, 0, 0]}\n")
    path = _rig(tmp_path, framed, "XM430-W350")
    servos = load_rig_config(path).servos
    assert servos.frame(0) == ServoFrame(100, True)
    kin = servos.kinematics()
    url = f"sim://dynamixel?ids=1,2,3&patient=original&chain={path}&seed=1"
    with open_port(url + "&clock=manual&wire_time=off") as port:
        bus, sp = port.simulator, port.simulated_patient
        bus.clock.advance(1.0)
        actual = np.array([bus.position(i) for i in (1, 2, 3)])
        present = actual.copy()
        present[0] = -actual[0] + 100  # Present Position = −actual + Homing Offset
        truth = sp.limb.joint(np.array([sp.now()]))[0]
        q = kin.forward(present)
        assert float(np.degrees(Q.angle(Q.multiply(q, Q.conjugate(truth))))) < 1e-6


def test_the_rig_bus_on_an_ax_chain_and_a_config_that_forgets_the_model(tmp_path):
    """The rig's servo bus on three AX-12A (Protocol 1.0, 1228.8 ticks per turn): with
    ``model: AX-12A`` it opens and reads ticks within the AX's 0..1023; without a model the
    chain defaults to the X series' 4096 ticks per turn, which would turn every angle wrong:
    refused at open, one line naming the servo, its model and both resolutions."""
    from rig.devices.config import loads_rig_config
    from rig.devices.dynamixel import DynamixelBus
    from rig.devices.ports import open_port

    url = "sim://dynamixel?ids=1,2,3&model=AX-12A"
    head = ("name: t\njoint: {name: shoulder, side: right, parent: thorax, child: humerus}\n"
            f"servos:\n  port: \"{url}\"\n  protocol: 1.0\n")
    good = loads_rig_config(head + "  model: AX-12A\n  chain:\n" + CHAIN3).servos
    bad = loads_rig_config(head + "  chain:\n" + CHAIN3).servos
    with open_port(url + "&clock=manual&wire_time=off", baud=good.baud) as port:
        bus = DynamixelBus(port, good)
        try:
            ticks = bus.read_ticks()
            assert ticks.tolist() == [512, 512, 512]  # the AX's centre (150°)
            assert good.kinematics().forward(ticks).tolist() == pytest.approx([1, 0, 0, 0])
        finally:
            bus.close()
        with pytest.raises(RigConfigError) as exc:
            DynamixelBus(port, bad)
    msg = str(exc.value)
    assert "\n" not in msg and "AX-12A (1228.8 ticks per revolution)" in msg
    assert "gives it 4096" in msg


def test_configure_writes_a_p_series_servos_signed_position_limits():
    """A PH54-200-S500 chain at its default tick range (±501,923, its own position-limit
    items' range): position mode and the limits written and read back, not the extended
    position mode an X-series range test would pick."""
    from rig.devices.config import loads_rig_config
    from rig.devices.dynamixel import DynamixelBus
    from rig.devices.ports import open_port

    url = "sim://dynamixel?ids=1,2,3&model=PH54-200-S500"
    servos = loads_rig_config(
        "name: t\njoint: {name: shoulder, side: right, parent: thorax, child: humerus}\n"
        f"servos:\n  port: \"{url}\"\n  model: PH54-200-S500\n  chain:\n" + CHAIN3).servos
    with open_port(url + "&clock=manual&wire_time=off", baud=servos.baud) as port:
        bus = DynamixelBus(port, servos)
        try:
            bus.configure()
            for i in (1, 2, 3):
                assert bus.read_register(i, "Operating Mode") == 3
                assert bus.read_register(i, "Min Position Limit") == -501_923
                assert bus.read_register(i, "Max Position Limit") == 501_923
            assert bus.read_ticks().tolist() == [0, 0, 0]  # P-series power on at 0
        finally:
            bus.close()
