"""``rig enforce``: keep a servo-driven limb inside a patient's range in a real-time loop.

``rig enforce --rig NAME|FILE --model M.onnx --targets SOURCE [--rate HZ] [--duration S]
[--telemetry T.csv] [--summary-json S.json] [--db DB [--session ID | --patient P]]
[--constraint C.yaml] [--force-model] [--safe-state hold|torque-off]``

Everything is checked, and the devices opened, before the loop starts: a bad option, file,
model, constraint mismatch, rig config or port is one line ``rig: error: ...``, exit 2.
Exit status after the loop: 0 when it ran to its end, 1 when a fault put the limb in the safe
state, 130 / 143 after SIGINT / SIGTERM (the limb is left in the safe state).

See :mod:`rig.loop` and ``docs/loop.md``.
"""

from __future__ import annotations

import json
import math
import signal
import sys
from pathlib import Path

import click


@click.command("enforce")
@click.option("--rig", "rig_name", required=True, metavar="NAME|FILE",
              help="Rig configuration with a servo chain (e.g. sim-shoulder) or a YAML file.")
@click.option("--model", "model_path", required=True, metavar="M.onnx",
              help="Correction model from `rig train` (its metadata names its constraint).")
@click.option("--targets", required=True, metavar="SOURCE",
              help="PATH.csv (t_s,w,x,y,z), script:slow|sweep|adversarial|hold[?seed=N], or "
                   "mirror / mirror:RIG (an IMU-worn limb through the orientation sources).")
@click.option("--frames", type=click.Choice(["rig", "isb"]), default=None,
              help="Segment frames of a targets file's joint orientations: rig (default) or "
                   "isb (+Y proximal, +X anterior, +Z right).")
@click.option("--rate", type=float, default=200.0, show_default=True, metavar="HZ",
              help="Loop rate.")
@click.option("--duration", type=float, default=None, metavar="S",
              help="Seconds to run (default: a CSV's length, else until Ctrl-C).")
@click.option("--telemetry", "telemetry_path", default=None, metavar="T.csv",
              help="Per-cycle telemetry CSV.")
@click.option("--summary-json", "summary_path", default=None, metavar="S.json",
              help="Write the end-of-run summary as JSON.")
@click.option("--db", default=None, metavar="DB",
              help="Session store (SQLite path, sqlite:///..., postgresql://...): the run and "
                   "its telemetry are stored in an 'enforce' session.")
@click.option("--session", "session_id", type=int, default=None, metavar="ID",
              help="Recording session (in --db) whose boundary is enforced and whose patient "
                   "the model must belong to.")
@click.option("--patient", default=None, metavar="PSEUDONYM",
              help="Patient pseudonym for the stored run (default: the session's).")
@click.option("--constraint", "constraint_path", default=None, metavar="C.yaml",
              help="Constraint to enforce (default: the session's boundary, else the rig "
                   "config's, else the model's own).")
@click.option("--force-model", is_flag=True,
              help="Run a model made for another constraint / joint / side / patient (the "
                   "supervisor still enforces the constraint).")
@click.option("--safe-state", type=click.Choice(["hold", "torque-off"]), default="hold",
              show_default=True, help="What faults and Ctrl-C leave the servos in.")
@click.option("--tolerance-deg", type=float, default=1.0, show_default=True,
              help="No command is sent further than this outside the boundary (0.25-10°).")
@click.option("--max-velocity-deg-s", type=float, default=120.0, show_default=True,
              help="Goal angular velocity limit.")
@click.option("--max-accel-deg-s2", type=float, default=1200.0, show_default=True,
              help="Goal angular acceleration limit.")
@click.option("--stale-servo-ms", type=float, default=100.0, show_default=True,
              help="Servo data older than this (reads failing) puts the limb in the safe state.")
@click.option("--stale-target-ms", type=float, default=100.0, show_default=True,
              help="A target older than this holds the last safe goal.")
