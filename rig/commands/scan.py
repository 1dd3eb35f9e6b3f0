"""``rig scan PORT [--baud B]``: which Dynamixel servos answer on a bus, at which baud rate.

Per-ID PINGs through ``dynamixel_sdk`` (:func:`rig.devices.dynamixel.find_servos`); every X-series
rate the SDK can set when no ``--baud`` is given, fastest first. At each rate Protocol 2.0
PINGs, then Protocol 1.0 PINGs of the IDs still silent (AX, MX on 1.0 firmware; ``--protocol``:
by default both for at most 24 IDs, 2.0 alone for more — 1.0 has no broadcast PING). The model
name comes from the SDK's control-table files (1.0 models: the e-Manual's, typed in
:mod:`firmware_protocol.dynamixel.tables_protocol1`). Nothing answering is an error (exit 2),
with the rates tried. Each servo's Homing Offset (ticks) and direction (Drive Mode bit 0:
normal / reverse) are read after its PING and shown beside it ("-" for a model without the
item), so a servo calibrated by another tool stands out.
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
@click.option("--protocol", "protocol", type=click.Choice(["1", "2", "both"]), default=None,
              help="Protocols to ping in (default: both for at most 24 IDs, else 2).")
def scan(port: str, baud: int | None, ids_text: str, latency_ms: float | None,
         protocol: str | None) -> None:
    """List the servos answering on PORT (/dev/ttyUSB0, COM3 or sim://dynamixel?...)."""
    from rig.devices.dynamixel import find_servos

    header = False

    def show(info) -> None:
        nonlocal header
        if not header:
            click.echo(f"{'ID':>3}  {'model':<14} {'firmware':>8}  {'baud':>8}  protocol  "
                       f"{'homing':>8}  direction")
            header = True
        offset = "-" if info.homing_offset is None else str(info.homing_offset)
        direction = "-" if info.reverse is None else ("reverse" if info.reverse else "normal")
        click.echo(f"{info.id:>3}  {info.model:<14} {info.firmware:>8}  {info.baud:>8}  "
                   f"{info.protocol:>8.1f}  {offset:>8}  {direction}")

    protocols = {None: None, "1": (1.0,), "2": (2.0,), "both": (2.0, 1.0)}[protocol]
    find_servos(port, baud=baud, ids=parse_id_ranges(ids_text), latency_ms=latency_ms,
                on_found=show, on_note=lambda tip: click.echo(f"rig: note: {tip}", err=True),
                protocols=protocols)
