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

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from models import kinds
from models.errors import ConstraintError
from models.fileio import write_owner_only
from models.kinds.hinge import HingeLimits
from models.limits import (
    ConeSwing,
    PolygonSwing,
    TwistLimits,
    fmt_vec,
    label,
    plain,
    reject_unknown,
    vec_out,
    vector,
)
from models.quaternion import LIMB_AXIS
from models.yamlio import safe_dump_yaml, safe_load_yaml

__all__ = [
    "SIDES",
    "JointConstraint",
    "dump_constraint",
    "load_constraint",
    "loads_constraint",
    "parse_yaml",
    "read_text",
]

#: Accepted values of ``side``.
SIDES = ("left", "right")

#: Top-level keys of a constraint file: the binding, every registered kind's limits keys
#: (:func:`models.kinds.file_keys`), the provenance.
_TOP_KEYS = ("name", "kind", "limb_axis", "joint", "side", "patient", *kinds.file_keys(),
             "provenance")


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
    kind : str
        A registered kind (:data:`models.kinds.KINDS`); ``ball`` when the file says nothing.
    limits : object or None
        The kind's own limits block when its limits are not a swing region and a twist (a
        hinge's :class:`~models.kinds.hinge.HingeLimits`); its ``swing`` and ``twist`` are then
        None.
    """

    name: str
    swing: ConeSwing | PolygonSwing | None
    twist: TwistLimits | None = None
    limb_axis: np.ndarray = field(default_factory=lambda: LIMB_AXIS.copy())
    joint: str | None = None
    side: str | None = None
    patient: str | None = None
    provenance: dict[str, Any] = field(default_factory=dict)
    kind: str = kinds.DEFAULT_KIND
    limits: Any = None

    @property
    def hinge(self) -> HingeLimits | None:
        """The limits of a hinge (None for another kind)."""
        return self.limits if isinstance(self.limits, HingeLimits) else None

    @property
    def joint_kind(self) -> kinds.JointKind:
        """This constraint's registered kind (:func:`models.kinds.get_kind`)."""
        return kinds.get_kind(self.kind)

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
        return cls.from_dict(plain(d, "constraint"))

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
        return cls.from_dict(plain(d, "constraint"))

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
        reject_unknown(data, _TOP_KEYS, None, source)
        name = data.get("name", "unnamed")
        if not isinstance(name, str) or not name.strip():
            raise ConstraintError("must be a non-empty string", "name", source)
        limb_axis = vector(data.get("limb_axis", [1, 0, 0]), "limb_axis", source)
        joint = label(data.get("joint"), "joint", source)
        side = label(data.get("side"), "side", source)
        if side is not None:
            side = side.lower()
            if side not in SIDES:
                raise ConstraintError(
                    f"must be one of {', '.join(SIDES)}, got {data['side']!r}", "side", source
                )
        patient = label(data.get("patient"), "patient", source)
        provenance = data.get("provenance", {})
        if provenance is None:
            provenance = {}
        if not isinstance(provenance, dict):
            raise ConstraintError(
                f"expected a mapping (free-form), got {provenance!r}", "provenance", source
            )
        kind = data.get("kind", kinds.DEFAULT_KIND)
        jk = kinds.get_kind(kind, "kind", source)
        jk.refuse(data, source)
        for other in kinds.registered():
            for key in other.file_keys:
                if key not in jk.file_keys and data.get(key) is not None:
                    raise ConstraintError(f"only 'kind: {other.name}' takes a {key} (this is "
                                          f"kind {kind})", key, source)
        parsed = jk.parse(data, source)
        return cls(
            name=name,
            swing=parsed["swing"],
            twist=parsed["twist"],
            limb_axis=limb_axis,
            joint=joint,
            side=side,
            patient=patient,
            provenance=dict(provenance),
            kind=kind,
            limits=parsed["limits"],
        )

    # -- queries --------------------------------------------------------------------------
    def require_swing_twist(self, what: str) -> None:
        """Raise :class:`ConstraintError` unless this joint's limits are a swing region and a
        twist (what a tool built for swing-twist joints says of a hinge, whose exact oracle
        exists but whose learned models and simulated patients do not yet)."""
        if not self.joint_kind.swing_twist:
            names = [k.name for k in kinds.registered() if k.swing_twist]
            raise ConstraintError(f"{what} handles {' and '.join(names)} joints; "
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
        if self.kind != kinds.DEFAULT_KIND:  # a ball joint's file stays as it always was
            out["kind"] = self.kind
        out["limb_axis"] = vec_out(self.limb_axis)
        for key in ("joint", "side", "patient"):
            if getattr(self, key) is not None:
                out[key] = getattr(self, key)
        out.update(self.joint_kind.limits_dict(self))
        if self.provenance:
            out["provenance"] = plain(self.provenance, "provenance")
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
            and self.limits == other.limits
            and np.allclose(self.limb_axis, other.limb_axis, atol=1e-12)
        )

    __hash__ = None  # type: ignore[assignment]

    def summary(self) -> str:
        """A few human-readable lines describing the limits."""
        lines = [f"constraint {self.name!r}", f"  limb axis   {fmt_vec(self.limb_axis)}"]
        bound = [
            f"{k} {getattr(self, k)}" for k in ("joint", "side", "patient") if getattr(self, k)
        ]
        if bound:
            lines.append(f"  bound to    {', '.join(bound)}")
        lines.extend(self.joint_kind.summary_lines(self))
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




def _fmt_provenance(p: dict) -> str:
    text = ", ".join(f"{k}: {v}" for k, v in p.items() if not isinstance(v, (dict, list)))
    return text if len(text) <= 100 else text[:97] + "..."

