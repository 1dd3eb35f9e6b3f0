"""Guided calibration at the start of a recording, and joint orientations from samples.

The protocol is :class:`calibration.protocol.CalibrationProtocol`: a static neutral pose
(standing, arm hanging at the side, forearm forward; ``static_s``), then flexion/extension of
the straight arm in the sagittal plane (``functional_s``), with ``settle_s`` trimmed at both ends
of each phase. Its :meth:`~calibration.protocol.CalibrationProtocol.windows` slice the samples;
the maths is :class:`calibration.alignment.ImuJointCalibration` (IMU rigs). On a servo rig the
forward kinematics already give the joint orientation; the neutral pose then checks the chain's
zero (residual = RMS angle from the identity) and the functional movement its axis.

**Protocol time.** On a simulated rig the simulated patient performs the protocol from its own
time 0 and the steps advance by themselves: protocol time is the patient's time, from the
rig's :meth:`~rig.record.rigio.OpenRig.patient_time`. On hardware the clinician is prompted,
gets the patient into the neutral pose and presses Enter: protocol time starts at the first
sample after that, and the display says when to start the flexion/extension.

**Whole limbs.** A rig configuration with ``limb: arm|leg`` (one IMU per segment) follows
:class:`calibration.protocol.LimbCalibrationProtocol` instead: the static pose, then each
joint's flexion/extension in turn (proximal first), announced as it starts; the maths is
:class:`calibration.limb_calibration.LimbImuCalibration`, stored as an ``imu-limb``
calibration. The live joint orientations (coverage, checkpoints) are the proximal joint's.

Everything recorded during the protocol is also in the store; the windows used are in the
calibration's data.
"""

from __future__ import annotations

import math
import os
import select
import sys
import threading
from dataclasses import dataclass

import numpy as np

from calibration.errors import CalibrationError
from calibration.joint_angles import CLINICAL_MOVEMENTS, angle_peaks, joint_angles
from calibration.protocol import LimbCalibrationProtocol
from models import quaternion as Q
from rig.record.procedures import NEUTRAL_WORDS, CalibrationResult, procedure_for
from rig.record.pump import SampleBatch

__all__ = ["AnglesReached", "GuidedCalibration", "NeutralCheckpoints"]


