"""The guided calibration of a leader or follower servo arm (``rig calibrate``): the session on
the bus; the maths and the file are :mod:`calibration.arm`.

The person (on the simulator: the back-driven patient, who performs the same protocol by
itself) follows the prompts of a :class:`calibration.protocol.ServoMoveProtocol` built from the
rig configuration (:func:`servo_move_protocol`): the zero pose (every joint at the kinematics'
zero), then one move per servo, in chain order — from the zero pose, that servo's joint turned
about that servo's axis alone (e.g. ``shoulder: raise the arm sideways (abduction) by about
25°, turning servo ID 2 (shoulder-elevation) alone``), by ``amplitude_deg`` or less where the
servo's configured tick range is narrow, held, and back — then (``ranges``) every joint moved
through its whole range. Torque stays off; the bus's Present Position is read at ``rate_hz``
throughout. Then:

- zero: each servo's median ticks in the static window (still within ``still_deg``);
- directions: in each servo's move, that servo must turn the way the rig configuration's
  ``direction`` says and by at least a third of what was asked, and every other servo must
  stay still (:func:`calibration.arm.direction_from_servo_move`): every servo's direction is
  confirmed by its own move;
- ranges: the least and greatest ticks over the whole session, within the configured limits.

The file is refused (:class:`~calibration.errors.CalibrationError`, one line naming the servo)
when a servo turned the other way, did not follow its move, moved during the zero pose, or
turned during another servo's move (both named: swapped IDs or cables).
"""

from __future__ import annotations

import datetime as _dt
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from calibration.arm import (
    STEPS,
    ArmCalibration,
    ServoCalibration,
    direction_from_servo_move,
    ranges_from,
    zero_from_static,
)
from calibration.protocol import ServoMoveProtocol, servo_moves
from rig.devices.config import RigConfig, ServosConfig, load_rig_config
from rig.devices.dynamixel import REVERSE_BIT, DynamixelBus
from rig.devices.ports import open_port
from rig.errors import RigConfigError
from rig.record.procedures import NEUTRAL_WORDS

__all__ = ["CalibrateRequest", "CalibrateResult", "run_calibrate", "servo_move_protocol"]


@dataclass
class CalibrateRequest:
    """What ``rig calibrate`` is asked.

    Attributes
    ----------
    rig : str, Path or RigConfig
        A shipped rig name, a rig file, or a loaded configuration (its ``servos``).
    out : Path
        Where the calibration file is written.
    steps : tuple of str
        Among :data:`calibration.arm.STEPS`; the others keep the rig configuration's values.
    note : str
        The file's ``note``.
    port : str, optional
        Instead of ``servos.port``.
    rate_hz : float
        Readings per second.
    ranges_s : float
        How long the person moves every joint through its range (step ``ranges``).
    lead_s : float
        Seconds to get ready before the zero pose.
    still_deg : float
        :func:`calibration.arm.zero_from_static`.
    other_deg : float
        :func:`calibration.arm.direction_from_servo_move`: how far another servo may turn
        during a servo's move (at least; a third of the turn asked where that is more).
    margin_deg : float
        The file's start-up margin.
    amplitude_deg : float
        The turn each servo's move asks where its range allows (:func:`servo_move_protocol`).
    protocol : ServoMoveProtocol, optional
        The protocol (default: :func:`servo_move_protocol` of the rig with ``amplitude_deg``).
    """

    rig: str | Path | RigConfig
    out: Path
    steps: tuple[str, ...] = STEPS
    note: str = ""
    port: str | None = None
    rate_hz: float = 50.0
    ranges_s: float = 20.0
    lead_s: float = 3.0
    still_deg: float = 2.0
    other_deg: float = 5.0
    margin_deg: float = 10.0
    amplitude_deg: float = 25.0
    protocol: ServoMoveProtocol | None = None


@dataclass
class CalibrateResult:
    """What the session measured.

    Attributes
    ----------
    calibration : ArmCalibration
    path : Path
    readings : int
        Present Position readings taken.
    lines : list of str
        One line per servo, for people.
    unconfirmed : list of str
        Servos whose direction no move confirmed (the configuration's is kept): all of them
        without the ``directions`` step, none with it.
    prompts : list of str
        What the person was asked, in order.
    guided_s : float
        How long the person was guided (the protocol, plus the ranges).
    """

    calibration: ArmCalibration
    path: Path
    readings: int
    lines: list[str] = field(default_factory=list)
    unconfirmed: list[str] = field(default_factory=list)
    prompts: list[str] = field(default_factory=list)
    guided_s: float = 0.0


