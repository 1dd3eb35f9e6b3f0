"""Clinical angles of the elbow, wrist, hip, knee and ankle: ISB / Grood-Suntay Cardan angles,
peaks per movement, normative values (issue 21, part 3; the shoulder has its own,
:mod:`calibration.clinical`).

Frames
------
Every segment's rig frame (:mod:`calibration.frames`) has +X along the segment pointing
distally, +Y anterior, +Z to the body's right — except the **foot**, whose long axis lies
horizontal in standing: +X towards the toes (its long axis, anterior), +Y superior, +Z right,
which is the ISB calcaneus frame itself (Wu et al. 2002 §3.1). With ``M_s`` the rig axes of
segment ``s`` in its ISB frame (:data:`calibration.frames.SEGMENT_TO_ISB`: ``RIG_TO_ISB``,
the identity for the foot), a joint orientation (child ``c`` relative to parent ``p``, rig
frames) is ``J_isb = M_p J_rig M_cᵀ`` in ISB frames. So the ankle's neutral joint orientation
in rig frames is not the identity but ``M_shankᵀ``: the foot's long axis along the shank's +Y
(anterior). **Left limbs** are mirrored through the sagittal plane first (``(w, x, y, z) →
(w, −x, −y, z)``, as for the shoulder), so every sign below holds for either side.

Angles (:func:`joint_angles`)
-----------------------------
All five joints use the Z-X'-Y'' Cardan sequence of the joint coordinate system,
``J_isb = Rz(α) Rx(β) Ry(γ)``: ``α`` about the proximal segment's medio-lateral axis (Z), ``γ``
about the distal segment's long axis (Y), ``β`` about the floating axis between them:

===========  ==========================  ==============================  ===========================
joint        α (Z, proximal)             β (floating)                    γ (Y, distal)
===========  ==========================  ==============================  ===========================
elbow        flexion + / extension −     varus + / valgus −              pronation + / supination −
wrist        flexion + / extension −     ulnar + / radial deviation −    pronation + / supination −
hip          flexion + / extension −     adduction + / abduction −       internal + / external rot.
knee         flexion + / extension −     adduction + / abduction −       internal + / external rot.
ankle        dorsiflexion + / plantar −  inversion + / eversion −        internal + / external rot.
===========  ==========================  ==============================  ===========================

Sources: elbow (humerus–forearm) and wrist (hand–radius): Wu et al. 2005, *J Biomech* 38:981,
§3.4 and §4.4; hip and ankle (calcaneus–tibia): Wu et al. 2002, *J Biomech* 35:543, §2.4 and
§3.4; knee: Grood & Suntay 1983, *J Biomech Eng* 105:136 (flexion about the femur's
medio-lateral axis, tibial rotation about the tibia's long axis, ab/adduction about the
floating axis — the same Z-X'-Y'' sequence in these frames). The knee flexes the other way
about +Z than the hip, elbow and wrist (the shank swings backwards), so its ``α`` is negated:
knee flexion is positive, as Grood & Suntay report it.

Peaks (:func:`angle_peaks`)
---------------------------
Per movement, the farthest angle reached in its direction (0 when never reached), after a
running median over ``window`` samples (default 5) so that an isolated spike is not a peak: a
goniometer reads a position the patient held, not one sample.

Normative values (:data:`NORMATIVE`)
------------------------------------
AAOS 1965 (*Joint motion: method of measuring and recording*, American Academy of Orthopaedic
Surgeons), the table clinics use as "normal": elbow flexion 150°, extension 0°; forearm
pronation 80°, supination 80°; wrist flexion 80°, extension 70°, radial deviation 20°, ulnar
deviation 30°; hip flexion 120°, extension 30°, abduction 45°, adduction 30°, internal and
external rotation 45°; knee flexion 135°, extension 0°; ankle dorsiflexion 20°, plantarflexion
50°; inversion 35°, eversion 15° (the AAOS measures these at the subtalar and midtarsal joints
together, so the ankle's Cardan β is shown beside them, not compared).

Population values (:data:`POPULATION`, :func:`population_reference`)
---------------------------------------------------------------------
Measured means of healthy people, by sex and age band, one published source per joint (the
shoulder's are Gill et al. 2020, :mod:`calibration.clinical`):

- hip, knee, ankle: Soucie JM, Wang C, Forsyth A, Funk S, Denny M, Roach KE, Boone D, and the
  Hemophilia Treatment Center Network. Range of motion measurements: reference values and a
  database for comparison studies. *Haemophilia* 2011;17(3):500-507
  (doi:10.1111/j.1365-2516.2010.02399.x). CDC Normal Joint Range of Motion Study: 674 healthy
  subjects aged 2-69 (53.6 % female), passive motion, universal goniometer, nine physical
  therapists; mean and 95 % confidence interval per sex and age group (2-8, 9-19, 20-44, 45-69).
  Hip flexion and extension, knee flexion and extension, ankle dorsiflexion and
  plantarflexion. No hip ab/adduction or rotation, no ankle inversion or eversion (shown "—").
  The 2-8 band was read on the CDC study page; the 20-44 and 45-69 values as quoted from the
  CDC table in public notes (named per value); no 9-19 values were found, so a patient of 9-19
  has none. Knee extension is tabulated for 2-8 only, plantarflexion for 20-44 only.
- elbow (flexion, extension, pronation, supination) and wrist (flexion, extension, radial and
  ulnar deviation): Boone DC, Azen SP. Normal range of motion of joints in male subjects.
  *J Bone Joint Surg Am* 1979;61(5):756-759 (109 men, 18 months to 54 years, active motion,
  goniometer) for men; Macedo LG, Magee DJ. Differences in range of motion between dominant and
  nondominant sides of upper and lower extremities. *J Manipulative Physiol Ther*
  2008;31(8):577-582 (90 healthy women aged 18-59, goniometer) for women. Means only, one band
  per sex, as tabulated side by side (TABLE A.1 "Shoulder, Elbow, Forearm, and Wrist Motion:
  Mean Values in Degrees", F.A. Davis PT collection; its bands, 1-54 and 18-59, are shown).

The values, their sources, methods and where each number was read are one cited table,
``calibration/norms.yaml`` (:mod:`calibration.norms`); :data:`POPULATION` is built from the
sources its ``report`` section names per joint (above), and :func:`population_band` is
:func:`calibration.norms.norm_band` over them: the band of the patient's sex containing the
age; past the oldest adult band, the oldest; age unknown, the band containing an adult of
:data:`UNKNOWN_AGE` years (the text names the band, so the choice shows). The table also holds
Soucie 2011's arm values (shoulder flexion, elbow flexion and extension, pronation and
supination, by sex for 2-8, 20-44 and 45-69 as far as found), available through
:func:`calibration.norms.norm_band` with ``sources=["soucie2011"]``.

Movements a joint's kind does not measure (:func:`not_measured`)
-----------------------------------------------------------------
A hinge measures its angle alone, a two-axis joint its two swing angles, a ball joint all
three (:data:`KIND_ANGLES`, the kind from :data:`calibration.joints.JOINTS`). A clinical
movement outside them — the elbow hinge's pronation and supination — has no peak (None) and
no comparison: a table shows "not measured by a hinge", never a share of the AAOS value.

Physiological reach (:func:`physiological_max`, :func:`beyond_reach`)
---------------------------------------------------------------------
Per joint and movement, the widest value any cited norm gives (:data:`WIDEST_NORMS`: the AAOS
value, every population mean and 95 % CI upper end above, the shoulder's AAOS and Gill 2020
values) plus :data:`REACH_MARGIN_DEG` (20°). A peak beyond it is not a person's range — e.g. a
knee extension of 176° (widest norm 6.9°, Soucie 2011) read from sensor orientations rather
than segment orientations — and is flagged with what likely caused it. A movement no norm
gives (the shoulder's adduction) is not judged.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from calibration.alignment import trusted_samples
from calibration.clinical import NORMATIVE as SHOULDER
from calibration.clinical import check_side, mirror_quaternions, range_of_motion, text_table
from calibration.frames import SEGMENT_TO_ISB
from calibration.joints import JOINTS, joint_spec
from calibration.kinds import calibration_kind, registered
from calibration.norms import JOINT_MOVEMENTS, NORMS, REPORT_SOURCES, UNKNOWN_AGE, Norm, norm_band
from models import quaternion as Q
from models.constraint import JointConstraint

__all__ = ["CLINICAL_MOVEMENTS", "JOINT_ANGLES", "KIND_ANGLES", "NORMATIVE", "POPULATION",
           "REACH_MARGIN_DEG", "UNKNOWN_AGE", "WIDEST_NORMS", "JointAngleSet",
           "JointRangeOfMotion", "PopulationValue", "allowed_rom", "angle_peaks", "beyond_reach",
           "constraint_rom", "from_angles", "joint_angles", "largest_rom", "not_measured",
           "physiological_max", "population_band", "population_reference", "recorded_rom"]

@dataclass(frozen=True)
class JointAngleSet:
    """One joint's Cardan angles: the segments, and per angle (α, β, γ) its movement names
    (positive, negative) and the sign turning the Cardan angle into the positive movement."""

    parent: str
    child: str
    movements: tuple[tuple[str, str], tuple[str, str], tuple[str, str]]
    signs: tuple[float, float, float]
    source: str


_WU2005 = "Wu et al. 2005, J Biomech 38:981"
_WU2002 = "Wu et al. 2002, J Biomech 35:543"

#: The joints and their angles (module doc).
JOINT_ANGLES: dict[str, JointAngleSet] = {
    "elbow": JointAngleSet("upper-arm", "forearm", (("flexion", "extension"), ("varus", "valgus"),
                                                    ("pronation", "supination")),
                           (1.0, 1.0, 1.0), f"{_WU2005} §3.4"),
    "wrist": JointAngleSet("forearm", "hand", (("flexion", "extension"),
                                               ("ulnar_deviation", "radial_deviation"),
                                               ("pronation", "supination")),
                           (1.0, 1.0, 1.0), f"{_WU2005} §4.4"),
    "hip": JointAngleSet("pelvis", "thigh", (("flexion", "extension"), ("adduction", "abduction"),
                                             ("internal_rotation", "external_rotation")),
                         (1.0, 1.0, 1.0), f"{_WU2002} §2.4"),
    "knee": JointAngleSet("thigh", "shank", (("flexion", "extension"), ("adduction", "abduction"),
                                             ("internal_rotation", "external_rotation")),
                          (-1.0, 1.0, 1.0), "Grood & Suntay 1983, J Biomech Eng 105:136"),
    "ankle": JointAngleSet("shank", "foot", (("dorsiflexion", "plantarflexion"),
                                             ("inversion", "eversion"),
                                             ("internal_rotation", "external_rotation")),
                           (1.0, 1.0, 1.0), f"{_WU2002} §3.4"),
}

_AAOS = "AAOS 1965, Joint motion: method of measuring and recording"

#: Normative values (degrees) per joint and movement, and which are shown but not compared.
NORMATIVE: dict = {
    "source": _AAOS,
    "aaos": {
        "elbow": {"flexion": 150.0, "extension": 0.0, "pronation": 80.0, "supination": 80.0},
        "wrist": {"flexion": 80.0, "extension": 70.0, "radial_deviation": 20.0,
                  "ulnar_deviation": 30.0},
        "hip": {"flexion": 120.0, "extension": 30.0, "abduction": 45.0, "adduction": 30.0,
                "internal_rotation": 45.0, "external_rotation": 45.0},
        "knee": {"flexion": 135.0, "extension": 0.0},
        "ankle": {"dorsiflexion": 20.0, "plantarflexion": 50.0, "inversion": 35.0,
                  "eversion": 15.0},
    },
    "not_comparable": {
        ("ankle", "inversion"): "AAOS measures the subtalar and midtarsal joints together",
        ("ankle", "eversion"): "AAOS measures the subtalar and midtarsal joints together",
    },
}


# -- population values --------------------------------------------------------------------------
# The values, their sources and where each was read live in one cited table,
# calibration/norms.yaml (:mod:`calibration.norms`); the report's population column takes the
# sources its ``report`` section names per joint.

@dataclass(frozen=True)
class PopulationValue:
    """One published value: mean (degrees) of one sex in one age band (years, inclusive), its
    standard deviation and 95 % confidence interval where published, and where it was read."""

    sex: str
    age_lo: int
    age_hi: int
    mean: float
    sd: float | None = None
    ci95: tuple[float, float] | None = None
    where: str = ""
    source: str = ""  # the publication (its short citation)
    method: str = ""  # how it measured (active or passive, instrument, position)

    @classmethod
    def from_norm(cls, n: Norm) -> PopulationValue:
        """The value of one row of :data:`calibration.norms.NORMS` (a band, not an overall
        value: the columns of these joints have only bands)."""
        return cls(n.sex, n.age_lo, n.age_hi, n.value, n.sd, n.ci95, n.where, n.source.cite,
                   n.source.method)

    def to_json(self) -> dict:
        """Plain types: sex, age band, mean, sd and ci95 (None where not published), and the
        value's source and measurement method."""
        return {"sex": self.sex, "age": [self.age_lo, self.age_hi], "mean": self.mean,
                "sd": self.sd, "ci95": None if self.ci95 is None else list(self.ci95),
                "source": self.source, "method": self.method}


