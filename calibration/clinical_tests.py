"""The coupled clinical tests clinicians know, read from a limb's limits and a recording.

A limb file's couplings (``docs/limb-format.md``: one joint's limits at keyframes of another
joint's angle) are what the two-joint-muscle tests measure. Each test here holds the other
joint at the test's position, puts the measured joint's other clinical angles at zero, and
reads the measured angle (ISB / Grood-Suntay, :mod:`calibration.joint_angles`; the shoulder's
sagittal-plane angle as :mod:`calibration.clinical` reads it) as a goniometer reads a position:

==========================  =========================  ====================================
measure (:data:`MEASURES`)  angle read                 the other joint
==========================  =========================  ====================================
``straight_leg_raise``      hip flexion, farthest      knee at 0° (straight)
``popliteal_angle``         knee flexion, least        hip at 90° flexion
``silfverskiold_straight``  ankle dorsiflexion         knee at 0°
``silfverskiold_bent``      ankle dorsiflexion         knee at 90°
``thomas_hip``              hip extension, farthest    knee at 90° (the modified Thomas
                                                       test's hanging leg)
``thomas_knee``             knee flexion, farthest     hip at 0° (thigh level with the table)
``shoulder_flexion_*``      shoulder flexion           elbow at 0° (straight) / 90° (bent)
``shoulder_extension_*``    shoulder extension         elbow at 0° / 90°
==========================  =========================  ====================================

**From the limits** (:func:`limits_value`): the limb's own oracle
(:meth:`models.oracle.ConstraintOracle.evaluate_joint`) answers whether the measured joint's
posture is within its limits with the other joint's coupling angle at the test position
(clinical angle → the source's coupling angle by its kind, clamped into the source's range
as the limb oracle judges a coupled joint at the corrected source angle). The angle is scanned
on a 0.5° grid and refined on a 0.01° grid about the farthest (or, for the popliteal angle, the
least) angle within the limits. A test whose other joint is scanned (the popliteal angle, the
Thomas test's knee) requires both joints within their limits. Where the measured joint is not
coupled to the other, the uncoupled limits answer and the measure says so.

**From a recording** (postures ``(N, J, 4)``): the samples whose other joint lies within
``tolerance_deg`` (default :data:`TOLERANCE_DEG`, 10°: a clinician's "knee straight" or
"hip at 90°" position as a goniometer reads it) of the test position; the farthest (least)
reading of the measured angle among them, after the running median of
:func:`calibration.joint_angles.recorded_rom` (5 samples). A swing joint's samples must lie
within :data:`BAND_DEG` (5°) of the movement's plane as well (β, the ab/adduction or
inversion; the shoulder's sagittal plane, :func:`calibration.clinical.range_of_motion`'s
band); the limits are read in the plane itself.
**No sample at the test position: "not reached in this recording"** — the value is then None
even when limits are given (their limits there are interpolation or a clamped keyframe, not a
position the patient was seen in). **Limits that do not couple the two joints, with a
recording**: the value is the recording's reading (status ``"recording"``, no verdict), not
the limits' — uncoupled limits hold the joint's range at every angle of the other joint (a
limb file extracted from a recording that showed no coupling), which no test position
restricts; ``from_limits`` still gives it. A recording of free movement (walking, dancing) is
not the passive end-range test: its reading is the farthest the patient went there, a lower bound,
and no verdict is drawn from it alone.

Thresholds and norms (:data:`REFERENCES`)
------------------------------------------
- Passive knee extension (popliteal angle): knee angle > 40° with the hip at 90° = short
  hamstrings; passive ankle dorsiflexion: < 18° with the knee at 0° and > 18° at 90° = short
  gastrocnemius, < 18° at both = short soleus, > 18° at both = good triceps surae flexibility;
  modified Thomas test: hip angle > 0° (the thigh above the table: no hip extension) = short
  one-joint hip flexors, knee angle < 67° = short two-joint hip flexors. BMC Sports Science,
  Medicine and Rehabilitation 2021, doi:10.1186/s13102-021-00242-y, Table 4.
- Standard errors of measurement of the Thomas test by goniometer: the knee angle (rectus
  femoris) 7° — Peeler JD, Anderson JE. Reliability limits of the modified Thomas test for
  assessing rectus femoris muscle flexibility about the knee joint. J Athl Train
  2008;43(5):470-476, doi:10.4085/1062-6050-43.5.470 (54 adults aged 18-45, three athletic
  therapists); the hip angle 11° — Peeler J, Anderson JE. Reliability of the Thomas test for
  assessing range of motion about the hip. Phys Ther Sport 2007;8:14-21 (54 adults aged
  18-45). A
  reading within its SEM of the threshold is called borderline.
- Straight-leg raise: 61° ± 6.7° (passive, pelvis and opposite thigh strapped) and passive
  knee extension at 90° hip flexion 31° ± 7.5°, 30 healthy men (Comparison of four clinical
  tests for assessing hamstring muscle length, J Orthop Sports Phys Ther 1993;18(5):614-618,
  doi:10.2519/jospt.1993.18.5.614): a norm, not a threshold.
- The shoulder: full elbow flexion limits shoulder flexion (triceps' long head) and full elbow
  extension limits shoulder extension (biceps' long head), measured on 30 men from lateral
  photographs ("Passive insufficiency of two-joint shoulder muscles", abstract read at
  discovery.researcher.life; its authors and journal not verified here); no published
  threshold was found:
  the AAOS 1965 values (flexion 180°, extension 60°, :data:`calibration.clinical.NORMATIVE`)
  are shown as the norm.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from calibration.clinical import NORMATIVE as SHOULDER_NORMS
from calibration.clinical import check_side, mirror_quaternions, text_table
from calibration.joint_angles import JOINT_ANGLES, from_angles, joint_angles
from calibration.joints import JOINTS
from calibration.kinds import calibration_kind
from models import quaternion as Q
from models.kinds import get_kind
from models.limb import Limb
from models.oracle import ConstraintOracle

__all__ = ["BAND_DEG", "MEASURES", "REFERENCES", "TOLERANCE_DEG", "CoupledMeasure", "MeasureSpec",
           "coupled_measures", "format_coupled_tests", "limits_value", "measure_sources"]

#: How near the other joint must be to the test position (degrees) for a recorded sample to
#: count as "at the test position" (module doc).
TOLERANCE_DEG = 10.0
#: A goniometer's alignment tolerance (degrees): a recording's samples of a swing joint count
#: within this of the movement's plane (out-of-plane angle β; the shoulder: of the sagittal
#: plane), as :func:`calibration.clinical.range_of_motion` reads the shoulder's; the limits
#: are read in the plane itself.
BAND_DEG = 5.0
_WINDOW = 5  # running median over samples, as calibration.joint_angles.recorded_rom
_COARSE_DEG = 0.5
_FINE_DEG = 0.01

_TABLE4 = ("BMC Sports Sci Med Rehabil 2021, doi:10.1186/s13102-021-00242-y, Table 4")
_JOSPT1993 = ("J Orthop Sports Phys Ther 1993;18(5):614-618, doi:10.2519/jospt.1993.18.5.614 "
              "(30 healthy men)")
_JAT2008 = ("Peeler & Anderson, J Athl Train 2008;43(5):470-476 (goniometric SEM of the "
            "modified Thomas test's knee angle, 7°)")
_PTS2007 = ("Peeler & Anderson, Phys Ther Sport 2007;8:14-21 (goniometric SEM of the Thomas "
            "test's hip angle, 11°)")
_SHOULDER_SRC = ("'Passive insufficiency of two-joint shoulder muscles' (30 men, lateral "
                 "photographs; the coupling); norm AAOS 1965")

#: Thresholds, norms and sources per test (module doc).
REFERENCES: dict[str, dict[str, Any]] = {
    "straight_leg_raise": {"norm": "61° ± 6.7° (passive, mean ± SD)", "threshold": None,
                           "source": _JOSPT1993},
    "popliteal_angle": {"norm": "31° ± 7.5° (passive, mean ± SD; " + _JOSPT1993 + ")",
                        "threshold": "> 40° = short hamstrings", "source": _TABLE4},
    "silfverskiold": {"norm": None,
                      "threshold": "< 18° straight, > 18° bent = short gastrocnemius",
                      "source": _TABLE4},
    "thomas_hip": {"norm": None, "threshold": "hip angle > 0° (no extension) = short one-joint "
                   "hip flexors", "source": _TABLE4, "sem_deg": 11.0, "sem_source": _PTS2007},
    "thomas_knee": {"norm": None, "threshold": "knee angle < 67° = short two-joint hip "
                    "flexors", "source": _TABLE4, "sem_deg": 7.0, "sem_source": _JAT2008},
    "shoulder_flexion": {"norm": f"{SHOULDER_NORMS['aaos']['flexion']:g}° (AAOS)",
                         "threshold": None, "source": _SHOULDER_SRC},
    "shoulder_extension": {"norm": f"{SHOULDER_NORMS['aaos']['extension']:g}° (AAOS)",
                           "threshold": None, "source": _SHOULDER_SRC},
}


@dataclass(frozen=True)
class MeasureSpec:
    """One measure: the joint and angle read (``sign`` +1 for the positive clinical movement,
    −1 for its opposite), the other joint and its clinical angle at the test position; which
    of the two is scanned (``scan``: "measured", or "other" for the popliteal angle and the
    Thomas test's knee, whose value is the other joint's angle at a fixed measured posture),
    and whether the value is the farthest (``"max"``) or the least (``"min"``) angle."""

    key: str
    test: str
    label: str
    joint: str
    movement: str
    sign: float
    other: str
    other_deg: float
    reference: str
    scan: str = "measured"
    pick: str = "max"
    fixed_deg: float = 0.0  # scan "other": the measured joint's angle held

    @property
    def definition(self) -> str:
        if self.scan == "other":
            what = ("extension deficit (least flexion)" if self.pick == "min"
                    else "flexion (farthest)")
            return (f"{self.other} {what} with the {self.joint} at {self.fixed_deg:g}° "
                    f"{self.movement}")
        return f"{self.joint} {self.movement} with the {self.other} at {self.other_deg:g}°"

    @property
    def position(self) -> dict[str, Any]:
        """The joint held at the test position and its clinical angle (degrees)."""
        if self.scan == "other":
            return {"joint": self.joint, "movement": self.movement, "deg": self.fixed_deg}
        return {"joint": self.other, "movement": "flexion", "deg": self.other_deg}

    @property
    def angles(self) -> str:
        """The angles read and where their definitions come from."""
        def one(joint: str) -> str:
            if joint == "shoulder":
                return ("shoulder: the humerus's angle from the arm at the side within 5° of "
                        "the sagittal plane, thorax frame (Wu et al. 2005, J Biomech 38:981)")
            return f"{joint}: the first Cardan angle α (Z-X'-Y''), {JOINT_ANGLES[joint].source}"
        return "; ".join(one(j) for j in (self.joint, self.other))


_LEG = (
    MeasureSpec("straight_leg_raise", "straight-leg raise", "Straight-leg raise", "hip",
                "flexion", 1.0, "knee", 0.0, "straight_leg_raise"),
    MeasureSpec("popliteal_angle", "popliteal angle", "Popliteal angle", "hip", "flexion", 1.0,
                "knee", 0.0, "popliteal_angle", scan="other", pick="min", fixed_deg=90.0),
    MeasureSpec("silfverskiold_straight", "Silfverskiöld test", "Silfverskiöld, knee straight",
                "ankle", "dorsiflexion", 1.0, "knee", 0.0, "silfverskiold"),
    MeasureSpec("silfverskiold_bent", "Silfverskiöld test", "Silfverskiöld, knee bent",
                "ankle", "dorsiflexion", 1.0, "knee", 90.0, "silfverskiold"),
    MeasureSpec("thomas_hip", "Thomas test (modified)", "Thomas test, hip", "hip", "extension",
                -1.0, "knee", 90.0, "thomas_hip"),
    MeasureSpec("thomas_knee", "Thomas test (modified)", "Thomas test, knee", "hip", "flexion",
                1.0, "knee", 0.0, "thomas_knee", scan="other", pick="max", fixed_deg=0.0),
)
_ARM = tuple(
    MeasureSpec(f"shoulder_{mv}_{pos}", "shoulder reach, elbow straight vs bent",
                f"Shoulder {mv}, elbow {pos}", "shoulder", mv, 1.0 if mv == "flexion" else -1.0,
                "elbow", at, f"shoulder_{mv}")
    for mv in ("flexion", "extension") for pos, at in (("straight", 0.0), ("bent", 90.0)))

#: Every measure, by limb.
MEASURES: dict[str, tuple[MeasureSpec, ...]] = {"leg": _LEG, "arm": _ARM}


@dataclass
class CoupledMeasure:
    """One measure's result (degrees). ``value``: what the test reads — the limits' value
    when limits coupling the two joints are given (None where a recording given never reached
    the test position), else the recording's; ``from_limits``, ``recorded`` both readings (None
    when not available); ``reached``: whether the recording came to the test position (None
    without a recording); ``coupled``: whether the limb couples the two joints (False: the
    uncoupled limits answered, or the recording did where it reached the position);
    ``status``: ``"limits"``, ``"recording"``, ``"not reached in this recording"`` or ``"not
    possible"`` (no angle within the limits)."""

    spec: MeasureSpec
    value: float | None
    status: str
    from_limits: float | None = None
    recorded: float | None = None
    reached: bool | None = None
    samples_at_position: int = 0
    coupled: bool | None = None
    verdict: str | None = None
    notes: list[str] = field(default_factory=list)

    def to_json(self) -> dict[str, Any]:
        ref = REFERENCES[self.spec.reference]

        def r(v):
            return None if v is None else round(float(v), 2)
        return {"measure": self.spec.key, "test": self.spec.test, "label": self.spec.label,
                "definition": self.spec.definition, "angles": self.spec.angles,
                "joint": self.spec.joint,
                "movement": self.spec.movement, "other_joint": self.spec.other,
                "other_deg": None if self.spec.scan == "other" else self.spec.other_deg,
                "position": self.spec.position,
                "value": r(self.value), "status": self.status,
                "from_limits": r(self.from_limits), "recorded": r(self.recorded),
                "reached": self.reached, "samples_at_position": int(self.samples_at_position),
                "coupled": self.coupled, "norm": ref.get("norm"),
                "threshold": ref.get("threshold"), "sem_deg": ref.get("sem_deg"),
                "sem_source": ref.get("sem_source"), "source": ref["source"],
                "verdict": self.verdict, "notes": list(self.notes)}


