"""Protocol 1.0 on the simulated bus, driven by the official ``dynamixel_sdk`` unchanged
(``PacketHandler(1.0)``): AX-12A, MX-28 on 1.0 firmware, an XM430-W350 switched to 1.0 by its
Protocol Type, and a bus that carries both protocols.

Addresses from the e-Manual control tables (AX-12A, MX-28 1.0; XM430 "Protocol Type" 13).
No sleeps; motion on a manual clock.
"""

from __future__ import annotations

import pytest
from dynamixel_sdk import COMM_RX_TIMEOUT, COMM_SUCCESS, GroupSyncWrite, PacketHandler, PortHandler

from firmware_protocol.dynamixel import protocol1 as p1
from rig.errors import RigConfigError
from rig.sim.dynamixel import bus_from_url, start_servo_bus
from rig.sim.dynamixel.servo import BOOT_TIME_S
from rig.sim.dynamixel.servo_legacy import LegacyServo

pytestmark = pytest.mark.usefixtures("tolerant_sdk_timeouts")

ID_, BAUD, CW, CCW, SRL = 3, 4, 6, 8, 16
TORQUE, GOAL, SPEED, PRESENT, PRESENT_SPEED = 24, 30, 32, 36, 38
XM_PRESENT = 132
RANGE, ANGLE, INSTRUCTION = 0x08, 0x02, 0x40
MIXED = "sim://dynamixel?ids=1:AX-12A,2:MX-28:1,3:XM430-W350:1,4:XM430-W350&wire_time=off"


@pytest.fixture
def mixed(clock):
    with bus_from_url(MIXED, clock=clock) as bus:
        port = PortHandler(bus.port)
        assert port.openPort() and port.setBaudRate(1_000_000)
        yield bus, port
        port.closePort()
        assert bus.server_error is None


def raw(port, ph, dxl_id, inst, params=()):
    """One instruction through the SDK's own ``txRxPacket`` (REBOOT, which its 1.0 handler
    refuses to send)."""
    tx = [0] * (6 + len(params))
    tx[2], tx[3], tx[4] = dxl_id, len(params) + 2, inst
    tx[5:5 + len(params)] = params
    return ph.txRxPacket(port, tx)


def test_each_servo_answers_only_its_protocol(mixed):
    bus, port = mixed
    v1, v2 = PacketHandler(1.0), PacketHandler(2.0)
    assert v1.ping(port, 1) == (12, COMM_SUCCESS, 0)
    assert v1.ping(port, 2) == (29, COMM_SUCCESS, 0)
    assert v1.ping(port, 3) == (1020, COMM_SUCCESS, 0)
    assert v1.ping(port, 4)[1] == COMM_RX_TIMEOUT
    found, result = v2.broadcastPing(port)
    assert result == COMM_SUCCESS and sorted(found) == [4]
    assert v2.ping(port, 1)[1] == COMM_RX_TIMEOUT
    assert isinstance(bus.servo(1), LegacyServo) and isinstance(bus.servo(2), LegacyServo)


