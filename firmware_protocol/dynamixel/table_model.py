"""The data model of a Dynamixel control table: items, units, indirect blocks, the table.

A leaf module: :mod:`firmware_protocol.dynamixel.control_table` (the Protocol 2.0 tables, from
the SDK's ``.model`` files) and :mod:`firmware_protocol.dynamixel.tables_protocol1` (the
Protocol 1.0 tables, typed from the e-Manual) both build :class:`ControlTable` objects.
"""

from __future__ import annotations

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
        Indirect Address/Data blocks (the X430/540 and MX two of 28 slots, X330 one of 20 or
        28, P-series / PRO(A) one of 128).
    home_ticks : float
        Shaft position at power-on the simulator starts a servo at, ticks (X series 2048, the
        middle of 0..4095; P-series / PRO(A) 0, the middle of ±max; XL-320 512).
    family : str
        Which family table the defaults and ranges came from (``"x430"``, ``"x330"``,
        ``"xl320"``, ``"mx2"``, ``"p"``, ``"pro_a"``).
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
    home_ticks: float = 2048.0
    family: str = "x430"

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
        for block in self.indirect:  # e-Manual: slot k's address defaults to its own data byte
            for k in range(block.count):
                a = block.address_start + 2 * k
                mem[a:a + 2] = (block.data_start + k).to_bytes(2, "little")
        for name, value in self.defaults.items():
            item = self.items.get(name)
            if item is not None:
                mem[item.address:item.end] = item.encode(value)
        return mem


# ---------------------------------------------------------------------------- family data
# Defaults, ranges and units per family, typed from the e-Manual control-table pages named in
# each family's comment; per-model values the pages give differently are in _MODEL_OVERRIDES.
# Addresses and sizes stay in the SDK's .model files.


def model_key(model: str) -> str:
    """Normalise ``"XM430-W350"``, ``"xm430_w350"`` or ``"xm430_w350.model"`` to a file stem."""
    key = model.strip().lower().removesuffix(".model")
    return re.sub(r"[-\s]+", "_", key)


def model_display_name(key: str) -> str:
    """``"xm430_w350"`` -> ``"XM430-W350"``."""
    return key.upper().replace("_", "-")
