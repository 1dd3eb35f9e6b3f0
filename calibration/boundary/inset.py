"""How far inside a recorded envelope the limit lies: measured errors only (steps 3, 4b, 6).

A limit the patient dwells on leaves a ridge of samples blurred by measurement error; the
envelope of the samples sits on the ridge's outer tail. Each estimate of how far inside it the
limit lies is used only as far as a *measured* error supports it, capped at ``NOISE_REACH``
times that error (the largest of a few hundred Gaussian draws):

- **white noise** (:func:`fast_noise`): for white noise of std σ the ``k``-th difference of
  consecutive samples has std ``σ √C(2k, k)`` whatever ``k``; smooth motion contributes its
  ``k``-th derivative times ``Δtᵏ``, less at every order where the motion is well sampled. The
  robust std of the fourth differences over √70 is the noise when it is at least
  ``WHITE_RATIO`` of the second-order figure (white noise's signature); otherwise the
  differences are motion and no noise is claimed. Its estimate of the inset is the ridge's
  crest (:func:`pileup_offset`), capped at 3σ;
- **slow errors** (a fused heading wandering between visits shifts whole visits), given as a
  measured ``slow_error_deg`` (the heading correction's own uncertainty): the typical visit's
  closest approach to the swing envelope (:func:`visit_offset`) or the typical dwell's depth
  at a twist limit (:func:`dwell_depth`), capped at 3× that error. Without a measured slow
  error, visits that stop short of a limit are what people do, and are not taken off.

These estimators work on any depth inward from an envelope (plane distance for the swing
region, degrees of angle for the twist, and so for a hinge's angle interval).
:func:`swing_inset` combines them for a swing region; the shrinking itself and the re-joining
of the shrunk pieces is :func:`calibration.boundary.region.apply_inset`.

Documented in docs/calibration.md, "Boundary extraction", steps 3 (measured noise), 4b and 6.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from calibration.boundary.planar import ring_distance

__all__ = [
    "NOISE_REACH",
    "WHITE_RATIO",
    "InsetEstimate",
    "InsetSettings",
    "difference_std",
    "dwell_depth",
    "dwell_medians",
    "fast_noise",
    "pileup_offset",
    "swing_inset",
    "visit_offset",
]

#: How far outside the limit white noise of std σ (per axis) carries the envelope of the
#: samples pressed against it, in σ: the largest of a few hundred draws of a Gaussian.
NOISE_REACH = 3.0
#: White noise gives the same figure from every order of difference; smooth motion gives less
#: from each higher order. Below this ratio of the 4th-order figure to the 2nd-order one, the
#: differences are motion, and the noise — smaller still — cannot be told from it.
WHITE_RATIO = 0.6


def difference_std(p: np.ndarray, k: int) -> float:
    """Robust (MAD) standard deviation per axis of the ``k``-th differences of consecutive
    rows of ``p`` (N, D), divided by the factor white noise gains (``√Σ C(k, i)²``), averaged
    over the axes."""
    dk = np.diff(p, n=k, axis=0)
    mad = np.median(np.abs(dk - np.median(dk, axis=0)), axis=0)
    return float(np.mean(1.4826 * mad) / math.sqrt(math.comb(2 * k, k)))


def fast_noise(p: np.ndarray) -> float:
    """White measurement noise of consecutive samples ``p`` (N, D) (std per axis, in the units
    of ``p``), or 0 when the recording does not show it (module doc).

    A 60 Hz optical recording gives 0.05° from second differences and 0.007° from fourth ones
    (motion: no noise claimed); a device-fused IMU gives 0.43° from both (white noise)."""
    if len(p) < 20:
        return 0.0
    s2, s4 = difference_std(p, 2), difference_std(p, 4)
    return s4 if s4 >= WHITE_RATIO * s2 else 0.0


def pileup_offset(depth: np.ndarray, band: float, bin_width: float, prominence: float) -> float:
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


def visit_offset(depth: np.ndarray, near: np.ndarray, where: np.ndarray, segment: float,
                 gap: int, min_visits: int) -> tuple[float, int]:
    """How far inside the envelope a typical visit stopped (step 4b).

    ``depth`` (N,) is every sample's depth inside the envelope, ``near`` the indices
    (recording order, ascending) of the samples within the band, ``where`` their nearest
    boundary point as arc length along the envelope. The envelope is cut into stretches of
    ``segment``; in each, a visit is a run of samples in recording order with no gap longer
    than ``gap`` samples, and its closest approach is its minimum depth. Returns the median
    over the stretches with at least ``min_visits`` visits of the median closest approach, and
    the number of such stretches (0, 0 when there is none)."""
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


def dwell_depth(depth: np.ndarray, band: float, min_samples: int,
                max_iqr: float) -> tuple[int, float]:
    """Dwells at a limit: runs of consecutive samples with ``depth`` (degrees inward from the
    envelope, in recording order) within ``band``, at least ``min_samples`` long, whose
    interquartile range is at most ``max_iqr``. Returns their number and the median of their
    median depths (0 when there is none)."""
    meds = dwell_medians(depth, band, min_samples, max_iqr)
    return len(meds), (float(np.median(meds)) if meds else 0.0)


def dwell_medians(depth: np.ndarray, band: float, min_samples: int,
                  max_iqr: float) -> list[float]:
    """Each dwell's median depth (:func:`dwell_depth`), in recording order."""
    idx = np.flatnonzero(depth <= band)
    if idx.size < min_samples:
        return []
    cuts = np.flatnonzero(np.diff(idx) > 1) + 1
    starts = np.concatenate(([0], cuts))
    ends = np.concatenate((cuts, [idx.size]))
    meds = []
    for a, b in zip(starts, ends, strict=True):
        if b - a < min_samples:
            continue
        q1, q2, q3 = np.percentile(depth[idx[a:b]], [25.0, 50.0, 75.0])
        if q3 - q1 <= max_iqr:
            meds.append(float(q2))
    return meds


