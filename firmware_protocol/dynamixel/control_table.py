"""Control tables of Protocol 2.0 servos, loaded from the data that the ROBOTIS SDK ships.

Source of each fact
-------------------
* **Address, size, name** of every item: the ``[control table]`` section of
  ``dynamixel_easy_sdk/control_table/<model>.model`` in the installed ``dynamixel-sdk`` wheel
  (the same files ``dynamixel_easy_sdk.control_table.ControlTable`` parses). Not retyped here.
* **Model number**: ``dynamixel_easy_sdk/control_table/dynamixel.model`` (number -> file name).
* **Signedness**: the ``[unit info]`` "Sign Type" column where present, plus the X-series
  e-Manual for the items it does not list (offsets, goals, present values, trajectories).
* **EEPROM end, read-only items, defaults, ranges, operating modes, baud rates, units,
  indirect blocks, power-on position**: one family table each (X430/540, X330, MX 2.0,
  P-series, PRO(A), XL-320), typed from the family's e-Manual reference page, plus per-model
  overrides typed from that model's own page (:data:`_MODEL_OVERRIDES`, each with its page).
  Two X330 items the .model files omit (Startup Configuration, Backup Ready) are added.
* **Table end**: the last item of the .model file or the end of the last indirect data block.

Layout of a ``.model`` file (tab-separated)::

    [type info]        name / value rows (radian conversion)
    [unit info]        Data Name / value / unit / Sign Type
    [control table]    Address / Size / Data Name
"""

from __future__ import annotations

import dataclasses
import functools
import importlib.util
from dataclasses import dataclass, field
from pathlib import Path

from firmware_protocol.dynamixel import tables_protocol1
from firmware_protocol.dynamixel.table_model import (
    BAUD_RATES,
    EEPROM_END,
    OPERATING_MODES,
    READ_ONLY,
    SIGNED,
    ControlItem,
    ControlTable,
    IndirectBlock,
    ServoUnits,
    model_display_name,
    model_key,
)

__all__ = ["BAUD_RATES", "EEPROM_END", "OPERATING_MODES", "READ_ONLY", "SIGNED", "ControlItem",
           "ControlTable", "IndirectBlock", "ServoUnits", "available_models",
           "load_control_table", "model_display_name", "model_key", "model_numbers"]

_X_DEFAULTS = {
    "ID": 1, "Baud Rate": 1, "Return Delay Time": 250, "Drive Mode": 0, "Operating Mode": 3,
    "Secondary(Shadow) ID": 255, "Protocol Type": 2, "Homing Offset": 0,
    "Moving Threshold": 10, "Temperature Limit": 80, "Max Voltage Limit": 160,
    "Min Voltage Limit": 95, "PWM Limit": 885, "Current Limit": 1193, "Velocity Limit": 200,
    "Max Position Limit": 4095, "Min Position Limit": 0, "Shutdown": 52, "Torque Enable": 0,
    "LED": 0, "Status Return Level": 2, "Velocity I Gain": 1920, "Velocity P Gain": 100,
    "Position D Gain": 0, "Position I Gain": 0, "Position P Gain": 800, "Bus Watchdog": 0,
    "Profile Acceleration": 0, "Profile Velocity": 0, "Present Input Voltage": 120,
    "Present Temperature": 30, "Firmware Version": 48, "PWM Slope": 140,
    "Feedforward 1st Gain": 0, "Feedforward 2nd Gain": 0, "Acceleration Limit": 32767,
    "Startup Configuration": 0,
}
"""X430/X540 family, from emanual.robotis.com/docs/en/dxl/x/xm430-w350/ (Control Table of
EEPROM / RAM Area, "Default Value" column)."""

_X_RANGES = {
    "ID": (0, 252), "Baud Rate": (0, 7), "Return Delay Time": (0, 254), "Drive Mode": (0, 13),
    "Secondary(Shadow) ID": (0, 255), "Protocol Type": (1, 2),
    "Homing Offset": (-1_044_479, 1_044_479), "Moving Threshold": (0, 1023),
    "Temperature Limit": (0, 100), "Max Voltage Limit": (95, 160),
    "Min Voltage Limit": (95, 160), "PWM Limit": (0, 885), "Current Limit": (0, 1193),
    "Velocity Limit": (0, 1023), "Acceleration Limit": (0, 32767),
    "Max Position Limit": (0, 4095), "Min Position Limit": (0, 4095), "Torque Enable": (0, 1),
    "LED": (0, 1), "Status Return Level": (0, 2), "Profile Acceleration": (0, 32767),
    "Profile Velocity": (0, 32767), "Goal Position": (-1_048_575, 1_048_575),
    "Velocity I Gain": (0, 16383), "Velocity P Gain": (0, 16383), "Position D Gain": (0, 16383),
    "Position I Gain": (0, 16383), "Position P Gain": (0, 16383),
    "Feedforward 1st Gain": (0, 16383), "Feedforward 2nd Gain": (0, 16383),
    "Bus Watchdog": (0, 127), "PWM Slope": (1, 255), "Startup Configuration": (0, 3),
}
"""X-series ranges (xm430-w350 page "Range" column). Secondary ID: 0..252 names a secondary
ID, 253..255 switch it off (255 the default), so the writable range is 0..255. Goal Position:
the extended-position range; position mode clamps to the position limits. Goal PWM / Current /
Velocity are bounded by their limit items (a Data Limit error), not by a fixed range."""

