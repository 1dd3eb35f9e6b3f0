"""The host BNO055 driver against the simulated chip, over a real pty with pyserial."""

from __future__ import annotations

import numpy as np
import pytest

from firmware_protocol.imu import bno055 as B
from models import quaternion as Q
from rig.devices.bno055 import Bno055
from rig.errors import RigConnectionError, RigError
from rig.sim.imu import Bno055Simulator
from rig.sim.limb import NoiseModel, SimulatedLimb


@pytest.fixture
def chip():
    limb = SimulatedLimb(sensors=2, noise=NoiseModel.ideal(), seed=4)
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
