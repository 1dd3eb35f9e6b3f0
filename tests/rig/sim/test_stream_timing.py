"""The stream board's timing contract on a loaded host (issue 37, item 4): the simulated board
measures its patient in batches (a running clock measures ahead into a FIFO, so its cost per
sample is a fraction of one ``measure_many`` call), and answers a command that arrives while it
catches up on its grid before the rest of the backlog (one batch of work per server iteration).

Counts of work, never clocks: the running clock here is a :class:`StepClock` the test moves,
and the command is sent from inside the simulator's own measurement, at a known point.

The limb rigs' boards are served from a process of their own (``process=on``, as hardware is
outside the host): the recorder's process may be starved, the board is not; the patient's copy
in the recorder's process (its ground truth, and the calibration protocol it starts) moves as
the child's does.
"""

from __future__ import annotations

import numpy as np
import serial

from firmware_protocol.imu import stream as S
from rig.sim.clock import ManualClock
from rig.sim.imu import StreamImuSimulator
from rig.sim.limb import NoiseModel, SimulatedJoint

MAX_READS = 2000
"""Bound on the reads a receive loop makes (a count, not a clock)."""


class StepClock:
    """A running clock (no ``subscribe``: the simulator treats it as real time) that moves only
    when the test sets :attr:`t` — the simulator's server wakes at its deadlines meanwhile."""

    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


class CountingLimb:
    """A simulated limb whose ``measure_many`` calls are counted (``on_measure`` runs in the
    simulator's thread before each)."""

    def __init__(self, limb, on_measure=None) -> None:
        self.limb = limb
        self.calls = 0
        self.on_measure = on_measure

    def __getattr__(self, name):
        return getattr(self.limb, name)

    def measure_many(self, ts):
        self.calls += 1
        if self.on_measure is not None:
            self.on_measure(self.calls)
        return self.limb.measure_many(ts)


def _frames(ser: serial.Serial, dec: S.StreamDecoder, until) -> list:
    """Frames read from ``ser`` until ``until(frames)`` holds."""
    frames: list = []
    for _ in range(MAX_READS):
        dec.feed(ser.read(max(1, ser.in_waiting)))
        frames.extend(dec.drain())
        if until(frames):
            return frames
    raise AssertionError(f"gave up after {len(frames)} frames")


def _ack(frames: list, seq: int) -> int | None:
    """Index of the ACK of command ``seq`` in ``frames`` (None if absent)."""
    return next((i for i, f in enumerate(frames)
                 if isinstance(f, S.Ack) and f.command_seq == seq), None)


def test_a_running_clock_measures_the_patient_in_batches():
    """200 samples streamed one slot at a time: before, one ``measure_many`` per sample (a
    four-segment chain ~0.8 ms each, a fifth of a core at 200 Hz); now one per
    ``AHEAD_S`` of slots."""
    clock = StepClock()
    limb = CountingLimb(SimulatedJoint(sensors=2, noise=NoiseModel.ideal(), seed=4))
    rate, n = 200, 200
    with StreamImuSimulator(limb, rate_hz=rate, clock=clock, flow_control=True) as sim, \
            serial.Serial(sim.port, timeout=0.05) as ser:
        dec = S.StreamDecoder()
        ser.write(S.encode_command(0, S.CommandType.START))
        _frames(ser, dec, lambda fs: _ack(fs, 0) is not None)
        for k in range(1, n):
            clock.t = k / rate
            assert sim.wait_for(lambda k=k: sim.samples_sent >= k + 1, timeout=30.0)
        ser.write(S.encode_command(1, S.CommandType.STOP))
        _frames(ser, dec, lambda fs: _ack(fs, 1) is not None)
        sent = sim.samples_sent
    assert sent == n
    assert limb.calls <= n // 10, limb.calls  # was n; now n / (1 + AHEAD_S * rate) + 1


