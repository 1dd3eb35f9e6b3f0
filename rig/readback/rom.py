"""``rig rom`` as a library: the clinical range of motion of a recording or a constraint.

The elbow, wrist, hip, knee and ankle (``joint``): the ISB / Grood-Suntay angles' peaks per
movement (:func:`calibration.joint_angles.recorded_rom` of the recording's samples,
:func:`~calibration.joint_angles.constraint_rom` of a constraint file), against the AAOS values.

The shoulder's peaks (flexion, extension, abduction, adduction, horizontal adduction, internal
and external rotation) come from the patient's boundary
(:func:`calibration.clinical.range_of_motion`): extracted from the recording as ``rig boundary``
does (:func:`rig.readback.boundary.extract`), or read from a constraint file; with a recording,
each peak is the smaller of the boundary's and the recorded samples' reading.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from calibration.alignment import trusted_samples
from calibration.clinical import format_rom_table, range_of_motion
from calibration.clinical_tests import coupled_measures, format_coupled_tests
from calibration.joint_angles import (
    JOINT_ANGLES,
    JointRangeOfMotion,
    allowed_rom,
    beyond_reach,
    recorded_rom,
)
from calibration.joints import joint_mismatch
from models.limb import Limb, load_limits
from rig.errors import RigConfigError
from rig.readback.boundary import extract, stored_limb
from rig.readback.data import RecordingFacts
from rig.readback.sessions import joint_orientations_from_store, session_limb
from rig.readback.source import RecordingSource, check_joint
from rig.store import open_store

__all__ = ["RomRequest", "RomResult", "run_rom"]


@dataclass(frozen=True)
class RomRequest:
    """A recording (``source``, which names its joint) or a constraint file (``constraint``,
    with ``joint``: default the constraint's own, else the shoulder), and the side (default:
    the recording's or the constraint's, else right)."""

    source: RecordingSource | None = None
    constraint: str | None = None
    side: str | None = None
    joint: str | None = None
    #: the coupled clinical tests (:mod:`calibration.clinical_tests`): None (default) adds
    #: them wherever the source is a limb file or a whole-limb session and says nothing
    #: otherwise; True requires them (one line when the source has none: one joint's
    #: constraint, an orientation file, a session of one joint); False leaves them out
    coupled_tests: bool | None = None

    def check(self) -> None:
        """Option combinations and files, before any work (one-line errors)."""
        check_joint(self.joint)
        if self.constraint is None:
            if self.source is None:
                raise RigConfigError("give a recording or --constraint")
            self.source.check(side=self.side)
            return
        src = self.source
        if src is not None and (src.file is not None or src.db is not None
                                or src.session_id is not None):
            raise RigConfigError("give either --constraint or a recording, not both")
        if src is not None and src.frames is not None:
            raise RigConfigError("--frames applies to orientation files, not to --constraint")
        if not Path(self.constraint).is_file():
            raise RigConfigError(f"{self.constraint}: no such file")


@dataclass
class RomResult:
    """The range of motion (:class:`calibration.clinical.RangeOfMotion`), the joint, what it
    was read from (for people) and, for a recording, its facts."""

    rom: Any
    joint: str | None
    source: str
    facts: RecordingFacts | None = None
    #: the limb's coupled clinical tests (:func:`calibration.clinical_tests.coupled_measures`):
    #: a limb file's or a whole-limb session's unless left out (``--no-coupled-tests``);
    #: None for one joint
    coupled: list | None = None

    @property
    def warnings(self) -> list[str]:
        """Reasons to doubt the figures (one line each): the recording's facts, and every
        movement beyond what people reach (:attr:`beyond_reach`)."""
        facts = [] if self.facts is None else self.facts.warnings()
        return facts + [b["text"] for b in self.beyond_reach.values()]

    @property
    def beyond_reach(self) -> dict[str, dict]:
        """Movements beyond physiological reach
        (:func:`calibration.joint_angles.beyond_reach`): movement → value, the largest
        plausible, the norm it comes from and the line saying so."""
        return beyond_reach(self.rom, self.joint if not self.is_shoulder else "shoulder")

    def table(self, *, age: int | None = None, sex: str | None = None) -> str:
        """What ``rig rom`` prints: the source, the warnings, the table against the AAOS
        values and (the shoulder) the population reference for ``age`` / ``sex``."""
        lines = [self.source, *(f"warning: {w}" for w in self.warnings)]
        if self.is_shoulder:
            lines.append(format_rom_table(self.rom, age=age, sex=sex))
        else:
            lines.append(self.rom.table(age=age, sex=sex))
        if self.coupled is not None:
            lines.append(format_coupled_tests(self.coupled))
        return "\n".join(lines)

    @property
    def is_shoulder(self) -> bool:
        """The shoulder's table (:class:`calibration.clinical.RangeOfMotion`), not another
        joint's (:class:`calibration.joint_angles.JointRangeOfMotion`)."""
        return not isinstance(self.rom, JointRangeOfMotion)

    def to_json(self, *, age: int | None = None, sex: str | None = None) -> dict:
        """``rig rom --json``: movement (snake_case, as in the table) → degrees (2 decimals) or
        None, plus ``joint``, ``side``, ``coverage`` (share of the swing sphere's sectors
        explored, 0-1; None for a constraint file), ``interrupted`` (None when unknown: files
        and constraints), ``neutral_outside_deg``, ``beyond_reach`` (movement → ``value``,
        ``max``, ``norm``, ``source``: beyond what people reach), ``warnings`` and
        ``source``."""
        r, facts = self.rom, self.facts
        if self.is_shoulder:
            out: dict = {"joint": self.joint or "shoulder", "side": r.side}
            for m in r.MOVEMENTS:
                v = getattr(r, m)
                out[m] = None if v is None else round(float(v), 2)
        else:
            out = r.to_json(age=age, sex=sex)
        out["coverage"] = (None if facts is None or facts.coverage is None
                           else round(facts.coverage, 4))
        out["interrupted"] = None if facts is None else facts.interrupted
        if self.is_shoulder:
            out["neutral_outside_deg"] = round(float(r.neutral_outside_deg), 2)
        out["beyond_reach"] = {m: {k: v for k, v in b.items() if k != "text"}
                               for m, b in self.beyond_reach.items()}
        out["warnings"] = self.warnings
        out["source"] = self.source
        if self.coupled is not None:
            out["coupled_tests"] = [m.to_json() for m in self.coupled]
        return out


