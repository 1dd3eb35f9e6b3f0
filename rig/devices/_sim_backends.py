"""``sim://`` backends of :func:`rig.devices.ports.open_port` (imported only when used).

:func:`open_sim_port` starts the simulator a port string names (:data:`rig.sim.urls.SIM_DEVICES`)
on a pseudo-terminal and returns a :class:`~rig.devices.ports.Port` whose ``close`` stops it,
with the :class:`~rig.devices.ports.SimulatedPatient` view of its patient. The query is parsed
once, by :class:`rig.sim.urls.SimUrl`; the simulated patient (``patient=`` and the other patient
keys) is resolved by :func:`rig.sim.patients.patient_from_url`, for the IMU simulators and the
back-driven servo bus alike.

Back-driving (``sim://dynamixel?...&patient=...``): each servo's hand position is a function of
the simulator's clock, ``ticks_i(t) = IK(limb.joint(t - t0))_i`` with the joint's closed-form
inverse kinematics (:class:`rig.devices.kinematics.JointKinematics`), evaluated once per
millisecond of simulated time and shared by the servos; the IK solution nearest the previous one
keeps the joint angles continuous. While torque is off, Present Position follows it
(:meth:`rig.sim.dynamixel.DynamixelBus.set_hand`), as a clinician moving a back-drivable limb.
With ``hand_stiffness=K`` (N·m/rad; ``hand_damping=B``, N·m·s/rad, default ``0.01 K``) the hand
is an impedance instead: it pushes ``K (θ_hand − θ) − B ω`` on each shaft, torque on or off — a
therapist pushing a leader arm that may push back (:mod:`rig.loop.leader_spring`).

A bus of its own (``sim://dynamixel?...&process=on``): the servos are served by ``rig sim servos``
in a child process, as hardware is outside the host process — the simulator's thread then takes
neither the interpreter lock nor the scheduling of the process that drives it; where the system
allows it the child runs under ``SCHED_FIFO``, since the hardware it stands in for answers on
time whatever the host does. ``open_port(...,
separate_process=True)`` asks for it unless the URL says ``process=off`` (the live loop does).
The port has no ``simulator`` object (nothing to inject faults into). A ``patient=`` (or
``limb=``) moves the limb in the child while torque is off, as a real patient moves a real
limb; the port's :class:`~rig.devices.ports.SimulatedPatient` is this process's copy of it
(the same keys: the same motion), on the child's clock origin and time scale (its second
line), and a protocol started on it is sent to the child, as for a stream board (below) — a
recorder has the patient of ``sim-servo-arm`` perform the limb's calibration protocol so.
Closing the port stops the child, and so does the parent's end
(the child stops when its stdin closes). The child runs in
a session of its own: a Ctrl-C at the terminal reaches the driving process, which still has a
bus to command its safe state on.

A stream board of its own (``sim://imu-stream?...&process=on``): ``rig sim imu`` in a child
process likewise (the shipped ``sim-arm`` and ``sim-leg`` rigs: a recorder starved on a busy
host must not starve its board). The recorder needs the patient, so the port's
:class:`~rig.devices.ports.SimulatedPatient` is this process's copy of it
(:func:`rig.sim.imu.stream_patient` of the same string moves alike), on the child's clock origin
and time scale (its second line); a protocol started on it is sent to the child
(:class:`_ProtocolSender`, :func:`serve_control`).
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import os
import select
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

from calibration.protocol import CalibrationProtocol, LimbCalibrationProtocol, ServoMoveProtocol
from rig.devices.config import load_rig_config
from rig.devices.kinematics import NEAREST_TOLERANCE_DEG, JointKinematics, LimbKinematics
from rig.devices.port import Port, SimulatedPatient
from rig.errors import RigConfigError, RigConnectionError, UnreachableError
from rig.sim.clock import ManualClock, ScaledClock
from rig.sim.dynamixel.url import DEVICES, EXAMPLE, KEYS, bus_from_query
from rig.sim.imu import StreamImuSimulator, stream_patient, stream_query
from rig.sim.patients import limb_from_url, patient_from_url
from rig.sim.urls import SimUrl, query_keys, sim_device_of, with_keys, without_keys

BACKDRIVE_KEYS = ("patient", "chain", "speed", "excursion", "limb", "side", "hand_stiffness",
                  "hand_damping")
"""The keys a ``sim://dynamixel`` URL takes besides the bus's: the back-driving patient's
(``seed`` is the bus's, shared) and its hand's (:func:`hand_impedance`)."""

#: ``hand_damping`` when only ``hand_stiffness`` is given, seconds × K: a 10 ms time constant.
HAND_DAMPING_S = 0.01


def hand_impedance(q: Any) -> tuple[float | None, float | None]:
    """``(stiffness N·m/rad, damping N·m·s/rad)`` of the back-driver's hand from ``q``'s
    ``hand_stiffness`` / ``hand_damping`` (:meth:`rig.sim.dynamixel.DynamixelBus.set_hand`):
    ``(None, None)`` without ``hand_stiffness`` — the rigid hand, exactly as before; damping
    defaults to :data:`HAND_DAMPING_S` × stiffness.

    Raises
    ------
    RigConfigError
        A value out of range, or ``hand_damping`` without ``hand_stiffness`` (naming the URL).
    """
    k = q.number("hand_stiffness", None, 0.0, open_lo=True)
    b = q.number("hand_damping", None, 0.0)
    if k is None:
        if b is not None:
            raise RigConfigError(f"{q.url}: hand_damping needs hand_stiffness (an impedance "
                                 "hand)")
        return None, None
    return k, (HAND_DAMPING_S * k if b is None else b)

_BLOCK_MS = 100  # the back-drive's ticks are computed this many milliseconds at a time
_AHEAD_BLOCKS = 10  # ... and this many blocks ahead of the last one asked for

PROCESS_KEY = "process"
"""``process=on``: serve the servos from a child process (see the module docstring)."""

#: How long a child simulator may take to start (import, open its pty) before the port fails.
CHILD_START_S = 60.0


def open_sim_port(url: str, *, baud: int | None = None,
                  separate_process: bool = False) -> Port:
    """The port of the simulator ``url`` names (``baud``: the host's line speed, which a
    simulated Dynamixel bus without ``baud=`` runs at; ``separate_process``: a servo bus's
    default for ``process=``)."""
    device = sim_device_of(url)
    if device.name == "dynamixel":
        return _open_dynamixel(url, baud, device.kind, separate_process)
    if device.name == "imu-stream":
        try:
            q = stream_query(url, (PROCESS_KEY,))
            if q.flag(PROCESS_KEY, separate_process):
                return _open_stream_process(q, device.kind)
        except RigConfigError as err:  # every message names the URL
            raise RigConfigError(str(err) if url in str(err) else f"{url}: {err}") from err
        return _open_imu(url, device.start(without_keys(url, PROCESS_KEY)), device.kind)
    return _open_imu(url, device.start(url), device.kind)


def _patient(limb: Any, clock: Any, clock_t0: float, **kwargs: Any) -> SimulatedPatient:
    """The view of a patient whose motion time is 0 when the simulator's ``clock`` reads
    ``clock_t0``: :attr:`~rig.devices.ports.SimulatedPatient.t0` is host monotonic time on the
    real clock and on a :class:`~rig.sim.clock.ScaledClock` (its ``host_time``), the clock's own
    reading on a :class:`~rig.sim.clock.ManualClock` (whose time no host time corresponds to)."""
    if isinstance(clock, ScaledClock):
        t0, scale = float(clock.host_time(clock_t0)), clock.scale
    else:
        t0, scale = float(clock_t0), 1.0
    return SimulatedPatient(limb, clock=clock, clock_t0=clock_t0, t0=t0, scale=scale, **kwargs)


class _BackDrive:
    """Servo ticks of a simulated patient through its limb's IK, one value per millisecond.

    ``limb`` is the patient (:meth:`~rig.sim.limb.SimulatedLimb.joints`: its posture, (N, J, 4))
    and ``kinematics`` the servo limb's :class:`~rig.devices.kinematics.LimbKinematics` of the
    same J joints: each joint's servos take the IK solution of its orientation nearest their
    ticks of the millisecond before; a joint whose orientation is out of its reach stays put
    (the others move).

    The ticks are computed in blocks of :data:`_BLOCK_MS` milliseconds (the patient's posture
    vectorised over the block), in order from time 0, by a worker thread that keeps
    :data:`_AHEAD_BLOCKS` blocks (1 s of patient time) ahead of the last one asked for: a
    whole limb's patient computes its motion's knots in bursts — 70-230 ms every 10 s of
    motion on arm 3 (the largest where the protocol hands over to free motion) — which the
    servos' answers must not wait for. A block not ready when asked is computed there and
    then, unless the worker is computing (a burst): the limb then holds its last position for
    that answer (an answer never waits) — but with ``wait`` (a manual clock: no real time,
    every answer the same whatever the threads do) it waits for the block. A protocol the
    patient is told to perform starts 2 s later
    (:meth:`~rig.devices.port.SimulatedPatient.start_protocol`); the blocks computed before it
    was told still show the motion it replaces.
    """

    def __init__(self, limb: Any, kinematics: Any, t0: float, *, wait: bool = False,
                 frames: Any = ()) -> None:
        self.limb = limb
        self.frames = tuple(frames)  # each servo's ServoFrame (empty: the factory's)
        self.wait = wait
        self.kin = kinematics
        self.t0 = t0
        self._lock = threading.Lock()  # computing blocks, in order
        self._blocks: dict[int, np.ndarray] = {}
        self._next = 0  # the first block not computed
        self._last = kinematics.zero_ticks.astype(np.float64)
        self._served = self._last
        self._asked = 0  # the latest block asked for
        self.unreachable = 0
        self._wanted = 0
        self._wake = threading.Condition()
        self._closed = False
        self._worker: threading.Thread | None = None  # started by the first ask (ticks)

    def ticks(self, now: float) -> np.ndarray:
        key = max(0, int(now * 1000.0) - round(self.t0 * 1000.0))
        b = key // _BLOCK_MS
        self._asked = max(self._asked, b)
        block = self._blocks.get(b)
        if block is None:
            if not self._lock.acquire(blocking=self.wait):  # the worker is in a burst: an
                return self._served                        # answer does not wait, the limb
                                                           # holds still
            try:
                self._compute(b)
                block = self._blocks[b]
            finally:
                self._lock.release()
        if b + _AHEAD_BLOCKS >= self._next:
            with self._wake:
                if self._worker is None and not self._closed:
                    self._worker = threading.Thread(target=self._work, name="back-drive",
                                                    daemon=True)
                    self._worker.start()
                self._wanted = max(self._wanted, b + _AHEAD_BLOCKS)
                self._wake.notify()
        self._served = block[key - b * _BLOCK_MS]
        return self._served

    def _compute(self, upto: int) -> None:
        """Blocks ``self._next`` .. ``upto`` (lock held), dropping those long past (two blocks
        before the latest asked for)."""
        while self._next <= upto:
            b = self._next
            t = (b * _BLOCK_MS + np.arange(_BLOCK_MS)) / 1000.0
            q = self.limb.joints(t)
            out = np.empty((_BLOCK_MS, len(self._last)))
            ticks = self._last
            for i in range(_BLOCK_MS):
                ticks, missed = self._step(q[i], ticks)
                self.unreachable += missed > 0
                out[i] = ticks
            self._last = ticks
            self._blocks[b] = out
            for old in [k for k in self._blocks if k < self._asked - 2]:
                del self._blocks[old]  # long past: the clock does not go back
            self._next = b + 1

    def _work(self) -> None:
        while True:
            with self._wake:
                while not self._closed and self._wanted < self._next:
                    self._wake.wait()
                if self._closed:
                    return
                wanted = self._wanted
            with self._lock:
                self._compute(min(wanted, self._next))  # a block at a time: asks come first

    def close(self) -> None:
        """Stop the worker (idempotent)."""
        with self._wake:
            self._closed = True
            self._wake.notify()
            worker = self._worker
        if worker is not None and worker is not threading.current_thread():
            worker.join()

    def _step(self, q: np.ndarray, ticks: np.ndarray) -> tuple[np.ndarray, int]:
        """The servos' ticks for the posture ``q`` (J, 4): each joint's IK solution nearest its
        part of ``ticks``, or that part unchanged where the joint's orientation is out of reach
        (the servo limb cannot follow: it stays put). Also says how many joints were not
        reached."""
        out = ticks.copy()
        missed = 0
        for joint, s, qj in zip(self.kin.joints, self.kin.slices, q, strict=True):
            try:
                out[s] = joint.inverse_float(qj, ticks[s])
            except UnreachableError:
                missed += 1
        return out, missed

    def follow(self, joint_q: np.ndarray) -> tuple[np.ndarray, int]:
        """The postures (N, J, 4) the servos take, from their zero, while the patient moves
        through ``joint_q`` (N, J, 4), unquantised, and at how many instants some joint was
        out of reach."""
        ticks = self.kin.zero_ticks.astype(np.float64)
        out = np.empty((len(joint_q), len(ticks)))
        missed = 0
        for i, q in enumerate(joint_q):
            ticks, m = self._step(q, ticks)
            missed += m > 0
            out[i] = ticks
        return self.kin.forward_batch(out), missed

    def hand(self, index: int):
        """Servo ``index``'s hand position, a function of the simulator's time: ACTUAL shaft
        ticks (:meth:`rig.sim.dynamixel.DynamixelBus.set_hand`), the IK's ticks — in the frame
        the rig config gives the servo's registers (Present Position = (reverse ? −1 : 1) ×
        actual + Homing Offset, e-Manual "Homing Offset" / "Drive Mode") — taken back through
        its frame."""
        frame = self.frames[index] if self.frames else None
        if frame is None or (frame.homing_offset == 0 and not frame.reverse):
            return lambda now: float(self.ticks(now)[index])
        sign = -1.0 if frame.reverse else 1.0
        offset = float(frame.homing_offset)
        return lambda now: sign * (float(self.ticks(now)[index]) - offset)


def _open_dynamixel(url: str, baud: int | None, kind: str, separate_process: bool) -> Port:
    overrides: dict[str, Any] = {}
    try:
        q = SimUrl(url, DEVICES, (*KEYS, *BACKDRIVE_KEYS, PROCESS_KEY), EXAMPLE)
        if q.flag(PROCESS_KEY, separate_process):
            return _open_dynamixel_process(q, baud, kind)
        if "baud" not in q and baud is not None:
            overrides["baud_rate"] = int(baud)
        bus = bus_from_query(q, **overrides)
    except RigConfigError as err:  # every message names the URL
        raise RigConfigError(str(err) if url in str(err) else f"{url}: {err}") from err
    port = Port(url=url, path=bus.port, simulator=bus, kind=kind)
    port.add_closer(bus.close)
    own = [k for k in BACKDRIVE_KEYS if k in q]
    if "patient" not in q and "limb" not in q:
        if own:
            port.close()
            raise RigConfigError(f"{url}: {', '.join(sorted(own))} need patient= or limb=")
        return port
    try:
        port.simulated_patient, drive = _back_driving_patient(q, bus)
        port.add_closer(drive.close)
    except BaseException:
        port.close()
        raise
    return port


def _open_dynamixel_process(q: Any, baud: int | None, kind: str) -> Port:
    """``rig sim servos`` serving ``q``'s servos in a child process; the port of its pty."""
    url = q.url
    if q.text("clock") == "manual":
        raise RigConfigError(f"{url}: clock=manual: nothing would advance the clock of a "
                             f"simulator in its own process")
    child_url = without_keys(url, PROCESS_KEY)
    if "baud" not in q and baud is not None:
        child_url = with_keys(child_url, baud=int(baud))
    backdriven = "patient" in q or "limb" in q
    # first: a bad patient fails here, before a child starts; this process's copy of it
    limb, kin, _ = _back_driven_limb(q) if backdriven else (None, None, ())
    proc, closer, lines = _start_child("servos", url, child_url, 2 if backdriven else 1)
    port = Port(url=url, path=lines[0], simulator=None, kind=kind)
    port.add_closer(closer)
    if not backdriven:
        return port
    try:
        t0, scale, _ = (float(v) for v in lines[1].split())
        port.simulated_patient = SimulatedPatient(
            limb, clock=lambda: (time.monotonic() - t0) * scale, clock_t0=0.0, t0=t0,
            scale=scale, backdrive=_BackDrive(limb, kin, 0.0),
            protocol_pinned="calibrate" in q, on_protocol=_ProtocolSender(proc, url))
    except BaseException:
        port.close()
        raise
    return port


