"""The rotation conventions (models.quaternion) against scipy and first principles."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from models import quaternion as Q
from models.errors import QuaternionError

rng = np.random.default_rng(11)
QS = Q.random_quaternions(500, rng)
PS = Q.random_quaternions(500, rng)
VS = rng.standard_normal((500, 3))


def test_hamilton_basis_products():
    i, j, k = np.eye(4)[1], np.eye(4)[2], np.eye(4)[3]
    np.testing.assert_array_equal(Q.multiply(i, j), k)
    np.testing.assert_array_equal(Q.multiply(j, k), i)
    np.testing.assert_array_equal(Q.multiply(k, i), j)
    np.testing.assert_array_equal(Q.multiply(i, i), [-1, 0, 0, 0])


def test_scalar_first_matches_scipy():
    r = Q.to_rotation(QS)
    np.testing.assert_allclose(r.apply(VS), Q.rotate(QS, VS), atol=1e-12)
    np.testing.assert_allclose(Q.canonical(Q.from_rotation(r)), Q.canonical(QS), atol=1e-12)
    # a +90° turn about z: scalar first
    q = Q.from_axis_angle(np.array([0.0, 0, 1]), math.pi / 2)
    np.testing.assert_allclose(q, [math.cos(math.pi / 4), 0, 0, math.sin(math.pi / 4)])
    np.testing.assert_allclose(Q.rotate(q, [1, 0, 0]), [0, 1, 0], atol=1e-15)


def test_product_composes_right_to_left():
    left = Q.rotate(Q.multiply(PS, QS), VS)
    right = Q.rotate(PS, Q.rotate(QS, VS))
    np.testing.assert_allclose(left, right, atol=1e-12)
    scipy = Rotation.from_quat(PS, scalar_first=True) * Rotation.from_quat(QS, scalar_first=True)
    np.testing.assert_allclose(scipy.apply(VS), left, atol=1e-12)


def test_conjugate_inverts():
    np.testing.assert_allclose(
        Q.canonical(Q.multiply(QS, Q.conjugate(QS))), np.tile(Q.IDENTITY, (500, 1)), atol=1e-12
    )


def test_swing_twist_reconstructs_exactly_and_twist_is_about_axis():
    swing, twist = Q.swing_twist(QS)
    np.testing.assert_allclose(Q.multiply(swing, twist), QS, atol=1e-12)
    # swing has no component about the limb axis; twist has nothing else
    np.testing.assert_allclose(swing[:, 1], 0.0, atol=1e-12)
    np.testing.assert_allclose(twist[:, 2:], 0.0, atol=1e-12)
    # the swing takes +X to the limb direction
    np.testing.assert_allclose(Q.rotate(swing, Q.LIMB_AXIS), Q.rotate(QS, Q.LIMB_AXIS), atol=1e-12)
    phi = Q.twist_angle(QS)
    np.testing.assert_allclose(Q.twist_angle(-QS), phi, atol=1e-12)
    np.testing.assert_allclose(np.abs(phi), Q.angle(twist), atol=1e-9)


def test_from_two_vectors_is_minimal_and_handles_antiparallel():
    a = VS / np.linalg.norm(VS, axis=1, keepdims=True)
    b = np.roll(a, 1, axis=0)
    q = Q.from_two_vectors(a, b)
    np.testing.assert_allclose(Q.rotate(q, a), b, atol=1e-12)
    np.testing.assert_allclose(Q.angle(q), Q.angle_between(a, b), atol=1e-12)
    assert (q[:, 0] >= 0).all()
    q_anti = Q.from_two_vectors(a, -a)
    np.testing.assert_allclose(Q.rotate(q_anti, a), -a, atol=1e-12)
    # same rule for a single vector
    np.testing.assert_allclose(Q.from_two_vectors(a[0], -a[0]), q_anti[0])


def test_canonical_picks_w_nonnegative_deterministically():
    c = Q.canonical(np.vstack([QS, -QS]))
    np.testing.assert_array_equal(c[:500], c[500:])
    assert (c[:, 0] >= 0).all()
    np.testing.assert_array_equal(Q.canonical(np.array([0.0, -1, 0, 0])), [0, 1, 0, 0])


@settings(max_examples=100, deadline=None)
@given(st.floats(-math.pi, math.pi), st.floats(-1, 1), st.floats(-1, 1))
def test_twist_angle_recovers_a_pure_twist(phi, y, z):
    twist = Q.from_axis_angle(np.array([1.0, 0, 0]), phi)
    direction = np.array([1.0, y, z]) / math.sqrt(1 + y * y + z * z)
    swing = Q.from_two_vectors(np.array([1.0, 0, 0]), direction)
    q = Q.multiply(swing, twist)
    got = float(Q.twist_angle(q))
    assert min(abs(got - phi), 2 * math.pi - abs(got - phi)) < 1e-9


@pytest.mark.parametrize(
    "bad, message",
    [
        ([[1, 0, 0, 0], [np.nan, 0, 0, 0]], r"orientation\[1\] has a NaN"),
        ([[0, 0, 0, 0]], "zero norm"),
        ([[1.1, 0, 0, 0]], "not a unit quaternion"),
        (np.zeros((2, 3)), "expected shape"),
        ("abc", "not a numeric array"),
    ],
)
def test_check_quaternions_errors(bad, message):
    with pytest.raises(QuaternionError, match=message):
        Q.check_quaternions(bad)


def test_check_quaternions_normalises_only_on_request():
    np.testing.assert_allclose(Q.check_quaternions([2.0, 0, 0, 0], normalize=True), [1, 0, 0, 0])
    # rounding-level deviations (float32 sensors) are accepted and removed
    q = np.array([1.0 + 1e-7, 0, 0, 0])
    assert np.linalg.norm(Q.check_quaternions(q)) == pytest.approx(1.0, abs=1e-15)


# -- one angle-wrap convention, (-π, π], on every path ------------------------------------------
def _unit(t):
    q = np.array(t, dtype=float)
    return q / np.linalg.norm(q)


quaternion_tuples = st.tuples(*[st.floats(-1, 1, allow_nan=False) for _ in range(4)]).filter(
    lambda t: math.sqrt(sum(c * c for c in t)) > 1e-3
)


@settings(max_examples=200, deadline=None)
@given(quaternion_tuples, st.booleans())
def test_twist_angle_is_sign_independent_bit_for_bit_and_in_range(t, half_turn):
    q = _unit(t)
    if half_turn and np.linalg.norm(q[1:]) > 1e-3:  # w = 0 exactly: x != 0 is a half-turn twist
        q[0] = 0.0
        q = q / np.linalg.norm(q)
    a = float(Q.twist_angle(q))
    b = float(Q.twist_angle(-q))
    assert a == b
    assert -math.pi < a <= math.pi
    # the scalar twin: same bits for q and -q, and numpy's value to the last bit or so (numpy's
    # arctan2 and libm's atan2 may differ by an ulp); half turns are exactly +π on both
    s = Q.twist_angle1(tuple(q), (1.0, 0.0, 0.0))
    assert Q.twist_angle1(tuple(-q), (1.0, 0.0, 0.0)) == s
    assert -math.pi < s <= math.pi
    assert abs(s - a) <= 1e-15
    if q[0] == 0.0 and q[1] != 0.0:
        assert a == s == math.pi


@pytest.mark.parametrize("q", [(0.0, 1.0, 0.0, 0.0), (-0.0, -1.0, 0.0, 0.0), (0.0, -1.0, 0.0, 0.0)])
def test_half_turn_twist_is_plus_pi(q):
    q = np.array(q)
    assert Q.twist_angle(q) == math.pi
    assert Q.twist_angle1(tuple(q), (1.0, 0.0, 0.0)) == math.pi
    np.testing.assert_array_equal(Q.twist_angle(np.stack([q, -q])), [math.pi, math.pi])


@settings(max_examples=300, deadline=None)
@given(
    st.floats(-20.0, 20.0, allow_nan=False)
    | st.sampled_from([-math.pi, math.pi, 0.0, 3 * math.pi, -3 * math.pi, 2 * math.pi])
)
def test_wrap_angle_scalar_and_vector_agree(x):
    v = float(Q.wrap_angle(np.array([x]))[0])
    assert v == Q.wrap_angle1(x)
    assert -math.pi < v <= math.pi
    assert math.isclose(math.cos(v), math.cos(x), abs_tol=1e-12)
    assert math.isclose(math.sin(v), math.sin(x), abs_tol=1e-12)
    if -math.pi < x <= math.pi:
        assert v == x  # angles already in range are untouched


def test_wrap_angle_maps_minus_pi_to_plus_pi():
    np.testing.assert_array_equal(
        Q.wrap_angle(np.array([-math.pi, math.pi, 3 * math.pi, -3 * math.pi])), [math.pi] * 4
    )
    assert Q.wrap_angle1(-math.pi) == math.pi


def test_tangent_basis_is_orthonormal_and_right_handed():
    rng = np.random.default_rng(1)
    for c in Q.random_unit_vectors(50, rng):
        u, v = Q.tangent_basis(c)
        assert np.allclose([u @ u, v @ v, u @ c, v @ c, u @ v], [1, 1, 0, 0, 0], atol=1e-12)
        assert np.allclose(np.cross(u, v), c, atol=1e-12)
        assert np.allclose(u, Q.perpendicular(c), atol=1e-15)


def test_wrap_angle_mod_is_half_open_below():
    x = np.array([-math.pi, math.pi, 3 * math.pi, -0.5, 7.0])
    out = Q.wrap_angle_mod(x)
    assert out[0] == -math.pi and out[1] == -math.pi and out[2] == -math.pi
    assert np.all((out >= -math.pi) & (out < math.pi))
    assert np.allclose(np.cos(out), np.cos(x)) and np.allclose(np.sin(out), np.sin(x))
    assert Q.wrap_angle(np.array([-math.pi]))[0] == math.pi  # the other convention
