"""Sensor-to-segment alignment and joint orientation from two orientation sensors (IMUs).

Frames (quaternions scalar-first, Hamilton, conventions of :mod:`models.quaternion`)
------------------------------------------------------------------------------------
- **world_i** — the earth frame of sensor ``i`` (Z up). Each IMU fuses its own heading, so two
  sensors' worlds share the vertical but differ by a rotation about it (the *heading offset*).
- **sensor** — the IMU housing. A sensor reports ``q_ws``: sensor relative to its world.
- **segment** — thorax or upper arm (humerus). The rig's segment frame (the simulated patient's,
  :mod:`rig.sim.limb`): **+X inferior** along the long axis (the limb axis; it points down with
  the arm hanging at the side), **+Y anterior**, **+Z** = X × Y, to the body's right. In the
  neutral pose (standing, arm hanging at the side, forearm forward) both segments have the
  same frame, so the joint orientation is the identity.
- **mount** ``m`` — sensor relative to segment (unknown, what calibration finds):
  ``q_ws = q_w,segment ⊗ m``, so ``segment = q_ws ⊗ m⁻¹``.

Joint orientation (limb relative to thorax, in segment frames)::

    q_joint = (q_ws,thorax ⊗ m_t⁻¹)⁻¹ ⊗ (q_ws,limb ⊗ m_l⁻¹) = m_t ⊗ q_t⁻¹ ⊗ q_l ⊗ m_l⁻¹

Calibration (the standard two-step functional calibration: a static pose fixes the long axis by
gravity, a functional movement fixes a second axis; e.g. Luinge et al. 2007, *J Biomech* 40:78;
de Vries et al. 2010, *Gait Posture* 31:120; Favre et al. 2009, *J Biomech* 42:2330)
------------------------------------------------------------------------------------------------
1. **Static neutral pose** (a few seconds). Gravity, expressed in each sensor frame,
   ``g = q_ws⁻¹ ⊗ (0, 0, −1) ⊗ q_ws``, is the segment's +X (inferior) axis in sensor
   coordinates: ``x_s = normalise(mean g)``. The spread of ``g`` is the static residual.
2. **Functional movement**: flexion/extension of the arm (a hinge-like swing about the
   medio-lateral axis, +Z). The relative rotation of the limb sensor with respect to the
   thorax sensor, ``R(t) = q_t⁻¹ ⊗ q_l``, measured from the neutral pose,
   ``Δ(t) = R₀⁻¹ ⊗ R(t) = m_l⁻¹ ⊗ Rz(θ(t)) ⊗ m_l``, is a rotation about the medio-lateral axis
   written in limb-sensor coordinates; its direction is the principal axis of the rotation
   vectors ``log Δ(t)`` (largest eigenvector of Σ rv rvᵀ). A constant heading offset between the
   two sensors' worlds cancels in ``Δ``. The sign makes flexion positive: the protocol starts
   with flexion, so the first large excursion is taken as positive. The off-axis RMS of the
   rotation vectors is the functional residual.
3. **Orthonormalise** (gravity is trusted more than the functional axis): ``x`` kept,
   ``z ← normalise(z − (z·x) x)``, ``y = z × x``; ``m⁻¹`` is the rotation whose columns are
   ``x, y, z`` (segment axes in sensor coordinates). The angle removed from ``z`` is reported.
4. **Heading alignment between the sensors**: the thorax sensor's medio-lateral axis is the
   limb's, carried into thorax-sensor coordinates through the mean neutral-pose relative
   orientation ``R̄₀`` (``z_t = R̄₀ z_l``). This defines the thorax heading so that the joint
   is the identity in the neutral pose, which removes the heading offset between the two
   sensors' worlds at calibration time (whatever it is: it is absorbed, and it cannot be
   measured from orientations alone, since nothing else fixes the thorax's anterior
   direction). Heading drift *after* calibration is not observable either; it is the dominant
   error of the IMU path (docs/calibration.md).

The neutral pose *defines* the segment frames: a thorax leaning by a small rotation ``s``
during the static pose (postural sway) turns every recovered joint orientation into
``s J s⁻¹``, an error of about ``2 sin(|J|/2) |s|``.

The sensor orientations come either from the devices' own fusion or from the host's fusion of
their raw samples (:mod:`calibration.fusion`, VQF); in the latter both sensors share one world
(the earth's field is the heading reference), and the calibration must be fitted on those
orientations, not on the device's.
"""

from __future__ import annotations

import math

import numpy as np

from calibration.errors import CalibrationError
from models import quaternion as Q

__all__ = [
    "ImuJointCalibration",
    "functional_axis",
    "gravity_axis",
    "joint_orientation",
    "mean_rotation",
    "mount_from_axes",
    "rotation_vectors",
    "status_ok",
    "trusted_samples",
]

