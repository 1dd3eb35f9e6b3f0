"""Orientation sources: the interface recording and the live loop consume."""

from __future__ import annotations

import numpy as np
import pytest

from models import quaternion as Q
from rig.devices import (
    ImuSetSource,
    OrientationSource,
    ServoLimbSource,
    load_rig_config,
    open_port,
    open_source,
)
from rig.devices.config import loads_rig_config
from rig.errors import RigConfigError, RigConnectionError


def test_servo_limb_source_reports_the_patient_joint():
    cfg = load_rig_config("sim-shoulder")
    with open_port(cfg.servos.port) as port, \
            open_source(cfg, ports={cfg.servos.port: port}, rate_hz=200) as src:
        assert isinstance(src, ServoLimbSource) and isinstance(src, OrientationSource)
        assert src.names == ("shoulder",)
        batches = []
        for batch in src:
            batches.append(batch)
            if len(batches) == 10:
                break
        for (s,) in batches:
            assert s.kind == "joint" and s.name == "shoulder" and s.device_t is None
            truth = port.patient.joint(s.t - port.patient_t0)[0]
            assert np.degrees(Q.angle(Q.multiply(s.q, Q.conjugate(truth)))) < 1.0
        assert src.dropped == 0
        port.simulator.unplug(adapter=True)
        with pytest.raises(RigConnectionError):
            src.read(1.0)


def test_servo_source_turns_a_silent_bus_into_a_connection_error():
    """A reading that fails every attempt (a hiccup: the next status packets dropped) costs
    that reading only; a bus that stays silent (the cable pulled) is lost once
    LOST_AFTER_S has passed without a good reading."""
    cfg = load_rig_config("sim-shoulder")
    with open_port(cfg.servos.port) as port, \
            open_source(cfg, ports={cfg.servos.port: port}) as src:
        assert src.read(1.0)
        bus = src.limb.bus
        port.simulator.drop_responses(bus.retries + 1)  # every attempt of one reading
        assert src.read(1.0) == [] and src.missed == 1
        assert src.read(1.0)  # the next reading comes: the recording goes on
        port.simulator.unplug()  # the bus cable: nobody answers, the adapter stays
        with pytest.raises(RigConnectionError, match="stopped answering"):
            for _ in range(10_000):  # each failed reading takes its attempts' timeouts
                src.read(1.0)
        assert src.missed > 1


def test_imu_set_source_names_segments():
    cfg = load_rig_config("sim-imu")
    with open_source(cfg) as src:
        assert isinstance(src, ImuSetSource) and src.names == ("thorax", "humerus")
        got = []
        while len(got) < 40:
            got += src.read(1.0)
        assert {s.name for s in got} == {"thorax", "humerus"}
        assert all(s.kind == "sensor" and s.device_t is not None for s in got)
        # sensors.raw: true in sim-imu: accelerometer ~ g, magnetometer ~ 48 µT
        raw = np.array([s.raw for s in got])
        assert raw.shape == (len(got), 9) and np.isfinite(raw).all()
        assert np.abs(np.linalg.norm(raw[:, :3], axis=1) - 9.81).max() < 3.0
        assert np.abs(np.linalg.norm(raw[:, 6:], axis=1) - 48.0).max() < 10.0
        assert src.dropped == 0


def test_bno055_pair_source():
    cfg = loads_rig_config("""
name: two-chips
joint: {name: shoulder, side: left, parent: thorax, child: humerus}
sensors:
  protocol: bno055
  port: ["sim://bno055?sensor=0&seed=2", "sim://bno055?sensor=1&seed=2"]
  rate_hz: 50
  segments: {thorax: 0, humerus: 1}
  raw: true
""", "two-chips.yaml")
    with open_source(cfg) as src:
        batch = []
        while not batch:
            batch = src.read(1.0)
        assert [s.name for s in batch] == ["thorax", "humerus"]
        assert all(np.linalg.norm(s.q) == pytest.approx(1.0) for s in batch)
        assert all(s.raw.shape == (9,) and np.isfinite(s.raw).all() for s in batch)


def test_both_kinds_need_a_choice():
    cfg = load_rig_config("hardware-template")
    with pytest.raises(RigConfigError, match="say which"):
        open_source(cfg)