def _limits_rom(request: RomRequest) -> RomResult:
    """The range of motion a constraint file allows, or one joint's in a limb file (a
    coupled joint: the largest over its keyframes, movement by movement — what it allows at
    some angle of the joint it depends on)."""
    path = request.constraint
    limits = load_limits(path)
    source = path
    if isinstance(limits, Limb):
        names = ", ".join(limits.joint_names)
        if request.joint is None:
            raise RigConfigError(f"{path}: a limb file (joints {names}): give --joint")
        if request.joint not in limits.joint_names:
            raise RigConfigError(f"{path}: limb {limits.name!r} has no joint "
                                 f"{request.joint!r} (it has {names})")
        if limits.side is not None and request.side is not None and limits.side != request.side:
            raise RigConfigError(f"{path}: limb {limits.name!r} is for the {limits.side} side, "
                                 f"not the {request.side} (--side {request.side})")
        lj = limits.joints[limits.index(request.joint)]
        constraints = [lj.constraint] if lj.coupling is None else list(lj.coupling.keyframes)
        side = request.side or limits.side or "right"
        source = f"{path}: the {lj.name} of limb {limits.name!r}"
        if lj.coupling is not None:
            at = ", ".join(f"{a:.1f}" for a in lj.coupling.at_deg)
            source += (f", the largest over its keyframes at {lj.coupling.by} {at} deg "
                       "(the range depends on that joint's angle)")
        joint = named = request.joint
    else:
        why = joint_mismatch(limits, for_joint=request.joint, for_side=request.side)
        if why is not None:
            asked = " ".join(f"--{k} {v}" for k, v in (("joint", request.joint),
                                                        ("side", request.side)) if v)
            raise RigConfigError(f"{path}: constraint {limits.name!r} {why} ({asked})")
        constraints = [limits]
        side = request.side or getattr(limits, "side", None) or "right"
        joint = request.joint or getattr(limits, "joint", None) or "shoulder"
        named = joint if joint != "shoulder" else getattr(limits, "joint", None)
    if joint != "shoulder":
        if joint not in JOINT_ANGLES:
            raise RigConfigError(f"{path}: joint {joint!r} has no clinical angles; give "
                                 f"--joint (one of shoulder, {', '.join(JOINT_ANGLES)})")
    else:
        for c in constraints:
            c.require_swing_twist("rig rom")
    coupled = None
    if request.coupled_tests or (request.coupled_tests is None and isinstance(limits, Limb)):
        if not isinstance(limits, Limb):
            raise RigConfigError(f"{path}: --coupled-tests reads a limb file (an arm or a "
                                 "leg), not one joint's constraint")
        coupled = coupled_measures(limits, side=side)
    return RomResult(allowed_rom(constraints, joint, side), named, source, coupled=coupled)


