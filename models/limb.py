"""Limb files: a chain of joints (arm, leg), each with its limits, and couplings between them.

A *limb file* describes one patient's limb as a chain of joints from the trunk outwards —
shoulder → elbow → wrist, hip → knee → ankle — each joint with its kind (``ball``,
``hinge``, ``two-axis``, ``forearm``: :mod:`models.constraint`), the segments it joins, and
its limits. A joint's limits may depend on another joint's angle (**a coupling**: muscles
that cross two joints — the hamstrings limit hip flexion when the knee is straight): they are
then given at two or more values of that angle (**keyframes**) and interpolated between them.
Reference: ``docs/limb-format.md``.

Conventions as everywhere: scalar-first quaternions, Hamilton product; joint ``j``'s
orientation is its child segment's frame relative to its parent segment's (the previous joint's
child); a segment's long axis is the joint constraint's ``limb_axis`` (+X by default).

Coupling semantics
------------------
- The coupling angle is the angle of a **hinge** joint of the same limb (the rotation about its
  hinge axis, degrees, as in its ``hinge`` interval) or the flexion of a **forearm** joint (the
  ``θ`` of ``F(θ) ⊗ R(φ)``, as in its ``forearm.flexion`` interval: an elbow that also
  pronates; :meth:`models.kinds.base.JointKind.coupling_angle`); other kinds have no single
  angle and are refused.
- Between keyframes ``k`` and ``k+1`` (at angles ``a_k < a_{k+1}``) the limits at angle ``a``
  are those of the interpolation at ``t = (a − a_k) / (a_{k+1} − a_k)``; outside the keyframes'
  range the nearer end keyframe's limits hold (clamped, never extrapolated).
- Twist and hinge intervals: ``min`` and ``max`` interpolated linearly in ``t``. Cones: centre
  by normalised linear interpolation, radius linearly.
- Swing polygons may differ in vertex count. Both keyframes' boundaries are oriented alike
  (region to the left), parametrised by normalised arc length from an **anchor** (the vertex
  nearest in azimuth to a reference direction about the keyframes' mean interior point), and
  **matched**: sampled at :data:`MATCH_POINTS` points each, the monotone pairing of those
  points with the least summed geodesic distance (dynamic time warping, from the anchors)
  gives a strictly increasing map between the two parameters (piecewise linear through the
  mean of each run where one boundary advances while the other waits). Both are resampled at
  the union of the first's vertex parameters and the second's mapped back, so each keeps all
  of its own vertices (every added point lies on one of its edges: the same boundary). Vertex
  ``i`` of the interpolated polygon is the normalised ``(1 − t) a_i + t b_i``. A stretch of
  boundary the two keyframes share is matched onto itself, so every limit between them holds
  it (pairing by arc length alone slid along such a stretch wherever the boundaries'
  lengths differed elsewhere, and cut its corners: a simulated shoulder's coupled limits left
  1.6 % of the recorded postures more than 1° out, 86 % of them inside both keyframes).
  At ``t = 0`` and ``t = 1`` the polygon is the keyframe's own boundary; every vertex moves
  continuously with ``t``, so the region does (in the Hausdorff distance): the limits are well
  defined and continuous in the coupling angle. When the file is read, each interpolation is
  checked exactly for the first angle at which it would touch itself
  (:func:`models.geometry.first_contact_along`: a vertex meeting an edge is a root of a cubic
  in ``t``; sampling at 16 steps let a fold that lasted 0.8° of the elbow's angle through, and
  the limits there could not be built), and for its other defects at :data:`CHECK_STEPS`
  steps.
- Correction is **hierarchical** (``models.oracle``): a joint on which another depends is
  corrected by its own limits first; the dependent joint is then corrected against its limits
  interpolated at the **corrected** angle. Joints are evaluated in an order where every
  coupling's source comes before its dependant; a cycle of couplings is refused.
"""

from __future__ import annotations

import difflib
import hashlib
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from models import quaternion as Q
from models.constraint import SIDES, JointConstraint, parse_yaml, read_text
from models.errors import ConstraintError, GeometryError
from models.fileio import write_owner_only
from models.geometry import SphericalPolygon, check_polygon, first_contact_along
from models.kinds import JointKind, get_kind
from models.limits import ConeSwing, PolygonSwing, label, plain, reject_unknown
from models.yamlio import safe_dump_yaml

