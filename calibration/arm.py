"""A servo arm's calibration that checks itself: the maths of the guided session and the file.

No device I/O here: :mod:`rig.record.arm_calibration` runs the guided session on a bus and
hands the ticks it read to the functions below; :mod:`rig.devices.config` loads the file a rig
configuration names (``servos.calibration``) and :mod:`rig.devices.dynamixel` compares it with
the arm at start-up (:meth:`ArmCalibration.startup_mismatch`).

What is measured (ticks ``t`` of each servo, read while a person — or the simulated patient —
follows the prompts of a calibration protocol, :mod:`calibration.protocol`):

- **zero** (the static window: every joint at the kinematics' zero, the identity): each servo's
  median ticks, refused if the servo moved more than ``still_deg`` (peak to peak) meanwhile
  (:func:`zero_from_static`);
- **direction** (one move per servo, :class:`calibration.protocol.ServoMoveProtocol`: from the
  zero pose, the servo's joint turned about that servo's axis alone, held, and back): the turn
  ``θ(u)`` the move asks of servo ``k`` (direction +1, from its zero) and every servo's change
  of ticks from its zero ``m_j = (t_j − z_j) · 2π / T_j``. Servo ``k`` turns the way the rig
  says when ``d_k Σ θ m_k > 0`` (``d_k`` its configured direction), and must turn by at least a
  third of what was asked ("did not follow its move" otherwise); every other servo must stay
  within ``max(other_deg, a third of the turn asked)`` of its zero — one that turns is named
  with servo ``k``: two swapped IDs or cables turn each other's servo
  (:func:`direction_from_servo_move`);
- **ranges**: the least and greatest ticks read over the whole session (:func:`ranges_from`).

A direction flip cannot be seen without motion: at start-up the file's directions are checked
against the rig configuration's (they must agree: :meth:`ArmCalibration.check`) and each servo's
guided move at calibration is what confirmed them (``direction_confirmed``: true for every servo
of a file ``rig calibrate`` wrote with the ``directions`` step).

File (YAML, :meth:`ArmCalibration.to_yaml` / :func:`load_arm_calibration`; unknown keys are
refused naming the key)::

    rig: sim-servo-arm                 # the rig configuration's name
    created: "2026-11-28T23:10:00Z"    # when rig calibrate wrote it
    note: ""                           # free text a person may edit
    steps: [zero, directions, ranges]  # what was measured (the rest is the rig config's)
    margin_deg: 10                     # start-up: present ticks within the range ± this
    servos:                            # one per servo of the rig
      - {id: 1, name: shoulder-plane, model: XM430-W350, zero_ticks: 2049, direction: 1,
         direction_confirmed: true, min_ticks: 1700, max_ticks: 3100, homing_offset: 0,
         reverse: false}
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from calibration.errors import CalibrationError
from models.yamlio import safe_load_yaml

__all__ = ["STEPS", "ArmCalibration", "ExpectedServo", "ServoCalibration",
           "direction_from_servo_move", "load_arm_calibration", "loads_arm_calibration",
           "ranges_from", "zero_from_static"]

STEPS = ("zero", "directions", "ranges")
"""The guided steps, in the order they are performed."""

_TOP_REQUIRED = {"rig", "servos"}
_TOP_OPTIONAL = {"created", "note", "steps", "margin_deg"}
_SERVO_REQUIRED = {"id", "model", "zero_ticks", "direction", "min_ticks", "max_ticks"}
_SERVO_OPTIONAL = {"name", "direction_confirmed", "homing_offset", "reverse"}


@dataclass(frozen=True)
class ServoCalibration:
    """One servo's calibration (ticks in the frame its Homing Offset / reverse bit give).

    Attributes
    ----------
    id : int
    model : str
        The model the servo reported (e-Manual name).
    zero_ticks : int
        Present Position with the joint at its zero (the identity).
    direction : int
        ±1: +1 when increasing ticks turn the joint positively about the servo's axis.
    min_ticks, max_ticks : int
        The range reached during the calibration.
    homing_offset : int
        The servo's Homing Offset (item 20) during the calibration, ticks.
    reverse : bool
        Its Drive Mode bit 0 (reverse direction) during the calibration.
    name : str or None
    direction_confirmed : bool
        Whether a guided move turned this servo and confirmed its direction.
    """

    id: int
    model: str
    zero_ticks: int
    direction: int
    min_ticks: int
    max_ticks: int
    homing_offset: int = 0
    reverse: bool = False
    name: str | None = None
    direction_confirmed: bool = False

    @property
    def label(self) -> str:
        """``servo ID 2 (shoulder-elevation)``: how messages name it."""
        return f"servo ID {self.id}" + (f" ({self.name})" if self.name else "")


@dataclass(frozen=True)
class ExpectedServo:
    """What a rig configuration says of one servo, for :meth:`ArmCalibration.check`.

    ``model`` None: the configuration names no model (any is accepted).
    """

    id: int
    direction: int
    model: str | None = None
    homing_offset: int = 0
    reverse: bool = False
    name: str | None = None


@dataclass(frozen=True)
class ArmCalibration:
    """A servo arm's calibration file (module docstring).

    Attributes
    ----------
    rig : str
        The rig configuration's name.
    servos : tuple of ServoCalibration
    created : str
    note : str
    steps : tuple of str
        The steps measured (:data:`STEPS`).
    margin_deg : float
        Start-up tolerance around each servo's range, degrees.
    source : str
        Where it was read from (messages), ``<calibration>`` when built in memory.
    """

    rig: str
    servos: tuple[ServoCalibration, ...]
    created: str = ""
    note: str = ""
    steps: tuple[str, ...] = STEPS
    margin_deg: float = 10.0
    source: str = field(default="<calibration>", compare=False)

    def servo(self, dxl_id: int) -> ServoCalibration | None:
        """The servo with ID ``dxl_id``, or None."""
        return next((s for s in self.servos if s.id == dxl_id), None)

    # -- file ------------------------------------------------------------------------------
    def to_dict(self) -> dict:
        """Plain types, in the file's key order."""
        servos = []
        for s in self.servos:
            d: dict[str, Any] = {"id": s.id}
            if s.name:
                d["name"] = s.name
            d.update(model=s.model, zero_ticks=int(s.zero_ticks), direction=int(s.direction),
                     direction_confirmed=bool(s.direction_confirmed),
                     min_ticks=int(s.min_ticks), max_ticks=int(s.max_ticks),
                     homing_offset=int(s.homing_offset), reverse=bool(s.reverse))
            servos.append(d)
        return {"rig": self.rig, "created": self.created, "note": self.note,
                "steps": list(self.steps), "margin_deg": float(self.margin_deg),
                "servos": servos}

    def to_yaml(self) -> str:
        """The file's text: a header comment, then one flow mapping per servo."""
        d = self.to_dict()
        servos = d.pop("servos")
        head = yaml.safe_dump(d, sort_keys=False, default_flow_style=None, width=100)
        lines = ["# A servo arm's calibration, written by `rig calibrate` (docs/devices.md).",
                 "# 'note' is free text; every other value is checked against the rig "
                 "configuration", "# when a rig file names this one (servos.calibration).",
                 head.rstrip("\n"), "servos:"]
        for s in servos:
            lines.append("  - " + yaml.safe_dump(s, sort_keys=False, default_flow_style=True,
                                                 width=1000).strip())
        return "\n".join(lines) + "\n"

    def save(self, path: str | Path) -> None:
        """Write :meth:`to_yaml` to ``path``."""
        Path(path).write_text(self.to_yaml(), encoding="utf-8")

    # -- checks ----------------------------------------------------------------------------
    def check(self, rig: str, expected: Sequence[ExpectedServo],
              model_range: Callable[[str], tuple[int, int]]) -> None:
        """Refuse a calibration that does not fit the rig configuration.

        Parameters
        ----------
        rig : str
            The rig configuration's name.
        expected : sequence of ExpectedServo
            The configuration's servos.
        model_range : callable
            ``model_range(model) -> (lo, hi)``: the model's position range in ticks (its Min /
            Max Position Limit's valid values); ValueError for an unknown model.

        Raises
        ------
        CalibrationError
            One line naming the file and the first servo (or key) that does not fit.
        """
        src = self.source
        if self.rig != rig:
            raise CalibrationError(f"{src}: rig: {self.rig!r} in the calibration, but the rig "
                                   f"configuration is {rig!r}")
        for e in expected:
            label = f"servo ID {e.id}" + (f" ({e.name})" if e.name else "")
            s = self.servo(e.id)
            if s is None:
                raise CalibrationError(f"{src}: {label} of rig {rig!r} is not in the "
                                       f"calibration; run rig calibrate again")
            if s.direction != e.direction:
                raise CalibrationError(
                    f"{src}: {label}: direction {s.direction} in the calibration, "
                    f"{e.direction} in rig {rig!r}; a direction is confirmed by rig "
                    f"calibrate's guided move, not edited: calibrate again or fix the rig")
            if e.model is not None and s.model.upper() != e.model.upper():
                raise CalibrationError(f"{src}: {label}: model {s.model} in the calibration, "
                                       f"{e.model} in rig {rig!r}")
            if s.homing_offset != e.homing_offset or s.reverse != e.reverse:
                raise CalibrationError(
                    f"{src}: {label}: homing_offset {s.homing_offset} / reverse "
                    f"{str(s.reverse).lower()} in the calibration, {e.homing_offset} / "
                    f"{str(e.reverse).lower()} in rig {rig!r}; calibrate again after "
                    f"changing a servo's frame")
            try:
                lo, hi = model_range(s.model)
            except ValueError as err:
                raise CalibrationError(f"{src}: {label}: model: {err}") from None
            if not lo <= s.min_ticks <= s.max_ticks <= hi:
                raise CalibrationError(
                    f"{src}: {label}: range {s.min_ticks}..{s.max_ticks} is not within the "
                    f"{s.model}'s {lo}..{hi} (need min_ticks <= max_ticks)")
            if not s.min_ticks <= s.zero_ticks <= s.max_ticks:
                raise CalibrationError(f"{src}: {label}: zero_ticks {s.zero_ticks} is outside "
                                       f"its range {s.min_ticks}..{s.max_ticks}")
        ids = {e.id for e in expected}
        for s in self.servos:
            if s.id not in ids:
                raise CalibrationError(f"{src}: {s.label} is not a servo of rig {rig!r}")

    def startup_mismatch(self, models: Mapping[int, str],
                         frames: Mapping[int, tuple[int | None, bool | None]],
                         ticks: Mapping[int, float],
                         ticks_per_rev: Mapping[int, float]) -> str | None:
        """Why the arm found at start-up no longer matches this calibration, or None.

        Parameters
        ----------
        models : mapping of int to str
            Each servo's model as found.
        frames : mapping of int to (int or None, bool or None)
            Each servo's Homing Offset and reverse bit as read (None: its model has none).
        ticks : mapping of int to float
            Each servo's Present Position.
        ticks_per_rev : mapping of int to float
            Each servo's resolution (to turn :attr:`margin_deg` into ticks).

        Returns
        -------
        str or None
            One line naming the first servo that differs and how.
        """
        for s in self.servos:
            if s.id not in models:
                continue
            if models[s.id].upper() != s.model.upper():
                return (f"{s.label} is an {models[s.id]}, the calibration {self.source} was "
                        f"made with an {s.model}: calibrate again")
            off, rev = frames.get(s.id, (None, None))
            if off is not None and off != s.homing_offset:
                return (f"{s.label}: Homing Offset holds {off}, the calibration {self.source} "
                        f"was made with {s.homing_offset}: the arm was re-homed; calibrate "
                        f"again")
            if rev is not None and rev != s.reverse:
                return (f"{s.label}: its reverse bit (Drive Mode bit 0) is "
                        f"{str(rev).lower()}, the calibration {self.source} was made with "
                        f"{str(s.reverse).lower()}: calibrate again")
            margin = self.margin_deg / 360.0 * ticks_per_rev.get(s.id, 4096.0)
            t = ticks.get(s.id)
            if t is not None and not s.min_ticks - margin <= t <= s.max_ticks + margin:
                return (f"{s.label} reads {int(t)} ticks, outside its calibrated range "
                        f"{s.min_ticks}..{s.max_ticks} ± {self.margin_deg:g}° "
                        f"({self.source}): re-assembled or moved off its horn? calibrate again")
        return None


