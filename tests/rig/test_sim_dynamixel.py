"""The simulated servo chain, driven by the official ROBOTIS ``dynamixel_sdk`` unchanged.

Tests synchronise on replies (every SDK call blocks until the status packet or its timeout);
nothing here sleeps. Motion tests use a manual clock so positions are exact.
"""

from __future__ import annotations

import math
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from dynamixel_sdk import (
    COMM_RX_CORRUPT,
    COMM_RX_TIMEOUT,
    COMM_SUCCESS,
    GroupBulkRead,
    GroupBulkWrite,
    GroupSyncRead,
    GroupSyncWrite,
    PacketHandler,
    PortHandler,
)

from firmware_protocol.dynamixel import ErrorCode, decode_packet, instructions
from rig.errors import RigConfigError
from rig.sim.clock import ManualClock
from rig.sim.dynamixel import (
    ACCEL_UNIT,
    BOOT_TIME_S,
    VELOCITY_UNIT,
    DynamixelBus,
    bus_from_url,
    start_servo_bus,
)
from tests.rig.rigs import reap

pytestmark = pytest.mark.usefixtures("tolerant_sdk_timeouts")

# X-series control table addresses (e-Manual)
RETURN_DELAY, OPERATING_MODE, MAX_POS, MIN_POS = 9, 11, 48, 52
TORQUE, LED, SRL, HW_ERROR = 64, 65, 68, 70
POS_P_GAIN, GOAL_VELOCITY, PROFILE_ACC, PROFILE_VEL = 84, 104, 108, 112
GOAL_POS, MOVING, PRESENT_POS, PRESENT_TEMP = 116, 122, 132, 146

ALERT = 0x80


def le(value: int, size: int) -> list[int]:
    return list((value & ((1 << 8 * size) - 1)).to_bytes(size, "little"))


def signed32(value: int) -> int:
    return value - (1 << 32) if value & 0x80000000 else value


# ---------------------------------------------------------------------------- basics


def test_port_is_a_pty_and_close_is_idempotent():
    bus = start_servo_bus([1])
    assert bus.port.startswith("/dev/pts/")
    bus.close()
    bus.close()
    assert bus.closed


def test_ping_reports_model_numbers_of_a_mixed_chain():
    with start_servo_bus([(1, "XM430-W350"), (2, "XL430-W250"), (3, "XC330-M288")]) as bus:
        port = PortHandler(bus.port)
        assert port.openPort()
        try:
            ph = PacketHandler(2.0)
            assert ph.ping(port, 1) == (1020, COMM_SUCCESS, 0)
            assert ph.ping(port, 2) == (1060, COMM_SUCCESS, 0)
            assert ph.ping(port, 3) == (1240, COMM_SUCCESS, 0)
            assert ph.ping(port, 4)[1] == COMM_RX_TIMEOUT
        finally:
            port.closePort()


def test_broadcast_ping(sdk):
    port, ph = sdk
    found, result = ph.broadcastPing(port)
    assert result == COMM_SUCCESS
    assert found == {1: [1020, 48], 2: [1020, 48], 3: [1020, 48]}


def test_read_write_1_2_4_byte_items(sdk):
    port, ph = sdk
    assert ph.write1ByteTxRx(port, 2, LED, 1) == (COMM_SUCCESS, 0)
    assert ph.read1ByteTxRx(port, 2, LED) == (1, COMM_SUCCESS, 0)
    assert ph.write2ByteTxRx(port, 2, POS_P_GAIN, 1234) == (COMM_SUCCESS, 0)
    assert ph.read2ByteTxRx(port, 2, POS_P_GAIN) == (1234, COMM_SUCCESS, 0)
    assert ph.write4ByteTxRx(port, 2, PROFILE_VEL, 300) == (COMM_SUCCESS, 0)
    assert ph.read4ByteTxRx(port, 2, PROFILE_VEL) == (300, COMM_SUCCESS, 0)
    assert ph.read2ByteTxRx(port, 2, 0) == (1020, COMM_SUCCESS, 0)  # model number
    # the other servos are untouched
    assert ph.read1ByteTxRx(port, 1, LED) == (0, COMM_SUCCESS, 0)


def test_sync_read_and_sync_write_three_servos(sdk, bus, clock):
    port, ph = sdk
    for i in (1, 2, 3):
        assert ph.write1ByteTxRx(port, i, TORQUE, 1) == (COMM_SUCCESS, 0)
    writer = GroupSyncWrite(port, ph, GOAL_POS, 4)
    for i, goal in zip((1, 2, 3), (1000, 2000, 3000), strict=True):
        assert writer.addParam(i, le(goal, 4))
    assert writer.txPacket() == COMM_SUCCESS
    assert ph.ping(port, 1)[1] == COMM_SUCCESS  # a broadcast has no reply: sync on a ping
    clock.t += 10.0
    reader = GroupSyncRead(port, ph, PRESENT_POS, 4)
    for i in (1, 2, 3):
        assert reader.addParam(i)
    assert reader.txRxPacket() == COMM_SUCCESS
    assert [reader.getData(i, PRESENT_POS, 4) for i in (1, 2, 3)] == [1000, 2000, 3000]
    # fast sync read: one status packet for all three
    clock.t += 1.0
    assert reader.fastSyncRead() == COMM_SUCCESS
    assert [reader.getData(i, PRESENT_POS, 4) for i in (1, 2, 3)] == [1000, 2000, 3000]


