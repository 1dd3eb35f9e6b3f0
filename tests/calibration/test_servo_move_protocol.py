"""The servo-move protocol of ``rig calibrate`` (:class:`calibration.protocol.ServoMoveProtocol`):
one single-axis move per servo, named in clinical words, inside each servo's range."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from calibration.protocol import ServoMoveProtocol, servo_movement, servo_moves
from models import quaternion as Q

X, Y, Z = (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)
ARM = [("shoulder", [("plane", Z, -180, 180), ("elevation", Y, -100, 100),
                     ("axial", X, -180, 180)]),
       ("elbow", [("elbow-flexion", Z, -10, 160), ("pronation", X, -90, 90)]),
       ("wrist", [("wrist-flexion", Z, -90, 90), ("deviation", Y, -50, 50)])]


@pytest.mark.parametrize("joint, axis, side, movement", [
    ("shoulder", Z, "right", "flexion"), ("shoulder", Y, "right", "adduction"),
    ("shoulder", X, "right", "external_rotation"), ("shoulder", Y, "left", "abduction"),
    ("elbow", Z, "right", "flexion"), ("elbow", X, "right", "supination"),
    ("wrist", Y, "right", "ulnar_deviation"), ("knee", Z, "right", "extension"),
])
def test_a_positive_turn_is_named_by_its_clinical_movement(joint, axis, side, movement):
    assert servo_movement(joint, axis, side) == movement


def test_moves_go_away_from_a_stop_and_stay_inside_the_range():
    moves = servo_moves(ARM, "right")
    assert [m.angle_deg for m in moves] == [25.0, -25.0, 25.0, 25.0, 25.0, 25.0, 25.0]
    assert moves[1].movement == "abduction"  # the hanging arm's adduction is at the trunk
    assert moves[1].words == "raise the arm sideways (abduction)"
    narrow = servo_moves([("elbow", [("flexion", Z, -30, 8), ("pronation", X, -20, 20)])])
    assert narrow[0].angle_deg == -18.0 and narrow[0].movement == "extension"
    assert narrow[1].angle_deg == 12.0
    with pytest.raises(ValueError, match=r"pronation: its range -2\.0\.\.3\.0°"):
        servo_moves([("elbow", [("pronation", X, -2, 3)])])


def test_one_servo_turns_at_a_time_and_the_protocol_crosses_a_pipe_as_json():
    p = ServoMoveProtocol(servo_moves(ARM), ("shoulder", "elbow", "wrist"), "arm",
                          static_s=2.0, move_s=1.0, hold_s=0.5, rest_s=0.5)
    assert p.period_s == 3.0 and p.duration_s == 23.0
    assert p.windows()["elevation"] == (5.0, 8.0)
    t = np.array([0.0, 1.0, 5.0 + 1.2, 8.0 + 1.2, 22.9])
    a = p.angles(t)
    assert np.count_nonzero(a) == 2 and a[2, 1] == -25.0 and a[3, 2] == 25.0
    q = p.joint_orientations(t)
    assert np.allclose(q[2, 0], Q.from_axis_angle(np.array(Y), np.radians(-25.0)))
    assert np.allclose(q[:, 1:, 0], 1.0) and np.allclose(q[[0, 1, 4], :, 0], 1.0)
    back = ServoMoveProtocol(**json.loads(json.dumps(dataclasses.asdict(p))))
    assert back == p