@click.option("--seed", type=int, default=0, show_default=True, help="Seed of scripted targets.")
@click.option("--quiet", is_flag=True, help="Print only the summary line.")
def enforce(rig_name, model_path, targets, frames, rate, duration, telemetry_path,
            summary_path, db, session_id, patient, constraint_path, force_model, safe_state,
            tolerance_deg, max_velocity_deg_s, max_accel_deg_s2, stale_servo_ms,
            stale_target_ms, seed, quiet) -> None:
    """Enforce a patient's joint limits on a servo limb in real time."""
    from rig.store.store import pseudonym_warning

    result: dict = {}

    if pseudonym_warning(patient):
        click.echo(f"warning: {pseudonym_warning(patient)}", err=True)
    code = run_enforce(
        rig=rig_name, model=model_path, targets=targets, frames=frames, rate_hz=rate,
        duration_s=duration,
        telemetry=telemetry_path, summary_json=summary_path, db=db, session_id=session_id,
        patient=patient, constraint=constraint_path, force_model=force_model,
        safe_state=safe_state, tolerance_deg=tolerance_deg,
        max_velocity_deg_s=max_velocity_deg_s, max_accel_deg_s2=max_accel_deg_s2,
        stale_servo_ms=stale_servo_ms, stale_target_ms=stale_target_ms, seed=seed,
        echo=(lambda m: None) if quiet else click.echo, install_signals=True, result=result)
    if quiet and "summary" in result:
        click.echo(summary_line(result["summary"]))
    if code:
        sys.exit(code)


def summary_line(s: dict) -> str:
    """The end-of-run summary on one line (``--quiet``)."""
    hz = s.get("achieved_hz")
    line = (f"cycles {s['cycles']} at {'n/a' if hz is None else f'{hz:.1f}'} Hz, max violation "
            f"{s['max_violation_deg']:.3f}° (tolerance {s['tolerance_deg']:g}°), interventions "
            f"{s['interventions']}, overruns {s['overruns']}, safe-state entries "
            f"{s['safe_state_entries']}, end {s['end_reason']}")
    return line


#: Largest ``--tolerance-deg``: a goal may leave the boundary by at most this much.
MAX_TOLERANCE_DEG = 10.0


def _check_out_path(option: str, value) -> Path | None:
    from rig.errors import RigConfigError

    if value is None:
        return None
    p = Path(value)
    if p.exists() and p.is_dir():
        raise RigConfigError(f"{option} {value}: is a directory")
    parent = p.parent if str(p.parent) else Path(".")
    if not parent.exists():
        raise RigConfigError(f"{option} {value}: directory {parent} does not exist")
    return p


