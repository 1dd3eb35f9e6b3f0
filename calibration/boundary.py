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

Method
------
1. **Directions and twist.** ``d = q a q*`` (limb axis ``a``, default +X) and the twist ``φ``
   of ``q = swing ⊗ twist`` about ``a`` (:mod:`models.quaternion`). Samples whose IMU
   calibration status (BNO055 ``CALIB_STAT`` system level, bits 7-6) is below
   ``min_system_status`` are dropped first (magnetic disturbances drop it).
2. **Spikes** (the only outliers). Consecutive samples are *linked* when the limb could have
   moved between them: the step's angular speed is at most ``max_speed_dps`` (default
   3,000°/s, faster than any limb segment's swing; the fastest human segment rotations reported,
   about 2,500°/s, are the forearm's in throwing; without sample times a step is a jump when it
   exceeds 15° and 20 median steps). A run of at most ``spike_max_samples`` (2) samples between
   two jumps — reached and left at a speed no limb has — is a spike: a sensor glitch, dropped
   and counted (``spikes``). A brief excursion to a limit is coherent motion, linked all the
   way, and is never dropped however rare. (When such runs would hold more than 5 % of the
   samples, the samples are not a trajectory in recording order and nothing is dropped.)
3. **Projection.** The centre ``c`` is the normalised mean direction, re-centred on the samples
   nearest it (95 %). Directions are mapped to the plane by the *azimuthal-equidistant*
   projection about ``c`` (Snyder 1987, *Map projections — a working manual*, USGS PP 1395,
   §25): ``p = θ (cos α, sin α)`` with ``θ = ∠(d, c)`` in degrees and ``α`` the azimuth in a
   tangent basis at ``c``. Distances from ``c`` are exact; other distances are stretched by
   ``θ / sin θ`` across the radial direction (5 % at 30°, 21 % at 60°), which only matters for
   the alpha radius, not for the result's accuracy (vertices are mapped back exactly).
   **Measured noise**: the white noise of the directions, ``σ`` (degrees per axis), is the
   robust standard deviation of the fourth differences of consecutive plane positions over
   √70 — for white noise every order of difference gives ``σ``; smooth motion adds its fourth
   derivative times Δt⁴, less at each higher order (a 60 Hz optical recording gives 0.05° from
   second differences and 0.007° from fourth ones). Only when the fourth-order figure is at
   least 0.6 of the second-order one (white noise's signature) is it taken as noise; otherwise
   the differences are motion (a slowly sampled recording looks rough at every order) and no
   noise is claimed (:func:`_fast_noise`).
4. **Alpha shape** (Edelsbrunner, Kirkpatrick & Seidel 1983, *IEEE Trans. Inf. Theory*
   29:551): the Delaunay triangulation (:class:`scipy.spatial.Delaunay`) of the points — each
   occupied ``cell_deg`` cell's mean position, and in the cells at the edge of the occupied
   area also the cell's outermost samples in eight directions, so that the envelope passes
   through recorded samples rather than through cell means up to half a cell inside them —
   triangles with circumradius ``< alpha_deg`` merged with :func:`shapely.coverage_union_all`.
   The region is concave where the data is and claims no range the limb did not visit; a
   swing limit is simply connected, so the pieces are joined and holes filled, on recorded
   evidence only:

   i. *Clusters.* Cells are connected by Delaunay edges shorter than ``2 alpha`` (the longest
      edge an alpha triangle can have) and by linked trajectory steps (step 2). Cells outside
      the cluster holding most samples, in clusters of less than ``cluster_share`` of the
      samples each, are isolated glitch clusters — reached and left only by jumps no limb
      makes: left out, and not counted as evidence (``glitch_cluster_samples`` in the
      provenance). Only the main cluster's triangles are used.
   ii. *Along the trajectory.* Cells are labelled by the piece of the shape they lie in. A run of
      consecutive trajectory samples between two labelled samples is a **transit** when the
      pieces differ (the limb went from one to the other through the gap, e.g. a thin neck) and
      an **excursion** when it leaves the shape by more than ``cell_deg`` (a sparse stretch, such
      as a lobe visited once, that formed no triangle); so are runs at the ends of a stretch of
      trajectory. These runs are buffered by ``cell_deg / 2`` and merged with the pieces, then
      closed by ``cell_deg`` (a slit of less than two cells is no evidence of a limit).
   iii. *Bridges.* Pieces still apart that hold at least ``min_piece_samples`` samples (a lobe
      only ever seen inside, never on the way in) are joined to the piece holding most samples
      along the minimax path through the recorded cells — the Euclidean minimum spanning tree
      (:func:`scipy.sparse.csgraph.minimum_spanning_tree`; edges inside a piece cost nothing),
      edges shorter than ``2 alpha``: alpha grown locally, along the data, not everywhere.
   iv. The piece holding most samples is kept and its holes filled.
   v. *Held samples.* A sample of the main cluster still outside (a trajectory that grazed the
      shape by less than ``cell_deg``) is reached by a strip 0.02° wide from the region's
      nearest point: the envelope touches every recorded sample.

   If a piece other than the largest holds more than ``1 − coverage`` of the evidence (a
   sparse recording splits the whole shape into pieces, with unvisited pockets between them),
   or the final region (after 4b) leaves more than that out by more than ``cell_deg`` + the
   inset, ``alpha`` grows by 1.5× (up to 4 times).

   4b. **Noise inset, as far as the measured errors support it.** A limit the patient dwells
   on leaves a ridge of samples blurred by measurement error; the envelope sits on the ridge's
   outer tail. Two estimates of how far inside the envelope the limit lies, each capped by
   ``3 ×`` the error it stands for (the largest of a few hundred Gaussian draws), the larger
   one taken:

   - *fast (white) noise*: the ridge's crest, the mode of the samples' depth inside the region
     (0.2° bins over ``pileup_band_deg``, used only when it stands 2× above the band's median;
     depth to within 0.025°, from the boundary's points 0.05° apart), capped by ``3 σ`` (step
     3). On clean data ``σ`` is a few thousandths of a degree and so is the inset, whatever
     the density of the samples near the envelope;
   - *slow errors* (a fused heading that wanders by a degree between visits shifts whole
     visits, and the envelope follows the outermost one): the typical **visit**'s closest
     approach. The boundary is cut into stretches of ``visit_segment_deg`` (by the nearest
     boundary point of each sample within ``visit_band_deg``); in each stretch, a visit is a
     run of samples in recording order with no gap longer than ``visit_gap_samples``, its
     closest approach to the envelope is its minimum depth, and the stretch's value is the
     median over its visits (stretches with at least ``visit_min`` visits); the estimate is the
     median over the stretches. Visits that stop short of a limit are what people do, not
     error, so this estimate is used only with a **measured** slow error (``slow_error_deg``:
     the IMU read path passes the heading correction's own uncertainty,
     :meth:`calibration.heading.HeadingCorrection.uncertainty_deg`), and capped at 3× it.
     Without one (files, servo limbs) it is 0.

   The shrunk pieces are joined again as in 4 ii-iii (transits, excursions beyond the unshrunk
   shape, bridges): a neck narrower than twice the inset does not cut a recorded lobe off.
5. **Simplification around the region.** Douglas-Peucker (topology-preserving,
   :meth:`shapely.Polygon.simplify`) with tolerance ``tol`` of the region grown by
   ``tol + margin`` (margin 0.01°): the simplified boundary lies between ``margin`` and
   ``2 tol + margin`` outside the region, so simplification never cuts recorded range off;
   ``tol`` starts at ``simplify_deg`` and grows by 1.25× until at most ``max_vertices`` remain.
   The vertices are mapped back to the sphere and joined by great-circle edges; if a
   great-circle edge still leaves a sample the region held outside (it bulges inwards of its
   straight image in the plane), the margin is tripled and the step repeated. The result is
   validated by :mod:`models.constraint` (simple, non-degenerate); the interior point is the
   pole of inaccessibility (:func:`shapely.ops.polylabel`), or ``c`` when that is nearly as deep.
6. **Twist range**: the envelope of the kept samples' twist (minimum and maximum after centring
   on their circular mean, so a range across ±180° is handled), each end moved in as in 4b: by
   the crest of the pile-up of samples below it, capped at 3× the twist's measured white noise
   (fourth differences of the unwrapped twist); and, with a measured ``slow_error_deg``, by the
   patient's *dwells* at it, capped at 3× that error (the samples within
   ``twist_dwell_band_deg`` of the end form runs of consecutive samples; a run of at least
   ``twist_dwell_min_samples`` whose twist spread (interquartile range) is at most
   ``twist_dwell_max_iqr_deg`` is a dwell; with at least ``twist_dwell_min_runs`` dwells the
   estimate is the median over the dwells of each dwell's median depth: slowly varying errors
   such as an IMU pair's relative heading drift shift each dwell by the error at that moment).
   **By swing region** (contract 3, ``twist.by_swing``): at table directions ``d_i`` on a grid
   of spacing ``by_swing_spacing_deg`` inside the polygon, where the kernel
   ``exp(κ (d·d_i − 1))``, ``κ = 1 / (1 − cos β)``, gives an effective sample count
   ``(Σw)²/Σw²`` of at least ``by_swing_min_samples``, the twist extremes of the samples within
   ``β`` of ``d_i``; then every interval is widened as little as possible (a linear programme,
   :func:`_hold_twists`) until the table's interpolated limits hold every kept sample's twist
   at its direction. Emitted when ``by_swing`` is True, or ("auto") when some region's limit
   then still differs from the envelope by more than ``by_swing_min_diff_deg``. Limits are
   written rounded outwards (3 decimals).
