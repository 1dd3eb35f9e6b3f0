"""Simulated IMUs: the limb model, pyserial against both simulators, and ``rig sim imu``.

Every exchange synchronises on the device's replies (serial reads with a deadline), never on
sleeps. Simulator time that matters (calibration progress, BNO055 sample instants) runs on a
manual clock where a test depends on it.
"""

from __future__ import annotations

import math
import signal
import subprocess
import sys

import numpy as np
import pytest
import serial

from firmware_protocol.imu import bno055 as B
from firmware_protocol.imu import stream as S
from models import quaternion as Q
from models.constraint import JointConstraint
from models.oracle import ConstraintOracle
from rig.errors import RigConfigError
from rig.sim.clock import ManualClock
from rig.sim.imu import Bno055Simulator, StreamImuSimulator, bno055_from_url, stream_from_url
from rig.sim.limb import NoiseModel, SensorMount, SimulatedJoint

QUIET = NoiseModel(disturbance_rate_hz=0.0, calibration_time_s=0.5)
HANG_GUARD_S = 30.0
"""Serial read timeout that only stops a broken simulator from hanging the suite (never a speed
requirement: the machine may be heavily loaded)."""
MAX_READS = 2000
"""Bound on the reads a receive loop makes before it gives up (each read waits at most the port's
timeout); a count, not a clock: pytest-timeout stops a wedged test long before it is reached."""

def _angle_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.degrees(Q.angle(Q.multiply(np.asarray(a), Q.conjugate(np.asarray(b)))))


# -- limb model (no pty) ------------------------------------------------------------------


def test_limb_is_reproducible():
    a, b = SimulatedJoint(sensors=3, seed=5), SimulatedJoint(sensors=3, seed=5)
    t = np.linspace(0.0, 10.0, 50)
    np.testing.assert_array_equal(a.truth(t).sensors, b.truth(t).sensors)
    for ti in t:
        np.testing.assert_array_equal(a.measure(ti).quaternions, b.measure(ti).quaternions)
    assert not np.allclose(SimulatedJoint(seed=6).joint(t), a.joint(t))


def test_limb_sweeps_to_and_along_the_cone_limit():
    rom = JointConstraint.cone((1, 0, 0), 50.0, twist=(-30.0, 40.0))
    limb = SimulatedJoint(rom, seed=2)
    t = np.arange(0.0, 120.0, 0.02)
    q = limb.joint(t)
    swing = np.degrees(Q.angle_between(Q.rotate(q, Q.LIMB_AXIS), limb.centre))
    twist = np.degrees(Q.twist_angle(q))
    assert swing.max() <= 50.0 + 1e-6 and swing.max() > 49.99
    assert 0.1 < np.mean(swing > 49.99) < 0.6  # a good part of the time on the limit
    assert twist.min() >= -30.0 - 1e-6 and twist.max() <= 40.0 + 1e-6
    assert np.mean(twist > 39.99) > 0.05 and np.mean(twist < -29.99) > 0.05
    # smooth, human-like: peak angular speed below 400 °/s
    step = _angle_deg(q[1:], q[:-1]) / 0.02
    assert step.max() < 400.0


def test_limb_with_constraint_oracle():
    c = JointConstraint.polygon(
        [[0.6, 0.8, 0.0], [0.6, 0.0, 0.8], [0.6, -0.8, 0.0], [0.8, 0.0, -0.6]],
        interior=[1, 0, 0], twist=(-20, 50))
    limb = SimulatedJoint.from_constraint(c, seed=4)
    q = limb.joint(np.arange(0.0, 60.0, 0.05))
    oracle = ConstraintOracle(c)
    assert oracle.is_valid(q, normalize=True).all()
    dist = oracle.signed_distance(q, normalize=True)
    assert np.mean(dist > -1e-6) > 0.1  # reaches the boundary


def test_limb_projects_exactly_as_the_oracle_does():
    """One implementation: twist range (0°, 90°) and a -170° twist go to 90° (the nearer end
    round the circle), as the exact oracle says; the limb's motion is the oracle's projection."""
    c = JointConstraint.cone((1, 0, 0), 60.0, twist=(0.0, 90.0))
    limb = SimulatedJoint(c, seed=1)
    q = Q.from_axis_angle(np.array([1.0, 0.0, 0.0]), math.radians(-170.0))[None]
    assert np.degrees(Q.twist_angle(limb.oracle.project(q, normalize=True))) == \
        pytest.approx([90.0])
    t = np.linspace(0.0, 30.0, 200)
    expected = ConstraintOracle(c).project(limb.raw_joint(t), normalize=True)
    assert _angle_deg(limb.project(limb.raw_joint(t)), expected).max() < 1e-6
    # the motion is that projected target, smoothed (a cubic B-spline with 40 ms knots)
    assert _angle_deg(limb.joint(t), expected).max() < 1.0


def test_sensor_quaternions_compose_frames():
    limb = SimulatedJoint(sensors=[SensorMount("thorax", (1.0, 0, 0, 0)),
                                  SensorMount("limb", tuple(Q.from_axis_angle(
                                      np.array([0, 0, 1.0]), 0.3)))], seed=1)
    st = limb.truth(np.linspace(0, 5, 20))
    thorax, arm = st.sensors[:, 0], st.sensors[:, 1]
    mount = np.asarray(limb.mounts[1].mount)
    joint = Q.multiply(Q.conjugate(thorax), Q.multiply(arm, Q.conjugate(mount)))
    assert _angle_deg(joint, st.joint).max() < 1e-6
    # world differs from thorax: the default has a heading and a 90° pitch
    assert _angle_deg(st.thorax, Q.IDENTITY).min() > 45.0


def test_ideal_sensors_equal_truth_and_gyro_is_the_rate():
    limb = SimulatedJoint(sensors=2, noise=NoiseModel.ideal(), seed=3)
    m0, m1 = limb.measure(1.0), limb.measure(1.001)
    assert _angle_deg(m0.quaternions, m0.truth.sensors[0]).max() < 1e-6
    assert list(m0.calibration) == [0xFF, 0xFF]
    rel = Q.multiply(Q.conjugate(m0.truth.sensors[0]), m1.truth.sensors[0])
    rate = 2.0 * rel[:, 1:] / 0.001 * np.sign(rel[:, :1])
    np.testing.assert_allclose(m0.gyro, rate, atol=0.02)


