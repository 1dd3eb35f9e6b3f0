"""Boundary extraction on simulated patients (servo path: fast and exact ground truth)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from calibration import BoundaryExtractor, CalibrationError, boundary_distance, outside_fraction
from models import quaternion as Q
from models.constraint import JointConstraint, loads_constraint
from models.oracle import ConstraintOracle

X = np.array([1.0, 0.0, 0.0])


@pytest.fixture(scope="module")
def extracted(servo_patient):
    c, rec = servo_patient
    return c, rec, BoundaryExtractor().fit(rec.limb, provenance={"file": "test"})


def test_boundary_and_twist_match_the_truth(extracted):
    c, rec, ex = extracted
    d = boundary_distance(ex.constraint_, c)
    assert d["mean_deg"] < 1.0
    assert outside_fraction(ex.constraint_, Q.rotate(rec.truth, X), 1.0) < 0.002
    assert ex.twist_deg_[0] == pytest.approx(c.twist.min_deg, abs=1.5)
    assert ex.twist_deg_[1] == pytest.approx(c.twist.max_deg, abs=1.5)
    assert 3 <= len(ex.vertices_) <= ex.max_vertices


def test_the_concave_notch_is_kept(extracted):
    c, _, ex = extracted
    truth = ConstraintOracle(JointConstraint.from_dict(
        {"name": "t", "swing": c.swing.to_dict()}))
    got = ConstraintOracle(JointConstraint.from_dict(
        {"name": "g", "swing": ex.constraint_.swing.to_dict()}))
    # directions inside the truth's spherical convex hull (between neighbouring vertices across
    # the notch) but outside the truth: the notch. They must be outside the extraction too.
    v = c.swing.vertices
    mids = []
    for i in range(len(v)):
        for k in (3, 4, 5, 6):
            m = v[i] + v[(i + k) % len(v)]
            mids.append(m / np.linalg.norm(m))
    mids = np.array(mids)
    notch = mids[truth.swing_distance(mids) > math.radians(3.0)]
    assert len(notch) > 0, "the test patient has a notch"
    assert np.mean(got.swing_distance(notch) > 0) > 0.9


def test_constraint_file_round_trips_with_provenance(extracted):
    _, rec, ex = extracted
    text = ex.constraint_.to_yaml()
    again = loads_constraint(text)
    assert again == ex.constraint_
    prov = again.provenance
    assert prov["samples"] == len(rec.limb)
    assert prov["file"] == "test"
    assert prov["parameters"]["alpha_deg"] == ex.alpha_deg


def test_isolated_spikes_are_dropped_and_nothing_else(servo_patient):
    # sensor glitches: one or two samples turned 70-180° off the limb's orientation, here and
    # there in a 50 Hz recording — 3,500°/s or more, and back: no limb moves like that
    c, rec = servo_patient
    rng = np.random.default_rng(3)
    q = rec.limb.copy()
    at = rng.choice(np.arange(10, len(q) - 10, 7), len(q) // 400, replace=False)
    glitch = np.concatenate([a + np.arange(1 + k % 2) for k, a in enumerate(at)])
    axis = Q.random_unit_vectors(len(glitch), rng)
    axis -= (axis @ X)[:, None] * X  # turn the limb axis itself, not just about it
    turn = Q.from_axis_angle(axis / np.linalg.norm(axis, axis=1, keepdims=True),
                             np.radians(rng.uniform(70.0, 180.0, len(glitch))))
    q[glitch] = Q.multiply(q[glitch], turn)
    ex = BoundaryExtractor().fit(q, t=rec.t)
    assert ex.n_spikes_ == len(glitch)
    assert ex.constraint_.provenance["spikes"] == ex.n_spikes_
    # every other recorded sample is inside the boundary written, but for the measured noise
    # (the encoders' quantisation) taken off the envelope
    got = ConstraintOracle(JointConstraint.from_dict(
        {"name": "g", "swing": ex.constraint_.swing.to_dict()}))
    rest = np.setdiff1d(np.arange(len(q)), glitch)
    assert ex.inset_deg_ < 0.2
    outside = np.degrees(got.swing_distance(Q.rotate(q[rest], X)))
    assert outside.max() <= ex.inset_deg_ + 0.01
    assert boundary_distance(ex.constraint_, c)["mean_deg"] < 0.5


def test_a_brief_fast_excursion_is_kept(servo_patient):
    # one fast reach 30° beyond the range and back within 0.2 s (300°/s, 30 Hz): coherent
    # motion, however brief and however rare — never an outlier
    c, rec = servo_patient
    q, t = rec.limb[::2], rec.t[::2]  # 25 Hz
    d = Q.rotate(q, X)
    k = int(np.argmax(ConstraintOracle(c).swing_distance(d)))  # at the limit
    axis = np.cross(c.swing.interior, d[k])
    axis /= np.linalg.norm(axis)
    out = [Q.multiply(Q.from_axis_angle(axis, math.radians(a)), q[k]) for a in (10, 20, 30, 20,
                                                                              10)]
    q = np.concatenate((q[: k + 1], np.array(out), q[k + 1:]))
    t = np.concatenate((t[: k + 1], t[k] + 0.04 * np.arange(1, 6), t[k + 1:] + 0.24))
    ex = BoundaryExtractor().fit(q, t=t)
    assert ex.n_spikes_ == 0 and ex.n_glitch_cluster_ == 0
    assert outside_fraction(ex.constraint_, Q.rotate(np.array(out), X), 0.0) == 0.0


def test_unrecorded_range_is_not_claimed_and_sparse_arcs_are_reported(servo_patient):
    c, rec = servo_patient
    d = Q.rotate(rec.limb, X)
    centre = c.swing.interior
    side = np.cross(centre, [0.0, 0.0, 1.0])
    half = rec.limb[(d - centre) @ side < 0.0]  # the patient never moved to one side
    ex = BoundaryExtractor().fit(half)
    other = Q.rotate(rec.truth, X)
    other = other[(other - centre) @ side > 0.15]
    assert outside_fraction(ex.constraint_, other, 1.0) > 0.9
    full = BoundaryExtractor().fit(rec.limb)
    assert sum(a.length_deg for a in ex.sparse_arcs_) >= sum(
        a.length_deg for a in full.sparse_arcs_)


def test_low_status_samples_are_dropped(servo_patient):
    _, rec = servo_patient
    status = np.full(len(rec.limb), 0xFF)
    status[::2] = 0x40  # system level 1: a magnetic disturbance
    ex = BoundaryExtractor().fit(rec.limb, status=status)
    assert ex.n_status_dropped_ == (len(status) + 1) // 2


def test_swing_dependent_twist_table_follows_contract_3(extracted):
    _, rec, _ = extracted
    ex = BoundaryExtractor(by_swing=True).fit(rec.limb)
    tw = ex.constraint_.to_dict()["twist"]
    table = tw["by_swing"]
    assert set(table) == {"bandwidth_deg", "points"}
    assert len(table["points"]) >= 3
    for p in table["points"]:
        assert set(p) == {"direction", "min_deg", "max_deg"}
        assert tw["min_deg"] <= p["min_deg"] <= p["max_deg"] <= tw["max_deg"]
    assert loads_constraint(ex.constraint_.to_yaml()) == ex.constraint_


def test_too_few_samples_or_whole_sphere_are_refused():
    rng = np.random.default_rng(0)
    with pytest.raises(CalibrationError, match="at least 100"):
        BoundaryExtractor().fit(Q.random_quaternions(50, rng))
    with pytest.raises(CalibrationError):
        BoundaryExtractor().fit(Q.random_quaternions(5000, rng))


def test_boundary_distance_of_nested_cones():
    a = JointConstraint.cone((1.0, 0, 0), 40.0)
    b = JointConstraint.cone((1.0, 0, 0), 43.0)
    assert boundary_distance(a, a)["mean_deg"] == pytest.approx(0.0, abs=1e-6)
    d = boundary_distance(a, b)
    assert d["mean_deg"] == pytest.approx(3.0, abs=1e-3)
    assert d["hausdorff_deg"] == pytest.approx(3.0, abs=1e-3)


def test_slow_error_is_taken_off_only_as_far_as_it_was_measured(servo_patient):
    # a fused heading that wanders slowly (OU, 1.5°, 20 s) shifts each visit to the limit as a
    # whole: the envelope follows the outermost visits, the typical visit's closest approach
    # (step 4b) measures the shift — but only a measured slow error (the heading correction's
    # uncertainty) says it is error and not what the patient did
    import math

    c, rec = servo_patient
    clean = BoundaryExtractor().fit(rec.limb, t=rec.t)
    assert clean.inset_deg_ < 0.2 and clean.inside_ > 0.99  # clean data: kept as recorded
    n = len(rec.limb)
    rng = np.random.default_rng(3)
    a = math.exp(-(1.0 / 50.0) / 20.0)
    psi = np.zeros(n)
    xi = rng.standard_normal(n)
    for i in range(1, n):
        psi[i] = a * psi[i - 1] + math.sqrt(1.0 - a * a) * 1.5 * xi[i]
    q = Q.multiply(Q.from_axis_angle(X, np.radians(psi)), rec.limb)
    blind = BoundaryExtractor().fit(q, t=rec.t)  # no evidence of the drift
    assert blind.inset_estimates_["visit_deg"] == 0.0 and blind.inside_ > 0.99
    ex = BoundaryExtractor().fit(q, t=rec.t, slow_error_deg=1.5)
    est = ex.inset_estimates_
    assert est["visit_deg"] > est["pileup_deg"] + 0.2 and est["visit_stretches"] > 50
    assert est["slow_error_deg"] == 1.5
    assert ex.inset_deg_ == pytest.approx(est["visit_deg"], abs=1e-3)  # (rounded there)
    assert ex.constraint_.to_dict()["provenance"]["noise_inset_estimates"] == est
    # the vertices sit on the truth (median signed distance), nothing recorded is left out
    v = Q.check_vectors(ex.constraint_.swing.vertices)
    assert abs(float(np.median(np.degrees(ConstraintOracle(c).swing_distance(v))))) < 0.3
    assert boundary_distance(ex.constraint_, c)["mean_deg"] < 1.0
    assert outside_fraction(ex.constraint_, Q.rotate(rec.truth, X), 1.0) < 0.002
