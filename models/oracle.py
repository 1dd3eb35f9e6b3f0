"""The exact joint-constraint oracle: validity, nearest valid orientation, correction, distance.

One vectorised implementation, used for dataset generation, model evaluation and the live
supervisor.

Maths
-----
Let ``q`` be an orientation (limb relative to parent), ``a`` the limb axis (limb frame) and
``d = q a q*`` the limb direction (parent frame). Decompose ``q = swing ⊗ twist`` about ``a``
(:func:`models.quaternion.swing_twist`) and let ``φ`` be the twist angle.

*Swing.* ``d`` must lie in the region ``S ⊂ S²`` (cone or spherical polygon). If it does not,
the limb endpoint moves along the geodesic to the nearest boundary point ``b`` — nearness
measured "by the effect on unit vectors" (thesis ch. 4), i.e. by the angle between ``d`` and
``b``. The swing correction is the minimal rotation taking ``d`` to ``b``, expressed in the parent
frame: ``Δ = [cos(θ/2), (d×b)/|d×b| sin(θ/2)]`` with ``θ = ∠(d, b)`` (thesis eq. 63-68 with the
cone centre ``C``: ``b`` lies on the great circle through ``d`` and ``C``, ``r`` from ``C``).

*Twist.* After the swing correction, the twist ``φ'`` of ``Δ ⊗ q`` is clamped to
``[min, max]`` by a right-multiplied rotation about ``a``; the limb direction is unchanged.

So ``project(q) = Δ ⊗ q ⊗ τ`` and ``correction(q) = project(q) ⊗ q⁻¹`` (identity for a valid
``q``; returned with ``w ≥ 0``). For swing-only constraints the correction angle equals the
angular distance ``θ`` from ``d`` to the swing boundary.

Signed distance: for an invalid ``q``, the angle of its correction (> 0); for a valid one,
``−min(swing margin, twist margin)`` (≤ 0), where the swing margin is the angle from ``d`` to
the boundary and the twist margin ``min(φ − min, max − φ)``.

Determinism at discontinuities (thesis's "correctional" and "concave-region" discontinuities)
--------------------------------------------------------------------------------------------
- Cone, ``d = −centre`` (every boundary point equidistant): ``b`` is reached by rotating about
  the axis ``centre × e`` where ``e`` is the basis vector least aligned with the centre (lowest
  index on ties) — the same rule as :func:`models.quaternion.from_two_vectors`.
- Polygon, several boundary points exactly equidistant: the edge with the lowest index wins
  (edge ``i`` joins vertices ``i`` and ``i+1``).
- Twist exactly half-way round from the allowed interval: clamped to ``max``.
- A point within :data:`BOUNDARY_TOLERANCE` outside counts as valid (its correction is identity).
- ``q`` and ``−q`` give the same validity, distance and correction; ``project`` keeps the sign
  of its input.

Speed
-----
A polygon's nearest edge is found through a cube-map grid over S²: for every cell the oracle
precomputes the edges that can be nearest to *any* point of the cell (edges whose distance from
the cell centre is within ``D + 2ρ`` of the nearest, ``ρ`` the cell's angular radius), so the
search is exact yet touches only a handful of edges per query.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from models import quaternion as Q
from models.constraint import ConeSwing, JointConstraint, PolygonSwing

__all__ = [
    "BOUNDARY_TOLERANCE",
    "ConstraintOracle",
    "OracleResult",
    "polygon_area_sr",
    "polygon_boundary_distance",
]

#: Orientations at most this far (radians) outside the boundary count as valid.
BOUNDARY_TOLERANCE = 1e-9


@dataclass(frozen=True)
class OracleResult:
    """Everything the oracle knows about a batch of orientations (arrays of length N).

    Attributes
    ----------
    valid : (N,) bool
    distance : (N,) float64, radians; > 0 outside (correction angle), <= 0 inside (-margin)
    projected : (N, 4) float64, nearest valid orientation, same sign as the input
    correction : (N, 4) float64, ``projected ⊗ q⁻¹`` with ``w >= 0``; identity when valid
    swing_distance : (N,) float64, radians, signed distance of the limb direction to the swing
        boundary (negative inside; ``-inf`` when swing is unconstrained)
    twist : (N,) float64, radians, twist angle of the input about the limb axis
    """

    valid: np.ndarray
    distance: np.ndarray
    projected: np.ndarray
    correction: np.ndarray
    swing_distance: np.ndarray
    twist: np.ndarray


class ConstraintOracle:
    """Exact answers for one :class:`~models.constraint.JointConstraint`.

    Parameters
    ----------
    constraint : JointConstraint

    All methods accept ``q`` of shape ``(4,)`` or ``(N, 4)`` (scalar-first, unit norm, either
    sign; validated by :func:`models.quaternion.check_quaternions`) and return arrays with the
    matching leading shape.
    """

    def __init__(self, constraint: JointConstraint):
        self.constraint = constraint
        self.axis = np.asarray(constraint.limb_axis, dtype=np.float64)
        self._axis_t = tuple(self.axis.tolist())
        swing = constraint.swing
        if isinstance(swing, ConeSwing):
            self._swing: _ConeSolver | _PolygonSolver | None = _ConeSolver(swing)
        elif isinstance(swing, PolygonSwing):
            self._swing = _PolygonSolver(swing.vertices, swing.interior)
        else:
            self._swing = None
        tw = constraint.twist
        self._twist = (tw.min, tw.max) if tw is not None else None

    # -- public API ------------------------------------------------------------------------
    def evaluate(self, q, *, normalize: bool = False) -> OracleResult:
        """Validity, distance, projection and correction in one pass.

        A single orientation (shape ``(4,)``) takes a scalar path (plain floats, one small
        numpy gather for a polygon) built for the control loop; it gives the same answers as
        the batched path.
        """
        if isinstance(q, np.ndarray) and q.shape == (4,) and q.dtype.kind in "fiu":
            return self._evaluate_one(q, normalize)
        q = Q.check_quaternions(q, normalize=normalize)
        single = q.ndim == 1
        q2 = q.reshape(-1, 4)
        res = self._evaluate(q2)
        if single:
            res = OracleResult(*(np.asarray(x)[0] for x in res.__dict__.values()))
        return res

    def is_valid(self, q, *, normalize: bool = False) -> np.ndarray:
        """True where the orientation satisfies the constraint (within tolerance)."""
        q2, single = self._prep(q, normalize)
        valid = self._swing_dist(Q.rotate(q2, self.axis)) <= BOUNDARY_TOLERANCE
        if self._twist is not None:
            phi = Q.twist_angle(q2, self.axis)
            lo, hi = self._twist
            valid &= (phi >= lo - BOUNDARY_TOLERANCE) & (phi <= hi + BOUNDARY_TOLERANCE)
        return valid[0] if single else valid

    def project(self, q, *, normalize: bool = False) -> np.ndarray:
        """Nearest valid orientation (same quaternion sign as the input)."""
        return self.evaluate(q, normalize=normalize).projected

    def correction(self, q, *, normalize: bool = False) -> np.ndarray:
        """Corrective quaternion ``project(q) ⊗ q⁻¹`` (``w >= 0``, identity when valid)."""
        return self.evaluate(q, normalize=normalize).correction

    def signed_distance(self, q, *, normalize: bool = False) -> np.ndarray:
        """Signed angular distance to the boundary, radians (> 0 outside, <= 0 inside)."""
        return self.evaluate(q, normalize=normalize).distance

    def swing_distance(self, directions) -> np.ndarray:
        """Signed angular distance (radians) of limb directions (N, 3) to the swing boundary."""
        d = Q.check_vectors(directions, name="direction")
        single = d.ndim == 1
        out = self._swing_dist(d.reshape(-1, 3))
        return out[0] if single else out

    def nearest_swing_point(self, directions) -> np.ndarray:
        """Nearest point of the swing region (N, 3): the direction itself when inside."""
        d = Q.check_vectors(directions, name="direction")
        single = d.ndim == 1
        d2 = d.reshape(-1, 3)
        if self._swing is None:
            return d
        dist, b = self._swing.nearest(d2)
        out = np.where((dist > BOUNDARY_TOLERANCE)[:, None], b, d2)
        return out[0] if single else out

    # -- internals -------------------------------------------------------------------------
    def _evaluate_one(self, q: np.ndarray, normalize: bool) -> OracleResult:
        """Scalar twin of :meth:`_evaluate` for one orientation (same maths, same tie rules)."""
        w, x, y, z = q.tolist()
        nrm = math.sqrt(w * w + x * x + y * y + z * z)
        if (
            not math.isfinite(nrm)
            or nrm < 1e-12
            or (not normalize and abs(nrm - 1.0) > Q.UNIT_TOLERANCE)
        ):
            Q.check_quaternions(q, normalize=normalize)  # raises with the precise message
        qt = (w / nrm, x / nrm, y / nrm, z / nrm)
        ax = self._axis_t
        d = _rot1(qt, ax)
        proj = qt
        swing_out = False
        if self._swing is not None:
            sdist, b = self._swing.nearest_one(d)
            if sdist > BOUNDARY_TOLERANCE:
                swing_out = True
                proj = _mul1(_two_vectors1(d, b), qt)
        else:
            sdist = -math.inf
        phi = _twist1(qt, ax)
        margin = -sdist
        invalid = swing_out
        if self._twist is not None:
            lo, hi = self._twist
            phi_p = _twist1(proj, ax) if swing_out else phi
            if phi_p < lo - BOUNDARY_TOLERANCE or phi_p > hi + BOUNDARY_TOLERANCE:
                d_lo = abs(_wrap1(phi_p - lo))
                d_hi = abs(_wrap1(phi_p - hi))
                half = 0.5 * _wrap1((lo if d_lo < d_hi else hi) - phi_p)
                sh = math.sin(half)
                proj = _mul1(proj, (math.cos(half), ax[0] * sh, ax[1] * sh, ax[2] * sh))
            margin = min(margin, phi - lo, hi - phi)
            invalid = invalid or phi < lo - BOUNDARY_TOLERANCE or phi > hi + BOUNDARY_TOLERANCE
        if invalid:
            c = _mul1(proj, (qt[0], -qt[1], -qt[2], -qt[3]))
            cn = math.sqrt(c[0] * c[0] + c[1] * c[1] + c[2] * c[2] + c[3] * c[3])
            sign = -1.0 if c[0] < 0.0 or (c[0] == 0.0 and _first_nonzero_negative(c)) else 1.0
            corr = tuple(sign * v / cn for v in c)
            pn = math.sqrt(proj[0] ** 2 + proj[1] ** 2 + proj[2] ** 2 + proj[3] ** 2)
            proj = tuple(v / pn for v in proj)
            distance = 2.0 * math.atan2(
                math.sqrt(corr[1] ** 2 + corr[2] ** 2 + corr[3] ** 2), abs(corr[0])
            )
        else:
            corr = (1.0, 0.0, 0.0, 0.0)
            distance = -max(margin, 0.0)
        return OracleResult(
            valid=np.bool_(not invalid),
            distance=np.float64(distance),
            projected=np.array(proj),
            correction=np.array(corr),
            swing_distance=np.float64(sdist),
            twist=np.float64(phi),
        )

    def _prep(self, q, normalize):
        q = Q.check_quaternions(q, normalize=normalize)
        return q.reshape(-1, 4), q.ndim == 1

    def _swing_dist(self, d: np.ndarray) -> np.ndarray:
        if self._swing is None:
            return np.full(len(d), -np.inf)
        return self._swing.nearest(d, need_point=False)[0]

    def _evaluate(self, q: np.ndarray) -> OracleResult:
        n = len(q)
        d = Q.rotate(q, self.axis)
        projected = q.copy()
        if self._swing is not None:
            sdist, b = self._swing.nearest(d)
            out = sdist > BOUNDARY_TOLERANCE
            if out.any():
                delta = Q.from_two_vectors(d[out], b[out])
                projected[out] = Q.multiply(delta, q[out])
        else:
            sdist = np.full(n, -np.inf)
            out = np.zeros(n, dtype=bool)
        phi = Q.twist_angle(q, self.axis)
        margin = -sdist
        if self._twist is not None:
            lo, hi = self._twist
            phi_p = Q.twist_angle(projected, self.axis) if out.any() else phi
            bad_tw = (phi_p < lo - BOUNDARY_TOLERANCE) | (phi_p > hi + BOUNDARY_TOLERANCE)
            if bad_tw.any():
                f = phi_p[bad_tw]
                d_lo = np.abs(_wrap(f - lo))
                d_hi = np.abs(_wrap(f - hi))
                target = np.where(d_lo < d_hi, lo, hi)
                tau = Q.from_axis_angle(self.axis, _wrap(target - f))
                projected[bad_tw] = Q.multiply(projected[bad_tw], tau)
            tw_margin = np.minimum(phi - lo, hi - phi)
            margin = np.minimum(margin, tw_margin)
            invalid = out | (phi < lo - BOUNDARY_TOLERANCE) | (phi > hi + BOUNDARY_TOLERANCE)
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


def _wrap(x: np.ndarray) -> np.ndarray:
    return np.mod(x + np.pi, 2.0 * np.pi) - np.pi


# -- scalar kernels for the single-orientation path (tuples of floats, w x y z) ---------------
def _wrap1(x: float) -> float:
    return (x + math.pi) % (2.0 * math.pi) - math.pi


def _mul1(p, q):
    pw, px, py, pz = p
    qw, qx, qy, qz = q
    return (
        pw * qw - px * qx - py * qy - pz * qz,
        pw * qx + px * qw + py * qz - pz * qy,
        pw * qy - px * qz + py * qw + pz * qx,
        pw * qz + px * qy - py * qx + pz * qw,
    )


def _rot1(q, v):
    w, x, y, z = q
    tx = 2.0 * (y * v[2] - z * v[1])
    ty = 2.0 * (z * v[0] - x * v[2])
    tz = 2.0 * (x * v[1] - y * v[0])
    return (
        v[0] + w * tx + (y * tz - z * ty),
        v[1] + w * ty + (z * tx - x * tz),
        v[2] + w * tz + (x * ty - y * tx),
    )


def _twist1(q, a) -> float:
    return _wrap1(2.0 * math.atan2(q[1] * a[0] + q[2] * a[1] + q[3] * a[2], q[0]))


def _two_vectors1(a, b):
    w = 1.0 + a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
    if w < 1e-12:  # antiparallel: same rule as models.quaternion.from_two_vectors
        return (0.0, *Q._perpendicular(np.array(a)).tolist())
    q = (w, a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])
    n = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    return (q[0] / n, q[1] / n, q[2] / n, q[3] / n)


def _first_nonzero_negative(c) -> bool:
    for v in c:
        if v != 0.0:
            return v < 0.0
    return False


# ---------------------------------------------------------------------------------------------
# Swing solvers: nearest(d) -> (signed distance (N,), nearest boundary point (N, 3))
# ---------------------------------------------------------------------------------------------
class _ConeSolver:
    """Closed form for a circular boundary (thesis eq. 59-68)."""

    def __init__(self, cone: ConeSwing):
        self.c = np.asarray(cone.centre, dtype=np.float64)
        self.r = cone.radius
        self._perp = Q._perpendicular(self.c)
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

    def nearest_one(self, d: tuple[float, float, float]):
        """Scalar twin of :meth:`nearest` for one direction."""
        c = self._c_t
        cos_t = d[0] * c[0] + d[1] * c[1] + d[2] * c[2]
        tang = (d[0] - cos_t * c[0], d[1] - cos_t * c[1], d[2] - cos_t * c[2])
        sin_t = math.sqrt(tang[0] ** 2 + tang[1] ** 2 + tang[2] ** 2)
        dist = math.atan2(sin_t, cos_t) - self.r
        u = self._perp_t if sin_t < 1e-15 else (tang[0] / sin_t, tang[1] / sin_t, tang[2] / sin_t)
        cr, sr = math.cos(self.r), math.sin(self.r)
        return dist, (cr * c[0] + sr * u[0], cr * c[1] + sr * u[1], cr * c[2] + sr * u[2])


class _PolygonSolver:
    """Exact nearest boundary point of a spherical polygon, with a cube-map candidate grid."""

    def __init__(self, vertices: np.ndarray, interior: np.ndarray | None, grid: int | None = None):
        v = np.asarray(vertices, dtype=np.float64)
        self.m = len(v)
        self.v0 = v
        self.v1 = np.roll(v, -1, axis=0)
        g = np.cross(self.v0, self.v1)
        self.g = g / np.linalg.norm(g, axis=1, keepdims=True)  # geometric edge normals
        self.t0 = np.cross(self.g, self.v0)  # along the edge at its start
        self.t1 = np.cross(self.v1, self.g)  # back along the edge at its end
        self.orient = 1.0
        self._set_pseudo_normals()
        if interior is None:  # only unsigned distances are wanted
            return
        # orient the normals so that the interior point is inside
        if self._brute(np.asarray(interior, dtype=np.float64)[None, :])[0][0] > 0.0:
            self.orient = -1.0
            self._set_pseudo_normals()
        self.G = grid if grid is not None else int(np.clip(round(3.0 * math.sqrt(self.m)), 8, 64))
        self._build_grid()

    def _set_pseudo_normals(self):
        n_in = self.orient * self.g
        # vertex k is the start of edge k and the end of edge k-1
        self.vertex_normal = n_in + np.roll(n_in, 1, axis=0)
        # one row per edge, gathered once per (point, edge) pair: g | t0 | t1 | v0 | v1
        self._table = np.ascontiguousarray(
            np.stack((self.g, self.t0, self.t1, self.v0, self.v1), 1)
        )
        # plain-float copies for the scalar (single-orientation) path
        self._g_list = [tuple(r) for r in self.g.tolist()]
        self._v_list = [tuple(r) for r in self.v0.tolist()]
        self._vn_list = [tuple(r) for r in self.vertex_normal.tolist()]

    # -- per (point, edge) pair ----------------------------------------------------------------
    def _pair_keys(self, p: np.ndarray, e: np.ndarray):
        """Squared chord from p to edge e's nearest point, plus what is needed to classify.

        ``p`` (K, 3) and ``e`` (K,) list the pairs. Returns ``key`` (squared chord, monotonic in
        the angle), ``in_arc`` (the nearest point is inside the edge, not an end), ``s`` (sine
        of the angle to the edge's great circle, signed by the geometric normal) and
        ``end_is_1`` (when an end is nearest: is it the edge's second vertex).
        """
        t = self._table[e]  # (K, 5, 3): g, t0, t1, v0, v1 of each pair's edge
        dots = np.einsum("kij,kj->ki", t[:, :3], p)
        s = dots[:, 0]
        in_arc = (dots[:, 1] >= 0.0) & (dots[:, 2] >= 0.0) & (np.abs(s) < 1.0 - 1e-12)
        s2 = s * s
        key_in = 2.0 * s2 / (1.0 + np.sqrt(np.maximum(1.0 - s2, 0.0)))
        # squared chords to the ends by differences (not 2 - 2 p·v: exact near a vertex)
        diff = t[:, 3:] - p[:, None, :]
        k01 = np.einsum("kij,kij->ki", diff, diff)
        end_is_1 = k01[:, 1] < k01[:, 0]
        key = np.where(in_arc, key_in, np.minimum(k01[:, 0], k01[:, 1]))
        return key, in_arc, s, end_is_1

    def _finish(self, p, e, key, in_arc, s, end_is_1, need_point):
        """Signed distance (and nearest point) from the winning edge of each point."""
        theta = 2.0 * np.arcsin(np.minimum(np.sqrt(key) * 0.5, 1.0))
        vidx = np.where(end_is_1, (e + 1) % self.m, e)
        inside_edge = self.orient * s >= 0.0
        inside_vertex = np.einsum("ij,ij->i", p, self.vertex_normal[vidx]) >= 0.0
        inside = np.where(in_arc, inside_edge, inside_vertex)
        dist = np.where(inside, -theta, theta)
        if not need_point:
            return dist, None
        foot = p - s[:, None] * self.g[e]
        fn = np.linalg.norm(foot, axis=1, keepdims=True)
        foot = foot / np.where(fn < 1e-300, 1.0, fn)
        b = np.where(in_arc[:, None], foot, self.v0[vidx])
        return dist, b

    def _brute(self, p: np.ndarray, need_point: bool = False):
        """Nearest over all edges (used for set-up and as the reference in tests)."""
        n = len(p)
        pi = np.repeat(np.arange(n), self.m)
        e = np.tile(np.arange(self.m), n)
        key, in_arc, s, end1 = self._pair_keys(p[pi], e)
        best = np.argmin(key.reshape(n, self.m), axis=1)  # first minimum: lowest edge index
        sel = np.arange(n) * self.m + best
        return self._finish(p, best, key[sel], in_arc[sel], s[sel], end1[sel], need_point)

    # -- grid ------------------------------------------------------------------------------
    #: finest grid and the candidate count below which refining stops paying
    MAX_GRID = 128
    TARGET_CANDIDATES = 6.0
    MAX_BUILD_PAIRS = 4_000_000

    def _cell_index(self, p: np.ndarray, G: int | None = None) -> np.ndarray:
        G = self.G if G is None else G
        ab = np.abs(p)
        ax = np.argmax(ab, axis=1)
        r = np.arange(len(p))
        major = p[r, ax]
        inv = 1.0 / np.abs(major)
        u = p[r, (ax + 1) % 3] * inv
        v = p[r, (ax + 2) % 3] * inv
        i = np.clip(((u + 1.0) * (0.5 * G)).astype(np.int64), 0, G - 1)
        j = np.clip(((v + 1.0) * (0.5 * G)).astype(np.int64), 0, G - 1)
        face = 2 * ax + (major < 0)
        return (face * G + i) * G + j

    def _build_grid(self):
        """Candidate edges per cube-map cell, refined level by level (each cell's list is a
        subset of its parent's, so a level only searches its parent's candidates)."""
        G = 8
        ptr = np.arange(6 * G * G + 1) * self.m
        edges = np.tile(np.arange(self.m), 6 * G * G)
        while True:
            ptr, edges = self._refine(G, ptr, edges)
            mean = (ptr[-1]) / (len(ptr) - 1)
            if (
                G >= self.MAX_GRID
                or mean <= self.TARGET_CANDIDATES
                or 4 * len(edges) > self.MAX_BUILD_PAIRS  # the next level would cost too much
            ):
                break
            # subdivide: child (i, j) at 2G inherits the list of parent (i // 2, j // 2) at G
            G2 = 2 * G
            f, i, j = np.meshgrid(np.arange(6), np.arange(G2), np.arange(G2), indexing="ij")
            parent = ((f * G + i // 2) * G + j // 2).ravel()
            counts = ptr[parent + 1] - ptr[parent]
            starts = ptr[parent]
            new_ptr = np.concatenate(([0], np.cumsum(counts)))
            owner = np.repeat(np.arange(len(parent)), counts)
            edges = edges[np.arange(new_ptr[-1]) - new_ptr[owner] + starts[owner]]
            ptr, G = new_ptr, G2
        self.G = G
        self.cell_ptr = ptr
        self.cell_edges = edges
        self.mean_candidates = float(ptr[-1] / (len(ptr) - 1))

    def _refine(self, G: int, ptr: np.ndarray, edges: np.ndarray):
        """Keep, per cell of a G-grid, the edges that can be nearest to some point of the cell."""
        centres, radii = _cube_cells(G)
        n_cells = len(centres)
        counts = np.diff(ptr)
        owner = np.repeat(np.arange(n_cells), counts)
        angles = np.empty(len(edges))
        chunk = 1_000_000
        for s in range(0, len(edges), chunk):
            key = self._pair_keys(centres[owner[s : s + chunk]], edges[s : s + chunk])[0]
            angles[s : s + chunk] = 2.0 * np.arcsin(np.minimum(np.sqrt(key) * 0.5, 1.0))
        starts = ptr[:-1]
        nearest = np.minimum.reduceat(angles, starts) if len(edges) else np.zeros(n_cells)
        bound = nearest + 2.0 * radii + 1e-9
        keep = angles <= bound[owner]
        new_counts = np.add.reduceat(keep.astype(np.int64), starts)
        return np.concatenate(([0], np.cumsum(new_counts))), edges[keep]

    def nearest(self, p: np.ndarray, need_point: bool = True, chunk: int = 16384):
        """Signed distance (N,) and nearest boundary point (N, 3) of unit directions ``p``."""
        n = len(p)
        if n > chunk:
            parts = [self.nearest(p[s : s + chunk], need_point, chunk) for s in range(0, n, chunk)]
            dist = np.concatenate([x[0] for x in parts])
            pts = np.concatenate([x[1] for x in parts]) if need_point else None
            return dist, pts
        cell = self._cell_index(p)
        start = self.cell_ptr[cell]
        counts = self.cell_ptr[cell + 1] - start
        offsets = np.zeros(n, dtype=np.int64)
        np.cumsum(counts[:-1], out=offsets[1:])
        total = int(offsets[-1] + counts[-1]) if n else 0
        owner = np.repeat(np.arange(n), counts)
        pos = np.arange(total) - (offsets - start)[owner]
        e = self.cell_edges[pos]
        key, in_arc, s, end1 = self._pair_keys(p[owner], e)
        best_key = np.minimum.reduceat(key, offsets)
        hit = np.flatnonzero(key == best_key[owner])
        first = hit[np.searchsorted(owner[hit], np.arange(n))]  # lowest edge index on ties
        return self._finish(
            p, e[first], key[first], in_arc[first], s[first], end1[first], need_point
        )

    def nearest_one(self, d: tuple[float, float, float]):
        """Scalar twin of :meth:`nearest` for one direction (one gather of the cell's edges)."""
        px, py, pz = d
        ab = (abs(px), abs(py), abs(pz))
        ax = 0 if ab[0] >= ab[1] and ab[0] >= ab[2] else (1 if ab[1] >= ab[2] else 2)
        major = d[ax]
        u = d[(ax + 1) % 3] / abs(major)
        v = d[(ax + 2) % 3] / abs(major)
        G = self.G
        i = min(max(int((u + 1.0) * (0.5 * G)), 0), G - 1)
        j = min(max(int((v + 1.0) * (0.5 * G)), 0), G - 1)
        cell = ((2 * ax + (major < 0)) * G + i) * G + j
        cand = self.cell_edges[self.cell_ptr[cell] : self.cell_ptr[cell + 1]]
        # all five dot products of every candidate edge in one product; the end chords come
        # from 2 - 2 p·v here (ranking only: the winner's distance is recomputed exactly below)
        dots = self._table[cand] @ np.array(d)
        s = dots[:, 0]
        s2 = s * s
        in_arc = (dots[:, 1] >= 0.0) & (dots[:, 2] >= 0.0) & (s2 < (1.0 - 1e-12) ** 2)
        key_in = 2.0 * s2 / (1.0 + np.sqrt(np.maximum(1.0 - s2, 0.0)))
        k01 = 2.0 - 2.0 * dots[:, 3:]
        k = int(np.argmin(np.where(in_arc, key_in, k01.min(axis=1))))  # ties: lowest edge
        e = int(cand[k])
        if in_arc[k]:
            sk = float(s[k])
            key = 2.0 * sk * sk / (1.0 + math.sqrt(max(1.0 - sk * sk, 0.0)))
            inside = self.orient * sk >= 0.0
            g = self._g_list[e]
            f = (px - sk * g[0], py - sk * g[1], pz - sk * g[2])
            fn = math.sqrt(f[0] * f[0] + f[1] * f[1] + f[2] * f[2]) or 1.0
            b = (f[0] / fn, f[1] / fn, f[2] / fn)
        else:
            vi = (e + 1) % self.m if k01[k, 1] < k01[k, 0] else e
            b = self._v_list[vi]
            key = (px - b[0]) ** 2 + (py - b[1]) ** 2 + (pz - b[2]) ** 2
            mv = self._vn_list[vi]
            inside = px * mv[0] + py * mv[1] + pz * mv[2] >= 0.0
        theta = 2.0 * math.asin(min(math.sqrt(key) * 0.5, 1.0))
        return (-theta if inside else theta), b


def _cube_cells(G: int) -> tuple[np.ndarray, np.ndarray]:
    """Centres (6G², 3) and angular radii (6G²,) of a G×G cube map's cells, in index order."""
    edges = (np.arange(G + 1) / G) * 2.0 - 1.0
    mids = (np.arange(G) + 0.5) / G * 2.0 - 1.0
    centres, radii = [], []
    uu, vv = np.meshgrid(mids, mids, indexing="ij")
    for face in range(6):
        ax, sign = face // 2, -1.0 if face % 2 else 1.0
        c = _face_points(ax, sign, uu.ravel(), vv.ravel())
        rad = np.zeros(len(c))
        for du in (0, 1):
            for dv in (0, 1):
                cu, cv = np.meshgrid(edges[du : G + du], edges[dv : G + dv], indexing="ij")
                corner = _face_points(ax, sign, cu.ravel(), cv.ravel())
                rad = np.maximum(rad, Q.angle_between(c, corner))
        centres.append(c)
        radii.append(rad)
    return np.concatenate(centres), np.concatenate(radii)


def _face_points(ax: int, sign: float, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    p = np.empty((len(u), 3))
    p[:, ax] = sign
    p[:, (ax + 1) % 3] = u
    p[:, (ax + 2) % 3] = v
    return p / np.linalg.norm(p, axis=1, keepdims=True)


# ---------------------------------------------------------------------------------------------
# Helpers used by constraint validation and summaries
# ---------------------------------------------------------------------------------------------
def polygon_boundary_distance(vertices: np.ndarray, point: np.ndarray) -> float:
    """Unsigned angular distance (radians) from ``point`` to a polygon's boundary (brute force)."""
    solver = _PolygonSolver(vertices, interior=None)
    return float(abs(solver._brute(np.asarray(point, dtype=np.float64)[None, :])[0][0]))


def polygon_area_sr(swing: PolygonSwing) -> float:
    """Solid angle (steradians) of a polygon's valid region, from the turning angles."""
    v = swing.vertices
    g = np.cross(v, np.roll(v, -1, axis=0))
    g /= np.linalg.norm(g, axis=1, keepdims=True)
    t_out = np.cross(g, v)  # leaving vertex k along edge k
    t_in = np.cross(np.roll(g, 1, axis=0), v)  # arriving at vertex k along edge k-1
    turn = np.arctan2(
        np.einsum("ij,ij->i", np.cross(t_in, t_out), v), np.einsum("ij,ij->i", t_in, t_out)
    )
    left_area = (2.0 * math.pi - float(turn.sum())) % (4.0 * math.pi)  # region left of travel
    solver = _PolygonSolver(v, interior=None)
    interior_left = solver._brute(np.asarray(swing.interior)[None, :])[0][0] <= 0.0
    return left_area if interior_left else 4.0 * math.pi - left_area
