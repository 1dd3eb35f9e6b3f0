"""A recording session, start to end: ``rig record`` is a thin layer over :func:`record`.

Sequence (every step that can fail on a user mistake comes before anything is recorded)
------------------------------------------------------------------------------------------
1. Check the options; load the rig configuration (unknown keys, bad values → RigConfigError);
   open the devices (wrong port, silent device → RigConnectionError / RigTimeoutError); open
   the store. The CLI shows any of these as one line, exit 2, nothing written.
2. Create (or find) the pseudonymised patient, start the session, register its sensors, start
   the reader thread (:class:`~rig.record.pump.SamplePump`) and the store's sample writer. From
   here on every sample is written, calibration steps included.
3. **Guided calibration** (:mod:`rig.record.guided`): a static neutral pose, then functional
   flexion/extension. On simulated rigs the steps advance by themselves (the simulated patient
   performs them); on hardware the clinician is prompted and presses Enter. The calibration and
   its residual are stored (``store.calibrations.add``).
4. **Recording** until ``duration_s`` of sample time, Ctrl-C / SIGTERM, or a vanished device.
   Joint orientations (calibrated) feed the live :class:`~calibration.coverage.CoverageMap`.
   On a calibrated IMU rig the patient's returns to the neutral pose are marked as
   **neutral checkpoints** (:class:`~rig.record.guided.NeutralCheckpoints`: the simulated
   patient's schedule, or Enter on hardware), each stored as it ends
   (``store.calibrations.add(session, "neutral-checkpoint", {"window": [t0, t1], "time": ...})``)
   for the read path's heading re-zeroing.
5. **End**: the reader is stopped, the queue drained, the writer closed (last commit) and the
   session ended with its status (``completed``, ``interrupted``, ``device_lost``, ``failed``)
   and counts (samples, sequence gaps, queue overflow).

Crash safety is the store's commit cadence: the writer commits at least once a second, so a
``kill -9`` loses at most the last second; SQLite's WAL keeps the file consistent.
"""

from __future__ import annotations

import contextlib
import math
import signal
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from calibration.coverage import CoverageMap
from calibration.joints import JOINTS
from rig.errors import RigConfigError, RigConnectionError, RigError
from rig.record.display import PlainDisplay, RecordStatus
from rig.record.guided import (
    AnglesReached,
    GuidedCalibration,
    NeutralCheckpoints,
    patient_performs_protocol,
)
from rig.record.procedures import CalibrationResult, procedure_for
from rig.record.pump import SampleBatch, SamplePump
from rig.record.rigio import OpenRig, load_config, open_rig
from rig.store import SampleWriter, open_store

__all__ = ["Annotation", "RecordOptions", "RecordResult", "parse_annotation", "record"]


@dataclass(frozen=True)
class Annotation:
    """A note attached to the recording at ``at_s`` seconds of sample time (None: at start)."""

    text: str
    at_s: float | None = None


def parse_annotation(spec: str) -> Annotation:
    """``"text"`` (at the start) or ``"12.5:text"`` (12.5 s into the recording)."""
    head, sep, tail = spec.partition(":")
    if sep:
        try:
            at = float(head)
        except ValueError:
            return Annotation(spec.strip())
        if not math.isfinite(at) or at < 0:
            raise RigConfigError(f"--annotate {spec!r}: the time must be >= 0 seconds")
        if not tail.strip():
            raise RigConfigError(f"--annotate {spec!r}: no text after the time")
        return Annotation(tail.strip(), at)
    if not spec.strip():
        raise RigConfigError("--annotate: empty text")
    return Annotation(spec.strip())