def test_bulk_read_and_bulk_write(sdk):
    port, ph = sdk
    writer = GroupBulkWrite(port, ph)
    assert writer.addParam(1, LED, 1, [1])
    assert writer.addParam(2, PROFILE_VEL, 4, le(77, 4))
    assert writer.addParam(3, POS_P_GAIN, 2, le(900, 2))
    assert writer.txPacket() == COMM_SUCCESS
    reader = GroupBulkRead(port, ph)
    assert reader.addParam(1, LED, 1)
    assert reader.addParam(2, PROFILE_VEL, 4)
    assert reader.addParam(3, POS_P_GAIN, 2)
    assert reader.txRxPacket() == COMM_SUCCESS
    assert reader.getData(1, LED, 1) == 1
    assert reader.getData(2, PROFILE_VEL, 4) == 77
    assert reader.getData(3, POS_P_GAIN, 2) == 900
    assert reader.fastBulkRead() == COMM_SUCCESS
    assert reader.getData(2, PROFILE_VEL, 4) == 77
    assert reader.getData(3, POS_P_GAIN, 2) == 900


def _fast_bulk_chain():
    return start_servo_bus([1, 4, 5], return_delay_us=0, positions=[100, 400, 500])


def test_fast_bulk_read_reply_is_well_formed():
    with _fast_bulk_chain() as bus:
        port = PortHandler(bus.port)
        assert port.openPort()
        try:
            ph = PacketHandler(2.0)
            port.clearPort()
            port.writePort(instructions.bulk_read([(1, 132, 4), (4, 132, 4), (5, 132, 4)],
                                                  fast=True).encode())
            port.setPacketTimeout(3 * 14)
            reply, result = ph.rxPacket(port, True)
            assert result == COMM_SUCCESS
            status = decode_packet(bytes(reply))
            assert [(i, int.from_bytes(d, "little")) for _, i, d in
                    instructions.parse_fast_status(status, [4, 4, 4])] == [
                (1, 100), (4, 400), (5, 500)]
        finally:
            port.closePort()


@pytest.mark.xfail(reason="dynamixel-sdk 4.1.0 fastBulkReadRx looks IDs up with param.index() "
                          "in the flat [id, addr, addr, len, len, ...] list, so ID 4 matches "
                          "ID 1's length byte; the servos after it are silently dropped",
                   strict=False)
def test_sdk_fast_bulk_read_with_an_id_equal_to_a_length_byte():
    with _fast_bulk_chain() as bus:
        port = PortHandler(bus.port)
        assert port.openPort()
        try:
            reader = GroupBulkRead(port, PacketHandler(2.0))
            for i in (1, 4, 5):
                reader.addParam(i, PRESENT_POS, 4)
            assert reader.fastBulkRead() == COMM_SUCCESS
            assert [reader.getData(i, PRESENT_POS, 4) for i in (1, 4, 5)] == [100, 400, 500]
        finally:
            port.closePort()


def test_header_bytes_inside_data_survive_both_directions(sdk):
    """The SDK sends such data unstuffed (its txPacket drops addStuffing's result); the servo
    replies stuffed and the SDK's rxPacket unstuffs it."""
    port, ph = sdk
    value = int.from_bytes(b"\xff\xff\xfd\x00", "little")
    assert ph.write4ByteTxRx(port, 1, 224, value) == (COMM_SUCCESS, 0)  # indirect data block
    assert ph.read4ByteTxRx(port, 1, 224) == (value, COMM_SUCCESS, 0)


def test_reg_write_then_action(sdk):
    port, ph = sdk
    assert ph.regWriteTxRx(port, 1, LED, 1, [1]) == (COMM_SUCCESS, 0)
    assert ph.read1ByteTxRx(port, 1, LED)[0] == 0
    assert ph.read1ByteTxRx(port, 1, 69)[0] == 1  # Registered Instruction
    assert ph.action(port, 1) == COMM_SUCCESS
    assert ph.read1ByteTxRx(port, 1, LED)[0] == 1
    # ACTION without a registered write: instruction error (the SDK's action() never reads
    # the status, so receive it with the SDK's own rxPacket)
    port.clearPort()
    port.writePort(instructions.action(1).encode())
    port.setPacketTimeout(11)
    reply, result = ph.rxPacket(port, False)
    assert result == COMM_SUCCESS and reply[8] == ErrorCode.INSTRUCTION


def _raw(packet: bytes) -> list[int]:
    """An SDK tx buffer for an already-encoded packet (the SDK recomputes header and CRC)."""
    return list(packet)


def test_factory_reset_keeps_id_and_baud_with_option_2(sdk, clock):
    port, ph = sdk
    assert ph.write1ByteTxRx(port, 3, RETURN_DELAY, 100) == (COMM_SUCCESS, 0)
    assert ph.factoryReset(port, 3, 0x02) == (COMM_SUCCESS, 0)
    clock.advance(BOOT_TIME_S)  # the reset reboots the servo: silent while it boots
    assert ph.read1ByteTxRx(port, 3, RETURN_DELAY) == (250, COMM_SUCCESS, 0)


# ---------------------------------------------------------------------------- errors


