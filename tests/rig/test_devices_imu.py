"""IMU drivers over real ptys: the stream-protocol board and the BNO055 (timeouts retried)."""

from __future__ import annotations

import os
import threading

import numpy as np
import pytest

from firmware_protocol.imu import bno055 as B
from models import quaternion as Q
from rig.devices import Bno055, StreamImu, open_port
from rig.errors import RigConfigError, RigConnectionError, RigTimeoutError

IMU_BACKENDS = [pytest.param("sim", id="sim"),
                pytest.param("hardware", id="hardware", marks=pytest.mark.hardware)]


def angle_deg(p, q):
    return float(np.degrees(Q.angle(Q.multiply(p, Q.conjugate(q)))))


def collect(imu, n):
    out = []
    while len(out) < n:
        out += imu.read(1.0)
    return out


def test_stream_samples_are_timestamped_and_true():
    # flow=on, max_lag=none: the board waits for the host and never skips (a loaded machine)
    with open_port("sim://imu-stream?sensors=3&rate=200&noise=off&seed=3&max_lag=none&flow=on") \
            as port, \
            StreamImu(port, sensors=[0, 2], rate_hz=200) as imu:
        assert imu.identity.present_mask == 0b111 and imu.sensors == [0, 2]
        samples = collect(imu, 100)
        assert {s.sensor for s in samples} == {0, 2}
        for sensor in (0, 2):
            mine = [s for s in samples if s.sensor == sensor]
            dt = np.diff([s.device_t for s in mine])
            assert np.allclose(dt, 1 / 200, atol=1e-6)  # the device's sample grid, no gaps
            assert np.all(np.diff([s.t for s in mine]) > 0)
            for s in mine[::10]:
                truth = port.patient.truth(s.device_t).sensors[0, sensor]
                assert angle_deg(s.q, truth) < 0.1  # 2^-14 quantisation
        assert imu.dropped == 0 and imu.corrupt == 0


def test_stream_raw_samples_in_si_units():
    """raw=True on a 1.1 board: each sample carries accelerometer, gyroscope and magnetometer
    in the sensor frame — checked against the sample's own quaternions (noise off)."""
    url = "sim://imu-stream?sensors=2&rate=200&noise=off&seed=3&flow=on"
    with open_port(url) as port, StreamImu(port, rate_hz=200, raw=True) as imu:
        assert port.simulator.fields == 1
        samples = collect(imu, 200)
    for sensor in (0, 1):
        mine = [s for s in samples if s.sensor == sensor]
        raw = np.array([s.raw for s in mine])
        q = np.array([s.q for s in mine])
        assert raw.shape == (len(mine), 9) and np.isfinite(raw).all()
        # at rest the accelerometer reads +g along world up: the arm moves slowly, so the
        # specific force stays within a few degrees of the sensor's up axis
        up = Q.rotate(Q.conjugate(q), np.array([0.0, 0.0, 1.0]))
        cos = np.sum(raw[:, :3] * up, axis=1) / np.linalg.norm(raw[:, :3], axis=1)
        assert np.degrees(np.arccos(np.clip(cos, -1, 1))).max() < 10.0
        assert np.abs(np.linalg.norm(raw[:, 6:], axis=1) - 48.0).max() < 1.0  # µT
        # the gyroscope is the rate of the quaternions (sensor frame), within the record's
        # resolution and the finite difference
        dt = np.diff([s.device_t for s in mine])
        rate = Q.to_rotation(Q.multiply(Q.conjugate(q[:-1]), q[1:])).as_rotvec() / dt[:, None]
        mid = 0.5 * (raw[:-1, 3:6] + raw[1:, 3:6])
        assert np.median(np.linalg.norm(rate - mid, axis=1)) < 0.02  # rad/s
        if sensor == 1:
            assert np.linalg.norm(mid, axis=1).max() > 0.2  # the arm does move


def test_stream_raw_needs_protocol_1_1_and_at_most_8_sensors():
    with open_port("sim://imu-stream?sensors=2&protocol=1.0") as port:
        with pytest.raises(RigConfigError) as err:
            StreamImu(port, raw=True)
        assert "speaks stream protocol 1.0; raw samples need 1.1" in str(err.value)
        assert "\n" not in str(err.value)
        with StreamImu(port) as imu:  # without raw, a 1.0 board is fine
            assert collect(imu, 2)[0].raw is None
    with open_port("sim://imu-stream?sensors=9") as port:
        with pytest.raises(RigConfigError, match="at most 8 sensors"):
            StreamImu(port, raw=True)
        with StreamImu(port, sensors=range(8), raw=True) as imu:
            assert collect(imu, 8)[0].raw.shape == (9,)


