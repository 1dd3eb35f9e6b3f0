"""The guided calibration protocols: what the patient is asked to do, as a function of time.

:class:`CalibrationProtocol` (the shoulder, two sensors) and :class:`LimbCalibrationProtocol`
(an arm or a leg, one sensor per segment; below).

Shoulder: two phases, then free recording (frames of :mod:`calibration.alignment`: +X inferior
along the arm, +Y anterior, +Z = X × Y; flexion is a positive rotation about +Z):

1. **static** (``static_s`` seconds): neutral pose, arm hanging at the side, forearm forward;
   the joint orientation is the identity.
2. **functional** (``functional_s`` seconds): flexion/extension in the sagittal plane,
   ``θ(t) = A(t) sin(2π t / period_s)``, flexion first; ``A = flexion_deg`` while
   ``sin > 0``, ``extension_deg`` otherwise. Joint orientation ``Rz(θ)``.

:meth:`CalibrationProtocol.joint` gives the scripted joint orientation (a simulator drives the
simulated patient with it, through the patient's own range limits); :meth:`windows` gives the
time windows a recorder slices the samples by. Times are seconds from the start of the
protocol.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from calibration.clinical import mirror_quaternions
from calibration.joint_angles import from_angles
from calibration.joints import LIMB_CHAINS
from models import quaternion as Q

__all__ = ["LIMB_CHAINS", "CalibrationProtocol", "LimbCalibrationProtocol"]

_Z = np.array([0.0, 0.0, 1.0])


@dataclass(frozen=True)
class CalibrationProtocol:
    """Durations (s) and amplitudes (deg) of the calibration movements (see module doc).

    ``settle_s`` at the start and end of each phase are excluded from its window (the patient
    getting into position).
    """

    static_s: float = 5.0
    functional_s: float = 10.0
    flexion_deg: float = 30.0
    extension_deg: float = 15.0
    period_s: float = 5.0
    settle_s: float = 0.5

    def __post_init__(self) -> None:
        for name in ("static_s", "functional_s", "period_s"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)!r}")
        if not 0 <= 2 * self.settle_s < min(self.static_s, self.functional_s):
            raise ValueError("settle_s must leave part of each phase")

    @property
    def duration_s(self) -> float:
        """Total length of the protocol, seconds."""
        return self.static_s + self.functional_s

    def windows(self) -> dict[str, tuple[float, float]]:
        """``{"static": (t0, t1), "functional": (t0, t1)}``, seconds from the protocol start."""
        s = self.settle_s
        return {
            "static": (s, self.static_s - s),
            "functional": (self.static_s + s, self.duration_s - s),
        }

    def flexion_angle(self, t) -> np.ndarray:
        """Scripted flexion angle θ(t), radians (0 during the static phase and after the end)."""
        t = np.atleast_1d(np.asarray(t, dtype=np.float64))
        u = t - self.static_s
        s = np.sin(2.0 * math.pi * u / self.period_s)
        amp = np.where(s > 0, math.radians(self.flexion_deg), math.radians(self.extension_deg))
        active = (u >= 0) & (u <= self.functional_s)
        return np.where(active, amp * s, 0.0)

    def joint(self, t) -> np.ndarray:
        """Scripted joint orientation (N, 4), limb relative to thorax, at times ``t`` (N,)."""
        return Q.from_axis_angle(_Z, self.flexion_angle(t))


#: Default amplitudes (flexion, extension) of each joint's functional movement, degrees: a
#: comfortable part of every adult's range (AAOS 1965); the elbow and the knee only flex (their
#: extension stops at about 0°), the ankle's "flexion" is dorsiflexion.
FUNCTIONAL_AMPLITUDES: dict[str, tuple[float, float]] = {
    "shoulder": (30.0, 15.0), "elbow": (60.0, 0.0), "wrist": (35.0, 30.0),
    "hip": (30.0, 10.0), "knee": (60.0, 0.0), "ankle": (12.0, 20.0),
}


@dataclass(frozen=True)
class LimbCalibrationProtocol:
    """The calibration of a limb with one sensor per segment (4 segments, 3 joints).

    Phases, one after the other (seconds from the protocol start; :meth:`windows`):
    1. ``"static"`` (``static_s``): the neutral standing pose — arm hanging at the side, palm
       facing the thigh, fingers down (arm); standing straight, foot flat and pointing forward
       (leg). Every joint at its clinical zero (:func:`calibration.joint_angles.from_angles`
       with all angles 0; the shoulder's joint orientation is the identity).
    2. one movement per joint, proximal to distal, named after the joint (``"shoulder"``,
       ``"elbow"``, ``"wrist"`` / ``"hip"``, ``"knee"``, ``"ankle"``; ``movement_s`` each):
       that joint's flexion/extension — the rotation about its medio-lateral axis, the
       clinical angle α of :mod:`calibration.joint_angles` (shoulder: ``Rz(θ)`` as in
       :class:`CalibrationProtocol`) — ``θ(t) = A(t) sin(2π u / period_s)``, flexion first,
       ``A`` the joint's flexion amplitude while ``sin > 0`` and its extension amplitude
       otherwise (:data:`FUNCTIONAL_AMPLITUDES`; 0 for the elbow's and knee's extension, which
       then rest at 0° for half of each period); every other joint stays at its zero.

    ``settle_s`` at the start and end of each phase are excluded from its window. The movement
    of a joint is what calibrates its segments' medio-lateral axes (the parent's and the
    child's); gravity in the static pose gives each segment's long axis (the foot's superior
    axis).
    """

    limb: str = "arm"
    static_s: float = 5.0
    movement_s: float = 8.0
    period_s: float = 4.0
    settle_s: float = 0.5
    amplitudes: tuple[tuple[str, float, float], ...] | None = None

    def __post_init__(self) -> None:
        if self.limb not in LIMB_CHAINS:
            raise ValueError(f"limb must be one of {', '.join(LIMB_CHAINS)}, got {self.limb!r}")
        for name in ("static_s", "movement_s", "period_s"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)!r}")
        if not 0 <= 2 * self.settle_s < min(self.static_s, self.movement_s):
            raise ValueError("settle_s must leave part of each phase")
        for joint, flex, ext in self.amplitudes or ():
            if joint not in self.joints:
                raise ValueError(f"amplitudes: {joint!r} is not a joint of the {self.limb}")
            if not (0 <= flex < 90 and 0 <= ext < 90 and flex > 0):
                raise ValueError(f"amplitudes of {joint}: expected 0 < flexion < 90 and "
                                 f"0 <= extension < 90 degrees, got {flex}, {ext}")

    @property
    def joints(self) -> tuple[str, ...]:
        """The limb's joints, proximal to distal."""
        return tuple(j for j, _, _ in LIMB_CHAINS[self.limb])

    @property
    def segments(self) -> tuple[str, ...]:
        """The limb's segments, proximal to distal (4)."""
        chain = LIMB_CHAINS[self.limb]
        return (chain[0][1], *(c for _, _, c in chain))

    def amplitude(self, joint: str) -> tuple[float, float]:
        """(flexion, extension) amplitudes of ``joint``'s movement, degrees."""
        for j, flex, ext in self.amplitudes or ():
            if j == joint:
                return flex, ext
        return FUNCTIONAL_AMPLITUDES[joint]

    @property
    def duration_s(self) -> float:
        """Total length of the protocol, seconds."""
        return self.static_s + len(self.joints) * self.movement_s

    def windows(self) -> dict[str, tuple[float, float]]:
        """``{"static": (t0, t1), joint: (t0, t1), ...}``, seconds from the protocol start."""
        s = self.settle_s
        out = {"static": (s, self.static_s - s)}
        for i, joint in enumerate(self.joints):
            t0 = self.static_s + i * self.movement_s
            out[joint] = (t0 + s, t0 + self.movement_s - s)
        return out

    def angles(self, t) -> np.ndarray:
        """Scripted flexion angle of each joint (N, 3), degrees, at times ``t`` (N,) (0 outside
        its movement)."""
        t = np.atleast_1d(np.asarray(t, dtype=np.float64))
        out = np.zeros((len(t), len(self.joints)))
        for i, joint in enumerate(self.joints):
            flex, ext = self.amplitude(joint)
            u = t - (self.static_s + i * self.movement_s)
            s = np.sin(2.0 * math.pi * u / self.period_s)
            active = (u >= 0) & (u <= self.movement_s)
            out[:, i] = np.where(active, np.where(s > 0, flex, ext) * s, 0.0)
        return out

    def joint_orientations(self, t, side: str = "right") -> np.ndarray:
        """Scripted joint orientations (N, 3, 4), rig frames (child relative to parent,
        :mod:`calibration.frames`), at times ``t`` (N,)."""

        a = self.angles(t)
        out = np.empty((len(a), len(self.joints), 4))
        for i, joint in enumerate(self.joints):
            if joint == "shoulder":
                theta = np.radians(a[:, i])
                q = Q.from_axis_angle(_Z, theta)
                if side == "left":
                    q = mirror_quaternions(q)
                out[:, i] = q
            else:
                out[:, i] = from_angles(a[:, i], 0.0, 0.0, joint, side)
        return out
