"""What every joint kind provides in ``models/``, and the oracle primitives the kinds share.

A joint kind (:mod:`models.kinds`) owns the limits block of its constraint file (parsing,
validating, writing, summarising) and its exact oracle. :class:`JointKind` is the base of
every kind; :class:`KindOracle` the base of every kind's oracle, which
:class:`models.oracle.ConstraintOracle` drives: a batched path on ``(N, 4)`` orientations and a
single-orientation path in plain floats for the control loop, giving the same answers.

Shared maths: an angle interval ``[lo, hi]`` (radians) lives on the circle — ``φ`` is inside
when ``φ``, ``φ − 2π`` or ``φ + 2π`` is, within :data:`BOUNDARY_TOLERANCE` (so ``±π`` is inside
``[−π, …]`` and ``[…, π]`` alike); a correction ``proj ⊗ q⁻¹`` is returned with ``w >= 0``
(:func:`models.quaternion.canonical`'s rule).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from models import qscalar as qs
from models import quaternion as Q

__all__ = [
    "BOUNDARY_TOLERANCE",
    "SING2",
    "TWIST_SINGULARITY",
    "JointKind",
    "KindOracle",
    "OracleResult",
    "across_seam1",
    "correction1",
    "locate1",
    "reaches_seam",
    "singular",
    "twist_inside",
]

#: Orientations at most this far (radians) outside the boundary count as valid.
BOUNDARY_TOLERANCE = 1e-9

#: Where the twist part of ``q`` (``(w, (v·a) a)``) is shorter than this, the limb points within
#: about 2e-6 rad of ``−a`` (the swing-twist singularity): the twist is undefined there, no
#: rotation about ``a`` changes it, and the twist limit is not applied.
TWIST_SINGULARITY = 1e-6
#: ``TWIST_SINGULARITY²`` (what the tests compare a squared norm with).
SING2 = TWIST_SINGULARITY**2

_TWO_PI = 2.0 * math.pi


@dataclass(frozen=True)
class OracleResult:
    """Everything the oracle knows about a batch of orientations (arrays of length N).

    Attributes
    ----------
    valid : (N,) bool
    distance : (N,) float64, radians; > 0 outside (correction angle), <= 0 inside (-margin)
    projected : (N, 4) float64, nearest valid orientation, same sign as the input
    correction : (N, 4) float64, ``projected ⊗ q⁻¹`` with ``w >= 0``; identity when valid
        (a half-turn correction's sign is the rounding's: see :mod:`models.oracle`)
    swing_distance : (N,) float64, radians, signed distance of the limb direction to the swing
        boundary (negative inside; ``-inf`` when swing is unconstrained); for a kind without a
        swing region, the angle of the part of ``q`` off its own rotations (see the kind)
    twist : (N,) float64, radians, twist angle of the input about the limb axis (or about the
        kind's own axis: a hinge's angle)
    """

    valid: np.ndarray
    distance: np.ndarray
    projected: np.ndarray
    correction: np.ndarray
    swing_distance: np.ndarray
    twist: np.ndarray


class KindOracle:
    """The exact oracle of one constraint of one kind (built by :meth:`JointKind.oracle`).

    Attributes
    ----------
    swing : object or None
        The swing-region solver (``nearest(d, need_point=True) -> (signed distance (N,),
        nearest point (N, 3))``), None for a kind without a swing region.
    """

    swing: Any = None

    def prepare(self) -> None:
        """Build what the single-orientation path needs (compiled kernels, grids)."""

    def evaluate(self, q: np.ndarray) -> OracleResult:
        """The batched oracle on ``q`` (N, 4), unit."""
        raise NotImplementedError

    def evaluate_one(self, qt: tuple[float, float, float, float]) -> OracleResult:
        """The single-orientation path on one unit orientation (same maths, same tie rules)."""
        raise NotImplementedError

    def distance_projected_one(self, qt: tuple[float, float, float, float]
                               ) -> tuple[float, tuple[float, float, float, float]]:
        """``(D(q), projection of q)`` for one unit orientation, plain floats."""
        r = self.evaluate_one(qt)
        p = r.projected
        return float(r.distance), (float(p[0]), float(p[1]), float(p[2]), float(p[3]))

    def is_valid(self, q: np.ndarray) -> np.ndarray:
        """(N,) bool validity of ``q`` (N, 4), unit."""
        return self.evaluate(q).valid


class JointKind:
    """One kind of joint in ``models/``: its limits block and its exact oracle.

    Attributes
    ----------
    name : str
        The ``kind:`` value of a constraint file.
    words : str
        How a sentence names a joint of this kind (``"ball joint"``, ``"hinge"``).
    file_keys : tuple of str
        The top-level keys of a constraint file that hold this kind's limits.
    swing_twist : bool
        Its limits are a swing region and a twist interval (tools built for swing-twist joints
        — learned models, dataset generators — take it).
    drives_couplings : bool
        Its angle (:meth:`coupling_axis`) can drive another joint's limits in a limb.
    coupled_interval_key : str
        The file key of the interval a coupling interpolates between keyframes
        (:meth:`coupled_interval`).
    single_axis : bool
        Its limits are one angle interval about one axis (a hinge): reports, simulators and
        read-back treat it by that angle.
    narrow_twist : bool
        Its twist about the limb axis is fixed or narrow (a two-axis joint): a report names its
        swing region and its narrow twist.
    servo_axes : int
        How many servos drive a joint of this kind on a servo limb (a ball joint 3, a hinge 1,
        a forearm 2: flexion then pronation-supination, a two-axis joint 2).
    flexion_rotation : bool
        Its limits are a flexion interval about one axis and an axial-rotation interval about
        the limb axis (a forearm): the limb model compiles it as such a group.
    """

    name: str = ""
    words: str = ""
    file_keys: tuple[str, ...] = ()
    swing_twist: bool = False
    drives_couplings: bool = False
    coupled_interval_key: str = "twist"
    single_axis: bool = False
    narrow_twist: bool = False
    servo_axes: int = 3
    flexion_rotation: bool = False

    def refuse(self, data: dict, source: str | None) -> None:
        """Raise for keys of a constraint file this kind refuses with its own message (checked
        before the registry's "only 'kind: X' takes ..." for another kind's keys)."""

    def parse(self, data: dict, source: str | None) -> dict[str, Any]:
        """This kind's limits from a constraint file's mapping ``data``.

        Returns
        -------
        dict
            ``swing``, ``twist`` and ``limits`` of :class:`models.constraint.JointConstraint`
            (None where the kind has none). Raises
            :class:`~models.errors.ConstraintError` naming the file and field.
        """
        raise NotImplementedError

    def limits_dict(self, constraint: Any) -> dict[str, Any]:
        """The file's limits keys of ``constraint`` (what :meth:`parse` reads back)."""
        raise NotImplementedError

    def summary_lines(self, constraint: Any) -> list[str]:
        """Human-readable lines describing the limits (after the name, axis and binding)."""
        raise NotImplementedError

    def oracle(self, constraint: Any) -> KindOracle:
        """The exact oracle of ``constraint`` (a constraint of this kind)."""
        raise NotImplementedError

    def evaluate_coupled(self, q: np.ndarray, axis: np.ndarray, limits: Any, k: np.ndarray,
                         t: np.ndarray) -> OracleResult:
        """The batched oracle of a coupled joint of this kind: ``q`` (N, 4) unit, its limb
        ``axis`` (3,), its limits interpolated between keyframes (``limits`` a
        :class:`models.limb.InterpolatedLimits`, ``k`` (N,) the keyframe segment and ``t``
        (N,) the fraction along it at each sample's coupling angle)."""
        raise NotImplementedError

    def coupled_one(self, axis: np.ndarray, limits: Any):
        """The single-orientation twin of :meth:`evaluate_coupled` for the control loop: a
        callable ``one(w, x, y, z, angle) -> (valid, distance, projected, correction)`` (plain
        floats, the quaternions 4-tuples) of one unit orientation with its limits at coupling
        angle ``angle`` (radians), giving :meth:`evaluate_coupled`'s answers; built once (what
        can be is prepared here). None when the kind has none (the oracle then evaluates a
        batch of one)."""
        return None

    def coupling_angle_one(self, constraint: Any):
        """The scalar twin of :meth:`coupling_angle`: a callable ``angle(w, x, y, z) -> float``
        (radians) of one unit orientation, built once."""
        axis = tuple(float(v) for v in self.coupling_axis(constraint))
        twist1 = Q.twist_angle1

        def angle(w: float, x: float, y: float, z: float) -> float:
            return twist1((w, x, y, z), axis)
        return angle

    def coupled_interval(self, constraint: Any) -> tuple[float, float]:
        """The angle interval (radians) a coupling interpolates between keyframes of this
        kind (a twist interval, a hinge interval)."""
        return constraint.twist.min, constraint.twist.max

    def check_keyframe(self, c: Any, first: Any, where: str, source: str | None) -> None:
        """Raise :class:`~models.errors.ConstraintError` (naming ``where``) unless keyframe
        ``c`` of a coupling can be interpolated with keyframe 0, ``first`` (same kind and limb
        axis already checked)."""

    def loosest(self, keyframes: tuple, name: str) -> Any:
        """The hull of a coupled joint's keyframe limits as one constraint, None when it is
        not one constraint of this kind."""
        return None

    def coupling_axis(self, constraint: Any) -> np.ndarray | None:
        """The axis (3,) whose angle can drive another joint's limits in a limb (a hinge's
        axis, a flexion axis), None when this kind cannot be a coupling's source."""
        return None

    def coupling_angle(self, constraint: Any, q: np.ndarray) -> np.ndarray:
        """The angle (radians, (N,), in (−π, π]) of orientations ``q`` (N, 4) that drives the
        joints coupled to this one — what a coupling's ``at_deg`` measures: by default the
        rotation about :meth:`coupling_axis` (:func:`models.quaternion.twist_angle`, a
        hinge's angle)."""
        return Q.twist_angle(q, self.coupling_axis(constraint))

    def coupling_range(self, constraint: Any) -> tuple[float, float]:
        """The interval (radians) the coupling angle of a valid orientation lies in (a
        hinge's interval, a forearm's flexion)."""
        raise NotImplementedError(f"a {self.words} does not drive couplings")

    def at_coupling_angle(self, constraint: Any, angle: np.ndarray,
                          rng: np.random.Generator) -> np.ndarray:
        """Valid orientations (N, 4) whose coupling angle is ``angle`` (N,) (radians, inside
        :meth:`coupling_range`), the joint's other angles (if any) drawn from ``rng`` within
        their limits; a kind without other angles draws nothing."""
        raise NotImplementedError(f"a {self.words} does not drive couplings")

    def flexion_axis(self, constraint: Any) -> np.ndarray | None:
        """The axis (3,, parent frame) a joint of this kind flexes about — what tells an
        elbow's (+Z) from a knee's (−Z) — None for a swing-twist joint."""
        return self.coupling_axis(constraint)


