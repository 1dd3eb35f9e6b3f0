"""The ball joint: a swing region on the sphere and a twist interval about the limb axis.

File block (see :mod:`models.constraint` for the whole format)::

    swing: {cone: {centre: [1, 0, 0], radius_deg: 45}}   # or polygon: {vertices, interior}
    twist: {min_deg: -60, max_deg: 60}                    # optional by_swing table

At least one of ``swing`` and ``twist``; a file without ``kind:`` is a ball joint.

Oracle (the maths is :mod:`models.oracle`'s docstring): the limb direction ``d = q a q*`` is
moved along the geodesic to the nearest point of the swing region (``Δ``), then the twist of
``Δ ⊗ q`` is clamped to its limits at the corrected direction by a right-multiplied rotation
about the limb axis: ``project(q) = Δ ⊗ q ⊗ τ``. :func:`evaluate_ball` is the batched path;
:func:`_ball_kernel` the compiled single-orientation path with the same maths and tie rules.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from models import qkernels as qk
from models import qscalar as qs
from models import quaternion as Q
from models.errors import ConstraintError
from models.geometry import SphericalPolygon, nearest_in_cell, nearest_on_polygons, rank_one
from models.jit import njit
from models.kinds.base import (
    BOUNDARY_TOLERANCE,
    SING2,
    JointKind,
    KindOracle,
    OracleResult,
    reaches_seam,
    singular,
    twist_inside,
)
from models.limits import (
    ConeSwing,
    PolygonSwing,
    fmt_vec,
    parse_swing,
    parse_twist,
    table_limits_one,
)

__all__ = ["BallKind", "BallOracle", "ConeSolver", "evaluate_ball"]

_TWO_PI = 2.0 * math.pi


class BallKind(JointKind):
    """A ball joint: ``swing`` region and ``twist`` interval (either may be absent, not both)."""

    name = "ball"
    words = "ball joint"
    file_keys = ("swing", "twist")
    swing_twist = True

    def parse(self, data: dict, source: str | None) -> dict[str, Any]:
        swing = parse_swing(data.get("swing"), source)
        twist = parse_twist(data.get("twist"), source)
        if swing is None and twist is None:
            raise ConstraintError(
                "a constraint needs a 'swing' limit, a 'twist' limit, or both",
                source=source
            )
        return {"swing": swing, "twist": twist, "limits": None}

    def limits_dict(self, constraint: Any) -> dict[str, Any]:
        out: dict[str, Any] = {}
        if constraint.swing is not None:
            out["swing"] = constraint.swing.to_dict()
        if constraint.twist is not None:
            out["twist"] = constraint.twist.to_dict()
        return out

    def summary_lines(self, constraint: Any) -> list[str]:
        lines = []
        swing = constraint.swing
        if isinstance(swing, ConeSwing):
            lines.append(
                f"  swing       cone, centre {fmt_vec(swing.centre)}, "
                f"radius {swing.radius_deg:g} deg"
            )
        elif isinstance(swing, PolygonSwing):
            area = swing.area_sr()
            lines.append(
                f"  swing       polygon, {len(swing.vertices)} vertices, "
                f"interior {fmt_vec(swing.interior)}, "
                f"area {area:.4f} sr ({100 * area / (4 * math.pi):.1f} % of the sphere)"
            )
        else:
            lines.append("  swing       unconstrained")
        if constraint.twist is not None:
            tw = constraint.twist
            lines.append(f"  twist       {tw.min_deg:g} .. {tw.max_deg:g} deg")
            if tw.by_swing is not None:
                t = tw.by_swing
                lines[-1] += " (envelope)"
                lines.append(
                    f"  by swing    {len(t.directions)} points, bandwidth {t.bandwidth_deg:g} deg, "
                    f"min {t.min_deg.min():g} .. {t.min_deg.max():g} deg, "
                    f"max {t.max_deg.min():g} .. {t.max_deg.max():g} deg"
                )
        else:
            lines.append("  twist       unconstrained")
        return lines

    def oracle(self, constraint: Any) -> BallOracle:
        return BallOracle(constraint)

    def check_keyframe(self, c: Any, first: Any, where: str, source: str | None) -> None:
        w = where
        if type(c.swing) is not type(first.swing):
            shape = {ConeSwing: "a cone", PolygonSwing: "a polygon", type(None): "no swing"}
            raise ConstraintError(f"every keyframe of a coupling has the same swing shape: "
                                  f"keyframe 0 has {shape[type(first.swing)]}, this one "
                                  f"{shape[type(c.swing)]}", f"{w}.swing", source)
        if (c.twist is None) != (first.twist is None):
            raise ConstraintError("every keyframe of a coupling limits the twist, or none does",
                                  f"{w}.twist", source)
        if c.twist is not None and c.twist.by_swing is not None:
            raise ConstraintError("a keyframe's twist is an interval (min_deg, max_deg); "
                                  "by_swing tables are not interpolated", f"{w}.twist.by_swing",
                                  source)

    def evaluate_coupled(self, q, axis, limits, k, t) -> OracleResult:
        first = limits.keyframes[0]
        nearest = None
        if isinstance(first.swing, ConeSwing):
            def nearest(d):
                return _cones_nearest(d, *limits.cones(k, t))
        elif isinstance(first.swing, PolygonSwing):
            def nearest(d):
                dist = np.empty(len(d))
                pts = np.empty((len(d), 3))
                for seg in np.unique(k):
                    rows = np.nonzero(k == seg)[0]
                    dist[rows], pts[rows] = nearest_on_polygons(
                        limits.polygon_at(seg, t[rows]), d[rows])
                return dist, pts
        twist_limits = None
        if first.twist is not None:
            lo, hi = limits.interval(k, t)

            def twist_limits(e):
                return lo, hi
        return evaluate_ball(q, axis, nearest, twist_limits, True)


class BallOracle(KindOracle):
    """The exact oracle of a swing-twist constraint (a ball or two-axis joint)."""

    def __init__(self, constraint: Any):
        self.axis = np.asarray(constraint.limb_axis, dtype=np.float64)
        self._axis_t = tuple(self.axis.tolist())
        swing = constraint.swing
        if isinstance(swing, ConeSwing):
            self.swing: ConeSolver | SphericalPolygon | None = ConeSolver(swing)
        elif isinstance(swing, PolygonSwing):
            self.swing = SphericalPolygon(swing.vertices, swing.interior)
        else:
            self.swing = None
        tw = constraint.twist
        self._twist = (tw.min, tw.max) if tw is not None else None
        self._table = tw.by_swing if tw is not None else None
        self._kernel_args: tuple | None = None  # built by the first single-orientation query
        # can an interval reach the ±π seam (so the twist test must look across it)?
        self._wraps = tw is not None and reaches_seam(tw.min, tw.max)

    def prepare(self) -> None:
        if isinstance(self.swing, SphericalPolygon):
            self.swing.prepare()

    def limits(self, d: np.ndarray):
        """Twist limits at unit directions (N, 3): arrays for a table, floats otherwise."""
        if self._table is not None:
            return self._table.limits_at(d)
        return self._twist

    def swing_dist(self, d: np.ndarray) -> np.ndarray:
        """Signed angular distance (N,) of unit directions (N, 3) to the swing boundary."""
        if self.swing is None:
            return np.full(len(d), -np.inf)
        return self.swing.nearest(d, need_point=False)[0]

    def is_valid(self, q2: np.ndarray) -> np.ndarray:
        d = Q.rotate(q2, self.axis)
        if self._twist is None:
            return self.swing_dist(d) <= BOUNDARY_TOLERANCE
        lo, hi = self.limits(d)
        valid = twist_inside(Q.twist_angle(q2, self.axis), lo, hi, self._wraps)
        if not valid.all():
            valid |= singular(q2, self.axis)
        # the swing's nearest-edge search (the costly part) only where the twist passes
        rows = np.flatnonzero(valid)
        if len(rows):
            valid[rows] = self.swing_dist(d[rows]) <= BOUNDARY_TOLERANCE
        return valid

    def evaluate(self, q: np.ndarray) -> OracleResult:
        return evaluate_ball(q, self.axis,
                             None if self.swing is None else self.swing.nearest,
                             None if self._twist is None else self.limits, self._wraps)

    def evaluate_one(self, qt) -> OracleResult:
        r = self._ball_one(qt)
        return OracleResult(
            valid=np.bool_(not r[0]),
            distance=np.float64(r[1]),
            projected=np.array(r[2:6]),
            correction=np.array(r[6:10]),
            swing_distance=np.float64(r[10]),
            twist=np.float64(r[11]),
        )

    def distance_projected_one(self, qt):
        r = self._ball_one(qt)
        return r[1], (r[2], r[3], r[4], r[5])

    def _ball_one(self, qt):
        """The compiled ball-joint kernel (:func:`_ball_kernel`) on one unit orientation."""
        k = self._kernel_args
        if k is None:
            k = self._kernel_args = self._make_kernel_args()
        if k[1] == _SWING_CANDIDATES:  # a polygon answered by its cap tree: candidates first
            d = qs.rotate(qt, self._axis_t)
            cand = self.swing._tree.search(np.array([d]), 0.0)[1]
            k = (*k[:5], cand, *k[6:])
        return _ball_kernel(*qt, *k)

    def _make_kernel_args(self) -> tuple:
        """The kernel's view of this constraint: the swing's and twist's arrays (placeholders
        of the same types where a part is absent, so one compiled signature serves all)."""
        none_i = np.zeros(1, dtype=np.int64)
        cone = np.zeros(7)
        G, ptr, edges = 1, none_i, none_i
        table, v0, vn, orient = np.zeros((1, 5, 3)), np.zeros((1, 3)), np.zeros((1, 3)), 1.0
        sw = self.swing
        if sw is None:
            kind = _SWING_NONE
        elif isinstance(sw, ConeSolver):
            kind = _SWING_CONE
            cone = np.array([*sw._c_t, sw.r, *sw._perp_t])
        else:
            table, v0, vn, orient = sw._table, sw.v0, sw.vertex_normal, float(sw.orient)
            if sw._lists:
                kind, G, ptr, edges = _SWING_CELLS, int(sw.G), sw.cell_ptr, sw.cell_edges
            else:
                kind = _SWING_CANDIDATES
        if self._twist is None:
            tkind, lo, hi = _TWIST_NONE, 0.0, 0.0
        else:
            tkind, (lo, hi) = _TWIST_CONSTANT, self._twist
        dirs_k, sums, kappa = np.zeros((1, 3)), np.zeros((3, 1)), 0.0
        if self._table is not None:
            tkind = _TWIST_TABLE
            dirs_k, sums, kappa = self._table._dirs_k, self._table._sums, self._table.kappa
        ax = np.array(self._axis_t)
        return (ax, kind, cone, G, ptr, edges, table, v0, vn, orient, tkind, float(lo),
                float(hi), bool(self._wraps), dirs_k, sums, float(kappa))


def evaluate_ball(q: np.ndarray, axis: np.ndarray, nearest, limits, wraps: bool = True
                  ) -> OracleResult:
    """The ball (and two-axis) joint oracle, batched, given its swing and twist as functions.

    Parameters
    ----------
    q : (N, 4) unit orientations
    axis : (3,) the limb axis
    nearest : callable or None
        ``nearest(d) -> (signed distance (N,), nearest boundary point (N, 3))`` for limb
        directions ``d`` (N, 3); None: the swing is unconstrained.
    limits : callable or None
        ``limits(e) -> (lo, hi)`` twist limits (radians, floats or (N,) arrays) at the corrected
        limb directions ``e``; None: the twist is unconstrained.
    wraps : bool
        An interval may reach the ±π seam (False only speeds the twist test up).
    """
    n = len(q)
    d = Q.rotate(q, axis)
    projected = q.copy()
    if nearest is not None:
        sdist, b = nearest(d)
        out = sdist > BOUNDARY_TOLERANCE
        if out.any():
            delta = Q.from_two_vectors(d[out], b[out])
            projected[out] = Q.multiply(delta, q[out])
    else:
        sdist = np.full(n, -np.inf)
        out = np.zeros(n, dtype=bool)
        b = d
    phi = Q.twist_angle(q, axis)
    margin = -sdist
    if limits is not None:
        any_out = bool(out.any())
        lo, hi = limits(np.where(out[:, None], b, d) if any_out else d)  # corrected direction
        lo = np.broadcast_to(lo, (n,))
        hi = np.broadcast_to(hi, (n,))
        phi_p = Q.twist_angle(projected, axis) if any_out else phi
        bad_tw = ~twist_inside(phi_p, lo, hi, wraps)
        if bad_tw.any():
            bad_tw &= ~singular(projected, axis)
        if bad_tw.any():
            f = phi_p[bad_tw]
            lo_b, hi_b = lo[bad_tw], hi[bad_tw]
            d_lo = np.abs(Q.wrap_angle(f - lo_b))
            d_hi = np.abs(Q.wrap_angle(f - hi_b))
            target = np.where(d_lo < d_hi, lo_b, hi_b)
            tau = Q.from_axis_angle(axis, Q.wrap_angle(target - f))
            projected[bad_tw] = Q.multiply(projected[bad_tw], tau)
        # the plain margin; across the seam a valid twist is within the tolerance of a
        # limit, and the distance clips the margin at 0 anyway
        margin = np.minimum(margin, np.minimum(phi - lo, hi - phi))
        tw_bad = ~twist_inside(phi, lo, hi, wraps)
        if tw_bad.any():
            sing = singular(q, axis)
            if sing.any():
                tw_bad &= ~sing
                margin = np.where(sing, np.minimum(margin, 0.0), margin)
        invalid = out | tw_bad
    else:
        invalid = out
    corr = np.tile(Q.IDENTITY, (n, 1))
    if invalid.any():
        c = Q.multiply(projected[invalid], Q.conjugate(q[invalid]))
        corr[invalid] = Q.canonical(c / np.linalg.norm(c, axis=1, keepdims=True))
        projected[invalid] /= np.linalg.norm(projected[invalid], axis=1, keepdims=True)
    distance = np.where(invalid, Q.angle(corr), -np.maximum(margin, 0.0))
    return OracleResult(
        valid=~invalid,
        distance=distance,
        projected=projected,
        correction=corr,
        swing_distance=sdist,
        twist=phi,
    )



# -- the compiled ball-joint kernel (the control loop's single-orientation path) -------------
_SWING_NONE, _SWING_CONE, _SWING_CELLS, _SWING_CANDIDATES = 0, 1, 2, 3
_TWIST_NONE, _TWIST_CONSTANT, _TWIST_TABLE = 0, 1, 2
_PI = math.pi


@njit(inline="always")
def _twist_k(w, x, y, z, ax):
    """:func:`models.quaternion.twist_angle1`."""
    p = x * ax[0] + y * ax[1] + z * ax[2]
    phi = 2.0 * math.atan2(-p, -w) if w < 0.0 else 2.0 * math.atan2(p, abs(w))
    return _PI if phi <= -_PI else phi


@njit(inline="always")
def _wrap_k(phi):
    """:func:`models.quaternion.wrap_angle1`."""
    if -_PI < phi <= _PI:
        return phi
    out = (phi + _PI) % _TWO_PI - _PI
    return _PI if out == -_PI else out


@njit(inline="always")
def _across_k(phi, lo, hi):
    t = BOUNDARY_TOLERANCE
    return phi - _TWO_PI >= lo - t or phi + _TWO_PI <= hi + t


@njit(inline="always")
def _two_vectors_k(a0, a1, a2, b0, b1, b2):
    """:func:`models.qscalar.from_two_vectors` (antiparallel: :func:`Q.perpendicular`)."""
    w = 1.0 + a0 * b0 + a1 * b1 + a2 * b2
    if w < 1e-12:
        m0, m1, m2 = abs(a0), abs(a1), abs(a2)
        k = 0 if m0 <= m1 and m0 <= m2 else (1 if m1 <= m2 else 2)
        e0, e1, e2 = (1.0 if k == 0 else 0.0), (1.0 if k == 1 else 0.0), (1.0 if k == 2 else 0.0)
        p0, p1, p2 = a1 * e2 - a2 * e1, a2 * e0 - a0 * e2, a0 * e1 - a1 * e0
        n = math.sqrt(p0 * p0 + p1 * p1 + p2 * p2)
        return 0.0, p0 / n, p1 / n, p2 / n
    q1, q2, q3 = a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0
    n = math.sqrt(w * w + q1 * q1 + q2 * q2 + q3 * q3)
    return w / n, q1 / n, q2 / n, q3 / n


@njit
def _ball_kernel(w, x, y, z, ax, swing_kind, cone, G, cell_ptr, cell_edges, table, v0, vn,
                 orient, twist_kind, lo, hi, wraps, dirs_k, sums, kappa):
    """:func:`evaluate_ball` for one unit orientation of a ball (or two-axis)
    joint: the same maths and tie rules in compiled plain floats. Returns ``(invalid,
    distance, projected (4), correction (4), swing distance, twist)``."""
    d0, d1, d2 = qk.rotate(w, x, y, z, ax[0], ax[1], ax[2])  # the limb direction
    p0, p1, p2, p3 = w, x, y, z
    swing_out = False
    b0, b1, b2 = d0, d1, d2
    if swing_kind == _SWING_NONE:
        sdist = -math.inf
    else:
        if swing_kind == _SWING_CONE:  # ConeSolver.nearest's closed form, one direction
            c0, c1, c2, r = cone[0], cone[1], cone[2], cone[3]
            cos_t = d0 * c0 + d1 * c1 + d2 * c2
            g0, g1, g2 = d0 - cos_t * c0, d1 - cos_t * c1, d2 - cos_t * c2
            sin_t = math.sqrt(g0 ** 2 + g1 ** 2 + g2 ** 2)
            sdist = math.atan2(sin_t, cos_t) - r
            if sin_t < 1e-15:
                u0, u1, u2 = cone[4], cone[5], cone[6]
            else:
                u0, u1, u2 = g0 / sin_t, g1 / sin_t, g2 / sin_t
            cr, sr = math.cos(r), math.sin(r)
            n0, n1, n2 = cr * c0 + sr * u0, cr * c1 + sr * u1, cr * c2 + sr * u2
        elif swing_kind == _SWING_CELLS:
            sdist, n0, n1, n2 = nearest_in_cell(d0, d1, d2, G, cell_ptr, cell_edges, table,
                                                 v0, vn, orient)
        else:
            sdist, n0, n1, n2 = rank_one(d0, d1, d2, cell_edges, table, v0, vn, orient)
        if sdist > BOUNDARY_TOLERANCE:
            swing_out = True
            b0, b1, b2 = n0, n1, n2
            e0, e1, e2, e3 = _two_vectors_k(d0, d1, d2, n0, n1, n2)
            p0, p1, p2, p3 = qk.mul(e0, e1, e2, e3, w, x, y, z)
    phi = _twist_k(w, x, y, z, ax)
    margin = -sdist
    invalid = swing_out
    if twist_kind != _TWIST_NONE:
        if twist_kind == _TWIST_TABLE:
            lo, hi = table_limits_one(b0, b1, b2, dirs_k, sums, kappa)
        phi_p = _twist_k(p0, p1, p2, p3, ax) if swing_out else phi
        t = BOUNDARY_TOLERANCE
        if not lo - t <= phi_p <= hi + t and not (
            (wraps and _across_k(phi_p, lo, hi))
            or p0 * p0 + (p1 * ax[0] + p2 * ax[1] + p3 * ax[2]) ** 2 < SING2
        ):
            d_lo = abs(_wrap_k(phi_p - lo))
            d_hi = abs(_wrap_k(phi_p - hi))
            half = 0.5 * _wrap_k((lo if d_lo < d_hi else hi) - phi_p)
            sh = math.sin(half)
            p0, p1, p2, p3 = qk.mul(p0, p1, p2, p3, math.cos(half), ax[0] * sh, ax[1] * sh,
                                    ax[2] * sh)
        if lo - t <= phi <= hi + t:
            margin = min(margin, phi - lo, hi - phi)
        elif (wraps and _across_k(phi, lo, hi)) or (
            w * w + (x * ax[0] + y * ax[1] + z * ax[2]) ** 2 < SING2
        ):
            margin = min(margin, 0.0)  # at a limit across the seam, or twist undefined
        else:
            invalid = True
    if invalid:  # correction1: proj ⊗ q⁻¹, w >= 0 (canonical's rule), and its angle
        k0, k1, k2, k3 = qk.mul(p0, p1, p2, p3, w, -x, -y, -z)
        cn = math.sqrt(k0 * k0 + k1 * k1 + k2 * k2 + k3 * k3)
        neg = k0 < 0.0
        if k0 == 0.0:
            for v in (k1, k2, k3):
                if v != 0.0:
                    neg = v < 0.0
                    break
        sign = -1.0 if neg else 1.0
        k0, k1, k2, k3 = sign * k0 / cn, sign * k1 / cn, sign * k2 / cn, sign * k3 / cn
        distance = 2.0 * math.atan2(math.sqrt(k1 * k1 + k2 * k2 + k3 * k3), abs(k0))
        pn = math.sqrt(p0 * p0 + p1 * p1 + p2 * p2 + p3 * p3)
        p0, p1, p2, p3 = p0 / pn, p1 / pn, p2 / pn, p3 / pn
    else:
        k0, k1, k2, k3 = 1.0, 0.0, 0.0, 0.0
        distance = -max(margin, 0.0)
    return invalid, distance, p0, p1, p2, p3, k0, k1, k2, k3, sdist, phi


# ---------------------------------------------------------------------------------------------
# Swing solvers: nearest(d) -> (signed distance (N,), nearest boundary point (N, 3))


# -- swing solvers: nearest(d) -> (signed distance (N,), nearest boundary point (N, 3)) -------
class ConeSolver:
    """Closed form for a circular boundary (thesis eq. 59-68)."""

    def __init__(self, cone: ConeSwing):
        self.c = np.asarray(cone.centre, dtype=np.float64)
        self.r = cone.radius
        self._perp = Q.perpendicular(self.c)
        self._c_t = tuple(self.c.tolist())
        self._perp_t = tuple(self._perp.tolist())

    def nearest(self, d: np.ndarray, need_point: bool = True):
        c = self.c
        cos_t = d @ c
        tang = d - cos_t[:, None] * c  # component of d perpendicular to the centre
        sin_t = np.linalg.norm(tang, axis=1)
        theta = np.arctan2(sin_t, cos_t)  # eq. 61: angle between limb and centre
        dist = theta - self.r  # eq. 62-63: valid iff theta <= r
        if not need_point:
            return dist, None
        # boundary point on the great circle through c and d (rotating d towards c by dist)
        tiny = sin_t < 1e-15
        safe = np.where(tiny, 1.0, sin_t)[:, None]
        u = np.where(tiny[:, None], self._perp, tang / safe)
        b = math.cos(self.r) * c + math.sin(self.r) * u
        return dist, b


# ---------------------------------------------------------------------------------------------
# Helpers kept for callers of the former API (the geometry now lives in models.geometry)


def _cones_nearest(d: np.ndarray, c: np.ndarray, r: np.ndarray):
    """:class:`ConeSolver`'s closed form with one cone (centre, radius) per row."""
    cos_t = np.einsum("ij,ij->i", d, c)
    tang = d - cos_t[:, None] * c
    sin_t = np.linalg.norm(tang, axis=1)
    dist = np.arctan2(sin_t, cos_t) - r
    tiny = sin_t < 1e-15
    u = tang / np.where(tiny, 1.0, sin_t)[:, None]
    if tiny.any():
        u[tiny] = Q.perpendicular(c[tiny])
    b = np.cos(r)[:, None] * c + np.sin(r)[:, None] * u
    return dist, b
