"""The steps of boundary extraction used on their own (calibration.boundary's modules)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from calibration import CalibrationError
from calibration.boundary.alpha import alpha_region, cell_means
from calibration.boundary.compare import boundary_points, inside_share
from calibration.boundary.inset import InsetSettings, dwell_depth, fast_noise, pileup_offset
from calibration.boundary.outliers import find_spikes, trajectory_links, usable_samples
from calibration.boundary.projection import Projection, centre_of
from calibration.boundary.region import RegionSettings
from calibration.boundary.simplify import simplify_around, spherical_polygon
from calibration.boundary.sparse import sparse_arcs
from calibration.boundary.twist import TwistSettings, hold_twists, twist_envelope
from models import quaternion as Q
from models.constraint import JointConstraint
from models.limits import SwingTwistTable

X = np.array([1.0, 0.0, 0.0])


def _disc(n: int, radius_deg: float) -> np.ndarray:
    """Directions (n, 3) sweeping a disc of ``radius_deg`` about +X at 50 Hz: turning at
    0.37 Hz while the radius rises and falls at 0.013 Hz (smooth motion, recording order)."""
    t = np.arange(n) / 50.0
    ang = 2.0 * math.pi * 0.37 * t
    r = radius_deg * np.sqrt(0.5 + 0.5 * np.sin(2.0 * math.pi * 0.013 * t))
    return Projection.about(X).inverse(np.column_stack((r * np.cos(ang), r * np.sin(ang))))


def test_projection_round_trip_and_exact_distance_from_the_centre():
    rng = np.random.default_rng(2)
    d = Q.random_unit_vectors(2000, rng)
    d = d[d @ X > -0.5]
    proj = Projection.about(centre_of(np.vstack((d, np.tile(X, (len(d), 1))))))
    p = proj.forward(d)
    assert np.allclose(proj.inverse(p), d, atol=1e-12)
    assert np.allclose(np.hypot(p[:, 0], p[:, 1]), np.degrees(Q.angle_between(d, proj.centre)))
    with pytest.raises(CalibrationError, match="no clear centre"):
        centre_of(np.vstack((X, -X)))


def test_usable_samples_drop_low_status_and_check_times():
    q = np.tile(Q.IDENTITY, (200, 1))
    status = np.full(200, 0xFF)
    status[:50] = 0x40
    u = usable_samples(q, status, np.arange(200.0))
    assert (u.n_samples, u.n_status_dropped, len(u.q), len(u.t)) == (200, 50, 150, 150)
    with pytest.raises(CalibrationError, match="at least 100 usable samples"):
        usable_samples(q, np.full(200, 0x40))
    with pytest.raises(CalibrationError, match="non-decreasing"):
        usable_samples(q, t=np.arange(200.0)[::-1])


def test_a_one_sample_glitch_is_a_spike_and_fast_motion_is_not():
    t = np.arange(500) / 50.0
    ang = np.radians(30.0 * np.sin(t))  # at most 30°/s
    d = np.column_stack((np.cos(ang), np.sin(ang), np.zeros_like(ang)))
    assert trajectory_links(d, t, 3000.0).all()
    assert not find_spikes(d, t, 3000.0, 2).any()
    d[200] = [0.0, 0.0, 1.0]  # 90° away and back within 40 ms
    spikes = find_spikes(d, t, 3000.0, 2)
    assert np.flatnonzero(spikes).tolist() == [200]
    assert np.flatnonzero(~trajectory_links(d, None, 3000.0)).tolist() == [199, 200]


def test_noise_and_envelope_depth_estimators():
    rng = np.random.default_rng(4)
    smooth = np.column_stack((np.sin(np.arange(5000) / 200.0),) * 2)
    assert fast_noise(smooth) == 0.0  # motion, not noise
    noisy = smooth + rng.normal(0.0, 0.3, smooth.shape)
    assert fast_noise(noisy) == pytest.approx(0.3, rel=0.1)
    depth = np.abs(rng.normal(2.0, 0.2, 5000))  # a ridge 2° inside the envelope
    assert pileup_offset(depth, 10.0, 0.2, 2.0) == pytest.approx(2.0, abs=0.2)
    dwell = np.concatenate([np.full(30, 1.5), np.full(5, 20.0)] * 6)
    assert dwell_depth(dwell, 10.0, 20, 3.0) == (6, 1.5)


def test_swing_region_simplified_around_it_holds_the_samples():
    d = _disc(6000, 30.0)
    proj = Projection.about(centre_of(d))
    p = proj.forward(d)
    cells = cell_means(p, 0.5)
    assert cells.counts.sum() == len(p)
    swing = alpha_region(p, trajectory_links(d, None, 3000.0), RegionSettings(),
                         InsetSettings(), noise_deg=fast_noise(p))
    assert swing.n_glitch_cluster == 0 and swing.coverage >= 0.995
    verts2d = simplify_around(swing.region, 0.3, 0.01, 32)
    assert len(verts2d) <= 32
    polygon = spherical_polygon(verts2d, proj)
    c = JointConstraint.polygon(polygon.vertices, polygon.interior)
    assert inside_share(c, d).share >= 0.999
    # and it claims nothing far beyond the disc
    assert math.degrees(Q.angle_between(polygon.vertices, X).max()) < 32.0
    # the rim was visited throughout: no sparse arc
    assert sparse_arcs(polygon.vertices, d, 3.0, 10) == []
    half = d[d[:, 1] > 0.0]
    arcs = sparse_arcs(polygon.vertices, half, 3.0, 10)
    assert sum(a.length_deg for a in arcs) > 0.3 * boundary_points(polygon.vertices)[1].sum()


def test_twist_envelope_and_a_table_held_by_the_linear_programme():
    rng = np.random.default_rng(6)
    phi = np.radians(rng.uniform(-20.0, 40.0, 3000))
    env = twist_envelope(phi, TwistSettings(enabled=False))
    assert env.min_deg == pytest.approx(math.degrees(phi.min()), abs=1e-9)
    assert env.max_deg == pytest.approx(math.degrees(phi.max()), abs=1e-9)
    across = Q.wrap_angle(np.radians(rng.uniform(170.0, 200.0, 3000)))  # across ±180°
    env = twist_envelope(across, TwistSettings(enabled=False))
    assert env.max_deg - env.min_deg <= 30.0 and 180.0 in (env.max_deg, -env.min_deg)
    # a table too narrow for the recorded twists is widened until it holds them
    dirs = Projection.about(X).inverse(np.array([[-15.0, 0.0], [15.0, 0.0], [0.0, 15.0]]))
    d = Projection.about(X).inverse(rng.uniform(-15.0, 15.0, (400, 2)))
    tw = 20.0 * (d @ dirs[0])  # 15-20°, more towards the first direction
    lo0, hi0 = np.zeros(3), np.full(3, 5.0)
    lo, hi = hold_twists(dirs, lo0, hi0, 20.0, d, tw, -30.0, 30.0)
    assert (lo0 == 0.0).all() and (hi0 == 5.0).all()  # inputs untouched
    got_lo, got_hi = SwingTwistTable(20.0, dirs, lo, hi).limits_at(d)
    assert (np.degrees(got_hi) >= tw).all() and (np.degrees(got_lo) <= tw).all()
    assert (hi <= 30.0).all() and (lo <= hi).all()