def test_measure_many_is_the_same_process_as_measure():
    """Batched measurements: identical to one-by-one without errors; with errors, the same
    statistics (draw order differs)."""
    a, b = (SimulatedJoint(sensors=3, noise=NoiseModel.ideal(), seed=12) for _ in range(2))
    ts = np.arange(60) / 100.0
    for x, y in zip(a.measure_many(ts), [b.measure(t) for t in ts], strict=True):
        np.testing.assert_allclose(x.quaternions, y.quaternions, atol=1e-12)
        np.testing.assert_allclose(x.gyro, y.gyro, atol=1e-9)
        assert list(x.calibration) == list(y.calibration)
    white = NoiseModel(white_deg=0.5, drift_heading_deg=0.0, drift_tilt_deg=0.0,
                       disturbance_rate_hz=0.0, calibration_time_s=0.0)
    limb = SimulatedJoint(sensors=4, noise=white, seed=8)
    err = np.concatenate([_angle_deg(m.quaternions, m.truth.sensors[0])
                          for m in limb.measure_many(np.arange(150) * 0.01)])
    assert abs(np.sqrt(np.mean(err**2)) - 0.5 * math.sqrt(3)) < 0.1
    with pytest.raises(ValueError, match="back in time"):
        limb.measure_many([0.5])


def test_noise_model_statistics():
    white = NoiseModel(white_deg=0.5, drift_heading_deg=0.0, drift_tilt_deg=0.0,
                       disturbance_rate_hz=0.0, calibration_time_s=0.0)
    limb = SimulatedJoint(sensors=4, noise=white, seed=8)
    err = np.concatenate([_angle_deg(m.quaternions, m.truth.sensors[0])
                          for m in (limb.measure(k * 0.01) for k in range(150))])
    # |n| of a 3-D Gaussian with σ per axis has RMS σ√3
    assert abs(np.sqrt(np.mean(err**2)) - 0.5 * math.sqrt(3)) < 0.1
    drift = NoiseModel(white_deg=0.0, drift_heading_deg=3.0, drift_tilt_deg=0.0,
                       drift_time_s=5.0, disturbance_rate_hz=0.0)
    limb = SimulatedJoint(sensors=4, noise=drift, seed=9)
    heading = []
    for k in range(500):
        m = limb.measure(k * 0.5)
        e = Q.canonical(Q.multiply(m.quaternions, Q.conjugate(m.truth.sensors[0])))  # world
        assert np.abs(e[:, 1:3]).max() < 1e-9  # heading only: about world Z
        heading.append(np.degrees(2 * np.arctan2(e[:, 3], e[:, 0])))
    heading = np.array(heading)
    assert 2.0 < heading.std() < 4.0  # stationary std 3°
    lag1 = np.mean([np.corrcoef(h[:-1], h[1:])[0, 1] for h in heading.T])
    assert 0.8 < lag1 < 0.97  # slowly wandering: exp(-0.5 / 5) = 0.905


def test_magnetic_disturbances_are_transient_and_drop_mag_calibration():
    noise = NoiseModel(white_deg=0.0, drift_heading_deg=0.0, drift_tilt_deg=0.0,
                       disturbance_rate_hz=0.5, disturbance_deg=20.0, calibration_time_s=0.0)
    limb = SimulatedJoint(sensors=4, noise=noise, seed=10)
    errs, mags = [], []
    for k in range(600):
        m = limb.measure(k * 0.05)
        errs.append(_angle_deg(m.quaternions, m.truth.sensors[0]))
        mags.append(m.calibration & 3)
    errs, mags = np.concatenate(errs), np.concatenate(mags)
    assert errs.max() > 10.0 and np.mean(errs < 0.5) > 0.05  # large but transient
    assert set(mags[errs > 5.0]) == {1} and set(mags[errs < 0.01]) == {3}


def test_calibration_rises_over_time():
    limb = SimulatedJoint(sensors=2, noise=NoiseModel(calibration_time_s=4.0,
                                                     disturbance_rate_hz=0), seed=11)
    stat = [limb.measure(t).calibration for t in np.arange(0.0, 5.0, 0.1)]
    sys_levels = np.array([s >> 6 for s in stat])
    assert (sys_levels[0] == 0).all() and (sys_levels[-1] == 3).all()
    assert (np.diff(sys_levels, axis=0) >= 0).all()


def test_bad_limb_arguments():
    with pytest.raises(TypeError):
        SimulatedJoint("original")
    with pytest.raises(ValueError):
        SimulatedJoint(sensors=0)
    with pytest.raises(ValueError):
        NoiseModel(white_deg=-1)
    limb = SimulatedJoint()
    limb.measure(1.0)
    with pytest.raises(ValueError, match="back in time"):
        limb.measure(0.5)


# -- BNO055 over pyserial -----------------------------------------------------------------


def _xfer(ser: serial.Serial, request: bytes):
    """Send one request, read one complete response."""
    ser.write(request)
    dec = B.ResponseDecoder()
    for _ in range(MAX_READS):
        dec.feed(ser.read(1))
        resp = dec.next()
        if resp is not None:
            return resp
    raise AssertionError(f"no response to {request.hex(' ')}")


def _read(ser, reg, n):
    resp = _xfer(ser, B.encode_read(reg, n))
    assert isinstance(resp, B.ReadResponse), resp
    return resp.data


def _write(ser, reg, data) -> int:
    resp = _xfer(ser, B.encode_write(reg, bytes(data)))
    assert isinstance(resp, B.StatusResponse)
    return resp.status


@pytest.fixture
def bno():
    clock = ManualClock(1000.0)
    limb = SimulatedJoint(sensors=2, noise=QUIET, seed=21)
    with Bno055Simulator(limb, clock=clock, char_timeout_s=0.05) as sim, \
            serial.Serial(sim.port, 115200, timeout=0.5) as ser:
        yield sim, ser, clock


def test_bno055_published_exchanges_over_pty(bno):
    sim, ser, _ = bno
    ser.write(bytes.fromhex("AA 01 00 01"))
    assert ser.read(3) == bytes.fromhex("BB 01 A0")
    ser.write(bytes.fromhex("AA 00 3D 01 0C"))
    assert ser.read(2) == bytes.fromhex("EE 01")
    assert sim.mode == B.OperationMode.NDOF


