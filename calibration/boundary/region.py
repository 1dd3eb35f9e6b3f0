"""One swing region from the pieces of an alpha shape, joined on recorded evidence (step 4).

A swing limit is simply connected, so the pieces of the alpha shape
(:mod:`calibration.boundary.alpha`) are joined and holes filled — on recorded evidence only
(:class:`Evidence`: the cells, their sample counts, the main cluster, the trajectory links and
the short Delaunay edges):

- **along the trajectory** (:func:`join`): cells are labelled by the piece they lie in. A run
  of consecutive linked samples between two labelled samples is a *transit* when the pieces
  differ (the limb went from one to the other through the gap, e.g. a thin neck) and an
  *excursion* when it leaves the reference shape by more than ``cell_deg`` (a sparse stretch,
  such as a lobe visited once, that formed no triangle; :func:`leaving`); so are runs at the
  ends of a stretch of trajectory. These runs are buffered by ``cell_deg / 2`` and merged with
  the pieces, then closed by ``cell_deg`` (a slit of less than two cells is no evidence of a
  limit);
- **bridges** (:func:`bridge`): pieces still apart that hold at least ``min_piece_samples``
  samples (a lobe only ever seen inside) are joined to the piece holding most samples along
  the minimax path through the recorded cells — the Euclidean minimum spanning tree
  (:func:`scipy.sparse.csgraph.minimum_spanning_tree`; edges inside a piece cost nothing),
  edges shorter than ``2 alpha``: alpha grown locally, along the data, not everywhere;
- the piece holding most samples is kept and its holes filled;
- **held samples** (:func:`hold`): a sample of the main cluster still outside (a trajectory
  that grazed the shape by less than ``cell_deg``) is reached by a strip 0.02° wide from the
  region's nearest point: the envelope touches every recorded sample;
- **the noise inset** (:func:`apply_inset`; its amount from
  :func:`calibration.boundary.inset.swing_inset`): the region shrunk, its pieces joined again
  as above, so that a neck narrower than twice the inset does not cut a recorded lobe off.

Documented in docs/calibration.md, "Boundary extraction", steps 4 and 4b.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calibration.boundary.planar import boundary_distance_2d, label_parts
from calibration.errors import CalibrationError

__all__ = ["Evidence", "RegionSettings", "apply_inset", "bridge", "hold", "join", "leaving"]


@dataclass(frozen=True)
class RegionSettings:
    """Hyper-parameters of the swing region (steps 4, 4 i-v); angles in degrees.

    Attributes
    ----------
    alpha_deg : float, alpha-shape radius (the first tried; grown ×1.5 up to 4 times)
    cell_deg : float, cell size of the alpha shape's points; corridor width and closing radius
    min_piece_samples : int, samples a separate piece needs to be bridged to the main one
    coverage : float, share of the evidence the region must hold
    cluster_share : float, clusters apart from the main one holding less are glitch clusters
    """

    alpha_deg: float = 4.0
    cell_deg: float = 0.5
    min_piece_samples: int = 5
    coverage: float = 0.995
    cluster_share: float = 0.01


@dataclass(frozen=True)
class Evidence:
    """What the region is joined on: the alpha shape's cells at one alpha.

    Attributes
    ----------
    shape : shapely (Multi)Polygon, the alpha shape of the main cluster
    points : (C, 2) float64, the cells' points (plane degrees): means, then outermost samples
    counts : (C,) int, samples per point (0: geometry, not evidence)
    cell_of : (N,) int, each sample's cell (index into ``points``)
    in_main : (C,) bool, the point belongs to the main cluster (step 4 i)
    links : (N-1,) bool, consecutive samples linked
        (:func:`~calibration.boundary.outliers.trajectory_links`)
    edges : (E, 2) int, Delaunay edges of the main cluster shorter than ``2 alpha``
    edge_len : (E,) float64, their lengths
    """

    shape: object
    points: np.ndarray
    counts: np.ndarray
    cell_of: np.ndarray
    in_main: np.ndarray
    links: np.ndarray
    edges: np.ndarray
    edge_len: np.ndarray


def join(union, reference, p: np.ndarray, ev: Evidence, settings: RegionSettings):
    """The part of ``union`` holding most samples, joined to the others by the trajectory.

    Cells are labelled by the part of ``union`` they lie in. A *run* is a stretch of linked
    samples (all in the main cluster) between two consecutive labelled samples: a
    **transit** when the labels differ (the limb went from one part to another), an
    **excursion** when they agree but the run leaves ``reference`` by more than
    ``cell_deg`` (recorded range outside the alpha shape).
    Runs also at the ends of a stretch of linked samples (leaving a part and not coming
    back). The runs are buffered by ``cell_deg / 2`` and merged; of the result, the part
    holding most samples is kept and its holes filled.

    Parameters
    ----------
    union : shapely geometry, the pieces to join
    reference : shapely geometry, what an excursion leaves
    p : (N, 2) float64, the samples (plane degrees, recording order)

    Returns
    -------
    shapely.Polygon
    """
    import shapely

    pts, counts, inv, in_main, links = ev.points, ev.counts, ev.cell_of, ev.in_main, ev.links
    parts = [g for g in getattr(union, "geoms", [union]) if not g.is_empty]
    cell_part = label_parts(parts, pts)
    lab = np.where(in_main[inv], cell_part[inv], -2)  # -2: not in the main cluster
    ok = links & (lab[:-1] != -2) & (lab[1:] != -2)
    chain = np.concatenate(([0], np.cumsum(~ok)))
    k = np.flatnonzero(lab >= 0)
    runs = []
    if len(k):
        k1, k2 = k[:-1], k[1:]
        same_chain = chain[k1] == chain[k2]
        transit = same_chain & (lab[k1] != lab[k2])
        excursion = same_chain & (lab[k1] == lab[k2]) & (k2 - k1 > 1)
        runs.append(np.column_stack((k1[transit], k2[transit])))
        ends = []
        exc = np.column_stack((k1[excursion], k2[excursion]))
        # stretches that leave a part and end (or begin) outside every part
        first = np.ones(len(k), dtype=bool)
        first[1:] = chain[k[1:]] != chain[k[:-1]]
        last = np.ones(len(k), dtype=bool)
        last[:-1] = first[1:]
        start_of = np.searchsorted(chain, chain[k[first]], side="left")
        end_of = np.searchsorted(chain, chain[k[last]], side="right") - 1
        ends.append(np.column_stack((start_of, k[first])))
        ends.append(np.column_stack((k[last], end_of)))
        cand = np.concatenate([exc, *ends])
        cand = cand[cand[:, 1] > cand[:, 0]]
        if len(cand):
            runs.append(leaving(cand, reference, p, lab, settings.cell_deg))
    runs = np.concatenate(runs) if runs else np.zeros((0, 2), dtype=np.int64)
    geoms = parts
    if len(runs):
        length = runs[:, 1] - runs[:, 0] + 1
        ids = np.repeat(np.arange(len(runs)), length)
        idx = np.repeat(runs[:, 0] - np.cumsum(np.r_[0, length[:-1]]), length) \
            + np.arange(length.sum())
        lines = shapely.linestrings(p[idx], indices=ids)
        geoms = [*parts, *shapely.buffer(lines, 0.5 * settings.cell_deg, quad_segs=2)]
    if not geoms:
        raise CalibrationError("no alpha shape could be formed from the recorded directions")
    # closing by one cell: a slit narrower than two cells between the pieces is no
    # evidence of a limit (it would leave an unvisited pocket in the region)
    # (united with the pieces themselves: the closing would erase a sliver of the alpha
    # shape along a boundary the limb slid along, which encloses such a pocket)
    r = settings.cell_deg
    merged = shapely.union_all(geoms)
    merged = shapely.union(merged.buffer(r, quad_segs=4).buffer(-r, quad_segs=4), merged)
    pieces = list(getattr(merged, "geoms", [merged]))
    if len(pieces) > 1:
        pieces = bridge(pieces, ev, settings)
    held = [counts[shapely.intersects_xy(g, pts[:, 0], pts[:, 1])].sum() for g in pieces]
    return shapely.Polygon(pieces[int(np.argmax(held))].exterior)


def hold(poly, p: np.ndarray, ev: Evidence):
    """``poly`` reaching out to every sample of the main cluster still outside it (a
    trajectory that grazed the shape by less than ``cell_deg``, so no excursion of step
    4 ii): joined by a strip 0.02° wide from the nearest point of the region, so the
    envelope touches it. Returns a shapely.Polygon."""
    import shapely

    evidence = ev.in_main[ev.cell_of]  # not the samples of glitch clusters (step 4 i)
    out = p[evidence & ~shapely.contains_xy(poly, p[:, 0], p[:, 1])]
    if not len(out):
        return poly
    # one sample per occupied 0.05° cell is enough to hold them all within that
    key = np.unique(np.floor(out / 0.05).astype(np.int64), axis=0, return_index=True)[1]
    lines = shapely.shortest_line(poly, shapely.points(out[key]))
    strips = shapely.buffer(lines, 0.01, quad_segs=1)
    merged = shapely.union_all([poly, *strips])
    pieces = list(getattr(merged, "geoms", [merged]))
    return shapely.Polygon(max(pieces, key=lambda g: g.area).exterior)


def bridge(pieces, ev: Evidence, settings: RegionSettings) -> list:
    """Join pieces of the region that the trajectory did not join (a lobe the limb was only
    ever seen inside): along the minimax path through the recorded cells from each piece
    to the piece holding most samples, edges shorter than ``2 alpha`` (local alpha growth
    along the Euclidean minimum spanning tree, which holds every minimax path). Pieces
    with fewer than ``min_piece_samples`` samples are left alone (they fall away).
    Returns the pieces (polygons) after bridging."""
    import shapely
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import breadth_first_order, minimum_spanning_tree

    pts, counts, e, elen = ev.points, ev.counts, ev.edges, ev.edge_len
    n = len(pts)
    cp = label_parts(pieces, pts)
    held = np.bincount(cp[cp >= 0], weights=counts[cp >= 0], minlength=len(pieces))
    main = int(np.argmax(held))
    # inside one piece an edge costs (almost) nothing: the tree crosses between pieces on
    # the shortest edges
    inside = (cp[e[:, 0]] == cp[e[:, 1]]) & (cp[e[:, 0]] >= 0)
    w = np.where(inside, 1e-9, elen)
    tree = minimum_spanning_tree(coo_matrix((w, (e[:, 0], e[:, 1])), shape=(n, n)).tocsr())
    root = int(np.flatnonzero(cp == main)[0])
    _, pred = breadth_first_order(tree, root, directed=False, return_predecessors=True)
    segs = []
    for k in np.flatnonzero(held >= settings.min_piece_samples):
        if k == main:
            continue
        node = int(np.flatnonzero(cp == k)[0])
        path = []
        while node >= 0 and cp[node] != main:
            nxt = int(pred[node])
            if nxt >= 0 and not (cp[node] == cp[nxt] and cp[node] >= 0):
                path.append((node, nxt))
            node = nxt
        if node >= 0:  # reached the main piece
            segs.extend(path)
    if not segs:
        return pieces
    s = np.asarray(segs)
    lines = shapely.linestrings(np.stack((pts[s[:, 0]], pts[s[:, 1]]), axis=1))
    merged = shapely.union_all([*pieces, *shapely.buffer(lines, 0.5 * settings.cell_deg,
                                                         quad_segs=2)])
    return list(getattr(merged, "geoms", [merged]))


def leaving(cand: np.ndarray, reference, p: np.ndarray, lab: np.ndarray,
            cell_deg: float) -> np.ndarray:
    """Of candidate runs ``cand`` (M, 2: first and last sample index), those with a sample
    more than ``cell_deg`` outside ``reference``; ``lab`` (N,) is each sample's part label
    (< 0: in none)."""
    import shapely

    length = cand[:, 1] - cand[:, 0] + 1
    ids = np.repeat(np.arange(len(cand)), length)
    idx = np.repeat(cand[:, 0] - np.cumsum(np.r_[0, length[:-1]]), length) \
        + np.arange(length.sum())
    outside = lab[idx] < 0
    far = np.zeros(len(cand), dtype=bool)
    if outside.any():
        xy = p[idx[outside]]
        dist = np.where(shapely.intersects_xy(reference, xy[:, 0], xy[:, 1]), 0.0,
                        boundary_distance_2d(reference, xy))
        np.maximum.at(far, ids[outside], dist > cell_deg)
    return cand[far]


def apply_inset(poly, inset_deg: float, p: np.ndarray, ev: Evidence,
                settings: RegionSettings):
    """``poly`` moved in by ``inset_deg`` (round joins), the shrunk parts joined again along
    the trajectory against the unshrunk alpha shape (a neck narrower than twice the inset, or
    a corridor, does not cut a recorded lobe off).

    Returns
    -------
    region : shapely.Polygon
    inset_deg : float, the inset applied (0 when none is, or when nothing would be left)
    """
    if inset_deg <= 0.0:
        return poly, 0.0
    shrunk = poly.buffer(-inset_deg, join_style="round")
    if shrunk.is_empty:
        return poly, 0.0
    return join(shrunk, ev.shape, p, ev, settings), inset_deg