def _start_child(command: str, url: str, child_url: str, n_lines: int):
    """``rig sim <command>`` serving ``child_url`` in a child process (its own session,
    ``SCHED_FIFO`` where allowed, stopped when its stdin closes): the process, its closer and
    the first ``n_lines`` lines it printed (its pty path first)."""
    root = str(Path(__file__).resolve().parents[2])  # the folder holding the rig package
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        p for p in (root, os.environ.get("PYTHONPATH")) if p))
    err = tempfile.TemporaryFile()
    proc = subprocess.Popen(
        [sys.executable, "-m", "rig", "sim", command, "--stop-on-stdin-eof", "--realtime",
         child_url],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=err, env=env,
        start_new_session=True)
    closer = _ChildCloser(proc, err)
    try:
        lines = _first_lines(proc, n_lines, CHILD_START_S)
        if len(lines) < n_lines:
            proc.wait(timeout=CHILD_START_S)
            err.seek(0)
            said = [ln.strip() for ln in err.read().decode(errors="replace").splitlines()
                    if ln.strip()]
            last = said[-1] if said else f"exit status {proc.returncode}"
            raise RigConfigError(f"{url}: the simulator process did not start: "
                                 f"{last.removeprefix('rig: error: ')}")
    except BaseException:
        closer()
        raise
    return proc, closer, lines


