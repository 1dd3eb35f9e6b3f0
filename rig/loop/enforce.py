"""``rig enforce`` as a library: keep a servo-driven limb inside a patient's range in a real-time
loop (:func:`run_enforce`: :class:`EnforceRequest` → :class:`EnforceResult`).

Everything is checked, and the devices opened, before the loop starts: a bad option, file,
model, constraint mismatch, rig configuration or port raises a user error (the CLI's one line,
exit status 2) before anything moves. The exit status after the loop: 0 when it ran to its end,
1 when a fault put the limb in the safe state, 130 / 143 after SIGINT / SIGTERM (the limb left
in the safe state).

With a store (``db``) the run and its telemetry are stored in an ``enforce`` session; with a
recording ``session_id`` its last boundary is the constraint enforced (unless ``constraint``
names one) and its patient must be the model's.
"""

from __future__ import annotations

import dataclasses
import json
import math
import signal
from collections.abc import Callable
from contextlib import ExitStack
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from models import quaternion as Q
from models.constraint import load_constraint, loads_constraint
from models.fileio import check_output, write_owner_only
from models.limb import load_limits, loads_limb
from models.onnx_io import load_model
from models.oracle import ConstraintOracle
from rig.devices.config import load_rig_config
from rig.devices.ports import open_port, real_time_port
from rig.errors import RigConfigError
from rig.loop import realtime
from rig.loop.binding import bind_model
from rig.loop.leader import LEADER_COLUMNS, LEADER_STALE_PERIODS, LeaderTargets
from rig.loop.leader_spring import SpringSettings
from rig.loop.realtime import check_cpu
from rig.loop.runner import (
    SAFE_STATES,
    EnforcementLoop,
    LoopConfig,
    prepare_servo_limb,
)
from rig.loop.supervisor import SupervisorConfig
from rig.loop.targets import open_targets, valid_targets
from rig.loop.telemetry import Telemetry, telemetry_columns

__all__ = ["MAX_TOLERANCE_DEG", "EnforceHooks", "EnforceRequest", "EnforceResult",
           "run_enforce"]

#: Largest ``tolerance_deg``: a goal may leave the boundary by at most this much.
MAX_TOLERANCE_DEG = 10.0


def _silent(_: str) -> None:
    pass