def test_a_command_is_answered_before_the_rest_of_the_backlog():
    """The board 999 slots behind its grid when STOP arrives (sent while it measures its
    first batch): the ACK comes after at most one batch, not after the backlog (with flow
    control: 8 kB of it)."""
    clock = ManualClock()
    host: dict = {}

    def stop_now(call: int) -> None:  # in the simulator's thread, inside its catch-up
        if host.pop("armed", False):
            host["ser"].write(S.encode_command(1, S.CommandType.STOP))

    limb = CountingLimb(SimulatedJoint(sensors=1, noise=NoiseModel.ideal(), seed=4), stop_now)
    with StreamImuSimulator(limb, rate_hz=200, clock=clock, flow_control=True) as sim, \
            serial.Serial(sim.port, timeout=0.05) as ser:
        host["ser"] = ser
        dec = S.StreamDecoder()
        ser.write(S.encode_command(0, S.CommandType.START))
        _frames(ser, dec, lambda fs: _ack(fs, 0) is not None)
        assert sim.wait_for(lambda: sim.samples_sent == 1)  # the slot at START: sent
        host["armed"] = True
        clock.advance(999 / 200)  # 999 more slots due at once
        frames = _frames(ser, dec, lambda fs: _ack(fs, 1) is not None)
        before_ack = sum(isinstance(f, S.Sample) and f.timestamp_us > 0  # not the slot at START
                         for f in frames[:_ack(frames, 1)])
        assert not sim.streaming
    assert 0 < before_ack <= StreamImuSimulator._BATCH, before_ack  # was ~270


# -- a board served from a process of its own --------------------------------------------------


def test_the_limb_rigs_boards_are_served_from_their_own_process():
    """``sim-leg`` / ``sim-arm``: the board runs in a child process (as hardware is outside the
    host: a busy recorder does not starve it), and the recorder still knows a simulated patient
    performs the calibration steps (before: the board was a thread of the recorder)."""
    from rig.record.rigio import load_config, open_rig

    for name in ("sim-leg", "sim-arm"):
        with open_rig(load_config(name), calibrate=True) as rig:
            (port,) = rig.ports
            assert port.simulator is None and port.is_simulated, name
            assert rig.simulators == [] and rig.simulated, name
            assert rig.protocol is not None and rig.protocol.limb == name[4:]


def test_a_board_in_its_own_process_moves_as_the_patient_copy_here():
    """The child's patient and this process's copy move alike (ground truth within the
    protocol's quantisation), the calibration protocol started here included — its time scale
    and clock origin come from the child."""
    from calibration.protocol import LimbCalibrationProtocol
    from models import quaternion as Q
    from rig.devices.ports import open_port
    from rig.devices.stream_imu import StreamImu
    from rig.sim.imu import stream_patient, stream_query

    url = ("sim://imu-stream?sensors=4&limb=arm&seed=5&rate=100&noise=off&flow=on"
           "&time_scale=10&process=on")
    with open_port(url) as port:
        sp = port.simulated_patient
        assert port.simulator is None and sp.scale == 10.0
        sp.start_protocol(LimbCalibrationProtocol("arm"), lead_s=0.5)
        start = sp.limb.protocol_start_s
        got = []
        with StreamImu(port, rate_hz=100) as imu:
            for _ in range(MAX_READS):  # into the shoulder's step, 5 s after the neutral pose
                got += imu.read(0.5)
                if got and got[-1].device_t - sp.device_t0 > start + 7.0:
                    break
    t = np.array([s.device_t for s in got]) - sp.device_t0
    q = np.array([s.q for s in got])
    k = np.array([s.sensor for s in got])
    keep = t > start + 0.5
    assert keep.sum() > 400

    def off_deg(limb) -> np.ndarray:
        truth = limb.truth(t[keep]).sensors[np.arange(keep.sum()), k[keep]]
        return np.degrees(Q.angle(Q.multiply(q[keep], Q.conjugate(truth))))

    assert off_deg(sp.limb).max() < 0.05
    free = stream_patient(stream_query(url, ("process",)))  # the same patient, no protocol
    assert off_deg(free).max() > 5.0
