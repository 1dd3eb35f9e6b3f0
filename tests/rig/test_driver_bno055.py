"""The host BNO055 driver against the simulated chip, over a real pty with pyserial."""

from __future__ import annotations

import numpy as np
import pytest

from firmware_protocol.imu import bno055 as B
from models import quaternion as Q
from rig.devices.bno055 import Bno055
from rig.errors import RigConnectionError, RigError
from rig.sim.imu import Bno055Simulator
from rig.sim.limb import NoiseModel, SimulatedJoint


@pytest.fixture
def chip():
    limb = SimulatedJoint(sensors=2, noise=NoiseModel.ideal(), seed=4)
    with Bno055Simulator(limb) as sim, Bno055(sim.port) as dev:
        yield sim, dev


def test_reads_chip_id_and_fused_quaternion(chip):
    sim, dev = chip
    assert dev.chip_id() == B.CHIP_ID_VALUE
    dev.set_mode(B.OperationMode.NDOF)
    q = dev.quaternion()
    assert np.linalg.norm(q) == pytest.approx(1.0)
    truth = sim.last.truth.sensors[0, sim.sensor]
    # register resolution is 1/16384 per component: well under 0.05°
    assert np.degrees(Q.angle(Q.multiply(q, Q.conjugate(truth)))) < 0.05


def test_raw_sample_in_one_burst_in_si_units():
    limb = SimulatedJoint(sensors=2, noise=NoiseModel.ideal(), seed=5)
    with Bno055Simulator(limb) as sim, Bno055(sim.port, raw=True) as dev:
        dev.set_mode(B.OperationMode.NDOF)
        s = dev.sample()
        m, k = sim.last, sim.sensor
        assert s.raw.shape == (9,)
        np.testing.assert_allclose(s.raw[:3], m.accel[k], atol=0.0051)  # 100 LSB per m/s²
        np.testing.assert_allclose(s.raw[3:6], m.gyro[k], atol=np.radians(1 / 32) + 1e-9)
        np.testing.assert_allclose(s.raw[6:], m.mag[k], atol=1 / 32 + 1e-9)  # 16 LSB per µT
        truth = m.truth.sensors[0, k]
        assert np.degrees(Q.angle(Q.multiply(s.q, Q.conjugate(truth)))) < 0.05
        # other units (mg, rad/s): the driver follows the UNIT_SEL it wrote
        dev.set_mode(B.OperationMode.CONFIG)
        dev.write(B.Register.UNIT_SEL, bytes([0x83]))
        dev.set_mode(B.OperationMode.NDOF)
        s = dev.sample()
        m = sim.last
        np.testing.assert_allclose(s.raw[:3], m.accel[k], atol=0.0051)  # 1 mg LSB
        np.testing.assert_allclose(s.raw[3:6], m.gyro[k], atol=1 / 1800 + 1e-9)
    with Bno055Simulator(seed=5) as sim, Bno055(sim.port) as dev:
        dev.set_mode(B.OperationMode.NDOF)
        assert dev.sample().raw is None


def test_quaternion_outside_fusion_mode_is_an_error(chip):
    _, dev = chip
    dev.set_mode(B.OperationMode.CONFIG)
    with pytest.raises(RigError, match="not in a fusion mode"):
        dev.quaternion()


def test_write_refused_names_the_status(chip):
    _, dev = chip
    dev.set_mode(B.OperationMode.NDOF)
    with pytest.raises(RigError, match="write to 0x41 failed"):
        dev.write(B.Register.AXIS_MAP_CONFIG, b"\x24")  # config register outside CONFIG mode


def test_missing_port_is_a_connection_error(tmp_path):
    with pytest.raises(RigConnectionError, match="no such port"):
        Bno055(str(tmp_path / "ttyUSB9"))
