"""``rig enforce``: keep a servo-driven limb inside a patient's range in a real-time loop (click
code over :func:`rig.loop.run_enforce`).

``rig enforce --rig NAME|FILE --model M.onnx --targets SOURCE [--rate HZ] [--duration S]
[--telemetry T.csv] [--summary-json S.json] [--db DB [--session ID | --patient P]]
[--constraint C.yaml] [--force-model] [--safe-state hold|torque-off] [--realtime] [--cpu N]
[--busy-wait] [--no-warm-up] [--start-mismatch-deg D] [--on-start-mismatch ramp|refuse]
[--at-end hold|rest] [--servo-max-velocity-deg-s V]
[--leader-spring GAIN_MA_PER_DEG[,MAX_MA[,DEAD_BAND_DEG]]]``

Exit status: 2 for a user mistake (one line, before anything moves), 0 when the loop ran to its
end, 1 when a fault put the limb in the safe state, 130 / 143 after SIGINT / SIGTERM (the limb
is left in the safe state). See :mod:`rig.loop` and ``docs/loop.md``.
"""

from __future__ import annotations

import sys

import click

from rig.commands._options import finite_seconds


@click.command("enforce")
@click.option("--rig", "rig_name", required=True, metavar="NAME|FILE",
              help="Rig configuration with a servo chain (e.g. sim-shoulder), a servo limb "
                   "(sim-servo-arm) or a YAML file.")
@click.option("--model", "model_path", required=True, metavar="M.onnx",
              help="Correction model from `rig train` (its metadata names its constraint; a "
                   "servo limb's: a limb model).")
@click.option("--targets", required=True, metavar="SOURCE",
              help="PATH.csv (t_s,w,x,y,z; a servo limb: t_s then <joint>_w,<joint>_x,"
                   "<joint>_y,<joint>_z per joint in the limb file's order), "
                   "script:slow|sweep|adversarial|hold[?seed=N], mirror / mirror:RIG (an "
                   "IMU-worn limb through the orientation sources), or leader:RIG|PORT (a "
                   "leader arm moved by a person: a rig configuration whose servos are the "
                   "leader, or a twin of the follower's servos on PORT).")
@click.option("--frames", type=click.Choice(["rig", "isb"]), default=None,
              help="Segment frames of a targets file's joint orientations: rig (default) or "
                   "isb (+Y proximal, +X anterior, +Z right).")
@click.option("--rate", type=float, default=200.0, show_default=True, metavar="HZ",
              help="Loop rate.")
@click.option("--duration", type=float, default=None, metavar="S", callback=finite_seconds,
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
              help="Constraint to enforce, a limb file for a servo limb (default: the "
                   "session's boundary, else the rig config's, else the model's own).")
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
@click.option("--watchdog-ms", type=int, default=None, metavar="MS",
              help="The servos' Bus Watchdog: a servo that hears nothing from the loop for "
                   "this long stops, and the loop enters its safe state (0-2540 ms, 20 ms "
                   "steps; 0: off; default: the rig configuration's).")
@click.option("--stale-target-ms", type=float, default=None,
              help="A target older than this holds the last safe goal (default 100 ms; with "
                   "--targets leader:... 1.5 loop periods).")
@click.option("--seed", type=int, default=0, show_default=True, help="Seed of scripted targets.")
@click.option("--realtime", is_flag=True,
              help="Run the loop's thread with real-time priority (SCHED_FIFO) and hold idle "
                   "CPUs awake (PM QoS CPU latency 0) for the run, when the system allows it "
                   "(one line says what it does not allow).")
@click.option("--cpu", type=int, default=None, metavar="N",
              help="Pin the loop's thread to CPU N.")
@click.option("--busy-wait", is_flag=True,
              help="Spin between cycles instead of sleeping: the compute runs on a hot CPU, "
                   "at the cost of a whole core (give it one with --cpu N).")
@click.option("--no-warm-up", "no_warm_up", is_flag=True,
              help="Do not run the compute once on the last target shortly before each "
                   "deadline (the warm-up keeps the real compute's caches warm; it costs that "
                   "compute again in CPU time per cycle).")
@click.option("--start-mismatch-deg", type=float, default=20.0, show_default=True,
              metavar="D", help="The first target further than this from the limb's present "
                               "posture in any joint is a start-up mismatch.")
@click.option("--on-start-mismatch", type=click.Choice(["ramp", "refuse"]), default="ramp",
              show_default=True,
              help="ramp: move to the first target at the velocity limits (always so); refuse: "
                   "end before anything moves (one line, exit 2).")
@click.option("--at-end", type=click.Choice(["hold", "rest"]), default="hold",
              show_default=True,
              help="At a normal end (duration, the targets' end): hold the last goal, or slide "
                   "to the rest pose (the servos' zero pose, nearest admissible) at the velocity "
                   "limits first. Faults and Ctrl-C: --safe-state.")
@click.option("--servo-max-velocity-deg-s", type=float, default=None, metavar="V",
              help="Per-servo velocity limit: no servo's goal moves more than V × period a "
                   "cycle (default: off; the joints' --max-velocity-deg-s still applies).")
@click.option("--leader-spring", default=None, metavar="GAIN[,MAX_MA[,DEAD_BAND_DEG]]",
              help="With --targets leader:...: the limit felt at the leader — while the "
                   "patient's limit binds, each leader servo is pulled towards the posture "
                   "the limits admit with GAIN mA per degree, at most MAX_MA (default 150), "
                   "free within DEAD_BAND_DEG (default 1) (current-based position mode; "
                   "default: off).")
@click.option("--quiet", is_flag=True, help="Print only the summary line.")
def enforce(rig_name, model_path, targets, frames, rate, duration, telemetry_path,
            summary_path, db, session_id, patient, constraint_path, force_model, safe_state,
            tolerance_deg, max_velocity_deg_s, max_accel_deg_s2, stale_servo_ms, watchdog_ms,
            stale_target_ms, seed, realtime, cpu, busy_wait, no_warm_up, start_mismatch_deg,
            on_start_mismatch, at_end, servo_max_velocity_deg_s, leader_spring, quiet) -> None:
    """Enforce a patient's joint limits on a servo limb in real time."""
    from rig.loop import EnforceHooks, EnforceRequest, run_enforce
    from rig.store.pseudonyms import pseudonym_warning

    if pseudonym_warning(patient):
        click.echo(f"warning: {pseudonym_warning(patient)}", err=True)
    result = run_enforce(
        EnforceRequest(
            rig=rig_name, model=model_path, targets=targets, frames=frames, rate_hz=rate,
            duration_s=duration, telemetry=telemetry_path, summary_json=summary_path, db=db,
            session_id=session_id, patient=patient, constraint=constraint_path,
            force_model=force_model, safe_state=safe_state, tolerance_deg=tolerance_deg,
            max_velocity_deg_s=max_velocity_deg_s, max_accel_deg_s2=max_accel_deg_s2,
            stale_servo_ms=stale_servo_ms, watchdog_ms=watchdog_ms,
            stale_target_ms=stale_target_ms, seed=seed,
            realtime=realtime, cpu=cpu, busy_wait=busy_wait, warm_up=not no_warm_up,
            start_mismatch_deg=start_mismatch_deg, on_start_mismatch=on_start_mismatch,
            at_end=at_end, servo_max_velocity_deg_s=servo_max_velocity_deg_s,
            leader_spring=leader_spring),
        echo=(lambda m: None) if quiet else click.echo,
        hooks=EnforceHooks(install_signals=True))
    if quiet:
        click.echo(result.summary_line())
    if result.exit_status:
        sys.exit(result.exit_status)
