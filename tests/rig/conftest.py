"""Fixtures of the simulated-servo wire tests (``test_sim_dynamixel*.py``,
``test_sim_servo_wire.py``; a module's own fixture of the same name wins).

``tolerant_sdk_timeouts`` (a module opts in with ``pytestmark =
pytest.mark.usefixtures("tolerant_sdk_timeouts")``) raises the SDK's ``LATENCY_TIMER`` knob
(its USB adapter latency, 16 ms by default) to 50 ms: a packet timeout of ~100 ms, so replies
that should come are not lost to scheduling jitter, and timeout tests stay quick. ``clock`` is
a :class:`~rig.sim.clock.ManualClock`; ``bus`` three XM430-W350 on it; ``sdk`` the SDK's port
and 2.0 packet handler on that bus.
"""

from __future__ import annotations

import dynamixel_sdk.port_handler
import pytest
from dynamixel_sdk import PacketHandler, PortHandler

from rig.sim.clock import ManualClock
from rig.sim.dynamixel import start_servo_bus


@pytest.fixture
def tolerant_sdk_timeouts(monkeypatch):
    monkeypatch.setattr(dynamixel_sdk.port_handler, "LATENCY_TIMER", 50)


@pytest.fixture
def clock():
    return ManualClock(100.0)


@pytest.fixture
def bus(clock):
    with start_servo_bus([1, 2, 3], "XM430-W350", return_delay_us=0, clock=clock) as b:
        yield b
        assert b.server_error is None


@pytest.fixture
def sdk(bus):
    port = PortHandler(bus.port)
    assert port.openPort()
    yield port, PacketHandler(2.0)
    port.closePort()