@dataclass(frozen=True)
class InsetSettings:
    """Hyper-parameters of the swing noise inset (step 4b); angles in degrees.

    Attributes
    ----------
    enabled : bool, False: no inset (the estimates are not computed)
    pileup_band_deg : float, depth band of the pile-up histogram (0.2° bins)
    visit_band_deg, visit_segment_deg : float, samples considered, stretch length
    visit_gap_samples : int, longest gap inside one visit
    visit_min : int, fewest visits a stretch needs to count
    measured_deg : float or None, an inset already measured on a larger recording of the
        same sensors (a limb's keyframe: the joint's whole recording), used as it is instead
        of an estimate from these samples
    """

    enabled: bool = True
    pileup_band_deg: float = 10.0
    visit_band_deg: float = 6.0
    visit_segment_deg: float = 3.0
    visit_gap_samples: int = 20
    visit_min: int = 3
    measured_deg: float | None = None


@dataclass(frozen=True)
class InsetEstimate:
    """How far to move a swing envelope in, and the estimates behind it.

    Attributes
    ----------
    inset_deg : float, ≥ 0, the larger of the capped estimates
    estimates : dict, ``noise_deg``, ``pileup_deg``, ``visit_deg``, ``visit_stretches``,
        ``slow_error_deg`` (rounded: the provenance's ``noise_inset_estimates``)
    """

    inset_deg: float
    estimates: dict[str, Any]


def swing_inset(poly, p: np.ndarray, noise_deg: float, slow_error_deg: float | None,
                settings: InsetSettings) -> InsetEstimate:
    """How far inside the envelope ``poly`` (a shapely polygon, plane degrees) of the samples
    ``p`` (N, 2, recording order) the limit lies, as far as the measured errors support it:
    the pile-up crest capped at ``NOISE_REACH × noise_deg`` and, with a measured
    ``slow_error_deg``, the typical visit's closest approach capped at
    ``NOISE_REACH × slow_error_deg``; the larger (module doc)."""
    import shapely

    estimates: dict[str, Any] = {"noise_deg": round(noise_deg, 4), "pileup_deg": 0.0,
                                 "visit_deg": 0.0, "visit_stretches": 0,
                                 "slow_error_deg": slow_error_deg}
    if not settings.enabled:
        return InsetEstimate(0.0, estimates)
    if settings.measured_deg is not None:
        estimates["measured_deg"] = round(float(settings.measured_deg), 3)
        return InsetEstimate(float(settings.measured_deg), estimates)
    ring = poly.exterior
    inside = shapely.contains_xy(poly, p[:, 0], p[:, 1])
    dist, arc = ring_distance(ring, p, bound=max(settings.pileup_band_deg,
                                                 settings.visit_band_deg) + 1.0)
    depth = np.where(inside, dist, 0.0)
    pileup = pileup_offset(depth, settings.pileup_band_deg, 0.2, 2.0)
    visit, stretches = 0.0, 0
    if slow_error_deg:
        near = np.flatnonzero(depth <= settings.visit_band_deg)
        visit, stretches = visit_offset(depth, near, arc[near], settings.visit_segment_deg,
                                        settings.visit_gap_samples, settings.visit_min)
    estimates.update({"pileup_deg": round(pileup, 3), "visit_deg": round(visit, 3),
                      "visit_stretches": stretches})
    # each estimate only as far as the measured errors support it: white noise blurs the
    # envelope out by a few of its standard deviations, slow errors by about their size
    fast = min(pileup, NOISE_REACH * noise_deg)
    slow = min(visit, NOISE_REACH * (slow_error_deg or 0.0))
    return InsetEstimate(max(fast, slow), estimates)
