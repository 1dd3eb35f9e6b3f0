"""Segment frames from skin markers (C3D files of motion labs), per the ISB, and the joint
angles the labs' own models store beside the markers.

Marker sets (:data:`MARKER_SETS`)
---------------------------------
Each segment's frame is built from at least three points: markers, or joint centres computed
from markers of the segment above. Frames are ISB (Wu et al. 2002, *J Biomech* 35:543, §2-3;
+Y along the segment towards proximal, +X anterior, +Z to the subject's right on either side;
the foot's +X towards the toes, +Y up), as :mod:`calibration.frames` names them; columns are
named as OpenSim's bodies (``pelvis``, ``femur_r``, ``tibia_r``, ``calcn_r`` and ``_l``).

``plug-in-gait`` — Vicon Plug-in Gait lower body (the Helen Hayes / Davis marker set: Davis RB,
Õunpuu S, Tyburski D, Gage JR, *Hum Mov Sci* 1991;10:575-587; names as Vicon's Plug-in Gait
reference guide):

=========  ======================================  ==========================================
segment    points                                  frame
=========  ======================================  ==========================================
pelvis     LASI, RASI, LPSI, RPSI (or SACR)        Z: LASI → RASI; X: mid-PSIS → mid-ASIS ⊥ Z
femur      HJC (from the pelvis), xKNE, xTHI       Y: KJC → HJC; Z: towards the right, in the
                                                   plane of HJC, xKNE, xTHI (xKNE side of KJC)
tibia      KJC, xANK, xTIB                         Y: AJC → KJC; Z as the femur's (xANK, xTIB)
calcn      AJC, xTOE, tibia                        X: AJC → xTOE; Z: the tibia's Z ⊥ X
=========  ======================================  ==========================================

The foot is Plug-in Gait's uncorrected foot (its long axis AJC → TOE); Plug-in Gait's static
trial offsets (``StaticPlantFlex``, ``StaticRotOff``) are not applied, so dorsiflexion differs
from its ``AnkleAngles`` by a constant (its range does not).

Plug-in Gait's upper body (the same set's arm and trunk markers, names as Vicon's Plug-in Gait
reference guide; frames per Wu G, van der Helm FCT, Veeger HEJ, et al. ISB recommendation on
definitions of joint coordinate systems of various joints ... Part II: shoulder, elbow, wrist and
hand. *J Biomech* 2005;38:981-992, the markers standing in for its landmarks):

=========  ======================================  ==========================================
segment    points                                  frame
=========  ======================================  ==========================================
thorax     CLAV (≈ IJ), STRN (≈ PX), C7, T10       Y: mid(STRN, T10) → mid(CLAV, C7); Z ⊥ the
           (≈ T8)                                  plane of CLAV, C7, mid(STRN, T10), to the
                                                   right (Wu 2005: thorax)
humerus    SJC, EJC, WJC (xSHO, xELB, xWRA, xWRB)  Y: EJC → SJC; Z ⊥ the plane of the upper
                                                   arm and forearm, to the right (Wu 2005:
                                                   humerus, its second option)
ulna       EJC, WJC, xWRA, xWRB                    Y: WJC → EJC; Z: ulnar (xWRB) → radial
(forearm)                                          (xWRA) styloid marker on the right arm,
                                                   the reverse on the left (Wu 2005: forearm)
hand       WJC, xFIN, xWRA, xWRB                   Y: hand centre → WJC; Z as the forearm's
=========  ======================================  ==========================================

Joint centres of the arm, Plug-in Gait's constructions (its "chord function", as for the knee;
as pyCGM reproduces Vicon's, cadop/pyCGM ``pyCGM_Single/pyCGM.py``): the thorax origin a marker
radius behind CLAV; the shoulder's (SJC) ``ShoulderOffset`` + marker radius from xSHO,
perpendicular to the line to the thorax origin, in the plane that holds that line and the
thorax's vertical, downwards; the elbow's (EJC) ``ElbowWidth``/2 + radius from xELB,
perpendicular to the line to the SJC, in the plane that holds that line and the normal of the
plane of SJC, xELB and the wrist bar's midpoint, medially; the wrist's (WJC) ``WristWidth``/2 +
radius from the bar's midpoint, perpendicular to the line to the EJC and to the bar (anterior);
the hand's ``HandThickness``/2 + radius palmar of xFIN. Measurements from the C3D's
``PROCESSING`` (``LShoulderOffset``, ``RElbowWidth``, ``LWristWidth``, ``RHandThickness``, …),
else :data:`DEFAULT_WIDTHS_MM`. On pyCGM's Vicon trial the elbow flexion this gives is Plug-in
Gait's stored ``ElbowAngles`` within 0.01° RMS. A property of the elbow construction, not of
the markers: its flexion axis is normal to a plane through the *lateral* marker, so on an ideal
arm (xELB exactly on the flexion axis, 55 mm lateral of the centre) it reads flexion high near
extension — by 30° at 5°, 10° at 35°, 2-4° at 80°, under 1° beyond 110° — as Plug-in Gait
does. Upper-body columns: ``thorax``, ``humerus_r``, ``ulna_r``, ``hand_r`` (and ``_l``); an
upper-body trial needs no pelvis markers.

``isb-landmarks`` — anatomical landmarks named as Van Sint Jan's atlas (Van Sint Jan S, *Color
Atlas of Skeletal Landmark Definitions*, Churchill Livingstone 2007; e.g. Qualisys' files):
pelvis ``L_IAS, R_IAS, L_IPS, R_IPS``; femur HJC with ``x_FLE, x_FME`` (epicondyles, KJC their
midpoint); tibia KJC with ``x_FAL, x_TAM`` (malleoli, AJC their midpoint); calcaneus ``x_FCC``
with ``x_FM1, x_FM5`` (X: FCC → mid-metatarsals, Z: FM1 → FM5 on the right). This is Wu 2002's
own construction (§2.3, §3.3: the epicondyles and malleoli define the medio-lateral axes).

Joint centres
-------------
- **Hip** (HJC), Plug-in Gait set with the subject's leg lengths in the file (``LLegLength``,
  ``RLegLength``, mm): Davis et al. 1991's regression as Plug-in Gait applies it, in the pelvis
  frame from mid-ASIS, ``x = C cos θ sin β − (AT + r) cos β`` (anterior), ``y = −(AT + r) sin β
  − C cos θ cos β`` (superior), ``|z| = PW/2 − C sin θ`` (lateral), with ``θ = 0.5 rad``,
  ``β = 0.314 rad``, ``C = 0.115 LL − 15.3`` (LL the mean leg length), ``AT = 0.1288 LL_side −
  48.56`` (the ASIS-trochanter distance, or the file's ``xAsisTrocanterDistance``), ``r`` the
  marker radius, ``PW`` the inter-ASIS distance. Otherwise:
- **Hip** (HJC): Harrington ME, Zavatsky AB, Lawson SEM, Yuan Z, Theologis TN. Prediction of the
  hip joint centre in adults, children, and patients with cerebral palsy based on magnetic
  resonance imaging. *J Biomech* 2007;40:595-602: in the pelvis frame from mid-ASIS (mm),
  ``x = −0.24 PD − 9.9``, ``y = −0.30 PW − 10.9``, ``z = ±(0.33 PW + 7.3)`` (PW inter-ASIS
  distance, PD mid-ASIS to mid-PSIS depth).
- **Knee, ankle** with Plug-in Gait's lateral markers only: the centre lies half the joint's
  width plus the marker's radius medial of the lateral marker, perpendicular to the segment
  axis, in the plane of the segment's three markers (Davis 1991's construction, Plug-in Gait's
  "chord function"); widths from the C3D's ``PROCESSING`` parameters (``LKneeWidth``,
  ``RAnkleWidth``, ``MarkerDiameter``, mm) when it has them, else :data:`DEFAULT_WIDTHS_MM`.
  With landmarks on both epicondyles / malleoli, their midpoint.

Model outputs (:func:`model_joint_angles`)
------------------------------------------
Plug-in Gait stores its joint angles as points named ``LHipAngles``, ``LKneeAngles``,
``LAnkleAngles``, ``LElbowAngles`` (and ``R…``): x flexion (ankle: dorsiflexion), y
adduction (knee: varus; ankle: inversion), z internal rotation, degrees, each side signed
anatomically (Plug-in Gait's elbow carries flexion only: its forearm frame shares the
humerus's flexion axis, its y and z are 0); the same
sequence and signs as :func:`calibration.joint_angles.joint_angles` (flexion about the proximal
segment's medio-lateral axis, rotation about the distal long axis, ab/adduction about the
floating axis). They become joint orientations (ISB frames) so the rig reads them as it reads a
joint column of a ``.sto`` (``--child LKneeAngles``).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from calibration.frames import SEGMENT_TO_ISB
from calibration.joint_angles import from_angles
from models import quaternion as Q

__all__ = [
    "DEFAULT_WIDTHS_MM",
    "MARKER_SETS",
    "MODEL_OUTPUTS",
    "SEGMENT_KINDS",
    "THORAX_MARKERS",
    "davis_hip_joint_centres",
    "hip_joint_centres",
    "marker_set_of",
    "model_joint_angles",
    "segment_frames",
]

#: Columns this module builds → the segment's name in :data:`calibration.frames.SEGMENT_TO_ISB`.
SEGMENT_KINDS = {"pelvis": "pelvis", "femur_r": "thigh", "femur_l": "thigh",
                 "tibia_r": "shank", "tibia_l": "shank", "calcn_r": "foot", "calcn_l": "foot",
                 "thorax": "thorax", "humerus_r": "upper-arm", "humerus_l": "upper-arm",
                 "ulna_r": "forearm", "ulna_l": "forearm", "hand_r": "hand", "hand_l": "hand"}

#: The thorax markers of Plug-in Gait's upper body (:data:`MARKER_SETS`).
THORAX_MARKERS = ("CLAV", "STRN", "C7", "T10")

#: Marker set → segment column → the markers it needs (``a|b``: either). The femur needs the
#: pelvis's markers too (its hip joint centre), the tibia the femur's (its knee joint centre).
MARKER_SETS: dict[str, dict[str, tuple[str, ...]]] = {
    "plug-in-gait": {
        "pelvis": ("LASI", "RASI", "LPSI|SACR", "RPSI|SACR"),
        **{f"femur_{s}": (f"{S}KNE", f"{S}THI") for s, S in (("r", "R"), ("l", "L"))},
        **{f"tibia_{s}": (f"{S}KNE", f"{S}THI", f"{S}ANK", f"{S}TIB")
           for s, S in (("r", "R"), ("l", "L"))},
        **{f"calcn_{s}": (f"{S}KNE", f"{S}THI", f"{S}ANK", f"{S}TIB", f"{S}TOE")
           for s, S in (("r", "R"), ("l", "L"))},
        "thorax": THORAX_MARKERS,
        **{f"{seg}_{s}": (*THORAX_MARKERS, f"{S}SHO", f"{S}ELB", f"{S}WRA", f"{S}WRB", *extra)
           for s, S in (("r", "R"), ("l", "L"))
           for seg, extra in (("humerus", ()), ("ulna", ()), ("hand", (f"{S}FIN",)))},
    },
    "isb-landmarks": {
        "pelvis": ("L_IAS", "R_IAS", "L_IPS", "R_IPS"),
        **{f"femur_{s}": (f"{S}_FLE", f"{S}_FME") for s, S in (("r", "R"), ("l", "L"))},
        **{f"tibia_{s}": (f"{S}_FLE", f"{S}_FME", f"{S}_FAL", f"{S}_TAM")
           for s, S in (("r", "R"), ("l", "L"))},
        **{f"calcn_{s}": (f"{S}_FAL", f"{S}_TAM", f"{S}_FCC", f"{S}_FM1", f"{S}_FM5")
           for s, S in (("r", "R"), ("l", "L"))},
    },
}

#: Plug-in Gait's joint-angle outputs → (joint, side).
MODEL_OUTPUTS = {f"{S}{name}Angles": (joint, side)
                 for S, side in (("L", "left"), ("R", "right"))
                 for name, joint in (("Hip", "hip"), ("Knee", "knee"), ("Ankle", "ankle"),
                                     ("Elbow", "elbow"))}

#: Knee and ankle widths, the marker diameter and the arm's measurements (mm) when the file does
#: not give them: an adult's typical values (knee 100 mm, ankle 70 mm; Plug-in Gait's 14 mm
#: markers; shoulder offset 50 mm, elbow width 90 mm, wrist thickness 60 mm, hand thickness
#: 30 mm — the pyCGM subject's own values are 50, 92-96, 61-65 and 30).
DEFAULT_WIDTHS_MM = {"KneeWidth": 100.0, "AnkleWidth": 70.0, "MarkerDiameter": 14.0,
                     "ShoulderOffset": 50.0, "ElbowWidth": 90.0, "WristWidth": 60.0,
                     "HandThickness": 30.0}


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _frame_y_z(y: np.ndarray, z_hint: np.ndarray) -> np.ndarray:
    """Rotation matrices (N, 3, 3), columns X, Y, Z: Y along ``y``, Z ``z_hint`` made ⊥ Y."""
    y = _unit(y)
    z = _unit(z_hint - np.sum(z_hint * y, axis=-1, keepdims=True) * y)
    return np.stack([np.cross(y, z), y, z], axis=-1)


def _frame_x_z(x: np.ndarray, z_hint: np.ndarray) -> np.ndarray:
    """Rotation matrices (N, 3, 3): X along ``x``, Z ``z_hint`` made ⊥ X, Y = Z × X."""
    x = _unit(x)
    z = _unit(z_hint - np.sum(z_hint * x, axis=-1, keepdims=True) * x)
    return np.stack([x, np.cross(z, x), z], axis=-1)


def _quat(m: np.ndarray) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    return Q.canonical(Q.from_rotation(Rotation.from_matrix(m)))


def _pick(markers: Mapping[str, np.ndarray], name: str) -> np.ndarray:
    for n in name.split("|"):
        if n in markers:
            return markers[n]
    raise KeyError(name)


def marker_set_of(labels) -> str | None:
    """The marker set whose pelvis markers ``labels`` hold, or ``plug-in-gait`` for its thorax
    markers alone (an upper-body trial; None: neither)."""
    have = set(labels)
    for name, segs in MARKER_SETS.items():
        if all(any(n in have for n in m.split("|")) for m in segs["pelvis"]):
            return name
    return "plug-in-gait" if all(n in have for n in THORAX_MARKERS) else None


def hip_joint_centres(lasi, rasi, lpsi, rpsi) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The pelvis frames (N, 3, 3) and the left and right hip joint centres (N, 3), lab units,
    from the ASIS and PSIS markers (Harrington et al. 2007; module doc). Marker units are
    taken as mm (C3D's usual ``POINT:UNITS``; the caller scales metres)."""
    mid_a, mid_p = (lasi + rasi) / 2, (lpsi + rpsi) / 2
    pelvis = _frame_x_z(mid_a - mid_p, rasi - lasi)
    pw = np.linalg.norm(rasi - lasi, axis=-1)
    pd = np.linalg.norm(mid_a - mid_p, axis=-1)
    x, y, z = -0.24 * pd - 9.9, -0.30 * pw - 10.9, 0.33 * pw + 7.3
    hjc = [mid_a + np.einsum("nij,nj->ni", pelvis, np.stack([x, y, s * z], axis=-1))
           for s in (-1.0, 1.0)]
    return pelvis, hjc[0], hjc[1]


