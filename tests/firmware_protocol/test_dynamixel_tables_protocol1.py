"""Protocol 1.0 control tables against the e-Manual control-table pages (values typed here
from emanual.robotis.com/docs/en/dxl/ax/ax-12a/, .../ax/ax-18a/, .../mx/mx-28/, .../mx/mx-64/,
.../mx/mx-106/, read in the e-Manual's source github.com/ROBOTIS-GIT/emanual: the pages'
tables plus the shared includes for ranges: temperature 0 ~ 100, MX voltage 50 ~ 160,
Multi Turn Offset -24,576 ~ 24,576)."""

from __future__ import annotations

import pytest

from firmware_protocol.dynamixel import load_control_table
from firmware_protocol.dynamixel import tables_protocol1 as t1

# name: (address, size, access, default or None, range or None)
AX_12A = {
    "Model Number": (0, 2, "R", 12, None), "ID": (3, 1, "RW", 1, (0, 253)),
    "Baud Rate": (4, 1, "RW", 1, (0, 254)), "Return Delay Time": (5, 1, "RW", 250, (0, 254)),
    "CW Angle Limit": (6, 2, "RW", 0, (0, 1023)), "CCW Angle Limit": (8, 2, "RW", 1023, (0, 1023)),
    "Temperature Limit": (11, 1, "RW", 70, (0, 100)),
    "Min Voltage Limit": (12, 1, "RW", 60, (50, 250)),
    "Max Voltage Limit": (13, 1, "RW", 140, (50, 250)),
    "Max Torque": (14, 2, "RW", 1023, (0, 1023)), "Status Return Level": (16, 1, "RW", 2, (0, 2)),
    "Alarm LED": (17, 1, "RW", 36, (0, 127)), "Shutdown": (18, 1, "RW", 36, (0, 127)),
    "Torque Enable": (24, 1, "RW", 0, (0, 1)), "LED": (25, 1, "RW", 0, (0, 1)),
    "CW Compliance Margin": (26, 1, "RW", 1, (0, 255)),
    "CCW Compliance Slope": (29, 1, "RW", 32, None),
    "Goal Position": (30, 2, "RW", None, (0, 1023)), "Moving Speed": (32, 2, "RW", None, (0, 2047)),
    "Torque Limit": (34, 2, "RW", 1023, (0, 1023)), "Present Position": (36, 2, "R", None, None),
    "Present Speed": (38, 2, "R", None, None), "Present Load": (40, 2, "R", None, None),
    "Present Voltage": (42, 1, "R", None, None), "Present Temperature": (43, 1, "R", None, None),
    "Registered": (44, 1, "R", 0, None), "Moving": (46, 1, "R", 0, None),
    "Lock": (47, 1, "RW", 0, (0, 1)), "Punch": (48, 2, "RW", 32, (32, 1023)),
}
AX_18A = {**AX_12A, "Model Number": (0, 2, "R", 18, None),
          "Temperature Limit": (11, 1, "RW", 75, (0, 99)),
          "Min Voltage Limit": (12, 1, "RW", 60, (50, 160)),
          "Max Voltage Limit": (13, 1, "RW", 140, (50, 160)),
          "Max Torque": (14, 2, "RW", 983, (0, 1023)),
          "Torque Limit": (34, 2, "RW", 983, (0, 1023))}
MX_28 = {k: v for k, v in AX_12A.items() if "Compliance" not in k}
MX_28.update({
    "Model Number": (0, 2, "R", 29, None), "Baud Rate": (4, 1, "RW", 34, (0, 254)),
    "CW Angle Limit": (6, 2, "RW", 0, (0, 4095)), "CCW Angle Limit": (8, 2, "RW", 4095, (0, 4095)),
    "Temperature Limit": (11, 1, "RW", 80, (0, 100)),
    "Min Voltage Limit": (12, 1, "RW", 60, (50, 160)),
    "Max Voltage Limit": (13, 1, "RW", 160, (50, 160)),
    "Multi Turn Offset": (20, 2, "RW", 0, (-24576, 24576)),
    "Resolution Divider": (22, 1, "RW", 1, (1, 4)),
    "D Gain": (26, 1, "RW", 0, (0, 254)), "I Gain": (27, 1, "RW", 0, (0, 254)),
    "P Gain": (28, 1, "RW", 32, (0, 254)), "Goal Position": (30, 2, "RW", None, (0, 4095)),
    "Punch": (48, 2, "RW", 0, (0, 1023)), "Realtime Tick": (50, 2, "R", None, None),
    "Goal Acceleration": (73, 1, "RW", 0, (0, 254)),
})
MX_64 = {**MX_28, "Model Number": (0, 2, "R", 310, None),
         "Current": (68, 2, "RW", 0, (0, 4095)),
         "Torque Control Mode Enable": (70, 1, "RW", 0, (0, 1)),
         "Goal Torque": (71, 2, "RW", 0, (0, 2047))}
