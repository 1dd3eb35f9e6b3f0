"""Heading re-zeroing at neutral checkpoints: removing the IMUs' relative heading drift.

The error
---------
Each IMU fuses its own heading (magnetometer-referenced), and the two sensors' headings drift
relative to each other after calibration (:mod:`calibration.alignment` absorbs the offset *at*
calibration, nothing can see it afterwards from orientations alone). A relative heading change
``δ`` is a rotation of one sensor's world about the world vertical. Carried through the joint
orientation ``q = m_t ⊗ q_t⁻¹ ⊗ q_l ⊗ m_l⁻¹`` it becomes a rotation about the **thorax's
vertical, expressed in the thorax segment frame** — with the thorax upright that is the segment's
long axis, **+X** (inferior), the limb axis at neutral. So the recorded joint orientation is

    q_recorded(t) = R_X(ψ(t)) ⊗ q_true(t)

a **left** multiplication (a rotation in the parent frame, the same for every limb direction),
not a right one (a rotation about the limb's own axis would depend on where the arm points).
With the arm at the side it adds directly to the twist (axial rotation); with the arm raised it
turns the swing direction about the vertical as well. Both are undone exactly by
``R_X(−ψ) ⊗ q_recorded``.

The measurement
---------------
In the neutral pose (arm hanging at the side, forearm forward) the true joint orientation is
the identity, up to the patient's repeatability ``n`` (about 2° of axial rotation). The twist
of the recorded orientation about +X there is ``ψ + n`` (to second order in the small swing).
Each **checkpoint** — a window of samples during which the patient held the neutral pose — gives
``ψ_k`` = circular mean of the twist angles (:func:`models.quaternion.twist_angle`) over the
window, at the window's centre time. A window is rejected (its reason kept) when

- it holds fewer than ``min_samples`` samples (with ``status``: samples whose system
  calibration level is at least ``min_system``; a magnetic disturbance drops it),
- the median angle of the limb axis from ``axis`` exceeds ``max_swing_deg``: the patient was not
  at neutral, so the twist there is not the heading,
- its ``ψ_k`` differs from the median of the other checkpoints' (anchors included) by more than
  ``max_jump_deg``: an outlier (the patient rotated the arm, or a disturbance).

Anchors are times at which ψ = 0 by construction: the calibration's own static neutral window
(the calibration makes the joint the identity there), so the correction starts from zero.

The correction
--------------
``ψ(t)`` is estimated from the nodes (accepted checkpoint centres and anchors, on the unwrapped
angles, so a drift through ±180° stays continuous); ``apply`` returns ``R_axis(−ψ(t)) ⊗ q``.
With no accepted checkpoint and no anchor the correction is the identity. Two estimators
(``drift``):

- ``"gp"`` (default): the posterior mean of a Gaussian process (scikit-learn's
  ``GaussianProcessRegressor``): an Ornstein-Uhlenbeck drift (``ConstantKernel × Matern(ν=½)``:
  amplitude σ, correlation time τ) plus white checkpoint noise (``WhiteKernel``, σ_n: the
  patient's repeatability). The three hyper-parameters are the maximum a posteriori on a grid
  (σ 0.3-9.6°, τ 15-480 s, σ_n 0.3-4.8°, factors of 2) of the marginal likelihood of the nodes
  times a weak log-normal prior (a factor e either way around 1.5°, 60 s, 1.5°): with a dozen
  checkpoints the plain maximum-likelihood fit is unstable (it sometimes explains the whole
  drift as noise, or the noise as drift). The prior mean is 0 when there is an anchor (the
  calibration defines ψ = 0), else the nodes' mean. Why not a straight line through the
  nodes: each checkpoint carries the patient's repeatability (~2°), and when the sensors
  drift little (a host-side 9-D fusion, :mod:`calibration.fusion`) joining noisy checkpoints
  adds more error than it removes. On simulated Ornstein-Uhlenbeck drifts (σ 0.7-2.8°, τ
  30-120 s, checkpoints every 20 s with 0.5° or 2° noise; 12 recordings each) the line left
  up to 2.2 times the RMS error of the best estimator tried, this estimate at most 1.07 times
  (and never more than no correction at all). With fewer than three nodes it falls back to
  the line.
- ``"linear"``: piecewise linear between the nodes, constant before the first and after the
  last — exact when the checkpoints are (a drift linear between them, a perfect return to
  neutral).
"""

