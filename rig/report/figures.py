"""Figures of the clinician's report, drawn with matplotlib (Agg) and returned as PNG bytes.

Swing directions are shown on a **Lambert azimuthal equal-area** map centred on the range of
motion: a direction ``d`` at angle ``θ`` from the centre ``c`` and azimuth ``α`` in the tangent
basis ``(u, v)`` of ``c`` is drawn at radius ``2 sin(θ/2)`` (equal areas on the sphere stay
equal on the page, so sample density and region sizes read honestly) and angle ``α``. Rings
mark 30°, 60°, … from the centre. Great-circle edges are densified by slerp before drawing.
The map is seen from outside the sphere, superior up (anterior up when it looks along the
vertical); anatomical directions are marked where they fall (:func:`anatomical_directions` for
the shoulder's report, :func:`joint_directions` for any joint of an arm or leg: the child's
long axis after 90° of each pure movement, in the parent segment's rig frame, so a left limb's
lateral lies on the other side of the map).

A hinge is drawn as an interval bar (:func:`hinge_figure`), a coupling as a joint's limit
against its hinge's angle (:func:`coupling_figure`).
"""

from __future__ import annotations

import io
import math

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from calibration.joint_angles import from_angles
from models import quaternion as Q

__all__ = [
    "EqualAreaMap",
    "anatomical_directions",
    "boundary_figure",
    "coupling_figure",
    "error_map_figure",
    "hinge_figure",
    "joint_directions",
    "map_side_of",
    "outline_style",
    "swing_map",
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


def _grid(ax, max_deg: float, label_azimuth_deg: float = 80.0) -> None:
    """The rings 30°, 60°, … from the centre, each labelled along ``label_azimuth_deg`` (on a
    white ground, so no outline hides it)."""
    ca, sa = math.cos(math.radians(label_azimuth_deg)), math.sin(math.radians(label_azimuth_deg))
    for deg in range(30, int(max_deg) + 1, 30):
        r = EqualAreaMap.ring_radius(deg)
        ax.add_patch(plt.Circle((0, 0), r, fill=False, lw=0.6, color="0.75", zorder=0))
        if deg <= 150:  # the rings crowd towards the antipode
            ax.text(r * ca, r * sa, f"{deg}°", fontsize=7, color="0.45", ha="center",
                    va="center", zorder=5,
                    bbox={"fc": "white", "ec": "none", "alpha": 0.8, "pad": 0.4})
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


#: The pure movements (clinical angles α, β, γ of :func:`calibration.joint_angles.from_angles`,
#: degrees) whose directions label a joint's map, with the anatomical direction they point to.
_JOINT_LABELS: dict[str, tuple[tuple[str, tuple[float, float, float]], ...]] = {
    "hip": (("flexion / anterior", (90.0, 0.0, 0.0)), ("extension / posterior", (-90.0, 0, 0)),
            ("adduction / medial", (0.0, 90.0, 0.0)), ("abduction / lateral", (0.0, -90.0, 0))),
    "wrist": (("flexion / palmar", (90.0, 0.0, 0.0)), ("extension / dorsal", (-90.0, 0, 0)),
              ("ulnar deviation / medial", (0.0, 90.0, 0.0)),
              ("radial deviation / lateral", (0.0, -90.0, 0.0))),
    # the ankle's β turns the foot about its own long axis: the toes go medially with γ
    "ankle": (("dorsiflexion / toes up", (90.0, 0.0, 0.0)),
              ("plantarflexion / toes down", (-90.0, 0.0, 0.0)),
              ("toes medial / inversion", (0.0, 0.0, 90.0)),
              ("toes lateral / eversion", (0.0, 0.0, -90.0))),
}


def joint_directions(joint: str, side: str | None) -> dict[str, np.ndarray]:
    """Label → unit direction (parent segment's rig frame) of the anatomical directions a
    joint's child segment can point to, for its map: ``"neutral"`` (every clinical angle 0)
    and each pure movement at 90° named with where it points (``"flexion / anterior"``,
    ``"abduction / lateral"``, …), mirrored for a left limb. The shoulder's are the thorax's
    (:func:`anatomical_directions`) named by movement; a joint without clinical angles gets
    :func:`anatomical_directions`."""
    if joint == "shoulder":
        a = anatomical_directions(side)
        return {"neutral (at side)": a["inferior (at side)"], "overhead": a["superior"],
                "flexion / anterior": a["anterior"], "extension / posterior": a["posterior"],
                "abduction / lateral": a["lateral"], "adduction / medial": a["medial"]}
    if joint not in _JOINT_LABELS:
        return anatomical_directions(side)
    s = "left" if side == "left" else "right"
    x = np.array([1.0, 0.0, 0.0])  # every rig segment's long axis, the foot's too
    out = {"neutral": Q.rotate(from_angles(0.0, 0.0, 0.0, joint, s)[0], x)}
    for label, angles in _JOINT_LABELS[joint]:
        out[label] = Q.rotate(from_angles(*angles, joint, s)[0], x)
    return out


def swing_map(centre, side: str | None = None) -> EqualAreaMap:
    """The map :func:`boundary_figure` draws about ``centre``: superior (−X of the parent
    segment) up, unless the map looks along the vertical (a range about the limb hanging
    down): then anterior (+Y) up."""
    anat = anatomical_directions(side)
    c = np.asarray(centre, dtype=np.float64)
    c = c / np.linalg.norm(c)
    up = anat["superior"] if abs(float(c @ anat["superior"])) < math.cos(math.radians(45.0)) \
        else anat["anterior"]
    return EqualAreaMap(c, up=up)


def map_side_of(m: EqualAreaMap, direction) -> str:
    """Where ``direction`` lies on the page from the map's centre: ``"up"``, ``"down"``,
    ``"left"``, ``"right"`` (the larger page component), or ``"centre"`` / ``"opposite"``
    within 5° of the centre or of its antipode."""
    d = np.asarray(direction, dtype=np.float64)
    theta = math.degrees(math.acos(max(-1.0, min(1.0, float(d @ m.centre)))))
    if theta < 5.0:
        return "centre"
    if theta > 175.0:
        return "opposite"
    x, y = float(d @ m.u), float(d @ m.v)
    if abs(x) >= abs(y):
        return "right" if x > 0 else "left"
    return "up" if y > 0 else "down"


def _ring_label_azimuth(m: EqualAreaMap, labels: dict[str, np.ndarray]) -> float:
    """The page azimuth (degrees) along which the rings are labelled: the one of 15° steps
    farthest from every anatomical label's direction on the map (a ring label on "anterior"
    hid it)."""
    taken = [math.degrees(math.atan2(float(d @ m.v), float(d @ m.u))) for d in labels.values()
             if 5.0 < math.degrees(math.acos(max(-1.0, min(1.0, float(d @ m.centre))))) < 175.0]
    taken += [90.0]  # the title and the edge label above the map

    def room(az: float) -> float:
        return min(abs((az - t + 180.0) % 360.0 - 180.0) for t in taken)

    return max(np.arange(0.0, 360.0, 15.0), key=lambda az: (room(az), -abs(az - 60.0)))


def _anatomical_labels(ax, m: EqualAreaMap, max_deg: float,
                       labels: dict[str, np.ndarray]) -> None:
    """Each anatomical direction marked where it falls on the map, or named at the map's edge
    in its direction (with an arrow) when it lies beyond the map."""
    rim = EqualAreaMap.ring_radius(max_deg)
    for label, d in labels.items():
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


#: Colours of further boundaries on a map (a coupled joint's keyframes), in order: distinct
#: from one another and from the samples' blue, the sparse arcs' red and the labels' purple
#: (Paul Tol's vibrant and muted schemes); past the last, the colours repeat dash-dotted.
OUTLINE_COLOURS = ("#222222", "#009988", "#ee7733", "#ee3377", "#997700", "#33bbee", "#117733",
                   "#882255", "#999999")


def outline_style(k: int) -> tuple[str, str]:
    """(colour, line style) of the ``k``-th further boundary: no two alike."""
    return (OUTLINE_COLOURS[k % len(OUTLINE_COLOURS)],
            "-" if k < len(OUTLINE_COLOURS) else "-.")


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
    labels: dict[str, np.ndarray] | None = None,
    outlines: list[tuple[object, str]] | None = None,
    reference_outlines: list[object] | None = None,
    title: str | None = None,
) -> bytes:
    """The recorded limb directions and the extracted swing boundary on an equal-area map.

    Parameters
    ----------
    directions : (N, 3) float
        Recorded limb directions, parent (thorax) frame, unit.
    swing : ConeSwing or PolygonSwing or None
        The extracted boundary (None: only ``outlines``).
    centre : (3,), optional
        Map centre; default the polygon's interior point or the cone centre (of the first
        outline when ``swing`` is None).
    side : "right", "left" or None
        The limb's side: the map is drawn with superior up and the anatomical directions
        (superior, inferior, anterior, posterior, lateral, medial) labelled.
    sparse_arcs : list of ((3,), (3,)), optional
        Boundary arcs with no samples nearby, drawn in red.
    reference_swing : optional
        A second boundary drawn dashed (e.g. the simulated patient's true range).
    max_points : int
        Samples drawn at most (a seeded random subset beyond that).
    labels : dict of label → (3,), optional
        The directions to label instead of :func:`anatomical_directions` (e.g.
        :func:`joint_directions`).
    outlines : list of (swing, label), optional
        Further boundaries, each in its own colour (:data:`OUTLINE_COLOURS`) and named in the
        legend: a coupled joint's limits at its keyframes.
    reference_outlines : list of swing, optional
        The reference boundary matching each of ``outlines``, dashed in the same colour.
    title : str, optional
        Instead of the default title.
    """
    d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    first = swing if swing is not None else (outlines[0][0] if outlines else None)
    if centre is None:
        centre = getattr(first, "interior", None)
        if centre is None:
            centre = getattr(first, "centre", None)
        if centre is None:
            centre = d.mean(axis=0) if len(d) else np.array([1.0, 0.0, 0.0])
    m = swing_map(centre, side)
    if len(d) > max_points:
        d = d[np.random.default_rng(seed).choice(len(d), max_points, replace=False)]
    outline = swing_outline(swing)
    ref = swing_outline(reference_swing)
    extra = [(swing_outline(s), label) for s, label in (outlines or [])]
    extra_ref = [swing_outline(s) for s in (reference_outlines or [])]
    fig, ax = plt.subplots(figsize=(5.4, 5.4))
    extent = _extent_deg(m, d, outline, ref, *(o for o, _ in extra), *extra_ref)
    labels = anatomical_directions(side) if labels is None else labels
    _grid(ax, extent, _ring_label_azimuth(m, labels))
    _anatomical_labels(ax, m, extent, labels)
    if len(d):
        p = m.project(d)
        ax.scatter(p[:, 0], p[:, 1], s=2.5, c="#4477aa", alpha=0.4, linewidths=0,
                   label=f"samples ({len(directions):,})", rasterized=True)
    if ref is not None:
        p = m.project(ref)
        ax.plot(p[:, 0], p[:, 1], "--", color="0.35", lw=1.0, label="reference range")
    for k, r in enumerate(extra_ref):
        if r is not None:
            p = m.project(r)
            ax.plot(p[:, 0], p[:, 1], "--", color=outline_style(k)[0],
                    lw=0.9, alpha=0.8, label="reference range" if k == 0 else None)
    if outline is not None:
        p = m.project(outline)
        ax.plot(p[:, 0], p[:, 1], "-", color="#222222", lw=1.6, label="recorded boundary")
    for k, (o, label) in enumerate(extra):
        if o is not None:
            p = m.project(o)
            colour, style = outline_style(k)
            ax.plot(p[:, 0], p[:, 1], style, color=colour, lw=1.5, label=label)
    for k, (a, b) in enumerate(sparse_arcs or []):
        p = m.project(densify_arc(a, b))
        ax.plot(p[:, 0], p[:, 1], "-", color="#cc3311", lw=3.2, alpha=0.85,
                label="sparsely sampled" if k == 0 else None)
    ax.plot([0], [0], "+", color="k", ms=8)
    # below the map, outside it: inside, it covered the labels at the map's edge
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, 0.0), ncol=2, fontsize=7,
              frameon=False)
    ax.set_title(title or "Swing range on an equal-area map (rings: degrees from centre)",
                 fontsize=9)
    return to_png(fig)


