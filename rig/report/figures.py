"""Figures of the clinician's report, drawn with matplotlib (Agg) and returned as PNG bytes.

Swing directions are shown on a **Lambert azimuthal equal-area** map centred on the range of
motion: a direction ``d`` at angle ``θ`` from the centre ``c`` and azimuth ``α`` in the tangent
basis ``(u, v)`` of ``c`` is drawn at radius ``2 sin(θ/2)`` (equal areas on the sphere stay
equal on the page, so sample density and region sizes read honestly) and angle ``α``. Rings
mark 30°, 60°, … from the centre. Great-circle edges are densified by slerp before drawing.
"""

from __future__ import annotations

import io
import math

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

__all__ = [
    "EqualAreaMap",
    "anatomical_directions",
    "boundary_figure",
    "error_map_figure",
    "to_png",
]


class EqualAreaMap:
    """Lambert azimuthal equal-area projection of unit vectors about a centre direction.

    Parameters
    ----------
    centre : (3,) array_like
        Direction at the middle of the map (normalised).
    """

    def __init__(self, centre, up=None) -> None:
        c = np.asarray(centre, dtype=np.float64)
        self.centre = c / np.linalg.norm(c)
        if up is not None:
            # page up = ``up`` made tangent at the centre; page right = up × centre (the
            # sphere seen from outside, looking at the centre)
            w = np.asarray(up, dtype=np.float64)
            w = w - (w @ self.centre) * self.centre
            if np.linalg.norm(w) > 1e-6:
                self.v = w / np.linalg.norm(w)
                self.u = np.cross(self.v, self.centre)
                return
        helper = np.eye(3)[int(np.argmin(np.abs(self.centre)))]
        u = np.cross(helper, self.centre)
        self.u = u / np.linalg.norm(u)
        self.v = np.cross(self.centre, self.u)

    def project(self, d: np.ndarray) -> np.ndarray:
        """(N, 3) unit directions → (N, 2) map coordinates (radius 2 sin(θ/2))."""
        d = np.atleast_2d(np.asarray(d, dtype=np.float64))
        cos_t = np.clip(d @ self.centre, -1.0, 1.0)
        r = np.sqrt(np.maximum(2.0 - 2.0 * cos_t, 0.0))  # = 2 sin(θ/2)
        a = np.arctan2(d @ self.v, d @ self.u)
        return np.column_stack([r * np.cos(a), r * np.sin(a)])

    @staticmethod
    def ring_radius(theta_deg: float) -> float:
        """Map radius of the ring ``theta_deg`` from the centre."""
        return 2.0 * math.sin(math.radians(theta_deg) / 2.0)


def densify_arc(a: np.ndarray, b: np.ndarray, step_deg: float = 1.0) -> np.ndarray:
    """Points along the minor great-circle arc from ``a`` to ``b`` (both included), (K, 3)."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    ang = math.acos(max(-1.0, min(1.0, float(a @ b))))
    k = max(2, math.ceil(math.degrees(ang) / step_deg) + 1)
    if ang < 1e-9:
        return np.vstack([a, b])
    t = np.linspace(0.0, 1.0, k)[:, None]
    pts = (np.sin((1.0 - t) * ang) * a + np.sin(t * ang) * b) / math.sin(ang)
    return pts


def _polygon_outline(vertices: np.ndarray) -> np.ndarray:
    v = np.asarray(vertices, dtype=np.float64)
    parts = [densify_arc(v[i], v[(i + 1) % len(v)])[:-1] for i in range(len(v))]
    parts.append(v[:1])
    return np.vstack(parts)


def _cone_outline(centre: np.ndarray, radius_rad: float, n: int = 361) -> np.ndarray:
    m = EqualAreaMap(centre)
    a = np.linspace(0.0, 2.0 * math.pi, n)[:, None]
    return (math.cos(radius_rad) * m.centre
            + math.sin(radius_rad) * (np.cos(a) * m.u + np.sin(a) * m.v))


def swing_outline(swing) -> np.ndarray | None:
    """Densified outline (K, 3) of a :class:`models.constraint` cone or polygon swing."""
    if swing is None:
        return None
    if hasattr(swing, "vertices"):
        return _polygon_outline(swing.vertices)
    return _cone_outline(np.asarray(swing.centre), float(swing.radius))


def _grid(ax, max_deg: float) -> None:
    for deg in range(30, int(max_deg) + 1, 30):
        r = EqualAreaMap.ring_radius(deg)
        ax.add_patch(plt.Circle((0, 0), r, fill=False, lw=0.6, color="0.75", zorder=0))
        ax.text(r * math.cos(math.radians(80)), r * math.sin(math.radians(80)), f"{deg}°",
                fontsize=7, color="0.45")
    lim = EqualAreaMap.ring_radius(max_deg) * 1.04
    ax.set_xlim(-lim, lim)
    ax.set_ylim(-lim, lim)
    ax.set_aspect("equal")
    ax.set_xticks([])
    ax.set_yticks([])
    for s in ax.spines.values():
        s.set_visible(False)


def _extent_deg(m: EqualAreaMap, *point_sets: np.ndarray | None) -> float:
    worst = 30.0
    for pts in point_sets:
        if pts is None or len(pts) == 0:
            continue
        theta = np.degrees(np.arccos(np.clip(np.asarray(pts) @ m.centre, -1, 1)))
        worst = max(worst, float(np.max(theta)))
    return min(180.0, 30.0 * math.ceil(worst / 30.0 + 0.05))


def to_png(fig, dpi: int = 110) -> bytes:
    """Render and close a figure; PNG bytes."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, bbox_inches="tight")
    plt.close(fig)
    return buf.getvalue()