from __future__ import annotations

import math

import numpy as np

from calibration.alignment import status_ok
from calibration.errors import CalibrationError
from models import quaternion as Q

__all__ = ["HeadingCorrection", "LimbHeadingCorrection"]


_Z = np.array([0.0, 0.0, 1.0])

#: Spacing (s) of the grid the drift estimate is evaluated on before interpolating to samples.
GRID_S = 0.25
#: Times per Gaussian-process prediction call (memory: this × nodes doubles).
_CHUNK = 4096


def _circular_mean(a: np.ndarray) -> float:
    return float(np.arctan2(np.mean(np.sin(a)), np.mean(np.cos(a))))


#: hyper-parameter grid of the "gp" drift estimate: drift amplitude σ (deg), correlation time τ
#: (s), checkpoint noise σ_n (deg), as natural logs
_GRID = [(math.log(s), math.log(t), math.log(n))
         for s in (0.3, 0.6, 1.2, 2.4, 4.8, 9.6) for t in (15.0, 30.0, 60.0, 120.0, 240.0, 480.0)
         for n in (0.3, 0.6, 1.2, 2.4, 4.8)]


def _log_prior(log_sigma: float, log_tau: float, log_noise: float) -> float:
    """Weakly informative log-normal prior (log-sd 1, i.e. a factor e either way) around a
    drift of 1.5° over a minute and a checkpoint repeatability of 1.5°."""
    return -0.5 * ((log_sigma - math.log(1.5)) ** 2 + (log_tau - math.log(60.0)) ** 2
                   + (log_noise - math.log(1.5)) ** 2)