def test_error_codes(sdk):
    port, ph = sdk
    assert ph.write1ByteTxRx(port, 1, TORQUE, 1) == (COMM_SUCCESS, 0)
    # EEPROM while torque is on
    assert ph.write1ByteTxRx(port, 1, OPERATING_MODE, 4) == (COMM_SUCCESS, ErrorCode.ACCESS)
    # read-only item
    assert ph.write4ByteTxRx(port, 1, PRESENT_POS, 5) == (COMM_SUCCESS, ErrorCode.ACCESS)
    # reserved gap and beyond the table
    assert ph.write1ByteTxRx(port, 1, 14, 1) == (COMM_SUCCESS, ErrorCode.ACCESS)
    assert ph.write1ByteTxRx(port, 1, 700, 1) == (COMM_SUCCESS, ErrorCode.ACCESS)
    assert ph.read4ByteTxRx(port, 1, 700) == (0, COMM_SUCCESS, ErrorCode.ACCESS)
    # half of a 4-byte item
    assert ph.write2ByteTxRx(port, 1, GOAL_POS, 5) == (COMM_SUCCESS, ErrorCode.DATA_LENGTH)
    # value outside the item's range
    assert ph.write1ByteTxRx(port, 1, SRL, 3) == (COMM_SUCCESS, ErrorCode.DATA_RANGE)
    # goal beyond its limit (Velocity Limit, default 200)
    assert ph.write4ByteTxRx(port, 1, GOAL_VELOCITY, 500) == (COMM_SUCCESS, ErrorCode.DATA_LIMIT)
    # unknown instruction
    _, result, error = ph.txRxPacket(port, _raw(instructions.InstructionPacket(1, 0x7F).encode()))
    assert (result, error) == (COMM_SUCCESS, ErrorCode.INSTRUCTION)
    # nothing was applied
    assert ph.read1ByteTxRx(port, 1, OPERATING_MODE)[0] == 3
    # EEPROM is writable once torque is off
    assert ph.write1ByteTxRx(port, 1, TORQUE, 0) == (COMM_SUCCESS, 0)
    assert ph.write1ByteTxRx(port, 1, OPERATING_MODE, 4) == (COMM_SUCCESS, 0)


def test_hardware_error_sets_alert_drops_torque_and_reboot_clears_it(sdk, bus, clock):
    port, ph = sdk
    assert ph.write1ByteTxRx(port, 2, TORQUE, 1) == (COMM_SUCCESS, 0)
    bus.raise_hardware_error(2, "overload")
    value, result, error = ph.read1ByteTxRx(port, 2, HW_ERROR)
    assert (value, result, error) == (0x20, COMM_SUCCESS, ALERT)  # alert, not a failure
    assert ph.read1ByteTxRx(port, 2, TORQUE) == (0, COMM_SUCCESS, ALERT)
    assert ph.write1ByteTxRx(port, 2, TORQUE, 1) == (COMM_SUCCESS, ALERT)
    assert ph.read1ByteTxRx(port, 2, TORQUE)[0] == 0  # refused until reboot
    assert ph.ping(port, 1) == (1020, COMM_SUCCESS, 0)  # other servos unaffected
    assert ph.reboot(port, 2) == (COMM_SUCCESS, ALERT)  # the reply precedes the reboot
    clock.advance(BOOT_TIME_S)  # a real servo is silent while it boots
    assert ph.read1ByteTxRx(port, 2, HW_ERROR) == (0, COMM_SUCCESS, 0)
    assert ph.write1ByteTxRx(port, 2, TORQUE, 1) == (COMM_SUCCESS, 0)


def test_overheating_from_temperature(sdk, bus):
    port, ph = sdk
    bus.set_temperature(3, 85.0)  # XM430 limit 80 °C
    assert ph.read1ByteTxRx(port, 3, PRESENT_TEMP) == (85, COMM_SUCCESS, ALERT)
    assert ph.read1ByteTxRx(port, 3, HW_ERROR)[0] == 0x04


def test_status_return_level(sdk):
    port, ph = sdk
    assert ph.write1ByteTxRx(port, 1, SRL, 1) == (COMM_SUCCESS, 0)
    assert ph.write1ByteTxRx(port, 1, LED, 1)[0] == COMM_RX_TIMEOUT  # applied, no reply
    assert ph.read1ByteTxRx(port, 1, LED) == (1, COMM_SUCCESS, 0)
    ph.write1ByteTxOnly(port, 1, SRL, 0)
    assert ph.read1ByteTxRx(port, 1, LED)[1] == COMM_RX_TIMEOUT
    assert ph.ping(port, 1) == (1020, COMM_SUCCESS, 0)


# ---------------------------------------------------------------------------- motion


def test_trapezoidal_profile(sdk, clock):
    port, ph = sdk
    pv, pa = 100, 20  # 0.229 rpm and 214.577 rev/min² units
    assert ph.write4ByteTxRx(port, 1, PROFILE_ACC, pa) == (COMM_SUCCESS, 0)
    assert ph.write4ByteTxRx(port, 1, PROFILE_VEL, pv) == (COMM_SUCCESS, 0)
    assert ph.write1ByteTxRx(port, 1, TORQUE, 1) == (COMM_SUCCESS, 0)
    start, goal = 2048, 3048
    assert ph.write4ByteTxRx(port, 1, GOAL_POS, goal) == (COMM_SUCCESS, 0)
    v, a = pv * VELOCITY_UNIT, pa * ACCEL_UNIT
    t_ramp = v / a
    t_total = (goal - start) / v + t_ramp  # trapezoid: cruise distance / v + one ramp

    def position_after(dt: float) -> int:
        clock.t += dt
        value, result, _ = ph.read4ByteTxRx(port, 1, PRESENT_POS)
        assert result == COMM_SUCCESS
        return signed32(value)

    half_ramp = position_after(t_ramp / 2)
    assert half_ramp == pytest.approx(start + 0.5 * a * (t_ramp / 2) ** 2, abs=3)
    assert ph.read1ByteTxRx(port, 1, MOVING)[0] == 1
    mid = position_after(t_total / 2 - t_ramp / 2)
    assert mid == pytest.approx((start + goal) / 2, abs=3)
    assert position_after(t_total / 2 + 0.05) == goal
    assert ph.read1ByteTxRx(port, 1, MOVING)[0] == 0