__all__ = [
    "CHECK_STEPS",
    "LIMBS",
    "LIMB_CHAINS",
    "Coupling",
    "InterpolatedLimits",
    "Limb",
    "LimbJoint",
    "dump_limb",
    "inline_constraint",
    "is_limb_file",
    "load_limb",
    "loads_limb",
]

#: The chains a limb file's ``limb`` names: limb → ((joint, parent segment, child segment),
#: ...), proximal to distal, in the rig's segment names (``calibration.joints`` builds its
#: joint table on it). A file that says ``limb: arm`` holds arm joints, in this order.
LIMB_CHAINS: dict[str, tuple[tuple[str, str, str], ...]] = {
    "arm": (("shoulder", "thorax", "upper-arm"), ("elbow", "upper-arm", "forearm"),
            ("wrist", "forearm", "hand")),
    "leg": (("hip", "pelvis", "thigh"), ("knee", "thigh", "shank"), ("ankle", "shank", "foot")),
}

#: What the ``limb`` field may say.
LIMBS = tuple(LIMB_CHAINS)

#: Steps between two keyframes at which the interpolated polygon is checked for simplicity.
CHECK_STEPS = 16

_TOP_KEYS = ("name", "limb", "side", "patient", "joints", "provenance")
_JOINT_KEYS = ("name", "parent", "child", "constraint", "coupled")
_COUPLED_KEYS = ("by", "keyframes")
_KEYFRAME_KEYS = ("at_deg", "constraint")
# what a joint's inline constraint may not say (the limb says it)
_BOUND_KEYS = ("joint", "side", "patient")


def _check_chain(limb: str, parsed: list[dict], source: str | None) -> None:
    """A file that says ``limb`` holds that limb's joints on its segments
    (:data:`LIMB_CHAINS`): a ``hip`` inside an arm is another limb's joint."""
    chain = LIMB_CHAINS[limb]
    names = [j for j, _, _ in chain]
    for p in parsed:  # the order follows: the segments chain (checked before)
        if p["name"] not in names:
            raise ConstraintError(f"{p['name']!r} is not a joint of the {limb} (its joints: "
                                  f"{', '.join(names)})", f"{p['w']}.name", source)
        _, parent, child = chain[names.index(p["name"])]
        if (p["parent"], p["child"]) != (parent, child):
            raise ConstraintError(f"the {limb}'s {p['name']} joins {parent} to {child}, not "
                                  f"{p['parent']} to {p['child']}", p["w"], source)


def _mapping(value: Any, where: str, source: str | None) -> dict:
    if not isinstance(value, dict):
        raise ConstraintError(f"expected a mapping, got {value!r}", where, source)
    return value


def _text(value: Any, where: str, source: str | None) -> str:
    """A required short text (:func:`models.limits.label`'s rules)."""
    text = label(value, where, source)
    if text is None:
        raise ConstraintError("expected a non-empty single-line text, got nothing", where,
                              source)
    return text


def _joint_constraint(value: Any, where: str, source: str | None) -> JointConstraint:
    """An inline constraint mapping; its errors are named under ``where``."""
    body = _mapping(value, where, source)
    for key in _BOUND_KEYS:
        if key in body:
            raise ConstraintError(f"'{key}' is given by the limb and the joint, not here",
                                  f"{where}.{key}", source)
    try:
        return JointConstraint.from_dict(body)
    except ConstraintError as err:
        field_name = f"{where}.{err.field}" if err.field else where
        msg = str(err)
        if err.field:
            msg = msg.split(f"{err.field}: ", 1)[-1]
        raise ConstraintError(msg, field_name, source) from err


# ---------------------------------------------------------------------------------------------
# Interpolation between keyframes
# ---------------------------------------------------------------------------------------------
def oriented_vertices(swing: PolygonSwing) -> np.ndarray:
    """The polygon's vertices ordered so that the region lies to the left of every edge (the
    side of ``v_i × v_{i+1}``)."""
    sp = SphericalPolygon(swing.vertices, swing.interior)
    return swing.vertices if sp.orient > 0 else swing.vertices[::-1].copy()


