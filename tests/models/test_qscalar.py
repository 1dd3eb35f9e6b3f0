"""The scalar quaternion kernels agree with their vectorised twins in models.quaternion."""

from __future__ import annotations

import numpy as np
import pytest

from models import qscalar as qs
from models import quaternion as Q


def _tup(q):
    return tuple(float(v) for v in q)


def test_scalar_kernels_match_models_quaternion():
    rng = np.random.default_rng(0)
    p, q = Q.random_quaternions(200, rng), Q.random_quaternions(200, rng)
    vecs = Q.random_unit_vectors(200, rng)
    for a, b, v in zip(p, q, vecs, strict=True):
        np.testing.assert_allclose(qs.mul(_tup(a), _tup(b)), Q.multiply(a, b), atol=1e-12)
        np.testing.assert_allclose(qs.conj(_tup(a)), Q.conjugate(a), atol=0)
        np.testing.assert_allclose(qs.rotate(_tup(a), _tup(v)), Q.rotate(a, v), atol=1e-12)
        assert qs.angle(_tup(a)) == pytest.approx(float(Q.angle(a)), abs=1e-12)
        r = qs.relative(_tup(a), _tup(b))
        assert r[0] >= 0
        np.testing.assert_allclose(Q.canonical(Q.multiply(r, a)), Q.canonical(b), atol=1e-12)
        v_r = qs.log_vec(r)
        np.testing.assert_allclose(qs.exp_vec(v_r), r, atol=1e-12)
        axis = np.asarray(v_r) / np.linalg.norm(v_r)
        np.testing.assert_allclose(Q.from_axis_angle(axis, np.linalg.norm(v_r)), r, atol=1e-12)
        np.testing.assert_allclose(qs.axis_angle(_tup(axis), float(np.linalg.norm(v_r))),
                                   Q.from_axis_angle(axis, np.linalg.norm(v_r)), atol=1e-12)


def test_from_two_vectors_matches_including_antiparallel():
    rng = np.random.default_rng(1)
    a, b = Q.random_unit_vectors(200, rng), Q.random_unit_vectors(200, rng)
    pairs = [*zip(a, b, strict=True), *((x, -x) for x in a[:20]),
             (np.array([1.0, 0, 0]), np.array([-1.0, 0, 0]))]
    for x, y in pairs:
        got = qs.from_two_vectors(_tup(x), _tup(y))
        np.testing.assert_allclose(got, Q.from_two_vectors(x, y), atol=1e-9)
        np.testing.assert_allclose(qs.rotate(got, _tup(x)), y, atol=1e-9)