@dataclass(frozen=True)
class EnforceRequest:
    """What ``rig enforce`` is asked (the options of the command, same names and units).

    Attributes
    ----------
    rig, model, targets : str
        Rig configuration with servos (name or file), the ONNX model, the target source
        (:func:`rig.loop.targets.open_targets`).
    frames : {"rig", "isb"}, optional
        Segment frames of a targets file.
    rate_hz, duration_s : float
        Loop rate; seconds to run (None: a CSV's length, else until stopped).
    telemetry, summary_json : str, optional
        Per-cycle CSV, end-of-run summary JSON (both owner-only).
    db, session_id, patient : optional
        Store, recording session, pseudonym of the stored run.
    constraint : str, optional
        Constraint file to enforce (default: the session's boundary, the rig's, the model's).
    force_model : bool
        Run a model made for another constraint / joint / side / patient.
    safe_state : {"hold", "torque-off"}
    tolerance_deg, max_velocity_deg_s, max_accel_deg_s2, stale_servo_ms, stale_target_ms
        The supervisor's limits (``stale_target_ms`` None: 100 ms, or with a leader arm
        :data:`rig.loop.leader.LEADER_STALE_PERIODS` loop periods, so that a leader that stops
        answering holds the follower from the next cycle).
    seed : int
        Seed of scripted targets.
    realtime : bool
        Ask for real-time scheduling of the loop's thread (:mod:`rig.loop.realtime`).
    cpu : int, optional
        Pin the loop's thread to this CPU.
    busy_wait : bool
        Spin between cycles instead of sleeping (:class:`~rig.loop.LoopConfig`).
    start_mismatch_deg, on_start_mismatch, at_end, servo_max_velocity_deg_s
        Start-up mismatch threshold (degrees, any joint) and what it does (``ramp`` /
        ``refuse``), what a normal end does (``hold`` / ``rest``), the per-servo velocity limit
        (None: off) (:class:`~rig.loop.LoopConfig`).
    warm_up : bool
        Warm the compute path before each deadline (:class:`~rig.loop.LoopConfig`).
    leader_spring : str, optional
        ``GAIN_MA_PER_DEG[,MAX_MA[,DEAD_BAND_DEG]]``: the limit felt at a leader arm
        (:class:`rig.loop.leader_spring.SpringSettings.from_option`); only with
        ``targets`` ``leader:...`` (None: off).
    """

    rig: str
    model: str
    targets: str
    frames: str | None = None
    rate_hz: float = 200.0
    duration_s: float | None = None
    telemetry: str | None = None
    summary_json: str | None = None
    db: str | None = None
    session_id: int | None = None
    patient: str | None = None
    constraint: str | None = None
    force_model: bool = False
    safe_state: str = "hold"
    tolerance_deg: float = 1.0
    max_velocity_deg_s: float = 120.0
    max_accel_deg_s2: float = 1200.0
    stale_servo_ms: float = 100.0
    watchdog_ms: int | None = None
    stale_target_ms: float | None = None
    seed: int = 0
    realtime: bool = False
    cpu: int | None = None
    busy_wait: bool = False
    warm_up: bool = True
    start_mismatch_deg: float = 20.0
    on_start_mismatch: str = "ramp"
    at_end: str = "hold"
    servo_max_velocity_deg_s: float | None = None
    leader_spring: str | None = None

    def spring_settings(self) -> SpringSettings | None:
        """The ``--leader-spring`` settings, checked (None: off).

        Raises
        ------
        RigConfigError
            A spring without ``--targets leader:...``, or a malformed value (one line).
        """
        if self.leader_spring is None:
            return None
        if not str(self.targets).strip().startswith("leader:"):
            raise RigConfigError(f"--leader-spring {self.leader_spring}: needs --targets "
                                 "leader:RIG|PORT (the spring pulls a leader arm)")
        return SpringSettings.from_option(self.leader_spring)

    def loop_config(self):
        """The :class:`~rig.loop.LoopConfig` of these options, checked (one-line errors)."""
        for name, v in (("--rate", self.rate_hz), ("--duration", self.duration_s),
                        ("--tolerance-deg", self.tolerance_deg),
                        ("--max-velocity-deg-s", self.max_velocity_deg_s),
                        ("--max-accel-deg-s2", self.max_accel_deg_s2),
                        ("--stale-servo-ms", self.stale_servo_ms),
                        ("--stale-target-ms", self.stale_target_ms),
                        ("--start-mismatch-deg", self.start_mismatch_deg),
                        ("--servo-max-velocity-deg-s", self.servo_max_velocity_deg_s)):
            if v is not None and not (math.isfinite(v) and v > 0):
                raise RigConfigError(f"{name} {v}: expected a positive number")
        if self.watchdog_ms is not None and not 0 <= self.watchdog_ms <= 2540:
            raise RigConfigError(f"--watchdog-ms {self.watchdog_ms}: expected 0-2540 ms (the "
                                 "Bus Watchdog's range; 0: off)")
        if self.rate_hz > 5000:
            raise RigConfigError(f"--rate {self.rate_hz}: at most 5000 Hz")
        if self.tolerance_deg <= 0.25:
            raise RigConfigError(f"--tolerance-deg {self.tolerance_deg}: must exceed 0.25° (the "
                                 "room kept for rounding goals to encoder ticks)")
        if self.tolerance_deg > MAX_TOLERANCE_DEG:
            raise RigConfigError(f"--tolerance-deg {self.tolerance_deg}: at most "
                                 f"{MAX_TOLERANCE_DEG:g}° (further outside than that, the "
                                 "boundary no longer limits the limb)")
        if self.safe_state not in SAFE_STATES:
            raise RigConfigError(f"--safe-state {self.safe_state!r}: expected one of "
                                 f"{', '.join(SAFE_STATES)}")
        if self.session_id is not None and self.db is None:
            raise RigConfigError("--session needs --db")
        if self.patient is not None and self.db is None:
            raise RigConfigError("--patient needs --db")
        _out_path("--telemetry", self.telemetry)
        _out_path("--summary-json", self.summary_json)
        self.spring_settings()

        check_cpu(self.cpu)
        try:  # LoopConfig checks its own settings (start-up, end), naming the option
            return self._loop_config()
        except ValueError as err:
            raise RigConfigError(str(err)) from None

    def _loop_config(self):
        return LoopConfig(
            rate_hz=float(self.rate_hz), duration_s=self.duration_s, safe_state=self.safe_state,
            watchdog_ms=self.watchdog_ms,
            busy_wait=bool(self.busy_wait), warm_up=bool(self.warm_up),
            start_mismatch_deg=float(self.start_mismatch_deg),
            on_start_mismatch=self.on_start_mismatch, at_end=self.at_end,
            servo_max_velocity_deg_s=None if self.servo_max_velocity_deg_s is None
            else float(self.servo_max_velocity_deg_s),
            supervisor=SupervisorConfig(tolerance_deg=float(self.tolerance_deg),
                                        max_velocity_deg_s=float(self.max_velocity_deg_s),
                                        max_accel_deg_s2=float(self.max_accel_deg_s2),
                                        stale_present_s=float(self.stale_servo_ms) / 1e3,
                                        stale_target_s=float(
                                            100.0 if self.stale_target_ms is None
                                            else self.stale_target_ms) / 1e3))


