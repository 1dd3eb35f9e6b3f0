"""One simulated Dynamixel X-series servo: control table, motion, hardware errors, Bus Watchdog.

State and behaviour only — no I/O: :class:`~rig.sim.dynamixel.bus.DynamixelBus` feeds it the
instructions it receives and serialises access with its lock.

Motion (position modes 3, 4, 5) is a trapezoidal velocity profile from Profile Velocity
(0.229 rev/min units) and Profile Acceleration (214.577 rev/min² units), 0 meaning "unlimited"
(Velocity Limit / instantaneous), or the time-based profile of Drive Mode bit 2; velocity mode
(1) ramps to Goal Velocity; integrated lazily, in :data:`STEP` steps, whenever the servo is
observed, on the bus's clock.

Bus Watchdog (address 98, X-series e-Manual §2.4.27, ``control_table_buswatchdog.md``):
0 off, 1..127 on in 20 ms units, monitored while Torque Enable is 1. When no instruction packet
reached the servo for longer than that, it stops at once (the e-Manual: Profile Acceleration
and Profile Velocity "applied as 0") — Goal Position becomes the present position, Goal
Velocity 0 — and Bus Watchdog reads -1 (0xFF). While it does, writing a Goal item (PWM 100,
Current 102, Velocity 104, Position 116) is refused with a Data Range Error; writing 0 to Bus
Watchdog clears the error. The trip is evaluated lazily at its exact simulated time.
"""

from __future__ import annotations

import math
import random
from collections.abc import Callable

from firmware_protocol.dynamixel.control_table import (
    BAUD_RATES,
    OPERATING_MODES,
    ControlTable,
    load_control_table,
)
from firmware_protocol.dynamixel.packets import ALERT, ErrorCode

__all__ = [
    "ACCEL_UNIT",
    "HARDWARE_ERRORS",
    "STEP",
    "TICKS_PER_REV",
    "VELOCITY_UNIT",
    "WATCHDOG_ERROR",
    "WATCHDOG_UNIT_S",
    "SimServo",
]

TICKS_PER_REV = 4096
VELOCITY_UNIT = 0.229 * TICKS_PER_REV / 60.0  # ticks/s per Profile/Present Velocity unit
ACCEL_UNIT = 214.577 * TICKS_PER_REV / 3600.0  # ticks/s² per Profile Acceleration unit
STEP = 0.001
"""Integration step of the motion, s."""
WATCHDOG_UNIT_S = 0.020
"""Bus Watchdog unit, s (e-Manual: 20 ms)."""
WATCHDOG_ERROR = 0xFF
"""Bus Watchdog byte while its error is flagged (-1 as a signed byte)."""

HARDWARE_ERRORS = {
    "input_voltage": 0x01,
    "overheating": 0x04,
    "encoder": 0x08,
    "electrical_shock": 0x10,
    "overload": 0x20,
}
"""Hardware Error Status (address 70) bits by name (X-series e-Manual)."""

_GOAL_ITEMS = ("Goal PWM", "Goal Current", "Goal Velocity", "Goal Position")


