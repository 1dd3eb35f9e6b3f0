"""Control tables of Protocol 1.0 servos: AX-12A, AX-18A, MX-28 / MX-64 / MX-106 on 1.0 firmware.

The SDK ships no ``.model`` file for them (its ``mx_28.model`` is the 2.0 firmware's table), so
they are typed here from the e-Manual control-table pages:

* AX-12A (model 12): emanual.robotis.com/docs/en/dxl/ax/ax-12a/ "Control Table"
* AX-18A (model 18): emanual.robotis.com/docs/en/dxl/ax/ax-18a/
* MX-28 (model 29, Protocol 1.0 firmware): emanual.robotis.com/docs/en/dxl/mx/mx-28/
* MX-64 (model 310): .../dxl/mx/mx-64/; MX-106 (model 320): .../dxl/mx/mx-106/

Common rules of these pages: addresses 0-23 are EEPROM (writable only while Torque Enable is
0), 24 and above RAM; every multi-byte item is little-endian (L, H bytes); Baud Rate value n
is 2,000,000 / (n + 1) bit/s, and on the MX series 250, 251, 252 are 2.25, 2.5 and 3 Mbit/s;
Present Speed / Present Load / Moving Speed (wheel mode) are sign-magnitude, bit 10 the
direction (CCW 0, CW 1), bits 0-9 the magnitude. Joint mode vs wheel mode is chosen by the
angle limits (both 0: wheel; on the MX series both 4095: multi-turn), so
:attr:`ControlTable.operating_modes` holds the X-series Operating Mode value each corresponds
to (1 velocity/wheel, 3 position/joint, 4 extended position/multi-turn).

Units ("Specifications" of each page): AX 1024 ticks over 300° (1228.8 per turn), Moving Speed
0.111 rpm; MX 4096 ticks per turn, 0.114 rpm, Goal Acceleration 8.583 °/s² (85.83 rpm²). MX-64
and MX-106 report Current (68) as 4.5 mA × (value − 2048).
"""

from __future__ import annotations

import functools

from firmware_protocol.dynamixel.table_model import (
    ControlItem,
    ControlTable,
    ServoUnits,
    model_key,
)

__all__ = ["EEPROM_END", "MODELS", "PROTOCOL1_ONLY", "baud_rates_1", "load"]

EEPROM_END = 24
"""Addresses below this are EEPROM on every Protocol 1.0 table here."""