def test_time_based_profile(sdk, clock):
    port, ph = sdk
    assert ph.write1ByteTxRx(port, 1, 10, 0x04) == (COMM_SUCCESS, 0)  # Drive Mode: time-based
    assert ph.write4ByteTxRx(port, 1, PROFILE_VEL, 2000) == (COMM_SUCCESS, 0)  # 2 s move
    assert ph.write4ByteTxRx(port, 1, PROFILE_ACC, 500) == (COMM_SUCCESS, 0)  # 0.5 s ramps
    assert ph.write1ByteTxRx(port, 1, TORQUE, 1) == (COMM_SUCCESS, 0)
    assert ph.write4ByteTxRx(port, 1, GOAL_POS, 2048 + 1500) == (COMM_SUCCESS, 0)
    clock.t += 1.0  # halfway in time is halfway in distance (symmetric trapezoid)
    assert signed32(ph.read4ByteTxRx(port, 1, PRESENT_POS)[0]) == pytest.approx(2048 + 750, abs=3)
    clock.t += 0.9  # 0.1 s before the end: 0.5 * a * 0.1² = 10 ticks to go
    assert ph.read1ByteTxRx(port, 1, MOVING)[0] == 1
    assert signed32(ph.read4ByteTxRx(port, 1, PRESENT_POS)[0]) == pytest.approx(3548 - 10, abs=3)
    clock.t += 0.11
    assert ph.read4ByteTxRx(port, 1, PRESENT_POS)[0] == 2048 + 1500


def test_goal_is_clamped_to_position_limits(sdk, clock):
    port, ph = sdk
    assert ph.write4ByteTxRx(port, 1, MAX_POS, 2500) == (COMM_SUCCESS, 0)
    assert ph.write4ByteTxRx(port, 1, MIN_POS, 1500) == (COMM_SUCCESS, 0)
    assert ph.write1ByteTxRx(port, 1, TORQUE, 1) == (COMM_SUCCESS, 0)
    assert ph.write4ByteTxRx(port, 1, GOAL_POS, 4000) == (COMM_SUCCESS, 0)
    clock.t += 5.0
    assert ph.read4ByteTxRx(port, 1, PRESENT_POS)[0] == 2500
    assert ph.write4ByteTxRx(port, 1, GOAL_POS, 10) == (COMM_SUCCESS, 0)
    clock.t += 5.0
    assert ph.read4ByteTxRx(port, 1, PRESENT_POS)[0] == 1500


def test_back_drive_with_torque_off_then_hold(sdk, bus, clock):
    port, ph = sdk
    for ticks in (2100, 1500, 900):
        bus.set_hand(1, ticks)
        clock.t += 0.1
        assert ph.read4ByteTxRx(port, 1, PRESENT_POS)[0] == ticks
    # torque on: the limb holds where the clinician left it
    assert ph.write1ByteTxRx(port, 1, TORQUE, 1) == (COMM_SUCCESS, 0)
    bus.set_hand(1, 3000)  # pushing against an energised servo does nothing
    clock.t += 1.0
    assert ph.read4ByteTxRx(port, 1, GOAL_POS)[0] == 900
    assert ph.read4ByteTxRx(port, 1, PRESENT_POS)[0] == 900


def test_hand_can_follow_a_function_of_time(sdk, bus, clock):
    port, ph = sdk
    bus.set_hand(2, lambda t: 2048 + 100 * (t - 100.0))  # 100 ticks/s sweep
    clock.t += 1.0
    assert ph.read4ByteTxRx(port, 2, PRESENT_POS)[0] == 2148
    clock.t += 1.0
    assert ph.read4ByteTxRx(port, 2, PRESENT_POS)[0] == 2248
    assert signed32(ph.read4ByteTxRx(port, 2, 128)[0]) == round(100 / VELOCITY_UNIT)


def test_velocity_mode(sdk, clock):
    port, ph = sdk
    assert ph.write1ByteTxRx(port, 2, OPERATING_MODE, 1) == (COMM_SUCCESS, 0)
    assert ph.write1ByteTxRx(port, 2, TORQUE, 1) == (COMM_SUCCESS, 0)
    assert ph.write4ByteTxRx(port, 2, GOAL_VELOCITY, 50) == (COMM_SUCCESS, 0)
    clock.t += 1.0
    expected = 2048 + 50 * VELOCITY_UNIT
    assert signed32(ph.read4ByteTxRx(port, 2, PRESENT_POS)[0]) == pytest.approx(expected, abs=2)
    assert signed32(ph.read4ByteTxRx(port, 2, 128)[0]) == 50  # present velocity


def test_encoder_noise_is_seeded():
    def readings(seed: int) -> list[int]:
        with start_servo_bus([1], noise_ticks=2.0, seed=seed) as bus:
            port = PortHandler(bus.port)
            assert port.openPort()
            try:
                ph = PacketHandler(2.0)
                return [ph.read4ByteTxRx(port, 1, PRESENT_POS)[0] for _ in range(20)]
            finally:
                port.closePort()

    first, again, other = readings(7), readings(7), readings(8)
    assert first == again != other
    assert len(set(first)) > 1
    assert all(abs(signed32(v) - 2048) < 12 for v in first)


# ---------------------------------------------------------------------------- timing


def test_return_delay_time_delays_the_reply():
    with start_servo_bus([1], return_delay_us=508) as bus:
        port = PortHandler(bus.port)
        assert port.openPort()
        try:
            ph = PacketHandler(2.0)
            t0 = port.getCurrentTime()
            assert ph.ping(port, 1)[1] == COMM_SUCCESS
            assert port.getCurrentTime() - t0 >= 0.5  # ms: never earlier than the delay
        finally:
            port.closePort()


