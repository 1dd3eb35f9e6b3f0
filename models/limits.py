"""The limits blocks of a constraint file that every swing-twist kind shares, and the
validators every kind's parser uses.

A swing region (:class:`ConeSwing`, :class:`PolygonSwing`) and a twist interval
(:class:`TwistLimits`, constant or swing-dependent through a :class:`SwingTwistTable`) make
the limits of a ball or two-axis joint; their YAML format and maths are described in
:mod:`models.constraint`. The validators (:func:`reject_unknown`, :func:`require_keys`,
:func:`label`, :func:`vector`, :func:`number`, :func:`degree_interval`) raise a
:class:`~models.errors.ConstraintError` naming the file and the field; the joint kinds of
:mod:`models.kinds` and the limb file (:mod:`models.limb`) parse with them.
"""

from __future__ import annotations

import datetime
import difflib
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from models.errors import ConstraintError, GeometryError
from models.geometry import check_polygon, polygon_area
from models.jit import njit
from models.quaternion import normalize_rows

__all__ = [
    "ConeSwing",
    "DegreeInterval",
    "PolygonSwing",
    "SwingTwistTable",
    "TwistLimits",
    "degree_interval",
    "fmt_vec",
    "label",
    "number",
    "parse_swing",
    "parse_twist",
    "plain",
    "reject_unknown",
    "require_keys",
    "table_limits_one",
    "vec_out",
    "vector",
]

#: Rows per block when evaluating the twist table on many directions (bounds the N×K temporary).
_TABLE_CHUNK = 32768

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
        return {"cone": {"centre": vec_out(self.centre), "radius_deg": float(self.radius_deg)}}

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
                "vertices": [vec_out(v) for v in self.vertices],
                "interior": vec_out(self.interior),
            }
        }

    def area_sr(self) -> float:
        """Solid angle (steradians) of the valid region."""
        return polygon_area(self.vertices, self.interior)

    def __eq__(self, other: object) -> bool:
        return (
            isinstance(other, PolygonSwing)
            and self.vertices.shape == other.vertices.shape
            and np.allclose(self.vertices, other.vertices, atol=1e-12)
            and np.allclose(self.interior, other.interior, atol=1e-12)
        )

    __hash__ = None  # type: ignore[assignment]


@njit
def table_limits_one(d0, d1, d2, dirs_k, sums, kappa):
    """Twist limits (radians) of a swing-twist table at one unit direction: the normalised
    kernel weights ``exp(κ (d·d_i − 1))`` (``dirs_k = κ d_i``) times each point's limits
    (``sums``: rows min, max and ones); if every weight underflows, shifted by the largest
    exponent instead (the normalised weights are the same)."""
    n = dirs_k.shape[0]
    z = np.empty(n)
    r0 = r1 = r2 = 0.0
    for i in range(n):
        z[i] = dirs_k[i, 0] * d0 + dirs_k[i, 1] * d1 + dirs_k[i, 2] * d2
        e = math.exp(z[i] - kappa)
        r0 += sums[0, i] * e
        r1 += sums[1, i] * e
        r2 += sums[2, i] * e
    if r2 < 1e-150:
        zmax = z.max()
        r0 = r1 = r2 = 0.0
        for i in range(n):
            e = math.exp(z[i] - zmax)
            r0 += sums[0, i] * e
            r1 += sums[1, i] * e
            r2 += sums[2, i] * e
    return r0 / r2, r1 / r2


