"""The simulated patient performs the guided calibration protocol, then moves freely."""

from __future__ import annotations

import numpy as np
import pytest

from calibration.protocol import CalibrationProtocol
from models import quaternion as Q
from models.shapes import load_shape
from rig.errors import RigConfigError
from rig.sim.imu import stream_from_url
from rig.sim.limb import SimulatedJoint


def _angle_deg(a, b):
    return np.degrees(Q.angle(Q.multiply(Q.conjugate(a), b)))


def test_protocol_then_smooth_hand_over_to_free_motion():
    protocol = CalibrationProtocol()
    start = 2.0
    limb = SimulatedJoint(load_shape("original"), calibration_protocol=protocol,
                         protocol_start_s=start, blend_s=3.0, seed=3)
    free = SimulatedJoint(load_shape("original"), seed=3)
    assert limb.calibration_protocol is protocol and limb.protocol_start_s == start
    assert limb.protocol_end_s == pytest.approx(start + protocol.duration_s)
    # neutral pose before and during the static phase: the identity (up to the motion's
    # smoothing, which reaches two knots, 2 x smooth_s, ahead)
    m = 2.0 * limb.smooth_s
    t = np.linspace(0.0, start + protocol.static_s - m, 200)
    assert _angle_deg(limb.joint(t), np.tile(Q.IDENTITY, (len(t), 1))).max() < 1e-9
    # the scripted flexion/extension (inside this patient's range: nothing projected), up to
    # the smoothing's approximation error (~h²/6 of the angular acceleration)
    u = np.linspace(protocol.static_s + m, protocol.duration_s - m, 500)
    got = limb.joint(u + start)
    assert _angle_deg(got, protocol.joint(u)).max() < 0.2
    flex = np.degrees(protocol.flexion_angle(u))
    assert flex.max() == pytest.approx(protocol.flexion_deg, abs=0.5)
    # after the blend: exactly the free motion
    late = np.linspace(limb.protocol_end_s + 3.0 + m, limb.protocol_end_s + 60.0, 300)
    assert _angle_deg(limb.joint(late), free.joint(late)).max() < 1e-9
    # no jump anywhere: small steps at 100 Hz, also through the blend
    t = np.arange(0.0, limb.protocol_end_s + 10.0, 0.01)
    q = limb.joint(t)
    steps = _angle_deg(q[:-1], q[1:])
    assert steps.max() < 2.0


def test_protocol_pose_outside_the_range_is_projected_onto_it():
    # a cone that does not contain 15 deg of extension: the patient stops at the limit
    from models.constraint import JointConstraint

    cone = JointConstraint.cone((1.0, 0.0, 0.0), 10.0, twist=(-30.0, 30.0))
    limb = SimulatedJoint(cone, calibration_protocol=CalibrationProtocol(), seed=0)
    t = np.linspace(0.0, limb.protocol_end_s + 10.0, 2000)
    q = limb.joint(t)
    assert limb.oracle.is_valid(q).all()


def test_url_key_calibrate():
    with stream_from_url("sim://imu-stream?sensors=2&patient=original&calibrate=on"
                         "&clock=manual") as sim:
        assert isinstance(sim.limb.calibration_protocol, CalibrationProtocol)
    with stream_from_url("sim://imu-stream?sensors=2&patient=original&clock=manual") as sim:
        assert sim.limb.calibration_protocol is None
    with pytest.raises(RigConfigError, match="calibrate"):
        stream_from_url("sim://imu-stream?calibrate=maybe")