# -- postures of a test position --------------------------------------------------------------
def _posture(joint: str, deg: np.ndarray, side: str) -> np.ndarray:
    """Joint orientations (M, 4) (rig frames) at clinical angle ``deg`` (M,) of the primary
    movement (flexion, dorsiflexion; the shoulder: flexion in the sagittal plane), the other
    angles zero: the position itself, in its plane."""
    deg = np.atleast_1d(np.asarray(deg, dtype=np.float64))
    if joint == "shoulder":  # the arm hanging along +X, flexion towards +Y about +Z
        q = Q.from_axis_angle(np.array([0.0, 0.0, 1.0]), np.radians(deg))
        return mirror_quaternions(q) if side == "left" else q
    return from_angles(deg, 0.0, 0.0, joint, side)


@functools.cache
def _reads_in_band(joint: str) -> bool:
    """Does a goniometer read this joint's primary angle within a band about its plane (a
    swing joint), or wherever it is (a hinge: its other angles are out-of-axis motion)?"""
    return joint == "shoulder" or calibration_kind(JOINTS[joint].kind).reads_in_band



class _Pair:
    """The measured joint and the other joint of one limb: their oracle queries. The other
    joint's range is its constraint's coupling range (a coupled hinge's: the hull of its
    keyframes); a joint that cannot drive couplings (no single angle) restricts nothing."""

    def __init__(self, limb: Limb, oracle: ConstraintOracle, joint: str, other: str,
                 side: str):
        self.side = side
        self.j = limb.index(joint)
        self.joint = joint
        self.other = other
        lj = limb.joints[self.j]
        self.coupled = lj.coupling is not None and lj.coupling.by == other
        self.oracle = oracle
        o = limb.joints[limb.index(other)]
        oc = o.constraint if o.constraint is not None else o.loosest()
        kind = None if oc is None else get_kind(oc.kind)
        self.other_constraint = oc
        self.other_kind = kind if kind is not None and kind.drives_couplings else None

    def other_angle(self, deg: np.ndarray) -> np.ndarray:
        """The other joint's coupling angle (radians) at its clinical angles ``deg``."""
        q = _posture(self.other, deg, self.side)
        return np.asarray(self.other_kind.coupling_angle(self.other_constraint, q), float)

    def other_allowed(self, deg: np.ndarray) -> np.ndarray:
        if self.other_kind is None:
            return np.ones(np.shape(deg), bool)
        lo, hi = self.other_kind.coupling_range(self.other_constraint)
        a = self.other_angle(deg)
        return (a >= lo - 1e-9) & (a <= hi + 1e-9)

    def valid(self, deg: np.ndarray, other_deg: np.ndarray) -> np.ndarray:
        """Is the measured joint at clinical angles ``deg`` (in its plane) within its limits
        with the other joint at ``other_deg`` (clamped into its range, as the limb oracle
        judges)?"""
        deg, other_deg = np.broadcast_arrays(np.atleast_1d(np.asarray(deg, float)),
                                             np.atleast_1d(np.asarray(other_deg, float)))
        q = _posture(self.joint, deg, self.side)
        if self.coupled:
            lo, hi = self.other_kind.coupling_range(self.other_constraint)
            angle = np.clip(self.other_angle(other_deg), lo, hi)
        else:
            angle = np.zeros(len(q))
        return np.asarray(self.oracle.evaluate_joint(self.j, q, angle).valid, bool)