def test_servos_only_answer_at_their_baud_rate(sdk):
    port, ph = sdk
    assert port.setBaudRate(57600)
    assert ph.ping(port, 1)[1] == COMM_RX_TIMEOUT
    assert port.setBaudRate(1_000_000)
    assert ph.ping(port, 1)[1] == COMM_SUCCESS


# ---------------------------------------------------------------------------- faults


def test_dropped_response_is_a_timeout(sdk, bus):
    port, ph = sdk
    bus.drop_responses(1)
    assert ph.read4ByteTxRx(port, 1, PRESENT_POS)[1] == COMM_RX_TIMEOUT
    assert ph.read4ByteTxRx(port, 1, PRESENT_POS)[1] == COMM_SUCCESS


def test_corrupted_crc_is_rx_corrupt(sdk, bus):
    port, ph = sdk
    bus.corrupt_responses(1)
    assert ph.read4ByteTxRx(port, 1, PRESENT_POS)[1] == COMM_RX_CORRUPT
    assert ph.ping(port, 1)[1] == COMM_SUCCESS


def test_truncated_response_is_rx_corrupt(sdk, bus):
    port, ph = sdk
    bus.truncate_responses(keep=9)
    assert ph.read4ByteTxRx(port, 1, PRESENT_POS)[1] == COMM_RX_CORRUPT
    assert ph.ping(port, 1)[1] == COMM_SUCCESS


def test_late_response_times_out_and_short_delay_does_not(sdk, bus):
    port, ph = sdk
    bus.delay_responses(0.3)  # beyond the SDK's packet timeout
    assert ph.ping(port, 1)[1] == COMM_RX_TIMEOUT
    bus.delay_responses(0.005)
    assert ph.ping(port, 1)[1] == COMM_SUCCESS
    assert ph.ping(port, 1)[1] == COMM_SUCCESS  # the stale late reply was cancelled


def test_unplug_and_replug(sdk, bus):
    port, ph = sdk
    bus.unplug([2])
    reader = GroupSyncRead(port, ph, PRESENT_POS, 4)
    for i in (1, 2, 3):
        reader.addParam(i)
    assert reader.txRxPacket() == COMM_RX_TIMEOUT
    assert ph.ping(port, 3)[1] == COMM_SUCCESS
    bus.unplug()
    assert ph.ping(port, 3)[1] == COMM_RX_TIMEOUT
    bus.replug()
    assert reader.txRxPacket() == COMM_SUCCESS


def test_adapter_disconnect_fails_the_port_like_a_usb_unplug(bus):
    port = PortHandler(bus.port)
    assert port.openPort()
    ph = PacketHandler(2.0)
    try:
        assert ph.ping(port, 1)[1] == COMM_SUCCESS
        bus.unplug(adapter=True)
        with pytest.raises(OSError):  # termios.error / SerialException: EIO
            try:
                ph.ping(port, 1)
            except Exception as err:  # termios.error is not an OSError subclass
                raise OSError(str(err)) from err
    finally:
        port.is_using = False
        port.closePort()
    new_port = bus.replug(adapter=True)
    assert new_port == bus.port
    port = PortHandler(new_port)
    assert port.openPort()
    try:
        assert ph.ping(port, 1)[1] == COMM_SUCCESS
    finally:
        port.closePort()


def test_serves_when_fd_numbers_exceed_fd_setsize():
    """A process with many open files: select() cannot take fd >= 1024, poll() takes over."""
    import resource

    soft, _ = resource.getrlimit(resource.RLIMIT_NOFILE)
    if soft < 1200:
        pytest.skip(f"RLIMIT_NOFILE {soft} too low to open fds beyond 1024")
    null = os.open(os.devnull, os.O_RDONLY)
    filler = [os.dup(null) for _ in range(1100)]
    try:
        bus = start_servo_bus([1], return_delay_us=0)
    finally:
        for fd in [*filler, null]:  # free low numbers: pyserial's own select() needs one
            os.close(fd)
    with bus:
        assert bus.fileno() >= 1024
        port = PortHandler(bus.port)
        assert port.openPort()
        try:
            assert PacketHandler(2.0).ping(port, 1) == (1020, COMM_SUCCESS, 0)
        finally:
            port.closePort()


# ---------------------------------------------------------------------------- configuration


@pytest.mark.parametrize(("kwargs", "match"), [
    ({"ids": [1, 1]}, "distinct"),
    ({"ids": [300]}, "0..252"),
    ({"ids": [1], "model": "XQ999"}, "unknown Dynamixel model"),
    ({"ids": [1], "baud_rate": 12345}, "baud rate"),
    ({"ids": []}, "at least one"),
])
def test_bad_configuration_is_a_config_error(kwargs, match):
    with pytest.raises(RigConfigError, match=match):
        start_servo_bus(**kwargs)


def test_port_string_chooses_the_simulator():
    with bus_from_url("sim://dynamixel?ids=4,5&model=XL430-W250&return_delay_us=0") as bus:
        port = PortHandler(bus.port)
        assert port.openPort()
        try:
            assert PacketHandler(2.0).ping(port, 5) == (1060, COMM_SUCCESS, 0)
        finally:
            port.closePort()
    for bad in ("/dev/ttyUSB0", "sim://imu", "sim://dynamixel?idz=1", "sim://dynamixel?ids=a"):
        with pytest.raises(RigConfigError):
            bus_from_url(bad)


# ---------------------------------------------------------------------------- CLI


SHOULDER_URL = ("sim://dynamixel?ids=1,2,3&model=XM430-W350&return_delay_us=0&patient=original"
                "&chain=sim-shoulder&seed=1")


