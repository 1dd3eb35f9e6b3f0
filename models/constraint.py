"""Joint-constraint definitions and their YAML file format.

A joint constraint limits the orientation ``q`` of a limb relative to its reference segment,
split by swing-twist about the limb axis (``q = swing ⊗ twist``, see :mod:`models.quaternion`):

- the **swing** limit is a region of the unit sphere S² that the limb direction
  ``d = rotate(q, limb_axis)`` must stay in: a *cone* (centre, radius — the thesis's "regular
  boundary") or a spherical *polygon* whose edges are great-circle arcs (the thesis's "irregular
  boundary"; concave allowed);
- the **twist** limit is an interval of the twist angle about the limb axis.

File format (YAML, read with ``yaml.safe_load``)::

    name: right-shoulder-example
    limb_axis: [1, 0, 0]                         # optional, default +X
    swing:
      cone: {centre: [1, 0, 0], radius_deg: 45}  # a regular boundary, or:
      # polygon: {vertices: [[x, y, z], ...], interior: [x, y, z]}   # irregular; concave allowed
    twist: {min_deg: -60, max_deg: 60}           # optional; absent = unconstrained
    # optional free-form provenance (patient id, recording session, ...), kept verbatim:
    source: {recorded: 2026-11-21, session: 12}

Vectors need not be unit length in the file; they are normalised on load. Polygon vertices are
listed in order along the boundary, either direction; ``interior`` is any point strictly inside,
which tells which of the two regions the polygon bounds (a polygon may enclose more than a
hemisphere). A polygon must be simple: no repeated consecutive vertices, no antipodal
neighbours, no crossing or overlapping edges, not all on one great circle.

Every validation error is a :class:`~models.errors.ConstraintError` that names the field.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from models.errors import ConstraintError
from models.quaternion import LIMB_AXIS

__all__ = [
    "ConeSwing",
    "JointConstraint",
    "PolygonSwing",
    "TwistLimits",
    "dump_constraint",
    "load_constraint",
    "loads_constraint",
]

#: Two directions closer than this (radians) are "the same point" for validation purposes.
_COINCIDENT = 1e-9


@dataclass(frozen=True, eq=False)
class ConeSwing:
    """A circular swing boundary: the limb direction within ``radius_deg`` of ``centre``.

    Attributes
    ----------
    centre : (3,) float64, unit, parent frame
    radius_deg : float, in (0, 180)
    """

    centre: np.ndarray
    radius_deg: float

    @property
    def radius(self) -> float:
        """Radius in radians."""
        return math.radians(self.radius_deg)

    def to_dict(self) -> dict[str, Any]:
        return {"cone": {"centre": _vec_out(self.centre), "radius_deg": float(self.radius_deg)}}

    def __eq__(self, other: object) -> bool:
        return (
            isinstance(other, ConeSwing)
            and np.allclose(self.centre, other.centre, atol=1e-12)
            and math.isclose(self.radius_deg, other.radius_deg, abs_tol=1e-12)
        )

    __hash__ = None  # type: ignore[assignment]


@dataclass(frozen=True, eq=False)
class PolygonSwing:
    """A spherical-polygon swing boundary with great-circle edges (concave allowed).

    Attributes
    ----------
    vertices : (M, 3) float64, unit, parent frame, in boundary order (either direction)
    interior : (3,) float64, unit, a point strictly inside the valid region
    """

    vertices: np.ndarray
    interior: np.ndarray

    def to_dict(self) -> dict[str, Any]:
        return {
            "polygon": {
                "vertices": [_vec_out(v) for v in self.vertices],
                "interior": _vec_out(self.interior),
            }
        }

    def __eq__(self, other: object) -> bool:
        return (
            isinstance(other, PolygonSwing)
            and self.vertices.shape == other.vertices.shape
            and np.allclose(self.vertices, other.vertices, atol=1e-12)
            and np.allclose(self.interior, other.interior, atol=1e-12)
        )

    __hash__ = None  # type: ignore[assignment]


@dataclass(frozen=True)
class TwistLimits:
    """Twist interval about the limb axis, degrees, ``-180 <= min_deg <= max_deg <= 180``."""

    min_deg: float
    max_deg: float

    @property
    def min(self) -> float:
        return math.radians(self.min_deg)

    @property
    def max(self) -> float:
        return math.radians(self.max_deg)

    def to_dict(self) -> dict[str, Any]:
        return {"min_deg": float(self.min_deg), "max_deg": float(self.max_deg)}


@dataclass(frozen=True, eq=False)
class JointConstraint:
    """A swing region and an optional twist interval for one joint.

    Use :func:`load_constraint` to read one from a file, :meth:`from_dict` for a parsed mapping,
    or the :meth:`cone` / :meth:`polygon` shortcuts in code.
    """

    name: str
    swing: ConeSwing | PolygonSwing | None
    twist: TwistLimits | None = None
    limb_axis: np.ndarray = field(default_factory=lambda: LIMB_AXIS.copy())
    extra: dict[str, Any] = field(default_factory=dict)

    # -- construction ---------------------------------------------------------------------
    @classmethod
    def cone(
        cls,
        centre=(1.0, 0.0, 0.0),
        radius_deg: float = 45.0,
        *,
        twist: tuple[float, float] | None = None,
        name: str = "cone",
        limb_axis=(1.0, 0.0, 0.0),
    ) -> JointConstraint:
        """A cone swing limit (optionally with twist limits in degrees)."""
        swing = {"cone": {"centre": list(centre), "radius_deg": radius_deg}}
        return cls._build(swing, twist, name, limb_axis)

    @classmethod
    def polygon(
        cls,
        vertices,
        interior,
        *,
        twist: tuple[float, float] | None = None,
        name: str = "polygon",
        limb_axis=(1.0, 0.0, 0.0),
    ) -> JointConstraint:
        """A polygon swing limit (optionally with twist limits in degrees)."""
        swing = {
            "polygon": {
                "vertices": np.asarray(vertices, dtype=float).tolist(),
                "interior": list(np.asarray(interior, dtype=float)),
            }
        }
        return cls._build(swing, twist, name, limb_axis)

    @classmethod
    def _build(cls, swing: dict, twist, name: str, limb_axis) -> JointConstraint:
        d: dict[str, Any] = {"name": name, "limb_axis": list(limb_axis), "swing": swing}
        if twist is not None:
            d["twist"] = {"min_deg": twist[0], "max_deg": twist[1]}
        return cls.from_dict(d)

    @classmethod
    def from_dict(cls, data: Any, source: str | None = None) -> JointConstraint:
        """Validate a parsed mapping (see the module docstring for the schema)."""
        if not isinstance(data, dict):
            raise ConstraintError(
                f"expected a mapping with 'name' and 'swing', got {type(data).__name__}",
                source=source,
            )
        known = {"name", "limb_axis", "swing", "twist"}
        name = data.get("name", "unnamed")
        if not isinstance(name, str) or not name.strip():
            raise ConstraintError("must be a non-empty string", "name", source)
        limb_axis = _vector(data.get("limb_axis", [1, 0, 0]), "limb_axis", source)
        swing = _parse_swing(data.get("swing"), source)
        twist = _parse_twist(data.get("twist"), source)
        if swing is None and twist is None:
            raise ConstraintError(
                "a constraint needs a 'swing' limit, a 'twist' limit, or both", source=source
            )
        extra = {k: v for k, v in data.items() if k not in known}
        return cls(name=name, swing=swing, twist=twist, limb_axis=limb_axis, extra=extra)

    # -- output ---------------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"name": self.name, "limb_axis": _vec_out(self.limb_axis)}
        if self.swing is not None:
            out["swing"] = self.swing.to_dict()
        if self.twist is not None:
            out["twist"] = self.twist.to_dict()
        out.update(self.extra)
        return out

    def to_yaml(self) -> str:
        """The constraint as YAML text that :func:`loads_constraint` reads back identically."""
        return yaml.safe_dump(self.to_dict(), sort_keys=False, default_flow_style=None)

    def __eq__(self, other: object) -> bool:
        """Same limits (name and provenance are ignored)."""
        return (
            isinstance(other, JointConstraint)
            and self.swing == other.swing
            and self.twist == other.twist
            and np.allclose(self.limb_axis, other.limb_axis, atol=1e-12)
        )

    __hash__ = None  # type: ignore[assignment]

    def summary(self) -> str:
        """A few human-readable lines describing the limits."""
        lines = [f"constraint {self.name!r}", f"  limb axis   {_fmt_vec(self.limb_axis)}"]
        if isinstance(self.swing, ConeSwing):
            lines.append(
                f"  swing       cone, centre {_fmt_vec(self.swing.centre)}, "
                f"radius {self.swing.radius_deg:g} deg"
            )
        elif isinstance(self.swing, PolygonSwing):
            from models.oracle import polygon_area_sr  # local: oracle imports this module

            area = polygon_area_sr(self.swing)
            lines.append(
                f"  swing       polygon, {len(self.swing.vertices)} vertices, "
                f"interior {_fmt_vec(self.swing.interior)}, "
                f"area {area:.4f} sr ({100 * area / (4 * math.pi):.1f} % of the sphere)"
            )
        else:
            lines.append("  swing       unconstrained")
        if self.twist is not None:
            lines.append(f"  twist       {self.twist.min_deg:g} .. {self.twist.max_deg:g} deg")
        else:
            lines.append("  twist       unconstrained")
        return "\n".join(lines)


# -- file I/O ---------------------------------------------------------------------------------
def loads_constraint(text: str, source: str | None = None) -> JointConstraint:
    """Parse constraint YAML text."""
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as err:
        mark = getattr(err, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        problem = getattr(err, "problem", None) or "malformed YAML"
        raise ConstraintError(f"not valid YAML{where}: {problem}", source=source) from err
    return JointConstraint.from_dict(data, source=source)


def load_constraint(path: str | Path) -> JointConstraint:
    """Read and validate a constraint file.

    Raises
    ------
    ConstraintError
        The file is missing, unreadable, not YAML, or fails validation (the message names the
        file and the field).
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError as err:
        raise ConstraintError("file not found", source=str(path)) from err
    except IsADirectoryError as err:
        raise ConstraintError("is a directory, not a constraint file", source=str(path)) from err
    except (OSError, UnicodeDecodeError) as err:
        raise ConstraintError(f"cannot read: {err}", source=str(path)) from err
    return loads_constraint(text, source=str(path))


