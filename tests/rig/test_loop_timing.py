"""Issue 19: the pieces of a loop that holds its rate, checked by content and counts (never by
wall time): the USB adapter's latency model, a servo bus in a process of its own, late cycles
told apart by cause, real-time scheduling and CPU affinity, and a host stall that is not a
fault."""

from __future__ import annotations

import dataclasses
import math
import os
import sys
from pathlib import Path

import numpy as np
import pytest

from models.oracle import ConstraintOracle
from rig.devices import DynamixelBus, load_rig_config
from rig.devices.ports import open_port
from rig.errors import RigConfigError
from rig.loop import EnforcementLoop, LoopConfig, ScriptedTargets, SupervisorConfig, realtime
from rig.loop.runner import prepare_servo_limb
from rig.loop.telemetry import CAUSES, count_causes, late_causes
from rig.sim.dynamixel import bus_from_url
from rig.sim.dynamixel.bus import latency_timer_tick

ROOT = Path(__file__).resolve().parents[2]
RIG = load_rig_config("sim-shoulder")
URL = "sim://dynamixel?ids=1,2,3&model=XM430-W350&return_delay_us=0"


# --------------------------------------------------------------------------- USB latency
@pytest.mark.parametrize(("t", "expected"), [
    (10.0, 10.0),        # on a tick: delivered on it
    (10.0001, 10.001),   # just after: the next tick
    (10.0009, 10.001),
    (10.001, 10.001),
    (10.001 + 1e-13, 10.001),  # float rounding of a tick: still that tick
])
def test_replies_reach_the_host_at_the_next_latency_timer_tick(t, expected):
    assert latency_timer_tick(t, 0.0, 0.001) == pytest.approx(expected, abs=1e-12)


def test_without_a_latency_timer_replies_arrive_when_on_the_wire():
    assert latency_timer_tick(10.0001234, 3.0, 0.0) == 10.0001234


def test_ticks_are_counted_from_the_adapter_epoch():
    # a timer started at 0.25 ms ticks at 0.25, 1.25, 2.25, ... ms
    assert latency_timer_tick(0.0013, 0.00025, 0.001) == pytest.approx(0.00225, abs=1e-12)


@pytest.mark.parametrize(("query", "latency_s"), [
    ("", 0.001),                         # a U2D2 with its latency timer at 1 ms
    ("&usb_latency_ms=16", 0.016),       # the FTDI default
    ("&usb_latency_ms=0", 0.0),
    ("&wire_time=off", 0.0),             # no wire time: no adapter delay either
])
def test_the_url_sets_the_latency_timer(query, latency_s):
    with bus_from_url(URL + query) as bus:
        assert bus.usb_latency_s == pytest.approx(latency_s)


@pytest.mark.parametrize(("query", "message"), [
    ("&usb_latency_ms=2&wire_time=off", "usb_latency_ms=2 needs wire_time=on"),
    ("&usb_latency_ms=-1", "usb_latency_ms='-1': must be a finite number in [0.0, 255.0]"),
    ("&usb_latency_ms=fast", "usb_latency_ms='fast': must be a number"),
])
def test_bad_latency_keys_are_named(query, message):
    with pytest.raises(RigConfigError, match=message.replace("[", r"\[").replace("]", r"\]")
                       .replace("(", r"\(")):
        bus_from_url(URL + query)


def test_the_sdk_reads_through_a_slow_latency_timer():
    """An adapter left at the FTDI default (16 ms): every read still succeeds, through the
    unchanged SDK, once the driver's packet timeout allows for the timer."""
    servos = dataclasses.replace(RIG.servos, port=URL + "&usb_latency_ms=16", latency_ms=16.0)
    with open_port(servos.port, baud=servos.baud) as port, DynamixelBus(port, servos) as bus:
        for _ in range(5):
            np.testing.assert_array_equal(bus.read_ticks(), [2048, 2048, 2048])


# --------------------------------------------------------------------------- own process
def _simulator_processes(url: str) -> list[int]:
    """Child simulators serving a URL that starts with ``url``."""
    pids = []
    for pid in os.listdir("/proc"):
        if not pid.isdigit():
            continue
        try:
            with open(f"/proc/{pid}/cmdline", "rb") as fh:
                cmd = fh.read().split(b"\0")
        except OSError:
            continue
        if b"--stop-on-stdin-eof" in cmd and any(c.startswith(url.encode()) for c in cmd):
            pids.append(int(pid))
    return pids