def hinge_figure(
    angles_deg: np.ndarray,
    interval: tuple[float, float],
    *,
    label: str = "hinge angle (°)",
    norm: tuple[float, float] | None = None,
    reference: tuple[float, float] | None = None,
    off_axis_deg: np.ndarray | None = None,
    title: str | None = None,
) -> bytes:
    """A hinge's allowed interval as a bar, with the recorded hinge angles' distribution and
    extremes above it.

    Parameters
    ----------
    angles_deg : (N,) float
        Recorded hinge angles (:func:`calibration.joints.hinge_angles`), degrees.
    interval : (min, max)
        The allowed interval, degrees.
    label : str
        The angle's name (x axis).
    norm : (min, max), optional
        The normal range (e.g. AAOS), drawn as a thin green band under the bar.
    reference : (min, max), optional
        A reference interval (the simulated patient's truth), dashed.
    off_axis_deg : (N,) float, optional
        Out-of-axis motion (:func:`calibration.joints.off_axis_angles`): its median, 95th
        percentile and largest value are written on the figure.
    """
    a = np.asarray(angles_deg, dtype=np.float64).reshape(-1)
    lo, hi = (float(v) for v in interval)
    spans = [lo, hi, *(norm or ()), *(reference or ())]
    if len(a):
        spans += [float(a.min()), float(a.max())]
    x0, x1 = min(spans), max(spans)
    pad = max(5.0, 0.06 * (x1 - x0))
    fig, (ax_h, ax_b) = plt.subplots(2, 1, figsize=(6.4, 2.9), sharex=True,
                                     gridspec_kw={"height_ratios": [2.2, 1.0], "hspace": 0.05})
    if len(a):
        bins = np.arange(math.floor(x0 - pad), math.ceil(x1 + pad) + 2.5, 2.5)
        ax_h.hist(a, bins=bins, color="#4477aa", alpha=0.75, label=f"recorded ({len(a):,})")
        for v, name in ((float(a.min()), "min"), (float(a.max()), "max")):
            ax_h.axvline(v, color="#4477aa", lw=1.0, ls=":")
            ax_h.annotate(f"{name} {v:.1f}°", (v, 1.0), xycoords=("data", "axes fraction"),
                          xytext=(3 if name == "max" else -3, -10), textcoords="offset points",
                          ha="left" if name == "max" else "right", fontsize=7, color="#4477aa")
    ax_h.set_yticks([])
    ax_h.set_ylabel("samples", fontsize=7)
    for s in ("top", "right", "left"):
        ax_h.spines[s].set_visible(False)
    head = title or "Hinge range: allowed interval and recorded angles"
    if off_axis_deg is not None and len(off_axis_deg):
        o = np.asarray(off_axis_deg, dtype=np.float64)
        head += (f"\noff-axis motion: median {np.median(o):.1f}°, 95th percentile "
                 f"{np.percentile(o, 95):.1f}°, max {o.max():.1f}°")
    ax_b.barh([0.0], [hi - lo], left=[lo], height=0.5, color="0.85", edgecolor="#222222",
              lw=1.4, label=f"allowed {lo:.1f}° … {hi:.1f}°")
    if norm is not None:
        ax_b.barh([-0.5], [norm[1] - norm[0]], left=[norm[0]], height=0.14, color="#1b7837",
                  alpha=0.6, label=f"normal {norm[0]:.0f}° … {norm[1]:.0f}°")
    if reference is not None:
        ax_b.barh([0.0], [reference[1] - reference[0]], left=[reference[0]], height=0.62,
                  fill=False, edgecolor="0.35", ls="--", lw=1.0, label="reference range")
    if len(a):
        ax_b.plot([a.min(), a.max()], [0.42, 0.42], "|-", color="#4477aa", ms=9, lw=1.2,
                  label="recorded extremes")
    ax_b.set_ylim(-0.8, 0.8)
    ax_b.set_yticks([])
    for s in ("top", "right", "left"):
        ax_b.spines[s].set_visible(False)
    ax_b.set_xlim(x0 - pad, x1 + pad)
    ax_b.set_xlabel(label, fontsize=8)
    ax_b.legend(loc="upper center", bbox_to_anchor=(0.5, -0.55), ncol=4, fontsize=7,
                frameon=False)
    ax_h.set_title(head, fontsize=9)
    return to_png(fig)