# -- angle intervals on the circle (both paths) -------------------------------------------------
def reaches_seam(lo, hi) -> bool:
    """Can an angle across the ±π seam lie within the tolerance of ``[lo, hi]``?"""
    t = BOUNDARY_TOLERANCE
    return bool(np.min(lo) <= -math.pi + t or np.max(hi) >= math.pi - t)


def twist_inside(phi, lo, hi, wraps: bool = True):
    """``φ`` (radians, (−π, π]) inside ``[lo, hi]`` on the circle, within the tolerance.

    ``φ − 2π`` and ``φ + 2π`` are tried too when ``wraps`` (an interval touching ±π)."""
    t = BOUNDARY_TOLERANCE
    inside = (phi >= lo - t) & (phi <= hi + t)
    if wraps:
        inside |= (phi - _TWO_PI >= lo - t) | (phi + _TWO_PI <= hi + t)
    return inside


def locate1(at: tuple[float, ...], angle: float) -> tuple[int, float]:
    """:meth:`models.limb.InterpolatedLimits.locate` of one coupling angle (radians), the
    keyframes' angles ``at`` a tuple: the keyframe interval ``k`` and the fraction ``t``."""
    n = len(at)
    a = min(max(angle, at[0]), at[-1]) if angle == angle else angle
    k = n - 2
    if a == a:
        k = -1
        for i in range(n):
            if at[i] <= a:
                k = i
        k = min(max(k, 0), n - 2)
    t = (a - at[k]) / (at[k + 1] - at[k])
    return k, (0.0 if t < 0.0 else 1.0 if t > 1.0 else t)


