"""Constraint file format: parsing, validation errors that name the field, round trips."""

from __future__ import annotations

import math

import numpy as np
import pytest

from models.constraint import JointConstraint, dump_constraint, load_constraint, loads_constraint
from models.errors import ConstraintError

MINIMAL = """
name: right-shoulder-example
limb_axis: [1, 0, 0]
swing:
  cone: {centre: [1, 0, 0], radius_deg: 45}
twist: {min_deg: -60, max_deg: 60}
"""

SQUARE = """
name: square
swing:
  polygon:
    vertices: [[1, 0.5, 0.5], [1, -0.5, 0.5], [1, -0.5, -0.5], [1, 0.5, -0.5]]
    interior: [1, 0, 0]
"""


def test_minimal_form_loads():
    c = loads_constraint(MINIMAL)
    assert c.name == "right-shoulder-example"
    assert c.swing.radius_deg == 45
    assert (c.twist.min_deg, c.twist.max_deg) == (-60, 60)
    np.testing.assert_array_equal(c.limb_axis, [1, 0, 0])


def test_limb_axis_defaults_to_x_and_twist_is_optional():
    c = loads_constraint("swing: {cone: {centre: [0, 2, 0], radius_deg: 30}}")
    np.testing.assert_array_equal(c.limb_axis, [1, 0, 0])
    np.testing.assert_allclose(c.swing.centre, [0, 1, 0])  # normalised on load
    assert c.twist is None


@pytest.mark.parametrize("text", [MINIMAL, SQUARE])
def test_yaml_round_trip(text, tmp_path):
    c = loads_constraint(text)
    path = tmp_path / "c.yaml"
    dump_constraint(c, path)
    again = load_constraint(path)
    assert again == c
    assert again.name == c.name


def test_provenance_is_kept_verbatim_and_round_trips(tmp_path):
    text = MINIMAL + (
        "provenance:\n"
        "  session: 3\n"
        "  recorded: 2026-11-21\n"
        "  parameters: {alpha_deg: 4.5, outliers: [0.01, 0.99], method: concave-hull}\n"
        "  samples: 120345\n"
    )
    c = loads_constraint(text)
    assert c.provenance["session"] == 3 and c.provenance["samples"] == 120345
    assert c.provenance["parameters"]["outliers"] == [0.01, 0.99]
    path = tmp_path / "c.yaml"
    dump_constraint(c, path)
    assert load_constraint(path).provenance == c.provenance


def test_binding_fields_round_trip_and_are_validated(tmp_path):
    c = loads_constraint(MINIMAL + "joint: shoulder\nside: Right\npatient: P-007\n")
    assert (c.joint, c.side, c.patient) == ("shoulder", "right", "P-007")
    path = tmp_path / "c.yaml"
    dump_constraint(c, path)
    again = load_constraint(path)
    assert (again.joint, again.side, again.patient) == ("shoulder", "right", "P-007")
    assert "bound to    joint shoulder, side right, patient P-007" in c.summary()
    with pytest.raises(ConstraintError, match="side: must be one of left, right") as info:
        loads_constraint(MINIMAL + "side: middle\n", source="c.yaml")
    assert info.value.field == "side"
    with pytest.raises(ConstraintError, match="patient: expected a short text"):
        loads_constraint(MINIMAL + "patient: [a, b]\n")
    with pytest.raises(ConstraintError, match="provenance: expected a mapping"):
        loads_constraint(MINIMAL + "provenance: recorded by hand\n")


def test_code_shortcuts_take_binding_and_numpy_provenance():
    c = JointConstraint.cone(
        [0, 1, 0],
        30,
        twist=(-10, 20),
        joint="elbow",
        side="left",
        patient="P-1",
        provenance={"samples": np.int64(12), "centre": np.array([0.0, 1.0, 0.0])},
    )
    again = loads_constraint(c.to_yaml())
    assert again == c and again.joint == "elbow" and again.side == "left"
    assert again.provenance == {"samples": 12, "centre": [0.0, 1.0, 0.0]}