def servo_move_protocol(config: RigConfig, servos: ServosConfig | None = None, *,
                        amplitude_deg: float = 25.0, **durations) -> ServoMoveProtocol:
    """The rig's servo-move protocol: one move per servo of ``servos`` (default the rig's,
    without a calibration), in chain order.

    Parameters
    ----------
    config : RigConfig
    servos : ServosConfig, optional
    amplitude_deg : float
        :func:`calibration.protocol.servo_moves`: the turn asked, less where a servo's
        configured tick range is narrow (its angles ``direction · (ticks − zero) · 2π / T``
        over ``min_ticks..max_ticks``).
    **durations
        ``static_s``, ``move_s``, ``hold_s``, ``rest_s``, ``settle_s`` of
        :class:`~calibration.protocol.ServoMoveProtocol`.

    Raises
    ------
    RigConfigError
        A servo's tick range leaves no room to turn it (named).
    """
    servos = servos or config.servos.without_calibration()
    joints = [(j.name, j.axes) for j in servos.joints] or [(config.joint.name, servos.axes)]
    side = config.joint.side if config.joint.side in ("left", "right") else "right"
    chain = []
    for name, axes in joints:
        rows = []
        for a in axes:
            ends = [math.degrees(a.angle(t)) for t in (a.min_ticks, a.max_ticks)]
            rows.append((_label(a), a.axis, min(ends), max(ends)))
        chain.append((name, rows))
    try:
        moves = servo_moves(chain, side, amplitude_deg=amplitude_deg)
        return ServoMoveProtocol(moves, tuple(n for n, _ in joints),
                                 config.limb if len(joints) > 1 else None, **durations)
    except ValueError as err:
        raise RigConfigError(f"rig {config.name!r}: {err}") from None


def _label(a) -> str:
    return f"servo ID {a.id}" + (f" ({a.name})" if a.name else "")


def run_calibrate(request: CalibrateRequest, *, echo: Callable[[str], None] = print,
                  port=None, wait: Callable[[float], None] | None = None) -> CalibrateResult:
    """The guided calibration (module docstring); writes ``request.out``.

    Parameters
    ----------
    request : CalibrateRequest
    echo : callable
        Prompts and results, one line each.
    port : rig.devices.port.Port, optional
        An opened port (tests: a manual-clock simulator); default: open ``servos.port``.
    wait : callable, optional
        ``wait(seconds)`` between readings (default :func:`time.sleep`; tests advance the
        simulator's manual clock).

    Raises
    ------
    RigConfigError
        Unknown step, a rig without servos.
    CalibrationError
        A servo moved during the zero pose, turned the other way or did not follow a move.
    """
    steps = tuple(request.steps)
    bad = [s for s in steps if s not in STEPS]
    if bad or not steps:
        raise RigConfigError(f"--steps: expected some of {','.join(STEPS)}, got "
                             f"{','.join(steps) or 'nothing'}")
    config = request.rig if isinstance(request.rig, RigConfig) else load_rig_config(request.rig)
    if config.servos is None:
        raise RigConfigError(f"rig {config.name!r} has no servos to calibrate")
    servos = config.servos.without_calibration()
    protocol = request.protocol or servo_move_protocol(config, servos,
                                                       amplitude_deg=request.amplitude_deg)
    wait = wait or time.sleep
    own_port = port is None
    if own_port:
        port = open_port(request.port or servos.port, baud=servos.baud)
    try:
        # not a real-time loop: a simulator computing its patient's next block, or a busy
        # host, may answer late; patience costs nothing here
        with DynamixelBus(port, servos, retries=5,
                          latency_ms=200.0 if port.is_simulated else None) as bus:
            bus.set_torque(False)
            times, ticks, protocol, prompts = _session(bus, port, protocol, config, steps,
                                                       request, echo, wait)
            models = {i: bus.found[i].model for i in bus.ids}
            frames = {i: (off or 0, bool((mode or 0) & REVERSE_BIT))
                      for i, (off, mode) in bus.read_frames().items()}
    finally:
        if own_port:
            port.close()
    result = _solve(times, ticks, protocol, config, servos, steps, request, models, frames,
                    echo)
    result.prompts = prompts
    result.guided_s = _end(protocol, steps, request)
    return result


def _end(protocol, steps, request) -> float:
    """How long the session reads, seconds from the protocol's start."""
    if "directions" in steps or "ranges" in steps:
        return protocol.duration_s + (request.ranges_s if "ranges" in steps else 0.0)
    return protocol.static_s


