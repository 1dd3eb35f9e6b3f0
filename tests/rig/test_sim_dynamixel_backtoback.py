"""Back-to-back: the same test bodies on the simulator and, when ``RIG_DXL_PORT`` names a real
port (U2D2 + X-series servos), on hardware.

Hardware settings: ``RIG_DXL_PORT`` (e.g. /dev/ttyUSB0), ``RIG_DXL_BAUD`` (default 1000000),
``RIG_DXL_IDS`` (default "1"). The bodies never enable torque, so nothing moves; they only
toggle the LED and read.
"""

from __future__ import annotations

import os
from collections.abc import Iterator

import dynamixel_sdk.port_handler
import pytest
from dynamixel_sdk import (
    COMM_RX_TIMEOUT,
    COMM_SUCCESS,
    GroupSyncRead,
    PacketHandler,
    PortHandler,
)

from firmware_protocol.dynamixel import ErrorCode, load_control_table
from rig.sim.dynamixel import start_servo_bus

LED, MODEL_NUMBER, PRESENT_POS, TORQUE = 65, 0, 132, 64


def _signed(value: int) -> int:
    return value - (1 << 32) if value & 0x80000000 else value


def _hardware_ids() -> list[int]:
    return [int(i) for i in os.environ.get("RIG_DXL_IDS", "1").split(",")]


@pytest.fixture(autouse=True)
def tolerant_sdk_timeouts(monkeypatch):
    """~100 ms packet timeout (SDK default ~34 ms) so a loaded test machine does not lose
    replies; also a sane value for a U2D2 whose latency timer is left at 16 ms."""
    monkeypatch.setattr(dynamixel_sdk.port_handler, "LATENCY_TIMER", 50)


@pytest.fixture(params=["sim", pytest.param("hardware", marks=pytest.mark.hardware)])
def chain(request) -> Iterator[tuple[PortHandler, PacketHandler, list[int]]]:
    """(open port, packet handler, servo ids) on the simulator or on real servos."""
    if request.param == "sim":
        bus = start_servo_bus([1, 2, 3], return_delay_us=0)
        name, baud, ids = bus.port, 1_000_000, [1, 2, 3]
    else:
        bus = None
        name = os.environ.get("RIG_DXL_PORT", "")
        if not name:
            pytest.skip("RIG_DXL_PORT is not set")
        baud, ids = int(os.environ.get("RIG_DXL_BAUD", "1000000")), _hardware_ids()
    port = PortHandler(name)
    try:
        assert port.openPort() and port.setBaudRate(baud)
        yield port, PacketHandler(2.0), ids
    finally:
        if port.is_open:
            port.closePort()
        if bus is not None:
            bus.close()


def test_ping_and_model_number(chain):
    port, ph, ids = chain
    for dxl_id in ids:
        model, result, error = ph.ping(port, dxl_id)
        assert result == COMM_SUCCESS and not error & 0x7F
        load_control_table(model)  # a model the SDK ships a control table for
        assert ph.read2ByteTxRx(port, dxl_id, MODEL_NUMBER)[:2] == (model, COMM_SUCCESS)
    assert ph.ping(port, 252)[1] == COMM_RX_TIMEOUT  # nobody there


def test_led_roundtrip_and_read_only_refusal(chain):
    port, ph, ids = chain
    dxl_id = ids[0]
    try:
        assert ph.write1ByteTxRx(port, dxl_id, LED, 1)[0] == COMM_SUCCESS
        assert ph.read1ByteTxRx(port, dxl_id, LED)[:2] == (1, COMM_SUCCESS)
    finally:
        ph.write1ByteTxRx(port, dxl_id, LED, 0)
    result, error = ph.write4ByteTxRx(port, dxl_id, PRESENT_POS, 0)
    assert result == COMM_SUCCESS and error & 0x7F == ErrorCode.ACCESS


def test_sync_read_positions(chain):
    port, ph, ids = chain
    reader = GroupSyncRead(port, ph, PRESENT_POS, 4)
    for dxl_id in ids:
        reader.addParam(dxl_id)
    assert reader.txRxPacket() == COMM_SUCCESS
    for dxl_id in ids:
        assert reader.isAvailable(dxl_id, PRESENT_POS, 4)
        synced = _signed(reader.getData(dxl_id, PRESENT_POS, 4))
        single = _signed(ph.read4ByteTxRx(port, dxl_id, PRESENT_POS)[0])
        assert abs(synced - single) <= 20  # torque is off: the shaft is (nearly) still
    assert ph.read1ByteTxRx(port, ids[0], TORQUE)[1] == COMM_SUCCESS


BUS_WATCHDOG = 98


def test_bus_watchdog_register_range(chain):
    """Bus Watchdog (98) takes 0..127 (20 ms units); other values are a Data Range Error.
    Torque stays off, so the watchdog is never armed and nothing moves."""
    port, ph, ids = chain
    dxl_id = ids[0]
    try:
        assert ph.write1ByteTxRx(port, dxl_id, BUS_WATCHDOG, 127)[:2] == (COMM_SUCCESS, 0)
        assert ph.read1ByteTxRx(port, dxl_id, BUS_WATCHDOG)[:2] == (127, COMM_SUCCESS)
        result, error = ph.write1ByteTxRx(port, dxl_id, BUS_WATCHDOG, 128)
        assert result == COMM_SUCCESS and error & 0x7F == ErrorCode.DATA_RANGE
        assert ph.read1ByteTxRx(port, dxl_id, BUS_WATCHDOG)[0] == 127
    finally:
        ph.write1ByteTxRx(port, dxl_id, BUS_WATCHDOG, 0)
    assert ph.read1ByteTxRx(port, dxl_id, BUS_WATCHDOG)[:2] == (0, COMM_SUCCESS)
