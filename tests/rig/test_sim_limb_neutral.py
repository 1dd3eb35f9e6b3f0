"""Neutral checkpoints of the simulated patient: periodic returns to the neutral pose."""

from __future__ import annotations

import numpy as np
import pytest

from calibration.protocol import CalibrationProtocol
from models import quaternion as Q
from models.shapes import load_shape
from rig.sim.limb import SimulatedJoint


def _angle_deg(a, b):
    return np.degrees(Q.angle(Q.multiply(Q.conjugate(a), b)))


def _rotvec(q):
    """Rotation vectors (N, 3), radians, of unit quaternions (N, 4)."""
    q = q * np.where(q[:, :1] < 0, -1.0, 1.0)
    vn = np.linalg.norm(q[:, 1:], axis=1)
    ang = 2.0 * np.arctan2(vn, q[:, 0])
    return q[:, 1:] * (ang / np.where(vn > 0, vn, 1.0))[:, None]


def _measures(limb, ts, chunk=500):
    out = []
    for i in range(0, len(ts), chunk):
        out.extend(limb.measure_many(ts[i:i + chunk]))
    q = np.stack([m.quaternions for m in out])
    g = np.stack([m.gyro for m in out])
    c = np.stack([m.calibration for m in out])
    return q, g, c


@pytest.mark.parametrize("protocol", [None, CalibrationProtocol()])
def test_off_is_bit_identical_to_a_limb_without_checkpoints(protocol):
    base = SimulatedJoint(load_shape("original"), seed=7, calibration_protocol=protocol)
    off = SimulatedJoint(load_shape("original"), seed=7, calibration_protocol=protocol,
                        neutral_every_s=0.0, neutral_hold_s=3.0, neutral_ramp_s=0.5,
                        neutral_sd_deg=5.0)
    assert off.neutral_every_s == 0.0 and off.neutral_sd_deg == 5.0
    assert off.neutral_windows(1000.0).shape == (0, 2)
    assert base.mounts == off.mounts
    t = np.arange(0.0, 120.0, 0.01)
    assert np.array_equal(base.joint(t), off.joint(t))
    assert np.array_equal(base.thorax(t), off.thorax(t))
    ts = np.arange(0.0, 60.0, 0.01)
    for a, b in zip(_measures(base, ts), _measures(off, ts), strict=True):
        assert np.array_equal(a, b)


def test_on_changes_only_the_checkpoints_and_no_random_draw():
    kw = dict(seed=11, calibration_protocol=CalibrationProtocol())
    base = SimulatedJoint(load_shape("original"), **kw)
    on = SimulatedJoint(load_shape("original"), neutral_every_s=20.0, **kw)
    assert base.mounts == on.mounts
    t = np.arange(0.0, 130.0, 0.01)
    w = on.neutral_windows(t[-1])
    near = np.zeros(len(t), bool)
    for t0, t1 in w:
        # (the gyro is taken from t and t + 1 ms)
        # (the motion's smoothing reaches two knots, 2 x smooth_s, either side)
        m = 2.0 * on.smooth_s
        near |= (t > t0 - on.neutral_ramp_s - m - 2e-3) & (t < t1 + on.neutral_ramp_s + m)
    assert near.sum() > 0 and (~near).sum() > 0
    qa, qb = base.joint(t), on.joint(t)
    assert np.array_equal(qa[~near], qb[~near])
    assert _angle_deg(qa[near], qb[near]).max() > 5.0  # the checkpoints do move the arm
    # sensor errors: the same draws, so the same measurements away from the checkpoints
    ma, mb = _measures(base, t), _measures(on, t)
    assert np.array_equal(ma[0][~near], mb[0][~near])
    assert np.array_equal(ma[1][~near], mb[1][~near])
    assert np.array_equal(ma[2], mb[2])


def test_hold_is_the_checkpoints_neutral_pose():
    sd = 2.0
    limb = SimulatedJoint(seed=5, calibration_protocol=CalibrationProtocol(),
                         neutral_every_s=20.0, neutral_sd_deg=sd)
    t = np.arange(0.0, 200.0, 0.01)
    windows = limb.neutral_windows(t[-1])
    assert len(windows) == 8
    q = limb.joint(t)
    poses = limb.neutral_poses(np.arange(1, len(windows) + 1))
    m = 2.0 * limb.smooth_s  # the motion's smoothing reaches two knots either side
    for k, (t0, t1) in enumerate(windows):
        inside = (t >= t0 + m) & (t <= t1 - m)
        assert inside.sum() >= 183
        held = q[inside]
        # constant, and the checkpoint's pose (well inside the default cone: not projected)
        assert _angle_deg(held, np.broadcast_to(held[0], held.shape)).max() < 1e-9
        assert _angle_deg(held, np.broadcast_to(poses[k], held.shape)).max() < 1e-9
        # within a few neutral_sd of the identity
        assert np.degrees(Q.angle(poses[k])) < 5.0 * sd
    # every checkpoint its own pose
    assert _angle_deg(poses[:-1], poses[1:]).min() > 1e-3