@dataclass(frozen=True, eq=False)
class SwingTwistTable:
    """Twist limits tabulated over swing directions, interpolated by a Gaussian kernel on S².

    Attributes
    ----------
    bandwidth_deg : float, in (0, 180)
        Kernel width ``β``; ``κ = 1 / (1 − cos β)``.
    directions : (K, 3) float64, unit, parent frame
        Limb directions ``d_i`` at which the limits are given.
    min_deg, max_deg : (K,) float64, degrees
        Twist interval at each direction, ``-180 <= min_deg[i] <= max_deg[i] <= 180``.
    """

    bandwidth_deg: float
    directions: np.ndarray
    min_deg: np.ndarray
    max_deg: np.ndarray

    def __post_init__(self) -> None:
        d = np.array(self.directions, dtype=np.float64).reshape(-1, 3)
        lo = np.array(self.min_deg, dtype=np.float64).reshape(-1)
        hi = np.array(self.max_deg, dtype=np.float64).reshape(-1)
        if not (len(d) == len(lo) == len(hi) >= 1):
            raise ConstraintError(
                f"directions, min_deg and max_deg need the same length >= 1, got "
                f"{len(d)}, {len(lo)}, {len(hi)}",
                "twist.by_swing.points",
            )
        # the file parser names the offending point; these guard construction in code
        n = np.linalg.norm(d, axis=1)
        if not (np.isfinite(d).all() and (n > 1e-12).all()):
            raise ConstraintError("directions must be finite and non-zero", "twist.by_swing.points")
        if not (np.isfinite(lo).all() and np.isfinite(hi).all()):
            raise ConstraintError("limits must be finite", "twist.by_swing.points")
        if (lo > hi).any() or lo.min() < -180.0 or hi.max() > 180.0:
            raise ConstraintError(
                "needs -180 <= min_deg <= max_deg <= 180 at every point", "twist.by_swing.points"
            )
        if not 0.0 < float(self.bandwidth_deg) < 180.0:
            raise ConstraintError(
                f"must be in (0, 180) degrees, got {self.bandwidth_deg}",
                "twist.by_swing.bandwidth_deg",
            )
        d = d / n[:, None]
        for a in (d, lo, hi):
            a.setflags(write=False)
        object.__setattr__(self, "directions", d)
        object.__setattr__(self, "min_deg", lo)
        object.__setattr__(self, "max_deg", hi)
        half = math.radians(self.bandwidth_deg) / 2.0
        object.__setattr__(self, "kappa", 1.0 / (2.0 * math.sin(half) ** 2))  # 1/(1 - cos β)
        # (3, K): radians min, max, and ones — one product gives Σw·min, Σw·max and Σw
        tab = np.stack((np.radians(lo), np.radians(hi), np.ones(len(lo))))
        object.__setattr__(self, "_sums", np.ascontiguousarray(tab))
        object.__setattr__(self, "_sums_t", np.ascontiguousarray(tab.T))
        object.__setattr__(self, "_dirs_k", np.ascontiguousarray(d * self.kappa))

    kappa: float = field(init=False, repr=False)

    def weights(self, directions) -> np.ndarray:
        """Normalised kernel weights ``w / Σw`` (N, K) at limb directions (N, 3), unit."""
        d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
        e = self._exponents(d)
        return e / e.sum(axis=1, keepdims=True)

    def _exponents(self, d: np.ndarray) -> np.ndarray:
        # κ(d·d_i − 1) ≤ 0; if every weight underflows (narrow kernel, far from all points)
        # shift by the row maximum instead — the normalised weights are the same
        z = d @ self._dirs_k.T - self.kappa
        w = np.exp(z)
        small = w.max(axis=1) < 1e-150
        if small.any():
            zs = z[small]
            w[small] = np.exp(zs - zs.max(axis=1, keepdims=True))
        return w

    def limits_at(self, directions) -> tuple[np.ndarray, np.ndarray]:
        """Twist limits (radians) at limb directions.

        Parameters
        ----------
        directions : (N, 3) or (3,) float64, unit, parent frame

        Returns
        -------
        lo, hi : (N,) float64 (or floats for one direction), radians
        """
        d = np.asarray(directions, dtype=np.float64)
        single = d.ndim == 1
        d = d.reshape(-1, 3)
        n = len(d)
        lo = np.empty(n)
        hi = np.empty(n)
        for s in range(0, n, _TABLE_CHUNK):
            w = self._exponents(d[s : s + _TABLE_CHUNK])
            r = w @ self._sums_t  # (n, 3): Σw·min, Σw·max, Σw
            lo[s : s + _TABLE_CHUNK] = r[:, 0] / r[:, 2]
            hi[s : s + _TABLE_CHUNK] = r[:, 1] / r[:, 2]
        if single:
            return float(lo[0]), float(hi[0])
        return lo, hi

    def limits_at_one(self, d: tuple[float, float, float]) -> tuple[float, float]:
        """Scalar twin of :meth:`limits_at` for one unit direction (the control loop's path,
        compiled: :func:`table_limits_one`, which the oracle's kernel calls too)."""
        return table_limits_one(float(d[0]), float(d[1]), float(d[2]), self._dirs_k,
                                 self._sums, self.kappa)

    def to_dict(self) -> dict[str, Any]:
        return {
            "bandwidth_deg": float(self.bandwidth_deg),
            "points": [
                {"direction": vec_out(d), "min_deg": float(a), "max_deg": float(b)}
                for d, a, b in zip(self.directions, self.min_deg, self.max_deg, strict=True)
            ],
        }

    def __eq__(self, other: object) -> bool:
        return (
            isinstance(other, SwingTwistTable)
            and math.isclose(self.bandwidth_deg, other.bandwidth_deg, abs_tol=1e-12)
            and self.directions.shape == other.directions.shape
            and np.allclose(self.directions, other.directions, atol=1e-12)
            and np.allclose(self.min_deg, other.min_deg, atol=1e-12)
            and np.allclose(self.max_deg, other.max_deg, atol=1e-12)
        )

    __hash__ = None  # type: ignore[assignment]


