"""The swing region of plane points: alpha shape, joined, held, inset; alpha grown (step 4).

Pipeline (:func:`alpha_region`), on the samples' plane positions ``p`` (azimuthal-equidistant
degrees, :mod:`calibration.boundary.projection`) in recording order with their trajectory
links (:func:`calibration.boundary.outliers.trajectory_links`):

1. **Cells** (:func:`cell_means`): each occupied ``cell_deg`` cell's mean position, and in the
   cells at the edge of the occupied area also the cell's outermost samples in eight
   directions, so that the envelope passes through recorded samples rather than through cell
   means up to half a cell inside them.
2. **Alpha shape** (Edelsbrunner, Kirkpatrick & Seidel 1983, *IEEE Trans. Inf. Theory*
   29:551; :func:`alpha_shape`): the Delaunay triangulation (:class:`scipy.spatial.Delaunay`,
   :func:`triangulate`) of the cells' points, triangles with circumradius ``< alpha`` merged
   with :func:`shapely.coverage_union_all`. *Clusters*: cells are connected by Delaunay edges
   shorter than ``2 alpha`` (the longest edge an alpha triangle can have) and by linked
   trajectory steps; cells outside the cluster holding most samples, in clusters of less than
   ``cluster_share`` of the samples each, are isolated glitch clusters — reached and left
   only by jumps no limb makes — left out and not counted as evidence. Only the main
   cluster's triangles are used.
3. **Joined, held, inset** (:mod:`calibration.boundary.region`,
   :func:`calibration.boundary.inset.swing_inset`).
4. **Alpha grown**: if a piece other than the largest holds more than ``1 − coverage`` of the
   evidence (a sparse recording splits the whole shape into pieces, with unvisited pockets
   between them), or the final region leaves more than that out by more than ``cell_deg`` +
   the inset, ``alpha`` grows by 1.5× (up to 4 times).

Documented in docs/calibration.md, "Boundary extraction", step 4.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from calibration.boundary.inset import InsetSettings, swing_inset
from calibration.boundary.region import Evidence, RegionSettings, apply_inset, hold, join
from calibration.errors import CalibrationError

__all__ = [
    "AlphaShape",
    "Cells",
    "SwingRegion",
    "Triangulation",
    "alpha_region",
    "alpha_shape",
    "cell_means",
    "grid",
    "triangulate",
]

#: Alpha values tried: the first, then grown by ``_ALPHA_GROWTH`` each time.
_ALPHA_TRIES = 5
_ALPHA_GROWTH = 1.5


def grid(p: np.ndarray, cell_deg: float) -> tuple[np.ndarray, tuple[int, int], np.ndarray]:
    """Cell indices (N, 2) of plane points (N, 2) in a grid of ``cell_deg`` cells, counted
    from the lowest occupied cell; the grid's shape; the lowest cell's index (2,)."""
    ij = np.floor(p / cell_deg).astype(np.int64)
    lo = ij.min(axis=0)
    ij -= lo
    shape = tuple(ij.max(axis=0) + 1)
    return ij, shape, lo


@dataclass(frozen=True)
class Cells:
    """The points an alpha shape is built on.

    Attributes
    ----------
    points : (C, 2) float64, each occupied cell's mean, then the edge cells' outermost samples
    counts : (C,) int64, samples per point (0 for the outermost samples: geometry, not
        evidence)
    cell_of : (N,) int64, each sample's cell (index into ``points``)
    """

    points: np.ndarray
    counts: np.ndarray
    cell_of: np.ndarray


def cell_means(p: np.ndarray, cell_deg: float) -> Cells:
    """Each occupied cell's mean position of the samples ``p`` (N, 2), then, for the cells at
    the edge of the occupied area (a 4-neighbour empty), the cell's outermost samples in
    eight directions (count 0: geometry, not evidence; cells of one sample have it as their
    mean): the envelope passes through the recorded samples, not through cell means up to
    half a cell inside them."""
    ij, shape, _ = grid(p, cell_deg)
    flat = ij[:, 0] * shape[1] + ij[:, 1]
    uniq, inv, counts = np.unique(flat, return_inverse=True, return_counts=True)
    inv = inv.reshape(-1)
    sx = np.bincount(inv, weights=p[:, 0])
    sy = np.bincount(inv, weights=p[:, 1])
    means = np.column_stack((sx / counts, sy / counts))
    occ = np.zeros((shape[0] + 2, shape[1] + 2), dtype=bool)
    ci, cj = uniq // shape[1] + 1, uniq % shape[1] + 1
    occ[ci, cj] = True
    edge = ~(occ[ci - 1, cj] & occ[ci + 1, cj] & occ[ci, cj - 1] & occ[ci, cj + 1])
    sel = np.flatnonzero(edge[inv] & (counts[inv] > 1))
    if not len(sel):
        return Cells(means, counts, inv)
    cell = inv[sel]
    extra = []
    for a in np.arange(8) * (math.pi / 4.0):
        score = p[sel, 0] * math.cos(a) + p[sel, 1] * math.sin(a)
        order = np.lexsort((score, cell))
        last = np.flatnonzero(np.r_[cell[order][1:] != cell[order][:-1], True])
        extra.append(sel[order[last]])
    extra = np.unique(np.concatenate(extra))
    return Cells(np.concatenate((means, p[extra])),
                 np.concatenate((counts, np.zeros(len(extra), dtype=counts.dtype))), inv)


@dataclass(frozen=True)
class Triangulation:
    """The Delaunay triangulation of the cells' points.

    Attributes
    ----------
    simplices : (T, 3) int, triangles (indices into the points)
    circumradius : (T,) float64, degrees
    edges : (E, 2) int, every edge once (sorted pairs)
    edge_len : (E,) float64, degrees
    """

    simplices: np.ndarray
    circumradius: np.ndarray
    edges: np.ndarray
    edge_len: np.ndarray


def triangulate(pts: np.ndarray) -> Triangulation:
    """Delaunay triangulation of plane points (C, 2), with circumradii and unique edges.

    Raises
    ------
    CalibrationError
        Fewer than 3 points, or all on one line.
    """
    from scipy.spatial import Delaunay, QhullError

    if len(pts) < 3:
        raise CalibrationError("the recorded directions cover too small an area")
    try:
        tri = Delaunay(pts)
    except QhullError as err:
        raise CalibrationError(
            "the recorded directions are degenerate (all on one line)"
        ) from err
    a, b, cc = (pts[tri.simplices[:, k]] for k in range(3))
    la = np.linalg.norm(b - cc, axis=1)
    lb = np.linalg.norm(a - cc, axis=1)
    lc = np.linalg.norm(a - b, axis=1)
    area2 = np.abs((b[:, 0] - a[:, 0]) * (cc[:, 1] - a[:, 1])
                   - (b[:, 1] - a[:, 1]) * (cc[:, 0] - a[:, 0]))
    circum = la * lb * lc / np.maximum(2.0 * area2, 1e-300)
    # the triangulation's edges, each once
    e = np.sort(np.concatenate([tri.simplices[:, [0, 1]], tri.simplices[:, [1, 2]],
                                tri.simplices[:, [2, 0]]]), axis=1)
    e = np.unique(e, axis=0)
    elen = np.linalg.norm(pts[e[:, 0]] - pts[e[:, 1]], axis=1)
    return Triangulation(tri.simplices, circum, e, elen)


@dataclass(frozen=True)
class AlphaShape:
    """The alpha shape of the main cluster at one alpha, and what it is joined on.

    Attributes
    ----------
    evidence : Evidence, its ``shape`` the union of the main cluster's alpha triangles
    glitch : (C,) bool, points of glitch clusters (step 4 i)
    evidence_count : int, samples that are evidence (all but those of glitch clusters)
    held : float, share of the evidence held by the shape's largest piece (within a cell)
    """

    evidence: Evidence
    glitch: np.ndarray
    evidence_count: int
    held: float


def alpha_shape(cells: Cells, tri: Triangulation, links: np.ndarray, alpha: float,
                settings: RegionSettings) -> AlphaShape | None:
    """The alpha shape of ``cells`` at ``alpha`` (module doc, 2), or None when no triangle
    has a circumradius below ``alpha``. ``links`` (N-1,): consecutive samples linked."""
    import shapely
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    pts, counts, inv = cells.points, cells.counts, cells.cell_of
    e, elen = tri.edges, tri.edge_len
    sel = tri.simplices[tri.circumradius < alpha]
    if not len(sel):
        return None
    # trajectory edges between cells: the limb moved continuously from one to the other
    ta, tb = inv[:-1][links], inv[1:][links]
    moved = ta != tb
    ta, tb = ta[moved], tb[moved]
    n = len(pts)
    total = counts.sum()
    # connected: within 2 alpha (the longest edge an alpha triangle can have) or along the
    # trajectory
    near = elen < 2.0 * alpha
    ea = np.concatenate((e[near, 0], ta))
    eb = np.concatenate((e[near, 1], tb))
    graph = coo_matrix((np.ones(len(ea)), (ea, eb)), shape=(n, n))
    _, label = connected_components(graph, directed=False)
    weight = np.bincount(label, weights=counts)
    main = int(np.argmax(weight))
    in_main = label == main
    # clusters joined to the main one neither in space nor along the trajectory, each holding
    # less than ``cluster_share``: isolated glitch clusters
    glitch = ~in_main & (weight[label] < settings.cluster_share * total)
    evidence = total - counts[glitch].sum()
    mine = sel[in_main[sel[:, 0]]]
    rings = np.concatenate((pts[mine], pts[mine][:, :1]), axis=1)
    union = shapely.coverage_union_all(shapely.polygons(rings))
    # alpha is large enough when one piece of the shape holds the evidence: a sparse recording
    # splits the shape into pieces (and leaves pockets between them), which a larger alpha
    # joins
    parts = list(getattr(union, "geoms", [union]))
    held = max(counts[shapely.contains_xy(g.buffer(settings.cell_deg), pts[:, 0],
                                          pts[:, 1])].sum() for g in parts) / evidence
    keep = in_main[e[:, 0]] & (elen < 2.0 * alpha)
    ev = Evidence(union, pts, counts, inv, in_main, links, e[keep], elen[keep])
    return AlphaShape(ev, glitch, evidence, held)


@dataclass(frozen=True)
class SwingRegion:
    """The swing region in the plane (step 4's result).

    Attributes
    ----------
    region : shapely.Polygon, plane degrees: joined, holding every evidence sample, inset
    alpha_deg : float, the alpha used
    coverage : float, share of the evidence the region held when alpha was chosen
    n_glitch_cluster : int, samples left out in glitch clusters
    inset_deg : float, the noise inset applied (step 4b)
    inset_estimates : dict, its estimates (:class:`~calibration.boundary.inset.InsetEstimate`)
    evidence : Evidence, what the region was joined on
    """

    region: Any
    alpha_deg: float
    coverage: float
    n_glitch_cluster: int
    inset_deg: float
    inset_estimates: dict
    evidence: Evidence


def _joined(p: np.ndarray, ev: Evidence, settings: RegionSettings, inset: InsetSettings,
            noise_deg: float, slow_error_deg: float | None):
    """The alpha shape joined (trajectory, bridges), holding every sample of the main cluster,
    moved in by the noise inset: (region, inset_deg, estimates)."""
    region = hold(join(ev.shape, ev.shape, p, ev, settings), p, ev)
    est = swing_inset(region, p, noise_deg, slow_error_deg, inset)
    region, inset_deg = apply_inset(region, est.inset_deg, p, ev, settings)
    return region, inset_deg, est.estimates


def alpha_region(p: np.ndarray, links: np.ndarray, settings: RegionSettings,
                 inset: InsetSettings, *, noise_deg: float = 0.0,
                 slow_error_deg: float | None = None) -> SwingRegion:
    """The swing region of the samples ``p`` (module doc).

    Parameters
    ----------
    p : (N, 2) float64, plane positions (degrees), recording order
    links : (N-1,) bool, consecutive samples linked (the limb could have moved between them)
    settings, inset : the region's and the noise inset's hyper-parameters
    noise_deg : float
        Measured white noise of ``p`` (:func:`~calibration.boundary.inset.fast_noise`).
    slow_error_deg : float, optional, measured slow error (None: none measured)

    Raises
    ------
    CalibrationError
        Too few or degenerate points; no alpha shape.
    """
    import shapely

    cells = cell_means(p, settings.cell_deg)
    tri = triangulate(cells.points)
    pts, counts = cells.points, cells.counts
    alpha = settings.alpha_deg
    best = None
    for _ in range(_ALPHA_TRIES):
        shape = alpha_shape(cells, tri, links, alpha, settings)
        if shape is not None:
            held, done = shape.held, None
            if held >= settings.coverage:
                # and the joined, inset region holds it too, but for the inset band (a pocket
                # of the shape opening onto the outside can leave a stretch of the boundary
                # the limb slid along out)
                done = _joined(p, shape.evidence, settings, inset, noise_deg, slow_error_deg)
                region, inset_deg, _ = done
                tol = settings.cell_deg + inset_deg
                held = counts[shapely.contains_xy(region.buffer(tol), pts[:, 0],
                                                  pts[:, 1])].sum() / shape.evidence_count
            best = (held, alpha, done, shape)
            if held >= settings.coverage:
                break
        alpha *= _ALPHA_GROWTH
    if best is None:
        raise CalibrationError("no alpha shape could be formed from the recorded directions")
    held, alpha, done, shape = best
    if done is None:
        done = _joined(p, shape.evidence, settings, inset, noise_deg, slow_error_deg)
    region, inset_deg, estimates = done
    return SwingRegion(region, float(alpha), float(held), int(counts[shape.glitch].sum()),
                       inset_deg, estimates, shape.evidence)