class GuidedCalibration:
    """Runs the calibration protocol over the recorder's sample stream.

    Parameters
    ----------
    config : RigConfig
    rig : OpenRig
    display : display object (``message``)
    protocol : CalibrationProtocol or LimbCalibrationProtocol, optional
    stdin : text stream, optional
        Where Enter is read on hardware (default ``sys.stdin``).
    procedure : JointProcedure or LimbProcedure, optional
        The rig's calibration procedure (default :func:`~rig.record.procedures.procedure_for`
        the configuration's ``limb``).
    """

    def __init__(self, config, rig, *, display, protocol=None, stdin=None,
                 procedure=None) -> None:

        self.config = config
        self.rig = rig
        self.display = display
        self.procedure = (procedure if procedure is not None
                          else procedure_for(getattr(config, "limb", None)))
        if protocol is None and rig.simulated:
            protocol = rig.protocol  # the one the simulated patient performs
        if protocol is None:
            protocol = self.procedure.default_protocol()
        if not self.procedure.accepts(protocol):

            what = "a whole-limb" if isinstance(protocol, LimbCalibrationProtocol) else "a joint"
            raise CalibrationError(f"the {self.procedure.name(config)} rig was given {what} "
                                   "calibration protocol")
        self.protocol = protocol
        self.stdin = stdin if stdin is not None else sys.stdin
        self.parent = config.joint.parent
        self.child = config.joint.child
        self._origin: float | None = None  # hardware: sample time at which the protocol began
        self._armed = False
        self._said = 0  # movement phases announced (_phases)
        self._done = False
        self._batches: list[tuple[np.ndarray, SampleBatch]] = []  # (protocol time, batch)
        self._enter = threading.Event()
        self._stop_reader = threading.Event()
        self._reader: threading.Thread | None = None
        self._result: CalibrationResult | None = None
        self._last_parent: np.ndarray | None = None

    # -- progress --------------------------------------------------------------------------
    @property
    def prompt(self) -> str:
        if self._done:
            return "calibrated"
        if not self._armed:
            return "calibration: neutral pose, press Enter when ready"
        if not self._said:
            return "calibration: neutral pose, hold still"
        return f"calibration: {self._phases()[self._said - 1][2]}"

    @property
    def enter(self) -> str | None:
        """What pressing Enter does now (hardware, before the protocol starts), else None."""
        if self._reader is None or self._armed or self._enter.is_set():
            return None
        return "start the calibration: the patient is in the neutral pose"

    def _phases(self) -> list[tuple[float, str, str]]:
        """The movement phases after the static pose: (start, what to say, short prompt)."""
        return self.procedure.phases(self.protocol)

    def begin(self, stop: threading.Event) -> None:
        """Announce the protocol; on hardware wait (in the background) for Enter."""
        self.display.message(self.procedure.announcement(self.protocol))
        if self.rig.simulated:
            self._armed = True
            self.display.message("simulated patient: the steps advance by themselves")
            return
        self.display.message("press Enter when the patient is in the neutral pose")
        self._reader = threading.Thread(target=self._read_enter, name="rig-record-enter",
                                        daemon=True)
        self._reader.start()

    def _read_enter(self) -> None:
        # Enter, or EOF / no usable stdin (nobody will press it): start at once
        _watch_enter(self.stdin, self._stop_reader, lambda: False)
        if not self._stop_reader.is_set():
            self._enter.set()

    def _protocol_time(self, batch: SampleBatch) -> np.ndarray:
        if self.rig.simulated:
            return self.rig.patient_time(batch) - self.rig.protocol_start_s
        clock = batch.time()
        if self._origin is None:
            self._origin = float(clock[0])
        return clock - self._origin

    def feed(self, batch: SampleBatch) -> bool:
        """Take a batch; True once the whole protocol has been recorded."""
        if self._done:
            return True
        if not self._armed:
            if not self._enter.is_set():
                return False
            self._armed = True
            self.display.message(f"neutral pose: hold still ({self.protocol.static_s:g} s)")
        pt = self._protocol_time(batch)
        self._batches.append((pt, batch))
        last = float(pt[-1])
        phases = self._phases()
        while self._said < len(phases) and last >= phases[self._said][0]:
            self.display.message(phases[self._said][1])
            self._said += 1
        if last >= self.protocol.duration_s:
            self._done = True
        return self._done

    def close(self) -> None:
        self._stop_reader.set()
        if self._reader is not None:
            self._reader.join()
            self._reader = None

    # -- solving ---------------------------------------------------------------------------
    def window(self, name: str) -> SampleBatch:
        """Samples inside protocol window ``name`` (``"static"``, ``"functional"``; a limb's
        joints)."""
        lo, hi = self.protocol.windows()[name]
        parts = [b.select((pt >= lo) & (pt <= hi)) for pt, b in self._batches]
        return _concat(parts)

    def finish(self) -> CalibrationResult:
        """Compute the calibration from the recorded protocol."""
        result = self.procedure.solve(self.window, self.protocol, self.config, self.rig.kind)
        fields = self.procedure.protocol_fields
        result.data = {**result.data,
                       "protocol": {k: getattr(self.protocol, k) for k in fields},
                       "windows_s": {k: list(v) for k, v in self.protocol.windows().items()}}
        origin = self._clock_origin()
        if origin is not None:  # where the windows are on the samples' clock
            result.data["protocol"]["origin"] = origin
        self._result = result
        self._batches.clear()
        return result

    def _clock_origin(self) -> dict | None:
        """Where protocol time 0 is on the samples' clock (:meth:`SampleBatch.time`: device
        time where the device has one, else host time), stored as the calibration's
        ``protocol.origin``: ``{"time": "device_t" | "t", "t0": seconds}``, so that a window
        ``windows_s[name]`` is ``t0 + window`` in that clock. None when the recorded batches mix
        the two clocks or the offset is not constant (a simulator whose patient runs faster
        than the host's clock)."""
        if not self._batches:
            return None
        dev = np.concatenate([b.device_t for _, b in self._batches])
        has = np.isfinite(dev)
        if has.any() and not has.all():
            return None
        off = np.concatenate([b.time() - pt for pt, b in self._batches])
        if not np.isfinite(off).all() or float(np.ptp(off)) > 1e-3:
            return None
        return {"time": "device_t" if has.all() else "t", "t0": float(np.median(off))}

    def joint_orientations(self, batch: SampleBatch) -> tuple[np.ndarray, np.ndarray]:
        """Joint orientations (M, 4) and their times (M,) from a batch, calibration applied.

        IMU rigs: each child-segment sample is paired with the latest parent-segment sample
        (the stream device sends both in one frame with one timestamp).
        """
        if self.rig.kind == "servo":  # the proximal joint's (a servo limb reads them all)
            sel = (batch.kind == "joint") & (batch.name == self.rig.sensors[0].name)
            return batch.q[sel], batch.time()[sel]
        is_parent = batch.name == self.parent
        is_child = batch.name == self.child
        if not is_child.any():
            if is_parent.any():
                self._last_parent = batch.q[np.flatnonzero(is_parent)[-1]]
            return np.empty((0, 4)), np.empty(0)
        # forward-fill the latest parent sample over the rows
        idx = np.where(is_parent, np.arange(len(batch)), -1)
        idx = np.maximum.accumulate(idx)
        child_rows = np.flatnonzero(is_child)
        src = idx[child_rows]
        have = src >= 0
        parent_q = np.empty((len(child_rows), 4))
        parent_q[have] = batch.q[src[have]]
        if (~have).any():
            if self._last_parent is None:
                child_rows, parent_q = child_rows[have], parent_q[have]
            else:
                parent_q[~have] = self._last_parent
        if is_parent.any():
            self._last_parent = batch.q[np.flatnonzero(is_parent)[-1]]
        child_q = batch.q[child_rows]
        if self._result is not None and self._result.model is not None:
            q = self.procedure.live(self._result.model, parent_q, child_q)
        else:
            q = Q.multiply(Q.conjugate(parent_q), child_q)
        return q, batch.time()[child_rows]

    def other_joints(self, batch: SampleBatch) -> dict[str, np.ndarray]:
        """The live orientations of the rig's joints other than the proximal one (a whole
        limb's elbow and wrist, knee and ankle): ``{joint: (M, 4)}``, empty for a rig of one
        joint and, on an IMU limb, before the calibration (no anatomical frames yet). A servo
        limb's are its joint samples as read (forward kinematics)."""
        if self.rig.kind == "servo":
            names = [s.name for s in self.rig.sensors[1:]]
            sel = batch.kind == "joint"
            return {n: batch.q[sel & (batch.name == n)] for n in names
                    if (sel & (batch.name == n)).any()}
        if self._result is None or self._result.model is None:
            return {}
        return self.procedure.live_joints(self._result.model, batch, self.protocol)