class HeadingCorrection:
    """Relative heading drift ψ(t) from neutral checkpoints, and its removal (module doc).

    Parameters
    ----------
    axis : (3,) array_like
        The thorax vertical in the joint (parent) frame = the limb axis at neutral (+X).
    max_swing_deg : float
        Largest median angle of the limb axis from ``axis`` in an accepted window.
    max_jump_deg : float
        Largest difference of a window's heading from the median of the others.
    min_samples : int
        Fewest usable samples in an accepted window.
    min_system : int
        Least BNO055 system calibration level of a usable sample (when ``status`` is given).
    drift : "gp" or "linear"
        How ψ(t) is estimated from the nodes (module doc).

    Attributes (after :meth:`fit`)
    ------------------------------
    times_ : (M,) float64
        Interpolation nodes (accepted checkpoint centres and anchors), ascending.
    psi_deg_ : (M,) float64
        ψ at the nodes, degrees, unwrapped (continuous through ±180°).
    accepted_ : list of (t0, t1)
        The accepted checkpoint windows.
    psi_window_deg_ : list of float
        ψ_k of each accepted window (wrapped to (−180, 180]), in the order of ``accepted_``.
    rejected_ : list of ((t0, t1), reason)
    anchors_ : list of float
        Anchor times (ψ = 0).
    checkpoints_ : int
        Windows given to :meth:`fit`.
    drift_model_ : dict
        The estimator used and, for ``"gp"``, its fitted hyper-parameters (``sigma_deg``,
        ``time_constant_s``, ``noise_deg``).
    """

    def __init__(self, axis=(1.0, 0.0, 0.0), *, max_swing_deg: float = 15.0,
                 max_jump_deg: float = 15.0, min_samples: int = 10, min_system: int = 2,
                 drift: str = "gp") -> None:
        if drift not in ("gp", "linear"):
            raise CalibrationError(f"heading correction: drift must be 'gp' or 'linear', "
                                   f"got {drift!r}")
        self.drift = drift
        self.axis = axis
        self.max_swing_deg = max_swing_deg
        self.max_jump_deg = max_jump_deg
        self.min_samples = min_samples
        self.min_system = min_system

    # -- fitting ---------------------------------------------------------------------------
    def fit(self, t, q, windows, *, axis=None, max_swing_deg: float | None = None,
            max_jump_deg: float | None = None, status=None, anchors=()) -> HeadingCorrection:
        """Estimate ψ at each checkpoint window.

        Parameters
        ----------
        t : (N,) array_like
            Sample times (seconds, the clock the windows are in).
        q : (N, 4) array_like
            Joint orientations after the sensor-to-segment calibration.
        windows : (K, 2) array_like
            Checkpoint windows ``[t0, t1]`` (the patient held the neutral pose).
        axis, max_swing_deg, max_jump_deg : optional
            Override the constructor's values.
        status : (N,) array_like of int, optional
            IMU calibration bytes; samples below ``min_system`` are not used.
        anchors : sequence of float
            Times at which ψ = 0 (the calibration's static window centre).

        Returns
        -------
        self
        """
        if axis is not None:
            self.axis = axis
        if max_swing_deg is not None:
            self.max_swing_deg = max_swing_deg
        if max_jump_deg is not None:
            self.max_jump_deg = max_jump_deg
        ax = np.asarray(self.axis, dtype=np.float64).reshape(3)
        n = float(np.linalg.norm(ax))
        if not (math.isfinite(n) and n > 1e-9):
            raise CalibrationError(f"heading correction: axis must be non-zero, got {self.axis}")
        ax = ax / n
        self.axis_ = ax
        t = np.asarray(t, dtype=np.float64).reshape(-1)
        q = Q.check_quaternions(q, normalize=True, name="joint orientations").reshape(-1, 4)
        if len(t) != len(q):
            raise CalibrationError(f"heading correction: {len(t)} times for {len(q)} "
                                   "orientations")
        w = np.asarray(windows, dtype=np.float64).reshape(-1, 2)
        if not np.isfinite(w).all() or (w[:, 1] < w[:, 0]).any():
            raise CalibrationError("heading correction: windows must be finite [t0, t1] with "
                                   "t0 <= t1")
        usable = np.ones(len(t), bool)
        if status is not None:
            usable = status_ok(np.asarray(status).reshape(-1), self.min_system)
        anchors = [float(a) for a in anchors if math.isfinite(float(a))]

        self.checkpoints_ = len(w)
        self.rejected_: list[tuple[tuple[float, float], str]] = []
        cands: list[tuple[tuple[float, float], float]] = []  # (window, psi rad)
        for t0, t1 in w:
            win = (float(t0), float(t1))
            sel = usable & (t >= t0) & (t <= t1)
            k = int(sel.sum())
            if k < self.min_samples:
                self.rejected_.append((win, f"{k} usable samples (< {self.min_samples})"))
                continue
            qs = q[sel]
            swing = float(np.degrees(np.median(Q.angle_between(Q.rotate(qs, ax), ax))))
            if swing > self.max_swing_deg:
                self.rejected_.append((win, f"not at neutral: limb axis {swing:.1f}° from it "
                                            f"(> {self.max_swing_deg:g}°)"))
                continue
            cands.append((win, _circular_mean(Q.twist_angle(qs, ax))))

        # outliers: a heading far from the median of the others (anchors count, at 0)
        psis = np.array([p for _, p in cands] + [0.0] * len(anchors))
        self.accepted_: list[tuple[float, float]] = []
        self.psi_window_deg_: list[float] = []
        for i, (win, p) in enumerate(cands):
            others = np.delete(psis, i)
            if len(others):
                jump = math.degrees(abs(float(np.median(Q.wrap_angle_mod(others - p)))))
                if jump > self.max_jump_deg:
                    self.rejected_.append((win, f"heading {math.degrees(p):.1f}° is {jump:.1f}° "
                                                f"from the others' (> {self.max_jump_deg:g}°)"))
                    continue
            self.accepted_.append(win)
            self.psi_window_deg_.append(math.degrees(p))
        self.anchors_ = anchors
        nodes = [(0.5 * (a + b), math.radians(p))
                 for (a, b), p in zip(self.accepted_, self.psi_window_deg_, strict=True)]
        nodes += [(a, 0.0) for a in anchors]
        nodes.sort(key=lambda x: x[0])
        self.times_ = np.array([x[0] for x in nodes], dtype=np.float64)
        psi = np.array([x[1] for x in nodes], dtype=np.float64)
        self.psi_deg_ = np.degrees(np.unwrap(psi)) if len(psi) else psi
        self._gp = None
        self.drift_model_ = {"method": "linear"}
        if self.drift == "gp" and len(self.times_) >= 3:
            self._fit_gp(prior_zero=bool(anchors))
        return self

    def _fit_gp(self, prior_zero: bool) -> None:
        from sklearn.gaussian_process import GaussianProcessRegressor
        from sklearn.gaussian_process.kernels import ConstantKernel, Matern, WhiteKernel

        self._gp_mean = 0.0 if prior_zero else float(np.mean(self.psi_deg_))
        y = self.psi_deg_ - self._gp_mean
        x = self.times_[:, None]
        kernel = (ConstantKernel(1.0, (1e-6, 1e6)) * Matern(60.0, (1e-3, 1e6), nu=0.5)
                  + WhiteKernel(1.0, (1e-6, 1e6)))
        gp = GaussianProcessRegressor(kernel, optimizer=None).fit(x, y)
        # maximum a posteriori over a grid (log θ = log σ², log τ, log σ_n²)
        best, theta = -math.inf, None
        for ls, lt, ln in _GRID:
            th = np.array([2.0 * ls, lt, 2.0 * ln])
            lp = gp.log_marginal_likelihood(th) + _log_prior(ls, lt, ln)
            if lp > best:
                best, theta = lp, th
        self._gp = GaussianProcessRegressor(kernel.clone_with_theta(theta),
                                            optimizer=None).fit(x, y)
        sig, tau, noise = np.exp(theta / np.array([2.0, 1.0, 2.0]))
        self.drift_model_ = {"method": "gp", "sigma_deg": round(float(sig), 3),
                             "time_constant_s": round(float(tau), 2),
                             "noise_deg": round(float(noise), 3)}

    # -- applying --------------------------------------------------------------------------
    def psi_deg(self, t) -> np.ndarray:
        """ψ(t) in degrees (the ``drift`` estimator's; 0 without nodes).

        The Gaussian process is evaluated on a grid (every ``GRID_S`` seconds over the samples'
        span, the nodes included) a chunk at a time and interpolated linearly to the samples:
        time and memory linear in the samples, not samples × checkpoints. The posterior mean
        varies on the drift's time constant (≥ 15 s on the hyper-parameter grid); between grid
        points 0.25 s apart the interpolation is within a few thousandths of a degree."""
        self._check_fitted()
        t = np.asarray(t, dtype=np.float64)
        if len(self.times_) == 0:
            return np.zeros(t.shape)
        if self._gp is None:
            return np.interp(t, self.times_, self.psi_deg_)
        flat = t.reshape(-1)
        if flat.size <= 2048:
            return self._predict(flat)[0].reshape(t.shape)
        lo, hi = float(flat.min()), float(flat.max())
        grid = np.union1d(np.linspace(lo, hi, max(2, math.ceil((hi - lo) / GRID_S) + 1)),
                          self.times_[(self.times_ > lo) & (self.times_ < hi)])
        return np.interp(flat, grid, self._predict(grid)[0]).reshape(t.shape)

    def _predict(self, t: np.ndarray, std: bool = False) -> tuple[np.ndarray, np.ndarray | None]:
        """The process's posterior mean (degrees) at times ``t`` (and its standard deviation),
        a chunk at a time: memory bounded by ``_CHUNK`` × nodes."""
        mean = np.empty(len(t))
        sd = np.empty(len(t)) if std else None
        for a in range(0, len(t), _CHUNK):
            x = t[a:a + _CHUNK].reshape(-1, 1)
            if std:
                mean[a:a + _CHUNK], sd[a:a + _CHUNK] = self._gp.predict(x, return_std=True)
            else:
                mean[a:a + _CHUNK] = self._gp.predict(x)
        return mean + self._gp_mean, sd

    def uncertainty_deg(self, t0: float, t1: float, step_s: float = 1.0) -> float | None:
        """The error the correction leaves, degrees: the root mean square over ``[t0, t1]``
        (a grid of ``step_s``) of the Gaussian process's posterior standard deviation of
        ψ(t) — the drift it could not pin down between checkpoints, by its own fitted model
        (OU amplitude, correlation time, checkpoint noise). None for the ``linear`` estimate
        (no error model) and without checkpoints."""
        self._check_fitted()
        if self._gp is None:
            return None
        n = max(2, min(100_000, math.ceil((t1 - t0) / step_s) + 1))
        _, std = self._predict(np.linspace(float(t0), float(t1), n), std=True)
        return float(math.sqrt(float(np.mean(np.square(std)))))

    def apply(self, t, q) -> np.ndarray:
        """``R_axis(−ψ(t)) ⊗ q`` (N, 4); ``q`` unchanged (a copy) with nothing accepted."""
        self._check_fitted()
        q = np.asarray(q, dtype=np.float64)
        if len(self.times_) == 0:
            return q.copy()
        psi = np.radians(self.psi_deg(t))
        return Q.multiply(Q.from_axis_angle(self.axis_, -psi), q)

    def fit_apply(self, t, q, windows, **kwargs) -> np.ndarray:
        """:meth:`fit` then :meth:`apply` on the same samples."""
        return self.fit(t, q, windows, **kwargs).apply(t, q)

    @property
    def accepted_count_(self) -> int:
        self._check_fitted()
        return len(self.accepted_)

    def to_dict(self) -> dict:
        """JSON-able summary for provenance."""
        self._check_fitted()
        return {
            "neutral_checkpoints": int(self.checkpoints_),
            "accepted": len(self.accepted_),
            "rejected": [{"window": [w[0], w[1]], "reason": r} for w, r in self.rejected_],
            "anchors": list(self.anchors_),
            "times_s": [float(x) for x in self.times_],
            "psi_deg": [round(float(x), 3) for x in self.psi_deg_],
            "axis": [float(x) for x in self.axis_],
            "max_swing_deg": float(self.max_swing_deg),
            "max_jump_deg": float(self.max_jump_deg),
            "drift_model": dict(self.drift_model_),
        }

    def _check_fitted(self) -> None:
        if not hasattr(self, "times_"):
            raise CalibrationError("heading correction: call fit() first")


