"""Simulated arm and leg patients (issue 21): anatomical limb constraints, the four-sensor chain
moving inside them, offline recordings and the stream board serving one."""

from __future__ import annotations

import math

import numpy as np
import pytest

from calibration.joint_angles import from_angles, joint_angles
from calibration.protocol import LimbCalibrationProtocol
from models import quaternion as Q
from models.oracle import ConstraintOracle
from rig.errors import RigConfigError
from rig.sim.limb import NoiseModel, SimulatedWholeLimb, limb_mounts
from rig.sim.patients import anatomical_limb, record_limb_imu, seeded_patient

X = np.array([1.0, 0.0, 0.0])
Z = np.array([0.0, 0.0, 1.0])


def _neutral(limb) -> np.ndarray:
    """Every joint at its clinical zero (J, 4)."""
    return LimbCalibrationProtocol(limb.limb).joint_orientations([-1.0], limb.side)[0]


def _limit(oracle, base, j, make, step=0.25, top=180.0) -> float:
    """The largest angle (step ``step``) at which joint ``j`` posed by ``make(angles)`` is
    valid, every other joint as in ``base``."""
    a = np.arange(0.0, top, step)
    p = np.repeat(base[None], len(a), axis=0)
    p[:, j] = make(a)
    bad = np.nonzero(~oracle.is_valid(p)[:, j])[0]
    return float(a[bad[0] - 1]) if len(bad) else top


def _concave(vertices: np.ndarray) -> bool:
    """Whether a spherical polygon turns both ways (some vertex is reflex)."""
    v = np.asarray(vertices)
    turn = np.einsum("ij,ij->i", np.cross(np.roll(v, 1, axis=0), v), np.roll(v, -1, axis=0))
    return bool((turn > 0).any() and (turn < 0).any())


# -- anatomical limbs ----------------------------------------------------------------------------
@pytest.mark.parametrize("kind", ["arm", "leg"])
@pytest.mark.parametrize("side", ["right", "left"])
def test_anatomical_limbs_load_and_neutral_is_valid(kind, side):
    for seed in range(6):
        limb = anatomical_limb(seed, kind, side)
        assert (limb.name, limb.limb, limb.side) == (f"sim-{kind}-{seed}", kind, side)
        assert ConstraintOracle(limb).is_valid(_neutral(limb)).all()
        swing = limb.joints[0].coupling.keyframes[0].swing
        assert _concave(swing.vertices)
        assert len(limb.joints[0].coupling.keyframes) >= 3
    # seeded: the same seed, the same limits
    a, b = anatomical_limb(4, kind, side), anatomical_limb(4, kind, side)
    assert a.content_hash() == b.content_hash()
    assert a.content_hash() != anatomical_limb(5, kind, side).content_hash()


