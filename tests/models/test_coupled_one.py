"""A coupled joint's single-orientation path (issue 39): the control loop's
:meth:`ConstraintOracle.joint_query` of a coupled joint and the source's
:meth:`ConstraintOracle.coupling_angle_one` give the batched oracle's answers (to 1e-12) for
every kind a limb file lets be coupled — a ball joint with a polygon or a cone swing, with and
without a twist interval, a twist-only ball joint, a two-axis joint, a hinge — over the whole
coupling range and beyond it, on random orientations and orientations on and near the boundary,
with a hinge or a forearm as the source."""

from __future__ import annotations

import math

import numpy as np
import pytest
import yaml

from models import quaternion as Q
from models.kinds.ball import BallKind
from models.limb import loads_limb
from models.limb_evaluation import random_limb
from models.oracle import ConstraintOracle

TOL = 1e-12


def _ring(centre, radius_deg, n, wobble=0.0):
    c = np.asarray(centre, dtype=float)
    c /= np.linalg.norm(c)
    e1, e2 = Q.tangent_basis(c)
    out = []
    for k in range(n):
        a = 2 * math.pi * k / n
        r = math.radians(radius_deg) * (1 + wobble * math.cos(3 * a))
        out.append((math.cos(r) * c + math.sin(r) * (math.cos(a) * e1 + math.sin(a) * e2))
                   .tolist())
    return out


def _poly(centre, radius_deg, n, wobble, twist, reverse=False):
    v = _ring(centre, radius_deg, n, wobble)
    body = {"swing": {"polygon": {"vertices": v[::-1] if reverse else v,
                                  "interior": list(centre)}}}
    if twist is not None:
        body["twist"] = {"min_deg": twist[0], "max_deg": twist[1]}
    return body


def _cone(centre, radius, twist, kind=None):
    body = {"swing": {"cone": {"centre": centre, "radius_deg": radius}}}
    if twist is not None:
        body["twist"] = {"min_deg": twist[0], "max_deg": twist[1]}
    if kind:
        body["kind"] = kind
    return body


def _twist_only(lo, hi):
    return {"twist": {"min_deg": lo, "max_deg": hi}}


def _hinge(lo, hi, axis=(0, 0, 1)):
    return {"kind": "hinge", "hinge": {"axis": list(axis), "min_deg": lo, "max_deg": hi}}


_FOREARM = {"kind": "forearm", "forearm": {"flexion": {"axis": [0, 0, 1], "min_deg": 0,
                                                       "max_deg": 140},
                                           "rotation": {"min_deg": -80, "max_deg": 70}}}


def _leg(hip_frames, ankle):
    """A leg: the hip coupled to a hinge knee through ``hip_frames`` (at 0, 60, 120 deg), the
    ankle's own constraint or its keyframes (coupled to the knee too)."""
    hip = {"name": "hip", "parent": "pelvis", "child": "thigh", "coupled": {
        "by": "knee", "keyframes": [{"at_deg": a, "constraint": c}
                                    for a, c in zip((0, 60, 120), hip_frames, strict=True)]}}
    ank = {"name": "ankle", "parent": "shank", "child": "foot"}
    if isinstance(ankle, list):
        ank["coupled"] = {"by": "knee", "keyframes": [
            {"at_deg": a, "constraint": c} for a, c in zip((10, 90), ankle, strict=True)]}
    else:
        ank["constraint"] = ankle
    return {"name": "leg", "limb": "leg", "side": "right", "joints": [
        hip, {"name": "knee", "parent": "thigh", "child": "shank", "constraint": _hinge(0, 135)},
        ank]}


def _arm(shoulder_frames, wrist):
    """An arm: the shoulder coupled to a forearm elbow's flexion (at 0, 70, 140 deg)."""
    sh = {"name": "shoulder", "parent": "thorax", "child": "upper-arm", "coupled": {
        "by": "elbow", "keyframes": [{"at_deg": a, "constraint": c}
                                     for a, c in zip((0, 70, 140), shoulder_frames,
                                                     strict=True)]}}
    wr = {"name": "wrist", "parent": "forearm", "child": "hand"}
    if isinstance(wrist, list):
        wr["coupled"] = {"by": "elbow", "keyframes": [
            {"at_deg": a, "constraint": c} for a, c in zip((20, 120), wrist, strict=True)]}
    else:
        wr["constraint"] = wrist
    return {"name": "arm", "limb": "arm", "side": "left", "joints": [
        sh, {"name": "elbow", "parent": "upper-arm", "child": "forearm", "constraint": _FOREARM},
        wr]}


