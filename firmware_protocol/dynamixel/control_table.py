"""Control tables of X-series servos, loaded from the data that the ROBOTIS SDK ships.

Source of each fact
-------------------
* **Address, size, name** of every item: the ``[control table]`` section of
  ``dynamixel_easy_sdk/control_table/<model>.model`` in the installed ``dynamixel-sdk`` wheel
  (the same files ``dynamixel_easy_sdk.control_table.ControlTable`` parses). Not retyped here.
* **Model number**: ``dynamixel_easy_sdk/control_table/dynamixel.model`` (number -> file name).
* **Signedness**: the ``[unit info]`` "Sign Type" column where present, plus the X-series
  e-Manual for the items it does not list (offsets, goals, present values, trajectories).
* **EEPROM / RAM**: X-series e-Manual rule "addresses 0-63 are EEPROM, 64 and above RAM".
* **Read-only items, default values, value ranges**: the X-series e-Manual control-table pages
  (XM430-W350, XL430-W250, XC330-M288), recalled and typed below; they are not in the .model
  files. Defaults that differ between models are in :data:`_MODEL_DEFAULTS`.
* **Table end**: last item of the .model file; the indirect data block that follows "Indirect
  Data Read" (28 one-byte slots on the X430 family) is counted as plain RAM.

Layout of a ``.model`` file (tab-separated)::

    [type info]        name / value rows (radian conversion)
    [unit info]        Data Name / value / unit / Sign Type
    [control table]    Address / Size / Data Name
"""

from __future__ import annotations

import functools
import importlib.util
import re
from dataclasses import dataclass, field
from pathlib import Path

EEPROM_END = 64
"""Addresses below this are EEPROM (X-series e-Manual)."""

READ_ONLY = frozenset({
    "Model Number", "Model Information", "Firmware Version", "Registered Instruction",
    "Hardware Error Status", "Realtime Tick", "Moving", "Moving Status", "Present PWM",
    "Present Current", "Present Load", "Present Velocity", "Present Position",
    "Velocity Trajectory", "Position Trajectory", "Present Input Voltage",
    "Present Temperature", "Backup Ready",
})
"""Items marked "R" in the X-series e-Manual."""

SIGNED = frozenset({
    "Homing Offset", "Goal PWM", "Goal Current", "Goal Velocity", "Goal Position",
    "Present PWM", "Present Current", "Present Load", "Present Velocity", "Present Position",
    "Velocity Trajectory", "Position Trajectory",
})
"""Items holding two's-complement values (e-Manual value ranges include negatives)."""

BAUD_RATES = {0: 9600, 1: 57600, 2: 115200, 3: 1_000_000, 4: 2_000_000, 5: 3_000_000,
              6: 4_000_000, 7: 4_500_000}
"""Baud Rate (address 8) value -> bits per second (X-series e-Manual)."""

OPERATING_MODES = frozenset({0, 1, 3, 4, 5, 16})
"""Operating Mode values: current, velocity, position, extended position, current-based
position, PWM."""

# e-Manual defaults common to the X series
_DEFAULTS = {
    "ID": 1, "Baud Rate": 1, "Return Delay Time": 250, "Drive Mode": 0, "Operating Mode": 3,
    "Secondary(Shadow) ID": 255, "Protocol Type": 2, "Homing Offset": 0,
    "Moving Threshold": 10, "Temperature Limit": 80, "Max Voltage Limit": 160,
    "Min Voltage Limit": 95, "PWM Limit": 885, "Current Limit": 1193, "Velocity Limit": 200,
    "Max Position Limit": 4095, "Min Position Limit": 0, "Shutdown": 52, "Torque Enable": 0,
    "LED": 0, "Status Return Level": 2, "Velocity I Gain": 1920, "Velocity P Gain": 100,
    "Position D Gain": 0, "Position I Gain": 0, "Position P Gain": 800, "Bus Watchdog": 0,
    "Profile Acceleration": 0, "Profile Velocity": 0, "Present Input Voltage": 120,
    "Present Temperature": 30, "Firmware Version": 48, "PWM Slope": 140,
}
_MODEL_DEFAULTS = {
    "xl430_w250": {"Temperature Limit": 72, "Max Voltage Limit": 140, "Min Voltage Limit": 60,
                   "Velocity Limit": 265, "Position P Gain": 640, "Velocity I Gain": 1000},
    "xc330_m288": {"Temperature Limit": 70, "Max Voltage Limit": 70, "Min Voltage Limit": 35,
                   "Current Limit": 1750, "Velocity Limit": 445, "Position P Gain": 400,
                   "Present Input Voltage": 50},
}

