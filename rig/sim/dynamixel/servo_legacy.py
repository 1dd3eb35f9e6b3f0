"""A simulated servo with an AX / MX (Protocol 1.0) or XL-320 style control table.

State and behaviour only, no I/O (the bus feeds it instructions, under its lock), like
:class:`~rig.sim.dynamixel.servo.SimServo`, whose memory helpers it shares; every per-model
fact comes from the model's :class:`~firmware_protocol.dynamixel.control_table.ControlTable`
(e-Manual pages cited in :mod:`firmware_protocol.dynamixel.tables_protocol1`).

What differs from the X series (AX-12A / MX-28 e-Manual, "Control Table"):

* **Modes from the angle limits**: CW Angle Limit (6) and CCW Angle Limit (8) are the
  position limits; both 0 is wheel mode; on the MX series both 4095 is multi-turn mode (not
  modelled: the shaft is held). The XL-320 has a Control Mode item (11): 1 wheel, 2 joint.
* **Moving Speed (32)**: in joint mode the speed of the move, in ``units.velocity_rpm``
  (0.111 rpm on the AX, 0.114 on the MX), 0 meaning the no-load maximum, values above it
  capped to it; in wheel mode the output as sign-magnitude (bits 0-9 of 1023, bit 10 the
  direction: 0 CCW = increasing position, 1 CW), here a fraction of the no-load speed.
* **Goal Acceleration (73, MX)**: 0 unlimited, else ``units.accel_rpm2`` per unit.
* **Goal Position outside the angle limits** (joint mode): the e-Manual's Angle Limit Error
  (Protocol 1.0 status bit 1); our reading: the write is refused, the goal unchanged.
* **Torque Limit (34)**: 0 leaves the shaft free (no torque), like torque off.
* **Present Speed / Present Load**: sign-magnitude, bit 10 set for CW. Present Load stays 0
  (no load model on these servos).
* **Hardware errors** are the Protocol 1.0 status bits (input voltage 0x01, overheating 0x04,
  overload 0x20 — the same bit values as the X series' Hardware Error Status); a bit also set
  in Shutdown (18) drops the torque until it is cleared (REBOOT or power cycle).
* EEPROM ends at ``table.eeprom_end`` (24 on AX/MX); no Bus Watchdog.

:meth:`read` / :meth:`write` return Protocol 2.0 result codes like SimServo (so an XL-320,
which speaks 2.0, runs through the same bus code); :meth:`error1_of` maps them to 1.0 bits.
"""

from __future__ import annotations

import math

from firmware_protocol.dynamixel.control_table import ControlTable, load_control_table
from firmware_protocol.dynamixel.packets import ALERT, ErrorCode
from firmware_protocol.dynamixel.protocol1 import Error1
from rig.sim.dynamixel.servo import STEP, SimServo

__all__ = ["ANGLE_LIMIT", "LegacyServo", "is_legacy_table", "nearest_baud_index"]

ANGLE_LIMIT = 0x100
"""Result code :meth:`LegacyServo.write` returns for a goal outside the angle limits (beyond
the 2.0 codes; the 2.0 dispatch reports it as a data limit error)."""

_HW_TO_1 = Error1.INPUT_VOLTAGE | Error1.OVERHEATING | Error1.OVERLOAD


def is_legacy_table(table: ControlTable) -> bool:
    """True for the tables :class:`LegacyServo` simulates (Protocol 1.0, or angle limits)."""
    return table.protocol == 1.0 or "CW Angle Limit" in table


def nearest_baud_index(table: ControlTable, baud_rate: int) -> int:
    """The Baud Rate value of ``table`` whose rate is closest to ``baud_rate``, within ±3 %
    (a 1.0 servo at 57,142 bit/s talks to a host at 57,600)."""
    index, rate = min(table.baud_rates.items(), key=lambda kv: abs(kv[1] - baud_rate))
    if abs(rate - baud_rate) > 0.03 * rate:
        raise ValueError(f"baud rate {baud_rate} is not a {table.display_name} rate (nearest "
                         f"{rate})")
    return index


def _sign_magnitude(value: float) -> int:
    """Bit 10 set for negative (CW) values, magnitude clipped to 1023."""
    mag = min(1023, round(abs(value)))
    return mag | (0x400 if value < 0 and mag else 0)