def run_rom(request: RomRequest) -> RomResult:
    """Check the request, then read the constraint or extract the recording's boundary, and
    compute the clinical peaks."""
    request.check()
    if request.constraint is not None:
        return _limits_rom(request)
    coupled = _session_coupled(request) if request.coupled_tests else None  # fail fast
    result = _recording_rom(request)
    if request.coupled_tests is None:  # after the recording's own errors, as before
        coupled = _session_coupled(request)
    result.coupled = coupled
    return result


def _session_coupled(request: RomRequest) -> list | None:
    """The coupled clinical tests of the request's whole-limb session
    (:func:`session_coupled_tests`); None for an orientation file or a session of one joint
    unless required (``coupled_tests=True``: one line)."""
    src = request.source
    required = request.coupled_tests is True
    if src.file is not None:
        if not required:
            return None
        raise RigConfigError("--coupled-tests reads a limb file (--constraint LIMB.yaml) or a "
                             "whole-limb session (--db --session), not an orientation file")
    with open_store(src.db, create=False) as store:
        if not required and session_limb(store.sessions.get(src.session_id)) is None:
            return None
        return session_coupled_tests(store, src.session_id, side=request.side,
                                     fusion=src.fusion)


def session_coupled_tests(store, session_id: int, *, side: str | None = None,
                          fusion: str = "auto") -> list:
    """The coupled clinical tests (:func:`calibration.clinical_tests.coupled_measures`) of a
    whole-limb session in an opened store: the last limb file stored with it (``rig boundary
    --limb --db``) and its recorded postures (those the sensors vouch for), or the postures
    alone when no limb file is stored.

    Raises
    ------
    RigConfigError
        A session of one joint (one line).
    """
    sess = store.sessions.get(session_id)
    if session_limb(sess) is None:
        raise RigConfigError(f"--coupled-tests: session {session_id} recorded one "
                             "joint; the coupled tests need a whole arm or leg")
    chain = joint_orientations_from_store(store, session_id, fusion=fusion)
    found = stored_limb(store, session_id)
    limb = found[0] if found is not None and found[0].joint_names == chain.joints else None
    ok = trusted_samples(chain.status, len(chain.joint_q))
    side = side or chain.side or "right"
    return coupled_measures(limb, chain.joint_q[ok], joint_names=chain.joints, side=side)


def _recording_rom(request: RomRequest) -> RomResult:
    """The range of motion of the recording ``request.source`` names."""
    src = request.source
    data = src.load()
    side = request.side or data.side or "right"
    source = src.label
    if data.orientations is not None:
        source += f" (IMU orientations {data.orientations})"
    if data.joint in JOINT_ANGLES:
        return RomResult(recorded_rom(data.q, data.joint, side, status=data.status), data.joint,
                         source, data.facts())
    constraint = extract(data, side=side).constraint_
    return RomResult(range_of_motion(constraint, side, directions=data.directions), data.joint,
                     source, data.facts())