#: World "down" (the sensors' worlds are Z up).
DOWN = np.array([0.0, 0.0, -1.0])


def joint_orientation(reference, limb) -> np.ndarray:
    """Limb relative to reference, ``reference⁻¹ ⊗ limb``, vectorised.

    Parameters
    ----------
    reference, limb : (N, 4) or (4,) array_like, scalar-first unit quaternions
        Orientations of the two segments relative to one common frame (broadcast).

    Returns
    -------
    (N, 4) float64, the joint orientation, the sign of a plain product (not canonicalised).
    """
    r = Q.check_quaternions(reference, name="reference")
    q = Q.check_quaternions(limb, name="limb")
    return Q.multiply(Q.conjugate(r), q)


def status_ok(status, min_system: int = 2) -> np.ndarray:
    """Mask of samples whose IMU calibration status is trustworthy.

    Parameters
    ----------
    status : (N,) or (N, S) array_like of int
        BNO055 ``CALIB_STAT`` bytes (``sys<<6 | gyr<<4 | acc<<2 | mag``); with several sensors
        per instant (columns), every sensor must pass.
    min_system : int
        Minimum system level (0-3). A magnetic disturbance drops it to 1.

    Returns
    -------
    (N,) bool
    """
    st = np.asarray(status).astype(np.int64)
    ok = ((st >> 6) & 3) >= min_system
    return ok if ok.ndim == 1 else ok.all(axis=1)


def trusted_samples(status, n: int, min_system: int = 2) -> np.ndarray:
    """(n,) mask of the samples to read figures from: :func:`status_ok` where ``status`` is
    given (None: every sample); every sample when none passes (a figure from all of them
    rather than none)."""
    if status is None:
        return np.ones(n, bool)
    ok = status_ok(status, min_system)
    if len(ok) != n:
        raise ValueError(f"status: {len(ok)} values for {n} samples")
    return ok if ok.any() else np.ones(n, bool)


def rotation_vectors(q) -> np.ndarray:
    """Rotation vectors (axis × angle, radians) of quaternions (N, 4), angle in [0, π]."""
    q = Q.canonical(np.asarray(q, dtype=np.float64))
    v = q[..., 1:]
    s = np.linalg.norm(v, axis=-1, keepdims=True)
    ang = 2.0 * np.arctan2(s, q[..., :1])
    return np.where(s > 1e-12, v / np.where(s > 1e-12, s, 1.0) * ang, 2.0 * v)


def gravity_axis(q_world_sensor) -> tuple[np.ndarray, float]:
    """Down direction in sensor coordinates from a static pose.

    Parameters
    ----------
    q_world_sensor : (N, 4) array_like
        Sensor relative to its (Z-up) world, during a static pose.

    Returns
    -------
    axis : (3,) float64, unit, sensor frame
    spread_deg : float
        RMS angle (degrees) of the per-sample directions about ``axis``.
    """
    q = Q.check_quaternions(q_world_sensor, normalize=True, name="static pose")
    q = q.reshape(-1, 4)
    if len(q) < 2:
        raise CalibrationError(f"static pose: need at least 2 samples, got {len(q)}")
    g = Q.rotate(Q.conjugate(q), DOWN)
    axis = g.mean(axis=0)
    n = float(np.linalg.norm(axis))
    if n < 0.5:
        raise CalibrationError(
            "static pose: the sensor was not still (gravity directions do not agree)"
        )
    axis = axis / n
    spread = np.degrees(Q.angle_between(g, axis))
    return axis, float(np.sqrt(np.mean(spread**2)))


def functional_axis(delta, *, min_angle_deg: float = 10.0) -> tuple[np.ndarray, float, float]:
    """Principal rotation axis of a hinge-like movement.

    Parameters
    ----------
    delta : (N, 4) array_like
        Rotations relative to the start pose, ``Δ(t)``, all in one frame.
    min_angle_deg : float
        The movement must reach at least this angle.

    Returns
    -------
    axis : (3,) float64, unit; signed so that the first excursion beyond half the largest one
        is a positive rotation (the protocol starts with flexion).
    residual_deg : float
        RMS (degrees) of the rotation vectors' components off the axis.
    range_deg : float
        Peak-to-peak rotation about the axis, degrees.
    """
    rv = rotation_vectors(Q.check_quaternions(delta, normalize=True, name="functional movement"))
    rv = rv.reshape(-1, 3)
    mags = np.linalg.norm(rv, axis=1)
    if len(rv) < 3 or mags.max() < math.radians(min_angle_deg):
        raise CalibrationError(
            f"functional movement: the limb must flex/extend by at least {min_angle_deg:g} deg "
            f"(got {math.degrees(float(mags.max(initial=0.0))):.1f} deg)"
        )
    _, vecs = np.linalg.eigh(rv.T @ rv)
    axis = vecs[:, -1]
    s = rv @ axis
    big = np.flatnonzero(np.abs(s) >= 0.5 * np.abs(s).max())
    if s[big[0]] < 0:
        axis, s = -axis, -s
    off = np.linalg.norm(rv - s[:, None] * axis, axis=1)
    return axis, math.degrees(float(np.sqrt(np.mean(off**2)))), math.degrees(float(np.ptp(s)))