7. **Sparse arcs.** Points every 0.5° along the final boundary with fewer than
   ``sparse_min_samples`` kept samples within ``sparse_deg`` are grouped into arcs and reported
   (``sparse_arcs_``): stretches of the limit the patient reached rarely or never, where the
   boundary is an interpolation.
8. **What the boundary holds**, measured on the constraint written (the exact oracle,
   :class:`models.oracle.ConstraintOracle`): the share of every usable recorded direction
   (spikes included) inside the swing region (``inside_``) and within 1° of it, and the
   farthest one outside; stored in the provenance (``inside``) and printed by ``rig boundary``.

Accuracy measure (:func:`boundary_distance`)
--------------------------------------------
The *symmetric mean boundary distance* between swing regions ``A`` and ``B`` is
``D = ½ (mean_{a ∈ ∂A} dist(a, ∂B) + mean_{b ∈ ∂B} dist(b, ∂A))`` with points spaced evenly
(0.25°) along each boundary by arc length and ``dist`` the geodesic distance to the other
boundary (exact, :class:`models.oracle.ConstraintOracle`). It is the mean of the two directed
average Hausdorff distances; the maximum of the per-point distances (Hausdorff) is reported too.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from calibration.errors import CalibrationError
from models import quaternion as Q
from models.constraint import JointConstraint
from models.errors import ConstraintError

__all__ = [
    "BoundaryExtractor",
    "SparseArc",
    "boundary_distance",
    "boundary_points",
    "outside_fraction",
]


@dataclass(frozen=True)
class SparseArc:
    """A stretch of the extracted boundary with few samples nearby.

    Attributes
    ----------
    start, end : (3,) float64, unit directions (parent frame) where the arc begins and ends
    length_deg : float, arc length along the boundary, degrees
    """

    start: np.ndarray
    end: np.ndarray
    length_deg: float

    def to_dict(self) -> dict[str, Any]:
        return {
            "from": [round(float(v), 6) for v in self.start],
            "to": [round(float(v), 6) for v in self.end],
            "length_deg": round(float(self.length_deg), 2),
        }