# -- unknown keys are errors at every level (a misspelt key must never drop a limit) -------------
@pytest.mark.parametrize(
    "text, field, hint",
    [
        (MINIMAL.replace("twist:", "twsit:"), "twsit", "did you mean 'twist'"),
        (MINIMAL + "source: {session: 3}\n", "source", "provenance"),
        (MINIMAL + "patient_name: Jane\n", "patient_name", "did you mean 'patient'"),
        (MINIMAL.replace("cone:", "cnoe:"), "swing.cnoe", "did you mean 'cone'"),
        (
            MINIMAL.replace("radius_deg: 45", "radius_deg: 45, colour: red"),
            "swing.cone.colour",
            "allowed here: centre, radius_deg",
        ),
        (MINIMAL.replace("max_deg: 60", "max_deg: 60, mx_deg: 3"), "twist.mx_deg", "max_deg"),
        (SQUARE.replace("interior:", "inteiror:"), "swing.polygon.inteiror", "interior"),
        (
            MINIMAL.replace(
                "max_deg: 60}",
                "max_deg: 60, by_swing: {bandwidth_deg: 20, points: [], kernel: gauss}}",
            ),
            "twist.by_swing.kernel",
            "allowed here: bandwidth_deg, points",
        ),
        (
            MINIMAL.replace(
                "max_deg: 60}",
                "max_deg: 60, by_swing: {bandwidth_deg: 20, points: "
                "[{direction: [1, 0, 0], min_deg: -5, max_deg: 5, weight: 2}]}}",
            ),
            "twist.by_swing.points[0].weight",
            "direction, min_deg, max_deg",
        ),
    ],
)
def test_unknown_keys_are_rejected_at_every_level(text, field, hint):
    with pytest.raises(ConstraintError, match="unknown key") as info:
        loads_constraint(text, source="patient.yaml")
    msg = str(info.value)
    assert info.value.field == field
    assert msg.startswith(f"patient.yaml: {field}: unknown key '{field.split('.')[-1]}'")
    assert hint in msg


@pytest.mark.parametrize(
    "text, field, message",
    [
        (
            "swing: {cone: {centre: [1, 0, 0], radius_deg: 0}}",
            "swing.cone.radius_deg",
            r"\(0, 180\)",
        ),
        ("swing: {cone: {centre: [1, 0, 0], radius_deg: 180}}", "swing.cone.radius_deg", "180"),
        ("swing: {cone: {centre: [1, 0, 0], radius_deg: -5}}", "swing.cone.radius_deg", "-5"),
        ("swing: {cone: {centre: [1, 0, 0], radius_deg: .nan}}", "swing.cone.radius_deg", "finite"),
        ("swing: {cone: {centre: [0, 0, 0], radius_deg: 30}}", "swing.cone.centre", "zero vector"),
        ("swing: {cone: {centre: [1, 0], radius_deg: 30}}", "swing.cone.centre", "3-vector"),
        ("swing: {cone: {centre: [1, 0, 0]}}", "swing.cone", "missing 'radius_deg'"),
        ("swing: {sphere: {}}", "swing.sphere", "unknown key 'sphere'"),
        (
            "swing: {cone: {centre: [1, 0, 0], radius_deg: 30},"
            " polygon: {vertices: [], interior: [1, 0, 0]}}",
            "swing",
            "exactly one of",
        ),
        (MINIMAL.replace("min_deg: -60", "min_deg: 70"), "twist", "greater than max_deg"),
        (MINIMAL.replace("max_deg: 60", "max_deg: 200"), "twist.max_deg", r"\[-180, 180\]"),
        (MINIMAL.replace("max_deg: 60", "max_deg: sixty"), "twist.max_deg", "expected a number"),
        ("name: x", None, "needs a 'swing' limit"),
        ("- 1\n- 2", None, "expected a mapping"),
        ("name: ''\nswing: {cone: {centre: [1,0,0], radius_deg: 3}}", "name", "non-empty"),
    ],
)
def test_invalid_definitions_name_the_field(text, field, message):
    with pytest.raises(ConstraintError, match=message) as info:
        loads_constraint(text, source="c.yaml")
    assert info.value.field == field
    assert str(info.value).startswith("c.yaml: ")


