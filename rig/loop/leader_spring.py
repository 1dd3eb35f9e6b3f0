"""The limit felt at the leader: a light spring towards the follower's admitted pose.

In leader–follower teleoperation the follower holds the patient's limits; without feedback the
person moving the leader only sees the follower stop. Where the leader's servos have current
control, :class:`LeaderSpring` makes the limit felt: while the admitted pose (the follower's,
expressed in the leader's joints) differs from the leader's by more than a dead band, each
leader servo is pulled towards the admitted pose with a current that grows with the error and
is capped, and is otherwise left free.

How (X-series e-Manual, XL330-M288 page, emanual.robotis.com/docs/en/dxl/x/xl330-m288/):

* **Current-based Position Control Mode** (Operating Mode(11) = 5): the position controller
  drives the shaft towards Goal Position(116) with "Goal Current(102) ... used to set a limit
  to current in Current-based Position Control Mode" (e-Manual Goal Current(102)). With Goal
  Current 0 the motor may draw no current: torque on, the servo exerts no torque and a person
  moves it freely (our reading of that sentence; on hardware friction and cogging remain).
* Operating Mode is an EEPROM item: written with torque off (e-Manual Operating Mode(11)).
* Goal Current cannot exceed Current Limit(38) (e-Manual Current Limit(38); the servo
  answers a Data Limit Error). Its unit is the model's (1 mA on the XL330, 2.69 mA on the
  XM430: ``table.units.current_ma``).

The spring, per cycle (:meth:`LeaderSpring.update`)::

    e_j  = angle(leader_q_j⁻¹ ⊗ admitted_q_j)                  joint j's error, degrees
    binding_j = e_j > dead_band                                 the limit is binding
    goal = IK_j(admitted_q_j) nearest the present ticks         (binding joints)
    I_s  = min(gain × |goal_s − present_s| (deg), max_current)  per servo, mA (0 if not binding)

Once the position error of the servo's own loop exceeds a few ticks, its PID output saturates
at Goal Current: the torque felt is ``kt × I_s`` (about 0.35 N·m/A on the XL330-M288), a
spring of ``kt × gain`` N·m per degree up to ``kt × max_current``.

Off by default: nothing builds a :class:`LeaderSpring` unless asked (:class:`SpringSettings`
``enabled``). A leader whose servos have no current control (XL430, AX: no mode 5 / no Goal
Current) refuses it in one line (:class:`~rig.errors.RigConfigError`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, fields

import numpy as np

from firmware_protocol.dynamixel.control_table import load_control_table
from models import quaternion as Q
from rig.devices.kinematics import JointKinematics, LimbKinematics
from rig.errors import RigConfigError, UnreachableError

__all__ = ["CURRENT_BASED_POSITION", "LeaderSpring", "SpringSettings", "current_control"]

CURRENT_BASED_POSITION = 5
"""Operating Mode(11) value of Current-based Position Control Mode (X-series e-Manual)."""


@dataclass(frozen=True)
class SpringSettings:
    """The leader spring's options (off by default).

    Attributes
    ----------
    enabled : bool
        False (default): no spring.
    gain_ma_per_deg : float
        Current per degree of error, mA/deg (> 0).
    max_current_ma : float
        Cap of the current, mA (> 0; at most every leader servo's Current Limit).
    dead_band_deg : float
        Joint error below which the limit is not binding and the leader stays free, deg (≥ 0).
    """

    enabled: bool = False
    gain_ma_per_deg: float = 10.0
    max_current_ma: float = 150.0
    dead_band_deg: float = 1.0

    def __post_init__(self) -> None:
        if not isinstance(self.enabled, bool):
            raise RigConfigError(f"leader spring: enabled must be true or false, got "
                                 f"{self.enabled!r}")
        for name, low, strict in (("gain_ma_per_deg", 0.0, True),
                                  ("max_current_ma", 0.0, True),
                                  ("dead_band_deg", 0.0, False)):
            v = getattr(self, name)
            ok = isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) \
                and (v > low if strict else v >= low)
            if not ok:
                raise RigConfigError(f"leader spring: {name} must be a finite number "
                                     f"{'>' if strict else '>='} {low:g}, got {v!r}")

    @classmethod
    def from_option(cls, text: str, option: str = "--leader-spring") -> SpringSettings:
        """Settings from ``GAIN_MA_PER_DEG[,MAX_MA[,DEAD_BAND_DEG]]`` (enabled; the omitted
        ones the defaults).

        Raises
        ------
        RigConfigError
            Not one to three numbers, or a value out of range (one line naming ``option``).
        """
        parts = [p.strip() for p in str(text).split(",")]
        if not 1 <= len(parts) <= 3 or not all(parts):
            raise RigConfigError(f"{option} {text!r}: expected GAIN_MA_PER_DEG[,MAX_MA"
                                 f"[,DEAD_BAND_DEG]], e.g. 10,150,1")
        try:
            values = [float(p) for p in parts]
        except ValueError:
            raise RigConfigError(f"{option} {text!r}: expected numbers: GAIN_MA_PER_DEG"
                                 f"[,MAX_MA[,DEAD_BAND_DEG]]") from None
        names = ("gain_ma_per_deg", "max_current_ma", "dead_band_deg")
        try:
            return cls(enabled=True, **dict(zip(names, values, strict=False)))
        except RigConfigError as err:
            raise RigConfigError(f"{option} {text!r}: {str(err).removeprefix('leader spring: ')}"
                                 ) from None

    @classmethod
    def from_mapping(cls, data: Mapping[str, object] | None,
                     where: str = "leader spring") -> SpringSettings:
        """Settings from a YAML mapping (unknown keys refused, in one line naming ``where``)."""
        if data is None:
            return cls()
        if not isinstance(data, Mapping):
            raise RigConfigError(f"{where}: must be a mapping, got {type(data).__name__}")
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(data) - known)
        if unknown:
            raise RigConfigError(f"{where}: unknown key {unknown[0]!r} (known: "
                                 f"{', '.join(sorted(known))})")
        return cls(**data)  # type: ignore[arg-type]


def current_control(model_number: int, protocol: float | None = None) -> bool:
    """True when a model has Current-based Position Control Mode and a Goal Current item."""
    table = load_control_table(model_number, protocol)
    return (CURRENT_BASED_POSITION in table.operating_modes
            and table.resolve("Goal Current") is not None
            and bool(table.units.current_ma))


class LeaderSpring:
    """Pull the leader arm's servos towards the follower's admitted pose (module docstring).

    Parameters
    ----------
    bus : rig.devices.dynamixel.DynamixelBus
        The leader's bus, open; its servos in the kinematics' tick-vector order.
    kinematics : LimbKinematics or JointKinematics
        The leader's joints (servo-frame ticks ↔ joint orientations).
    settings : SpringSettings, optional
        Gain, cap and dead band (``enabled`` is the caller's business: building a spring is
        asking for one).

    Attributes
    ----------
    armed : bool
    current_ma_ : (n,) float64
        The currents the last :meth:`update` commanded, mA (tick-vector order).
    binding_ : (J,) bool
        Joints whose limit was binding at the last update.
    error_deg_ : (J,) float64
        Each joint's leader–admitted angle at the last update.

    Raises
    ------
    RigConfigError
        A leader servo without current control (one line naming it), kinematics whose IDs
        are not the bus's, or a cap above a servo's Current Limit (at :meth:`arm`).
    """

    def __init__(self, bus, kinematics: LimbKinematics | JointKinematics,
                 settings: SpringSettings | None = None) -> None:
        if isinstance(kinematics, JointKinematics):
            kinematics = LimbKinematics([kinematics])
        self.bus = bus
        self.kinematics = kinematics
        self.settings = settings if settings is not None else SpringSettings(enabled=True)
        if tuple(bus.ids) != tuple(kinematics.ids):
            raise RigConfigError(f"leader spring: the leader's kinematics name servos "
                                 f"{list(kinematics.ids)}, its bus {list(bus.ids)}")
        self._units_ma = np.empty(kinematics.n)
        for k, dxl_id in enumerate(bus.ids):
            info = bus.found[dxl_id]
            protocol = getattr(info, "protocol", None)
            if not current_control(info.model_number, protocol):
                raise RigConfigError(f"leader spring: servo ID {dxl_id} ({info.model}) has no "
                                     f"current control (Current-based Position Control Mode); "
                                     f"turn the spring off or use XL330/XC330/XM-class servos")
            self._units_ma[k] = load_control_table(info.model_number,
                                                   protocol).units.current_ma
        self._deg_per_tick = np.degrees(kinematics.rad_per_tick)
        # axes whose range is a whole turn: in Current-based Position Control Mode their
        # Present Position is multi-turn (e-Manual Operating Mode(11): ±256 revolutions), so a
        # hand taking one through 4095 → 0 reads 4100, not 4; their goal is taken in the turn
        # of the present position, not a turn away within 0..4095
        self._tpr = np.asarray(kinematics.ticks_per_rev, dtype=np.float64)
        self._lo = np.asarray(kinematics.min_ticks, dtype=np.float64)
        self._free_turn = (np.asarray(kinematics.max_ticks, dtype=np.float64) - self._lo
                           + 1.0) >= self._tpr
        self.armed = False
        self._modes: dict[int, int] = {}
        self._sent_zero = True
        self.current_ma_ = np.zeros(kinematics.n)
        self.binding_ = np.zeros(len(kinematics), dtype=bool)
        self.error_deg_ = np.zeros(len(kinematics))

    def __enter__(self) -> LeaderSpring:
        self.arm()
        return self

    def __exit__(self, *exc: object) -> None:
        self.disarm()

    # ------------------------------------------------------------------ arm / disarm
    def arm(self) -> None:
        """Current-based position mode, Goal Current 0, Goal Position where each servo is,
        torque on: the leader is free to move (a person moves it) until :meth:`update` pulls.

        Raises
        ------
        RigConfigError
            ``max_current_ma`` above a servo's Current Limit.
        """
        if self.armed:
            return
        bus = self.bus
        cap = self.settings.max_current_ma
        for k, dxl_id in enumerate(bus.ids):
            limit_ma = bus.read_register(dxl_id, "Current Limit") * self._units_ma[k]
            if cap > limit_ma:
                raise RigConfigError(f"leader spring: max_current_ma {cap:g} above servo ID "
                                     f"{dxl_id}'s Current Limit ({limit_ma:g} mA)")
        for dxl_id in bus.ids:
            bus.write_register(dxl_id, "Torque Enable", 0)  # Operating Mode is EEPROM
            self._modes[dxl_id] = bus.read_register(dxl_id, "Operating Mode")
            bus.write_register(dxl_id, "Operating Mode", CURRENT_BASED_POSITION)
            bus.write_register(dxl_id, "Goal Current", 0)
        ticks = bus.read_ticks()
        for dxl_id, t in zip(bus.ids, ticks, strict=True):
            bus.write_register(dxl_id, "Goal Position", int(t))  # no stale goal at torque-on
            bus.write_register(dxl_id, "Torque Enable", 1)
        self.armed = True
        self._sent_zero = True
        self.current_ma_ = np.zeros(self.kinematics.n)

    def disarm(self) -> None:
        """Goal Current 0, torque off, each servo's Operating Mode back (idempotent)."""
        if not self.armed:
            return
        bus = self.bus
        self.armed = False
        bus.write_items("Goal Current", [0] * len(bus.ids))
        for dxl_id in bus.ids:
            bus.write_register(dxl_id, "Torque Enable", 0)
            mode = self._modes.get(dxl_id)
            if mode is not None and mode != CURRENT_BASED_POSITION:
                bus.write_register(dxl_id, "Operating Mode", mode)
        self.current_ma_ = np.zeros(self.kinematics.n)

    # ------------------------------------------------------------------ the cycle
    def update(self, leader_q: np.ndarray, admitted_q: np.ndarray,
               ticks: Sequence[float] | None = None) -> np.ndarray:
        """Command the spring for one cycle.

        Parameters
        ----------
        leader_q : (J, 4) float64
            The leader's joint orientations (scalar-first, child relative to parent), as read.
        admitted_q : (J, 4) float64
            The admitted pose in the leader's joints (the follower's, mapped back); a row that
            is not finite leaves its joint free.
        ticks : (n,) array_like, optional
            The leader's present ticks (what ``leader_q`` was computed from); default: the
            leader's IK of ``leader_q`` near the zero ticks.

        Returns
        -------
        (n,) float64
            The current commanded to each servo, mA (0: free).
        """
        if not self.armed:
            raise RuntimeError("leader spring: update() before arm()")
        kin, s = self.kinematics, self.settings
        lq = np.asarray(leader_q, dtype=np.float64).reshape(len(kin), 4)
        aq = np.asarray(admitted_q, dtype=np.float64).reshape(len(kin), 4)
        error = np.degrees(Q.angle(Q.multiply(Q.conjugate(lq), aq)))
        error = np.where(np.isfinite(error), error, 0.0)
        binding = error > s.dead_band_deg
        present = (np.asarray(ticks, dtype=np.float64) if ticks is not None
                   else self._ticks_of(lq))
        goal = present.copy()
        current = np.zeros(kin.n)
        for j, joint in enumerate(kin.joints):
            if not binding[j]:
                continue
            sl = kin.slices[j]
            p, free, tpr, lo = present[sl], self._free_turn[sl], self._tpr[sl], self._lo[sl]
            one_turn = np.where(free, lo + np.mod(p - lo, tpr), p)
            try:
                g = joint.inverse_float(aq[j], one_turn)
            except UnreachableError:
                binding[j] = False
                continue
            g = np.where(free, g + tpr * np.round((p - g) / tpr), g)  # the nearest turn
            goal[sl] = g
            current[sl] = np.minimum(s.gain_ma_per_deg * np.abs(g - present[sl])
                                     * self._deg_per_tick[sl], s.max_current_ma)
        self.binding_, self.error_deg_ = binding, error
        raw = np.rint(current / self._units_ma).astype(np.int64)
        self.current_ma_ = raw * self._units_ma
        if not raw.any():
            if not self._sent_zero:  # let go once, then send nothing while free
                self.bus.write_items("Goal Current", [0] * kin.n)
                self._sent_zero = True
            return self.current_ma_
        # position first: the current then pulls towards this cycle's goal, not a stale one
        self.bus.write_items("Goal Position", np.rint(goal).astype(np.int64).tolist())
        self.bus.write_items("Goal Current", raw.tolist())
        self._sent_zero = False
        return self.current_ma_

    def _ticks_of(self, lq: np.ndarray) -> np.ndarray:
        kin = self.kinematics
        out = np.empty(kin.n)
        for j, joint in enumerate(kin.joints):
            out[kin.slices[j]] = joint.inverse_float(lq[j], joint.zero_ticks)
        return out
