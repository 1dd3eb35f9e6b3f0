"""Coverage of the swing sphere (calibration.coverage) as the recorder shows it live
(rig.record.display), on seeded simulated-limb motion."""

from __future__ import annotations

import io
import math

import numpy as np
import pytest

from calibration.coverage import CoverageMap
from calibration.joint_angles import from_angles
from models import quaternion as Q
from models.constraint import JointConstraint
from models.geometry import fibonacci_sphere
from rig.record.display import PlainDisplay, RecordStatus, make_display, progress_line, render
from rig.record.guided import AnglesReached
from rig.sim.limb import NoiseModel, SimulatedJoint


def ConeRange(centre=(1.0, 0.0, 0.0), radius_deg=60.0, twist_deg=(-45.0, 45.0)):
    return JointConstraint.cone(centre, radius_deg, twist=twist_deg)


def _feed(cov: CoverageMap, limb: SimulatedJoint, seconds: float, rate: float = 50.0,
          t0: float = 0.0) -> None:
    t = t0 + np.arange(0.0, seconds, 1.0 / rate)
    for k in range(0, len(t), 50):
        cov.add(limb.joint(t[k:k + 50]), t[k:k + 50])
        cov.summary()  # as the recorder does a few times a second: the stability history


def test_fibonacci_sphere_is_nearly_uniform():
    p = fibonacci_sphere(4096)
    assert np.allclose(np.linalg.norm(p, axis=1), 1.0)
    assert np.linalg.norm(p.mean(axis=0)) < 1e-3
    # nearest-neighbour spacing ~ sqrt(4π/N): no clumps, no holes
    from scipy.spatial import cKDTree

    d, _ = cKDTree(p).query(p, k=2)
    nn = np.degrees(d[:, 1])
    assert 2.0 < nn.min() and nn.max() < 4.5


def test_cone_patient_covered_to_its_radius_and_sufficient():
    limb = SimulatedJoint(ConeRange(centre=(1, 0, 0), radius_deg=50, twist_deg=(-30, 40)),
                         seed=3, noise=NoiseModel.ideal())
    cov = CoverageMap(sectors=8, min_boundary_samples=50)
    _feed(cov, limb, 300.0)
    s = cov.summary()
    assert s.sufficient and s.explored == 8
    assert Q.angle_between(s.centre, np.array([1.0, 0.0, 0.0])) < math.radians(3)
    reach = np.array([sec.reach_deg for sec in s.sectors])
    # cells are ~3.2° apart: reach is the farthest occupied cell's angle
    assert np.all(np.abs(reach - 50.0) < 3.5), reach
    assert s.twist_deg[0] == pytest.approx(-30.0, abs=0.5)
    assert s.twist_deg[1] == pytest.approx(40.0, abs=0.5)
    d = s.as_dict()
    assert d["sufficient"] is True and len(d["sectors"]) == 8


def test_one_sided_motion_is_not_sufficient_and_says_where():
    limb = SimulatedJoint(ConeRange(centre=(1, 0, 0), radius_deg=50), seed=4,
                         noise=NoiseModel.ideal())
    # the sectors' centre from the rig configuration (the joint's usual centre)
    cov = CoverageMap(sectors=8, min_boundary_samples=50, centre=(1, 0, 0))
    t = np.arange(0.0, 300.0, 1.0 / 50)
    q = limb.joint(t)
    d = Q.rotate(q, np.array([1.0, 0.0, 0.0]))
    keep = d[:, 1] > 0.05  # the patient never moved towards -Y
    for k in range(0, len(t), 50):
        sl = slice(k, k + 50)
        cov.add(q[sl][keep[sl]], t[sl][keep[sl]] if keep[sl].any() else None)
        cov.summary()
    s = cov.summary()
    assert not s.sufficient
    unexplored = [sec for sec in s.sectors if not sec.explored]
    assert unexplored and len(unexplored) < len(s.sectors)
    # the unexplored sectors are the -Y side (azimuth measured about +X from the tangent basis)
    u = np.cross([1.0, 0, 0], np.eye(3)[int(np.argmin(np.abs([1.0, 0, 0])))])
    for sec in unexplored:
        mid = math.radians(0.5 * sum(sec.azimuth_deg))
        v = np.cross([1.0, 0, 0], u / np.linalg.norm(u))
        direction = math.cos(mid) * u / np.linalg.norm(u) + math.sin(mid) * v
        assert direction[1] < 0.5, sec