class AnglesReached:
    """The clinical movements reached so far by a whole limb's other joints (degrees): for each
    joint of :data:`calibration.joint_angles.CLINICAL_MOVEMENTS`, the running largest peak of
    each movement. Orientations are kept as they come (:meth:`add`, per batch) and turned into
    angles when asked (:meth:`peaks`, at the display's cadence), median-filtered first as the
    recorded range of motion is (:func:`calibration.joint_angles.angle_peaks`, window 5) so
    that a single noisy sample claims nothing.

    Parameters
    ----------
    side : {"left", "right"}
    """

    def __init__(self, side: str) -> None:
        self.side = side if side in ("left", "right") else "right"
        self.peaks_: dict[str, dict[str, float]] = {}
        self._pending: dict[str, list[np.ndarray]] = {}

    def add(self, joints: dict[str, np.ndarray]) -> None:
        """Take each joint's orientations (M, 4) of a batch."""
        for joint, q in joints.items():
            if joint in CLINICAL_MOVEMENTS and len(q):
                self._pending.setdefault(joint, []).append(q)

    def peaks(self) -> dict[str, dict[str, float]]:
        """``{joint: {movement: degrees}}`` reached so far (a copy)."""
        pending, self._pending = self._pending, {}
        for joint, parts in pending.items():
            got = angle_peaks(joint_angles(np.concatenate(parts), joint, self.side), joint)
            mine = self.peaks_.setdefault(joint, {})
            for movement in CLINICAL_MOVEMENTS[joint]:
                v = got.get(movement)
                if v is not None and v > mine.get(movement, -math.inf):
                    mine[movement] = float(v)
        return {j: dict(m) for j, m in self.peaks_.items()}


@dataclass
class Checkpoint:
    """One completed neutral checkpoint: what is stored, ``store.calibrations.add(session,
    "neutral-checkpoint", data, residual_deg)``.

    ``data`` is ``{"window": [t0, t1], "time": "device_t" | "t"}``: the hold window on the
    samples' clock, the one the calibration protocol's windows are in (:meth:`SampleBatch.time`:
    device time where the device has one, else host time), and which column that is.
    ``residual_deg`` is the median angle of the limb axis from the neutral direction during
    the window (live joint orientations), None without samples there.
    """

    data: dict
    residual_deg: float | None


