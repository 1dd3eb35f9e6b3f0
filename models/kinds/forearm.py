"""The forearm joint: elbow flexion about one axis plus axial rotation (pronation–supination)
about the limb's long axis, each with its interval.

File block (see :mod:`models.constraint` for the whole format)::

    kind: forearm
    limb_axis: [1, 0, 0]                                  # the forearm's long axis (default +X)
    forearm:
      flexion: {axis: [0, 0, 1], min_deg: 0, max_deg: 145}
      rotation: {min_deg: -80, max_deg: 80}               # about limb_axis

A forearm joint has no ``swing`` or ``twist`` (its two intervals are the whole limit). The
flexion axis must not be parallel to the limb axis (that would be one rotation, a hinge).

In a limb file (``docs/limb-format.md``) a forearm elbow drives couplings like a hinge: the
coupling angle is its flexion ``θ`` (:meth:`ForearmKind.coupling_angle`, the ``θ`` of
:func:`decompose`; on the joint's set, where the limb oracle reads it, it is exactly the ``θ``
of ``F(θ) ⊗ R(φ)``, and equal to the twist about ``n`` when ``n ⊥ x``).

Parameterisation
----------------
With ``n`` the flexion axis (parent frame; the child's frame coincides with the parent's at
zero, as for a hinge), ``x`` the limb axis (child frame), ``F(θ) = (cos θ/2, sin θ/2 · n)`` and
``R(φ) = (cos φ/2, sin φ/2 · x)``, the allowed orientations are::

    S = { F(θ) ⊗ R(φ) :  θ ∈ [θlo, θhi],  φ ∈ [φlo, φhi] }

flexion first about the proximal segment's axis, then the axial rotation about the distal
segment's own long axis (intrinsic): the elbow's ISB Z-X'-Y'' Cardan sequence (Wu et al. 2005,
*J Biomech* 38:981, §3.4: flexion about the humerus's medio-lateral axis, pronation about the
forearm's long axis) with the floating (carrying) angle held at zero. In rig frames ``n = +Z``
and ``x = +X``; ISB's forearm +Y points proximally, so pronation is ``−φ``
(:mod:`calibration.kinds.forearm`).

Exact oracle
------------
The nearest element of ``S`` by geodesic angle on SO(3) maximises ``|<q, F(θ) ⊗ R(φ)>|`` (the
angle is ``2 acos`` of it). With ``u = (cos θ/2, sin θ/2)``, ``v = (cos φ/2, sin φ/2)`` and the
basis quaternions ``e00 = 1``, ``e01 = x``, ``e10 = n``, ``e11 = n ⊗ x = (−n·x, n × x)``::

    F(θ) ⊗ R(φ) = Σ u_i v_j e_ij,    h(θ, φ) = <q, F(θ) ⊗ R(φ)> = uᵀ A v,  A_ij = <q, e_ij>

a bilinear form in two unit 2-vectors. Writing ``a = θ/2``, ``b = φ/2``::

    h = r1 cos(a − b − δ1) + r2 cos(a + b − δ2)
    r1 e^{iδ1} = ½(A00 + A11) + ½ i (A10 − A01),   r2 e^{iδ2} = ½(A00 − A11) + ½ i (A01 + A10)

so ``max |h| = r1 + r2`` (the largest singular value of ``A``), at ``θ0 = δ1 + δ2``,
``φ0 = δ2 − δ1`` (mod 2π: ``u`` and ``−u`` are the same rotation). Its only local maxima of
``|h|`` on the torus are these (the other critical points, ``h = ±(r1 − r2)``, are saddles), so
on the rectangle of intervals the maximum is ``(θ0, φ0)`` when it lies inside, and otherwise on
an edge. On an edge one angle is fixed and ``|h| = |w| |cos(b − β)|`` (``w = Aᵀu`` or ``A v``)
decreases with the wrapped distance of the free angle from ``2β``: its best value is the free
optimum clamped to the nearer end of its interval (the hinge's rule, :mod:`models.kinds.hinge`;
the upper end on a tie). The oracle compares the four edges' optima (``θ = θlo``, ``θhi``,
``φ = φlo``, ``φhi``, the first largest wins). Exact, closed form, batched in numpy
(:func:`evaluate_forearm`) and in plain floats for one orientation
(:meth:`ForearmOracle.evaluate_one`, the same formulas).

``distance`` is the correction angle outside, ``−min(θ0 − θlo, θhi − θ0, φ0 − φlo, φhi − φ0)``
(clipped at 0) inside; ``twist`` is ``φ0`` (the axial rotation) and ``swing_distance`` the angle
from ``q`` to the nearest rotation ``F(θ) ⊗ R(φ)`` with unbounded angles (the off-axis motion:
a carrying angle, varus/valgus).
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
    reaches_seam,
    twist_inside,
)
from models.limits import (
    degree_interval,
    fmt_vec,
    require_keys,
    vec_out,
    vector,
)

__all__ = ["ForearmKind", "ForearmLimits", "ForearmOracle", "basis", "decompose",
           "evaluate_forearm"]

#: Smallest angle (degrees) between the flexion axis and the limb axis.
MIN_AXIS_ANGLE_DEG = 1.0


@dataclass(frozen=True, eq=False)
class ForearmLimits:
    """A forearm joint's limits: flexion ``θ`` about ``axis`` (parent frame, unit) in
    ``[flexion_min_deg, flexion_max_deg]`` and axial rotation ``φ`` about the limb axis in
    ``[rotation_min_deg, rotation_max_deg]`` (degrees, each within [-180, 180])."""

    axis: np.ndarray
    flexion_min_deg: float
    flexion_max_deg: float
    rotation_min_deg: float
    rotation_max_deg: float

    @property
    def flexion(self) -> tuple[float, float]:
        """The flexion interval, radians."""
        return math.radians(self.flexion_min_deg), math.radians(self.flexion_max_deg)

    @property
    def rotation(self) -> tuple[float, float]:
        """The axial-rotation interval, radians."""
        return math.radians(self.rotation_min_deg), math.radians(self.rotation_max_deg)

    def to_dict(self) -> dict[str, Any]:
        return {"flexion": {"axis": vec_out(self.axis), "min_deg": float(self.flexion_min_deg),
                            "max_deg": float(self.flexion_max_deg)},
                "rotation": {"min_deg": float(self.rotation_min_deg),
                             "max_deg": float(self.rotation_max_deg)}}

    def __eq__(self, other: object) -> bool:
        return (isinstance(other, ForearmLimits)
                and np.allclose(self.axis, other.axis, atol=1e-12)
                and np.allclose([self.flexion_min_deg, self.flexion_max_deg,
                                 self.rotation_min_deg, self.rotation_max_deg],
                                [other.flexion_min_deg, other.flexion_max_deg,
                                 other.rotation_min_deg, other.rotation_max_deg], atol=1e-12))

    __hash__ = None  # type: ignore[assignment]


def parse_forearm(value: Any, limb_axis: np.ndarray, source: str | None) -> ForearmLimits:
    """The ``forearm:`` block ``{flexion: {axis, min_deg, max_deg}, rotation: {min_deg,
    max_deg}}``."""
    if not isinstance(value, dict):
        raise ConstraintError("expected {flexion: {axis, min_deg, max_deg}, rotation: "
                              f"{{min_deg, max_deg}}}}, got {value!r}", "forearm", source)
    require_keys(value, ("flexion", "rotation"), "forearm", source)
    flex, rot = value["flexion"], value["rotation"]
    if not isinstance(flex, dict):
        raise ConstraintError(f"expected {{axis, min_deg, max_deg}}, got {flex!r}",
                              "forearm.flexion", source)
    if not isinstance(rot, dict):
        raise ConstraintError(f"expected {{min_deg, max_deg}}, got {rot!r}", "forearm.rotation",
                              source)
    require_keys(flex, ("axis", "min_deg", "max_deg"), "forearm.flexion", source)
    require_keys(rot, ("min_deg", "max_deg"), "forearm.rotation", source)
    axis = vector(flex["axis"], "forearm.flexion.axis", source)
    if abs(float(axis @ limb_axis)) > math.cos(math.radians(MIN_AXIS_ANGLE_DEG)):
        raise ConstraintError("is parallel to limb_axis (flexion and axial rotation would be "
                              "one rotation: that is a hinge)", "forearm.flexion.axis", source)
    f_lo, f_hi = degree_interval(flex, "forearm.flexion", source)
    r_lo, r_hi = degree_interval(rot, "forearm.rotation", source)
    return ForearmLimits(axis=axis, flexion_min_deg=f_lo, flexion_max_deg=f_hi,
                         rotation_min_deg=r_lo, rotation_max_deg=r_hi)


class ForearmKind(JointKind):
    """A forearm joint: ``forearm: {flexion: {axis, min_deg, max_deg}, rotation: {min_deg,
    max_deg}}`` (no swing, no twist)."""

    name = "forearm"
    servo_axes = 2
    words = "forearm joint"
    file_keys = ("forearm",)
    drives_couplings = True
    flexion_rotation = True

    def refuse(self, data: dict, source: str | None) -> None:
        for key in ("swing", "twist"):
            if data.get(key) is not None:
                raise ConstraintError(
                    "a forearm joint has no swing or twist limits (its flexion and rotation "
                    "intervals are the whole limit)", key, source)

    def parse(self, data: dict, source: str | None) -> dict[str, Any]:
        limb_axis = vector(data.get("limb_axis", [1, 0, 0]), "limb_axis", source)
        return {"swing": None, "twist": None,
                "limits": parse_forearm(data.get("forearm"), limb_axis, source)}

    def limits_dict(self, constraint: Any) -> dict[str, Any]:
        return {"forearm": constraint.limits.to_dict()}

    def summary_lines(self, constraint: Any) -> list[str]:
        f = constraint.limits
        return [f"  kind        forearm, flexion axis {fmt_vec(f.axis)}, "
                f"{f.flexion_min_deg:g} .. {f.flexion_max_deg:g} deg",
                f"  rotation    about the limb axis, {f.rotation_min_deg:g} .. "
                f"{f.rotation_max_deg:g} deg"]

    def oracle(self, constraint: Any) -> ForearmOracle:
        return ForearmOracle(constraint.limits, constraint.limb_axis)

    def flexion_axis(self, constraint: Any) -> np.ndarray:
        return np.asarray(constraint.limits.axis, dtype=np.float64)

    def coupling_axis(self, constraint: Any) -> np.ndarray:
        return np.asarray(constraint.limits.axis, dtype=np.float64)

    def coupling_angle(self, constraint: Any, q: np.ndarray) -> np.ndarray:
        """The flexion ``θ`` of ``q`` (:func:`decompose`): on the joint's set ``F(θ) ⊗ R(φ)``
        exactly ``θ`` whatever the axes (the twist about ``n`` is ``θ`` too when ``n ⊥ x``,
        not otherwise)."""
        return decompose(q, constraint.limits.axis, constraint.limb_axis)[0]

    def coupling_angle_one(self, constraint: Any):
        """The flexion ``θ`` of one orientation (:func:`decompose`'s formulas in plain
        floats)."""
        e = tuple(tuple(float(v) for v in row)
                  for row in basis(np.asarray(constraint.limits.axis, dtype=np.float64),
                                        np.asarray(constraint.limb_axis, dtype=np.float64)))
        e0, e1, e2, e3 = e
        wrap1 = Q.wrap_angle1

        def angle(w: float, x: float, y: float, z: float) -> float:
            a0 = e0[0] * w + e0[1] * x + e0[2] * y + e0[3] * z
            a1 = e1[0] * w + e1[1] * x + e1[2] * y + e1[3] * z
            a2 = e2[0] * w + e2[1] * x + e2[2] * y + e2[3] * z
            a3 = e3[0] * w + e3[1] * x + e3[2] * y + e3[3] * z
            return wrap1(math.atan2(0.5 * (a2 - a1), 0.5 * (a0 + a3))
                         + math.atan2(0.5 * (a1 + a2), 0.5 * (a0 - a3)))
        return angle

    def coupling_range(self, constraint: Any) -> tuple[float, float]:
        return constraint.limits.flexion

    def at_coupling_angle(self, constraint: Any, angle: np.ndarray,
                          rng: np.random.Generator) -> np.ndarray:
        """``F(angle) ⊗ R(φ)``, ``φ`` uniform over the rotation interval."""
        lo, hi = constraint.limits.rotation
        phi = rng.uniform(lo, hi, np.shape(angle))
        return Q.multiply(Q.from_axis_angle(np.asarray(constraint.limits.axis), angle),
                          Q.from_axis_angle(np.asarray(constraint.limb_axis), phi))

    def check_keyframe(self, c: Any, first: Any, where: str, source: str | None) -> None:
        raise ConstraintError("a forearm joint's limits are not coupled to another joint's "
                              "angle (keyframes are ball, two-axis or hinge joints)",
                              f"{where}.kind", source)


# -- the oracle ---------------------------------------------------------------------------------
def basis(n: np.ndarray, x: np.ndarray) -> np.ndarray:
    """(4, 4): rows ``e00 = 1``, ``e01 = x``, ``e10 = n``, ``e11 = n ⊗ x`` — so that
    ``F(θ) ⊗ R(φ) = Σ u_i v_j e_ij`` (module docstring); the limb model's graph reads them."""
    nx = np.cross(n, x)
    return np.array([[1.0, 0.0, 0.0, 0.0], [0.0, *x], [0.0, *n],
                     [-float(n @ x), *nx]])


