"""The guided calibration of a leader or follower servo arm (``rig calibrate``): the session on
the bus; the maths and the file are :mod:`calibration.arm`.

The person (on the simulator: the back-driven patient, who performs the same protocol by
itself) follows the rig's calibration protocol — the one ``rig record`` prompts for
(:func:`rig.record.procedures.procedure_for`: :class:`calibration.protocol.CalibrationProtocol`
for a rig of one joint, :class:`~calibration.protocol.LimbCalibrationProtocol` for a limb): the
zero pose (every joint at the kinematics' zero), then each joint's flexion/extension, then
(``ranges``) every joint moved through its whole range. Torque stays off; the bus's Present
Position is read at ``rate_hz`` throughout. Then:

- zero: each servo's median ticks in the static window (still within ``still_deg``);
- directions: in each joint's movement window, each servo the scripted movement turns by at
  least ``min_move_deg`` must turn the way the rig configuration's ``direction`` says, and by
  at least a third of what was asked; a servo the movement does not turn (a flexion moves no
  abduction or axial servo) keeps the configured direction, marked unconfirmed;
- ranges: the least and greatest ticks over the whole session, within the configured limits.

The file is refused (:class:`~calibration.errors.CalibrationError`, one line naming the servo)
when a servo turned the other way, moved while it should be still, or did not follow a move.
"""

from __future__ import annotations

import datetime as _dt
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from calibration.arm import (
    STEPS,
    ArmCalibration,
    ServoCalibration,
    direction_from_move,
    ranges_from,
    zero_from_static,
)
from calibration.errors import CalibrationError
from rig.devices.config import RigConfig, load_rig_config
from rig.devices.dynamixel import REVERSE_BIT, DynamixelBus
from rig.devices.kinematics import JointKinematics
from rig.devices.ports import open_port
from rig.errors import RigConfigError
from rig.record.procedures import NEUTRAL_WORDS, procedure_for

