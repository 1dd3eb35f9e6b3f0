"""The boundary extractor: recorded joint orientations → a ball joint's constraint.

:class:`BoundaryExtractor` holds the hyper-parameters and runs the steps in order, each a
function of explicit inputs (docs/calibration.md, "Boundary extraction"):

1. directions ``d = q a q*`` (limb axis ``a``) and twist ``φ`` of ``q = swing ⊗ twist`` about
   ``a`` (:mod:`models.quaternion`), after dropping low-status samples
   (:func:`~calibration.boundary.outliers.usable_samples`);
2. isolated spikes dropped (:func:`~calibration.boundary.outliers.find_spikes`);
3. the azimuthal-equidistant plane about the centre
   (:mod:`~calibration.boundary.projection`) and the measured white noise
   (:func:`~calibration.boundary.inset.fast_noise`);
4. the swing region: alpha shape, joined on recorded evidence, holding every sample, moved in
   by the noise inset (4b) (:func:`~calibration.boundary.alpha.alpha_region`);
5. simplified around the region and mapped back to the sphere
   (:mod:`~calibration.boundary.simplify`) — margin tripled while a great-circle edge leaves a
   held sample outside, tolerance doubled while the polygon is not a valid constraint;
6. the twist envelope and the by-swing table (:mod:`~calibration.boundary.twist`);
7. sparse arcs (:mod:`~calibration.boundary.sparse`);
8. what the written boundary holds (:func:`~calibration.boundary.compare.inside_share`).

The fitted attributes are set once, from the steps' results, when every step has succeeded.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from calibration.boundary.alpha import alpha_region
from calibration.boundary.compare import Inside, inside_share, swing_oracle
from calibration.boundary.inset import InsetSettings, fast_noise
from calibration.boundary.outliers import find_spikes, trajectory_links, usable_samples
from calibration.boundary.projection import Projection, centre_of
from calibration.boundary.region import RegionSettings
from calibration.boundary.simplify import (
    MARGIN_DEG,
    SphericalPolygon,
    simplify_around,
    spherical_polygon,
)
from calibration.boundary.sparse import SparseArc, sparse_arcs
from calibration.boundary.twist import (
    TableSettings,
    TwistEnvelope,
    TwistSettings,
    choose_table,
    twist_envelope,
    twist_table,
)
from calibration.errors import CalibrationError
from models import quaternion as Q
from models.constraint import JointConstraint
from models.errors import ConstraintError
from models.kinds import DEFAULT_KIND, swing_twist_kinds
from models.kinds.two_axis import TWO_AXIS_MAX_TWIST_DEG, TwoAxisKind

#: The two-axis kind's name: a ball joint's extraction written as one when its twist allows.
TWO_AXIS = TwoAxisKind.name

__all__ = ["BoundaryExtractor"]

#: Farthest a recorded direction may be from the centre (degrees) for a swing region.
_MAX_SPAN_DEG = 150.0
#: Simplification attempts (step 5) before an invalid polygon is an error.
_ATTEMPTS = 6


@dataclass(frozen=True)
class _Written:
    """One attempt of steps 5-8: the polygon, the twist table, the constraint written."""

    polygon: SphericalPolygon
    table_candidate: dict | None
    table: dict | None
    arcs: list[SparseArc]
    inside: Inside
    constraint: JointConstraint


class BoundaryExtractor:
    """Recorded joint orientations → swing polygon, twist range, provenance (see
    :mod:`calibration.boundary`).

    Hyper-parameters (angles in degrees) are set here; :meth:`fit` returns ``self`` with the
    fitted state in trailing-underscore attributes.

    Parameters
    ----------
    alpha_deg : float
        Alpha-shape radius: concavities narrower than about twice this are bridged.
    cell_deg : float
        Cell size of the points the alpha shape is built on.
    max_speed_dps : float
        Fastest plausible angular speed of the limb direction, °/s (step 2).
    spike_max_samples : int
        Longest run between two jumps that counts as a spike (step 2).
    min_piece_samples : int
        Samples a separate piece needs to be bridged to the main one (step 4 iii).
    coverage : float
        Fraction of kept samples the region must hold (step 4).
    cluster_share : float
        A cluster joined to the main one neither in space nor along the trajectory and holding
        less than this share of the samples is a glitch cluster (step 4 i).
    max_vertices : int
        Vertex budget of the simplified polygon.
    simplify_deg : float
        Smallest simplification tolerance.
    by_swing : bool or "auto"
        Swing-dependent twist table (step 6).
    by_swing_bandwidth_deg, by_swing_spacing_deg, by_swing_min_samples, by_swing_min_diff_deg
        Kernel width, table spacing, effective samples per table point, "auto" threshold.
    sparse_deg, sparse_min_samples
        Sparse-arc test (step 7).
    min_system_status : int
        Minimum BNO055 system calibration level (0-3) of a sample, when statuses are given.
    noise_correction : bool
        Move the swing and twist envelopes in by the measured errors (steps 4b, 6).
    pileup_band_deg, visit_band_deg, visit_segment_deg, visit_gap_samples, visit_min
        Noise-inset estimates (step 4b).
    twist_dwell_band_deg, twist_dwell_min_samples, twist_dwell_max_iqr_deg, twist_dwell_min_runs
        Dwells at the twist limits (step 6).
    limb_axis : (3,) array_like
        Limb long axis in the limb frame.
    name : str
        Name of the constraint produced.

    Attributes
    ----------
    constraint_ : JointConstraint
    centre_ : (3,) unit, projection centre
    vertices_ : (M, 3) polygon vertices; ``interior_`` (3,)
    twist_deg_ : (float, float), the twist envelope (``twist_envelope_``: its
        :class:`~calibration.boundary.twist.TwistEnvelope`, the estimates behind its insets)
    by_swing_ : dict or None, the contract-3 ``by_swing`` mapping
    by_swing_candidate_ : dict or None, the table computed (also when not emitted)
    sparse_arcs_ : list of SparseArc
    alpha_used_deg_ : float
    n_samples_, n_status_dropped_, n_spikes_, n_used_, n_glitch_cluster_ : int
    recorded_ : (K, 3) every usable recorded direction (spikes included)
    noise_deg_, twist_noise_deg_ : float, measured white noise of direction and twist (deg)
    slow_error_deg_ : float or None, the measured slow error given to :meth:`fit`
    inset_deg_, inset_estimates_ : the swing noise inset and its estimates (step 4b)
    twist_inset_deg_ : (float, float); twist_dwells_ : (int, int), dwells at each end (step 6)
    coverage_ : float, share of the evidence the region held when alpha was chosen (step 4)
    inside_, inside_1deg_ : float, share of the recorded directions inside the written
        boundary, and within 1° of it; outside_max_deg_ : the farthest one outside (step 8)
    """

    def __init__(
        self,
        *,
        alpha_deg: float = 4.0,
        cell_deg: float = 0.5,
        max_speed_dps: float = 3000.0,
        spike_max_samples: int = 2,
        min_piece_samples: int = 5,
        coverage: float = 0.995,
        cluster_share: float = 0.01,
        max_vertices: int = 64,
        simplify_deg: float = 0.3,
        by_swing: bool | str = "auto",
        by_swing_bandwidth_deg: float = 20.0,
        by_swing_spacing_deg: float = 20.0,
        by_swing_min_samples: int = 500,
        by_swing_min_diff_deg: float = 8.0,
        sparse_deg: float = 3.0,
        sparse_min_samples: int = 10,
        min_system_status: int = 2,
        noise_correction: bool = True,
        pileup_band_deg: float = 10.0,
        visit_band_deg: float = 6.0,
        visit_segment_deg: float = 3.0,
        visit_gap_samples: int = 20,
        visit_min: int = 3,
        twist_dwell_band_deg: float = 10.0,
        twist_dwell_min_samples: int = 20,
        twist_dwell_max_iqr_deg: float = 3.0,
        twist_dwell_min_runs: int = 5,
        limb_axis=(1.0, 0.0, 0.0),
        name: str = "recorded",
        kind: str = DEFAULT_KIND,
    ) -> None:
        if kind not in swing_twist_kinds():
            raise ValueError(f"kind must be {' or '.join(map(repr, swing_twist_kinds()))}, "
                             f"got {kind!r}")
        if by_swing not in (True, False, "auto"):
            raise ValueError(f"by_swing must be True, False or 'auto', got {by_swing!r}")
        for label, val in (("alpha_deg", alpha_deg), ("cell_deg", cell_deg),
                           ("max_speed_dps", max_speed_dps), ("sparse_deg", sparse_deg),
                           ("simplify_deg", simplify_deg)):
            if not val > 0:
                raise ValueError(f"{label} must be > 0, got {val!r}")
        if spike_max_samples < 0:
            raise ValueError(f"spike_max_samples must be >= 0, got {spike_max_samples!r}")
        if max_vertices < 3:
            raise ValueError(f"max_vertices must be >= 3, got {max_vertices}")
        self.alpha_deg = float(alpha_deg)
        self.cell_deg = float(cell_deg)
        self.max_speed_dps = float(max_speed_dps)
        self.spike_max_samples = int(spike_max_samples)
        self.min_piece_samples = int(min_piece_samples)
        self.coverage = float(coverage)
        self.cluster_share = float(cluster_share)
        self.max_vertices = int(max_vertices)
        self.simplify_deg = float(simplify_deg)
        self.by_swing = by_swing
        self.by_swing_bandwidth_deg = float(by_swing_bandwidth_deg)
        self.by_swing_spacing_deg = float(by_swing_spacing_deg)
        self.by_swing_min_samples = int(by_swing_min_samples)
        self.by_swing_min_diff_deg = float(by_swing_min_diff_deg)
        self.sparse_deg = float(sparse_deg)
        self.sparse_min_samples = int(sparse_min_samples)
        self.min_system_status = int(min_system_status)
        self.noise_correction = bool(noise_correction)
        self.pileup_band_deg = float(pileup_band_deg)
        self.visit_band_deg = float(visit_band_deg)
        self.visit_segment_deg = float(visit_segment_deg)
        self.visit_gap_samples = int(visit_gap_samples)
        self.visit_min = int(visit_min)
        self.twist_dwell_band_deg = float(twist_dwell_band_deg)
        self.twist_dwell_min_samples = int(twist_dwell_min_samples)
        self.twist_dwell_max_iqr_deg = float(twist_dwell_max_iqr_deg)
        self.twist_dwell_min_runs = int(twist_dwell_min_runs)
        self.limb_axis = Q.check_vectors(limb_axis, name="limb_axis")
        self.name = name
        self.kind = kind

    def params(self) -> dict[str, Any]:
        """The hyper-parameters as plain types (recorded in the provenance)."""
        return {
            "alpha_deg": self.alpha_deg, "cell_deg": self.cell_deg,
            "max_speed_dps": self.max_speed_dps, "spike_max_samples": self.spike_max_samples,
            "min_piece_samples": self.min_piece_samples, "coverage": self.coverage,
            "cluster_share": self.cluster_share,
            "max_vertices": self.max_vertices, "simplify_deg": self.simplify_deg,
            "by_swing": self.by_swing,
            "by_swing_bandwidth_deg": self.by_swing_bandwidth_deg,
            "sparse_deg": self.sparse_deg, "sparse_min_samples": self.sparse_min_samples,
            "min_system_status": self.min_system_status,
            "noise_correction": self.noise_correction,
            "pileup_band_deg": self.pileup_band_deg,
            "visit": [self.visit_band_deg, self.visit_segment_deg, self.visit_gap_samples,
                      self.visit_min],
            "twist_dwell": [self.twist_dwell_band_deg, self.twist_dwell_min_samples,
                            self.twist_dwell_max_iqr_deg, self.twist_dwell_min_runs],
        }

    # -- the steps' hyper-parameters -------------------------------------------------------
    def region_settings(self) -> RegionSettings:
        """Hyper-parameters of the swing region (step 4)."""
        return RegionSettings(alpha_deg=self.alpha_deg, cell_deg=self.cell_deg,
                              min_piece_samples=self.min_piece_samples,
                              coverage=self.coverage, cluster_share=self.cluster_share)

    def inset_settings(self) -> InsetSettings:
        """Hyper-parameters of the swing noise inset (step 4b)."""
        return InsetSettings(enabled=self.noise_correction,
                             pileup_band_deg=self.pileup_band_deg,
                             visit_band_deg=self.visit_band_deg,
                             visit_segment_deg=self.visit_segment_deg,
                             visit_gap_samples=self.visit_gap_samples, visit_min=self.visit_min)

    def twist_settings(self) -> TwistSettings:
        """Hyper-parameters of the twist envelope (step 6)."""
        return TwistSettings(enabled=self.noise_correction,
                             pileup_band_deg=self.pileup_band_deg,
                             dwell_band_deg=self.twist_dwell_band_deg,
                             dwell_min_samples=self.twist_dwell_min_samples,
                             dwell_max_iqr_deg=self.twist_dwell_max_iqr_deg,
                             dwell_min_runs=self.twist_dwell_min_runs)

    def table_settings(self) -> TableSettings:
        """Hyper-parameters of the by-swing twist table (step 6)."""
        return TableSettings(bandwidth_deg=self.by_swing_bandwidth_deg,
                             spacing_deg=self.by_swing_spacing_deg,
                             min_samples=self.by_swing_min_samples)

    # -- fit -------------------------------------------------------------------------------
    def fit(self, q, *, status=None, t=None, provenance: dict | None = None,
            slow_error_deg: float | None = None,
            insets: tuple[float, tuple[float, float]] | None = None,
            reach_error_deg: float | None = None) -> BoundaryExtractor:
        """Extract the boundary from joint orientations.

        Parameters
        ----------
        q : (N, 4) array_like
            Joint orientations (limb relative to thorax), scalar-first, unit (either sign).
        status : (N,) array_like of int, optional
            IMU calibration bytes (``CALIB_STAT``); None for sources without one (servo FK).
        t : (N,) array_like, optional
            Sample times, seconds, non-decreasing: what tells a physically impossible jump
            (a spike) from fast motion. Without them a step counts as a jump when it is more
            than 20 times the recording's median step and more than 15°.
        slow_error_deg : float, optional
            Measured size of the recording's slowly varying errors (an IMU pair's relative
            heading drift left after the neutral-checkpoint correction, degrees): the evidence
            the visit estimate of the noise inset may use (step 4b). None: no such evidence,
            the inset comes from the measured fast noise only.
        insets : (swing_deg, (twist_lo_deg, twist_hi_deg)), optional
            The swing and twist insets already measured on a larger recording of the same
            sensors, used as they are instead of estimates from these samples (a limb's
            keyframe, a share of its joint's recording: :class:`LimbExtractor`). The
            extractor's ``inset_deg_`` and ``twist_inset_deg_`` after a fit are such a pair.
        reach_error_deg : float, optional
            A measured slow error used for the twist's singular reach alone (step 6), not for
            any inset (a limb's joints: :class:`LimbExtractor`); default ``slow_error_deg``.
        provenance : dict, optional
            Where the data came from (session, file, ...); extended with the parameters and
            sample counts and stored in the constraint's ``provenance``.

        Returns
        -------
        self

        Raises
        ------
        CalibrationError
            Too few usable samples, or directions spread too wide to form a swing region.
        """
        import shapely

        usable = usable_samples(q, status, t, min_system_status=self.min_system_status)
        recorded = Q.rotate(usable.q, self.limb_axis)  # what "inside" is measured on
        phi = Q.twist_angle(usable.q, self.limb_axis)
        spikes = find_spikes(recorded, usable.t, self.max_speed_dps, self.spike_max_samples)
        d, phi = recorded[~spikes], phi[~spikes]
        t = None if usable.t is None else usable.t[~spikes]
        slow = None if slow_error_deg is None else float(slow_error_deg)
        proj = Projection.about(centre_of(d))
        p = proj.forward(d)
        links = trajectory_links(d, t, self.max_speed_dps)
        noise = fast_noise(p)
        if np.hypot(p[:, 0], p[:, 1]).max() > _MAX_SPAN_DEG:
            raise CalibrationError(
                "recorded directions span more than 150 deg from their centre; a swing region "
                "this large cannot be extracted"
            )
        inset_settings, twist_settings = self.inset_settings(), self.twist_settings()
        if insets is not None:
            inset_settings = dataclasses.replace(inset_settings, measured_deg=float(insets[0]))
            twist_settings = dataclasses.replace(
                twist_settings, measured_deg=tuple(float(x) for x in insets[1]))
        swing = alpha_region(p, links, self.region_settings(), inset_settings,
                             noise_deg=noise, slow_error_deg=slow)
        swing_from_axis = np.arccos(np.clip(d @ self.limb_axis, -1.0, 1.0))
        twist = twist_envelope(phi, twist_settings, slow, swing=swing_from_axis,
                               reach_error_deg=reach_error_deg)
        provenance = dict(provenance or {})
        provenance.update({
            "method": "calibration.boundary.BoundaryExtractor",
            "parameters": self.params(),
            "samples": int(usable.n_samples),
            "samples_used": len(p),
            "dropped_status": int(usable.n_status_dropped),
            "spikes": int(spikes.sum()),
            "glitch_cluster_samples": int(swing.n_glitch_cluster),
            "alpha_used_deg": round(swing.alpha_deg, 3),
            "noise_inset_deg": round(swing.inset_deg, 3),
            "noise_inset_estimates": dict(swing.inset_estimates),
            "twist_noise_inset_deg": [round(x, 3) for x in twist.inset_deg],
            "twist_dwells": list(twist.dwells),
        })
        held = shapely.contains_xy(swing.region, p[:, 0], p[:, 1])  # the boundary must hold
        tol, margin = self.simplify_deg, MARGIN_DEG
        for attempt in range(_ATTEMPTS):
            verts2d = simplify_around(swing.region, tol, margin, self.max_vertices)
            try:
                written = self._write(spherical_polygon(verts2d, proj), proj, d, twist,
                                      recorded, provenance)
            except CalibrationError:
                # a corridor simplified to straight lines in the plane can still cross itself
                # on the sphere (great-circle edges): simplify further
                if attempt == _ATTEMPTS - 1:
                    raise
                tol *= 2.0
                continue
            o, _ = swing_oracle(written.constraint)
            if not held.any() or (o.swing_distance(d[held]) <= 0.0).all():
                break
            # a great-circle edge bulges inwards of its straight image in the plane by more
            # than the margin: widen it
            margin *= 3.0

        self.n_samples_ = usable.n_samples
        self.n_status_dropped_ = usable.n_status_dropped
        self.recorded_ = recorded
        self.n_spikes_ = int(spikes.sum())
        self.n_used_ = len(p)
        self.slow_error_deg_ = slow
        self.noise_deg_ = noise
        self.alpha_used_deg_ = swing.alpha_deg
        self.coverage_ = swing.coverage
        self.n_glitch_cluster_ = swing.n_glitch_cluster
        self.inset_deg_ = swing.inset_deg
        self.inset_estimates_ = swing.inset_estimates
        self.centre_ = proj.centre
        self.vertices_ = written.polygon.vertices
        self.interior_ = written.polygon.interior
        self.twist_deg_ = (twist.min_deg, twist.max_deg)
        self.twist_noise_deg_ = twist.noise_deg
        self.twist_inset_deg_ = twist.inset_deg
        self.twist_dwells_ = twist.dwells
        self.twist_envelope_ = twist
        self.by_swing_candidate_ = written.table_candidate
        self.by_swing_ = written.table
        self.sparse_arcs_ = written.arcs
        self.inside_ = written.inside.share
        self.inside_1deg_ = written.inside.within_1deg
        self.outside_max_deg_ = written.inside.farthest_outside_deg
        self.constraint_ = self._with_kind(written.constraint)
        return self

    def _with_kind(self, constraint):
        """The written constraint as a ``two-axis`` joint when asked and the recorded twist is
        narrow enough for one (:data:`models.kinds.two_axis.TWO_AXIS_MAX_TWIST_DEG`); otherwise
        the ball joint, with the reason in its provenance (``kind_note``)."""
        if self.kind != TWO_AXIS:
            return constraint
        d = constraint.to_dict()
        width = self.twist_deg_[1] - self.twist_deg_[0]
        if width <= TWO_AXIS_MAX_TWIST_DEG:
            d["kind"] = TWO_AXIS
        else:
            d.setdefault("provenance", {})["kind_note"] = (
                f"recorded twist {width:.1f} deg wide (a two-axis joint allows "
                f"{TWO_AXIS_MAX_TWIST_DEG:g}): written as a ball joint")
        return JointConstraint.from_dict(d)

    def _write(self, polygon: SphericalPolygon, proj: Projection, d: np.ndarray,
               twist: TwistEnvelope, recorded: np.ndarray, provenance: dict) -> _Written:
        """Steps 6 (table) to 8 for one simplified polygon: the constraint written, and what it
        holds of the ``recorded`` directions. ``d`` are the kept directions, ``provenance``
        everything but the sparse arcs and the share inside.

        Raises
        ------
        CalibrationError
            The polygon is not a valid constraint (it crosses itself on the sphere).
        """
        candidate = twist_table(d, twist, polygon.plane, proj, self.table_settings())
        table = choose_table(candidate, twist, self.by_swing, self.by_swing_min_diff_deg)
        arcs = sparse_arcs(polygon.vertices, d, self.sparse_deg, self.sparse_min_samples)
        prov = dict(provenance)
        prov["sparse_arcs"] = [a.to_dict() for a in arcs]
        limits: dict[str, Any] = {
            "min_deg": max(-180.0, math.floor(twist.min_deg * 1000.0) / 1000.0),
            "max_deg": min(180.0, math.ceil(twist.max_deg * 1000.0) / 1000.0)}
        if table is not None:
            limits["by_swing"] = table
        data = {
            "name": self.name,
            "limb_axis": [float(x) for x in self.limb_axis],
            "swing": {"polygon": {"vertices": polygon.vertices.tolist(),
                                  "interior": polygon.interior.tolist()}},
            "twist": limits,
            "provenance": prov,
        }
        try:
            constraint = JointConstraint.from_dict(data)
        except ConstraintError as err:
            raise CalibrationError(f"the extracted boundary is not a valid constraint: {err}") \
                from err
        # what the written boundary holds, measured on it: every usable recorded direction
        # (spikes included), the exact oracle's signed distance
        inside = inside_share(constraint, recorded)
        prov["inside"] = {
            "share": round(inside.share, 5), "within_1deg": round(inside.within_1deg, 5),
            "farthest_outside_deg": round(inside.farthest_outside_deg, 3),
            "directions": inside.directions}
        return _Written(polygon, candidate, table, arcs, inside,
                        JointConstraint.from_dict(data))

    def report(self) -> dict[str, Any]:
        """What the extraction did, as plain types (for the CLI and the store)."""
        return {
            "samples": self.n_samples_,
            "samples_used": self.n_used_,
            "dropped_status": self.n_status_dropped_,
            "spikes": self.n_spikes_,
            "glitch_cluster_samples": self.n_glitch_cluster_,
            "vertices": len(self.vertices_),
            "alpha_used_deg": self.alpha_used_deg_,
            "inside": self.inside_,
            "inside_1deg": self.inside_1deg_,
            "directions": len(self.recorded_),
            "noise_inset_deg": self.inset_deg_,
            "twist_deg": list(self.twist_deg_),
            "by_swing_points": 0 if self.by_swing_ is None else len(self.by_swing_["points"]),
            "sparse_arcs": [a.to_dict() for a in self.sparse_arcs_],
            "sparse_length_deg": float(sum(a.length_deg for a in self.sparse_arcs_)),
            "kind": self.constraint_.kind,
        }