class DegreeInterval:
    """``min`` / ``max`` in radians of a class's ``min_deg`` / ``max_deg`` (a twist envelope, a
    hinge interval, any kind's angle interval)."""

    min_deg: float
    max_deg: float

    @property
    def min(self) -> float:
        """Lower limit, radians."""
        return math.radians(self.min_deg)

    @property
    def max(self) -> float:
        """Upper limit, radians."""
        return math.radians(self.max_deg)

    def same_interval(self, other: DegreeInterval) -> bool:
        """Same ``min_deg`` and ``max_deg`` (to 1e-12 degrees)."""
        return (math.isclose(self.min_deg, other.min_deg, abs_tol=1e-12)
                and math.isclose(self.max_deg, other.max_deg, abs_tol=1e-12))


@dataclass(frozen=True, eq=False)
class TwistLimits(DegreeInterval):
    """Twist interval about the limb axis, degrees, ``-180 <= min_deg <= max_deg <= 180``.

    Attributes
    ----------
    min_deg, max_deg : float, degrees
        The interval; with ``by_swing`` the envelope that contains every tabulated interval.
    by_swing : SwingTwistTable or None
        Swing-dependent limits; None = the constant interval everywhere.
    """

    min_deg: float
    max_deg: float
    by_swing: SwingTwistTable | None = None

    def limits_at(self, directions) -> tuple[np.ndarray, np.ndarray]:
        """Twist limits (radians) at limb directions (N, 3) (unit, parent frame) → (N,), (N,).

        The constant interval when there is no ``by_swing`` table.
        """
        if self.by_swing is not None:
            return self.by_swing.limits_at(directions)
        d = np.asarray(directions, dtype=np.float64)
        if d.ndim == 1:
            return self.min, self.max
        n = len(d.reshape(-1, 3))
        return np.full(n, self.min), np.full(n, self.max)

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"min_deg": float(self.min_deg), "max_deg": float(self.max_deg)}
        if self.by_swing is not None:
            out["by_swing"] = self.by_swing.to_dict()
        return out

    def __eq__(self, other: object) -> bool:
        return (
            isinstance(other, TwistLimits)
            and self.same_interval(other)
            and self.by_swing == other.by_swing
        )

    __hash__ = None  # type: ignore[assignment]




# -- validation helpers (every kind's parser uses them) ------------------------------
def reject_unknown(
    body: dict, allowed: tuple[str, ...], where: str | None, source: str | None
) -> None:
    """Raise naming the first key of ``body`` not in ``allowed`` (with a spelling hint)."""
    for key in body:
        if key in allowed:
            continue
        path = f"{where}.{key}" if where else str(key)
        close = difflib.get_close_matches(str(key), allowed, n=1, cutoff=0.6)
        hint = f" (did you mean '{close[0]}'?)" if close else ""
        if key == "source" and where is None:
            hint = " (provenance now goes under 'provenance:')"
        raise ConstraintError(
            f"unknown key '{key}'{hint}; allowed here: {', '.join(allowed)}", path, source
        )


