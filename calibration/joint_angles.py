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
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calibration.clinical import _check_side, mirror_quaternions, text_table
from calibration.frames import SEGMENT_TO_ISB
from models import quaternion as Q

__all__ = ["CLINICAL_MOVEMENTS", "JOINT_ANGLES", "NORMATIVE", "JointAngleSet",
           "JointRangeOfMotion", "angle_peaks", "constraint_rom", "from_angles", "joint_angles",
           "recorded_rom"]

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


def _joint(name: str) -> JointAngleSet:
    if name not in JOINT_ANGLES:
        raise ValueError(f"joint must be one of {', '.join(JOINT_ANGLES)}, got {name!r}")
    return JOINT_ANGLES[name]


def _side(q: np.ndarray, side: str) -> np.ndarray:
    return mirror_quaternions(q) if _check_side(side) == "left" else q


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
    from scipy.spatial.transform import Rotation

    js = _joint(joint)
    ang = np.stack(np.broadcast_arrays(np.asarray(alpha, float) * js.signs[0],
                                       np.asarray(beta, float) * js.signs[1],
                                       np.asarray(gamma, float) * js.signs[2]), axis=-1)
    isb = Rotation.from_euler("ZXY", np.atleast_2d(ang), degrees=True).as_matrix()
    mp, mc = SEGMENT_TO_ISB[js.parent], SEGMENT_TO_ISB[js.child]
    q = Q.from_rotation(Rotation.from_matrix(mp.T @ isb @ mc))
    return _side(q, side)


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
CLINICAL_MOVEMENTS: dict[str, tuple[str, ...]] = {
    "elbow": ("flexion", "extension", "pronation", "supination"),
    "wrist": ("flexion", "extension", "radial_deviation", "ulnar_deviation"),
    "hip": ("flexion", "extension", "abduction", "adduction", "internal_rotation",
            "external_rotation"),
    "knee": ("flexion", "extension"),
    "ankle": ("dorsiflexion", "plantarflexion", "inversion", "eversion"),
}


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

    def table(self) -> str:
        """The clinical table as text: movement, measured peak, AAOS (:data:`NORMATIVE`)."""
        aaos = NORMATIVE["aaos"][self.joint]
        rows = [("movement", "measured", "AAOS")]
        for m in CLINICAL_MOVEMENTS[self.joint]:
            v = self.peaks.get(m)
            ref = aaos.get(m)
            comparable = (self.joint, m) not in NORMATIVE["not_comparable"]
            rows.append((m.replace("_", " "), "-" if v is None else f"{v:.1f}°",
                         "-" if ref is None or not comparable else f"{ref:.0f}°"))
        lines = [f"{self.joint} range of motion ({self.side} side)", *text_table(rows)]
        if self.arc is not None:
            pos, neg = JOINT_ANGLES[self.joint].movements[0]
            lines.append(f"arc: {pos} from {self.arc[0]:.1f}° to {self.arc[1]:.1f}° "
                         f"(negative: {neg})")
        for (j, m), why in NORMATIVE["not_comparable"].items():
            if j == self.joint:
                lines.append(f"note: {m} not compared with AAOS: {why}")
        lines.append(f"sources: angles = {JOINT_ANGLES[self.joint].source}; "
                     f"AAOS = {NORMATIVE['source']}")
        return "\n".join(lines)

    def to_json(self) -> dict:
        """Plain types: movement → degrees (2 decimals) or None, ``arc``, joint, side."""
        out: dict = {"joint": self.joint, "side": self.side}
        for m in CLINICAL_MOVEMENTS[self.joint]:
            v = self.peaks.get(m)
            out[m] = None if v is None else round(float(v), 2)
        out["arc"] = None if self.arc is None else [round(float(v), 2) for v in self.arc]
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
                 band_deg: float = 5.0) -> JointRangeOfMotion:
    """The range of motion of recorded joint orientations ``q`` (N, 4) (rig frames): each
    movement's farthest angle after a running median over ``window`` samples (an isolated
    spike is not a peak), among the samples at which a goniometer reads it (:func:`_in_band`,
    as :func:`constraint_rom`; a hinge's other angles are out-of-axis motion, not positions,
    and restrict nothing). A movement with no sample in its band is None."""
    from scipy.ndimage import median_filter

    from calibration.joints import JOINTS

    raw = joint_angles(q, joint, side)
    n = len(raw["alpha"])
    ang = {k: median_filter(v, size=min(window, n), mode="nearest") for k, v in raw.items()}
    where = None if JOINTS[joint].kind == "hinge" else _in_band(ang, band_deg)
    peaks = angle_peaks(ang, joint, window=1, where=where)
    return JointRangeOfMotion(joint, _check_side(side),
                              {m: peaks.get(m) for m in CLINICAL_MOVEMENTS[joint]},
                              (float(ang["alpha"].min()), float(ang["alpha"].max())))


