"""One simulated Dynamixel Protocol 2.0 servo: control table, motion, torque, hardware errors.

State and behaviour only — no I/O: :class:`~rig.sim.dynamixel.bus.DynamixelBus` feeds it the
instructions it receives and serialises access with its lock. Every per-model fact (units,
baud rates, operating modes, EEPROM end, indirect blocks, motor constants) comes from the
servo's :class:`~firmware_protocol.dynamixel.control_table.ControlTable`; the module constants
below that name X-series values are kept for the code that imports them.

Frames
------
``pos``/``vel``/``target`` and the hand / push APIs are in ACTUAL shaft ticks (the physical
world: the encoder, before any setting). Everything the host reads or writes is in the
servo's frame (X-series e-Manual, Homing Offset(20) and Drive Mode(10)):
``Present Position = direction × actual + Homing Offset``, direction −1 when Drive Mode bit 0
("Reverse Mode": CCW negative) is set. Goal Position, Position Trajectory and Min/Max Position
Limit are in that frame; Present/Goal Velocity, Velocity Trajectory, Present/Goal Current,
Present/Goal PWM and Present Load are multiplied by the direction. In Position Control Mode (3)
a Homing Offset outside ±1,024 is ignored (e-Manual note on Homing Offset(20)).

Motion
------
Position modes 3 and 4 with no external torque: a trapezoidal velocity profile from Profile
Velocity and Profile Acceleration (units from the table's ``units``), 0 meaning "unlimited"
(Velocity Limit / instantaneous), or the time-based profile of Drive Mode bit 2 — exactly as
before this model had a torque model (tests and goldens rely on it). Present Current there is
what the motion costs: ``(J α + b ω) / kt``. Velocity mode (1) ramps to Goal Velocity.
Integrated lazily, in :data:`STEP` steps, whenever the servo is observed, on the bus's clock.

Torque model (modes 0, 5, 16, and modes 3/4 while an external torque acts or until the shaft
is back on its profile): the output shaft is one rigid body,

    J dω/dt = kt·i + τ_push + τ_hand − b·ω

* ``kt = stall_torque / stall_current`` (output-shaft N·m/A, the table's ``units``);
* the motor at duty ``d`` (Goal/Present PWM ÷ ``pwm_max``) draws
  ``i = stall_current · (d − ω / ω_no_load)`` — the DC-motor line through the e-Manual's stall
  and no-load points, so the PWM (voltage) and back-EMF bound the current;
* ``J = τ_m · stall_torque / ω_no_load + load_inertia``: rotor and gearbox reflected to the
  output, from a mechanical time constant :data:`MECHANICAL_TIME_CONSTANT_S` (8 ms, typical of
  the small coreless / cored DC motors these servos use: a modelling choice — the e-Manual
  publishes no inertia), plus an optional load inertia (kg·m²);
* ``b = FRICTION_RATIO · stall_torque / ω_no_load``: viscous friction, 2 % of the motor's own
  back-EMF damping (modelling choice).
* ``τ_hand = K (θ_hand − θ) − B ω``: an impedance hand (:meth:`SimServo.set_hand` with a
  stiffness ``K`` N·m/rad and damping ``B`` N·m·s/rad), a person holding the shaft through the
  spring of their arm, torque on or off; 0 without one. The damping term is integrated
  implicitly (any ``B`` is stable); the stiffness explicitly, stable for ``K h² / J <`` 4
  (``h`` = :data:`STEP`), which :meth:`set_hand` checks. A hand without a stiffness (the
  default) is rigid instead: with torque off the shaft follows it exactly, as it always did.

Current mode (0): an ideal current loop holds ``Goal Current`` (≤ Current Limit) while the PWM
allows it. PWM mode (16): ``Goal PWM`` drives the motor directly. Position modes (3, 4, 5): a
PID on the position error (ticks) tracking the profile's reference gives a PWM (e-Manual gains:
``KPP = Position P Gain / 128``, ``KPI = Position I Gain / 65536``, ``KPD = Position D Gain /
16``; the integral and derivative are taken per 1 ms control period, our choice), bounded by
Goal PWM, then the current is bounded by Current Limit (3, 4) or Goal Current (5). Goal PWM
bounds the PWM in every mode (e-Manual Goal PWM(100)).

Bus Watchdog (address 98, X-series e-Manual §2.4.27, ``control_table_buswatchdog.md``):
0 off, 1..127 on in 20 ms units, monitored while Torque Enable is 1. When no instruction packet
reached the servo for longer than that, it stops at once (the e-Manual: Profile Acceleration
and Profile Velocity "applied as 0") — Goal Position becomes the present position, Goal
Velocity 0 — and Bus Watchdog reads -1 (0xFF). While it does, writing a Goal item (PWM 100,
Current 102, Velocity 104, Position 116) is refused with a Data Range Error; writing 0 to Bus
Watchdog clears the error. The trip is evaluated lazily at its exact simulated time.

Indirect addressing (e-Manual "Indirect Address, Indirect Data"): every block of
``table.indirect``; Indirect Address k (2 bytes, RAM, range 64 .. last address, initial value
the address of Indirect Data k) names the byte that Indirect Data k reads and writes, with that
byte's access rules, range and limits (a write through indirect data is validated as a write
of the target items). Inside :meth:`read` / :meth:`write`, so group reads and writes follow.

Secondary ID (12), 0..252: the servo also executes instructions sent to that ID, without a
status packet and without touching EEPROM (e-Manual "Secondary(Shadow) ID(12)"); see
:meth:`SimServo.addressed`. Boot: after REBOOT (and FACTORY_RESET, which reboots) the servo is
silent for :attr:`SimServo.boot_time_s` (:data:`BOOT_TIME_S`).
"""

from __future__ import annotations

import math
import random
from collections.abc import Callable

from firmware_protocol.dynamixel.control_table import (
    BAUD_RATES,
    ControlItem,
    ControlTable,
    load_control_table,
)
from firmware_protocol.dynamixel.packets import ALERT, ErrorCode