@pytest.mark.parametrize("side", ["right", "left"])
def test_leg_clinical_ranges(side):
    limb = anatomical_limb(7, "leg", side)
    o = ConstraintOracle(limb)
    c = limb.provenance["clinical"]
    base = _neutral(limb)

    def hip(a, b, g):
        return lambda x: from_angles(a * x, b * x, g * x, "hip", side)

    def at_knee(deg):
        p = base.copy()
        p[1] = from_angles(deg, 0, 0, "knee", side)[0]
        return p

    slr, half, full = (_limit(o, at_knee(k), 0, hip(1, 0, 0)) for k in (0, 45, 120))
    assert 60 <= slr <= 80 and 100 <= full <= 125 and slr < half < full  # the hamstrings
    assert abs(slr - c["hip"]["flexion_knee_straight"]) < 0.6
    assert abs(full - c["hip"]["flexion"]) < 0.6
    assert 10 <= _limit(o, base, 0, hip(-1, 0, 0)) <= 30  # extension
    assert 30 <= _limit(o, base, 0, hip(0, -1, 0)) <= 50  # abduction
    assert 15 <= _limit(o, base, 0, hip(0, 1, 0)) <= 30  # adduction
    assert 30 <= _limit(o, base, 0, hip(0, 0, 1)) <= 45  # internal rotation
    assert 35 <= _limit(o, base, 0, hip(0, 0, -1)) <= 50  # external rotation
    # knee: a hinge about (0, 0, -1): its angle is Grood-Suntay flexion
    knee = limb.joints[1].constraint.hinge
    assert np.allclose(knee.axis, [0, 0, -1]) and -5 <= knee.min_deg <= 0
    assert 130 <= knee.max_deg <= 150
    q = from_angles(np.array([30.0, 100.0]), 0, 0, "knee", side)
    assert np.allclose(np.degrees(Q.twist_angle(q, np.array([0.0, 0.0, -1.0]))), [30, 100])
    assert np.allclose(joint_angles(q, "knee", side)["alpha"], [30, 100])
    # ankle: the foot's +X along the shank's +Y at its neutral; dorsiflexion larger with the
    # knee bent (the gastrocnemius), plantarflexion, the toes' medial turn is inversion
    assert np.allclose(Q.rotate(from_angles(0, 0, 0, "ankle", side)[0], X), [0, 1, 0])

    def ankle(a):
        return lambda x: from_angles(a * x, 0, 0, "ankle", side)

    d0, d90 = _limit(o, at_knee(0), 2, ankle(1)), _limit(o, at_knee(90), 2, ankle(1))
    assert 10 <= d0 < d90 <= 25
    assert 40 <= _limit(o, base, 2, ankle(-1)) <= 55
    kf = limb.joints[2].coupling.keyframes[0]
    v = kf.swing.vertices
    medial, lateral = v[9], v[27]  # azimuths 90° and 270° (rig.sim.patients._swing_polygon)
    beta = [float(joint_angles(Q.from_two_vectors(X, d), "ankle", side)["beta"][0])
            for d in (medial, lateral)]
    assert beta[0] > 10 and beta[1] < -5  # inversion, eversion
    assert kf.twist.max_deg - kf.twist.min_deg <= 12  # narrow twist


@pytest.mark.parametrize("side", ["right", "left"])
def test_arm_clinical_ranges(side):
    limb = anatomical_limb(7, "arm", side)
    o = ConstraintOracle(limb)
    base = _neutral(limb)
    flip = -1.0 if side == "left" else 1.0

    def shoulder(axis):
        return lambda x: Q.from_axis_angle(axis, np.radians(x))

    def at_elbow(deg):
        p = base.copy()
        p[1] = from_angles(deg, 0, 0, "elbow", side)[0]
        return p

    assert 150 <= _limit(o, base, 0, shoulder(Z)) <= 165  # flexion about +Z
    abd_axis = np.array([0.0, -flip, 0.0])  # the arm out to the side (+Z right, -Z left)
    assert 150 <= _limit(o, base, 0, shoulder(abd_axis)) <= 165
    assert 20 <= _limit(o, base, 0, shoulder(-abd_axis)) <= 40  # adduction
    ext = [_limit(o, at_elbow(e), 0, shoulder(-Z)) for e in (0, 45, 90)]
    assert ext[0] < ext[1] < ext[2] and 40 <= ext[2] <= 60  # the biceps' long head
    elbow = limb.joints[1].constraint.hinge
    assert np.allclose(elbow.axis, [0, 0, 1]) and -5 <= elbow.min_deg <= 0
    assert 135 <= elbow.max_deg <= 150
    assert np.allclose(joint_angles(Q.from_axis_angle(Z, math.radians(70.0)), "elbow",
                                    "right")["alpha"], 70)

    def wrist(a, b):
        return lambda x: from_angles(a * x, b * x, 0, "wrist", side)

    assert 60 <= _limit(o, base, 2, wrist(1, 0)) <= 80
    assert 50 <= _limit(o, base, 2, wrist(-1, 0)) <= 70
    assert 25 <= _limit(o, base, 2, wrist(0, 1)) <= 35  # ulnar
    assert 15 <= _limit(o, base, 2, wrist(0, -1)) <= 25  # radial


# -- the chain's motion -----------------------------------------------------------------------
# The session fixtures sim_leg / sim_leg_motion (tests/conftest.py) are built on each xdist
# worker that runs a test using them: these tests join the group of the others that read them
# (tests/calibration/test_limb_boundary.py), so the leg's motion is simulated once.
SIM_LEG = pytest.mark.xdist_group("sim_leg")


