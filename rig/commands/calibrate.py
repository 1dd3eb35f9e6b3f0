"""``rig calibrate --rig R --out arm-cal.yaml [--steps zero,directions,ranges]``: the guided
calibration of a leader or follower servo arm (:func:`rig.record.arm_calibration.run_calibrate`),
written as a file a rig configuration may name (``servos.calibration``; docs/devices.md)."""

from __future__ import annotations

from pathlib import Path

import click


@click.command()
@click.option("--rig", "rig", required=True, help="Shipped rig name or rig file (servos).")
@click.option("--out", "out", required=True, type=click.Path(dir_okay=False, path_type=Path),
              help="The calibration file to write (YAML).")
@click.option("--steps", default="zero,directions,ranges", show_default=True,
              help="Which steps to measure; the others keep the rig's values.")
@click.option("--port", default=None, help="Instead of the rig's servos.port.")
@click.option("--note", default="", help="Free text stored in the file.")
@click.option("--ranges-s", type=click.FloatRange(min=1.0), default=20.0, show_default=True,
              help="Seconds to move every joint through its range.")
def calibrate(rig: str, out: Path, steps: str, port: str | None, note: str,
              ranges_s: float) -> None:
    """Calibrate a servo arm: zero pose, each servo's direction by a guided move, ranges."""
    from rig.record.arm_calibration import CalibrateRequest, run_calibrate

    names = tuple(s.strip() for s in steps.split(",") if s.strip())
    result = run_calibrate(CalibrateRequest(rig, out, names, note, port, ranges_s=ranges_s),
                           echo=click.echo)
    if result.unconfirmed:
        click.echo(f"not confirmed by a move (the rig's direction kept): "
                   f"{', '.join(result.unconfirmed)}")
