"""``rig record``: record a patient's range of motion into the session store.

A thin layer over :func:`rig.record.record`: options → :class:`~rig.record.RecordOptions`, a
display (rich on a terminal, plain lines otherwise), and the exit status:

- 0 — the session ended as asked (``--duration`` reached);
- 1 — the device vanished mid-session (everything up to then is kept, status ``device_lost``);
- 130 / 143 — ended by Ctrl-C (SIGINT) / SIGTERM: everything recorded is kept (status
  ``interrupted``), the status says it was stopped, as for every rig command;
- 2 — a user mistake (bad option, config, unknown key, wrong port), one line, nothing recorded.
"""

from __future__ import annotations

import json
import sys

import click

from rig.commands._options import finite_seconds


@click.command("record")
@click.option("--rig", "rig_name", required=True, metavar="NAME|FILE",
              help="Rig configuration: a shipped name (sim-imu, sim-shoulder, sim-arm, "
                   "sim-leg) or a YAML file.")
@click.option("--db", required=True, metavar="DB",
              help="Session store: a SQLite path, sqlite:///... or postgresql://...")
@click.option("--patient", required=True, metavar="PSEUDONYM",
              help="The patient's pseudonym (never a real name).")
@click.option("--duration", type=float, default=None, metavar="S", callback=finite_seconds,
              help="Seconds to record after calibration (sample time); default: until Ctrl-C.")
@click.option("--annotate", "annotations", multiple=True, metavar="[T:]TEXT",
              help="A note stored with the session, at T seconds into the recording "
                   "(default: at its start). Repeatable.")
@click.option("--no-calibration", is_flag=True,
              help="Skip the guided calibration steps (raw samples only).")
@click.option("--no-rom", is_flag=True,
              help="Do not compute the clinical range of motion at the end.")
@click.option("--display", type=click.Choice(["auto", "live", "plain"]), default="auto",
              show_default=True, help="Live panel (terminal) or plain progress lines.")
@click.option("--events", is_flag=True,
              help="Print machine-readable JSON lines (session id, commits) on stdout.")
def record(rig_name, db, patient, duration, annotations, no_calibration, no_rom, display,
           events):
    """Calibrate, then record a patient's shoulder (or whole arm or leg, on a rig with
    `limb:`) moving to its limits.

    Shows the coverage of the (proximal joint's) boundary per direction while recording; stop
    with Ctrl-C once it says COVERAGE SUFFICIENT (or give --duration).
    """
    from rig.record import RecordOptions, make_display, parse_annotation, record_session

    opts = RecordOptions(
        rig=rig_name, db=db, patient=patient, duration_s=duration,
        annotations=[parse_annotation(a) for a in annotations], calibrate=not no_calibration,
        rom=not no_rom)
    opts.check()
    from rig.store.pseudonyms import pseudonym_warning

    if pseudonym_warning(patient):
        click.echo(f"warning: {pseudonym_warning(patient)}", err=True)

    def on_event(name: str, info: dict) -> None:
        if events:
            print(json.dumps({"event": name, **info}), flush=True)

    shown = make_display(display, stream=sys.stderr if events else sys.stdout)
    result = record_session(opts, display=shown, on_event=on_event)
    summary = result.summary()
    if events:
        print(json.dumps({"event": "end", "session_id": result.session_id,
                          "status": result.status, "samples": result.samples,
                          "dropped": result.dropped, "first_t": result.first_t,
                          "last_t": result.last_t, "calibrated": result.calibrated,
                          "rom": result.rom}), flush=True)
    click.echo(summary, err=events)
    if result.rom_table:
        click.echo(f"range of motion of session {result.session_id} (from its extracted "
                   f"boundary; stored in the session):\n{result.rom_table}", err=events)
    elif result.rom_note and opts.rom:
        click.echo(result.rom_note, err=events)
    if result.status == "device_lost":
        click.echo(f"rig: error: device lost during the recording: {result.error}; "
                   f"session {result.session_id} kept with everything recorded so far", err=True)
        sys.exit(1)
    if result.signal is not None:  # kept everything, but say it was stopped (as train does)
        sys.exit(128 + int(result.signal))