#: How each joint's population column was measured, as its table's note says it.
_MEASURED = {"soucie2011": "passive, goniometer",
             "boone1979+macedo2008": "goniometer; Boone & Azen active motion"}
_SHORT = {"soucie2011": "Soucie 2011",
          "boone1979+macedo2008": "Boone 1979 (men) / Macedo 2008 (women)"}


def _population() -> dict[str, dict]:
    """:data:`POPULATION` from the norms table (its report sources, the shoulder apart)."""
    out: dict[str, dict] = {}
    for joint, keys in REPORT_SOURCES.items():
        if joint == "shoulder":
            continue
        srcs = [NORMS.sources[k] for k in keys]
        key = "+".join(keys)
        if len(srcs) == 1:
            source, cite = srcs[0].reference, srcs[0].cite
        else:  # one source per sex (Boone & Azen men, Macedo & Magee women)
            sexes = [{n.sex for n in NORMS.rows if n.source.key == k} for k in keys]
            who = [{"male": "men", "female": "women"}[next(iter(s))] for s in sexes]
            source = "; ".join(f"{w}: {s.reference}" for w, s in zip(who, srcs, strict=True))
            cite = "; ".join(f"{s.cite} ({w})" for w, s in zip(who, srcs, strict=True))
        movements: dict[str, list[PopulationValue]] = {}
        for n in NORMS.rows:
            if n.joint == joint and n.source.key in keys:
                movements.setdefault(n.movement, []).append(PopulationValue.from_norm(n))
        out[joint] = {"source": source, "cite": cite, "short": _SHORT.get(key, key),
                      "measured": _MEASURED.get(key, srcs[0].method), "movements": movements}
    return out


