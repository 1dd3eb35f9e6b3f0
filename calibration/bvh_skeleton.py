"""Segment orientations from a BVH file's joint rotations, per the file's own hierarchy, mapped
onto the rig's segments (ISB frames, :mod:`calibration.frames`).

A BVH joint's rotation turns everything below it; in the rest pose (every channel zero) all
joint frames are the lab's and the bones are the OFFSET vectors. A segment's orientation is
its proximal joint's global rotation (the product of the local rotations from the root down,
each in its CHANNELS order) times the segment's rest-pose frame, built from the rest pose's
geometry:

- limbs (``femur``, ``tibia``, ``humerus``, ``ulna``, ``hand``): +Y from the distal joint (the
  child's position, the hand's fingers or End Site) to the proximal joint, +X the rest pose's
  forward direction made orthogonal to Y, +Z = X × Y;
- trunk (``pelvis``, ``thorax``): +Y up, +X forward, +Z = X × Y (the subject's right);
- foot (``calcn``): +X the horizontal projection of ankle → toe, +Y up, +Z = X × Y.

Up is the BVH convention's +Y; forward is up × right, right the rest pose's left → right hip
(+Z when the file has no two hips). These are the ISB's axes for a subject standing in the
rest pose: a T-pose's humerus frame is bone-fixed with 90° of abduction (the CMU ``.sto``
excerpts of tests/calibration/data/real were made the same way).

Skeletons (:data:`SKELETONS`), by the names of their joints:

========  ====================  ==================================================================
name      source                pelvis, thorax, humerus, ulna, hand, femur, tibia, calcn (right)
========  ====================  ==================================================================
``daz``   CMU BVH conversion    ``hip, chest, rShldr, rForeArm, rHand, rThigh, rShin, rFoot``
          (SL/Daz skeleton)
``mb``    CMU cgspeed           ``Hips, Spine1, RightArm, RightForeArm, RightHand, RightUpLeg,
          (MotionBuilder;       RightLeg, RightFoot``
          Mixamo names too,
          ``mixamorig:`` cut)
``arena``  NaturalPoint Arena     ``Hips, Chest, RightShoulder, RightElbow, (none), RightHip,
          (OptiTrack) export    RightKnee, RightAnkle``
========  ====================  ==================================================================

Left: ``l…`` / ``Left…``. The thorax of ``mb`` falls back to ``Spine2`` / ``Spine`` when there is
no ``Spine1``. A skeleton is recognised by its pelvis and thorax joints and, for ``arena``, its
:data:`SIGNATURES` (every limb joint by name), never by a partial guess.

The ``arena`` skeleton is described by its own HIERARCHY (e.g. the University of Adelaide's
``louise.bvh``): ``Hips`` (6 channels) → ``Chest`` → ``Neck`` → ``Head``; ``Chest`` →
``LeftCollar`` → ``LeftShoulder`` → ``LeftElbow`` → ``LeftWrist`` (End Site); ``Hips`` →
``LeftHip`` → ``LeftKnee`` → ``LeftAnkle`` (End Site), every joint ``CHANNELS 3 Zrotation
Xrotation Yrotation``. Its joints are named where a bone starts, as the BVH format defines a
joint (its rotation turns the bone from it to its child; Meredith M, Maddock S. *Motion capture
file formats explained*, University of Sheffield, CS-01-11, 2001): ``LeftShoulder`` is the
glenohumeral joint and turns the upper arm (→ ``humerus_l``), ``LeftElbow`` the forearm,
``LeftHip`` the thigh, ``LeftKnee`` the shank, ``LeftAnkle`` the foot; ``LeftCollar`` (the
clavicle) has no column. Its rest pose is a T-pose facing +Z (the foot's End Site points
forward) except the wrist's End Site, 14 units *below* the wrist, at 90° to the forearm: not a
hand direction, so this skeleton gives no ``hand`` column (:data:`LACKS` says why).
"""

from __future__ import annotations

import numpy as np

from models import quaternion as Q

__all__ = ["LACKS", "SEGMENT_KINDS", "SIGNATURES", "SKELETONS", "segment_orientations",
           "skeleton_of"]

_SEGS = ("pelvis", "thorax", "humerus", "ulna", "hand", "femur", "tibia", "calcn")

#: Skeleton → column → candidate joint names (first found is used).
SKELETONS: dict[str, dict[str, tuple[str, ...]]] = {
    "daz": {"pelvis": ("hip",), "thorax": ("chest",),
            **{f"{seg}_{s}": (f"{s}{j}",) for s in ("r", "l")
               for seg, j in zip(_SEGS[2:], ("Shldr", "ForeArm", "Hand", "Thigh", "Shin",
                                             "Foot"), strict=True)}},
    "mb": {"pelvis": ("Hips",), "thorax": ("Spine1", "Spine2", "Spine"),
           **{f"{seg}_{s}": (f"{S}{j}",) for s, S in (("r", "Right"), ("l", "Left"))
              for seg, j in zip(_SEGS[2:], ("Arm", "ForeArm", "Hand", "UpLeg", "Leg", "Foot"),
                                strict=True)}},
    "arena": {"pelvis": ("Hips",), "thorax": ("Chest",),
              **{f"{seg}_{s}": (f"{S}{j}",) for s, S in (("r", "Right"), ("l", "Left"))
                 for seg, j in zip(_SEGS[2:], ("Shoulder", "Elbow", "", "Hip", "Knee", "Ankle"),
                                   strict=True) if j}},
}