# value ranges (inclusive) from the e-Manual; writing outside -> data range error
_RANGES = {
    "ID": (0, 252), "Baud Rate": (0, 7), "Return Delay Time": (0, 254), "Drive Mode": (0, 13),
    "Secondary(Shadow) ID": (0, 255), "Protocol Type": (1, 2),
    "Homing Offset": (-1_044_479, 1_044_479), "Moving Threshold": (0, 1023),
    "Temperature Limit": (0, 100), "PWM Limit": (0, 885), "Velocity Limit": (0, 1023),
    "Max Position Limit": (0, 4095), "Min Position Limit": (0, 4095), "Torque Enable": (0, 1),
    "LED": (0, 1), "Status Return Level": (0, 2), "Profile Acceleration": (0, 32767),
    "Profile Velocity": (0, 32767), "Goal Position": (-1_048_575, 1_048_575),
    "Velocity I Gain": (0, 16383), "Velocity P Gain": (0, 16383), "Position D Gain": (0, 16383),
    "Position I Gain": (0, 16383), "Position P Gain": (0, 16383), "Bus Watchdog": (0, 127),
}

_INDIRECT_DATA_SLOTS = 28


@dataclass(frozen=True, slots=True)
class ServoUnits:
    """Physical units and motor constants of one model (e-Manual "Specifications" and the
    unit column of each control-table item). Defaults: the XM430-W350.

    Attributes
    ----------
    ticks_per_rev : float
        Position resolution, ticks per revolution (X-series 4096; P-series 1,003,846 for
        ±180° = ±501,923; XL-320 / AX 1024 ticks over 300°, i.e. 1228.8 per turn).
    velocity_rpm : float
        rev/min per unit of Goal/Present Velocity and Profile Velocity (X 0.229).
    accel_rpm2 : float
        rev/min² per unit of Profile Acceleration (X 214.577).
    current_ma : float or None
        mA per unit of Goal/Present Current; None: the model has no current sensing.
    pwm_max : int
        Goal/Present PWM at 100 % duty (X 885).
    stall_torque_nm, stall_current_a, no_load_rpm : float
        Motor constants at the nominal voltage (the torque model of the simulator).
    """

    ticks_per_rev: float = 4096.0
    velocity_rpm: float = 0.229
    accel_rpm2: float = 214.577
    current_ma: float | None = 2.69
    pwm_max: int = 885
    stall_torque_nm: float = 4.1
    stall_current_a: float = 2.3
    no_load_rpm: float = 46.0


@dataclass(frozen=True, slots=True)
class IndirectBlock:
    """One block of indirect addressing: ``count`` 2-byte Indirect Address slots from
    ``address_start``; slot k maps data byte ``data_start + k`` onto the address it holds."""

    address_start: int
    data_start: int
    count: int