@pytest.mark.parametrize(("signum", "url"), [
    (signal.SIGTERM, "sim://dynamixel?ids=1,2,3&model=XM430-W350&baud=1000000"),
    (signal.SIGINT, SHOULDER_URL),  # a port string's own keys: a patient back-drives the chain
])
def test_cli_prints_port_serves_and_exits_cleanly_on_signal(signum, url):
    root = Path(__file__).resolve().parents[2]
    env = dict(os.environ, PYTHONPATH=str(root) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    proc = subprocess.Popen([sys.executable, "-m", "rig", "sim", "servos", url],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env, text=True)
    try:
        port_name = proc.stdout.readline().strip()
        assert port_name.startswith("/dev/pts/"), proc.stderr.read()
        port = PortHandler(port_name)
        assert port.openPort()
        try:
            ph = PacketHandler(2.0)
            assert ph.ping(port, 3) == (1020, COMM_SUCCESS, 0)
        finally:
            port.closePort()
        proc.send_signal(signum)
        assert proc.wait(timeout=10) == 0
    finally:
        reap(proc)


@pytest.mark.parametrize(("url", "needle"), [
    ("sim://dynamixel?model=XQ999", "'XQ999'"),
    ("sim://dynamixel?ids=1,x", "ids='1,x'"),
    ("sim://dynamixel?ids=1,1", "distinct"),
    ("sim://dynamixel?ids=300", "300"),
    ("sim://dynamixel?baud=12345", "12345"),
    ("sim://dynamixel?return_delay_us=600", "return_delay_us='600'"),
    ("sim://dynamixel?idz=1", "unknown key 'idz'"),
    ("sim://dynamixel?ids=1&ids=2", "given twice"),
    (SHOULDER_URL.replace("patient=original", "patient=nobody"), "nobody"),
    ("sim://dynamixel?speed=2", "speed need patient="),
])
def test_cli_bad_url_is_one_line_error_naming_it(url, needle, capsys):
    from rig.cli import main

    with pytest.raises(SystemExit) as info:
        main(["sim", "servos", url])
    out, err = capsys.readouterr()
    assert info.value.code == 2 and out == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1 and needle in lines[0], err
    assert lines[0].startswith((f"rig: error: {url}: ", f"rig: error: port {url!r}: ")), err


@pytest.mark.parametrize("url", ["sim://bno055", "/dev/ttyUSB0", "--ids"])
def test_cli_refuses_what_is_not_a_servo_port_string(url):
    root = Path(__file__).resolve().parents[2]
    env = dict(os.environ, PYTHONPATH=str(root))
    done = subprocess.run([sys.executable, "-m", "rig", "sim", "servos", url],
                          capture_output=True, text=True, env=env, timeout=30)
    assert done.returncode == 2 and done.stdout == ""
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("rig: error: "), done.stderr
    assert ("not a simulated dynamixel URL" in lines[0]) == (url != "--ids")


def test_math_sanity_of_units():
    # 1 unit of Profile Velocity is 0.229 rev/min = 15.63 ticks/s
    assert math.isclose(VELOCITY_UNIT, 0.229 * 4096 / 60)


def test_line_noise_and_a_half_packet_do_not_wedge_the_bus(sdk):
    port, ph = sdk
    port.writePort(b"\x13\x37\xff\xff")  # noise before an instruction: resync on the header
    assert ph.ping(port, 1)[1] == COMM_SUCCESS
    # an instruction with a bad CRC is ignored, as a servo does: no status at all
    bad = bytearray(instructions.ping(1).encode())
    bad[-1] ^= 0xFF
    port.clearPort()
    port.writePort(bytes(bad))
    port.setPacketTimeout(11)
    assert ph.rxPacket(port, False)[1] == COMM_RX_TIMEOUT
    # a header whose length promises 500 bytes that never come: the servo gives up on it
    # after its inter-byte timeout and then reads the ping that followed
    port.writePort(bytes.fromhex("FF FF FD 00 01 F4 01 03"))
    assert ph.ping(port, 2)[1] == COMM_SUCCESS


def test_random_instructions_never_break_the_simulator():
    """Thousands of random (well-framed) instructions through the pty: every one is decoded
    and answered or ignored, none raises inside the simulator, the bus still serves."""
    import random

    import serial

    rng = random.Random(99)
    codes = [0x01, 0x02, 0x03, 0x04, 0x05, 0x06, 0x08, 0x10, 0x82, 0x83, 0x8A, 0x92, 0x93, 0x9A,
             0x00, 0x55, 0x7F, 0xFF]
    with start_servo_bus([1, 2, 3], return_delay_us=0) as bus, \
            serial.Serial(bus.port, 1_000_000, timeout=0, write_timeout=10) as ser:
        # a writer stalled mid-packet on a loaded machine is not what this test is about:
        # no half-received packet is abandoned
        bus.packet_timeout = 60.0
        sent = 0
        for _ in range(3000):
            dxl_id = rng.choice((1, 2, 3, 0xFE, 7))
            params = rng.randbytes(rng.choice((0, 1, 2, 3, 4, 5, 6, 8, 10, 15, 30)))
            if rng.random() < 0.5 and len(params) >= 4:  # plausible address / length fields
                params = rng.randrange(0, 700).to_bytes(2, "little") + bytes(
                    (rng.randrange(0, 8), 0)) + params[4:]
            packet = instructions.InstructionPacket(dxl_id, rng.choice(codes), params)
            sent += packet.instruction != 0x55  # 0x55 is a status: ignored
            ser.write(packet.encode())
            ser.reset_input_buffer()  # replies are not the point
        assert bus.wait_for(lambda: bus.instructions_seen == sent, timeout=60)  # hang guard
        assert bus.server_error is None
        bus.restore_defaults()  # whatever state the storm left: IDs, baud rates, torque
        ser.reset_input_buffer()
    with start_servo_bus([1]) as other:  # and a fresh bus is unaffected, of course
        assert other.server_error is None


def test_restore_defaults_makes_a_stormed_bus_talk_again(sdk, bus):
    port, ph = sdk
    ph.write1ByteTxOnly(port, 2, 7, 42)  # ID 2 -> 42
    assert ph.ping(port, 42)[1] == COMM_SUCCESS
    assert ph.ping(port, 2)[1] == COMM_RX_TIMEOUT
    bus.restore_defaults()
    assert ph.ping(port, 2) == (1020, COMM_SUCCESS, 0)


# ---------------------------------------------------------------------------- Bus Watchdog

BUS_WATCHDOG = 98


def test_bus_watchdog_stops_a_moving_servo_and_locks_the_goals(sdk, bus, clock):
    """e-Manual Bus Watchdog(98): silent host for longer than the setting -> the servo stops
    where it is, the item reads -1, Goal writes get a Data Range Error until 0 is written."""
    port, ph = sdk
    assert ph.write4ByteTxRx(port, 1, PROFILE_VEL, 50) == (COMM_SUCCESS, 0)  # ~780 ticks/s
    assert ph.write1ByteTxRx(port, 1, TORQUE, 1) == (COMM_SUCCESS, 0)
    assert ph.write1ByteTxRx(port, 1, BUS_WATCHDOG, 5) == (COMM_SUCCESS, 0)  # 100 ms
    assert ph.write4ByteTxRx(port, 1, GOAL_POS, 4000) == (COMM_SUCCESS, 0)
    clock.t += 0.09  # within the watchdog time: still moving (observed without bus traffic)
    assert not bus.watchdog_tripped(1) and bus.position(1) > 2048
    clock.t += 1.0
    assert bus.watchdog_tripped(1)
    stopped = bus.position(1)
    expected = 2048 + 50 * VELOCITY_UNIT * 0.1  # moved for exactly the 100 ms
    assert stopped == pytest.approx(expected, abs=1.0)
    clock.t += 1.0
    assert bus.position(1) == stopped  # and stays stopped
    assert ph.read1ByteTxRx(port, 1, BUS_WATCHDOG) == (0xFF, COMM_SUCCESS, 0)  # -1
    assert ph.read4ByteTxRx(port, 1, GOAL_POS)[0] == round(stopped)
    assert ph.read1ByteTxRx(port, 1, MOVING)[0] == 0
    assert ph.write4ByteTxRx(port, 1, GOAL_POS, 100) == (COMM_SUCCESS, ErrorCode.DATA_RANGE)
    writer = GroupSyncWrite(port, ph, GOAL_POS, 4)
    writer.addParam(1, le(100, 4))
    assert writer.txPacket() == COMM_SUCCESS
    clock.t += 1.0
    assert bus.position(1) == stopped  # a sync write is refused too
    assert ph.write1ByteTxRx(port, 1, BUS_WATCHDOG, 3) == (COMM_SUCCESS, ErrorCode.DATA_RANGE)
    assert ph.write1ByteTxRx(port, 1, BUS_WATCHDOG, 0) == (COMM_SUCCESS, 0)  # clears
    assert ph.read1ByteTxRx(port, 1, BUS_WATCHDOG)[0] == 0
    assert ph.write4ByteTxRx(port, 1, GOAL_POS, 3000) == (COMM_SUCCESS, 0)
    clock.t += 5.0
    assert bus.position(1) == 3000


def test_bus_watchdog_in_velocity_mode_sets_goal_velocity_to_zero(sdk, bus, clock):
    port, ph = sdk
    assert ph.write1ByteTxRx(port, 2, OPERATING_MODE, 1) == (COMM_SUCCESS, 0)
    assert ph.write1ByteTxRx(port, 2, TORQUE, 1) == (COMM_SUCCESS, 0)
    assert ph.write1ByteTxRx(port, 2, BUS_WATCHDOG, 100) == (COMM_SUCCESS, 0)  # 2 s, e-Manual
    assert ph.write4ByteTxRx(port, 2, GOAL_VELOCITY, 50) == (COMM_SUCCESS, 0)
    clock.t += 10.0
    at_stop = bus.position(2)
    assert at_stop == pytest.approx(2048 + 50 * VELOCITY_UNIT * 2.0, abs=1.0)
    assert ph.read4ByteTxRx(port, 2, GOAL_VELOCITY)[0] == 0
    assert signed32(ph.read4ByteTxRx(port, 2, 128)[0]) == 0  # present velocity
    assert ph.write4ByteTxRx(port, 2, GOAL_VELOCITY, 150) == (COMM_SUCCESS,
                                                               ErrorCode.DATA_RANGE)


def test_bus_watchdog_is_fed_only_by_packets_that_reach_the_servo(sdk, bus, clock):
    """Traffic to servo 2 (and sync reads naming it) does not feed servo 1's watchdog; a
    sync read naming servo 1 does; with torque off nothing is monitored."""
    port, ph = sdk
    for i in (1, 2, 3):
        assert ph.write1ByteTxRx(port, i, BUS_WATCHDOG, 5) == (COMM_SUCCESS, 0)  # 100 ms
    for i in (1, 2):
        assert ph.write1ByteTxRx(port, i, TORQUE, 1) == (COMM_SUCCESS, 0)
    reader = GroupSyncRead(port, ph, PRESENT_POS, 4)
    reader.addParam(2)
    for _ in range(10):  # one second of host traffic to servo 2 only
        clock.t += 0.08
        assert reader.txRxPacket() == COMM_SUCCESS
    assert bus.watchdog_tripped(1) and not bus.watchdog_tripped(2)
    assert not bus.watchdog_tripped(3)  # torque off: not monitored
    clock.t += 1.0
    assert bus.watchdog_tripped(2)


def test_watchdog_trips_when_the_adapter_is_unplugged(bus, clock):
    """What the live loop relies on: the host vanishes, the servos stop by themselves."""
    port = PortHandler(bus.port)
    assert port.openPort()
    ph = PacketHandler(2.0)
    try:
        assert ph.write1ByteTxRx(port, 3, BUS_WATCHDOG, 10) == (COMM_SUCCESS, 0)
        assert ph.write1ByteTxRx(port, 3, TORQUE, 1) == (COMM_SUCCESS, 0)
        assert ph.write4ByteTxRx(port, 3, GOAL_POS, 4095) == (COMM_SUCCESS, 0)
    finally:
        port.closePort()
    bus.unplug(adapter=True)
    clock.t += 3.0
    assert bus.watchdog_tripped(3)
    assert 2048 < bus.position(3) < 4095
    assert bus.servo(3).watchdog_trips == 1


# ---------------------------------------------------------------------------- CRC, fault rates


def test_bad_crc_instruction_is_ignored_entirely(sdk, bus):
    """No status, no effect (docs/sim.md: CRC errors); counted for observation."""
    port, ph = sdk
    bad = bytearray(instructions.write(1, LED, b"\x01").encode())
    bad[-2] ^= 0x55
    port.clearPort()
    port.writePort(bytes(bad))
    port.setPacketTimeout(11)
    assert ph.rxPacket(port, False)[1] == COMM_RX_TIMEOUT
    assert bus.crc_errors == 1
    assert ph.read1ByteTxRx(port, 1, LED) == (0, COMM_SUCCESS, 0)
    bus.corrupt_instructions(1)  # the same through fault injection (line noise to the servos)
    assert ph.write1ByteTxRx(port, 1, LED, 1)[0] == COMM_RX_TIMEOUT
    assert ph.read1ByteTxRx(port, 1, LED) == (0, COMM_SUCCESS, 0)
    assert bus.crc_errors == 2 and bus.fault_counts["instructions_corrupted"] == 1


def test_random_fault_rates_are_seeded_and_counted(sdk, bus):
    port, ph = sdk
    outcomes = []
    for seed in (5, 5):
        bus.set_fault_rates(corrupt=0.3, seed=seed)
        outcomes.append([ph.read4ByteTxRx(port, 1, PRESENT_POS)[1] for _ in range(40)])
    bus.set_fault_rates()
    assert outcomes[0] == outcomes[1]  # reproducible
    corrupt = outcomes[0].count(COMM_RX_CORRUPT)
    assert 0 < corrupt < 40 and set(outcomes[0]) == {COMM_SUCCESS, COMM_RX_CORRUPT}
    assert bus.fault_counts["corrupted"] == 2 * corrupt
    assert ph.ping(port, 1)[1] == COMM_SUCCESS
    with pytest.raises(ValueError, match="drop"):
        bus.set_fault_rates(drop=1.5)


def test_url_clock_and_named_key_errors():
    with bus_from_url("sim://dynamixel?ids=1-3&clock=manual&wire_time=off") as bus:
        assert isinstance(bus.clock, ManualClock)
        assert sorted(bus.servos) == [1, 2, 3] and not bus.model_wire_time
    for url, key in (("sim://dynamixel?idz=1", "idz"), ("sim://dynamixel?baud=fast", "baud"),
                     ("sim://dynamixel?return_delay_us=600", "return_delay_us"),
                     ("sim://dynamixel?noise=-1", "noise"), ("sim://dynamixel?ids=1&ids=2",
                                                              "ids"),
                     ("sim://dynamixel?wire_time=sometimes", "wire_time")):
        with pytest.raises(RigConfigError, match=key):
            bus_from_url(url)


def test_a_scheduled_unplug_pulls_the_cable_after_so_many_instructions():
    """``unplug_after=`` / ``unplug_for=``: the cable out from the 4th instruction heard on,
    for 0.25 s of simulated time, whatever process drives the bus (a leader arm unplugged
    mid-run)."""
    url = "sim://dynamixel?ids=1-2&clock=manual&wire_time=off&unplug_after=3&unplug_for=0.25"
    with bus_from_url(url) as bus:
        port = PortHandler(bus.port)
        assert port.openPort()
        ph = PacketHandler(2.0)
        try:
            seen = []
            for t in (0.1, 0.2, 0.3, 0.4, 0.5, 0.64, 0.65, 2.0):
                bus.clock.advance(t - bus.clock())
                seen.append(ph.ping(port, 2)[1])
            assert seen == [COMM_SUCCESS] * 3 + [COMM_RX_TIMEOUT] * 3 + [COMM_SUCCESS] * 2
        finally:
            port.closePort()
    for url, message in (("sim://dynamixel?unplug_for=1", "unplug_for needs unplug_after"),
                         ("sim://dynamixel?unplug_after=-1", "unplug_after"),
                         ("sim://dynamixel?unplug_after=1&unplug_for=0", "unplug_for")):
        with pytest.raises(RigConfigError, match=message):
            bus_from_url(url)


def test_from_url_dispatches_on_the_device():
    from rig.sim import from_url
    from rig.sim.imu import Bno055Simulator, StreamImuSimulator

    for url, cls in (("sim://dynamixel?ids=2", DynamixelBus), ("sim://bno055", Bno055Simulator),
                     ("sim://imu-stream?sensors=1", StreamImuSimulator)):
        with from_url(url) as sim:
            assert isinstance(sim, cls) and sim.port.startswith("/dev/pts/")
    with pytest.raises(RigConfigError, match="names no simulator"):
        from_url("sim://toaster")