def davis_hip_joint_centres(pelvis, lasi, rasi, params: Mapping[str, float]
                            ) -> tuple[np.ndarray, np.ndarray]:
    """The left and right hip joint centres (N, 3), mm, from the pelvis frames (N, 3, 3), the
    ASIS markers and Plug-in Gait's subject measurements ``params`` (``LLegLength``,
    ``RLegLength``; optional ``xAsisTrocanterDistance``, ``MarkerDiameter``): Davis et al.
    1991 (module doc)."""
    ll = (params["LLegLength"] + params["RLegLength"]) / 2
    r = params.get("MarkerDiameter", DEFAULT_WIDTHS_MM["MarkerDiameter"]) / 2
    c = 0.115 * ll - 15.3
    theta, beta = 0.5, 0.314
    mid_a = (lasi + rasi) / 2
    half_pw = np.linalg.norm(rasi - lasi, axis=-1) / 2
    out = []
    for S, sign in (("L", -1.0), ("R", 1.0)):
        at = params.get(f"{S}AsisTrocanterDistance", 0.1288 * params[f"{S}LegLength"] - 48.56)
        x = c * np.cos(theta) * np.sin(beta) - (at + r) * np.cos(beta)
        y = -(at + r) * np.sin(beta) - c * np.cos(theta) * np.cos(beta)
        z = sign * (half_pw - c * np.sin(theta))
        local = np.stack(np.broadcast_arrays(x, y, z), axis=-1)
        out.append(mid_a + np.einsum("nij,nj->ni", pelvis, local))
    return out[0], out[1]


