"""Boundary extraction: recorded joint orientations → a patient-specific joint constraint.

Input: joint orientations ``q`` (N, 4) (limb relative to thorax, scalar-first), in recording
order with their sample times (consecutive samples are read as a trajectory; any other order
only loses that evidence). Output: a :class:`models.constraint.JointConstraint` with a
spherical-polygon swing limit, a twist range (and, when the data supports it, a
swing-dependent twist table), and its provenance.

The principle: **keep what was recorded.** A patient reaches a limit briefly; a range of motion
that leaves out a brief excursion is the one error a clinician cannot see. So the boundary
holds every recorded sample except isolated spikes (sensor glitches), and moves inwards only by
the measurement error the recording itself shows (near zero for optical motion capture or servo
encoders). What the written boundary holds is then measured on it and recorded.

The method is documented step by step in docs/calibration.md, "Boundary extraction"; each
step is a module of pure functions and small dataclasses, usable on its own (for any joint's
own orientations), which :class:`BoundaryExtractor` runs in order:

====  ==========================================  ============================================
step  what                                        module
====  ==========================================  ============================================
1-2   usable samples (status, times); spikes      :mod:`~calibration.boundary.outliers`
3     centre, azimuthal-equidistant plane         :mod:`~calibration.boundary.projection`
3, 4b measured noise; envelope-depth estimates    :mod:`~calibration.boundary.inset`
4     cells, alpha shape, clusters, alpha search  :mod:`~calibration.boundary.alpha`
4     pieces joined, held samples, inset applied  :mod:`~calibration.boundary.region`
4     plane distances and labels                  :mod:`~calibration.boundary.planar`
5     simplification around the region           :mod:`~calibration.boundary.simplify`
6     twist envelope, by-swing table (LP)         :mod:`~calibration.boundary.twist`
7     sparse arcs                                 :mod:`~calibration.boundary.sparse`
8     what a boundary holds; boundary distance    :mod:`~calibration.boundary.compare`
all   the orchestrator                            :mod:`~calibration.boundary.extractor`
1-2,6 a hinge's interval (elbow, knee)            :mod:`~calibration.boundary.hinge`
joint one joint's extraction (--joint, --limb)    :mod:`~calibration.boundary.joint`
limb  a limb's joints and their coupling          :mod:`~calibration.boundary.limb`
====  ==========================================  ============================================

Imports point one way: ``planar`` → ``inset``, ``region`` → ``alpha``; ``projection`` →
``simplify``, ``twist``; ``inset`` → ``twist``; ``compare`` → ``sparse``; all → ``extractor``.

Public API: :class:`BoundaryExtractor` (ball and two-axis joints), :class:`HingeExtractor`,
:class:`LimbExtractor` (the one extraction entry: a whole limb, or a limb of one joint),
:class:`SparseArc`, and the accuracy measures
:func:`boundary_distance` (symmetric mean boundary distance), :func:`boundary_points`,
:func:`outside_fraction` — each imported on first use (PEP 562 ``__getattr__``, as
:mod:`models`), so that importing one step's module (a joint kind's extractor,
:mod:`calibration.kinds`) does not import the limb extraction built on the kinds.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

#: public name -> the module defining it
_EXPORTS: dict[str, str] = {
    "BoundaryExtractor": "calibration.boundary.extractor",
    "HingeExtractor": "calibration.boundary.hinge",
    "LimbExtractor": "calibration.boundary.limb",
    "SparseArc": "calibration.boundary.sparse",
    "boundary_distance": "calibration.boundary.compare",
    "boundary_points": "calibration.boundary.compare",
    "outside_fraction": "calibration.boundary.compare",
}

__all__ = [
    "BoundaryExtractor",
    "HingeExtractor",
    "LimbExtractor",
    "SparseArc",
    "boundary_distance",
    "boundary_points",
    "outside_fraction",
]


def __getattr__(name: str) -> Any:
    try:
        module = _EXPORTS[name]
    except KeyError:
        raise AttributeError(f"module 'calibration.boundary' has no attribute {name!r}") from None
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value  # later look-ups skip __getattr__
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_EXPORTS))


if TYPE_CHECKING:  # pragma: no cover - for type checkers and IDEs only
    from calibration.boundary.compare import boundary_distance, boundary_points, outside_fraction
    from calibration.boundary.extractor import BoundaryExtractor
    from calibration.boundary.hinge import HingeExtractor
    from calibration.boundary.limb import LimbExtractor
    from calibration.boundary.sparse import SparseArc
