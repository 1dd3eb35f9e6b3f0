"""Minimal detectable change (MDC) of range-of-motion measurements, per joint, movement and
instrument, from published test-retest studies — the smallest change between two visits that
a measurement method can tell from its own error.

A change between visits is real evidence only when it exceeds the MDC of the method that
measured both visits. Studies report the MDC at 95 % (``MDC95 = 1.96 * sqrt(2) * SEM``) or 90 %
confidence, or as a smallest detectable difference (SDD); each entry keeps which. Where a
study gives a range (several raters, devices or joints), the entry keeps both ends: a change
beyond the upper end exceeds the MDC, one below the lower end does not, one between is
``"uncertain"`` (:func:`verdict`).

Instruments (:data:`INSTRUMENTS`): ``goniometer`` (universal goniometer), ``inclinometer``
(digital inclinometer), ``motion-capture`` (3D optoelectronic markers), ``imu`` (inertial
sensors). The rig's own measurement methods (:data:`METHODS`: ``imu``, ``servo``, ``file``) map
to the instrument whose published values apply (:data:`METHOD_INSTRUMENT`); no published
study gives a test-retest MDC of a back-driven servo limb, and this table holds no IMU value
(the search is described below). For a method without its own published value,
:func:`mdc_for` says ``"no published MDC"`` for that method and gives, marked as such
(``reference=True``), the clinical instruments' value (goniometer, else inclinometer): what a
clinician's own re-measurement could resolve — a conservative bar, since a patient's
day-to-day variation is part of every published MDC.

Sources (each entry names its own):

* Armstrong AD, MacDermid JC, Chinchalkar S, Stevens RS, King GJ. Reliability of
  range-of-motion measurement in the elbow and forearm. J Shoulder Elbow Surg
  1998;7(6):573-580 (intratester, universal goniometer, 95 % confidence: flexion 6°,
  extension 7°, pronation 8°, supination 8°).
* Reissner L, Fischer G, List R, Taylor WR, Giovanoli P, Calcagni M. Minimal detectable
  difference of the finger and wrist range of motion: comparison of goniometry and 3D motion
  analysis. J Orthop Surg Res 2019;14:173 (3D motion capture MDD 5-12° for the hand's joints
  incl. the wrist); the wrist's goniometric MDD 8-18° as quoted by Wirth MA, Fischer G,
  Verdú J, Reissner L, Balocco S, Calcagni M. Comparison of a new inertial sensor based
  system with an optoelectronic motion capture system for motion analysis of healthy human
  wrist joints. Sensors 2019;19(23):5297 (issue 42).
* Powden CJ, Hoch JM, Hoch MC. Reliability and minimal detectable change of the
  weight-bearing lunge test: a systematic review. Man Ther 2015;20(4):524-532 (ankle
  dorsiflexion, 12 studies: mean MDC 4.6° inter-clinician, 4.7° intra-clinician).
* Hancock GE, Hepworth T, Wembridge K. Accuracy and reliability of knee goniometry methods.
  J Exp Orthop 2018;5:46 (minimum significant difference: long-arm goniometer 10°, digital
  inclinometer 6°).
* Kolber MJ, Vega F, Widmayer K, Cheng MS. The reliability and minimal detectable change of
  shoulder mobility measurements using a digital inclinometer. Physiother Theory Pract
  2011;27(2):176-184 (interrater MDC90: flexion 8°, abduction 4°, internal rotation 8°,
  external rotation 9°).

* Wilken JM, Rodriguez KM, Brawner M, Darter BJ. Reliability and minimal detectible change
  values for gait kinematics and kinetics in healthy adults. Gait Posture 2012;35(2):301-307,
  PMID 22041096 (29 healthy adults, two marker-based gait assessments 5.6 ± 2.2 days apart,
  two raters: "changes in gait kinematics of greater than approximately 5° can be identified
  when comparing between sessions" — the abstract; its per-angle tables were not read here).
  Used for the ``motion-capture`` instrument (a lab's file, method ``file``) in the sagittal
  plane of the hip, knee and ankle only: McGinley JL, Baker R, Wolfe R, Morris ME. The
  reliability of three-dimensional kinematic gait measurements: a systematic review. Gait
  Posture 2009;29(3):360-369 found the highest reliability in the hip and knee sagittal
  plane and the largest errors in the hip and knee transverse plane, so the 5° is not carried
  to rotations or to the frontal plane. These are peaks during gait, not end-range positions:
  a lab's gait file measures the former.

No entry for the hip by goniometer: the goniometric studies found (Nussbaumer S et al., BMC
Musculoskelet Disord 2010;11:194) report reliability coefficients, not an MDC in degrees.

**IMU** (issue 42: "per measurement method"): no per-movement MDC or SEM of IMU-measured range
of motion could be read and cited here. Studies that report one, whose tables were not
readable through the sources available: Yoon T-L, J Korean Phys Ther 2017;29(3):145-151
(MyoMotion IMU, shoulder flexion, abduction and rotations, 33 participants: "small SEM and MDC
values", numbers in its tables); an inter-session study of IMU knee angles in gait (15
healthy volunteers, three test administrators; SEM 1.21-3.32°, MDC 3.37-9.21° in its
abstract) whose authors and journal could not be established. Studies read that give limits
of agreement or ICCs only (no MDC): Stołowski Ł et al., Sensors 2023;23:8782 (hip, RSQ
Motion IMU), Rigoni M et al., Sensors 2019;19:1781 (shoulder, Biokin IMU), Sacco G et al.,
Clin Interv Aging 2015;10:491-497 (elbow, MotionPod; ICC 0.15-0.50). IMU sessions therefore
keep the goniometer's (else the inclinometer's) value, marked ``reference``.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["INSTRUMENTS", "MDC_TABLE", "METHODS", "METHOD_INSTRUMENT", "MdcValue", "mdc_for",
           "verdict"]

INSTRUMENTS = ("goniometer", "inclinometer", "motion-capture", "imu")

#: The rig's measurement methods: IMU sessions, servo-limb sessions, orientation files.
METHODS = ("imu", "servo", "file")

#: The instrument whose published MDC applies to each of the rig's methods (None: none does).
#: A file from a motion lab holds marker-based 3D motion capture.
METHOD_INSTRUMENT: dict[str, str | None] = {"imu": "imu", "servo": None,
                                            "file": "motion-capture"}

#: The clinical instruments tried, in order, for a method without its own published value.
CLINICAL_REFERENCE = ("goniometer", "inclinometer")


@dataclass(frozen=True)
class MdcValue:
    """One published MDC: degrees (``low``..``high``; one value: equal), its confidence
    (``"MDC95"``, ``"MDC90"``, ``"SDD"``, ``"MSD"``: minimum significant difference,
    ``"MDD"``, ``"MDC"``: confidence not stated where it was read), the
    instrument, the source, and whether it stands in for a method without its own
    (``reference``)."""

    joint: str
    movement: str
    instrument: str
    low: float
    high: float
    kind: str
    source: str
    reference: bool = False

    @property
    def text(self) -> str:
        """For people: ``6°`` or ``8-18°``, the instrument, and ``(reference)`` when it
        stands in for a method without its own value."""
        deg = f"{self.low:g}°" if self.low == self.high else f"{self.low:g}-{self.high:g}°"
        ref = ", reference" if self.reference else ""
        return f"{deg} ({self.kind}, {self.instrument}{ref})"

    def to_json(self) -> dict:
        return {"low_deg": self.low, "high_deg": self.high, "kind": self.kind,
                "instrument": self.instrument, "source": self.source,
                "reference": self.reference}


_ARMSTRONG = ("Armstrong AD et al., J Shoulder Elbow Surg 1998;7(6):573-580 (intratester, "
              "universal goniometer, 95% confidence)")
_WIRTH = ("Wirth MA et al., Sensors 2019;19(23):5297, quoting Reissner L et al., J Orthop Surg "
          "Res 2019;14:173 (goniometric MDD at the wrist)")
_REISSNER_3D = "Reissner L et al., J Orthop Surg Res 2019;14:173 (3D motion capture MDD, 5-12°)"
_POWDEN = ("Powden CJ, Hoch JM, Hoch MC, Man Ther 2015;20(4):524-532 (weight-bearing lunge, "
           "systematic review: 4.6° inter-, 4.7° intra-clinician)")
_HANCOCK_G = "Hancock GE et al., J Exp Orthop 2018;5:46 (long-arm goniometer)"
_HANCOCK_I = "Hancock GE et al., J Exp Orthop 2018;5:46 (digital inclinometer)"
_WILKEN = ("Wilken JM et al., Gait Posture 2012;35(2):301-307 (marker-based gait kinematics "
           "between sessions, about 5°; sagittal plane per McGinley JL et al., Gait Posture "
           "2009;29:360-369)")
_KOLBER = ("Kolber MJ et al., Physiother Theory Pract 2011;27(2):176-184 (digital "
           "inclinometer, interrater)")


def _v(joint, movement, instrument, low, high, kind, source) -> MdcValue:
    return MdcValue(joint, movement, instrument, float(low), float(high), kind, source)


#: (joint, movement, instrument) → the published value.
MDC_TABLE: dict[tuple[str, str, str], MdcValue] = {
    (v.joint, v.movement, v.instrument): v for v in (
        _v("elbow", "flexion", "goniometer", 6, 6, "MDC95", _ARMSTRONG),
        _v("elbow", "extension", "goniometer", 7, 7, "MDC95", _ARMSTRONG),
        _v("elbow", "pronation", "goniometer", 8, 8, "MDC95", _ARMSTRONG),
        _v("elbow", "supination", "goniometer", 8, 8, "MDC95", _ARMSTRONG),
        *(_v("wrist", m, "goniometer", 8, 18, "MDD", _WIRTH)
          for m in ("flexion", "extension", "radial_deviation", "ulnar_deviation")),
        *(_v("wrist", m, "motion-capture", 5, 12, "MDD", _REISSNER_3D)
          for m in ("flexion", "extension", "radial_deviation", "ulnar_deviation")),
        _v("ankle", "dorsiflexion", "goniometer", 4.6, 4.7, "MDC95", _POWDEN),
        _v("knee", "flexion", "goniometer", 10, 10, "MSD", _HANCOCK_G),
        _v("knee", "extension", "goniometer", 10, 10, "MSD", _HANCOCK_G),
        _v("knee", "flexion", "inclinometer", 6, 6, "MSD", _HANCOCK_I),
        _v("knee", "extension", "inclinometer", 6, 6, "MSD", _HANCOCK_I),
        _v("shoulder", "flexion", "inclinometer", 8, 8, "MDC90", _KOLBER),
        _v("shoulder", "abduction", "inclinometer", 4, 4, "MDC90", _KOLBER),
        _v("shoulder", "internal_rotation", "inclinometer", 8, 8, "MDC90", _KOLBER),
        _v("shoulder", "external_rotation", "inclinometer", 9, 9, "MDC90", _KOLBER),
        *(_v(j, m, "motion-capture", 5, 5, "MDC", _WILKEN)
          for j, ms in (("hip", ("flexion", "extension")), ("knee", ("flexion", "extension")),
                        ("ankle", ("dorsiflexion", "plantarflexion"))) for m in ms),
    )
}

NO_MDC = "no published MDC"


def mdc_for(joint: str, movement: str, method: str) -> tuple[MdcValue | None, str]:
    """The MDC that applies to a change of ``joint``'s ``movement`` measured by ``method``
    (:data:`METHODS`) at both visits, and a line for people.

    The method's own instrument's value when published; else the clinical instruments'
    (goniometer, else inclinometer) as a marked reference (``reference=True``, the line says
    the method has none); else ``(None, "no published MDC ...")``.
    """
    if method not in METHOD_INSTRUMENT:
        raise ValueError(f"method must be one of {', '.join(METHODS)}, got {method!r}")
    own = METHOD_INSTRUMENT[method]
    if own is not None and (joint, movement, own) in MDC_TABLE:
        v = MDC_TABLE[(joint, movement, own)]
        return v, v.text
    for inst in CLINICAL_REFERENCE:
        v = MDC_TABLE.get((joint, movement, inst))
        if v is not None:
            ref = MdcValue(v.joint, v.movement, v.instrument, v.low, v.high, v.kind, v.source,
                           reference=True)
            return ref, f"{NO_MDC} for {method}; {ref.text}"
    return None, f"{NO_MDC} for the {joint}'s {movement.replace('_', ' ')}"


def verdict(change_deg: float | None, mdc: MdcValue | None) -> str | None:
    """``"exceeds"`` (|change| above the MDC's upper end), ``"within"`` (at most its lower
    end), ``"uncertain"`` (between the ends of a published range); None without a change or
    an MDC."""
    if change_deg is None or mdc is None:
        return None
    a = abs(float(change_deg))
    if a > mdc.high:
        return "exceeds"
    if a <= mdc.low:
        return "within"
    return "uncertain"