def _first_lines(proc: subprocess.Popen, n: int, timeout: float) -> list[str]:
    """The child's first ``n`` stdout lines (its pty path first); fewer if it ended or said
    nothing more in time."""
    fd = proc.stdout.fileno()
    buf = b""
    end = time.monotonic() + timeout
    while buf.count(b"\n") < n:
        left = end - time.monotonic()
        if left <= 0 or not select.select([fd], [], [], left)[0]:
            break
        chunk = os.read(fd, 4096)
        if not chunk:
            break
        buf += chunk
    return [ln.decode().strip() for ln in buf.split(b"\n")[:n] if ln.strip()][:n]


class _ChildCloser:
    """Stops a child simulator: stdin closed (it stops), SIGTERM after 5 s, SIGKILL after 5 more."""

    def __init__(self, proc: subprocess.Popen, err: Any) -> None:
        self.proc = proc
        self.err = err

    def __call__(self) -> None:
        proc = self.proc
        with contextlib.suppress(OSError):
            proc.stdin.close()
        try:
            proc.wait(timeout=5.0)
        except subprocess.TimeoutExpired:
            proc.terminate()
            try:
                proc.wait(timeout=5.0)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        finally:
            proc.stdout.close()
            self.err.close()


def _back_driven_limb(q: Any) -> tuple[Any, Any, tuple]:
    """The patient of ``q``, the kinematics it moves the servos through (the ``chain=``
    rig's, each servo with its own resolution) and the servos' frames (their registers' Homing
    Offset / reverse in that rig config): a servo limb's (``chain=sim-servo-arm``) by an arm
    or leg patient (``limb=``, or ``patient=`` a limb file:
    :func:`~rig.sim.patients.limb_from_url`, its joints' kinds the rig's — a forearm elbow
    turns about its long axis too), a joint's by a joint's patient."""
    url = q.url
    chain_name = q.text("chain", "sim-shoulder")
    cfg = load_rig_config(chain_name)
    if cfg.servos is None:
        raise RigConfigError(f"{url}: chain={chain_name!r} has no servo chain")
    # pushed by the patient, a joint of fewer than three servos takes the nearest orientation
    # its axes reach (the closed-form decomposition; a two-servo wrist cannot twist): the IK's
    # tolerance is no limit here, the tick limits still are
    kin = LimbKinematics([JointKinematics(j.servos, tolerance_deg=NEAREST_TOLERANCE_DEG)
                          for j in cfg.servos.limb_kinematics().joints], cfg.servos.joint_names)
    # a servo limb wears no IMU: the default straps (the motion does not depend on them)
    kinds = {j.name: j.kind for j in cfg.servos.joints}
    limb = limb_from_url(q, kinds=kinds, misplaced_straps=False) or patient_from_url(
        q, sensors=2, misplaced_straps=False)
    n = len(limb.joints(0.0)[0])
    if n != len(kin):
        raise RigConfigError(f"{url}: chain {chain_name!r} has {len(kin)} joint"
                             f"{'s' if len(kin) > 1 else ''} ({', '.join(kin.names)}), the "
                             f"patient {n}")
    return limb, kin, tuple(cfg.servos.frames)