def dump_constraint(constraint: JointConstraint, path: str | Path) -> None:
    """Write a constraint file (atomically: a partial file never replaces a good one)."""
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(constraint.to_yaml(), encoding="utf-8")
    tmp.replace(path)


# -- validation helpers -----------------------------------------------------------------------
def _vector(value: Any, field_name: str, source: str | None) -> np.ndarray:
    if not isinstance(value, (list, tuple)) or len(value) != 3:
        raise ConstraintError(f"expected a 3-vector [x, y, z], got {value!r}", field_name, source)
    try:
        v = np.array([float(c) for c in value])
    except (TypeError, ValueError) as err:
        raise ConstraintError(f"expected numbers, got {value!r}", field_name, source) from err
    if not np.isfinite(v).all():
        raise ConstraintError(f"has a NaN or infinite component: {value!r}", field_name, source)
    n = float(np.linalg.norm(v))
    if n < 1e-12:
        raise ConstraintError("is a zero vector and has no direction", field_name, source)
    return v / n


def _number(value: Any, field_name: str, source: str | None) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ConstraintError(f"expected a number, got {value!r}", field_name, source)
    x = float(value)
    if not math.isfinite(x):
        raise ConstraintError(f"must be finite, got {value!r}", field_name, source)
    return x


def _parse_swing(value: Any, source: str | None) -> ConeSwing | PolygonSwing | None:
    if value is None:
        return None
    if (
        not isinstance(value, dict)
        or len(value) != 1
        or next(iter(value))
        not in (
            "cone",
            "polygon",
        )
    ):
        raise ConstraintError(
            "expected exactly one of 'cone: {centre, radius_deg}' or "
            "'polygon: {vertices, interior}'",
            "swing",
            source,
        )
    kind, body = next(iter(value.items()))
    if not isinstance(body, dict):
        raise ConstraintError(f"expected a mapping, got {body!r}", f"swing.{kind}", source)
    if kind == "cone":
        _require(body, ("centre", "radius_deg"), "swing.cone", source)
        centre = _vector(body["centre"], "swing.cone.centre", source)
        radius = _number(body["radius_deg"], "swing.cone.radius_deg", source)
        if not 0.0 < radius < 180.0:
            raise ConstraintError(
                f"must be in (0, 180) degrees, got {radius:g}", "swing.cone.radius_deg", source
            )
        return ConeSwing(centre=centre, radius_deg=radius)
    _require(body, ("vertices", "interior"), "swing.polygon", source)
    raw = body["vertices"]
    if not isinstance(raw, (list, tuple)) or len(raw) < 3:
        raise ConstraintError(
            "expected a list of at least 3 [x, y, z] vertices", "swing.polygon.vertices", source
        )
    verts = np.stack(
        [_vector(v, f"swing.polygon.vertices[{i}]", source) for i, v in enumerate(raw)]
    )
    interior = _vector(body["interior"], "swing.polygon.interior", source)
    _check_polygon(verts, interior, source)
    return PolygonSwing(vertices=verts, interior=interior)


