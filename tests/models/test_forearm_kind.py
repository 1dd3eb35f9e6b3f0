"""The forearm joint kind (models.kinds.forearm): elbow flexion plus axial rotation, each with
its interval — its file block, its exact oracle (nearest by geodesic angle, batched and single
paths equal), and its registration."""

from __future__ import annotations

import math

import numpy as np
import pytest

from models import quaternion as Q
from models.constraint import JointConstraint, loads_constraint
from models.errors import ConstraintError
from models.kinds import KINDS, get_kind
from models.kinds.forearm import decompose
from models.oracle import ConstraintOracle

Z, X = np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 0.0])

FOREARM = """
name: right-forearm
kind: forearm
joint: elbow
side: right
forearm:
  flexion: {axis: [0, 0, 1], min_deg: 0, max_deg: 145}
  rotation: {min_deg: -80, max_deg: 70}
"""


def _set(theta_deg, phi_deg, n=Z, x=X):
    return Q.multiply(Q.from_axis_angle(n, np.radians(theta_deg)),
                      Q.from_axis_angle(x, np.radians(phi_deg)))


def test_registered_and_read_back_identically():
    assert "forearm" in KINDS and get_kind("forearm").name == "forearm"
    c = loads_constraint(FOREARM)
    assert c.kind == "forearm" and c.swing is None and c.twist is None and c.hinge is None
    assert loads_constraint(c.to_yaml()) == c
    assert "kind        forearm" in c.summary() and "-80 .. 70 deg" in c.summary()
    assert not c.joint_kind.swing_twist  # learned models refuse it in one line
    with pytest.raises(ConstraintError, match="handles ball and two-axis joints"):
        c.require_swing_twist("rig train")


@pytest.mark.parametrize("text, field", [
    (FOREARM + "swing: {cone: {centre: [1, 0, 0], radius_deg: 30}}\n", "swing"),
    (FOREARM.replace("axis: [0, 0, 1]", "axis: [1, 0, 0]"), "forearm.flexion.axis"),
    (FOREARM.replace("max_deg: 70", "max_deg: 190"), "forearm.rotation.max_deg"),
    (FOREARM.replace("rotation:", "rotaton:"), "forearm.rotaton"),
    ("name: x\nforearm: {flexion: {axis: [0, 0, 1], min_deg: 0, max_deg: 1}, "
     "rotation: {min_deg: 0, max_deg: 1}}\ntwist: {min_deg: -1, max_deg: 1}\n", "forearm"),
])
def test_bad_files_name_the_field(text, field):
    with pytest.raises(ConstraintError) as err:
        loads_constraint(text, source="f.yaml")
    assert field in str(err.value) and "f.yaml" in str(err.value)


def test_an_unknown_kind_is_one_line_naming_the_known_ones():
    with pytest.raises(ConstraintError) as err:
        loads_constraint("name: x\nkind: saddle\ntwist: {min_deg: 0, max_deg: 1}\n")
    msg = str(err.value)
    assert "\n" not in msg and all(k in msg for k in ("ball", "hinge", "two-axis", "forearm"))


def test_decompose_inverts_the_parameterisation():
    rng = np.random.default_rng(5)
    th, ph = rng.uniform(-179, 179, 500), rng.uniform(-179, 179, 500)
    q = _set(th, ph) * np.where(rng.random(500) < 0.5, -1.0, 1.0)[:, None]
    t, p, s = decompose(q, Z, X)
    np.testing.assert_allclose(np.degrees(t), th, atol=1e-9)
    np.testing.assert_allclose(np.degrees(p), ph, atol=1e-9)
    np.testing.assert_allclose(s, 1.0, atol=1e-12)


