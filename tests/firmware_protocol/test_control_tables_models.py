"""Every 2.0 model's control table against values typed here from its e-Manual page.

The expectations are typed separately from ``control_table.py`` so that a slip in either shows.
Family rows come from the family's reference page (xm430-w350, xl330-m288, mx-28-2,
ph54-200-s500-r, h54-200-s500-ra, xl320); MODEL rows from each model's own page.
"""

from __future__ import annotations

import pytest

from firmware_protocol.dynamixel import load_control_table
from firmware_protocol.dynamixel.control_table import model_numbers

X430 = ["xl430_w250", "2xl430_w250", "2xc430_w250", "xc430_w150", "xc430_w240", "xm430_w210",
        "xm430_w350", "xh430_w210", "xh430_w350", "xh430_v210", "xh430_v350", "xd430_t210",
        "xd430_t350", "xm540_w150", "xm540_w270", "xh540_w150", "xh540_w270", "xh540_v150",
        "xh540_v270", "xd540_t150", "xd540_t270", "xw540_t140", "xw540_t260", "xw540_h260",
        "xw430_t333"]
X330 = ["xl330_m077", "xl330_m288", "xc330_m181", "xc330_m288", "xc330_t181", "xc330_t288"]
MX2 = ["mx_28", "mx_64", "mx_106"]
P = ["ph42_020_s300", "ph54_100_s500", "ph54_200_s500", "pm42_010_s260", "pm54_040_s250",
     "pm54_060_s250"]
PRO_A = ["h42_20_s300_ra", "h54_100_s500_ra", "h54_200_s500_ra", "m42_10_s260_ra",
         "m54_40_s250_ra", "m54_60_s250_ra"]
NO_CURRENT = {"xl430_w250", "2xl430_w250", "2xc430_w250", "xc430_w150", "xc430_w240", "mx_28"}

