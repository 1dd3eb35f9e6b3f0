"""Coverage of the swing sphere near the range-of-motion boundary: live while recording
(:class:`CoverageMap`), and of a whole recording (:func:`coverage_of`).

Geometry
--------
A joint orientation ``q`` (limb relative to thorax, scalar-first) gives the limb direction
``d = rotate(q, a)`` (``a`` the limb axis, +X) and the twist ``φ = twist_angle(q, a)``
(swing-twist, :mod:`models.quaternion`). Directions are binned on a fixed Fibonacci grid of
``cells`` points on the unit sphere (nearest grid point, ``scipy.spatial.cKDTree``); each cell
keeps a sample count and its twist extremes. That accumulation is order-independent and cheap
(O(batch log cells)), and everything shown is derived from it on demand.

Regions are **azimuthal sectors around the range's centre** ``c``: a fixed ``centre`` when one
is given (the rig configuration's default constraint — a plausible centre for the joint), else
estimated as the normalised mean of the *occupied* cells' directions (each explored cell weighs
the same, so dwelling in one pose does not drag it). A fixed centre is better: with an estimated
one, a patient who never moved one way looks like a patient whose range is cut there.
With the tangent basis ``(u, v)`` at ``c``, a cell direction ``p`` has

    reach ρ = ∠(p, c),      azimuth α = atan2(p·v, p·u).

Per sector ``k`` (``α`` in ``[2πk/K, 2π(k+1)/K)``), over cells holding at least ``min_count``
samples (one noisy sample does not claim range):

- **reach** ``max ρ``: how far the limb got in that direction;
- **boundary samples**: samples in cells with ``ρ ≥ reach − band_deg`` (the boundary band);
- **stable**: the reach grew by less than ``settle_deg`` over the last ``settle_s`` seconds of
  sample time;
- **explored** = reach ≥ ``min_reach_deg``, boundary samples ≥ ``min_boundary_samples`` and
  stable.

**Coverage sufficient** when every sector is explored. The criterion asks for what boundary
extraction needs (``calibration.boundary``): samples along the whole limit, and limits that have
stopped moving outward — not a fixed recording time.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from models import quaternion as Q
from models.geometry import fibonacci_sphere

__all__ = ["CoverageMap", "CoverageSummary", "SectorCoverage", "coverage_of"]


@dataclass(frozen=True)
class SectorCoverage:
    """Coverage of one azimuthal sector (angles in degrees, azimuth about the centre)."""

    index: int
    azimuth_deg: tuple[float, float]
    reach_deg: float
    """Largest angle from the centre reached in this sector (NaN: never visited)."""
    boundary_samples: int
    """Samples within ``band_deg`` of the sector's reach."""
    samples: int
    """All samples in the sector."""
    twist_deg: tuple[float, float]
    """Twist extremes seen in the sector (NaN when empty)."""
    stable: bool
    explored: bool


@dataclass(frozen=True)
class CoverageSummary:
    """Snapshot of the coverage (see the module docstring)."""

    samples: int
    t_span_s: float
    """Sample time covered, seconds (last − first sample timestamp)."""
    centre: np.ndarray
    """(3,) estimated centre of the range, thorax frame."""
    sectors: tuple[SectorCoverage, ...]
    twist_deg: tuple[float, float]
    """Overall twist extremes, degrees (NaN before any sample)."""
    min_boundary_samples: int = 0
    """Boundary-band samples a sector needs to count as explored."""

    @property
    def explored(self) -> int:
        """Number of explored sectors."""
        return sum(s.explored for s in self.sectors)

    @property
    def sufficient(self) -> bool:
        """Every sector explored."""
        return bool(self.sectors) and all(s.explored for s in self.sectors)

    def as_dict(self) -> dict:
        """Plain types, for the session's metadata."""
        return {
            "samples": int(self.samples),
            "t_span_s": float(self.t_span_s),
            "centre": [float(x) for x in self.centre],
            "sufficient": self.sufficient,
            "explored_sectors": self.explored,
            "twist_deg": [_num(x) for x in self.twist_deg],
            "sectors": [
                {
                    "azimuth_deg": list(s.azimuth_deg),
                    "reach_deg": _num(s.reach_deg),
                    "boundary_samples": s.boundary_samples,
                    "samples": s.samples,
                    "twist_deg": [_num(x) for x in s.twist_deg],
                    "stable": s.stable,
                    "explored": s.explored,
                }
                for s in self.sectors
            ],
        }


def _num(x: float) -> float | None:
    return None if not math.isfinite(x) else round(float(x), 3)