def test_stream_host_without_raw_turns_a_left_over_raw_field_off():
    with open_port("sim://imu-stream?sensors=2&flow=on") as port:
        with StreamImu(port, raw=True) as imu:
            assert collect(imu, 2)[0].raw is not None
        assert port.simulator.fields == 1  # the board keeps it, as the SPEC says
        with StreamImu(port) as imu:
            assert port.simulator.fields == 0
            assert all(s.raw is None for s in collect(imu, 4))


def test_stream_sequence_gaps_are_counted():
    with open_port("sim://imu-stream?sensors=2&rate=400&flow=off") as port, \
            StreamImu(port, rate_hz=400) as imu:
        collect(imu, 10)
        # the host stops reading: the UART-like board loses what the pty cannot hold
        assert port.simulator.wait_for(lambda: port.simulator.bytes_dropped > 0, timeout=30)
        # the pty still holds up to a few seconds of frames from before the loss: read through
        # them (bounded) until the gap arrives
        for _ in range(100):
            imu.read(0.2)
            if imu.dropped + imu.corrupt > 0:
                break
        assert imu.dropped + imu.corrupt > 0


def test_stream_board_replugged_is_reconnected():
    with open_port("sim://imu-stream?sensors=2&rate=100") as port, \
            StreamImu(port, rate_hz=100, reconnect_s=5.0) as imu:
        collect(imu, 5)
        port.simulator.disconnect()
        port.simulator.reconnect()
        assert collect(imu, 5)
        assert imu.reconnects == 1


def test_stream_board_gone_is_a_connection_error():
    with open_port("sim://imu-stream?sensors=2&rate=100") as port, \
            StreamImu(port, rate_hz=100, reconnect_s=0.3) as imu:
        collect(imu, 5)
        port.simulator.disconnect()
        with pytest.raises(RigConnectionError, match="stopped answering"):
            for _ in range(50):
                imu.read(0.2)


def test_stream_refuses_what_the_board_cannot_do():
    with open_port("sim://imu-stream?sensors=2&rate=100") as port:
        with pytest.raises(RigConfigError, match="sensor 5 is not present"):
            StreamImu(port, sensors=[0, 5])
        with pytest.raises(RigConfigError, match="sample rate"):
            StreamImu(port, rate_hz=5000)


@pytest.fixture(params=IMU_BACKENDS)
def bno_port(request):
    if request.param == "hardware":
        if os.environ.get("RIG_IMU_PROTOCOL", "bno055") != "bno055" or \
                not os.environ.get("RIG_IMU_PORT"):
            pytest.skip("RIG_IMU_PORT with RIG_IMU_PROTOCOL=bno055 needed")
        yield os.environ["RIG_IMU_PORT"]
        return
    with open_port("sim://bno055?seed=4&noise=off") as port:
        yield port


def test_bno055_sample(bno_port):
    with Bno055(bno_port) as chip:
        chip.set_mode(B.OperationMode.NDOF)
        s = chip.sample()
        assert np.linalg.norm(s.q) == pytest.approx(1.0)
        assert 0 <= s.calibration <= 255 and s.device_t is None


def test_bno055_timeout_is_retried_then_raised():
    """A silent device: every attempt times out, is retried, then RigTimeoutError (the retry
    branch the old driver never reached). The requests seen on the wire are counted."""
    master, slave = os.openpty()
    try:
        os.set_blocking(master, False)
        path = os.ttyname(slave)
        with pytest.raises(RigTimeoutError, match=r"read of 0x00: no answer.*4 attempts"):
            Bno055(path, timeout=0.05, retries=3)
        decoder = B.RequestDecoder()
        decoder.feed(os.read(master, 4096))
        requests = []
        while (r := decoder.next()) is not None:
            requests.append(r)
        assert len(requests) == 4 and all(isinstance(r, B.ReadRequest) for r in requests)
    finally:
        os.close(master)
        os.close(slave)


def test_bno055_first_answer_lost_then_retry_succeeds():
    """A device on a real pty that ignores the first request and answers the second."""
    master, slave = os.openpty()
    stop = threading.Event()

    def device():
        decoder, seen = B.RequestDecoder(), 0
        while not stop.is_set():
            try:
                decoder.feed(os.read(master, 256))
            except BlockingIOError:
                stop.wait(0.005)
                continue
            while decoder.next() is not None:
                seen += 1
                if seen > 1:
                    os.write(master, B.encode_read_response(bytes([B.CHIP_ID_VALUE])))

    os.set_blocking(master, False)
    thread = threading.Thread(target=device, name="test-bno055-device")
    thread.start()
    try:
        with Bno055(os.ttyname(slave), timeout=0.1, retries=2) as chip:
            assert chip.retried == 1
    finally:
        stop.set()
        thread.join()
        os.close(master)
        os.close(slave)