_X330_DEFAULTS = {**_X_DEFAULTS, "Temperature Limit": 70, "Max Voltage Limit": 70,
                  "Min Voltage Limit": 35, "Current Limit": 1750, "Velocity Limit": 445,
                  "Velocity I Gain": 1600, "Velocity P Gain": 180, "Position P Gain": 400,
                  "Shutdown": 53, "Present Input Voltage": 50, "Firmware Version": 46}
"""XL330 / XC330 (5 V), from emanual.robotis.com/docs/en/dxl/x/xl330-m288/ (and xc330-m288).
Firmware Version 46 goes with the SDK's pre-v52 layout (indirect data at 224); the
``*_fw52`` tables report 52."""

_X330_RANGES = {**_X_RANGES, "Baud Rate": (0, 6), "Protocol Type": (2, 22),
                "Max Voltage Limit": (31, 70), "Min Voltage Limit": (31, 70),
                "Current Limit": (0, 1750), "Velocity Limit": (0, 2047)}
"""xl330-m288 page: baud up to 4 Mbit/s (value 6), Protocol Type 2 (DYNAMIXEL 2.0) to 22,
Velocity Limit 0..2,047."""

_MX2_DEFAULTS = {**_X_DEFAULTS, "Velocity Limit": 380, "Position P Gain": 850,
                 "Firmware Version": 46}
"""MX-28/64/106 on Protocol 2.0 firmware, from emanual.robotis.com/docs/en/dxl/mx/mx-28-2/
(Velocity Limit 380, Acceleration Limit 32,767, Position P Gain 850)."""

_P_DEFAULTS = {
    "ID": 1, "Baud Rate": 1, "Return Delay Time": 250, "Drive Mode": 0, "Operating Mode": 3,
    "Secondary ID": 255, "Protocol Type": 2, "Homing Offset": 0, "Moving Threshold": 20,
    "Temperature Limit": 80, "Max Voltage Limit": 350, "Min Voltage Limit": 150,
    "PWM Limit": 2009, "Current Limit": 22740, "Acceleration Limit": 3_992_644,
    "Velocity Limit": 2900, "Max Position Limit": 501_433, "Min Position Limit": -501_433,
    "External Port Mode 1": 3, "External Port Mode 2": 3, "External Port Mode 3": 3,
    "External Port Mode 4": 3, "Startup Configuration": 0, "Shutdown": 52, "Torque Enable": 0,
    "LED Red": 0, "LED Green": 0, "LED Blue": 0, "Status Return Level": 2,
    "Velocity I Gain": 2209, "Velocity P Gain": 6153, "Position D Gain": 0,
    "Position I Gain": 0, "Position P Gain": 314, "Feedforward 1st Gain": 0,
    "Feedforward 2nd Gain": 0, "Bus Watchdog": 0, "Profile Acceleration": 0,
    "Profile Velocity": 0, "Present Input Voltage": 240, "Present Temperature": 30,
    "Firmware Version": 12,
}
"""P-series, from emanual.robotis.com/docs/en/dxl/p/ph54-200-s500-r/ (PH54-200-S500-R); other
models override what their page gives differently (:data:`_MODEL_OVERRIDES`)."""

_P_RANGES = {
    "ID": (0, 252), "Baud Rate": (0, 9), "Return Delay Time": (0, 254), "Drive Mode": (0, 13),
    "Secondary ID": (0, 255), "Protocol Type": (2, 10),
    "Homing Offset": (-2_147_483_648, 2_147_483_647), "Moving Threshold": (0, 2900),
    "Temperature Limit": (0, 100), "Max Voltage Limit": (150, 350),
    "Min Voltage Limit": (150, 350), "PWM Limit": (0, 2009), "Current Limit": (0, 22740),
    "Acceleration Limit": (0, 3_992_644), "Velocity Limit": (0, 2900),
    "Max Position Limit": (-501_923, 501_923), "Min Position Limit": (-501_923, 501_923),
    "External Port Mode 1": (0, 3), "External Port Mode 2": (0, 3),
    "External Port Mode 3": (0, 3), "External Port Mode 4": (0, 3),
    "Startup Configuration": (0, 3), "Shutdown": (0, 63), "Torque Enable": (0, 1),
    "LED Red": (0, 255), "LED Green": (0, 255), "LED Blue": (0, 255),
    "Status Return Level": (0, 2), "Velocity I Gain": (0, 32767),
    "Velocity P Gain": (0, 32767), "Position D Gain": (0, 32767),
    "Position I Gain": (0, 32767), "Position P Gain": (0, 32767),
    "Feedforward 1st Gain": (0, 32767), "Feedforward 2nd Gain": (0, 32767),
    "Bus Watchdog": (0, 127), "Profile Acceleration": (0, 3_992_644),
    "Profile Velocity": (0, 2900), "Goal Position": (-2**31, 2**31 - 1),
}
"""ph54-200-s500-r page "Range" column; Goal Position: the int32 range of Extended Position
Control Mode (`_includes/en/dxl/p/control_table_564_goal_position.md`: in Position Control
Mode it must lie within Min/Max Position Limit — a Data Limit Error beyond, the servo model's
rule). Protocol Type holds 2 (DYNAMIXEL 2.0) or 10 (Modbus);
the range check is 2..10. Profile Acceleration / Velocity are bounded by the Acceleration /
Velocity Limit, typed here as each model's maximum."""