# item: (address, default or None, range or None) -- xm430-w350 page
X_EXPECT = {
    "ID": (7, 1, (0, 252)), "Baud Rate": (8, 1, (0, 7)), "Return Delay Time": (9, 250, (0, 254)),
    "Drive Mode": (10, 0, (0, 13)), "Operating Mode": (11, 3, None),
    "Secondary(Shadow) ID": (12, 255, (0, 255)), "Protocol Type": (13, 2, (1, 2)),
    "Homing Offset": (20, 0, (-1_044_479, 1_044_479)), "Moving Threshold": (24, 10, (0, 1023)),
    "Max Position Limit": (48, 4095, (0, 4095)), "Min Position Limit": (52, 0, (0, 4095)),
    "Torque Enable": (64, 0, (0, 1)), "Status Return Level": (68, 2, (0, 2)),
    "Hardware Error Status": (70, None, None), "Bus Watchdog": (98, 0, (0, 127)),
    "Goal PWM": (100, None, None), "Goal Velocity": (104, None, None),
    "Profile Acceleration": (108, 0, (0, 32767)), "Profile Velocity": (112, 0, (0, 32767)),
    "Goal Position": (116, None, (-1_048_575, 1_048_575)), "Present Velocity": (128, None, None),
    "Present Position": (132, None, None), "PWM Limit": (36, 885, (0, 885)),
}
# ph54-200-s500-r page (P-series) ; PRO(A) the same but no Protocol Type
P_EXPECT = {
    "ID": (7, 1, (0, 252)), "Baud Rate": (8, 1, (0, 9)), "Drive Mode": (10, 0, (0, 13)),
    "Operating Mode": (11, 3, None), "Secondary ID": (12, 255, (0, 255)),
    "Homing Offset": (20, 0, (-2_147_483_648, 2_147_483_647)), "Moving Threshold": (24, 20, None),
    "PWM Limit": (36, 2009, (0, 2009)), "Torque Enable": (512, 0, (0, 1)),
    "Status Return Level": (516, 2, (0, 2)), "Hardware Error Status": (518, None, None),
    "Bus Watchdog": (546, 0, (0, 127)), "Goal PWM": (548, None, None),
    "Goal Current": (550, None, None), "Goal Velocity": (552, None, None),
    "Profile Acceleration": (556, 0, None), "Profile Velocity": (560, 0, None),
    "Goal Position": (564, None, None), "Present Current": (574, None, None),
    "Present Velocity": (576, None, None), "Present Position": (580, None, None),
}
# per model: Max Position Limit default, position range half, Velocity Limit, Current Limit
P_MODEL = {
    "ph54_200_s500": (501_433, 501_923, 2900, 22740),
    "ph42_020_s300": (303_454, 303_750, 2920, 4500),
    "pm54_060_s250": (251_173, 251_417, 2830, 7980),
    "h54_200_s500_ra": (501_433, 501_923, 2900, 22740),
    "m42_10_s260_ra": (262_931, 263_187, 2600, 1461),
}
# per X model: Velocity Limit, Current Limit, Temperature Limit, (min V, max V) defaults
X_MODEL = {
    "xm430_w350": (200, 1193, 80, (95, 160)),
    "xl430_w250": (265, None, 72, (60, 140)),
    "xl330_m288": (445, 1750, 70, (35, 70)),
    # read in github.com/ROBOTIS-GIT/emanual docs/en/dxl/<series>/<model>.md
    "xm430_w210": (330, 1193, 80, (95, 160)),
    "xh430_w210": (210, 648, 80, (95, 160)), "xh430_w350": (130, 648, 80, (95, 160)),
    "xd430_t210": (210, 648, 80, (95, 160)), "xd430_t350": (130, 648, 80, (95, 160)),
    "xh430_v210": (380, 689, 80, (110, 300)), "xh430_v350": (135, 689, 80, (110, 300)),
    "xc430_w150": (460, None, 80, (60, 160)), "xc430_w240": (306, None, 80, (60, 160)),
    "2xl430_w250": (250, None, 72, (60, 140)), "2xc430_w250": (275, None, 80, (60, 160)),
    "xm540_w150": (380, 2047, 80, (95, 160)), "xm540_w270": (128, 2047, 80, (95, 160)),
    "mx_64": (435, 1941, 80, (95, 160)), "mx_106": (360, 2047, 80, (95, 160)),
}
# per model: Velocity I, Velocity P, Position D, Position P default gains (the same pages)
GAINS = {
    "xm430_w350": (1920, 100, 0, 800), "xm430_w210": (1920, 100, 0, 800),
    "xh430_w210": (1920, 100, 0, 900), "xh430_w350": (1920, 100, 0, 900),
    "xd430_t210": (1920, 100, 0, 900), "xd430_t350": (1920, 100, 0, 900),
    "xh430_v210": (1920, 100, 0, 800), "xh430_v350": (1920, 100, 0, 800),
    "xc430_w150": (1920, 100, 0, 460), "xc430_w240": (1920, 100, 0, 700),
    "2xl430_w250": (1800, 100, 2000, 640), "2xc430_w250": (1920, 100, 0, 700),
    "xm540_w150": (1920, 100, 0, 800), "xm540_w270": (1920, 100, 0, 800),
    "mx_64": (1920, 100, 0, 850), "mx_106": (1920, 100, 0, 850),
}
# per model: stall torque N·m, stall current A, no-load rpm at the nominal voltage, current
# unit mA (None: no current sensing) -- Specifications of each page (_data/dxl_x_info.yml,
# _data/dxl_mx_info.yml in the e-Manual's source)
MOTOR = {
    "xm430_w350": (4.1, 2.3, 46.0, 2.69), "xm430_w210": (3.0, 2.3, 77.0, 2.69),
    "xh430_w210": (2.5, 1.3, 50.0, 2.69), "xh430_w350": (3.4, 1.3, 30.0, 2.69),
    "xh430_v210": (2.6, 0.7, 52.0, 1.34), "xh430_v350": (3.3, 0.7, 31.0, 1.34),
    "xc430_w150": (1.6, 1.4, 106.0, None), "xc430_w240": (1.9, 1.4, 70.0, None),
    "2xl430_w250": (1.4, 1.3, 57.0, None), "2xc430_w250": (1.8, 1.4, 64.0, None),
    "xm540_w150": (7.3, 4.4, 53.0, 2.69), "xm540_w270": (10.6, 4.4, 30.0, 2.69),
    "xh540_w150": (7.1, 4.9, 70.0, 2.69), "xh540_w270": (9.9, 4.9, 39.0, 2.69),
    "xh540_v150": (6.4, 2.4, 60.0, 2.69), "xh540_v270": (9.2, 2.4, 34.0, 2.69),
    "xw540_t140": (6.9, 4.9, 72.0, 2.69), "xw540_t260": (9.5, 4.9, 40.0, 2.69),
    "xc330_m181": (0.60, 1.80, 129.0, 1.0), "xc330_m288": (0.93, 1.80, 81.0, 1.0),
    "xc330_t181": (0.76, 0.80, 104.0, 1.0), "xc330_t288": (0.92, 0.80, 65.0, 1.0),
    "mx_28": (2.5, 1.4, 55.0, None), "mx_64": (6.0, 4.1, 63.0, 3.36),
    "mx_106": (8.4, 5.2, 45.0, 3.36),
}


