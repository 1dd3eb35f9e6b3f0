"""``rig sim servos|imu [URL]``: a simulator that speaks a real wire protocol on a pty.

The simulator is described by the port string a rig config or ``--port`` carries
(``sim://dynamixel?ids=1,2,3``, ``sim://imu-stream?sensors=4&rate=200``,
``sim://bno055?patient=original``) and started by :func:`rig.devices.ports.open_port`, so the
command takes exactly the keys a port takes, with the same checks and the same one-line errors
(an unknown key is an error). ``docs/sim.md`` lists the keys.

Each command prints the port path (``/dev/pts/N``) as the first line on stdout, then serves
until SIGINT or SIGTERM, closes the simulator and exits 0. Open the path with
``dynamixel_sdk.PortHandler`` or ``serial.Serial`` as if it were a USB adapter::

    rig sim imu 'sim://imu-stream?sensors=4&rate=200' &
    python -c "import serial; s = serial.Serial('/dev/pts/N') ..."
"""

from __future__ import annotations

import contextlib
import gc
import os
import signal
import sys
import threading

import click

from rig.errors import RigConfigError


def serve(url: str, devices: tuple[str, ...], example: str, what: str | None = None, *,
          stop_on_stdin_eof: bool = False, realtime: bool = False) -> None:
    """Start the simulator ``url`` names (one of ``devices``), print its port, serve until
    SIGINT/SIGTERM (or, with ``stop_on_stdin_eof``, until stdin closes: the parent process
    that started it ended), close it. With ``realtime`` its threads run under ``SCHED_FIFO``
    when the system allows it (a simulator standing in for hardware answers on time whatever
    the host does; silently normal priority otherwise).

    Raises
    ------
    RigConfigError
        Not a ``sim://`` URL of one of ``devices``; an unknown key or a bad value (named);
        ``clock=manual``, which nothing would advance in a process of its own.
    """
    # block the stop signals before any thread starts (the simulator's server thread, and the
    # BLAS threads importing numpy starts), so they inherit the mask and only this thread
    # receives them (sigwait: no polling, no handler races)
    stop = {signal.SIGINT, signal.SIGTERM}
    old_mask = signal.pthread_sigmask(signal.SIG_BLOCK, stop)
    if realtime and hasattr(os, "SCHED_FIFO"):  # before any thread starts: they inherit it
        with contextlib.suppress(OSError):
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(SIM_RT_PRIORITY))
    try:
        from rig.devices.ports import open_port
        from rig.sim.clock import ManualClock
        from rig.sim.urls import query_keys, sim_device

        sim_device(url, devices, example, what)
        if "process" in query_keys(url):
            raise RigConfigError(f"{url}: process= is for a port opened by another program "
                                 f"(this command is already the simulator's own process)")
        with open_port(url) as port:
            if isinstance(port.simulator.clock, ManualClock):
                raise RigConfigError(f"{url}: clock=manual: nothing would advance the clock of "
                                     f"a simulator in its own process (time_scale= runs it "
                                     f"faster than real time)")
            # what is alive now (the simulator, its patient, numpy) leaves the cyclic garbage
            # collector's view: a full collection would otherwise hold a reply for milliseconds
            gc.collect()
            gc.freeze()
            # a back-driving patient's motion is computed by a thread of this process in
            # bursts (rig.devices._sim_backends._BackDrive); at the default 5 ms switch
            # interval a reply waited up to 5 ms for the interpreter lock at every step, and
            # the host's reads timed out (device lost): the simulator's thread takes it back
            # within 0.2 ms
            sys.setswitchinterval(SIM_SWITCH_INTERVAL_S)
            click.echo(port.path)
            sp = port.simulated_patient
            if stop_on_stdin_eof and sp is not None:  # the parent's copy of the patient
                click.echo(f"{sp.t0!r} {sp.scale!r} {sp.device_t0!r}")
            click.get_text_stream("stdout").flush()
            if stop_on_stdin_eof:
                threading.Thread(target=_stop_at_eof, args=(port,), daemon=True,
                                 name="stdin-eof").start()
            signal.sigwait(stop)
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old_mask)


#: SCHED_FIFO priority of a simulator standing in for hardware: above the live loop's
#: (:data:`rig.loop.realtime.RT_PRIORITY`), as a servo answers whatever the host is doing.
SIM_RT_PRIORITY = 45

#: The interpreter's switch interval in a simulator's own process (``sys.setswitchinterval``).
SIM_SWITCH_INTERVAL_S = 0.0002


def _stop_at_eof(port) -> None:
    """Obey the parent's lines on stdin (:func:`rig.devices._sim_backends.serve_control`) to
    its end, then stop the process (SIGTERM to itself: ``sigwait`` takes it)."""
    from rig.devices._sim_backends import serve_control

    with contextlib.suppress(OSError, ValueError):
        serve_control(port, sys.stdin.buffer)
    os.kill(os.getpid(), signal.SIGTERM)


@click.group()
def sim() -> None:
    """Run a simulated device on a pseudo-terminal (no hardware needed).

    The device is a port string, as in a rig config: its keys are listed in docs/sim.md.
    """


@sim.command("servos", short_help="Simulated Dynamixel servo chain (sim://dynamixel?...).")
@click.argument("url", default="sim://dynamixel")
@click.option("--stop-on-stdin-eof", is_flag=True, hidden=True,
              help="Stop when stdin closes (a parent process's ``process=on`` port).")
@click.option("--realtime", is_flag=True, hidden=True,
              help="SCHED_FIFO when permitted (a parent process's ``process=on`` port).")
def servos(url: str, stop_on_stdin_eof: bool, realtime: bool) -> None:
    """Simulated Dynamixel Protocol 2.0 servo chain, e.g. 'sim://dynamixel?ids=1,2,3'.

    Keys: ids, model, baud, return_delay_us, noise, seed, wire_time, usb_latency_ms,
    time_scale; patient, chain, speed, excursion (a simulated patient back-drives the chain;
    limb, side: an arm or leg patient, with chain=sim-servo-arm).
    Default: one
    XM430-W350 (ID 1) at 1 000 000 bit/s.
    """
    from rig.sim.dynamixel.url import EXAMPLE

    serve(url, ("dynamixel", "dxl"), EXAMPLE, stop_on_stdin_eof=stop_on_stdin_eof,
          realtime=realtime)


@sim.command("imu", short_help="Simulated IMU (sim://imu-stream?... or sim://bno055?...).")
@click.argument("url", default="sim://imu-stream")
@click.option("--stop-on-stdin-eof", is_flag=True, hidden=True,
              help="Stop when stdin closes (a parent process's ``process=on`` port).")
@click.option("--realtime", is_flag=True, hidden=True,
              help="SCHED_FIFO when permitted (a parent process's ``process=on`` port).")
def imu(url: str, stop_on_stdin_eof: bool, realtime: bool) -> None:
    """Simulated IMU: 'sim://imu-stream?...' (the rig stream protocol) or 'sim://bno055?...'
    (a BNO055 UART).

    Keys (both): patient, seed, noise, misplace_deg, excursion, speed, calibrate, rate,
    time_scale; imu-stream: sensors, max_lag, flow; bno055: sensor. Default: a 2-sensor stream
    board at 100 Hz.
    """
    serve(url, ("imu-stream", "stream", "bno055"), "sim://imu-stream?sensors=4&rate=200",
          "imu-stream or bno055", stop_on_stdin_eof=stop_on_stdin_eof, realtime=realtime)