def constraint_rom(constraint, joint: str, side: str = "right", *, band_deg: float = 5.0,
                   step_deg: float = 0.5) -> JointRangeOfMotion:
    """The range of motion a constraint allows (:class:`models.constraint.JointConstraint`,
    rig frames), read as a goniometer reads a position: each angle's farthest value among the
    allowed orientations at which a goniometer reads it (:func:`_in_band`). The angle read on
    a ``step_deg`` grid (α on 1°), the others on the band's 1° or, where free, β on 2° and γ
    on 10°. A hinge reads its interval (its other angles are zero); movements a constraint
    does not model are None."""
    from models.oracle import ConstraintOracle

    js = _joint(joint)
    side = _check_side(side)
    if constraint.kind == "hinge":
        h = constraint.hinge
        theta = np.arange(h.min_deg, h.max_deg + 1e-9, min(step_deg, 0.1))
        q = Q.from_axis_angle(np.asarray(h.axis, float), np.radians(theta))
        ang = joint_angles(q, joint, side)
        peaks = angle_peaks(ang, joint, window=1)
        named = set(js.movements[0])
        return JointRangeOfMotion(joint, side, {m: (peaks[m] if m in named else None)
                                                for m in CLINICAL_MOVEMENTS[joint]},
                                  (float(ang["alpha"].min()), float(ang["alpha"].max())))
    oracle = ConstraintOracle(constraint)
    band = np.arange(-band_deg, band_deg + 1e-9, 1.0)
    free = {"beta": np.arange(-90.0, 90.0 + 1e-9, 2.0), "gamma": np.arange(-180.0, 180.0, 10.0)}
    primary = {"alpha": np.arange(-180.0, 180.0, 1.0),
               "beta": np.arange(-90.0, 90.0 + 1e-9, step_deg),
               "gamma": np.arange(-180.0, 180.0, step_deg)}
    out: dict[str, float | None] = {}
    arc = None
    for k, key in enumerate(("alpha", "beta", "gamma")):
        # the other angles as _in_band has them: α at any β and γ, β at α in the band and any
        # γ, γ at α and β in the band
        others = {"alpha": (free["beta"], free["gamma"]), "beta": (band, free["gamma"]),
                  "gamma": (band, band)}[key]
        grids = np.meshgrid(primary[key], *others, indexing="ij")
        rest = [i for i in range(3) if i != k]
        angles: list = [None, None, None]
        angles[k] = grids[0].ravel()
        angles[rest[0]], angles[rest[1]] = grids[1].ravel(), grids[2].ravel()
        hit = angles[k][oracle.is_valid(from_angles(*angles, joint, side))]
        out.update(_pair(hit, *js.movements[k]))
        if k == 0 and hit.size:
            arc = (float(hit.min()), float(hit.max()))
    return JointRangeOfMotion(joint, side, {m: out.get(m) for m in CLINICAL_MOVEMENTS[joint]},
                              arc)