class CoverageMap:
    """Accumulates joint orientations and reports coverage per azimuthal sector.

    Parameters
    ----------
    sectors : int
        Number of azimuthal sectors around the centre.
    cells : int
        Fibonacci grid size on the sphere (4096 → ~3.2° spacing).
    band_deg : float
        Width of the boundary band below each sector's reach, degrees.
    min_count : int
        Samples a cell needs before it counts (rejects isolated outliers).
    min_boundary_samples : int
        Boundary-band samples a sector needs to be explored.
    settle_s : float
        Sample-time window over which the reach must stay within ``settle_deg``.
    settle_deg : float
        Largest reach growth over ``settle_s`` for a sector to be stable, degrees.
    min_reach_deg : float
        Least reach for a sector to count as explored (a limit closer to the centre is taken
        for a direction the patient has not tried yet).
    centre : (3,) array_like, optional
        Fixed centre of the sectors (thorax frame); default: estimated from the data.
    limb_axis : (3,) array_like
        Limb long axis in the limb frame (+X).
    """

    def __init__(
        self,
        *,
        sectors: int = 12,
        cells: int = 4096,
        band_deg: float = 6.0,
        min_count: int = 3,
        min_boundary_samples: int = 100,
        settle_s: float = 20.0,
        settle_deg: float = 1.0,
        min_reach_deg: float = 15.0,
        centre=None,
        limb_axis=Q.LIMB_AXIS,
    ) -> None:
        if sectors < 1:
            raise ValueError(f"sectors must be >= 1, got {sectors}")
        if not band_deg > 0 or not settle_s > 0 or not settle_deg > 0:
            raise ValueError("band_deg, settle_s and settle_deg must be > 0")
        self.n_sectors = int(sectors)
        self.band_deg = float(band_deg)
        self.min_count = int(min_count)
        self.min_boundary_samples = int(min_boundary_samples)
        self.settle_s = float(settle_s)
        self.settle_deg = float(settle_deg)
        self.min_reach_deg = float(min_reach_deg)
        self.fixed_centre = None if centre is None else Q.check_vectors(centre, name="centre")
        self.limb_axis = Q.check_vectors(limb_axis, name="limb_axis")
        self.grid_ = fibonacci_sphere(int(cells))
        self._tree = cKDTree(self.grid_)
        self.counts_ = np.zeros(len(self.grid_), dtype=np.int64)
        self.twist_min_ = np.full(len(self.grid_), np.inf)
        self.twist_max_ = np.full(len(self.grid_), -np.inf)
        self.samples_ = 0
        self.t_first_: float | None = None
        self.t_last_: float | None = None
        self._history: list[tuple[float, np.ndarray]] = []  # (t, reach per sector), for `stable`

    def add(self, q: np.ndarray, t: np.ndarray | float | None = None) -> None:
        """Add joint orientations.

        Parameters
        ----------
        q : (N, 4) or (4,) float64
            Joint orientations, limb relative to thorax, scalar-first.
        t : (N,) float or float, optional
            Sample times, seconds (any monotonic origin), for the stability window.
        """
        q = np.atleast_2d(np.asarray(q, dtype=np.float64))
        if q.size == 0:
            return
        d = Q.rotate(q, self.limb_axis)
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        _, idx = self._tree.query(d)
        np.add.at(self.counts_, idx, 1)
        phi = np.degrees(Q.twist_angle(q, self.limb_axis))
        np.minimum.at(self.twist_min_, idx, phi)
        np.maximum.at(self.twist_max_, idx, phi)
        self.samples_ += len(q)
        if t is not None:
            tt = np.atleast_1d(np.asarray(t, dtype=np.float64))
            if self.t_first_ is None:
                self.t_first_ = float(tt[0])
            self.t_last_ = float(tt[-1])

    def centre(self) -> np.ndarray:
        """Centre of the sectors (3,): the fixed one, or the mean direction of occupied cells."""
        if self.fixed_centre is not None:
            return self.fixed_centre.copy()
        occ = self.counts_ >= self.min_count
        if not occ.any():
            occ = self.counts_ > 0
        if not occ.any():
            return self.limb_axis.copy()
        m = self.grid_[occ].mean(axis=0)
        n = np.linalg.norm(m)
        return m / n if n > 1e-9 else self.grid_[occ][0]

    def reached(self) -> np.ndarray:
        """The swing-map cells visited (at least ``min_count`` samples) as seen from the
        centre: (M, 2) float64, degrees — azimuth α in [0, 360) and reach ρ (module
        docstring), the polar coordinates the sectors are cut in."""
        c = self.centre()
        u, v = Q.tangent_basis(c)
        p = self.grid_[self.counts_ >= self.min_count]
        rho = np.degrees(Q.angle_between(p, c))
        az = np.degrees(np.mod(np.arctan2(p @ v, p @ u), 2.0 * math.pi))
        return np.column_stack([az, rho])

    def summary(self) -> CoverageSummary:
        """Current coverage per sector (also records the reaches for the stability test)."""
        c = self.centre()
        u, v = Q.tangent_basis(c)
        occ = np.flatnonzero(self.counts_ >= self.min_count)
        p = self.grid_[occ]
        rho = np.degrees(Q.angle_between(p, c))
        az = np.mod(np.arctan2(p @ v, p @ u), 2.0 * math.pi)
        k = np.minimum((az / (2.0 * math.pi) * self.n_sectors).astype(int), self.n_sectors - 1)
        counts = self.counts_[occ]
        reach = np.full(self.n_sectors, np.nan)
        t_now = self.t_last_ if self.t_last_ is not None else 0.0
        span = 0.0 if self.t_first_ is None else t_now - self.t_first_
        sectors = []
        for s in range(self.n_sectors):
            sel = k == s
            if sel.any():
                reach[s] = rho[sel].max()
        self._history.append((t_now, reach.copy()))
        past = self._reach_at(t_now - self.settle_s)
        for s in range(self.n_sectors):
            sel = k == s
            lo = 360.0 * s / self.n_sectors
            hi = 360.0 * (s + 1) / self.n_sectors
            if not sel.any():
                sectors.append(SectorCoverage(s, (lo, hi), math.nan, 0, 0,
                                              (math.nan, math.nan), False, False))
                continue
            band = sel & (rho >= reach[s] - self.band_deg)
            nb = int(counts[band].sum())
            stable = bool(span >= self.settle_s and past is not None and np.isfinite(past[s])
                          and reach[s] - past[s] < self.settle_deg)
            cells = occ[sel]
            tw = (float(self.twist_min_[cells].min()), float(self.twist_max_[cells].max()))
            sectors.append(SectorCoverage(
                s, (lo, hi), float(reach[s]), nb, int(counts[sel].sum()), tw, stable,
                bool(stable and nb >= self.min_boundary_samples
                     and reach[s] >= self.min_reach_deg)))
        seen = self.counts_ > 0
        twist = ((float(self.twist_min_[seen].min()), float(self.twist_max_[seen].max()))
                 if seen.any() else (math.nan, math.nan))
        return CoverageSummary(self.samples_, span, c, tuple(sectors), twist,
                               self.min_boundary_samples)

    def _reach_at(self, t: float) -> np.ndarray | None:
        """Reaches recorded by the last :meth:`summary` at or before ``t`` (None if none)."""
        best = None
        keep_from = 0
        for i, (ti, r) in enumerate(self._history):
            if ti <= t:
                best = r
                keep_from = i
            else:
                break
        # older snapshots are never needed again (time only moves forward)
        if keep_from > 0:
            del self._history[:keep_from]
        return best