class LegacyServo(SimServo):
    """One simulated AX / MX-1.0 / XL-320 style servo (see the module docstring).

    Parameters
    ----------
    dxl_id : int
        ID, 0..253 (Protocol 1.0) or 0..252.
    model : str, int or ControlTable
        e-Manual name, model number or an already loaded table.
    protocol : float, optional
        1.0 asks for the model's Protocol 1.0 table (``"MX-28"`` on 1.0 firmware).
    baud_rate, return_delay_us, position, noise_ticks, rng
        As :class:`SimServo`; ``baud_rate`` must be within ±3 % of one of the model's rates.
    """

    def __init__(self, dxl_id: int, model: str | int | ControlTable = "AX-12A", *,
                 protocol: float | None = None, **kwargs):
        table = model if isinstance(model, ControlTable) else load_control_table(model, protocol)
        super().__init__(dxl_id, table=table, **kwargs)
        self._tick_s = table.units.ticks_per_rev / 60.0  # ticks/s per rpm
        self._set("Goal Position", round(self.pos))
        self._creation = (bytes(self.mem), self._creation[1])

    def _baud_index_of(self, baud_rate: int) -> int:
        """The table's rate nearest ``baud_rate`` (1.0 rates: 2,000,000 / (n + 1))."""
        return nearest_baud_index(self.table, baud_rate)

    def _start_position(self) -> float:
        """Mid-range: 512 (150°) on an AX, 2048 on an MX."""
        return float((self._max_tick() + 1) // 2)

    # ------------------------------------------------------------------ per-model facts
    def _max_tick(self) -> int:
        goal = self.table.ranges.get("Goal Position", (0, 1023))
        return goal[1]

    def _at(self, name: str) -> int:
        return self.table.resolve(name).address

    @property
    def id(self) -> int:
        """Current ID (address 3)."""
        return self.mem[self._at("ID")]

    @property
    def baud_rate(self) -> int:
        """Current line speed, bit/s (``table.baud_rates``)."""
        return self.table.baud_rates.get(self.get("Baud Rate"), 57142)

    @property
    def speaks(self) -> float:
        """The protocol this servo answers: its table's."""
        return self.table.protocol

    @property
    def watchdog_error(self) -> bool:
        """Always False: no Bus Watchdog on these servos."""
        return False

    def mode(self) -> str:
        """``"wheel"``, ``"joint"`` or ``"multi-turn"`` from the angle limits / Control Mode."""
        if "Control Mode" in self._fields:
            return "wheel" if self.get("Control Mode") == 1 else "joint"
        cw, ccw = self.get("CW Angle Limit"), self.get("CCW Angle Limit")
        if cw == 0 and ccw == 0:
            return "wheel"
        if self.table.protocol == 1.0 and cw == ccw == 4095:
            return "multi-turn"
        return "joint"

    def error1_of(self, code: int) -> int:
        """Protocol 1.0 error bits for a result code of :meth:`read` / :meth:`write`."""
        if code == ANGLE_LIMIT:
            return Error1.ANGLE_LIMIT
        if code == ErrorCode.INSTRUCTION:
            return Error1.INSTRUCTION
        return Error1.RANGE if code else 0

    # ------------------------------------------------------------------ physics
    def _vmax(self) -> float:
        """Joint-mode speed of a move, ticks/s (Moving Speed; 0 = no-load maximum)."""
        units = self.table.units
        speed = self.get("Moving Speed") & 0x3FF
        rpm = units.no_load_rpm if speed == 0 else min(speed * units.velocity_rpm,
                                                        units.no_load_rpm)
        return rpm * self._tick_s

    def _amax(self) -> float:
        if "Goal Acceleration" not in self._fields:
            return math.inf
        acc = self.get("Goal Acceleration")
        return acc * self.table.units.accel_rpm2 * self.table.units.ticks_per_rev / 3600.0 \
            if acc else math.inf

    def note_instruction(self, now: float) -> None:
        """An instruction reached the servo (no watchdog: only the motion advances)."""
        self.advance(now)
        self.last_instruction_t = now

    def advance(self, now: float) -> None:
        """Integrate the motion up to simulated time ``now``."""
        if self.last_t is None:
            self.last_t = self.boot_t = now
            return
        dt = now - self.last_t
        if dt <= 0:
            return
        self.last_t = now
        free = not self.torque or ("Torque Limit" in self._fields
                                   and self.get("Torque Limit") == 0)
        if free:
            if self.hand is not None:
                hand = float(self.hand(now)) if callable(self.hand) else self.hand
                self.vel = (hand - self.pos) / dt if dt > 1e-4 else 0.0
                self.pos = hand
            else:
                self.vel = 0.0
            return
        mode = self.mode()
        amax = self._amax()
        if mode == "wheel":
            raw = self.get("Moving Speed")
            frac = (raw & 0x3FF) / 1023.0 * (-1.0 if raw & 0x400 else 1.0)
            goal_v = frac * self.table.units.no_load_rpm * self._tick_s
            self._ramp_velocity(goal_v, amax, dt)
            return
        if mode == "multi-turn":
            self.vel = 0.0
            return
        vmax, target = self._vmax(), self.target
        while dt > 0:
            err = target - self.pos
            if abs(err) < 1e-6:
                self.pos, self.vel = target, 0.0
                break
            h = min(dt, STEP)
            dt -= h
            v_stop = math.sqrt(2.0 * amax * abs(err)) if math.isfinite(amax) else math.inf
            v_des = math.copysign(min(vmax, v_stop, abs(err) / h), err)
            dv = v_des - self.vel
            if math.isfinite(amax):
                dv = max(-amax * h, min(amax * h, dv))
            self.vel += dv
            self.pos += self.vel * h
            if (target - self.pos) * err <= 0:
                self.pos, self.vel = target, 0.0
                break

    def refresh(self, now: float) -> None:
        """Advance to ``now`` and write the present values into the table."""
        self.advance(now)
        noise = self.rng.gauss(0.0, self.noise_ticks) if self.noise_ticks > 0 else 0.0
        top = self._max_tick()
        self._set("Present Position", min(top, max(0, round(self.pos + noise))))
        rpm = self.vel / self._tick_s
        self._set("Present Speed", _sign_magnitude(rpm / self.table.units.velocity_rpm))
        self._set("Present Load", 0)
        self._set("Moving", int(abs(self.vel) > 0 or (abs(self.target - self.pos) >= 1.0
                                                      and self.torque
                                                      and self.mode() == "joint")))
        self._set("Present Temperature", round(self.temperature))
        self._set("Registered", int(self.registered is not None))
        self._set("Registered Instruction", int(self.registered is not None))
        if "Realtime Tick" in self._fields:
            self._set("Realtime Tick", int((now - self.boot_t) * 1000) % 32768)
        if "Hardware Error Status" in self._fields:
            self._set("Hardware Error Status", self.hardware_error)

    @property
    def error_byte(self) -> int:
        """For a 2.0 status (XL-320): the alert bit; 1.0 statuses use :meth:`error1_byte`."""
        return ALERT if self.hardware_error else 0

    def error1_byte(self) -> int:
        """The hardware-error bits of every 1.0 status packet."""
        return self.hardware_error & _HW_TO_1

    # ------------------------------------------------------------------ instructions
    def write(self, address: int, data: bytes, now: float, *, ram_only: bool = False) -> int:
        """WRITE all-or-nothing: a 2.0 result code, or :data:`ANGLE_LIMIT` (a 1.0 servo; a 2.0
        one reports a goal outside its angle limits as a data limit error). ``ram_only``: sent
        to the servo's Secondary ID (EEPROM refused)."""
        table = self.table
        end = address + len(data)
        if not data:
            return ErrorCode.DATA_LENGTH
        if end > table.size:
            return ErrorCode.ACCESS
        items = []
        a = address
        while a < end:
            item = table.item_covering(a)
            if item is None:
                a += 1
                continue
            if item.address < address or item.end > end:
                return ErrorCode.DATA_LENGTH
            items.append(item)
            a = item.end
        if not items:
            return ErrorCode.ACCESS
        for item in items:
            if not item.writable or (item.address < table.eeprom_end
                                     and (self.torque or ram_only)):
                return ErrorCode.ACCESS
        values = {it.name: it.decode(data[it.address - address:it.end - address])
                  for it in items}
        for name, value in values.items():
            lo_hi = table.ranges.get(name)
            if lo_hi and not lo_hi[0] <= value <= lo_hi[1]:
                return ErrorCode.DATA_RANGE
        if "Goal Position" in values and self.mode() == "joint":
            cw = values.get("CW Angle Limit", self.get("CW Angle Limit"))
            ccw = values.get("CCW Angle Limit", self.get("CCW Angle Limit"))
            if not cw <= values["Goal Position"] <= ccw:
                return ANGLE_LIMIT if self.speaks == 1.0 else ErrorCode.DATA_LIMIT
        self.advance(now)
        was_torque = self.torque
        self.mem[address:end] = data
        if "Torque Enable" in values:
            if values["Torque Enable"] and self.hardware_error & self.get("Shutdown"):
                self._set("Torque Enable", 0)
            elif values["Torque Enable"] and not was_torque:
                self.vel = 0.0
                self.hand = None
                self._set("Goal Position", round(self.pos))
                self.target = self.pos
        if "Goal Position" in values:
            self.target = float(values["Goal Position"])
        return ErrorCode.NONE

    def reboot(self) -> None:
        """REBOOT: RAM back to its power-on values, hardware errors cleared, torque off."""
        eeprom = self.table.eeprom_end
        keep = bytes(self.mem[:eeprom])
        self.mem = self.table.default_memory()
        self.mem[:eeprom] = keep
        if "Torque Limit" in self._fields and "Max Torque" in self._fields:
            self._set("Torque Limit", self.get("Max Torque"))  # power-on copy (e-Manual)
        self._set("Goal Position", round(self.pos))
        self.hardware_error = 0
        self.registered = None
        self.vel = 0.0
        self.target = self.pos
        if self.temperature > self.get("Temperature Limit"):
            self.temperature = float(self.table.defaults.get("Present Temperature", 30))
        self.boot_t = self.last_t or 0.0
        self.booting_until = self.boot_t + self.boot_time_s

    def factory_reset(self, option: int = 0xFF) -> None:
        """RESET (1.0: everything, ID and baud rate included) / FACTORY_RESET (2.0 options
        0xFF all, 0x01 all but ID, 0x02 all but ID and baud rate): the table's defaults."""
        dxl_id, baud = self.id, self.get("Baud Rate")
        self.mem = self.table.default_memory()
        if option in (0x01, 0x02):
            self._set("ID", dxl_id)
        if option == 0x02:
            self._set("Baud Rate", baud)
        self.reboot()