def _bno055_session(ser: serial.Serial) -> None:
    """Back-to-back body: runs on the simulator, and on a real BNO055 (``RIG_IMU_PORT``)."""
    assert _read(ser, B.Register.CHIP_ID, 1) == bytes([B.CHIP_ID_VALUE])
    assert _write(ser, B.Register.OPR_MODE, [B.OperationMode.CONFIG]) == B.Status.WRITE_SUCCESS
    assert _read(ser, B.Register.OPR_MODE, 1)[0] & 0x0F == B.OperationMode.CONFIG
    assert _write(ser, B.Register.OPR_MODE, [B.OperationMode.NDOF]) == B.Status.WRITE_SUCCESS
    for _ in range(MAX_READS):  # a real chip needs ~7 ms, then its first fusion output
        q = np.array(B.decode_quaternion(_read(ser, B.Register.QUA_DATA, 8)))
        if q.any():
            break
    assert abs(np.linalg.norm(q) - 1.0) < 2e-3
    B.CalibrationStatus.from_byte(_read(ser, B.Register.CALIB_STAT, 1)[0])
    assert _write(ser, B.Register.OPR_MODE, [B.OperationMode.CONFIG]) == B.Status.WRITE_SUCCESS


def test_bno055_session_on_simulator():
    with Bno055Simulator(seed=3) as sim, serial.Serial(sim.port, 115200, timeout=0.5) as ser:
        _bno055_session(ser)


@pytest.mark.hardware
def test_bno055_session_on_hardware():
    import os

    port = os.environ.get("RIG_IMU_PORT")
    if not port or os.environ.get("RIG_IMU_PROTOCOL", "bno055") != "bno055":
        pytest.skip("RIG_IMU_PORT does not name a BNO055 UART (RIG_IMU_PROTOCOL=bno055)")
    with serial.Serial(port, 115200, timeout=0.5) as ser:
        _bno055_session(ser)


def test_bno055_modes_gate_data_and_config_writes(bno):
    sim, ser, clock = bno
    assert _read(ser, B.Register.OPR_MODE, 1) == b"\x00"
    assert _read(ser, B.Register.QUA_DATA, 8) == bytes(8)  # no fusion in CONFIG
    assert _read(ser, B.Register.SYS_STATUS, 1) == b"\x00"
    assert _write(ser, B.Register.UNIT_SEL, [0x80]) == B.Status.WRITE_SUCCESS
    assert _write(ser, B.Register.AXIS_MAP_CONFIG, [0x24, 0x00]) == B.Status.WRITE_SUCCESS
    assert _write(ser, B.Register.OPR_MODE, [B.OperationMode.NDOF]) == B.Status.WRITE_SUCCESS
    assert _read(ser, B.Register.SYS_STATUS, 1) == b"\x05"
    assert _write(ser, B.Register.UNIT_SEL, [0x00]) == B.Status.REGMAP_WRITE_DISABLED
    assert _write(ser, B.Register.PWR_MODE, [0x00]) == B.Status.REGMAP_WRITE_DISABLED
    assert _write(ser, B.Register.CHIP_ID, [0x00]) == B.Status.REGMAP_WRITE_DISABLED
    assert _write(ser, B.Register.OPR_MODE, [0x0D]) == B.Status.WRITE_FAIL
    assert _write(ser, 0x6B, [0x00]) == B.Status.REGMAP_INVALID_ADDRESS
    assert _xfer(ser, B.encode_read(0x7F, 2)) == B.StatusResponse(B.Status.REGMAP_INVALID_ADDRESS)
    for k in range(5):
        clock.t += 0.013
        q = np.array(B.decode_quaternion(_read(ser, B.Register.QUA_DATA, 8)))
        assert abs(np.linalg.norm(q) - 1.0) < 3e-4
        truth = sim.last.truth.sensors[0, sim.sensor]
        assert _angle_deg(q, truth) < 12.0, k  # white 0.3°, drift σ 2° heading
    assert _write(ser, B.Register.OPR_MODE, [B.OperationMode.AMG]) == B.Status.WRITE_SUCCESS
    assert _read(ser, B.Register.QUA_DATA, 8) == bytes(8)  # not a fusion mode
    assert _read(ser, B.Register.SYS_STATUS, 1) == b"\x06"


def test_bno055_quaternion_matches_truth_without_noise():
    clock = ManualClock(1000.0)
    limb = SimulatedJoint(sensors=2, noise=NoiseModel.ideal(), seed=22)
    with Bno055Simulator(limb, clock=clock, rate_hz=100) as sim, \
            serial.Serial(sim.port, timeout=0.5) as ser:
        assert _write(ser, B.Register.OPR_MODE, [B.OperationMode.NDOF]) == 1
        for k in range(20):
            clock.t += 0.0371
            q = B.decode_quaternion(_read(ser, B.Register.QUA_DATA, 8))
            expected_t = math.floor((clock.t - 1000.0) * 100) / 100
            assert sim.last.t == pytest.approx(expected_t)  # fusion output on the 100 Hz grid
            truth = limb.truth(expected_t).sensors[0, 1]
            assert _angle_deg(q, truth) < 0.02, k  # quantisation only
        # Euler (16 LSB/°) and gyro agree with the quaternion / truth
        h, r, p = B.decode_vector(_read(ser, B.Register.EUL_DATA, 6), 16.0)
        rot = Q.to_rotation(sim.last.quaternions[1])
        yaw, pitch, roll = np.degrees(rot.as_euler("ZYX"))
        assert (h - (-yaw) % 360 + 180) % 360 - 180 == pytest.approx(0, abs=0.1)
        assert (r, p) == (pytest.approx(roll, abs=0.1), pytest.approx(pitch, abs=0.1))
        gyro = np.radians(B.decode_vector(_read(ser, B.Register.GYR_DATA, 6), 16.0))
        np.testing.assert_allclose(gyro, sim.last.gyro[1], atol=0.01)
        # radians units, then an axis remap (X<->Y swapped, Z negated: a proper rotation)
        assert _write(ser, B.Register.OPR_MODE, [0]) == 1
        assert _write(ser, B.Register.UNIT_SEL, [0x06]) == 1
        assert _write(ser, B.Register.AXIS_MAP_CONFIG, [0x21, 0x01]) == 1
        assert _write(ser, B.Register.OPR_MODE, [B.OperationMode.NDOF]) == 1
        clock.t += 0.05
        q = np.array(B.decode_quaternion(_read(ser, B.Register.QUA_DATA, 8)))
        gyro = np.array(B.decode_vector(_read(ser, B.Register.GYR_DATA, 6), 900.0))
        g0 = sim.last.gyro[1]
        np.testing.assert_allclose(gyro, [g0[1], g0[0], -g0[2]], atol=0.01)
        m = np.array([[0, 1, 0], [1, 0, 0], [0, 0, -1.0]])  # v_new = M v_old
        v_new = np.array([0.3, -0.2, 0.9])
        np.testing.assert_allclose(Q.rotate(q, v_new), Q.rotate(sim.last.quaternions[1],
                                                                m.T @ v_new), atol=1e-3)