def _extreme(ok_fn, lo: float, hi: float, pick: str) -> float | None:
    """The largest (``pick="max"``) or least angle in [lo, hi] where ``ok_fn`` holds: a 0.5°
    grid, then a 0.01° grid between the extreme and its outer neighbour."""
    grid = np.arange(lo, hi + 1e-9, _COARSE_DEG)
    ok = ok_fn(grid)
    if not ok.any():
        return None
    idx = np.flatnonzero(ok)
    if pick == "max":
        k = int(idx[-1])
        if k == len(grid) - 1:
            return float(grid[k])
        fine = np.arange(grid[k], grid[k + 1] + 1e-9, _FINE_DEG)
        return float(fine[np.flatnonzero(ok_fn(fine))[-1]])
    k = int(idx[0])
    if k == 0:
        return float(grid[0])
    fine = np.arange(grid[k - 1], grid[k] + 1e-9, _FINE_DEG)
    return float(fine[np.flatnonzero(ok_fn(fine))[0]])


def limits_value(limb: Limb, spec: MeasureSpec, side: str | None = None,
                 oracle: ConstraintOracle | None = None) -> tuple[float | None, bool, list[str]]:
    """One measure read from a limb's limits (module doc).

    Returns
    -------
    value : float or None
        Degrees, signed as the movement (a hip that cannot reach neutral has a negative Thomas
        extension); None where no angle is within the limits.
    coupled : bool
        Whether the limb couples the measured joint to the other joint.
    notes : list of str
    """
    side = check_side(side or limb.side or "right")
    oracle = oracle or ConstraintOracle(limb)
    pair = _Pair(limb, oracle, spec.joint, spec.other, side)
    notes: list[str] = []
    if not pair.coupled:
        notes.append(f"the limb has no coupling of the {spec.joint} to the {spec.other}: "
                     "computed from the uncoupled limits")
    if spec.scan == "other":
        fixed = spec.sign * spec.fixed_deg

        def ok(k):
            return pair.other_allowed(k) & pair.valid(np.full(len(k), fixed), k)
        value = _extreme(ok, -30.0, 180.0, spec.pick)
        if value is None:
            notes.append(f"the {spec.joint} is not within its limits at {spec.fixed_deg:g}° "
                         f"{spec.movement} at any {spec.other} angle")
        return value, pair.coupled, notes
    at = spec.other_deg
    if not bool(pair.other_allowed(np.array([at]))[0]):
        notes.append(f"the {spec.other} does not reach {at:g}° within its own limits: the "
                     f"{spec.joint} is read at the nearest angle of its range")
    top = 180.0 if spec.sign > 0 else 120.0

    def ok_measured(d):
        return pair.valid(spec.sign * d, np.full(len(d), at))
    value = _extreme(ok_measured, -90.0, top, "max")
    if value is None:
        notes.append(f"no {spec.joint} {spec.movement} angle is within its limits there")
    return value, pair.coupled, notes