def coverage_of(q, t=None, *, step_s: float = 1.0, **options) -> CoverageSummary:
    """The coverage a live :class:`CoverageMap` would have shown at the end of a recording.

    The samples are added in slices of ``step_s`` seconds of sample time with a summary after
    each (the stability test compares reaches ``settle_s`` apart), as the recorder does while
    it records; used for sessions whose recorder stored no final coverage (killed) and for
    imported files.

    Parameters
    ----------
    q : (N, 4) array_like
        Joint orientations, limb relative to thorax, scalar-first, in recording order.
    t : (N,) array_like, optional
        Sample times, seconds (non-decreasing). Without times the stability test never passes.
    options
        Keyword arguments of :class:`CoverageMap`.
    """
    q = np.atleast_2d(np.asarray(q, dtype=np.float64))
    cmap = CoverageMap(**options)
    if t is None or len(q) == 0:
        cmap.add(q)
        return cmap.summary()
    t = np.asarray(t, dtype=np.float64).reshape(-1)
    if len(t) != len(q):
        raise ValueError(f"t has {len(t)} entries for {len(q)} orientations")
    slot = np.floor((t - t[0]) / float(step_s)).astype(np.int64)
    cuts = np.flatnonzero(np.diff(slot)) + 1
    for a, b in zip(np.r_[0, cuts], np.r_[cuts, len(q)], strict=True):
        cmap.add(q[a:b], t[a:b])
        cmap.summary()
    return cmap.summary()
