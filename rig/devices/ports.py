"""Port strings choose the backend: hardware serial ports or simulators on pseudo-terminals.

The seam in the style of pyserial's URL handlers and python-can's interface table: a port string
is resolved once, here, and every driver above opens :attr:`Port.path` with the unchanged
``dynamixel_sdk`` / ``pyserial`` — no code above this module knows whether it has hardware.

Port strings
------------
``/dev/ttyUSB0``, ``/dev/ttyACM0``, ``/dev/serial/by-id/...``, ``COM3``
    Hardware: the path is used as is. On POSIX it is checked at once (exists, is a character
    device, is a terminal), so a wrong path fails in milliseconds, not after a long job.
``sim://dynamixel?ids=1,2,3&model=XM430-W350&baud=57600&return_delay_us=0&noise=0&seed=0``
    A simulated X-series servo bus (:mod:`rig.sim.dynamixel`). ``baud`` is the *servos'* rate; when
    absent the servos run at the rate the host asks for (``open_port(..., baud=B)``), so a URL
    with ``baud=57600`` opened at 1 Mbit/s is a bus where nobody answers, as on hardware.
    Extra keys handled here: ``patient=<shape name | constraint file>`` back-drives the servos
    (torque off) from a :class:`rig.sim.limb.SimulatedLimb` through the inverse kinematics of
    ``chain=<rig config name | file>`` (default ``sim-shoulder``), so a recording of the
    servo limb sees a patient's motion; ``speed`` scales that motion's frequencies,
    ``excursion`` its reach. ``usb_latency_ms`` is the USB adapter's latency timer (default 1,
    a U2D2 set as the SDK recommends); ``process=on`` serves the servos from a child process, as
    hardware is outside the host (:mod:`rig.devices._sim_backends`).
``sim://bno055?patient=original&seed=0&rate=100&sensor=1&noise=on|off``
    A simulated BNO055 on its UART (:func:`rig.sim.imu.bno055_from_url` lists the keys).
``sim://imu-stream?sensors=2&rate=200&patient=original&seed=1&flow=off`` (or ``sim://stream?...``)
    A simulated multi-IMU board speaking the rig stream protocol
    (:func:`rig.sim.imu.stream_from_url`). Sensor 0 is on the thorax, 1.. on the upper arm.
    ``process=on`` serves the board from a child process, the port's patient view being this
    process's copy of the same patient (:mod:`rig.devices._sim_backends`).

Unknown query keys are errors naming the key (one parser for every ``sim://`` string:
:class:`rig.sim.urls.SimUrl`; the simulated devices: :data:`rig.sim.urls.SIM_DEVICES`). A
simulator is started by :func:`open_port` and stopped by :meth:`Port.close`.

What code above the seam may ask of a simulated port
----------------------------------------------------
:attr:`Port.simulated_patient` is a :class:`SimulatedPatient` (None on hardware and on a
simulator nobody drives): the ground-truth limb, the patient's time for a host time, whether the
port back-drives servos (:meth:`SimulatedPatient.follow`), and having the patient start the
calibration protocol (:meth:`SimulatedPatient.start_protocol`). Nothing above this module looks
into a simulator object for these.
"""

from __future__ import annotations

import os
import stat

from rig.devices.port import Port, SimulatedPatient
from rig.errors import RigConfigError, RigConnectionError
from rig.sim.urls import SIM_DEVICES, query_keys, without_keys

__all__ = ["Port", "SimulatedPatient", "check_hardware_path", "open_port", "real_time_port"]


def open_port(url: str, *, baud: int | None = None, separate_process: bool = False) -> Port:
    """Resolve a port string: check a hardware path, or start a simulator.

    Parameters
    ----------
    url : str
        See the module docstring.
    baud : int, optional
        The line speed the host will use (a simulated Dynamixel bus without ``baud=`` in its
        URL runs its servos at this rate).
    separate_process : bool
        Serve a simulated servo bus or stream board from a process of its own unless its
        URL says ``process=off`` (a real-time loop's bus, as hardware is, outside the host
        process); nothing changes for hardware and the BNO055 simulator.

    Returns
    -------
    Port
        Close it (or use it as a context manager) to stop a simulator.

    Raises
    ------
    RigConfigError
        Unknown ``sim://`` device, unknown key or bad value.
    RigConnectionError
        A hardware path that does not exist or is not a serial port.
    """
    if not isinstance(url, str) or not url.strip():
        raise RigConfigError(f"port {url!r}: expected a device path or a sim:// URL")
    url = url.strip()
    if "://" in url:
        scheme = url.split("://", 1)[0]
        if scheme != "sim":
            hosts = ",".join(sorted(SIM_DEVICES))
            raise RigConfigError(f"port {url!r}: unknown scheme {scheme!r}; use a device path "
                                 f"(/dev/ttyUSB0, COM3) or sim://{{{hosts}}}")
        from rig.devices._sim_backends import (
            open_sim_port,  # lazy: only when a simulator is asked for
        )

        return open_sim_port(url, baud=baud, separate_process=separate_process)
    check_hardware_path(url)
    return Port(url=url, path=url)


def real_time_port(url: str) -> tuple[str, str | None]:
    """The port string a live loop opens for ``url``, and a note when it differs.

    A simulator's ``time_scale=`` runs its time — its servos' motion and Bus Watchdog, its
    patient — that many times faster than the host's: right for recording a long motion in a
    short test, wrong under a live loop, whose deadlines and watchdog checks are in the host's
    time (at ``time_scale=20`` a 1 s Bus Watchdog trips after 50 ms of the host's: a short
    stall of a loaded host stops the servos and the loop's goals are refused). The key is
    dropped, and the note says so; any other port string is returned as it is.
    """
    if not url.startswith("sim://") or "time_scale" not in query_keys(url):
        return url, None
    return without_keys(url, "time_scale"), (
        f"the simulated servos' time_scale is not used under the live loop: their time (motion, "
        f"Bus Watchdog) runs at the loop's ({url})")


def check_hardware_path(path: str) -> None:
    """Fail fast on a hardware path that cannot be a serial port (POSIX; no-op elsewhere).

    Raises
    ------
    RigConnectionError
        Missing path, not a character device, or not a terminal (e.g. ``/dev/null``).
    """
    if os.name != "posix":
        return
    try:
        st = os.stat(path)
    except FileNotFoundError:
        raise RigConnectionError("no such port (is the adapter plugged in? list candidates with "
                                 "`ls /dev/serial/by-id/`)", port=path) from None
    except OSError as err:
        raise RigConnectionError(f"cannot access the port: {err.strerror}", port=path) from err
    if not stat.S_ISCHR(st.st_mode):
        raise RigConnectionError("not a serial port (not a character device)", port=path)
    try:
        fd = os.open(path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
    except PermissionError as err:
        raise RigConnectionError("permission denied (add yourself to the 'dialout' group: "
                                 "`sudo usermod -aG dialout $USER`, then log in again)",
                                 port=path) from err
    except OSError as err:
        raise RigConnectionError(f"cannot open the port: {err.strerror}", port=path) from err
    try:
        if not os.isatty(fd):
            raise RigConnectionError("not a serial port (not a terminal device)", port=path)
    finally:
        os.close(fd)