# -- recordings -------------------------------------------------------------------------------
def _smooth(a: np.ndarray) -> np.ndarray:
    from scipy.ndimage import median_filter

    return median_filter(a, size=min(_WINDOW, len(a)), mode="nearest") if len(a) else a


def _primary_angle(q: np.ndarray, joint: str, side: str) -> tuple[np.ndarray, np.ndarray]:
    """The primary clinical angle (degrees, (N,)) of joint orientations and where a goniometer
    reads it (:func:`_reads_in_band`: within :data:`BAND_DEG` of its plane; a hinge
    everywhere), after the running median."""
    if joint == "shoulder":
        qq = mirror_quaternions(q) if side == "left" else q
        d = Q.rotate(qq, np.array([1.0, 0.0, 0.0]))
        psi = np.degrees(np.arctan2(d[:, 1], d[:, 0]))
        return _smooth(psi), np.abs(d[:, 2]) <= math.sin(math.radians(BAND_DEG))
    ang = joint_angles(q, joint, side)
    band = (np.abs(_smooth(ang["beta"])) <= BAND_DEG if _reads_in_band(joint)
            else np.ones(len(q), bool))
    return _smooth(ang["alpha"]), band


def _recorded(angles: dict[str, tuple[np.ndarray, np.ndarray]], spec: MeasureSpec,
              tolerance_deg: float) -> tuple[float | None, int]:
    """The recording's reading of a measure and how many samples were at the test position."""
    if spec.scan == "other":  # the measured joint held, the other joint's angle read
        a, band = angles[spec.joint]
        at = band & (np.abs(spec.sign * a - spec.fixed_deg) <= tolerance_deg)
        vals = angles[spec.other][0][at]
        if not len(vals):
            return None, 0
        return float(vals.min() if spec.pick == "min" else vals.max()), int(at.sum())
    o, _ = angles[spec.other]
    a, band = angles[spec.joint]
    at = band & (np.abs(o - spec.other_deg) <= tolerance_deg)
    if not at.any():
        return None, 0
    return float((spec.sign * a[at]).max()), int(at.sum())