# (address, size, name, access, default, (min, max) or None); default None: no fixed value.
# Common head of the AX and MX tables.
_HEAD = [
    (0, 2, "Model Number", "R", None, None),
    (2, 1, "Firmware Version", "R", None, None),
    (3, 1, "ID", "RW", 1, (0, 253)),
    (4, 1, "Baud Rate", "RW", 1, (0, 254)),
    (5, 1, "Return Delay Time", "RW", 250, (0, 254)),
    (6, 2, "CW Angle Limit", "RW", 0, (0, 1023)),
    (8, 2, "CCW Angle Limit", "RW", 1023, (0, 1023)),
    (11, 1, "Temperature Limit", "RW", 70, (0, 100)),
    (12, 1, "Min Voltage Limit", "RW", 60, (50, 250)),
    (13, 1, "Max Voltage Limit", "RW", 140, (50, 250)),
    (14, 2, "Max Torque", "RW", 1023, (0, 1023)),
    (16, 1, "Status Return Level", "RW", 2, (0, 2)),
    (17, 1, "Alarm LED", "RW", 36, (0, 127)),
    (18, 1, "Shutdown", "RW", 36, (0, 127)),
    (24, 1, "Torque Enable", "RW", 0, (0, 1)),
    (25, 1, "LED", "RW", 0, (0, 1)),
]
_AX_RAM = [
    (26, 1, "CW Compliance Margin", "RW", 1, (0, 255)),
    (27, 1, "CCW Compliance Margin", "RW", 1, (0, 255)),
    (28, 1, "CW Compliance Slope", "RW", 32, None),
    (29, 1, "CCW Compliance Slope", "RW", 32, None),
    (30, 2, "Goal Position", "RW", None, (0, 1023)),
    (32, 2, "Moving Speed", "RW", None, (0, 2047)),
    (34, 2, "Torque Limit", "RW", None, (0, 1023)),
    (36, 2, "Present Position", "R", None, None),
    (38, 2, "Present Speed", "R", None, None),
    (40, 2, "Present Load", "R", None, None),
    (42, 1, "Present Voltage", "R", None, None),
    (43, 1, "Present Temperature", "R", None, None),
    (44, 1, "Registered", "R", 0, None),
    (46, 1, "Moving", "R", 0, None),
    (47, 1, "Lock", "RW", 0, (0, 1)),
    (48, 2, "Punch", "RW", 32, (32, 1023)),
]
_MX_EEPROM = [
    (20, 2, "Multi Turn Offset", "RW", 0, (-24576, 24576)),
    (22, 1, "Resolution Divider", "RW", 1, (1, 4)),
]
_MX_RAM = [
    (26, 1, "D Gain", "RW", 0, (0, 254)),
    (27, 1, "I Gain", "RW", 0, (0, 254)),
    (28, 1, "P Gain", "RW", 32, (0, 254)),
    (30, 2, "Goal Position", "RW", None, (0, 4095)),
    (32, 2, "Moving Speed", "RW", None, (0, 2047)),
    (34, 2, "Torque Limit", "RW", None, (0, 1023)),
    (36, 2, "Present Position", "R", None, None),
    (38, 2, "Present Speed", "R", None, None),
    (40, 2, "Present Load", "R", None, None),
    (42, 1, "Present Voltage", "R", None, None),
    (43, 1, "Present Temperature", "R", None, None),
    (44, 1, "Registered", "R", 0, None),
    (46, 1, "Moving", "R", 0, None),
    (47, 1, "Lock", "RW", 0, (0, 1)),
    (48, 2, "Punch", "RW", 0, (0, 1023)),
    (50, 2, "Realtime Tick", "R", 0, None),
    (73, 1, "Goal Acceleration", "RW", 0, (0, 254)),
]
_MX_CURRENT = [  # MX-64 and MX-106 only
    (68, 2, "Current", "RW", 0, (0, 4095)),
    (70, 1, "Torque Control Mode Enable", "RW", 0, (0, 1)),
    (71, 2, "Goal Torque", "RW", 0, (0, 2047)),
]

_SIGNED = frozenset({"Multi Turn Offset"})
"""Two's-complement items (the speed/load items are sign-magnitude, decoded by the user)."""

_ROLES_COMMON = {
    "Min Position Limit": "CW Angle Limit",
    "Max Position Limit": "CCW Angle Limit",
    "Present Velocity": "Present Speed",
    "Goal Velocity": "Moving Speed",
    "Profile Velocity": "Moving Speed",
    "Present Input Voltage": "Present Voltage",
    "Registered Instruction": "Registered",
}
_ROLES_MX = {**_ROLES_COMMON, "Profile Acceleration": "Goal Acceleration",
             "Position P Gain": "P Gain", "Position I Gain": "I Gain",
             "Position D Gain": "D Gain"}