#: Population values per joint: ``source`` (full reference), ``cite`` (short, for the table),
#: ``short`` (name), ``measured`` (how), ``movements``:
#: movement → list of :class:`PopulationValue`. A movement absent here has no published value in
#: the joint's source; a joint absent has no source (its table column shows "—"). Built from
#: :data:`calibration.norms.NORMS` (the report's sources per joint).
POPULATION: dict[str, dict] = _population()

_WORD = {"female": "women", "male": "men"}


def _check_who(age, sex) -> None:
    if sex is not None and sex not in _WORD:
        raise ValueError(f"sex must be 'male' or 'female', got {sex!r}")
    if age is not None and not (isinstance(age, int | float) and 0 <= age < 150):
        raise ValueError(f"age must be years (0-149), got {age!r}")


def population_band(joint: str, movement: str, *, age: float | None = None,
                    sex: str | None = None) -> list[PopulationValue]:
    """The published values that apply to a patient (:func:`calibration.norms.norm_band` over
    the joint's report sources): per sex (both, women first, when ``sex`` is None) the band
    containing ``age``; past the oldest band, the oldest when it is an adult band; age unknown,
    the band containing :data:`UNKNOWN_AGE`. Empty when the joint has no source or the
    movement no value for that age."""
    _joint(joint)
    _check_who(age, sex)
    if joint not in POPULATION or movement not in JOINT_MOVEMENTS.get(joint, ()):
        return []
    return [PopulationValue.from_norm(n)
            for n in norm_band(joint, movement, age=age, sex=sex,
                               sources=REPORT_SOURCES[joint], unknown_age=UNKNOWN_AGE)]