_PRO_A_DEFAULTS = {k: v for k, v in _P_DEFAULTS.items()
                   if k not in ("Protocol Type", "Startup Configuration")}
_PRO_A_DEFAULTS.update({"Acceleration Limit": 9982})
"""PRO(A) (Advanced firmware of DYNAMIXEL PRO), from
emanual.robotis.com/docs/en/dxl/pro/h54-200-s500-ra/: the P-series table without Protocol Type
and Startup Configuration, Acceleration Limit 9,982 by default."""

_PRO_A_RANGES = {**{k: v for k, v in _P_RANGES.items()
                    if k not in ("Protocol Type", "Startup Configuration")},
                 "Return Delay Time": (0, 255), "Shutdown": (0, 255)}

_XL320_DEFAULTS = {
    "ID": 1, "Baud Rate": 3, "Return Delay Time": 250, "CW Angle Limit": 0,
    "CCW Angle Limit": 1023, "Control Mode": 2, "Temperature Limit": 65,
    "Min Voltage Limit": 60, "Max Voltage Limit": 90, "Max Torque": 1023,
    "Status Return Level": 2, "Shutdown": 3, "Torque Enable": 0, "LED": 0, "D Gain": 0,
    "I Gain": 0, "P Gain": 32, "Moving Speed": 0, "Torque Limit": 1023, "Punch": 32,
    "Present Voltage": 74, "Present Temperature": 30, "Firmware Version": 29,
}
"""XL-320 (Protocol 2.0), from emanual.robotis.com/docs/en/dxl/x/xl320/. Torque Limit starts as
a copy of Max Torque (the e-Manual leaves its initial value "-")."""

_XL320_RANGES = {
    "ID": (0, 252), "Baud Rate": (0, 3), "Return Delay Time": (0, 254),
    "CW Angle Limit": (0, 1023), "CCW Angle Limit": (0, 1023), "Control Mode": (1, 2),
    "Temperature Limit": (0, 150), "Min Voltage Limit": (50, 250),
    "Max Voltage Limit": (50, 250), "Max Torque": (0, 1023), "Status Return Level": (0, 2),
    "Shutdown": (0, 7), "Torque Enable": (0, 1), "LED": (0, 7), "D Gain": (0, 254),
    "I Gain": (0, 254), "P Gain": (0, 254), "Goal Position": (0, 1023),
    "Moving Speed": (0, 2047), "Torque Limit": (0, 1023), "Punch": (0, 1023),
}

_XL320_ROLES = {
    "Operating Mode": "Control Mode", "Min Position Limit": "CW Angle Limit",
    "Max Position Limit": "CCW Angle Limit", "Present Velocity": "Present Speed",
    "Present Input Voltage": "Present Voltage", "Goal Velocity": "Moving Speed",
    "Profile Velocity": "Moving Speed", "PWM Limit": "Max Torque", "Goal PWM": "Torque Limit",
    "Position P Gain": "P Gain", "Position I Gain": "I Gain", "Position D Gain": "D Gain",
}
"""X-series item -> XL-320 item. Moving Speed is the speed to the goal in joint mode (the role
of Profile Velocity) and the signed-magnitude speed in wheel mode (Goal Velocity); Max Torque
and Torque Limit bound the output as PWM Limit and Goal PWM do. No Velocity Limit, Current
items, Homing Offset, Drive Mode, Secondary ID, Bus Watchdog or Profile Acceleration."""

_P_ROLES = {"Secondary(Shadow) ID": "Secondary ID", "LED": "LED Red"}
_X_ROLES = {"Secondary ID": "Secondary(Shadow) ID", "Bus Watchdog": "BUS Watchdog"}

_X_READ_ONLY = READ_ONLY
_P_READ_ONLY = READ_ONLY
_XL320_READ_ONLY = frozenset({
    "Model Number", "Firmware Version", "Present Position", "Present Speed", "Present Load",
    "Present Voltage", "Present Temperature", "Registered Instruction", "Moving",
    "Hardware Error Status",
})
"""Items marked "R" on the xl320 page."""

_P_BAUD_RATES = {**BAUD_RATES, 8: 6_000_000, 9: 10_500_000}
"""P-series / PRO(A) Baud Rate values (e-Manual p/ "Baud Rate(8)": up to 10.5 Mbit/s)."""

_X330_BAUD_RATES = {k: v for k, v in BAUD_RATES.items() if k <= 6}
_XL320_BAUD_RATES = {0: 9600, 1: 57600, 2: 115200, 3: 1_000_000}

