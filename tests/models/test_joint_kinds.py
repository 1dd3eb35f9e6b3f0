"""Joint kinds in the constraint format (issue 20, part 1): ball (today's files, unchanged),
hinge (one axis, an interval; the exact geodesic correction) and two-axis (a swing region with
a fixed or narrow twist) — files, errors, and the hinge oracle's two paths."""

from __future__ import annotations

import math

import numpy as np
import pytest

from models import quaternion as Q
from models.constraint import JointConstraint, loads_constraint
from models.errors import ConstraintError
from models.oracle import ConstraintOracle
from models.shapes import load_shape

Z = np.array([0.0, 0.0, 1.0])
ELBOW = """
name: right-elbow
kind: hinge
joint: elbow
side: right
hinge: {axis: [0, 0, 2], min_deg: 0, max_deg: 140}
"""


def _rot(axis, deg):
    return Q.from_axis_angle(np.asarray(axis, dtype=float), math.radians(deg))


def _angle_deg(a, b):
    return float(np.degrees(Q.angle(Q.multiply(a, Q.conjugate(b)))))


# --------------------------------------------------------------------------- files
def test_todays_files_are_ball_joints_written_back_unchanged():
    c = load_shape("original")
    assert c.kind == "ball" and c.hinge is None
    assert "kind" not in c.to_dict()
    assert loads_constraint(c.to_yaml()) == c


def test_a_hinge_file_round_trips():
    c = loads_constraint(ELBOW, source="elbow.yaml")
    assert c.kind == "hinge" and c.swing is None and c.twist is None
    np.testing.assert_allclose(c.hinge.axis, Z)  # normalised on load
    assert (c.hinge.min_deg, c.hinge.max_deg) == (0.0, 140.0)
    again = loads_constraint(c.to_yaml())
    assert again == c and again.to_dict()["kind"] == "hinge"
    assert "hinge, axis [0.000, 0.000, 1.000], 0 .. 140 deg" in c.summary()
    assert c == JointConstraint.hinge_joint(Z, 0, 140, name="x")
    assert c != JointConstraint.hinge_joint(Z, 0, 130)


@pytest.mark.parametrize(("text", "message"), [
    ("name: a\nkind: hinge\n", "hinge: expected {axis, min_deg, max_deg}"),
    ("name: a\nkind: hinge\nhinge: {axis: [0, 0, 1], min_deg: 0}\n", "missing 'max_deg'"),
    ("name: a\nkind: hinge\nhinge: {axis: [0, 0, 1], min_deg: 50, max_deg: 10}\n",
     "min_deg (50) is greater than max_deg (10)"),
    ("name: a\nkind: hinge\nhinge: {axis: [0, 0, 0], min_deg: 0, max_deg: 10}\n", "hinge.axis"),
    ("name: a\nkind: hinge\nhinge: {axis: [0, 0, 1], min_deg: 0, max_deg: 10, ax: 1}\n",
     "unknown key 'ax'"),
    ("name: a\nkind: hinge\nhinge: {axis: [0, 0, 1], min_deg: 0, max_deg: 10}\n"
     "swing: {cone: {centre: [1, 0, 0], radius_deg: 30}}\n", "a hinge has no swing or twist"),
    ("name: a\nswing: {cone: {centre: [1, 0, 0], radius_deg: 30}}\n"
     "hinge: {axis: [0, 0, 1], min_deg: 0, max_deg: 10}\n", "only 'kind: hinge' takes a hinge"),
    ("name: a\nkind: hing\nhinge: {axis: [0, 0, 1], min_deg: 0, max_deg: 10}\n",
     "must be one of ball, hinge, two-axis"),
    ("name: a\nkind: two-axis\nswing: {cone: {centre: [1, 0, 0], radius_deg: 30}}\n",
     "a two-axis joint needs a 'swing' region and a (fixed or narrow) 'twist'"),
    ("name: a\nkind: two-axis\nswing: {cone: {centre: [1, 0, 0], radius_deg: 30}}\n"
     "twist: {min_deg: -40, max_deg: 40}\n", "at most 30 degrees wide, got 80"),
])
def test_bad_kind_files_name_the_field(text, message):
    with pytest.raises(ConstraintError) as err:
        loads_constraint(text, source="j.yaml")
    assert message in str(err.value) and "j.yaml" in str(err.value)


def test_a_two_axis_joint_is_a_swing_region_with_a_fixed_twist():
    c = loads_constraint("name: wrist\nkind: two-axis\n"
                         "swing: {cone: {centre: [1, 0, 0], radius_deg: 40}}\n"
                         "twist: {min_deg: 0, max_deg: 0}\n")
    assert c.kind == "two-axis" and loads_constraint(c.to_yaml()) == c
    o = ConstraintOracle(c)
    inside = _rot((0, 0, 1), 20)
    assert o.is_valid(inside)
    twisted = Q.multiply(inside, _rot((1, 0, 0), 10))  # 10° of twist: the twist is fixed at 0
    assert not o.is_valid(twisted)
    assert math.degrees(o.signed_distance(twisted)) == pytest.approx(10.0, abs=1e-9)
    np.testing.assert_allclose(Q.canonical(o.project(twisted)), Q.canonical(inside), atol=1e-12)