def test_read_write_angle_limit_and_range_errors(mixed, clock):
    _, port = mixed
    ph = PacketHandler(1.0)
    assert ph.read2ByteTxRx(port, 1, PRESENT) == (512, COMM_SUCCESS, 0)
    assert ph.read2ByteTxRx(port, 2, PRESENT) == (2048, COMM_SUCCESS, 0)
    assert ph.write2ByteTxRx(port, 1, CW, 100) == (COMM_SUCCESS, 0)  # EEPROM, torque off
    assert ph.write1ByteTxRx(port, 1, TORQUE, 1) == (COMM_SUCCESS, 0)
    assert ph.write2ByteTxRx(port, 1, CCW, 900) == (COMM_SUCCESS, RANGE)  # EEPROM, torque on
    assert ph.write2ByteTxRx(port, 1, GOAL, 50) == (COMM_SUCCESS, ANGLE)  # below CW limit
    assert ph.write2ByteTxRx(port, 1, GOAL, 1024) == (COMM_SUCCESS, RANGE)
    assert ph.write2ByteTxRx(port, 1, PRESENT, 1) == (COMM_SUCCESS, RANGE)  # read-only
    assert ph.write2ByteTxRx(port, 1, SPEED, 300) == (COMM_SUCCESS, 0)  # 33.3 rpm
    assert ph.write2ByteTxRx(port, 1, GOAL, 612) == (COMM_SUCCESS, 0)
    clock.advance(0.1)  # 33.3 rpm x 1228.8 / 60 = 682 ticks/s: 68.2 ticks
    assert ph.read2ByteTxRx(port, 1, PRESENT) == (580, COMM_SUCCESS, 0)
    speed, _, _ = ph.read2ByteTxRx(port, 1, PRESENT_SPEED)
    assert speed == 300  # CCW: bit 10 clear
    clock.advance(1.0)
    assert ph.read2ByteTxRx(port, 1, PRESENT) == (612, COMM_SUCCESS, 0)


def test_ax_wheel_mode_sign_magnitude(mixed, clock):
    bus, port = mixed
    ph = PacketHandler(1.0)
    ph.write2ByteTxRx(port, 1, CCW, 0)  # CW = CCW = 0: wheel mode
    ph.write1ByteTxRx(port, 1, TORQUE, 1)
    assert ph.write2ByteTxRx(port, 1, SPEED, 1024 + 1023) == (COMM_SUCCESS, 0)  # full CW
    clock.advance(0.1)
    assert bus.position(1) == pytest.approx(512 - 59 * 1228.8 / 60 * 0.1)
    speed, _, _ = ph.read2ByteTxRx(port, 1, PRESENT_SPEED)
    assert speed & 0x400 and speed & 0x3FF == 532  # 59 rpm / 0.111 rpm, CW


def test_sync_write_bulk_read_and_the_ax_that_ignores_it(mixed):
    _, port = mixed
    ph = PacketHandler(1.0)
    for i in (1, 2, 3):
        assert ph.write1ByteTxRx(port, i, TORQUE if i < 3 else 64, 1) == (COMM_SUCCESS, 0)
    sw = GroupSyncWrite(port, ph, GOAL, 2)
    assert sw.addParam(1, [0x00, 0x02]) and sw.addParam(2, [0x00, 0x04])
    assert sw.txPacket() == COMM_SUCCESS
    assert ph.read2ByteTxRx(port, 2, GOAL) == (1024, COMM_SUCCESS, 0)
    assert ph.read2ByteTxRx(port, 1, GOAL) == (512, COMM_SUCCESS, 0)
    # BULK_READ through the handler (GroupBulkRead's 1.0 path calls bulkReadTx with one
    # argument too many: a TypeError in dynamixel-sdk, see the report)
    assert ph.bulkReadTx(port, [2, 2, PRESENT, 2, 3, XM_PRESENT], 6) == COMM_SUCCESS
    assert ph.readRx(port, 2, 2)[1:] == (COMM_SUCCESS, 0)
    assert ph.readRx(port, 3, 2) == ([0x00, 0x08], COMM_SUCCESS, 0)
    # an AX does not take part: it and every servo after it stay silent
    assert ph.bulkReadTx(port, [2, 1, PRESENT, 2, 2, PRESENT], 6) == COMM_SUCCESS
    assert ph.readRx(port, 1, 2)[1] == COMM_RX_TIMEOUT