class NeutralCheckpoints:
    """Marks neutral-pose checkpoints during the free recording of an IMU rig.

    The patient returns to the neutral pose between movements; each return lets the read path
    re-zero the two sensors' relative heading (:class:`calibration.heading.HeadingCorrection`,
    :func:`rig.readback.joint_orientations_from_store`).

    - **Simulated rig**: the windows are the simulated patient's schedule
      (``neutral_windows(t_end)`` of :class:`rig.sim.limb.SimulatedLimb`, patient time, turned
      into the samples' clock); the display says "return to neutral" shortly before each (the
      simulated patient does it). No schedule (``neutral_every_s`` 0, or a patient without
      one): no checkpoints.
    - **Hardware**: the clinician presses Enter when the patient is back in the neutral pose;
      the window is ``[t_press, t_press + hold_s]`` of sample time (the patient holds still).

    Each window is handed back by :meth:`feed` once the samples have passed its end.

    Parameters
    ----------
    rig : OpenRig
    display : display object (``message``)
    stdin : text stream, optional
        Where Enter is read on hardware (default ``sys.stdin``).
    hold_s : float
        Hardware: how long the patient holds still after Enter.
    lead_s : float
        Simulated rig: the prompt comes this long before the patient starts moving back.
    """

    def __init__(self, rig, *, display, stdin=None, hold_s: float = 1.0,
                 lead_s: float = 1.0) -> None:
        self.rig = rig
        self.display = display
        self.stdin = stdin if stdin is not None else sys.stdin
        self.hold_s = float(hold_s)
        self.lead_s = float(lead_s)
        self.count = 0
        self._pose = NEUTRAL_WORDS.get(getattr(getattr(rig, "config", None), "limb", None),
                                       NEUTRAL_WORDS[None])
        self._patient = None
        if rig.simulated:
            pats = rig.patients
            patient = pats[0] if pats else None
            if (patient is not None and callable(getattr(patient, "neutral_windows", None))
                    and float(getattr(patient, "neutral_every_s", 0.0) or 0.0) > 0.0):
                self._patient = patient
        self.active = rig.kind == "imu" and (self._patient is not None or not rig.simulated)
        self._schedule = np.empty((0, 2))  # simulated: patient-time windows known so far
        self._horizon = -math.inf
        self._next = 0  # index of the next scheduled window not yet completed
        self._announced = 0  # scheduled windows announced
        self._open: list[list[float]] = []  # windows (samples' clock) waiting for their end
        self._buf_t: list[np.ndarray] = []
        self._buf_q: list[np.ndarray] = []
        self._presses = 0
        self._lock = threading.Lock()
        self._stop_reader = threading.Event()
        self._reader: threading.Thread | None = None
        self._prompt: str | None = None

    @property
    def prompt(self) -> str | None:
        """What the status line should say while a checkpoint is due or held (else None)."""
        return self._prompt

    @property
    def enter(self) -> str | None:
        """What pressing Enter does now (hardware, while listening), else None."""
        if self._reader is None:
            return None
        return "mark a neutral checkpoint: the patient is back in the neutral pose"

    def begin(self) -> None:
        """Say what to do; on hardware start reading Enter in the background."""
        if not self.active:
            return
        if self._patient is not None:
            every = float(self._patient.neutral_every_s)
            self.display.message(
                f"neutral checkpoints: the simulated patient returns to the neutral pose every "
                f"{every:g} s ({self._pose}) and holds it "
                f"{float(getattr(self._patient, 'neutral_hold_s', 2.0)):g} s")
            return
        try:
            self.stdin.fileno()
        except (AttributeError, OSError, ValueError):
            self.active = False  # no usable stdin: nobody can mark a checkpoint
            return
        self.display.message(
            "neutral checkpoints: between movements bring the patient back to the neutral pose "
            f"({self._pose}) and press Enter; hold still "
            f"{self.hold_s:g} s")
        self._reader = threading.Thread(target=self._read_enter, name="rig-record-neutral",
                                        daemon=True)
        self._reader.start()

    def _read_enter(self) -> None:
        _watch_enter(self.stdin, self._stop_reader, self._pressed)

    def _pressed(self) -> bool:
        with self._lock:
            self._presses += 1
        return True  # keep listening

    def close(self) -> None:
        self._stop_reader.set()
        if self._reader is not None:
            self._reader.join()
            self._reader = None

    # -- the recording loop ----------------------------------------------------------------
    def feed(self, batch: SampleBatch, joint_q: np.ndarray, joint_t: np.ndarray
             ) -> list[Checkpoint]:
        """Take a batch (and its live joint orientations); the checkpoints completed by it."""
        if not self.active or len(batch) == 0:
            return []
        clock = batch.time()
        now = float(clock[-1])
        base = "device_t" if np.isfinite(batch.device_t).all() else "t"
        if self._patient is not None:
            self._schedule_from_patient(batch)
        else:
            with self._lock:
                presses, self._presses = self._presses, 0
            if presses:
                self._open.append([now, now + self.hold_s])
                self._prompt = "neutral checkpoint: hold still"
                self.display.message(f"neutral checkpoint {self.count + len(self._open)}: hold "
                                     f"still {self.hold_s:g} s")
        if self._open and len(joint_q):
            lo = self._open[0][0]
            keep = joint_t >= lo
            if keep.any():
                self._buf_t.append(joint_t[keep])
                self._buf_q.append(joint_q[keep])
        done = []
        while self._open and now >= self._open[0][1]:
            t0, t1 = self._open.pop(0)
            done.append(Checkpoint({"window": [t0, t1], "time": base}, self._residual(t0, t1)))
            self.count += 1
            if not self._open:
                self._buf_t.clear()
                self._buf_q.clear()
                self._prompt = None
        return done

    def _schedule_from_patient(self, batch: SampleBatch) -> None:
        pt = self.rig.patient_time(batch)
        clock = batch.time()
        offset = float(np.median(clock - pt))  # samples' clock minus patient time
        now = float(pt[-1])
        patient = self._patient
        ramp = float(getattr(patient, "neutral_ramp_s", 0.0) or 0.0)
        if now + 60.0 > self._horizon:  # the schedule a minute ahead
            self._horizon = now + 120.0
            self._schedule = np.asarray(patient.neutral_windows(self._horizon),
                                        dtype=np.float64).reshape(-1, 2)
        sched = self._schedule
        while self._announced < len(sched) and now >= sched[self._announced, 0] - ramp - \
                self.lead_s:
            k = self._announced
            self._announced += 1
            if now >= sched[k, 1]:  # already over (the recording began after it): skip
                self._next = max(self._next, k + 1)
                continue
            self._prompt = "return to neutral"
            self.display.message(f"neutral checkpoint {self.count + 1}: return to the neutral "
                                 f"pose ({self._pose}) and hold still")
        while self._next < self._announced and now >= sched[self._next, 0]:
            t0, t1 = sched[self._next]
            self._open.append([float(t0 + offset), float(t1 + offset)])
            self._next += 1
            self._prompt = "neutral checkpoint: hold still"

    def _residual(self, t0: float, t1: float) -> float | None:
        if not self._buf_t:
            return None
        t = np.concatenate(self._buf_t)
        q = np.concatenate(self._buf_q)
        sel = (t >= t0) & (t <= t1)
        if not sel.any():
            return None
        x = np.array([1.0, 0.0, 0.0])
        return float(np.degrees(np.median(Q.angle_between(Q.rotate(q[sel], x), x))))