def loads_arm_calibration(text: str, source: str = "<calibration>") -> ArmCalibration:
    """Parse and validate a calibration file's text (shape and types; the rig is checked by
    :meth:`ArmCalibration.check`).

    Raises
    ------
    CalibrationError
        One line naming ``source`` and the key or servo at fault (unknown keys included).
    """
    try:
        data = safe_load_yaml(text)
    except yaml.YAMLError as err:
        raise CalibrationError(f"{source}: not valid YAML: {str(err).splitlines()[0]}") from err
    d = _mapping(data, source, "top level", _TOP_REQUIRED, _TOP_OPTIONAL)
    rig = _string(d["rig"], source, "rig")
    note = d.get("note") or ""
    if not isinstance(note, str):
        raise CalibrationError(f"{source}: note: expected text, got {note!r}")
    created = d.get("created") or ""
    created = str(created)
    steps = d.get("steps", list(STEPS))
    if not isinstance(steps, list) or any(s not in STEPS for s in steps):
        raise CalibrationError(f"{source}: steps: expected a list of {', '.join(STEPS)}, "
                               f"got {steps!r}")
    margin = d.get("margin_deg", 10.0)
    if isinstance(margin, bool) or not isinstance(margin, (int, float)) \
            or not (math.isfinite(margin) and 0 <= margin <= 180):
        raise CalibrationError(f"{source}: margin_deg: expected 0..180 degrees, got {margin!r}")
    raw = d["servos"]
    if not isinstance(raw, list) or not raw:
        raise CalibrationError(f"{source}: servos: expected a list of servos")
    servos = []
    for i, r in enumerate(raw):
        where = f"servos[{i}]"
        s = _mapping(r, source, where, _SERVO_REQUIRED, _SERVO_OPTIONAL)
        dxl_id = _integer(s["id"], source, f"{where}.id", 0, 252)
        where = f"servo ID {dxl_id}" + (f" ({s['name']})" if isinstance(s.get("name"), str)
                                         else "")
        direction = _integer(s["direction"], source, f"{where}: direction")
        if direction not in (1, -1):
            raise CalibrationError(f"{source}: {where}: direction: expected 1 or -1, "
                                   f"got {direction}")
        flags = {}
        for key in ("direction_confirmed", "reverse"):
            v = s.get(key, False)
            if not isinstance(v, bool):
                raise CalibrationError(f"{source}: {where}: {key}: expected true or false, "
                                       f"got {v!r}")
            flags[key] = v
        servos.append(ServoCalibration(
            dxl_id, _string(s["model"], source, f"{where}: model"),
            _integer(s["zero_ticks"], source, f"{where}: zero_ticks"), direction,
            _integer(s["min_ticks"], source, f"{where}: min_ticks"),
            _integer(s["max_ticks"], source, f"{where}: max_ticks"),
            _integer(s.get("homing_offset", 0), source, f"{where}: homing_offset"),
            flags["reverse"], s.get("name") if isinstance(s.get("name"), str) else None,
            flags["direction_confirmed"]))
    ids = [s.id for s in servos]
    dup = next((i for i in ids if ids.count(i) > 1), None)
    if dup is not None:
        raise CalibrationError(f"{source}: servos: servo ID {dup} is listed twice")
    return ArmCalibration(rig, tuple(servos), created, note, tuple(steps), float(margin),
                          source)