def test_a_bus_in_its_own_process_speaks_to_the_unchanged_sdk():
    url = URL + "&seed=4242&process=on"
    servos = dataclasses.replace(RIG.servos, port=url)
    with open_port(url, baud=servos.baud) as port:
        assert port.simulator is None and port.is_simulated and port.kind == "sim-dynamixel"
        assert _simulator_processes(URL + "&seed=4242")  # the child serves it (process= dropped)
        with DynamixelBus(port, servos) as bus:
            np.testing.assert_array_equal(bus.read_ticks(), [2048, 2048, 2048])
            bus.set_torque(True)
            bus.write_goal_ticks([2100, 2000, 2048])
    assert _simulator_processes(URL + "&seed=4242") == []  # closing the port stopped it


def test_separate_process_is_a_default_the_url_can_refuse():
    with open_port(URL + "&process=off", separate_process=True) as port:
        assert port.simulator is not None  # served from this process
    with open_port(URL, separate_process=True) as port:
        assert port.simulator is None and port.is_simulated


@pytest.mark.parametrize(("query", "message"), [
    ("&process=on&ids=x", "the simulator process did not start: sim://dynamixel?ids=1,2,3"),
    ("&process=on&clock=manual", "clock=manual: nothing would advance the clock"),
    ("&process=maybe", "process='maybe': must be on or off"),
])
def test_a_process_bus_with_a_bad_url_fails_in_one_line(query, message):
    url = URL.replace("ids=1,2,3", "ids=x") if "ids=x" in query else URL
    query = query.replace("&ids=x", "")
    with pytest.raises(RigConfigError) as err:
        open_port(url + query)
    text = str(err.value)
    assert "\n" not in text
    assert (message if "ids" not in message else "ids='x': must be a list of integers") in text


def test_rig_sim_servos_refuses_process_key(rig_cli):
    code, _, err = rig_cli(["sim", "servos", URL + "&process=on"])
    assert code == 2 and "process= is for a port opened by another program" in err


# --------------------------------------------------------------------------- causes
def test_overruns_are_put_down_to_the_part_that_grew():
    late = np.array([0.05, 0.05, 3.0, 0.05, 0.05, 0.05, 0.9, 0.05])
    bus = np.array([1.8, 1.8, 1.8, 6.0, 1.8, 1.8, 1.8, 1.8])
    comp = np.array([0.1, 0.1, 0.1, 0.1, 5.0, 0.1, 0.1, 0.1])
    over = np.array([0, 0, 1, 1, 1, 0, 0, 0], dtype=bool)
    causes = late_causes(late, bus, comp, over)
    assert [CAUSES[c] if c >= 0 else None for c in causes] == [
        None, None, "scheduler", "bus", "compute",
        None,          # starts on time after an overrun
        "scheduler",   # 0.9 ms late with no overrun before it: the host woke it late
        None]
    assert count_causes(causes, over) == {"scheduler": 1, "bus": 1, "compute": 1}


def test_a_late_start_after_an_overrun_inherits_its_cause():
    late = np.array([0.0, 0.0, 2.0, 0.0])
    bus = np.array([1.0, 9.0, 1.0, 1.0])
    comp = np.zeros(4)
    over = np.array([False, True, False, False])
    causes = late_causes(late, bus, comp, over)
    assert CAUSES[causes[1]] == "bus" and CAUSES[causes[2]] == "bus" and causes[3] == -1


def test_no_cycles_no_causes():
    assert late_causes([], [], [], []).tolist() == []
    assert count_causes(np.array([], dtype=int)) == {c: 0 for c in CAUSES}


# --------------------------------------------------------------------------- realtime
def test_a_cpu_the_process_may_not_use_is_refused():
    with pytest.raises(RigConfigError, match="--cpu 4096: not a CPU this process may run on"):
        realtime.check_cpu(4096)
    realtime.check_cpu(None)
    realtime.check_cpu(min(os.sched_getaffinity(0)))