def _centre(lateral: np.ndarray, proximal: np.ndarray, third: np.ndarray,
            half_width: float, towards_midline: np.ndarray) -> np.ndarray:
    """A joint centre ``half_width`` medial of its ``lateral`` marker: perpendicular to the
    centre → ``proximal`` line, in the plane of the three points (iterated); medial is the
    in-plane side ``towards_midline`` (N, 3) points to."""
    c = lateral
    n = _unit(np.cross(third - lateral, proximal - lateral))  # the plane's normal
    for _ in range(3):
        medial = _unit(np.cross(n, _unit(proximal - c)))
        flip = np.sum(medial * towards_midline, axis=-1, keepdims=True) < 0
        c = lateral + half_width * np.where(flip, -medial, medial)
    return c


def _pig(markers: Mapping[str, np.ndarray], params: Mapping[str, float],
         hjc: dict[str, np.ndarray], pelvis: np.ndarray) -> dict[str, np.ndarray]:
    out: dict[str, np.ndarray] = {}
    r = params.get("MarkerDiameter", DEFAULT_WIDTHS_MM["MarkerDiameter"]) / 2
    for s, S, sign in (("r", "R", 1.0), ("l", "L", -1.0)):
        try:
            kne, thi = markers[f"{S}KNE"], markers[f"{S}THI"]
        except KeyError:
            continue
        kw = params.get(f"{S}KneeWidth", DEFAULT_WIDTHS_MM["KneeWidth"])
        kjc = _centre(kne, hjc[s], thi, kw / 2 + r, -sign * pelvis[..., 2])
        out[f"femur_{s}"] = _frame_y_z(hjc[s] - kjc, sign * (kne - kjc))
        try:
            ank, tib = markers[f"{S}ANK"], markers[f"{S}TIB"]
        except KeyError:
            continue
        aw = params.get(f"{S}AnkleWidth", DEFAULT_WIDTHS_MM["AnkleWidth"])
        ajc = _centre(ank, kjc, tib, aw / 2 + r, -sign * pelvis[..., 2])
        out[f"tibia_{s}"] = _frame_y_z(kjc - ajc, sign * (ank - ajc))
        if f"{S}TOE" not in markers:
            continue
        toe = markers[f"{S}TOE"]
        out[f"calcn_{s}"] = _frame_x_z(toe - ajc, out[f"tibia_{s}"][..., 2])
    return out