def _require(body: dict, keys: tuple[str, ...], where: str, source: str | None) -> None:
    for k in keys:
        if k not in body:
            raise ConstraintError(f"missing '{k}'", where, source)
    unknown = set(body) - set(keys)
    if unknown:
        raise ConstraintError(f"unknown key(s) {sorted(unknown)}", where, source)


def _parse_twist(value: Any, source: str | None) -> TwistLimits | None:
    if value is None:
        return None
    if not isinstance(value, dict):
        raise ConstraintError(f"expected {{min_deg, max_deg}}, got {value!r}", "twist", source)
    _require(value, ("min_deg", "max_deg"), "twist", source)
    lo = _number(value["min_deg"], "twist.min_deg", source)
    hi = _number(value["max_deg"], "twist.max_deg", source)
    for v, f in ((lo, "twist.min_deg"), (hi, "twist.max_deg")):
        if not -180.0 <= v <= 180.0:
            raise ConstraintError(f"must be within [-180, 180] degrees, got {v:g}", f, source)
    if lo > hi:
        raise ConstraintError(f"min_deg ({lo:g}) is greater than max_deg ({hi:g})", "twist", source)
    return TwistLimits(min_deg=lo, max_deg=hi)


def _check_polygon(verts: np.ndarray, interior: np.ndarray, source: str | None) -> None:
    """Reject degenerate and self-intersecting spherical polygons."""
    f = "swing.polygon.vertices"
    m = len(verts)
    nxt = np.roll(verts, -1, axis=0)
    gap = np.arctan2(np.linalg.norm(np.cross(verts, nxt), axis=1), np.sum(verts * nxt, axis=1))
    for i in range(m):
        j = (i + 1) % m
        if gap[i] < _COINCIDENT:
            raise ConstraintError(f"vertices {i} and {j} coincide (zero-length edge)", f, source)
        if gap[i] > math.pi - 1e-6:
            raise ConstraintError(
                f"vertices {i} and {j} are antipodal: the edge between them is undefined", f, source
            )
    # all on one great circle -> zero area, inside undefined
    if np.linalg.svd(verts, compute_uv=False)[-1] < 1e-9:
        raise ConstraintError("all vertices lie on one great circle (zero area)", f, source)
    pair = _first_crossing(verts)
    if pair is not None:
        i, j = pair
        raise ConstraintError(
            f"the polygon intersects itself: edge {i}-{(i + 1) % m} crosses edge {j}-{(j + 1) % m}",
            f,
            source,
        )
    from models.oracle import polygon_boundary_distance  # local: oracle imports this module

    if polygon_boundary_distance(verts, interior) < 1e-6:
        raise ConstraintError(
            "lies on the boundary; it must be strictly inside", "swing.polygon.interior", source
        )