# -- projection -------------------------------------------------------------------------------
def _tangent_basis(c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    u = np.cross(c, np.eye(3)[int(np.argmin(np.abs(c)))])
    u /= np.linalg.norm(u)
    return u, np.cross(c, u)


def _ae_forward(d: np.ndarray, c: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Azimuthal-equidistant coordinates (N, 2), degrees, of unit directions (N, 3)."""
    x = d @ u
    y = d @ v
    s = np.hypot(x, y)
    theta = np.degrees(np.arctan2(s, d @ c))
    safe = np.where(s > 1e-15, s, 1.0)
    return np.column_stack((theta * x / safe, theta * y / safe))


def _ae_inverse(p: np.ndarray, c: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Unit directions (N, 3) of azimuthal-equidistant coordinates (N, 2), degrees."""
    theta = np.hypot(p[:, 0], p[:, 1])
    safe = np.where(theta > 1e-12, theta, 1.0)
    t = np.radians(theta)
    tang = (p[:, :1] / safe[:, None]) * u + (p[:, 1:] / safe[:, None]) * v
    return np.cos(t)[:, None] * c + np.sin(t)[:, None] * tang


def _steps(d: np.ndarray, t: np.ndarray | None) -> tuple[np.ndarray, np.ndarray | None]:
    """Angles (N-1,) in degrees between consecutive directions, and the time steps (N-1,)
    (duplicate or backward times replaced by half the median positive step), or None."""
    step = np.degrees(2.0 * np.arcsin(np.clip(0.5 * np.linalg.norm(d[1:] - d[:-1], axis=1),
                                              0.0, 1.0)))
    if t is None:
        return step, None
    dt = np.diff(t)
    pos = dt[dt > 0]
    floor = 0.5 * float(np.median(pos)) if len(pos) else 1.0
    return step, np.maximum(dt, floor)


def _links(d: np.ndarray, t: np.ndarray | None, max_speed_dps: float) -> np.ndarray:
    """(N-1,) bool: consecutive samples the limb could have moved between — the step's angular
    speed is at most ``max_speed_dps``. Without times, a step is a jump when it exceeds both
    15° and ``_JUMP_RATIO`` times the median step."""
    if len(d) < 2:
        return np.zeros(0, dtype=bool)
    step, dt = _steps(d, t)
    if dt is None:
        return step <= max(15.0, _JUMP_RATIO * float(np.median(step)))
    return step <= max_speed_dps * dt


#: How far outside the limit white noise of std σ (per axis) carries the envelope of the
#: samples pressed against it, in σ: the largest of a few hundred draws of a Gaussian.
_NOISE_REACH = 3.0
#: Least clearance (degrees) between the region and the simplified polygon around it.
_MARGIN_DEG = 0.01
#: Without sample times: a step more than this many median steps (and > 15°) is a jump.
_JUMP_RATIO = 20.0
#: A recording with more of its samples in short runs between jumps is not a trajectory in
#: recording order (shuffled, or sampled too sparsely to follow): no spike is taken out.
_MAX_SPIKE_SHARE = 0.05


def _spikes(d: np.ndarray, t: np.ndarray | None, max_speed_dps: float,
            max_len: int) -> np.ndarray:
    """(N,) bool: isolated spikes — runs of at most ``max_len`` consecutive samples that the
    limb could neither have reached from the sample before nor have left for the sample after
    (both steps faster than ``max_speed_dps``, :func:`_links`); a run at either end of the
    recording needs the jump on its one side. A sensor glitch, not motion: no limb turns that
    fast. Nothing is marked when such runs would hold more than ``_MAX_SPIKE_SHARE`` of the
    samples (the samples are not a trajectory in recording order)."""
    n = len(d)
    out = np.zeros(n, dtype=bool)
    if n < 2 * max_len + 2 or max_len < 1:
        return out
    jump = ~_links(d, t, max_speed_dps)
    if not jump.any():
        return out
    run = np.concatenate(([0], np.cumsum(jump)))  # runs of linked samples, cut at each jump
    short = np.bincount(run)[run] <= max_len
    if short.mean() > _MAX_SPIKE_SHARE:
        return np.zeros(n, dtype=bool)
    return short


def _difference_std(p: np.ndarray, k: int) -> float:
    """Robust (MAD) standard deviation per axis of the ``k``-th differences of consecutive
    rows of ``p``, divided by the factor white noise gains (``√Σ C(k, i)²``)."""
    dk = np.diff(p, n=k, axis=0)
    mad = np.median(np.abs(dk - np.median(dk, axis=0)), axis=0)
    return float(np.mean(1.4826 * mad) / math.sqrt(math.comb(2 * k, k)))


#: White noise gives the same figure from every order of difference; smooth motion gives less
#: from each higher order. Below this ratio of the 4th-order figure to the 2nd-order one, the
#: differences are motion, and the noise — smaller still — cannot be told from it.
_WHITE_RATIO = 0.6


def _fast_noise(p: np.ndarray) -> float:
    """White measurement noise of the limb direction, degrees (std per axis, plane
    coordinates), or 0 when the recording does not show it.

    For white noise of std σ, the ``k``-th difference of consecutive samples has std
    ``σ √C(2k, k)`` whatever ``k``; smooth motion contributes its ``k``-th derivative times
    ``Δtᵏ``, less with every order where the motion is well sampled (a 60 Hz optical recording:
    0.05° from second differences, 0.007° from fourth). So the estimate is the fourth-order
    figure when it is at least ``_WHITE_RATIO`` of the second-order one (the signature of white
    noise: a device-fused IMU gives 0.43° from both); otherwise the differences are the motion
    (slowly sampled motion looks rough at every order) and no noise is claimed."""
    if len(p) < 20:
        return 0.0
    s2, s4 = _difference_std(p, 2), _difference_std(p, 4)
    return s4 if s4 >= _WHITE_RATIO * s2 else 0.0


def _circular_centre(phi: np.ndarray) -> float:
    return float(np.angle(np.mean(np.exp(1j * phi))))


def _wrap(x):
    return (np.asarray(x) + math.pi) % (2.0 * math.pi) - math.pi


def _pileup_offset(depth: np.ndarray, band: float, bin_width: float, prominence: float) -> float:
    """Depth of the pile-up of samples just inside an envelope (0 when there is none).

    ``depth`` (≥ 0) is each sample's distance inward from the envelope. A limit the patient
    dwells on leaves a ridge of samples, blurred by measurement noise; the envelope sits on the
    ridge's outer tail, the ridge's crest on the limit. Returns the crest's depth: the mode of a
    histogram of ``depth`` over ``[0, band]`` (bins of ``bin_width``, smoothed over 3 bins),
    provided it stands ``prominence`` times above the median bin of the band; else 0.
    """
    d = depth[(depth >= 0) & (depth <= band)]
    if len(d) < 50:
        return 0.0
    edges = np.arange(0.0, band + bin_width, bin_width)
    h, _ = np.histogram(d, edges)
    hs = np.convolve(h, np.ones(3) / 3.0, mode="same")
    k = int(np.argmax(hs))
    if k == 0 or hs[k] < prominence * max(float(np.median(hs)), 1.0):
        return 0.0
    return float(0.5 * (edges[k] + edges[k + 1]))


def _visit_offset(depth: np.ndarray, near: np.ndarray, where: np.ndarray, segment: float,
                  gap: int, min_visits: int) -> tuple[float, int]:
    """How far inside the envelope a typical visit stopped (step 4b): ``near`` are the indices
    (recording order, ascending) of the samples within the band, ``where`` their nearest
    boundary point as arc length along the envelope. Returns the median over the stretches
    of ``segment`` degrees of the median over their visits of each visit's minimum depth, and
    the number of stretches used (0, 0 when none has ``min_visits`` visits)."""
    if not len(near):
        return 0.0, 0
    seg = np.floor(where / segment).astype(np.int64)
    order = np.lexsort((near, seg))  # by stretch, then in recording order
    seg, idx = seg[order], near[order]
    d = depth[idx]
    # a new visit where the stretch changes or the recording skips more than ``gap`` samples
    new = np.ones(len(idx), bool)
    new[1:] = (seg[1:] != seg[:-1]) | (np.diff(idx) > gap)
    visit = np.cumsum(new) - 1
    closest = np.full(visit[-1] + 1, np.inf)
    np.minimum.at(closest, visit, d)
    vseg = seg[new]
    values = []
    for k in np.unique(vseg):
        c = closest[vseg == k]
        if len(c) >= min_visits:
            values.append(float(np.median(c)))
    return (float(np.median(values)), len(values)) if values else (0.0, 0)


def _label(parts, xy: np.ndarray) -> np.ndarray:
    """Index of the part (polygons) covering each point (N, 2), or -1."""
    import shapely

    out = np.full(len(xy), -1, dtype=np.int64)
    for k, g in enumerate(parts):
        shapely.prepare(g)
        out[(out < 0) & shapely.intersects_xy(g, xy[:, 0], xy[:, 1])] = k
    return out


def _distance(geom, xy: np.ndarray, step: float = 0.05) -> np.ndarray:
    """Distance (N,) of points (N, 2) to the boundary of ``geom`` (or to a line), to within
    ``step / 2``: nearest of the boundary's points ``step`` apart (a k-d tree; exact distance to
    a ring of thousands of vertices is slow for 10⁵ points)."""
    line = geom if geom.geom_type in ("LineString", "LinearRing", "MultiLineString") \
        else geom.boundary
    return _ring_distance(line, xy, step)[0]


def _ring_distance(line, xy: np.ndarray, step: float = 0.05,
                   bound: float = math.inf) -> tuple[np.ndarray, np.ndarray]:
    """Distance (N,) of points (N, 2) to a line (:func:`_distance`) and, for a single ring or
    line, the arc length (N,) along it of their nearest point; both to within ``step / 2``, from
    one k-d tree query. Points farther than ``bound`` get ``inf`` (and arc 0): the tree stops
    searching for them, which makes the query several times faster on a recording whose
    samples are mostly far from the boundary."""
    import shapely
    from scipy.spatial import cKDTree

    pts = shapely.get_coordinates(shapely.segmentize(line, step))
    if len(xy) == 0 or len(pts) == 0:
        return np.zeros(len(xy)), np.zeros(len(xy))
    arc = np.concatenate(([0.0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1)), [0.0]))
    dist, k = cKDTree(pts).query(xy, distance_upper_bound=bound)
    return dist, arc[k]  # k == len(pts) beyond the bound: the appended 0


def _dwell_depth(depth: np.ndarray, band: float, min_samples: int,
                 max_iqr: float) -> tuple[int, float]:
    """Dwells at a limit: runs of consecutive samples with ``depth`` (degrees inward from the
    envelope, in recording order) within ``band``, at least ``min_samples`` long, whose
    interquartile range is at most ``max_iqr``. Returns their number and the median of their
    median depths (0 when there is none)."""
    idx = np.flatnonzero(depth <= band)
    if idx.size < min_samples:
        return 0, 0.0
    cuts = np.flatnonzero(np.diff(idx) > 1) + 1
    starts = np.concatenate(([0], cuts))
    ends = np.concatenate((cuts, [idx.size]))
    meds = []
    for a, b in zip(starts, ends, strict=True):
        if b - a < min_samples:
            continue
        q1, q2, q3 = np.percentile(depth[idx[a:b]], [25.0, 50.0, 75.0])
        if q3 - q1 <= max_iqr:
            meds.append(q2)
    return len(meds), (float(np.median(meds)) if meds else 0.0)


def _hold_twists(points: list[dict], bandwidth_deg: float, d: np.ndarray, tw: np.ndarray,
                 env_lo: float, env_hi: float) -> None:
    """Widen the table's intervals (in place) as little as possible so that its interpolated
    limits (:class:`models.constraint.SwingTwistTable`: kernel-weighted means of the points'
    limits) hold every recorded twist ``tw`` (degrees) at its direction ``d``: a linear
    programme per side — minimise the total widening ``Σ Δ_j ≥ 0`` subject to
    ``Σ_j r_ij (max_j + Δ_j) ≥ tw_i`` (``r_ij`` the normalised kernel weights) and
    ``max_j + Δ_j ≤`` the envelope, which every recorded twist is inside (so it is feasible),
    over the samples outside, re-solved until none is (cutting planes)."""
    from scipy.optimize import linprog

    from models.constraint import SwingTwistTable

    dirs = np.array([pt["direction"] for pt in points], dtype=np.float64)
    lo = np.array([pt["min_deg"] for pt in points], dtype=np.float64)
    hi = np.array([pt["max_deg"] for pt in points], dtype=np.float64)
    r = SwingTwistTable(bandwidth_deg, dirs, lo, hi).weights(d)  # (N, K)
    slack = 2e-3  # the file's 3 decimals, rounded outwards, keep a margin of 1e-3
    for limits, sign, bound in ((hi, 1.0, env_hi), (lo, -1.0, env_lo)):
        # in "sign" units the constraint reads r·(s·limits) + r·Δ >= s·tw, Δ <= s·bound - s·lim
        rows = np.zeros(0, dtype=np.int64)
        for _ in range(10):
            excess = sign * tw - r @ (sign * limits) + slack
            new = np.setdiff1d(np.flatnonzero(excess > 0), rows)
            if not len(new):
                break
            rows = np.union1d(rows, new)
            res = linprog(np.ones(len(limits)), A_ub=-r[rows],
                          b_ub=-(sign * tw[rows] - r[rows] @ (sign * limits) + slack),
                          bounds=list(zip(np.zeros(len(limits)),
                                          np.maximum(sign * bound - sign * limits, 0.0),
                                          strict=True)), method="highs")
            if not res.success:  # cannot happen (the envelope holds all): widen to it
                limits[:] = bound
                break
            limits += sign * res.x
    for pt, a, b in zip(points, lo, hi, strict=True):
        pt["min_deg"], pt["max_deg"] = float(a), float(max(a, b))


class BoundaryExtractor:
    """Recorded joint orientations → swing polygon, twist range, provenance (see module doc).

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
    limb_axis : (3,) array_like
        Limb long axis in the limb frame.
    name : str
        Name of the constraint produced.

    Attributes
    ----------
    constraint_ : JointConstraint
    centre_ : (3,) unit, projection centre
    vertices_ : (M, 3) polygon vertices; ``interior_`` (3,)
    twist_deg_ : (float, float), the twist envelope
    by_swing_ : dict or None, the contract-3 ``by_swing`` mapping
    by_swing_candidate_ : dict or None, the table computed (also when not emitted)
    sparse_arcs_ : list of SparseArc
    alpha_used_deg_ : float
    n_samples_, n_status_dropped_, n_spikes_, n_used_, n_glitch_cluster_ : int
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
    ) -> None:
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

    # -- fit -------------------------------------------------------------------------------
    def fit(self, q, *, status=None, t=None, provenance: dict | None = None,
            slow_error_deg: float | None = None) -> BoundaryExtractor:
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
            than ``jump_ratio`` times the recording's median step and more than 15°.
        slow_error_deg : float, optional
            Measured size of the recording's slowly varying errors (an IMU pair's relative
            heading drift left after the neutral-checkpoint correction, degrees): the evidence
            the visit estimate of the noise inset may use (step 4b). None: no such evidence,
            the inset comes from the measured fast noise only.
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
        q = Q.check_quaternions(q, normalize=True, name="joint orientation").reshape(-1, 4)
        self.n_samples_ = len(q)
        keep = np.ones(len(q), dtype=bool)
        if status is not None:
            st = np.asarray(status).reshape(-1)
            if len(st) != len(q):
                raise CalibrationError(f"status has {len(st)} entries for {len(q)} orientations")
            keep &= (st.astype(np.int64) >> 6) >= self.min_system_status
        self.n_status_dropped_ = int((~keep).sum())
        if keep.sum() < 100:
            raise CalibrationError(
                f"need at least 100 usable samples to extract a boundary, got {int(keep.sum())} "
                f"of {len(q)}"
                + (f" ({self.n_status_dropped_} dropped for calibration status "
                   f"< {self.min_system_status})" if self.n_status_dropped_ else "")
            )
        q = q[keep]
        if t is not None:
            t = np.asarray(t, dtype=np.float64).reshape(-1)
            if len(t) != self.n_samples_:
                raise CalibrationError(f"t has {len(t)} entries for {self.n_samples_} "
                                       "orientations")
            t = t[keep]
            if not np.isfinite(t).all() or (np.diff(t) < 0).any():
                raise CalibrationError("sample times must be finite and non-decreasing")
        d = Q.rotate(q, self.limb_axis)
        phi = Q.twist_angle(q, self.limb_axis)
        self.recorded_ = d  # every usable recorded direction: what "inside" is measured on
        spikes = _spikes(d, t, self.max_speed_dps, self.spike_max_samples)
        self.n_spikes_ = int(spikes.sum())
        d, phi = d[~spikes], phi[~spikes]
        t = None if t is None else t[~spikes]
        self.slow_error_deg_ = None if slow_error_deg is None else float(slow_error_deg)
        c = self._centre(d)
        u, v = _tangent_basis(c)
        p = _ae_forward(d, c, u, v)
        links = _links(d, t, self.max_speed_dps)
        self.noise_deg_ = _fast_noise(p)
        if np.hypot(p[:, 0], p[:, 1]).max() > 150.0:
            raise CalibrationError(
                "recorded directions span more than 150 deg from their centre; a swing region "
                "this large cannot be extracted"
            )
        self.n_used_ = len(p)
        poly = self._alpha_region(p, links)
        import shapely

        held = shapely.contains_xy(poly, p[:, 0], p[:, 1])  # what the written boundary must hold
        tol, margin = self.simplify_deg, _MARGIN_DEG
        for attempt in range(6):
            verts2d = self._simplify(poly, tol, margin)
            try:
                self._finish(verts2d, poly, p, d, phi, c, u, v, provenance)
            except CalibrationError:
                # a corridor simplified to straight lines in the plane can still cross itself
                # on the sphere (great-circle edges): simplify further
                if attempt == 5:
                    raise
                tol *= 2.0
                continue
            o, _ = _swing_oracle(self.constraint_)
            if not held.any() or (o.swing_distance(d[held]) <= 0.0).all():
                break
            # a great-circle edge bulges inwards of its straight image in the plane by more
            # than the margin: widen it
            margin *= 3.0
        return self

    def _centre(self, d: np.ndarray) -> np.ndarray:
        m = d.mean(axis=0)
        if np.linalg.norm(m) < 0.2:
            raise CalibrationError(
                "recorded directions have no clear centre (spread over the whole sphere)"
            )
        c = m / np.linalg.norm(m)
        ang = Q.angle_between(d, c)
        near = ang <= np.quantile(ang, 0.95)
        m = d[near].mean(axis=0)
        return m / np.linalg.norm(m)

    def _grid(self, p: np.ndarray):
        h = self.cell_deg
        ij = np.floor(p / h).astype(np.int64)
        lo = ij.min(axis=0)
        ij -= lo
        shape = tuple(ij.max(axis=0) + 1)
        return ij, shape, lo

    def _cell_means(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The points the alpha shape is built on: each occupied cell's mean position
        (``counts`` its samples, ``inv`` each sample's cell), then, for the cells at the edge
        of the occupied area (a 4-neighbour empty), the cell's outermost samples in eight
        directions (count 0: geometry, not evidence; cells of one sample have it as their
        mean): the envelope passes through the recorded samples, not through cell means up to
        half a cell inside them."""
        ij, shape, _ = self._grid(p)
        flat = ij[:, 0] * shape[1] + ij[:, 1]
        uniq, inv, counts = np.unique(flat, return_inverse=True, return_counts=True)
        inv = inv.reshape(-1)
        sx = np.bincount(inv, weights=p[:, 0])
        sy = np.bincount(inv, weights=p[:, 1])
        means = np.column_stack((sx / counts, sy / counts))
        occ = np.zeros((shape[0] + 2, shape[1] + 2), dtype=bool)
        ci, cj = uniq // shape[1] + 1, uniq % shape[1] + 1
        occ[ci, cj] = True
        edge = ~(occ[ci - 1, cj] & occ[ci + 1, cj] & occ[ci, cj - 1] & occ[ci, cj + 1])
        sel = np.flatnonzero(edge[inv] & (counts[inv] > 1))
        if not len(sel):
            return means, counts, inv
        cell = inv[sel]
        extra = []
        for a in np.arange(8) * (math.pi / 4.0):
            score = p[sel, 0] * math.cos(a) + p[sel, 1] * math.sin(a)
            order = np.lexsort((score, cell))
            last = np.flatnonzero(np.r_[cell[order][1:] != cell[order][:-1], True])
            extra.append(sel[order[last]])
        extra = np.unique(np.concatenate(extra))
        return (np.concatenate((means, p[extra])),
                np.concatenate((counts, np.zeros(len(extra), dtype=counts.dtype))), inv)

    def _alpha_region(self, p: np.ndarray, links: np.ndarray):
        """Alpha shape joined along the recorded trajectory (step 4); sets the join state."""
        import shapely
        from scipy.sparse import coo_matrix
        from scipy.sparse.csgraph import connected_components
        from scipy.spatial import Delaunay, QhullError

        pts, counts, inv = self._cell_means(p)
        if len(pts) < 3:
            raise CalibrationError("the recorded directions cover too small an area")
        try:
            tri = Delaunay(pts)
        except QhullError as err:
            raise CalibrationError(
                "the recorded directions are degenerate (all on one line)"
            ) from err
        a, b, cc = (pts[tri.simplices[:, k]] for k in range(3))
        la = np.linalg.norm(b - cc, axis=1)
        lb = np.linalg.norm(a - cc, axis=1)
        lc = np.linalg.norm(a - b, axis=1)
        area2 = np.abs((b[:, 0] - a[:, 0]) * (cc[:, 1] - a[:, 1])
                       - (b[:, 1] - a[:, 1]) * (cc[:, 0] - a[:, 0]))
        circum = la * lb * lc / np.maximum(2.0 * area2, 1e-300)
        # the triangulation's edges, each once
        e = np.sort(np.concatenate([tri.simplices[:, [0, 1]], tri.simplices[:, [1, 2]],
                                    tri.simplices[:, [2, 0]]]), axis=1)
        e = np.unique(e, axis=0)
        elen = np.linalg.norm(pts[e[:, 0]] - pts[e[:, 1]], axis=1)
        # trajectory edges between cells: the limb moved continuously from one to the other
        ta, tb = inv[:-1][links], inv[1:][links]
        moved = ta != tb
        ta, tb = ta[moved], tb[moved]
        n = len(pts)
        total = counts.sum()
        alpha = self.alpha_deg
        best = None
        for _ in range(5):
            sel = tri.simplices[circum < alpha]
            if len(sel):
                # connected: within 2 alpha (the longest edge an alpha triangle can have) or
                # along the trajectory
                near = elen < 2.0 * alpha
                ea = np.concatenate((e[near, 0], ta))
                eb = np.concatenate((e[near, 1], tb))
                graph = coo_matrix((np.ones(len(ea)), (ea, eb)), shape=(n, n))
                _, label = connected_components(graph, directed=False)
                weight = np.bincount(label, weights=counts)
                main = int(np.argmax(weight))
                in_main = label == main
                # clusters joined to the main one neither in space nor along the trajectory,
                # each holding less than ``cluster_share``: isolated glitch clusters
                glitch = ~in_main & (weight[label] < self.cluster_share * total)
                evidence = total - counts[glitch].sum()
                mine = sel[in_main[sel[:, 0]]]
                rings = np.concatenate((pts[mine], pts[mine][:, :1]), axis=1)
                union = shapely.coverage_union_all(shapely.polygons(rings))
                # alpha is large enough when one piece of the shape holds the evidence: a
                # sparse recording splits the shape into pieces (and leaves pockets between
                # them), which a larger alpha joins
                parts = list(getattr(union, "geoms", [union]))
                held = max(counts[shapely.contains_xy(g.buffer(self.cell_deg), pts[:, 0],
                                                      pts[:, 1])].sum() for g in parts) / evidence
                keep = in_main[e[:, 0]] & (elen < 2.0 * alpha)
                self._join_state = (union, pts, counts, inv, in_main, links, e[keep], elen[keep])
                region = None
                self.alpha_used_deg_ = float(alpha)
                if held >= self.coverage:
                    # and the joined, inset region holds it too, but for the inset band (a
                    # pocket of the shape opening onto the outside can leave a stretch of the
                    # boundary the limb slid along out)
                    region = self._noise_inset(self._hold(self._join(union, union, p), p), p)
                    tol = self.cell_deg + self.inset_deg_
                    held = counts[shapely.contains_xy(region.buffer(tol), pts[:, 0],
                                                      pts[:, 1])].sum() / evidence
                best = (held, alpha, region, self._join_state, glitch)
                if held >= self.coverage:
                    break
            alpha *= 1.5
        if best is None:
            raise CalibrationError("no alpha shape could be formed from the recorded directions")
        held, alpha, region, self._join_state, glitch = best
        self.coverage_ = float(held)
        self.n_glitch_cluster_ = int(counts[glitch].sum())
        self.alpha_used_deg_ = float(alpha)
        if region is None:
            region = self._hold(self._join(self._join_state[0], self._join_state[0], p), p)
            region = self._noise_inset(region, p)
        return region

    def _join(self, union, reference, p):
        """The part of ``union`` holding most samples, joined to the others by the trajectory.

        Cells are labelled by the part of ``union`` they lie in. A *run* is a stretch of linked
        samples (all in the main cluster) between two consecutive labelled samples: a
        **transit** when the labels differ (the limb went from one part to another), an
        **excursion** when they agree but the run leaves ``reference`` by more than
        ``cell_deg`` (recorded range outside the alpha shape).
        Runs also at the ends of a stretch of linked samples (leaving a part and not coming
        back). The runs are buffered by ``cell_deg / 2`` and merged; of the result, the part
        holding most samples is kept and its holes filled.
        """
        import shapely

        _, pts, counts, inv, in_main, links, _, _ = self._join_state
        parts = [g for g in getattr(union, "geoms", [union]) if not g.is_empty]
        cell_part = _label(parts, pts)
        lab = np.where(in_main[inv], cell_part[inv], -2)  # -2: not in the main cluster
        ok = links & (lab[:-1] != -2) & (lab[1:] != -2)
        chain = np.concatenate(([0], np.cumsum(~ok)))
        k = np.flatnonzero(lab >= 0)
        runs = []
        if len(k):
            k1, k2 = k[:-1], k[1:]
            same_chain = chain[k1] == chain[k2]
            transit = same_chain & (lab[k1] != lab[k2])
            excursion = same_chain & (lab[k1] == lab[k2]) & (k2 - k1 > 1)
            runs.append(np.column_stack((k1[transit], k2[transit])))
            ends = []
            exc = np.column_stack((k1[excursion], k2[excursion]))
            # stretches that leave a part and end (or begin) outside every part
            first = np.ones(len(k), dtype=bool)
            first[1:] = chain[k[1:]] != chain[k[:-1]]
            last = np.ones(len(k), dtype=bool)
            last[:-1] = first[1:]
            start_of = np.searchsorted(chain, chain[k[first]], side="left")
            end_of = np.searchsorted(chain, chain[k[last]], side="right") - 1
            ends.append(np.column_stack((start_of, k[first])))
            ends.append(np.column_stack((k[last], end_of)))
            cand = np.concatenate([exc, *ends])
            cand = cand[cand[:, 1] > cand[:, 0]]
            if len(cand):
                runs.append(self._leaving(cand, reference, p, lab))
        runs = np.concatenate(runs) if runs else np.zeros((0, 2), dtype=np.int64)
        geoms = parts
        if len(runs):
            length = runs[:, 1] - runs[:, 0] + 1
            ids = np.repeat(np.arange(len(runs)), length)
            idx = np.repeat(runs[:, 0] - np.cumsum(np.r_[0, length[:-1]]), length) \
                + np.arange(length.sum())
            lines = shapely.linestrings(p[idx], indices=ids)
            geoms = [*parts, *shapely.buffer(lines, 0.5 * self.cell_deg, quad_segs=2)]
        if not geoms:
            raise CalibrationError("no alpha shape could be formed from the recorded directions")
        # closing by one cell: a slit narrower than two cells between the pieces is no
        # evidence of a limit (it would leave an unvisited pocket in the region)
        # (united with the pieces themselves: the closing would erase a sliver of the alpha
        # shape along a boundary the limb slid along, which encloses such a pocket)
        r = self.cell_deg
        merged = shapely.union_all(geoms)
        merged = shapely.union(merged.buffer(r, quad_segs=4).buffer(-r, quad_segs=4), merged)
        pieces = list(getattr(merged, "geoms", [merged]))
        if len(pieces) > 1:
            pieces = self._bridge(pieces)
        held = [counts[shapely.intersects_xy(g, pts[:, 0], pts[:, 1])].sum() for g in pieces]
        return shapely.Polygon(pieces[int(np.argmax(held))].exterior)

    def _hold(self, poly, p: np.ndarray):
        """``poly`` reaching out to every sample of the main cluster still outside it (a
        trajectory that grazed the shape by less than ``cell_deg``, so no excursion of step
        4 ii): joined by a strip 0.02° wide from the nearest point of the region, so the
        envelope touches it."""
        import shapely

        _, _, _, inv, in_main, _, _, _ = self._join_state
        evidence = in_main[inv]  # not the samples of glitch clusters (step 4 i)
        out = p[evidence & ~shapely.contains_xy(poly, p[:, 0], p[:, 1])]
        if not len(out):
            return poly
        # one sample per occupied 0.05° cell is enough to hold them all within that
        key = np.unique(np.floor(out / 0.05).astype(np.int64), axis=0, return_index=True)[1]
        lines = shapely.shortest_line(poly, shapely.points(out[key]))
        strips = shapely.buffer(lines, 0.01, quad_segs=1)
        merged = shapely.union_all([poly, *strips])
        pieces = list(getattr(merged, "geoms", [merged]))
        return shapely.Polygon(max(pieces, key=lambda g: g.area).exterior)

    def _bridge(self, pieces):
        """Join pieces of the region that the trajectory did not join (a lobe the limb was only
        ever seen inside): along the minimax path through the recorded cells from each piece
        to the piece holding most samples, edges shorter than ``2 alpha`` (local alpha growth
        along the Euclidean minimum spanning tree, which holds every minimax path). Pieces
        with fewer than ``min_piece_samples`` samples are left alone (they fall away)."""
        import shapely
        from scipy.sparse import coo_matrix
        from scipy.sparse.csgraph import breadth_first_order, minimum_spanning_tree

        _, pts, counts, _, _, _, e, elen = self._join_state
        n = len(pts)
        cp = _label(pieces, pts)
        held = np.bincount(cp[cp >= 0], weights=counts[cp >= 0], minlength=len(pieces))
        main = int(np.argmax(held))
        # inside one piece an edge costs (almost) nothing: the tree crosses between pieces on
        # the shortest edges
        inside = (cp[e[:, 0]] == cp[e[:, 1]]) & (cp[e[:, 0]] >= 0)
        w = np.where(inside, 1e-9, elen)
        tree = minimum_spanning_tree(coo_matrix((w, (e[:, 0], e[:, 1])), shape=(n, n)).tocsr())
        root = int(np.flatnonzero(cp == main)[0])
        _, pred = breadth_first_order(tree, root, directed=False, return_predecessors=True)
        segs = []
        for k in np.flatnonzero(held >= self.min_piece_samples):
            if k == main:
                continue
            node = int(np.flatnonzero(cp == k)[0])
            path = []
            while node >= 0 and cp[node] != main:
                nxt = int(pred[node])
                if nxt >= 0 and not (cp[node] == cp[nxt] and cp[node] >= 0):
                    path.append((node, nxt))
                node = nxt
            if node >= 0:  # reached the main piece
                segs.extend(path)
        if not segs:
            return pieces
        s = np.asarray(segs)
        lines = shapely.linestrings(np.stack((pts[s[:, 0]], pts[s[:, 1]]), axis=1))
        merged = shapely.union_all([*pieces, *shapely.buffer(lines, 0.5 * self.cell_deg,
                                                             quad_segs=2)])
        return list(getattr(merged, "geoms", [merged]))

    def _leaving(self, cand, reference, p, lab):
        """Of candidate runs (M, 2), those with a sample more than ``cell_deg`` outside
        ``reference``."""
        import shapely

        length = cand[:, 1] - cand[:, 0] + 1
        ids = np.repeat(np.arange(len(cand)), length)
        idx = np.repeat(cand[:, 0] - np.cumsum(np.r_[0, length[:-1]]), length) \
            + np.arange(length.sum())
        outside = lab[idx] < 0
        far = np.zeros(len(cand), dtype=bool)
        if outside.any():
            xy = p[idx[outside]]
            dist = np.where(shapely.intersects_xy(reference, xy[:, 0], xy[:, 1]), 0.0,
                            _distance(reference, xy))
            np.maximum.at(far, ids[outside], dist > self.cell_deg)
        return cand[far]

    def _noise_inset(self, poly, p: np.ndarray):
        """Move the envelope in to the crest of the boundary pile-up (step 4b)."""
        import shapely

        self.inset_deg_ = 0.0
        self.inset_estimates_ = {"noise_deg": round(self.noise_deg_, 4), "pileup_deg": 0.0,
                                 "visit_deg": 0.0, "visit_stretches": 0,
                                 "slow_error_deg": self.slow_error_deg_}
        if not self.noise_correction:
            return poly
        ring = poly.exterior
        inside = shapely.contains_xy(poly, p[:, 0], p[:, 1])
        dist, arc = _ring_distance(ring, p, bound=max(self.pileup_band_deg,
                                                      self.visit_band_deg) + 1.0)
        depth = np.where(inside, dist, 0.0)
        pileup = _pileup_offset(depth, self.pileup_band_deg, 0.2, 2.0)
        visit, stretches = 0.0, 0
        if self.slow_error_deg_:
            near = np.flatnonzero(depth <= self.visit_band_deg)
            visit, stretches = _visit_offset(depth, near, arc[near], self.visit_segment_deg,
                                             self.visit_gap_samples, self.visit_min)
        self.inset_estimates_.update({"pileup_deg": round(pileup, 3),
                                      "visit_deg": round(visit, 3),
                                      "visit_stretches": stretches})
        # each estimate only as far as the measured errors support it: white noise blurs the
        # envelope out by a few of its standard deviations, slow errors by about their size
        fast = min(pileup, _NOISE_REACH * self.noise_deg_)
        slow = min(visit, _NOISE_REACH * (self.slow_error_deg_ or 0.0))
        inset = max(fast, slow)
        if inset <= 0.0:
            return poly
        union = self._join_state[0]
        shrunk = poly.buffer(-inset, join_style="round")
        if shrunk.is_empty:
            return poly
        self.inset_deg_ = inset
        # the shrunk parts joined again along the trajectory (a neck narrower than twice the
        # inset, or a corridor, does not cut a recorded lobe off)
        return self._join(shrunk, union, p)

    def _simplify(self, poly, tol: float, margin: float) -> np.ndarray:
        """Vertices (M, 2) of a polygon *around* ``poly`` with at most ``max_vertices``:
        Douglas-Peucker with tolerance ``tol`` of ``poly`` grown by ``tol + margin``, whose
        boundary then lies between ``margin`` and ``2 tol + margin`` outside ``poly`` — nothing
        the region holds is cut off; ``tol`` grows by 1.25× until the budget is met."""
        for _ in range(40):
            grown = poly.buffer(tol + margin, quad_segs=4)
            s = grown.simplify(tol, preserve_topology=True)
            if s.geom_type == "Polygon" and s.is_valid and s.area > 0:
                ring = np.asarray(s.exterior.coords)[:-1]
                if len(ring) <= self.max_vertices:
                    return ring
            tol *= 1.25
        raise CalibrationError("could not simplify the boundary to the vertex budget")

    def _finish(self, verts2d, poly, p, d, phi, c, u, v, provenance) -> None:
        from shapely.ops import polylabel

        verts = _ae_inverse(verts2d, c, u, v)
        # interior: the pole of inaccessibility, or the centre when it is nearly as deep
        import shapely

        spoly = shapely.Polygon(verts2d)
        pole = polylabel(spoly, tolerance=0.1)
        depth_pole = spoly.exterior.distance(pole)
        origin = shapely.Point(0.0, 0.0)
        interior2d = np.array([[pole.x, pole.y]])
        if spoly.contains(origin) and spoly.exterior.distance(origin) >= 0.5 * depth_pole:
            interior2d = np.zeros((1, 2))
        interior = _ae_inverse(interior2d, c, u, v)[0]
        self.centre_ = c
        self.vertices_ = verts
        self.interior_ = interior
        # twist: the envelope of the kept samples, each end moved in only as far as the
        # measured errors support (step 6)
        mid = _circular_centre(phi)
        rel = _wrap(phi - mid)
        lo, hi = float(rel.min()), float(rel.max())
        self.twist_noise_deg_ = _fast_noise(np.degrees(np.unwrap(phi))[:, None])
        self.twist_inset_deg_ = (0.0, 0.0)
        self.twist_dwells_ = (0, 0)
        if self.noise_correction:
            insets, dwells = [], []
            for depth in (np.degrees(rel - lo), np.degrees(hi - rel)):
                fast = min(_pileup_offset(depth, self.pileup_band_deg, 0.25, 2.0),
                           _NOISE_REACH * self.twist_noise_deg_)
                k, med = _dwell_depth(depth, self.twist_dwell_band_deg,
                                      self.twist_dwell_min_samples, self.twist_dwell_max_iqr_deg)
                dwells.append(k)
                slow = min(med, _NOISE_REACH * (self.slow_error_deg_ or 0.0)) \
                    if k >= self.twist_dwell_min_runs else 0.0
                insets.append(max(fast, slow))
            a, b = insets
            lo, hi = lo + math.radians(a), hi - math.radians(b)
            self.twist_inset_deg_ = (a, b)
            self.twist_dwells_ = (dwells[0], dwells[1])
        tw_lo = math.degrees(float(np.clip(lo + mid, -math.pi, math.pi)))
        tw_hi = math.degrees(float(np.clip(hi + mid, -math.pi, math.pi)))
        if tw_lo > tw_hi:  # the range crosses ±180°: keep the larger side, say so
            tw_lo, tw_hi = (tw_lo, 180.0) if 180.0 - tw_lo >= tw_hi + 180.0 else (-180.0, tw_hi)
        self.twist_deg_ = (tw_lo, tw_hi)
        self.by_swing_candidate_ = self._twist_table(d, rel, mid, verts, interior, spoly, c, u, v)
        table = self.by_swing_candidate_
        emit = False
        if table is not None and self.by_swing is True:
            emit = True
        elif table is not None and self.by_swing == "auto":
            mins = np.array([pt["min_deg"] for pt in table["points"]])
            maxs = np.array([pt["max_deg"] for pt in table["points"]])
            emit = bool(max(mins.max() - tw_lo, tw_hi - maxs.min()) > self.by_swing_min_diff_deg)
        self.by_swing_ = table if emit else None
        self.sparse_arcs_ = self._sparse_arcs(verts, d)
        prov = dict(provenance or {})
        prov.update({
            "method": "calibration.boundary.BoundaryExtractor",
            "parameters": self.params(),
            "samples": int(self.n_samples_),
            "samples_used": int(self.n_used_),
            "dropped_status": int(self.n_status_dropped_),
            "spikes": int(self.n_spikes_),
            "glitch_cluster_samples": int(self.n_glitch_cluster_),
            "alpha_used_deg": round(self.alpha_used_deg_, 3),
            "noise_inset_deg": round(self.inset_deg_, 3),
            "noise_inset_estimates": dict(getattr(self, "inset_estimates_", {})),
            "twist_noise_inset_deg": [round(x, 3) for x in self.twist_inset_deg_],
            "twist_dwells": list(self.twist_dwells_),
            "sparse_arcs": [a.to_dict() for a in self.sparse_arcs_],
        })
        twist: dict[str, Any] = {"min_deg": max(-180.0, math.floor(tw_lo * 1000.0) / 1000.0),
                                 "max_deg": min(180.0, math.ceil(tw_hi * 1000.0) / 1000.0)}
        if self.by_swing_ is not None:
            twist["by_swing"] = self.by_swing_
        data = {
            "name": self.name,
            "limb_axis": [float(x) for x in self.limb_axis],
            "swing": {"polygon": {"vertices": verts.tolist(), "interior": interior.tolist()}},
            "twist": twist,
            "provenance": prov,
        }
        try:
            constraint = JointConstraint.from_dict(data)
        except ConstraintError as err:
            raise CalibrationError(f"the extracted boundary is not a valid constraint: {err}") \
                from err
        # what the written boundary holds, measured on it: every usable recorded direction
        # (spikes included), the exact oracle's signed distance
        o, _ = _swing_oracle(constraint)
        dist = np.degrees(o.swing_distance(self.recorded_))
        self.inside_ = float(np.mean(dist <= 0.0))
        self.inside_1deg_ = float(np.mean(dist <= 1.0))
        self.outside_max_deg_ = float(max(0.0, dist.max()))
        data["provenance"]["inside"] = {
            "share": round(self.inside_, 5), "within_1deg": round(self.inside_1deg_, 5),
            "farthest_outside_deg": round(self.outside_max_deg_, 3),
            "directions": len(self.recorded_)}
        self.constraint_ = JointConstraint.from_dict(data)

    def _twist_table(self, d, rel, mid, verts, interior, spoly, c, u, v):
        """Kernel-weighted twist percentiles at grid directions inside the polygon."""
        import shapely

        step = self.by_swing_spacing_deg
        minx, miny, maxx, maxy = spoly.bounds
        gx = np.arange(math.floor(minx / step), math.ceil(maxx / step) + 1) * step
        gy = np.arange(math.floor(miny / step), math.ceil(maxy / step) + 1) * step
        xx, yy = np.meshgrid(gx, gy)
        grid = np.column_stack((xx.ravel(), yy.ravel()))
        grid = grid[shapely.contains_xy(spoly, grid[:, 0], grid[:, 1])]
        if len(grid) < 2:
            return None
        dirs = _ae_inverse(grid, c, u, v)
        beta = math.radians(self.by_swing_bandwidth_deg)
        kappa = 1.0 / (1.0 - math.cos(beta))
        points = []
        env_lo, env_hi = self.twist_deg_
        for di in dirs:
            w = np.exp(kappa * (d @ di - 1.0))
            sw = w.sum()
            if sw <= 0 or sw * sw / (w @ w) < self.by_swing_min_samples:
                continue
            near = d @ di >= math.cos(beta)  # the samples within the bandwidth: their extremes
            if not near.any():
                continue
            a, b = float(rel[near].min()), float(rel[near].max())
            a = float(np.clip(math.degrees(a + mid), env_lo, env_hi))
            b = float(np.clip(math.degrees(b + mid), env_lo, env_hi))
            points.append({"direction": [round(float(x), 6) for x in di],
                           "min_deg": a, "max_deg": max(a, b)})
        if len(points) < 3:
            return None
        _hold_twists(points, self.by_swing_bandwidth_deg, d,
                     np.degrees(_wrap(rel + mid)), env_lo, env_hi)
        for pt in points:  # rounded outwards: the file holds what the table holds
            pt["min_deg"] = math.floor(pt["min_deg"] * 1000.0) / 1000.0
            pt["max_deg"] = math.ceil(pt["max_deg"] * 1000.0) / 1000.0
        return {"bandwidth_deg": self.by_swing_bandwidth_deg, "points": points}

    def _sparse_arcs(self, verts: np.ndarray, d: np.ndarray) -> list[SparseArc]:
        from scipy.spatial import cKDTree

        pts, seg_len = boundary_points(verts, step_deg=0.5)
        tree = cKDTree(d)
        chord = 2.0 * math.sin(math.radians(self.sparse_deg) / 2.0)
        counts = tree.query_ball_point(pts, chord, return_length=True)
        sparse = counts < self.sparse_min_samples
        arcs: list[SparseArc] = []
        if not sparse.any():
            return arcs
        n = len(pts)
        if sparse.all():
            return [SparseArc(pts[0], pts[-1], float(seg_len.sum()))]
        # rotate so that the sequence starts on a non-sparse point, then group runs
        start = int(np.argmin(sparse))
        order = (np.arange(n) + start) % n
        run: list[int] = []
        for k in [*list(order), order[0]]:
            if sparse[k]:
                run.append(int(k))
            elif run:
                length = float(seg_len[run].sum())
                if length >= 1.0:
                    arcs.append(SparseArc(pts[run[0]], pts[run[-1]], length))
                run = []
        return arcs

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
        }