def run_enforce(*, rig, model, targets, frames=None, rate_hz=200.0, duration_s=None,
                telemetry=None,
                summary_json=None, db=None, session_id=None, patient=None, constraint=None,
                force_model=False, safe_state="hold", tolerance_deg=1.0,
                max_velocity_deg_s=120.0, max_accel_deg_s2=1200.0, stale_servo_ms=100.0,
                stale_target_ms=100.0, seed=0,
                echo=click.echo, install_signals=False, on_cycle=None, clock=None,
                ports=None, result=None) -> int:
    """What ``rig enforce`` does; returns the exit status (0, 1, 130, 143).

    ``on_cycle``, ``clock`` (a :class:`rig.sim.clock.ManualClock`) and ``ports`` (already opened
    :class:`rig.devices.ports.Port` by port string, for fault injection) serve tests; ``result``
    (a dict) receives the loop, summary and ids.

    Raises
    ------
    RigError, ModelsError, FileNotFoundError
        User mistakes, before anything moves (the CLI prints one line, exit 2).
    """
    from models.constraint import load_constraint, loads_constraint
    from models.onnx_io import load_model
    from models.oracle import ConstraintOracle
    from rig.devices.config import load_rig_config
    from rig.devices.ports import open_port
    from rig.errors import RigConfigError
    from rig.loop import EnforcementLoop, LoopConfig, SupervisorConfig, Telemetry, bind_model
    from rig.loop.runner import prepare_chain
    from rig.loop.targets import open_targets

    # -- options -------------------------------------------------------------------------------
    def positive(name, v):
        if v is not None and not (math.isfinite(v) and v > 0):
            raise RigConfigError(f"{name} {v}: expected a positive number")

    positive("--rate", rate_hz)
    positive("--duration", duration_s)
    positive("--tolerance-deg", tolerance_deg)
    positive("--max-velocity-deg-s", max_velocity_deg_s)
    positive("--max-accel-deg-s2", max_accel_deg_s2)
    positive("--stale-servo-ms", stale_servo_ms)
    positive("--stale-target-ms", stale_target_ms)
    if rate_hz > 5000:
        raise RigConfigError(f"--rate {rate_hz}: at most 5000 Hz")
    if tolerance_deg <= 0.25:
        raise RigConfigError(f"--tolerance-deg {tolerance_deg}: must exceed 0.25° (the room "
                             "kept for rounding goals to encoder ticks)")
    if tolerance_deg > MAX_TOLERANCE_DEG:
        raise RigConfigError(f"--tolerance-deg {tolerance_deg}: at most {MAX_TOLERANCE_DEG:g}° "
                             "(further outside than that, the boundary no longer limits the "
                             "limb)")
    tel_path = _check_out_path("--telemetry", telemetry)
    sum_path = _check_out_path("--summary-json", summary_json)
    if session_id is not None and db is None:
        raise RigConfigError("--session needs --db")
    if patient is not None and db is None:
        raise RigConfigError("--patient needs --db")
    cfg = LoopConfig(
        rate_hz=float(rate_hz), duration_s=duration_s, safe_state=safe_state,
        supervisor=SupervisorConfig(tolerance_deg=float(tolerance_deg),
                                    max_velocity_deg_s=float(max_velocity_deg_s),
                                    max_accel_deg_s2=float(max_accel_deg_s2),
                                    stale_present_s=float(stale_servo_ms) / 1e3,
                                    stale_target_s=float(stale_target_ms) / 1e3))

    # -- files: rig config, model, store, constraint ------------------------------------------
    rig_cfg = load_rig_config(rig)
    if rig_cfg.servos is None:
        raise RigConfigError(f"--rig {rig}: rig {rig_cfg.name!r} has no servo chain to drive")
    mdl = load_model(model)
    store = None
    session_constraint = session_patient = None
    alignment = None
    try:
        if db is not None:
            from rig.store import open_store

            store = open_store(db)
            if session_id is not None:
                sess = store.get_session(session_id)
                session_patient = sess.get("pseudonym")
                bounds = store.boundaries(session_id)
                if bounds:
                    session_constraint = loads_constraint(
                        bounds[-1]["constraint_yaml"],
                        source=f"boundary {bounds[-1]['id']} of session {session_id}")
                for cal in store.calibrations(session_id):
                    data = cal.get("data") or {}
                    if "thorax_mount" in data and "limb_mount" in data:
                        alignment = data
        explicit = load_constraint(constraint) if constraint is not None else None
        binding = bind_model(mdl, rig=rig_cfg, constraint=explicit,
                             constraint_source=f"--constraint {constraint}",
                             session_constraint=session_constraint, session_id=session_id,
                             session_patient=session_patient, force=force_model)
        for m in binding.mismatches:
            echo(f"warning: {m} (--force-model)")
        oracle = ConstraintOracle(binding.constraint)
        src = open_targets(targets, oracle=oracle, rig=rig_cfg, seed=seed, frames=frames)
        if alignment is not None and hasattr(src, "alignment"):
            from models import quaternion as Q

            src.alignment = {
                rig_cfg.joint.parent: tuple(Q.conjugate(alignment["thorax_mount"]).tolist()),
                rig_cfg.joint.child: tuple(Q.conjugate(alignment["limb_mount"]).tolist())}
        return _run_with_devices(
            rig_cfg=rig_cfg, mdl=mdl, binding=binding, oracle=oracle, src=src, cfg=cfg,
            tel_path=tel_path, sum_path=sum_path, store=store, session_id=session_id,
            patient=patient, session_patient=session_patient, echo=echo,
            install_signals=install_signals, on_cycle=on_cycle, clock=clock, ports=ports,
            result=result, open_port=open_port, prepare_chain=prepare_chain,
            EnforcementLoop=EnforcementLoop, Telemetry=Telemetry, targets_spec=targets)
    finally:
        if store is not None:
            store.close()