def population_reference(joint: str, movement: str, *, age: float | None = None,
                         sex: str | None = None) -> str | None:
    """The population reference of one movement as text, as the shoulder's
    (:func:`calibration.clinical.population_reference`): the mean of the patient's sex and age
    band, e.g. ``"138 (women, 45-69)"``; sex unknown, women and men apart,
    ``"142 (women, 20-44) / 138 (men, 20-44)"`` (:func:`population_band`). None when no
    published value applies."""
    parts = [f"{v.mean:.0f} ({_WORD[v.sex]}, {v.age_lo}-{v.age_hi})"
             for v in population_band(joint, movement, age=age, sex=sex)]
    return " / ".join(parts) if parts else None


def _joint(name: str) -> JointAngleSet:
    if name not in JOINT_ANGLES:
        raise ValueError(f"joint must be one of {', '.join(JOINT_ANGLES)}, got {name!r}")
    return JOINT_ANGLES[name]


def _side(q: np.ndarray, side: str) -> np.ndarray:
    return mirror_quaternions(q) if check_side(side) == "left" else q


def joint_angles(q, joint: str, side: str = "right") -> dict[str, np.ndarray]:
    """Cardan angles (degrees, (N,) each) of joint orientations ``q`` (N, 4) or (4,) (child
    relative to parent, rig frames, scalar-first): ``{"alpha", "beta", "gamma"}`` signed as the
    positive movements of :data:`JOINT_ANGLES` (knee flexion positive)."""
    js = _joint(joint)
    q = _side(Q.check_quaternions(np.atleast_2d(q), normalize=True, name="joint orientation"),
              side)
    mp, mc = SEGMENT_TO_ISB[js.parent], SEGMENT_TO_ISB[js.child]
    r = Q.to_rotation(q).as_matrix()
    isb = mp @ r @ mc.T
    from scipy.spatial.transform import Rotation

    a, b, c = np.degrees(Rotation.from_matrix(isb).as_euler("ZXY")).T
    return {"alpha": js.signs[0] * a, "beta": js.signs[1] * b, "gamma": js.signs[2] * c}


def from_angles(alpha, beta, gamma, joint: str, side: str = "right") -> np.ndarray:
    """Joint orientations (N, 4) (rig frames) with the given clinical angles (degrees, signed as
    :func:`joint_angles` returns them) — its inverse, for simulated patients and tests."""
    js = _joint(joint)
    ang = np.stack(np.broadcast_arrays(np.asarray(alpha, float) * js.signs[0],
                                       np.asarray(beta, float) * js.signs[1],
                                       np.asarray(gamma, float) * js.signs[2]), axis=-1)
    ang = np.radians(np.atleast_2d(ang))
    # the intrinsic Z-X-Y Cardan sequence, Rz(α) Rx(β) Ry(γ), as one quaternion product
    isb = Q.multiply(Q.multiply(Q.from_axis_angle(_E[2], ang[:, 0]),
                                Q.from_axis_angle(_E[0], ang[:, 1])),
                     Q.from_axis_angle(_E[1], ang[:, 2]))
    # the matrix Mpᵀ · R · Mc of the segment-to-ISB frames
    q = Q.multiply(Q.multiply(Q.conjugate(_isb_quaternion(js.parent)), isb),
                   _isb_quaternion(js.child))
    return _side(Q.canonical(q), side)


