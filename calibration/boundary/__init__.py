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
====  ==========================================  ============================================

Imports point one way: ``planar`` → ``inset``, ``region`` → ``alpha``; ``projection`` →
``simplify``, ``twist``; ``inset`` → ``twist``; ``compare`` → ``sparse``; all → ``extractor``.

Public API: :class:`BoundaryExtractor` (ball and two-axis joints), :class:`HingeExtractor`,
:class:`SparseArc`, and the accuracy measures :func:`boundary_distance` (symmetric mean
boundary distance), :func:`boundary_points`, :func:`outside_fraction`.

These are the steps. What each joint kind extracts with them is in :mod:`calibration.kinds`;
the one extraction entry, a limb of one or more joints (:class:`LimbExtractor`), is
:mod:`calibration.extraction`, above both: nothing here imports either.
"""

from calibration.boundary.compare import boundary_distance, boundary_points, outside_fraction
from calibration.boundary.extractor import BoundaryExtractor
from calibration.boundary.hinge import HingeExtractor
from calibration.boundary.sparse import SparseArc

__all__ = [
    "BoundaryExtractor",
    "HingeExtractor",
    "SparseArc",
    "boundary_distance",
    "boundary_points",
    "outside_fraction",
]
