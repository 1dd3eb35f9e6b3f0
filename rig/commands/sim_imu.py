"""``rig sim imu``: a simulated IMU on a pseudo-terminal.

Prints the port path (``/dev/pts/N``) as the first line on stdout, then serves until SIGINT or
SIGTERM and exits with status 0. Open the port with pyserial like a USB-UART::

    rig sim imu --protocol stream --rate 200 --sensors 4 &
    python -c "import serial; s = serial.Serial('/dev/pts/N') ..."
"""

from __future__ import annotations

import signal
import sys

import click

from rig.errors import RigConfigError

_MIN_RATE, _MAX_RATE = 100, 400


def build_simulator(protocol: str, rate: int, sensors: int, constraint: str | None, seed: int):
    """The simulator ``rig sim imu`` runs (started; the caller closes it).

    Raises
    ------
    RigConfigError
        Incompatible options, or a constraint file that cannot be used.
    """
    if not _MIN_RATE <= rate <= _MAX_RATE:
        raise RigConfigError(f"--rate {rate}: must be {_MIN_RATE}..{_MAX_RATE} Hz")
    if protocol == "bno055" and sensors != 1:
        raise RigConfigError(
            f"--sensors {sensors}: a BNO055 UART serves one sensor; use --protocol stream")
    if not 1 <= sensors <= 16:
        raise RigConfigError(f"--sensors {sensors}: must be 1..16")
    from rig.sim.imu import Bno055Simulator, StreamImuSimulator
    from rig.sim.limb import SimulatedLimb

    n_limb = 2 if protocol == "bno055" else sensors
    if constraint is not None:
        try:
            from models.constraint import load_constraint
        except ImportError as err:  # pragma: no cover - models.constraint is part of the package
            raise RigConfigError(f"--constraint {constraint}: constraint support missing") from err
        limb = SimulatedLimb.from_constraint(load_constraint(constraint), sensors=n_limb,
                                             seed=seed)
    else:
        limb = SimulatedLimb(sensors=n_limb, seed=seed)
    if protocol == "bno055":
        return Bno055Simulator(limb, rate_hz=rate)
    return StreamImuSimulator(limb, rate_hz=rate, min_rate_hz=min(10, rate),
                              max_rate_hz=max(400, rate))


@click.command("imu")
@click.option("--protocol", type=click.Choice(["bno055", "stream"]), default="stream",
              show_default=True, help="Wire protocol: BNO055 UART registers or the rig stream.")
@click.option("--rate", type=int, default=100, show_default=True,
              help="Fusion/sample rate in Hz (100-400).")
@click.option("--sensors", type=int, default=None,
              help="Sensors on the stream device (1-16; default 4; bno055: 1).")
@click.option("--constraint", type=click.Path(dir_okay=False), default=None,
              help="Joint-constraint YAML file giving the shoulder's range of motion.")
@click.option("--seed", type=int, default=0, show_default=True, help="Seed of motion and noise.")
def imu(protocol: str, rate: int, sensors: int | None, constraint: str | None, seed: int) -> None:
    """Serve a simulated IMU on a pseudo-terminal; print its port, run until Ctrl-C/SIGTERM."""
    if sensors is None:
        sensors = 1 if protocol == "bno055" else 4
    # block the stop signals before the server thread starts, so that only sigwait sees them
    stop = {signal.SIGINT, signal.SIGTERM}
    old = signal.pthread_sigmask(signal.SIG_BLOCK, stop)
    try:
        sim = build_simulator(protocol, rate, sensors, constraint, seed)
        try:
            click.echo(sim.port)
            sys.stdout.flush()
            signal.sigwait(stop)
        finally:
            sim.close()
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)
