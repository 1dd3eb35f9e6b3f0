"""``rig demo``: the whole job end to end on the simulated rig (no hardware needed).

A simulated patient with an irregular concave shoulder range → calibration → recording through
the IMUs and the back-driven servo limb → boundary extraction → training (``rig train``'s
default preset) → ONNX export → held-out evaluation → live enforcement against targets that try
to leave the range → the clinician's report; everything in ``<out>/rig.db``; a one-screen
summary with a verdict per stage. The stages are :mod:`rig.demo.joint` (``--limb``:
:mod:`rig.demo.limb`), run by :func:`rig.demo.pipeline.run_demo`.

``--dxl-port`` / ``--imu-port`` (hardware or ``sim://`` ports) are opened and exercised first
— ping, sync reads, IMU quaternions — so a wrong port, baud or missing servo is one line,
exit 2, before anything is written; the pipeline itself always runs on the simulators, whose
patient has a known true range to judge the results against.

Exit status: 0 when no stage failed, 1 otherwise, 2 on a user mistake.
"""

from __future__ import annotations

import sys
from pathlib import Path

import click


@click.command()
@click.option("--out", "out_dir", default="demo-output", show_default=True,
              type=click.Path(file_okay=False), help="Folder for the files the demo writes.")
@click.option("--seed", type=int, default=0, show_default=True,
              help="Seed of the simulated patient's motion, training and targets.")
@click.option("--quick", is_flag=True, help="Smoke-test size (short recordings and loop).")
@click.option("--limb", type=click.Choice(["arm", "leg"]), default=None,
              help="A whole simulated arm or leg (4 IMUs, coupled limits) instead of the "
              "shoulder: recorded, extracted, trained, evaluated and reported.")
@click.option("--rate", "rate_hz", type=float, default=200.0, show_default=True,
              help="Rate of the live enforcement loop, Hz.")
@click.option("--dxl-port", envvar="RIG_DXL_PORT", default=None,
              help="A Dynamixel port to check first (hardware or sim://). Env: RIG_DXL_PORT.")
@click.option("--dxl-ids", default="1,2,3", show_default=True,
              help="Servo IDs expected on --dxl-port (1 to 3, parent to child).")
@click.option("--dxl-baud", type=int, default=1_000_000, show_default=True,
              help="Dynamixel bus baud rate (X-series factory default: 57600).")
@click.option("--imu-port", envvar="RIG_IMU_PORT", default=None,
              help="A BNO055 UART port to check first (hardware or sim://). Env: RIG_IMU_PORT.")
def demo(out_dir, seed, quick, limb, rate_hz, dxl_port, dxl_ids, dxl_baud, imu_port) -> None:
    """Run the whole job on the simulated rig and write a report (no hardware needed)."""
    from rich.console import Console

    from rig.demo import DemoOptions, run_demo

    console = Console(highlight=False)
    # --dxl-ids, --dxl-baud and --rate are the shoulder's: the limb demo does not read them
    result = run_demo(DemoOptions(out=Path(out_dir), seed=seed, quick=quick, dxl_port=dxl_port,
                                  dxl_ids=dxl_ids, dxl_baud=dxl_baud, imu_port=imu_port,
                                  rate_hz=rate_hz, limb=limb), console=console)
    print_summary(result, console)
    if not result.ok:
        sys.exit(1)


_STYLE = {"PASS": "bold green", "WARN": "bold yellow", "FAIL": "bold red", "INFO": "cyan",
          "SKIP": "dim"}


def summary_table(result):
    """The one-screen summary: stage, time, verdict, what it is based on (a rich Table)."""
    from rich.table import Table

    table = Table(title=f"rig demo — {result.out}", title_justify="left", expand=True,
                  show_lines=False)
    table.add_column("stage", no_wrap=True)
    table.add_column("time", justify="right", no_wrap=True)
    table.add_column("verdict", no_wrap=True)
    table.add_column("based on", ratio=1)
    for s in result.stages:
        table.add_row(s.name, f"{s.seconds:.1f} s", f"[{_STYLE[s.verdict]}]{s.verdict}[/]",
                      s.detail)
    table.add_row("total", f"{result.total_s:.1f} s", "", "", end_section=True)
    return table


def print_summary(result, console) -> None:
    """Print :func:`summary_table`, the database and the report's path."""
    console.print()
    console.print(summary_table(result))
    console.print(f"database: {result.db}   sessions: "
                  + ", ".join(f"{k} {v}" for k, v in result.sessions.items() if v is not None),
                  markup=False, soft_wrap=True)  # a path is never broken across lines
    if result.report is not None:
        console.print(f"report:   {result.report}  (open it in a browser)", markup=False,
                      soft_wrap=True)
    verdict = "every stage ran" if result.ok else "a stage FAILED (see above)"
    console.print(f"[bold]{verdict}[/bold] in {result.total_s:.0f} s")
