"""The two-axis joint in ``calibration/`` (a wrist, an ankle): extracted as a ball joint and
written as a two-axis one when the recorded twist is narrow enough
(:class:`calibration.boundary.BoundaryExtractor` with ``kind="two-axis"``); it measures its two
swing angles (α, β: its narrow twist is not a range of motion).
"""

from __future__ import annotations

from calibration.kinds.ball import BallCalibration

__all__ = ["TwoAxisCalibration"]


class TwoAxisCalibration(BallCalibration):
    """The two-axis joint's extraction and clinical reading."""

    name = "two-axis"
    angles = (0, 1)
    unmeasured_words = "not measured by a two-axis joint"
