"""Clinical range of motion of the shoulder: ISB humerus-thorax angles, peaks, normative values.

Frames
------
The rig's segment frames (thorax and humerus alike, :mod:`calibration.alignment`): +X inferior
(the limb long axis, pointing distally with the arm at the side), +Y anterior, +Z = X × Y, to
the body's right. The ISB frames (Wu et al. 2005, *J Biomech* 38:981, thorax §2.3.1, humerus
option 1 §2.3.4): +Y superior (humerus: from the elbow towards the glenohumeral centre), +X
anterior, +Z to the right (lateral for a right arm). Hence, for both segments,

    X_rig = −Y_isb,   Y_rig = X_isb,   Z_rig = Z_isb,      R_isb = M R_rig Mᵀ,
    M = [[0, 1, 0], [−1, 0, 0], [0, 0, 1]]  (columns: rig axes in ISB coordinates).

**Left arms** are mirrored through the sagittal plane before anything else (Wu et al. 2005 §2:
left-side data are mirrored so that one set of definitions serves both sides): ``Z → −Z``,
which maps a quaternion ``(w, x, y, z) → (w, −x, −y, z)`` (rig and ISB alike) and a direction
``(x, y, z) → (x, y, −z)``. After mirroring, +Z is lateral for either arm.

Angles (:func:`isb_angles`)
---------------------------
Humerus relative to thorax, Y-X'-Y'' intrinsic (Wu et al. 2005 §3.3):
``R = Ry(α) Rx(β) Ry(γ)``, **plane of elevation** ``α`` (0° = abduction in the coronal plane,
90° = forward flexion), **elevation** ``−β`` (0° arm at the side, 90° horizontal), **axial
rotation** ``γ`` (internal rotation positive). The sequence is gimbal-locked with the arm at the
side (``β → 0``: ``α`` and ``γ`` both turn about Y), where ``α`` is undefined and ``α + γ`` alone
is determined. Following the literature's recommendation for arm positions near the side
(Šenk & Chèze 2006, *Clin Biomech* 21 Suppl 1:S3; Phadke et al. 2011, *J Orthop Sports Phys
Ther* 41:8), axial rotation is taken from the **X-Z'-Y''** sequence (``R = Rx Rz Ry(γ')``,
axial rotation about the humeral long axis last) whenever the elevation is below
``switch_deg`` (default 30°); above it, from Y-X'-Y''. The reported ``sequence`` column says
which was used per sample; with the arm at the side both agree with the twist about the long
axis. The plane of elevation is reported as NaN below 5° of elevation.

Peaks (:func:`range_of_motion`)
--------------------------------
From a swing-twist constraint (an extracted boundary, or the ground truth in tests): the extent
of the swing region along great circles from the arm-at-the-side direction (ISB −Y), i.e. the
clinical planar movements measured as with a goniometer:

- **flexion** / **extension**: along the sagittal plane, anteriorly / posteriorly;
- **abduction** / **adduction**: along the coronal plane, laterally / medially (adduction past
  neutral, in front of the body);
- **horizontal adduction**: along the horizontal plane at 90° elevation, from straight ahead
  towards medial (None when straight ahead at 90° is outside the range);
- **internal / external rotation**: the twist limits about the long axis with the arm at the
  side (the ``by_swing`` limits at that direction when the constraint has them). Note that the
  AAOS values are measured with the arm abducted 90°; the arm-at-the-side values are what every
  patient can perform, and the row says so.

The extent along a great circle is the first angle at which the circle leaves the region
(sampled every 0.05°, then bisected), so a concave notch ends it where the patient stops.

Normative values (:data:`NORMATIVE`)
------------------------------------
- AAOS (American Academy of Orthopaedic Surgeons, *Joint motion: method of measuring and
  recording*, 1965; the values as quoted by Gill H et al. 2006, *Br J Occup Ther* 69:556):
  flexion 180°, extension 60°, abduction 180°, internal rotation 70°, external rotation 90°.
- Gill TK, Shanahan EM, Tucker GR, Buchbinder R, Hill CL. Shoulder range of movement in the
  general population: age and gender stratified normative data using a community-based cohort.
  *BMC Musculoskelet Disord* 2020;21:676 (doi:10.1186/s12891-020-03665-9): active right-shoulder
  range, 2404 adults aged 20-91, Plurimeter V inclinometer. Means by sex (abstract): flexion
  161.5° (men) / 158.5° (women), abduction 151.5° / 149.7°. Medians by 5-year age band for
  abduction and external rotation (arm at the side) as tabulated from the same data set.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from models import quaternion as Q
from models.constraint import JointConstraint

__all__ = [
    "NORMATIVE",
    "RIG_TO_ISB",
    "RangeOfMotion",
    "format_rom_table",
    "isb_angles",
    "mirror_directions",
    "mirror_quaternions",
    "normative_band",
    "range_of_motion",
    "to_isb",
]

#: Columns: the rig's X, Y, Z axes in ISB coordinates (see module doc).
RIG_TO_ISB = np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])

_DOWN = np.array([1.0, 0.0, 0.0])  # rig: arm at the side
_ANTERIOR = np.array([0.0, 1.0, 0.0])
_LATERAL = np.array([0.0, 0.0, 1.0])  # after mirroring a left arm


def _check_side(side: str) -> str:
    if side not in ("right", "left"):
        raise ValueError(f"side must be 'right' or 'left', got {side!r}")
    return side


def mirror_quaternions(q) -> np.ndarray:
    """Reflect orientations through the sagittal (X-Y) plane: ``(w, x, y, z) → (w, −x, −y, z)``."""
    out = np.array(q, dtype=np.float64, copy=True)
    out[..., 1:3] *= -1.0
    return out


def mirror_directions(d) -> np.ndarray:
    """Reflect directions through the sagittal plane: ``(x, y, z) → (x, y, −z)``."""
    out = np.array(d, dtype=np.float64, copy=True)
    out[..., 2] *= -1.0
    return out


def to_isb(q, side: str = "right"):
    """scipy Rotation of joint orientations (N, 4) in ISB frames (left arms mirrored)."""
    from scipy.spatial.transform import Rotation

    q = Q.check_quaternions(q, normalize=True, name="joint orientation")
    if _check_side(side) == "left":
        q = mirror_quaternions(q)
    m = RIG_TO_ISB
    return Rotation.from_matrix(m @ Q.to_rotation(q).as_matrix() @ m.T)


def isb_angles(q, side: str = "right", *, switch_deg: float = 30.0) -> dict[str, np.ndarray]:
    """ISB humerus-thorax angles (degrees) of joint orientations (see module doc).

    Parameters
    ----------
    q : (N, 4) or (4,) array_like
        Joint orientations, humerus relative to thorax, rig frames, scalar-first.
    side : "right" or "left"
    switch_deg : float
        Below this elevation, axial rotation comes from the X-Z'-Y'' sequence.

    Returns
    -------
    dict of (N,) float64 arrays: ``plane_of_elevation`` (NaN below 5° elevation),
    ``elevation``, ``axial_rotation`` (internal positive, switch rule applied),
    ``axial_rotation_yxy`` (raw third Y-X'-Y'' angle), and ``sequence`` (0 = YXY, 1 = XZY).
    """
    import warnings

    r = to_isb(np.atleast_2d(q), side)
    with warnings.catch_warnings():  # the YXY gimbal lock at the side is handled below
        warnings.simplefilter("ignore", UserWarning)
        yxy = np.degrees(r.as_euler("YXY"))
    xzy = np.degrees(r.as_euler("XZY"))
    elevation = -yxy[:, 1]
    plane = yxy[:, 0].copy()
    axial = yxy[:, 2].copy()
    # as_euler returns β in [0, π] for proper sequences; fold to elevation ≥ 0 with β ≤ 0
    flip = elevation < 0
    if flip.any():
        # R = Ry(α) Rx(β) Ry(γ) = Ry(α+π) Rx(−β) Ry(γ+π)
        elevation[flip] = -elevation[flip]
        plane[flip] = plane[flip] + 180.0
        axial[flip] = axial[flip] + 180.0
    plane = (plane + 180.0) % 360.0 - 180.0
    axial = (axial + 180.0) % 360.0 - 180.0
    raw = axial.copy()
    low = elevation < switch_deg
    axial[low] = xzy[low, 2]
    plane[elevation < 5.0] = np.nan
    return {
        "plane_of_elevation": plane,
        "elevation": elevation,
        "axial_rotation": axial,
        "axial_rotation_yxy": raw,
        "sequence": low.astype(np.int64),
    }


# -- peaks from a constraint --------------------------------------------------------------------
def _swing_distance_fn(constraint: JointConstraint):
    from models.oracle import ConstraintOracle

    if constraint.swing is None:
        return lambda d: np.full(len(d), -1.0)
    swing_only = JointConstraint.from_dict(
        {"name": "swing", "limb_axis": [float(x) for x in constraint.limb_axis],
         "swing": constraint.swing.to_dict()})
    oracle = ConstraintOracle(swing_only)
    return oracle.swing_distance


def _extent(dist, start: np.ndarray, toward: np.ndarray, limit_deg: float = 180.0):
    """First angle (deg) at which the great circle start → toward leaves the region, or
    ``limit_deg``; None when ``start`` itself is outside."""
    if dist(start[None, :])[0] > 0:
        return None
    theta = np.radians(np.arange(0.0, limit_deg + 1e-9, 0.05))
    pts = np.cos(theta)[:, None] * start + np.sin(theta)[:, None] * toward
    out = dist(pts) > 0
    if not out.any():
        return float(limit_deg)
    k = int(np.argmax(out))
    lo, hi = theta[k - 1], theta[k]
    for _ in range(30):
        mid = 0.5 * (lo + hi)
        p = math.cos(mid) * start + math.sin(mid) * toward
        if dist(p[None, :])[0] > 0:
            hi = mid
        else:
            lo = mid
    return math.degrees(0.5 * (lo + hi))


@dataclass(frozen=True)
class RangeOfMotion:
    """Peak clinical angles (degrees; None where the movement is not possible from neutral)."""

    side: str
    flexion: float | None
    extension: float | None
    abduction: float | None
    adduction: float | None
    horizontal_adduction: float | None
    internal_rotation: float | None
    external_rotation: float | None

    MOVEMENTS = ("flexion", "extension", "abduction", "adduction", "horizontal_adduction",
                 "internal_rotation", "external_rotation")

    def to_dict(self) -> dict[str, Any]:
        return {"side": self.side, **{m: getattr(self, m) for m in self.MOVEMENTS}}


def range_of_motion(constraint: JointConstraint, side: str = "right") -> RangeOfMotion:
    """Clinical peaks of a shoulder constraint (rig frames; see module doc for definitions).

    Parameters
    ----------
    constraint : JointConstraint
        Swing region (limb directions, thorax frame) and twist limits of the humerus.
    side : "right" or "left"
        The arm the constraint belongs to; a left arm is mirrored first.
    """
    _check_side(side)
    dist0 = _swing_distance_fn(constraint)
    if side == "left":
        def dist(p):
            return dist0(mirror_directions(p))
    else:
        dist = dist0
    flex = _extent(dist, _DOWN, _ANTERIOR)
    ext = _extent(dist, _DOWN, -_ANTERIOR)
    abd = _extent(dist, _DOWN, _LATERAL)
    add = _extent(dist, _DOWN, -_LATERAL)
    hadd = _extent(dist, _ANTERIOR, -_LATERAL, limit_deg=180.0)
    ir = er = None
    tw = constraint.twist
    if tw is not None:
        down = _DOWN if side == "right" else mirror_directions(_DOWN)
        if hasattr(tw, "limits_at"):
            lo, hi = tw.limits_at(down[None, :])
            lo, hi = math.degrees(float(np.ravel(lo)[0])), math.degrees(float(np.ravel(hi)[0]))
        else:  # pragma: no cover - older constraint API
            lo, hi = tw.min_deg, tw.max_deg
        # twist φ about the distal long axis (+X_rig = −Y_isb): φ > 0 is external rotation of
        # a right arm (ISB internal rotation is positive about +Y); mirrored for a left arm
        if side == "right":
            er, ir = hi, -lo
        else:
            er, ir = -lo, hi
    return RangeOfMotion(side, flex, ext, abd, add, hadd, ir, er)


# -- normative values ---------------------------------------------------------------------------
_AAOS = "AAOS 1965 (as quoted by Gill H et al. 2006)"
_GILL = "Gill TK et al. 2020, BMC Musculoskelet Disord 21:676"

#: Normative values (degrees). ``aaos``: movement → value; ``gill2020_mean``: movement → sex →
#: mean; ``gill2020_band_median``: movement → sex → list of (age_lo, age_hi, median).
NORMATIVE: dict[str, Any] = {
    "sources": {"aaos": _AAOS, "gill2020": _GILL},
    "aaos": {"flexion": 180.0, "extension": 60.0, "abduction": 180.0,
             "internal_rotation": 70.0, "external_rotation": 90.0},
    "gill2020_mean": {
        "flexion": {"male": 161.5, "female": 158.5},
        "abduction": {"male": 151.5, "female": 149.7},
    },
    "gill2020_band_median": {
        "abduction": {
            "male": [(20, 24, 164.0), (25, 29, 160.0), (30, 34, 160.0), (35, 39, 160.0),
                     (40, 44, 158.0), (45, 49, 156.0), (50, 54, 160.0), (55, 59, 150.0),
                     (60, 64, 148.0), (65, 69, 142.0), (70, 74, 141.3), (75, 79, 140.0),
                     (80, 84, 132.0)],
            "female": [(20, 24, 160.0), (25, 29, 158.4), (30, 34, 156.0), (35, 39, 160.0),
                       (40, 44, 158.0), (45, 49, 152.0), (50, 54, 154.0), (55, 59, 150.0),
                       (60, 64, 142.0), (65, 69, 144.0), (70, 74, 141.8), (75, 79, 140.0),
                       (80, 84, 124.5)],
        },
        "external_rotation": {
            "male": [(20, 24, 65.0), (25, 29, 65.0), (30, 34, 60.0), (35, 39, 55.0),
                     (40, 44, 50.0), (45, 49, 50.0), (50, 54, 56.3), (55, 59, 50.0),
                     (60, 64, 50.0), (65, 69, 50.0), (70, 74, 50.0), (75, 79, 45.0),
                     (80, 84, 50.0)],
            "female": [(20, 24, 80.0), (25, 29, 75.0), (30, 34, 70.0), (35, 39, 65.0),
                       (40, 44, 55.0), (45, 49, 50.0), (50, 54, 60.0), (55, 59, 51.2),
                       (60, 64, 55.0), (65, 69, 55.0), (70, 74, 53.5), (75, 79, 50.0),
                       (80, 84, 50.0)],
        },
    },
}


def normative_band(movement: str, *, age: int | None = None, sex: str | None = None):
    """Population reference for one movement: the Gill 2020 age/sex-band median when age and
    sex are given and tabulated, else the Gill 2020 sex mean, else None."""
    if sex is not None and sex not in ("male", "female"):
        raise ValueError(f"sex must be 'male' or 'female', got {sex!r}")
    bands = NORMATIVE["gill2020_band_median"].get(movement)
    if bands is not None and age is not None and sex is not None:
        for lo, hi, med in bands[sex]:
            if lo <= age <= hi:
                return med
        last = bands[sex][-1]
        if age > last[1]:
            return last[2]
    means = NORMATIVE["gill2020_mean"].get(movement)
    if means is not None and sex is not None:
        return means[sex]
    return None


_LABELS = {
    "flexion": "flexion", "extension": "extension", "abduction": "abduction",
    "adduction": "adduction", "horizontal_adduction": "horizontal adduction",
    "internal_rotation": "internal rotation (arm at side)",
    "external_rotation": "external rotation (arm at side)",
}


def format_rom_table(rom: RangeOfMotion, *, age: int | None = None,
                     sex: str | None = None) -> str:
    """The clinical table as text: movement, measured peak, AAOS, population reference."""
    pop_head = "Gill 2020" + (f" ({sex}, {age})" if sex and age else f" ({sex})" if sex else "")
    rows = [("movement", "measured", "AAOS", pop_head)]
    for m in rom.MOVEMENTS:
        v = getattr(rom, m)
        aaos = NORMATIVE["aaos"].get(m)
        pop = normative_band(m, age=age, sex=sex) if sex else None
        rows.append((
            _LABELS[m],
            "-" if v is None else f"{v:.1f}°",
            "-" if aaos is None else f"{aaos:.0f}°",
            "-" if pop is None else f"{pop:.1f}°",
        ))
    widths = [max(len(r[i]) for r in rows) for i in range(4)]
    lines = [f"shoulder range of motion ({rom.side} arm)"]
    for k, r in enumerate(rows):
        lines.append("  ".join(c.ljust(w) if i == 0 else c.rjust(w)
                               for i, (c, w) in enumerate(zip(r, widths, strict=True))))
        if k == 0:
            lines.append("  ".join("-" * w for w in widths))
    lines.append(f"sources: AAOS = {_AAOS}; population = {_GILL}")
    return "\n".join(lines)
