"""``rig scan PORT [--baud B]``: which Dynamixel servos answer on a bus, at which baud rate.

Per-ID PINGs through ``dynamixel_sdk`` (:func:`rig.devices.dynamixel.find_servos`); every X-series
rate the SDK can set when no ``--baud`` is given, fastest first. The model name comes from the
SDK's control-table files. Each servo's Homing Offset (ticks) and direction (Drive Mode bit 0:
normal / reverse) are read after its PING and shown beside it ("-" for a model without the
item), so a servo calibrated by another tool stands out. Nothing answering is an error
(exit 2), with the rates tried.
"""

from __future__ import annotations

import click


def parse_id_ranges(text: str) -> list[int]:
    """``"1-3,7"`` -> ``[1, 2, 3, 7]`` (IDs 0..252)."""
    from rig.errors import RigConfigError

    ids: list[int] = []
    try:
        for part in text.split(","):
            part = part.strip()
            if not part:
                continue
            if "-" in part:
                lo, hi = (int(x) for x in part.split("-", 1))
                ids.extend(range(lo, hi + 1))
            else:
                ids.append(int(part))
    except ValueError as err:
        raise RigConfigError(f"--ids {text!r}: expected IDs or ranges like 1-3,7") from err
    if not ids or any(not 0 <= i <= 252 for i in ids):
        raise RigConfigError(f"--ids {text!r}: IDs must be 0..252")
    return sorted(set(ids))


@click.command()
@click.argument("port")
@click.option("--baud", type=int, default=None,
              help="Only this baud rate (default: every X-series rate, fastest first).")
@click.option("--ids", "ids_text", default="0-252", show_default=True,
              help="IDs to ping, e.g. 1-3,7.")
@click.option("--latency-ms", type=float, default=None,
              help="Latency in the SDK's timeout formula (default: the adapter's USB latency "
                   "timer; 50 ms on a simulator).")
def scan(port: str, baud: int | None, ids_text: str, latency_ms: float | None) -> None:
    """List the servos answering on PORT (/dev/ttyUSB0, COM3 or sim://dynamixel?...)."""
    from rig.devices.dynamixel import find_servos

    header = False

    def show(info) -> None:
        nonlocal header
        if not header:
            click.echo(f"{'ID':>3}  {'model':<14} {'firmware':>8}  {'baud':>8}  "
                       f"{'homing':>8}  direction")
            header = True
        offset = "-" if info.homing_offset is None else str(info.homing_offset)
        direction = "-" if info.reverse is None else ("reverse" if info.reverse else "normal")
        click.echo(f"{info.id:>3}  {info.model:<14} {info.firmware:>8}  {info.baud:>8}  "
                   f"{offset:>8}  {direction}")

    find_servos(port, baud=baud, ids=parse_id_ranges(ids_text), latency_ms=latency_ms,
                on_found=show, on_note=lambda tip: click.echo(f"rig: note: {tip}", err=True))