def _upper(markers: Mapping[str, np.ndarray], params: Mapping[str, float]
           ) -> dict[str, np.ndarray]:
    """Plug-in Gait's upper-body markers to ISB frames (Wu 2005; module doc)."""
    if not all(n in markers for n in THORAX_MARKERS):
        return {}
    clav, strn, c7, t10 = (markers[n] for n in THORAX_MARKERS)
    low = (strn + t10) / 2
    thorax = _frame_y_z((clav + c7) / 2 - low, np.cross(c7 - clav, low - clav))
    out = {"thorax": thorax}
    r = params.get("MarkerDiameter", DEFAULT_WIDTHS_MM["MarkerDiameter"]) / 2
    origin = clav - r * thorax[..., 0]  # the thorax origin: a marker radius behind CLAV
    for s, S, sign in (("r", "R", 1.0), ("l", "L", -1.0)):
        try:
            sho, elb, wra, wrb = (markers[f"{S}{n}"] for n in ("SHO", "ELB", "WRA", "WRB"))
        except KeyError:
            continue
        off = params.get(f"{S}ShoulderOffset", DEFAULT_WIDTHS_MM["ShoulderOffset"]) + r
        wand = origin + _unit(sign * np.cross(sho - origin, thorax[..., 0]))
        sjc = _centre(sho, origin, wand, off, -thorax[..., 1])
        bar = sign * (wra - wrb)  # ulnar → radial styloid: the subject's right, either side
        half = params.get(f"{S}ElbowWidth", DEFAULT_WIDTHS_MM["ElbowWidth"]) / 2 + r
        wrist = params.get(f"{S}WristWidth", DEFAULT_WIDTHS_MM["WristWidth"]) / 2 + r
        mid = (wra + wrb) / 2
        # the elbow centre: `half` from xELB, ⊥ the line to the SJC, in the plane that holds
        # that line and the normal of the plane of SJC, xELB and the wrist bar's midpoint
        normal = _unit(np.cross(sjc - elb, mid - elb))
        ejc = _centre(elb, sjc, elb + 500.0 * normal, half, sign * normal)
        wjc = mid + wrist * _frame_y_z(ejc - mid, bar)[..., 0]
        right = _unit(np.cross(wjc - ejc, sjc - ejc))
        out[f"humerus_{s}"] = _frame_y_z(sjc - ejc, right)
        out[f"ulna_{s}"] = _frame_y_z(ejc - wjc, bar)
        if f"{S}FIN" not in markers:
            continue
        fin = markers[f"{S}FIN"]
        palmar = _frame_y_z(wjc - fin, bar)[..., 0]
        t = params.get(f"{S}HandThickness", DEFAULT_WIDTHS_MM["HandThickness"]) / 2 + r
        out[f"hand_{s}"] = _frame_y_z(wjc - (fin + t * palmar), bar)
    return out