def _poly(vertices, interior=(1, 0, 0)):
    return {"name": "p", "swing": {"polygon": {"vertices": vertices, "interior": list(interior)}}}


@pytest.mark.parametrize(
    "vertices, interior, message",
    [
        ([[1, 0.5, 0.5], [1, -0.5, 0.5]], (1, 0, 0), "at least 3"),
        ([[1, 0.5, 0.5], [1, 0.5, 0.5], [1, -0.5, -0.5]], (1, 0, 0), "coincide"),
        ([[1, 0, 0], [-1, 0, 0], [0, 1, 0]], (0, 0, 1), "antipodal"),
        ([[1, 0, 0], [0, 1, 0], [-1, 0.01, 0], [0, -1, 0]], (0, 0, 1), "great circle"),
        # a bow tie: edges 0-1 and 2-3 cross
        (
            [[1, 0.5, 0.5], [1, -0.5, -0.5], [1, 0.5, -0.5], [1, -0.5, 0.5]],
            (1, 0.3, 0),
            "intersects",
        ),
        ([[1, 0.5, 0.5], [1, -0.5, 0.5], [1, -0.5, -0.5], [1, 0.5, -0.5]], (1, 0.5, 0), "boundary"),
        ([[1, 0.5, 0.5], [1, -0.5, 0.5], [1, "a", -0.5]], (1, 0, 0), r"vertices\[2\]"),
    ],
)
def test_degenerate_polygons_are_rejected(vertices, interior, message):
    with pytest.raises(ConstraintError, match=message):
        JointConstraint.from_dict(_poly(vertices, interior))


def test_overlapping_collinear_edges_are_rejected():
    # the boundary doubles back along the equator: edges 1-2 and 3-4 overlap
    verts = [[0, 0, 1], [1, 0, 0], [0.8, 0.6, 0], [0.9, 0.43589, 0], [0.6, 0.8, 0], [0, 1, 0.2]]
    with pytest.raises(ConstraintError, match="intersects"):
        JointConstraint.from_dict(_poly(verts, (0.5, 0.5, 0.6)))


def test_concave_polygon_is_accepted():
    verts = [[1, 0.5, 0.5], [1, 0.0, 0.1], [1, -0.5, 0.5], [1, -0.5, -0.5], [1, 0.5, -0.5]]
    c = JointConstraint.from_dict(_poly(verts, (1, 0, -0.2)))
    assert len(c.swing.vertices) == 5


def test_malformed_yaml_names_line(tmp_path):
    path = tmp_path / "bad.yaml"
    path.write_text("name: x\nswing: {cone: {centre: [1, 0, 0], radius_deg: 45}\n")
    with pytest.raises(ConstraintError, match=r"bad.yaml: not valid YAML at line \d+"):
        load_constraint(path)


def test_missing_file_and_directory(tmp_path):
    with pytest.raises(ConstraintError, match="file not found"):
        load_constraint(tmp_path / "nope.yaml")
    with pytest.raises(ConstraintError, match="directory"):
        load_constraint(tmp_path)


def test_yaml_tags_are_not_executed(tmp_path):
    path = tmp_path / "evil.yaml"
    path.write_text("!!python/object/apply:os.system ['echo hacked']\n")
    with pytest.raises(ConstraintError, match="not valid YAML"):
        load_constraint(path)