def test_bno055_raw_data_registers():
    """ACC_DATA and MAG_DATA (and GYR_DATA) hold the limb's raw readings in UNIT_SEL units, in
    the modes that run those sensors, axis-remapped like the rest."""
    clock = ManualClock(1000.0)
    limb = SimulatedJoint(sensors=2, noise=NoiseModel.ideal(), seed=23)
    with Bno055Simulator(limb, clock=clock) as sim, serial.Serial(sim.port, timeout=0.5) as ser:
        assert _read(ser, B.Register.ACC_DATA, 12) == bytes(12)  # CONFIG: nothing measured
        assert _write(ser, B.Register.OPR_MODE, [B.OperationMode.NDOF]) == 1
        clock.t += 0.2
        data = _read(ser, B.Register.ACC_DATA, 18)
        m, k = sim.last, sim.sensor
        np.testing.assert_allclose(B.decode_vector(data[:6], 100.0), m.accel[k], atol=0.0051)
        np.testing.assert_allclose(B.decode_vector(data[6:12], 16.0), m.mag[k], atol=0.032)
        np.testing.assert_allclose(np.radians(B.decode_vector(data[12:], 16.0)), m.gyro[k],
                                   atol=0.001)
        # IMU mode runs no magnetometer; ACCONLY no magnetometer and no gyroscope
        assert _write(ser, B.Register.OPR_MODE, [B.OperationMode.IMU]) == 1
        data = _read(ser, B.Register.ACC_DATA, 18)
        assert data[6:12] == bytes(6) and data[:6] != bytes(6) and data[12:] != bytes(6)
        assert _write(ser, B.Register.OPR_MODE, [B.OperationMode.ACCONLY]) == 1
        data = _read(ser, B.Register.ACC_DATA, 18)
        assert data[6:] == bytes(12) and data[:6] != bytes(6)
        # mg units (UNIT_SEL bit 0) and an axis remap (X<->Y swapped, Z negated)
        assert _write(ser, B.Register.OPR_MODE, [0]) == 1
        assert _write(ser, B.Register.UNIT_SEL, [0x81]) == 1
        assert _write(ser, B.Register.AXIS_MAP_CONFIG, [0x21, 0x01]) == 1
        assert _write(ser, B.Register.OPR_MODE, [B.OperationMode.AMG]) == 1
        clock.t += 0.05
        data = _read(ser, B.Register.ACC_DATA, 12)
        a0, f0 = sim.last.accel[k], sim.last.mag[k]
        np.testing.assert_allclose(np.array(B.decode_vector(data[:6], 1.0)) * 9.80665e-3,
                                   [a0[1], a0[0], -a0[2]], atol=0.006)
        np.testing.assert_allclose(B.decode_vector(data[6:], 16.0), [f0[1], f0[0], -f0[2]],
                                   atol=0.032)


def test_bno055_framing_errors_and_character_timeout(bno):
    _, ser, _ = bno
    ser.write(b"\x42")
    assert ser.read(2) == bytes.fromhex("EE 06")
    ser.write(bytes.fromhex("AA 01 00 00"))
    assert ser.read(2) == bytes.fromhex("EE 09")
    ser.write(bytes.fromhex("AA 01 00 90"))
    assert ser.read(2) == bytes.fromhex("EE 08")
    ser.write(bytes.fromhex("AA 00 3D 01"))  # data byte never comes
    assert ser.read(2) == bytes.fromhex("EE 0A")
    assert _read(ser, 0, 1) == b"\xa0"  # and the chip still answers


def test_bno055_calibration_rises_while_fusing(bno):
    _, ser, clock = bno
    assert _write(ser, B.Register.OPR_MODE, [B.OperationMode.NDOF]) == 1
    first = B.CalibrationStatus.from_byte(_read(ser, B.Register.CALIB_STAT, 1)[0])
    assert first.system == 0
    clock.t += 0.6  # QUIET calibrates within 0.5 s of fusion
    assert _read(ser, B.Register.CALIB_STAT, 1) == b"\xff"
    # time in CONFIG does not count; a reset starts calibration over
    assert _write(ser, B.Register.SYS_TRIGGER, [0x20]) == 1
    assert _read(ser, B.Register.OPR_MODE, 1) == b"\x00"
    assert _write(ser, B.Register.OPR_MODE, [B.OperationMode.NDOF]) == 1
    assert _read(ser, B.Register.CALIB_STAT, 1)[0] >> 6 == 0


def test_bno055_pages(bno):
    _, ser, _ = bno
    assert _write(ser, B.Register.PAGE_ID, [1]) == 1
    assert _read(ser, B.Register.PAGE_ID, 1) == b"\x01"
    assert _read(ser, 0x00, 1) == b"\x00"  # page 1 has no CHIP_ID
    assert _write(ser, B.Register.PAGE_ID, [2]) == B.Status.WRITE_FAIL
    assert _write(ser, B.Register.PAGE_ID, [0]) == 1
    assert _read(ser, 0x00, 7) == bytes.fromhex("A0 FB 32 0F 11 03 15")


def test_simulator_close_is_idempotent_and_reports_thread_errors():
    sim = Bno055Simulator(seed=1)
    sim.close()
    sim.close()
    assert sim.closed

    class Broken(SimulatedJoint):
        def measure(self, t, calibration_elapsed_s=None):
            raise ZeroDivisionError("boom")

    sim = Bno055Simulator(Broken(), char_timeout_s=0.05)
    with serial.Serial(sim.port, timeout=HANG_GUARD_S) as ser:
        ser.write(B.encode_write(B.Register.OPR_MODE, [0x0C]))
        assert ser.read(2) == bytes.fromhex("EE 01")
        ser.write(B.encode_read(B.Register.QUA_DATA, 8))
        assert sim.wait_for(lambda: sim.server_error is not None, HANG_GUARD_S)
        assert isinstance(sim.server_error, ZeroDivisionError)
        assert ser.in_waiting == 0  # the device died: no answer
    with pytest.raises(RuntimeError, match="boom"):
        sim.close()
    sim.close()


# -- stream device over pyserial ----------------------------------------------------------


