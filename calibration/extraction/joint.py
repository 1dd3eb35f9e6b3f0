"""One joint's limits from its own orientations: the one extraction behind ``rig boundary
--joint`` (:func:`rig.readback.boundary.extract`) and each joint of ``rig boundary --limb``
(:class:`~calibration.boundary.LimbExtractor`), so that the two cannot disagree about a joint
the limb does not couple.

- the extractor of the joint's kind (:meth:`calibration.kinds.base.CalibrationKind.extractor`):
  a hinge (elbow, knee) :class:`~calibration.boundary.HingeExtractor` about the joint's hinge
  axis; otherwise :class:`~calibration.boundary.BoundaryExtractor` (the wrist and the ankle as
  ``two-axis`` joints when their recorded twist allows).

A measured slow error (``slow_error_deg``: the heading correction's own uncertainty) is used
one of two ways (``slow_insets``):

- ``False`` — for the twist's singular reach alone
  (:func:`calibration.boundary.twist.singular_reach`): nothing is moved in; the limits hold
  what was recorded except isolated spikes and the white noise's measured inset. Whole-limb
  recordings read so (docs/calibration.md, "Measured errors in limb sessions": moving a limb's
  limits in by the error put them inside the truth by the calibration's bias);
- ``True`` — also moving the limits in by what the error explains (the visits' closest
  approach to the swing limit, the dwells at a twist or hinge end: steps 4b and 6 of
  :mod:`calibration.boundary`). One-joint IMU sessions read so.
"""

from __future__ import annotations

from typing import Any

from calibration.boundary.hinge import HingeExtractor
from calibration.joints import JOINTS
from calibration.kinds import calibration_kind
from models.kinds import DEFAULT_KIND

__all__ = ["fit_joint", "joint_extractor"]


def joint_extractor(joint: str | None, *, limb_axis=None, alpha_deg: float = 4.0,
                    max_vertices: int = 64, by_swing: bool | str = "auto",
                    name: str = "recorded", kind: str | None = None) -> Any:
    """The unfitted extractor of ``joint`` (:data:`calibration.joints.JOINTS`; a name it does
    not list, or None, is a ball joint); ``limb_axis`` defaults to the joint's; ``kind`` (a
    registered joint kind, e.g. ``forearm`` for an elbow that also turns about its long axis)
    replaces the joint's own kind."""
    spec = JOINTS.get(joint or "shoulder")
    if kind is None:
        kind = DEFAULT_KIND if spec is None else spec.kind
    axis = limb_axis if limb_axis is not None else (
        (1.0, 0.0, 0.0) if spec is None else spec.limb_axis)
    return calibration_kind(kind).extractor(spec, limb_axis=axis, alpha_deg=alpha_deg,
                                            max_vertices=max_vertices, by_swing=by_swing,
                                            name=name)


def fit_joint(ex, q, *, t=None, status=None, slow_error_deg: float | None = None,
              slow_insets: bool = False, insets=None, provenance: dict | None = None):
    """``ex`` (:func:`joint_extractor`) fitted on one joint's orientations ``q`` (N, 4), sample
    times ``t`` and IMU ``status`` when known, with its measured slow error used as
    ``slow_insets`` says (module doc); ``insets``: a keyframe's, measured on its joint's
    whole recording (``slow_insets`` only)."""

    slow = float(slow_error_deg) if slow_error_deg else None
    kw: dict[str, Any] = {"t": t, "status": status, "provenance": provenance}
    if not slow_insets:
        if slow and not isinstance(ex, HingeExtractor):
            kw["reach_error_deg"] = slow
        return ex.fit(q, **kw)
    kw["slow_error_deg"] = slow
    if insets is not None:
        kw["insets"] = insets
    return ex.fit(q, **kw)