#: Anatomical directions of the limb in the rig's thorax frame (+X inferior, +Y anterior, +Z
#: right): a right limb's lateral is +Z, a left limb's −Z.
def anatomical_directions(side: str | None) -> dict[str, np.ndarray]:
    """Label → unit direction (thorax frame, rig axes) of the six anatomical directions a
    limb can point to; ``side`` decides which of ±Z is lateral (right when None)."""
    lateral = -1.0 if side == "left" else 1.0
    return {"superior": np.array([-1.0, 0.0, 0.0]), "inferior (at side)": np.array([1.0, 0, 0]),
            "anterior": np.array([0.0, 1.0, 0.0]), "posterior": np.array([0.0, -1.0, 0.0]),
            "lateral": np.array([0.0, 0.0, lateral]), "medial": np.array([0.0, 0.0, -lateral])}


def _anatomical_labels(ax, m: EqualAreaMap, max_deg: float, side: str | None) -> None:
    """Each anatomical direction marked where it falls on the map, or named at the map's edge
    in its direction (with an arrow) when it lies beyond the map."""
    rim = EqualAreaMap.ring_radius(max_deg)
    for label, d in anatomical_directions(side).items():
        theta = math.degrees(math.acos(max(-1.0, min(1.0, float(d @ m.centre)))))
        x, y = m.project(d[None, :])[0]
        if theta <= max_deg and theta < 150.0:
            ax.plot([x], [y], "s", color="#762a83", ms=4)
            ax.annotate(label, (x, y), xytext=(4, 4), textcoords="offset points", fontsize=7,
                        color="#762a83")
        else:
            if theta >= 150.0:  # nearly opposite the centre: its azimuth says nothing
                ax.text(0.0, 1.0, f"{label}: opposite the centre", transform=ax.transAxes,
                        fontsize=7, color="#762a83", ha="left", va="top")
                continue
            a = math.atan2(float(d @ m.v), float(d @ m.u))
            ca, sa = math.cos(a), math.sin(a)
            arrow = ("→" if ca > 0 else "←") if abs(ca) >= abs(sa) else ("↑" if sa > 0 else "↓")
            ax.annotate(f"{label} {arrow}", (0.97 * rim * ca, 0.97 * rim * sa), fontsize=7,
                        color="#762a83", ha="center", va="center")