class StreamHost:
    """Minimal host: sends commands, waits for the matching ACK/NAK, keeps the samples."""

    def __init__(self, ser: serial.Serial) -> None:
        self.ser = ser
        self.dec = S.StreamDecoder()
        self.seq = 0
        self.samples: list[S.Sample] = []
        self.frames: list = []

    def _pump(self) -> None:
        self.dec.feed(self.ser.read(max(1, self.ser.in_waiting)))
        for item in self.dec.drain():
            self.frames.append(item)
            if isinstance(item, S.Sample):
                self.samples.append(item)

    def send(self, wire: bytes):
        """Send raw bytes that end in a command with ``self.seq - 1``; return its reply."""
        self.ser.write(wire)
        want = (self.seq - 1) & 0xFFFF
        for _ in range(MAX_READS):
            start = len(self.frames)
            self._pump()
            for f in self.frames[start:]:
                if isinstance(f, S.Ack | S.Nak) and f.command_seq == want:
                    return f
        raise AssertionError(f"no reply to command seq {want}")

    def command(self, kind: S.CommandType, value: int | None = None):
        wire = S.encode_command(self.seq, kind, value)
        self.seq = (self.seq + 1) & 0xFFFF
        return self.send(wire)

    def wait_samples(self, n: int) -> list[S.Sample]:
        for _ in range(MAX_READS):
            if len(self.samples) >= n:
                return self.samples
            self._pump()
        raise AssertionError(f"only {len(self.samples)} of {n} samples")


@pytest.fixture
def stream():
    """A 4-sensor stream device on a manual clock: time moves only when the test says; with
    flow control, as a clock jump produces a burst larger than the pty's buffer."""
    clock = ManualClock()
    limb = SimulatedJoint(sensors=4, noise=QUIET, seed=31)
    with StreamImuSimulator(limb, rate_hz=100, clock=clock, flow_control=True) as sim, \
            serial.Serial(sim.port, timeout=0.05) as ser:
        yield sim, StreamHost(ser), clock
        assert sim.server_error is None


def test_stream_identify(stream):
    sim, host, _ = stream
    ack = host.command(S.CommandType.IDENTIFY)
    assert isinstance(ack, S.Ack) and ack.command == S.CommandType.IDENTIFY
    assert ack.identity == S.Identity(1, 1, 0x0100, sim.serial, 16, False, 0x000F, 0x000F, 100,
                                      10, 400)


