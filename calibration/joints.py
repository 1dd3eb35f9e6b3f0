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
from models.limb import LIMB_CHAINS  # limb → ((joint, parent, child), ...), proximal first

__all__ = ["JOINTS", "LIMB_CHAINS", "JointSpec", "hinge_angles", "joint_mismatch", "joint_spec",
           "off_axis_angles"]




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
    if (c.kind == "hinge") != (spec.kind == "hinge"):
        return f"holds {c.kind} limits, but the {for_joint} is a {spec.kind} joint"
    if spec.hinge_axis is not None and c.hinge is not None:
        axis = np.asarray(c.hinge.axis, dtype=np.float64)
        if float(axis @ np.asarray(spec.hinge_axis)) < math.cos(math.radians(30.0)):
            return (f"is a hinge about {np.round(axis, 3).tolist()}, but the {for_joint}'s "
                    f"turns about {list(spec.hinge_axis)} (rig segment frames)")
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
