"""Raw sensor physics of the simulated patient: accelerometer and magnetometer."""

from __future__ import annotations

import math

import numpy as np
import pytest

from calibration.protocol import CalibrationProtocol
from models import quaternion as Q
from rig.sim.limb import GRAVITY, NoiseModel, SimulatedJoint

_UP = np.array([0.0, 0.0, 1.0])


def _stack(ms, name):
    return np.stack([getattr(m, name) for m in ms])


def _angle_deg(a, b):
    return np.degrees(Q.angle(Q.multiply(Q.conjugate(a), b)))


def _triad(accel, mag):
    """Sensor-to-world quaternions (N, 4) from accelerometer (up) and magnetometer (north
    = world +Y) readings (N, 3), sensor frame."""
    up = accel / np.linalg.norm(accel, axis=-1, keepdims=True)
    east = np.cross(mag, up)  # world +X
    east /= np.linalg.norm(east, axis=-1, keepdims=True)
    north = np.cross(up, east)
    rows = np.stack((east, north, up), axis=-2)  # world axes in the sensor frame: R^T rows
    from scipy.spatial.transform import Rotation

    return Q.from_rotation(Rotation.from_matrix(rows))


def _dip_deg(mag, up_sensor):
    return np.degrees(np.arcsin(-np.sum(mag * up_sensor, axis=-1)
                                / np.linalg.norm(mag, axis=-1)))


def test_noise_model_raw_fields():
    nz = NoiseModel()
    assert (nz.field_ut, nz.dip_deg, nz.accel_noise, nz.mag_noise_ut) == (48.0, 64.0, 0.02, 0.5)
    np.testing.assert_allclose(nz.earth_field, 48.0 * np.array(
        [0.0, math.cos(math.radians(64.0)), -math.sin(math.radians(64.0))]))
    ideal = NoiseModel.ideal()
    assert ideal.accel_noise == 0.0 and ideal.mag_noise_ut == 0.0 and ideal.field_ut == 48.0
    for kw in (dict(accel_noise=-1.0), dict(mag_noise_ut=-0.1), dict(field_ut=-1.0),
               dict(dip_deg=91.0)):
        with pytest.raises(ValueError, match=next(iter(kw))):
            NoiseModel(**kw)
    with pytest.raises(ValueError, match="limb_lever_m"):
        SimulatedJoint(seed=0, limb_lever_m=-0.1)


@pytest.mark.parametrize("noise", [NoiseModel.ideal(), NoiseModel()])
def test_at_rest_the_accelerometer_reads_gravity_and_the_magnetometer_the_field(noise):
    protocol = CalibrationProtocol()
    limb = SimulatedJoint(seed=3, sway_deg=0.0, noise=noise, calibration_protocol=protocol,
                         protocol_start_s=2.0)
    # neutral pose until the protocol's static phase ends: the patient stands still (up to
    # the motion's smoothing, which starts moving two knots, 2 x smooth_s, before the end)
    ts = np.arange(0.0, 2.0 + protocol.static_s - 2.0 * limb.smooth_s, 0.01)
    ms = limb.measure_many(ts)
    acc, mag = _stack(ms, "accel"), _stack(ms, "mag")
    assert acc.shape == mag.shape == (len(ts), 2, 3)
    q = np.stack([m.truth.sensors[0] for m in ms])  # (N, S, 4)
    up = Q.rotate(Q.conjugate(q), np.broadcast_to(_UP, acc.shape))
    tol = 0.0 if noise.accel_noise == 0 else 5.0 * noise.accel_noise
    err = np.abs(acc - GRAVITY * up)
    assert err.max() <= tol + 1e-9
    if tol:  # the white noise is there, with its standard deviation
        assert np.std(acc - GRAVITY * up) == pytest.approx(noise.accel_noise, rel=0.1)
    # magnetometer: norm and dip of the earth field (no disturbance: ideal, or noise averaged)
    norm = np.linalg.norm(mag, axis=-1)
    dip = _dip_deg(mag, up)
    if noise.mag_noise_ut == 0:
        np.testing.assert_allclose(norm, noise.field_ut, rtol=1e-12)
        np.testing.assert_allclose(dip, noise.dip_deg, atol=1e-9)
    else:
        assert abs(np.median(norm) - noise.field_ut) < 0.1
        assert abs(np.median(dip) - noise.dip_deg) < 0.2


def test_field_norm_and_dip_hold_during_motion_and_disturbances():
    nz = NoiseModel(white_deg=0.0, drift_heading_deg=0.0, drift_tilt_deg=0.0,
                    gyro_bias_dps=0.0, gyro_noise_dps=0.0, accel_noise=0.0, mag_noise_ut=0.0,
                    disturbance_rate_hz=0.2, field_ut=50.0, dip_deg=-30.0)
    limb = SimulatedJoint(seed=8, noise=nz)
    ms = limb.measure_many(np.arange(0.0, 60.0, 0.02))
    mag = _stack(ms, "mag")
    q = np.stack([m.truth.sensors[0] for m in ms])
    up = Q.rotate(Q.conjugate(q), np.broadcast_to(_UP, mag.shape))
    np.testing.assert_allclose(np.linalg.norm(mag, axis=-1), 50.0, rtol=1e-12)
    np.testing.assert_allclose(_dip_deg(mag, up), -30.0, atol=1e-9)