def _run_with_devices(*, rig_cfg, mdl, binding, oracle, src, cfg, tel_path, sum_path, store,
                      session_id, patient, session_patient, echo, install_signals, on_cycle,
                      clock, ports, result, open_port, prepare_chain, EnforcementLoop, Telemetry,
                      targets_spec) -> int:
    from rig.errors import RigConfigError

    servos = rig_cfg.servos
    ports = dict(ports or {})
    own_port = servos.port not in ports
    port = ports[servos.port] if not own_port else None
    chain = None
    telemetry = None
    run_id = enforce_session = None
    try:
        with src:
            if own_port:
                port = open_port(servos.port, baud=servos.baud)
            chain = prepare_chain(port, servos, oracle, log=echo)
            for tip in getattr(chain, "advice", []):
                echo(f"note: {tip}")
            # -- the store: an 'enforce' session and a run ------------------------------------
            store_writer = None
            if store is not None:
                pseudonym = patient or session_patient or binding.constraint.patient
                if pseudonym is None:
                    raise RigConfigError("--db: say whose run this is: --patient PSEUDONYM or "
                                         "--session ID")
                pid = store.ensure_patient(pseudonym)
                enforce_session = store.start_session(
                    pid, rig_name=rig_cfg.name, joint=rig_cfg.joint.name,
                    side=rig_cfg.joint.side, kind="enforce",
                    meta={"model": str(mdl.path), "targets": targets_spec,
                          "constraint_source": binding.source,
                          "recording_session": session_id})
                run_id = store.start_run(enforce_session, {
                    "rate_hz": cfg.rate_hz, "safe_state": cfg.safe_state,
                    "tolerance_deg": cfg.supervisor.tolerance_deg,
                    "constraint": binding.constraint.to_yaml()
                    if hasattr(binding.constraint, "to_yaml") else None,
                    "model": str(mdl.path), "targets": targets_spec})
                store_writer = store.telemetry_writer(run_id)
            telemetry = Telemetry(tel_path, store_writer, keep=result is not None)
            kw = {}
            if clock is not None:
                kw = {"clock": clock, "sleep": clock.sleep}
            loop = EnforcementLoop(chain, mdl, oracle, src, cfg, telemetry=telemetry,
                                   on_cycle=on_cycle, log=echo, **kw)
            if result is not None:
                result["loop"] = loop
                result["port"] = port
            echo(f"enforcing {binding.constraint.name!r} ({binding.source}) on rig "
                 f"{rig_cfg.name!r} at {cfg.rate_hz:g} Hz; model {mdl.path}; targets "
                 f"{src.description}; safe state {cfg.safe_state}")
            loop.setup()
            restore = _install_signals(loop) if install_signals else None
            try:
                summary = loop.run()
            finally:
                if restore is not None:
                    restore()
            telemetry.close()
            summary["model"] = str(mdl.path)
            summary["constraint"] = binding.constraint.name
            summary["constraint_source"] = binding.source
            summary["targets"] = src.description
            if hasattr(src, "dropped"):
                summary["target_samples_dropped"] = int(src.dropped)
            if store is not None:
                status = ("completed" if loop.safe_state_entries == 0 else
                          "interrupted" if loop.stop_reason else "safe_state")
                store.end_run(run_id, summary, status=status)
                store.end_session(enforce_session, status="completed" if status == "completed"
                                  else "interrupted" if status == "interrupted" else "failed",
                                  meta={"run_id": run_id})
                summary["session_id"] = enforce_session
                summary["run_id"] = run_id
            if sum_path is not None:
                from models.fileio import write_owner_only

                write_owner_only(sum_path, json.dumps(summary, indent=2, sort_keys=True) + "\n")
            if result is not None:
                result["summary"] = summary
                result["telemetry"] = telemetry
            echo(_summary_text(summary))
            if loop.stop_reason is not None:
                return 143 if "SIGTERM" in loop.stop_reason else 130
            return 1 if loop.safe_state_entries else 0
    except BaseException:
        if store is not None and run_id is not None:
            try:
                store.end_run(run_id, {"error": "aborted"}, status="failed")
                store.end_session(enforce_session, status="failed")
            except Exception:  # the original error matters more
                pass
        raise
    finally:
        if telemetry is not None:
            telemetry.close()
        if chain is not None:
            chain.close()
        if own_port and port is not None:
            port.close()


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


def _summary_text(s: dict) -> str:
    def f(v, fmt="{:.3f}"):
        return "n/a" if v is None else fmt.format(v)

    lines = [
        f"cycles {s['cycles']} at {f(s.get('achieved_hz'), '{:.1f}')} Hz (asked "
        f"{s['rate_hz']:g}); cycle p50 {f(s['p50_cycle_ms'])} ms, p99 {f(s['p99_cycle_ms'])} "
        f"ms; overruns {s['overruns']}; compute p50 {f(s['p50_compute_us'], '{:.0f}')} µs",
        f"max violation {s['max_violation_deg']:.3f}° (tolerance {s['tolerance_deg']:g}°); "
        f"interventions {s['interventions']} {s['interventions_by_kind']}",
        f"faults {s['faults'] or 'none'}; safe-state entries {s['safe_state_entries']}"
        + (f" ({s['safe_state_reason']})" if s.get("safe_state_reason") else "")
        + f"; end: {s['end_reason']}",
    ]
    return "\n".join(lines)