_NO_CURRENT_MODE = frozenset({1, 3, 4, 16})
_P_MODES = frozenset({0, 1, 3, 4, 16})

_EXTRA_ITEMS = {
    "x330": ((60, 1, "Startup Configuration"), (147, 1, "Backup Ready")),
}
"""Items the e-Manual page lists and the SDK's .model file leaves out (xl330-m288 page:
Startup Configuration 60, Backup Ready 147)."""


@dataclass(frozen=True)
class _Family:
    defaults: dict
    ranges: dict
    modes: frozenset
    baud_rates: dict
    units: ServoUnits
    eeprom_end: int = EEPROM_END
    read_only: frozenset = READ_ONLY
    roles: dict = field(default_factory=dict)
    home_ticks: float = 2048.0
    second_block: tuple[int, int] | None = None  # (address start, data start) of slots 29..56
    slots: int | None = None  # first block's slot count when not (data - address) / 2


_FAMILIES = {
    "x430": _Family(_X_DEFAULTS, _X_RANGES, OPERATING_MODES, BAUD_RATES, ServoUnits(),
                    roles=_X_ROLES, second_block=(578, 634)),
    "x330": _Family(_X330_DEFAULTS, _X330_RANGES, OPERATING_MODES, _X330_BAUD_RATES,
                    ServoUnits(current_ma=1.0, stall_torque_nm=0.52, stall_current_a=1.47,
                               no_load_rpm=103.0), roles=_X_ROLES),
    "mx2": _Family(_MX2_DEFAULTS, _X_RANGES, OPERATING_MODES, BAUD_RATES,
                   ServoUnits(current_ma=3.36, stall_torque_nm=2.5, stall_current_a=1.4,
                              no_load_rpm=55.0), roles=_X_ROLES, second_block=(578, 634)),
    "p": _Family(_P_DEFAULTS, _P_RANGES, _P_MODES, _P_BAUD_RATES,
                 ServoUnits(ticks_per_rev=1_003_846.0, velocity_rpm=0.01, accel_rpm2=1.0,
                            current_ma=1.0, pwm_max=2009, stall_torque_nm=44.7,
                            stall_current_a=9.3, no_load_rpm=33.1),
                 eeprom_end=512, roles=_P_ROLES, home_ticks=0.0, slots=128),
    "pro_a": _Family(_PRO_A_DEFAULTS, _PRO_A_RANGES, _P_MODES, _P_BAUD_RATES,
                     ServoUnits(ticks_per_rev=1_003_846.0, velocity_rpm=0.01, accel_rpm2=1.0,
                                current_ma=1.0, pwm_max=2009, stall_torque_nm=44.7,
                                stall_current_a=9.3, no_load_rpm=33.1),
                     eeprom_end=512, roles=_P_ROLES, home_ticks=0.0, slots=128),
    "xl320": _Family(_XL320_DEFAULTS, _XL320_RANGES, frozenset({1, 2}), _XL320_BAUD_RATES,
                     ServoUnits(ticks_per_rev=1228.8, velocity_rpm=0.111, accel_rpm2=0.0,
                                current_ma=None, pwm_max=1023, stall_torque_nm=0.39,
                                stall_current_a=1.1, no_load_rpm=114.0),
                     eeprom_end=24, read_only=_XL320_READ_ONLY, roles=_XL320_ROLES,
                     home_ticks=512.0),
}
"""Family tables. P-series / PRO(A) motor constants: their pages give continuous (not stall)
torque and current; those stand in for the torque model's stall figures."""


def _family_of(key: str) -> str:
    base = key.removesuffix("_fw52")
    if base == "xl320":
        return "xl320"
    if base.startswith(("xl330", "xc330")):
        return "x330"
    if base.startswith("mx_"):
        return "mx2"
    if base.startswith(("ph", "pm")):
        return "p"
    if base[:1] in ("h", "m") and base.endswith("_ra"):
        return "pro_a"
    return "x430"


def _p(ticks_half: int, limit: int, velocity: int, current: int, accel: int,
       accel_max: int, torque: float, amps: float, rpm: float, **more: int) -> dict:
    """Per-model P-series / PRO(A) values: position range ±ticks_half (also the .model's
    value_of_max_radian_position), default position limits ±limit, Velocity Limit, Current
    Limit, Acceleration Limit default and maximum, continuous torque / current, no-load speed."""
    return {"defaults": {"Max Position Limit": limit, "Min Position Limit": -limit,
                         "Velocity Limit": velocity, "Current Limit": current,
                         "Acceleration Limit": accel, **more},
            "ranges": {"Max Position Limit": (-ticks_half, ticks_half),
                       "Min Position Limit": (-ticks_half, ticks_half),
                       "Velocity Limit": (0, velocity), "Moving Threshold": (0, velocity),
                       "Profile Velocity": (0, velocity), "Current Limit": (0, current),
                       "Acceleration Limit": (0, accel_max),
                       "Profile Acceleration": (0, accel_max)},
            "units": {"ticks_per_rev": 2.0 * ticks_half, "stall_torque_nm": torque,
                      "stall_current_a": amps, "no_load_rpm": rpm}}