def baud_rates_1(mx: bool) -> dict[int, int]:
    """Baud Rate value -> bit/s: 2,000,000 / (n + 1) (floored), MX also 250..252."""
    rates = {n: 2_000_000 // (n + 1) for n in range(255)}
    if mx:
        rates.update({250: 2_250_000, 251: 2_500_000, 252: 3_000_000})
    else:  # the AX pages: 7,843 bit/s .. 1 Mbit/s (value 1); 0 would be 2 Mbit/s
        del rates[0]
    return rates


_MX_VOLTS = {"Min Voltage Limit": (50, 160), "Max Voltage Limit": (50, 160)}
"""MX pages include control_table_volt_limit.md: 50 ~ 160 (5.0 ~ 16.0 V)."""

# model number -> key, rows, mx, defaults and ranges overriding the rows', units.
# Pages read from the e-Manual's source (github.com/ROBOTIS-GIT/emanual, file @ commit):
#   AX-12A  docs/en/dxl/ax/ax-12a.md @486d85b1 (its voltage-range include,
#           control_table_volt_limit_high.md, was not readable: 50..250 is unchecked)
#   AX-18A  docs/en/dxl/ax/ax-18a.md @2ac64e5f (Max Torque 983, Temperature Limit 75 in
#           0 ~ 99, voltage via control_table_volt_limit.md 50 ~ 160)
#   MX-28   docs/en/dxl/mx/mx-28.md @1b03e234; MX-64 docs/en/dxl/mx/mx-64.md @b942e2d6;
#   MX-106  docs/en/dxl/mx/mx-106.md @78f3b8be
#   shared includes: _includes/en/dxl/control_table_temp_limit.md @187f56cd (0 ~ 100),
#   control_table_volt_limit.md @187f56cd (50 ~ 160), control_table_multiturn_offset.md
#   @24e68fc8 (-24,576 ~ 24,576), control_table_mx_pid.md @0a1cc01d (gains 0 ~ 254),
#   control_table_goal_acceleration.md @7758f426 (0 ~ 254, 8.583 deg/s^2),
#   control_table_baudrate.md @3a6f8fed; specifications: _data/dxl_mx_info.yml @5d02e95a
#   (MX stall torque / current / no-load speed at 12 V).
MODELS: dict[int, dict] = {
    12: {"key": "ax_12a", "rows": _HEAD + _AX_RAM, "mx": False,
         "defaults": {},
         "units": ServoUnits(ticks_per_rev=1228.8, velocity_rpm=0.111, accel_rpm2=0.0,
                             current_ma=None, pwm_max=1023, stall_torque_nm=1.5,
                             stall_current_a=1.5, no_load_rpm=59.0)},
    18: {"key": "ax_18a", "rows": _HEAD + _AX_RAM, "mx": False,
         "defaults": {"Temperature Limit": 75, "Max Torque": 983},
         "ranges": {"Temperature Limit": (0, 99), "Min Voltage Limit": (50, 160),
                    "Max Voltage Limit": (50, 160)},
         "units": ServoUnits(ticks_per_rev=1228.8, velocity_rpm=0.111, accel_rpm2=0.0,
                             current_ma=None, pwm_max=1023, stall_torque_nm=1.8,
                             stall_current_a=2.2, no_load_rpm=97.0)},
    29: {"key": "mx_28", "rows": _HEAD + _MX_EEPROM + _MX_RAM, "mx": True,
         "defaults": {"Baud Rate": 34, "CCW Angle Limit": 4095, "Temperature Limit": 80,
                      "Max Voltage Limit": 160},
         "ranges": _MX_VOLTS,
         "units": ServoUnits(ticks_per_rev=4096.0, velocity_rpm=0.114, accel_rpm2=85.83,
                             current_ma=None, pwm_max=1023, stall_torque_nm=2.5,
                             stall_current_a=1.4, no_load_rpm=55.0)},
    # mx-64.md @b942e2d6 prints Max Voltage Limit 240, outside its own 50 ~ 160 range and
    # the 10 ~ 14.8 V input: kept at 160 (MX-28 / MX-106 pages) until the lead decides
    310: {"key": "mx_64", "rows": _HEAD + _MX_EEPROM + _MX_RAM + _MX_CURRENT, "mx": True,
          "defaults": {"Baud Rate": 34, "CCW Angle Limit": 4095, "Temperature Limit": 80,
                       "Max Voltage Limit": 160},
          "ranges": _MX_VOLTS,
          "units": ServoUnits(ticks_per_rev=4096.0, velocity_rpm=0.114, accel_rpm2=85.83,
                              current_ma=4.5, pwm_max=1023, stall_torque_nm=6.0,
                              stall_current_a=4.1, no_load_rpm=63.0)},
    320: {"key": "mx_106",
          "rows": [*_HEAD, (10, 1, "Drive Mode", "RW", 0, (0, 3)), *_MX_EEPROM, *_MX_RAM,
                   *_MX_CURRENT], "mx": True,
          "defaults": {"Baud Rate": 34, "CCW Angle Limit": 4095, "Temperature Limit": 80,
                       "Max Voltage Limit": 160},
          "ranges": _MX_VOLTS,
          "units": ServoUnits(ticks_per_rev=4096.0, velocity_rpm=0.114, accel_rpm2=85.83,
                              current_ma=4.5, pwm_max=1023, stall_torque_nm=8.4,
                              stall_current_a=5.2, no_load_rpm=45.0)},
}

_NAMES = {"ax_12a": 12, "ax_12": 12, "ax_12+": 12, "ax_12_": 12, "ax_18a": 18, "ax_18f": 18,
          "ax_18": 18, "mx_28": 29, "mx_28t": 29, "mx_28r": 29, "mx_28at": 29, "mx_28ar": 29,
          "mx_64": 310, "mx_64t": 310, "mx_64at": 310, "mx_106": 320, "mx_106t": 320}

PROTOCOL1_ONLY = frozenset({12, 18})
"""Model numbers that speak only Protocol 1.0 (whatever their firmware); the MX numbers here
(29, 310, 320) are the 1.0 firmware of models that also have 2.0 firmware (30, 311, 321)."""


def _number(model: str | int) -> int | None:
    if isinstance(model, int):
        return model if model in MODELS else None
    return _NAMES.get(model_key(model))


def load(model: str | int) -> ControlTable | None:
    """The Protocol 1.0 table of ``model`` (e-Manual name such as ``"AX-12A"``, ``"MX-28"``,
    or model number 12, 18, 29, 310, 320), or None when ``model`` has no table of its own for
    Protocol 1.0 (an X-series servo switched to 1.0 by its Protocol Type keeps its table)."""
    number = _number(model)
    return None if number is None else _build(number)


@functools.cache
def _build(number: int) -> ControlTable:
    spec = MODELS[number]
    items: dict[str, ControlItem] = {}
    defaults: dict[str, int] = {"Model Number": number}
    ranges: dict[str, tuple[int, int]] = {}
    read_only = set()
    mx = spec["mx"]
    for address, size, name, access, default, limits in spec["rows"]:
        items[name] = ControlItem(name=name, address=address, size=size,
                                  writable=access != "R", eeprom=address < EEPROM_END,
                                  signed=name in _SIGNED)
        if access == "R":
            read_only.add(name)
        if default is not None:
            defaults[name] = default
        if limits is not None:
            ranges[name] = limits
    if mx:
        ranges["CW Angle Limit"] = ranges["CCW Angle Limit"] = (0, 4095)
        defaults["Baud Rate"] = 34
    defaults.update(spec["defaults"])
    ranges.update(spec.get("ranges", {}))
    # power-on copies of EEPROM values; measured values at rest and the firmware version are
    # values of our choosing (the e-Manual gives none)
    defaults.update({"Torque Limit": defaults["Max Torque"], "Present Voltage": 120,
                     "Present Temperature": 30, "Firmware Version": 36 if mx else 24,
                     "Goal Position": 0, "Moving Speed": 0})
    size = max(it.end for it in items.values())
    units: ServoUnits = spec["units"]
    return ControlTable(
        model=spec["key"], model_number=number, items=items, size=size, defaults=defaults,
        ranges=ranges, source=None, protocol=1.0, eeprom_end=EEPROM_END,
        baud_rates=baud_rates_1(mx),
        operating_modes=frozenset({1, 3, 4}) if mx else frozenset({1, 3}),
        read_only=frozenset(read_only), units=units,
        roles=dict(_ROLES_MX if mx else _ROLES_COMMON), indirect=())