def _first_crossing(verts: np.ndarray) -> tuple[int, int] | None:
    """First pair of non-adjacent edges (great-circle arcs) that cross or overlap, else None."""
    m = len(verts)
    a0 = verts
    a1 = np.roll(verts, -1, axis=0)
    n = np.cross(a0, a1)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    i, j = np.triu_indices(m, k=2)
    keep = ~((i == 0) & (j == m - 1))  # first and last edges share vertex 0
    i, j = i[keep], j[keep]
    if len(i) == 0:
        return None
    hits = np.zeros(len(i), dtype=bool)
    chunk = 200_000
    for s in range(0, len(i), chunk):
        ii, jj = i[s : s + chunk], j[s : s + chunk]
        hits[s : s + chunk] = _arcs_cross(a0[ii], a1[ii], n[ii], a0[jj], a1[jj], n[jj])
    if hits.any():
        k = int(np.argmax(hits))
        return int(i[k]), int(j[k])
    return None


def _on_arc(p, a0, a1, n, tol=1e-12):
    """Is unit ``p`` (on the great circle with normal ``n``) within the arc a0→a1?"""
    return (np.sum(np.cross(a0, p) * n, axis=-1) >= -tol) & (
        np.sum(np.cross(p, a1) * n, axis=-1) >= -tol
    )


def _arcs_cross(a0, a1, na, b0, b1, nb):
    line = np.cross(na, nb)
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


def _vec_out(v: np.ndarray) -> list[float]:
    return [float(round(c, 12)) for c in v]


def _fmt_vec(v: np.ndarray) -> str:
    return "[" + ", ".join(f"{c:.3f}" for c in v) + "]"