_E = np.eye(3)


@functools.cache
def _isb_quaternion(segment: str) -> np.ndarray:
    """:data:`SEGMENT_TO_ISB` ``[segment]`` as a quaternion (the same rotation)."""
    from scipy.spatial.transform import Rotation

    q = Q.from_rotation(Rotation.from_matrix(SEGMENT_TO_ISB[segment]))
    q.setflags(write=False)
    return q


def _pair(v: np.ndarray, pos: str, neg: str) -> dict[str, float | None]:
    """A movement pair's peaks from one angle's values: the farthest positive and negative
    (≥ 0; 0 when never reached), None when there are no values."""
    if not v.size:
        return {pos: None, neg: None}
    return {pos: float(max(0.0, v.max())), neg: float(max(0.0, -v.min()))}


def angle_peaks(angles: dict[str, np.ndarray], joint: str, window: int = 5,
                where: dict[str, np.ndarray] | None = None) -> dict[str, float | None]:
    """Peak per movement (degrees, ≥ 0) of :func:`joint_angles` output over a recording (module
    doc: running median over ``window`` samples first), over the samples ``where[key]`` selects
    for each angle when given (None for a movement with no sample selected)."""
    from scipy.ndimage import median_filter

    js = _joint(joint)
    if window < 1:
        raise ValueError(f"window must be >= 1, got {window}")
    out: dict[str, float | None] = {}
    for key, (pos, neg) in zip(("alpha", "beta", "gamma"), js.movements, strict=True):
        a = np.asarray(angles[key], dtype=float)
        if a.size == 0:
            raise ValueError("no samples")
        a = median_filter(a, size=min(window, a.size), mode="nearest")
        out.update(_pair(a if where is None else a[where[key]], pos, neg))
    return out


#: The movements a clinic reports per joint (the others' Cardan angles are computed, not
#: tabulated: an elbow's varus/valgus or a knee's ab/adduction is not a range of motion).
#: The one list is :data:`calibration.norms.JOINT_MOVEMENTS` (the shoulder's is
#: :class:`calibration.clinical.RangeOfMotion`'s).
CLINICAL_MOVEMENTS: dict[str, tuple[str, ...]] = {
    j: m for j, m in JOINT_MOVEMENTS.items() if j != "shoulder"}

#: The Cardan angles (0 = α, 1 = β, 2 = γ) each joint kind (:data:`calibration.joints.JOINTS`)
#: measures: a hinge its angle about its axis alone (its other angles are out-of-axis motion:
#: an elbow hinge has no forearm rotation, which happens between the radius and the ulna
#: within the forearm segment), a two-axis joint α and β (its narrow twist is not a range of
#: motion), a ball joint all three.
KIND_ANGLES: dict[str, tuple[int, ...]] = {k.name: k.angles for k in registered()}


def not_measured(joint: str, kind: str | None = None) -> dict[str, str]:
    """The clinical movements (:data:`CLINICAL_MOVEMENTS`) of ``joint`` that its kind cannot
    measure (:data:`KIND_ANGLES`), each with the words a table shows for it, e.g. the elbow's
    ``{"pronation": "not measured by a hinge", "supination": ...}``; empty for most joints.
    ``kind``: the kind of the constraint the peaks come from, when it is not the joint's own
    (an elbow held by a ``forearm`` constraint measures pronation and supination).
    The one place that decides it: the peaks, the tables and the report ask here."""
    spec_kind = joint_spec(joint).kind  # ValueError naming the joints for an unknown one
    kind = spec_kind if kind is None else kind
    if joint not in JOINT_ANGLES:  # the shoulder (a ball joint): its own angles, all measured
        return {}
    js = JOINT_ANGLES[joint]
    words = calibration_kind(kind).unmeasured_words
    return {m: words for k, pair in enumerate(js.movements) if k not in KIND_ANGLES[kind]
            for m in pair if m in CLINICAL_MOVEMENTS[joint]}


# -- physiological reach ------------------------------------------------------------------------
#: Degrees beyond the widest published norm at which a reading is flagged as beyond what people
#: reach (:func:`physiological_max`). The norms are means (Soucie 2011, Boone 1979, Macedo
#: 2008, Gill 2020) or the round values clinics use as normal (AAOS 1965), not the largest
#: ranges people have: the margin leaves room for individual variation above them and for a
#: measurement's alignment error. It is a threshold for readings no person makes, not a norm.
REACH_MARGIN_DEG = 20.0


