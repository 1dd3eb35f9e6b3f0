"""DynamixelBus through the real dynamixel_sdk: the same bodies on sim:// and on hardware.

``RIG_DXL_PORT=/dev/ttyUSB0`` (with ``RIG_DXL_IDS=1,2,3`` and ``RIG_DXL_BAUD``) runs the
``bus`` tests on real servos too; they only read (torque is never enabled on hardware).
Fault-injection tests need the simulator and run on it only.
"""

from __future__ import annotations

import os

import numpy as np
import pytest

from rig.devices import (
    DynamixelBus,
    JointKinematics,
    Servo,
    ServoAxis,
    ServoLimb,
    open_port,
    scan,
)
from rig.errors import (
    HardwareAlertError,
    RigConnectionError,
    RigError,
    RigProtocolError,
    RigTimeoutError,
    UnreachableError,
)

AXES = [(0, 0, 1), (0, 1, 0), (1, 0, 0)]


def servos(ids, lo=0, hi=4095):
    return [Servo(i, min_ticks=lo, max_ticks=hi) for i in ids]


def joint(ids, lo=0, hi=4095):
    """The kinematics of a joint moved by these servos (about Z, Y', X'')."""
    return JointKinematics([ServoAxis(i, AXES[k], min_ticks=lo, max_ticks=hi)
                            for k, i in enumerate(ids)])


BACKENDS = [pytest.param("sim", id="sim"),
            pytest.param("hardware", id="hardware", marks=pytest.mark.hardware)]


@pytest.fixture(params=BACKENDS)
def bus(request):
    """(port string or Port, ids, baud) for the back-to-back tests."""
    if request.param == "hardware":
        ids = [int(i) for i in os.environ.get("RIG_DXL_IDS", "1").split(",")]
        yield os.environ["RIG_DXL_PORT"], ids, int(os.environ.get("RIG_DXL_BAUD", "1000000"))
        return
    with open_port("sim://dynamixel?ids=1,2,3&model=XM430-W350&return_delay_us=0") as port:
        yield port, [1, 2, 3], 1_000_000


@pytest.fixture
def sim():
    with open_port("sim://dynamixel?ids=1,2,3&model=XM430-W350&return_delay_us=0") as port:
        yield port


# -- the same bodies on the simulator and on hardware ------------------------------------------
def test_open_reports_what_answered(bus):
    port, ids, baud = bus
    with DynamixelBus(port, servos(ids), baud=baud) as dxl:
        assert sorted(dxl.found) == sorted(ids)
        for info in dxl.found.values():
            assert info.model.startswith(("XM", "XL", "XC", "XH", "XW", "XD"))
            assert info.baud == baud
        assert dxl.ping(ids[0]).model_number == dxl.found[ids[0]].model_number


@pytest.mark.parametrize("fast", [False, True])
def test_sync_read_matches_single_reads(bus, fast):
    port, ids, baud = bus
    with DynamixelBus(port, servos(ids), baud=baud, fast=fast) as dxl:
        ticks = dxl.read_ticks()
        assert ticks.shape == (len(ids),) and ticks.dtype == np.int64
        single = [dxl.read_register(i, "Present Position") for i in ids]
        assert np.abs(ticks - single).max() < 50  # the limb may be moving (by hand)
        q = ServoLimb(dxl, joint(ids)).read_orientations()
        assert q.shape == (1, 4) and np.linalg.norm(q) == pytest.approx(1.0)


@pytest.mark.parametrize("fast", [False, True])
def test_the_receive_waits_for_bytes_instead_of_spinning(bus, fast):
    """The SDK's receive loop calls ``readPort`` until its packet is complete; ours waits in
    ``select`` while nothing has arrived, so a reply that takes half a millisecond (return
    delay 500 µs) costs a call or two per status packet, not hundreds of empty polls."""
    port, ids, baud = bus
    slow = port if isinstance(port, str) else \
        "sim://dynamixel?ids=1,2,3&model=XM430-W350&return_delay_us=500"
    with DynamixelBus(slow, servos(ids), baud=baud, fast=fast) as dxl:
        sdk_port = dxl._sdk_port
        calls = []
        read = sdk_port.readPort
        sdk_port.readPort = lambda n: calls.append(n) or read(n)
        for _ in range(20):
            dxl.read_ticks()
    packets = 20 * (1 if fast else len(ids))
    assert len(calls) <= 4 * packets, len(calls) / packets  # busy polling: ~300 per packet