# -- accuracy measures ------------------------------------------------------------------------
def boundary_points(vertices, step_deg: float = 0.25) -> tuple[np.ndarray, np.ndarray]:
    """Points evenly spaced along a spherical polygon's great-circle edges.

    Parameters
    ----------
    vertices : (M, 3) array_like, unit, in boundary order
    step_deg : float, spacing along each edge (at most)

    Returns
    -------
    points : (K, 3) unit
    length_deg : (K,) arc length each point stands for (sums to the perimeter)
    """
    v = Q.check_vectors(vertices, name="vertices")
    w = np.roll(v, -1, axis=0)
    out, lens = [], []
    for a, b in zip(v, w, strict=True):
        ang = float(Q.angle_between(a, b))
        n = max(1, math.ceil(math.degrees(ang) / step_deg))
        t = (np.arange(n) + 0.5) / n
        s = math.sin(ang)
        pts = (np.sin((1 - t) * ang)[:, None] * a + np.sin(t * ang)[:, None] * b) / s
        out.append(pts)
        lens.append(np.full(n, math.degrees(ang) / n))
    return np.concatenate(out), np.concatenate(lens)


def _swing_oracle(constraint_or_vertices, interior=None):
    from models.oracle import ConstraintOracle

    if isinstance(constraint_or_vertices, JointConstraint):
        c = constraint_or_vertices
        return ConstraintOracle(JointConstraint.from_dict(
            {"name": "swing", "limb_axis": [float(x) for x in c.limb_axis],
             "swing": c.swing.to_dict()})), c.swing
    raise TypeError("expected a JointConstraint")


