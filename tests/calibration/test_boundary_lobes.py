"""Boundary extraction keeps a rarely visited lobe and still drops an isolated glitch cluster."""

from __future__ import annotations

import math

import numpy as np
import pytest

from calibration import BoundaryExtractor, boundary_distance, outside_fraction
from models import quaternion as Q
from models.constraint import JointConstraint
from models.oracle import ConstraintOracle
from rig.sim.patients import record_servo, seeded_patient

X = np.array([1.0, 0.0, 0.0])
Y = np.array([0.0, 1.0, 0.0])
Z = np.array([0.0, 0.0, 1.0])
MAIN_DEG = 30.0  # main region: a disc about +X
NECK_HALF_DEG = 2.5  # the neck: 5° wide, from the disc out to the lobe
LOBE_CENTRE_DEG, LOBE_DEG = 46.0, 7.0  # the lobe: a 7° disc 46° from +X, towards +Y


def _direction(xy_deg) -> np.ndarray:
    """Unit directions of azimuthal-equidistant coordinates (deg) about +X (Y, Z tangent)."""
    xy = np.radians(np.atleast_2d(xy_deg))
    t = np.hypot(xy[:, 0], xy[:, 1])
    s = np.where(t > 0, np.sin(t) / np.where(t > 0, t, 1.0), 1.0)
    return np.cos(t)[:, None] * X + (s * xy[:, 0])[:, None] * Y + (s * xy[:, 1])[:, None] * Z


def _lobed_truth() -> JointConstraint:
    """Disc + neck + lobe, one polygon (anticlockwise in azimuthal-equidistant degrees)."""
    a = math.degrees(math.asin(NECK_HALF_DEG / MAIN_DEG))
    b = math.degrees(math.asin(NECK_HALF_DEG / LOBE_DEG))
    t_main = np.radians(np.linspace(a, 360.0 - a, 48))
    t_lobe = np.radians(np.linspace(-180.0 + b, 180.0 - b, 24))
    ring = np.concatenate((
        MAIN_DEG * np.column_stack((np.cos(t_main), np.sin(t_main))),
        [LOBE_CENTRE_DEG, 0.0] + LOBE_DEG * np.column_stack((np.cos(t_lobe), np.sin(t_lobe)))))
    return JointConstraint.polygon(_direction(ring), X, name="lobed")


def _visit(step_deg: float = 1.5) -> np.ndarray:
    """One continuous visit of the lobe: out along the neck, once round inside the lobe's
    boundary, back along the neck (directions, ``step_deg`` apart)."""
    start, tip = MAIN_DEG - 3.0, LOBE_CENTRE_DEG - LOBE_DEG + 1.5
    out = np.linspace(start, tip, round((tip - start) / step_deg) + 1)
    r = LOBE_DEG - 1.0
    n = round(2 * math.pi * r / step_deg)
    t = math.pi + np.linspace(0.0, 2 * math.pi, n + 1)
    loop = np.column_stack((LOBE_CENTRE_DEG + r * np.cos(t), r * np.sin(t)))
    path = np.concatenate((np.column_stack((out, np.zeros_like(out))), loop,
                           np.column_stack((out[::-1], np.zeros_like(out)))))
    return _direction(path)


def _swing(d: np.ndarray) -> np.ndarray:
    return Q.from_two_vectors(np.broadcast_to(X, d.shape), d)


@pytest.fixture(scope="module")
def lobed_recording():
    """300 s at 20 Hz of a patient moving about the disc (never into the neck), with one
    visit of the lobe and one burst of 40 glitches (a tight cluster 25° outside the disc, on the
    other side) spliced in."""
    disc = JointConstraint.cone(X, MAIN_DEG, twist=(-40.0, 40.0), name="disc")
    rec = record_servo(seeded_patient(11, disc, calibrate=False), 300.0, 20.0)
    base = rec.limb
    visit = _swing(_visit())
    rng = np.random.default_rng(5)
    centre = _direction([[-(MAIN_DEG + 25.0) * 0.6, -(MAIN_DEG + 25.0) * 0.8]])[0]
    jitter = np.radians(0.4) * rng.standard_normal((40, 3))
    glitch_dirs = centre + jitter - np.outer(jitter @ centre, centre)
    glitch_dirs /= np.linalg.norm(glitch_dirs, axis=1, keepdims=True)
    glitches = _swing(glitch_dirs)
    n = len(base)
    q = np.concatenate((base[: n // 3], visit, base[n // 3: 2 * n // 3], glitches,
                        base[2 * n // 3:]))
    return q, Q.rotate(visit, X), centre


def test_a_rarely_visited_lobe_is_kept_and_a_glitch_cluster_is_not(lobed_recording):
    q, visit, glitch_centre = lobed_recording
    assert len(visit) < 0.01 * len(q)  # rarely visited: under 1 % of the samples
    ex = BoundaryExtractor().fit(q)
    est = ex.constraint_
    # every direction of the visit is inside the extracted region (within 1°)
    assert outside_fraction(est, visit, 1.0) == 0.0
    # the glitch cluster is not: its centre is far outside, and it is reported
    far = ConstraintOracle(JointConstraint.from_dict(
        {"name": "s", "swing": est.swing.to_dict()})).swing_distance(glitch_centre[None])[0]
    assert math.degrees(far) > 15.0
    assert ex.n_glitch_cluster_ == 40
    assert est.provenance["glitch_cluster_samples"] == 40
    # and the region is the truth's, lobe included
    assert boundary_distance(est, _lobed_truth())["mean_deg"] < 1.5


def test_without_the_visit_the_lobe_is_not_claimed(lobed_recording):
    q, visit, _ = lobed_recording
    n = len(q) - len(visit) - 40
    base = np.concatenate((q[: n // 3], q[n // 3 + len(visit): len(q) - 40 - (n - 2 * n // 3)],
                           q[len(q) - (n - 2 * n // 3):]))
    assert len(base) == n
    ex = BoundaryExtractor().fit(base)
    lobe = visit[np.abs(np.degrees(np.arccos(np.clip(visit @ X, -1, 1))) - LOBE_CENTRE_DEG) < 3]
    assert len(lobe) > 0
    assert outside_fraction(ex.constraint_, lobe, 5.0) == 1.0
