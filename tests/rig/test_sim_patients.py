"""The simulated-patient factory (``rig.sim.patients``): reproducible patients, the same patient
as the ``sim://imu-stream`` port string describes, and the two offline recordings."""

from __future__ import annotations

import math

import numpy as np

from models import quaternion as Q
from models.constraint import dump_constraint
from models.oracle import ConstraintOracle
from rig.sim import from_url
from rig.sim.limb import (
    NoiseModel,
    SimulatedJoint,
    SimulatedLimb,
    SimulatedWholeLimb,
    misplaced_mounts,
)
from rig.sim.patients import (
    anatomical_limb,
    record_imu,
    record_servo,
    seeded_patient,
    star_constraint,
)


def test_star_constraint_is_seeded_and_keeps_the_neutral_pose_inside():
    a, b = star_constraint(5), star_constraint(5)
    assert a.to_dict() == b.to_dict() and a.name == "star-5"
    assert star_constraint(6).to_dict() != a.to_dict()
    for seed in range(20):
        c = star_constraint(seed)
        tilt = math.degrees(math.acos(np.clip(c.swing.interior[0], -1.0, 1.0)))
        assert tilt <= 10.0 + 1e-9
        assert c.twist.min_deg < 0.0 < c.twist.max_deg
        assert ConstraintOracle(c).is_valid(np.array(Q.IDENTITY)).all()  # neutral pose


def test_seeded_patient_is_the_patient_of_the_port_string(tmp_path):
    c = star_constraint(3)
    path = tmp_path / "p.yaml"
    dump_constraint(c, path)
    url = (f"sim://imu-stream?sensors=2&patient={path}&seed=3&misplace_deg=25&calibrate=on"
           "&clock=manual")
    with from_url(url) as sim:  # a manual clock: the device does not run
        port = sim.limb
    limb = seeded_patient(3, c, misplace_deg=25.0, protocol_start_s=port.protocol_start_s)
    assert [m.mount for m in limb.mounts] == [m.mount for m in port.mounts]
    t = np.linspace(0.0, 60.0, 300)
    np.testing.assert_allclose(limb.joint(t), port.joint(t), atol=1e-12)
    # each strap is turned misplace_deg off its nominal mounting
    nominal = misplaced_mounts(np.random.default_rng([3, 0x5EA7]), 0.0)
    for m, n in zip(limb.mounts, nominal, strict=True):
        ang = math.degrees(Q.angle(Q.multiply(Q.conjugate(np.array(n.mount)), m.mount)))
        assert abs(ang - 25.0) < 1e-9


def test_offline_recordings_follow_the_truth():
    c = star_constraint(4)
    servo = record_servo(seeded_patient(4, c), 10.0, rate_hz=20.0)
    assert len(servo.t) == round((5.0 + servo.protocol.duration_s + 10.0) * 20.0)
    err = np.degrees(Q.angle(Q.multiply(servo.limb, Q.conjugate(servo.truth))))
    assert err.max() < 3 * 360.0 / 4096  # three encoders, each off by at most half a tick
    assert servo.window("static").sum() > 0 and servo.window("free")[-1]
    limb = seeded_patient(4, c, noise=NoiseModel.ideal(), sway_deg=0.0)
    imu = record_imu(limb, 5.0, rate_hz=20.0, chunk=64)
    np.testing.assert_allclose(imu.truth, limb.joint(imu.t), atol=1e-12)
    # no sensor errors: thorax* ⊗ limb sensor = joint ⊗ (thorax mount* ⊗ limb mount) changes
    # only with the joint
    rel = Q.multiply(Q.conjugate(imu.thorax), imu.limb)
    m0, m1 = (np.array(m.mount) for m in limb.mounts)
    want = Q.multiply(Q.multiply(Q.conjugate(m0), imu.truth), m1)
    assert np.degrees(Q.angle(Q.multiply(rel, Q.conjugate(want)))).max() < 1e-6
    assert np.all(imu.status >> 6 == 3)  # ideal sensors: calibrated from the start


def test_one_factory_for_a_joint_and_a_whole_limb():
    """``seeded_patient``: a joint's constraint gives a limb of one joint, an arm or a leg (or a
    limb file's Limb) a whole limb — both simulated limbs, both seeded alike."""
    joint = seeded_patient(8, star_constraint(8), noise=NoiseModel.ideal(), calibrate=False)
    arm = seeded_patient(8, "arm", noise=NoiseModel.ideal(), calibrate=False)
    again = seeded_patient(8, anatomical_limb(8, "arm"), noise=NoiseModel.ideal(),
                           calibrate=False)
    assert isinstance(joint, SimulatedJoint) and isinstance(arm, SimulatedWholeLimb)
    assert isinstance(joint, SimulatedLimb) and isinstance(arm, SimulatedLimb)
    assert joint.n_sensors == 2 and arm.n_sensors == 4
    assert joint.calibration_protocol is None and arm.calibration_protocol is None
    t = np.arange(0.0, 5.0, 0.1)
    assert np.array_equal(arm.truth(t).joints, again.truth(t).joints)
    m = joint.measure_many(t[:3]) + arm.measure_many(t[:3])
    assert [x.truth.sensors.shape for x in m] == [(1, 2, 4)] * 3 + [(1, 4, 4)] * 3