def _boundary_vertices(swing, step_deg):
    if hasattr(swing, "vertices"):
        return boundary_points(swing.vertices, step_deg)
    # a cone: a circle of points
    c = np.asarray(swing.centre, dtype=float)
    u, v = _tangent_basis(c)
    n = max(8, math.ceil(360.0 * math.sin(swing.radius) / step_deg))
    a = 2 * math.pi * (np.arange(n) + 0.5) / n
    r = swing.radius
    pts = math.cos(r) * c + math.sin(r) * (np.cos(a)[:, None] * u + np.sin(a)[:, None] * v)
    return pts, np.full(n, 360.0 * math.sin(r) / n)


def boundary_distance(a: JointConstraint, b: JointConstraint, step_deg: float = 0.25) -> dict:
    """Symmetric mean boundary-to-boundary distance of two swing regions (see module doc).

    Returns
    -------
    dict with ``mean_deg`` (the symmetric mean ``D``), ``a_to_b_deg``, ``b_to_a_deg`` (directed
    arc-length-weighted means), ``hausdorff_deg`` (largest point distance either way).
    """
    oa, sa = _swing_oracle(a)
    ob, sb = _swing_oracle(b)
    pa, la = _boundary_vertices(sa, step_deg)
    pb, lb = _boundary_vertices(sb, step_deg)
    da = np.degrees(np.abs(ob.swing_distance(pa)))
    db = np.degrees(np.abs(oa.swing_distance(pb)))
    ab = float(np.sum(da * la) / la.sum())
    ba = float(np.sum(db * lb) / lb.sum())
    return {"mean_deg": 0.5 * (ab + ba), "a_to_b_deg": ab, "b_to_a_deg": ba,
            "hausdorff_deg": float(max(da.max(), db.max()))}


def outside_fraction(constraint: JointConstraint, directions, tolerance_deg: float = 1.0) -> float:
    """Fraction of limb directions (N, 3) more than ``tolerance_deg`` outside the swing region."""
    o, _ = _swing_oracle(constraint)
    dist = o.swing_distance(Q.check_vectors(directions, name="directions"))
    return float(np.mean(dist > math.radians(tolerance_deg)))