# -- verdicts ---------------------------------------------------------------------------------
def _verdict(spec: MeasureSpec, v: float | None, by_key: dict[str, float | None],
             recorded_only: bool) -> str | None:
    if v is None or recorded_only:  # free movement is not the passive end-range test
        return None
    hedge = ""
    sem = REFERENCES[spec.reference].get("sem_deg")
    if spec.key == "popliteal_angle":
        return ("above 40°: reads as short hamstrings" if v > 40.0
                else "within 40°: no short hamstrings") + hedge
    if spec.key == "silfverskiold_straight":
        return ("below 18° with the knee straight" if v < 18.0 else
                "18° or more with the knee straight") + hedge
    if spec.key == "silfverskiold_bent":
        straight = by_key.get("silfverskiold_straight")
        if straight is None:
            return None
        if straight < 18.0 < v:
            words = "below 18° straight, above 18° bent: reads as a short gastrocnemius"
        elif straight < 18.0 and v < 18.0:
            words = "below 18° straight and bent: reads as a short soleus"
        elif straight > 18.0 and v > 18.0:
            words = "above 18° straight and bent: good triceps surae flexibility"
        else:
            words = "no pattern of Table 4"
        return words + hedge
    if spec.key == "thomas_hip":
        words = ("the hip does not reach neutral (hip angle > 0°): reads as short one-joint hip "
                 "flexors" if v < 0.0 else "the hip reaches neutral or extends")
        if abs(v) <= sem:
            words += f" (within the test's SEM of {sem:g}°: borderline)"
        return words + hedge
    if spec.key == "thomas_knee":
        words = ("knee angle below 67°: reads as short two-joint hip flexors" if v < 67.0
                 else "knee angle 67° or more: no short two-joint hip flexors")
        if abs(v - 67.0) <= sem:
            words += f" (within the test's SEM of {sem:g}°: borderline)"
        return words + hedge
    return None