def singular(q: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """(N,) bool: the twist of ``q`` is undefined (limb within ~2e-6 rad of ``−axis``)."""
    p = q[:, 1:] @ axis
    return q[:, 0] * q[:, 0] + p * p < SING2


def across_seam1(phi: float, lo: float, hi: float) -> bool:
    """Scalar: ``φ ∓ 2π`` inside ``[lo, hi]`` (within the tolerance)."""
    t = BOUNDARY_TOLERANCE
    return phi - _TWO_PI >= lo - t or phi + _TWO_PI <= hi + t


def correction1(proj, qt) -> tuple[tuple[float, float, float, float], float]:
    """The correction ``proj ⊗ qt⁻¹`` (unit, ``w >= 0``: :func:`models.quaternion.canonical`'s
    rule) and its angle, radians (tuples of floats, w x y z)."""
    c = qs.mul(proj, (qt[0], -qt[1], -qt[2], -qt[3]))
    cn = math.sqrt(c[0] * c[0] + c[1] * c[1] + c[2] * c[2] + c[3] * c[3])
    sign = -1.0 if c[0] < 0.0 or (c[0] == 0.0 and _first_nonzero_negative(c)) else 1.0
    c = (sign * c[0] / cn, sign * c[1] / cn, sign * c[2] / cn, sign * c[3] / cn)
    return c, 2.0 * math.atan2(math.sqrt(c[1] * c[1] + c[2] * c[2] + c[3] * c[3]), abs(c[0]))


def _first_nonzero_negative(c) -> bool:
    for v in c:
        if v != 0.0:
            return v < 0.0
    return False