@pytest.mark.parametrize("rate", [100, 400])
def test_stream_samples_at_requested_rate(stream, rate):
    sim, host, clock = stream
    assert isinstance(host.command(S.CommandType.SET_RATE, rate), S.Ack)
    assert isinstance(host.command(S.CommandType.START), S.Ack)
    n = rate // 2  # half a second of data: sample 0 at once, then n - 1 periods
    clock.advance((n - 1) / rate)
    samples = host.wait_samples(n)
    assert sim.wait_for(lambda: sim.samples_sent == n)
    assert len(samples) == n and sim.samples_skipped == 0
    assert host.dec.gaps == 0 and host.dec.errors == 0
    seqs = [s.seq for s in samples]
    assert seqs == [(seqs[0] + k) & 0xFFFF for k in range(n)]
    ts = np.array([s.timestamp_us for s in samples], dtype=np.int64)
    np.testing.assert_array_equal(ts, np.round(np.arange(n) * 1e6 / rate))  # exact grid
    for s in samples[:: max(1, n // 25)]:
        assert [r.sensor_id for r in s.readings] == [0, 1, 2, 3]
        q = np.array([r.quaternion for r in s.readings])
        assert np.abs(np.linalg.norm(q, axis=1) - 1.0).max() < 3e-4
        truth = sim.limb.truth(s.timestamp_us / 1e6).sensors[0]
        assert _angle_deg(q, truth).max() < 12.0  # white 0.3°, drift σ 2° heading, tilt 0.3°
    host.command(S.CommandType.STOP)


def test_stream_commands_and_refusals(stream):
    sim, host, clock = stream
    nak = host.command(S.CommandType.SET_RATE, 5)
    assert nak == S.Nak(nak.seq, 0, S.CommandType.SET_RATE, S.ErrorCode.BAD_ARGUMENT)
    assert host.command(S.CommandType.SET_SENSORS, 0x10).error == S.ErrorCode.BAD_ARGUMENT
    assert host.command(S.CommandType.SET_SENSORS, 0).error == S.ErrorCode.BAD_ARGUMENT
    assert isinstance(host.command(S.CommandType.SET_SENSORS, 0b0101), S.Ack)
    # unknown command type, wrong length, other major version, device->host type
    host.seq += 1
    assert host.send(S.encode_frame(0x9F, host.seq - 1)).error == S.ErrorCode.UNKNOWN_COMMAND
    host.seq += 1
    assert host.send(S.encode_frame(S.CommandType.STOP, host.seq - 1, b"\x00")).error == \
        S.ErrorCode.BAD_LENGTH
    host.seq += 1
    body = bytearray([2, S.CommandType.START]) + (host.seq - 1).to_bytes(2, "little")
    body += S.crc32(body).to_bytes(4, "little")
    from firmware_protocol.imu import cobs

    assert host.send(cobs.encode(bytes(body)) + b"\x00").error == \
        S.ErrorCode.UNSUPPORTED_VERSION
    host.seq += 1
    assert host.send(S.encode_sample(host.seq - 1, 0, [])).error == S.ErrorCode.UNKNOWN_COMMAND
    # garbage (with and without delimiters) before a command costs nothing but itself
    host.seq += 1
    reply = host.send(b"\x00\x13\x37\x00\xff\xfe" + b"\x00"
                      + S.encode_command(host.seq - 1, S.CommandType.START))
    assert isinstance(reply, S.Ack) and reply.command == S.CommandType.START
    clock.advance(0.02)
    samples = host.wait_samples(3)
    assert [r.sensor_id for r in samples[0].readings] == [0, 2]
    assert sim.frames_rejected >= 1
    # STOP: the next frame after its ACK is the IDENTIFY reply, no sample in between
    stop = host.command(S.CommandType.STOP)
    start = host.frames.index(stop) + 1
    clock.advance(0.5)
    ident = host.command(S.CommandType.IDENTIFY)
    assert host.frames[start:] == [ident]
    assert ident.identity.streaming is False and ident.identity.active_mask == 0b0101


#: half an LSB of the raw record fields: acc m/s², gyr rad/s, mag µT
RAW_HALF_LSB = np.array([0.5 / S.ACC_SCALE] * 3 + [math.radians(0.5 / S.GYR_SCALE)] * 3
                        + [0.5 / S.MAG_SCALE] * 3) + 1e-9


def test_stream_raw_fields_are_the_limb_measurement():
    """SET_FIELDS RAW: every record carries the simulated accelerometer, gyroscope and
    magnetometer of its instant (the limb's Measurement), at the record's resolution; RAW off
    again gives 1.0 records."""
    clock = ManualClock()
    limb = SimulatedJoint(sensors=3, noise=NoiseModel.ideal(), seed=8)
    with StreamImuSimulator(limb, rate_hz=100, clock=clock, flow_control=True) as sim, \
            serial.Serial(sim.port, timeout=0.05) as ser:
        host = StreamHost(ser)
        assert isinstance(host.command(S.CommandType.SET_FIELDS, S.FieldFlag.RAW), S.Ack)
        assert sim.fields == S.FieldFlag.RAW
        host.command(S.CommandType.START)
        clock.advance(0.49)
        samples = host.wait_samples(50)
        off = host.command(S.CommandType.SET_FIELDS, 0)
        clock.advance(0.05)
        host.wait_samples(len(host.samples) + 5)
        host.command(S.CommandType.STOP)
        assert host.dec.errors == 0 and sim.server_error is None
    times = np.array([s.timestamp_us for s in samples[:50]]) / 1e6
    twin = SimulatedJoint(sensors=3, noise=NoiseModel.ideal(), seed=8)  # the same patient
    for s, m in zip(samples[:50], twin.measure_many(times), strict=True):
        got = np.array([r.raw for r in s.readings])
        want = np.hstack([m.accel, m.gyro, m.mag])
        assert np.all(np.abs(got - want) <= RAW_HALF_LSB), s.seq
    # the specific force of a slowly moving arm is about g; the field about 48 µT
    acc = np.array([r.raw[:3] for s in samples[:50] for r in s.readings])
    mag = np.array([r.raw[6:] for s in samples[:50] for r in s.readings])
    assert np.all(np.abs(np.linalg.norm(acc, axis=1) - 9.81) < 2.0)
    assert np.all(np.abs(np.linalg.norm(mag, axis=1) - 48.0) < 1.0)
    after = [f for f in host.frames[host.frames.index(off) + 1:] if isinstance(f, S.Sample)]
    assert after and all(r.raw is None for f in after for r in f.readings)


def test_stream_set_fields_refusals():
    clock = ManualClock()
    with StreamImuSimulator(sensors=10, clock=clock, flow_control=True) as sim, \
            serial.Serial(sim.port, timeout=0.05) as ser:
        host = StreamHost(ser)
        assert host.command(S.CommandType.SET_FIELDS, 0x02).error == S.ErrorCode.BAD_ARGUMENT
        # 10 active sensors: a raw SAMPLE would not fit a frame
        assert host.command(S.CommandType.SET_FIELDS, 1).error == S.ErrorCode.BAD_ARGUMENT
        assert isinstance(host.command(S.CommandType.SET_SENSORS, 0x00FF), S.Ack)
        assert isinstance(host.command(S.CommandType.SET_FIELDS, 1), S.Ack)
        assert host.command(S.CommandType.SET_SENSORS, 0x01FF).error == S.ErrorCode.BAD_ARGUMENT
        host.command(S.CommandType.START)
        clock.advance(0.02)
        (first, *_) = host.wait_samples(3)
        assert [r.sensor_id for r in first.readings] == list(range(8))
        assert all(r.raw is not None for r in first.readings)
        host.command(S.CommandType.STOP)
        assert sim.fields == 1 and sim.active_mask == 0x00FF


def test_a_1_0_board_refuses_set_fields():
    with stream_from_url("sim://imu-stream?protocol=1.0&clock=manual") as sim, \
            serial.Serial(sim.port, timeout=0.05) as ser:
        host = StreamHost(ser)
        assert host.command(S.CommandType.IDENTIFY).identity.protocol_minor == 0
        nak = host.command(S.CommandType.SET_FIELDS, 1)
        assert nak.error == S.ErrorCode.UNKNOWN_COMMAND and nak.command == 0x85
        assert sim.fields == 0
    with stream_from_url("sim://imu-stream?clock=manual") as sim:
        assert sim.protocol_minor == 1


def test_stream_sequence_numbers_wrap():
    clock = ManualClock()
    with StreamImuSimulator(sensors=1, clock=clock, initial_seq=0xFFFD,
                            flow_control=True) as sim, \
            serial.Serial(sim.port, timeout=0.05) as ser:
        host = StreamHost(ser)
        host.command(S.CommandType.START)  # its ACK is 0xFFFD
        clock.advance(0.05)
        samples = host.wait_samples(6)
        assert [s.seq for s in samples[:5]] == [0xFFFE, 0xFFFF, 0, 1, 2]
        assert host.dec.gaps == 0
        host.command(S.CommandType.STOP)


def test_stream_rate_change_while_streaming(stream):
    sim, host, clock = stream
    host.command(S.CommandType.START)
    clock.advance(0.02)  # samples at 0, 10, 20 ms
    host.wait_samples(3)
    ack = host.command(S.CommandType.SET_RATE, 400)  # next slot (30 ms) starts the 400 Hz grid
    clock.advance(0.03)  # to 50 ms: the 400 Hz slots 30, 32.5, ..., 50 ms
    host.wait_samples(len(host.samples) + 9)
    after = [f for f in host.frames[host.frames.index(ack) + 1:] if isinstance(f, S.Sample)]
    assert [s.timestamp_us for s in after] == [30_000 + 2_500 * k for k in range(9)]
    assert sim.samples_skipped == 0
    host.command(S.CommandType.STOP)


def test_stream_timestamps_wrap_and_unwrap():
    limb = SimulatedJoint(sensors=1, noise=NoiseModel.ideal(), seed=5)
    offset = 2**32 - 100_000  # wraps 0.1 s after the start
    clock = ManualClock()
    with StreamImuSimulator(limb, rate_hz=400, timestamp_offset_us=offset, clock=clock,
                            flow_control=True) as sim, \
            serial.Serial(sim.port, timeout=0.05) as ser:
        host = StreamHost(ser)
        host.command(S.CommandType.START)
        clock.advance(119 / 400)
        samples = host.wait_samples(120)
        host.command(S.CommandType.STOP)
    raw = [s.timestamp_us for s in samples]
    assert max(raw) > 2**32 - 5000 and min(raw) < 5000  # wrapped
    unwrap = S.TimestampUnwrapper()
    full = np.array([unwrap(t) for t in raw])
    assert (np.diff(full) == 2500).all()
    for s, t in zip(samples[::20], full[::20], strict=True):
        truth = limb.truth((t - offset) / 1e6).sensors[0, 0]
        assert _angle_deg(s.readings[0].quaternion, truth) < 0.02


def test_starved_device_skips_and_counts_unless_told_not_to():
    """With a lag limit the device drops samples it is too late for (counted); without one
    and with flow control it sends every sample of the grid, however far time jumps."""
    for max_lag, expect_skips in ((0.1, True), (None, False)):
        clock = ManualClock()
        with StreamImuSimulator(sensors=1, rate_hz=100, clock=clock, max_lag_s=max_lag,
                                flow_control=True) as sim, \
                serial.Serial(sim.port, timeout=0.05) as ser:
            host = StreamHost(ser)
            host.command(S.CommandType.START)
            clock.advance(0.99)  # one jump of a second: 100 slots
            assert sim.wait_for(lambda s=sim: s.samples_sent + s.samples_skipped >= 100)
            assert host.command(S.CommandType.STOP)
            assert (sim.samples_skipped > 0) is expect_skips
            assert len(host.samples) == sim.samples_sent == 100 - sim.samples_skipped
            assert sim.bytes_dropped == 0


def test_fast_simulated_time_loses_nothing_through_the_pty():
    """The benchmark's recipe at a test's scale: 2 sensors at 400 Hz, 5 simulated seconds
    advanced at once (far faster than real time); every sample arrives, in order, no gaps."""
    url = ("sim://imu-stream?sensors=2&rate=400&patient=original&seed=3"
           "&clock=manual&flow=on")
    with stream_from_url(url) as sim, serial.Serial(sim.port, timeout=0.05) as ser:
        host = StreamHost(ser)
        host.command(S.CommandType.START)
        sim.clock.advance(5.0)
        samples = host.wait_samples(2001)
        assert len(samples) == 2001 and host.dec.gaps == 0 and host.dec.errors == 0
        assert sim.samples_skipped == 0 and sim.bytes_dropped == 0
        assert all(len(s.readings) == 2 for s in samples)
        np.testing.assert_array_equal(np.diff([s.timestamp_us for s in samples]), 2500)


def test_imu_adapter_unplug_and_replug():
    clock = ManualClock()
    with StreamImuSimulator(sensors=1, clock=clock) as sim:
        with serial.Serial(sim.port, timeout=0.05) as ser:
            StreamHost(ser).command(S.CommandType.IDENTIFY)
            sim.disconnect()
            assert not sim.connected
            with pytest.raises(serial.SerialException):
                ser.write(b"\x00")
                ser.read(1)
        port = sim.reconnect()
        assert sim.connected and port == sim.port
        with serial.Serial(port, timeout=0.05) as ser:
            assert isinstance(StreamHost(ser).command(S.CommandType.IDENTIFY), S.Ack)


# -- port strings ---------------------------------------------------------------------------


def test_bno055_from_url_serves_the_named_patient(tmp_path):
    with bno055_from_url("sim://bno055?seed=1&rate=100&patient=original&clock=manual") as sim, \
            serial.Serial(sim.port, 115200, timeout=0.5) as ser:
        assert isinstance(sim.clock, ManualClock)
        assert sim.limb.constraint.name == "original"
        assert _read(ser, B.Register.CHIP_ID, 1) == bytes([B.CHIP_ID_VALUE])
    cfile = tmp_path / "c.yaml"
    cfile.write_text("name: mine\nswing:\n  cone: {centre: [1, 0, 0], radius_deg: 40}\n")
    with bno055_from_url(f"sim://bno055?patient={cfile}&noise=off&misplace_deg=0") as sim:
        assert sim.limb.constraint.name == "mine"
        assert sim.limb.noise == NoiseModel.ideal()


def test_stream_from_url_builds_a_realistic_patient():
    with stream_from_url("sim://imu-stream?sensors=3&rate=200&patient=c-shape&seed=2") as sim:
        assert sim.rate_hz == 200 and sim.limb.n_sensors == 3
        assert sim.limb.constraint.name == "c-shape"
        assert sim.limb.noise == NoiseModel()  # realistic errors by default
        assert [m.segment for m in sim.limb.mounts] == ["thorax", "limb", "limb"]
    a = stream_from_url("sim://imu-stream?seed=4&misplace_deg=0")
    b = stream_from_url("sim://imu-stream?seed=4&misplace_deg=10")
    with a, b:
        moved = _angle_deg(np.array([m.mount for m in a.limb.mounts]),
                           np.array([m.mount for m in b.limb.mounts]))
        np.testing.assert_allclose(moved, 10.0, atol=1e-6)


def test_url_keys_neutral_checkpoints():
    with stream_from_url("sim://imu-stream?sensors=2&patient=original&neutral=20&neutral_sd=3"
                         "&clock=manual") as sim:
        limb = sim.limb
        assert (limb.neutral_every_s, limb.neutral_hold_s, limb.neutral_ramp_s,
                limb.neutral_sd_deg) == (20.0, 2.0, 1.5, 3.0)
        np.testing.assert_allclose(limb.neutral_windows(45.0), [[20, 22], [40, 42]])
    with bno055_from_url("sim://bno055?neutral=6&calibrate=on&clock=manual") as sim:
        assert sim.limb.neutral_every_s == 6.0  # the least: 1.5 s in, 2 s held, 1.5 s out, 1 s
        assert sim.limb.neutral_start_s == pytest.approx(sim.limb.protocol_end_s + 3.0)
    with stream_from_url("sim://imu-stream?neutral=0&clock=manual") as sim, \
            stream_from_url("sim://imu-stream?clock=manual") as default:
        for limb in (sim.limb, default.limb):
            assert limb.neutral_every_s == 0.0 and limb.neutral_sd_deg == 2.0
            assert limb.neutral_windows(1e4).shape == (0, 2)
    with pytest.raises(RigConfigError) as err:
        stream_from_url("sim://imu-stream?neutral=4")
    assert str(err.value) == ("sim://imu-stream?neutral=4: neutral='4': must be 0 (off) or a "
                              "checkpoint interval >= 6 s")


BAD_IMU_URLS = [
    ("sim://imu-stream?sensorz=2", "sensorz"),
    ("sim://imu-stream?sensors=17", "sensors"),
    ("sim://imu-stream?sensors=two", "sensors"),
    ("sim://imu-stream?rate=0", "rate"),
    ("sim://imu-stream?patient=nobody", "patient"),
    ("sim://imu-stream?noise=maybe", "noise"),
    ("sim://imu-stream?max_lag=-1", "max_lag"),
    ("sim://imu-stream?flow=yes-please", "flow"),
    ("sim://imu-stream?protocol=1.2", "protocol"),
    ("sim://imu-stream?speed=0", "speed"),
    ("sim://imu-stream?excursion=nan", "excursion"),
    ("sim://imu-stream?clock=sundial", "clock"),
    ("sim://imu-stream?seed=1&seed=2", "seed"),
    ("sim://bno055?sensor=2", "sensor"),
    ("sim://bno055?sensors=2", "sensors"),
    ("sim://bno055?misplace_deg=-3", "misplace_deg"),
    ("sim://bno055?time_scale=0", "time_scale"),
    ("sim://bno055?rate=100&patient=/no/such/file.yaml", "file.yaml"),
    ("sim://imu-stream?neutral=often", "neutral"),
    ("sim://imu-stream?neutral=-20", "neutral"),
    ("sim://imu-stream?neutral=5", "neutral"),  # shorter than ramp in, hold, ramp out + 1 s
    ("sim://imu-stream?neutral=inf", "neutral"),
    ("sim://bno055?neutral_sd=11", "neutral_sd"),
    ("sim://bno055?neutral_sd=-1", "neutral_sd"),
    ("sim://bno055?neutral=20&neutral_sd=two", "neutral_sd"),
]


@pytest.mark.parametrize(("url", "key"), BAD_IMU_URLS)
def test_bad_imu_urls_name_the_key(url, key):
    build = stream_from_url if "imu-stream" in url else bno055_from_url
    with pytest.raises(RigConfigError, match=key) as err:
        build(url)
    assert "\n" not in str(err.value)


def test_foreign_urls_are_refused():
    for url, build in (("sim://bno055", stream_from_url), ("sim://imu-stream", bno055_from_url),
                       ("/dev/ttyUSB0", stream_from_url)):
        with pytest.raises(RigConfigError, match="not a simulated"):
            build(url)


# -- CLI ----------------------------------------------------------------------------------


def _run_cli(*args: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "rig", "sim", "imu", *args],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


@pytest.mark.parametrize("device", ["bno055", "imu-stream"])
def test_cli_serves_the_port_string_until_sigterm(device, tmp_path):
    cfile = tmp_path / "shoulder.yaml"
    cfile.write_text("name: test\nswing:\n  cone: {centre: [1, 0, 0], radius_deg: 40}\n"
                     "twist: {min_deg: -30, max_deg: 30}\n")
    extra = "&sensors=3" if device == "imu-stream" else "&sensor=0"
    proc = _run_cli(f"sim://{device}?rate=200&seed=3&patient={cfile}&time_scale=2{extra}")
    try:
        port = proc.stdout.readline().strip()
        assert port.startswith("/dev/pts/"), proc.stderr.read() if not port else port
        with serial.Serial(port, timeout=0.05) as ser:
            if device == "bno055":
                assert _read(ser, 0, 1) == b"\xa0"
            else:
                host = StreamHost(ser)
                identity = host.command(S.CommandType.IDENTIFY).identity
                assert identity.rate_hz == 200 and identity.present_mask == 0b111
                host.command(S.CommandType.START)
                host.wait_samples(5)
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 0, err
    assert out == "" and err == ""


def test_cli_default_is_a_stream_board_and_sigint_also_exits_zero():
    proc = _run_cli()
    try:
        port = proc.stdout.readline().strip()
        assert port.startswith("/dev/pts/")
        with serial.Serial(port, timeout=0.05) as ser:
            identity = StreamHost(ser).command(S.CommandType.IDENTIFY).identity
            assert identity.rate_hz == 100 and identity.present_mask == 0b11  # URL defaults
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 0, err


def test_the_sim_command_starts_no_thread_before_it_blocks_its_stop_signals():
    """`rig sim` blocks SIGINT/SIGTERM before any thread exists, so that only its main thread
    takes them (sigwait). Importing the command must therefore not import numpy or scipy,
    whose native BLAS threads would start unblocked and could take a SIGINT (`rig: aborted`,
    exit 130): issue 38 had moved `rig.errors`' imports of the packages' error roots to the top
    of the file, which did."""
    code = ("import sys, rig.commands.sim; "
            "print(sorted(m for m in ('numpy', 'scipy', 'onnxruntime') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, timeout=60).stdout
    assert out.strip() == "[]"


def _cli_error(capsys, *args: str) -> str:
    from rig.cli import main

    with pytest.raises(SystemExit) as info:
        main(["sim", "imu", *args])
    out, err = capsys.readouterr()
    assert info.value.code == 2 and out == ""
    assert len(err.strip().splitlines()) == 1, err
    return err


@pytest.mark.parametrize(("url", "key"), BAD_IMU_URLS)
def test_cli_bad_url_is_the_ports_one_line_error(url, key, capsys):
    """The command takes the port's keys through the port's parser: the same message."""
    from rig.devices.ports import open_port

    with pytest.raises(RigConfigError) as port_error:
        open_port(url)
    err = _cli_error(capsys, url)
    assert err == f"rig: error: {port_error.value}\n" and key in err


@pytest.mark.parametrize(("url", "needle"), [
    ("sim://dynamixel?ids=1", "not a simulated imu-stream or bno055 URL"),
    ("/dev/ttyUSB0", "not a simulated imu-stream or bno055 URL"),
    ("sim://imu-stream?clock=manual", "clock=manual"),
])
def test_cli_refuses_other_devices_and_a_manual_clock(url, needle, capsys):
    err = _cli_error(capsys, url)
    assert err.startswith(f"rig: error: {url}") or err.startswith(f"rig: error: {url!r}")
    assert needle in err


def test_cli_old_options_are_usage_errors(capsys):
    err = _cli_error(capsys, "--protocol", "stream")
    assert "--protocol" in err


def test_cli_bad_url_in_a_real_process_has_no_traceback():
    proc = _run_cli("sim://imu-stream?rate=fast")
    out, err = proc.communicate(timeout=20)
    assert proc.returncode == 2 and out == ""
    assert err == "rig: error: sim://imu-stream?rate=fast: rate='fast': must be an integer\n"