def _x(defaults: dict | None = None, ranges: dict | None = None, **units: float) -> dict:
    return {"defaults": defaults or {}, "ranges": ranges or {}, "units": units}


_NO_CURRENT = {"current_ma": None}
_MODEL_OVERRIDES: dict[str, dict] = {
    # X series -------------------------------------------------------------------------------
    # xm430-w350 page: the family defaults; motor constants at 12 V (4.1 N·m, 2.3 A, 46 rpm)
    "xm430_w350": _x(),
    # xl430-w250 / 2xl430-w250 pages: 72 °C, 6.0..14.0 V, Velocity Limit 265, no current
    # sensing (Present Load), 1.4 N·m / 1.3 A / 57 rpm at 11.1 V
    "xl430_w250": _x({"Temperature Limit": 72, "Max Voltage Limit": 140,
                      "Min Voltage Limit": 60, "Velocity Limit": 265, "Position P Gain": 640,
                      "Velocity I Gain": 1000, "Present Input Voltage": 111},
                     {"Max Voltage Limit": (60, 140), "Min Voltage Limit": (60, 140)},
                     stall_torque_nm=1.4, stall_current_a=1.3, no_load_rpm=57.0, **_NO_CURRENT),
    # xl330-m288 page: the x330 family values; 0.52 N·m / 1.47 A / 103 rpm at 5 V
    "xl330_m288": _x(),
    # xl330-m077 page: 0.215 N·m / 1.47 A / 383 rpm at 5 V
    "xl330_m077": _x(stall_torque_nm=0.215, stall_current_a=1.47, no_load_rpm=383.0),
    # xc330-m288 page: 0.93 N·m / 1.80 A / 81 rpm at 5 V
    "xc330_m288": _x(stall_torque_nm=0.93, stall_current_a=1.80, no_load_rpm=81.0),
    # Pages read from the e-Manual's source, github.com/ROBOTIS-GIT/emanual (file @ commit);
    # motor constants from its _data/dxl_x_info.yml @00280385 (bold = nominal voltage).
    # xm430-w210: docs/en/dxl/x/xm430-w210.md @8bb7656a: Velocity Limit 330; 3.0 N·m, 2.3 A,
    # 77 rpm at 12 V
    "xm430_w210": _x({"Velocity Limit": 330}, stall_torque_nm=3.0, stall_current_a=2.3,
                     no_load_rpm=77.0),
    # xh430-w210.md @1cf2abe6: Current Limit 648, Velocity Limit 210, Position P Gain 900;
    # 2.5 N·m, 1.3 A, 50 rpm at 12 V
    "xh430_w210": _x({"Current Limit": 648, "Velocity Limit": 210, "Position P Gain": 900},
                     stall_torque_nm=2.5, stall_current_a=1.3, no_load_rpm=50.0),
    # xh430-w350.md @6aca77e9: Current Limit 648, Velocity Limit 130, Position P Gain 900;
    # 3.4 N·m, 1.3 A, 30 rpm at 12 V
    "xh430_w350": _x({"Current Limit": 648, "Velocity Limit": 130, "Position P Gain": 900},
                     stall_torque_nm=3.4, stall_current_a=1.3, no_load_rpm=30.0),
    # xh430-v210.md @b6bee155 (the page's older layout, no Range column): 24 V model, Max / Min
    # Voltage Limit 300 / 110, Current Limit 689 in 1.34 mA, Velocity Limit 380; 2.6 N·m,
    # 0.7 A, 52 rpm at 24 V. The voltage range 110 ~ 300 is xh430-v350's.
    "xh430_v210": _x({"Max Voltage Limit": 300, "Min Voltage Limit": 110, "Current Limit": 689,
                      "Velocity Limit": 380, "Present Input Voltage": 240},
                     {"Max Voltage Limit": (110, 300), "Min Voltage Limit": (110, 300)},
                     current_ma=1.34, stall_torque_nm=2.6, stall_current_a=0.7,
                     no_load_rpm=52.0),
    # xh430-v350.md @6058d277: Voltage Limits 110 ~ 300 (300 / 110), Current Limit 689 in
    # 1.34 mA, Velocity Limit 135; 3.3 N·m, 0.7 A, 31 rpm at 24 V
    "xh430_v350": _x({"Max Voltage Limit": 300, "Min Voltage Limit": 110, "Current Limit": 689,
                      "Velocity Limit": 135, "Present Input Voltage": 240},
                     {"Max Voltage Limit": (110, 300), "Min Voltage Limit": (110, 300)},
                     current_ma=1.34, stall_torque_nm=3.3, stall_current_a=0.7,
                     no_load_rpm=31.0),
    # xd430-t210.md / xd430-t350.md @a75ff4a3: the XH430-W210 / -W350 tables ("control tables
    # are identical"); their motor constants are not in dxl_x_info.yml @00280385 (unchecked)
    "xd430_t210": _x({"Current Limit": 648, "Velocity Limit": 210, "Position P Gain": 900}),
    "xd430_t350": _x({"Current Limit": 648, "Velocity Limit": 130, "Position P Gain": 900}),
    # xc430-w150.md @e187952c: Voltage Limits 60 ~ 160 (160 / 60), Velocity Limit 460,
    # Position P Gain 460, no current sensing; 1.6 N·m, 1.4 A, 106 rpm at 12 V
    "xc430_w150": _x({"Min Voltage Limit": 60, "Velocity Limit": 460, "Position P Gain": 460},
                     {"Max Voltage Limit": (60, 160), "Min Voltage Limit": (60, 160)},
                     stall_torque_nm=1.6, stall_current_a=1.4, no_load_rpm=106.0,
                     **_NO_CURRENT),
    # xc430-w240.md @d33bc5f9: Voltage Limits 60 ~ 160, Velocity Limit 306, Position P Gain
    # 700; 1.9 N·m, 1.4 A, 70 rpm at 12 V
    "xc430_w240": _x({"Min Voltage Limit": 60, "Velocity Limit": 306, "Position P Gain": 700},
                     {"Max Voltage Limit": (60, 160), "Min Voltage Limit": (60, 160)},
                     stall_torque_nm=1.9, stall_current_a=1.4, no_load_rpm=70.0,
                     **_NO_CURRENT),
    # 2xl430-w250.md @4103eaba: 72 °C, Voltage Limits 60 ~ 140 (140 / 60), Velocity Limit 250,
    # Velocity I Gain 1,800, Position D / P Gain 2,000 / 640; 1.4 N·m, 1.3 A, 57 rpm at 11.1 V
    "2xl430_w250": _x({"Temperature Limit": 72, "Max Voltage Limit": 140,
                       "Min Voltage Limit": 60, "Velocity Limit": 250, "Velocity I Gain": 1800,
                       "Position D Gain": 2000, "Position P Gain": 640,
                       "Present Input Voltage": 111},
                      {"Max Voltage Limit": (60, 140), "Min Voltage Limit": (60, 140)},
                      stall_torque_nm=1.4, stall_current_a=1.3, no_load_rpm=57.0,
                      **_NO_CURRENT),
    # 2xc430-w250.md @2a91568e: Voltage Limits 60 ~ 160 (160 / 60), Velocity Limit 275,
    # Position P Gain 700; 1.8 N·m, 1.4 A, 64 rpm at 12 V
    "2xc430_w250": _x({"Min Voltage Limit": 60, "Velocity Limit": 275, "Position P Gain": 700},
                      {"Max Voltage Limit": (60, 160), "Min Voltage Limit": (60, 160)},
                      stall_torque_nm=1.8, stall_current_a=1.4, no_load_rpm=64.0,
                      **_NO_CURRENT),
    # xm540-w150.md @486d85b1 (older layout): Current Limit 2,047, Velocity Limit 380;
    # 7.3 N·m, 4.4 A, 53 rpm at 12 V
    "xm540_w150": _x({"Current Limit": 2047, "Velocity Limit": 380},
                     stall_torque_nm=7.3, stall_current_a=4.4, no_load_rpm=53.0),
    # xm540-w270.md @7d10aced: Current Limit 2,047, Velocity Limit 128; 10.6 N·m, 4.4 A,
    # 30 rpm at 12 V
    "xm540_w270": _x({"Current Limit": 2047, "Velocity Limit": 128},
                     stall_torque_nm=10.6, stall_current_a=4.4, no_load_rpm=30.0),
    # X540 models whose control-table page was not read: motor constants only
    # (dxl_x_info.yml @00280385); Current / Velocity Limit etc. stay the family's (unchecked)
    "xh540_w150": _x(stall_torque_nm=7.1, stall_current_a=4.9, no_load_rpm=70.0),
    "xh540_w270": _x(stall_torque_nm=9.9, stall_current_a=4.9, no_load_rpm=39.0),
    "xh540_v150": _x(stall_torque_nm=6.4, stall_current_a=2.4, no_load_rpm=60.0),  # 24 V
    "xh540_v270": _x(stall_torque_nm=9.2, stall_current_a=2.4, no_load_rpm=34.0),  # 24 V
    "xw540_t140": _x(stall_torque_nm=6.9, stall_current_a=4.9, no_load_rpm=72.0),
    "xw540_t260": _x(stall_torque_nm=9.5, stall_current_a=4.9, no_load_rpm=40.0),
    # XC330 models whose control-table page was not read: motor constants only
    # (dxl_x_info.yml @00280385); the T models are 11.1 V servos (6.5 ~ 12.0 V input), so
    # the family's 5 V voltage limits are certainly not theirs (unchecked)
    "xc330_m181": _x(stall_torque_nm=0.60, stall_current_a=1.80, no_load_rpm=129.0),
    "xc330_t181": _x(stall_torque_nm=0.76, stall_current_a=0.80, no_load_rpm=104.0),
    "xc330_t288": _x(stall_torque_nm=0.92, stall_current_a=0.80, no_load_rpm=65.0),
    # MX (2.0) -------------------------------------------------------------------------------
    # mx-28-2 page: no current sensing (Present Load), no current mode; 2.5 N·m / 1.4 A /
    # 55 rpm at 12 V
    "mx_28": _x(**_NO_CURRENT),
    # mx-64-2.md @1b03e234: Current Limit 1,941 (3.36 mA), Velocity Limit 435, Position P Gain
    # 850; 6.0 N·m, 4.1 A, 63 rpm at 12 V (also _data/dxl_mx_info.yml @5d02e95a)
    "mx_64": _x({"Current Limit": 1941, "Velocity Limit": 435},
                stall_torque_nm=6.0, stall_current_a=4.1, no_load_rpm=63.0),
    # mx-106-2.md @79c049e3: Current Limit 2,047, Velocity Limit 360, Position P Gain 850;
    # 8.4 N·m, 5.2 A, 45 rpm at 12 V
    "mx_106": _x({"Current Limit": 2047, "Velocity Limit": 360},
                 stall_torque_nm=8.4, stall_current_a=5.2, no_load_rpm=45.0),
    # P-series -------------------------------------------------------------------------------
    # ph54-200-s500-r page: the p family values
    "ph54_200_s500": _p(501_923, 501_433, 2900, 22740, 3_992_644, 3_992_644, 44.7, 9.3, 33.1),
    # ph42-020-s300-r page: ±303,750 (607,500 pulse/rev), limits ±303,454, 2,920 ×0.01 rpm,
    # 4,500 mA, Acceleration Limit 10,765 (max 4,306,173), Shutdown 58; 5.1 N·m, 1.5 A, 32.7 rpm
    "ph42_020_s300": _p(303_750, 303_454, 2920, 4500, 10_765, 4_306_173, 5.1, 1.5, 32.7,
                        Shutdown=58),
    # pm54-060-s250-r page: ±251,417 (502,834 pulse/rev), limits ±251,173, 2,830 ×0.01 rpm,
    # 7,980 mA, Acceleration Limit 11,145 (max 4,457,932), Shutdown 58
    "pm54_060_s250": _p(251_417, 251_173, 2830, 7980, 11_145, 4_457_932, 10.1, 3.0, 33.1,
                        Shutdown=58),
    # PRO(A) ---------------------------------------------------------------------------------
    # h54-200-s500-ra page: the pro_a family values
    "h54_200_s500_ra": _p(501_923, 501_433, 2900, 22740, 9982, 3_992_644, 44.7, 9.3, 33.1),
    # m42-10-s260-ra page: ±263,187 (526,375 pulse/rev), limits ±262,931, 2,600 ×0.01 rpm,
    # 1,461 mA, Acceleration Limit 10,867 (max 4,346,756); 1.7 N·m, 0.6 A, 28.0 rpm
    "m42_10_s260_ra": _p(263_187, 262_931, 2600, 1461, 10_867, 4_346_756, 1.7, 0.6, 28.0),
}
"""Per-model values typed from each model's own e-Manual page (the comment names it). Models
absent here take their family's values: see ``docs/sim.md`` for which pages are not yet
checked model by model."""