@dataclass(frozen=True, slots=True)
class ControlItem:
    """One item of a control table.

    Attributes
    ----------
    name : str
        Name as in the e-Manual and the .model file (e.g. ``"Goal Position"``).
    address : int
        First byte.
    size : int
        Size in bytes (1, 2 or 4); values are little-endian.
    writable : bool
        False for items the e-Manual marks read-only.
    eeprom : bool
        True below address 64: writable only while torque is off.
    signed : bool
        Two's-complement value.
    """

    name: str
    address: int
    size: int
    writable: bool = True
    eeprom: bool = False
    signed: bool = False

    @property
    def end(self) -> int:
        """One past the last byte."""
        return self.address + self.size

    def decode(self, data: bytes) -> int:
        """Value of this item from its ``size`` little-endian bytes."""
        return int.from_bytes(data, "little", signed=self.signed)

    def encode(self, value: int) -> bytes:
        """Little-endian bytes of ``value`` (wrapped to the item's size)."""
        return (value & ((1 << (8 * self.size)) - 1)).to_bytes(self.size, "little")


@dataclass
class ControlTable:
    """Control table of one servo model.

    Attributes
    ----------
    model : str
        Canonical file stem, e.g. ``"xm430_w350"``.
    model_number : int
        Number the servo reports to PING and at address 0.
    items : dict of str to ControlItem
        By name (aliases such as "Indirect Data Write" included).
    size : int
        Number of addressable bytes (address range 0..size-1).
    defaults : dict of str to int
        Power-on / factory values.
    ranges : dict of str to (int, int)
        Inclusive valid range of writable items that have one.
    source : pathlib.Path
        The .model file the layout was read from.
    protocol : float
        The protocol the model speaks when it leaves the factory (1.0 or 2.0).
    eeprom_end : int
        Addresses below this are EEPROM (writable only with torque off).
    baud_rates : dict of int to int
        Baud Rate item value -> bit/s.
    operating_modes : frozenset of int
        Valid values of the Operating Mode item (or the model's role for it).
    read_only : frozenset of str
        Items the e-Manual marks "R".
    units : ServoUnits
    roles : dict of str to str
        X-series item name -> this model's item name, for the items whose name differs
        (XL-320 "Control Mode" for "Operating Mode", AX "CW Angle Limit" for "Min Position
        Limit", ...); :meth:`resolve` looks names up through it.
    indirect : tuple of IndirectBlock
    """

    model: str
    model_number: int
    items: dict[str, ControlItem]
    size: int
    defaults: dict[str, int] = field(default_factory=dict)
    ranges: dict[str, tuple[int, int]] = field(default_factory=dict)
    source: Path | None = None
    protocol: float = 2.0
    eeprom_end: int = EEPROM_END
    baud_rates: dict[int, int] = field(default_factory=lambda: dict(BAUD_RATES))
    operating_modes: frozenset[int] = OPERATING_MODES
    read_only: frozenset[str] = READ_ONLY
    units: ServoUnits = field(default_factory=ServoUnits)
    roles: dict[str, str] = field(default_factory=dict)
    indirect: tuple[IndirectBlock, ...] = ()

    def __post_init__(self) -> None:
        self._at: dict[int, ControlItem] = {}
        for item in self.items.values():
            self._at.setdefault(item.address, item)
        self._cover: list[ControlItem | None] = [None] * self.size
        for item in sorted(self._at.values(), key=lambda it: it.address):
            for a in range(item.address, min(item.end, self.size)):
                if self._cover[a] is None:
                    self._cover[a] = item

    @property
    def display_name(self) -> str:
        """e-Manual spelling, e.g. ``"XM430-W350"``."""
        return model_display_name(self.model)

    def __getitem__(self, name: str) -> ControlItem:
        return self.items[name]

    def __contains__(self, name: object) -> bool:
        return name in self.items

    def resolve(self, name: str) -> ControlItem | None:
        """The item playing the role of X-series item ``name`` in this model (its own name
        first, then :attr:`roles`), or None when the model has none."""
        item = self.items.get(name)
        if item is None and name in self.roles:
            item = self.items.get(self.roles[name])
        return item

    def item_covering(self, address: int) -> ControlItem | None:
        """The item that contains byte ``address``, or None for a reserved gap."""
        if 0 <= address < self.size:
            return self._cover[address]
        return None

    def item_at(self, address: int) -> ControlItem | None:
        """The item that starts at ``address``, if any."""
        return self._at.get(address)

    def default_memory(self) -> bytearray:
        """A fresh memory image holding the default value of every item."""
        mem = bytearray(self.size)
        for name, value in self.defaults.items():
            item = self.items.get(name)
            if item is not None:
                mem[item.address:item.end] = item.encode(value)
        return mem


