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
From a swing-twist constraint (an extracted boundary, or the ground truth in tests): how far the
swing region reaches along each clinical plane, read as a goniometer aligned with the trunk
reads a position — the angle from the arm at the side (ISB −Y) *within the plane*, for limb
directions within ``band_deg`` (default 5°, a goniometer's alignment tolerance) of it:

- **flexion** / **extension**: the sagittal plane, anteriorly / posteriorly;
- **abduction** / **adduction**: the coronal plane, laterally / medially (adduction past
  neutral, in front of the body);
- **horizontal adduction**: the horizontal plane at 90° elevation, from straight ahead towards
  medial (the band is then vertical);
- **internal / external rotation**: the twist limits about the long axis with the arm at the
  side (the ``by_swing`` limits at that direction when the constraint has them). Note that the
  AAOS values are measured with the arm abducted 90°; the arm-at-the-side values are what every
  patient can perform, and the row says so.

Each peak is the **farthest** angle along its arc at which the band meets the region — the end
position the patient reached in that plane, whatever path led there (a goniometer reads
positions, not paths), so a sparsely recorded range or a concave notch the patient went round
still gets its figure, and a region that does not contain the arm-at-the-side direction (a
patient who cannot bring the arm to the side, or a recording that never rests there) gets its
flexion, extension, abduction and adduction all the same. The arcs split the plane's great
circle between the two directions of a movement pair: flexion and abduction run from the arm at
the side through horizontal and overhead up to 240° (hyperflexion past vertical counts as
flexion), extension and adduction the remaining 120° on the other side (no shoulder extends or
adducts that far; an arm overhead is never counted as extension). None where the band never
meets the region. Horizontal adduction runs from straight ahead to straight behind (180°).
Angles are found on a 0.5° grid along the arc and ±``band_deg`` across it in 0.5° steps, then
refined about the farthest hit (a 0.02° grid, then bisection).

**With the recording.** Given the recorded limb directions too, each swing peak is the smaller
of two readings, each free of one bias: the region's (above) and the recording's own — the
farthest recorded direction within the band, at its in-plane angle. The region holds every
recorded direction, so where the recording is clean the recording's reading is the smaller: the
region's filling between recorded excursions (its alpha shape) is interpolation, not a position
the patient was seen in. Where the recording is noisy the region's is the smaller: its envelope
was moved in by the measured noise, while the outermost samples carry it. A movement with no
recorded direction in its band is None (not recorded in that plane).

``neutral_outside_deg`` says how far outside the region the arm-at-the-side direction lies (0
when inside): the rotations are then the twist limits at a position the recording did not
reach, and the table says so.

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

from calibration.frames import RIG_TO_ISB
from calibration.norms import JOINT_MOVEMENTS, NORMS, norm_band, norm_text
from models import quaternion as Q
from models.constraint import JointConstraint
from models.oracle import ConstraintOracle

__all__ = [
    "AAOS_NOT_COMPARABLE",
    "NORMATIVE",
    "RIG_TO_ISB",
    "RangeOfMotion",
    "check_side",
    "format_rom_table",
    "isb_angles",
    "mirror_directions",
    "mirror_quaternions",
    "normative_band",
    "population_reference",
    "range_of_motion",
    "to_isb",
]


_DOWN = np.array([1.0, 0.0, 0.0])  # rig: arm at the side
_ANTERIOR = np.array([0.0, 1.0, 0.0])
_LATERAL = np.array([0.0, 0.0, 1.0])  # after mirroring a left arm


def check_side(side: str) -> str:
    """``side`` itself when it is ``"right"`` or ``"left"``; ValueError naming both otherwise."""
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
    if check_side(side) == "left":
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

    if constraint.swing is None:
        return lambda d: np.full(len(d), -1.0)
    swing_only = JointConstraint.from_dict(
        {"name": "swing", "limb_axis": [float(x) for x in constraint.limb_axis],
         "swing": constraint.swing.to_dict()})
    oracle = ConstraintOracle(swing_only)
    return oracle.swing_distance


def _reach(dist, down: np.ndarray, toward: np.ndarray, across: np.ndarray, limit_deg: float,
           band_deg: float) -> float | None:
    """Farthest angle (deg, in-plane) along the arc ``down → toward`` (up to ``limit_deg``) at
    which a direction within ``band_deg`` of the plane (offset along ``across``) is inside the
    region (``dist <= 0``); None when none is (see the module doc)."""
    offsets = np.radians(np.arange(-band_deg, band_deg + 1e-9, 0.5)) if band_deg > 0 \
        else np.zeros(1)

    def hit(theta_deg: np.ndarray) -> np.ndarray:
        th = np.radians(theta_deg)[:, None]
        inplane = np.cos(th)[..., None] * down + np.sin(th)[..., None] * toward  # (T, 1, 3)
        pts = (np.cos(offsets)[None, :, None] * inplane
               + np.sin(offsets)[None, :, None] * across)  # (T, F, 3)
        return (dist(pts.reshape(-1, 3)) <= 0.0).reshape(len(th), -1).any(axis=1)

    coarse = np.arange(0.0, limit_deg + 1e-9, 0.5)
    inside = hit(coarse)
    if not inside.any():
        return None
    k = int(np.flatnonzero(inside)[-1])
    if k == len(coarse) - 1:
        return float(limit_deg)
    fine = np.arange(coarse[k], coarse[k + 1] + 1e-9, 0.02)
    j = int(np.flatnonzero(hit(fine))[-1])
    lo, hi = fine[j], fine[min(j + 1, len(fine) - 1)]
    for _ in range(12):  # to ~5e-6°
        mid = 0.5 * (lo + hi)
        if hit(np.array([mid]))[0]:
            lo = mid
        else:
            hi = mid
    return float(lo)


def _recorded_reach(d: np.ndarray, down: np.ndarray, toward: np.ndarray, across: np.ndarray,
                    limit_deg: float, band_deg: float) -> float | None:
    """Farthest in-plane angle (deg) along the arc ``down → toward`` (up to ``limit_deg``) of
    the directions ``d`` (N, 3) within ``band_deg`` of the plane; None when there is none."""
    near = np.abs(d @ across) <= math.sin(math.radians(band_deg))
    if not near.any():
        return None
    psi = np.degrees(np.arctan2(d[near] @ toward, d[near] @ down)) % 360.0
    psi = psi[psi <= limit_deg]
    return float(psi.max()) if len(psi) else None


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
    neutral_outside_deg: float = 0.0
    """How far the arm-at-the-side direction lies outside the swing region (0 when inside):
    when > 0, the swing peaks are where the range ends along each clinical plane (module doc)
    and the rotations are the twist limits there, a position the patient did not reach."""

    MOVEMENTS = JOINT_MOVEMENTS["shoulder"]

    def to_dict(self) -> dict[str, Any]:
        return {"side": self.side, **{m: getattr(self, m) for m in self.MOVEMENTS}}


def range_of_motion(constraint: JointConstraint, side: str = "right", *,
                    band_deg: float = 5.0, directions=None) -> RangeOfMotion:
    """Clinical peaks of a shoulder constraint (rig frames; see module doc for definitions).

    Parameters
    ----------
    constraint : JointConstraint
        Swing region (limb directions, thorax frame) and twist limits of the humerus.
    side : "right" or "left"
        The arm the constraint belongs to; a left arm is mirrored first.
    band_deg : float
        Half-width of the band about each clinical plane whose directions count, degrees.
    directions : (N, 3) array_like, optional
        The recorded limb directions (thorax frame, rig axes, not mirrored): each swing peak is
        then the smaller of the region's reading and the recording's (module doc).
    """
    if not 0.0 <= band_deg <= 30.0:
        raise ValueError(f"band_deg must be in [0, 30], got {band_deg!r}")
    check_side(side)
    dist0 = _swing_distance_fn(constraint)
    if side == "left":
        def dist(p):
            return dist0(mirror_directions(p))
    else:
        dist = dist0
    gap = max(0.0, math.degrees(float(dist(_DOWN[None, :])[0])))
    rec = None
    if directions is not None:
        rec = Q.check_vectors(directions, name="directions").reshape(-1, 3)
        if side == "left":
            rec = mirror_directions(rec)
    peaks = []
    for args in ((_DOWN, _ANTERIOR, _LATERAL, 240.0), (_DOWN, -_ANTERIOR, _LATERAL, 120.0),
                 (_DOWN, _LATERAL, _ANTERIOR, 240.0), (_DOWN, -_LATERAL, _ANTERIOR, 120.0),
                 (_ANTERIOR, -_LATERAL, _DOWN, 180.0)):
        v = _reach(dist, *args, band_deg)
        if rec is not None and v is not None:
            r = _recorded_reach(rec, *args, band_deg)
            v = None if r is None else min(v, r)
        peaks.append(v)
    flex, ext, abd, add, hadd = peaks
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
    return RangeOfMotion(side, flex, ext, abd, add, hadd, ir, er, gap)


# -- normative values ---------------------------------------------------------------------------
_AAOS = "AAOS 1965 (as quoted by Gill H et al. 2006)"
_GILL = "Gill TK et al. 2020, BMC Musculoskelet Disord 21:676"

def _gill() -> tuple[dict, dict]:
    """Gill 2020's sex means and 5-year band medians from the norms table
    (:data:`calibration.norms.NORMS`), in the shapes of :data:`NORMATIVE`."""
    means: dict = {}
    bands: dict = {}
    for n in NORMS.rows:
        if n.joint != "shoulder" or n.source.key != "gill2020":
            continue
        if n.overall:
            means.setdefault(n.movement, {})[n.sex] = n.value
        else:
            bands.setdefault(n.movement, {}).setdefault(n.sex, []).append(
                (n.age_lo, n.age_hi, n.value))
    for by_sex in bands.values():
        for rows in by_sex.values():
            rows.sort()
    return means, bands


#: Normative values (degrees). ``aaos``: movement → value; ``gill2020_mean``: movement → sex →
#: mean; ``gill2020_band_median``: movement → sex → list of (age_lo, age_hi, median). The Gill
#: 2020 values come from the norms table, calibration/norms.yaml.
NORMATIVE: dict[str, Any] = {
    "sources": {"aaos": _AAOS, "gill2020": _GILL},
    "aaos": {"flexion": 180.0, "extension": 60.0, "abduction": 180.0,
             "internal_rotation": 70.0, "external_rotation": 90.0},
}
NORMATIVE["gill2020_mean"], NORMATIVE["gill2020_band_median"] = _gill()


def _gill_band(movement: str, age, sex: str | None):
    """Gill 2020's values for a patient (:func:`calibration.norms.norm_band`): per sex, the
    band median at ``age`` (past the oldest band, the oldest), else the sex mean; no band of
    an unknown age."""
    if sex is not None and sex not in ("male", "female"):
        raise ValueError(f"sex must be 'male' or 'female', got {sex!r}")
    if movement not in RangeOfMotion.MOVEMENTS:
        return []
    return norm_band("shoulder", movement, age=age, sex=sex, sources=("gill2020",),
                     unknown_age=None)


def normative_band(movement: str, *, age: int | None = None, sex: str | None = None):
    """Population reference for one movement: the Gill 2020 age/sex-band median when age and
    sex are given and tabulated, else the Gill 2020 sex mean, else None."""
    if sex is None:
        return None
    got = _gill_band(movement, age, sex)
    return got[0].value if got else None


#: Movements whose AAOS value was measured in another position than ours (rotations: AAOS at
#: 90° abduction, the rig's peaks with the arm at the side): shown, never compared.
AAOS_NOT_COMPARABLE = {"internal_rotation": "AAOS measures it at 90° abduction",
                       "external_rotation": "AAOS measures it at 90° abduction"}


def population_reference(movement: str, *, age: int | None = None,
                         sex: str | None = None) -> str | None:
    """The population reference of one movement as text (Gill et al. 2020): the median of the
    patient's 5-year age band and sex when both are known, e.g. ``"152 (women, 45-49)"``; with
    one of them unknown, women and men apart (band medians at that age, else the sex means,
    ``"158 (women, all ages) / 162 (men, all ages)"``); None when not tabulated."""
    got = _gill_band(movement, age, sex)
    if len(got) != (1 if sex is not None else 2):
        return None
    return norm_text(got)


_LABELS = {
    "flexion": "flexion", "extension": "extension", "abduction": "abduction",
    "adduction": "adduction", "horizontal_adduction": "horizontal adduction",
    "internal_rotation": "internal rotation (arm at side)",
    "external_rotation": "external rotation (arm at side)",
}


def text_table(rows: list[tuple[str, ...]]) -> list[str]:
    """Lines of a plain-text table: the first row a header underlined with dashes, the first
    column left-aligned, the others right-aligned."""
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    lines = []
    for k, r in enumerate(rows):
        lines.append("  ".join(c.ljust(w) if i == 0 else c.rjust(w)
                               for i, (c, w) in enumerate(zip(r, widths, strict=True))))
        if k == 0:
            lines.append("  ".join("-" * w for w in widths))
    return lines


def format_rom_table(rom: RangeOfMotion, *, age: int | None = None,
                     sex: str | None = None) -> str:
    """The clinical table as text: movement, measured peak, AAOS, population reference (the
    age band and sex when known, women and men apart otherwise; :func:`population_reference`).
    AAOS values measured in another position (:data:`AAOS_NOT_COMPARABLE`) are not shown."""
    who = ", ".join(x for x in ({"female": "women", "male": "men"}.get(sex or ""),
                                None if age is None else f"age {age}") if x)
    pop_head = "Gill 2020" + (f" ({who})" if who else "")
    rows = [("movement", "measured", "AAOS", pop_head)]
    for m in rom.MOVEMENTS:
        v = getattr(rom, m)
        aaos = None if m in AAOS_NOT_COMPARABLE else NORMATIVE["aaos"].get(m)
        pop = population_reference(m, age=age, sex=sex)
        rows.append((
            _LABELS[m],
            "-" if v is None else f"{v:.1f}°",
            "-" if aaos is None else f"{aaos:.0f}°",
            "-" if pop is None else pop,
        ))
    lines = [f"shoulder range of motion ({rom.side} arm)", *text_table(rows)]
    if rom.neutral_outside_deg > 0:
        lines.append(f"note: the arm at the side is {rom.neutral_outside_deg:.1f}° outside the "
                     "recorded range: the rotations at the side were not recorded (the twist "
                     "limits there are shown)")
    lines.append("note: AAOS measures the rotations at 90° abduction, these are with the arm at "
                 "the side (not comparable)")
    lines.append(f"sources: AAOS = {_AAOS}; population = {_GILL}")
    return "\n".join(lines)