def _data_dir() -> Path:
    spec = importlib.util.find_spec("dynamixel_easy_sdk")
    if spec is None or not spec.submodule_search_locations:
        raise FileNotFoundError("dynamixel_easy_sdk (part of dynamixel-sdk >= 4) is not installed; "
                                "its control_table/*.model files are needed")
    return Path(next(iter(spec.submodule_search_locations))) / "control_table"


@functools.lru_cache(maxsize=1)
def model_numbers() -> dict[str, int]:
    """File stem -> model number, from the SDK's ``dynamixel.model``."""
    path = _data_dir() / "dynamixel.model"
    out: dict[str, int] = {}
    for line in path.read_text(encoding="utf-8").splitlines()[1:]:
        parts = line.strip().split("\t")
        if len(parts) >= 2 and parts[0].isdigit():
            out[model_key(parts[1])] = int(parts[0])
    for path in sorted(_data_dir().glob("*_fw52.model")):  # same servo, firmware v52 layout
        base = path.stem.removesuffix("_fw52")
        if base in out:
            out[path.stem] = out[base]
    return out


def available_models() -> list[str]:
    """e-Manual names of every model the SDK ships a table for."""
    return sorted(model_display_name(k) for k in model_numbers())


def _parse_model_file(text: str) -> tuple[list[tuple[int, int, str]], set[str]]:
    section = ""
    rows: list[tuple[int, int, str]] = []
    signed: set[str] = set()
    header_skipped = False
    for raw in text.splitlines():
        line = raw.strip()
        if not line:
            continue
        if line.startswith("[") and line.endswith("]"):
            section, header_skipped = line[1:-1], False
            continue
        if not header_skipped:  # the column-title row after each section header
            header_skipped = True
            continue
        parts = line.split("\t")
        if section == "control table" and len(parts) >= 3:
            rows.append((int(parts[0]), int(parts[1]), parts[2].strip()))
        elif section == "unit info" and len(parts) >= 4 and parts[3].strip() == "signed":
            signed.add(parts[0].strip())
    return rows, signed