# --------------------------------------------------------------------------- hinge oracle
@pytest.fixture(scope="module")
def elbow():
    return ConstraintOracle(loads_constraint(ELBOW))


def test_on_the_hinge_inside_the_interval_is_valid(elbow):
    q = _rot(Z, 30)
    r = elbow.evaluate(q)
    assert r.valid and math.degrees(r.distance) == pytest.approx(-30.0)  # 30° from 0°
    np.testing.assert_array_equal(r.correction, Q.IDENTITY)
    np.testing.assert_array_equal(r.projected, q)


def test_beyond_an_end_goes_to_that_end(elbow):
    r = elbow.evaluate(_rot(Z, 160))
    assert not r.valid and math.degrees(r.distance) == pytest.approx(20.0)
    assert _angle_deg(r.projected, _rot(Z, 140)) == pytest.approx(0.0, abs=1e-9)
    r = elbow.evaluate(_rot(Z, -30))
    assert _angle_deg(r.projected, _rot(Z, 0)) == pytest.approx(0.0, abs=1e-9)
    # -110° is 110° from 0° and 110° (the other way round) from 140°: the tie goes to the top
    r = elbow.evaluate(_rot(Z, -110))
    assert _angle_deg(r.projected, _rot(Z, 140)) == pytest.approx(0.0, abs=1e-9)


def test_out_of_axis_motion_is_corrected_onto_the_hinge(elbow):
    """A real elbow's few degrees of carrying-angle motion: corrected to the hinge rotation of
    the same flexion, by exactly the out-of-axis angle."""
    q = Q.multiply(_rot(Z, 60), _rot((1, 0, 0), 5))
    r = elbow.evaluate(q)
    assert not r.valid and math.degrees(r.distance) == pytest.approx(5.0, abs=1e-9)
    assert _angle_deg(r.projected, _rot(Z, 60)) == pytest.approx(0.0, abs=1e-9)
    corrected = Q.multiply(r.correction, q)
    assert _angle_deg(corrected, r.projected) == pytest.approx(0.0, abs=1e-9)
    assert math.degrees(r.swing_distance) == pytest.approx(5.0, abs=1e-9)


def test_the_correction_is_the_nearest_allowed_rotation(elbow):
    """Geodesic optimality against a brute-force search over the interval (0.01° steps)."""
    rng = np.random.default_rng(3)
    q = Q.random_quaternions(300, rng)
    r = elbow.evaluate(q)
    arc = Q.from_axis_angle(Z, np.radians(np.arange(0.0, 140.0 + 1e-9, 0.01)))
    # angle between q_i and every arc point: 2 acos |<q, h>|
    best = np.degrees(2.0 * np.arccos(np.clip(np.abs(q @ arc.T), 0.0, 1.0))).min(axis=1)
    np.testing.assert_allclose(np.degrees(r.distance), best, atol=0.01)
    assert (np.degrees(r.distance) <= best + 1e-6).all()
    # corrected = correction ⊗ q lands on the hinge, inside the interval
    again = elbow.evaluate(Q.multiply(r.correction, q))
    assert (np.degrees(again.distance) <= 1e-6).all()


EDGE = [_rot(Z, 0), _rot(Z, 140), _rot(Z, 180), _rot(Z, -180), _rot((1, 0, 0), 180),
        np.array([0.0, 0.6, 0.8, 0.0]), -_rot(Z, 45), _rot(Z, 70 + 1e-10)]


@pytest.mark.parametrize("interval", [(0, 140), (-180, 180), (-10, 10), (20, 20), (150, 180)])
def test_scalar_path_equals_batch_path(interval):
    o = ConstraintOracle(JointConstraint.hinge_joint((0.3, -0.2, 0.9), *interval))
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
        assert one.correction[0] >= 0.0
    np.testing.assert_array_equal(o.is_valid(qs), many.valid)


def test_tools_for_swing_twist_joints_refuse_a_hinge_in_one_line(tmp_path, rig_cli):
    (tmp_path / "elbow.yaml").write_text(ELBOW)
    for argv in (["train", "--constraint", str(tmp_path / "elbow.yaml"), "--out",
                  str(tmp_path / "m.onnx")],
                 ["dataset", "make", "--n", "100", "--constraint", str(tmp_path / "elbow.yaml"),
                  "--out", str(tmp_path / "d.npz")]):
        code, _, err = rig_cli(argv)
        lines = [ln for ln in err.splitlines() if ln.strip()]
        assert code == 2 and len(lines) == 1, err
        assert "handles ball and two-axis joints; 'right-elbow' is a hinge joint" in lines[0]
    assert not (tmp_path / "m.onnx").exists()
    code, out, err = rig_cli(["constraint", "check", str(tmp_path / "elbow.yaml")])
    assert code == 0, err
    assert "kind        hinge" in out and "0 % of all orientations" in out
