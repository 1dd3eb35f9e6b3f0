"""Host-side 9-D sensor fusion of raw IMU samples with VQF (one sensor at a time, offline).

What it does
------------
:func:`fuse_vqf` turns one sensor's raw samples — accelerometer (m/s², specific force: +9.81
along world up at rest), gyroscope (rad/s), magnetometer (µT, any unit works), all in the
sensor frame — into its orientation ``q_ws`` (sensor relative to world, scalar-first, Hamilton)
with :func:`vqf.offlineVQF` (Laidig & Seel 2023, *Information Fusion* 91:187,
doi:10.1016/j.inffus.2022.10.014): gyroscope strapdown integration, accelerometer inclination
correction, magnetometer heading correction with magnetic-disturbance detection and
rejection, and gyroscope bias estimation at rest and in motion. The offline variant is acausal
(it uses future samples too), which a recording allows.

VQF's world is ENU: Z up, heading from magnetic north (+Y north). It is the same for every
sensor fused here (the earth's field is the reference), unlike device fusion, where each IMU
keeps its own heading; a calibration fitted on device quaternions (whose mounts absorbed the
device worlds' heading offset) therefore does not apply to VQF quaternions, and the read path
re-fits it (:func:`rig.readback.joint_orientations_from_store`).

Irregular sample times
----------------------
``offlineVQF`` needs one constant sampling interval. The samples are split at gaps longer than
``max_gap_s`` (a dropped stretch: integrating the gyroscope across it would be a guess), each
piece is **resampled to the median sampling interval** of the whole series (linear
interpolation of the raw channels onto ``t0 + k·Ts``), fused, and the orientations are
interpolated back to the original times (normalised linear interpolation between the two
neighbouring grid orientations, same hemisphere). Each piece starts the filter afresh.
Jitter of a few percent (device time stamps in whole milliseconds) thus costs nothing but the
interpolation.

Parameters (:data:`VQF_PARAMS`, VQF's own names; everything else at VQF's defaults)
-----------------------------------------------------------------------------------------
- ``magNewMinGyr = 0`` (default 20 °/s). VQF accepts a *new* magnetic reference (norm and
  dip of the field; its first one too) only after ``magNewFirstTime`` (5 s) / ``magNewTime``
  (20 s) of samples during which the sensor turns faster than ``magNewMinGyr``. A thorax sensor
  never turns at 20 °/s, so with the default it stays "magnetically disturbed" for the whole
  recording (measured: 100 % of its samples flagged on a simulated session) and its heading is
  the gyroscope's alone. With 0 the first reference is taken after 5 s of samples; the cost
  is that a sensor held still next to iron for 20 s would adopt the disturbed field as its new
  reference — acceptable for a thorax in a clinic room, and the neutral-checkpoint heading
  correction (:mod:`calibration.heading`) removes slow relative heading errors anyway.
- ``restBiasEstEnabled = False`` (default True). VQF's rest detector looks at the
  gyroscope's deviation from its own 0.5 s low-pass (``restThGyr`` 2 °/s) and the
  accelerometer's; a worn sensor's slow postural sway (a few °/s at 0.03-0.3 Hz) passes it, and
  the sway rate is then taken for gyroscope bias with the small rest uncertainty, so it
  sticks (measured on the simulated patient: thorax bias estimate 1.4 °/s against a true
  0.12 °/s, heading off by 2.5° for the first 30 s — the calibration's window). The bias is
  still estimated in motion (``motionBiasEstEnabled``, default on). On the dev seeds 201-205 it
  lowers the median relative heading error from 0.45° to 0.34° (docs/calibration.md).
- ``tauAcc = 3 s``, ``tauMag = 9 s`` (VQF defaults, the values of the paper's evaluation):
  time constants of the inclination and heading corrections.
- ``magDistRejectionEnabled = True`` (default): while the field's norm or dip departs from the
  reference by more than ``magNormTh`` (10 %) or ``magDipTh`` (10°), the magnetometer is not
  used for up to ``magMaxRejectionTime`` (60 s) and the heading comes from the gyroscope
  (bias-compensated). Those samples are flagged (``mag_disturbed``) but their orientation is
  VQF's best estimate, so they are not dropped downstream.
- Everything else at VQF's defaults.

Overrides are given as a dict of VQF parameter names (:func:`fuse_vqf` ``params=``); unknown
names are errors.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field

import numpy as np

from calibration.errors import CalibrationError
from models import quaternion as Q

__all__ = ["VQF_PARAMS", "FusionResult", "fuse_vqf", "vqf_params"]

#: The VQF parameters the rig changes from VQF's defaults (module docstring).
VQF_PARAMS: dict[str, float | bool] = {"magNewMinGyr": 0.0, "restBiasEstEnabled": False}

#: Fewest samples of one sensor fusion is run on (VQF needs seconds to settle; 10 samples are
#: the least from which anything but the gyroscope's first step comes out).
MIN_SAMPLES = 10


@dataclass
class FusionResult:
    """One sensor fused (arrays over its N samples, in the order given).

    Attributes
    ----------
    q : (N, 4) float64
        Sensor relative to world (ENU, Z up), scalar-first, w ≥ 0.
    mag_disturbed : (N,) bool
        VQF's magnetic disturbance detection (magnetometer not used there).
    rest : (N,) bool
        VQF's rest detection (reported; with :data:`VQF_PARAMS` it no longer feeds the bias).
    bias : (N, 3) float64
        Gyroscope bias estimate, rad/s, sensor frame.
    rate_hz : float
        The rate the samples were resampled to (1 / median interval).
    pieces : int
        Pieces fused separately (split at gaps longer than ``max_gap_s``).
    params : dict
        The VQF parameters that differ from VQF's defaults.
    """

    q: np.ndarray
    mag_disturbed: np.ndarray
    rest: np.ndarray
    bias: np.ndarray
    rate_hz: float
    pieces: int
    params: dict = field(default_factory=dict)

    @property
    def disturbed_share(self) -> float:
        """Share of the samples VQF flagged as magnetically disturbed."""
        return float(np.mean(self.mag_disturbed)) if len(self.mag_disturbed) else 0.0

    @property
    def bias_dps(self) -> list[float]:
        """Final gyroscope bias estimate, degrees per second."""
        return [round(math.degrees(float(b)), 4) for b in self.bias[-1]] if len(self.bias) else []


def vqf_params(overrides: dict | None = None) -> dict:
    """The rig's VQF parameters (:data:`VQF_PARAMS`) with ``overrides`` (VQF names) applied;
    unknown names raise :class:`CalibrationError`."""
    import vqf

    defaults = vqf.VQF(0.01).params
    params = dict(VQF_PARAMS)
    for k, v in (overrides or {}).items():
        if k not in defaults:
            raise CalibrationError(f"VQF parameter {k!r} unknown (VQF has "
                                   f"{', '.join(sorted(defaults))})")
        params[k] = v
    return params


def fuse_vqf(t, raw, *, params: dict | None = None, max_gap_s: float = 0.5) -> FusionResult:
    """Fuse one sensor's raw samples with ``vqf.offlineVQF`` (9-D).

    Parameters
    ----------
    t : (N,) array_like
        Sample times, seconds, strictly increasing (the device's clock where it has one).
    raw : (N, 9) array_like
        Accelerometer (m/s²), gyroscope (rad/s), magnetometer (µT), sensor frame; finite.
    params : dict, optional
        VQF parameter overrides (VQF's names) on top of :data:`VQF_PARAMS`.
    max_gap_s : float
        An interval longer than this (and than 5 median intervals) splits the series; each
        piece is fused on its own.

    Returns
    -------
    FusionResult
    """
    import vqf

    t = np.asarray(t, dtype=np.float64).reshape(-1)
    raw = np.asarray(raw, dtype=np.float64)
    if raw.ndim != 2 or raw.shape[1] != 9:
        raise CalibrationError(f"raw samples: expected shape (N, 9), got {raw.shape}")
    if len(t) != len(raw):
        raise CalibrationError(f"raw samples: {len(t)} times for {len(raw)} samples")
    if len(t) < MIN_SAMPLES:
        raise CalibrationError(f"raw samples: fusion needs at least {MIN_SAMPLES} samples, "
                               f"got {len(t)}")
    bad = ~np.isfinite(raw).all(axis=1)
    if bad.any():
        raise CalibrationError(f"raw samples: {int(bad.sum())} of {len(raw)} are missing or "
                               f"not finite (first at t = {t[np.argmax(bad)]:.3f} s)")
    if not np.isfinite(t).all():
        raise CalibrationError("raw samples: times must be finite")
    dt = np.diff(t)
    if (dt <= 0).any():
        raise CalibrationError(f"raw samples: times must increase strictly ({int((dt <= 0).sum())} "
                               "repeated or backward steps)")
    p = vqf_params(params)
    ts = float(np.median(dt))
    gap = max(float(max_gap_s), 5.0 * ts)
    cuts = np.flatnonzero(dt > gap) + 1
    bounds = np.concatenate(([0], cuts, [len(t)]))
    n = len(t)
    out_q = np.empty((n, 4))
    dist = np.zeros(n, bool)
    rest = np.zeros(n, bool)
    bias = np.zeros((n, 3))
    for a, b in itertools.pairwise(bounds):
        tp, rp = t[a:b], raw[a:b]
        m = math.floor((tp[-1] - tp[0]) / ts + 1e-9) + 1
        grid = tp[0] + ts * np.arange(m + (1 if tp[0] + ts * (m - 1) < tp[-1] else 0))
        # each sensor's three axes resampled straight into the contiguous arrays VQF takes
        acc, gyr, mag = (np.empty((len(grid), 3)) for _ in range(3))
        for j in range(9):
            (acc, gyr, mag)[j // 3][:, j % 3] = np.interp(grid, tp, rp[:, j])
        res = vqf.offlineVQF(gyr, acc, mag, ts, dict(p))
        del acc, gyr, mag
        qg = np.asarray(res["quat9D"], dtype=np.float64)
        flags = (np.asarray(res["magDistDetected"], bool), np.asarray(res["restDetected"], bool),
                 np.asarray(res["bias"], dtype=np.float64))
        del res  # VQF's other outputs (6-D quaternion, bias sigma, ...) are not kept
        # back to the sample times, a chunk at a time: nlerp between the two neighbouring
        # grid orientations
        for c in range(0, b - a, _CHUNK):
            tc = tp[c:c + _CHUNK]
            u = np.clip((tc - grid[0]) / ts, 0.0, len(grid) - 1.0)
            i0 = np.minimum(np.floor(u).astype(np.int64), len(grid) - 1)
            i1 = np.minimum(i0 + 1, len(grid) - 1)
            w = (u - i0)[:, None]
            q0, q1 = qg[i0], qg[i1]
            q1 *= np.where(np.sum(q0 * q1, axis=1, keepdims=True) < 0, -1.0, 1.0)
            q = (1.0 - w) * q0 + w * q1
            sl = slice(a + c, a + c + len(tc))
            out_q[sl] = q / np.linalg.norm(q, axis=1, keepdims=True)
            near = np.where(w[:, 0] < 0.5, i0, i1)
            dist[sl], rest[sl], bias[sl] = (f[near] for f in flags)
    return FusionResult(Q.canonical(out_q), dist, rest, bias, 1.0 / ts, len(bounds) - 1,
                        dict(p))


#: Samples per chunk when fused orientations are interpolated back to the sample times.
_CHUNK = 65536