@dataclass
class EnforceHooks:
    """What tests, benchmarks and the demo attach to a run (the CLI attaches only signals).

    ``on_cycle(loop, k)`` runs after each cycle; ``clock`` (a
    :class:`rig.sim.clock.ManualClock`) replaces real time; ``ports`` maps port strings to
    already opened :class:`~rig.devices.ports.Port` (fault injection); ``install_signals``
    turns SIGINT / SIGTERM into the loop's safe state; ``keep_telemetry`` keeps the rows in
    memory (:attr:`EnforceResult.telemetry`)."""

    on_cycle: Callable[[Any, int], None] | None = None
    clock: Any = None
    ports: dict[str, Any] | None = None
    install_signals: bool = False
    keep_telemetry: bool = False


@dataclass
class EnforceResult:
    """How the run ended: the exit status, the summary (:func:`rig.loop.telemetry.summarise`
    plus the model, constraint, targets and, with a store, ``session_id`` / ``run_id``), the
    loop, its telemetry and the servo port."""

    exit_status: int
    summary: dict
    loop: Any = None
    telemetry: Any = None
    port: Any = None

    def summary_line(self) -> str:
        """The summary on one line (``--quiet``)."""
        s = self.summary
        hz = s.get("achieved_hz")
        return (f"cycles {s['cycles']} at {'n/a' if hz is None else f'{hz:.1f}'} Hz, max "
                f"violation {s['max_violation_deg']:.3f}° (tolerance {s['tolerance_deg']:g}°), "
                f"interventions {s['interventions']}, overruns {s['overruns']}, safe-state "
                f"entries {s['safe_state_entries']}, end {s['end_reason']}")

    def summary_text(self) -> str:
        """The summary as ``rig enforce`` prints it (three lines)."""
        s = self.summary

        def f(v, fmt="{:.3f}"):
            return "n/a" if v is None else fmt.format(v)

        return "\n".join([
            f"cycles {s['cycles']} at {f(s.get('achieved_hz'), '{:.1f}')} Hz (asked "
            f"{s['rate_hz']:g}); cycle p50 {f(s['p50_cycle_ms'])} ms, p99 "
            f"{f(s['p99_cycle_ms'])} ms; overruns {s['overruns']}{_causes(s)}; compute p50 "
            f"{f(s['p50_compute_us'], '{:.0f}')} µs",
            f"max violation {s['max_violation_deg']:.3f}° (tolerance {s['tolerance_deg']:g}°); "
            f"interventions {s['interventions']} {s['interventions_by_kind']}",
            f"faults {s['faults'] or 'none'}; safe-state entries {s['safe_state_entries']}"
            + (f" ({s['safe_state_reason']})" if s.get("safe_state_reason") else "")
            + f"; end: {s['end_reason']}",
        ])


def _causes(s: dict) -> str:
    """`` (bus 2, scheduler 1)``: the summary's overruns by cause, those that occurred."""
    by = {k: v for k, v in (s.get("overruns_by_cause") or {}).items() if v}
    return f" ({', '.join(f'{k} {v}' for k, v in by.items())})" if by else ""


def _out_path(option: str, value) -> Path | None:
    """``--telemetry`` / ``--summary-json`` checked writable (:func:`models.fileio.check_output`):
    :meth:`EnforceRequest.loop_config` runs it before the servo backstop is written."""
    if value is None:
        return None

    return check_output(value, option)


@dataclass
class _Prepared:
    """Everything checked and loaded before the devices are opened."""

    request: EnforceRequest
    cfg: Any  # LoopConfig
    rig_cfg: Any
    model: Any
    binding: Any
    oracle: Any
    targets: Any
    store: Any = None
    session_patient: str | None = None