def _back_driving_patient(q: Any, bus: Any) -> tuple[SimulatedPatient, _BackDrive]:
    """The patient of ``q`` (:func:`_back_driven_limb`) moving ``bus``'s servos; and what
    moves them (closed with the port)."""
    limb, kin, frames = _back_driven_limb(q)
    kin.compile()  # before the bus answers: no stall at a first read
    missing = [i for i in kin.ids if i not in bus.servos]
    if missing:
        raise RigConfigError(f"{q.url}: chain {q.text('chain', 'sim-shoulder')!r} needs servo "
                             f"IDs {list(kin.ids)}, the simulated bus has no ID {missing[0]}")
    t0 = bus.clock()
    drive = _BackDrive(limb, kin, t0, wait=isinstance(bus.clock, ManualClock), frames=frames)
    stiffness, damping = hand_impedance(q)
    for k, dxl_id in enumerate(kin.ids):
        if stiffness is None:  # the rigid hand (torque off), as always
            bus.set_hand(dxl_id, drive.hand(k))
            continue
        try:
            bus.set_hand(dxl_id, drive.hand(k), stiffness=stiffness, damping=damping)
        except ValueError as err:
            drive.close()
            raise RigConfigError(f"{q.url}: hand_stiffness={stiffness:g}: {err}") from None
    return _patient(limb, bus.clock, t0, backdrive=drive), drive