def require_keys(
    body: dict,
    keys: tuple[str, ...],
    where: str,
    source: str | None,
    optional: tuple[str, ...] = (),
) -> None:
    """Raise unless ``body`` has every key of ``keys`` and no key outside ``keys + optional``."""
    reject_unknown(body, keys + optional, where, source)
    for k in keys:
        if k not in body:
            raise ConstraintError(f"missing '{k}'", where, source)


def label(value: Any, field_name: str, source: str | None) -> str | None:
    """A short single-line text (a name, side or pseudonym) or None; raise naming the field."""
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, (str, int)):
        raise ConstraintError(f"expected a short text, got {value!r}", field_name, source)
    text = str(value).strip()
    if not text or "\n" in text:
        raise ConstraintError("must be a non-empty single-line text", field_name, source)
    return text


def vector(value: Any, field_name: str, source: str | None) -> np.ndarray:
    """A finite non-zero 3-vector from the file, normalised to unit length, (3,) float64."""
    if not isinstance(value, (list, tuple)) or len(value) != 3:
        raise ConstraintError(f"expected a 3-vector [x, y, z], got {value!r}", field_name, source)
    try:
        v = np.array([float(c) for c in value])
    except (TypeError, ValueError) as err:
        raise ConstraintError(f"expected numbers, got {value!r}", field_name, source) from err
    if not np.isfinite(v).all():
        raise ConstraintError(f"has a NaN or infinite component: {value!r}", field_name, source)
    unit, n = normalize_rows(v[None, :])  # [0, 0, 1e308] keeps its direction (its square overflows)
    if n[0] < 1e-12:
        raise ConstraintError("is a zero vector and has no direction", field_name, source)
    return unit[0]