def mount_from_axes(down_s: np.ndarray, z_s: np.ndarray, down_seg=(1.0, 0.0, 0.0), *,
                    what: str = "functional movement") -> tuple[np.ndarray, float]:
    """Mount (sensor relative to segment) from two of the segment's directions in sensor
    coordinates: ``down_s``, the one gravity gives in the neutral pose (kept exactly), and
    ``z_s``, the segment's +Z (the functional movement's axis, made orthogonal to it).
    ``down_seg`` is the direction pointing down in segment coordinates (+X, the long axis,
    for every segment but the foot, whose −Y points down).

    Returns the mount (4,), ``w ≥ 0``, and the angle (degrees) removed from ``z_s`` to make it
    orthogonal; CalibrationError naming ``what`` when the two are within 20° of each other.
    """
    rs, n = _triad(down_s, z_s)
    if n < math.sin(math.radians(20.0)):
        raise CalibrationError(
            f"{what}: its axis is within 20 deg of the long axis (gravity); flex/extend the "
            "joint, not a rotation of the segment about itself"
        )
    rb, _ = _triad(np.asarray(down_seg, dtype=np.float64), np.array([0.0, 0.0, 1.0]))
    from scipy.spatial.transform import Rotation

    m_inv = Q.from_rotation(Rotation.from_matrix(rs @ rb.T))  # segment → sensor coordinates
    removed = math.degrees(math.asin(min(1.0, abs(float(z_s @ down_s)))))
    return Q.canonical(Q.conjugate(m_inv)), removed


def _triad(v1: np.ndarray, v2: np.ndarray) -> tuple[np.ndarray, float]:
    """Orthonormal basis (columns) from ``v1`` (kept) and ``v2`` (made orthogonal), and
    ``|v2⊥|`` (the sine of their angle for unit inputs)."""
    b1 = v1 / np.linalg.norm(v1)
    b2 = v2 - (v2 @ b1) * b1
    n = float(np.linalg.norm(b2))
    b2 = b2 / max(n, 1e-12)
    return np.column_stack((b1, b2, Q.cross(b1, b2))), n


def mean_rotation(q: np.ndarray) -> np.ndarray:
    """Chordal L2 mean of unit quaternions (Markley et al. 2007), sign-invariant."""
    _, vecs = np.linalg.eigh(q.T @ q)
    return Q.canonical(vecs[:, -1])