def boundary_figure(
    directions: np.ndarray,
    swing,
    *,
    centre=None,
    side: str | None = None,
    sparse_arcs: list[tuple[np.ndarray, np.ndarray]] | None = None,
    reference_swing=None,
    max_points: int = 20000,
    seed: int = 0,
) -> bytes:
    """The recorded limb directions and the extracted swing boundary on an equal-area map.

    Parameters
    ----------
    directions : (N, 3) float
        Recorded limb directions, parent (thorax) frame, unit.
    swing : ConeSwing or PolygonSwing
        The extracted boundary.
    centre : (3,), optional
        Map centre; default the polygon's interior point or the cone centre.
    side : "right", "left" or None
        The limb's side: the map is drawn with superior up and the anatomical directions
        (superior, inferior, anterior, posterior, lateral, medial) labelled.
    sparse_arcs : list of ((3,), (3,)), optional
        Boundary arcs with no samples nearby, drawn in red.
    reference_swing : optional
        A second boundary drawn dashed (e.g. the simulated patient's true range).
    max_points : int
        Samples drawn at most (a seeded random subset beyond that).
    """
    d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    if centre is None:
        centre = getattr(swing, "interior", None)
        if centre is None:
            centre = getattr(swing, "centre", None)
        if centre is None:
            centre = d.mean(axis=0) if len(d) else np.array([1.0, 0.0, 0.0])
    anat = anatomical_directions(side)
    c = np.asarray(centre, dtype=np.float64) / np.linalg.norm(centre)
    # superior up, unless the map looks along the vertical (a range about the arm at the
    # side): then anterior up
    up = anat["superior"] if abs(float(c @ anat["superior"])) < math.cos(math.radians(45.0)) \
        else anat["anterior"]
    m = EqualAreaMap(centre, up=up)
    if len(d) > max_points:
        d = d[np.random.default_rng(seed).choice(len(d), max_points, replace=False)]
    outline = swing_outline(swing)
    ref = swing_outline(reference_swing)
    fig, ax = plt.subplots(figsize=(5.4, 5.4))
    extent = _extent_deg(m, d, outline, ref)
    _grid(ax, extent)
    _anatomical_labels(ax, m, extent, side)
    if len(d):
        p = m.project(d)
        ax.scatter(p[:, 0], p[:, 1], s=2.5, c="#4477aa", alpha=0.4, linewidths=0,
                   label=f"samples ({len(directions):,})", rasterized=True)
    if ref is not None:
        p = m.project(ref)
        ax.plot(p[:, 0], p[:, 1], "--", color="0.35", lw=1.0, label="reference range")
    if outline is not None:
        p = m.project(outline)
        ax.plot(p[:, 0], p[:, 1], "-", color="#222222", lw=1.6, label="recorded boundary")
    for k, (a, b) in enumerate(sparse_arcs or []):
        p = m.project(densify_arc(a, b))
        ax.plot(p[:, 0], p[:, 1], "-", color="#cc3311", lw=3.2, alpha=0.85,
                label="sparsely sampled" if k == 0 else None)
    ax.plot([0], [0], "+", color="k", ms=8)
    ax.legend(loc="lower left", fontsize=7, frameon=False)
    ax.set_title("Swing range on an equal-area map (rings: degrees from centre)", fontsize=9)
    return to_png(fig)


def error_map_figure(
    directions: np.ndarray,
    error: np.ndarray,
    swing,
    *,
    centre=None,
    label: str = "3-D error (%)",
    vmax: float | None = None,
) -> bytes:
    """Per-direction model error coloured on the equal-area map (thesis-style error map).

    Parameters
    ----------
    directions : (N, 3) float
        Limb directions where the model was evaluated (parent frame).
    error : (N,) float
        Error at each direction (e.g. 3-D error in percent).
    swing : ConeSwing or PolygonSwing
        The boundary, drawn on top.
    """
    d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    e = np.asarray(error, dtype=np.float64).reshape(-1)
    if centre is None:
        centre = getattr(swing, "interior", None)
        if centre is None:
            centre = getattr(swing, "centre", np.array([1.0, 0.0, 0.0]))
    m = EqualAreaMap(centre)
    outline = swing_outline(swing)
    fig, ax = plt.subplots(figsize=(5.8, 5.2))
    _grid(ax, _extent_deg(m, d))
    p = m.project(d)
    top = vmax if vmax is not None else max(float(np.percentile(e, 99)), 1e-6)
    sc = ax.scatter(p[:, 0], p[:, 1], c=e, s=7, cmap="viridis", vmin=0.0, vmax=top,
                    linewidths=0, rasterized=True)
    if outline is not None:
        q = m.project(outline)
        ax.plot(q[:, 0], q[:, 1], "-", color="#cc3311", lw=1.4)
    cb = fig.colorbar(sc, ax=ax, fraction=0.046, pad=0.02)
    cb.set_label(label, fontsize=8)
    ax.set_title("Model error by limb direction (boundary in red)", fontsize=9)
    return to_png(fig)