@dataclass
class RecordOptions:
    """What ``rig record`` takes (see :func:`record`).

    Attributes
    ----------
    rig : str
        Rig configuration name (``sim-imu``) or YAML path.
    db : str
        Store path or URL.
    patient : str
        Pseudonym (never a real name).
    duration_s : float or None
        Recording length in sample time after calibration; None: until Ctrl-C.
    annotations : sequence of Annotation
    calibrate : bool
        Run the guided calibration steps (default). Without them the recording is stored raw
        and calibration must come from elsewhere.
    queue_batches : int
        Capacity of the reader → writer queue, in batches.
    rom : bool
        At the end, extract the boundary from the session and store the clinical range of
        motion (:func:`calibration.clinical.range_of_motion`) in the session's metadata
        (``rom``) — only for calibrated recordings (IMU) or joint samples (servo limb).
    coverage : dict
        Keyword arguments of :class:`~calibration.coverage.CoverageMap`.
    source_options : dict
        Extra keyword arguments for opening the orientation source.
    """

    rig: str
    db: str
    patient: str
    duration_s: float | None = None
    annotations: Sequence[Annotation] = ()
    calibrate: bool = True
    queue_batches: int = 1024
    rom: bool = True
    coverage: dict = field(default_factory=dict)
    source_options: dict = field(default_factory=dict)

    def check(self) -> None:
        """Raise :class:`RigConfigError` on a bad option (before anything is opened)."""
        if not self.patient or not self.patient.strip():
            raise RigConfigError("--patient: a pseudonym is required")
        if self.duration_s is not None and not (math.isfinite(self.duration_s)
                                                and self.duration_s > 0):
            raise RigConfigError(f"--duration must be > 0 seconds, got {self.duration_s}")
        if self.queue_batches < 1:
            raise RigConfigError("queue size must be >= 1")


@dataclass
class RecordResult:
    """How a session ended.

    Attributes
    ----------
    session_id, patient_id : int
    status : str
        ``completed`` (duration reached), ``interrupted`` (Ctrl-C / SIGTERM), ``device_lost``
        (the source raised RigConnectionError), ``failed`` (anything else; re-raised).
    samples : int
        Samples written to the store.
    gaps, overflow : int
        Samples lost at the source (sequence gaps) and in the queue (writer too slow).
    span_s : float
        Sample time covered (first to last sample), seconds.
    first_t, last_t : float
        Host time (``t`` column) of the first and last sample written.
    calibration : CalibrationResult or None
    calibrated : bool
        The joint orientations are calibrated: an IMU recording with a stored ``imu-alignment``
        calibration, or a servo limb (its forward kinematics are the joint orientation; the
        ``servo-zero`` step only checks them). False for an IMU recording without one — its
        coverage and angles are sensor-frame approximations and say so.
    neutral_checkpoints : int
        Neutral checkpoints marked and stored (calibrated IMU rigs).
    rom, rom_table : dict, str or None
        Clinical range-of-motion peaks of the session's extracted boundary and their table
        (:mod:`calibration.clinical`), when computed; ``rom_note`` says why not otherwise.
    coverage : dict
        :meth:`CoverageSummary.as_dict` at the end.
    error : str or None
        What ended a ``device_lost`` session.
    """

    session_id: int
    patient_id: int
    status: str
    samples: int = 0
    gaps: int = 0
    overflow: int = 0
    span_s: float = 0.0
    first_t: float = math.nan
    last_t: float = math.nan
    calibration: CalibrationResult | None = None
    coverage: dict = field(default_factory=dict)
    error: str | None = None
    calibrated: bool = False
    neutral_checkpoints: int = 0
    rom: dict | None = None
    rom_table: str | None = None
    rom_note: str | None = None
    signal: int | None = None  # SIGINT / SIGTERM that ended the session, if one did

    @property
    def dropped(self) -> int:
        return self.gaps + self.overflow

    def summary(self) -> str:
        """The one line ``rig record`` ends with (and the browser's recording): the session,
        its status, samples and span, what was dropped, the calibration, the neutral
        checkpoints and the coverage."""
        text = (f"session {self.session_id}: {self.status}, {self.samples} samples over "
                f"{self.span_s:.1f} s, dropped {self.dropped} (sequence gaps "
                f"{self.gaps}, queue overflow {self.overflow})")
        if self.calibration is not None:
            text += f", calibration residual {self.calibration.residual_deg:.2f}°"
        elif not self.calibrated:
            text += ", NOT calibrated (sensor frames)"
        if self.neutral_checkpoints:
            text += f", {self.neutral_checkpoints} neutral checkpoints"
        cov = self.coverage
        if cov:
            text += (", coverage sufficient" if cov.get("sufficient") else
                     f", coverage {cov.get('explored_sectors', 0)}/"
                     f"{len(cov.get('sectors', []))} sectors")
        return text


