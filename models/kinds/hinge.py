"""The hinge: one axis and an angle interval.

File block (see :mod:`models.constraint` for the whole format)::

    kind: hinge
    hinge: {axis: [0, 0, 1], min_deg: 0, max_deg: 140}

A hinge has no ``swing`` or ``twist``: its axis and interval are the whole limit.

Oracle. The allowed set is the arc ``{h(θ) = (cos θ/2, sin θ/2 · a) : lo <= θ <= hi}``. For a
unit ``q = (w, v)``, ``|<q, h(θ)>| = c |cos((θ − φ)/2)|`` with ``c = sqrt(w² + (v·a)²)`` and
``φ`` the twist of ``q`` about ``a``: the geodesic distance to ``h(θ)`` grows with ``|θ − φ|``
(wrapped), so the nearest allowed rotation is ``h(φ)`` when ``φ`` is inside the interval and
the nearer end otherwise (the upper one on a tie). The off-axis part of ``q`` (its swing about
``a``) is corrected with it. :func:`evaluate_hinge` is the batched path,
:meth:`HingeOracle.evaluate_one` its plain-Python twin (same maths, same tie rules).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from models import quaternion as Q
from models.errors import ConstraintError
from models.kinds.base import (
    BOUNDARY_TOLERANCE,
    JointKind,
    KindOracle,
    OracleResult,
    across_seam1,
    correction1,
    locate1,
    reaches_seam,
    twist_inside,
)
from models.limits import (
    DegreeInterval,
    degree_interval,
    fmt_vec,
    require_keys,
    vec_out,
    vector,
)

__all__ = ["HingeKind", "HingeLimits", "HingeOracle", "evaluate_hinge", "hinge_one",
           "parse_hinge"]


@dataclass(frozen=True, eq=False)
class HingeLimits(DegreeInterval):
    """A hinge: the joint's allowed orientations are the rotations ``axis_angle(axis, θ)`` with
    ``min_deg <= θ <= max_deg`` (degrees, ``-180 <= min_deg <= max_deg <= 180``), about a unit
    ``axis`` of the parent frame (the child's frame coincides with the parent's at 0)."""

    axis: np.ndarray
    min_deg: float
    max_deg: float

    def to_dict(self) -> dict[str, Any]:
        return {"axis": vec_out(self.axis), "min_deg": float(self.min_deg),
                "max_deg": float(self.max_deg)}

    def __eq__(self, other: object) -> bool:
        return (
            isinstance(other, HingeLimits)
            and np.allclose(self.axis, other.axis, atol=1e-12)
            and self.same_interval(other)
        )

    __hash__ = None  # type: ignore[assignment]



def parse_hinge(value: Any, source: str | None) -> HingeLimits:
    """The ``hinge:`` block ``{axis, min_deg, max_deg}``."""
    if not isinstance(value, dict):
        raise ConstraintError(f"expected {{axis, min_deg, max_deg}}, got {value!r}", "hinge",
                              source)
    require_keys(value, ("axis", "min_deg", "max_deg"), "hinge", source)
    axis = vector(value["axis"], "hinge.axis", source)
    lo, hi = degree_interval(value, "hinge", source)
    return HingeLimits(axis=axis, min_deg=lo, max_deg=hi)


class HingeKind(JointKind):
    """A hinge: ``hinge: {axis, min_deg, max_deg}`` (no swing, no twist)."""

    name = "hinge"
    words = "hinge"
    file_keys = ("hinge",)
    drives_couplings = True
    coupled_interval_key = "hinge"
    single_axis = True
    servo_axes = 1

    def refuse(self, data: dict, source: str | None) -> None:
        for key in ("swing", "twist"):
            if data.get(key) is not None:
                raise ConstraintError(
                    "a hinge has no swing or twist limits (its 'hinge' axis and interval "
                    "are the whole limit)", key, source)

    def parse(self, data: dict, source: str | None) -> dict[str, Any]:
        return {"swing": None, "twist": None, "limits": parse_hinge(data.get("hinge"), source)}

    def limits_dict(self, constraint: Any) -> dict[str, Any]:
        return {"hinge": constraint.limits.to_dict()}

    def summary_lines(self, constraint: Any) -> list[str]:
        h = constraint.limits
        return [f"  kind        hinge, axis {fmt_vec(h.axis)}, {h.min_deg:g} .. {h.max_deg:g} deg"]

    def oracle(self, constraint: Any) -> HingeOracle:
        return HingeOracle(constraint.limits)

    def evaluate_coupled(self, q, axis, limits, k, t) -> OracleResult:
        lo, hi = limits.interval(k, t)
        return evaluate_hinge(q, self.coupling_axis(limits.keyframes[0]), lo, hi, True)

    def coupled_one(self, axis, limits):
        """Plain Python (:func:`hinge_one` at the interval interpolated at the angle)."""
        at = tuple(float(a) for a in limits.at)
        los = tuple(float(self.coupled_interval(c)[0]) for c in limits.keyframes)
        his = tuple(float(self.coupled_interval(c)[1]) for c in limits.keyframes)
        axis_t = tuple(float(v) for v in self.coupling_axis(limits.keyframes[0]))

        def one(w, x, y, z, angle):
            k, t = locate1(at, angle)
            lo = (1.0 - t) * los[k] + t * los[k + 1]
            hi = (1.0 - t) * his[k] + t * his[k + 1]
            r = hinge_one((w, x, y, z), axis_t, lo, hi, True)
            return not r[0], r[1], r[2], r[3]
        return one

    def coupled_interval(self, constraint: Any) -> tuple[float, float]:
        return constraint.limits.min, constraint.limits.max

    def check_keyframe(self, c: Any, first: Any, where: str, source: str | None) -> None:
        if not np.allclose(c.limits.axis, first.limits.axis, atol=1e-9):
            raise ConstraintError("every keyframe of a coupled hinge has the same axis "
                                  "(only its interval changes)", f"{where}.hinge.axis", source)

    def loosest(self, keyframes: tuple, name: str) -> Any:
        h = keyframes[0].limits
        return type(keyframes[0]).hinge_joint(h.axis, min(c.limits.min_deg for c in keyframes),
                                              max(c.limits.max_deg for c in keyframes),
                                              name=name)

    def coupling_axis(self, constraint: Any) -> np.ndarray:
        return np.asarray(constraint.limits.axis)

    def coupling_range(self, constraint: Any) -> tuple[float, float]:
        return constraint.limits.min, constraint.limits.max

    def at_coupling_angle(self, constraint: Any, angle: np.ndarray,
                          rng: np.random.Generator) -> np.ndarray:
        return Q.from_axis_angle(np.asarray(constraint.limits.axis), angle)


class HingeOracle(KindOracle):
    """The exact oracle of a hinge (see the module docstring)."""

    def __init__(self, h: HingeLimits):
        self._hinge = (tuple(float(v) for v in h.axis), h.min, h.max, reaches_seam(h.min, h.max))

    def evaluate(self, q: np.ndarray) -> OracleResult:
        axis_t, lo, hi, wraps = self._hinge
        return evaluate_hinge(q, np.asarray(axis_t), lo, hi, wraps)

    def evaluate_one(self, qt: tuple[float, float, float, float]) -> OracleResult:
        """Scalar twin of :meth:`evaluate` (same maths, same tie rules)."""
        axis_t, lo, hi, wraps = self._hinge
        invalid, distance, proj, corr, off, phi = hinge_one(qt, axis_t, lo, hi, wraps)
        return OracleResult(valid=np.bool_(not invalid), distance=np.float64(distance),
                            projected=np.array(proj), correction=np.array(corr),
                            swing_distance=np.float64(off), twist=np.float64(phi))

    def distance_projected_one(self, qt):
        axis_t, lo, hi, wraps = self._hinge
        r = hinge_one(qt, axis_t, lo, hi, wraps)
        return r[1], r[2]


def hinge_one(qt, axis_t, lo: float, hi: float, wraps: bool):
    """:func:`evaluate_hinge` for one unit orientation ``qt`` (4-tuple) about ``axis_t``
    (3-tuple), plain floats (same maths, same tie rules): ``(invalid, distance, projected,
    correction, off-axis angle, twist)``."""
    phi = Q.twist_angle1(qt, axis_t)
    t = BOUNDARY_TOLERANCE
    inside = lo - t <= phi <= hi + t or (wraps and across_seam1(phi, lo, hi))
    if inside:
        theta = phi
    else:
        theta = lo if abs(Q.wrap_angle1(phi - lo)) < abs(Q.wrap_angle1(phi - hi)) else hi
    ch, sh = math.cos(0.5 * theta), math.sin(0.5 * theta)
    h = (ch, sh * axis_t[0], sh * axis_t[1], sh * axis_t[2])
    if h[0] * qt[0] + h[1] * qt[1] + h[2] * qt[2] + h[3] * qt[3] < 0.0:
        h = (-h[0], -h[1], -h[2], -h[3])
    c, gap = correction1(h, qt)
    invalid = gap > t
    if invalid:
        corr, proj, distance = c, h, gap
    else:
        corr, proj = (1.0, 0.0, 0.0, 0.0), qt
        distance = -max(min(phi - lo, hi - phi), 0.0)
    p = qt[1] * axis_t[0] + qt[2] * axis_t[1] + qt[3] * axis_t[2]
    r2 = qt[0] * qt[0] + p * p
    off = 2.0 * math.atan2(math.sqrt(max(1.0 - r2, 0.0)), math.sqrt(r2))
    return invalid, distance, proj, corr, off, phi


def evaluate_hinge(q: np.ndarray, a: np.ndarray, lo, hi, wraps: bool = True) -> OracleResult:
    """The hinge oracle, batched: ``q`` (N, 4) unit, hinge axis ``a`` (3,), the interval
    ``[lo, hi]`` (radians, floats or (N,) arrays: one interval per orientation, as a coupled
    joint's are). See the module docstring for the maths."""
    phi = Q.twist_angle(q, a)
    inside = twist_inside(phi, lo, hi, wraps)
    d_lo = np.abs(Q.wrap_angle(phi - lo))
    d_hi = np.abs(Q.wrap_angle(phi - hi))
    theta = np.where(inside, phi, np.where(d_lo < d_hi, lo, hi))
    h = Q.from_axis_angle(a, theta)
    dot = np.einsum("ij,ij->i", h, q)
    h = np.where((dot < 0.0)[:, None], -h, h)  # the input's sign
    c = Q.multiply(h, Q.conjugate(q))
    c = Q.canonical(c / np.linalg.norm(c, axis=1, keepdims=True))
    gap = Q.angle(c)
    invalid = gap > BOUNDARY_TOLERANCE
    n = len(q)
    corr = np.where(invalid[:, None], c, np.tile(Q.IDENTITY, (n, 1)))
    projected = np.where(invalid[:, None], h, q)
    margin = np.minimum(phi - lo, hi - phi)
    distance = np.where(invalid, gap, -np.maximum(margin, 0.0))
    p = q[:, 1:] @ a
    off = 2.0 * np.arctan2(np.sqrt(np.maximum(1.0 - (q[:, 0] ** 2 + p * p), 0.0)),
                           np.sqrt(q[:, 0] ** 2 + p * p))
    return OracleResult(valid=~invalid, distance=distance, projected=projected,
                        correction=corr, swing_distance=off, twist=phi)


# -- twist intervals on the circle (both paths) -------------------------------------------------