def _check(t, expect):
    for name, (address, default, rng) in expect.items():
        item = t.resolve(name)
        assert item is not None, name
        assert item.address == address, name
        if default is not None:
            assert t.defaults[item.name] == default, name
        if rng is not None:
            assert t.ranges[item.name] == rng, name


def test_every_model_of_the_families_is_shipped():
    numbers = model_numbers()
    for key in X430 + X330 + MX2 + P + PRO_A + ["xl320"]:
        assert key in numbers, key


@pytest.mark.parametrize("key", X430 + MX2)
def test_x430_540_and_mx(key):
    t = load_control_table(key)
    _check(t, X_EXPECT)
    assert t.eeprom_end == 64 and t.home_ticks == 2048
    assert t.baud_rates == {0: 9600, 1: 57600, 2: 115200, 3: 1_000_000, 4: 2_000_000,
                            5: 3_000_000, 6: 4_000_000, 7: 4_500_000}
    modes = {1, 3, 4, 16} if key in NO_CURRENT else {0, 1, 3, 4, 5, 16}
    assert t.operating_modes == modes
    assert [(b.address_start, b.data_start, b.count) for b in t.indirect] == [
        (168, 224, 28), (578, 634, 28)]
    assert t.size == 662
    mem = t.default_memory()
    assert int.from_bytes(mem[168:170], "little") == 224  # Indirect Address 1 -> Data 1
    assert int.from_bytes(mem[632:634], "little") == 661  # Indirect Address 56 -> Data 56
    if key in NO_CURRENT:
        assert t.resolve("Present Load").address == 126 and t.units.current_ma is None
        assert "Current Limit" not in t.ranges
    else:
        assert t["Present Current"].address == 126 and t["Goal Current"].address == 102
        assert t.defaults["Goal Current"] == t.defaults["Current Limit"]
    for name in ("Present Position", "Present Velocity", "Model Number", "Model Information",
                 "Hardware Error Status", "Firmware Version"):
        assert not t[name].writable, name
    assert t["Goal Position"].writable and t["ID"].eeprom and not t["Torque Enable"].eeprom
    if key.startswith("mx_"):
        assert t.defaults["Acceleration Limit"] == 32767 and t.defaults["Position P Gain"] == 850


@pytest.mark.parametrize("key", X330)
def test_x330(key):
    t = load_control_table(key)
    expect = dict(X_EXPECT, **{"Baud Rate": (8, 1, (0, 6)), "Protocol Type": (13, 2, (2, 22)),
                               "Max Voltage Limit": (32, 70, (31, 70)),
                               "Min Voltage Limit": (34, 35, (31, 70)),
                               "Velocity Limit": (44, 445, (0, 2047))})
    _check(t, expect)
    assert t.operating_modes == {0, 1, 3, 4, 5, 16}
    assert max(t.baud_rates) == 6 and t.baud_rates[6] == 4_000_000
    assert [(b.address_start, b.data_start, b.count) for b in t.indirect] == [(168, 224, 28)]
    assert t.units.current_ma == 1.0
    assert t["Backup Ready"].address == 147 and not t["Backup Ready"].writable
    assert t["Startup Configuration"].address == 60 and t["Startup Configuration"].eeprom
    fw52 = load_control_table(f"{key}_fw52")
    assert [(b.address_start, b.data_start, b.count) for b in fw52.indirect] == [(168, 208, 20)]
    assert fw52.model_number == t.model_number and fw52.size == 228
    assert load_control_table(t.model_number).model == key  # the number keeps the SDK's file


@pytest.mark.parametrize("key", P + PRO_A)
def test_p_series_and_pro_a(key):
    t = load_control_table(key)
    expect = dict(P_EXPECT)
    if key in PRO_A:
        assert "Protocol Type" not in t
    else:
        expect["Protocol Type"] = (13, 2, (2, 10))
    _check(t, expect)
    assert t.eeprom_end == 512 and t.home_ticks == 0
    assert t["Homing Offset"].eeprom and not t["Torque Enable"].eeprom
    assert t.operating_modes == {0, 1, 3, 4, 16}
    assert t.baud_rates[8] == 6_000_000 and t.baud_rates[9] == 10_500_000
    assert [(b.address_start, b.data_start, b.count) for b in t.indirect] == [(168, 634, 128)]
    assert t.units.velocity_rpm == 0.01 and t.units.accel_rpm2 == 1.0
    assert t.units.current_ma == 1.0 and t.units.pwm_max == 2009
    assert t.roles["LED"] == "LED Red" and t.resolve("Secondary(Shadow) ID").address == 12
    half = t.ranges["Max Position Limit"][1]
    assert t.ranges["Max Position Limit"] == (-half, half) == t.ranges["Min Position Limit"]
    assert t.units.ticks_per_rev == 2 * half
    if key in P_MODEL:
        limit, rng, velocity, current = P_MODEL[key]
        assert t.defaults["Max Position Limit"] == limit
        assert t.defaults["Min Position Limit"] == -limit
        assert half == rng
        assert t.defaults["Velocity Limit"] == velocity == t.ranges["Velocity Limit"][1]
        assert t.defaults["Current Limit"] == current == t.ranges["Current Limit"][1]