__all__ = [
    "ACCEL_UNIT",
    "BOOT_TIME_S",
    "FRICTION_RATIO",
    "HARDWARE_ERRORS",
    "MECHANICAL_TIME_CONSTANT_S",
    "STEP",
    "TICKS_PER_REV",
    "VELOCITY_UNIT",
    "WATCHDOG_ERROR",
    "WATCHDOG_UNIT_S",
    "SimServo",
]

TICKS_PER_REV = 4096
"""X-series ticks per revolution (kept for importers; a servo uses ``table.units``)."""
VELOCITY_UNIT = 0.229 * TICKS_PER_REV / 60.0
"""X-series ticks/s per velocity unit (kept for importers; a servo uses ``velocity_unit``)."""
ACCEL_UNIT = 214.577 * TICKS_PER_REV / 3600.0
"""X-series ticks/s² per Profile Acceleration unit (a servo uses ``accel_unit``)."""
STEP = 0.001
"""Integration step of the motion, s."""
WATCHDOG_UNIT_S = 0.020
"""Bus Watchdog unit, s (e-Manual: 20 ms)."""
WATCHDOG_ERROR = 0xFF
"""Bus Watchdog byte while its error is flagged (-1 as a signed byte)."""
BOOT_TIME_S = 0.4
"""Silence after REBOOT, s. The e-Manual gives no figure; an XC330 measured by a user is
silent "about 0.4 seconds" after answering REBOOT (github.com/ROBOTIS-GIT/emanual issue 1698,
which ROBOTIS declined to document)."""
MECHANICAL_TIME_CONSTANT_S = 0.008
"""Mechanical time constant of motor + gearbox (sets the reflected inertia), s: modelling
choice (see the module docstring)."""
FRICTION_RATIO = 0.02
"""Viscous friction as a fraction of the motor's back-EMF damping (modelling choice)."""
SECONDARY_ID_MAX = 252
"""Secondary ID 0..252 is active, 253..255 off (e-Manual Secondary(Shadow) ID(12))."""
HOMING_OFFSET_JOINT_MODE = 1024
"""In Position Control Mode a Homing Offset beyond ±90° (±1,024 ticks on the X series; a
quarter of each model's turn: P-series ±250,961) is ignored (e-Manual notes on Homing Offset)."""

HARDWARE_ERRORS = {
    "input_voltage": 0x01,
    "overheating": 0x04,
    "encoder": 0x08,
    "electrical_shock": 0x10,
    "overload": 0x20,
}
"""Hardware Error Status (address 70) bits by name (X-series e-Manual)."""

_GOAL_ITEMS = ("Goal PWM", "Goal Current", "Goal Velocity", "Goal Position")
_DIRECTIONAL = frozenset({"Goal PWM", "Goal Current", "Goal Velocity"})
# P-series and PRO(A): Goal Position outside Min/Max Position Limit is a Data Limit Error
# (P-series e-Manual "Goal Position(564)": range Min Position Limit ~ Max Position Limit);
# the X series clamps it (our reading of the X-series e-Manual; unverified on hardware)
_LIMIT_REFUSING_FAMILIES = ("ph", "pm", "h42", "h54", "m42", "m54")
_TWO_PI = 2.0 * math.pi