# -- the one entry point ----------------------------------------------------------------------
def _limb_kind(limb: Limb | None, joint_names) -> str:
    kind = None if limb is None else limb.limb
    names = tuple(joint_names)
    if kind is None:
        kind = "leg" if {"hip", "knee", "ankle"} & set(names) else "arm"
    return kind


def coupled_measures(limb: Limb | None = None, postures=None, *, joint_names=None,
                     side: str | None = None,
                     tolerance_deg: float = TOLERANCE_DEG) -> list[CoupledMeasure]:
    """The coupled clinical tests of an arm or a leg (module doc): from its limits, a
    recording, or both.

    Parameters
    ----------
    limb : models.limb.Limb, optional
        The limits (a limb file, or the session's); None: the recording alone.
    postures : (N, J, 4) array_like, optional
        Recorded joint orientations (child relative to parent, rig segment frames,
        scalar-first), joints in ``limb``'s order (or ``joint_names``'). With it, a measure
        whose test position the recording never came within ``tolerance_deg`` of is "not
        reached in this recording" (value None).
    joint_names : sequence of str, optional
        The postures' joints when no limb is given (default: the limb's).
    side : {"right", "left"}, optional
        Default: the limb's, else right.
    tolerance_deg : float
        How near the other joint must be to the test position, degrees.

    Returns
    -------
    list of CoupledMeasure
        One per measure of :data:`MEASURES` whose two joints the limb (or the postures) has.
    """
    if limb is None and postures is None:
        raise ValueError("coupled_measures: give a limb, postures, or both")
    if not 0.0 < tolerance_deg <= 45.0:
        raise ValueError(f"tolerance_deg must be in (0, 45], got {tolerance_deg!r}")
    names = tuple(limb.joint_names if limb is not None else (joint_names or ()))
    if limb is not None and joint_names is not None and tuple(joint_names) != names:
        raise ValueError(f"joint_names {tuple(joint_names)} differ from the limb's {names}")
    if not names:
        raise ValueError("coupled_measures: give joint_names with postures and no limb")
    side = check_side(side or (limb.side if limb is not None else None) or "right")
    if limb is not None and limb.side is not None and limb.side != side:
        raise ValueError(f"side {side!r}: the limb {limb.name!r} is a {limb.side} "
                         f"{limb.limb or 'limb'}")
    specs = [s for s in MEASURES[_limb_kind(limb, names)]
             if s.joint in names and s.other in names]
    angles: dict[str, tuple[np.ndarray, np.ndarray]] | None = None
    if postures is not None:
        q = np.asarray(postures, dtype=np.float64)
        if q.ndim != 3 or q.shape[1] != len(names) or q.shape[2] != 4 or not len(q):
            raise ValueError(f"postures: expected shape (N, {len(names)}, 4) with N >= 1 "
                             f"(joints {', '.join(names)}), got {q.shape}")
        needed = {s.joint for s in specs} | {s.other for s in specs}
        angles = {n: _primary_angle(Q.check_quaternions(q[:, i], normalize=True,
                                                        name=f"postures[:, {i}]"), n, side)
                  for i, n in enumerate(names) if n in needed}
    oracle = ConstraintOracle(limb) if limb is not None else None
    out: list[CoupledMeasure] = []
    for spec in specs:
        lim, coupled, notes = (None, None, [])
        if limb is not None:
            lim, coupled, notes = limits_value(limb, spec, side, oracle)
        rec, n_at = (None, 0)
        reached = None
        if angles is not None:
            rec, n_at = _recorded(angles, spec, tolerance_deg)
            reached = n_at > 0
        if angles is not None and not reached:
            value, status = None, "not reached in this recording"
            held = spec.joint if spec.scan == "other" else spec.other
            notes.append(f"no recorded posture had the {held} within {tolerance_deg:g}° of "
                         "the test position")
        elif limb is not None and angles is not None and coupled is False:
            # uncoupled limits hold the joint's range at every angle of the other joint: not
            # the test's reading. The recording's own, at the test position, is.
            value, status = rec, "recording"
            notes = [f"the limb has no coupling of the {spec.joint} to the {spec.other}: its "
                     f"limits ({_deg(lim)}) do not depend on the {spec.other}'s angle, so the "
                     "recording's own reading at the test position is shown"]
        elif limb is not None:
            value, status = lim, "limits" if lim is not None else "not possible"
        else:
            value, status = rec, "recording"
        out.append(CoupledMeasure(spec, value, status, from_limits=lim, recorded=rec,
                                  reached=reached, samples_at_position=n_at, coupled=coupled,
                                  notes=notes))
    by_key = {m.spec.key: m.value for m in out}
    for m in out:
        m.verdict = _verdict(m.spec, m.value, by_key, m.status == "recording")
        if not REFERENCES[m.spec.reference].get("threshold"):
            continue
        if m.status == "recording":
            m.notes.append("no verdict: a recording's reading is the farthest the patient went "
                           "at the test position, not the passive end-range test")
        elif m.status == "limits" and m.reached:
            m.notes.append("limits extracted from a recording hold what it explored: the "
                           "verdict stands for an end-range (passive) exploration")
    return out


