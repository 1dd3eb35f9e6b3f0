"""Sensor-to-segment calibration of a whole arm or leg, one orientation sensor (IMU) per segment.

The chain of :mod:`calibration.alignment` (the shoulder's two sensors) extended to the four
segments of a limb (:data:`calibration.protocol.LIMB_CHAINS`): thorax, upper arm, forearm, hand
or pelvis, thigh, shank, foot, calibrated from the protocol of
:class:`calibration.protocol.LimbCalibrationProtocol` (a static neutral pose, then each joint's
flexion/extension in turn, proximal to distal, every other joint at its clinical zero).

Frames (quaternions scalar-first, Hamilton, conventions of :mod:`models.quaternion`)
------------------------------------------------------------------------------------
- **world_k** — the earth frame of sensor ``k`` (Z up). Each IMU fuses its own heading: the
  four worlds share the vertical and differ by rotations about it (the *heading offsets*).
- **sensor** — the IMU housing; sensor ``k`` reports ``q_k``, sensor relative to world_k.
- **segment** — the rig's segment frames (:mod:`calibration.frames`,
  :mod:`calibration.joint_angles`): **+X** along the segment, pointing distally (inferior
  when standing), **+Y** anterior, **+Z** = X × Y, to the body's right; the **foot**: +X
  towards the toes, +Y superior, +Z right. +Z points to the body's *right* on either side: on
  a left limb it points medially, and flexion is still a positive rotation about +Z (a
  rotation about the normal of the mirror plane is its own mirror image), except at the knee,
  whose flexion is negative about +Z on both sides (the shank swings backwards).
- **mount** ``m_k`` — sensor relative to segment: ``q_k = H_k ⊗ S_k ⊗ m_k`` with ``S_k`` the
  segment relative to a common world and ``H_k`` the rotation about Z from it to world_k.
- **heading correction** ``h_k = Rz(ψ_k)`` — what calibration finds for each sensor's world:
  ``h_k ⊗ q_k`` is in the root sensor's world (``ψ_0 = 0``).
- **joint orientation** ``k`` (child ``k`` relative to parent ``k − 1``, rig frames)::

      σ_k = h_k ⊗ q_k ⊗ m_k⁻¹,      J_k = σ_{k−1}⁻¹ ⊗ σ_k

  In the neutral pose ``J_k`` is the protocol's neutral ``N_k`` (its
  :meth:`~calibration.protocol.LimbCalibrationProtocol.joint_orientations` at rest): the
  identity, except the ankle's ``from_angles(0, 0, 0, 'ankle')`` (Rz(90°): the foot's +X along
  the shank's +Y).

Calibration (the two-step functional calibration of :mod:`calibration.alignment` — Luinge et
al. 2007, *J Biomech* 40:78; de Vries et al. 2010, *Gait Posture* 31:120; Favre et al. 2009,
*J Biomech* 42:2330 — with the heading offsets between the sensors' worlds estimated from the
movements: two sensors turning together see one rotation axis, written in worlds that differ
by their heading offset; compare the heading offset of a hinge joint's two sensors found from
its kinematic constraint by Laidig, Schauer & Seel 2017, *Proc. IEEE ICORR*, 971)
----------------------------------------------------------------------------------------------
1. **Static neutral pose**: gravity in each sensor's frame
   (:func:`~calibration.alignment.gravity_axis`) is the segment direction that points down in
   the neutral pose, in sensor coordinates: +X, the foot's −Y. Its spread is the ``gravity``
   residual.
2. **Heading offsets from the movements**: while joint ``j`` flexes, every segment distal to
   it moves with its child as one rigid body (the other joints rest at zero), so the sensors
   on them turn by one rotation ``G(t)``, seen in world_k as ``H_k G H_k⁻¹``: the rotation
   vectors of ``q_k(t) ⊗ q̄_k⁻¹`` (``q̄_k`` the sensor's mean over that movement, not over the
   static pose: a sensor whose heading drifted since the static pose would add the drift to
   every rotation and bias the offset by half of it) of two such sensors differ by
   their heading offset, found in closed form (2-D Procrustes of the horizontal components,
   pooled over every movement both sensors share). The flexion axes are horizontal in the
   neutral pose, so this is well determined; the offset between the root and the first
   segment is not (the root never moves with another segment): as for the shoulder, it is
   absorbed in the root's mount (``ψ_0 = ψ_1``), exact while the root stays upright.
3. **Flexion axis of each joint**: with the heading-corrected sensors, the child's rotation
   relative to the parent, ``R = q_p⁻¹ ⊗ q_c``, about its mean over the movement,
   ``Δ(t) = R̄⁻¹ ⊗ R(t)``, is a rotation about the joint's medio-lateral axis in child-sensor
   coordinates; its principal axis (:func:`~calibration.alignment.functional_axis`) gives the
   child's ±Z, signed so that the first large excursion from the static pose (``R̄₀⁻¹ ⊗ R``,
   ``R̄₀`` the static mean) is positive — flexion first, by protocol — and then by the
   protocol's own script (the knee's flexion is about −Z). About the movement's own mean, not
   the static pose: a change of the two sensors' relative heading since the static pose
   (drift) is a constant factor on the parent's side, which drops out of ``R̄⁻¹ ⊗ R`` but
   tilts an axis fitted to ``R̄₀⁻¹ ⊗ R`` (test
   ``test_heading_drift_after_the_static_pose_leaves_the_mounts_exact``: up to 2° of axis
   and 5° of joint error for 4° of drift). The off-axis RMS is the ``functional`` residual,
   the peak-to-peak angle the ``range`` (not an error). Carried through ``R̄`` it gives the
   parent's ±Z too.
4. **Combine**: the root's Z comes from its child's movement (as the shoulder's thorax); a
   middle segment's from two movements (as the child of its proximal joint and as the parent
   of its distal one), averaged with weights ``Σ s²`` (the squared flexion angles of each
   movement: the inverse variance of an axis fitted to rotation vectors with white noise);
   the angle between the two is the ``axes`` residual. Both must point the same way: if they
   do not (more than 90° apart), the fewest joints whose flip makes every pair agree (a
   movement begun with extension) are flipped and named in ``flipped_``.
5. **Orthonormalise**, gravity trusted more: the angle removed from Z is the
   ``orthogonality`` residual.
6. **Heading alignment from the neutral pose**: proximal to distal, ``ψ_k`` is the rotation
   about the vertical that makes the mean static joint ``J_k`` equal to ``N_k`` (its twist
   about world Z; ``ψ_0 = 0``). Its difference from the movements' offset (step 2) is the
   ``heading`` residual of segments 2 and 3 (a sensor that turned on its strap between the
   phases, or a mount twist found wrong); the RMS angle of each static ``J_k`` from ``N_k`` is
   the joint's ``static`` residual.

7. **The root's lean during the static pose** (optional: ``fit(upright=...)``, further neutral
   standings such as a session's neutral checkpoints). Gravity is each segment's long axis
   only if the patient stood upright in the static pose; a root leaning by ``s`` there (the
   whole chain leans with it, joints at neutral) conjugates every joint by ``s``. The root's
   down axis is taken as the median of its gravity axes over the static pose and every
   further standing (the sway averages out over standings minutes apart); the rotation from
   the static pose's gravity to it is the lean, taken off every segment's gravity axis (in
   each sensor's world through ``ψ_k``), and steps 5-6 run again. It needs the sensors'
   worlds to share the vertical's heading reference: the root's lean direction reaches the
   other segments through ``ψ``, and ``ψ_1`` is absorbed (step 2), so the read path uses it
   on the host's fusion (one world for every sensor) only. ``lean_deg_`` is the lean taken
   off. On development arms (``bench_limb_imu.py --seeds 1,2,3,4,5 --limbs arm``, 300 s,
   checkpoints every 20 s) the shoulder's calibration error went 0.21 → 0.13° with error-free
   sensors and 1.00 → 0.73° through the host's fusion, the elbow's 0.59 → 0.44° (medians).

Without step 7 the neutral pose alone defines the segment frames, and heading drift after
calibration is not observable (docs/calibration.md).

Accuracy (measured)
-------------------
Synthetic recordings of the protocol at 50 Hz (``tests/calibration/test_limb_calibration.py``):
mounts misplaced up to ±30°, a random heading per sensor's world, white noise 0.5° per axis
and sample (0.87° RMS angle per sensor), root sway of three 0.3° sinusoids (0.1-0.5 Hz); five
seeds per limb and side, measured with ``.venv/bin/python -m pytest -q -s -k accuracy
tests/calibration/test_limb_calibration.py``. Calibration error = the fitted calibration
applied to the noise-free sensor orientations, against the truth (angle of ``J_true⁻¹ ⊗ J``);
median / max, degrees, arm and leg alike (either side):

=====================  ==========================  ==========================
joint                  protocol's movements        60 s random motion
=====================  ==========================  ==========================
shoulder / hip         0.48 / 1.38                 0.69 / 2.01
elbow / knee           0.13 / 0.23                 0.16 / 0.40
wrist / ankle          0.06 / 0.33                 0.09 / 0.48
=====================  ==========================  ==========================

Adding the sensors' own noise, every joint is at 1.1-1.3° median, 3.1-4.1° max (the noise of
two sensors). The non-root mounts are recovered within 0.44°; ``residual_deg_`` is 1.24-1.33°
(the noise). Without noise and sway the calibration is exact (< 1e-6°). The root joint's larger
error is the absorbed heading offset (step 2): a root leaning by ``s`` from its static pose
turns the first joint by about ``2 sin(δ/2) |s|``, ``δ`` the offset between the root's and
the first segment's sensor worlds (the seeds' ``|δ|`` are 14-131°); a root leaning 10° gives
2.5° (``δ = 14°``) to 18° (``δ = 131°``) at the shoulder or hip, as predicted, and leaves the
other joints within 0.6° (test ``test_root_lean_error_is_the_absorbed_heading_offset``).
Sensors sharing one world (the host's VQF fusion, :mod:`calibration.fusion`) have ``δ ≈ 0``.
"""

