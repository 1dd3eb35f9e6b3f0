"""The servo bus base class: named servos, the goal check, and the defaults a backend without
alerts or a watchdog inherits (callers never ask a bus whether it has a method)."""

from __future__ import annotations

import numpy as np
import pytest

from rig.devices import JointKinematics, Servo, ServoAxis, ServoBus, ServoLimb, open_port
from rig.errors import HardwareAlertError, RigConfigError, RigProtocolError, UnreachableError


class MemoryBus(ServoBus):
    """Servos that are where they were last told to be: no alerts, no watchdog."""

    kind = "memory bus"

    def _open(self) -> None:
        self.present = np.array([2048] * len(self.ids), dtype=np.int64)
        self.on = [False] * len(self.ids)
        self.stuck: set[int] = set()

    def _read_ticks(self, deadline: float) -> np.ndarray:
        return self.present.copy()

    def _write_goal_ticks(self, ticks: list[int]) -> None:
        self.present = np.array(ticks, dtype=np.int64)

    def _read_torque(self):
        return self.on

    def _write_torque(self, on: bool) -> None:
        self.on = [on and i not in self.stuck for i in self.ids]


@pytest.fixture
def port():
    with open_port("sim://dynamixel?ids=1") as p:  # any port: the memory bus never uses it
        yield p


def test_servos_are_named_and_found_by_id_or_name(port):
    with MemoryBus(port, [Servo(3, "elevation"), 5, Servo(7, "rotation")]) as bus:
        assert bus.ids == (3, 5, 7) and bus.names == ("elevation", "5", "rotation")
        assert bus.index("rotation") == 2 and bus.index(5) == 1
        with pytest.raises(KeyError, match="no servo 'wrist'"):
            bus.index("wrist")
    with pytest.raises(RigConfigError, match="distinct IDs"):
        MemoryBus(port, [1, 1])


def test_defaults_of_a_backend_without_alerts_or_watchdog(port):
    bus = MemoryBus(port, [1, 2])
    assert bus.poll_alerts() == [] and not bus.alert_pending
    assert bus.arm_watchdog(100) == 0 and bus.arm_watchdog() == 0
    bus.disarm_watchdog()
    bus.feed_watchdog()
    bus.configure()
    assert bus.advice == []
    np.testing.assert_array_equal(bus.set_torque(True), [True, True])
    bus.stuck.add(2)
    with pytest.raises(RigProtocolError, match="ID 2: torque did not come on"):
        bus.set_torque(True)
    bus.shutdown()
    bus.shutdown()  # idempotent
    assert bus.closed


def test_goals_outside_a_servos_limits_are_not_written(port):
    with MemoryBus(port, [Servo(1, min_ticks=1000, max_ticks=3000), 2]) as bus:
        bus.write_goal_ticks([1500, 4000])
        np.testing.assert_array_equal(bus.read_ticks(), [1500, 4000])
        with pytest.raises(UnreachableError, match="ID 1") as info:
            bus.write_goal_ticks([999, 2000])
        assert info.value.expected == "1000..3000"
        bus.set_position_limits([0, 0], [4095, 3000])
        with pytest.raises(UnreachableError, match="ID 2"):
            bus.write_goal_ticks([999, 3001])
        np.testing.assert_array_equal(bus.max_ticks, [4095, 3000])


def test_a_servo_limb_composes_a_bus_and_its_joints_kinematics(port):
    kin = JointKinematics([ServoAxis(1, (0, 0, 1)), ServoAxis(2, (0, 1, 0))])
    with ServoLimb(MemoryBus(port, [1, 2]), kin) as limb:
        goal = limb.write_orientations(kin.forward([2100, 1900])[None], [2048, 2048])
        assert goal.tolist() == [2100, 1900]
        np.testing.assert_array_equal(limb.read_orientations()[0], kin.forward([2100, 1900]))
        limb.set_position_limits([2000, 1800], [2200, 2100])
        assert limb.kinematics.joint(0).max_ticks.tolist() == [2200, 2100]
        with pytest.raises(UnreachableError, match="ID 1"):
            limb.bus.write_goal_ticks([2300, 2000])
        with pytest.raises(RigConfigError, match="zero_ticks outside"):
            limb.set_position_limits([2100, 1800], [2200, 2100])  # nothing changed
        assert limb.bus.min_ticks.tolist() == [2000, 1800]
    assert limb.bus.closed
    with pytest.raises(RigConfigError, match="name different servos"):
        ServoLimb(MemoryBus(port, [2, 1]), kin)


def test_a_hardware_alert_names_the_servo_that_stays_off(port):
    from rig.errors import HardwareAlert

    class AlertingBus(MemoryBus):
        def _poll_alerts(self):
            return [HardwareAlert(str(self.port), 2, 0.0, 0x20, ("overload",), False)]

    with AlertingBus(port, [1, 2]) as bus:
        bus.stuck.add(2)
        bus.alert_pending = True
        with pytest.raises(HardwareAlertError, match="ID 2: hardware alert overload"):
            bus.set_torque(True)
        assert not bus.alert_pending  # the poll cleared it


def test_a_backend_without_a_split_read_reads_at_the_finish(port):
    """begin_read / finish_read on a backend that only has ``_read_ticks``: nothing is sent at
    the begin, the whole read happens at the finish."""
    with MemoryBus(port, [1, 2]) as bus:
        bus.write_goal_ticks([100, 200])
        bus.begin_read()
        bus.write_goal_ticks([300, 400])  # (a caller must not; here: the read is at the finish)
        np.testing.assert_array_equal(bus.finish_read(), [300, 400])
        with pytest.raises(RuntimeError, match="without begin_read"):
            bus.finish_read()