def test_xl320():
    t = load_control_table("XL320")
    expect = {"ID": (3, 1, (0, 252)), "Baud Rate": (4, 3, (0, 3)),
              "Return Delay Time": (5, 250, (0, 254)), "Min Position Limit": (6, 0, (0, 1023)),
              "Max Position Limit": (8, 1023, (0, 1023)), "Operating Mode": (11, 2, (1, 2)),
              "Temperature Limit": (12, 65, (0, 150)), "Min Voltage Limit": (13, 60, (50, 250)),
              "Max Voltage Limit": (14, 90, (50, 250)), "PWM Limit": (15, 1023, (0, 1023)),
              "Status Return Level": (17, 2, (0, 2)), "Shutdown": (18, 3, (0, 7)),
              "Torque Enable": (24, 0, (0, 1)), "LED": (25, 0, (0, 7)),
              "Position P Gain": (29, 32, (0, 254)), "Goal Position": (30, None, (0, 1023)),
              "Goal Velocity": (32, None, (0, 2047)), "Goal PWM": (35, None, (0, 1023)),
              "Present Position": (37, None, None), "Present Velocity": (39, None, None),
              "Present Input Voltage": (45, None, None), "Hardware Error Status": (50, None, None)}
    _check(t, expect)
    assert t.eeprom_end == 24 and t["Shutdown"].eeprom and not t["Torque Enable"].eeprom
    assert t.baud_rates == {0: 9600, 1: 57600, 2: 115200, 3: 1_000_000}
    assert t.operating_modes == {1, 2} and t.indirect == () and t.home_ticks == 512
    assert t.units.ticks_per_rev == pytest.approx(1228.8) and t.units.velocity_rpm == 0.111
    assert t.units.current_ma is None
    for name in ("Present Position", "Present Speed", "Present Load", "Present Voltage",
                 "Moving", "Hardware Error Status", "Registered Instruction"):
        assert not t[name].writable, name
    for absent in ("Homing Offset", "Drive Mode", "Secondary ID", "Bus Watchdog",
                   "Present Current", "Profile Acceleration"):
        assert t.resolve(absent) is None, absent


@pytest.mark.parametrize("key", sorted(X_MODEL))
def test_x_models_own_values(key):
    velocity, current, temperature, (vmin, vmax) = X_MODEL[key]
    t = load_control_table(key)
    assert t.defaults["Velocity Limit"] == velocity
    assert t.defaults.get("Current Limit") == current
    assert t.defaults["Temperature Limit"] == temperature
    assert (t.defaults["Min Voltage Limit"], t.defaults["Max Voltage Limit"]) == (vmin, vmax)
    assert t.ranges["Max Voltage Limit"] == t.ranges["Min Voltage Limit"]
    lo, hi = t.ranges["Max Voltage Limit"]
    assert lo <= vmin <= vmax <= hi


@pytest.mark.parametrize("key", sorted(GAINS))
def test_x_models_gains(key):
    t = load_control_table(key)
    names = ("Velocity I Gain", "Velocity P Gain", "Position D Gain", "Position P Gain")
    assert tuple(t.defaults[n] for n in names) == GAINS[key]


@pytest.mark.parametrize("key", sorted(MOTOR))
def test_x_models_motor_constants(key):
    u = load_control_table(key).units
    assert (u.stall_torque_nm, u.stall_current_a, u.no_load_rpm, u.current_ma) == MOTOR[key]


def test_xm430_w350_defaults_unchanged():
    t = load_control_table("XM430-W350")
    assert t.defaults["Firmware Version"] == 48 and t.defaults["Position P Gain"] == 800
    assert (t.defaults["Velocity I Gain"], t.defaults["Velocity P Gain"]) == (1920, 100)
    assert t.units.current_ma == 2.69 and t.units.stall_torque_nm == 4.1