def run_enforce(request: EnforceRequest, *, echo: Callable[[str], None] = _silent,
                hooks: EnforceHooks | None = None) -> EnforceResult:
    """Check, load, open the devices, run the loop, store and summarise; ``echo`` receives
    what ``rig enforce`` prints.

    Raises
    ------
    RigError, ModelsError, FileNotFoundError
        User mistakes, before anything moves.
    """
    hooks = hooks or EnforceHooks()
    cfg = request.loop_config()
    rig_cfg = load_rig_config(request.rig)
    if rig_cfg.servos is None:
        raise RigConfigError(f"--rig {request.rig}: rig {rig_cfg.name!r} has no servo chain to "
                             "drive")
    # a servo limb (servos.joints) runs a limb model over a limb file; one joint, one joint's
    servo_joints = tuple(rig_cfg.servos.joints)
    mdl = load_model(request.model, limb=bool(servo_joints))
    store = None
    session_constraint = session_patient = alignment = None
    try:
        if request.db is not None:
            from rig.store import open_store  # lazy: --db is optional

            store = open_store(request.db, readonly=False)  # the run is stored: refused now
            if request.session_id is not None:
                sid = request.session_id
                session_patient = store.sessions.get(sid).get("pseudonym")
                # a joint's constraint for a rig of one joint, a limb file for a servo limb
                bounds = store.boundaries.list(sid, limb=bool(servo_joints))
                if bounds:
                    read = loads_limb if servo_joints else loads_constraint
                    session_constraint = read(
                        bounds[-1]["constraint_yaml"],
                        source=f"boundary {bounds[-1]['id']} of session {sid}")
                for cal in store.calibrations.list(sid):
                    data = cal.get("data") or {}
                    if "thorax_mount" in data and "limb_mount" in data:
                        alignment = data
        # a servo limb's --constraint may be a limb file (refused by the binding when it is
        # not this limb's); a rig of one joint's reads as it always has
        read_limits = load_limits if servo_joints else load_constraint
        explicit = (read_limits(request.constraint) if request.constraint is not None
                    else None)
        binding = bind_model(mdl, rig=rig_cfg, constraint=explicit,
                             constraint_source=f"--constraint {request.constraint}",
                             session_constraint=session_constraint,
                             session_id=request.session_id, session_patient=session_patient,
                             force=request.force_model)
        for m in binding.mismatches:
            echo(f"warning: {m} (--force-model)")
        if store is not None and (request.patient or session_patient
                                  or binding.constraint.patient) is None:
            raise RigConfigError("--db: say whose run this is: --patient PSEUDONYM or "
                                 "--session ID")
        oracle = ConstraintOracle(binding.constraint)
        spring = request.spring_settings()
        src = open_targets(request.targets, oracle=oracle, rig=rig_cfg, seed=request.seed,
                           frames=request.frames, separate_process=hooks.clock is None,
                           **({} if spring is None else {"spring": spring, "log": echo}))
        if isinstance(src, LeaderTargets) and request.stale_target_ms is None:
            cfg.supervisor = dataclasses.replace(
                cfg.supervisor, stale_target_s=LEADER_STALE_PERIODS / cfg.rate_hz)
        if alignment is not None and hasattr(src, "alignment") and src.n_joints == 1:
            src.alignment = {
                rig_cfg.joint.parent: tuple(Q.conjugate(alignment["thorax_mount"]).tolist()),
                rig_cfg.joint.child: tuple(Q.conjugate(alignment["limb_mount"]).tolist())}
        prep = _Prepared(request, cfg, rig_cfg, mdl, binding, oracle, src, store,
                         session_patient)
        return _run_with_devices(prep, echo, hooks)
    finally:
        if store is not None:
            store.close()


