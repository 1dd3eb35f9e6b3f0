"""Joint-constraint definitions and their YAML file format.

A joint constraint limits the orientation ``q`` of a limb relative to its reference segment,
split by swing-twist about the limb axis (``q = swing ⊗ twist``, see :mod:`models.quaternion`):

- the **swing** limit is a region of the unit sphere S² that the limb direction
  ``d = rotate(q, limb_axis)`` must stay in: a *cone* (centre, radius — the thesis's "regular
  boundary") or a spherical *polygon* whose edges are great-circle arcs (the thesis's "irregular
  boundary"; concave allowed; geometry in :mod:`models.geometry`);
- the **twist** limit is an interval of the twist angle about the limb axis — constant, or
  depending smoothly on the swing direction (``by_swing``, below).

File format (YAML, read with :func:`models.yamlio.safe_load_yaml`: safe, no anchors or
aliases; full reference in ``docs/constraint-format.md``)::

    name: right-shoulder-example
    limb_axis: [1, 0, 0]                         # optional, default +X
    joint: shoulder                              # optional binding: joint name,
    side: right                                  #   side (left | right),
    patient: P-007                               #   patient pseudonym (never a real name)
    swing:
      cone: {centre: [1, 0, 0], radius_deg: 45}  # a regular boundary, or:
      # polygon: {vertices: [[x, y, z], ...], interior: [x, y, z]}   # irregular; concave allowed
    twist:                                       # optional; absent = unconstrained
      min_deg: -60                               # the envelope (and fallback)
      max_deg: 60
      by_swing:                                  # optional swing-dependent limits
        bandwidth_deg: 20
        points:
          - {direction: [1, 0, 0], min_deg: -50, max_deg: 40}
          - {direction: [0, 1, 0], min_deg: -20, max_deg: 60}
    provenance: {session: 12, recorded: 2026-11-21}   # optional, free-form, kept verbatim

Unknown keys are errors at every level (a misspelt ``twsit:`` must not silently drop a limit);
only ``provenance`` is free-form. Vectors need not be unit length in the file; they are
normalised on load. Polygon vertices are listed in order along the boundary, either direction;
``interior`` is any point strictly inside, which tells which of the two regions the polygon
bounds (a polygon may enclose more than a hemisphere). A polygon must be simple: no repeated
consecutive vertices, no antipodal neighbours, no crossing or overlapping edges, not all on one
great circle.

Swing-dependent twist (``by_swing``)
------------------------------------
The limits at a limb direction ``d`` (unit, parent frame) are Gaussian-kernel (von Mises-Fisher)
weighted means of the tabulated limits at directions ``d_i``::

    w_i = exp(κ (d·d_i − 1)),   κ = 1 / (1 − cos β)   (β = bandwidth_deg)
    min(d) = Σ w_i min_i / Σ w_i,   max(d) = Σ w_i max_i / Σ w_i

i.e. ``w / Σw = softmax(κ d·d_i)``: smooth in ``d``, everywhere defined, and exactly
reproducible in an ONNX graph (MatMul, Softmax, MatMul). ``min_deg``/``max_deg`` are the
envelope: every point's interval must lie within it, so the interpolated interval does too.
The oracle clamps the twist to the limits at the *corrected* swing direction.

Every validation error is a :class:`~models.errors.ConstraintError` that names the file and the
field.
"""

from __future__ import annotations

import datetime
import difflib
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from models.errors import ConstraintError, GeometryError
from models.fileio import write_owner_only
from models.geometry import check_polygon, polygon_area
from models.jit import njit
from models.quaternion import LIMB_AXIS, normalize_rows
from models.yamlio import safe_dump_yaml, safe_load_yaml

__all__ = [
    "KINDS",
    "SIDES",
    "TWO_AXIS_MAX_TWIST_DEG",
    "ConeSwing",
    "HingeLimits",
    "JointConstraint",
    "PolygonSwing",
    "SwingTwistTable",
    "TwistLimits",
    "dump_constraint",
    "load_constraint",
    "loads_constraint",
]

#: Accepted values of ``side``.
SIDES = ("left", "right")