class LimbHeadingCorrection:
    """The heading drift of a whole limb's sensors, removed at neutral checkpoints.

    Each of the four IMUs (:mod:`calibration.limb_calibration`: one per segment) fuses its own
    heading, which drifts: sensor ``k``'s world turns about the vertical by ``d_k(t)``,
    ``q_k = Rz(d_k) ⊗ q_k⁰``. A joint sees only its two sensors' difference, and for a distal
    joint that difference is a rotation about the vertical *in the world*, which in the parent
    segment's frame is a different axis at every pose (the upper arm raised, the forearm's
    drift turns about the upper arm's +Y, not its +X): :class:`HeadingCorrection`'s joint-level
    ``R_X(−ψ) ⊗ q`` holds for a joint whose parent stays upright (the shoulder, the hip) only.
    So the drift is removed where it happens, at each sensor, relative to the root's:
    ``δ_k = d_k − d_0``, and ``Rz(−δ_k(t)) ⊗ q_k`` turns sensor ``k`` back into the root's
    drifting world; the root's own drift cancels in every joint.

    The measurement: with every joint at its neutral ``N_j`` (a checkpoint), each segment is the
    root's times the neutral chain ``C_k`` (``σ_k = σ_0 ⊗ C_k``, ``σ`` the calibration's
    :meth:`~calibration.limb_calibration.LimbImuCalibration.segment_orientations`), so
    ``σ_k ⊗ C_k⁻¹ ⊗ σ_0⁻¹ = Rz(δ_k)`` up to the patient's repeatability. For each ``k ≥ 1``
    that product is given to a :class:`HeadingCorrection` about +Z (the worlds' vertical):
    the same windows, acceptance tests (its swing test reads how far the segment's vertical is
    from the root's neutral chain: the patient not at neutral), outlier rejection, anchors (the
    calibration's static window: ψ = 0 there by construction) and drift estimator.

    Parameters
    ----------
    calibration : calibration.limb_calibration.LimbImuCalibration
        Fitted.
    **kwargs
        :class:`HeadingCorrection`'s (``max_swing_deg``, ``max_jump_deg``, ``min_samples``,
        ``min_system``, ``drift``), the same for every sensor.

    Attributes (after :meth:`fit`)
    ------------------------------
    sensors_ : dict
        ``{segment: HeadingCorrection}`` for the segments after the root.
    """

    def __init__(self, calibration, **kwargs) -> None:
        calibration._check_fitted()
        self.calibration = calibration
        self.kwargs = kwargs
        HeadingCorrection(**kwargs)  # its argument checks, now

    def fit(self, t, sensors, windows, *, status=None, anchors=()) -> LimbHeadingCorrection:
        """Estimate each sensor's heading relative to the root's at the checkpoint windows.

        Parameters
        ----------
        t : (N,) array_like
            Sample times (the windows' clock).
        sensors : (N, 4, 4) array_like
            The four sensors' orientations (sensor relative to its world), proximal to distal.
        windows : (K, 2) array_like
            Neutral checkpoint windows.
        status : (N,) array_like of int, optional
            The lowest of the four sensors' calibration bytes per sample.
        anchors : sequence of float
            Times at which every ``δ_k`` is 0 (the calibration's static window centre).
        """
        cal = self.calibration
        seg = cal.segment_orientations(sensors)
        chain = cal.neutral_chain()
        self.sensors_ = {}
        for k in range(1, seg.shape[1]):
            # parent-relative: Rz(δ_k − δ_{k−1}) at neutral
            rel = Q.multiply(Q.multiply(seg[:, k], Q.conjugate(chain[k])),
                             Q.multiply(chain[k - 1], Q.conjugate(seg[:, k - 1])))
            self.sensors_[cal.segments_[k]] = HeadingCorrection((0.0, 0.0, 1.0), **self.kwargs).fit(
                t, rel, windows, status=status, anchors=anchors)
        return self

    def psi_deg(self, t) -> np.ndarray:
        """δ_k(t) (N, 4) degrees, the root's column 0."""
        self._check_fitted()
        t = np.asarray(t, dtype=np.float64).reshape(-1)
        rel = [np.zeros(len(t)), *(hc.psi_deg(t) for hc in self.sensors_.values())]
        return np.cumsum(np.stack(rel, axis=1), axis=1)

    def apply(self, t, sensors) -> np.ndarray:
        """The sensors (N, 4, 4) with each one's drift relative to the root's removed:
        ``Rz(−δ_k(t)) ⊗ q_k`` (the root's unchanged)."""
        self._check_fitted()
        q = np.array(sensors, dtype=np.float64)
        psi = np.radians(self.psi_deg(t))
        for k in range(1, q.shape[1]):
            q[:, k] = Q.multiply(Q.from_axis_angle(_Z, -psi[:, k]), q[:, k])
        return q

    @property
    def accepted_count_(self) -> int:
        """Checkpoints accepted for every sensor (the fewest over the sensors)."""
        self._check_fitted()
        return min(hc.accepted_count_ for hc in self.sensors_.values())

    def to_dict(self) -> dict:
        """JSON-able summary: each sensor's :meth:`HeadingCorrection.to_dict`."""
        self._check_fitted()
        return {seg: hc.to_dict() for seg, hc in self.sensors_.items()}

    def _check_fitted(self) -> None:
        if not hasattr(self, "sensors_"):
            raise CalibrationError("heading correction: call fit() first")