def number(value: Any, field_name: str, source: str | None) -> float:
    """A finite number from the file (not a bool), as a float."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ConstraintError(f"expected a number, got {value!r}", field_name, source)
    x = float(value)
    if not math.isfinite(x):
        raise ConstraintError(f"must be finite, got {value!r}", field_name, source)
    return x


def parse_swing(value: Any, source: str | None) -> ConeSwing | PolygonSwing | None:
    """The ``swing:`` block (a cone or a polygon), None when absent."""
    if value is None:
        return None
    expected = (
        "expected exactly one of 'cone: {centre, radius_deg}' or 'polygon: {vertices, interior}'"
    )
    if not isinstance(value, dict):
        raise ConstraintError(f"{expected}, got {value!r}", "swing", source)
    reject_unknown(value, ("cone", "polygon"), "swing", source)
    if len(value) != 1:
        raise ConstraintError(expected, "swing", source)
    kind, body = next(iter(value.items()))
    if not isinstance(body, dict):
        raise ConstraintError(f"expected a mapping, got {body!r}", f"swing.{kind}", source)
    if kind == "cone":
        require_keys(body, ("centre", "radius_deg"), "swing.cone", source)
        centre = vector(body["centre"], "swing.cone.centre", source)
        radius = number(body["radius_deg"], "swing.cone.radius_deg", source)
        if not 0.0 < radius < 180.0:
            raise ConstraintError(
                f"must be in (0, 180) degrees, got {radius:g}", "swing.cone.radius_deg", source
            )
        return ConeSwing(centre=centre, radius_deg=radius)
    require_keys(body, ("vertices", "interior"), "swing.polygon", source)
    raw = body["vertices"]
    if not isinstance(raw, (list, tuple)) or len(raw) < 3:
        raise ConstraintError(
            "expected a list of at least 3 [x, y, z] vertices", "swing.polygon.vertices", source
        )
    verts = np.stack(
        [vector(v, f"swing.polygon.vertices[{i}]", source) for i, v in enumerate(raw)]
    )
    interior = vector(body["interior"], "swing.polygon.interior", source)
    _check_polygon(verts, interior, source)
    return PolygonSwing(vertices=verts, interior=interior)


def degree_interval(body: dict, where: str, source: str | None) -> tuple[float, float]:
    """``(min_deg, max_deg)`` of a block: each in [-180, 180] degrees, ``min <= max``."""
    lo = number(body["min_deg"], f"{where}.min_deg", source)
    hi = number(body["max_deg"], f"{where}.max_deg", source)
    for v, f in ((lo, f"{where}.min_deg"), (hi, f"{where}.max_deg")):
        if not -180.0 <= v <= 180.0:
            raise ConstraintError(f"must be within [-180, 180] degrees, got {v:g}", f, source)
    if lo > hi:
        raise ConstraintError(f"min_deg ({lo:g}) is greater than max_deg ({hi:g})", where, source)
    return lo, hi



def parse_twist(value: Any, source: str | None) -> TwistLimits | None:
    """The ``twist:`` block (an interval, optionally ``by_swing``), None when absent."""
    if value is None:
        return None
    if not isinstance(value, dict):
        raise ConstraintError(f"expected {{min_deg, max_deg}}, got {value!r}", "twist", source)
    require_keys(value, ("min_deg", "max_deg"), "twist", source, optional=("by_swing",))
    lo, hi = degree_interval(value, "twist", source)
    table = None
    if value.get("by_swing") is not None:
        table = _parse_by_swing(value["by_swing"], lo, hi, source)
    return TwistLimits(min_deg=lo, max_deg=hi, by_swing=table)


def _parse_by_swing(value: Any, env_lo: float, env_hi: float, source: str | None):
    where = "twist.by_swing"
    if not isinstance(value, dict):
        raise ConstraintError(
            f"expected {{bandwidth_deg, points: [...]}}, got {value!r}", where, source
        )
    require_keys(value, ("bandwidth_deg", "points"), where, source)
    bw = number(value["bandwidth_deg"], f"{where}.bandwidth_deg", source)
    if not 0.0 < bw < 180.0:
        raise ConstraintError(
            f"must be in (0, 180) degrees, got {bw:g}", f"{where}.bandwidth_deg", source
        )
    points = value["points"]
    if not isinstance(points, (list, tuple)) or not points:
        raise ConstraintError(
            "expected a non-empty list of {direction, min_deg, max_deg}", f"{where}.points", source
        )
    dirs, los, his = [], [], []
    for i, p in enumerate(points):
        pw = f"{where}.points[{i}]"
        if not isinstance(p, dict):
            raise ConstraintError(
                f"expected {{direction, min_deg, max_deg}}, got {p!r}", pw, source
            )
        require_keys(p, ("direction", "min_deg", "max_deg"), pw, source)
        dirs.append(vector(p["direction"], f"{pw}.direction", source))
        lo, hi = degree_interval(p, pw, source)
        if lo < env_lo or hi > env_hi:
            raise ConstraintError(
                f"interval {lo:g} .. {hi:g} deg lies outside the envelope twist.min_deg .. "
                f"twist.max_deg ({env_lo:g} .. {env_hi:g} deg); widen the envelope",
                pw,
                source,
            )
        los.append(lo)
        his.append(hi)
    return SwingTwistTable(
        bandwidth_deg=bw, directions=np.stack(dirs), min_deg=np.array(los), max_deg=np.array(his)
    )


def _check_polygon(verts: np.ndarray, interior: np.ndarray, source: str | None) -> None:
    """Reject degenerate and self-intersecting spherical polygons (:mod:`models.geometry`)."""
    try:
        check_polygon(verts, interior)
    except GeometryError as err:
        raise ConstraintError(str(err), f"swing.polygon.{err.part}", source) from err


def plain(value: Any, where: str) -> Any:
    """``value`` as plain YAML-safe Python (numpy scalars and arrays, tuples converted)."""
    if isinstance(value, dict):
        return {str(k): plain(v, f"{where}.{k}") for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [plain(v, f"{where}[{i}]") for i, v in enumerate(value)]
    if isinstance(value, np.ndarray):
        return plain(value.tolist(), where)
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, Path):
        return str(value)
    if value is None or isinstance(value, (str, bool, int, float)):
        return value
    if isinstance(value, (datetime.date, datetime.datetime)):
        return value
    raise ConstraintError(f"cannot be written as YAML: {type(value).__name__}", where)


def vec_out(v: np.ndarray) -> list[float]:
    """A unit vector as the file writes it (plain floats rounded to 12 decimals)."""
    return [float(round(c, 12)) for c in v]


def fmt_vec(v: np.ndarray) -> str:
    """A vector for a summary line, three decimals."""
    return "[" + ", ".join(f"{c:.3f}" for c in v) + "]"


