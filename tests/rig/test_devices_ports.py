"""Port strings choose the backend: sim:// starts a simulator on a pty, paths are checked."""

from __future__ import annotations

import os

import numpy as np
import pytest

from rig.devices.ports import open_port, real_time_port
from rig.errors import RigConfigError, RigConnectionError


def test_sim_dynamixel_port_serves_a_pty_and_close_stops_it():
    port = open_port("sim://dynamixel?ids=1,2&model=XM430-W350", baud=57600)
    try:
        assert port.is_simulated and port.kind == "sim-dynamixel"
        assert port.path.startswith("/dev/pts/") and os.path.exists(port.path)
        assert sorted(port.simulator.servos) == [1, 2]
        # no baud= in the URL: the servos run at the rate the host asked for
        assert all(s.baud_rate == 57600 for s in port.simulator.servos.values())
    finally:
        port.close()
    port.close()  # idempotent
    assert port.simulator.closed


@pytest.mark.parametrize("url", ["sim://bno055?seed=2", "sim://imu-stream?sensors=3&rate=50"])
def test_sim_imu_ports(url):
    with open_port(url) as port:
        assert port.path.startswith("/dev/pts/")
        assert port.patient is not None
    assert port.simulator.closed


@pytest.mark.parametrize(("url", "match"), [
    ("sim://dynamixel?ids=1&colour=red", "colour"),
    ("sim://toaster", "unknown simulated device 'toaster'"),
    ("tcp://host:1", "unknown scheme 'tcp'"),
    ("sim://dynamixel?ids=1&speed=2", "need patient="),
    ("sim://dynamixel?ids=1,2&patient=original", "no ID 3"),
    ("sim://dynamixel?ids=1,2,3&patient=no-such-shape", "no-such-shape"),
])
def test_bad_sim_urls_name_the_problem(url, match):
    with pytest.raises(RigConfigError, match=match):
        open_port(url)


def test_missing_and_non_serial_paths_fail_at_once(tmp_path):
    with pytest.raises(RigConnectionError, match="no such port"):
        open_port(str(tmp_path / "ttyUSB9"))
    with pytest.raises(RigConnectionError, match="not a serial port"):
        open_port("/dev/null")
    plain = tmp_path / "file"
    plain.write_text("x")
    with pytest.raises(RigConnectionError, match="not a serial port"):
        open_port(str(plain))


def test_back_driven_servos_follow_the_simulated_patient():
    from models import quaternion as Q
    from rig.devices import DynamixelBus, load_rig_config

    cfg = load_rig_config("sim-shoulder")
    kin = cfg.servos.kinematics()
    with DynamixelBus(cfg.servos.port, cfg.servos) as bus:
        port = bus.port
        assert port.patient is not None
        seen, ticks_list = [], []
        for _ in range(20):
            ticks = bus.read_ticks()
            q = kin.forward(ticks)
            truth = port.patient.joint(port.simulator.clock() - port.patient_t0)[0]
            seen.append(float(np.degrees(Q.angle(Q.multiply(q, Q.conjugate(truth))))))
            ticks_list.append(ticks)
        # within a few encoder ticks of the patient's joint (0.088° per tick)
        assert max(seen) < 1.0
        assert len({tuple(t) for t in ticks_list}) > 1  # the patient moves


def test_sim_dynamixel_unknown_key_lists_the_back_driving_keys_too():
    # the bus and the back-driven patient share one URL: the error names every key it accepts,
    # and a bus error names the URL as given
    with pytest.raises(RigConfigError) as err:
        open_port("sim://dynamixel?ids=1&bogus=2")
    msg = str(err.value)
    assert msg.startswith("sim://dynamixel?ids=1&bogus=2: unknown key 'bogus'")
    for key in ("patient", "chain", "speed", "excursion", "ids", "baud"):
        assert key in msg.split("known keys:")[1]
    with pytest.raises(RigConfigError, match=r"^sim://dynamixel\?ids=300&patient=original: "
                                             r"servo id must be 0\.\.252"):
        open_port("sim://dynamixel?ids=300&patient=original")


def test_sim_stream_is_the_short_form_of_imu_stream():
    port = open_port("sim://stream?sensors=2")
    try:
        assert port.kind == "sim-imu-stream" and port.path.startswith("/dev/")
    finally:
        port.close()


def test_simulated_patient_of_a_back_driven_port():
    from calibration.protocol import CalibrationProtocol
    from models import quaternion as Q
    from rig.devices import load_rig_config

    servos = load_rig_config("sim-shoulder").servos
    with open_port(servos.port + "&clock=manual&wire_time=off", baud=servos.baud) as port:
        sp = port.simulated_patient
        assert sp.back_drives and sp.limb is port.patient and sp.t0 == port.patient_t0
        clock = port.simulator.clock
        assert sp.now() == 0.0
        clock.advance(1.5)
        assert sp.now() == 1.5 and sp.time_at([clock()])[0] == 1.5  # manual: scale 1
        truth = sp.limb.joint(np.arange(0.0, 3.0, 0.01))
        chain_q, missed = sp.follow(truth)
        assert missed == 0
        assert np.degrees(Q.angle(Q.multiply(chain_q, Q.conjugate(truth)))).max() < 1e-6
        sp.start_protocol(CalibrationProtocol())
        assert sp.limb.protocol_start_s == 3.5  # 2 s of patient time after now


def test_simulated_patient_of_imu_ports_and_none_elsewhere():
    with open_port("sim://imu-stream?sensors=2&clock=manual") as port:
        sp = port.simulated_patient
        assert not sp.back_drives and not sp.protocol_pinned
        assert sp.limb is port.simulator.limb and sp.device_t0 == 0.0
        with pytest.raises(ValueError, match="back-drives no servo chain"):
            sp.follow(np.array([[1.0, 0.0, 0.0, 0.0]]))
    with open_port("sim://bno055?calibrate=off&clock=manual") as port:
        assert port.simulated_patient.protocol_pinned
    with open_port("sim://dynamixel?ids=1") as port:
        assert port.simulated_patient is None and port.patient is None
        assert port.patient_t0 == 0.0


def test_simulated_patient_time_on_a_scaled_clock():
    import time

    with open_port("sim://imu-stream?sensors=1&time_scale=8") as port:
        sp, sim = port.simulated_patient, port.simulator
        assert sp.scale == 8.0
        host = time.monotonic()
        assert sp.time_at([host])[0] == pytest.approx(sim.clock.at(host) - sim.started_at,
                                                      abs=1e-6)


def test_port_closers_run_once_in_reverse_order():
    from rig.devices.ports import Port

    calls = []
    port = Port(url="x", path="x")
    port.add_closer(lambda: calls.append(1))
    port.add_closer(lambda: calls.append(2))
    port.close()
    port.close()
    assert calls == [2, 1] and port.closed


def test_a_live_loop_runs_a_simulator_in_its_own_time():
    """``time_scale`` of a simulated bus is dropped under the live loop (its Bus Watchdog and
    motion in the loop's time), with a note naming the port; other ports are left alone."""
    url, note = real_time_port("sim://dynamixel?ids=1-3&time_scale=20&seed=2")
    assert url == "sim://dynamixel?ids=1-3&seed=2"
    assert "time_scale" in note and "sim://dynamixel?ids=1-3&time_scale=20&seed=2" in note
    for same in ("sim://dynamixel?ids=1-3&seed=2", "/dev/ttyUSB0", "sim://dynamixel"):
        assert real_time_port(same) == (same, None)