def _session(bus, port, protocol, config, steps, request, echo, wait):
    """Prompts on the protocol's timeline and the readings: times (s from the protocol's
    start), ticks (M, n), the protocol followed and the prompts said."""
    sp = getattr(port, "simulated_patient", None)
    if sp is not None:
        now = sp.now
        if isinstance(sp.limb.calibration_protocol, ServoMoveProtocol):  # already told to
            protocol = sp.limb.calibration_protocol
            t0 = float(sp.limb.protocol_start_s)
        else:
            t0 = max(0.0, now()) + request.lead_s
            sp.start_protocol(protocol, lead_s=request.lead_s)
    else:
        now = time.monotonic
        t0 = now() + request.lead_s
    end = _end(protocol, steps, request)
    phases = [(0.0, f"zero pose: {NEUTRAL_WORDS[config.limb]}; hold still "
                    f"{protocol.static_s:g} s")]
    if "directions" in steps or "ranges" in steps:
        phases += [(protocol.start_of(k), m.prompt(protocol.hold_s))
                   for k, m in enumerate(protocol.moves)]
    if "ranges" in steps:
        phases.append((protocol.duration_s, f"now move every joint slowly through its whole "
                                             f"range ({request.ranges_s:g} s)"))
    echo(f"calibration of rig {config.name!r} ({', '.join(steps)}, {end:.0f} s): get ready, "
         f"{max(0.0, t0 - now()):.0f} s")
    period = 1.0 / request.rate_hz
    times, rows, k = [], [], 0
    while True:
        t = now() - t0
        if t >= end:
            break
        while k < len(phases) and t >= phases[k][0]:
            echo(phases[k][1])
            k += 1
        if t >= 0:
            rows.append(bus.read_ticks())
            times.append(t)
        wait(period)
    echo("done: the arm may rest")
    return (np.asarray(times), np.asarray(rows, dtype=np.float64).reshape(-1, len(bus.ids)),
            protocol, [p for _, p in phases[:k]])


def _window(times, protocol, name):
    a, b = protocol.windows()[name]
    return (times >= a) & (times <= b)


def _solve(times, ticks, protocol, config, servos, steps, request, models, frames, echo
           ) -> CalibrateResult:
    axes = servos.axes
    n = len(axes)
    tpr = np.array([a.ticks_per_rev for a in axes])
    labels = [_label(a) for a in axes]
    zero = np.array([a.zero_ticks for a in axes], dtype=np.int64)
    if "zero" in steps:
        zero = zero_from_static(ticks[_window(times, protocol, "static")], tpr, labels,
                                request.still_deg)
    confirmed = [False] * n
    notes = [""] * n
    if "directions" in steps:
        column = {label: k for k, label in enumerate(labels)}
        asked = np.radians(protocol.angles(times))
        for i, move in enumerate(protocol.moves):
            k = column.get(move.servo)
            if k is None:
                raise RigConfigError(f"the protocol moves {move.servo}, not a servo of rig "
                                     f"{config.name!r}")
            sel = _window(times, protocol, move.servo)
            found = direction_from_servo_move(
                k, asked[sel, i], ticks[sel], zero, tpr, [a.direction for a in axes], labels,
                what=f"its move ({move.words})", rig=repr(config.name),
                other_deg=request.other_deg)
            confirmed[k] = True
            notes[k] = (f"direction {found.direction} confirmed by its move, {move.words} "
                        f"({found.moved_deg:.0f}° of {found.asked_deg:.0f}° asked)")
    lo = np.array([a.min_ticks for a in axes], dtype=np.int64)
    hi = np.array([a.max_ticks for a in axes], dtype=np.int64)
    if "ranges" in steps:
        rlo, rhi = ranges_from(ticks)
        lo, hi = np.maximum(np.minimum(rlo, zero), lo), np.minimum(np.maximum(rhi, zero), hi)
    out_servos, lines, unconfirmed = [], [], []
    for k, a in enumerate(axes):
        fr = frames[a.id]
        out_servos.append(ServoCalibration(
            a.id, models[a.id], int(zero[k]), a.direction, int(lo[k]), int(hi[k]),
            int(fr[0]), bool(fr[1]), a.name, confirmed[k]))
        dz = (int(zero[k]) - a.zero_ticks) * 360.0 / tpr[k]
        if not confirmed[k]:
            unconfirmed.append(labels[k])
        said = notes[k] or f"direction {a.direction} (not confirmed: no directions step)"
        lines.append(f"{labels[k]}: zero {int(zero[k])} ({dz:+.1f}° from the rig's), {said}, "
                     f"range {int(lo[k])}..{int(hi[k])}")
    cal = ArmCalibration(config.name, tuple(out_servos),
                         _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
                         request.note, steps, float(request.margin_deg), str(request.out))
    path = Path(request.out)
    cal.save(path)
    for line in lines:
        echo(line)
    echo(f"wrote {path} ({len(times)} readings)")
    return CalibrateResult(cal, path, len(times), lines, unconfirmed)