def test_orientations_of_the_set_are_valid_with_their_margin():
    o = ConstraintOracle(loads_constraint(FOREARM))
    q = _set([10.0, 100.0, 0.0, 145.0], [0.0, -70.0, -80.0, 70.0])
    r = o.evaluate(q)
    assert r.valid.all() and np.allclose(r.correction, Q.IDENTITY)
    np.testing.assert_allclose(np.degrees(r.distance), [-10.0, -10.0, 0.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(np.degrees(r.twist), [0.0, -70.0, -80.0, 70.0], atol=1e-9)
    assert not o.evaluate(_set(150.0, 0.0)).valid and not o.evaluate(_set(20.0, 75.0)).valid


@pytest.mark.parametrize("axis, limits", [
    ((0, 0, 1), (0, 145, -80, 70)),
    ((0.2, -0.1, 0.95), (-20, 130, -60, 90)),
    ((0, 0, 1), (-180, 180, -10, 10)),
    ((0, 1, 0), (30, 30, -180, 180)),
])
def test_the_correction_is_the_nearest_valid_orientation(axis, limits):
    """Seeded: the oracle's correction angle is never larger than a dense grid's best, and
    within the grid's resolution of it; the corrected orientation is valid."""
    f_lo, f_hi, r_lo, r_hi = limits
    c = JointConstraint.from_dict({"name": "f", "kind": "forearm", "forearm": {
        "flexion": {"axis": list(axis), "min_deg": f_lo, "max_deg": f_hi},
        "rotation": {"min_deg": r_lo, "max_deg": r_hi}}})
    o = ConstraintOracle(c)
    rng = np.random.default_rng(17)
    q = Q.random_quaternions(400, rng)
    r = o.evaluate(q)
    n = np.asarray(c.limits.axis)
    th = np.linspace(f_lo, f_hi, max(2, int((f_hi - f_lo) / 0.5) + 1))
    ph = np.linspace(r_lo, r_hi, max(2, int((r_hi - r_lo) / 0.5) + 1))
    T, P = np.meshgrid(th, ph, indexing="ij")
    grid = _set(T.ravel(), P.ravel(), n=n)
    best = np.degrees(2.0 * np.arccos(np.clip(np.abs(q @ grid.T).max(axis=1), 0.0, 1.0)))
    got = np.degrees(np.where(r.valid, 0.0, r.distance))
    assert (got <= best + 1e-9).all()
    assert (best - got).max() < 0.5  # the grid's 0.5° steps
    again = o.evaluate(Q.multiply(r.correction, q))
    assert again.valid.all()


EDGE = [*_set([0.0, 145.0, -180.0, 72.5, 145.0 + 1e-10], [0.0, 70.0, 180.0, -5.0, 0.0]),
        Q.from_axis_angle(np.array([0.0, 1.0, 0.0]), math.pi), np.array([0.0, 0.6, 0.8, 0.0]),
        -_set([45.0], [20.0])[0]]


@pytest.mark.parametrize("limits", [(0, 145, -80, 70), (-180, 180, -180, 180), (20, 20, 0, 0),
                                    (150, 180, -90, -30)])
def test_single_path_equals_batched_path(limits):
    f_lo, f_hi, r_lo, r_hi = limits
    o = ConstraintOracle(JointConstraint.from_dict({"name": "f", "kind": "forearm", "forearm": {
        "flexion": {"axis": [0.3, -0.2, 0.9], "min_deg": f_lo, "max_deg": f_hi},
        "rotation": {"min_deg": r_lo, "max_deg": r_hi}}}))
    rng = np.random.default_rng(11)
    qs = np.vstack([Q.random_quaternions(200, rng), np.array(EDGE)])
    many = o.evaluate(qs)
    for i, q in enumerate(qs):
        one = o.evaluate(q)
        assert bool(one.valid) == bool(many.valid[i]) == bool(o.is_valid(q))
        np.testing.assert_allclose(one.distance, many.distance[i], atol=1e-12)
        np.testing.assert_allclose(one.projected, many.projected[i], atol=1e-12)
        np.testing.assert_allclose(one.correction, many.correction[i], atol=1e-12)
        np.testing.assert_allclose(one.twist, many.twist[i], atol=1e-12)
        np.testing.assert_allclose(one.swing_distance, many.swing_distance[i], atol=1e-12)
        d, p = o.distance_projected_one(*q)
        assert abs(d - float(many.distance[i])) <= 1e-12
        np.testing.assert_allclose(p, many.projected[i], atol=1e-12)
    np.testing.assert_array_equal(o.is_valid(qs), many.valid)