def test_status_return_level_reg_write_action_broadcast(mixed):
    _, port = mixed
    ph = PacketHandler(1.0)
    assert ph.write1ByteTxRx(port, 1, SRL, 1) == (COMM_SUCCESS, 0)  # acknowledged at level 2
    assert ph.write1ByteTxRx(port, 1, 25, 1)[0] == COMM_RX_TIMEOUT  # level 1: no write status
    assert ph.read1ByteTxRx(port, 1, 25) == (1, COMM_SUCCESS, 0)
    assert ph.ping(port, 1)[1] == COMM_SUCCESS
    assert ph.regWriteTxRx(port, 2, 25, 1, [1]) == (COMM_SUCCESS, 0)
    assert ph.read1ByteTxRx(port, 2, 25) == (0, COMM_SUCCESS, 0)
    assert ph.action(port, p1.BROADCAST_ID) == COMM_SUCCESS  # broadcast: no status
    assert ph.read1ByteTxRx(port, 2, 25) == (1, COMM_SUCCESS, 0)
    assert ph.action(port, 2) == COMM_SUCCESS  # nothing registered
    assert raw(port, ph, 2, p1.Instruction1.ACTION)[2] == INSTRUCTION


def test_reboot_and_factory_reset(mixed, clock):
    bus, port = mixed
    ph = PacketHandler(1.0)
    ph.write1ByteTxRx(port, 2, TORQUE, 1)
    bus.raise_hardware_error(2, "overload")
    assert ph.read1ByteTxRx(port, 2, TORQUE) == (0, COMM_SUCCESS, 0x20)  # Shutdown 36
    assert raw(port, ph, 2, p1.Instruction1.REBOOT)[1:] == (COMM_SUCCESS, 0x20)
    assert ph.ping(port, 2)[1] == COMM_RX_TIMEOUT  # silent while it boots
    clock.advance(BOOT_TIME_S)
    assert ph.read1ByteTxRx(port, 2, TORQUE) == (0, COMM_SUCCESS, 0)
    assert ph.write1ByteTxOnly(port, 2, ID_, 7) == COMM_SUCCESS  # the status comes from ID 7
    assert ph.factoryReset(port, 7) == (COMM_SUCCESS, 0)
    clock.advance(BOOT_TIME_S)
    assert ph.ping(port, 7)[1] == COMM_RX_TIMEOUT  # ID 1 and 57,142 bit/s now
    port.setBaudRate(57600)  # within 1 % of 57,142: heard
    assert ph.ping(port, 1) == (29, COMM_SUCCESS, 0)
    # the XM430 on Protocol Type 1: a RESET puts it back to Protocol 2.0
    port.setBaudRate(1_000_000)
    assert ph.factoryReset(port, 3) == (COMM_SUCCESS, 0)
    clock.advance(BOOT_TIME_S)
    port.setBaudRate(57600)
    assert PacketHandler(2.0).ping(port, 1) == (1020, COMM_SUCCESS, 0)


def test_bad_checksum_is_ignored(mixed):
    bus, port = mixed
    ph = PacketHandler(1.0)
    pkt = bytearray(p1.encode_instruction(1, p1.Instruction1.WRITE, bytes((25, 1))))
    pkt[-1] ^= 0xFF
    port.clearPort()
    port.writePort(list(pkt))
    port.setPacketTimeout(6)
    assert ph.rxPacket(port)[1] == COMM_RX_TIMEOUT
    assert ph.read1ByteTxRx(port, 1, 25) == (0, COMM_SUCCESS, 0)
    assert bus.crc_errors == 1


def test_url_keys_and_errors():
    with start_servo_bus([1], "AX-12A", baud_rate=57600, model_wire_time=False) as bus:
        assert bus.servo(1).baud_rate == 57142 and bus.servo(1).get("Baud Rate") == 34
    with pytest.raises(RigConfigError, match=r"only Protocol 1\.0"):
        bus_from_url("sim://dynamixel?model=AX-12A&protocol=2")
    with pytest.raises(RigConfigError, match="ID:MODEL"):
        bus_from_url("sim://dynamixel?ids=1:AX-12A:3")
    with pytest.raises(RigConfigError, match="protocol"):
        bus_from_url("sim://dynamixel?protocol=1.5")
