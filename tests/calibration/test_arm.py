"""A servo's direction from its own move (:func:`calibration.arm.direction_from_servo_move`),
on synthetic ticks: confirmed, and each refusal one line naming the servo(s)."""

from __future__ import annotations

import numpy as np
import pytest

from calibration.arm import direction_from_servo_move
from calibration.errors import CalibrationError

LABELS = ["servo ID 1 (a)", "servo ID 2 (b)", "servo ID 3 (c)"]
TPR = np.full(3, 4096.0)
ZERO = np.full(3, 2048)
ASKED = np.radians(25.0) * np.sin(np.linspace(0.0, np.pi, 50))  # out and back


def _ticks(turns) -> np.ndarray:
    """Ticks (50, 3): servo j turning ``turns[j]`` times the asked move (plus a little noise)."""
    rng = np.random.default_rng(4)
    t = ZERO + np.outer(ASKED, turns) * 4096 / (2 * np.pi)
    return np.rint(t + rng.normal(0.0, 0.5, t.shape))


def _judge(turns, directions=(1, 1, 1)):
    return direction_from_servo_move(1, ASKED, _ticks(turns), ZERO, TPR, directions, LABELS,
                                     rig="'r'")


def test_a_servo_turned_as_asked_alone_is_confirmed():
    found = _judge([0.0, 0.9, 0.02])
    assert found.direction == 1 and found.asked_deg == pytest.approx(25.0, abs=0.1)
    assert found.moved_deg == pytest.approx(22.5, abs=0.3)
    assert _judge([0.0, -1.0, 0.0], (1, -1, 1)).direction == -1


@pytest.mark.parametrize("turns, directions, words", [
    ([0.0, -1.0, 0.0], (1, 1, 1), "servo ID 2 (b) turned the other way during its move: "
                                  "direction -1 measured, 1 in rig 'r'"),
    ([0.0, 0.2, 0.0], (1, 1, 1), "servo ID 2 (b) did not follow its move: it turned 5."),
    ([1.0, 0.0, 0.0], (1, 1, 1), "servo ID 1 (a) turned 25° during the move of servo ID 2 (b), "
                                 "which did not follow it: are the two servos' IDs or cables "
                                 "swapped?"),
])
def test_each_refusal_is_one_line_naming_the_servo(turns, directions, words):
    with pytest.raises(CalibrationError) as err:
        _judge(turns, directions)
    assert str(err.value).startswith(words) and "\n" not in str(err.value)
