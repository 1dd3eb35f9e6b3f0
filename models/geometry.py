"""Spherical-polygon geometry on the unit sphere S²: validity, area, inside test, nearest point.

A spherical polygon is a closed chain of vertices ``v_0 … v_{M−1}`` (unit vectors) joined by
great-circle arcs (edge ``i`` runs from ``v_i`` to ``v_{i+1}``, indices mod M) plus one point
strictly inside, which says which of the two regions bounded by the chain is meant (a polygon
may cover more than a hemisphere). Used by :mod:`models.constraint` (validation),
:mod:`models.oracle` (exact projection) and boundary extraction.

Maths
-----
*Edge.* The great circle of edge ``i`` has unit normal ``g_i = v_i × v_{i+1} / |…|``. A unit
point ``p`` lies at angle ``asin(p·g_i)`` from that circle; its foot ``p − (p·g_i) g_i``
(normalised) lies inside the arc iff ``(g_i × v_i)·p ≥ 0`` and ``(v_{i+1} × g_i)·p ≥ 0``;
otherwise the nearest point of the arc is the nearer end. Distances are ranked by squared
chords (monotonic in the angle, accurate near 0): ``2 s² / (1 + √(1 − s²))`` to the circle
(``s = p·g_i``) and ``|p − v|²`` to a vertex.

*Inside.* Signed distance by pseudo-normals (Bærentzen & Aanæs 2005, on the sphere): when the
nearest point is inside an edge the sign is that of ``p·g_i`` (oriented so the interior point
is inside); when it is a vertex, that of ``p·(n_{i−1} + n_i)``, the sum of the two edges'
inward normals. This is exact for simple polygons, concave ones included.

*Area* (Gauss–Bonnet): the region to the left of the travel direction has area
``2π − Σ turning angles`` (mod 4π); the interior point says whether it is that region or its
complement.

*Simplicity.* Two arcs cross where their great circles meet (``± g_a × g_b``) at a point on
both arcs; arcs on one great circle overlap if an end or midpoint of one lies strictly inside
the other. Only pairs of edges that come within reach of each other are tested: every edge is
cut into *pieces* (arcs of length ``≤ h``, ``h`` about the median edge length; a point of a
piece is within its half-length ``r`` of the piece's midpoint), and two arcs can share a point
only if two of their pieces' midpoints are within ``r_a + r_b`` — a k-d tree over the
midpoints lists those pairs in O(M log M).

*Speed.* :class:`SphericalPolygon` finds the nearest edge exactly, through two structures that
both only ever drop edges that cannot be nearest:

- a cube-map grid over S²: for every cell it precomputes the edges that can be nearest to
  *any* point of the cell (edges whose distance from the cell centre is within ``D + 2ρ`` of
  the nearest, ``ρ`` the cell's angular radius), so a query touches a handful of edges;
- a tree of bounding caps over the pieces in boundary order (a piece's cap: its midpoint and
  half-length; a node's cap contains its two children's), searched level by level: a node is
  dropped when ``∠(p, centre) − radius`` exceeds ``U``, the distance from ``p`` to the nearest
  piece midpoint seen so far (a boundary point, so ``U ≥ D``). Cells whose grid list would be
  long — far from the boundary of a polygon with many vertices, where a list holds on the order
  of ``√(Dρ)`` / (edge length) edges — are answered by the tree instead, which touches on the
  order of ``√(D / edge length)`` edges per query.

Both rank the surviving edges of a point by the same per-pair key, so the answer is the
brute-force one, bit for bit, whichever structure served the point.

Determinism: several boundary points exactly equidistant → the edge with the lowest index wins.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial import cKDTree

from models.errors import GeometryError
from models.jit import njit
from models.quaternion import cross

__all__ = [
    "SphericalPolygon",
    "arc_distance",
    "boundary_distance",
    "check_polygon",
    "densify",
    "fibonacci_sphere",
    "first_contact_along",
    "first_crossing",
    "nearest_in_cell",
    "polygon_area",
    "rank_one",
]

#: Two directions closer than this (radians) are "the same point" for validation purposes.
COINCIDENT = 1e-9


def fibonacci_sphere(n: int) -> np.ndarray:
    """``n`` nearly uniform unit vectors ``(n, 3)``: the golden-angle spiral from +Z to −Z
    (point ``i`` at ``z = 1 − (2i + 1)/n``, azimuth ``π(3 − √5)(i + ½)``), deterministic."""
    if n < 2:
        raise ValueError(f"need at least 2 points, got {n}")
    i = np.arange(n, dtype=np.float64) + 0.5
    z = 1.0 - 2.0 * i / n
    r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    phi = math.pi * (3.0 - math.sqrt(5.0)) * i
    return np.stack((r * np.cos(phi), r * np.sin(phi), z), axis=1)


def _angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.arctan2(np.linalg.norm(cross(a, b), axis=-1), np.sum(a * b, axis=-1))


# -- validation -------------------------------------------------------------------------------
def check_polygon(vertices, interior=None) -> None:
    """Raise :class:`~models.errors.GeometryError` unless the polygon is simple and valid.

    Parameters
    ----------
    vertices : (M, 3) float64, unit, boundary order
    interior : (3,) float64, unit, optional
        Must lie strictly inside (more than 1e-6 rad from the boundary) when given.

    Raises
    ------
    GeometryError
        Fewer than 3 vertices, coincident or antipodal neighbours, all vertices on one great
        circle, crossing or overlapping edges (``part="vertices"``), or an interior point on the
        boundary (``part="interior"``). The message names the vertices or edges.
    """
    verts = np.asarray(vertices, dtype=np.float64)
    if verts.ndim != 2 or verts.shape[1] != 3 or len(verts) < 3:
        raise GeometryError(f"expected at least 3 vertices of shape (M, 3), got {verts.shape}")
    m = len(verts)
    gap = _angle(verts, np.roll(verts, -1, axis=0))
    bad = np.flatnonzero((gap < COINCIDENT) | (gap > math.pi - 1e-6))
    if len(bad):  # the first defective edge, as a walk along the boundary meets it
        i = int(bad[0])
        j = (i + 1) % m
        if gap[i] < COINCIDENT:
            raise GeometryError(f"vertices {i} and {j} coincide (zero-length edge)")
        raise GeometryError(
            f"vertices {i} and {j} are antipodal: the edge between them is undefined"
        )
    # all on one great circle -> zero area, inside undefined
    if np.linalg.svd(verts, compute_uv=False)[-1] < 1e-9:
        raise GeometryError("all vertices lie on one great circle (zero area)")
    pair = first_crossing(verts)
    if pair is not None:
        i, j = pair
        raise GeometryError(
            f"the polygon intersects itself: edge {i}-{(i + 1) % m} crosses edge {j}-{(j + 1) % m}"
        )
    if interior is not None and boundary_distance(verts, interior) < 1e-6:
        raise GeometryError("lies on the boundary; it must be strictly inside", part="interior")


def first_crossing(vertices) -> tuple[int, int] | None:
    """First pair ``(i, j)``, ``i < j``, of non-adjacent edges that cross or overlap, else None.

    "First" orders by ``i``, then ``j``. Only pairs of edges within reach of each other are
    tested (module docstring, *Simplicity*): O(M log M) for a boundary that does not pack many
    edges into one spot.
    """
    verts = np.asarray(vertices, dtype=np.float64)
    m = len(verts)
    a0 = verts
    a1 = np.roll(verts, -1, axis=0)
    n = cross(a0, a1)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    mid, half, edge = _arc_pieces(a0, a1, _angle(a0, a1))
    # two pieces share a point only if their midpoints are within r_a + r_b; the margin covers
    # rounding and the 1e-12 tolerance of _on_arc
    reach = min(2.0 * float(half.max()) + 1e-9, math.pi)
    pairs = cKDTree(mid).query_pairs(2.0 * math.sin(reach / 2.0) + 1e-12, output_type="ndarray")
    if len(pairs) == 0:
        return None
    ea, eb = edge[pairs[:, 0]], edge[pairs[:, 1]]
    i, j = np.minimum(ea, eb), np.maximum(ea, eb)
    keep = (j - i >= 2) & ~((i == 0) & (j == m - 1))  # first and last edges share vertex 0
    code = np.unique(i[keep] * m + j[keep])  # sorted by i, then j
    i, j = code // m, code % m
    chunk = 200_000
    for s in range(0, len(i), chunk):
        ii, jj = i[s : s + chunk], j[s : s + chunk]
        hits = _arcs_cross(a0[ii], a1[ii], n[ii], a0[jj], a1[jj], n[jj])
        if hits.any():
            k = int(np.argmax(hits))
            return int(ii[k]), int(jj[k])
    return None


def first_contact_along(a, b, chunk: int = 1 << 20) -> float | None:
    """The first ``t`` in (0, 1) at which the polygon with vertices ``normalise((1 − t) a_i +
    t b_i)`` has a vertex on an edge it does not end (the moment it stops being simple), or
    None when it never does.

    Exact, not sampled: a polygon that is simple at ``t = 0`` can only become non-simple
    through such a contact (two arcs begin to cross where an end of one passes over the
    other). Vertex ``p`` lies on the great circle of edge ``(q, r)`` where ``p · (q × r) = 0``;
    normalising does not change that sign, so with ``x(t) = x_a + t (x_b − x_a)`` it is a
    cubic in ``t``, whose coefficients for every (vertex, edge) pair are four matrix
    products. Its roots in (0, 1) are bracketed between the roots of its derivative (each
    piece monotonic) and found by bisection to 1e-12; a root counts when ``p`` is then inside
    the arc ``q r``. A touch without crossing (a double root) is not reported.

    Parameters
    ----------
    a, b : (M, 3) array_like
        The polygon's vertices at ``t = 0`` and ``t = 1`` (corresponding, in boundary order).
    chunk : int
        Pairs handled at once (memory).
    """
    A = np.asarray(a, dtype=np.float64)
    D = np.asarray(b, dtype=np.float64) - A
    m = len(A)
    Ar, Dr = np.roll(A, -1, axis=0), np.roll(D, -1, axis=0)
    # q × r = E0 + t E1 + t² E2 per edge (q = vertex i, r = vertex i + 1)
    E0 = cross(A, Ar)
    E1 = cross(A, Dr) + cross(D, Ar)
    E2 = cross(D, Dr)
    c0, c1 = A @ E0.T, A @ E1.T + D @ E0.T           # (vertex, edge)
    c2, c3 = A @ E2.T + D @ E1.T, D @ E2.T
    p_idx, e_idx = np.nonzero(np.ones((m, m), dtype=bool))
    keep = (p_idx != e_idx) & (p_idx != (e_idx + 1) % m)
    p_idx, e_idx = p_idx[keep], e_idx[keep]
    best = math.inf
    for s in range(0, len(p_idx), chunk):
        pi, ei = p_idx[s:s + chunk], e_idx[s:s + chunk]
        k = np.stack((c0[pi, ei], c1[pi, ei], c2[pi, ei], c3[pi, ei]), axis=1)
        for t in _cubic_roots_01(k):
            ok = np.isfinite(t)
            if not ok.any():
                continue
            ii, jj, tt = pi[ok], ei[ok], t[ok]
            if tt.min() >= best:
                continue
            p = A[ii] + tt[:, None] * D[ii]
            q = A[jj] + tt[:, None] * D[jj]
            r = Ar[jj] + tt[:, None] * Dr[jj]
            g = cross(q, r)
            on = ((np.sum(cross(q, p) * g, axis=1) >= 0.0)
                  & (np.sum(cross(p, r) * g, axis=1) >= 0.0)
                  & (np.sum(p * (q + r), axis=1) > 0.0))
            if on.any():
                best = min(best, float(tt[on].min()))
    return None if best == math.inf else best


def _cubic_roots_01(k: np.ndarray) -> list[np.ndarray]:
    """Roots in (0, 1) of ``k0 + k1 t + k2 t² + k3 t³`` (rows of ``k`` (N, 4)) where the cubic
    changes sign: up to three arrays (N,), NaN where that piece has none."""
    n = len(k)
    # pieces between the derivative's roots, where the cubic is monotonic
    qa, qb, qc = 3.0 * k[:, 3], 2.0 * k[:, 2], k[:, 1]
    disc = qb * qb - 4.0 * qa * qc
    with np.errstate(invalid="ignore", divide="ignore"):
        sq = np.sqrt(np.where(disc >= 0.0, disc, np.nan))
        quad = np.abs(qa) > 1e-300
        r1 = np.where(quad, (-qb - sq) / (2.0 * qa), np.where(qb != 0, -qc / qb, np.nan))
        r2 = np.where(quad, (-qb + sq) / (2.0 * qa), np.nan)
    cuts = np.sort(np.stack((r1, r2), axis=1), axis=1)  # NaN sorts last
    cuts = np.where((cuts > 0.0) & (cuts < 1.0), cuts, np.nan)
    edges = np.column_stack((np.zeros(n), cuts, np.ones(n)))
    # drop the NaN cuts by carrying the previous edge forward: empty pieces then
    for c in (1, 2):
        edges[:, c] = np.where(np.isnan(edges[:, c]), edges[:, c - 1], edges[:, c])

    def f(t):
        return ((k[:, 3] * t + k[:, 2]) * t + k[:, 1]) * t + k[:, 0]

    out = []
    for lo_c in range(3):
        lo, hi = edges[:, lo_c].copy(), edges[:, lo_c + 1].copy()
        flo, fhi = f(lo), f(hi)
        has = (hi > lo) & (np.sign(flo) * np.sign(fhi) < 0)
        if not has.any():
            continue
        idx = np.flatnonzero(has)
        lo, hi, flo = lo[idx], hi[idx], flo[idx]
        kk = k[idx]
        for _ in range(45):  # 2^-45 of at most 1: below 1e-13
            mid = 0.5 * (lo + hi)
            fm = ((kk[:, 3] * mid + kk[:, 2]) * mid + kk[:, 1]) * mid + kk[:, 0]
            left = np.sign(fm) == np.sign(flo)
            lo = np.where(left, mid, lo)
            flo = np.where(left, fm, flo)
            hi = np.where(left, hi, mid)
        root = np.full(n, np.nan)
        root[idx] = 0.5 * (lo + hi)
        out.append(root)
    return out


def _arc_pieces(v0: np.ndarray, v1: np.ndarray, theta: np.ndarray):
    """Edges cut into pieces of length ``≤ h``, in boundary order.

    ``h`` is the median edge length, but at least half the mean (so there are at most 3M
    pieces). Returns the pieces' midpoints (P, 3), unit, their half-lengths (P,), radians — every
    point of a piece lies within that angle of its midpoint — and their edges (P,), int64.
    """
    m = len(theta)
    h = max(float(np.median(theta)), 0.5 * float(theta.sum()) / m, 1e-12)
    k = np.maximum(np.ceil(theta / h), 1.0).astype(np.int64)
    edge = np.repeat(np.arange(m), k)
    first = np.cumsum(k) - k
    t = (np.arange(len(edge)) - first[edge] + 0.5) / k[edge]
    th = theta[edge]
    # slerp without the 1/sin θ factor (normalised below), so short edges stay accurate
    mid = np.sin((1.0 - t) * th)[:, None] * v0[edge] + np.sin(t * th)[:, None] * v1[edge]
    norm = np.linalg.norm(mid, axis=1, keepdims=True)
    ok = norm > 0.0
    mid = np.where(ok, mid / np.where(ok, norm, 1.0), v0[edge])  # a zero-length edge: its vertex
    return mid, 0.5 * (theta / k)[edge], edge


def _on_arc(p, a0, a1, n, tol=1e-12):
    """Is unit ``p`` (on the great circle with normal ``n``) within the arc a0→a1?"""
    return (np.sum(cross(a0, p) * n, axis=-1) >= -tol) & (
        np.sum(cross(p, a1) * n, axis=-1) >= -tol
    )


def _arcs_cross(a0, a1, na, b0, b1, nb):
    line = cross(na, nb)
    ln = np.linalg.norm(line, axis=1)
    same_circle = ln < 1e-12
    safe = np.where(same_circle, 1.0, ln)[:, None]
    x = line / safe
    hit = np.zeros(len(a0), dtype=bool)
    for s in (1.0, -1.0):
        p = s * x
        hit |= _on_arc(p, a0, a1, na) & _on_arc(p, b0, b1, nb)
    if same_circle.any():
        # arcs on one great circle overlap when a point of one lies strictly inside the other
        k = same_circle
        mid_b = b0[k] + b1[k]
        mid_b /= np.linalg.norm(mid_b, axis=1, keepdims=True)
        strict = -1e-12
        hit[k] = (
            _on_arc(b0[k], a0[k], a1[k], na[k], strict)
            | _on_arc(b1[k], a0[k], a1[k], na[k], strict)
            | _on_arc(a0[k], b0[k], b1[k], nb[k], strict)
            | _on_arc(a1[k], b0[k], b1[k], nb[k], strict)
            | _on_arc(mid_b, a0[k], a1[k], na[k], strict)
        )
    return hit


# -- measures ---------------------------------------------------------------------------------
def polygon_area(vertices, interior) -> float:
    """Solid angle (steradians) of the region bounded by the polygon that contains ``interior``."""
    v = np.asarray(vertices, dtype=np.float64)
    g = cross(v, np.roll(v, -1, axis=0))
    g /= np.linalg.norm(g, axis=1, keepdims=True)
    t_out = cross(g, v)  # leaving vertex k along edge k
    t_in = cross(np.roll(g, 1, axis=0), v)  # arriving at vertex k along edge k-1
    turn = np.arctan2(
        np.einsum("ij,ij->i", cross(t_in, t_out), v), np.einsum("ij,ij->i", t_in, t_out)
    )
    left_area = (2.0 * math.pi - float(turn.sum())) % (4.0 * math.pi)  # region left of travel
    solver = SphericalPolygon(v, interior=None)
    interior_left = solver.brute_nearest(np.asarray(interior, dtype=np.float64)[None, :])[0][0] <= 0
    return left_area if interior_left else 4.0 * math.pi - left_area


def boundary_distance(vertices, point) -> float:
    """Unsigned angular distance (radians) from one unit ``point`` (3,) to the polygon's boundary.

    Brute force over the edges; no interior point needed.
    """
    solver = SphericalPolygon(vertices, interior=None)
    return float(abs(solver.brute_nearest(np.asarray(point, dtype=np.float64)[None, :])[0][0]))


def arc_distance(points, a, b) -> np.ndarray:
    """Unsigned angular distance (radians) from unit ``points`` to the great-circle arc a→b.

    Parameters
    ----------
    points : (N, 3) float64, unit
    a, b : (3,) or (N, 3) float64, unit, the arc's ends (not antipodal; the shorter arc)

    Returns
    -------
    (N,) float64, radians, in [0, π]
    """
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    a = np.broadcast_to(np.asarray(a, dtype=np.float64), p.shape)
    b = np.broadcast_to(np.asarray(b, dtype=np.float64), p.shape)
    g = cross(a, b)
    g = g / np.linalg.norm(g, axis=1, keepdims=True)
    s = np.einsum("ij,ij->i", p, g)
    in_arc = (np.einsum("ij,ij->i", cross(g, a), p) >= 0.0) & (
        np.einsum("ij,ij->i", cross(b, g), p) >= 0.0
    )
    to_circle = np.abs(np.arcsin(np.clip(s, -1.0, 1.0)))
    to_ends = np.minimum(_angle(p, a), _angle(p, b))
    return np.where(in_arc, to_circle, to_ends)


def densify(vertices, max_step_deg: float = 1.0) -> np.ndarray:
    """Points along the closed boundary, at most ``max_step_deg`` apart (M' , 3), unit.

    Each edge contributes its start vertex and evenly spaced points along the great-circle arc
    (spherical interpolation), in boundary order.
    """
    v = np.asarray(vertices, dtype=np.float64)
    v1 = np.roll(v, -1, axis=0)
    out = []
    step = math.radians(max_step_deg)
    for a, b in zip(v, v1, strict=True):
        theta = float(_angle(a, b))
        k = max(1, math.ceil(theta / step))
        t = np.arange(k)[:, None] / k
        sin_t = math.sin(theta)
        out.append((np.sin((1 - t) * theta) * a + np.sin(t * theta) * b) / sin_t)
    return np.concatenate(out)


# -- nearest boundary point -------------------------------------------------------------------
class _ArcTree:
    """Bounding caps over the boundary's pieces, for exact candidate search at any vertex count.

    Leaves are the pieces of :func:`_arc_pieces` in boundary order (cap = midpoint, half-length);
    a node of the level above joins two neighbours (cap centre: the normalised sum of theirs,
    radius: enough to hold both caps). Consecutive pieces are close on S², so the caps stay
    tight. Every node also carries a *rep*, a boundary point inside it (its first piece's
    midpoint), whose distance bounds ``D`` from above. Below the root every level has an even
    length (an odd one gets a dummy that is never kept: NaN centre), so node ``i``'s children
    are ``2i`` and ``2i + 1``.
    """

    #: added to every pruning bound (radians): covers rounding in caps, chords and angles
    SLACK = 2e-9
    #: margin on dot products and squared chords: covers their rounding (unit vectors)
    DOT_MARGIN = 1e-15

    def __init__(self, v0: np.ndarray, v1: np.ndarray):
        centre, radius, edge = _arc_pieces(v0, v1, _angle(v0, v1))
        rep = centre
        levels = []
        while True:
            # one row per node: centre | rep | cos r | sin r | r
            rows = np.hstack((centre, rep, np.cos(radius)[:, None], np.sin(radius)[:, None],
                              radius[:, None]))
            if len(centre) % 2 and len(centre) > 1:  # pad: a dummy whose tests never pass
                dummy = np.r_[np.full(3, np.nan), rep[-1], np.nan, np.nan, -np.inf]
                rows = np.vstack((rows, dummy))
            levels.append(rows)
            if len(centre) == 1:
                break
            n2 = len(centre) // 2
            a, b = centre[0 : 2 * n2 : 2], centre[1 : 2 * n2 : 2]
            s = a + b
            sn = np.linalg.norm(s, axis=1, keepdims=True)
            c = np.where(sn > 1e-12, s / np.where(sn > 1e-12, sn, 1.0), a)
            r = np.maximum(
                _angle(c, a) + radius[0 : 2 * n2 : 2], _angle(c, b) + radius[1 : 2 * n2 : 2]
            )
            rp = rep[0 : 2 * n2 : 2]
            if len(centre) % 2:  # the odd one out moves up unchanged
                c = np.concatenate((c, centre[-1:]))
                r = np.concatenate((r, radius[-1:]))
                rp = np.concatenate((rp, rep[-1:]))
            centre, radius, rep = c, np.minimum(r, math.pi), rp
        self.levels = levels[::-1]  # root first
        self.edge = np.append(edge, edge[-1]) if len(edge) % 2 else edge

    def search(self, p: np.ndarray, pad, limit: int | None = None):
        """Every piece whose cap comes within ``D + pad`` of its point, as edge candidates.

        Parameters
        ----------
        p : (N, 3) float64, unit
        pad : float or (N,) float64, radians, >= 0
            0 for a nearest-edge search; ``2ρ`` lists what a grid cell of radius ρ needs.
        limit : int, optional
            Give up (return None) when more than this many (point, node) pairs are alive.

        Returns
        -------
        owner, edge : (K,) int64
            Pairs sorted by owner (every point has at least one), edges non-decreasing within
            an owner (an edge may repeat: one entry per piece). Every edge within ``D + pad`` of
            a point is among its pairs.

        A node survives when ``∠(p, centre) ≤ U + pad + radius``, tested as
        ``p·centre ≥ cos(U + pad + radius)`` (with :attr:`DOT_MARGIN`), where ``U`` is the
        angle to the nearest rep seen so far, rounded up.
        """
        n = len(p)
        pad = np.broadcast_to(np.asarray(pad, dtype=np.float64), (n,)) + self.SLACK
        owner = np.arange(n)
        node = np.zeros(n, dtype=np.int64)
        best = np.full(n, -1.0)  # largest p·rep seen: the nearest boundary point so far
        margin = self.DOT_MARGIN
        last = len(self.levels) - 1
        for depth, rows in enumerate(self.levels):
            g = rows[node]
            dots = np.einsum("kij,kj->ki", g[:, :6].reshape(-1, 2, 3), p[owner])  # centre, rep
            first = np.flatnonzero(np.diff(owner, prepend=-1))  # owner is sorted
            who = owner[first]
            best[who] = np.maximum(best[who], np.maximum.reduceat(dots[:, 1], first))
            chord2 = np.maximum(2.0 - 2.0 * best, 0.0) + margin
            u = 2.0 * np.arcsin(np.minimum(np.sqrt(chord2) * 0.5, 1.0)) + pad  # U + pad >= D
            cu, su = np.cos(u), np.sin(u)
            far = u[owner] + g[:, 8] >= math.pi  # the cap reaches every point
            keep = far | (dots[:, 0] >= cu[owner] * g[:, 6] - su[owner] * g[:, 7] - margin)
            owner, node = owner[keep], node[keep]
            if depth == last:
                break
            owner = np.repeat(owner, 2)
            node = (2 * node[:, None] + np.arange(2)).ravel()
            if limit is not None and len(owner) > limit:
                return None
        return owner, self.edge[node]


def _pair_keys(t: np.ndarray, p: np.ndarray):
    """The per-(point, edge) kernel of :class:`SphericalPolygon` for listed pairs: ``t``
    (K, 5, 3) holds each pair's edge as rows g, t0, t1, v0, v1; ``p`` (K, 3) its point. See
    :meth:`SphericalPolygon._pair_keys` for what is returned; the arithmetic is
    :func:`_all_pair_keys`'s (each pair a polygon of one edge)."""
    out = _all_pair_keys(*(t[:, None, i] for i in range(5)), p)
    return tuple(x[:, 0] for x in out)


def _all_pair_keys(g, t0, t1, v0, v1, p):
    """Squared chord from each point to each edge's nearest point (the key, monotonic in the
    angle), whether that nearest point is inside the edge (``in_arc``, not an end), the sine of
    the angle to the edge's great circle (``s``, signed by its geometric normal) and, when an
    end is nearest, whether it is the edge's second vertex — for every point with every edge
    of its polygon: the edge rows (M, 3) of one polygon, or (N, M, 3) of one polygon per
    point; points ``p`` (N, 3). Returns (N, M) arrays."""
    pp = p[:, None, :]
    s = np.einsum("...j,...j->...", g, pp)
    in_arc = ((np.einsum("...j,...j->...", t0, pp) >= 0.0)
              & (np.einsum("...j,...j->...", t1, pp) >= 0.0) & (np.abs(s) < 1.0 - 1e-12))
    s2 = s * s
    key_in = 2.0 * s2 / (1.0 + np.sqrt(np.maximum(1.0 - s2, 0.0)))
    # squared chords to the ends by differences (not 2 - 2 p·v: exact near a vertex)
    e0 = v0 - pp
    e1 = v1 - pp
    k0 = np.einsum("...j,...j->...", e0, e0)
    k1 = np.einsum("...j,...j->...", e1, e1)
    key = np.where(in_arc, key_in, np.minimum(k0, k1))
    return key, in_arc, s, k1 < k0


def nearest_on_polygons(vertices: np.ndarray, points: np.ndarray, chunk_pairs: int = 400_000):
    """Signed distance and nearest boundary point of each point to **its own** polygon.

    For polygons that differ from point to point (a coupled joint's boundary interpolated at
    each sample's coupling angle). Every polygon is searched by brute force with the kernel of
    :class:`SphericalPolygon` (same keys, same lowest-index rule on ties, same pseudo-normal
    sign), so a polygon's answers are :meth:`SphericalPolygon.brute_nearest`'s.

    Parameters
    ----------
    vertices : (N, M, 3) float64
        Unit vertices of each point's polygon, **oriented**: the region is on the side of each
        edge's normal ``v_i × v_{i+1}`` (to the left walking along the boundary, seen from
        outside the sphere). Consecutive vertices distinct and not antipodal.
    points : (N, 3) float64, unit

    Returns
    -------
    dist : (N,) radians, negative inside
    nearest : (N, 3) the nearest boundary point
    """
    v = np.asarray(vertices, dtype=np.float64)
    p = np.asarray(points, dtype=np.float64)
    n, m = v.shape[:2]
    step = max(1, chunk_pairs // m)
    dist = np.empty(n)
    near = np.empty((n, 3))
    for a in range(0, n, step):
        vb, pb = v[a:a + step], p[a:a + step]
        k = len(vb)
        v1 = np.roll(vb, -1, axis=1)
        g = cross(vb, v1)
        g /= np.linalg.norm(g, axis=2, keepdims=True)
        key, in_arc, s, end1 = _all_pair_keys(g, cross(g, vb), cross(v1, g), vb, v1, pb)
        best = np.argmin(key, axis=1)  # first minimum: lowest edge index
        rows = np.arange(k)
        vidx = np.where(end1[rows, best], (best + 1) % m, best)
        vnormal = g[rows, vidx] + g[rows, (vidx - 1) % m]  # inward normals of its two edges
        dist[a:a + k], near[a:a + k] = _finish(pb, key[rows, best], in_arc[rows, best],
                                               s[rows, best], 1.0, vnormal,
                                               (g[rows, best], vb[rows, vidx]))
    return dist, near


def _finish(p, key, in_arc, s, orient, vertex_normal, point_from):
    """Signed distance (and nearest point) of points from their winning edge's pair keys.

    ``s``: the sine to the edge's great circle (signed by its geometric normal); ``orient``:
    +1 when the region is on that normal's side, else -1; ``vertex_normal``: the pseudo-normal
    of the nearer end; ``point_from``: None, or (the edge's geometric normal, the nearer end)
    to build the nearest point."""
    theta = 2.0 * np.arcsin(np.minimum(np.sqrt(key) * 0.5, 1.0))
    inside = np.where(in_arc, orient * s >= 0.0,
                      np.einsum("ij,ij->i", p, vertex_normal) >= 0.0)
    dist = np.where(inside, -theta, theta)
    if point_from is None:
        return dist, None
    g_edge, end = point_from
    foot = p - s[:, None] * g_edge
    fn = np.linalg.norm(foot, axis=1, keepdims=True)
    foot = foot / np.where(fn < 1e-300, 1.0, fn)
    return dist, np.where(in_arc[:, None], foot, end)


class SphericalPolygon:
    """A simple spherical polygon: exact signed distance and nearest boundary point.

    Parameters
    ----------
    vertices : (M, 3) float64, unit, in boundary order (either direction)
    interior : (3,) float64, unit, or None
        A point strictly inside; None builds only what unsigned distances need (no grid,
        :meth:`brute_nearest` only — used during validation).
    grid : int, optional
        Kept for compatibility; the cube-map resolution is chosen automatically.

    Attributes
    ----------
    G : int
        Cube-map cells per face side.
    cell_ptr, cell_edges : (6G² + 1,) int64, (K,) int64
        Candidate edges of cell ``c``: ``cell_edges[cell_ptr[c]:cell_ptr[c + 1]]``, ascending.
    cell_tree : (6G²,) bool
        Cells whose points :meth:`nearest` sends to the tree of bounding caps.
    mean_candidates : float
        Mean list length over the other cells (NaN when every cell goes to the tree).
    tree_fraction : float
        Fraction of the cells marked in ``cell_tree``.

    The polygon is assumed simple (see :func:`check_polygon`); distances are angles in
    radians, negative inside. ``nearest`` and ``nearest_one`` give identical answers (the
    batched and the per-sample path): each takes a set of candidate edges that holds every
    edge nearest to the point (its cell's list, or the tree's search), ranks them by the same
    per-pair key (:meth:`_pair_keys`) and keeps the lowest key, the lowest edge index on ties —
    which is the answer of :meth:`brute_nearest`, whatever the set. The grid is built when the
    queries make it pay (after :attr:`GRID_AFTER_POINTS` points, or at once by
    :meth:`prepare`); until then :meth:`nearest` answers by brute force, the same answers. Its
    set-up and memory grow as M log M with the vertex count M.
    """

    def __init__(self, vertices, interior=None, grid: int | None = None):
        v = np.asarray(vertices, dtype=np.float64)
        self.vertices = v
        self.interior = None if interior is None else np.asarray(interior, dtype=np.float64)
        self.m = len(v)
        self.v0 = v
        self.v1 = np.roll(v, -1, axis=0)
        g = cross(self.v0, self.v1)
        self.g = g / np.linalg.norm(g, axis=1, keepdims=True)  # geometric edge normals
        self.t0 = cross(self.g, self.v0)  # along the edge at its start
        self.t1 = cross(self.v1, self.g)  # back along the edge at its end
        self.orient = 1.0
        self._set_pseudo_normals()
        if interior is None:  # only unsigned distances are wanted
            return
        # orient the normals so that the interior point is inside
        if self.brute_nearest(np.asarray(interior, dtype=np.float64)[None, :])[0][0] > 0.0:
            self.orient = -1.0
            self._set_pseudo_normals()
        self._tree = _ArcTree(self.v0, self.v1)
        self._brute_points = 0  # points answered by brute force so far (no grid yet)

    #: the grid's attributes: built on first use (:meth:`_build_grid`)
    _GRID_ATTRS = frozenset(("G", "cell_ptr", "cell_edges", "cell_tree", "mean_candidates",
                             "tree_fraction", "_lists"))

    def __getattr__(self, name):
        # only reached when the attribute is missing: the grid has not been built yet
        if name in SphericalPolygon._GRID_ATTRS and "_tree" in self.__dict__:
            self._build_grid()
            return self.__dict__[name]
        raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")

    def prepare(self) -> SphericalPolygon:
        """Build now what the queries need (the grid, and the scalar path's compiled kernels),
        so that no query pays for it; the live loop calls it before its first cycle. Returns
        self."""
        if self.interior is not None:
            self.nearest_one(tuple(self.interior))
        return self

    def _set_pseudo_normals(self):
        n_in = self.orient * self.g
        # vertex k is the start of edge k and the end of edge k-1
        self.vertex_normal = n_in + np.roll(n_in, 1, axis=0)
        # one row per edge, gathered once per (point, edge) pair: g | t0 | t1 | v0 | v1
        self._table = np.ascontiguousarray(
            np.stack((self.g, self.t0, self.t1, self.v0, self.v1), 1)
        )

    # -- per (point, edge) pair ----------------------------------------------------------------
    def _pair_keys(self, p: np.ndarray, e: np.ndarray):
        """Squared chord from p to edge e's nearest point, plus what is needed to classify.

        ``p`` (K, 3) and ``e`` (K,) list the pairs. Returns ``key`` (squared chord, monotonic in
        the angle), ``in_arc`` (the nearest point is inside the edge, not an end), ``s`` (sine
        of the angle to the edge's great circle, signed by the geometric normal) and
        ``end_is_1`` (when an end is nearest: is it the edge's second vertex).
        """
        return _pair_keys(self._table[e], p)

    def _finish(self, p, e, key, in_arc, s, end_is_1, need_point):
        """Signed distance (and nearest point) from the winning edge of each point."""
        vidx = np.where(end_is_1, (e + 1) % self.m, e)
        return _finish(p, key, in_arc, s, self.orient, self.vertex_normal[vidx],
                       (self.g[e], self.v0[vidx]) if need_point else None)

    def brute_nearest(self, p: np.ndarray, need_point: bool = False):
        """:meth:`nearest` by trying every edge (set-up, validation, and a reference for tests)."""
        n = len(p)
        step = max(1, self.BRUTE_PAIRS // self.m)  # points per block: bounds the N×M temporaries
        if n > step:
            parts = [self.brute_nearest(p[s : s + step], need_point) for s in range(0, n, step)]
            dist = np.concatenate([x[0] for x in parts])
            pts = np.concatenate([x[1] for x in parts]) if need_point else None
            return dist, pts
        key, in_arc, s, end1 = _all_pair_keys(self.g, self.t0, self.t1, self.v0, self.v1, p)
        best = np.argmin(key, axis=1)  # first minimum: lowest edge index
        r = np.arange(n)
        return self._finish(p, best, key[r, best], in_arc[r, best], s[r, best], end1[r, best],
                            need_point)

    #: (point, edge) pairs per block of :meth:`brute_nearest`
    BRUTE_PAIRS = 1_000_000

    # -- grid ------------------------------------------------------------------------------
    #: points answered by brute force before the grid is built: building it costs about as
    #: much as answering 3,000-7,000 points by brute force from 40 to 2,000 vertices (22-930
    #: ms against 6-140 µs a point), so a polygon queried a few times (a boundary compared
    #: once) never builds it and one queried often pays at most about twice the least
    GRID_AFTER_POINTS = 4000
    #: finest grid and the candidate count below which refining stops paying
    MAX_GRID = 128
    TARGET_CANDIDATES = 6.0
    MAX_BUILD_PAIRS = 4_000_000
    #: a cell with more candidates than this is answered by the cap tree instead
    CELL_CAP = 96
    #: points per block of a tree search (bounds the (point, node) pairs alive at once)
    TREE_CHUNK = 2048

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
        subset of its parent's, so a level only searches its parent's candidates).

        The first level (8×8 per face) comes from the cap tree; refining stops at
        :attr:`MAX_GRID`, at :attr:`TARGET_CANDIDATES` per cell on average, or when the next
        level would test more than :attr:`MAX_BUILD_PAIRS` pairs. Cells left with more than
        :attr:`CELL_CAP` candidates are marked in ``cell_tree``: :meth:`nearest` sends their
        points to the tree (for many points a tree search is cheaper than a long list);
        :meth:`nearest_one` still uses the list, pruned by edge caps first.
        """
        G = 8
        lists = self._first_level(G)
        if lists is None:  # too many edges near the cells for lists to pay: the tree only
            ptr, edges = np.zeros(6 * G * G + 1, dtype=np.int64), np.zeros(0, dtype=np.int64)
            tree = np.ones(6 * G * G, dtype=bool)
        else:
            ptr, edges = lists
            tree = np.zeros(6 * G * G, dtype=bool)
        while not tree.all():
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
            ptr, edges = self._refine(G, ptr, edges)
        self._lists = not tree.all()  # False: no lists at all, every query goes to the tree
        counts = np.diff(ptr)
        if self._lists:
            tree = counts > self.CELL_CAP
        self.G = G
        self.cell_ptr = ptr
        self.cell_edges = edges
        self.cell_tree = tree
        #: mean list length over the cells the batched search serves from their lists
        self.mean_candidates = float(counts[~tree].mean()) if not tree.all() else float("nan")
        self.tree_fraction = float(tree.mean())  # of the cells

    def _first_level(self, G: int):
        """Cell lists of a G-grid from the tree: the edges within ``D + 2ρ`` of each centre.

        Returns ``(ptr, edges)``, or None when the lists would hold more than
        :attr:`MAX_BUILD_PAIRS` entries. Cells go to the tree a few at a time (bounded memory).
        """
        centres, radii = _cube_cells(G)
        counts, kept, total = [], [], 0
        step = 16
        for s in range(0, len(centres), step):
            c, r = centres[s : s + step], radii[s : s + step]
            found = self._tree.search(c, 2.0 * r, limit=self.MAX_BUILD_PAIRS)
            if found is None:
                return None
            owner, e = found
            key = self._pair_keys(c[owner], e)[0]
            angles = 2.0 * np.arcsin(np.minimum(np.sqrt(key) * 0.5, 1.0))
            first = np.flatnonzero(np.r_[True, owner[1:] != owner[:-1]])
            bound = np.minimum.reduceat(angles, first) + 2.0 * r + 1e-9
            keep = angles <= bound[owner]
            keep[1:] &= (owner[1:] != owner[:-1]) | (e[1:] != e[:-1])  # one entry per edge
            counts.append(np.bincount(owner[keep], minlength=len(c)))
            kept.append(e[keep])
            total += len(kept[-1])
            if total > self.MAX_BUILD_PAIRS:
                return None
        ptr = np.concatenate(([0], np.cumsum(np.concatenate(counts))))
        return ptr, np.concatenate(kept)

    def _refine(self, G: int, ptr: np.ndarray, edges: np.ndarray):
        """Keep, per cell of a G-grid, the edges that can be nearest to some point of the cell."""
        centres, radii = _cube_cells(G)
        n_cells = len(centres)
        counts = np.diff(ptr)
        owner = np.repeat(np.arange(n_cells), counts)
        angles = np.empty(len(edges))
        chunk = 250_000  # pairs per block: bounds the (K, 5, 3) gather
        for s in range(0, len(edges), chunk):
            key = self._pair_keys(centres[owner[s : s + chunk]], edges[s : s + chunk])[0]
            angles[s : s + chunk] = 2.0 * np.arcsin(np.minimum(np.sqrt(key) * 0.5, 1.0))
        starts = ptr[:-1]
        nearest = np.minimum.reduceat(angles, starts) if len(edges) else np.zeros(n_cells)
        bound = nearest + 2.0 * radii + 1e-9
        keep = angles <= bound[owner]
        new_counts = np.add.reduceat(keep.astype(np.int64), starts)
        return np.concatenate(([0], np.cumsum(new_counts))), edges[keep]

    # -- search ------------------------------------------------------------------------------
    def _pick(self, p, owner, e, need_point):
        """The lowest key of each point's candidates (owner sorted, every point present; edges
        non-decreasing per point, so the first lowest key is the lowest edge index)."""
        n = len(p)
        key, in_arc, s, end1 = self._pair_keys(p[owner], e)
        starts = np.searchsorted(owner, np.arange(n))
        best_key = np.minimum.reduceat(key, starts)
        hit = np.flatnonzero(key == best_key[owner])
        first = hit[np.searchsorted(owner[hit], np.arange(n))]
        return self._finish(
            p, e[first], key[first], in_arc[first], s[first], end1[first], need_point
        )

    def _grid_candidates(self, p: np.ndarray, cell: np.ndarray):
        start = self.cell_ptr[cell]
        counts = self.cell_ptr[cell + 1] - start
        n = len(p)
        offsets = np.zeros(n, dtype=np.int64)
        np.cumsum(counts[:-1], out=offsets[1:])
        total = int(offsets[-1] + counts[-1]) if n else 0
        owner = np.repeat(np.arange(n), counts)
        return owner, self.cell_edges[np.arange(total) - (offsets - start)[owner]]

    def nearest(self, p: np.ndarray, need_point: bool = True, chunk: int = 16384):
        """Signed distance (N,) and nearest boundary point (N, 3) of unit directions ``p`` (N, 3).

        Without an interior point the search is brute force and only ``|distance|`` means
        anything.
        """
        if self.interior is None:
            return self.brute_nearest(p, need_point)
        n = len(p)
        if "G" not in self.__dict__ and self._brute_points + n <= self.GRID_AFTER_POINTS:
            self._brute_points += n  # the grid would not pay yet: the same answers by brute force
            return self.brute_nearest(p, need_point)
        if n > chunk:
            parts = [self.nearest(p[s : s + chunk], need_point, chunk) for s in range(0, n, chunk)]
            dist = np.concatenate([x[0] for x in parts])
            pts = np.concatenate([x[1] for x in parts]) if need_point else None
            return dist, pts
        cell = self._cell_index(p)
        by_tree = self.cell_tree[cell]
        if not by_tree.any():
            return self._pick(p, *self._grid_candidates(p, cell), need_point)
        dist = np.empty(n)
        pts = np.empty((n, 3)) if need_point else None
        parts = [np.flatnonzero(~by_tree)] if not by_tree.all() else []
        listed = len(parts)
        tree_idx = np.flatnonzero(by_tree)
        step = self.TREE_CHUNK
        parts += [tree_idx[s : s + step] for s in range(0, len(tree_idx), step)]
        for k, idx in enumerate(parts):
            q = p[idx]
            if k < listed:
                found = self._grid_candidates(q, cell[idx])
            else:
                found = self._tree.search(q, 0.0)
            d, b = self._pick(q, *found, need_point)
            dist[idx] = d
            if need_point:
                pts[idx] = b
        return dist, pts

    def nearest_one(self, d: tuple[float, float, float]):
        """Scalar twin of :meth:`nearest` for one direction: the same candidates, ranked by the
        same keys (so the same edge wins); the winner's signed distance and point in plain
        floats. Compiled (:func:`nearest_in_cell`, :func:`rank_one`): about a µs."""
        px, py, pz = float(d[0]), float(d[1]), float(d[2])
        if self._lists:
            r = nearest_in_cell(px, py, pz, self.G, self.cell_ptr, self.cell_edges,
                                 self._table, self.v0, self.vertex_normal, self.orient)
        else:
            cand = self._tree.search(np.array([[px, py, pz]]), 0.0)[1]
            r = rank_one(px, py, pz, cand, self._table, self.v0, self.vertex_normal,
                          self.orient)
        return r[0], (r[1], r[2], r[3])

    # -- conveniences ----------------------------------------------------------------------
    def _need_interior(self) -> None:
        if self.interior is None:
            raise GeometryError(
                "this polygon has no interior point: signed queries need one", part="interior"
            )

    def signed_distance(self, points) -> np.ndarray:
        """Signed angular distance (radians) of unit points (N, 3) to the boundary, < 0 inside."""
        self._need_interior()
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        return self.nearest(p, need_point=False)[0]

    def contains(self, points, tolerance: float = 0.0) -> np.ndarray:
        """Point-in-polygon test: (N,) bool, True inside or within ``tolerance`` rad outside."""
        return self.signed_distance(points) <= tolerance

    def nearest_point(self, points) -> np.ndarray:
        """Nearest boundary point (N, 3) of unit points (N, 3) — inside points included."""
        self._need_interior()
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        return self.nearest(p)[1]

    def area(self) -> float:
        """Solid angle (steradians) of the region containing the interior point."""
        self._need_interior()
        return polygon_area(self.vertices, self.interior)


@njit
def rank_one(px, py, pz, cand, table, v0, vertex_normal, orient):
    """The nearest of the candidate edges ``cand`` to the unit direction ``p``: the keys of
    :func:`_pair_keys` and the rule of :func:`_finish` for one point (the first minimum wins,
    so the same edge as the batched path). Returns (signed distance, nearest point)."""
    best = math.inf
    win = -1
    win_in = False
    win_s = 0.0
    win_end1 = False
    for e in cand:
        t = table[e]
        s = t[0, 0] * px + t[0, 1] * py + t[0, 2] * pz
        in_arc = (t[1, 0] * px + t[1, 1] * py + t[1, 2] * pz >= 0.0
                  and t[2, 0] * px + t[2, 1] * py + t[2, 2] * pz >= 0.0 and abs(s) < 1.0 - 1e-12)
        a0, a1, a2 = t[3, 0] - px, t[3, 1] - py, t[3, 2] - pz
        b0, b1, b2 = t[4, 0] - px, t[4, 1] - py, t[4, 2] - pz
        k0 = a0 * a0 + a1 * a1 + a2 * a2
        k1 = b0 * b0 + b1 * b1 + b2 * b2
        if in_arc:
            s2 = s * s
            key = 2.0 * s2 / (1.0 + math.sqrt(max(1.0 - s2, 0.0)))
        else:
            key = k0 if k0 <= k1 else k1
        if key < best:
            best, win, win_in, win_s, win_end1 = key, e, in_arc, s, k1 < k0
    if win_in:
        inside = orient * win_s >= 0.0
        g = table[win, 0]
        f0, f1, f2 = px - win_s * g[0], py - win_s * g[1], pz - win_s * g[2]
        fn = math.sqrt(f0 * f0 + f1 * f1 + f2 * f2)
        if fn == 0.0:
            fn = 1.0
        b0, b1, b2 = f0 / fn, f1 / fn, f2 / fn
    else:
        vi = (win + 1) % len(table) if win_end1 else win
        b0, b1, b2 = v0[vi, 0], v0[vi, 1], v0[vi, 2]
        mv = vertex_normal[vi]
        inside = px * mv[0] + py * mv[1] + pz * mv[2] >= 0.0
    theta = 2.0 * math.asin(min(math.sqrt(best) * 0.5, 1.0))
    return (-theta if inside else theta), b0, b1, b2


@njit
def nearest_in_cell(px, py, pz, G, cell_ptr, cell_edges, table, v0, vertex_normal, orient):
    """:func:`rank_one` on the candidates of the cube-map cell of ``p`` (the cell rule of
    :meth:`SphericalPolygon._cell_index`): a polygon's nearest boundary point to one unit
    direction, compiled for the control loop (the ball joint's kernel calls it). Returns
    (signed distance, nearest point)."""
    ax0, ax1, ax2 = abs(px), abs(py), abs(pz)
    if ax0 >= ax1 and ax0 >= ax2:
        ax, major, u, v = 0, px, py, pz
    elif ax1 >= ax2:
        ax, major, u, v = 1, py, pz, px
    else:
        ax, major, u, v = 2, pz, px, py
    inv = 1.0 / abs(major)
    u *= inv
    v *= inv
    i = min(max(int((u + 1.0) * (0.5 * G)), 0), G - 1)
    j = min(max(int((v + 1.0) * (0.5 * G)), 0), G - 1)
    cell = ((2 * ax + (1 if major < 0 else 0)) * G + i) * G + j
    return rank_one(px, py, pz, cell_edges[cell_ptr[cell]:cell_ptr[cell + 1]], table, v0,
                     vertex_normal, orient)


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
                rad = np.maximum(rad, _angle(c, corner))
        centres.append(c)
        radii.append(rad)
    return np.concatenate(centres), np.concatenate(radii)


def _face_points(ax: int, sign: float, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    p = np.empty((len(u), 3))
    p[:, ax] = sign
    p[:, (ax + 1) % 3] = u
    p[:, (ax + 2) % 3] = v
    return p / np.linalg.norm(p, axis=1, keepdims=True)