def load_arm_calibration(path: str | Path) -> ArmCalibration:
    """:func:`loads_arm_calibration` of a file (CalibrationError naming it if missing)."""
    p = Path(path)
    if not p.is_file():
        raise CalibrationError(f"{p}: no such calibration file")
    return loads_arm_calibration(p.read_text(encoding="utf-8"), str(p))


def _mapping(value: Any, src: str, where: str, required: set[str], optional: set[str]) -> dict:
    if not isinstance(value, Mapping):
        raise CalibrationError(f"{src}: {where}: expected a mapping, got "
                               f"{type(value).__name__}")
    for key in value:
        if key not in required | optional:
            raise CalibrationError(f"{src}: {where}: unknown key {key!r} (known: "
                                   f"{', '.join(sorted(required | optional))})")
    for key in sorted(required):
        if key not in value:
            raise CalibrationError(f"{src}: {where}: missing required key {key!r}")
    return dict(value)


def _string(value: Any, src: str, where: str) -> str:
    if not isinstance(value, str) or not value.strip():
        raise CalibrationError(f"{src}: {where}: expected a non-empty string, got {value!r}")
    return value.strip()


def _integer(value: Any, src: str, where: str, lo: int | None = None,
             hi: int | None = None) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise CalibrationError(f"{src}: {where}: expected a whole number, got {value!r}")
    if (lo is not None and value < lo) or (hi is not None and value > hi):
        raise CalibrationError(f"{src}: {where}: {value} is out of range {lo}..{hi}")
    return value