def _data_dir() -> Path:
    spec = importlib.util.find_spec("dynamixel_easy_sdk")
    if spec is None or not spec.submodule_search_locations:
        raise FileNotFoundError("dynamixel_easy_sdk (part of dynamixel-sdk >= 4) is not installed; "
                                "its control_table/*.model files are needed")
    return Path(next(iter(spec.submodule_search_locations))) / "control_table"


def model_key(model: str) -> str:
    """Normalise ``"XM430-W350"``, ``"xm430_w350"`` or ``"xm430_w350.model"`` to a file stem."""
    key = model.strip().lower().removesuffix(".model")
    return re.sub(r"[-\s]+", "_", key)


def model_display_name(key: str) -> str:
    """``"xm430_w350"`` -> ``"XM430-W350"``."""
    return key.upper().replace("_", "-")


@functools.lru_cache(maxsize=1)
def model_numbers() -> dict[str, int]:
    """File stem -> model number, from the SDK's ``dynamixel.model``."""
    path = _data_dir() / "dynamixel.model"
    out: dict[str, int] = {}
    for line in path.read_text(encoding="utf-8").splitlines()[1:]:
        parts = line.strip().split("\t")
        if len(parts) >= 2 and parts[0].isdigit():
            out[model_key(parts[1])] = int(parts[0])
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
        from firmware_protocol.dynamixel import tables_protocol1
        table = tables_protocol1.load(model)
        if table is not None:
            return table
    numbers = model_numbers()
    if isinstance(model, int) and model not in numbers.values() or \
            isinstance(model, str) and model_key(model) not in numbers:
        # a model the SDK has no table for may be a Protocol 1.0 one (AX-12A, model 29, ...)
        from firmware_protocol.dynamixel import tables_protocol1
        table = tables_protocol1.load(model)
        if table is not None:
            return table
    if isinstance(model, int):
        by_number = {v: k for k, v in numbers.items()}
        if model not in by_number:
            raise ValueError(f"unknown Dynamixel model number {model}")
        key = by_number[model]
    else:
        key = model_key(model)
        if key not in numbers:
            raise ValueError(f"unknown Dynamixel model {model!r}; known models: "
                             f"{', '.join(available_models())}")
    path = _data_dir() / f"{key}.model"
    rows, signed = _parse_model_file(path.read_text(encoding="utf-8"))
    if not rows:
        raise ValueError(f"{path}: no [control table] section")
    items: dict[str, ControlItem] = {}
    for address, size, name in rows:
        items[name] = ControlItem(name=name, address=address, size=size,
                                  writable=name not in READ_ONLY, eeprom=address < EEPROM_END,
                                  signed=name in signed or name in SIGNED)
    size = max(a + s for a, s, _ in rows)
    if "Indirect Data Read" in items:
        size = max(size, items["Indirect Data Read"].address + _INDIRECT_DATA_SLOTS)
    defaults = dict(_DEFAULTS)
    defaults.update(_MODEL_DEFAULTS.get(key, {}))
    defaults["Model Number"] = numbers[key]
    defaults["Goal PWM"] = defaults["PWM Limit"]
    defaults["Goal Current"] = defaults["Current Limit"]
    defaults = {k: v for k, v in defaults.items() if k in items}
    ranges = {k: v for k, v in _RANGES.items() if k in items}
    indirect = ()
    if "Indirect Address 1" in items and "Indirect Data 1" in items:
        indirect = (IndirectBlock(items["Indirect Address 1"].address,
                                  items["Indirect Data 1"].address, _INDIRECT_DATA_SLOTS),)
    return ControlTable(model=key, model_number=numbers[key], items=items, size=size,
                        defaults=defaults, ranges=ranges, source=path, indirect=indirect)