def test_growing_reach_is_not_stable():
    # a patient still pushing further out: the reach grows over the settle window
    cov = CoverageMap(sectors=4, settle_s=10.0, min_boundary_samples=1)
    for k in range(60):
        t = float(k)
        radius = math.radians(10.0 + k)  # 1°/s outward, all around
        az = np.linspace(0, 2 * math.pi, 40, endpoint=False)
        d = np.stack((np.full_like(az, math.cos(radius)), math.sin(radius) * np.cos(az),
                      math.sin(radius) * np.sin(az)), axis=1)
        q = Q.from_two_vectors(np.array([1.0, 0.0, 0.0]), d)
        cov.add(np.repeat(q, 3, axis=0), np.full(3 * len(q), t))
        s = cov.summary()
    assert not any(sec.stable for sec in s.sectors)
    assert not s.sufficient


def test_outlier_cells_do_not_claim_range():
    limb = SimulatedJoint(ConeRange(radius_deg=30), seed=5, noise=NoiseModel.ideal())
    cov = CoverageMap(sectors=6, min_count=3)
    _feed(cov, limb, 120.0)
    before = [sec.reach_deg for sec in cov.summary().sectors]
    # two isolated glitches far outside the range (e.g. a magnetic disturbance)
    glitch = Q.from_two_vectors(np.array([1.0, 0, 0]), np.array([0.0, 1.0, 0.0]))
    cov.add(np.stack([glitch, glitch]), np.array([120.0, 120.0]))
    after = [sec.reach_deg for sec in cov.summary().sectors]
    assert after == before


def test_plain_and_live_display_show_the_verdict():
    limb = SimulatedJoint(ConeRange(radius_deg=40), seed=6, noise=NoiseModel.ideal())
    cov = CoverageMap(sectors=6, min_boundary_samples=20)
    _feed(cov, limb, 200.0)
    st = RecordStatus(patient="P-017", phase="recording", elapsed_s=200.0, samples=10000,
                      rate_hz=50.0, dropped=0, coverage=cov.summary(),
                      annotations=[(12.0, "pain at the limit")])
    line = progress_line(st)
    assert "COVERAGE SUFFICIENT" in line and "explored=6/6" in line and "dropped=0" in line
    out = io.StringIO()
    PlainDisplay(out).update(st, force=True)
    assert "COVERAGE SUFFICIENT" in out.getvalue()
    from rich.console import Console

    console = Console(file=io.StringIO(), width=120, record=True, force_terminal=False)
    console.print(render(st))
    text = console.export_text()
    assert "COVERAGE SUFFICIENT" in text and "P-017" in text and "pain at the limit" in text
    assert "explored" in text
    # without a terminal, auto picks plain lines
    assert isinstance(make_display("auto", io.StringIO()), PlainDisplay)


def test_display_says_what_is_missing():
    cov = CoverageMap(sectors=4)
    st = RecordStatus(patient="P-1", phase="recording", coverage=cov.summary())
    assert "coverage incomplete" in progress_line(st)
    from rich.console import Console

    console = Console(file=io.StringIO(), width=120, record=True)
    console.print(render(st))
    assert "not visited" in console.export_text()


def test_the_swing_map_cells_are_the_sectors_own():
    # the web app's swing map (CoverageMap.reached) draws the cells the sectors are cut from:
    # each sector's reach is the farthest of its cells
    rng = np.random.default_rng(4)
    axis = Q.LIMB_AXIS
    ax = rng.normal(size=(3000, 3)) * [0.2, 1.0, 1.0]
    ax /= np.linalg.norm(ax, axis=1, keepdims=True)
    q = Q.from_axis_angle(ax, np.radians(rng.uniform(0, 70, 3000)))
    cov = CoverageMap(centre=axis, min_count=1)
    cov.add(q, np.linspace(0.0, 30.0, len(q)))
    summary = cov.summary()
    cells = cov.reached()
    assert cells.shape == (int((cov.counts_ >= 1).sum()), 2)
    k = np.minimum((cells[:, 0] / 360.0 * len(summary.sectors)).astype(int),
                   len(summary.sectors) - 1)
    for s in summary.sectors:
        assert cells[k == s.index, 1].max() == pytest.approx(s.reach_deg)


def test_a_limbs_other_joints_report_the_movements_reached():
    # held at each end (the median filter, as the recorded range of motion's, keeps a hold)
    flex = np.r_[np.linspace(0.0, 120.0, 40), np.full(10, 120.0), np.linspace(120.0, -5.0, 40),
                 np.full(10, -5.0)]
    q = from_angles(flex, np.zeros(100), np.zeros(100), "elbow", "right")
    got = AnglesReached("right")
    got.add({"elbow": q[:60]})
    assert got.peaks()["elbow"]["flexion"] == pytest.approx(120.0, abs=0.5)
    got.add({"elbow": q[60:], "shoulder": q[:5]})  # the proximal joint is the coverage's
    peaks = got.peaks()
    assert set(peaks) == {"elbow"}
    assert peaks["elbow"]["extension"] == pytest.approx(5.0, abs=0.5)
    assert peaks["elbow"]["flexion"] == pytest.approx(120.0, abs=0.5)