# ------------------------------------------------------------------------ the guided steps
def zero_from_static(ticks: np.ndarray, ticks_per_rev: np.ndarray, labels: Sequence[str],
                     still_deg: float = 2.0) -> np.ndarray:
    """Each servo's zero: the median of its ticks in the static window.

    Parameters
    ----------
    ticks : (M, n) array_like
        Ticks read during the zero pose.
    ticks_per_rev : (n,) array_like
    labels : sequence of str
        How messages name each servo.
    still_deg : float
        Largest peak-to-peak movement accepted, degrees.

    Returns
    -------
    (n,) int64

    Raises
    ------
    CalibrationError
        Fewer than 3 readings, or a servo that moved more than ``still_deg`` (named).
    """
    t = np.asarray(ticks, dtype=np.float64)
    if t.ndim != 2 or len(t) < 3:
        raise CalibrationError("too few readings during the zero pose (need 3)")
    deg = np.ptp(t, axis=0) * 360.0 / np.asarray(ticks_per_rev, dtype=np.float64)
    for k in np.flatnonzero(deg > still_deg):
        raise CalibrationError(f"{labels[k]} moved {deg[k]:.1f}° during the zero pose (at most "
                               f"{still_deg:g}° allowed): hold the arm still and calibrate "
                               f"again")
    return np.rint(np.median(t, axis=0)).astype(np.int64)


