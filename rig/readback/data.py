"""What a recording read back is: joint orientations with their provenance
(:class:`JointData`), and the facts a reader must know before trusting figures from them
(:class:`RecordingFacts`)."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from models.kinds import DEFAULT_KIND, get_kind
from models.quaternion import normalize_rows
from rig.errors import RigConfigError

__all__ = ["CUT_SHORT", "FUSION_CHOICES", "ChainData", "JointData", "RecordingFacts",
           "parse_axis"]

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
    """Joint orientations from a session or file, and where they came from."""

    q: np.ndarray  # (N, 4) limb relative to reference
    status: np.ndarray | None  # (N,) IMU calibration bytes, or None
    limb_axis: np.ndarray  # (3,)
    side: str | None
    provenance: dict[str, Any] = field(default_factory=dict)
    patient: str | None = None
    joint: str | None = None
    t: np.ndarray | None = None  # (N,) sample times, seconds (any origin), or None

    recording: RecordingFacts | None = None

    def facts(self) -> RecordingFacts:
        """What a reader must know before trusting figures from this recording (coverage
        computed from the joint orientations when the recorder stored none)."""
        if self.recording is None:
            self.recording = RecordingFacts()
        if self.recording.sectors is None and get_kind(self.kind).single_axis:
            # one angle: no swing sphere to cover (the interval's ends are the evidence)
            self.recording = replace(self.recording, explored=0, sectors=0)
        if self.recording.sectors is None:
            from calibration.coverage import coverage_of

            cov = coverage_of(self.q, self.t, limb_axis=self.limb_axis)
            self.recording = replace(self.recording, explored=cov.explored,
                                     sectors=len(cov.sectors), sufficient=cov.sufficient)
        return self.recording

    @property
    def kind(self) -> str:
        """The joint's kind (:data:`calibration.joints.JOINTS`; a joint it does not list, such
        as an older recording's name, is read as a ball joint)."""
        from calibration.joints import JOINTS

        spec = JOINTS.get(self.joint or "shoulder")
        return DEFAULT_KIND if spec is None else spec.kind

    @property
    def directions(self) -> np.ndarray:
        """(N, 3) the recorded limb directions, parent frame (rig axes)."""
        from models import quaternion as Q

        return Q.rotate(self.q, self.limb_axis)

    @property
    def slow_error_deg(self) -> float | None:
        """Measured size of the slowly varying errors left in the orientations (the heading
        correction's own uncertainty, IMU sessions with neutral checkpoints), else None."""
        return (self.provenance.get("heading_correction") or {}).get("uncertainty_deg")

    @property
    def orientations(self) -> str | None:
        """Which IMU orientations an IMU session was read through, for people (None for joint
        samples and files)."""
        method = (self.provenance.get("fusion") or {}).get("method")
        return {"vqf": "fused on the host by VQF from the raw samples",
                "device": "as fused by the devices"}.get(method)


@dataclass
class ChainData:
    """A whole limb's postures from a session: every joint's orientation at the same instants
    (child relative to parent, rig frames), and where they came from.

    ``q`` is (N, J, 4) in the order of ``joints`` (:data:`calibration.joints.LIMB_CHAINS`
    ``[limb]``, proximal to distal); ``t`` (N,) seconds; ``status`` (N,) the lowest of the
    sensors' calibration bytes or None."""

    q: np.ndarray
    t: np.ndarray
    limb: str
    joints: tuple[str, ...]
    side: str | None
    status: np.ndarray | None = None
    provenance: dict[str, Any] = field(default_factory=dict)
    patient: str | None = None
    recording: RecordingFacts | None = None

    def joint(self, name: str, axis: np.ndarray | None = None) -> JointData:
        """One joint's :class:`JointData` (its facts: the session's, coverage from its own
        orientations)."""
        if name not in self.joints:
            raise RigConfigError(f"the {self.limb} has no {name} (its joints: "
                                 f"{', '.join(self.joints)})")
        facts = self.recording
        if facts is not None:  # coverage is the joint's own, not the recorder's live one
            facts = replace(facts, explored=None, sectors=None, sufficient=None)
        prov = {**self.provenance, "joint": name}
        hc = prov.get("heading_correction")
        if hc and "segments" in hc:  # the joint's own: its distal sensor's, relative
            prov["heading_correction"] = {**hc, "uncertainty_deg": self.slow_error_deg[name]}
        return JointData(self.q[:, self.joints.index(name)], self.status,
                         parse_axis(None) if axis is None else axis, self.side,
                         prov, self.patient, name, self.t, facts)

    @property
    def slow_error_deg(self) -> dict[str, float | None]:
        """Joint → measured size of the slowly varying error left in its orientations: the
        limb heading correction's own uncertainty for the joint's distal sensor, which is
        corrected relative to its proximal neighbour (IMU sessions with neutral checkpoints;
        None otherwise)."""
        from calibration.joints import LIMB_CHAINS

        segs = (self.provenance.get("heading_correction") or {}).get("segments") or {}
        return {name: (segs.get(child) or {}).get("uncertainty_deg")
                for name, _, child in LIMB_CHAINS[self.limb]}


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

