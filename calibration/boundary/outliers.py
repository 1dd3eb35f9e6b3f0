"""What is not evidence of the range: low-status samples and isolated spikes (steps 1-2).

- **Usable samples** (:func:`usable_samples`): samples whose IMU calibration status (BNO055
  ``CALIB_STAT`` system level, bits 7-6) is below the minimum are dropped (magnetic
  disturbances drop it); sample times, when given, must be finite and non-decreasing.
- **Links** (:func:`trajectory_links`): consecutive samples are linked when the limb could
  have moved between them — the step's angular speed is at most ``max_speed_dps`` (3,000°/s
  by default: faster than any limb segment's swing; the fastest human segment rotations
  reported, about 2,500°/s, are the forearm's in throwing). Without sample times a step is a
  jump when it exceeds 15° and ``JUMP_RATIO`` median steps.
- **Spikes** (:func:`find_spikes`), the only outliers: a run of at most ``max_len`` samples
  between two jumps — reached and left at a speed no limb has — is a sensor glitch. A brief
  excursion to a limit is coherent motion, linked all the way, and never dropped however
  rare. When such runs would hold more than ``MAX_SPIKE_SHARE`` of the samples, the samples
  are not a trajectory in recording order and nothing is marked.

Documented in docs/calibration.md, "Boundary extraction", steps 1-2.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calibration.errors import CalibrationError
from models import quaternion as Q

__all__ = [
    "JUMP_RATIO",
    "MAX_SPIKE_SHARE",
    "Usable",
    "find_spikes",
    "steps",
    "trajectory_links",
    "usable_samples",
]

#: Without sample times: a step more than this many median steps (and > 15°) is a jump.
JUMP_RATIO = 20.0
#: A recording with more of its samples in short runs between jumps is not a trajectory in
#: recording order (shuffled, or sampled too sparsely to follow): no spike is taken out.
MAX_SPIKE_SHARE = 0.05


@dataclass(frozen=True)
class Usable:
    """The samples a boundary may be extracted from.

    Attributes
    ----------
    q : (K, 4) float64, unit, scalar-first, the orientations kept (recording order)
    t : (K,) float64 or None, their sample times, seconds
    n_samples : int, orientations given
    n_status_dropped : int, dropped for a calibration status below the minimum
    """

    q: np.ndarray
    t: np.ndarray | None
    n_samples: int
    n_status_dropped: int


def usable_samples(q, status=None, t=None, *, min_system_status: int = 2,
                   min_samples: int = 100) -> Usable:
    """Validate orientations, drop those with a low calibration status, check the times.

    Parameters
    ----------
    q : (N, 4) array_like
        Orientations, scalar-first, unit (either sign); normalised here.
    status : (N,) array_like of int, optional
        IMU calibration bytes (``CALIB_STAT``); a sample is kept when its system level
        (bits 7-6) is at least ``min_system_status``.
    t : (N,) array_like, optional
        Sample times, seconds: finite and non-decreasing.
    min_samples : int
        Fewest samples that may remain.

    Raises
    ------
    CalibrationError
        Lengths that do not match, fewer than ``min_samples`` usable samples, bad times.
    """
    q = Q.check_quaternions(q, normalize=True, name="joint orientation").reshape(-1, 4)
    n_samples = len(q)
    keep = np.ones(len(q), dtype=bool)
    if status is not None:
        st = np.asarray(status).reshape(-1)
        if len(st) != len(q):
            raise CalibrationError(f"status has {len(st)} entries for {len(q)} orientations")
        keep &= (st.astype(np.int64) >> 6) >= min_system_status
    n_dropped = int((~keep).sum())
    if keep.sum() < min_samples:
        raise CalibrationError(
            f"need at least {min_samples} usable samples to extract a boundary, got "
            f"{int(keep.sum())} of {len(q)}"
            + (f" ({n_dropped} dropped for calibration status "
               f"< {min_system_status})" if n_dropped else "")
        )
    q = q[keep]
    if t is not None:
        t = np.asarray(t, dtype=np.float64).reshape(-1)
        if len(t) != n_samples:
            raise CalibrationError(f"t has {len(t)} entries for {n_samples} orientations")
        t = t[keep]
        if not np.isfinite(t).all() or (np.diff(t) < 0).any():
            raise CalibrationError("sample times must be finite and non-decreasing")
    return Usable(q, t, n_samples, n_dropped)


def steps(d: np.ndarray, t: np.ndarray | None) -> tuple[np.ndarray, np.ndarray | None]:
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


def trajectory_links(d: np.ndarray, t: np.ndarray | None, max_speed_dps: float) -> np.ndarray:
    """(N-1,) bool: consecutive samples the limb could have moved between — the step's angular
    speed is at most ``max_speed_dps``. Without times, a step is a jump when it exceeds both
    15° and ``JUMP_RATIO`` times the median step."""
    if len(d) < 2:
        return np.zeros(0, dtype=bool)
    step, dt = steps(d, t)
    if dt is None:
        return step <= max(15.0, JUMP_RATIO * float(np.median(step)))
    return step <= max_speed_dps * dt


def find_spikes(d: np.ndarray, t: np.ndarray | None, max_speed_dps: float,
                max_len: int) -> np.ndarray:
    """(N,) bool: isolated spikes — runs of at most ``max_len`` consecutive samples that the
    limb could neither have reached from the sample before nor have left for the sample after
    (both steps faster than ``max_speed_dps``, :func:`trajectory_links`); a run at either end
    of the recording needs the jump on its one side. A sensor glitch, not motion: no limb
    turns that fast. Nothing is marked when such runs would hold more than
    ``MAX_SPIKE_SHARE`` of the samples (the samples are not a trajectory in recording order)."""
    n = len(d)
    out = np.zeros(n, dtype=bool)
    if n < 2 * max_len + 2 or max_len < 1:
        return out
    jump = ~trajectory_links(d, t, max_speed_dps)
    if not jump.any():
        return out
    run = np.concatenate(([0], np.cumsum(jump)))  # runs of linked samples, cut at each jump
    short = np.bincount(run)[run] <= max_len
    if short.mean() > MAX_SPIKE_SHARE:
        return np.zeros(n, dtype=bool)
    return short
