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
@click.option("--amplitude-deg", type=click.FloatRange(min=5.0, max=45.0), default=25.0,
              show_default=True,
              help="How far each servo's move turns it (less where its tick range is narrow).")
@click.option("--ranges-s", type=click.FloatRange(min=1.0), default=20.0, show_default=True,
              help="Seconds to move every joint through its range.")
def calibrate(rig: str, out: Path, steps: str, port: str | None, note: str,
              amplitude_deg: float, ranges_s: float) -> None:
    """Calibrate a servo arm, torque off, by prompts a person follows.

    \b
    1. zero pose: every joint at its zero, held still (each servo's zero ticks);
    2. one move per servo, in chain order: from the zero pose, turn that servo's joint
       about that servo's axis alone, e.g. "shoulder: raise the arm sideways (abduction)
       by about 25°, turning servo ID 2 (shoulder-elevation) alone", hold, back to zero.
       Each servo must turn the way the rig's direction says, by at least a third of the
       turn asked, while every other servo stays still: every direction is confirmed by
       its own move, and a swapped ID or cable is refused naming both servos;
    3. ranges: every joint moved slowly through its whole range.

    On a sim://dynamixel port with a back-driven patient, the patient follows the prompts.
    """
    from rig.record.arm_calibration import CalibrateRequest, run_calibrate

    names = tuple(s.strip() for s in steps.split(",") if s.strip())
    result = run_calibrate(CalibrateRequest(rig, out, names, note, port, ranges_s=ranges_s,
                                            amplitude_deg=amplitude_deg), echo=click.echo)
    if result.unconfirmed:
        click.echo(f"not confirmed by a move (the rig's direction kept): "
                   f"{', '.join(result.unconfirmed)}")
