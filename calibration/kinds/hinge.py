"""The hinge in ``calibration/``: its interval extracted about the joint's axis
(:class:`calibration.boundary.HingeExtractor`); it measures its angle alone (α: an elbow hinge
has no forearm rotation, which happens between the radius and the ulna within the forearm
segment; a knee's ab/adduction is out-of-axis motion), read over every sample.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from calibration.boundary.hinge import HingeExtractor
from calibration.kinds.base import CalibrationKind
from models import quaternion as Q

__all__ = ["HingeCalibration"]


class HingeCalibration(CalibrationKind):
    """The hinge's extraction and clinical reading."""

    name = "hinge"
    angles = (0,)
    unmeasured_words = "not measured by a hinge"
    reads_in_band = False
    bounds = (0,)

    def extractor(self, spec, *, limb_axis, alpha_deg, max_vertices, by_swing, name) -> Any:
        return HingeExtractor(spec.hinge_axis, limb_axis=limb_axis, name=name)

    def allowed_samples(self, constraint, step_deg: float) -> np.ndarray:
        h = constraint.hinge
        theta = np.arange(h.min_deg, h.max_deg + 1e-9, min(step_deg, 0.1))
        return Q.from_axis_angle(np.asarray(h.axis, float), np.radians(theta))
