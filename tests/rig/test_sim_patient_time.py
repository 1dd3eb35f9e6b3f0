"""``Port.patient_t0`` of the ``sim://`` ports: when the simulated patient's motion time was 0,
on real, manual and scaled simulator clocks (the ground truth tests compare readings with)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import serial

from firmware_protocol.imu import bno055 as B
from models import quaternion as Q
from rig.devices import DynamixelBus, load_rig_config
from rig.devices.ports import open_port
from rig.sim.clock import ManualClock, ScaledClock

SERVOS = load_rig_config("sim-shoulder").servos


def _angle_deg(a, b) -> float:
    return float(np.degrees(Q.angle(Q.multiply(a, Q.conjugate(b)))))


def test_back_driven_servos_follow_the_patient_on_a_manual_clock():
    url = SERVOS.port + "&clock=manual&wire_time=off"
    kin = SERVOS.kinematics()
    with open_port(url, baud=SERVOS.baud) as port, DynamixelBus(port, SERVOS) as bus:
        clock = port.simulator.clock
        assert isinstance(clock, ManualClock)
        assert clock() - port.patient_t0 == 0.0  # the patient starts with the simulator
        errors = []
        for _ in range(8):
            clock.advance(0.75)
            q = kin.forward(bus.read_ticks())
            truth = port.patient.joint(clock() - port.patient_t0)[0]
            errors.append(_angle_deg(q, truth))
        # within a few encoder ticks of the patient's joint (0.088° per tick)
        assert max(errors) < 1.0, errors


@pytest.mark.parametrize("clock_key", ["", "&clock=manual", "&time_scale=8"])
def test_stream_imu_device_clock_is_zero_at_patient_t0(clock_key):
    """The stream device's clock is the patient's time: 0 at ``patient_t0`` (host time on real
    and scaled clocks, the simulator clock's reading on a manual one)."""
    with open_port("sim://imu-stream?sensors=2&rate=200" + clock_key) as port:
        sim = port.simulator
        t0 = port.patient_t0
        if isinstance(sim.clock, ScaledClock):
            assert sim.clock.scale == 8.0
            t0 = sim.clock.at(t0)  # host time -> the simulator clock's reading
        assert sim.device_time_us(now=t0) == sim.timestamp_offset_us


def test_bno055_samples_the_patient_at_patient_time_on_a_manual_clock():
    with open_port("sim://bno055?rate=100&seed=2&clock=manual") as port, \
            serial.Serial(port.path, 115200, timeout=0.5) as ser:
        sim = port.simulator
        sim.clock.advance(1.234)
        ser.write(B.encode_read(0x20, 8))  # the quaternion: the chip samples the patient
        assert len(ser.read(10)) == 10  # 0xBB, length, 8 bytes
        expected = math.floor((sim.clock() - port.patient_t0) * 100) / 100
        assert sim.last.t == pytest.approx(expected, abs=1e-9)
        assert expected == pytest.approx(1.23)