def _arc_params(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Cumulative normalised arc length at each vertex (starting 0) and the edge lengths."""
    nxt = np.roll(v, -1, axis=0)
    lengths = np.arctan2(np.linalg.norm(Q.cross(v, nxt), axis=1), np.einsum("ij,ij->i", v, nxt))
    cum = np.concatenate(([0.0], np.cumsum(lengths)[:-1])) / lengths.sum()
    return cum, lengths


def _resample(v: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Points at normalised arc-length parameters ``u`` (sorted, in [0, 1)) along the closed
    boundary ``v`` (slerp along each edge: every point lies on the boundary)."""
    cum, lengths = _arc_params(v)
    total = lengths.sum()
    edge = np.clip(np.searchsorted(cum, u, side="right") - 1, 0, len(v) - 1)
    a = v[edge]
    b = v[(edge + 1) % len(v)]
    ang = lengths[edge]
    frac = np.where(ang > 0, (u - cum[edge]) * total / np.where(ang > 0, ang, 1.0), 0.0)
    frac = np.clip(frac, 0.0, 1.0)
    sa = np.sin(ang)
    safe = np.where(sa > 1e-15, sa, 1.0)
    wa = np.where(sa > 1e-15, np.sin((1.0 - frac) * ang) / safe, 1.0 - frac)
    wb = np.where(sa > 1e-15, np.sin(frac * ang) / safe, frac)
    p = wa[:, None] * a + wb[:, None] * b
    return p / np.linalg.norm(p, axis=1, keepdims=True)


def _anchored(v: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """``v`` rolled to start at the vertex nearest in azimuth to the reference direction of a
    tangent basis at ``centre`` (ties: the lowest index)."""
    e1, e2 = Q.tangent_basis(centre)
    az = np.arctan2(v @ e2, v @ e1)
    return np.roll(v, -int(np.argmin(np.abs(az))), axis=0)


#: Points per boundary on which two keyframes' boundaries are matched (:func:`_match`).
MATCH_POINTS = 160


def _match(pa: np.ndarray, pb: np.ndarray) -> np.ndarray:
    """The monotone matching of two closed boundaries sampled at ``n`` points each from
    corresponding anchors that minimises the summed geodesic distance of matched points
    (dynamic time warping): the path ``(i, j)`` pairs (K, 2) from (0, 0) to (n−1, n−1), ties
    resolved towards the diagonal."""
    cost = np.arctan2(np.linalg.norm(Q.cross(pa[:, None], pb[None]), axis=2), pa @ pb.T)
    n, m = cost.shape
    acc = np.full((n + 1, m + 1), np.inf)
    acc[0, 0] = 0.0
    for d in range(2, n + m + 1):  # one anti-diagonal at a time
        i = np.arange(max(1, d - m), min(n, d - 1) + 1)
        j = d - i
        acc[i, j] = cost[i - 1, j - 1] + np.minimum(np.minimum(acc[i - 1, j - 1],
                                                               acc[i - 1, j]), acc[i, j - 1])
    i, j, path = n, m, []
    while i > 0 and j > 0:
        path.append((i - 1, j - 1))
        step = int(np.argmin((acc[i - 1, j - 1], acc[i - 1, j], acc[i, j - 1])))
        i, j = (i - 1, j - 1) if step == 0 else (i - 1, j) if step == 1 else (i, j - 1)
    return np.array(path[::-1])


def _warp(path: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """A strictly increasing piecewise-linear map between the two boundaries' parameters from
    a matching path: knots ``(u_a, u_b)`` at (0, 0), at the mean of each run of the path
    between diagonal steps (where one boundary advances while the other waits), and (1, 1)."""
    diagonal = np.all(np.diff(path, axis=0) == 1, axis=1)
    group = np.concatenate(([0], np.cumsum(diagonal)))
    count = np.bincount(group)
    ua = np.bincount(group, weights=path[:, 0]) / count / n
    ub = np.bincount(group, weights=path[:, 1]) / count / n
    return np.concatenate(([0.0], ua[1:], [1.0])), np.concatenate(([0.0], ub[1:], [1.0]))


def corresponding_polygons(a: PolygonSwing, b: PolygonSwing) -> tuple[np.ndarray, np.ndarray]:
    """Two keyframe polygons resampled to vertices in correspondence (see the module
    docstring): ``(A, B)``, both (K, 3), oriented, each holding all of its own vertices."""
    centre = a.interior + b.interior
    if np.linalg.norm(centre) < 1e-9:
        centre = a.interior
    centre = centre / np.linalg.norm(centre)
    va = _anchored(oriented_vertices(a), centre)
    vb = _anchored(oriented_vertices(b), centre)
    s = np.arange(MATCH_POINTS) / MATCH_POINTS
    ka, kb = _warp(_match(_resample(va, s), _resample(vb, s)), MATCH_POINTS)
    ua, _ = _arc_params(va)
    ub, _ = _arc_params(vb)
    u = np.unique(np.concatenate((ua, np.interp(ub, kb, ka))))
    keep = np.concatenate(([True], np.diff(u) > 1e-12))
    u = u[keep]
    return _resample(va, u), _resample(vb, np.interp(u, ka, kb))


@dataclass(frozen=True, eq=False)
class InterpolatedLimits:
    """A coupled joint's limits between its keyframes, ready for evaluation.

    Attributes
    ----------
    kind : str
    at : (K,) float64, radians, increasing — the keyframes' coupling angles
    keyframes : tuple of JointConstraint
    polygons : tuple of (A, B) vertex arrays per keyframe interval (polygon swings), else ()
    """

    kind: str
    at: np.ndarray
    keyframes: tuple[JointConstraint, ...]
    polygons: tuple[tuple[np.ndarray, np.ndarray], ...] = ()

    def locate(self, angle) -> tuple[np.ndarray, np.ndarray]:
        """Keyframe interval index (N,) and fraction ``t`` (N,) in [0, 1] of coupling angles
        (radians), clamped to the keyframes' range."""
        a = np.clip(np.asarray(angle, dtype=np.float64), self.at[0], self.at[-1])
        k = np.clip(np.searchsorted(self.at, a, side="right") - 1, 0, len(self.at) - 2)
        t = (a - self.at[k]) / (self.at[k + 1] - self.at[k])
        return k, np.clip(t, 0.0, 1.0)

    def _lerp(self, k, t, get) -> np.ndarray:
        vals = np.array([get(c) for c in self.keyframes], dtype=np.float64)
        return (1.0 - t) * vals[k] + t * vals[k + 1]

    def interval(self, k, t) -> tuple[np.ndarray, np.ndarray]:
        """Twist (ball, two-axis) or hinge interval (radians) at the located angles."""
        interval = get_kind(self.kind).coupled_interval
        return (self._lerp(k, t, lambda c: interval(c)[0]),
                self._lerp(k, t, lambda c: interval(c)[1]))

    def cones(self, k, t) -> tuple[np.ndarray, np.ndarray]:
        """Cone centres (N, 3) and radii (N,) at the located angles."""
        cs = np.array([c.swing.centre for c in self.keyframes])
        c = (1.0 - t)[:, None] * cs[k] + t[:, None] * cs[k + 1]
        c /= np.linalg.norm(c, axis=1, keepdims=True)
        return c, self._lerp(k, t, lambda j: j.swing.radius)

    def polygon_at(self, k: int, t) -> np.ndarray:
        """The oriented interpolated polygon (M, 3) of keyframe interval ``k`` at ``t``; for
        an array of fractions (n,), one polygon per fraction (n, M, 3)."""
        a, b = self.polygons[k]
        tt = np.asarray(t, dtype=np.float64)[..., None, None]
        v = (1.0 - tt) * a + tt * b
        return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _interpolation(kf: list[tuple[float, JointConstraint]], where: str, by: str,
                   source: str | None) -> InterpolatedLimits:
    """Check the keyframes agree in kind and shape; build the interpolation."""
    first = kf[0][1]
    kind = first.kind
    for i, (_, c) in enumerate(kf):
        w = f"{where}.keyframes[{i}].constraint"
        if c.kind != kind:
            raise ConstraintError(f"every keyframe of a coupling is one kind of joint: keyframe "
                                  f"0 is {kind}, this one {c.kind}", f"{w}.kind", source)
        if not np.allclose(c.limb_axis, first.limb_axis, atol=1e-9):
            raise ConstraintError("every keyframe of a coupling has the same limb_axis",
                                  f"{w}.limb_axis", source)
        get_kind(kind).check_keyframe(c, first, w, source)
    at = np.radians([a for a, _ in kf])
    polygons: list[tuple[np.ndarray, np.ndarray]] = []
    if isinstance(first.swing, PolygonSwing):
        for i in range(len(kf) - 1):
            a, b = corresponding_polygons(kf[i][1].swing, kf[i + 1][1].swing)
            dots = np.einsum("ij,ij->i", a, b)
            if dots.min() < -1.0 + 1e-9:
                raise ConstraintError(f"keyframes {i} and {i + 1}: corresponding boundary "
                                      f"points are antipodal; the boundaries are too far apart "
                                      f"to interpolate (add a keyframe between)", where, source)
            contact = first_contact_along(a, b)
            if contact is not None:
                ang = math.degrees((1.0 - contact) * at[i] + contact * at[i + 1])
                raise ConstraintError(
                    f"keyframes {i} and {i + 1}: the boundary interpolated at {by} {ang:.3g} "
                    f"deg is not a simple polygon (a vertex meets an edge there); give "
                    f"boundaries that change gradually, or a keyframe between", where, source)
            for step in range(1, CHECK_STEPS):
                t = step / CHECK_STEPS
                v = (1.0 - t) * a + t * b
                v /= np.linalg.norm(v, axis=1, keepdims=True)
                try:
                    check_polygon(v)
                except GeometryError as err:
                    ang = math.degrees((1.0 - t) * at[i] + t * at[i + 1])
                    raise ConstraintError(
                        f"keyframes {i} and {i + 1}: the boundary interpolated at {by} "
                        f"{ang:g} deg is not a simple polygon ({err}); give boundaries that "
                        f"change gradually, or a keyframe between", where, source) from err
            polygons.append((a, b))
    return InterpolatedLimits(kind=kind, at=at, keyframes=tuple(c for _, c in kf),
                              polygons=tuple(polygons))


# ---------------------------------------------------------------------------------------------
# The limb
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class Coupling:
    """A joint's limits at keyframes of another joint's angle (a hinge's, a forearm's
    flexion).

    Attributes
    ----------
    by : str
        The joint (a hinge, a forearm) whose angle the limits depend on.
    at_deg : tuple of float, increasing (at least 2)
    limits : InterpolatedLimits
        The keyframes' constraints and their interpolation (:attr:`keyframes`).
    """

    by: str
    at_deg: tuple[float, ...]
    limits: InterpolatedLimits

    @property
    def keyframes(self) -> tuple[JointConstraint, ...]:
        """The limits at each of :attr:`at_deg`."""
        return self.limits.keyframes

    def to_dict(self) -> dict[str, Any]:
        return {"by": self.by, "keyframes": [
            {"at_deg": float(a), "constraint": inline_constraint(c)}
            for a, c in zip(self.at_deg, self.keyframes, strict=True)]}

    def at(self, angle_deg: float) -> JointConstraint:
        """The limits at one coupling angle (degrees) as a constraint of their own: a keyframe
        itself at its angle (for reports and single-joint tools)."""
        lim = self.limits
        k, t = lim.locate(np.array([math.radians(angle_deg)]))
        ki, ti = int(k[0]), float(t[0])
        if ti in (0.0, 1.0):
            return self.keyframes[ki + int(ti)]
        d = self.keyframes[ki].to_dict()
        key = get_kind(lim.kind).coupled_interval_key
        if key in d:
            lo, hi = (math.degrees(float(x[0])) for x in lim.interval(k, t))
            d[key].update(min_deg=lo, max_deg=hi)
        sw = self.keyframes[ki].swing
        if isinstance(sw, ConeSwing):
            c, r = lim.cones(k, t)
            d["swing"] = {"cone": {"centre": c[0].tolist(),
                                   "radius_deg": math.degrees(float(r[0]))}}
        elif isinstance(sw, PolygonSwing):
            v = lim.polygon_at(ki, ti)
            d["swing"] = {"polygon": {"vertices": v.tolist(),
                                      "interior": _inside_point(v).tolist()}}
        return JointConstraint.from_dict(d)


def _inside_point(v: np.ndarray) -> np.ndarray:
    """A point inside an oriented polygon: the midpoint of its longest edge nudged inwards."""
    nxt = np.roll(v, -1, axis=0)
    i = int(np.argmax(np.linalg.norm(nxt - v, axis=1)))
    g = Q.cross(v[i], nxt[i])
    g /= np.linalg.norm(g)
    mid = v[i] + nxt[i]
    mid /= np.linalg.norm(mid)
    sp = SphericalPolygon(v, None)
    for eps in (1e-2, 1e-3, 1e-4):
        p = mid + eps * g
        p /= np.linalg.norm(p)
        if sp.brute_nearest(p[None, :])[0][0] > 0.5 * eps:
            return p
    return p


@dataclass(frozen=True, eq=False)
class LimbJoint:
    """One joint of a limb: its name, the segments it joins, and its limits — a constraint of
    its own, or a coupling (limits at keyframes of another joint's angle)."""

    name: str
    parent: str
    child: str
    constraint: JointConstraint | None = None
    coupling: Coupling | None = None

    @property
    def kind(self) -> str:
        """The joint's kind name (its constraint's, or its keyframes')."""
        return (self.constraint.kind if self.constraint is not None
                else self.coupling.limits.kind)

    @property
    def joint_kind(self) -> JointKind:
        """The joint's registered kind (:func:`models.kinds.get_kind`)."""
        return get_kind(self.kind)

    @property
    def limb_axis(self) -> np.ndarray:
        c = self.constraint if self.constraint is not None else self.coupling.keyframes[0]
        return c.limb_axis

    def loosest(self) -> JointConstraint | None:
        """For a coupled hinge: the hull of its keyframe intervals; None for a coupled ball or
        two-axis joint (the union of its keyframe regions is not one polygon in general)."""
        if self.constraint is not None:
            return self.constraint
        return get_kind(self.kind).loosest(self.coupling.keyframes, self.name)

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"name": self.name, "parent": self.parent, "child": self.child}
        if self.constraint is not None:
            out["constraint"] = inline_constraint(self.constraint)
        else:
            out["coupled"] = self.coupling.to_dict()
        return out


def inline_constraint(c: JointConstraint) -> dict[str, Any]:
    """A joint's constraint as a limb file writes it inline: without the binding the limb gives
    (joint, side, patient) and without its own name."""
    d = c.to_dict()
    for key in (*_BOUND_KEYS, "name"):
        d.pop(key, None)
    return d


@dataclass(frozen=True, eq=False)
class Limb:
    """A chain of joints with their limits and couplings.

    Attributes
    ----------
    name : str
    limb : {"arm", "leg"} or None
    side, patient : str or None
    joints : tuple of LimbJoint, proximal to distal; joint ``j``'s parent segment is joint
        ``j − 1``'s child segment
    order : tuple of int
        Evaluation order: every coupling's source before its dependant (file order otherwise).
    provenance : dict
    """

    name: str
    joints: tuple[LimbJoint, ...]
    order: tuple[int, ...]
    limb: str | None = None
    side: str | None = None
    patient: str | None = None
    provenance: dict[str, Any] = field(default_factory=dict)

    @property
    def joint_names(self) -> tuple[str, ...]:
        return tuple(j.name for j in self.joints)

    def index(self, name: str) -> int:
        return self.joint_names.index(name)

    @property
    def coupled(self) -> tuple[int, ...]:
        """Indices of the joints whose limits depend on another joint."""
        return tuple(i for i, j in enumerate(self.joints) if j.coupling is not None)

    @classmethod
    def from_dict(cls, data: Any, source: str | None = None) -> Limb:
        """Validate a parsed mapping (schema: ``docs/limb-format.md``)."""
        body = _mapping(data, "", source) if isinstance(data, dict) else None
        if body is None:
            raise ConstraintError(f"expected a mapping with 'joints', got "
                                  f"{type(data).__name__}", source=source)
        reject_unknown(body, _TOP_KEYS, "", source)
        name = _text(body.get("name", "unnamed"), "name", source)
        limb = body.get("limb")
        if limb is not None and limb not in LIMBS:
            raise ConstraintError(f"must be one of {', '.join(LIMBS)}, got {limb!r}", "limb",
                                  source)
        side = body.get("side")
        if side is not None:
            side = _text(side, "side", source).lower()
            if side not in SIDES:
                raise ConstraintError(f"must be one of {', '.join(SIDES)}, got {body['side']!r}",
                                      "side", source)
        patient = None if body.get("patient") is None else _text(body["patient"], "patient",
                                                                   source)
        provenance = body.get("provenance") or {}
        if not isinstance(provenance, dict):
            raise ConstraintError(f"expected a mapping (free-form), got {provenance!r}",
                                  "provenance", source)
        raw = body.get("joints")
        if not isinstance(raw, list) or not raw:
            raise ConstraintError("expected a list of joints (proximal to distal)", "joints",
                                  source)
        names: list[str] = []
        parsed: list[dict] = []
        for i, jd in enumerate(raw):
            w = f"joints[{i}]"
            jd = _mapping(jd, w, source)
            reject_unknown(jd, _JOINT_KEYS, w, source)
            for key in ("name", "parent", "child"):
                if key not in jd:
                    raise ConstraintError(f"missing '{key}'", w, source)
            jname = _text(jd["name"], f"{w}.name", source)
            if jname in names:
                raise ConstraintError(f"joint name {jname!r} used twice", f"{w}.name", source)
            names.append(jname)
            parent = _text(jd["parent"], f"{w}.parent", source)
            child = _text(jd["child"], f"{w}.child", source)
            if parsed and parent != parsed[-1]["child"]:
                raise ConstraintError(
                    f"the chain is broken: joint {jname!r} hangs from segment {parent!r}, but "
                    f"the joint before it ({parsed[-1]['name']!r}) ends in segment "
                    f"{parsed[-1]['child']!r}", f"{w}.parent", source)
            if ("constraint" in jd) == ("coupled" in jd):
                raise ConstraintError("give either 'constraint' (the joint's limits) or "
                                      "'coupled' (limits at keyframes of another joint's angle)",
                                      w, source)
            parsed.append({"name": jname, "parent": parent, "child": child, "raw": jd, "w": w})
        if limb is not None:
            _check_chain(limb, parsed, source)
        # constraints first: a coupling's source must drive couplings (a hinge, a forearm)
        kinds: dict[str, str] = {}
        built: dict[str, Any] = {}
        for p in parsed:
            jd, w = p["raw"], p["w"]
            if "constraint" in jd:
                c = _joint_constraint(jd["constraint"], f"{w}.constraint", source)
                built[p["name"]] = c
                kinds[p["name"]] = c.kind
            else:
                cd = _mapping(jd["coupled"], f"{w}.coupled", source)
                reject_unknown(cd, _COUPLED_KEYS, f"{w}.coupled", source)
                for key in _COUPLED_KEYS:
                    if key not in cd:
                        raise ConstraintError(f"missing '{key}'", f"{w}.coupled", source)
                kfl = cd["keyframes"]
                if not isinstance(kfl, list) or len(kfl) < 2:
                    raise ConstraintError("expected a list of at least 2 keyframes",
                                          f"{w}.coupled.keyframes", source)
                kf: list[tuple[float, JointConstraint]] = []
                for k, kd in enumerate(kfl):
                    kw = f"{w}.coupled.keyframes[{k}]"
                    kd = _mapping(kd, kw, source)
                    reject_unknown(kd, _KEYFRAME_KEYS, kw, source)
                    for key in _KEYFRAME_KEYS:
                        if key not in kd:
                            raise ConstraintError(f"missing '{key}'", kw, source)
                    a = kd["at_deg"]
                    if isinstance(a, bool) or not isinstance(a, (int, float)) \
                            or not math.isfinite(a) or not -180.0 <= a <= 180.0:
                        raise ConstraintError(f"expected an angle in degrees in [-180, 180], "
                                              f"got {a!r}", f"{kw}.at_deg", source)
                    if kf and a <= kf[-1][0]:
                        raise ConstraintError(f"keyframes go in increasing angle: {a:g} after "
                                              f"{kf[-1][0]:g}", f"{kw}.at_deg", source)
                    kf.append((float(a), _joint_constraint(kd["constraint"],
                                                           f"{kw}.constraint", source)))
                built[p["name"]] = (cd["by"], kf)
                kinds[p["name"]] = kf[0][1].kind
        joints: list[LimbJoint] = []
        deps: dict[int, int] = {}
        for i, p in enumerate(parsed):
            b, w = built[p["name"]], p["w"]
            if isinstance(b, JointConstraint):
                joints.append(LimbJoint(p["name"], p["parent"], p["child"], constraint=b))
                continue
            by, kf = b
            by = _text(by, f"{w}.coupled.by", source)
            if by not in names:
                close = difflib.get_close_matches(by, names, n=1, cutoff=0.6)
                hint = f" (did you mean '{close[0]}'?)" if close else ""
                raise ConstraintError(f"no joint named {by!r}{hint} in this limb; joints: "
                                      f"{', '.join(names)}", f"{w}.coupled.by", source)
            if by == p["name"]:
                raise ConstraintError("a joint's limits cannot depend on its own angle",
                                      f"{w}.coupled.by", source)
            if not get_kind(kinds[by]).drives_couplings:
                raise ConstraintError(f"a coupling follows a hinge's angle or a forearm's "
                                      f"flexion; {by!r} is a {kinds[by]} joint",
                                      f"{w}.coupled.by", source)
            limits = _interpolation(kf, f"{w}.coupled", by, source)
            joints.append(LimbJoint(p["name"], p["parent"], p["child"], coupling=Coupling(
                by=by, at_deg=tuple(a for a, _ in kf), limits=limits)))
            deps[i] = names.index(by)
        order = _evaluation_order(len(joints), deps, names, source)
        return cls(name=name, joints=tuple(joints), order=order, limb=limb, side=side,
                   patient=patient, provenance=dict(provenance))

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"name": self.name}
        for key in ("limb", "side", "patient"):
            if getattr(self, key) is not None:
                out[key] = getattr(self, key)
        out["joints"] = [j.to_dict() for j in self.joints]
        if self.provenance:
            out["provenance"] = plain(self.provenance, "provenance")
        return out

    def to_yaml(self) -> str:
        """The limb as YAML text that :func:`loads_limb` reads back identically."""
        return safe_dump_yaml(self.to_dict(), sort_keys=False, default_flow_style=None)

    def content_hash(self) -> str:
        """SHA-256 of the limits (name, binding and provenance left out): what a model trained
        on this limb names in its metadata."""
        d = self.to_dict()
        for key in ("name", "side", "patient", "provenance"):
            d.pop(key, None)
        # rounded to 1e-9: a file written and read back (vectors renormalised) hashes alike
        text = safe_dump_yaml(_rounded(d), sort_keys=True)
        return hashlib.sha256(text.encode()).hexdigest()

    def summary(self) -> str:
        lines = [f"limb {self.name!r}" + (f" ({self.limb})" if self.limb else "")]
        bound = [f"{k} {getattr(self, k)}" for k in ("side", "patient") if getattr(self, k)]
        if bound:
            lines.append(f"  bound to    {', '.join(bound)}")
        for j in self.joints:
            head = f"  {j.name:<10} {j.parent} -> {j.child}, {j.kind}"
            if j.coupling is not None:
                head += (f", coupled to {j.coupling.by} at "
                         f"{', '.join(f'{a:g}' for a in j.coupling.at_deg)} deg")
            lines.append(head)
        return "\n".join(lines)


def _rounded(value: Any) -> Any:
    if isinstance(value, float):
        return round(value, 9) + 0.0  # + 0.0: no negative zero
    if isinstance(value, dict):
        return {k: _rounded(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_rounded(v) for v in value]
    return value


def _evaluation_order(n: int, deps: dict[int, int], names: list[str],
                      source: str | None) -> tuple[int, ...]:
    """File order, except that a coupling's source goes before its dependant; cycles refused."""
    order: list[int] = []
    state = [0] * n  # 0 new, 1 on the stack, 2 done

    def visit(i: int, path: list[int]) -> None:
        if state[i] == 2:
            return
        if state[i] == 1:
            cyc = " -> ".join(names[k] for k in [*path[path.index(i):], i])
            raise ConstraintError(f"the couplings form a cycle ({cyc}): no joint could be "
                                  f"corrected first", "joints", source)
        state[i] = 1
        if i in deps:
            visit(deps[i], [*path, i])
        state[i] = 2
        order.append(i)

    for i in range(n):
        visit(i, [])
    return tuple(order)


# -- file I/O ---------------------------------------------------------------------------------
def loads_limb(text: str, source: str | None = None) -> Limb:
    """Parse limb YAML text (``source`` names it in error messages)."""
    return Limb.from_dict(parse_yaml(text, source), source=source)


def load_limb(path: str | Path) -> Limb:
    """Read and validate a limb file (:class:`ConstraintError` naming the file and field)."""
    return loads_limb(read_text(path, "a limb file"), source=str(path))


def dump_limb(limb: Limb, path: str | Path) -> None:
    """Write a limb file atomically and owner-only (it may name a patient)."""
    write_owner_only(Path(path), limb.to_yaml())


def is_limb_file(data: Any) -> bool:
    """Does a parsed YAML document look like a limb file (a mapping with ``joints``)?"""
    return isinstance(data, dict) and "joints" in data


def load_limits(path: str | Path) -> Limb | JointConstraint:
    """A constraint file or a limb file, read and parsed once: the :class:`Limb` or the
    :class:`~models.constraint.JointConstraint` it describes (for the tools that take either)."""
    data = parse_yaml(read_text(path), source=str(path))
    if is_limb_file(data):
        return Limb.from_dict(data, source=str(path))
    return JointConstraint.from_dict(data, source=str(path))