class _Stop:
    """SIGINT / SIGTERM set a flag instead of raising somewhere inside a store commit."""

    def __init__(self, event: threading.Event) -> None:
        self.event = event
        self.signal: int | None = None
        self._old: dict[int, object] = {}

    def __enter__(self) -> _Stop:
        if threading.current_thread() is threading.main_thread():
            for sig in (signal.SIGINT, signal.SIGTERM):
                self._old[sig] = signal.signal(sig, self._handle)
        return self

    def _handle(self, signum, frame) -> None:
        self.signal = signum
        self.event.set()

    def __exit__(self, *exc: object) -> None:
        for sig, old in self._old.items():
            signal.signal(sig, old)


def record(
    options: RecordOptions,
    *,
    display=None,
    stop: threading.Event | None = None,
    on_event: Callable[[str, dict], None] | None = None,
    rig: OpenRig | None = None,
    stdin=None,
    complete: threading.Event | None = None,
) -> RecordResult:
    """Run one recording session (see the module docstring).

    Parameters
    ----------
    options : RecordOptions
    display : PlainDisplay or LiveDisplay, optional
        Default: plain progress lines on stdout.
    stop : threading.Event, optional
        Set it to end the session (as Ctrl-C does); SIGINT/SIGTERM also set it when called from
        the main thread.
    on_event : callable(name, info), optional
        Called at ``"session"`` (ids), ``"calibrated"``, ``"recording"`` and ``"committed"``
        (samples written so far) — used by tests and the CLI's machine-readable output.
    rig : OpenRig, optional
        An already opened rig (tests, benchmarks); otherwise opened from ``options.rig``. Either
        way it is closed at the end.
    complete : threading.Event, optional
        Set it to end the session as ``completed`` (the clinician's Stop in the web app: the
        coverage is judged enough), as reaching ``duration_s`` does (``interrupted`` when set
        before the calibration is done); ``stop`` ends it ``interrupted``.
    stdin : text stream with a file descriptor, optional
        Where Enter is read on hardware (default ``sys.stdin``): the calibration's start and
        the neutral checkpoints. The web app gives a pipe its "continue" button writes a
        newline to (:mod:`rig.web.jobs`); what Enter does at any moment is
        :attr:`RecordStatus.enter <rig.record.display.RecordStatus.enter>`.

    Returns
    -------
    RecordResult

    Raises
    ------
    RigConfigError, RigConnectionError, RigTimeoutError, FileNotFoundError
        Before anything is recorded: bad options, config, store path or ports.
    """
    options.check()
    stop = stop if stop is not None else threading.Event()
    display = display if display is not None else PlainDisplay()
    emit = on_event if on_event is not None else (lambda name, info: None)

    if rig is None:
        config = load_config(options.rig)
        rig = open_rig(config, calibrate=options.calibrate,
                       **options.source_options)  # wrong port: fails here, no DB yet
        try:
            store = open_store(options.db, readonly=False)  # it records: writable
        except BaseException:
            rig.close()
            raise
    else:
        config = rig.config
        try:
            store = open_store(options.db, readonly=False)  # it records: writable
        except BaseException:
            rig.close()
            raise
    with contextlib.ExitStack() as stack:
        stack.callback(_close, store)
        stack.callback(rig.close)
        result = _run(options, config, rig, store, display, stop, emit, stdin, complete)
        rig.close()  # devices first: the range of motion is computed from the store
        if options.rom:
            _range_of_motion(store, result, config)
        return result