def _deg(v: float | None) -> str:
    return "none within them" if v is None else f"{v:.1f}°"


def measure_sources(measures: list[CoupledMeasure]) -> list[str]:
    """The sources the measures' thresholds, norms and SEMs come from, each once, sorted."""
    refs = [REFERENCES[m.spec.reference] for m in measures]
    return sorted({r["source"] for r in refs} | {r["sem_source"] for r in refs
                                                   if "sem_source" in r})


def format_coupled_tests(measures: list[CoupledMeasure]) -> str:
    """The measures as a plain-text table with their verdicts, notes and sources."""
    rows = [("test", "value", "limits", "recorded", "norm / threshold")]
    for m in measures:
        ref = REFERENCES[m.spec.reference]

        def f(v):
            return "-" if v is None else f"{v:.1f}°"
        rows.append((m.spec.label, f(m.value) if m.value is not None else
                     ("not reached" if m.status.startswith("not reached") else "-"),
                     f(m.from_limits), f(m.recorded),
                     ref.get("threshold") or ref.get("norm") or "-"))
    lines = ["coupled clinical tests", *text_table(rows)]
    for m in measures:
        if m.verdict:
            lines.append(f"{m.spec.label}: {m.verdict}")
        for n in m.notes:
            lines.append(f"note ({m.spec.label}): {n}")
    sources = measure_sources(measures)
    if sources:
        lines.append("sources: " + "; ".join(sources))
    return "\n".join(lines)