_WRIST = _cone([1, 0, 0.2], 35, (-5, 5), "two-axis")

LIMBS = {
    # a concave polygon and twist (7, 12 and 5 vertices, one listed clockwise); a hinge ankle
    # coupled too
    "polygon+twist, hinge": _leg([_poly([1, 0, 0], 40, 7, 0.3, (-30, 40)),
                                  _poly([0.8, 0.6, 0], 55, 12, 0.25, (-35, 45), reverse=True),
                                  _poly([0.6, 0.8, 0], 65, 5, 0.1, (-40, 50))],
                                 [_hinge(-30, 20, (0, 1, 0)), _hinge(-10, 45, (0, 1, 0))]),
    # a polygon without twist; a twist interval reaching the seam on the ankle (twist only)
    "polygon, twist only": _leg([_poly([1, 0, 0], 40, 7, 0.3, None),
                                 _poly([0.8, 0.6, 0], 55, 12, 0.25, None),
                                 _poly([0.6, 0.8, 0], 65, 5, 0.1, None)],
                                [_twist_only(-180, 20), _twist_only(-90, 180)]),
    # cones and twist on a forearm's flexion; a coupled two-axis wrist
    "cone+twist, two-axis": _arm([_cone([1, 0, 0], 40, (-30, 40)),
                                  _cone([0.8, 0.6, 0], 60, (-40, 50)),
                                  _cone([0.5, 0.8, 0.3], 75, (-50, 60))],
                                 [_cone([1, 0, 0.2], 35, (-5, 5), "two-axis"),
                                  _cone([1, 0.3, 0], 25, (-10, 12), "two-axis")]),
    # a cone without twist, a centre crossing the limb's −axis side
    "cone": _arm([_cone([1, 0, 0], 40, None), _cone([-0.2, 1, 0], 90, None),
                  _cone([-0.6, 0.8, 0], 120, None)], _WRIST),
}


def _limbs():
    out = {name: loads_limb(yaml.safe_dump(doc), source=f"{name}.yaml")
           for name, doc in LIMBS.items()}
    out["random leg"] = random_limb(9_000, "leg")
    out["random forearm arm"] = random_limb(9_001, "arm", forearm=True)
    return out


@pytest.fixture(scope="module")
def limbs():
    return {name: ConstraintOracle(limb).prepare() for name, limb in _limbs().items()}


def _samples(oracle: ConstraintOracle, j: int, rng) -> tuple[np.ndarray, np.ndarray]:
    """Orientations and coupling angles: random ones (both signs) over the coupling range
    widened by 20 deg, at every keyframe and end; the boundary at those angles (random
    orientations projected) and points just off it (1e-10 .. 1e-5 rad either way)."""
    lo, hi = oracle.coupling_range(j)
    n = 300
    q = Q.random_quaternions(n, rng)
    q[::2] *= -1.0
    ang = rng.uniform(lo - math.radians(20), hi + math.radians(20), n)
    keys = np.array([lo, hi, *oracle.limb.joints[j].coupling.limits.at])
    ang[:60] = keys[rng.integers(0, len(keys), 60)]
    on = oracle.evaluate_joint(j, q, ang).projected
    steps = 10.0 ** rng.uniform(-10, -5, n)
    axes = Q.random_unit_vectors(n, rng)
    near = Q.multiply(_small_rotations(axes, steps), on)
    return np.concatenate((q, on, near)), np.concatenate((ang, ang, ang))


def _small_rotations(axes: np.ndarray, angles: np.ndarray) -> np.ndarray:
    h = 0.5 * angles
    return np.concatenate((np.cos(h)[:, None], np.sin(h)[:, None] * axes), axis=1)


def _same_rotation(a: np.ndarray, b: np.ndarray) -> float:
    """Largest difference of two (N, 4) arrays of quaternions as rotations (q ~ −q)."""
    return float(np.minimum(np.abs(a - b).max(axis=1), np.abs(a + b).max(axis=1)).max())


def _coupled(oracle: ConstraintOracle) -> list[int]:
    return [j for j in range(oracle.n_joints) if oracle.joint_source(j) is not None]


