"""Twist limits: the envelope of the recorded twist, and its swing-dependent table (step 6).

**Envelope** (:func:`twist_envelope`): the minimum and maximum of the kept samples' twist
after centring on their circular mean (so a range across ±180° is handled), each end moved in
as the swing envelope is (:mod:`calibration.boundary.inset`): by the crest of the pile-up of
samples below it, capped at 3× the twist's measured white noise (fourth differences of the
unwrapped twist); and, with a measured ``slow_error_deg``, by the patient's *dwells* at it,
capped at 3× that error (runs of consecutive samples within ``dwell_band_deg`` of the end, at
least ``dwell_min_samples`` long with an interquartile range of at most
``dwell_max_iqr_deg``; with at least ``dwell_min_runs`` dwells, the median over the dwells of
each dwell's median depth). Nothing here is specific to a twist: any joint angle recorded
over time (a hinge's) has its interval the same way.

**By swing region** (contract 3, ``twist.by_swing``; :func:`twist_table`): at table
directions ``d_i`` on a grid of spacing ``spacing_deg`` inside the swing polygon, where the
kernel ``exp(κ (d·d_i − 1))``, ``κ = 1 / (1 − cos β)``, gives an effective sample count
``(Σw)²/Σw²`` of at least ``min_samples``, the twist extremes of the samples within ``β`` of
``d_i``; then every interval is widened as little as possible (a linear programme,
:func:`hold_twists`) until the table's interpolated limits hold every kept sample's twist at
its direction. Emitted (:func:`choose_table`) when asked, or ("auto") when some region's limit
then still differs from the envelope by more than ``min_diff_deg``. Limits are written
rounded outwards (3 decimals).

Documented in docs/calibration.md, "Boundary extraction", step 6.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from calibration.boundary.inset import NOISE_REACH, dwell_medians, fast_noise, pileup_offset
from calibration.boundary.projection import Projection
from models import quaternion as Q
from models.limits import SwingTwistTable

__all__ = [
    "TableSettings",
    "TwistEnvelope",
    "TwistSettings",
    "choose_table",
    "circular_centre",
    "end_insets",
    "hold_twists",
    "pooled_insets",
    "singular_reach",
    "twist_envelope",
    "twist_table",
]


def circular_centre(phi: np.ndarray) -> float:
    """Circular mean (radians) of angles ``phi`` (N,), radians."""
    return float(np.angle(np.mean(np.exp(1j * phi))))


@dataclass(frozen=True)
class TwistSettings:
    """Hyper-parameters of the twist envelope's insets (step 6); angles in degrees.

    Attributes
    ----------
    enabled : bool, False: the envelope as recorded
    pileup_band_deg : float, depth band of the pile-up histogram (0.25° bins)
    dwell_band_deg, dwell_min_samples, dwell_max_iqr_deg, dwell_min_runs : the dwell test
    measured_deg : (float, float) or None, each end's inset already measured on a larger
        recording of the same sensors (a limb's keyframe: the joint's whole recording), used
        as it is instead of estimates from these samples
    """

    enabled: bool = True
    pileup_band_deg: float = 10.0
    dwell_band_deg: float = 10.0
    dwell_min_samples: int = 20
    dwell_max_iqr_deg: float = 3.0
    dwell_min_runs: int = 5
    measured_deg: tuple[float, float] | None = None


@dataclass(frozen=True)
class TwistEnvelope:
    """The twist range of a recording.

    Attributes
    ----------
    mid : float, radians, circular mean of the twist
    rel : (N,) float64, radians, each sample's twist about ``mid`` in [-π, π)
    min_deg, max_deg : float, the limits (degrees, in [-180, 180]; a range across ±180° keeps
        its larger side)
    noise_deg : float, measured white noise of the twist
    inset_deg : (float, float), how far each end was moved in
    dwells : (int, int), dwells found at each end
    fast_deg : (float, float), each end's fast-noise estimate (capped)
    dwell_depths : (tuple, tuple), each end's dwells' median depths (degrees)
    """

    mid: float
    rel: np.ndarray
    min_deg: float
    max_deg: float
    noise_deg: float
    inset_deg: tuple[float, float]
    dwells: tuple[int, int]
    fast_deg: tuple[float, float] = (0.0, 0.0)
    dwell_depths: tuple[tuple[float, ...], tuple[float, ...]] = ((), ())


def twist_envelope(phi: np.ndarray, settings: TwistSettings,
                   slow_error_deg: float | None = None,
                   swing: np.ndarray | None = None,
                   reach_error_deg: float | None = None) -> TwistEnvelope:
    """The envelope of the twists ``phi`` (N,), radians, recording order; each end moved in
    only as far as the measured errors support (module doc). ``swing`` (N,), radians: each
    sample's swing from the twist axis, for the singularity reach (module doc) of
    ``reach_error_deg`` (default ``slow_error_deg``: a measured error given for the reach
    alone moves no dwell inset)."""
    mid = circular_centre(phi)
    rel = Q.wrap_angle_mod(phi - mid)
    reach = (singular_reach(swing, reach_error_deg if reach_error_deg is not None
                            else slow_error_deg) if settings.enabled else None)
    # each end from the samples' twists moved in by their own reach
    at_lo, at_hi = (rel, rel) if reach is None else (rel + reach, rel - reach)
    lo, hi = float(at_lo.min()), float(at_hi.max())
    noise = fast_noise(np.degrees(np.unwrap(phi))[:, None])
    inset, dwells, fasts, depths = (0.0, 0.0), (0, 0), (0.0, 0.0), ((), ())
    if settings.enabled and settings.measured_deg is not None:
        a, b = (float(x) for x in settings.measured_deg)
        lo, hi = lo + math.radians(a), hi - math.radians(b)
        inset = (a, b)
    elif settings.enabled:
        fast_l, meds_l = [], []
        width = math.degrees(hi - lo)  # a dwell lies within a quarter of the range of its end
        for depth in (np.degrees(at_lo - lo), np.degrees(hi - at_hi)):
            fast_l.append(min(pileup_offset(depth, settings.pileup_band_deg, 0.25, 2.0),
                              NOISE_REACH * noise))
            meds_l.append(tuple(dwell_medians(depth, min(settings.dwell_band_deg, width / 4.0),
                                              settings.dwell_min_samples,
                                              settings.dwell_max_iqr_deg)))
        fasts, depths = (fast_l[0], fast_l[1]), (meds_l[0], meds_l[1])
        a, b = end_insets(fasts, depths, settings, slow_error_deg)
        lo, hi = lo + math.radians(a), hi - math.radians(b)
        inset, dwells = (a, b), (len(depths[0]), len(depths[1]))
    tw_lo = math.degrees(float(np.clip(lo + mid, -math.pi, math.pi)))
    tw_hi = math.degrees(float(np.clip(hi + mid, -math.pi, math.pi)))
    if tw_lo > tw_hi:  # the range crosses ±180°: keep the larger side, say so
        tw_lo, tw_hi = (tw_lo, 180.0) if 180.0 - tw_lo >= tw_hi + 180.0 else (-180.0, tw_hi)
    return TwistEnvelope(mid, rel, tw_lo, tw_hi, noise, inset, dwells, fasts, depths)


def end_insets(fast: tuple[float, float], dwell_depths, settings: TwistSettings,
               slow_error_deg: float | None) -> tuple[float, float]:
    """Each end's inset (degrees) from its fast-noise estimate and its dwells' median depths:
    the larger of the fast estimate and, with a measured slow error and at least
    ``dwell_min_runs`` dwells, the median dwell depth capped at ``NOISE_REACH`` × that error
    (module doc)."""
    out = []
    for f, meds in zip(fast, dwell_depths, strict=True):
        slow = (min(float(np.median(meds)), NOISE_REACH * (slow_error_deg or 0.0))
                if len(meds) >= settings.dwell_min_runs else 0.0)
        out.append(max(float(f), slow))
    return out[0], out[1]


def pooled_insets(envelopes: list[TwistEnvelope], settings: TwistSettings,
                  slow_error_deg: float | None) -> tuple[float, float]:
    """Each end's inset measured on several recordings' envelopes of the same sensors at
    once (a limb's keyframes, each a share of its joint's recording): the median of their
    fast estimates and every dwell of every envelope (:func:`end_insets`) — a keyframe alone
    holds too few dwells to tell."""
    fast = tuple(float(np.median([e.fast_deg[k] for e in envelopes])) for k in (0, 1))
    depths = tuple(tuple(d for e in envelopes for d in e.dwell_depths[k]) for k in (0, 1))
    return end_insets(fast, depths, settings, slow_error_deg)


def singular_reach(swing: np.ndarray | None, slow_error_deg: float | None) -> np.ndarray | None:
    """How far each sample's twist may be carried by a direction error it shares with its
    slow error, beyond what a sample at 90° of swing carries (radians, (N,)): a rotation error
    ``ε`` perpendicular to the limb turns the swing-twist twist by up to ``ε tan(s/2)`` at a
    swing ``s`` from the twist axis (singular at the axis's antipode, the arm raised
    overhead), so a sample's twist counts towards an end only beyond
    ``NOISE_REACH · slow_error · max(0, tan(s/2) − 1)``. None without a measured error or
    swings."""
    if swing is None or not slow_error_deg:
        return None
    half = np.clip(0.5 * np.asarray(swing, dtype=np.float64), 0.0, math.radians(89.0))
    return (NOISE_REACH * math.radians(float(slow_error_deg))
            * np.maximum(0.0, np.tan(half) - 1.0))


@dataclass(frozen=True)
class TableSettings:
    """Hyper-parameters of the by-swing twist table (step 6); angles in degrees.

    Attributes
    ----------
    bandwidth_deg : float, kernel width β (and the radius the extremes are taken within)
    spacing_deg : float, grid spacing of the table directions (plane degrees)
    min_samples : int, effective samples a table direction needs
    """

    bandwidth_deg: float = 20.0
    spacing_deg: float = 20.0
    min_samples: int = 500


def twist_table(d: np.ndarray, env: TwistEnvelope, plane_polygon, proj: Projection,
                settings: TableSettings) -> dict | None:
    """The by-swing twist table (contract 3 mapping ``{"bandwidth_deg", "points"}``), or None
    when fewer than 3 table directions have the samples (module doc).

    Parameters
    ----------
    d : (N, 3) float64, unit, the samples' directions (those ``env`` was taken from)
    env : TwistEnvelope, their twist; every table interval lies inside it
    plane_polygon : shapely.Polygon, the swing polygon in the plane of ``proj``
    proj : Projection
    """
    import shapely

    step = settings.spacing_deg
    minx, miny, maxx, maxy = plane_polygon.bounds
    gx = np.arange(math.floor(minx / step), math.ceil(maxx / step) + 1) * step
    gy = np.arange(math.floor(miny / step), math.ceil(maxy / step) + 1) * step
    xx, yy = np.meshgrid(gx, gy)
    grid = np.column_stack((xx.ravel(), yy.ravel()))
    grid = grid[shapely.contains_xy(plane_polygon, grid[:, 0], grid[:, 1])]
    if len(grid) < 2:
        return None
    dirs = proj.inverse(grid)
    beta = math.radians(settings.bandwidth_deg)
    kappa = 1.0 / (1.0 - math.cos(beta))
    rel, mid = env.rel, env.mid
    env_lo, env_hi = env.min_deg, env.max_deg
    table_dirs, lows, highs = [], [], []
    for di in dirs:
        w = np.exp(kappa * (d @ di - 1.0))
        sw = w.sum()
        if sw <= 0 or sw * sw / (w @ w) < settings.min_samples:
            continue
        near = d @ di >= math.cos(beta)  # the samples within the bandwidth: their extremes
        if not near.any():
            continue
        a, b = float(rel[near].min()), float(rel[near].max())
        a = float(np.clip(math.degrees(a + mid), env_lo, env_hi))
        b = float(np.clip(math.degrees(b + mid), env_lo, env_hi))
        table_dirs.append([round(float(x), 6) for x in di])
        lows.append(a)
        highs.append(max(a, b))
    if len(table_dirs) < 3:
        return None
    lo, hi = hold_twists(np.array(table_dirs, dtype=np.float64),
                         np.array(lows, dtype=np.float64), np.array(highs, dtype=np.float64),
                         settings.bandwidth_deg, d, np.degrees(Q.wrap_angle_mod(rel + mid)),
                         env_lo, env_hi)
    points = []
    for di, a, b in zip(table_dirs, lo, hi, strict=True):
        a, b = float(a), float(max(a, b))
        # rounded outwards: the file holds what the table holds
        points.append({"direction": di, "min_deg": math.floor(a * 1000.0) / 1000.0,
                       "max_deg": math.ceil(b * 1000.0) / 1000.0})
    return {"bandwidth_deg": settings.bandwidth_deg, "points": points}


def hold_twists(directions: np.ndarray, lo: np.ndarray, hi: np.ndarray, bandwidth_deg: float,
                d: np.ndarray, tw: np.ndarray, env_lo: float,
                env_hi: float) -> tuple[np.ndarray, np.ndarray]:
    """A table's intervals widened as little as possible so that its interpolated limits
    (:class:`models.limits.SwingTwistTable`: kernel-weighted means of the points' limits)
    hold every recorded twist ``tw`` (N,), degrees, at its direction ``d`` (N, 3).

    A linear programme per side — minimise the total widening ``Σ Δ_j ≥ 0`` subject to
    ``Σ_j r_ij (max_j + Δ_j) ≥ tw_i`` (``r_ij`` the normalised kernel weights) and
    ``max_j + Δ_j ≤`` the envelope ``[env_lo, env_hi]``, which every recorded twist is inside
    (so it is feasible) — over the samples outside, re-solved until none is (cutting planes).

    Parameters
    ----------
    directions : (K, 3) float64, unit, the table's directions
    lo, hi : (K,) float64, degrees, its intervals (not modified)

    Returns
    -------
    lo, hi : (K,) float64, degrees, the widened intervals
    """
    from scipy.optimize import linprog

    lo, hi = lo.copy(), hi.copy()
    r = SwingTwistTable(bandwidth_deg, directions, lo, hi).weights(d)  # (N, K)
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
    return lo, hi


def choose_table(table: dict | None, env: TwistEnvelope, by_swing: bool | str,
                 min_diff_deg: float) -> dict | None:
    """The table to write: ``table`` when ``by_swing`` is True, or when it is "auto" and some
    table limit differs from the envelope's by more than ``min_diff_deg``; else None."""
    if table is None:
        return None
    if by_swing is True:
        return table
    if by_swing == "auto":
        mins = np.array([pt["min_deg"] for pt in table["points"]])
        maxs = np.array([pt["max_deg"] for pt in table["points"]])
        if max(mins.max() - env.min_deg, env.max_deg - maxs.min()) > min_diff_deg:
            return table
    return None