class SimServo:
    """State and behaviour of one simulated servo (not thread-safe: the bus locks around it).

    Subclasses (e.g. Protocol 1.0 servos) override the small methods: :meth:`direction`,
    :meth:`homing_offset`, :meth:`addressed`, :meth:`listening`, :meth:`refresh`,
    :meth:`_validate`, :meth:`_apply_effects`, :meth:`_goal_limits_refused`,
    :meth:`_start_position`.

    Parameters
    ----------
    dxl_id : int
        ID, 0..252.
    model : str or int
        e-Manual name, file stem or model number (see
        :func:`firmware_protocol.dynamixel.control_table.load_control_table`).
    baud_rate : int
        Initial Baud Rate in bit/s (one of the table's ``baud_rates``).
    return_delay_us : int or None
        Initial Return Delay Time in µs (even, 0..508); None keeps the e-Manual default 500 µs.
    position : float or None
        Initial ACTUAL shaft position, ticks; None: the model's power-on position (half a turn
        on the X series, 2048).
    noise_ticks : float
        Standard deviation of the encoder noise added to Present Position, ticks.
    rng : random.Random
        Source of the encoder noise.
    boot : bool
        True: the servo is booting at power-on (silent for :attr:`boot_time_s` from the moment
        the bus calls :meth:`power_on`); False (default): already booted.
    load_inertia : float
        Inertia of what the shaft carries, kg·m² (added to the motor's reflected inertia).
    table : ControlTable, optional
        A ready table (subclasses for other protocols); default ``load_control_table(model)``.

    Attributes
    ----------
    push : float, callable or None
        External torque on the shaft, N·m, ACTUAL frame (positive pushes towards increasing
        encoder ticks); a callable of the simulated time (s) for a torque that varies.
    hand : float, callable or None
        Where a hand holds the shaft, ACTUAL ticks (or a function of the simulated time).
    hand_stiffness, hand_damping : float or None, float
        The hand's impedance, N·m/rad and N·m·s/rad; stiffness None: a rigid hand (torque off
        only; torque on lets go of it).
    current : float
        Motor current, A, actual frame (Present Current is this × direction).
    boot_time_s : float
        Silence after REBOOT / power-on, s.
    """

    boot_time_s: float = BOOT_TIME_S

    def __init__(self, dxl_id: int, model: str | int = "XM430-W350", *,
                 baud_rate: int = 1_000_000, return_delay_us: int | None = None,
                 position: float | None = None, noise_ticks: float = 0.0,
                 rng: random.Random | None = None, boot: bool = False,
                 load_inertia: float = 0.0, table: ControlTable | None = None):
        if not (math.isfinite(load_inertia) and load_inertia >= 0.0):
            raise ValueError(f"load inertia must be a finite number >= 0 kg·m², got "
                             f"{load_inertia}")
        self.table: ControlTable = table if table is not None else load_control_table(model)
        max_id = 253 if self.table.protocol == 1.0 else 252  # 1.0: 254 is its broadcast ID
        if not 0 <= dxl_id <= max_id:
            raise ValueError(f"servo id must be 0..{max_id}, got {dxl_id}")
        # name -> (first byte, one past last, signed, size): the hot path of get/_set
        self._fields = {n: (it.address, it.end, it.signed, it.size)
                        for n, it in self.table.items.items()}
        self._setup_units(load_inertia)
        self._setup_indirect()
        self.mem = self._default_memory()
        self._baud_index = self._baud_index_of(baud_rate)
        self._set("ID", dxl_id)
        self._set("Baud Rate", self._baud_index)
        if return_delay_us is not None:
            if not 0 <= return_delay_us <= 508:
                raise ValueError(f"return delay must be 0..508 µs, got {return_delay_us}")
            self._set("Return Delay Time", return_delay_us // 2)
        eeprom_end = self.table.eeprom_end
        self._eeprom_boot = bytes(self.mem[:eeprom_end])
        self.noise_ticks = float(noise_ticks)
        self.rng = rng or random.Random(dxl_id)
        if position is None:
            position = self._start_position()
        self.pos = float(position)
        self.vel = 0.0  # ticks/s
        self.target = float(position)
        self.hand: float | Callable[[float], float] | None = None
        self.hand_stiffness: float | None = None
        self.hand_damping = 0.0
        self.push: float | Callable[[float], float] | None = None
        self._reset_dynamics()
        self.hardware_error = 0
        self.temperature = float(self.get("Present Temperature")) \
            if "Present Temperature" in self._fields else 30.0
        self.registered: tuple[int, bytes] | None = None
        self._time_profile: tuple[float, float] | None = None
        self.plugged = True
        self.last_t: float | None = None
        self.boot_t = 0.0
        self.boot_at_power_on = bool(boot)
        self.booting_until: float | None = None
        """Simulated time until which the servo is booting (silent), or None."""
        self.last_instruction_t: float | None = None
        """Simulated time the last instruction packet reached this servo (Bus Watchdog)."""
        self.watchdog_trips = 0
        """How many times the Bus Watchdog stopped this servo."""
        self._creation = (bytes(self.mem), float(position))

    # ------------------------------------------------------------------ setup
    def _setup_units(self, load_inertia: float) -> None:
        units = self.table.units
        self.ticks_per_rev = float(units.ticks_per_rev)
        self.velocity_unit = units.velocity_rpm * units.ticks_per_rev / 60.0
        """ticks/s per Goal/Present/Profile Velocity unit."""
        self.accel_unit = units.accel_rpm2 * units.ticks_per_rev / 3600.0
        """ticks/s² per Profile Acceleration unit."""
        self.kt = units.stall_torque_nm / units.stall_current_a
        """Torque constant at the output shaft, N·m/A."""
        self.no_load_w = units.no_load_rpm * _TWO_PI / 60.0
        self.inertia = (MECHANICAL_TIME_CONSTANT_S * units.stall_torque_nm / self.no_load_w
                        + float(load_inertia))
        """Shaft inertia J, kg·m² (reflected rotor + gearbox, plus the load)."""
        self.friction = FRICTION_RATIO * units.stall_torque_nm / self.no_load_w
        """Viscous friction b, N·m·s/rad."""
        self._rad_per_tick = _TWO_PI / self.ticks_per_rev

    def _setup_indirect(self) -> None:
        # Indirect Data byte address -> its Indirect Address slot's first byte
        self._indirect_data: dict[int, int] = {}
        self._indirect_slots: dict[int, int] = {}  # slot first byte -> its data byte
        for block in self.table.indirect:
            for k in range(block.count):
                self._indirect_data[block.data_start + k] = block.address_start + 2 * k
                self._indirect_slots[block.address_start + 2 * k] = block.data_start + k
        self._indirect_slot_bytes = {a + j for a in self._indirect_slots for j in (0, 1)}

    def _default_memory(self) -> bytearray:
        mem = self.table.default_memory()
        # e-Manual: Indirect Address k starts as the address of Indirect Data k
        for slot, data in self._indirect_slots.items():
            if slot + 2 <= len(mem) and mem[slot] == 0 and mem[slot + 1] == 0:
                mem[slot:slot + 2] = data.to_bytes(2, "little")
        return mem

    def _start_position(self) -> float:
        """Power-on ACTUAL position: the table's ``home_ticks`` (X series 2048, P-series and
        PRO(A) 0)."""
        return float(self.table.home_ticks)

    def _reset_dynamics(self) -> None:
        self.ref_pos = self.pos
        self.ref_vel = 0.0
        self.current = 0.0
        self.duty = 0.0
        self._integral = 0.0
        self._off_profile = False

    def power_on(self, now: float) -> None:
        """The bus powers the servo at simulated time ``now``: booting if asked at creation."""
        if self.boot_at_power_on:
            self.booting_until = now + self.boot_time_s

    # ------------------------------------------------------------------ memory helpers
    def get(self, name: str) -> int:
        """Current value of control-table item ``name``."""
        start, end, signed, _ = self._fields[name]
        return int.from_bytes(self.mem[start:end], "little", signed=signed)

    def _get_or(self, name: str, default: int) -> int:
        return self.get(name) if name in self._fields else default

    def _set(self, name: str, value: int) -> None:
        field = self._fields.get(name)
        if field is not None:
            start, end, _, size = field
            self.mem[start:end] = (int(value) & ((1 << (8 * size)) - 1)).to_bytes(size, "little")

    @property
    def id(self) -> int:
        """Current ID (address 7)."""
        return self.mem[self.table["ID"].address]

    @property
    def baud_rate(self) -> int:
        """Current line speed in bit/s, from the Baud Rate item."""
        rates = self.table.baud_rates
        return rates.get(self.get("Baud Rate"), next(iter(rates.values())))

    @property
    def return_delay(self) -> float:
        """Return Delay Time in seconds."""
        return self.get("Return Delay Time") * 2e-6

    @property
    def torque(self) -> bool:
        """Torque Enable."""
        return bool(self.get("Torque Enable"))

    # ------------------------------------------------------------------ frame
    def direction(self) -> int:
        """+1, or −1 when Drive Mode bit 0 (Reverse Mode) is set."""
        return -1 if self._get_or("Drive Mode", 0) & 0x01 else 1

    def homing_offset(self) -> int:
        """Homing Offset in force (0 in Position Control Mode when beyond ±1,024)."""
        offset = self._get_or("Homing Offset", 0)
        if self._get_or("Operating Mode", 3) == 3 and abs(offset) > self.ticks_per_rev / 4.0:
            return 0
        return offset

    def to_frame(self, actual: float) -> float:
        """ACTUAL shaft ticks -> the servo's frame (Present Position)."""
        d, off = self.direction(), self.homing_offset()
        return actual if d == 1 and off == 0 else d * actual + off

    def from_frame(self, value: float) -> float:
        """The servo's frame (Goal Position) -> ACTUAL shaft ticks."""
        d, off = self.direction(), self.homing_offset()
        return value if d == 1 and off == 0 else d * (value - off)

    # ------------------------------------------------------------------ bus hooks
    def addressed(self, pkt_id: int) -> tuple[bool, bool]:
        """Whether an instruction sent to ``pkt_id`` (not broadcast) is executed by this servo,
        and whether it replies: its ID (execute, reply); its active Secondary ID (execute, no
        status packet — e-Manual); else (False, False)."""
        if pkt_id == self.id:
            return True, True
        item = self.table.resolve("Secondary(Shadow) ID")
        secondary = item.decode(self.mem[item.address:item.end]) if item is not None else 255
        if secondary <= SECONDARY_ID_MAX and pkt_id == secondary:
            return True, False
        return False, False

    def listening(self, now: float) -> bool:
        """False while the servo boots (after REBOOT, FACTORY_RESET or a booting power-on)."""
        return self.booting_until is None or now >= self.booting_until

    # ------------------------------------------------------------------ bench tools
    def set_item(self, name: str, value: int) -> None:
        """Write control-table item ``name`` directly, bypassing every access rule.

        A bench tool (as editing the table with the servo powered on a jig), for tests and
        benchmarks; the host's writes go through :meth:`write`.
        """
        if name not in self._fields:
            raise KeyError(f"{self.table.display_name} has no item {name!r}")
        self._set(name, value)

    def restore(self) -> None:
        """Back to the state at creation: control table, position, no errors, torque off."""
        mem, position = self._creation
        self.mem = bytearray(mem)
        self.pos = self.target = position
        self.vel = 0.0
        self.hand = None
        self.hand_stiffness = None
        self.hand_damping = 0.0
        self.push = None
        self._reset_dynamics()
        self.hardware_error = 0
        self.registered = None
        self._time_profile = None
        self.plugged = True
        self.booting_until = None
        self.temperature = float(self.table.defaults.get("Present Temperature", 30))
        self.last_instruction_t = None

    # ------------------------------------------------------------------ physics
    def _limits(self) -> tuple[float, float]:
        return float(self.get("Min Position Limit")), float(self.get("Max Position Limit"))

    def _profile(self) -> tuple[float, float]:
        """(max velocity ticks/s, acceleration ticks/s²) of the current move."""
        if self._time_profile is not None:
            return self._time_profile
        pv = self._get_or("Profile Velocity", 0)
        pa = self._get_or("Profile Acceleration", 0)
        vlim = self._get_or("Velocity Limit", 0) or 1023
        vmax = (pv if pv else vlim) * self.velocity_unit
        amax = pa * self.accel_unit if pa else math.inf
        return vmax, amax

    @property
    def _external(self) -> bool:
        """An external torque acts: a push, or an impedance hand (a rigid one acts only with
        torque off, and not through the torque model)."""
        return self.push is not None or (self.hand is not None
                                         and self.hand_stiffness is not None)

    def set_hand(self, position: float | Callable[[float], float] | None,
                 stiffness: float | None = None, damping: float | None = None) -> None:
        """Hold the shaft by hand: rigidly (``stiffness`` None) or through an impedance.

        Parameters
        ----------
        position : float, callable or None
            ACTUAL shaft ticks, or a function of the simulated time (s) returning them; None
            lets go.
        stiffness : float or None
            N·m/rad: the hand pushes ``K (θ_hand − θ) − B ω`` on the shaft, torque on or off
            (module docstring). None: the rigid hand (torque off: the shaft is where the hand
            is; turning torque on lets go).
        damping : float or None
            N·m·s/rad (``B``), with a stiffness only; None is 0.

        Raises
        ------
        ValueError
            A negative or non-finite stiffness or damping, a damping without a stiffness, or
            a stiffness too stiff for the 1 ms integration step (``K h² / J ≥ 4``).
        """
        if stiffness is None:
            if damping is not None:
                raise ValueError("a hand's damping needs a stiffness (an impedance hand)")
        else:
            stiffness = float(stiffness)
            damping = 0.0 if damping is None else float(damping)
            for what, v in (("stiffness", stiffness), ("damping", damping)):
                if not (math.isfinite(v) and v >= 0.0):
                    raise ValueError(f"hand {what} must be a finite number >= 0, got {v}")
            top = 4.0 * self.inertia / STEP ** 2
            if stiffness >= top:
                raise ValueError(f"hand stiffness {stiffness:g} N·m/rad too stiff for the "
                                 f"{STEP * 1e3:g} ms step on this shaft (< {top:.4g})")
        self.hand = position if position is None or callable(position) else float(position)
        self.hand_stiffness = None if position is None else stiffness
        self.hand_damping = 0.0 if position is None or damping is None else damping

    def hand_torque(self, now: float) -> float:
        """The impedance hand's torque on the shaft at ``now`` (N·m, ACTUAL frame; 0 for no
        hand or a rigid one): ``K (θ_hand − θ) − B ω`` at the present state."""
        if self.hand is None or self.hand_stiffness is None:
            return 0.0
        hand = float(self.hand(now)) if callable(self.hand) else self.hand
        k = self._rad_per_tick
        return self.hand_stiffness * (hand - self.pos) * k - self.hand_damping * self.vel * k

    def _push_torque(self, now: float) -> float:
        push = self.push
        if push is None:
            return 0.0
        return float(push(now)) if callable(push) else float(push)

    # ------------------------------------------------------------------ Bus Watchdog
    @property
    def watchdog_error(self) -> bool:
        """True while the Bus Watchdog error is flagged (the item reads -1)."""
        return "Bus Watchdog" in self._fields and self.get("Bus Watchdog") == WATCHDOG_ERROR

    def note_instruction(self, now: float) -> None:
        """An instruction packet reached this servo at simulated time ``now``.

        Anything due before it (a watchdog trip) happens first; then the watchdog restarts.
        """
        self.advance(now)
        self.last_instruction_t = now

    def _watchdog_deadline(self) -> float | None:
        if "Bus Watchdog" not in self._fields or self.last_instruction_t is None:
            return None
        setting = self.get("Bus Watchdog")
        if not 1 <= setting <= 127 or not self.torque:
            return None
        return self.last_instruction_t + setting * WATCHDOG_UNIT_S

    def _watchdog_stop(self) -> None:
        """Stop at once where the shaft is, flag the error (e-Manual Bus Watchdog example)."""
        self.vel = 0.0
        self.target = self.pos
        self.ref_pos, self.ref_vel = self.pos, 0.0
        self._time_profile = None
        self._set("Goal Position", round(self.to_frame(self.pos)))
        if self.get("Operating Mode") == 1:
            self._set("Goal Velocity", 0)
        self._set("Bus Watchdog", WATCHDOG_ERROR)
        self.watchdog_trips += 1

    def advance(self, now: float) -> None:
        """Integrate the motion up to simulated time ``now`` (seconds), watchdog included."""
        trip = self._watchdog_deadline()
        if trip is not None and now > trip and self.last_t is not None:
            self._integrate(max(trip, self.last_t))
            self._watchdog_stop()
        self._integrate(now)

    def _integrate(self, now: float) -> None:
        if self.last_t is None:
            self.last_t = now
            self.boot_t = now
            return
        dt = now - self.last_t
        if dt <= 0:
            return
        t0 = self.last_t
        self.last_t = now
        if not self.torque:
            self.current = self.duty = 0.0
            self._integral = 0.0
            if self.hand is not None and self.hand_stiffness is None:
                hand = float(self.hand(now)) if callable(self.hand) else self.hand
                self.vel = (hand - self.pos) / dt if dt > 1e-4 else 0.0
                self.pos = hand
            elif self._external:
                self._dynamics(t0, dt, None)
            else:
                self.vel = 0.0
            self.ref_pos, self.ref_vel, self._off_profile = self.pos, self.vel, False
            return
        mode = self.get("Operating Mode")
        if mode == 1:
            self._velocity_mode(dt)
        elif mode in (3, 4) and not self._external and not self._off_profile:
            self._profile_mode(dt)
        elif mode in (0, 3, 4, 5, 16):
            if mode in (3, 4) and not self._off_profile:
                self.ref_pos, self.ref_vel, self._off_profile = self.pos, self.vel, True
            self._dynamics(t0, dt, mode)
        else:
            self.vel = 0.0

    def _velocity_mode(self, dt: float) -> None:
        _, amax = self._profile()
        goal_v = self.direction() * self.get("Goal Velocity") * self.velocity_unit
        self._ramp_velocity(goal_v, amax, dt, self._note_motion_current)

    def _ramp_velocity(self, goal_v: float, amax: float, dt: float,
                       on_step: Callable[[float], None] | None = None) -> None:
        """Integrate ``dt`` s towards shaft speed ``goal_v`` (ticks/s) at acceleration at most
        ``amax`` (ticks/s², inf: at once), in :data:`STEP` steps; ``on_step(acceleration)``
        after each (velocity mode, wheel mode)."""
        while dt > 0:
            h = min(dt, STEP)
            dv = goal_v - self.vel
            if math.isfinite(amax):
                dv = max(-amax * h, min(amax * h, dv))
            self.vel += dv
            self.pos += self.vel * h
            dt -= h
            if on_step is not None:
                on_step(dv / h)
            if self.vel == goal_v and goal_v == 0:
                break

    @staticmethod
    def _profile_step(pos: float, vel: float, target: float, vmax: float, amax: float,
                      h: float) -> tuple[float, float, bool]:
        """One step of the trapezoidal profile: (position, velocity, arrived)."""
        err = target - pos
        direction = 1.0 if err > 0 else -1.0
        # the fastest speed from which we can still stop at the target (trapezoid ramp-down)
        v_stop = math.sqrt(2.0 * amax * abs(err)) if math.isfinite(amax) else math.inf
        v_des = direction * min(vmax, v_stop, abs(err) / h)
        dv = v_des - vel
        if math.isfinite(amax):
            dv = max(-amax * h, min(amax * h, dv))
        vel += dv
        pos += vel * h
        if (target - pos) * err <= 0:  # reached or crossed the target
            return target, 0.0, True
        return pos, vel, False

    def _profile_mode(self, dt: float) -> None:
        vmax, amax = self._profile()
        target = self.target
        while dt > 0:
            if abs(target - self.pos) < 1e-6 and abs(self.vel) < 1e-6:
                self.pos, self.vel = target, 0.0
                self._note_motion_current(0.0)
                break
            h = min(dt, STEP)
            dt -= h
            v0 = self.vel
            self.pos, self.vel, arrived = self._profile_step(self.pos, self.vel, target,
                                                             vmax, amax, h)
            self._note_motion_current((self.vel - v0) / h)
            if arrived:
                if dt > 0:  # standing at the goal for the rest of the interval
                    self._note_motion_current(0.0)
                break

    def _note_motion_current(self, accel_ticks: float) -> None:
        """Current and PWM a profile's motion costs (no external torque): (J α + b ω) / kt."""
        k = self._rad_per_tick
        w = self.vel * k
        self.current = (self.inertia * accel_ticks * k + self.friction * w) / self.kt
        self.duty = self.current / self.table.units.stall_current_a + w / self.no_load_w

    def _pwm_cap(self) -> float:
        """Largest duty (0..1): Goal PWM and PWM Limit."""
        pwm_max = self.table.units.pwm_max
        cap = self._get_or("PWM Limit", pwm_max)
        if "Goal PWM" in self._fields:
            cap = min(cap, abs(self.get("Goal PWM")))
        return min(cap, pwm_max) / pwm_max

    def _current_amps(self, raw: int) -> float:
        unit = self.table.units.current_ma
        return raw * unit / 1000.0 if unit else math.inf

    def _dynamics(self, t0: float, dt: float, mode: int | None) -> None:
        """The torque model over ``dt`` from ``t0`` (``mode`` None: torque off, motor idle)."""
        units = self.table.units
        k = self._rad_per_tick
        i_stall = units.stall_current_a
        d = self.direction()
        cap = self._pwm_cap()
        vmax, amax = self._profile()
        limit = math.inf
        if mode in (3, 4):
            limit = self._current_amps(self._get_or("Current Limit", 0)) \
                if "Current Limit" in self._fields else math.inf
        elif mode == 5:
            limit = self._current_amps(abs(self._get_or("Goal Current", 0)))
        kpp = self._get_or("Position P Gain", 0) / 128.0
        kpi = self._get_or("Position I Gain", 0) / 65536.0
        kpd = self._get_or("Position D Gain", 0) / 16.0
        t = t0
        while dt > 1e-12:
            h = min(dt, STEP)
            dt -= h
            t += h
            w = self.vel * k
            back = w / self.no_load_w
            if mode is None:
                i = 0.0
                duty = 0.0
            elif mode == 16:
                duty = d * self.get("Goal PWM") / units.pwm_max
                duty = max(-cap, min(cap, duty))
                i = i_stall * (duty - back)
            elif mode == 0:
                goal = d * self._current_amps(self.get("Goal Current"))
                lim = self._current_amps(self._get_or("Current Limit", 0)) \
                    if "Current Limit" in self._fields else math.inf
                goal = max(-lim, min(lim, goal))
                i = max(i_stall * (-cap - back), min(i_stall * (cap - back), goal))
                duty = i / i_stall + back
            else:
                if abs(self.target - self.ref_pos) > 1e-9 or self.ref_vel != 0.0:
                    self.ref_pos, self.ref_vel, _ = self._profile_step(
                        self.ref_pos, self.ref_vel, self.target, vmax, amax, h)
                err = self.ref_pos - self.pos
                self._integral += err * h * 1000.0
                u = (kpp * err + kpi * self._integral
                     + kpd * (self.ref_vel - self.vel) * 1e-3) / units.pwm_max
                duty = max(-cap, min(cap, u))
                i = i_stall * (duty - back)
                if abs(i) > limit:
                    i = math.copysign(limit, i)
                    duty = i / i_stall + back
            tau = self.kt * i + self._push_torque(t) - self.friction * w
            if self.hand is not None and self.hand_stiffness is not None:  # impedance hand
                hand = float(self.hand(t)) if callable(self.hand) else self.hand
                tau += self.hand_stiffness * (hand - self.pos) * k
                # the damping implicitly: ω' = (ω + τ h / J) / (1 + B h / J)
                self.vel = (self.vel + tau / self.inertia / k * h) \
                    / (1.0 + self.hand_damping * h / self.inertia)
            else:
                self.vel += tau / self.inertia / k * h
            self.pos += self.vel * h
            self.current, self.duty = i, duty
        if mode in (3, 4) and not self._external and self._off_profile \
                and abs(self.ref_pos - self.pos) < 0.5 and abs(self.vel - self.ref_vel) < 1.0 \
                and self.ref_pos == self.target:
            # back on the profile: the exact trapezoid takes over again
            self.pos, self.vel, self._off_profile = self.ref_pos, self.ref_vel, False
            self._integral = 0.0

    def current_mode_equilibrium(self, push_nm: float) -> tuple[float, float]:
        """Analytic steady state of Current Control Mode under a constant push.

        Solves ``kt·i(ω) + τ_push − b·ω = 0`` with ``i(ω)`` = Goal Current (≤ Current Limit)
        bounded by what the PWM allows at speed ω (module docstring), by bisection; the
        reference the integrated model is checked against.

        Parameters
        ----------
        push_nm : float
            External torque, N·m, ACTUAL frame.

        Returns
        -------
        (float, float)
            Shaft speed (rad/s) and motor current (A), both ACTUAL frame.
        """
        i_stall = self.table.units.stall_current_a
        cap = self._pwm_cap()
        goal = self.direction() * self._current_amps(self.get("Goal Current"))
        lim = self._current_amps(self._get_or("Current Limit", 0)) \
            if "Current Limit" in self._fields else math.inf
        goal = max(-lim, min(lim, goal))

        def current(w: float) -> float:
            back = w / self.no_load_w
            return max(i_stall * (-cap - back), min(i_stall * (cap - back), goal))

        def net(w: float) -> float:
            return self.kt * current(w) + push_nm - self.friction * w

        lo, hi = -1e4, 1e4  # rad/s; net() decreases with w
        for _ in range(200):
            mid = 0.5 * (lo + hi)
            if net(mid) > 0:
                lo = mid
            else:
                hi = mid
        w = 0.5 * (lo + hi)
        return w, current(w)

    def refresh(self, now: float) -> None:
        """Advance to ``now`` and write the present values into the control table."""
        self.advance(now)
        d = self.direction()
        noise = self.rng.gauss(0.0, self.noise_ticks) if self.noise_ticks > 0 else 0.0
        self._set("Present Position", round(self.to_frame(self.pos + noise)))
        vel_units = round(d * self.vel / self.velocity_unit)
        self._set("Present Velocity", vel_units)
        self._set("Position Trajectory", round(self.to_frame(self.target)))
        self._set("Velocity Trajectory", vel_units)
        units = self.table.units
        if units.current_ma:
            self._set("Present Current", round(d * self.current * 1000.0 / units.current_ma))
        self._set("Present PWM", round(d * self.duty * units.pwm_max))
        # Present Load: 0.1 % of the stall current (models without current sensing)
        self._set("Present Load", round(d * self.current / units.stall_current_a * 1000.0))
        moving = abs(self.vel) > 0 or (self.torque and abs(self.target - self.pos) >
                                       self._get_or("Moving Threshold", 0))
        self._set("Moving", int(moving))
        in_position = abs(self.target - self.pos) <= self._get_or("Moving Threshold", 0)
        self._set("Moving Status", (1 if in_position else 0) | (2 if moving else 0))
        self._set("Realtime Tick", int((now - self.boot_t) * 1000) % 32768)
        self._set("Present Temperature", round(self.temperature))
        self._set("Hardware Error Status", self.hardware_error)
        self._set("Registered Instruction", int(self.registered is not None))

    def raise_error(self, bits: int) -> None:
        """Set Hardware Error Status bits; bits in Shutdown (63) drop the torque."""
        self.hardware_error |= bits
        if self.hardware_error & self._get_or("Shutdown", 0):
            self._set("Torque Enable", 0)

    def set_temperature(self, celsius: float) -> None:
        """Set the winding temperature; above the Temperature Limit raises overheating."""
        self.temperature = float(celsius)
        if celsius > self.get("Temperature Limit"):
            self.raise_error(HARDWARE_ERRORS["overheating"])

    @property
    def error_byte(self) -> int:
        """Alert bit to put on every status packet."""
        return ALERT if self.hardware_error else 0

    # ------------------------------------------------------------------ instructions
    def read(self, address: int, length: int, now: float) -> tuple[int, bytes]:
        """READ: ``(error code, data)``; data is zero-filled on error (as hardware does).

        Indirect Data bytes read the byte their Indirect Address names.
        """
        if length == 0:
            return ErrorCode.DATA_LENGTH, b""
        if address + length > self.table.size:
            return ErrorCode.ACCESS, bytes(length)
        self.refresh(now)
        data = bytearray(self.mem[address:address + length])
        if self._indirect_data:
            for a in range(address, address + length):
                slot = self._indirect_data.get(a)
                if slot is not None:
                    target = self._indirect_target(slot)
                    if target is not None and target != a:
                        data[a - address] = self.mem[target]
        return ErrorCode.NONE, bytes(data)

    def _indirect_target(self, slot: int) -> int | None:
        target = int.from_bytes(self.mem[slot:slot + 2], "little")
        return target if self.table.eeprom_end <= target < self.table.size else None

    def write(self, address: int, data: bytes, now: float, *, ram_only: bool = False) -> int:
        """WRITE: apply ``data`` at ``address`` all-or-nothing; returns the error code.

        Parameters
        ----------
        address : int
        data : bytes
        now : float
            Simulated time, s.
        ram_only : bool
            Refuse EEPROM items with an Access Error (an instruction sent to the Secondary ID).
        """
        table = self.table
        end = address + len(data)
        if not data:
            return ErrorCode.DATA_LENGTH
        if end > table.size:
            return ErrorCode.ACCESS
        plain_from = table["Indirect Address 1"].address if "Indirect Address 1" in table \
            else table.size
        touched: list[ControlItem | None] = []
        patches: dict[int, int] = {}  # address -> byte, indirect targets and slots
        indirect: dict[int, int] = {}
        slots: dict[int, int] = {}
        a = address
        while a < end:
            byte = data[a - address]
            if a in self._indirect_data:
                target = self._indirect_target(self._indirect_data[a])
                if target is None or target == a:
                    touched.append(None)
                    patches[a] = byte
                else:
                    indirect[target] = byte
                a += 1
                continue
            if a in self._indirect_slot_bytes:
                first = a if a in self._indirect_slots else a - 1
                if first < address or first + 2 > end:
                    return ErrorCode.DATA_LENGTH
                slots[first] = int.from_bytes(data[first - address:first - address + 2],
                                              "little")
                touched.append(None)
                a = first + 2
                continue
            item = table.item_covering(a)
            if item is None:
                if a >= plain_from:
                    touched.append(None)
                patches[a] = byte  # a reserved byte takes what it is sent (as it always did)
                a += 1
                continue
            if item.address < address or item.end > end:
                return ErrorCode.DATA_LENGTH
            touched.append(item)
            for j in range(item.size):
                patches[item.address + j] = data[item.address - address + j]
            a = item.end
        if not touched and not indirect:
            return ErrorCode.ACCESS
        items = [it for it in touched if it is not None]
        # indirect targets: the items they fall in, written with the bytes given (the rest kept)
        for target in sorted(indirect):
            item = table.item_covering(target)
            if item is None:
                patches[target] = indirect[target]
                continue
            if item not in items:
                items.append(item)
            patches[target] = indirect[target]
        values: dict[str, int] = {}
        for item in items:
            raw = bytes(patches.get(item.address + j, self.mem[item.address + j])
                        for j in range(item.size))
            values[item.name] = item.decode(raw)
        for item in items:
            if not item.writable or item.name in table.read_only:
                return ErrorCode.ACCESS
            if item.address < table.eeprom_end and (self.torque or ram_only):
                return ErrorCode.ACCESS
        for value in slots.values():
            if not table.eeprom_end <= value < table.size:
                return ErrorCode.DATA_RANGE
        error = self._validate(values)
        if error:
            return error
        self.advance(now)
        if self.watchdog_error:
            # e-Manual: the Goal items turn read-only (Data Range Error) until 0 is written
            # to Bus Watchdog; any other value keeps the error (our reading: also refused)
            if any(n in values for n in _GOAL_ITEMS) or values.get("Bus Watchdog", 0) != 0:
                return ErrorCode.DATA_RANGE
        was_torque = self.torque
        for a, byte in patches.items():
            self.mem[a] = byte
        for slot, value in slots.items():
            self.mem[slot:slot + 2] = value.to_bytes(2, "little")
        self._apply_effects(values, was_torque)
        return ErrorCode.NONE

    def _validate(self, values: dict[str, int]) -> int:
        """Range and limit checks of the item values a write would set (0: accepted)."""
        table = self.table
        for name, value in values.items():
            lo_hi = table.ranges.get(name)
            if lo_hi and not lo_hi[0] <= value <= lo_hi[1]:
                return ErrorCode.DATA_RANGE
            if name == "Operating Mode" and value not in table.operating_modes:
                return ErrorCode.DATA_RANGE
            if name == "Baud Rate" and value not in table.baud_rates:
                return ErrorCode.DATA_RANGE
        limits = {"Goal Velocity": "Velocity Limit", "Goal PWM": "PWM Limit",
                  "Goal Current": "Current Limit"}
        for name, limit in limits.items():
            if name in values and limit in table:
                lim = values.get(limit, self.get(limit))
                if abs(values[name]) > lim:
                    return ErrorCode.DATA_LIMIT
        if "Goal Position" in values and self._goal_limits_refused():
            mode = values.get("Operating Mode", self._get_or("Operating Mode", 3))
            if mode == 3:
                lo = values.get("Min Position Limit", self._get_or("Min Position Limit", 0))
                hi = values.get("Max Position Limit", self._get_or("Max Position Limit", 0))
                if not lo <= values["Goal Position"] <= hi:
                    return ErrorCode.DATA_LIMIT
        return ErrorCode.NONE

    def _goal_limits_refused(self) -> bool:
        """True for models that answer a Goal Position beyond the position limits with a
        Data Limit Error (P-series / PRO(A)); the X series clamps it."""
        return self.table.model.startswith(_LIMIT_REFUSING_FAMILIES)

    def _apply_effects(self, values: dict[str, int], was_torque: bool) -> None:
        """What writing ``values`` (already in memory) does to the servo's state."""
        goal_written = any(n in values for n in _GOAL_ITEMS)
        if (goal_written and not was_torque and "Torque Enable" not in values
                and self._get_or("Drive Mode", 0) & 0x08):
            # Drive Mode bit 3 "Torque On by Goal Update" (X-series firmware v52+)
            self._set("Torque Enable", 1)
            values = {**values, "Torque Enable": 1}
            if "Goal Position" not in values:
                self._set("Goal Position", round(self.to_frame(self.pos)))
        if "Torque Enable" in values:
            if values["Torque Enable"] and self.hardware_error & self._get_or("Shutdown", 0):
                self._set("Torque Enable", 0)  # shut down until reboot
            elif values["Torque Enable"] and not was_torque:
                self.vel = 0.0
                if self.hand_stiffness is None:
                    self.hand = None  # a rigid hand lets go; an impedance hand keeps holding
                if self._get_or("Operating Mode", 3) == 3:
                    self._wrap_one_turn()  # e-Manual: torque on in Position Control Mode
                self._reset_dynamics()
                if "Goal Position" not in values:
                    self._set("Goal Position", round(self.to_frame(self.pos)))
                self.target = self.pos
        if values.get("Operating Mode") == 3 and "Torque Enable" not in values:
            self._wrap_one_turn()  # e-Manual: Operating Mode changed to Position Control Mode
            self.target = self.ref_pos = self.pos
        if "Goal Position" in values or "Torque Enable" in values or any(
                n in values for n in ("Min Position Limit", "Max Position Limit")):
            self._update_target()

    def _update_target(self) -> None:
        goal = float(self.get("Goal Position"))
        if self.get("Operating Mode") == 3:
            lo, hi = self._limits()
            goal = min(max(goal, lo), hi)
        goal = self.from_frame(goal)
        self.target = goal
        self._time_profile = None
        if self._get_or("Drive Mode", 0) & 0x04:
            # time-based profile (Drive Mode bit 2): Profile Velocity is the time to reach the
            # goal and Profile Acceleration the ramp time, both ms; the ramp is at most half
            total = self.get("Profile Velocity") / 1000.0
            ramp = min(self.get("Profile Acceleration") / 1000.0, total / 2.0)
            if total > 0:
                v = abs(goal - self.pos) / (total - ramp)
                self._time_profile = (v, v / ramp if ramp > 0 else math.inf)

    def clear_multi_turn(self, now: float) -> int:
        """CLEAR (multi-turn): the shaft's turn count dropped, only while it stands still."""
        self.advance(now)
        if self.vel != 0:
            return ErrorCode.RESULT_FAIL
        self._wrap_one_turn()
        self.target = self.ref_pos = self.pos
        return ErrorCode.NONE

    def _wrap_one_turn(self) -> None:
        """The shaft's count back within one turn about the power-on position (X series
        0..4095, P-series ±half a turn): e-Manual "Present Position(132)" — when torque is
        turned on or the Operating Mode changed to Position Control Mode, at power-on and after
        REBOOT (Homing Offset still applies on top)."""
        lo = float(self.table.home_ticks) - self.ticks_per_rev / 2.0
        self.pos = lo + (self.pos - lo) % self.ticks_per_rev

    def reboot(self) -> None:
        """REBOOT: RAM back to defaults, hardware errors cleared, torque off; silent for
        :attr:`boot_time_s` from the instruction."""
        eeprom_end = self.table.eeprom_end
        keep = bytes(self.mem[:eeprom_end])
        self.mem = self._default_memory()
        self.mem[:eeprom_end] = keep
        self.hardware_error = 0
        self.registered = None
        self.vel = 0.0
        self._wrap_one_turn()  # e-Manual: at power-on and after REBOOT
        self.target = self.pos
        self._reset_dynamics()
        if self.temperature > self.get("Temperature Limit"):
            self.temperature = float(self.table.defaults.get("Present Temperature", 30))
        self.boot_t = self.last_t or 0.0
        self.booting_until = self.boot_t + self.boot_time_s

    def factory_reset(self, option: int) -> None:
        """FACTORY_RESET: 0xFF all, 0x01 all but ID, 0x02 all but ID and baud rate."""
        dxl_id, baud = self.id, self.get("Baud Rate")
        self.mem = self._default_memory()
        self._set("Baud Rate", self.table.defaults.get("Baud Rate", 1))  # e-Manual: 57600
        if option in (0x01, 0x02):
            self._set("ID", dxl_id)
        if option == 0x02:
            self._set("Baud Rate", baud)
        self.reboot()

    def _baud_index_of(self, baud_rate: int) -> int:
        for index, rate in self.table.baud_rates.items():
            if rate == baud_rate:
                return index
        rates = self.table.baud_rates.values()
        raise ValueError(f"baud rate {baud_rate} is not a {self.table.display_name} rate; use "
                         f"one of {', '.join(str(b) for b in rates)}")


def _baud_index(baud_rate: int) -> int:
    """Baud Rate item value of ``baud_rate`` on the X series (kept for importers)."""
    for index, rate in BAUD_RATES.items():
        if rate == baud_rate:
            return index
    raise ValueError(f"baud rate {baud_rate} is not an X-series rate; use one of "
                     f"{', '.join(str(b) for b in BAUD_RATES.values())}")