#: Joints a skeleton must have besides its pelvis and thorax to be recognised (its signature:
#: Arena names a joint where the next bone starts, so its ``LeftShoulder`` is the glenohumeral
#: joint, while MotionBuilder's ``LeftShoulder`` is the clavicle).
SIGNATURES: dict[str, tuple[str, ...]] = {
    "daz": (), "mb": (),
    "arena": ("LeftCollar", "RightCollar", "LeftShoulder", "RightShoulder", "LeftElbow",
              "RightElbow", "LeftWrist", "RightWrist", "LeftHip", "RightHip", "LeftKnee",
              "RightKnee", "LeftAnkle", "RightAnkle"),
}

#: Columns a skeleton does not give, and why.
LACKS: dict[str, dict[str, str]] = {
    "arena": {f"hand_{s}": "a hand bone (Arena's wrist End Site is not along the hand: its rest "
                           "pose has it at 90° to the forearm)" for s in ("r", "l")},
}

#: Column → the segment's name in :data:`calibration.frames.SEGMENT_TO_ISB`.
SEGMENT_KINDS = {"pelvis": "pelvis", "thorax": "thorax",
                 **{f"{seg}_{s}": kind for s in ("r", "l")
                    for seg, kind in (("humerus", "upper-arm"), ("ulna", "forearm"),
                                      ("hand", "hand"), ("femur", "thigh"), ("tibia", "shank"),
                                      ("calcn", "foot"))}}

_PREFIXES = ("mixamorig:", "mixamorig_")


def _clean(name: str) -> str:
    for p in _PREFIXES:
        if name.startswith(p):
            return name[len(p):]
    return name


def skeleton_of(names) -> str | None:
    """The skeleton whose pelvis and thorax joints ``names`` hold (None: none known)."""
    have = {_clean(n) for n in names}
    for sk, cols in SKELETONS.items():
        if any(n in have for n in cols["pelvis"]) and any(n in have for n in cols["thorax"]) \
                and all(n in have for n in SIGNATURES[sk]):
            return sk
    return None


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def _rest_frame(kind: str, top: np.ndarray, tip: np.ndarray, up: np.ndarray,
                forward: np.ndarray) -> np.ndarray:
    if kind == "trunk":
        x, y = forward, up
    elif kind == "foot":
        d = tip - top
        x, y = _unit(d - np.dot(d, up) * up), up
    else:
        y = _unit(top - tip)
        x = _unit(forward - np.dot(forward, y) * y)
    return np.stack([x, y, np.cross(x, y)], axis=-1)


def segment_orientations(names: list[str], parents: list[int], offsets: np.ndarray,
                         tips: np.ndarray, local_q: np.ndarray
                         ) -> tuple[str | None, dict[str, np.ndarray], dict[str, str]]:
    """The skeleton, the segment orientations (ISB frames, segment → lab, (N, 4)
    scalar-first) and, per column of the skeleton the file lacks, the joint it lacks.

    ``names`` the joints in file order, ``parents`` each one's parent index (−1: the root),
    ``offsets`` (J, 3) their OFFSETs, ``tips`` (J, 3) where each joint's bone ends relative to
    it in the rest pose (its first child's offset that is not zero, else its End Site), and
    ``local_q`` (J, N, 4) each joint's rotation per frame (scalar-first, the CHANNELS
    applied in their order)."""
    from scipy.spatial.transform import Rotation

    clean = [_clean(n) for n in names]
    sk = skeleton_of(clean)
    if sk is None:
        return None, {}, {c: "a pelvis and a thorax joint of a known skeleton"
                          for c in SKELETONS["mb"]}
    index = {n: i for i, n in enumerate(clean)}
    rest = np.zeros((len(names), 3))
    glob = np.empty_like(local_q)
    for i, p in enumerate(parents):  # parents come before their children in a BVH
        rest[i] = offsets[i] + (rest[p] if p >= 0 else 0.0)
        glob[i] = local_q[i] if p < 0 else Q.multiply(glob[p], local_q[i])
    cols = SKELETONS[sk]
    found = {c: next((index[n] for n in cand if n in index), None) for c, cand in cols.items()}
    up = np.array([0.0, 1.0, 0.0])
    forward = np.array([0.0, 0.0, 1.0])
    if found["femur_r"] is not None and found["femur_l"] is not None:
        right = rest[found["femur_r"]] - rest[found["femur_l"]]
        forward = _unit(np.cross(up, right - np.dot(right, up) * up))
    out, missing = {}, dict(LACKS.get(sk, {}))
    for col, i in found.items():
        if i is None:
            missing[col] = " or ".join(cols[col])
            continue
        kind = "trunk" if col in ("pelvis", "thorax") else "foot" if col.startswith("calcn") \
            else "limb"
        b = _rest_frame(kind, rest[i], rest[i] + tips[i], up, forward)
        bq = Q.from_rotation(Rotation.from_matrix(b))
        out[col] = Q.canonical(Q.multiply(glob[i], np.broadcast_to(bq, glob[i].shape)))
    return sk, out, missing
