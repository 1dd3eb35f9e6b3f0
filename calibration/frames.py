"""Segment-frame conventions of orientation data: the rig's and the ISB's.

Two conventions name the axes fixed in a body segment (both right-handed, both with +Z to the
body's right for either side, as OpenSim's bodies have it):

============  ==========================================  ==========  ==========
convention    long axis                                    +X          +Z
============  ==========================================  ==========  ==========
``rig``       +X along the segment, pointing distally      distal      right
``isb``       +Y along the segment, pointing proximally    anterior    right
============  ==========================================  ==========  ==========

``isb`` follows the ISB recommendations (Wu et al. 2002, *J Biomech* 35:543, hip and ankle;
Wu et al. 2005, *J Biomech* 38:981, shoulder, elbow, wrist) and is what OpenSim bodies and
OpenSense's IMU tools give; the rig's own frames put the limb long axis on +X (the thesis's and
the constraint file's convention). With the columns of ``M`` the rig's axes in ISB
coordinates::

    X_rig = −Y_isb,   Y_rig = X_isb,   Z_rig = Z_isb,
    M = [[0, 1, 0], [−1, 0, 0], [0, 0, 1]]        (a rotation by −90° about Z)

a **segment** orientation (segment → lab) in ISB frames becomes one in rig frames by
``R_rig = R_isb M`` (``q_rig = q_isb ⊗ m``, ``m`` the quaternion of ``M``), and a **joint**
orientation (child relative to parent, both in the same convention) by
``J_rig = Mᵀ J_isb M`` (``m* ⊗ J ⊗ m``). A direction (a limb axis) given in ISB coordinates
is ``Mᵀ v`` in rig coordinates. The conversion is exact (no fitting): the same recording read
in either convention gives the same joint orientations, hence the same boundary and clinical
angles.
"""

from __future__ import annotations

import math

import numpy as np

from models import quaternion as Q

__all__ = [
    "FRAMES",
    "RIG_TO_ISB",
    "SEGMENT_TO_ISB",
    "direction_to_rig",
    "joint_to_rig",
    "segment_to_rig",
]

#: Conventions an orientation file may be in.
FRAMES = ("rig", "isb")

#: Columns: the rig's X, Y, Z axes in ISB coordinates (see module doc).
RIG_TO_ISB = np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])

#: Each segment's rig axes in its ISB frame (columns): :data:`RIG_TO_ISB`, except the foot,
#: whose long axis lies horizontal in standing: its rig frame has +X towards the toes, +Y
#: superior, +Z right — the ISB calcaneus frame itself (Wu et al. 2002 §3.1). A joint
#: orientation (child ``c`` relative to parent ``p``) is then ``M_p J_rig M_cᵀ`` in ISB frames.
SEGMENT_TO_ISB: dict[str, np.ndarray] = {
    **{s: RIG_TO_ISB for s in ("thorax", "upper-arm", "forearm", "hand", "pelvis", "thigh",
                               "shank")},
    "foot": np.eye(3),
}

#: ``m``: the quaternion of :data:`RIG_TO_ISB` (−90° about Z), scalar-first.
_M = np.array([math.sqrt(0.5), 0.0, 0.0, -math.sqrt(0.5)])
_IDENTITY = np.array([1.0, 0.0, 0.0, 0.0])


def _check(frames: str) -> str:
    if frames not in FRAMES:
        raise ValueError(f"frames must be one of {', '.join(FRAMES)}, got {frames!r}")
    return frames


def _m(segment: str | None) -> np.ndarray:
    """The quaternion of ``segment``'s rig axes in its ISB frame (:data:`SEGMENT_TO_ISB`;
    None: a limb segment, :data:`RIG_TO_ISB`)."""
    if segment is None:
        return _M
    if segment not in SEGMENT_TO_ISB:
        raise ValueError(f"segment must be one of {', '.join(SEGMENT_TO_ISB)}, got {segment!r}")
    return _IDENTITY if segment == "foot" else _M


def segment_to_rig(q, frames: str, segment: str | None = None) -> np.ndarray:
    """Segment orientations (N, 4) (segment → lab, scalar-first) in ``frames`` → rig frames
    (``segment``: its name in :data:`SEGMENT_TO_ISB`, for the foot; None: a limb segment)."""
    q = np.asarray(q, dtype=np.float64)
    if _check(frames) == "rig":
        return q
    return Q.multiply(q, np.broadcast_to(_m(segment), q.shape))


def joint_to_rig(q, frames: str, parent: str | None = None,
                 child: str | None = None) -> np.ndarray:
    """Joint orientations (N, 4) (child relative to parent) in ``frames`` → rig frames:
    ``m_p* ⊗ J ⊗ m_c`` (the segments' names as in :func:`segment_to_rig`)."""
    q = np.asarray(q, dtype=np.float64)
    if _check(frames) == "rig":
        return q
    mp = np.broadcast_to(_m(parent), q.shape)
    mc = np.broadcast_to(_m(child), q.shape)
    return Q.multiply(Q.conjugate(mp), Q.multiply(q, mc))


def direction_to_rig(v, frames: str, segment: str | None = None) -> np.ndarray:
    """A direction (3,) or (N, 3) in segment coordinates of ``frames`` → rig coordinates."""
    v = np.asarray(v, dtype=np.float64)
    if _check(frames) == "rig":
        return v
    return v @ (SEGMENT_TO_ISB[segment] if segment is not None else RIG_TO_ISB)  # Mᵀ v