@functools.cache
def load_control_table(model: str | int, protocol: float | None = None) -> ControlTable:
    """Load the control table of ``model`` from the SDK's data files.

    Parameters
    ----------
    model : str or int
        e-Manual name (``"XM430-W350"``), file stem (``"xc330_m288"``) or model number (1020).
    protocol : float, optional
        1.0: the model's Protocol 1.0 table (AX-12A, AX-18A, MX-28 on 1.0 firmware: typed from
        the e-Manual in :mod:`firmware_protocol.dynamixel.tables_protocol1`; an X-series model
        keeps its table, switched by its Protocol Type item). None or 2.0: the SDK's table.

    Returns
    -------
    ControlTable

    Raises
    ------
    ValueError
        Unknown model (the message lists the known ones).
    """
    if protocol is not None and float(protocol) == 1.0:
        table = tables_protocol1.load(model)
        if table is not None:
            return table
    numbers = model_numbers()
    if (isinstance(model, int) and model not in numbers.values()) or \
            (isinstance(model, str) and model_key(model) not in numbers):
        # a model the SDK has no table for may be a Protocol 1.0 one (AX-12A, model 29, ...)
        table = tables_protocol1.load(model)
        if table is not None:
            return table
    if isinstance(model, int):
        by_number = {v: k for k, v in numbers.items() if not k.endswith("_fw52")}
        if model not in by_number:
            raise ValueError(f"unknown Dynamixel model number {model}")
        key = by_number[model]
    else:
        key = model_key(model)
        if key not in numbers:
            raise ValueError(f"unknown Dynamixel model {model!r}; known models: "
                             f"{', '.join(available_models())}")
    return _build(key, numbers[key])


