"""``rig sim servos``: a simulated Dynamixel X-series chain on a pseudo-terminal.

Prints the port path as the first line on stdout, serves until SIGINT or SIGTERM, then closes
the bus and exits 0. Open the printed path with ``dynamixel_sdk.PortHandler`` as if it were a
U2D2 adapter.
"""

from __future__ import annotations

import signal

import click

from rig.errors import RigConfigError


def parse_ids(text: str) -> list[int]:
    """``"1,2,3"`` or ``"1-3"`` -> ``[1, 2, 3]``; raises :class:`RigConfigError` on nonsense."""
    ids: list[int] = []
    try:
        for part in text.split(","):
            part = part.strip()
            if "-" in part:
                lo, hi = (int(p) for p in part.split("-", 1))
                ids.extend(range(lo, hi + 1))
            else:
                ids.append(int(part))
    except ValueError:
        raise RigConfigError(f"--ids: {text!r} is not a list of servo ids such as 1,2,3") \
            from None
    if not ids or any(not 0 <= i <= 252 for i in ids):
        raise RigConfigError(f"--ids: servo ids must be 0..252, got {text!r}")
    if len(set(ids)) != len(ids):
        raise RigConfigError(f"--ids: servo ids must be distinct, got {text!r}")
    return ids


@click.command("servos")
@click.option("--ids", default="1", show_default=True, help="Servo IDs, e.g. 1,2,3 or 1-3.")
@click.option("--model", default="XM430-W350", show_default=True,
              help="Servo model (e-Manual name), e.g. XM430-W350, XL430-W250, XC330-M288.")
@click.option("--baud", "baud_rate", default=1_000_000, show_default=True, type=int,
              help="Bus baud rate in bit/s (an X-series rate).")
@click.option("--return-delay-us", default=None, type=int,
              help="Return Delay Time in µs (default: the servo default, 500).")
@click.option("--noise-ticks", default=0.0, show_default=True, type=float,
              help="Encoder noise standard deviation, ticks.")
@click.option("--seed", default=0, show_default=True, type=int, help="Encoder noise seed.")
def servos(ids: str, model: str, baud_rate: int, return_delay_us: int | None,
           noise_ticks: float, seed: int) -> None:
    """Simulated Dynamixel Protocol 2.0 servo chain."""
    from rig.sim.dynamixel import start_servo_bus

    id_list = parse_ids(ids)
    # block the stop signals before the server thread starts, so it inherits the mask and
    # only this thread receives them (sigwait: no polling, no handler races)
    stop = {signal.SIGINT, signal.SIGTERM}
    old_mask = signal.pthread_sigmask(signal.SIG_BLOCK, stop)
    try:
        try:
            bus = start_servo_bus(id_list, model, baud_rate=baud_rate,
                                  return_delay_us=return_delay_us, noise_ticks=noise_ticks,
                                  seed=seed)
        except RigConfigError as err:  # name the option the message is about
            text = str(err)
            option = ("--model" if "model" in text else
                      "--return-delay-us" if "return delay" in text else "--baud")
            raise RigConfigError(f"{option}: {text}") from None
        with bus:
            click.echo(bus.port)
            click.get_text_stream("stdout").flush()
            signal.sigwait(stop)
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old_mask)