def test_neutral_poses_spread_matches_neutral_sd_and_is_deterministic():
    sd = 2.0
    limb = SimulatedJoint(seed=9, neutral_every_s=20.0, neutral_sd_deg=sd)
    k = np.arange(1, 4001)
    r = np.degrees(_rotvec(limb.neutral_poses(k)))
    # limb axis +X: axial rotation sd, the two swing components sd / 2
    np.testing.assert_allclose(r.std(axis=0), [sd, sd / 2, sd / 2], rtol=0.06)
    assert np.all(np.abs(r.mean(axis=0)) < 4.0 * np.array([sd, sd / 2, sd / 2]) / np.sqrt(len(k)))
    assert abs(np.corrcoef(r.T)[0, 1]) < 0.06
    # deterministic per seed, independent of the order of evaluation, different per seed
    again = SimulatedJoint(seed=9, neutral_every_s=20.0, neutral_sd_deg=sd)
    assert np.array_equal(again.neutral_poses([7, 3])[::-1], limb.neutral_poses([3, 7]))
    other = SimulatedJoint(seed=10, neutral_every_s=20.0, neutral_sd_deg=sd)
    assert _angle_deg(other.neutral_poses(k[:50]), limb.neutral_poses(k[:50])).min() > 1e-3
    # a Generator seed: its own seed sequence, nothing drawn from it
    g = np.random.default_rng(9)
    from_gen = SimulatedJoint(seed=g, neutral_every_s=20.0, neutral_sd_deg=sd)
    assert np.array_equal(from_gen.neutral_poses(k[:10]), limb.neutral_poses(k[:10]))
    # sd 0: the identity
    exact = SimulatedJoint(seed=9, neutral_every_s=20.0, neutral_sd_deg=0.0)
    assert np.array_equal(exact.neutral_poses(k[:10]), np.tile(Q.IDENTITY, (10, 1)))
    with pytest.raises(ValueError, match="from 1"):
        limb.neutral_poses(0)


def test_motion_is_c1_at_the_ramp_boundaries():
    limb = SimulatedJoint(seed=2, excursion=0.25, calibration_protocol=CalibrationProtocol(),
                         neutral_every_s=20.0, neutral_sd_deg=3.0)
    end = 130.0
    t = np.arange(0.0, end, 0.01)
    assert limb.oracle.is_valid(limb.raw_joint(t)).all()  # no projection: smooth everywhere
    h = 1e-4
    ramp, hold = limb.neutral_ramp_s, limb.neutral_hold_s
    jumps, speeds = [], []
    for t0, _ in limb.neutral_windows(end):
        for b in (t0 - ramp, t0, t0 + hold, t0 + hold + ramp):
            q = limb.joint(np.array([b - 2 * h, b - h, b + h, b + 2 * h]))
            rel = Q.multiply(Q.conjugate(q[[0, 2]]), q[[1, 3]])
            rel *= np.where(rel[:, :1] < 0, -1.0, 1.0)
            w_left, w_right = 2.0 * rel[:, 1:] / h  # body-frame angular velocity, rad/s
            jumps.append(np.linalg.norm(w_right - w_left))
            speeds.append(max(np.linalg.norm(w_left), np.linalg.norm(w_right)))
            assert _angle_deg(q[1:2], q[2:3])[0] < np.degrees(2 * h * 10.0)  # continuous
    assert len(jumps) == 20
    # the velocity is continuous: its change over 3 h is h-small (a C0 blend would jump by
    # the rate of the blend itself, ~0.1-1 rad/s here)
    assert max(jumps) < 1e-2
    assert max(speeds) > 0.05  # the free motion is moving at the outer ends