@dataclass(frozen=True)
class DirectionFinding:
    """One servo's finding in its own guided move (:func:`direction_from_servo_move`).

    Attributes
    ----------
    direction : int
        ±1: the direction measured (``d`` of the module docstring).
    asked_deg, moved_deg : float
        The largest turn asked of the servo and the largest it made (from its zero), degrees.
    """

    direction: int
    asked_deg: float
    moved_deg: float


def direction_from_servo_move(k: int, asked_rad: np.ndarray, ticks: np.ndarray,
                              zero_ticks: np.ndarray, ticks_per_rev: np.ndarray,
                              directions: Sequence[int], labels: Sequence[str], *,
                              what: str = "its move", rig: str = "the rig",
                              other_deg: float = 5.0) -> DirectionFinding:
    """Servo ``k``'s direction from its own move, every other servo held still (module
    docstring).

    Parameters
    ----------
    k : int
        The servo the move turns (its column).
    asked_rad : (M,) array_like
        The turn the move asks of servo ``k`` (direction +1, from its zero), radians.
    ticks : (M, n) array_like
        Every servo's ticks read at the same instants.
    zero_ticks, ticks_per_rev : (n,) array_like
    directions : sequence of int
        The rig configuration's direction of each servo (±1).
    labels : sequence of str
        How messages name each servo.
    what : str
        How messages name the move (e.g. ``its move (raise the arm sideways (abduction))``).
    rig : str
        How messages name the rig configuration.
    other_deg : float
        Another servo may turn up to ``max(other_deg, a third of the turn asked)`` during the
        move.

    Returns
    -------
    DirectionFinding
        Servo ``k``'s, its direction equal to ``directions[k]``.

    Raises
    ------
    CalibrationError
        One line: another servo turned during the move (both named: a swapped ID or cable);
        servo ``k`` turned less than a third of what was asked ("did not follow its move");
        it turned the other way than ``directions[k]``.
    """
    a = np.asarray(asked_rad, dtype=np.float64).reshape(-1)
    t = np.asarray(ticks, dtype=np.float64)
    tpr = np.asarray(ticks_per_rev, dtype=np.float64)
    if len(a) < 3 or t.shape != (len(a), len(tpr)):
        raise CalibrationError(f"too few readings during the move of {labels[k]} (need 3)")
    m = (t - np.asarray(zero_ticks, dtype=np.float64)) * 2.0 * math.pi / tpr  # rad, as read
    moved = np.degrees(np.max(np.abs(m), axis=0))
    asked = float(np.degrees(np.max(np.abs(a))))
    limit = max(other_deg, asked / 3.0)
    others = [j for j in range(len(tpr)) if j != k and moved[j] > limit]
    if others:
        j = max(others, key=lambda i: moved[i])
        itself = ", which did not follow it" if moved[k] < asked / 3.0 else ""
        raise CalibrationError(
            f"{labels[j]} turned {moved[j]:.0f}° during the move of {labels[k]}{itself}: "
            f"are the two servos' IDs or cables swapped? check the wiring against rig {rig}, "
            f"then calibrate again")
    if moved[k] < asked / 3.0:
        raise CalibrationError(
            f"{labels[k]} did not follow its move: it turned {moved[k]:.1f}° of the "
            f"{asked:.0f}° asked; check its horn and cable, then calibrate again")
    direction = 1 if float(np.sum(a * m[:, k])) > 0 else -1  # sign of Σ θ m
    if direction != directions[k]:
        raise CalibrationError(
            f"{labels[k]} turned the other way during {what}: direction {direction} "
            f"measured, {directions[k]} in rig {rig}; set the servo's reverse bit or the "
            f"rig's direction, then calibrate again")
    return DirectionFinding(direction, asked, float(moved[k]))


def ranges_from(ticks: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The least and greatest ticks of each servo over a session's readings (M, n)."""
    t = np.asarray(ticks, dtype=np.float64)
    if t.ndim != 2 or not len(t):
        raise CalibrationError("no readings to take the ranges from")
    return (np.floor(t.min(axis=0)).astype(np.int64), np.ceil(t.max(axis=0)).astype(np.int64))


def with_servo(cal: ArmCalibration, dxl_id: int, **changes) -> ArmCalibration:
    """``cal`` with servo ``dxl_id``'s fields changed (tests, hand edits in code)."""
    return replace(cal, servos=tuple(replace(s, **changes) if s.id == dxl_id else s
                                     for s in cal.servos))