@SIM_LEG
def test_chain_motion_is_valid_and_reaches_every_limit(sim_leg, sim_leg_motion):
    leg = sim_leg
    _, q = sim_leg_motion
    res = leg.oracle.evaluate(q)
    # in range, but for the B-spline's overshoot where it rounds a corner or slides along a
    # concave limit (module docstring of rig.sim.limb.whole): under 1.5°, rarely over 0.1°
    over = np.degrees(np.nan_to_num(res.distance, nan=-1.0))
    assert over.max() < 1.5 and (over > 0.1).mean() < 0.02 and (over > 0.5).mean() < 0.005
    # the knee's both ends within 2°
    knee = leg.limb.joints[1].constraint.hinge
    ang = np.degrees(Q.twist_angle(q[:, 1], np.array([0.0, 0.0, -1.0])))
    assert ang.min() < knee.min_deg + 2 and ang.max() > knee.max_deg - 2
    # the hip's boundary in every 30° sector of directions about the thigh hanging down, and
    # the ankle's
    for j, (e1, e2) in ((0, ((0, 1, 0), (0, 0, -1))), (2, ((-1, 0, 0), (0, 0, -1)))):
        d = Q.rotate(q[:, j], X)
        near = res.distance[:, j] > -math.radians(2.0)
        az = np.degrees(np.arctan2(d @ np.array(e2, float), d @ np.array(e1, float))) % 360
        assert len(np.unique(az[near] // 30)) >= 10, j
    # at the hip's flexion limit (within 2°, thigh forward) at many knee angles
    d = Q.rotate(q[:, 0], X)
    az = np.degrees(np.arctan2(-d[:, 2], d[:, 1]))
    at_flexion = (res.distance[:, 0] > -math.radians(2.0)) & (np.abs(az) < 15)
    knee_there = np.degrees(res.coupling_angle[at_flexion, 0])
    assert len(np.unique(np.clip(knee_there, 0, 135) // 15)) >= 6


@SIM_LEG
def test_chain_motion_is_smooth(sim_leg_motion):
    t, q = sim_leg_motion
    rel = Q.multiply(Q.conjugate(q[:-1]), q[1:])
    speed = np.degrees(2 * np.arccos(np.clip(np.abs(rel[..., 0]), 0, 1))) / np.diff(t)[:, None]
    assert np.percentile(speed, 99, axis=0).max() < 400  # °/s
    assert (speed > 800).mean() < 1e-3


def test_sensors_see_a_continuous_limb():
    """Arm 102 used to jump where the projection into its coupled, concave ranges switched
    branches (3,100°/s at 100 Hz, specific forces of 7,800 m/s²) and a host fusion of its raw
    samples lost the jumps (tilt 30-77° off): now the gyroscope integrates to the truth from
    sample to sample, and the accelerometer's linear acceleration averages out as a limb held
    at the shoulder must (its velocity stays bounded)."""
    chain = seeded_patient(102, "arm", noise=NoiseModel.ideal(), neutral=20.0)
    rec = record_limb_imu(chain, 100.0, 100.0)
    t = rec.t
    for k in range(1, 4):
        s = rec.sensors_true[:, k]
        w = 0.5 * (rec.gyro[:-1, k] + rec.gyro[1:, k])
        pred = Q.multiply(s[:-1], Q.from_axis_angle(
            w / np.maximum(np.linalg.norm(w, axis=1, keepdims=True), 1e-12),
            np.linalg.norm(w, axis=1) * np.diff(t)))
        step_err = np.degrees(Q.angle(Q.multiply(Q.conjugate(pred), s[1:])))
        assert step_err.max() < 0.5, (k, step_err.max())
        assert np.degrees(np.linalg.norm(rec.gyro[:, k], axis=1)).max() < 1000.0
        gravity = Q.rotate(Q.conjugate(s), np.broadcast_to([0.0, 0.0, 9.81], (len(t), 3)))
        lin = Q.rotate(s, rec.accel[:, k] - gravity)  # world frame
        mean3s = np.stack([np.convolve(lin[:, i], np.ones(300) / 300, "valid")
                           for i in range(3)], axis=1)
        assert np.linalg.norm(mean3s, axis=1).max() < 1.5, k


def test_a_jumping_target_is_followed_at_bounded_speed_around_the_range():
    """RateLimit: a target that jumps 150° is followed at the speed limit, every knot in
    range, and the values do not depend on the order they are asked in."""
    from rig.sim.limb.motion import RateLimit

    chain = SimulatedWholeLimb(anatomical_limb(11, "leg"), seed=11, noise=NoiseModel.ideal())
    neutral = _neutral(chain.limb)
    far = chain.project(np.array([[Q.from_axis_angle(Z, math.radians(150.0)), *neutral[1:]]]))
    step_s, speed = 0.04, math.radians(300.0)

    def target(ts):
        return np.where((np.asarray(ts) >= 1.0)[:, None, None], far, neutral[None])

    def limiter():
        return RateLimit(step_s, speed, chain._nearest, chain._near_range, chunk=16)

    key = object()
    ts = np.arange(0.0, 4.0, step_s)
    q = limiter()(ts, target, key)
    rel = Q.angle(Q.multiply(Q.conjugate(q[:-1]), q[1:]))
    # a step, and the projection's: within the step in the oracle's swing-and-twist metric,
    # a little more as a rotation angle
    assert rel.max() <= speed * step_s * 3.0
    assert np.allclose(q[ts < 1.0 - 1e-9], neutral) and np.allclose(q[-1], far[0])
    arrived = ts[np.all(np.isclose(np.abs(np.sum(q * far, axis=-1)), 1.0), axis=1)][0]
    apart = Q.angle(Q.multiply(Q.conjugate(neutral[0]), far[0, 0]))
    assert apart > math.radians(60.0)
    assert arrived >= 1.0 + apart / (3.0 * speed) - step_s  # no faster than the limit allows
    assert chain.oracle.is_valid(q).all()
    late_first = limiter()
    later = late_first(ts[::-1][:10], target, key)
    assert np.allclose(later, q[::-1][:10])


def test_protocol_is_followed_within_limits():
    chain = seeded_patient(5, "leg", noise=NoiseModel.ideal(), misplace_deg=0.0)
    p = chain.calibration_protocol
    assert isinstance(p, LimbCalibrationProtocol) and chain.protocol_start_s == 5.0
    w = chain.protocol_windows()
    assert set(w) == {"static", "hip", "knee", "ankle"}
    neutral = _neutral(chain.limb)
    t = np.linspace(*w["static"], 50)
    q = chain.joints(t)
    assert Q.angle_between(Q.rotate(q.reshape(-1, 4), X),
                           Q.rotate(np.tile(neutral, (50, 1)), X)).max() < math.radians(1.0)
    for i, joint in enumerate(("hip", "knee", "ankle")):
        t = np.linspace(*w[joint], 400)
        ang = [joint_angles(chain.joints(t)[:, k], n, "right")["alpha"]
               for k, n in enumerate(("hip", "knee", "ankle"))]
        flex, _ = p.amplitude(joint)
        assert ang[i].max() > 0.9 * flex  # this joint flexes
        assert all(np.abs(ang[k]).max() < 2.0 for k in range(3) if k != i)  # the others rest
    # the free motion takes over after the hand-over
    assert chain.protocol_end_s == 5.0 + p.duration_s
    late = chain.joints(np.linspace(chain.protocol_end_s + chain.blend_s, 120, 200))
    assert np.degrees(Q.angle(Q.multiply(Q.conjugate(late[:, 0]), late[1:2, 0]))).max() > 30


def test_sensors_are_root_chain_mount_and_reproducible():
    limb = anatomical_limb(2, "arm")
    mounts = limb_mounts(("thorax", "upper-arm", "forearm", "hand"),
                          np.random.default_rng(1), 20.0)
    chain = SimulatedWholeLimb(limb, sensors=mounts, seed=2, noise=NoiseModel.ideal())
    ts = np.arange(0.0, 3.0, 0.01)
    ms = chain.measure_many(ts)
    s = chain.truth(ts)
    seg = s.root
    for k in range(4):
        if k:
            seg = Q.multiply(seg, s.joints[:, k - 1])
        want = Q.multiply(seg, np.broadcast_to(np.array(mounts[k].mount), seg.shape))
        got = np.array([m.quaternions[k] for m in ms])
        assert np.degrees(Q.angle(Q.multiply(Q.conjugate(want), got))).max() < 0.02
        np.testing.assert_allclose(Q.canonical(s.sensors[:, k]), Q.canonical(want), atol=1e-12)
    acc = np.array([m.accel for m in ms])
    mag = np.array([m.mag for m in ms])
    assert np.abs(np.linalg.norm(mag, axis=-1) - 48.0).max() < 1e-6
    dev = np.abs(np.linalg.norm(acc, axis=-1) - 9.81)
    assert dev[:, 0].max() < 0.1  # the swaying thorax: g
    assert np.median(dev) < 3.0  # the limb: about g (jolts where a joint meets a limit)
    # the same seed: the same samples; another seed: others
    twin = SimulatedWholeLimb(limb, sensors=mounts, seed=2, noise=NoiseModel.ideal())
    again = twin.measure_many(ts)
    assert all(np.array_equal(a.quaternions, b.quaternions) and np.array_equal(a.accel, b.accel)
               for a, b in zip(ms, again, strict=True))


def test_offline_recording():
    chain = seeded_patient(3, "arm", side="left")
    rec = record_limb_imu(chain, 5.0, rate_hz=50.0)
    n = round((chain.protocol_end_s + 5.0) * 50)
    assert rec.quaternions.shape == (n, 4, 4) and rec.joints.shape == (n, 3, 4)
    assert rec.accel.shape == rec.gyro.shape == rec.mag.shape == (n, 4, 3)
    assert rec.segments == ("thorax", "upper-arm", "forearm", "hand")
    assert set(rec.windows) == {"static", "shoulder", "elbow", "wrist"}
    assert rec.window("elbow").sum() > 0 and rec.window("free").sum() == 5 * 50
    over = ConstraintOracle(chain.limb).evaluate(rec.joints).distance
    assert np.nanmax(over) < np.radians(1.5)  # the B-spline's brief overshoot at most
    # the same seed twice: the same recording (noise, drift, disturbances included)
    again = record_limb_imu(seeded_patient(3, "arm", side="left"), 5.0, rate_hz=50.0)
    assert np.array_equal(rec.quaternions, again.quaternions)
    assert np.array_equal(rec.mag, again.mag)


# -- on the stream board ---------------------------------------------------------------------------
def test_stream_board_serves_four_chain_sensors():
    from rig.devices.ports import open_port
    from rig.devices.stream_imu import StreamImu

    url = "sim://imu-stream?sensors=4&limb=leg&side=right&seed=3&noise=off&rate=100&flow=on"
    with open_port(url) as port, StreamImu(port, rate_hz=100, raw=True) as imu:
        assert imu.identity.present_mask == 0b1111
        chain = port.patient
        assert isinstance(chain, SimulatedWholeLimb) and chain.limb.name == "sim-leg-3"
        samples = []
        while len(samples) < 4 * 40:
            samples += imu.read(1.0)
        assert imu.dropped == 0 and imu.corrupt == 0
    assert {s.sensor for s in samples} == {0, 1, 2, 3}
    for s in samples[::7]:
        truth = chain.truth(s.device_t).sensors[0, s.sensor]
        assert np.degrees(Q.angle(Q.multiply(Q.conjugate(truth), s.q))) < 0.1
        assert np.isfinite(s.raw).all()


@pytest.mark.parametrize("query, key", [
    ("limb=hand", "limb"),
    ("limb=arm&sensors=2", "sensors"),
    ("limb=leg&side=up", "side"),
    ("side=left", "side"),
    ("limb=arm&patient=original", "patient"),
    ("limb=arm&seed=x", "seed"),
    ("limb=arm&limbs=2", "limbs"),
])
def test_bad_chain_keys_name_the_key(query, key):
    from rig.sim.imu import stream_from_url

    with pytest.raises(RigConfigError, match=f"sim://imu-stream.*{key}") as err:
        stream_from_url(f"sim://imu-stream?{query}").close()
    assert "\n" not in str(err.value)


def test_limb_file_patient(tmp_path):
    from rig.sim.imu import stream_from_url

    path = tmp_path / "leg.yaml"
    path.write_text(anatomical_limb(9, "leg", "left").to_yaml())
    with stream_from_url(f"sim://imu-stream?patient={path}&clock=manual") as sim:
        assert isinstance(sim.limb, SimulatedWholeLimb) and sim.limb.side == "left"
        assert sim.limb.n_sensors == 4


def test_shipped_configs_name_the_chain():
    from rig.devices.config import load_rig_config

    for name, segs in (("sim-arm", ("thorax", "upper-arm", "forearm", "hand")),
                       ("sim-leg", ("pelvis", "thigh", "shank", "foot"))):
        cfg = load_rig_config(name)
        assert tuple(cfg.sensors.segments) == segs
        assert [cfg.sensors.segments[s] for s in segs] == [0, 1, 2, 3]