# -- swing-dependent twist (twist.by_swing) ------------------------------------------------------
BY_SWING = """
name: table
swing:
  cone: {centre: [1, 0, 0], radius_deg: 70}
twist:
  min_deg: -60
  max_deg: 70
  by_swing:
    bandwidth_deg: 20
    points:
      - {direction: [1, 0, 0], min_deg: -50, max_deg: 40}
      - {direction: [0, 2, 0], min_deg: -20, max_deg: 70}
      - {direction: [1, 0, 1], min_deg: -60, max_deg: 10}
"""


def test_by_swing_loads_normalises_and_round_trips(tmp_path):
    c = loads_constraint(BY_SWING)
    t = c.twist.by_swing
    assert t.bandwidth_deg == 20 and len(t.directions) == 3
    np.testing.assert_allclose(t.directions[1], [0, 1, 0])
    np.testing.assert_allclose(t.directions[2], np.array([1, 0, 1]) / np.sqrt(2))
    np.testing.assert_array_equal(t.min_deg, [-50, -20, -60])
    path = tmp_path / "c.yaml"
    dump_constraint(c, path)
    again = load_constraint(path)
    assert again == c and again.twist.by_swing == t
    # the table is part of the limits: a different table is a different constraint
    other = loads_constraint(BY_SWING.replace("max_deg: 10", "max_deg: 11"))
    assert other != c
    assert "by swing    3 points, bandwidth 20 deg" in c.summary()