def _range_of_motion(store, result: RecordResult, config) -> None:
    """Clinical peaks, stored in the session's metadata (never fails the session): the rig's
    calibration procedure's (:meth:`JointProcedure.range_of_motion
    <rig.record.procedures.JointProcedure.range_of_motion>`: the joint's boundary;
    :meth:`LimbProcedure.range_of_motion
    <rig.record.procedures.LimbProcedure.range_of_motion>`: every joint's).

    Only for calibrated joint orientations: an uncalibrated IMU recording has no anatomical
    frames, and angles from it would be numbers without meaning.
    """
    if result.samples == 0 or result.status == "failed":
        result.rom_note = "no range of motion: nothing recorded"
        return
    if not result.calibrated:
        result.rom_note = ("no range of motion: the recording is not calibrated (sensor frames, "
                           "not anatomical ones)")
        return
    procedure_for(config.limb).range_of_motion(store, result, config)


def _close(store) -> None:
    close = getattr(store, "close", None)
    if close is not None:
        close()


def _run(options, config, rig: OpenRig, store, display, stop, emit, stdin=None,
         complete: threading.Event | None = None) -> RecordResult:
    joint = config.joint
    patient_id = int(store.patients.ensure(options.patient.strip(), side=joint.side))
    meta = {"rig": config.name, "simulated": rig.simulated,
            "duration_s": options.duration_s, "sensors": [s.name for s in rig.sensors]}
    procedure = procedure_for(config.limb)
    meta.update(procedure.session_meta())  # a whole limb: every joint is read back from it
    kinds = {j.name: j.kind for j in getattr(config.servos, "joints", ())
             if j.kind != JOINTS[j.name].kind}
    if kinds:  # a servo limb's joints of another kind than their own (a forearm elbow)
        meta["kinds"] = kinds
    session_id = int(store.sessions.start(patient_id, rig_name=config.name, joint=joint.name,
                                          side=joint.side, kind="record", meta=meta))
    for s in rig.sensors:
        store.samples.add_sensor(session_id, s.name, segment=s.segment, kind=s.kind, port=s.port)
    emit("session", {"session_id": session_id, "patient_id": patient_id})
    result = RecordResult(session_id, patient_id, status="failed")
    status = RecordStatus(patient=options.patient, phase="starting",
                          duration_s=options.duration_s)
    coverage = CoverageMap(**{"centre": _range_centre(config), **options.coverage})
    writer = SampleWriter(store, session_id)
    pump = SamplePump(rig.source, maxsize=options.queue_batches)
    calib = GuidedCalibration(config, rig, display=display, procedure=procedure, stdin=stdin)
    checkpoints = NeutralCheckpoints(rig, display=display, stdin=stdin)
    reached = AnglesReached(joint.side)  # a whole limb's other joints (elbow, knee...)
    marking = False  # neutral checkpoints are being marked (calibrated IMU rig)
    pending = sorted(options.annotations, key=lambda a: -1.0 if a.at_s is None else a.at_s)
    t_start: float | None = None  # sample time (best clock) when recording proper began
    rate = _Rate()
    last_commit_report = -math.inf
    error: BaseException | None = None
    calibrate = options.calibrate
    if calibrate and rig.simulated and not patient_performs_protocol(rig):
        display.message("the simulated patient does not perform the calibration protocol: "
                        "calibration skipped, samples recorded raw")
        calibrate = False
    phase = "calibration" if calibrate else "recording"
    result.calibrated = rig.kind == "servo" and not calibrate  # FK: joint orientations as read
    if not calibrate and rig.kind != "servo":
        display.message("not calibrated: coverage and twist are shown in the sensors' frames "
                        "(thorax sensor⁻¹ ⊗ arm sensor), not anatomical ones")
    display.start()
    try:
        with _Stop(stop) as stopper:
            pump.start()
            if calibrate:
                calib.begin(stop)
            else:
                emit("recording", {"session_id": session_id})
            while True:
                batch = pump.get(timeout=0.1)
                if batch is not None:
                    _write(writer, batch)
                    result.samples += len(batch)
                    if math.isnan(result.first_t):
                        result.first_t = float(batch.t[0])
                    result.last_t = float(batch.t[-1])
                    rate.add(len(batch))
                    clock = batch.time()
                    if phase == "calibration":
                        done = calib.feed(batch)
                        if done:
                            try:
                                cal = calib.finish()
                            except ValueError as err:  # CalibrationError: repeat it
                                result.error = f"calibration failed: {err}"
                                raise RigError(f"calibration failed: {err} (session "
                                               f"{session_id} kept, status failed; repeat "
                                               "the recording)") from err
                            result.calibration = cal
                            result.calibrated = cal.model is not None or rig.kind == "servo"
                            store.calibrations.add(session_id, cal.kind, cal.data, cal.residual_deg)
                            if cal.model is not None:
                                display.message(f"calibration stored: {cal.kind}, residual "
                                                f"{cal.residual_deg:.2f}°")
                            else:  # servo limb: a check of the chain's zeros, no correction
                                display.message(f"calibration check stored: {cal.kind} (zero "
                                                f"and axis of the chain checked, no correction "
                                                f"applied), residual {cal.residual_deg:.2f}°")
                            emit("calibrated", {"residual_deg": cal.residual_deg})
                            if cal.model is not None and checkpoints.active:
                                calib.close()  # its Enter reader is done: one reader of stdin
                                checkpoints.begin()
                                marking = checkpoints.active
                                status.checkpoints = 0 if marking else None
                            phase = "recording"
                            emit("recording", {"session_id": session_id})
                    if phase == "recording":
                        if t_start is None:
                            t_start = float(clock[0])
                        joint_q, joint_t = calib.joint_orientations(batch)
                        if len(joint_q):
                            coverage.add(joint_q, joint_t)
                        reached.add(calib.other_joints(batch))
                        if marking:
                            for cp in checkpoints.feed(batch, joint_q, joint_t):
                                store.calibrations.add(session_id, "neutral-checkpoint",
                                                       cp.data, cp.residual_deg)
                            result.neutral_checkpoints = checkpoints.count
                            status.checkpoints = checkpoints.count
                        status.elapsed_s = float(clock[-1]) - t_start
                        while pending and (pending[0].at_s is None
                                           or pending[0].at_s <= status.elapsed_s):
                            note = pending.pop(0)
                            _annotate(store, session_id, float(batch.t[-1]), note.text, status)
                        if (options.duration_s is not None
                                and status.elapsed_s >= options.duration_s):
                            result.status = "completed"
                            break
                if complete is not None and complete.is_set() and not stop.is_set():
                    # before the calibration is done nothing usable is recorded: interrupted
                    result.status = "completed" if phase == "recording" else "interrupted"
                    break
                if stop.is_set():
                    result.status = "interrupted"
                    result.signal = stopper.signal
                    break
                if pump.finished:
                    if pump.error is not None:
                        error = pump.error
                        if not isinstance(error, RigConnectionError | OSError):
                            raise error
                        result.status = "device_lost"
                        result.error = str(error) or type(error).__name__
                    else:
                        result.status = "interrupted"
                    break
                now = time.monotonic()
                if now - last_commit_report >= 1.0:
                    last_commit_report = now
                    emit("committed", {"samples": result.samples, "last_t": result.last_t,
                                       "written": writer.written})
                status.phase = (calib.prompt if phase == "calibration" else
                                "recording" if result.calibrated else "recording, uncalibrated")
                if marking and checkpoints.prompt:
                    status.phase = f"recording — {checkpoints.prompt}"
                status.samples = result.samples
                status.last_t = result.last_t
                status.enter = calib.enter if phase == "calibration" else (
                    checkpoints.enter if marking else None)
                status.rate_hz = rate.value()
                status.dropped = pump.dropped
                writer.set_dropped(pump.dropped)
                if phase == "recording":
                    if rate.due_summary():
                        status.coverage = coverage.summary()
                        status.reached = coverage.reached()
                        status.angles = reached.peaks()
                display.update(status)
    except BaseException:
        result.status = "failed"
        raise
    finally:
        pump.stop()
        # what the reader had queued is kept, whatever ended the session
        for batch in pump.drain():
            _write(writer, batch)
            result.samples += len(batch)
            if math.isnan(result.first_t):
                result.first_t = float(batch.t[0])
            result.last_t = float(batch.t[-1])
        calib.close()
        checkpoints.close()
        if marking:
            display.message(f"neutral checkpoints marked: {result.neutral_checkpoints}")
        result.gaps = int(getattr(rig.source, "dropped", 0) or 0)
        result.overflow = pump.overflow
        writer.set_dropped(result.dropped)
        writer.close()
        final = coverage.summary()
        result.coverage = final.as_dict()
        result.span_s = final.t_span_s
        status.coverage = final
        status.reached = coverage.reached()
        status.angles = reached.peaks()
        status.enter = None
        status.last_t = result.last_t
        status.samples = result.samples
        status.dropped = result.dropped
        status.phase = result.status
        display.update(status, force=True)
        display.stop()
        end_meta = {
            "samples": result.samples, "dropped": result.dropped, "gaps": result.gaps,
            "queue_overflow": result.overflow, "coverage": result.coverage,
            "calibration_residual_deg": (None if result.calibration is None
                                         else result.calibration.residual_deg),
            "calibrated": result.calibrated,
        }
        if marking:
            end_meta["neutral_checkpoints"] = result.neutral_checkpoints
        if result.error:
            end_meta["error"] = result.error
        store.sessions.end(session_id, status=result.status, meta=end_meta,
                           dropped=result.dropped)
    return result


