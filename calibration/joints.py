"""The joints the rig measures: each one's kind, segments and (for a hinge) axis.

One table (:data:`JOINTS`) that the boundary extraction, the clinical angles, the readers of
recordings and the simulated patients agree on. Segment frames are the rig's
(:mod:`calibration.frames`: +X along the segment distally, +Y anterior, +Z to the body's right;
the foot +X to the toes, +Y superior), the same for either side: left limbs are mirrored by the
clinical code, not here.

======== =========== =========== ========== ====================================================
joint    parent      child       kind       limits (:mod:`models.constraint`)
======== =========== =========== ========== ====================================================
shoulder thorax      upper-arm   ball       swing region of the arm's long axis + twist
elbow    upper-arm   forearm     hinge      flexion about +Z (the forearm swings anteriorly)
wrist    forearm     hand        two-axis   swing region of the hand's long axis, narrow twist
hip      pelvis      thigh       ball       swing region of the thigh's long axis + twist
knee     thigh       shank       hinge      flexion about −Z (the shank swings posteriorly)
ankle    shank       foot        two-axis   swing region of the foot's long axis, narrow twist
======== =========== =========== ========== ====================================================

A hinge's angle is the rotation about its axis (the twist about it, :func:`hinge_angles`), so
with these axes it equals the clinical flexion angle of :mod:`calibration.joint_angles` for a
motion about the axis (the elbow's α, the knee's Grood-Suntay flexion), on either side. The
forearm's pronation and supination happen between the radius and the ulna, within the forearm
segment of a two-segment model: an elbow hinge leaves them out, and a recording's rotation of
the forearm about its long axis shows as out-of-axis motion of the hinge (reported, not a
limit).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from models import quaternion as Q
from models.kinds import get_kind
from models.limb import LIMB_CHAINS  # limb → ((joint, parent, child), ...), proximal first

__all__ = ["JOINTS", "LIMB_CHAINS", "JointSpec", "columns_mismatch", "hinge_angles",
           "joint_mismatch", "joint_of_columns", "joint_spec", "off_axis_angles",
           "segment_of_column"]




@dataclass(frozen=True)
class JointSpec:
    """One joint: name, kind, segments (parent → child), limb (``arm``/``leg``), hinge axis
    (parent = child frame at the hinge's zero; None unless a hinge), and the child's long axis
    in its own frame (the direction a swing region is drawn for)."""

    name: str
    kind: str
    parent: str
    child: str
    limb: str
    hinge_axis: tuple[float, float, float] | None = None
    limb_axis: tuple[float, float, float] = (1.0, 0.0, 0.0)


_KINDS = {"shoulder": ("ball", None), "elbow": ("hinge", (0.0, 0.0, 1.0)),
          "wrist": ("two-axis", None), "hip": ("ball", None),
          "knee": ("hinge", (0.0, 0.0, -1.0)), "ankle": ("two-axis", None)}

#: The joints, proximal to distal per limb (module doc).
JOINTS: dict[str, JointSpec] = {
    name: JointSpec(name, _KINDS[name][0], parent, child, limb, _KINDS[name][1])
    for limb, chain in LIMB_CHAINS.items() for name, parent, child in chain
}


def joint_spec(name: str) -> JointSpec:
    """The joint called ``name``; ValueError naming the joints otherwise."""
    if name not in JOINTS:
        raise ValueError(f"joint must be one of {', '.join(JOINTS)}, got {name!r}")
    return JOINTS[name]


def joint_mismatch(c, *, for_joint: str | None, for_side: str | None = None) -> str | None:
    """Why the limits ``c`` (:class:`models.constraint.JointConstraint`) cannot serve as
    ``for_joint``'s on ``for_side`` (each None: unknown), as the end of a sentence (``"is for
    the knee, not the shoulder"``); None when they can.

    The one check every path makes before it reads a file as a joint's (a constraint file, a
    model's embedded constraint, a rig configuration's constraint, a session's boundary): a
    joint or side the file names must be the one asked for, and the limits must fit the joint
    of :data:`JOINTS` even when the file names none — a hinge's interval is no swing region,
    so a hinge cannot stand for a ball or two-axis joint nor the reverse, and a hinge turns
    about the joint's own axis (the elbow's +Z, the knee's −Z: read as the other, flexion
    would change sign).
    """
    if c.joint is not None and for_joint is not None and c.joint != for_joint:
        return f"is for the {c.joint}, not the {for_joint}"
    if c.side is not None and for_side is not None and c.side != for_side:
        return f"is for the {c.side} side, not the {for_side}"
    spec = JOINTS.get(for_joint) if for_joint is not None else None
    if spec is None:
        return None
    if c.joint_kind.swing_twist != get_kind(spec.kind).swing_twist:
        return f"holds {c.kind} limits, but the {for_joint} is a {spec.kind} joint"
    own = c.joint_kind.flexion_axis(c)  # a hinge's or forearm's (None: a swing-twist joint)
    if spec.hinge_axis is not None and own is not None:
        axis = np.asarray(own, dtype=np.float64)
        if float(axis @ np.asarray(spec.hinge_axis)) < math.cos(math.radians(30.0)):
            return (f"is a {c.kind} about {np.round(axis, 3).tolist()}, but the {for_joint}'s "
                    f"turns about {list(spec.hinge_axis)} (rig segment frames)")
    return None


#: Names of each rig segment in files from other tools: OpenSim's bodies (``femur_r``,
#: ``calcn_r``, ``ulna_r``: Rajagopal 2016, Gait2392) and OpenSense's IMU columns
#: (``femur_r_imu``), ISB's segment names, Xsens MVN's (``RightUpperLeg``, ``T8``), and ours.
_SEGMENT_WORDS: dict[str, tuple[str, ...]] = {
    "thorax": ("thorax", "torso", "trunk", "chest", "sternum", "t8"),
    "pelvis": ("pelvis", "sacrum"),
    "upper-arm": ("upperarm", "humerus"),
    "forearm": ("forearm", "ulna", "radius", "lowerarm"),
    "hand": ("hand",),
    "thigh": ("thigh", "femur", "upperleg"),
    "shank": ("shank", "tibia", "shin", "fibula", "lowerleg", "calf"),
    "foot": ("foot", "calcn", "calcaneus", "talus"),
}
_WORD_SEGMENT = {w: seg for seg, words in _SEGMENT_WORDS.items() for w in words}
_SIDE_WORDS = {"r": "right", "right": "right", "l": "left", "left": "left"}
_NOISE_WORDS = {"imu", "sensor", "segment", "body", "orientation", "quat", "q"}


def segment_of_column(name: str) -> tuple[str | None, str | None]:
    """The rig segment and side a file's column name says, each None when it says none:
    ``"femur_r_imu"`` → ``("thigh", "right")``, ``"RightForeArm"`` → ``("forearm",
    "right")``, ``"thorax"`` → ``("thorax", None)``, ``"s1"`` → ``(None, None)``."""
    import re

    words = re.findall(r"[A-Z]?[a-z]+|[A-Z]+(?![a-z])|\d+", name.replace("-", "_"))
    words = [w.lower() for w in words]
    side = None
    rest = []
    for i, w in enumerate(words):
        if w in _SIDE_WORDS and (len(w) > 1 or i > 0 or len(words) > 1):
            side = _SIDE_WORDS[w]
        elif w not in _NOISE_WORDS:
            rest.append(w)
    joined = "".join(rest)
    if joined in _WORD_SEGMENT:
        return _WORD_SEGMENT[joined], side
    for w in rest:  # "t8", a body name beside a number
        if w in _WORD_SEGMENT:
            return _WORD_SEGMENT[w], side
    return None, side


def columns_mismatch(columns, segments, *, side: str | None = None,
                     what: str = "columns") -> str | None:
    """Why file ``columns`` cannot be the rig ``segments`` (same order; None: any) on
    ``side``, judged by their names (:func:`segment_of_column`; a name that says nothing is
    not judged); None when nothing contradicts: ``"column 'femur_r' is a thigh, not the
    upper-arm"``. A hint naming the joint the columns are for follows where one fits."""
    sides = set()
    for col, seg in zip(columns, segments, strict=True):
        found, s = segment_of_column(col)
        if found is not None and seg is not None and found != seg:
            return f"column {col!r} is a {found}, not the {seg}"
        if s is not None:
            if side is not None and s != side:
                return f"column {col!r} is a {s} segment, but the {side} side is asked"
            sides.add(s)
    if len(sides) > 1:
        return f"{what} {', '.join(map(repr, columns))} mix the left and right sides"
    return None