def coupling_figure(
    angle_deg: np.ndarray,
    lower: np.ndarray,
    upper: np.ndarray,
    *,
    keyframes_deg=(),
    recorded: tuple[np.ndarray, np.ndarray] | None = None,
    reference: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
    xlabel: str = "coupling angle (°)",
    ylabel: str = "limit (°)",
    title: str | None = None,
    max_points: int = 6000,
    seed: int = 0,
) -> bytes:
    """A coupled joint's limits against its hinge's angle: the allowed band between ``lower``
    and ``upper`` (its interpolation between keyframes, clamped beyond them), the keyframes
    marked, the recorded postures scattered.

    Parameters
    ----------
    angle_deg : (M,) float, increasing
        Coupling angles at which the limits were evaluated.
    lower, upper : (M,) float
        The dependent joint's limits there (NaN where it has none).
    keyframes_deg : sequence of float
        The coupling's keyframe angles (dotted verticals, limits marked).
    recorded : ((N,), (N,)), optional
        Recorded coupling angles and the dependent joint's angle at each.
    reference : ((K,), (K,), (K,)), optional
        A reference's angles, lower and upper limits, dashed.
    """
    x = np.asarray(angle_deg, dtype=np.float64)
    lo = np.asarray(lower, dtype=np.float64)
    hi = np.asarray(upper, dtype=np.float64)
    fig, ax = plt.subplots(figsize=(6.4, 4.0))
    ax.fill_between(x, lo, hi, color="0.88", label="allowed", lw=0)
    ax.plot(x, hi, "-", color="#222222", lw=1.5, label="limits")
    ax.plot(x, lo, "-", color="#222222", lw=1.5)
    if reference is not None:
        rx, rlo, rhi = (np.asarray(v, dtype=np.float64) for v in reference)
        ax.plot(rx, rhi, "--", color="0.35", lw=1.0, label="reference limits")
        ax.plot(rx, rlo, "--", color="0.35", lw=1.0)
    if recorded is not None and len(recorded[0]):
        rx, ry = (np.asarray(v, dtype=np.float64).reshape(-1) for v in recorded)
        if len(rx) > max_points:
            keep = np.random.default_rng(seed).choice(len(rx), max_points, replace=False)
            rx, ry = rx[keep], ry[keep]
        ax.scatter(rx, ry, s=3, c="#4477aa", alpha=0.45, linewidths=0,
                   label=f"recorded postures ({len(recorded[0]):,})", rasterized=True)
    for k, a in enumerate(keyframes_deg):
        ax.axvline(a, color="#ee7733", lw=0.9, ls=":", label="keyframes" if k == 0 else None)
        for v in (np.interp(a, x, hi), np.interp(a, x, lo)):
            if np.isfinite(v):
                ax.plot([a], [v], "o", color="#ee7733", ms=5)
    ax.set_xlabel(xlabel, fontsize=8)
    ax.set_ylabel(ylabel, fontsize=8)
    ax.tick_params(labelsize=7)
    ax.grid(True, color="0.9", lw=0.5)
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.13), ncol=3, fontsize=7,
              frameon=False)
    ax.set_title(title or "Coupled limits against the hinge angle", fontsize=9)
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