from __future__ import annotations

import math

import numpy as np

from calibration.alignment import (
    functional_axis,
    gravity_axis,
    mean_rotation,
    mount_from_axes,
    rotation_vectors,
)
from calibration.errors import CalibrationError
from calibration.protocol import LIMB_CHAINS, LimbCalibrationProtocol
from models import quaternion as Q

__all__ = ["LimbImuCalibration"]

_X = np.array([1.0, 0.0, 0.0])
_Z = np.array([0.0, 0.0, 1.0])
_MIN_AXIS_GRAVITY_DEG = 20.0


def _rz(psi) -> np.ndarray:
    """Rotation(s) about world Z by ``psi`` (radians)."""
    return Q.from_axis_angle(_Z, np.asarray(psi, dtype=np.float64))


def _check_sensors(a, name: str, n_segments: int) -> np.ndarray:
    """(N, S, 4) sensor orientations → float64, unit norm; CalibrationError on bad input."""
    try:
        arr = np.asarray(a, dtype=np.float64)
    except (TypeError, ValueError) as err:
        raise CalibrationError(f"{name}: not a numeric array ({err})") from err
    if arr.ndim != 3 or arr.shape[1:] != (n_segments, 4):
        raise CalibrationError(
            f"{name}: expected shape (N, {n_segments}, 4) (instants, segments proximal to "
            f"distal, scalar-first quaternions), got {arr.shape}"
        )
    bad = ~np.isfinite(arr).all(axis=2)
    if bad.any():
        i, k = np.argwhere(bad)[0]
        raise CalibrationError(f"{name}[{i}, {k}]: a NaN or infinite quaternion component")
    norm = np.linalg.norm(arr, axis=2, keepdims=True)
    if (norm < 1e-6).any():
        i, k = np.argwhere(norm[..., 0] < 1e-6)[0]
        raise CalibrationError(f"{name}[{i}, {k}]: a zero quaternion")
    return arr / norm


