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

from typing import Any, ClassVar

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
    movements : tuple of (str, str)
        The movement pairs (positive, negative) of the kind's own clinical angles
        (:meth:`clinical_angles`); empty when the kind has none of its own (a joint of it is
        read by its joint's Cardan angles, :mod:`calibration.joint_angles`).
    norms : dict
        Normative values (degrees) of the kind's own movements, ``{movement: degrees}``;
        ``norms_source`` cites them.
    """

    name: str = ""
    angles: tuple[int, ...] = (0, 1, 2)
    unmeasured_words: str = ""
    reads_in_band: bool = True
    bounds: tuple[int, ...] = (0, 1, 2)
    movements: tuple[tuple[str, str], ...] = ()
    norms: ClassVar[dict[str, float]] = {}
    norms_source: str = ""

    def extractor(self, spec: Any, *, limb_axis, alpha_deg: float, max_vertices: int,
                  by_swing: bool | str, name: str) -> Any:
        """The unfitted extractor of a joint of this kind (``spec`` a
        :class:`calibration.joints.JointSpec` or None), fitted with
        :func:`calibration.extraction.joint.fit_joint`."""
        raise NotImplementedError

    def clinical_angles(self, q: np.ndarray, side: str = "right") -> dict[str, np.ndarray]:
        """The kind's own clinical angles (degrees, (N,) each, keyed by the positive movement
        of each pair of :attr:`movements`) of joint orientations ``q`` (N, 4) (child relative
        to parent, rig frames; a left joint mirrored first). Kinds without angles of their
        own raise NotImplementedError: their joints are read by Cardan angles."""
        raise NotImplementedError(f"a {self.name} joint is read by its joint's Cardan angles")

    def clinical_peaks(self, q: np.ndarray, side: str = "right") -> dict[str, float]:
        """The farthest value (degrees, >= 0; 0 when never reached) of each movement of
        :attr:`movements` over joint orientations ``q`` (N, 4)."""
        ang = self.clinical_angles(q, side)
        out: dict[str, float] = {}
        for pos, neg in self.movements:
            v = np.asarray(ang[pos], dtype=float)
            out[pos] = float(max(0.0, v.max()))
            out[neg] = float(max(0.0, -v.min()))
        return out

    def allowed_samples(self, constraint: Any, step_deg: float) -> np.ndarray:
        """Orientations (N, 4) where the set ``constraint`` allows takes its extreme angles
        (its boundary; every one allowed), ``step_deg`` apart."""
        raise NotImplementedError

    def describe_extraction(self, ex: Any, report: dict[str, Any]) -> list[str] | None:
        """What ``rig boundary`` prints of a fitted extractor of this kind (``report`` its
        :meth:`report`), one line a step; None: the swing or hinge lines
        (:func:`rig.readback.boundary.describe`) say it."""
        return None
