"""What every joint kind provides in ``calibration/``: the extraction of its limits from
recorded orientations, which clinical angles it measures, how a constraint of the kind is read
as a range of motion.

A calibration kind is registered in :mod:`calibration.kinds` under the name of its
``models`` kind (:mod:`models.kinds`); :class:`CalibrationKind` is the base of every one.
Clinical angles are the Cardan angles of :mod:`calibration.joint_angles` (``α`` about the
proximal segment's medio-lateral axis, ``β`` the floating axis, ``γ`` about the distal
segment's long axis) unless the kind computes its own (:meth:`CalibrationKind.clinical_angles`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["CalibrationKind"]


class CalibrationKind:
    """One kind of joint in ``calibration/``.

    Attributes
    ----------
    name : str
        The kind's name (:data:`models.kinds.KINDS`).
    angles : tuple of int
        The Cardan angles (0 = α, 1 = β, 2 = γ) a joint of this kind measures (a clinical
        movement of another angle is "not measured" by it).
    unmeasured_words : str
        What a table shows for a movement the kind does not measure.
    reads_in_band : bool
        A recording's or a constraint's peaks are read where the joint's other angles are near
        neutral (a goniometer's reading, :func:`calibration.joint_angles.recorded_rom`);
        False: every sample (a hinge: its other angles are out-of-axis motion).
    bounds : tuple of int
        The Cardan angles a constraint of this kind bounds (what
        :func:`calibration.joint_angles.constraint_rom` reads from it).
    """

    name: str = ""
    angles: tuple[int, ...] = (0, 1, 2)
    unmeasured_words: str = ""
    reads_in_band: bool = True
    bounds: tuple[int, ...] = (0, 1, 2)

    def extractor(self, spec: Any, *, limb_axis, alpha_deg: float, max_vertices: int,
                  by_swing: bool | str, name: str) -> Any:
        """The unfitted extractor of a joint of this kind (``spec`` a
        :class:`calibration.joints.JointSpec` or None), fitted with
        :func:`calibration.boundary.joint.fit_joint`."""
        raise NotImplementedError

    def allowed_samples(self, constraint: Any, step_deg: float) -> np.ndarray:
        """Orientations (N, 4) where the set ``constraint`` allows takes its extreme angles
        (its boundary; every one allowed), ``step_deg`` apart."""
        raise NotImplementedError