def _widest_norms() -> dict[str, dict[str, tuple[float, str]]]:
    """Per joint and movement, the widest value the cited norms give (AAOS 1965; every
    population mean and 95 % CI upper end of :data:`POPULATION`; the shoulder's AAOS and Gill
    2020 means and band medians, :data:`calibration.clinical.NORMATIVE`) and its source."""

    out: dict[str, dict[str, tuple[float, str]]] = {}

    def keep(joint: str, movement: str, value: float, source: str) -> None:
        have = out.setdefault(joint, {}).get(movement)
        if have is None or value > have[0]:
            out[joint][movement] = (float(value), source)

    for m, v in SHOULDER["aaos"].items():
        keep("shoulder", m, v, "AAOS 1965")
    for m, by_sex in SHOULDER["gill2020_mean"].items():
        for v in by_sex.values():
            keep("shoulder", m, v, "Gill 2020")
    for m, by_sex in SHOULDER["gill2020_band_median"].items():
        for bands in by_sex.values():
            for *_, v in bands:
                keep("shoulder", m, v, "Gill 2020")
    for joint, table in NORMATIVE["aaos"].items():
        for m, v in table.items():
            keep(joint, m, v, "AAOS 1965")
    for joint, src in POPULATION.items():
        for m, values in src["movements"].items():
            for p in values:
                keep(joint, m, p.mean if p.ci95 is None else max(p.mean, p.ci95[1]),
                     src["short"])
    return out


#: Per joint and movement, the widest published norm (degrees) and its source
#: (:func:`_widest_norms`); a movement with no published value has none.
WIDEST_NORMS: dict[str, dict[str, tuple[float, str]]] = _widest_norms()


def physiological_max(joint: str, movement: str) -> float | None:
    """The largest angle (degrees) a person reaches in ``movement`` of ``joint``, as far as the
    cited norms tell: the widest of them (:data:`WIDEST_NORMS`) plus
    :data:`REACH_MARGIN_DEG`; None where no norm gives the movement (a shoulder's adduction)."""
    got = WIDEST_NORMS.get(joint, {}).get(movement)
    return None if got is None else got[0] + REACH_MARGIN_DEG


def beyond_reach(rom, joint: str | None = None) -> dict[str, dict]:
    """The movements of a range of motion (a :class:`JointRangeOfMotion`, or the shoulder's
    :class:`calibration.clinical.RangeOfMotion`) beyond what people reach
    (:func:`physiological_max`): movement → ``{"value", "max", "norm", "source", "text"}``,
    ``text`` one line saying so and what likely caused it. Empty when every value is within
    reach."""
    if isinstance(rom, JointRangeOfMotion):
        joint, values = rom.joint, dict(rom.peaks)
    else:
        joint = joint or "shoulder"
        values = {m: getattr(rom, m) for m in rom.MOVEMENTS}
    out: dict[str, dict] = {}
    for m, v in values.items():
        top = physiological_max(joint, m)
        if v is None or top is None or v <= top:
            continue
        norm, source = WIDEST_NORMS[joint][m]
        text = (f"{joint} {m.replace('_', ' ')} {v:.1f}° is beyond what people reach (the widest "
                f"published norm is {norm:g}°, {source}; flagged beyond {top:g}°): likely "
                "not the segments' orientations — sensor orientations (as `rig export` writes "
                "them) rather than segment orientations, the wrong --parent/--child "
                "segments, or another joint's or side's data")
        out[m] = {"value": round(float(v), 2), "max": top, "norm": norm, "source": source,
                  "text": text}
    return out