class ImuJointCalibration:
    """Two-sensor (thorax + upper arm) calibration: mounts, heading alignment, joint orientation.

    scikit-learn style: hyper-parameters here, :meth:`fit` returns ``self``, fitted state in
    trailing-underscore attributes, :meth:`transform` maps sensor orientations to joint ones.

    Parameters
    ----------
    min_flexion_deg : float
        The functional movement must rotate the arm at least this far (default 10°).

    Attributes
    ----------
    thorax_mount_, limb_mount_ : (4,) float64
        Sensor relative to segment (w ≥ 0).
    residuals_ : dict[str, float]
        Degrees: ``static`` (RMS angle of the calibrated joint from identity over the static
        pose), ``gravity_thorax``/``gravity_limb`` (spread of gravity), ``functional``
        (off-axis RMS of the flexion movement), ``orthogonality`` (angle removed from the
        functional axis), ``functional_range`` (peak-to-peak flexion, not an error).
    residual_deg_ : float
        ``max(static, functional)``: one number to judge the calibration by.
    """

    def __init__(self, *, min_flexion_deg: float = 10.0) -> None:
        self.min_flexion_deg = float(min_flexion_deg)

    def fit(self, static_thorax, static_limb, functional_thorax, functional_limb, *,
            static_ok=None, functional_ok=None):
        """Calibrate from a static neutral pose and a flexion/extension movement.

        Parameters
        ----------
        static_thorax, static_limb : (N, 4) array_like
            Sensor-relative-to-world orientations during the static neutral pose (arm hanging
            at the side, forearm forward), same instants.
        functional_thorax, functional_limb : (M, 4) array_like
            The same during the flexion/extension movement (flexion first).
        static_ok, functional_ok : (N,), (M,) array_like of bool, optional
            Samples to use (e.g. :func:`status_ok` of the sensors' calibration bytes, which
            drops magnetic disturbances); default all.

        Returns
        -------
        self
        """
        st = Q.check_quaternions(static_thorax, normalize=True, name="static thorax")
        sl = Q.check_quaternions(static_limb, normalize=True, name="static limb")
        ft = Q.check_quaternions(functional_thorax, normalize=True, name="functional thorax")
        fl = Q.check_quaternions(functional_limb, normalize=True, name="functional limb")
        st, sl, ft, fl = (a.reshape(-1, 4) for a in (st, sl, ft, fl))
        if len(st) != len(sl) or len(ft) != len(fl):
            raise CalibrationError(
                "thorax and limb samples must pair up (same instants): "
                f"static {len(st)} vs {len(sl)}, functional {len(ft)} vs {len(fl)}"
            )
        for ok, name in ((static_ok, "static"), (functional_ok, "functional")):
            if ok is not None and np.asarray(ok).shape != ((len(st),) if name == "static"
                                                            else (len(ft),)):
                raise CalibrationError(f"{name}_ok: one flag per {name} sample expected")
        if static_ok is not None:
            st, sl = st[np.asarray(static_ok, bool)], sl[np.asarray(static_ok, bool)]
        if functional_ok is not None:
            ft, fl = ft[np.asarray(functional_ok, bool)], fl[np.asarray(functional_ok, bool)]
        x_t, g_t = gravity_axis(st)
        x_l, g_l = gravity_axis(sl)
        r0 = mean_rotation(Q.multiply(Q.conjugate(st), sl))  # limb sensor in thorax sensor
        rel = Q.multiply(Q.conjugate(ft), fl)
        delta = Q.multiply(Q.conjugate(r0), rel)  # about the flexion axis, limb-sensor coords
        z_l, functional_res, flex_range = functional_axis(delta, min_angle_deg=self.min_flexion_deg)
        self.limb_mount_, ortho = mount_from_axes(x_l, z_l)
        z_t = Q.rotate(r0, z_l)
        self.thorax_mount_, _ = mount_from_axes(x_t, z_t)
        static_angle = np.degrees(Q.angle(self.transform(st, sl)))
        self.residuals_ = {
            "static": float(np.sqrt(np.mean(static_angle**2))),
            "gravity_thorax": g_t,
            "gravity_limb": g_l,
            "functional": functional_res,
            "orthogonality": ortho,
            "functional_range": flex_range,
        }
        self.residual_deg_ = max(self.residuals_["static"], functional_res)
        return self

    def transform(self, thorax, limb) -> np.ndarray:
        """Joint orientations (N, 4), limb relative to thorax in segment frames.

        Parameters
        ----------
        thorax, limb : (N, 4) array_like
            Sensor-relative-to-world orientations at the same instants.
        """
        self._check_fitted()
        t = Q.check_quaternions(thorax, normalize=True, name="thorax")
        q = Q.check_quaternions(limb, normalize=True, name="limb")
        return Q.multiply(Q.multiply(self.thorax_mount_, Q.conjugate(t)),
                          Q.multiply(q, Q.conjugate(self.limb_mount_)))

    def to_dict(self) -> dict:
        """Plain-type summary (for the store's calibration record)."""
        self._check_fitted()
        return {
            "kind": "imu-two-sensor",
            "thorax_mount": [float(v) for v in self.thorax_mount_],
            "limb_mount": [float(v) for v in self.limb_mount_],
            "residuals_deg": {k: float(v) for k, v in self.residuals_.items()},
            "residual_deg": float(self.residual_deg_),
        }

    @classmethod
    def from_dict(cls, data: dict) -> ImuJointCalibration:
        """Rebuild a fitted calibration from :meth:`to_dict` output (plus the recorder's
        ``protocol`` and ``windows_s`` entries, which are ignored); other keys are errors."""
        known = {"kind", "thorax_mount", "limb_mount", "residuals_deg",
                 "residual_deg",
                 "protocol", "windows_s"}  # what the recorder adds: the protocol it ran
        unknown = set(data) - known
        if unknown:
            raise CalibrationError(f"calibration record: unknown key(s) {sorted(unknown)}")
        self = cls()
        try:
            self.thorax_mount_ = Q.check_quaternions(data["thorax_mount"], name="thorax_mount")
            self.limb_mount_ = Q.check_quaternions(data["limb_mount"], name="limb_mount")
            self.residuals_ = dict(data.get("residuals_deg", {}))
            self.residual_deg_ = float(data.get("residual_deg", math.nan))
        except KeyError as err:
            raise CalibrationError(f"calibration record: missing {err.args[0]!r}") from err
        return self

    def _check_fitted(self) -> None:
        if not hasattr(self, "limb_mount_"):
            raise CalibrationError("calibration is not fitted: call fit() first")