def _mask(ok, n: int, name: str) -> np.ndarray:
    if ok is None:
        return np.ones(n, dtype=bool)
    ok = np.asarray(ok)
    if ok.shape != (n,):
        raise CalibrationError(f"{name}: one flag per sample expected ({n}), got {ok.shape}")
    return ok.astype(bool)


def _heading_sums(rv_a: np.ndarray, rv_b: np.ndarray) -> np.ndarray:
    """Procrustes sums (Σ cross, Σ dot) of horizontal components: ``ψ = atan2(cross, dot)``
    is the rotation about Z taking ``rv_b`` onto ``rv_a`` best (least squares)."""
    cross = np.sum(rv_a[:, 1] * rv_b[:, 0] - rv_a[:, 0] * rv_b[:, 1])
    dot = np.sum(rv_a[:, 0] * rv_b[:, 0] + rv_a[:, 1] * rv_b[:, 1])
    return np.array([cross, dot])


class LimbImuCalibration:
    """One IMU per segment of an arm or a leg: mounts, heading alignment, joint orientations.

    scikit-learn style: hyper-parameters here, :meth:`fit` returns ``self``, fitted state in
    trailing-underscore attributes, :meth:`transform` maps sensor orientations to joint ones.
    See the module doc for frames and method.

    Parameters
    ----------
    limb : {"arm", "leg"}
        Which chain (:data:`calibration.protocol.LIMB_CHAINS`): segments thorax, upper-arm,
        forearm, hand or pelvis, thigh, shank, foot (proximal to distal).
    side : {"right", "left"}
        The limb's side (the protocol's neutral and flexion script for that side).
    protocol : LimbCalibrationProtocol, optional
        The protocol performed (its neutral pose and the direction each movement starts in);
        default ``LimbCalibrationProtocol(limb)``. Its ``limb`` must be ``limb``.
    min_flexion_deg : float
        Each joint's movement must reach at least this angle (default 10°).

    Attributes
    ----------
    segments_, joints_ : tuple of str
        Names, proximal to distal (4 and 3).
    mounts_ : (4, 4) float64
        Sensor relative to segment, per segment (``w ≥ 0``); the root's absorbs the heading
        offset between its sensor's world and the first segment's (module doc).
    headings_deg_ : (4,) float64
        ``ψ_k``: the rotation about the vertical (degrees) that takes sensor ``k``'s world to the
        root sensor's (``ψ_0 = 0``).
    neutral_ : (3, 4) float64
        The protocol's neutral joint orientations (rig frames).
    flipped_ : tuple of str
        Joints whose movement axis sign was set by its neighbours, not by its own first
        excursion (module doc, step 4); normally empty.
    residuals_ : dict[str, dict[str, float]]
        Degrees, per joint: ``static`` (RMS angle of the calibrated joint from its neutral over
        the static pose), ``functional`` (off-axis RMS of its movement), ``range`` (its
        peak-to-peak flexion, not an error); per segment: ``gravity`` (spread of gravity in the
        static pose), ``orthogonality`` (angle removed from the flexion axis), and for the
        middle segments ``axes`` (angle between the flexion axes from its two movements), for
        the last two ``heading`` (neutral-pose heading offset minus the movements').
    residual_deg_ : float
        The largest residual (``range`` excluded): one number to judge the calibration by.
    lean_deg_ : float or None
        The root's lean during the static pose that step 7 took off (degrees; None without
        ``upright`` standings).
    """

    def __init__(self, limb: str = "arm", side: str = "right", *,
                 protocol: LimbCalibrationProtocol | None = None,
                 min_flexion_deg: float = 10.0) -> None:
        self.limb = limb
        self.side = side
        self.protocol = protocol
        self.min_flexion_deg = float(min_flexion_deg)

    # -- protocol-derived constants -----------------------------------------------------------

    def _setup(self) -> LimbCalibrationProtocol:
        if self.limb not in LIMB_CHAINS:
            raise CalibrationError(f"limb must be one of {', '.join(LIMB_CHAINS)}, "
                                   f"got {self.limb!r}")
        if self.side not in ("right", "left"):
            raise CalibrationError(f"side must be 'right' or 'left', got {self.side!r}")
        p = self.protocol if self.protocol is not None else LimbCalibrationProtocol(self.limb)
        if p.limb != self.limb:
            raise CalibrationError(f"protocol is for the {p.limb}, calibration for the "
                                   f"{self.limb}")
        self.segments_ = p.segments
        self.joints_ = p.joints
        w = p.windows()
        self.neutral_ = p.joint_orientations(np.array([0.5 * sum(w["static"])]), self.side)[0]
        return p

    def _scripted_axes(self, p: LimbCalibrationProtocol) -> np.ndarray:
        """Per joint, ±1: the sign of +Z (child coordinates) of the scripted movement's axis as
        :func:`functional_axis` signs it (first large excursion positive)."""
        w = p.windows()
        out = np.empty(len(self.joints_))
        for j, joint in enumerate(self.joints_):
            t = np.linspace(*w[joint], 400)
            q = p.joint_orientations(t, self.side)[:, j]
            u, _, _ = functional_axis(Q.multiply(Q.conjugate(self.neutral_[j]), q))
            if abs(u[2]) < 0.999 or abs(Q.rotate(self.neutral_[j], u)[2]) < 0.999:
                raise CalibrationError(f"protocol: the {joint}'s movement is not about +Z")
            out[j] = math.copysign(1.0, u[2])
        return out

    # -- fit ----------------------------------------------------------------------------------

    def fit(self, static, functional, *, static_ok=None, functional_ok=None, upright=None):
        """Calibrate from the static neutral pose and each joint's flexion/extension.

        Parameters
        ----------
        static : (N, 4, 4) array_like
            Sensor-relative-to-world orientations (scalar-first) of the four segments'
            sensors, proximal to distal, during the static neutral pose (N instants).
        functional : dict[str, (M_j, 4, 4) array_like]
            The same during each joint's movement window, keyed by joint name (the protocol's
            :meth:`~calibration.protocol.LimbCalibrationProtocol.windows`), flexion first.
        static_ok : (N,) array_like of bool, optional
            Samples to use (e.g. :func:`calibration.alignment.status_ok` of the four sensors'
            status bytes); default all.
        functional_ok : dict[str, (M_j,) array_like of bool], optional
            The same per movement (a joint left out uses all its samples).
        upright : sequence of (M_i, 4, 4) array_like, optional
            The sensors' orientations during further neutral standings (a session's neutral
            checkpoints), as ``static``; only the root sensor's are used. The root's down axis
            is then the median of the static pose's and these windows' gravity axes (one vote
            per window), and the root's lean during the static pose away from it is taken off
            every segment's gravity axis (step 7 of the module doc; the sensors must share one
            world). Windows where the sensor was not still are left out.

        Returns
        -------
        self
        """
        p = self._setup()
        n_seg = len(self.segments_)
        st = _check_sensors(static, "static", n_seg)
        st = st[_mask(static_ok, len(st), "static_ok")]
        if not isinstance(functional, dict):
            raise CalibrationError("functional: expected a dict {joint: (M, 4, 4) array}")
        unknown = set(functional) - set(self.joints_)
        if unknown:
            raise CalibrationError(f"functional: unknown joint(s) {sorted(unknown)} for the "
                                   f"{self.limb} ({', '.join(self.joints_)})")
        missing = [j for j in self.joints_ if j not in functional]
        if missing:
            raise CalibrationError(f"functional: no movement of the {', '.join(missing)} "
                                   "(each joint's flexion/extension is needed)")
        fok = {} if functional_ok is None else functional_ok
        if not isinstance(fok, dict) or set(fok) - set(self.joints_):
            raise CalibrationError("functional_ok: expected a dict {joint: (M,) bool} with "
                                   f"joints of the {self.limb} ({', '.join(self.joints_)})")
        fn = {}
        for joint in self.joints_:
            a = _check_sensors(functional[joint], f"functional[{joint!r}]", n_seg)
            fn[joint] = a[_mask(fok.get(joint), len(a), f"functional_ok[{joint!r}]")]
        signs = self._scripted_axes(p)

        # 1. gravity and the static means
        g_s, res_seg = [], {s: {} for s in self.segments_}
        for k, seg in enumerate(self.segments_):
            try:
                axis, spread = gravity_axis(st[:, k])
            except CalibrationError as err:
                raise CalibrationError(f"{seg}: {err}") from err
            g_s.append(axis)
            res_seg[seg]["gravity"] = spread
        qbar = np.stack([mean_rotation(st[:, k]) for k in range(n_seg)])
        g_seg = Q.rotate(Q.conjugate(self._chain(self.neutral_)), _X)  # down, segment coords

        # 2. heading offsets between adjacent sensors from the movements they share
        psi_mov = np.zeros(n_seg)
        for k in range(1, n_seg - 1):
            sums = np.zeros(2)
            for j in range(k):  # joint j moves segments j+1 ... together
                f = fn[self.joints_[j]]
                # about each sensor's mean over the movement, not its static mean: a sensor
                # whose heading drifted since the static pose then still turns by H G H⁻¹
                rv_a = rotation_vectors(Q.multiply(f[:, k], Q.conjugate(mean_rotation(f[:, k]))))
                rv_b = rotation_vectors(Q.multiply(f[:, k + 1],
                                                   Q.conjugate(mean_rotation(f[:, k + 1]))))
                sums += _heading_sums(rv_a, rv_b)
            psi_mov[k + 1] = psi_mov[k] + math.atan2(sums[0], sums[1])
        h_mov = _rz(psi_mov)

        # 3. each joint's flexion axis in its child sensor's coordinates
        axes, weights, res_joint = [], [], {j: {} for j in self.joints_}
        r_movs = []
        for j, joint in enumerate(self.joints_):
            hp, hc = h_mov[j], h_mov[j + 1]
            rel_st = Q.multiply(Q.conjugate(Q.multiply(hp, st[:, j])),
                                Q.multiply(hc, st[:, j + 1]))
            r0 = mean_rotation(rel_st)
            f = fn[joint]
            rel = Q.multiply(Q.conjugate(Q.multiply(hp, f[:, j])), Q.multiply(hc, f[:, j + 1]))
            delta = Q.multiply(Q.conjugate(r0), rel)
            peak = math.degrees(float(Q.angle(delta).max(initial=0.0)))
            if len(delta) < 3 or peak < self.min_flexion_deg:
                raise CalibrationError(
                    f"{joint} movement: the joint must flex/extend by at least "
                    f"{self.min_flexion_deg:g} deg (got {peak:.1f} deg)"
                )
            # step 3: the axis from the movement's own relative rotations (about their mean),
            # signed by the excursion from the static pose (flexion first)
            r_mov = mean_rotation(rel)
            own = Q.multiply(Q.conjugate(r_mov), rel)
            a, fres, frange = functional_axis(own, min_angle_deg=0.0)
            s0 = rotation_vectors(delta) @ a
            first = s0[np.flatnonzero(np.abs(s0) >= 0.5 * np.abs(s0).max())[0]]
            a = a if first >= 0 else -a
            child = self.segments_[j + 1]
            if abs(float(a @ g_s[j + 1])) > math.cos(math.radians(_MIN_AXIS_GRAVITY_DEG)):
                raise CalibrationError(
                    f"{joint} movement: its axis is within {_MIN_AXIS_GRAVITY_DEG:g} deg of the "
                    f"vertical in the {child}'s sensor; flex/extend the {joint}, do not rotate "
                    f"the {child} about itself"
                )
            s = rotation_vectors(delta) @ a
            axes.append(a * signs[j])  # the child's +Z, child-sensor coordinates
            weights.append(float(s @ s))
            r_movs.append(r_mov)
            res_joint[joint]["functional"] = fres
            res_joint[joint]["range"] = frange

        # 4. +Z of each segment: own (as a child) and carried (as a parent)
        own = [None, *axes]
        carried = [Q.rotate(r_movs[j], axes[j]) for j in range(len(self.joints_))] + [None]
        conflict = [float(own[k] @ carried[k]) < 0 for k in range(1, n_seg - 1)]
        flip = set()
        if all(conflict):
            flip = {1}
        elif conflict[0]:
            flip = {0}
        elif conflict[1]:
            flip = {2}
        for j in flip:
            own[j + 1] = -own[j + 1]
            carried[j] = -carried[j]
        self.flipped_ = tuple(self.joints_[j] for j in sorted(flip))
        z_s = []
        for k, seg in enumerate(self.segments_):
            if own[k] is None or carried[k] is None:
                z_s.append(own[k] if carried[k] is None else carried[k])
                continue
            z = weights[k - 1] * own[k] + weights[k] * carried[k]
            z_s.append(z / np.linalg.norm(z))
            res_seg[seg]["axes"] = math.degrees(float(Q.angle_between(own[k], carried[k])))

        # 5. mounts
        self.mounts_ = self._mounts(g_s, z_s, g_seg, res_seg)

        # 6. headings from the neutral pose, proximal to distal
        psi = self._headings(qbar)
        # 7. the root's lean during the static pose, from further neutral standings
        self.lean_deg_ = None
        if upright is not None:
            g_up = [g_s[0]]
            for i, w in enumerate(upright):
                root = _check_sensors(w, f"upright[{i}]", n_seg)[:, 0]
                try:
                    g_up.append(gravity_axis(root)[0])
                except CalibrationError:
                    continue  # not still, or too short: not a standing
            if len(g_up) > 1:
                # the median, component by component: one standing that was not upright (a
                # patient leaning at one checkpoint) does not move it
                g_root = np.median(g_up, axis=0)
                g_root /= np.linalg.norm(g_root)
                lean = Q.from_two_vectors(g_s[0], g_root)  # root-sensor coordinates
                world = Q.multiply(Q.multiply(qbar[0], lean), Q.conjugate(qbar[0]))
                for k in range(n_seg):
                    h = _rz(psi[k])
                    in_k = Q.multiply(Q.multiply(Q.conjugate(h), world), h)  # world_k
                    r = Q.multiply(Q.multiply(Q.conjugate(qbar[k]), in_k), qbar[k])
                    g_s[k] = Q.rotate(r, g_s[k])
                self.lean_deg_ = math.degrees(float(Q.angle_between(g_s[0], g_up[0])))
                self.mounts_ = self._mounts(g_s, z_s, g_seg, res_seg)
                psi = self._headings(qbar)
        self.headings_deg_ = np.degrees(psi)
        for k in range(2, n_seg):
            d = Q.wrap_angle((psi[k] - psi[1]) - psi_mov[k])
            res_seg[self.segments_[k]]["heading"] = abs(math.degrees(float(d)))

        joints = self.transform(st)
        for j, joint in enumerate(self.joints_):
            err = np.degrees(Q.angle(Q.multiply(Q.conjugate(self.neutral_[j]), joints[:, j])))
            res_joint[joint]["static"] = float(np.sqrt(np.mean(err**2)))
        self.residuals_ = {**{j: res_joint[j] for j in self.joints_},
                           **{s: res_seg[s] for s in self.segments_}}
        self.residual_deg_ = max(v for r in self.residuals_.values()
                                 for k, v in r.items() if k != "range")
        return self

    def _mounts(self, g_s, z_s, g_seg, res_seg) -> np.ndarray:
        """Step 5: each segment's mount (S, 4) from its down axis ``g_s`` and +Z ``z_s``
        (sensor coordinates), recording the ``orthogonality`` residuals in ``res_seg``."""
        mounts = []
        for k, seg in enumerate(self.segments_):
            m, removed = mount_from_axes(g_s[k], z_s[k], g_seg[k], what=seg)
            mounts.append(m)
            res_seg[seg]["orthogonality"] = removed
        return np.stack(mounts)

    def _headings(self, qbar: np.ndarray) -> np.ndarray:
        """Step 6: ``ψ_k`` (radians) that makes each mean static joint its neutral, proximal to
        distal, from the static means ``qbar`` and the mounts."""
        psi = np.zeros(len(qbar))
        sigma = Q.multiply(qbar[0], Q.conjugate(self.mounts_[0]))
        for k in range(1, len(qbar)):
            target = Q.multiply(Q.multiply(sigma, self.neutral_[k - 1]),
                                Q.multiply(self.mounts_[k], Q.conjugate(qbar[k])))
            psi[k] = float(Q.twist_angle(target, _Z))
            sigma = Q.multiply(Q.multiply(_rz(psi[k]), qbar[k]), Q.conjugate(self.mounts_[k]))
        return psi

    @staticmethod
    def _chain(neutral: np.ndarray) -> np.ndarray:
        """(4, 4): each segment relative to the root in the neutral pose."""
        out = [Q.IDENTITY.copy()]
        for q in neutral:
            out.append(Q.multiply(out[-1], q))
        return np.stack(out)

    def neutral_chain(self) -> np.ndarray:
        """(4, 4): each segment relative to the root in the neutral pose (the protocol's
        neutral joints, composed proximal to distal)."""
        self._check_fitted()
        return self._chain(self.neutral_)

    # -- transform ----------------------------------------------------------------------------

    def segment_orientations(self, sensors) -> np.ndarray:
        """Segment orientations (N, 4, 4) relative to the root sensor's world, rig frames.

        Parameters
        ----------
        sensors : (N, 4, 4) array_like
            Sensor-relative-to-world orientations of the four segments, proximal to distal.
        """
        self._check_fitted()
        q = _check_sensors(sensors, "sensors", len(self.segments_))
        h = _rz(np.radians(self.headings_deg_))
        return Q.multiply(Q.multiply(h, q), Q.conjugate(self.mounts_))

    def transform(self, sensors) -> np.ndarray:
        """Joint orientations (N, 3, 4), child relative to parent, rig segment frames.

        Parameters
        ----------
        sensors : (N, 4, 4) array_like
            Sensor-relative-to-world orientations of the four segments, proximal to distal.
        """
        s = self.segment_orientations(sensors)
        return Q.multiply(Q.conjugate(s[:, :-1]), s[:, 1:])

    def joints(self, sensors) -> dict[str, np.ndarray]:
        """:meth:`transform` per joint: ``{joint: (N, 4)}`` (e.g. for
        :func:`calibration.joint_angles.joint_angles`)."""
        q = self.transform(sensors)
        return {joint: q[:, j] for j, joint in enumerate(self.joints_)}

    # -- records ------------------------------------------------------------------------------

    def to_dict(self) -> dict:
        """Plain-type summary (for the store's calibration record)."""
        self._check_fitted()
        return {
            "kind": "imu-limb",
            "limb": self.limb,
            "side": self.side,
            "segments": list(self.segments_),
            "mounts": [[float(v) for v in m] for m in self.mounts_],
            "headings_deg": [float(v) for v in self.headings_deg_],
            "flipped": list(self.flipped_),
            "residuals_deg": {name: {k: float(v) for k, v in r.items()}
                              for name, r in self.residuals_.items()},
            "residual_deg": float(self.residual_deg_),
        }

    @classmethod
    def from_dict(cls, data: dict) -> LimbImuCalibration:
        """Rebuild a fitted calibration from :meth:`to_dict` output (plus the recorder's
        ``protocol`` and ``windows_s`` entries, which are ignored); other keys are errors."""
        known = {"kind", "limb", "side", "segments", "mounts", "headings_deg", "flipped",
                 "residuals_deg", "residual_deg", "protocol", "windows_s"}
        unknown = set(data) - known
        if unknown:
            raise CalibrationError(f"calibration record: unknown key(s) {sorted(unknown)}")
        if data.get("kind", "imu-limb") != "imu-limb":
            raise CalibrationError(f"calibration record: kind {data['kind']!r} is not imu-limb")
        try:
            self = cls(data["limb"], data["side"])
            self._setup()
            if list(data.get("segments", self.segments_)) != list(self.segments_):
                raise CalibrationError(f"calibration record: segments {data['segments']} are "
                                       f"not the {self.limb}'s {list(self.segments_)}")
            mounts = np.asarray(data["mounts"], dtype=np.float64)
            headings = np.asarray(data["headings_deg"], dtype=np.float64)
        except KeyError as err:
            raise CalibrationError(f"calibration record: missing {err.args[0]!r}") from err
        except (TypeError, ValueError) as err:
            raise CalibrationError(f"calibration record: {err}") from err
        n = len(self.segments_)
        if mounts.shape != (n, 4) or headings.shape != (n,):
            raise CalibrationError(f"calibration record: expected {n} mounts of 4 and {n} "
                                   f"headings, got {mounts.shape} and {headings.shape}")
        self.mounts_ = Q.check_quaternions(mounts, name="mounts")
        self.headings_deg_ = headings
        self.flipped_ = tuple(data.get("flipped", ()))
        self.residuals_ = {k: dict(v) for k, v in data.get("residuals_deg", {}).items()}
        self.residual_deg_ = float(data.get("residual_deg", math.nan))
        self.lean_deg_ = None
        return self

    def _check_fitted(self) -> None:
        if not hasattr(self, "mounts_"):
            raise CalibrationError("calibration is not fitted: call fit() first")