def _concat(batches: list[SampleBatch]) -> SampleBatch:
    if not batches:
        e = np.empty(0)
        return SampleBatch(e, e, np.empty(0, object), np.empty(0, object), np.empty((0, 4)),
                           np.empty(0, np.int64))
    return SampleBatch(*(np.concatenate([getattr(b, f) for b in batches])
                         for f in ("t", "device_t", "name", "kind", "q", "status", "raw")))


def patient_performs_protocol(rig) -> bool:
    """Whether every simulated patient of ``rig`` follows the calibration protocol.

    A :class:`rig.sim.limb.SimulatedLimb` that performs it exposes the protocol it follows as
    ``calibration_protocol`` (None: it moves freely from time 0, and calibrating against it
    would fit noise).
    """
    patients = rig.patients
    return bool(patients) and all(p.calibration_protocol is not None for p in patients)


def _watch_enter(stdin, stop: threading.Event, on_enter) -> None:
    """Read ``stdin`` until ``stop`` is set, EOF, or ``on_enter()`` (called at each line that
    holds an Enter) returns False. Returns at once when ``stdin`` has no file descriptor."""
    try:
        fd = stdin.fileno()
    except (AttributeError, OSError, ValueError):
        return
    while not stop.is_set():
        ready, _, _ = select.select([fd], [], [], 0.2)
        if ready:
            data = os.read(fd, 1024)
            if not data:  # EOF: nobody will press it again
                return
            if b"\n" in data and not on_enter():
                return
