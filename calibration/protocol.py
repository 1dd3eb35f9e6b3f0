"""The guided calibration protocols: what the patient is asked to do, as a function of time.

:class:`CalibrationProtocol` (the shoulder, two sensors) and :class:`LimbCalibrationProtocol`
(an arm or a leg, one sensor per segment; below) are what a recording's calibration asks;
:class:`ServoMoveProtocol` is what ``rig calibrate`` asks of a servo arm: the zero pose, then one
single-axis move per servo (built by :func:`servo_moves`, each named in clinical words by
:func:`servo_movement`), so that every servo's direction is seen on its own.

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

from calibration.clinical import isb_angles, mirror_quaternions
from calibration.joint_angles import JOINT_ANGLES, from_angles, joint_angles
from calibration.joints import LIMB_CHAINS
from models import quaternion as Q

__all__ = ["AT_A_STOP", "LIMB_CHAINS", "MOVEMENT_WORDS", "CalibrationProtocol",
           "LimbCalibrationProtocol", "ServoMove", "ServoMoveProtocol", "servo_movement",
           "servo_moves"]

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


#: The movement each servo's single-axis move is named by (:func:`servo_movement`), in words a
#: person moving the arm can follow: joint → movement → what to do.
MOVEMENT_WORDS: dict[str, dict[str, str]] = {
    "shoulder": {"flexion": "raise the arm forwards", "extension": "move the arm backwards",
                 "abduction": "raise the arm sideways",
                 "adduction": "move the arm in across the body",
                 "internal_rotation": "turn the arm inwards about its long axis",
                 "external_rotation": "turn the arm outwards about its long axis"},
    "elbow": {"flexion": "bend the elbow", "extension": "straighten the elbow",
              "varus": "tilt the forearm inwards", "valgus": "tilt the forearm outwards",
              "pronation": "turn the palm backwards", "supination": "turn the palm forwards"},
    "wrist": {"flexion": "bend the hand towards the palm", "extension": "bend the hand back",
              "ulnar_deviation": "tilt the hand towards the little finger",
              "radial_deviation": "tilt the hand towards the thumb",
              "pronation": "turn the hand palm backwards",
              "supination": "turn the hand palm forwards"},
    "hip": {"flexion": "raise the thigh forwards", "extension": "move the leg backwards",
            "adduction": "move the leg in across the other",
            "abduction": "move the leg out sideways",
            "internal_rotation": "turn the leg inwards", "external_rotation": "turn the leg "
                                                                              "outwards"},
    "knee": {"flexion": "bend the knee", "extension": "straighten the knee",
             "adduction": "tilt the shank inwards", "abduction": "tilt the shank outwards",
             "internal_rotation": "turn the shank inwards",
             "external_rotation": "turn the shank outwards"},
    "ankle": {"dorsiflexion": "pull the foot up", "plantarflexion": "point the foot down",
              "inversion": "turn the sole inwards", "eversion": "turn the sole outwards",
              "internal_rotation": "turn the foot inwards",
              "external_rotation": "turn the foot outwards"},
}

#: Movements a servo's move avoids from the zero pose when the other way is free: the pose
#: is at (or next to) their stop — the trunk stops the hanging arm's adduction, a straight
#: elbow or knee extends no further.
AT_A_STOP: frozenset[tuple[str, str]] = frozenset({
    ("shoulder", "adduction"), ("elbow", "extension"), ("knee", "extension")})


def servo_movement(joint: str, axis, side: str = "right") -> str:
    """The clinical movement a positive turn about ``axis`` (the joint at its zero, the
    identity) makes: ``"abduction"``, ``"flexion"``, ...; ``""`` for a joint without clinical
    angles.

    Parameters
    ----------
    joint : str
        Joint name (``shoulder``, ``elbow``, ``wrist``, ``hip``, ``knee``, ``ankle``).
    axis : (3,) array_like
        The servo's axis in the joint's parent frame (rig frames, :mod:`calibration.frames`).
    side : "right" or "left"

    Notes
    -----
    A 10° turn about ``axis`` is named by its largest clinical angle: the shoulder's by the ISB
    plane of elevation (0° abduction, 90° flexion, ±180° adduction, −90° extension) when it
    elevates the arm, else by its axial rotation (:func:`calibration.clinical.isb_angles`,
    internal positive); the other joints by their Cardan angles
    (:func:`calibration.joint_angles.joint_angles`, :data:`~calibration.joint_angles.
    JOINT_ANGLES`' movement names).
    """
    side = side if side in ("left", "right") else "right"
    q = Q.from_axis_angle(np.asarray(axis, dtype=np.float64), math.radians(10.0))
    if joint == "shoulder":
        a = isb_angles(np.atleast_2d(q), side)
        if a["elevation"][0] > 5.0:
            plane = float(a["plane_of_elevation"][0])
            names = ((0.0, "abduction"), (90.0, "flexion"), (180.0, "adduction"),
                     (-180.0, "adduction"), (-90.0, "extension"))
            return min(names, key=lambda pn: abs(plane - pn[0]))[1]
        return "internal_rotation" if a["axial_rotation"][0] > 0 else "external_rotation"
    if joint not in JOINT_ANGLES:
        return ""
    ang = joint_angles(q, joint, side)
    values = [float(ang[k][0]) for k in ("alpha", "beta", "gamma")]
    i = int(np.argmax(np.abs(values)))
    return JOINT_ANGLES[joint].movements[i][0 if values[i] > 0 else 1]


def _opposite(joint: str, movement: str) -> str:
    """The movement a negative turn makes (its pair's other name)."""
    pairs = ([("flexion", "extension"), ("abduction", "adduction"),
              ("internal_rotation", "external_rotation")] if joint == "shoulder"
             else list(JOINT_ANGLES[joint].movements) if joint in JOINT_ANGLES else [])
    for a, b in pairs:
        if movement in (a, b):
            return b if movement == a else a
    return ""


@dataclass(frozen=True)
class ServoMove:
    """One servo's move of a :class:`ServoMoveProtocol`: from the zero pose, its joint turned
    about the servo's axis alone by ``angle_deg``, held, and back.

    Attributes
    ----------
    joint : str
        The joint the servo turns.
    index : int
        The joint's place in the limb (0 for a rig of one joint).
    servo : str
        How prompts and messages name the servo (``servo ID 2 (shoulder-elevation)``).
    axis : (3,) tuple of float
        The servo's axis, in the joint's parent frame (rig frames), unit.
    angle_deg : float
        Signed turn about ``axis`` (the servo's own angle with direction +1).
    movement : str
        The clinical movement it makes (:func:`servo_movement`), ``""`` if none is named.
    """

    joint: str
    index: int
    servo: str
    axis: tuple[float, float, float]
    angle_deg: float
    movement: str = ""

    def __post_init__(self) -> None:
        a = np.asarray(self.axis, dtype=np.float64)
        n = float(np.linalg.norm(a))
        if a.shape != (3,) or not n > 0:
            raise ValueError(f"{self.servo}: axis must be a non-zero 3-vector, got {self.axis!r}")
        object.__setattr__(self, "axis", tuple(float(v) for v in a / n))
        object.__setattr__(self, "angle_deg", float(self.angle_deg))

    @property
    def words(self) -> str:
        """What the person does, e.g. ``raise the arm sideways (abduction)``."""
        said = MOVEMENT_WORDS.get(self.joint, {}).get(self.movement)
        name = self.movement.replace("_", " ")
        if said:
            return f"{said} ({name})"
        sign = "positive" if self.angle_deg > 0 else "negative"
        return f"turn it the {sign} way about ({', '.join(f'{v:g}' for v in self.axis)})"

    def prompt(self, hold_s: float) -> str:
        """The prompt said as the move begins."""
        return (f"{self.joint}: {self.words} by about {abs(self.angle_deg):.0f}°, turning "
                f"{self.servo} alone; hold {hold_s:g} s, then back to the zero pose")


@dataclass(frozen=True)
class ServoMoveProtocol:
    """The calibration of a servo arm's directions: one single-axis move per servo.

    Phases (seconds from the protocol start; :meth:`windows`):

    1. ``"static"`` (``static_s``): the zero pose, every joint at its kinematics' zero (the
       identity: for the arm, standing straight, arm hanging at the side, palm facing the
       thigh).
    2. one move per servo, in the order of :attr:`moves`, each ``period_s = 2 move_s + hold_s
       + rest_s`` long and named after its servo: the servo's joint turned about the servo's
       axis alone (every other servo of the arm at its zero), ``θ(u) = A s(u / move_s)`` out,
       held at ``A`` for ``hold_s``, ``A (1 − s(·))`` back, then ``rest_s`` at the zero pose
       (``s`` the smoothstep ``3x² − 2x³``, ``A`` the move's ``angle_deg``).

    A move turns one servo by ``A`` and no other, so each servo's direction is seen on its
    own, and a servo that turns during another's move is a swapped ID or cable.

    Attributes
    ----------
    moves : tuple of ServoMove
    joints : tuple of str
        The limb's joints, proximal to distal (the postures' J).
    limb : str or None
        ``"arm"`` or ``"leg"`` (a whole-limb patient performs it), None for a rig of one joint.
    static_s, move_s, hold_s, rest_s, settle_s : float
        Durations, seconds; ``settle_s`` at each end of the static phase is left out of its
        window.
    """

    moves: tuple[ServoMove, ...]
    joints: tuple[str, ...]
    limb: str | None = None
    static_s: float = 5.0
    move_s: float = 1.5
    hold_s: float = 1.0
    rest_s: float = 1.0
    settle_s: float = 0.5

    def __post_init__(self) -> None:
        # a protocol read back from JSON (a simulator in a process of its own) has lists and
        # mappings: make them the dataclass's tuples
        object.__setattr__(self, "moves", tuple(
            m if isinstance(m, ServoMove) else ServoMove(**m) for m in self.moves))
        object.__setattr__(self, "joints", tuple(self.joints))
        if not self.moves:
            raise ValueError("a servo-move protocol needs at least one move")
        for name in ("static_s", "move_s"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)!r}")
        for name in ("hold_s", "rest_s"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"{name} must be >= 0, got {getattr(self, name)!r}")
        if not 0 <= 2 * self.settle_s < self.static_s:
            raise ValueError("settle_s must leave part of the static phase")
        for m in self.moves:
            if not 0 <= m.index < len(self.joints) or self.joints[m.index] != m.joint:
                raise ValueError(f"{m.servo}: joint {m.joint!r} is not joint {m.index} of "
                                 f"{', '.join(self.joints)}")
        names = [m.servo for m in self.moves]
        dup = next((n for n in names if names.count(n) > 1), None)
        if dup is not None:
            raise ValueError(f"{dup} has two moves")

    @property
    def period_s(self) -> float:
        """One move's length, seconds: out, hold, back, rest."""
        return 2.0 * self.move_s + self.hold_s + self.rest_s

    @property
    def duration_s(self) -> float:
        """Total length of the protocol, seconds."""
        return self.static_s + len(self.moves) * self.period_s

    def start_of(self, k: int) -> float:
        """When move ``k`` begins, seconds from the protocol start."""
        return self.static_s + k * self.period_s

    def windows(self) -> dict[str, tuple[float, float]]:
        """``{"static": (t0, t1), move.servo: (t0, t1), ...}``: each move's whole period."""
        s = self.settle_s
        out = {"static": (s, self.static_s - s)}
        for k, m in enumerate(self.moves):
            out[m.servo] = (self.start_of(k), self.start_of(k) + self.period_s)
        return out

    def angles(self, t) -> np.ndarray:
        """Each move's turn (N, K), degrees, at times ``t`` (N,) (0 outside its move)."""
        t = np.atleast_1d(np.asarray(t, dtype=np.float64))
        out = np.zeros((len(t), len(self.moves)))
        for k, m in enumerate(self.moves):
            u = t - self.start_of(k)
            up = _smoothstep(u / self.move_s)
            down = 1.0 - _smoothstep((u - self.move_s - self.hold_s) / self.move_s)
            out[:, k] = np.where((u >= 0) & (u <= self.period_s),
                                 m.angle_deg * np.minimum(up, down), 0.0)
        return out

    def joint_orientations(self, t, side: str = "right") -> np.ndarray:
        """Scripted joint orientations (N, J, 4) at times ``t`` (N,): the identity but for the
        moving servo's joint. ``side`` is not used: the axes are the rig's own, for its side."""
        a = np.radians(self.angles(t))
        out = np.zeros((len(a), len(self.joints), 4))
        out[..., 0] = 1.0
        for k, m in enumerate(self.moves):
            out[:, m.index] = Q.multiply(out[:, m.index],
                                         Q.from_axis_angle(np.asarray(m.axis), a[:, k]))
        return out

    def joint(self, t) -> np.ndarray:
        """The first joint's scripted orientation (N, 4) (a patient of one joint)."""
        return self.joint_orientations(t)[:, 0]


def _smoothstep(x) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def servo_moves(joints, side: str = "right", *, amplitude_deg: float = 25.0,
                least_deg: float = 5.0) -> tuple[ServoMove, ...]:
    """One move per servo of an arm, in chain order.

    Parameters
    ----------
    joints : sequence of (str, sequence of (str, (3,) array_like, float, float))
        Per joint, proximal to distal: its name and its servos, each as (how to name it, its
        axis, the least and greatest angle its configured tick range allows, degrees, signed
        as the servo's angle with direction +1 from its zero).
    side : "right" or "left"
    amplitude_deg : float
        The turn asked where the range allows it.
    least_deg : float
        Least room worth a move on one side of the zero.

    Returns
    -------
    tuple of ServoMove
        Each turned the positive way, unless that movement is :data:`AT_A_STOP` or its side of
        the range has less room than the other and less than ``2 least_deg``; by
        ``min(amplitude_deg, 0.6 × the room that way)``.

    Raises
    ------
    ValueError
        A servo's range leaves less than ``least_deg`` either way of its zero (named).
    """
    out = []
    for index, (joint, servos) in enumerate(joints):
        for name, axis, lo, hi in servos:
            movement = servo_movement(joint, axis, side)
            room = {1: max(0.0, float(hi)), -1: max(0.0, -float(lo))}
            sign = -1 if (joint, movement) in AT_A_STOP and room[-1] >= least_deg else 1
            if room[sign] < 2 * least_deg and room[-sign] > room[sign]:
                sign = -sign
            if room[sign] < least_deg:
                raise ValueError(f"{name}: its range {lo:.1f}..{hi:.1f}° leaves less than "
                                 f"{least_deg:g}° to turn it from its zero")
            out.append(ServoMove(joint, index, name, tuple(axis),
                                 sign * min(amplitude_deg, 0.6 * room[sign]),
                                 movement if sign > 0 else _opposite(joint, movement)))
    return tuple(out)
