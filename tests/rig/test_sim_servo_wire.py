"""Indirect addressing, Secondary ID and boot silence through the official dynamixel_sdk.

The simulator runs on a ManualClock: motion and boot time move only when the test advances it.
"""

from __future__ import annotations

import pytest
from dynamixel_sdk import (
    COMM_RX_TIMEOUT,
    COMM_SUCCESS,
    GroupSyncRead,
)

from firmware_protocol.dynamixel import ErrorCode
from firmware_protocol.dynamixel.control_table import load_control_table
from rig.sim.clock import ManualClock
from rig.sim.dynamixel import BOOT_TIME_S, bus_from_url

pytestmark = pytest.mark.usefixtures("tolerant_sdk_timeouts")

RETURN_DELAY, SECONDARY_ID, TORQUE, LED = 9, 12, 64, 65
GOAL_POS, PRESENT_POS = 116, 132
INDIRECT_ADDR_1, INDIRECT_DATA_1 = 168, 224
INDIRECT_ADDR_29, INDIRECT_DATA_29 = 578, 634


def map_indirect(port, ph, dxl_id, slot_address, first_target, count):
    for k in range(count):
        assert ph.write2ByteTxRx(port, dxl_id, slot_address + 2 * k,
                                 first_target + k) == (COMM_SUCCESS, 0)


def test_indirect_goal_moves_and_indirect_present_reads_back(sdk, clock):
    port, ph = sdk
    for dxl_id in (1, 2):  # as ROBOTIS's indirect_address example: goal, then present
        map_indirect(port, ph, dxl_id, INDIRECT_ADDR_1, GOAL_POS, 4)
        map_indirect(port, ph, dxl_id, INDIRECT_ADDR_1 + 8, PRESENT_POS, 4)
        assert ph.write1ByteTxRx(port, dxl_id, TORQUE, 1) == (COMM_SUCCESS, 0)
    assert ph.write4ByteTxRx(port, 1, INDIRECT_DATA_1, 1000) == (COMM_SUCCESS, 0)
    assert ph.write4ByteTxRx(port, 2, INDIRECT_DATA_1, 3000) == (COMM_SUCCESS, 0)
    assert ph.read4ByteTxRx(port, 1, GOAL_POS) == (1000, COMM_SUCCESS, 0)
    clock.advance(5.0)
    sync = GroupSyncRead(port, ph, INDIRECT_DATA_1 + 4, 4)
    assert sync.addParam(1) and sync.addParam(2)
    assert sync.txRxPacket() == COMM_SUCCESS
    assert [sync.getData(i, INDIRECT_DATA_1 + 4, 4) for i in (1, 2)] == [1000, 3000]
    # reading goal and present in one indirect run of 8 bytes
    data, result, error = ph.readTxRx(port, 1, INDIRECT_DATA_1, 8)
    assert (result, error) == (COMM_SUCCESS, 0)
    assert list(data) == list((1000).to_bytes(4, "little")) * 2


def test_indirect_data_inherits_the_targets_rules(sdk):
    port, ph = sdk
    map_indirect(port, ph, 1, INDIRECT_ADDR_1, PRESENT_POS, 4)
    # Present Position is read-only: so is its indirect data
    assert ph.write4ByteTxRx(port, 1, INDIRECT_DATA_1, 5) == (COMM_SUCCESS, ErrorCode.ACCESS)
    # outside the RAM area: Data Range Error, nothing changed
    assert ph.write2ByteTxRx(port, 1, INDIRECT_ADDR_1, 20) == (COMM_SUCCESS,
                                                               ErrorCode.DATA_RANGE)
    assert ph.read2ByteTxRx(port, 1, INDIRECT_ADDR_1) == (PRESENT_POS, COMM_SUCCESS, 0)
    # the second block (Indirect Address 29..56), when the table lists it; LED both ways
    if any(b.address_start == INDIRECT_ADDR_29
           for b in load_control_table("XM430-W350").indirect):
        assert ph.write2ByteTxRx(port, 1, INDIRECT_ADDR_29, LED) == (COMM_SUCCESS, 0)
        assert ph.write1ByteTxRx(port, 1, INDIRECT_DATA_29, 1) == (COMM_SUCCESS, 0)
        assert ph.read1ByteTxRx(port, 1, LED) == (1, COMM_SUCCESS, 0)