def test_ideal_accel_and_mag_give_the_devices_orientation_by_triad():
    # sensors at their pivots (no lever arm: no linear acceleration), no fusion drift or noise,
    # magnetic disturbances on: TRIAD of accel and mag is what the device's fusion reports
    nz = NoiseModel(white_deg=0.0, drift_heading_deg=0.0, drift_tilt_deg=0.0,
                    gyro_bias_dps=0.0, gyro_noise_dps=0.0, accel_noise=0.0, mag_noise_ut=0.0,
                    calibration_time_s=0.0, disturbance_rate_hz=0.2, disturbance_deg=10.0)
    limb = SimulatedJoint(seed=5, noise=nz, sensors=3, limb_lever_m=0.0, thorax_lever_m=0.0)
    ms = limb.measure_many(np.arange(0.0, 90.0, 0.01))
    acc, mag = _stack(ms, "accel"), _stack(ms, "mag")
    np.testing.assert_allclose(np.linalg.norm(acc, axis=-1), GRAVITY, rtol=1e-9)
    device = _stack(ms, "quaternions")
    truth = np.stack([m.truth.sensors[0] for m in ms])
    triad = _triad(acc.reshape(-1, 3), mag.reshape(-1, 3)).reshape(device.shape)
    assert _angle_deg(triad, device).max() < 0.1
    # ... which differs from the truth by the disturbances, present in this recording
    assert _angle_deg(triad, truth).max() > 3.0


def test_a_disturbance_shows_in_mag_exactly_when_in_the_device_heading():
    nz = NoiseModel(white_deg=0.0, drift_heading_deg=0.0, drift_tilt_deg=0.0,
                    gyro_bias_dps=0.0, gyro_noise_dps=0.0, accel_noise=0.0, mag_noise_ut=0.0,
                    calibration_time_s=0.0, disturbance_rate_hz=0.1)
    limb = SimulatedJoint(seed=12, noise=nz)
    ms = []
    for t in np.arange(0.0, 120.0, 0.05):  # the single-sample path too
        ms.append(limb.measure(t))
    mag = _stack(ms, "mag")
    q = np.stack([m.truth.sensors[0] for m in ms])
    undisturbed = Q.rotate(Q.conjugate(q), np.broadcast_to(nz.earth_field, mag.shape))
    # the device's heading error: measured = exp(h z) ⊗ truth
    err = Q.multiply(_stack(ms, "quaternions"), Q.conjugate(q))
    heading = 2.0 * np.arctan2(err[..., 3], err[..., 0])
    heading = (heading + math.pi) % (2.0 * math.pi) - math.pi
    # the magnetometer's departure from the undisturbed field: the horizontal field turned by
    # the same angle, so its chord is 2 |m_h| |sin(h / 2)| — zero exactly when h is
    horiz = nz.field_ut * math.cos(math.radians(nz.dip_deg))
    chord = np.linalg.norm(mag - undisturbed, axis=-1)
    want = 2.0 * horiz * np.abs(np.sin(heading / 2))
    np.testing.assert_allclose(chord, want, atol=1e-9)
    assert np.array_equal(chord > 1e-6, want > 1e-6)
    assert (np.degrees(np.abs(heading)) > 1.0).sum() > 50  # disturbances happened
    assert (chord < 1e-9).sum() > 100  # and undisturbed stretches


def test_accelerometer_sees_the_lever_arms_linear_acceleration():
    nz = NoiseModel.ideal()
    limb = SimulatedJoint(seed=4, noise=nz, excursion=0.25, speed=3.0)
    assert limb.limb_lever_m == 0.15 and limb.thorax_lever_m == 0.3
    ts = np.arange(1.0, 30.0, 0.05)
    ms = limb.measure_many(ts)
    acc = _stack(ms, "accel")
    # independent: positions from the public truth, second difference with a 10 ms step
    h = 0.01

    def pos(t):
        st = limb.truth(t)
        arm = Q.rotate(Q.multiply(st.thorax, st.joint), limb.limb_lever_m * limb.limb_axis)
        trunk = Q.rotate(st.thorax, np.array([-limb.thorax_lever_m, 0.0, 0.0]))
        return np.stack((trunk, arm), axis=1)

    a_lin = (pos(ts + h) - 2.0 * pos(ts) + pos(ts - h)) / h**2
    q = np.stack([m.truth.sensors[0] for m in ms])
    want = Q.rotate(Q.conjugate(q), a_lin + GRAVITY * _UP)
    assert np.abs(acc - want).max() < 0.01
    assert np.linalg.norm(a_lin[:, 1], axis=-1).max() > 0.3  # the arm does accelerate


def test_existing_draws_do_not_change_and_batching_does_not_matter():
    a = SimulatedJoint(seed=21)
    b = SimulatedJoint(seed=21)
    ts = np.arange(0.0, 5.0, 0.01)
    one = a.measure_many(ts)
    parts = []
    for i in range(0, len(ts), 37):
        parts.extend(b.measure_many(ts[i:i + 37]))
    for name in ("quaternions", "gyro", "accel", "mag", "calibration"):
        assert np.array_equal(_stack(one, name), _stack(parts, name))