def test_realtime_and_affinity_are_undone():
    policy, cpus = os.sched_getscheduler(0), os.sched_getaffinity(0)
    cpu = min(cpus)
    restore, notes = realtime.apply(realtime=True, cpu=cpu)
    try:
        assert os.sched_getaffinity(0) == {cpu}
        fifo_notes = [n for n in notes if "normal priority" in n]
        qos_notes = [n for n in notes if realtime.CPU_LATENCY_DEVICE in n]
        assert len(notes) == len(fifo_notes) + len(qos_notes) and len(qos_notes) <= 1
        if fifo_notes:  # not permitted here: one line saying so, the loop at normal priority
            assert len(fifo_notes) == 1
            assert os.sched_getscheduler(0) == policy
        else:
            assert os.sched_getscheduler(0) == os.SCHED_FIFO
    finally:
        restore()
    assert os.sched_getscheduler(0) == policy and os.sched_getaffinity(0) == cpus


def test_the_cpu_latency_request_is_written_and_held_until_released(tmp_path):
    """The PM QoS request is the 32-bit value written to the device, held while the file is
    open (a regular file stands in for /dev/cpu_dma_latency: the bytes are the same)."""
    dev = tmp_path / "cpu_dma_latency"
    dev.write_bytes(b"")
    before = set(os.listdir("/proc/self/fd"))
    release, note = realtime.hold_cpu_latency(0, device=str(dev))
    assert note is None
    assert dev.read_bytes() == (0).to_bytes(4, sys.byteorder, signed=True)
    assert len(set(os.listdir("/proc/self/fd")) - before) == 1  # held open
    release()
    assert set(os.listdir("/proc/self/fd")) == before


def test_a_system_without_the_cpu_latency_device_gets_one_line(tmp_path):
    release, note = realtime.hold_cpu_latency(0, device=str(tmp_path / "missing"))
    release()
    assert note is not None and "\n" not in note and "does not exist" in note


# --------------------------------------------------------------------------- host stalls
@pytest.mark.parametrize("stall_s", [0.02, 0.09])
def test_a_host_stall_shorter_than_the_stale_limit_is_not_a_fault(stall_s):
    """The loop reads the servos before it judges their age, so a host that stalls (the loop's
    process not scheduled) for less than the stale limit never puts the limb in the safe
    state: the first cycle after the stall has fresh data. The stall is simulated time on the
    manual clock the bus and the loop share."""
    constraint = RIG.load_constraint()
    oracle = ConstraintOracle(constraint)
    cfg = LoopConfig(rate_hz=200.0, watchdog_ms=1000,
                     supervisor=SupervisorConfig(stale_present_s=0.1))
    servos = dataclasses.replace(RIG.servos, port=URL)
    with open_port(URL + "&clock=manual&wire_time=off", baud=servos.baud) as port:
        clk = port.simulator.clock

        def on_cycle(loop, k):
            if k == 40:
                clk.advance(stall_s)  # the host stalls before the cycle's read

        limb = prepare_servo_limb(port, servos, oracle)
        try:
            loop = EnforcementLoop(limb, None, oracle, ScriptedTargets("sweep", oracle), cfg,
                                   clock=clk, sleep=clk.sleep, on_cycle=on_cycle)
            loop.setup()
            summary = loop.run(max_cycles=120)
        finally:
            limb.close()
    assert summary["safe_state_entries"] == 0 and summary["end_reason"] == "completed"
    # the stall is one overrun, counted under one cause; the deadlines it passed are skipped,
    # never caught up in a burst
    assert summary["overruns"] == 1 and sum(summary["overruns_by_cause"].values()) == 1
    assert summary["cycles"] + summary["skipped_deadlines"] == 120
    assert summary["skipped_deadlines"] >= math.floor(stall_s / 0.005) - 2


# --------------------------------------------------------------------------- rig enforce
def test_rig_enforce_serves_a_simulated_bus_from_its_own_process(tmp_path, rig_cli):
    """``rig enforce --rig sim-shoulder``: the servo simulator runs in a process of its own,
    as hardware is outside the host (no simulator thread shares the loop's interpreter)."""
    from rig.loop import EnforceRequest, run_enforce

    code, _, err = rig_cli(["train", "--constraint", str(ROOT / "models/shapes/original.yaml"),
                            "--out", str(tmp_path / "m.onnx")])
    assert code == 0, err
    result = run_enforce(EnforceRequest(rig="sim-shoulder", model=str(tmp_path / "m.onnx"),
                                        targets="script:slow", duration_s=0.3,
                                        stale_servo_ms=1000.0, watchdog_ms=1000))
    assert result.exit_status == 0 and result.summary["cycles"] > 0
    assert result.port.simulator is None and result.port.is_simulated and result.port.closed