def _open_stream_process(q: Any, kind: str) -> Port:
    """``rig sim imu`` serving ``q``'s stream board in a child process; the port of its pty,
    with this process's copy of the patient (:func:`rig.sim.imu.stream_patient` of the same
    query: the same motion) as the port's simulated patient. The child prints its pty path,
    then when its patient's time was 0 (host monotonic time, shared by the processes) and how
    fast that time runs; a protocol started here is sent to the child on its stdin
    (:func:`serve_control`)."""
    url = q.url
    if q.text("clock") == "manual":
        raise RigConfigError(f"{url}: clock=manual: nothing would advance the clock of a "
                             f"simulator in its own process")
    limb = stream_patient(q)  # first: a bad patient fails here, before a child starts
    proc, closer, (path, timing) = _start_child("imu", url, without_keys(url, PROCESS_KEY), 2)
    port = Port(url=url, path=path, simulator=None, kind=kind)
    port.add_closer(closer)
    try:
        t0, scale, device_t0 = (float(v) for v in timing.split())
        send = _ProtocolSender(proc, url)
        port.simulated_patient = SimulatedPatient(
            limb, clock=lambda: (time.monotonic() - t0) * scale, clock_t0=0.0, t0=t0,
            scale=scale, device_t0=device_t0, protocol_pinned="calibrate" in q,
            on_protocol=send)
    except BaseException:
        port.close()
        raise
    return port