@pytest.mark.parametrize("fast", [False, True])
def test_a_split_read_is_the_plain_read(bus, fast):
    """begin_read sends the request and returns; finish_read collects the reply (other work in
    between: the loop's compute); read_ticks is the two in a row."""
    port, ids, baud = bus
    with DynamixelBus(port, servos(ids), baud=baud, fast=fast) as dxl:
        whole = dxl.read_ticks()
        dxl.begin_read()
        sum(range(10_000))  # work while the reply travels
        split = dxl.finish_read()
        assert split.shape == whole.shape and split.dtype == np.int64
        assert np.abs(split - whole).max() < 50  # the limb may be moving (by hand)
        with pytest.raises(RuntimeError, match="without begin_read"):
            dxl.finish_read()


def test_bulk_read_and_torque_state(bus):
    port, ids, baud = bus
    with DynamixelBus(port, servos(ids), baud=baud) as dxl:
        data = dxl.bulk_read({i: (dxl.table["Firmware Version"].address, 1) for i in ids})
        assert {i: d[0] for i, d in data.items()} == {i: s.firmware
                                                      for i, s in dxl.found.items()}
        assert dxl.torque().dtype == bool


def test_scan_finds_the_chain(bus):
    port, ids, baud = bus
    found = scan(port, [baud], ids=range(max(ids) + 2), latency_ms=50)  # generous: loaded CI
    assert sorted(s.id for s in found) == sorted(ids)


# -- opening: every mistake is one typed error, before any work --------------------------------
def test_wrong_baud_is_nobody_answering():
    with open_port("sim://dynamixel?ids=1,2&baud=57600") as port:
        with pytest.raises(RigConnectionError, match="no servo answered at 1000000") as info:
            DynamixelBus(port, servos([1, 2]), baud=1_000_000)
        assert info.value.expected == [1, 2] and info.value.actual == []
        assert not port.simulator.closed  # a Port passed in is the caller's to close


def test_missing_id_is_named(sim):
    with pytest.raises(RigConnectionError, match="servo ID 4 did not answer"):
        DynamixelBus(sim, servos([1, 4]))


def test_wrong_model_is_named(sim):
    from rig.devices.config import ServosConfig

    cfg = ServosConfig(port="", axes=tuple(joint([1]).servos), model="XL430-W250")
    with pytest.raises(RigError, match="XL430-W250"):
        DynamixelBus(sim, cfg)


def test_port_string_simulator_is_stopped_with_the_chain():
    dxl = DynamixelBus("sim://dynamixel?ids=1", servos([1]))
    bus = dxl.port.simulator
    dxl.close()
    dxl.close()
    assert bus.closed


# -- fault injection (simulator) ------------------------------------------------------------
def test_timeout_is_retried_then_succeeds(sim):
    with DynamixelBus(sim, servos([1, 2, 3]), fast=False) as dxl:
        sim.simulator.drop_responses(1)
        assert dxl.read_ticks().shape == (3,)
        assert dxl.retried == 1


def test_persistent_timeout_is_a_typed_error_after_the_retries(sim):
    with DynamixelBus(sim, servos([1, 2, 3]), retries=2) as dxl:
        sim.simulator.unplug([2])
        with pytest.raises(RigTimeoutError, match="3 attempts") as info:
            dxl.read_ticks()
        assert info.value.port == str(sim)
        assert dxl.retried == 2


def test_a_split_read_raises_the_typed_errors_once(sim):
    """finish_read is one attempt (the loop retries with read_ticks): a dropped reply is a
    timeout, a garbled one a protocol error, an adapter gone a connection error."""
    with DynamixelBus(sim, servos([1, 2, 3]), retries=2) as dxl:
        sim.simulator.drop_responses(1)
        dxl.begin_read()
        with pytest.raises(RigTimeoutError):
            dxl.finish_read()
        sim.simulator.corrupt_responses(1)
        dxl.begin_read()
        with pytest.raises(RigProtocolError):
            dxl.finish_read()
        assert dxl.retried == 0
        assert dxl.read_ticks().shape == (3,)
        sim.simulator.unplug(adapter=True)
        with pytest.raises(RigConnectionError, match="unplugged"):
            dxl.begin_read()  # the request may still leave: the reply's wait finds it out
            dxl.finish_read()


def test_garbled_reply_is_retried(sim):
    with DynamixelBus(sim, servos([1, 2, 3])) as dxl:
        sim.simulator.corrupt_responses(1)
        dxl.read_ticks()
        assert dxl.retried == 1


def test_unplugged_adapter_is_a_connection_error_without_retries(sim):
    with DynamixelBus(sim, servos([1, 2, 3])) as dxl:
        dxl.read_ticks()
        sim.simulator.unplug(adapter=True)
        with pytest.raises(RigConnectionError, match="unplugged"):
            dxl.read_ticks()
        assert dxl.retried == 0
        with pytest.raises(RigConnectionError):
            dxl.write_goal_ticks([2048, 2048, 2048])