MX_106 = {**MX_64, "Model Number": (0, 2, "R", 320, None), "Drive Mode": (10, 1, "RW", 0, (0, 3))}
# stall torque N·m, stall current A, no-load rpm at 12 V (each page's Specifications)
MOTOR = {"AX-12A": (1.5, 1.5, 59.0), "AX-18A": (1.8, 2.2, 97.0), 29: (2.5, 1.4, 55.0),
         310: (6.0, 4.1, 63.0), 320: (8.4, 5.2, 45.0)}


@pytest.mark.parametrize(("model", "expect"), [("AX-12A", AX_12A), ("AX-18A", AX_18A),
                                                (29, MX_28), (310, MX_64), (320, MX_106)])
def test_items_defaults_and_ranges(model, expect):
    t = load_control_table(model, protocol=1.0)
    assert t.protocol == 1.0 and t.eeprom_end == 24
    for name, (address, size, access, default, limits) in expect.items():
        item = t[name]
        assert (item.address, item.size) == (address, size), name
        assert item.writable == (access == "RW") and (name in t.read_only) == (access == "R")
        assert item.eeprom == (address < 24), name
        if default is not None:
            assert t.defaults[name] == default, name
        assert t.ranges.get(name) == limits, name


def test_names_numbers_and_x_series_fall_through():
    assert t1.load("AX-12").model_number == t1.load(12).model_number == 12
    assert t1.load("AX-18A").model_number == 18
    assert load_control_table("MX-28", protocol=1.0).model_number == 29
    assert load_control_table("MX-28").model_number == 30  # the 2.0 firmware's table
    assert load_control_table("AX-12A").protocol == 1.0  # no 2.0 table: 1.0 whatever asked
    assert load_control_table(29).display_name == "MX-28"
    assert t1.load("XM430-W350") is None
    assert load_control_table("XM430-W350", protocol=1.0).model_number == 1020
    assert load_control_table(310).resolve("Profile Acceleration").address == 73


def test_baud_rates_units_roles():
    ax, mx = load_control_table("AX-12A"), load_control_table(29)
    assert ax.baud_rates[1] == 1_000_000 and ax.baud_rates[34] == 57142
    assert ax.baud_rates[207] == 9615 and 0 not in ax.baud_rates
    assert mx.baud_rates[34] == 57142 and mx.baud_rates[252] == 3_000_000
    assert mx.baud_rates[0] == 2_000_000
    assert ax.units.ticks_per_rev == pytest.approx(1228.8) and ax.units.velocity_rpm == 0.111
    assert mx.units.ticks_per_rev == 4096 and mx.units.velocity_rpm == 0.114
    assert ax.resolve("Min Position Limit").name == "CW Angle Limit"
    assert ax.resolve("Max Position Limit").name == "CCW Angle Limit"
    assert ax.resolve("Present Velocity").name == "Present Speed"
    assert ax.resolve("Goal Velocity").name == "Moving Speed"
    assert ax.resolve("Present Input Voltage").name == "Present Voltage"
    assert ax.resolve("Bus Watchdog") is None and ax.resolve("Operating Mode") is None
    mem = ax.default_memory()
    assert mem[0] == 12 and mem[4] == 1 and mem[34] | mem[35] << 8 == 1023


@pytest.mark.parametrize("model", sorted(MOTOR, key=str))
def test_motor_constants(model):
    units = load_control_table(model, protocol=1.0).units
    assert (units.stall_torque_nm, units.stall_current_a, units.no_load_rpm) == MOTOR[model]
