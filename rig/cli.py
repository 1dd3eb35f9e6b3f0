"""Command-line interface: ``rig`` (console script) and ``python -m rig``.

The CLI is a thin layer: every command calls a function that the tests also call directly.
Sub-command groups live in :mod:`rig.commands` (one module per group) and are imported lazily, so
``rig --help`` stays fast and a broken optional piece cannot stop the others from loading.

User mistakes (bad files, bad options, missing ports) are reported as one line on stderr,
``rig: error: <what is wrong>``, with exit status 2; no traceback. ``RIG_DEBUG=1`` shows it.
"""

from __future__ import annotations

import os
import sys

import click

from rig import __version__
from rig.commands._lazy import lazy_group_class
from rig.errors import user_errors

# name -> (module, attribute, one-line help). Imported only when the command is used.
_COMMANDS: dict[str, tuple[str, str, str]] = {
    "demo": (
        "rig.commands.demo",
        "demo",
        "Run the main job on the simulated rig (no hardware needed).",
    ),
    "constraint": (
        "rig.commands.constraint",
        "constraint",
        "Validate and inspect joint-constraint files.",
    ),
    "dataset": ("rig.commands.dataset", "dataset", "Generate training datasets (thesis ch. 3-4)."),
    "scan": ("rig.commands.scan", "scan", "List the Dynamixel servos answering on a port."),
    "sim": ("rig.commands.sim", "sim", "Run a simulated servo chain or IMU on a pseudo-terminal."),
    "train": ("rig.commands.train", "train", "Train a corrective-constraint network, export ONNX."),
    "evaluate": ("rig.commands.train", "evaluate", "Metrics of an ONNX model on held-out data."),
    "enforce": (
        "rig.commands.enforce",
        "enforce",
        "Enforce a patient's joint limits on a servo limb in real time.",
    ),
    "calibrate": (
        "rig.commands.calibrate",
        "calibrate",
        "Calibrate a leader or follower servo arm (zero, directions, ranges) into a file.",
    ),
    "session": (
        "rig.commands.session",
        "session",
        "List the sessions in a store (--db); close one a killed recorder left running.",
    ),
    "record": (
        "rig.commands.record",
        "record",
        "Calibrate and record a patient's range of motion (live coverage display).",
    ),
    "export": (
        "rig.commands.export",
        "export",
        "Export a session's orientations as OpenSim .sto or CSV.",
    ),
    "boundary": (
        "rig.commands.boundary",
        "boundary",
        "Extract a patient-specific constraint file from a recording (session or .sto/.csv).",
    ),
    "rom": (
        "rig.commands.rom",
        "rom",
        "Print the clinical range of motion of a session, a file or a constraint.",
    ),
    "progress": (
        "rig.commands.progress",
        "progress",
        "A patient's range of motion across visits, each change against the MDC.",
    ),
    "report": (
        "rig.commands.report",
        "report",
        "Write the clinician's HTML report of a session.",
    ),
    "serve": (
        "rig.commands.serve",
        "serve",
        "Serve the clinic's local web app (patients, sessions, reports, progress).",
    ),
}


@click.group(
    cls=lazy_group_class(_COMMANDS), context_settings={"help_option_names": ["-h", "--help"]}
)
@click.version_option(__version__, "--version", prog_name="rig")
def cli() -> None:
    """Learn patient-specific joint limits and enforce them on a servo limb."""


def main(argv: list[str] | None = None) -> None:
    """Entry point; exits with 0 on success, 2 on a user error, 130 on Ctrl-C."""
    try:
        # In non-standalone mode click returns the code of a ``click.exceptions.Exit`` (and
        # ``ctx.exit(n)``) instead of raising it: honour it.
        rc = cli.main(args=argv, prog_name="rig", standalone_mode=False)
    except click.exceptions.Abort:
        click.echo("rig: aborted", err=True)
        sys.exit(130)
    except click.exceptions.Exit as exc:
        sys.exit(exc.exit_code)
    except click.UsageError as exc:
        # one line, like every other user mistake: "rig record: Invalid value for '--duration' ..."
        where = exc.ctx.command_path if exc.ctx is not None else "rig"
        click.echo(f"rig: error: {where}: {exc.format_message()} (see --help)", err=True)
        sys.exit(2)
    except click.ClickException as exc:
        click.echo(f"rig: error: {exc.format_message()}", err=True)
        sys.exit(exc.exit_code)
    except KeyboardInterrupt:
        sys.exit(130)
    except user_errors() as exc:
        if os.environ.get("RIG_DEBUG"):
            raise
        msg = str(exc) or type(exc).__name__
        if isinstance(exc, OSError) and exc.filename and str(exc.filename) not in msg:
            msg = f"{exc.filename}: {msg}"
        click.echo(f"rig: error: {msg}", err=True)
        sys.exit(2)
    sys.exit(rc if isinstance(rc, int) and not isinstance(rc, bool) else 0)