@pytest.mark.parametrize("name", [*LIMBS, "random leg", "random forearm arm"])
def test_a_coupled_joints_query_is_the_batched_answer(limbs, name):
    oracle = limbs[name]
    rng = np.random.default_rng(abs(hash(name)) % 2**32)
    for j in _coupled(oracle):
        q, ang = _samples(oracle, j, rng)
        r = oracle.evaluate_joint(j, q, ang)
        query = oracle.joint_query(j)
        got = [query(*map(float, qi), float(a)) for qi, a in zip(q, ang, strict=True)]
        dist = np.array([g[0] for g in got])
        proj = np.array([g[1] for g in got])
        assert np.abs(dist - r.distance).max() < TOL
        assert np.abs(proj - r.projected).max() < TOL  # the input's sign kept
        # a query of a non-unit orientation answers its normalised one
        g = query(*map(float, 2.0 * q[0]), float(ang[0]))
        assert abs(g[0] - r.distance[0]) < TOL


@pytest.mark.parametrize("name", [*LIMBS, "random forearm arm"])
def test_validity_and_correction_match_too(limbs, name):
    """The kind's single path (:meth:`JointKind.coupled_one`) answers validity and the
    correction as the batched path does (corrections compared as rotations: half a turn's
    sign is the rounding's)."""
    oracle = limbs[name]
    rng = np.random.default_rng(5)
    for j in _coupled(oracle):
        q, ang = _samples(oracle, j, rng)
        r = oracle.evaluate_joint(j, q, ang)
        lim = oracle.limb.joints[j].coupling.limits
        one = lim.keyframes[0].joint_kind.coupled_one(oracle.axes[j], lim)
        got = [one(*map(float, qi), float(a)) for qi, a in zip(q, ang, strict=True)]
        assert [g[0] for g in got] == r.valid.tolist()
        assert _same_rotation(np.array([g[3] for g in got]), r.correction) < TOL


@pytest.mark.parametrize("name", [*LIMBS, "random forearm arm"])
def test_the_sources_coupling_angle_is_the_batched_one(limbs, name):
    """A coupled joint is judged at the coupling angle of its corrected source: the scalar
    :meth:`coupling_angle_one` of the source's corrected orientation is the angle the limb
    oracle used."""
    oracle = limbs[name]
    rng = np.random.default_rng(11)
    postures = Q.random_quaternions(400 * oracle.n_joints, rng).reshape(400, oracle.n_joints, 4)
    res = oracle.evaluate(postures)
    for j in _coupled(oracle):
        src = oracle.joint_source(j)
        got = [oracle.coupling_angle_one(src, *map(float, p)) for p in res.projected[:, src]]
        assert np.abs(np.array(got) - res.coupling_angle[:, j]).max() < TOL


def test_the_single_path_builds_no_batch(limbs, monkeypatch):
    """A coupled ball joint's query never runs the batched evaluation."""
    oracle = limbs["polygon+twist, hinge"]
    query = oracle.joint_query(0)

    def refuse(*args, **kwargs):
        raise AssertionError("the batched path was called")
    monkeypatch.setattr(BallKind, "evaluate_coupled", refuse)
    d, p = query(0.3, 0.5, -0.2, 0.8, 0.7)
    assert math.isfinite(d) and len(p) == 4


def test_a_kind_without_a_single_path_falls_back_to_a_batch_of_one(monkeypatch):
    """A kind whose :meth:`coupled_one` is None is answered by its batched evaluation on one
    sample: the same answers."""
    limb = loads_limb(yaml.safe_dump(LIMBS["polygon+twist, hinge"]), source="leg.yaml")
    fast = ConstraintOracle(limb).prepare()
    monkeypatch.setattr(BallKind, "coupled_one", lambda self, axis, limits: None)
    slow = ConstraintOracle(limb).prepare()
    rng = np.random.default_rng(3)
    qf, qs = fast.joint_query(0), slow.joint_query(0)
    for qi, a in zip(Q.random_quaternions(50, rng), rng.uniform(-0.5, 2.5, 50), strict=True):
        df, pf = qf(*map(float, qi), float(a))
        ds, ps = qs(*map(float, qi), float(a))
        assert abs(df - ds) < TOL and np.abs(np.subtract(pf, ps)).max() < TOL


def test_a_zero_orientation_is_refused_as_before(limbs):
    query = limbs["cone"].joint_query(0)
    with pytest.raises(ValueError):
        query(0.0, 0.0, 0.0, 0.0, 0.5)