def _protocol_json(protocol: Any) -> str:
    """A calibration protocol (a frozen dataclass of numbers and names) as one line of JSON."""
    return json.dumps({"kind": type(protocol).__name__, **dataclasses.asdict(protocol)})


def _protocol_from_json(text: str) -> Any:
    """The protocol :func:`_protocol_json` wrote (JSON only: no code crosses the pipe; a
    :class:`~calibration.protocol.ServoMoveProtocol` turns its moves' mappings back into
    moves itself)."""
    d = json.loads(text)
    cls = {c.__name__: c for c in (CalibrationProtocol, LimbCalibrationProtocol,
                                   ServoMoveProtocol)}[d.pop("kind")]
    if d.get("amplitudes") is not None:  # JSON lists back to the dataclass's tuples
        d["amplitudes"] = tuple(tuple(a) for a in d["amplitudes"])
    return cls(**d)


class _ProtocolSender:
    """Has the patient of a child simulator perform a calibration protocol: one line on the
    child's stdin, ``protocol <start_s> <the protocol as JSON>``."""

    def __init__(self, proc: subprocess.Popen, url: str) -> None:
        self.proc = proc
        self.url = url

    def __call__(self, protocol: Any, start_s: float) -> None:
        try:
            self.proc.stdin.write(
                f"protocol {float(start_s)!r} {_protocol_json(protocol)}\n".encode())
            self.proc.stdin.flush()
        except (OSError, ValueError) as err:  # the child ended (or the port was closed)
            raise RigConnectionError("the simulator process is gone", port=self.url) from err


