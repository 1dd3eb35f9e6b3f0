"""What a recording read back is: joint orientations with their provenance
(:class:`JointData`: N samples of J joints, a one-joint recording J = 1), and the facts a
reader must know before trusting figures from them (:class:`RecordingFacts`)."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from calibration.coverage import coverage_of
from calibration.joints import JOINTS
from models import quaternion as Q
from models.kinds import DEFAULT_KIND, get_kind
from models.quaternion import normalize_rows
from rig.errors import RigConfigError

__all__ = ["CUT_SHORT", "FUSION_CHOICES", "JointData", "RecordingFacts", "parse_axis"]

#: Session statuses that mean the recording stopped before its planned end.
CUT_SHORT = ("interrupted", "device_lost", "failed")

#: Where an IMU session's orientations come from (``--fusion``;
#: :func:`rig.readback.sessions.joint_orientations_from_store`).
FUSION_CHOICES = ("auto", "device", "vqf")


@dataclass(frozen=True)
class RecordingFacts:
    """What a reader must know before trusting figures from a recording.

    ``interrupted``: the session ended before its planned end (Ctrl-C, SIGTERM, a lost device,
    a killed recorder), None for files (unknown). ``explored``/``sectors``/``sufficient``: the
    coverage of the swing sphere (:mod:`calibration.coverage`: sectors around the range's
    centre where the limit was reached and stopped moving outward). ``simulated``: samples
    from a simulator (``sim://`` ports), None when unknown.
    """

    status: str | None = None
    interrupted: bool | None = None
    explored: int | None = None
    sectors: int | None = None
    sufficient: bool | None = None
    simulated: bool | None = None
    unmeasured_drift: bool = False  # IMU orientations with no neutral checkpoint accepted

    @property
    def coverage(self) -> float | None:
        """Share of the sectors explored, 0-1 (None before it is known)."""
        if not self.sectors:
            return None
        return self.explored / self.sectors

    def warnings(self) -> list[str]:
        """One line per reason to doubt the figures (empty when there is none)."""
        out = []
        if self.interrupted:
            out.append(f"the session was cut short (status {self.status!r}): the range of "
                       "motion may not have been recorded to the end")
        if self.sectors and not self.sufficient:
            out.append(f"coverage {self.explored} of {self.sectors} directions explored: "
                       "where a limit was not reached, the boundary and the peaks understate "
                       "the range")
        if self.unmeasured_drift:
            out.append("no neutral checkpoint was accepted: the IMUs' relative heading drift is "
                       "neither removed nor measured, so the rotations (and the boundary away "
                       "from the neutral pose) may be overstated by it")
        return out

    def as_dict(self) -> dict[str, Any]:
        return {"status": self.status, "interrupted": self.interrupted,
                "coverage": None if self.coverage is None else round(self.coverage, 4),
                "explored_sectors": self.explored, "sectors": self.sectors,
                "coverage_sufficient": self.sufficient, "simulated": self.simulated,
                "unmeasured_drift": self.unmeasured_drift}


@dataclass
class JointData:
    """Joint orientations read back from a session or a file, and where they came from: N
    samples of J joints at the same instants — a whole limb (``limb``: arm or leg, J = 3) or
    one joint (a limb of one joint, J = 1).

    Attributes
    ----------
    joint_q : (N, J, 4) float64
        Every joint's orientation, scalar-first, child relative to parent (rig segment frames),
        in the order of ``joints`` (proximal to distal).
    joints : tuple of (str or None)
        The joints' names (:data:`calibration.joints.JOINTS`; None: a file's unnamed joint).
    t : (N,) float64 or None
        Sample times, seconds (any origin).
    status : (N,) or None
        IMU calibration bytes (a limb: the lowest of its sensors'), or None.
    limb_axis : (3,) float64
        The distal segment's long axis in its frame (a one joint's ``--limb-axis``; +X).
    side : {"left", "right"} or None
    provenance : dict
    patient : str or None
    limb : {"arm", "leg"} or None
        The whole limb recorded, or None for one joint (a joint selected from a limb keeps
        ``provenance["limb"]``).
    recording : RecordingFacts or None
    slow_errors : dict
        Joint → measured size of the slowly varying error left in its orientations, as the
        reader that made them measured it (:attr:`slow_errors_deg`; a joint not in it: None).

    The one joint's views (``q``, ``joint``, ``kind``, ``directions``, ``slow_error_deg``,
    :meth:`facts` with coverage) need J = 1: :meth:`select` takes one joint of a limb.
    """

    joint_q: np.ndarray
    joints: tuple[str | None, ...]
    t: np.ndarray | None = None
    status: np.ndarray | None = None
    limb_axis: np.ndarray = field(default_factory=lambda: parse_axis(None))
    side: str | None = None
    provenance: dict[str, Any] = field(default_factory=dict)
    patient: str | None = None
    limb: str | None = None
    recording: RecordingFacts | None = None
    slow_errors: dict[str | None, float | None] = field(default_factory=dict)

    @classmethod
    def of_joint(cls, q: np.ndarray, joint: str | None, *, t: np.ndarray | None = None,
                 status: np.ndarray | None = None, limb_axis: np.ndarray | None = None,
                 side: str | None = None, provenance: dict[str, Any] | None = None,
                 patient: str | None = None, recording: RecordingFacts | None = None
                 ) -> JointData:
        """One joint's orientations ``q`` (N, 4) as a limb of one joint (J = 1); its measured
        slow error the heading correction's own uncertainty in ``provenance`` (IMU sessions
        with neutral checkpoints)."""
        prov = {} if provenance is None else provenance
        slow = (prov.get("heading_correction") or {}).get("uncertainty_deg")
        return cls(np.asarray(q)[:, None, :], (joint,), t, status,
                   parse_axis(None) if limb_axis is None else limb_axis, side,
                   prov, patient, None, recording, {joint: slow})

    def _one(self, what: str) -> None:
        if len(self.joints) != 1:
            raise RigConfigError(f"{what} of one joint: the {self.limb or 'recording'} has "
                                 f"{len(self.joints)} ({', '.join(map(str, self.joints))}); "
                                 "select one")

    @property
    def q(self) -> np.ndarray:
        """(N, 4) the one joint's orientations (J = 1)."""
        self._one("orientations")
        return self.joint_q[:, 0]

    @property
    def joint(self) -> str | None:
        """The one joint's name (J = 1; None: a file's unnamed joint)."""
        self._one("the name")
        return self.joints[0]

    def select(self, name: str, axis: np.ndarray | None = None) -> JointData:
        """One joint of the recording (J = 1), ``axis`` its limb axis (default +X); its facts
        the recording's, with coverage from its own orientations."""
        if name not in self.joints:
            raise RigConfigError(f"the {self.limb or 'recording'} has no {name} (its joints: "
                                 f"{', '.join(map(str, self.joints))})")
        facts = self.recording
        if facts is not None:  # coverage is the joint's own, not the recorder's live one
            facts = replace(facts, explored=None, sectors=None, sufficient=None)
        prov = {**self.provenance, "joint": name}
        hc = prov.get("heading_correction")
        if hc:  # the joint's own (a limb's: its distal sensor's, relative to its neighbour)
            prov["heading_correction"] = {**hc, "uncertainty_deg": self.slow_errors_deg[name]}
        return JointData.of_joint(self.joint_q[:, self.joints.index(name)], name, t=self.t,
                                  status=self.status,
                                  limb_axis=parse_axis(None) if axis is None else axis,
                                  side=self.side, provenance=prov, patient=self.patient,
                                  recording=facts)

    def facts(self) -> RecordingFacts:
        """What a reader must know before trusting figures from this recording (one joint:
        coverage computed from its orientations when the recorder stored none)."""
        if self.recording is None:
            self.recording = RecordingFacts()
        if len(self.joints) != 1:
            return self.recording
        if self.recording.sectors is None and get_kind(self.kind).single_axis:
            # one angle: no swing sphere to cover (the interval's ends are the evidence)
            self.recording = replace(self.recording, explored=0, sectors=0)
        if self.recording.sectors is None:
            cov = coverage_of(self.q, self.t, limb_axis=self.limb_axis)
            self.recording = replace(self.recording, explored=cov.explored,
                                     sectors=len(cov.sectors), sufficient=cov.sufficient)
        return self.recording

    @property
    def kind(self) -> str:
        """The one joint's kind (:data:`calibration.joints.JOINTS`; a joint it does not list,
        such as an older recording's name, is read as a ball joint)."""
        spec = JOINTS.get(self.joint or "shoulder")
        return DEFAULT_KIND if spec is None else spec.kind

    @property
    def directions(self) -> np.ndarray:
        """(N, 3) the one joint's recorded limb directions, parent frame (rig axes)."""
        return Q.rotate(self.q, self.limb_axis)

    @property
    def slow_error_deg(self) -> float | None:
        """Measured size of the slowly varying errors left in the one joint's orientations
        (the heading correction's own uncertainty, IMU sessions with neutral checkpoints),
        else None."""
        self._one("the slow error")
        return self.slow_errors_deg[self.joints[0]]

    @property
    def slow_errors_deg(self) -> dict[str | None, float | None]:
        """Joint → measured size of the slowly varying error left in its orientations, in the
        order of ``joints`` (:attr:`slow_errors`; None where none was measured). One joint:
        the heading correction's own uncertainty; a whole limb: the limb heading
        correction's for the joint's distal sensor, which is corrected relative to its
        proximal neighbour (IMU sessions with neutral checkpoints)."""
        return {name: self.slow_errors.get(name) for name in self.joints}

    @property
    def orientations(self) -> str | None:
        """Which IMU orientations an IMU session was read through, for people (None for joint
        samples and files)."""
        method = (self.provenance.get("fusion") or {}).get("method")
        return {"vqf": "fused on the host by VQF from the raw samples",
                "device": "as fused by the devices"}.get(method)


def parse_axis(text: str | None) -> np.ndarray:
    """``--limb-axis`` text ``x,y,z`` as a unit vector (+X when None); one-line error otherwise."""
    if text is None:
        return np.array([1.0, 0.0, 0.0])
    try:
        v = np.array([float(c) for c in text.split(",")])
    except ValueError as err:
        raise RigConfigError(f"--limb-axis: expected x,y,z numbers, got {text!r}") from err
    if v.shape != (3,) or not np.isfinite(v).all():
        raise RigConfigError(f"--limb-axis: expected a non-zero x,y,z vector, got {text!r}")
    unit, n = normalize_rows(v[None, :])
    if n[0] < 1e-9:
        raise RigConfigError(f"--limb-axis: expected a non-zero x,y,z vector, got {text!r}")
    return unit[0]