#: Top-level keys of a constraint file.
_TOP_KEYS = ("name", "kind", "limb_axis", "joint", "side", "patient", "swing", "twist", "hinge",
             "provenance")

#: Joint kinds (``kind:``): a ball joint (swing region + twist), a hinge (one axis, an angle
#: interval) and a two-axis joint (a swing region with a fixed or narrow twist).
KINDS = ("ball", "hinge", "two-axis")

#: Widest twist interval of a ``two-axis`` joint, degrees (wider: it is a ball joint).
TWO_AXIS_MAX_TWIST_DEG = 30.0

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
def _table_limits_one(d0, d1, d2, dirs_k, sums, kappa):
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
        compiled: :func:`_table_limits_one`, which the oracle's kernel calls too)."""
        return _table_limits_one(float(d[0]), float(d[1]), float(d[2]), self._dirs_k,
                                 self._sums, self.kappa)

    def to_dict(self) -> dict[str, Any]:
        return {
            "bandwidth_deg": float(self.bandwidth_deg),
            "points": [
                {"direction": _vec_out(d), "min_deg": float(a), "max_deg": float(b)}
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


class _DegreeInterval:
    """``min`` / ``max`` in radians of a class's ``min_deg`` / ``max_deg`` (twist envelope,
    hinge interval)."""

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

    def _same_interval(self, other: _DegreeInterval) -> bool:
        return (math.isclose(self.min_deg, other.min_deg, abs_tol=1e-12)
                and math.isclose(self.max_deg, other.max_deg, abs_tol=1e-12))


@dataclass(frozen=True, eq=False)
class TwistLimits(_DegreeInterval):
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
            and self._same_interval(other)
            and self.by_swing == other.by_swing
        )

    __hash__ = None  # type: ignore[assignment]


@dataclass(frozen=True, eq=False)
class HingeLimits(_DegreeInterval):
    """A hinge: the joint's allowed orientations are the rotations ``axis_angle(axis, θ)`` with
    ``min_deg <= θ <= max_deg`` (degrees, ``-180 <= min_deg <= max_deg <= 180``), about a unit
    ``axis`` of the parent frame (the child's frame coincides with the parent's at 0)."""

    axis: np.ndarray
    min_deg: float
    max_deg: float

    def to_dict(self) -> dict[str, Any]:
        return {"axis": _vec_out(self.axis), "min_deg": float(self.min_deg),
                "max_deg": float(self.max_deg)}

    def __eq__(self, other: object) -> bool:
        return (
            isinstance(other, HingeLimits)
            and np.allclose(self.axis, other.axis, atol=1e-12)
            and self._same_interval(other)
        )

    __hash__ = None  # type: ignore[assignment]


@dataclass(frozen=True, eq=False)
class JointConstraint:
    """A swing region and an optional twist interval for one joint.

    Use :func:`load_constraint` to read one from a file, :meth:`from_dict` for a parsed mapping,
    or the :meth:`cone` / :meth:`polygon` shortcuts in code.

    Attributes
    ----------
    name : str
    swing : ConeSwing, PolygonSwing or None (unconstrained)
    twist : TwistLimits or None (unconstrained)
    limb_axis : (3,) float64, unit, limb frame
    joint, side, patient : str or None
        What the constraint is bound to: joint name (``shoulder``), side (``left``/``right``),
        patient pseudonym. Models trained on it carry them (see :mod:`models.onnx_io`).
    provenance : dict
        Free-form record of where the boundary came from (session or file, parameters, sample
        count), kept verbatim.
    kind : {"ball", "hinge", "two-axis"}
        :data:`KINDS`; ``ball`` when the file says nothing.
    hinge : HingeLimits or None
        The limits of a ``hinge`` (its ``swing`` and ``twist`` are None).
    """

    name: str
    swing: ConeSwing | PolygonSwing | None
    twist: TwistLimits | None = None
    limb_axis: np.ndarray = field(default_factory=lambda: LIMB_AXIS.copy())
    joint: str | None = None
    side: str | None = None
    patient: str | None = None
    provenance: dict[str, Any] = field(default_factory=dict)
    kind: str = "ball"
    hinge: HingeLimits | None = None

    # -- construction ---------------------------------------------------------------------
    @classmethod
    def hinge_joint(
        cls,
        axis=(0.0, 0.0, 1.0),
        min_deg: float = 0.0,
        max_deg: float = 140.0,
        *,
        name: str = "hinge",
        limb_axis=(1.0, 0.0, 0.0),
        **binding: Any,
    ) -> JointConstraint:
        """A hinge (``binding`` as in :meth:`cone`)."""
        d: dict[str, Any] = {"name": name, "kind": "hinge", "limb_axis": list(limb_axis),
                             "hinge": {"axis": list(axis), "min_deg": min_deg,
                                       "max_deg": max_deg}}
        d.update({k: v for k, v in binding.items() if v is not None})
        return cls.from_dict(_plain(d, "constraint"))

    @classmethod
    def cone(
        cls,
        centre=(1.0, 0.0, 0.0),
        radius_deg: float = 45.0,
        *,
        twist=None,
        name: str = "cone",
        limb_axis=(1.0, 0.0, 0.0),
        **binding: Any,
    ) -> JointConstraint:
        """A cone swing limit.

        ``twist`` is ``(min_deg, max_deg)``, a ``twist:`` mapping (with ``by_swing``) or a
        :class:`TwistLimits`; ``binding`` takes ``joint``, ``side``, ``patient``,
        ``provenance``.
        """
        swing = {"cone": {"centre": list(centre), "radius_deg": radius_deg}}
        return cls._build(swing, twist, name, limb_axis, binding)

    @classmethod
    def polygon(
        cls,
        vertices,
        interior,
        *,
        twist=None,
        name: str = "polygon",
        limb_axis=(1.0, 0.0, 0.0),
        **binding: Any,
    ) -> JointConstraint:
        """A polygon swing limit (``twist`` and ``binding`` as in :meth:`cone`)."""
        swing = {
            "polygon": {
                "vertices": np.asarray(vertices, dtype=float).tolist(),
                "interior": list(np.asarray(interior, dtype=float)),
            }
        }
        return cls._build(swing, twist, name, limb_axis, binding)

    @classmethod
    def _build(cls, swing, twist, name: str, limb_axis, binding: dict) -> JointConstraint:
        d: dict[str, Any] = {"name": name, "limb_axis": list(limb_axis), "swing": swing}
        if swing is None:
            del d["swing"]
        if isinstance(twist, TwistLimits):
            d["twist"] = twist.to_dict()
        elif isinstance(twist, dict):
            d["twist"] = twist
        elif twist is not None:
            d["twist"] = {"min_deg": twist[0], "max_deg": twist[1]}
        d.update({k: v for k, v in binding.items() if v is not None})
        return cls.from_dict(_plain(d, "constraint"))

    @classmethod
    def from_dict(cls, data: Any, source: str | None = None) -> JointConstraint:
        """Validate a parsed mapping (see the module docstring for the schema)."""
        if not isinstance(data, dict):
            raise ConstraintError(
                f"expected a mapping with 'name' and 'swing', got {type(data).__name__}",
                source=source,
            )
        if "joints" in data:  # a limb file (models.limb.is_limb_file) given for one joint
            joints = data.get("joints")
            names = ", ".join(str(j.get("name")) for j in joints if isinstance(j, dict)) \
                if isinstance(joints, list) else ""
            raise ConstraintError(
                f"a limb file ({names or 'a list of joints'}), not one joint's constraint file: "
                "give the constraint of a single joint here", source=source)
        _reject_unknown(data, _TOP_KEYS, None, source)
        name = data.get("name", "unnamed")
        if not isinstance(name, str) or not name.strip():
            raise ConstraintError("must be a non-empty string", "name", source)
        limb_axis = _vector(data.get("limb_axis", [1, 0, 0]), "limb_axis", source)
        joint = _label(data.get("joint"), "joint", source)
        side = _label(data.get("side"), "side", source)
        if side is not None:
            side = side.lower()
            if side not in SIDES:
                raise ConstraintError(
                    f"must be one of {', '.join(SIDES)}, got {data['side']!r}", "side", source
                )
        patient = _label(data.get("patient"), "patient", source)
        provenance = data.get("provenance", {})
        if provenance is None:
            provenance = {}
        if not isinstance(provenance, dict):
            raise ConstraintError(
                f"expected a mapping (free-form), got {provenance!r}", "provenance", source
            )
        kind = data.get("kind", "ball")
        if kind not in KINDS:
            raise ConstraintError(f"must be one of {', '.join(KINDS)}, got {kind!r}", "kind",
                                  source)
        hinge = None
        if kind == "hinge":
            for key in ("swing", "twist"):
                if data.get(key) is not None:
                    raise ConstraintError(
                        "a hinge has no swing or twist limits (its 'hinge' axis and interval "
                        "are the whole limit)", key, source)
            hinge = _parse_hinge(data.get("hinge"), source)
            swing = twist = None
        else:
            if data.get("hinge") is not None:
                raise ConstraintError(f"only 'kind: hinge' takes a hinge (this is kind {kind})",
                                      "hinge", source)
            swing = _parse_swing(data.get("swing"), source)
            twist = _parse_twist(data.get("twist"), source)
            if swing is None and twist is None:
                raise ConstraintError(
                    "a constraint needs a 'swing' limit, a 'twist' limit, or both",
                    source=source
                )
        if kind == "two-axis":
            if swing is None or twist is None:
                raise ConstraintError("a two-axis joint needs a 'swing' region and a (fixed or "
                                      "narrow) 'twist' interval", source=source)
            width = twist.max_deg - twist.min_deg
            if width > TWO_AXIS_MAX_TWIST_DEG:
                raise ConstraintError(
                    f"a two-axis joint's twist interval is at most "
                    f"{TWO_AXIS_MAX_TWIST_DEG:g} degrees wide, got {width:g} (a wider twist "
                    f"is a ball joint: kind: ball)", "twist", source)
        return cls(
            name=name,
            swing=swing,
            twist=twist,
            limb_axis=limb_axis,
            joint=joint,
            side=side,
            patient=patient,
            provenance=dict(provenance),
            kind=kind,
            hinge=hinge,
        )

    # -- queries --------------------------------------------------------------------------
    def require_kind(self, what: str, kinds: tuple[str, ...] = ("ball", "two-axis")) -> None:
        """Raise :class:`ConstraintError` unless this joint's kind is one of ``kinds`` (what a
        tool built for swing-twist joints says of a hinge, whose exact oracle exists but whose
        learned models and simulated patients do not yet)."""
        if self.kind not in kinds:
            raise ConstraintError(f"{what} handles {' and '.join(kinds)} joints; "
                                  f"{self.name!r} is a {self.kind} joint", "kind")

    def twist_limits_at(self, directions) -> tuple[np.ndarray, np.ndarray]:
        """Twist limits (radians) at limb directions; ``(-π, π)`` when twist is unconstrained.

        Parameters
        ----------
        directions : (N, 3) or (3,) float64, unit, parent frame

        Returns
        -------
        lo, hi : (N,) float64 radians (floats for a single direction)
        """
        if self.twist is not None:
            return self.twist.limits_at(directions)
        d = np.asarray(directions, dtype=np.float64)
        if d.ndim == 1:
            return -math.pi, math.pi
        n = len(d.reshape(-1, 3))
        return np.full(n, -math.pi), np.full(n, math.pi)

    # -- output ---------------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"name": self.name}
        if self.kind != "ball":  # a ball joint's file stays as it always was
            out["kind"] = self.kind
        out["limb_axis"] = _vec_out(self.limb_axis)
        for key in ("joint", "side", "patient"):
            if getattr(self, key) is not None:
                out[key] = getattr(self, key)
        if self.swing is not None:
            out["swing"] = self.swing.to_dict()
        if self.twist is not None:
            out["twist"] = self.twist.to_dict()
        if self.hinge is not None:
            out["hinge"] = self.hinge.to_dict()
        if self.provenance:
            out["provenance"] = _plain(self.provenance, "provenance")
        return out

    def to_yaml(self) -> str:
        """The constraint as YAML text that :func:`loads_constraint` reads back identically."""
        return safe_dump_yaml(self.to_dict(), sort_keys=False, default_flow_style=None)

    def __eq__(self, other: object) -> bool:
        """Same limits (name, binding and provenance are ignored)."""
        return (
            isinstance(other, JointConstraint)
            and self.kind == other.kind
            and self.swing == other.swing
            and self.twist == other.twist
            and self.hinge == other.hinge
            and np.allclose(self.limb_axis, other.limb_axis, atol=1e-12)
        )

    __hash__ = None  # type: ignore[assignment]

    def summary(self) -> str:
        """A few human-readable lines describing the limits."""
        lines = [f"constraint {self.name!r}", f"  limb axis   {_fmt_vec(self.limb_axis)}"]
        bound = [
            f"{k} {getattr(self, k)}" for k in ("joint", "side", "patient") if getattr(self, k)
        ]
        if bound:
            lines.append(f"  bound to    {', '.join(bound)}")
        if self.hinge is not None:
            h = self.hinge
            lines.append(f"  kind        hinge, axis {_fmt_vec(h.axis)}, "
                         f"{h.min_deg:g} .. {h.max_deg:g} deg")
            if self.provenance:
                lines.append(f"  provenance  {_fmt_provenance(self.provenance)}")
            return "\n".join(lines)
        if self.kind != "ball":
            lines.append(f"  kind        {self.kind}")
        if isinstance(self.swing, ConeSwing):
            lines.append(
                f"  swing       cone, centre {_fmt_vec(self.swing.centre)}, "
                f"radius {self.swing.radius_deg:g} deg"
            )
        elif isinstance(self.swing, PolygonSwing):
            area = self.swing.area_sr()
            lines.append(
                f"  swing       polygon, {len(self.swing.vertices)} vertices, "
                f"interior {_fmt_vec(self.swing.interior)}, "
                f"area {area:.4f} sr ({100 * area / (4 * math.pi):.1f} % of the sphere)"
            )
        else:
            lines.append("  swing       unconstrained")
        if self.twist is not None:
            tw = self.twist
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
        if self.provenance:
            lines.append(f"  provenance  {_fmt_provenance(self.provenance)}")
        return "\n".join(lines)


# -- file I/O ---------------------------------------------------------------------------------
def parse_yaml(text: str, source: str | None = None) -> Any:
    """YAML text of a constraint or limb file → plain data (:class:`ConstraintError` naming
    the line when it is not YAML)."""
    try:
        return safe_load_yaml(text)
    except yaml.YAMLError as err:
        mark = getattr(err, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        problem = getattr(err, "problem", None) or "malformed YAML"
        raise ConstraintError(f"not valid YAML{where}: {problem}", source=source) from err


def read_text(path: str | Path, what: str = "a constraint file") -> str:
    """A constraint or limb file's text (:class:`ConstraintError` naming the file when it is
    missing, a folder or unreadable)."""
    path = Path(path)
    try:
        return path.read_text(encoding="utf-8")
    except FileNotFoundError as err:
        raise ConstraintError("file not found", source=str(path)) from err
    except IsADirectoryError as err:
        raise ConstraintError(f"is a directory, not {what}", source=str(path)) from err
    except (OSError, UnicodeDecodeError) as err:
        raise ConstraintError(f"cannot read: {err}", source=str(path)) from err


def loads_constraint(text: str, source: str | None = None) -> JointConstraint:
    """Parse constraint YAML text (``source`` names it in error messages)."""
    return JointConstraint.from_dict(parse_yaml(text, source), source=source)


def load_constraint(path: str | Path) -> JointConstraint:
    """Read and validate a constraint file.

    Raises
    ------
    ConstraintError
        The file is missing, unreadable, not YAML, or fails validation (the message names the
        file and the field).
    """
    return loads_constraint(read_text(path), source=str(path))


def dump_constraint(constraint: JointConstraint, path: str | Path) -> None:
    """Write a constraint file atomically (a partial file never replaces a good one) and
    owner-only (it may name a patient: :func:`models.fileio.write_owner_only`)."""
    write_owner_only(Path(path), constraint.to_yaml())


# -- validation helpers -----------------------------------------------------------------------
def _reject_unknown(
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


def _require(
    body: dict,
    keys: tuple[str, ...],
    where: str,
    source: str | None,
    optional: tuple[str, ...] = (),
) -> None:
    _reject_unknown(body, keys + optional, where, source)
    for k in keys:
        if k not in body:
            raise ConstraintError(f"missing '{k}'", where, source)


def _label(value: Any, field_name: str, source: str | None) -> str | None:
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, (str, int)):
        raise ConstraintError(f"expected a short text, got {value!r}", field_name, source)
    text = str(value).strip()
    if not text or "\n" in text:
        raise ConstraintError("must be a non-empty single-line text", field_name, source)
    return text


def _vector(value: Any, field_name: str, source: str | None) -> np.ndarray:
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
    expected = (
        "expected exactly one of 'cone: {centre, radius_deg}' or 'polygon: {vertices, interior}'"
    )
    if not isinstance(value, dict):
        raise ConstraintError(f"{expected}, got {value!r}", "swing", source)
    _reject_unknown(value, ("cone", "polygon"), "swing", source)
    if len(value) != 1:
        raise ConstraintError(expected, "swing", source)
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


def _twist_interval(body: dict, where: str, source: str | None) -> tuple[float, float]:
    lo = _number(body["min_deg"], f"{where}.min_deg", source)
    hi = _number(body["max_deg"], f"{where}.max_deg", source)
    for v, f in ((lo, f"{where}.min_deg"), (hi, f"{where}.max_deg")):
        if not -180.0 <= v <= 180.0:
            raise ConstraintError(f"must be within [-180, 180] degrees, got {v:g}", f, source)
    if lo > hi:
        raise ConstraintError(f"min_deg ({lo:g}) is greater than max_deg ({hi:g})", where, source)
    return lo, hi


def _parse_hinge(value: Any, source: str | None) -> HingeLimits:
    if not isinstance(value, dict):
        raise ConstraintError(f"expected {{axis, min_deg, max_deg}}, got {value!r}", "hinge",
                              source)
    _require(value, ("axis", "min_deg", "max_deg"), "hinge", source)
    axis = _vector(value["axis"], "hinge.axis", source)
    lo, hi = _twist_interval(value, "hinge", source)
    return HingeLimits(axis=axis, min_deg=lo, max_deg=hi)


def _parse_twist(value: Any, source: str | None) -> TwistLimits | None:
    if value is None:
        return None
    if not isinstance(value, dict):
        raise ConstraintError(f"expected {{min_deg, max_deg}}, got {value!r}", "twist", source)
    _require(value, ("min_deg", "max_deg"), "twist", source, optional=("by_swing",))
    lo, hi = _twist_interval(value, "twist", source)
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
    _require(value, ("bandwidth_deg", "points"), where, source)
    bw = _number(value["bandwidth_deg"], f"{where}.bandwidth_deg", source)
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
        _require(p, ("direction", "min_deg", "max_deg"), pw, source)
        dirs.append(_vector(p["direction"], f"{pw}.direction", source))
        lo, hi = _twist_interval(p, pw, source)
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


def _plain(value: Any, where: str) -> Any:
    """``value`` as plain YAML-safe Python (numpy scalars and arrays, tuples converted)."""
    if isinstance(value, dict):
        return {str(k): _plain(v, f"{where}.{k}") for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v, f"{where}[{i}]") for i, v in enumerate(value)]
    if isinstance(value, np.ndarray):
        return _plain(value.tolist(), where)
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, Path):
        return str(value)
    if value is None or isinstance(value, (str, bool, int, float)):
        return value
    if isinstance(value, (datetime.date, datetime.datetime)):
        return value
    raise ConstraintError(f"cannot be written as YAML: {type(value).__name__}", where)


def _vec_out(v: np.ndarray) -> list[float]:
    return [float(round(c, 12)) for c in v]


def _fmt_vec(v: np.ndarray) -> str:
    return "[" + ", ".join(f"{c:.3f}" for c in v) + "]"


def _fmt_provenance(p: dict) -> str:
    text = ", ".join(f"{k}: {v}" for k, v in p.items() if not isinstance(v, (dict, list)))
    return text if len(text) <= 100 else text[:97] + "..."