def decompose(q: np.ndarray, n, x) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The nearest ``F(θ) ⊗ R(φ)`` to each orientation with unbounded angles (module doc).

    Parameters
    ----------
    q : (N, 4) float64, unit, scalar-first (either sign)
    n, x : (3,) the flexion axis (parent frame) and the limb axis (child frame), unit

    Returns
    -------
    theta, phi : (N,) float64, radians, in (−π, π]
    sigma : (N,) float64, ``max |<q, F(θ) ⊗ R(φ)>|`` (1 on the set)
    """
    a = q @ basis(np.asarray(n, float), np.asarray(x, float)).T  # (N, 4): A00 A01 A10 A11
    d1 = np.arctan2(0.5 * (a[:, 2] - a[:, 1]), 0.5 * (a[:, 0] + a[:, 3]))
    d2 = np.arctan2(0.5 * (a[:, 1] + a[:, 2]), 0.5 * (a[:, 0] - a[:, 3]))
    r1 = np.hypot(0.5 * (a[:, 2] - a[:, 1]), 0.5 * (a[:, 0] + a[:, 3]))
    r2 = np.hypot(0.5 * (a[:, 1] + a[:, 2]), 0.5 * (a[:, 0] - a[:, 3]))
    return Q.wrap_angle(d1 + d2), Q.wrap_angle(d2 - d1), r1 + r2


def _clamp(free, lo, hi, wraps):
    """The hinge's rule: ``free`` when inside ``[lo, hi]`` (on the circle), else the nearer
    end (the upper one on a tie)."""
    inside = twist_inside(free, lo, hi, wraps)
    d_lo = np.abs(Q.wrap_angle(free - lo))
    d_hi = np.abs(Q.wrap_angle(free - hi))
    return np.where(inside, free, np.where(d_lo < d_hi, lo, hi))


def _h(a: np.ndarray, theta, phi) -> np.ndarray:
    """``uᵀ A v`` at the angles (radians)."""
    cu, su = np.cos(0.5 * theta), np.sin(0.5 * theta)
    cv, sv = np.cos(0.5 * phi), np.sin(0.5 * phi)
    return a[:, 0] * cu * cv + a[:, 1] * cu * sv + a[:, 2] * su * cv + a[:, 3] * su * sv


def evaluate_forearm(q: np.ndarray, n: np.ndarray, x: np.ndarray, flexion, rotation
                     ) -> OracleResult:
    """The forearm oracle, batched: ``q`` (N, 4) unit, flexion axis ``n`` and limb axis ``x``
    (3,), the intervals ``flexion`` and ``rotation`` (radians, ``(lo, hi)``). See the module
    docstring for the maths."""
    n = np.asarray(n, float)
    x = np.asarray(x, float)
    (t_lo, t_hi), (p_lo, p_hi) = flexion, rotation
    t_wraps, p_wraps = reaches_seam(t_lo, t_hi), reaches_seam(p_lo, p_hi)
    a = q @ basis(n, x).T
    theta0, phi0, sigma = decompose(q, n, x)
    inside = twist_inside(theta0, t_lo, t_hi, t_wraps) & twist_inside(phi0, p_lo, p_hi, p_wraps)
    cand_t, cand_p, vals = [], [], []
    for t_fix in (t_lo, t_hi):  # an edge θ fixed: w = Aᵀu, the free φ = 2 atan2(w1, w0)
        cu, su = math.cos(0.5 * t_fix), math.sin(0.5 * t_fix)
        free = Q.wrap_angle(2.0 * np.arctan2(a[:, 1] * cu + a[:, 3] * su,
                                             a[:, 0] * cu + a[:, 2] * su))
        p = _clamp(free, p_lo, p_hi, p_wraps)
        t = np.full(len(q), t_fix)
        cand_t.append(t)
        cand_p.append(p)
        vals.append(np.abs(_h(a, t, p)))
    for p_fix in (p_lo, p_hi):  # an edge φ fixed: w = A v, the free θ = 2 atan2(w1, w0)
        cv, sv = math.cos(0.5 * p_fix), math.sin(0.5 * p_fix)
        free = Q.wrap_angle(2.0 * np.arctan2(a[:, 2] * cv + a[:, 3] * sv,
                                             a[:, 0] * cv + a[:, 1] * sv))
        t = _clamp(free, t_lo, t_hi, t_wraps)
        p = np.full(len(q), p_fix)
        cand_t.append(t)
        cand_p.append(p)
        vals.append(np.abs(_h(a, t, p)))
    best = np.argmax(np.stack(vals, axis=1), axis=1)  # the first largest edge
    rows = np.arange(len(q))
    theta = np.where(inside, theta0, np.stack(cand_t, axis=1)[rows, best])
    phi = np.where(inside, phi0, np.stack(cand_p, axis=1)[rows, best])
    proj = Q.multiply(Q.from_axis_angle(n, theta), Q.from_axis_angle(x, phi))
    dot = np.einsum("ij,ij->i", proj, q)
    proj = np.where((dot < 0.0)[:, None], -proj, proj)  # the input's sign
    c = Q.multiply(proj, Q.conjugate(q))
    c = Q.canonical(c / np.linalg.norm(c, axis=1, keepdims=True))
    gap = Q.angle(c)
    invalid = gap > BOUNDARY_TOLERANCE
    corr = np.where(invalid[:, None], c, np.tile(Q.IDENTITY, (len(q), 1)))
    projected = np.where(invalid[:, None], proj, q)
    margin = np.minimum(np.minimum(theta0 - t_lo, t_hi - theta0),
                        np.minimum(phi0 - p_lo, p_hi - phi0))
    distance = np.where(invalid, gap, -np.maximum(margin, 0.0))
    s = np.minimum(sigma, 1.0)
    off = 2.0 * np.arctan2(np.sqrt(np.maximum(1.0 - s * s, 0.0)), s)
    return OracleResult(valid=~invalid, distance=distance, projected=projected,
                        correction=corr, swing_distance=off, twist=phi0)


# -- the single-orientation path, plain floats (w x y z tuples) ---------------------------------
def _wrap1(a: float) -> float:
    return Q.wrap_angle1(a)


def _clamp1(free: float, lo: float, hi: float, wraps: bool) -> float:
    t = BOUNDARY_TOLERANCE
    if lo - t <= free <= hi + t or (wraps and across_seam1(free, lo, hi)):
        return free
    return lo if abs(_wrap1(free - lo)) < abs(_wrap1(free - hi)) else hi


def _h1(a, theta: float, phi: float) -> float:
    cu, su = math.cos(0.5 * theta), math.sin(0.5 * theta)
    cv, sv = math.cos(0.5 * phi), math.sin(0.5 * phi)
    return a[0] * cu * cv + a[1] * cu * sv + a[2] * su * cv + a[3] * su * sv


class ForearmOracle(KindOracle):
    """The exact oracle of a forearm joint (see the module docstring)."""

    def __init__(self, limits: ForearmLimits, limb_axis):
        self.n = np.asarray(limits.axis, dtype=np.float64)
        self.x = np.asarray(limb_axis, dtype=np.float64)
        self.flexion = limits.flexion
        self.rotation = limits.rotation
        self._basis = tuple(tuple(float(v) for v in row) for row in basis(self.n, self.x))
        self._wraps = (reaches_seam(*self.flexion), reaches_seam(*self.rotation))
        self._n_t = tuple(float(v) for v in self.n)
        self._x_t = tuple(float(v) for v in self.x)

    def evaluate(self, q: np.ndarray) -> OracleResult:
        return evaluate_forearm(q, self.n, self.x, self.flexion, self.rotation)

    def evaluate_one(self, qt: tuple[float, float, float, float]) -> OracleResult:
        """Scalar twin of :meth:`evaluate` (the same formulas, the same tie rules)."""
        invalid, distance, out, corr, off, phi0 = self._one(qt)
        return OracleResult(valid=np.bool_(not invalid), distance=np.float64(distance),
                            projected=np.array(out), correction=np.array(corr),
                            swing_distance=np.float64(off), twist=np.float64(phi0))

    def distance_projected_one(self, qt):
        r = self._one(qt)
        return r[1], r[2]

    def _one(self, qt):
        """:meth:`evaluate_one`'s answers as plain floats and tuples: ``(invalid, distance,
        projected, correction, off-set angle, rotation)``."""
        a = [e[0] * qt[0] + e[1] * qt[1] + e[2] * qt[2] + e[3] * qt[3] for e in self._basis]
        (t_lo, t_hi), (p_lo, p_hi) = self.flexion, self.rotation
        t_wraps, p_wraps = self._wraps
        y1, x1 = 0.5 * (a[2] - a[1]), 0.5 * (a[0] + a[3])
        y2, x2 = 0.5 * (a[1] + a[2]), 0.5 * (a[0] - a[3])
        d1, d2 = math.atan2(y1, x1), math.atan2(y2, x2)
        sigma = math.hypot(y1, x1) + math.hypot(y2, x2)
        theta0, phi0 = _wrap1(d1 + d2), _wrap1(d2 - d1)
        tol = BOUNDARY_TOLERANCE
        inside = ((t_lo - tol <= theta0 <= t_hi + tol
                   or (t_wraps and across_seam1(theta0, t_lo, t_hi)))
                  and (p_lo - tol <= phi0 <= p_hi + tol
                       or (p_wraps and across_seam1(phi0, p_lo, p_hi))))
        if inside:
            theta, phi = theta0, phi0
        else:
            best = -1.0
            theta = phi = 0.0
            for t_fix in (t_lo, t_hi):
                cu, su = math.cos(0.5 * t_fix), math.sin(0.5 * t_fix)
                free = _wrap1(2.0 * math.atan2(a[1] * cu + a[3] * su, a[0] * cu + a[2] * su))
                p = _clamp1(free, p_lo, p_hi, p_wraps)
                v = abs(_h1(a, t_fix, p))
                if v > best:
                    best, theta, phi = v, t_fix, p
            for p_fix in (p_lo, p_hi):
                cv, sv = math.cos(0.5 * p_fix), math.sin(0.5 * p_fix)
                free = _wrap1(2.0 * math.atan2(a[2] * cv + a[3] * sv, a[0] * cv + a[1] * sv))
                t = _clamp1(free, t_lo, t_hi, t_wraps)
                v = abs(_h1(a, t, p_fix))
                if v > best:
                    best, theta, phi = v, t, p_fix
        ct, st = math.cos(0.5 * theta), math.sin(0.5 * theta)
        cp, sp = math.cos(0.5 * phi), math.sin(0.5 * phi)
        n, x = self._n_t, self._x_t
        f = (ct, st * n[0], st * n[1], st * n[2])
        r = (cp, sp * x[0], sp * x[1], sp * x[2])
        proj = (f[0] * r[0] - f[1] * r[1] - f[2] * r[2] - f[3] * r[3],
                f[0] * r[1] + f[1] * r[0] + f[2] * r[3] - f[3] * r[2],
                f[0] * r[2] - f[1] * r[3] + f[2] * r[0] + f[3] * r[1],
                f[0] * r[3] + f[1] * r[2] - f[2] * r[1] + f[3] * r[0])
        if proj[0] * qt[0] + proj[1] * qt[1] + proj[2] * qt[2] + proj[3] * qt[3] < 0.0:
            proj = (-proj[0], -proj[1], -proj[2], -proj[3])
        c, gap = correction1(proj, qt)
        invalid = gap > tol
        if invalid:
            corr, out, distance = c, proj, gap
        else:
            corr, out = (1.0, 0.0, 0.0, 0.0), qt
            distance = -max(min(theta0 - t_lo, t_hi - theta0, phi0 - p_lo, p_hi - phi0), 0.0)
        s = min(sigma, 1.0)
        off = 2.0 * math.atan2(math.sqrt(max(1.0 - s * s, 0.0)), s)
        return invalid, distance, out, corr, off, phi0