@dataclass(frozen=True)
class JointRangeOfMotion:
    """One joint's range of motion in clinical terms: the peak per movement (degrees, None
    when the source does not tell it — a hinge constraint says nothing of forearm rotation),
    and the arc of the primary angle α (flexion for the elbow, knee, hip, wrist; dorsiflexion
    for the ankle) from its lowest to its highest value."""

    joint: str
    side: str
    peaks: dict[str, float | None]
    arc: tuple[float, float] | None = None
    #: the kind of the constraint the peaks come from, when not the joint's own
    #: (:func:`not_measured`)
    kind: str | None = None

    def table(self, *, age: float | None = None, sex: str | None = None) -> str:
        """The clinical table as text: movement, measured peak, AAOS (:data:`NORMATIVE`) and the
        population reference for ``age`` / ``sex`` (:func:`population_reference`; women and men
        apart when the sex is unknown, "—" where no published value applies)."""
        _check_who(age, sex)
        aaos = NORMATIVE["aaos"][self.joint]
        who = ", ".join(x for x in (_WORD.get(sex or ""),
                                    None if age is None else f"age {age:g}") if x)
        rows = [("movement", "measured", "AAOS", "population" + (f" ({who})" if who else ""))]
        missing = []
        unmeasured = not_measured(self.joint, self.kind)
        for m in CLINICAL_MOVEMENTS[self.joint]:
            if m in unmeasured:  # no deficit to read: the model has no such movement
                rows.append((m.replace("_", " "), unmeasured[m], "-", "-"))
                continue
            v = self.peaks.get(m)
            ref = aaos.get(m)
            comparable = (self.joint, m) not in NORMATIVE["not_comparable"]
            pop = population_reference(self.joint, m, age=age, sex=sex)
            if pop is None:
                missing.append(m.replace("_", " "))
            rows.append((m.replace("_", " "), "-" if v is None else f"{v:.1f}°",
                         "-" if ref is None or not comparable else f"{ref:.0f}°",
                         "—" if pop is None else pop))
        lines = [f"{self.joint} range of motion ({self.side} side)", *text_table(rows)]
        if self.arc is not None:
            pos, neg = JOINT_ANGLES[self.joint].movements[0]
            lines.append(f"arc: {pos} from {self.arc[0]:.1f}° to {self.arc[1]:.1f}° "
                         f"(negative: {neg})")
        for (j, m), why in NORMATIVE["not_comparable"].items():
            if j == self.joint:
                lines.append(f"note: {m} not compared with AAOS: {why}")
        if unmeasured:
            lines.append(f"note: {' and '.join(unmeasured)}: the {self.joint} is modelled as a "
                         f"{self.kind or joint_spec(self.joint).kind}, which has no such "
                         "movement: not "
                         "reported (not a deficit)")
        pop_src = POPULATION.get(self.joint)
        if pop_src is None:
            lines.append(f"note: no published population values found for the {self.joint}")
        elif missing:
            lines.append(f"note: no population value for {', '.join(missing)}"
                         + ("" if age is None else f" at age {age:g}") + f" in {pop_src['short']}")
        if pop_src is not None and age is None:
            lines.append(f"note: age unknown: the population band of a {UNKNOWN_AGE}-year-old "
                         "is shown")
        lines.append(f"sources: angles = {JOINT_ANGLES[self.joint].source}; "
                     f"AAOS = {NORMATIVE['source']}"
                     + ("" if pop_src is None else
                        f"; population = {pop_src['cite']} ({pop_src['measured']})"))
        return "\n".join(lines)

    def to_json(self, *, age: float | None = None, sex: str | None = None) -> dict:
        """Plain types: movement → degrees (2 decimals) or None, ``arc``, joint, side; and the
        population reference for ``age`` / ``sex``: ``population`` (movement → text or None, as
        the table), ``population_values`` (movement → the published values applied,
        :meth:`PopulationValue.to_json`), ``population_source`` (the reference, None when the
        joint has none) and ``population_for`` (the age and sex asked); ``not_measured``
        (movement → why, :func:`not_measured`: None, no population reference)."""
        _check_who(age, sex)
        out: dict = {"joint": self.joint, "side": self.side}
        unmeasured = not_measured(self.joint, self.kind)
        shown = [m for m in CLINICAL_MOVEMENTS[self.joint] if m not in unmeasured]
        for m in CLINICAL_MOVEMENTS[self.joint]:
            v = None if m in unmeasured else self.peaks.get(m)
            out[m] = None if v is None else round(float(v), 2)
        out["arc"] = None if self.arc is None else [round(float(v), 2) for v in self.arc]
        out["not_measured"] = dict(unmeasured)
        out["population"] = {m: population_reference(self.joint, m, age=age, sex=sex)
                             if m in shown else None for m in CLINICAL_MOVEMENTS[self.joint]}
        out["population_values"] = {
            m: [p.to_json() for p in population_band(self.joint, m, age=age, sex=sex)]
            if m in shown else [] for m in CLINICAL_MOVEMENTS[self.joint]}
        src = POPULATION.get(self.joint)
        out["population_source"] = None if src is None else src["source"]
        out["population_for"] = {"age": age, "sex": sex}
        return out


def _in_band(ang: dict[str, np.ndarray], band_deg: float) -> dict[str, np.ndarray]:
    """Per angle, the samples at which a goniometer reads it: α (flexion, dorsiflexion) at any
    other angle (the first Cardan angle is the sagittal-plane angle itself); β with α within
    ``band_deg`` of zero (abduction is measured without flexion; axial rotation does not move
    the segment's direction); γ with both swing angles within ``band_deg`` of zero."""
    a, b = np.abs(ang["alpha"]), np.abs(ang["beta"])
    return {"alpha": np.ones(a.shape, bool), "beta": a <= band_deg,
            "gamma": (a <= band_deg) & (b <= band_deg)}