__all__ = ["CalibrateRequest", "CalibrateResult", "run_calibrate"]


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
    still_deg, min_move_deg, margin_deg : float
        :func:`calibration.arm.zero_from_static`, :func:`calibration.arm.direction_from_move`,
        and the file's start-up margin.
    protocol : object, optional
        The calibration protocol (default: the rig's, as ``rig record`` prompts it).
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
    min_move_deg: float = 10.0
    margin_deg: float = 10.0
    protocol: object | None = None


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
        Servos no guided move turned (their direction is the configuration's).
    """

    calibration: ArmCalibration
    path: Path
    readings: int
    lines: list[str] = field(default_factory=list)
    unconfirmed: list[str] = field(default_factory=list)


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
    procedure = procedure_for(config.limb)
    protocol = request.protocol or procedure.default_protocol()
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
            times, ticks, protocol = _session(bus, port, protocol, procedure, config, steps,
                                              request, echo, wait)
            models = {i: bus.found[i].model for i in bus.ids}
            frames = {i: (off or 0, bool((mode or 0) & REVERSE_BIT))
                      for i, (off, mode) in bus.read_frames().items()}
    finally:
        if own_port:
            port.close()
    return _solve(times, ticks, protocol, config, servos, steps, request, models, frames, echo)


def _session(bus, port, protocol, procedure, config, steps, request, echo, wait):
    """Prompts on the protocol's timeline and the readings: times (s from the protocol's
    start) and ticks (M, n)."""
    sp = getattr(port, "simulated_patient", None)
    if sp is not None:
        now = sp.now
        if sp.limb.calibration_protocol is not None:  # the port string made it perform one
            protocol = sp.limb.calibration_protocol
            t0 = float(sp.limb.protocol_start_s)
        else:
            t0 = max(0.0, now()) + request.lead_s
            sp.start_protocol(protocol, lead_s=request.lead_s)
    else:
        now = time.monotonic
        t0 = now() + request.lead_s
    moving = "directions" in steps or "ranges" in steps
    end = protocol.duration_s + (request.ranges_s if "ranges" in steps else 0.0) if moving \
        else protocol.static_s
    limb = config.limb
    phases = [(0.0, f"zero pose: {NEUTRAL_WORDS[limb]}; hold still "
                    f"{protocol.static_s:g} s")]
    if moving:
        phases += [(start, words) for start, words, _ in procedure.phases(protocol)]
    if "ranges" in steps:
        phases.append((protocol.duration_s, f"now move every joint slowly through its whole "
                                             f"range ({request.ranges_s:g} s)"))
    echo(f"calibration of rig {config.name!r} ({', '.join(steps)}): get ready, "
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
    return np.asarray(times), np.asarray(rows, dtype=np.float64).reshape(-1, len(bus.ids)), \
        protocol


def _window(times, protocol, name):
    a, b = protocol.windows()[name]
    return (times >= a) & (times <= b)


def _solve(times, ticks, protocol, config, servos, steps, request, models, frames, echo
           ) -> CalibrateResult:
    axes = servos.axes
    n = len(axes)
    tpr = np.array([a.ticks_per_rev for a in axes])
    labels = [f"servo ID {a.id}" + (f" ({a.name})" if a.name else "") for a in axes]
    zero = np.array([a.zero_ticks for a in axes], dtype=np.int64)
    if "zero" in steps:
        zero = zero_from_static(ticks[_window(times, protocol, "static")], tpr, labels,
                                request.still_deg)
    confirmed = [False] * n
    notes = [""] * n
    if "directions" in steps:
        joints = servos.joints or ()
        groups = [(j.name, j.axes) for j in joints] or [(config.joint.name, axes)]
        start = 0
        for ji, (joint, jaxes) in enumerate(groups):
            idx = list(range(start, start + len(jaxes)))
            start += len(jaxes)
            key = joint if joint in protocol.windows() else "functional"
            sel = _window(times, protocol, key)
            asked = _asked(protocol, times[sel], ji, config, jaxes)
            found = direction_from_move(asked, ticks[sel][:, idx], zero[idx], tpr[idx],
                                        request.min_move_deg)
            for k, f in zip(idx, found, strict=True):
                if not f.judged:
                    continue
                want = axes[k].direction
                if f.direction != want:
                    raise CalibrationError(
                        f"{labels[k]} turned the other way during the {joint} move: direction "
                        f"{f.direction} measured, {want} in rig {config.name!r}; set the "
                        f"servo's reverse bit or the rig's direction, then calibrate again")
                if f.moved_deg < f.asked_deg / 3.0:
                    raise CalibrationError(
                        f"{labels[k]} did not follow the {joint} move: it turned "
                        f"{f.moved_deg:.1f}° of the {f.asked_deg:.0f}° asked; check the horn "
                        f"and calibrate again")
                confirmed[k] = True
                notes[k] = (f"direction {want} confirmed by the {joint} move "
                            f"({f.moved_deg:.0f}° of {f.asked_deg:.0f}° asked)")
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
        lines.append(f"{labels[k]}: zero {int(zero[k])} ({dz:+.1f}° from the rig's), "
                     f"{notes[k] or f'direction {a.direction} (no guided move turned it)'}, "
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


def _asked(protocol, t, joint_index, config, jaxes) -> np.ndarray:
    """The servo angles (M, n) the scripted movement asks of a joint's chain: its inverse
    kinematics with direction +1, zero 0 and no tick limits, each solution nearest the one
    before (radians)."""
    if hasattr(protocol, "joint_orientations"):
        side = config.joint.side if config.joint.side in ("left", "right") else "right"
        q = protocol.joint_orientations(t, side)[:, joint_index]
    else:
        q = np.asarray(protocol.joint(t), dtype=np.float64).reshape(-1, 4)
    plain = [replace(a, zero_ticks=0, direction=1, min_ticks=-10 * round(a.ticks_per_rev),
                     max_ticks=10 * round(a.ticks_per_rev)) for a in jaxes]
    kin = JointKinematics(plain, tolerance_deg=180.0)
    tpr = np.array([a.ticks_per_rev for a in jaxes])
    out = np.zeros((len(q), len(jaxes)))
    near = np.zeros(len(jaxes))
    for i, qi in enumerate(q):
        near = kin.inverse_float(qi, near)
        out[i] = near
    return out * 2.0 * math.pi / tpr