def test_checkpoints_start_after_the_protocol_and_its_hand_over():
    protocol = CalibrationProtocol()
    kw = dict(seed=4, calibration_protocol=protocol, protocol_start_s=2.0, blend_s=3.0)
    base = SimulatedJoint(**kw)
    limb = SimulatedJoint(neutral_every_s=8.0, **kw)
    start = 2.0 + protocol.duration_s + 3.0
    assert limb.neutral_start_s == pytest.approx(start)
    first = limb.neutral_windows(100.0)[0]
    assert first[0] - limb.neutral_ramp_s >= limb.protocol_end_s + limb.blend_s
    # protocol and hand-over exactly as without checkpoints
    t = np.arange(0.0, first[0] - limb.neutral_ramp_s - 2.0 * limb.smooth_s, 0.005)
    assert np.array_equal(base.joint(t), limb.joint(t))
    # a protocol given later (as the back-driven servo patient gets it) moves the schedule
    late = SimulatedJoint(seed=4, neutral_every_s=8.0)
    np.testing.assert_allclose(late.neutral_windows(30.0), [[8, 10], [16, 18], [24, 26]])
    late.perform_protocol(protocol, start_s=10.0)
    assert late.neutral_start_s == pytest.approx(10.0 + protocol.duration_s + 3.0)
    np.testing.assert_allclose(late.neutral_windows(60.0), [[36, 38], [44, 46], [52, 54]])


def test_neutral_windows():
    limb = SimulatedJoint(seed=0, neutral_every_s=20.0)
    assert (limb.neutral_every_s, limb.neutral_hold_s, limb.neutral_ramp_s,
            limb.neutral_sd_deg) == (20.0, 2.0, 1.5, 2.0)
    np.testing.assert_array_equal(limb.neutral_windows(100.0),
                                  [[20, 22], [40, 42], [60, 62], [80, 82]])
    np.testing.assert_array_equal(limb.neutral_windows(61.9), [[20, 22], [40, 42]])
    np.testing.assert_array_equal(limb.neutral_windows(62.0), [[20, 22], [40, 42], [60, 62]])
    for t_end in (0.0, 19.0, 21.9, -5.0):
        assert limb.neutral_windows(t_end).shape == (0, 2)
    other = SimulatedJoint(seed=0, neutral_every_s=10.0, neutral_hold_s=3.0, neutral_ramp_s=1.0,
                          calibration_protocol=CalibrationProtocol(), protocol_start_s=0.0,
                          blend_s=2.0)
    np.testing.assert_allclose(other.neutral_windows(50.0), [[27, 30], [37, 40], [47, 50]])
    # the windows are where the limb holds still (but for the smoothing's two knots each end)
    m = 2.0 * other.smooth_s
    t = np.linspace(27.0 + m, 30.0 - m, 301)
    q = other.joint(t)
    assert _angle_deg(q, np.broadcast_to(q[0], q.shape)).max() < 1e-9


@pytest.mark.parametrize(("kwargs", "needle"), [
    (dict(neutral_every_s=5.0), "neutral_every_s"),  # < 2 * 1.5 + 2 + 1
    (dict(neutral_every_s=-1.0), "neutral_every_s"),
    (dict(neutral_every_s=float("nan")), "neutral_every_s"),
    (dict(neutral_every_s=20.0, neutral_hold_s=0.0), "neutral_hold_s"),
    (dict(neutral_every_s=20.0, neutral_ramp_s=-1.0), "neutral_ramp_s"),
    (dict(neutral_sd_deg=-0.5), "neutral_sd_deg"),
    (dict(neutral_every_s=6.0, neutral_ramp_s=2.0), "neutral_every_s"),  # needs 8
])
def test_bad_neutral_arguments(kwargs, needle):
    with pytest.raises(ValueError, match=needle):
        SimulatedJoint(seed=0, **kwargs)
    assert SimulatedJoint(seed=0, neutral_every_s=6.0).neutral_every_s == 6.0  # the least


def test_sim_imu_config_patient_returns_to_neutral_every_20_s():
    from rig.record.rigio import load_config, open_rig

    cfg = load_config("sim-imu")
    assert "neutral=20" in cfg.sensors.port
    with open_rig(cfg, calibrate=True) as rig:
        limb = rig.patients[0]
        assert limb.neutral_every_s == 20.0 and limb.neutral_sd_deg == 2.0
        assert limb.calibration_protocol is not None
        w = limb.neutral_windows(limb.neutral_start_s + 45.0)
        np.testing.assert_allclose(w - limb.neutral_start_s, [[20, 22], [40, 42]])