def _run_with_devices(prep: _Prepared, echo: Callable[[str], None],
                      hooks: EnforceHooks) -> EnforceResult:
    req, cfg, store, binding, src = prep.request, prep.cfg, prep.store, prep.binding, prep.targets
    servos = prep.rig_cfg.servos
    ports = dict(hooks.ports or {})
    own_port = servos.port not in ports
    port = ports.get(servos.port)
    opened = ExitStack()  # closed in reverse when the run ends: telemetry, servo limb, own port
    run_id = enforce_session = None
    try:
        with src:
            if own_port:  # a simulated bus in a process of its own, as hardware is
                url, note = real_time_port(servos.port)
                if note:
                    echo(f"note: {note}")
                port = open_port(url, baud=servos.baud, separate_process=hooks.clock is None)
                opened.callback(port.close)
            limb = prepare_servo_limb(port, servos, prep.oracle, log=echo)
            opened.callback(limb.close)
            for tip in limb.bus.advice:
                echo(f"note: {tip}")
            # -- the store: an 'enforce' session and a run ------------------------------------
            store_writer = None
            if store is not None:
                pseudonym = req.patient or prep.session_patient or binding.constraint.patient
                pid = store.patients.ensure(pseudonym)
                enforce_session = store.sessions.start(
                    pid, rig_name=prep.rig_cfg.name, joint=prep.rig_cfg.joint.name,
                    side=prep.rig_cfg.joint.side, kind="enforce",
                    meta={"model": str(prep.model.path), "targets": req.targets,
                          "constraint_source": binding.source,
                          "recording_session": req.session_id})
                run_id = store.runs.start(enforce_session, {
                    "rate_hz": cfg.rate_hz, "safe_state": cfg.safe_state,
                    "tolerance_deg": cfg.supervisor.tolerance_deg,
                    "constraint": binding.constraint.to_yaml()
                    if hasattr(binding.constraint, "to_yaml") else None,
                    "model": str(prep.model.path), "targets": req.targets})
                from rig.store import TelemetryWriter  # lazy like open_store: --db is optional

                store_writer = TelemetryWriter(store, run_id)
            leader = src if isinstance(src, LeaderTargets) else None
            telemetry = Telemetry(_out_path("--telemetry", req.telemetry), store_writer,
                                  keep=hooks.keep_telemetry or leader is not None,
                                  columns=telemetry_columns(limb.kinematics.names)
                                  + (LEADER_COLUMNS if leader is not None else ()),
                                  extra=None if leader is None else leader.telemetry_values)
            opened.callback(telemetry.close)
            kw = {} if hooks.clock is None else {"clock": hooks.clock,
                                                 "sleep": hooks.clock.sleep}
            loop = EnforcementLoop(limb, prep.model, prep.oracle, src, cfg, telemetry=telemetry,
                                   on_cycle=hooks.on_cycle, log=echo, **kw)
            echo(f"enforcing {binding.constraint.name!r} ({binding.source}) on rig "
                 f"{prep.rig_cfg.name!r} at {cfg.rate_hz:g} Hz; model {prep.model.path}; "
                 f"targets {src.description}; safe state {cfg.safe_state}")
            loop.setup()
            if leader is not None:  # the spring's register writes before the schedule starts
                leader.arm_spring()
            restore = _install_signals(loop) if hooks.install_signals else None

            unpin, notes = realtime.apply(realtime=req.realtime, cpu=req.cpu)
            for note in notes:
                echo(f"note: {note}")
            try:
                summary = loop.run()
            finally:
                unpin()
                if restore is not None:
                    restore()
            telemetry.close()
            summary["model"] = str(prep.model.path)
            summary["constraint"] = binding.constraint.name
            summary["constraint_source"] = binding.source
            summary["targets"] = src.description
            if loop.start_mismatch is not None:
                summary["start_mismatch_deg"] = {n: round(a, 3) for n, a in
                                                 loop.start_mismatch.items()}
            if loop.rest_reached is not None:
                summary["rest_reached"] = loop.rest_reached
            if hasattr(src, "dropped"):
                summary["target_samples_dropped"] = int(src.dropped)
            if leader is not None:
                summary["leader"] = leader.summary(telemetry.table(), prep.oracle, valid_targets)
            if store is not None:
                status = ("completed" if loop.safe_state_entries == 0 else
                          "interrupted" if loop.stop_reason else "safe_state")
                store.runs.end(run_id, summary, status=status)
                store.sessions.end(enforce_session, status="completed" if status == "completed"
                                   else "interrupted" if status == "interrupted" else "failed",
                                   meta={"run_id": run_id})
                summary["session_id"] = enforce_session
                summary["run_id"] = run_id
            sum_path = _out_path("--summary-json", req.summary_json)
            if sum_path is not None:
                write_owner_only(sum_path, json.dumps(summary, indent=2, sort_keys=True) + "\n")
            if loop.stop_reason is not None:
                code = 143 if "SIGTERM" in loop.stop_reason else 130
            else:
                code = 1 if loop.safe_state_entries else 0
            result = EnforceResult(code, summary, loop, telemetry, port)
            echo(result.summary_text())
            return result
    except BaseException:
        if store is not None and run_id is not None:
            try:
                store.runs.end(run_id, {"error": "aborted"}, status="failed")
                store.sessions.end(enforce_session, status="failed")
            except Exception:  # the original error matters more
                pass
        raise
    finally:
        opened.close()


def _install_signals(loop):
    """SIGINT / SIGTERM → the loop's safe state; returns a function restoring the handlers."""
    def handler(signum, frame):
        loop.request_stop(signal.Signals(signum).name)

    old = {}
    for s in (signal.SIGINT, signal.SIGTERM):
        try:
            old[s] = signal.signal(s, handler)
        except ValueError:  # not the main thread
            pass

    def restore():
        for s, h in old.items():
            signal.signal(s, h)
    return restore