def test_kernel_interpolation_matches_the_formula():
    c = loads_constraint(BY_SWING)
    t = c.twist.by_swing
    rng = np.random.default_rng(0)
    d = rng.standard_normal((500, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    kappa = 1.0 / (1.0 - np.cos(np.radians(20)))
    w = np.exp(kappa * (d @ t.directions.T - 1.0))
    lo_ref = np.radians((w @ t.min_deg) / w.sum(axis=1))
    hi_ref = np.radians((w @ t.max_deg) / w.sum(axis=1))
    lo, hi = c.twist_limits_at(d)
    np.testing.assert_allclose(lo, lo_ref, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(hi, hi_ref, rtol=1e-12, atol=1e-14)
    assert t.kappa == pytest.approx(kappa, rel=1e-12)
    np.testing.assert_allclose(t.weights(d), w / w.sum(axis=1, keepdims=True), atol=1e-14)
    # within the envelope everywhere, and the single-direction twin agrees
    assert (lo >= np.radians(-60) - 1e-12).all() and (hi <= np.radians(70) + 1e-12).all()
    for i in range(20):
        one = t.limits_at_one(tuple(d[i]))
        assert one == pytest.approx((lo[i], hi[i]), abs=1e-14)
        assert c.twist_limits_at(d[i]) == pytest.approx((lo[i], hi[i]), abs=1e-14)


def test_narrow_kernel_far_from_every_point_is_still_defined():
    text = BY_SWING.replace("bandwidth_deg: 20", "bandwidth_deg: 0.5")
    t = loads_constraint(text).twist.by_swing
    far = np.array([[-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])  # every weight underflows to 0
    lo, hi = t.limits_at(far)
    assert np.isfinite(lo).all() and np.isfinite(hi).all()
    # the nearest point dominates: from -Y that is +X or the (1, 0, 1) point, not +Y
    assert math.degrees(lo[1]) < -40
    assert t.limits_at_one((0.0, -1.0, 0.0)) == pytest.approx((lo[1], hi[1]), abs=1e-12)
    # at a table point with a narrow kernel the limits are that point's
    lo0, hi0 = t.limits_at(np.array([[0.0, 1.0, 0.0]]))
    assert math.degrees(lo0[0]) == pytest.approx(-20) and math.degrees(hi0[0]) == pytest.approx(70)


def test_constant_twist_limits_at():
    c = loads_constraint(MINIMAL)
    lo, hi = c.twist_limits_at(np.array([[1.0, 0, 0], [0, 1.0, 0]]))
    np.testing.assert_array_equal(lo, [math.radians(-60)] * 2)
    np.testing.assert_array_equal(hi, [math.radians(60)] * 2)


@pytest.mark.parametrize(
    "old, new, field, message",
    [
        ("bandwidth_deg: 20", "bandwidth_deg: 0", "twist.by_swing.bandwidth_deg", r"\(0, 180\)"),
        ("bandwidth_deg: 20", "bandwidth_deg: 180", "twist.by_swing.bandwidth_deg", "180"),
        ("bandwidth_deg: 20", "bandwidth_deg: wide", "twist.by_swing.bandwidth_deg", "number"),
        ("    bandwidth_deg: 20\n", "", "twist.by_swing", "missing 'bandwidth_deg'"),
        (
            "direction: [0, 2, 0]",
            "direction: [0, 0, 0]",
            "twist.by_swing.points[1].direction",
            "zero vector",
        ),
        (
            "direction: [0, 2, 0]",
            "direction: [0, 2]",
            "twist.by_swing.points[1].direction",
            "3-vector",
        ),
        (
            "min_deg: -20, max_deg: 70",
            "min_deg: 30, max_deg: 20",
            "twist.by_swing.points[1]",
            "greater than max_deg",
        ),
        (
            "min_deg: -20, max_deg: 70",
            "min_deg: -20, max_deg: 190",
            "twist.by_swing.points[1].max_deg",
            r"\[-180, 180\]",
        ),
        (
            "min_deg: -20, max_deg: 70",
            "min_deg: -20, max_deg: 75",
            "twist.by_swing.points[1]",
            "outside the envelope",
        ),
        (
            "min_deg: -20, max_deg: 70",
            "max_deg: 70",
            "twist.by_swing.points[1]",
            "missing 'min_deg'",
        ),
    ],
)
def test_by_swing_validation_names_the_field(old, new, field, message):
    assert old in BY_SWING
    with pytest.raises(ConstraintError, match=message) as info:
        loads_constraint(BY_SWING.replace(old, new, 1), source="t.yaml")
    assert info.value.field == field
    assert str(info.value).startswith(f"t.yaml: {field}: ")


@pytest.mark.parametrize(
    "by_swing, message",
    [
        ("[]", "expected {bandwidth_deg"),
        ("{bandwidth_deg: 20, points: []}", "non-empty list"),
        ("{bandwidth_deg: 20, points: [[1, 0, 0]]}", "expected {direction"),
    ],
)
def test_by_swing_shape_errors(by_swing, message):
    text = f"twist: {{min_deg: -10, max_deg: 10, by_swing: {by_swing}}}"
    with pytest.raises(ConstraintError, match=message):
        loads_constraint(text)


def test_a_vector_whose_square_overflows_keeps_its_direction():
    """Issue 37, case 5: ``axis: [0, 0, 1e308]`` squared overflows; it normalised to zeros with
    a numpy RuntimeWarning, passed the check, and the elbow's range read 0°/0°."""
    import warnings

    from models import quaternion as Q
    from models.constraint import loads_constraint

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        c = loads_constraint("kind: hinge\nhinge: {axis: [0, 0, 1e308], min_deg: 0, "
                             "max_deg: 140}\n")
        np.testing.assert_array_equal(c.hinge.axis, [0.0, 0.0, 1.0])
        c = loads_constraint("swing: {cone: {centre: [1e308, 1e308, 0], radius_deg: 30}}\n")
        np.testing.assert_allclose(c.swing.centre, [math.sqrt(0.5), math.sqrt(0.5), 0.0])
        np.testing.assert_allclose(Q.check_vectors([[0, -1e308, 0], [3, 4, 0]]),
                                   [[0, -1, 0], [0.6, 0.8, 0]])
        np.testing.assert_allclose(Q.check_quaternions([1e308, 0, 0, 1e308], normalize=True),
                                   [math.sqrt(0.5), 0, 0, math.sqrt(0.5)])