def _build(key: str, number: int) -> ControlTable:
    path = _data_dir() / f"{key}.model"
    rows, signed = _parse_model_file(path.read_text(encoding="utf-8"))
    if not rows:
        raise ValueError(f"{path}: no [control table] section")
    name = _family_of(key)
    fam = _FAMILIES[name]
    known = {n for _, _, n in rows}
    rows += [r for r in _EXTRA_ITEMS.get(name, ()) if r[2] not in known]
    read_only = fam.read_only | {"Backup Ready", "Model Information"}
    items: dict[str, ControlItem] = {}
    for address, size, item_name in rows:
        items[item_name] = ControlItem(
            name=item_name, address=address, size=size, writable=item_name not in read_only,
            eeprom=address < fam.eeprom_end, signed=item_name in signed or item_name in SIGNED)
    size = max(a + s for a, s, _ in rows)
    indirect: list[IndirectBlock] = []
    if "Indirect Address 1" in items and "Indirect Data 1" in items:
        # the first block's slots run from Indirect Address 1 up to Indirect Data 1
        start, data = items["Indirect Address 1"].address, items["Indirect Data 1"].address
        indirect.append(IndirectBlock(start, data, fam.slots or (data - start) // 2))
        if fam.second_block is not None:
            start, data = fam.second_block
            indirect.append(IndirectBlock(start, data, (data - start) // 2))
    for block in indirect:
        size = max(size, block.data_start + block.count)
    override = _MODEL_OVERRIDES.get(key.removesuffix("_fw52"), {})
    defaults = {**fam.defaults, **override.get("defaults", {})}
    if key.endswith("_fw52"):
        defaults["Firmware Version"] = 52
    defaults["Model Number"] = number
    if "PWM Limit" in defaults:
        defaults["Goal PWM"] = defaults["PWM Limit"]
    if "Current Limit" in defaults:
        defaults["Goal Current"] = defaults["Current Limit"]
    def own(name: str) -> str:  # the family's spelling -> this model's (MX "BUS Watchdog")
        return name if name in items else fam.roles.get(name, name)

    defaults = {own(k): v for k, v in defaults.items() if own(k) in items}
    ranges = {**fam.ranges, **override.get("ranges", {})}
    if "Current Limit" in defaults:  # e-Manual: 0 ~ the model's own default
        ranges["Current Limit"] = (0, defaults["Current Limit"])
    ranges = {own(k): v for k, v in ranges.items() if own(k) in items}
    for name, (lo, _) in ranges.items():  # a range with negatives: a two's-complement item
        if lo < 0 and not items[name].signed:  # (P-series Min/Max Position Limit)
            items[name] = dataclasses.replace(items[name], signed=True)
    unit_values = override.get("units", {})
    if "Present Current" not in items:  # no current sensing: Present Load instead
        unit_values = {**unit_values, "current_ma": None}
    units = dataclasses.replace(fam.units, **unit_values) if unit_values else fam.units
    modes = fam.modes
    if "Goal Current" not in items:  # no current control: no current / current-based modes
        modes = modes - {0, 5}
    return ControlTable(model=key, model_number=number, items=items, size=size,
                        defaults=defaults, ranges=ranges, source=path, protocol=2.0,
                        eeprom_end=fam.eeprom_end, baud_rates=dict(fam.baud_rates),
                        operating_modes=frozenset(modes),
                        read_only=frozenset(read_only & set(items)),
                        units=units, roles=dict(fam.roles), indirect=tuple(indirect),
                        home_ticks=fam.home_ticks, family=name)
