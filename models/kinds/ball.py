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
A coupled joint (limits at keyframes of another joint's angle, :mod:`models.limb`):
:meth:`BallKind.evaluate_coupled` batched, :func:`_coupled_ball_kernel` for one orientation —
the keyframes located (:func:`locate_k`), the cone or the corresponding polygon vertices and the
twist interval interpolated inside the kernel, the polygon's nearest edge by
:func:`lerped_polygon_nearest` (every edge, as :func:`models.geometry.nearest_on_polygons`),
then :func:`_ball_kernel`'s maths (:func:`_ball_rest`).
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

    def coupled_one(self, axis, limits):
        """Compiled (:func:`_coupled_ball_kernel`): the keyframes' cones, the corresponding
        polygons of every keyframe interval (one pair of vertex arrays, rows by interval) and
        the twist intervals are gathered here once; a query interpolates only what its angle
        needs — O(vertices) for a polygon, every edge tried as the batched path does."""
        first = limits.keyframes[0]
        n = len(limits.at)
        cones = np.zeros((n, 4))
        ptr = np.zeros(n, dtype=np.int64)
        va = vb = np.zeros((1, 3))
        if isinstance(first.swing, ConeSwing):
            kind = _SWING_CONE
            cones[:, :3] = [c.swing.centre for c in limits.keyframes]
            cones[:, 3] = [c.swing.radius for c in limits.keyframes]
        elif isinstance(first.swing, PolygonSwing):
            kind = _SWING_POLYGON
            ptr[1:] = np.cumsum([len(a) for a, _ in limits.polygons])
            va = np.ascontiguousarray(np.concatenate([a for a, _ in limits.polygons]))
            vb = np.ascontiguousarray(np.concatenate([b for _, b in limits.polygons]))
        else:
            kind = _SWING_NONE
        tkind, t_lo, t_hi = _TWIST_NONE, np.zeros(n), np.zeros(n)
        if first.twist is not None:
            tkind = _TWIST_CONSTANT
            t_lo[:] = [self.coupled_interval(c)[0] for c in limits.keyframes]
            t_hi[:] = [self.coupled_interval(c)[1] for c in limits.keyframes]
        args = (np.ascontiguousarray(limits.at, dtype=np.float64),
                np.array([float(v) for v in axis]), kind, cones, ptr, va, vb, tkind, t_lo, t_hi)
        kernel = _coupled_ball_kernel

        def one(w, x, y, z, angle):
            r = kernel(w, x, y, z, float(angle), *args)
            return not r[0], r[1], (r[2], r[3], r[4], r[5]), (r[6], r[7], r[8], r[9])
        one(1.0, 0.0, 0.0, 0.0, float(limits.at[0]))  # compiled or loaded now, not in a cycle
        return one


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
_SWING_NONE, _SWING_CONE, _SWING_CELLS, _SWING_CANDIDATES, _SWING_POLYGON = 0, 1, 2, 3, 4
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
    n0, n1, n2 = d0, d1, d2
    if swing_kind == _SWING_NONE:
        sdist = -math.inf
    elif swing_kind == _SWING_CONE:  # ConeSolver.nearest's closed form, one direction
        sdist, n0, n1, n2 = _cone_k(d0, d1, d2, cone[0], cone[1], cone[2], cone[3], cone[4],
                                    cone[5], cone[6])
    elif swing_kind == _SWING_CELLS:
        sdist, n0, n1, n2 = nearest_in_cell(d0, d1, d2, G, cell_ptr, cell_edges, table, v0,
                                             vn, orient)
    else:
        sdist, n0, n1, n2 = rank_one(d0, d1, d2, cell_edges, table, v0, vn, orient)
    return _ball_rest(w, x, y, z, ax, d0, d1, d2, sdist, n0, n1, n2, twist_kind, lo, hi, wraps,
                      dirs_k, sums, kappa)


@njit(inline="always")
def _cone_k(d0, d1, d2, c0, c1, c2, r, u0, u1, u2):
    """:meth:`ConeSolver.nearest` for one unit direction: (signed distance, nearest point);
    ``u`` the perpendicular taken when ``d`` is on the centre's axis."""
    cos_t = d0 * c0 + d1 * c1 + d2 * c2
    g0, g1, g2 = d0 - cos_t * c0, d1 - cos_t * c1, d2 - cos_t * c2
    sin_t = math.sqrt(g0 ** 2 + g1 ** 2 + g2 ** 2)
    sdist = math.atan2(sin_t, cos_t) - r
    if sin_t >= 1e-15:
        u0, u1, u2 = g0 / sin_t, g1 / sin_t, g2 / sin_t
    cr, sr = math.cos(r), math.sin(r)
    return sdist, cr * c0 + sr * u0, cr * c1 + sr * u1, cr * c2 + sr * u2


@njit(inline="always")
def _ball_rest(w, x, y, z, ax, d0, d1, d2, sdist, n0, n1, n2, twist_kind, lo, hi, wraps,
               dirs_k, sums, kappa):
    """:func:`evaluate_ball` after the swing's nearest point ``n`` of the limb direction ``d``
    at signed distance ``sdist`` (``-inf``: no swing limit): the swing correction, the twist,
    the correction (the returns of :func:`_ball_kernel`)."""
    p0, p1, p2, p3 = w, x, y, z
    swing_out = False
    b0, b1, b2 = d0, d1, d2
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


# -- a coupled ball (or two-axis) joint's compiled single-orientation path -------------------
@njit(inline="always")
def locate_k(at, angle):
    """:meth:`models.limb.InterpolatedLimits.locate` of one coupling angle: ``(k, t)``."""
    n = len(at)
    a = angle
    if a < at[0]:
        a = at[0]
    if a > at[n - 1]:
        a = at[n - 1]
    if a != a:  # NaN sorts last (searchsorted)
        k = n - 2
    else:
        k = -1
        for i in range(n):
            if at[i] <= a:
                k = i
        k = min(max(k, 0), n - 2)
    t = (a - at[k]) / (at[k + 1] - at[k])
    if t < 0.0:
        t = 0.0
    elif t > 1.0:
        t = 1.0
    return k, t


@njit(inline="always")
def _lerp_vertex(va, vb, i, t):
    """Vertex ``i`` of an interpolated polygon: :meth:`InterpolatedLimits.polygon_at`'s
    normalised ``(1 − t) a_i + t b_i``."""
    u = 1.0 - t
    v0 = u * va[i, 0] + t * vb[i, 0]
    v1 = u * va[i, 1] + t * vb[i, 1]
    v2 = u * va[i, 2] + t * vb[i, 2]
    n = math.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
    return v0 / n, v1 / n, v2 / n


@njit(inline="always")
def _edge_normal(va, vb, lo, m, i, t):
    """Unit normal ``v_i × v_{i+1} / |…|`` of edge ``i`` of the interpolated polygon whose
    ``m`` vertices start at row ``lo``."""
    a0, a1, a2 = _lerp_vertex(va, vb, lo + i, t)
    b0, b1, b2 = _lerp_vertex(va, vb, lo + (i + 1) % m, t)
    g0, g1, g2 = a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0
    gn = math.sqrt(g0 * g0 + g1 * g1 + g2 * g2)
    return g0 / gn, g1 / gn, g2 / gn


@njit
def lerped_polygon_nearest(px, py, pz, va, vb, lo, m, t):
    """:func:`models.geometry.nearest_on_polygons` for one unit point and its polygon, the
    interpolation at ``t`` of the oriented vertex rows ``lo .. lo + m`` of ``va`` and ``vb``
    (:meth:`models.limb.InterpolatedLimits.polygon_at`): every edge tried, the same keys, the
    lowest edge index on ties, the same pseudo-normal sign. Returns (signed distance, nearest
    point)."""
    best = math.inf
    win = -1
    win_in = False
    win_s = 0.0
    win_end1 = False
    w0 = w1 = w2 = 0.0
    f0, f1, f2 = _lerp_vertex(va, vb, lo, t)
    a0, a1, a2 = f0, f1, f2
    for i in range(m):
        if i + 1 < m:
            b0, b1, b2 = _lerp_vertex(va, vb, lo + i + 1, t)
        else:
            b0, b1, b2 = f0, f1, f2
        g0, g1, g2 = a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0
        gn = math.sqrt(g0 * g0 + g1 * g1 + g2 * g2)
        g0, g1, g2 = g0 / gn, g1 / gn, g2 / gn
        s = g0 * px + g1 * py + g2 * pz
        # t0 = g × v_i, t1 = v_{i+1} × g (along the edge at its start, back at its end)
        t00, t01, t02 = g1 * a2 - g2 * a1, g2 * a0 - g0 * a2, g0 * a1 - g1 * a0
        t10, t11, t12 = b1 * g2 - b2 * g1, b2 * g0 - b0 * g2, b0 * g1 - b1 * g0
        in_arc = (t00 * px + t01 * py + t02 * pz >= 0.0
                  and t10 * px + t11 * py + t12 * pz >= 0.0 and abs(s) < 1.0 - 1e-12)
        e0, e1, e2 = a0 - px, a1 - py, a2 - pz
        h0, h1, h2 = b0 - px, b1 - py, b2 - pz
        k0 = e0 * e0 + e1 * e1 + e2 * e2
        k1 = h0 * h0 + h1 * h1 + h2 * h2
        if in_arc:
            s2 = s * s
            key = 2.0 * s2 / (1.0 + math.sqrt(max(1.0 - s2, 0.0)))
        else:
            key = k0 if k0 <= k1 else k1
        if key < best:
            best, win, win_in, win_s, win_end1 = key, i, in_arc, s, k1 < k0
            w0, w1, w2 = g0, g1, g2
        a0, a1, a2 = b0, b1, b2
    if win_in:
        inside = win_s >= 0.0
        f0, f1, f2 = px - win_s * w0, py - win_s * w1, pz - win_s * w2
        fn = math.sqrt(f0 * f0 + f1 * f1 + f2 * f2)
        if fn < 1e-300:
            fn = 1.0
        n0, n1, n2 = f0 / fn, f1 / fn, f2 / fn
    else:
        vi = (win + 1) % m if win_end1 else win
        n0, n1, n2 = _lerp_vertex(va, vb, lo + vi, t)
        # the pseudo-normal: the inward normals of the vertex's two edges
        c0, c1, c2 = _edge_normal(va, vb, lo, m, vi, t)
        d0, d1, d2 = _edge_normal(va, vb, lo, m, (vi - 1) % m, t)
        inside = px * (c0 + d0) + py * (c1 + d1) + pz * (c2 + d2) >= 0.0
    theta = 2.0 * math.asin(min(math.sqrt(best) * 0.5, 1.0))
    return (-theta if inside else theta), n0, n1, n2


@njit
def _coupled_ball_kernel(w, x, y, z, angle, at, ax, swing_kind, cones, ptr, va, vb,
                         twist_kind, t_lo, t_hi):
    """:meth:`BallKind.evaluate_coupled` for one unit orientation at one coupling angle (the
    keyframes at angles ``at``): the limits interpolated as :class:`~models.limb.InterpolatedLimits`
    does — ``cones`` (K, 4) each keyframe's centre and radius; a polygon's corresponding vertex
    rows of keyframe interval ``k`` at ``ptr[k] .. ptr[k + 1]`` of ``va`` and ``vb``; twist
    intervals ``t_lo``, ``t_hi`` (K,) — then :func:`_ball_kernel`'s maths (returns alike)."""
    k, t = locate_k(at, angle)
    d0, d1, d2 = qk.rotate(w, x, y, z, ax[0], ax[1], ax[2])  # the limb direction
    n0, n1, n2 = d0, d1, d2
    if swing_kind == _SWING_NONE:
        sdist = -math.inf
    elif swing_kind == _SWING_CONE:  # InterpolatedLimits.cones, then _cones_nearest
        u = 1.0 - t
        c0 = u * cones[k, 0] + t * cones[k + 1, 0]
        c1 = u * cones[k, 1] + t * cones[k + 1, 1]
        c2 = u * cones[k, 2] + t * cones[k + 1, 2]
        cn = math.sqrt(c0 * c0 + c1 * c1 + c2 * c2)
        c0, c1, c2 = c0 / cn, c1 / cn, c2 / cn
        r = u * cones[k, 3] + t * cones[k + 1, 3]
        # models.quaternion.perpendicular: × the basis axis least aligned (lowest index on ties)
        m0, m1, m2 = abs(c0), abs(c1), abs(c2)
        j = 0 if m0 <= m1 and m0 <= m2 else (1 if m1 <= m2 else 2)
        e0, e1, e2 = (1.0 if j == 0 else 0.0), (1.0 if j == 1 else 0.0), (1.0 if j == 2 else 0.0)
        q0, q1, q2 = c1 * e2 - c2 * e1, c2 * e0 - c0 * e2, c0 * e1 - c1 * e0
        qn = math.sqrt(q0 * q0 + q1 * q1 + q2 * q2)
        sdist, n0, n1, n2 = _cone_k(d0, d1, d2, c0, c1, c2, r, q0 / qn, q1 / qn, q2 / qn)
    else:
        lo = ptr[k]
        sdist, n0, n1, n2 = lerped_polygon_nearest(d0, d1, d2, va, vb, lo, ptr[k + 1] - lo, t)
    lo_t = (1.0 - t) * t_lo[k] + t * t_lo[k + 1]
    hi_t = (1.0 - t) * t_hi[k] + t * t_hi[k + 1]
    return _ball_rest(w, x, y, z, ax, d0, d1, d2, sdist, n0, n1, n2, twist_kind, lo_t, hi_t,
                      True, cones, cones, 0.0)


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