def joint_of_columns(reference: str | None, limb: str) -> str | None:
    """The joint whose parent and child segments a reference and a limb column name, if
    their names say so (``pelvis``, ``femur_r`` → ``hip``); else None."""
    if reference is None:
        return None
    parent, child = segment_of_column(reference)[0], segment_of_column(limb)[0]
    for spec in JOINTS.values():
        if (spec.parent, spec.child) == (parent, child):
            return spec.name
    return None


def hinge_angles(q, axis) -> np.ndarray:
    """Hinge angle (degrees, (N,)) of joint orientations ``q`` (N, 4) about ``axis``: the twist
    about it (:func:`models.quaternion.twist_angle`), so a rotation about the axis reads its
    own angle and out-of-axis motion is ignored."""
    q = Q.check_quaternions(np.atleast_2d(q), normalize=True, name="joint orientation")
    return np.degrees(Q.twist_angle(q, Q.check_vectors(axis, name="hinge axis")))


def off_axis_angles(q, axis) -> np.ndarray:
    """How far (degrees, (N,)) each joint orientation is from the nearest rotation about
    ``axis``: the angle of its swing part about the axis (the geodesic distance to the hinge's
    one-parameter subgroup)."""
    q = Q.check_quaternions(np.atleast_2d(q), normalize=True, name="joint orientation")
    swing, _ = Q.swing_twist(q, Q.check_vectors(axis, name="hinge axis"))
    return np.degrees(Q.angle(swing))