def serve_control(port: Port, stream: Any) -> None:
    """In a child simulator: obey the lines its parent writes on ``stream`` (stdin, binary)
    until it closes — ``protocol <start_s> <the protocol as JSON>``: the patient performs it
    from patient time ``start_s`` (:meth:`SimulatedPatient.start_protocol` in the parent)."""
    for line in iter(stream.readline, b""):
        words = line.split(None, 2)
        sp = port.simulated_patient
        if len(words) == 3 and words[0] == b"protocol" and sp is not None:
            sp.limb.perform_protocol(_protocol_from_json(words[2].decode()),
                                     start_s=float(words[1]))


def _open_imu(url: str, sim: Any, kind: str) -> Port:
    port = Port(url=url, path=sim.port, simulator=sim, kind=kind)
    port.add_closer(sim.close)
    try:
        # the simulator samples its patient at clock() - started_at (its device time); a
        # stream board's samples carry that time, from its timestamp offset
        device_t0 = (sim.timestamp_offset_us / 1e6 if isinstance(sim, StreamImuSimulator)
                     else 0.0)
        port.simulated_patient = _patient(sim.limb, sim.clock, sim.started_at,
                                          device_t0=device_t0,
                                          protocol_pinned="calibrate" in query_keys(url))
    except BaseException:
        port.close()
        raise
    return port