class SimServo:
    """State and behaviour of one simulated servo (not thread-safe: the bus locks around it).

    Parameters
    ----------
    dxl_id : int
        ID, 0..252.
    model : str or int
        e-Manual name, file stem or model number (see
        :func:`firmware_protocol.dynamixel.control_table.load_control_table`).
    baud_rate : int
        Initial Baud Rate in bit/s (must be one of the X-series rates).
    return_delay_us : int or None
        Initial Return Delay Time in µs (even, 0..508); None keeps the e-Manual default 500 µs.
    position : float
        Initial shaft position, ticks.
    noise_ticks : float
        Standard deviation of the encoder noise added to Present Position, ticks.
    rng : random.Random
        Source of the encoder noise.
    """

    def __init__(self, dxl_id: int, model: str | int = "XM430-W350", *,
                 baud_rate: int = 1_000_000, return_delay_us: int | None = None,
                 position: float = 2048.0, noise_ticks: float = 0.0,
                 rng: random.Random | None = None):
        if not 0 <= dxl_id <= 252:
            raise ValueError(f"servo id must be 0..252, got {dxl_id}")
        self.table: ControlTable = load_control_table(model)
        # name -> (first byte, one past last, signed, size): the hot path of get/_set
        self._fields = {n: (it.address, it.end, it.signed, it.size)
                        for n, it in self.table.items.items()}
        self.mem = self.table.default_memory()
        self._baud_index = _baud_index(baud_rate)
        self._set("ID", dxl_id)
        self._set("Baud Rate", self._baud_index)
        if return_delay_us is not None:
            if not 0 <= return_delay_us <= 508:
                raise ValueError(f"return delay must be 0..508 µs, got {return_delay_us}")
            self._set("Return Delay Time", return_delay_us // 2)
        self._eeprom_boot = bytes(self.mem[:64])
        self.noise_ticks = float(noise_ticks)
        self.rng = rng or random.Random(dxl_id)
        self.pos = float(position)
        self.vel = 0.0  # ticks/s
        self.target = float(position)
        self.hand: float | Callable[[float], float] | None = None
        self.hardware_error = 0
        self.temperature = float(self.get("Present Temperature"))
        self.registered: tuple[int, bytes] | None = None
        self._time_profile: tuple[float, float] | None = None
        self.plugged = True
        self.last_t: float | None = None
        self.boot_t = 0.0
        self.last_instruction_t: float | None = None
        """Simulated time the last instruction packet reached this servo (Bus Watchdog)."""
        self.watchdog_trips = 0
        """How many times the Bus Watchdog stopped this servo."""
        self._creation = (bytes(self.mem), float(position))

    # ------------------------------------------------------------------ memory helpers
    def get(self, name: str) -> int:
        """Current value of control-table item ``name``."""
        start, end, signed, _ = self._fields[name]
        return int.from_bytes(self.mem[start:end], "little", signed=signed)

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
        return BAUD_RATES.get(self.get("Baud Rate"), 57600)

    @property
    def return_delay(self) -> float:
        """Return Delay Time in seconds."""
        return self.get("Return Delay Time") * 2e-6

    @property
    def torque(self) -> bool:
        """Torque Enable."""
        return bool(self.get("Torque Enable"))

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
        self.hardware_error = 0
        self.registered = None
        self._time_profile = None
        self.plugged = True
        self.temperature = float(self.table.defaults.get("Present Temperature", 30))
        self.last_instruction_t = None

    # ------------------------------------------------------------------ physics
    def _limits(self) -> tuple[float, float]:
        return float(self.get("Min Position Limit")), float(self.get("Max Position Limit"))

    def _profile(self) -> tuple[float, float]:
        """(max velocity ticks/s, acceleration ticks/s²) of the current move."""
        if self._time_profile is not None:
            return self._time_profile
        pv = self.get("Profile Velocity")
        pa = self.get("Profile Acceleration")
        vlim = self.get("Velocity Limit") or 1023
        vmax = (pv if pv else vlim) * VELOCITY_UNIT
        amax = pa * ACCEL_UNIT if pa else math.inf
        return vmax, amax

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
        self._time_profile = None
        self._set("Goal Position", round(self.pos))
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
        self.last_t = now
        if not self.torque:
            if self.hand is not None:
                hand = float(self.hand(now)) if callable(self.hand) else self.hand
                self.vel = (hand - self.pos) / dt if dt > 1e-4 else 0.0
                self.pos = hand
            else:
                self.vel = 0.0
            return
        mode = self.get("Operating Mode")
        vmax, amax = self._profile()
        if mode == 1:  # velocity control
            goal_v = self.get("Goal Velocity") * VELOCITY_UNIT
            while dt > 0:
                h = min(dt, STEP)
                dv = goal_v - self.vel
                if math.isfinite(amax):
                    dv = max(-amax * h, min(amax * h, dv))
                self.vel += dv
                self.pos += self.vel * h
                dt -= h
                if self.vel == goal_v and goal_v == 0:
                    break
            return
        if mode not in (3, 4, 5):  # current / PWM control: not modelled, the shaft stays
            self.vel = 0.0
            return
        target = self.target
        while dt > 0:
            err = target - self.pos
            if abs(err) < 1e-6 and abs(self.vel) < 1e-6:
                self.pos, self.vel = target, 0.0
                break
            h = min(dt, STEP)
            dt -= h
            direction = 1.0 if err > 0 else -1.0
            # the fastest speed from which we can still stop at the target (trapezoid ramp-down)
            v_stop = math.sqrt(2.0 * amax * abs(err)) if math.isfinite(amax) else math.inf
            v_des = direction * min(vmax, v_stop, abs(err) / h)
            dv = v_des - self.vel
            if math.isfinite(amax):
                dv = max(-amax * h, min(amax * h, dv))
            self.vel += dv
            self.pos += self.vel * h
            if (target - self.pos) * err <= 0:  # reached or crossed the target
                self.pos, self.vel = target, 0.0
                break

    def refresh(self, now: float) -> None:
        """Advance to ``now`` and write the present values into the control table."""
        self.advance(now)
        noise = self.rng.gauss(0.0, self.noise_ticks) if self.noise_ticks > 0 else 0.0
        present = round(self.pos + noise)
        self._set("Present Position", present)
        self._set("Present Velocity", round(self.vel / VELOCITY_UNIT))
        self._set("Position Trajectory", round(self.target))
        self._set("Velocity Trajectory", round(self.vel / VELOCITY_UNIT))
        moving = abs(self.vel) > 0 or (self.torque and abs(self.target - self.pos) >
                                       self.get("Moving Threshold"))
        self._set("Moving", int(moving))
        in_position = abs(self.target - self.pos) <= self.get("Moving Threshold")
        self._set("Moving Status", (1 if in_position else 0) | (2 if moving else 0))
        self._set("Realtime Tick", int((now - self.boot_t) * 1000) % 32768)
        self._set("Present Temperature", round(self.temperature))
        self._set("Hardware Error Status", self.hardware_error)
        self._set("Registered Instruction", int(self.registered is not None))

    def raise_error(self, bits: int) -> None:
        """Set Hardware Error Status bits; bits in Shutdown (63) drop the torque."""
        self.hardware_error |= bits
        if self.hardware_error & self.get("Shutdown"):
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
        """READ: ``(error code, data)``; data is zero-filled on error (as hardware does)."""
        if length == 0:
            return ErrorCode.DATA_LENGTH, b""
        if address + length > self.table.size:
            return ErrorCode.ACCESS, bytes(length)
        self.refresh(now)
        return ErrorCode.NONE, bytes(self.mem[address:address + length])

    def write(self, address: int, data: bytes, now: float) -> int:
        """WRITE: apply ``data`` at ``address`` all-or-nothing; returns the error code."""
        table = self.table
        end = address + len(data)
        if not data:
            return ErrorCode.DATA_LENGTH
        if end > table.size:
            return ErrorCode.ACCESS
        plain_from = table["Indirect Address 1"].address if "Indirect Address 1" in table \
            else table.size
        touched = []
        a = address
        while a < end:
            item = table.item_covering(a)
            if item is None:
                if a >= plain_from:
                    touched.append(None)
                a += 1
                continue
            if item.address < address or item.end > end:
                return ErrorCode.DATA_LENGTH
            touched.append(item)
            a = item.end
        if not touched:
            return ErrorCode.ACCESS
        items = [it for it in touched if it is not None]
        for item in items:
            if not item.writable or (item.eeprom and self.torque):
                return ErrorCode.ACCESS
        values = {it.name: it.decode(data[it.address - address:it.end - address]) for it in items}
        for name, value in values.items():
            lo_hi = table.ranges.get(name)
            if lo_hi and not lo_hi[0] <= value <= lo_hi[1]:
                return ErrorCode.DATA_RANGE
            if name == "Operating Mode" and value not in OPERATING_MODES:
                return ErrorCode.DATA_RANGE
        limits = {"Goal Velocity": "Velocity Limit", "Goal PWM": "PWM Limit",
                  "Goal Current": "Current Limit"}
        for name, limit in limits.items():
            if name in values and limit in table:
                lim = values.get(limit, self.get(limit))
                if abs(values[name]) > lim:
                    return ErrorCode.DATA_LIMIT
        self.advance(now)
        if self.watchdog_error:
            # e-Manual: the Goal items turn read-only (Data Range Error) until 0 is written
            # to Bus Watchdog; any other value keeps the error (our reading: also refused)
            if any(n in values for n in _GOAL_ITEMS) or values.get("Bus Watchdog", 0) != 0:
                return ErrorCode.DATA_RANGE
        was_torque = self.torque
        self.mem[address:end] = data
        if "Torque Enable" in values:
            if values["Torque Enable"] and self.hardware_error & self.get("Shutdown"):
                self._set("Torque Enable", 0)  # shut down until reboot
            elif values["Torque Enable"] and not was_torque:
                self.vel = 0.0
                self.hand = None
                self._set("Goal Position", round(self.pos))
                self.target = self.pos
        if "Goal Position" in values or "Torque Enable" in values or any(
                n in values for n in ("Min Position Limit", "Max Position Limit")):
            self._update_target()
        return ErrorCode.NONE

    def _update_target(self) -> None:
        goal = float(self.get("Goal Position"))
        if self.get("Operating Mode") == 3:
            lo, hi = self._limits()
            goal = min(max(goal, lo), hi)
        self.target = goal
        self._time_profile = None
        if self.get("Drive Mode") & 0x04:
            # time-based profile (Drive Mode bit 2): Profile Velocity is the time to reach the
            # goal and Profile Acceleration the ramp time, both ms; the ramp is at most half
            total = self.get("Profile Velocity") / 1000.0
            ramp = min(self.get("Profile Acceleration") / 1000.0, total / 2.0)
            if total > 0:
                v = abs(goal - self.pos) / (total - ramp)
                self._time_profile = (v, v / ramp if ramp > 0 else math.inf)

    def reboot(self) -> None:
        """REBOOT: RAM back to defaults, hardware errors cleared, torque off."""
        keep = bytes(self.mem[:64])
        self.mem = self.table.default_memory()
        self.mem[:64] = keep
        self.hardware_error = 0
        self.registered = None
        self.vel = 0.0
        self.target = self.pos
        if self.temperature > self.get("Temperature Limit"):
            self.temperature = float(self.table.defaults.get("Present Temperature", 30))
        self.boot_t = self.last_t or 0.0

    def factory_reset(self, option: int) -> None:
        """FACTORY_RESET: 0xFF all, 0x01 all but ID, 0x02 all but ID and baud rate."""
        dxl_id, baud = self.id, self.get("Baud Rate")
        self.mem = self.table.default_memory()
        self._set("Baud Rate", 1)  # e-Manual factory default 57600 bps
        if option in (0x01, 0x02):
            self._set("ID", dxl_id)
        if option == 0x02:
            self._set("Baud Rate", baud)
        self.reboot()



def _baud_index(baud_rate: int) -> int:
    for index, rate in BAUD_RATES.items():
        if rate == baud_rate:
            return index
    raise ValueError(f"baud rate {baud_rate} is not an X-series rate; use one of "
                     f"{', '.join(str(b) for b in BAUD_RATES.values())}")