def recorded_rom(q, joint: str, side: str = "right", *, window: int = 5,
                 band_deg: float = 5.0, status=None) -> JointRangeOfMotion:
    """The range of motion of recorded joint orientations ``q`` (N, 4) (rig frames): each
    movement's farthest angle after a running median over ``window`` samples (an isolated
    spike is not a peak), among the samples at which a goniometer reads it (:func:`_in_band`,
    as :func:`constraint_rom`; a hinge's other angles are out-of-axis motion, not positions,
    and restrict nothing). A movement with no sample in its band is None.

    ``status`` (N,) — the IMUs' calibration bytes per sample (the lowest of the sensors'),
    when the orientations come from IMUs: samples the sensors flag
    (:func:`calibration.alignment.status_ok`: a magnetic disturbance drops the system level)
    are left out, as the boundary extraction leaves them out — a peak is the farthest value,
    so one disturbed stretch would otherwise be the peak. All are used when none passes."""
    from scipy.ndimage import median_filter

    if status is not None:
        q = np.asarray(q)[trusted_samples(np.asarray(status).reshape(-1), len(q))]
    raw = joint_angles(q, joint, side)
    n = len(raw["alpha"])
    ang = {k: median_filter(v, size=min(window, n), mode="nearest") for k, v in raw.items()}
    where = _in_band(ang, band_deg) if calibration_kind(JOINTS[joint].kind).reads_in_band \
        else None
    peaks = angle_peaks(ang, joint, window=1, where=where)
    unmeasured = not_measured(joint)
    return JointRangeOfMotion(joint, check_side(side),
                              {m: None if m in unmeasured else peaks.get(m)
                               for m in CLINICAL_MOVEMENTS[joint]},
                              (float(ang["alpha"].min()), float(ang["alpha"].max())))


def constraint_rom(constraint, joint: str, side: str = "right", *, band_deg: float = 5.0,
                   step_deg: float = 0.25) -> JointRangeOfMotion:
    """The range of motion a constraint allows (:class:`models.constraint.JointConstraint`,
    rig frames), read as a goniometer reads a position: each angle's farthest value among the
    allowed orientations at which a goniometer reads it (:func:`_in_band`). Swing joints: the
    angles of :func:`calibration.kinds.ball.allowed_boundary_samples` (``step_deg`` apart
    along the boundary; a Cardan grid read a narrow twist interval only where a grid line
    crossed it: a simulated ankle's inversion 4.5-6° short). A hinge reads its interval (its
    other angles are zero); movements a constraint does not model are None."""
    js = _joint(joint)
    side = check_side(side)
    kind = calibration_kind(constraint.kind)
    ang = joint_angles(kind.allowed_samples(constraint, step_deg), joint, side)
    where = _in_band(ang, band_deg) if kind.reads_in_band else None
    unmeasured = not_measured(joint, constraint.kind)
    out: dict[str, float | None] = {}
    for k, key in enumerate(("alpha", "beta", "gamma")):
        if k in kind.bounds:  # the angles a constraint of its kind bounds
            out.update(_pair(ang[key] if where is None else ang[key][where[key]],
                             *js.movements[k]))
    return JointRangeOfMotion(joint, side, {m: None if m in unmeasured else out.get(m)
                                            for m in CLINICAL_MOVEMENTS[joint]},
                              (float(ang["alpha"].min()), float(ang["alpha"].max())),
                              constraint.kind)


def largest_rom(roms: list):
    """Movement by movement, the largest of several ranges of motion of one joint (None where
    every one is None): a :class:`JointRangeOfMotion`'s arc its widest ends, a shoulder's
    (:class:`calibration.clinical.RangeOfMotion`) ``neutral_outside_deg`` the least."""
    import dataclasses

    if not roms:
        raise ValueError("largest_rom: no ranges of motion")
    if len(roms) == 1:
        return roms[0]

    def top(values):
        got = [v for v in values if v is not None]
        return max(got) if got else None

    first = roms[0]
    if hasattr(first, "peaks"):
        arcs = [r.arc for r in roms if r.arc is not None]
        return dataclasses.replace(
            first, peaks={m: top(r.peaks[m] for r in roms) for m in first.peaks},
            arc=(min(a[0] for a in arcs), max(a[1] for a in arcs)) if arcs else None)
    return dataclasses.replace(
        first, neutral_outside_deg=min(r.neutral_outside_deg for r in roms),
        **{m: top(getattr(r, m) for r in roms) for m in first.MOVEMENTS})


def allowed_rom(constraints, joint: str, side: str = "right", *, directions=None):
    """The clinical range of motion limits allow: one constraint's, or a coupled joint's (its
    keyframes' constraints, at several angles of the joint it depends on) — what it allows at
    *some* angle of that joint, movement by movement the largest over the keyframes (a
    movement a keyframe's recording did not reach would otherwise read short: a simulated
    shoulder's widest keyframe, by area, read its abduction 15° short).

    The shoulder: :func:`calibration.clinical.range_of_motion` (with the recorded limb
    ``directions``, each peak the smaller of the limits' and the recording's reading — the
    same recording for every keyframe, so the largest of the smaller is the smaller of the
    largest); the other joints: :func:`constraint_rom`. ``rig rom --constraint``, the limb
    report and the IMU-path benchmark read coupled joints here."""

    if isinstance(constraints, JointConstraint):
        constraints = [constraints]
    if joint == "shoulder":
        return largest_rom([range_of_motion(c, side, directions=directions)
                            for c in constraints])
    return largest_rom([constraint_rom(c, joint, side) for c in constraints])