def test_indirect_address_defaults_to_its_own_data_and_reboot_restores_it(sdk, bus, clock):
    port, ph = sdk
    assert ph.read2ByteTxRx(port, 1, INDIRECT_ADDR_1 + 2) == (INDIRECT_DATA_1 + 1,
                                                              COMM_SUCCESS, 0)
    assert ph.write2ByteTxRx(port, 1, INDIRECT_ADDR_1, LED) == (COMM_SUCCESS, 0)
    assert ph.reboot(port, 1) == (COMM_SUCCESS, 0)
    clock.advance(BOOT_TIME_S)
    assert ph.read2ByteTxRx(port, 1, INDIRECT_ADDR_1) == (INDIRECT_DATA_1, COMM_SUCCESS, 0)


def test_secondary_id_executes_without_replying_and_spares_eeprom(sdk, bus):
    port, ph = sdk
    for dxl_id in (1, 2):
        assert ph.write1ByteTxRx(port, dxl_id, SECONDARY_ID, 9) == (COMM_SUCCESS, 0)
    assert ph.write1ByteTxOnly(port, 9, LED, 1) == COMM_SUCCESS
    assert ph.write1ByteTxOnly(port, 9, RETURN_DELAY, 7) == COMM_SUCCESS  # EEPROM: refused
    # a status for the writes above would have been taken as these replies' bytes
    assert [ph.read1ByteTxRx(port, i, LED) for i in (1, 2, 3)] == [(1, COMM_SUCCESS, 0),
                                                                   (1, COMM_SUCCESS, 0),
                                                                   (0, COMM_SUCCESS, 0)]
    assert ph.read1ByteTxRx(port, 1, RETURN_DELAY) == (0, COMM_SUCCESS, 0)
    assert ph.ping(port, 9)[1] == COMM_RX_TIMEOUT  # executed by both, answered by none


def test_rebooting_servo_is_silent_until_it_has_booted(sdk, clock):
    port, ph = sdk
    assert ph.reboot(port, 1) == (COMM_SUCCESS, 0)  # the reply precedes the reboot
    assert ph.ping(port, 1)[1] == COMM_RX_TIMEOUT
    assert ph.ping(port, 2) == (1020, COMM_SUCCESS, 0)  # the others listen
    clock.advance(BOOT_TIME_S - 0.01)
    assert ph.ping(port, 1)[1] == COMM_RX_TIMEOUT
    clock.advance(0.01)
    assert ph.ping(port, 1) == (1020, COMM_SUCCESS, 0)


def test_boot_on_powers_the_servos_on_booting():
    clock = ManualClock(5.0)
    with bus_from_url("sim://dynamixel?ids=1,2&boot=on", clock=clock) as bus:
        assert not bus.servo(1).listening(clock())
        clock.advance(BOOT_TIME_S)
        assert bus.servo(1).listening(clock()) and bus.servo(2).listening(clock())
    with bus_from_url("sim://dynamixel?ids=1", clock=clock) as bus:
        assert bus.servo(1).listening(clock())


def test_push_on_the_bus_is_felt_by_a_current_mode_servo(bus, clock):
    servo = bus.servo(1)
    servo.set_item("Operating Mode", 0)
    servo.set_item("Goal Current", 0)
    servo.set_item("Torque Enable", 1)
    bus.push(1, lambda t: 0.5)
    clock.advance(0.2)
    assert bus.position(1) > 2048 + 10  # the hand wins over a zero current
    bus.push(1, None)
    assert servo.push is None