def _isb(markers: Mapping[str, np.ndarray], hjc: dict[str, np.ndarray]
         ) -> dict[str, np.ndarray]:
    out: dict[str, np.ndarray] = {}
    for s, S, sign in (("r", "R", 1.0), ("l", "L", -1.0)):
        try:
            fle, fme = markers[f"{S}_FLE"], markers[f"{S}_FME"]
        except KeyError:
            continue
        kjc = (fle + fme) / 2
        out[f"femur_{s}"] = _frame_y_z(hjc[s] - kjc, sign * (fle - fme))
        try:
            fal, tam = markers[f"{S}_FAL"], markers[f"{S}_TAM"]
        except KeyError:
            continue
        ajc = (fal + tam) / 2
        out[f"tibia_{s}"] = _frame_y_z(kjc - ajc, sign * (fal - tam))
        try:
            fcc, fm1, fm5 = markers[f"{S}_FCC"], markers[f"{S}_FM1"], markers[f"{S}_FM5"]
        except KeyError:
            continue
        out[f"calcn_{s}"] = _frame_x_z((fm1 + fm5) / 2 - fcc, sign * (fm5 - fm1))
    return out


def segment_frames(markers: Mapping[str, np.ndarray], params: Mapping[str, float] | None = None,
                   *, scale_to_mm: float = 1.0
                   ) -> tuple[str | None, dict[str, np.ndarray], dict[str, str]]:
    """The marker set, the segment orientations (ISB frames, segment → lab, (N, 4)
    scalar-first) that ``markers`` (label → (N, 3) positions) allow, and for each segment they
    do not allow the markers it lacks (``{"femur_r": "RTHI"}``). ``params``: Plug-in Gait's
    subject measurements (mm); ``scale_to_mm``: the markers' unit in mm (1000 for metres)."""
    params = params or {}
    name = marker_set_of(markers)
    if name is None:
        return None, {}, {seg: "the pelvis markers of a known set"
                          for seg in MARKER_SETS["plug-in-gait"]}
    spec = MARKER_SETS[name]
    m = {k: np.asarray(v, dtype=np.float64) * scale_to_mm for k, v in markers.items()}
    mats: dict[str, np.ndarray] = {}
    if all(any(x in m for x in n.split("|")) for n in spec["pelvis"]):
        pel = [_pick(m, n) for n in spec["pelvis"]]
        pelvis, hjc_l, hjc_r = hip_joint_centres(*pel)
        if name == "plug-in-gait" and "LLegLength" in params and "RLegLength" in params:
            hjc_l, hjc_r = davis_hip_joint_centres(pelvis, pel[0], pel[1], params)
        mats["pelvis"] = pelvis
        hjc = {"l": hjc_l, "r": hjc_r}
        mats.update(_pig(m, params, hjc, pelvis) if name == "plug-in-gait" else _isb(m, hjc))
    if name == "plug-in-gait":
        mats.update(_upper(m, params))
    missing = {seg: ", ".join(n for n in need if not any(x in m for x in n.split("|")))
               for seg, need in spec.items() if seg not in mats}
    return name, {seg: _quat(r) for seg, r in mats.items()}, missing


def _isb_q(segment: str) -> np.ndarray:
    return _quat(SEGMENT_TO_ISB[segment][None])[0]


def model_joint_angles(angles_deg: np.ndarray, name: str) -> np.ndarray:
    """Joint orientations (N, 4), ISB frames (child relative to parent, both ISB), of a lab
    model's joint-angle output ``name`` (:data:`MODEL_OUTPUTS`; ``angles_deg`` (N, 3): x
    flexion, y adduction, z internal rotation)."""
    joint, side = MODEL_OUTPUTS[name]
    a = np.asarray(angles_deg, dtype=np.float64)
    rig = from_angles(a[:, 0], a[:, 1], a[:, 2], joint, side)
    parent, child = {"hip": ("pelvis", "thigh"), "knee": ("thigh", "shank"),
                     "ankle": ("shank", "foot"), "elbow": ("upper-arm", "forearm")}[joint]
    # J_isb = m_p ⊗ J_rig ⊗ m_c*  (the inverse of calibration.frames.joint_to_rig)
    mp = np.broadcast_to(_isb_q(parent), rig.shape)
    mc = np.broadcast_to(_isb_q(child), rig.shape)
    return Q.canonical(Q.multiply(mp, Q.multiply(rig, Q.conjugate(mc))))