def _range_centre(config) -> np.ndarray | None:
    """Centre of the rig configuration's default constraint (cone centre, polygon interior)."""
    try:
        constraint = config.load_constraint()
    except Exception:  # a default that does not load is no reason to refuse a recording
        return None
    swing = getattr(constraint, "swing", None)
    for attr in ("centre", "interior"):
        c = getattr(swing, attr, None)
        if c is not None:
            return np.asarray(c, dtype=np.float64)
    return None


def _write(writer, batch: SampleBatch) -> None:
    writer.add_many(batch.t, batch.device_t, batch.name, batch.kind, batch.q, batch.status,
                    raw=batch.raw)


def _annotate(store, session_id: int, t: float, text: str, status: RecordStatus) -> None:
    store.annotations.add(session_id, t, text)
    status.annotations.append((status.elapsed_s, text))


class _Rate:
    """Samples per second over the last couple of real seconds (display only)."""

    def __init__(self) -> None:
        self._marks: list[tuple[float, int]] = []
        self._last_summary = -math.inf

    def add(self, n: int) -> None:
        now = time.monotonic()
        self._marks.append((now, n))
        while self._marks and now - self._marks[0][0] > 2.0:
            self._marks.pop(0)

    def value(self) -> float:
        if len(self._marks) < 2:
            return 0.0
        dt = self._marks[-1][0] - self._marks[0][0]
        return sum(n for _, n in self._marks[1:]) / dt if dt > 0 else 0.0

    def due_summary(self) -> bool:
        now = time.monotonic()
        if now - self._last_summary >= 0.25:
            self._last_summary = now
            return True
        return False