def test_hardware_error_is_an_event_with_the_reported_torque(sim):
    with DynamixelBus(sim, servos([1, 2, 3])) as dxl:
        dxl.set_torque(True)
        assert dxl.poll_alerts() == []
        sim.simulator.raise_hardware_error(2, "overload")
        dxl.read_ticks()  # not an exception: the read still ran
        assert dxl.alert_pending
        alerts = dxl.poll_alerts()
        assert [(a.dxl_id, a.names, a.torque) for a in alerts] == [(2, ("overload",), False)]
        assert not dxl.alert_pending
        assert dxl.torque().tolist() == [True, False, True]
        assert dxl.alert_pending  # every status of servo 2 carries the alert bit until reboot
        with pytest.raises(HardwareAlertError, match="ID 2: hardware alert overload"):
            dxl.set_torque(True)
        dxl.reboot(2)  # returns once the servo answers again (silent while it boots)
        assert sim.simulator.servo(2).listening(sim.simulator.clock())
        assert dxl.poll_alerts() == []


def test_goals_move_the_servos_and_out_of_range_goals_are_not_sent(sim):
    with DynamixelBus(sim, servos([1, 2, 3], lo=1024, hi=3072)) as dxl:
        dxl.configure()
        dxl.set_torque(True)
        dxl.write_goal_ticks([2100, 2000, 2300])
        # the bus is quiet after a sync write (no reply): read until the servo is there
        # (``wait_for`` would sleep until traffic or its timeout)
        for _ in range(500):
            if abs(int(dxl.read_ticks()[2]) - 2300) <= 1:
                break
        assert abs(sim.simulator.position(3) - 2300) < 1
        with pytest.raises(UnreachableError, match="ID 2") as info:
            dxl.write_goal_ticks([2100, 3500, 2300])
        assert info.value.actual == 3500 and info.value.expected == "1024..3072"
        assert abs(sim.simulator.position(2) - 2000) < 1  # nothing was sent
        limb = ServoLimb(dxl, joint([1, 2, 3], lo=1024, hi=3072))
        goal = limb.write_orientations(limb.kinematics.forward([2200, 1900, 2048]),
                                       dxl.read_ticks())
        assert goal.tolist() == [2200, 1900, 2048]


def test_configure_writes_registers_and_refuses_eeprom_with_torque_on(sim):
    with DynamixelBus(sim, servos([1, 2], lo=1000, hi=3000)) as dxl:
        dxl.configure()
        assert dxl.read_register(1, "Min Position Limit") == 1000
        assert dxl.read_register(2, "Max Position Limit") == 3000
        assert dxl.read_register(2, "Return Delay Time") == 0
        assert dxl.arm_watchdog(100) == 100
        assert dxl.read_register(1, "Bus Watchdog") == 5
        dxl.set_torque(True)
        dxl.configure()  # nothing to change: fine with torque on
    with DynamixelBus(sim, servos([1, 2], lo=500, hi=3000)) as dxl:
        with pytest.raises(RigError, match="torque is on"):
            dxl.configure()


def test_scan_of_every_id_finds_the_servos_through_one_broadcast_ping():
    from rig.devices.dynamixel import BROADCAST_SCAN_ABOVE

    assert len(range(253)) > BROADCAST_SCAN_ABOVE
    found = scan("sim://dynamixel?ids=4,9,200&baud=57600", bauds=[1_000_000, 57600])
    assert [(s.id, s.model, s.baud) for s in found] == [
        (4, "XM430-W350", 57600), (9, "XM430-W350", 57600), (200, "XM430-W350", 57600)]


def test_new_position_limits_are_checked_on_goals_and_written_by_configure(sim):
    with DynamixelBus(sim, servos([1, 2, 3], lo=1024, hi=3072)) as dxl:
        dxl.set_position_limits([1500, 1600, 1700], [2500, 2600, 2700])
        with pytest.raises(UnreachableError, match="ID 1") as info:
            dxl.write_goal_ticks([1400, 2000, 2000])
        assert info.value.actual == 1400 and info.value.expected == "1500..2500"
        dxl.configure()
        assert [dxl.read_register(i, "Min Position Limit") for i in (1, 2, 3)] == [
            1500, 1600, 1700]
        assert [dxl.read_register(i, "Max Position Limit") for i in (1, 2, 3)] == [
            2500, 2600, 2700]
        with pytest.raises(ValueError, match="need 3 min and max ticks"):
            dxl.set_position_limits([1500, 1600], [2500, 2600])
