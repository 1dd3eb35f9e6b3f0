"""``rig boundary`` as a library: a patient-specific constraint file from a recording of one
joint, or a limb file from a recording of a whole limb (a joint is a limb of one joint; one
service for both).

:func:`run_boundary` takes a :class:`BoundaryRequest` (which recording, one joint or a whole
``limb``, the extractor's parameters, where to write) and returns a :class:`BoundaryResult`;
:func:`extract` runs one joint's extraction (:mod:`calibration.extraction.joint`) on joint
orientations already loaded (the recorder's range of motion, the report, the demo), and
:func:`extract_limb` a whole limb's (:class:`calibration.boundary.LimbExtractor`). The
constraint or limb file records its provenance (session or file, parameters, sample counts,
sparse arcs, the recording's facts) and its binding (patient, joint, side).
"""

from __future__ import annotations

import datetime as dt
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from calibration.extraction import LimbExtractor
from calibration.joints import JOINTS, LIMB_CHAINS, columns_mismatch
from calibration.kinds import calibration_kind
from models.constraint import JointConstraint, dump_constraint, load_constraint
from models.fileio import check_output
from models.kinds import DEFAULT_KIND, KINDS, get_kind
from models.limb import Limb, dump_limb, inline_constraint, load_limb, loads_limb
from rig.errors import RigConfigError
from rig.readback.data import FUSION_CHOICES, JointData
from rig.readback.files import limb_orientations_from_file
from rig.readback.sessions import joint_orientations_from_store, session_shape
from rig.readback.source import RecordingSource, check_file, check_session_side
from rig.store import LIMB_BOUNDARY, open_store

__all__ = ["BY_SWING_CHOICES", "BoundaryRequest", "BoundaryResult", "OneJointBoundary",
           "WholeLimbBoundary", "default_name", "describe", "extract", "extract_limb",
           "one_joint_limb", "run_boundary", "stored_limb"]

#: ``--by-swing``: swing-dependent twist limits when the data supports them, always, never.
BY_SWING_CHOICES = ("auto", "on", "off")


@dataclass(frozen=True)
class BoundaryRequest:
    """What ``rig boundary`` is asked: one joint's constraint file, or a whole limb's limb file
    (``limb``).

    Attributes
    ----------
    source : RecordingSource
        The recording. A whole limb from a file names no ``source.child`` column, ``limb_axis``
        or ``joint`` (its segments are ``segments``); a session knows its segments.
    out : str or Path
        Constraint (or limb) file to write (YAML, owner-only).
    name : str, optional
        Constraint name (default: :func:`default_name`; a whole limb: the file's stem or
        ``session-N``, and the limb).
    side : {"left", "right"}, optional
        Side recorded in the constraint (default: the session's or file's).
    alpha_deg, max_vertices, by_swing
        The extractor's alpha-shape radius, vertex budget and swing-dependent twist choice
        (``by_swing``: one joint; a limb's swing joints and keyframes decide it themselves).
    store : bool
        With a session: also store the boundary in the session's database (the database must
        be writable; checked first); a whole limb's is a boundary whose ``meta.kind`` is
        :data:`rig.store.LIMB_BOUNDARY` (:func:`stored_limb` reads the last one back).
    limb : {"arm", "leg"}, optional
        A whole limb (``--limb arm|leg``): a limb file, with a coupling where the recording
        supports one, from a whole-limb session or from a file's ``segments``.
    segments : str, optional
        A file's segment columns of the whole ``limb``, proximal to distal, comma-separated:
        four (thorax or pelvis first), or three when ``source.parent`` names the first.
    """

    source: RecordingSource
    out: str | Path
    name: str | None = None
    side: str | None = None
    alpha_deg: float = 4.0
    max_vertices: int = 64
    by_swing: str = "auto"
    store: bool = True
    limb: str | None = None
    segments: str | None = None
    kind: str | None = None

    def columns(self) -> list[str]:
        """A whole limb's four segment columns of the file, proximal to distal."""
        cols = [c.strip() for c in (self.segments or "").split(",") if c.strip()]
        if self.source.parent is not None:
            cols = [self.source.parent, *cols]
        if len(cols) != 4 or len(set(cols)) != 4:
            raise RigConfigError(f"--segments {self.segments!r}: expected the {self.limb}'s four "
                                 "segment columns proximal to distal (or three with "
                                 "--parent), all different")
        return cols

    @property
    def work(self) -> OneJointBoundary | WholeLimbBoundary:
        """What the request asks for: one joint's constraint file, or a whole limb's limb file.
        The user's ``--limb arm|leg`` option decides, here and nowhere else in this module
        (the request's check, reading and extraction ask the object it gives)."""
        return WholeLimbBoundary() if self.limb is not None else OneJointBoundary()

    def check(self) -> None:
        """Everything that can be checked before reading the recording (one-line errors)."""
        self.work.check(self)

    def load(self) -> JointData:
        """The recording the request names, read (after :meth:`check`): one joint's
        orientations (J = 1, :meth:`RecordingSource.load`), or every joint of the whole
        ``limb`` (J = 3) — what ``rig report FILE`` reads as ``rig boundary`` does."""
        return self.source.load() if self.limb is None else _load_limb(self)


class OneJointBoundary:
    """``rig boundary`` of one joint: a constraint file (:func:`extract`)."""

    def check(self, request: BoundaryRequest) -> None:
        """One joint's request, before reading the recording (one-line errors)."""
        request.source.check(side=request.side)
        if request.kind is not None and request.kind not in KINDS:
            raise RigConfigError(f"--kind {request.kind!r}: expected one of {', '.join(KINDS)}")
        if request.by_swing not in BY_SWING_CHOICES:
            raise RigConfigError(f"--by-swing {request.by_swing!r}: expected one of "
                                 f"{', '.join(BY_SWING_CHOICES)}")
        _check_side_and_out(request.side, request.out)
        if request.source.db is not None and request.store:
            _check_can_store(request.source.db)

    def run(self, request: BoundaryRequest, path: Path) -> tuple[BoundaryResult, str, dict]:
        """Read, extract and write the constraint file: the result, the YAML text and the
        metadata to store with the session."""
        data = request.source.load()
        ex = extract(data, name=request.name, side=request.side, alpha_deg=request.alpha_deg,
                     max_vertices=request.max_vertices, by_swing=request.by_swing,
                     kind=request.kind)
        dump_constraint(ex.constraint_, path)
        result = BoundaryResult(ex, data, path, warnings=data.facts().warnings())
        return result, ex.constraint_.to_yaml(), {"path": str(path), **ex.report()}

    def limits(self, request: BoundaryRequest, data: JointData, side: str) -> tuple[Limb, str]:
        """The limits of the loaded recording as a limb of its one joint
        (:func:`one_joint_limb` of :func:`extract`'s constraint), for a report, and how they
        were made (the command)."""
        ex = extract(data, side=side, alpha_deg=request.alpha_deg,
                     max_vertices=request.max_vertices, by_swing=request.by_swing,
                     kind=request.kind)
        limb = one_joint_limb(ex.constraint_, data.joint or "shoulder",
                              name=request.name or default_name(data), side=side)
        return limb, "rig boundary"

    def reference(self, reference, data: JointData, side: str) -> Limb:
        """Limits drawn dashed beside the recording's: a constraint (or its file) as a limb
        of the recording's joint."""
        if isinstance(reference, (str, Path)):
            reference = load_constraint(reference)
        return one_joint_limb(reference, data.joint or "shoulder", name=reference.name,
                              side=side)


class WholeLimbBoundary:
    """``rig boundary --limb arm|leg``: a whole limb's limb file (:func:`extract_limb`)."""

    def check(self, request: BoundaryRequest) -> None:
        """A whole limb's request (``--limb arm|leg``), before reading the recording."""
        src = request.source
        if request.limb not in LIMB_CHAINS:
            raise RigConfigError(f"--limb {request.limb!r}: expected one of "
                                 f"{', '.join(LIMB_CHAINS)}")
        if request.kind is not None:
            raise RigConfigError(f"--kind applies to one joint; the {request.limb}'s joints "
                                 "have their own kinds")
        if src.file is not None and (src.db is not None or src.session_id is not None):
            raise RigConfigError("give either FILE or --db/--session, not both")
        if src.file is None:
            if src.db is None or src.session_id is None:
                raise RigConfigError(f"--limb {request.limb} needs a recording: FILE "
                                     "--segments COL,COL,COL, or --db DB --session ID")
            for flag, value in (("--segments", request.segments),
                                ("--parent", src.parent), ("--frames", src.frames)):
                if value is not None:
                    raise RigConfigError(f"{flag} applies to files; a session knows its "
                                         "segments")
            if src.fusion not in FUSION_CHOICES:
                raise RigConfigError(f"fusion must be one of {', '.join(FUSION_CHOICES)}, got "
                                     f"{src.fusion!r}")
            if request.store:
                _check_can_store(src.db)
            check_session_side(src.db, src.session_id, request.side)
        else:
            if request.segments is None:
                raise RigConfigError(f"--limb {request.limb} needs --segments COL,COL,COL "
                                     "(proximal to distal)")
            order = LIMB_CHAINS[request.limb]
            why = columns_mismatch(request.columns(),
                                   [order[0][1], *(c for _, _, c in order)],
                                   side=request.side, what="--segments")
            if why is not None:
                raise RigConfigError(f"{src.file}: {why} (reading the {request.limb}: --limb "
                                     f"{request.limb})")
            check_file(src.file, src.frames)
        _check_side_and_out(request.side, request.out)

    def run(self, request: BoundaryRequest, path: Path) -> tuple[BoundaryResult, str, dict]:
        """Read, extract and write the limb file: the result, the YAML text and the metadata
        to store with the session (a boundary of kind :data:`rig.store.LIMB_BOUNDARY`)."""
        data = _load_limb(request)
        ex = extract_limb(data, name=request.name, side=request.side,
                          alpha_deg=request.alpha_deg, max_vertices=request.max_vertices)
        dump_limb(ex.limb_, path)
        meta = {"kind": LIMB_BOUNDARY, "limb": request.limb, "path": str(path),
                "coupled": {k: bool(v["coupled"]) for k, v in ex.report()["couplings"].items()}}
        return BoundaryResult(ex, data, path), ex.limb_.to_yaml(), meta

    def limits(self, request: BoundaryRequest, data: JointData, side: str) -> tuple[Limb, str]:
        """The whole limb's limits (:func:`extract_limb`, its couplings where the recording
        supports them), for a report, and how they were made (the command)."""
        limb = extract_limb(data, name=request.name, side=side, alpha_deg=request.alpha_deg,
                            max_vertices=request.max_vertices).limb_
        return limb, f"rig boundary --limb {request.limb}"

    def reference(self, reference, data: JointData, side: str) -> Limb:
        """Limits drawn dashed beside the recording's: a limb (or its file)."""
        return load_limb(reference) if isinstance(reference, (str, Path)) else reference


@dataclass
class BoundaryResult:
    """What ``rig boundary`` produced: the fitted extractor (one joint: its ``constraint_``; a
    whole limb: the :class:`~calibration.boundary.LimbExtractor` and its ``limb_``; both
    ``report()``), the joint orientations it saw, the file written, the stored boundary's id
    and session (None when not stored) and the reasons to doubt the recording (one line each;
    none is printed for a whole limb)."""

    extractor: Any
    data: JointData
    path: Path
    boundary_id: int | None = None
    warnings: list[str] = field(default_factory=list)
    session_id: int | None = None

    @property
    def constraint(self):
        """The :class:`~models.constraint.JointConstraint` written (one joint)."""
        return self.extractor.constraint_

    def describe(self) -> str:
        """The summary ``rig boundary`` prints (:func:`describe`; a whole limb:
        :func:`describe_limb`)."""
        if isinstance(self.extractor, LimbExtractor):
            return describe_limb(self.extractor, self.path, self.boundary_id, self.session_id)
        return describe(self.extractor, self.path)


def _check_side_and_out(side: str | None, out: str | Path) -> None:
    """``--side`` and ``--out`` (a file this process can write), before any work."""
    if side not in (None, "left", "right"):
        raise RigConfigError(f"--side {side!r}: expected left or right")
    check_output(out, "--out")


def _check_can_store(db) -> None:
    """The result will be stored with the session: a read-only database is refused now, not
    after the extraction."""
    with open_store(db, create=False) as st:
        if st.readonly:
            raise RigConfigError(f"--db {db} is read-only ({st.readonly_reason}): add "
                                 "--no-store to extract the boundary without storing it in "
                                 "the session")


def run_boundary(request: BoundaryRequest) -> BoundaryResult:
    """Check the request, read the recording (one joint, or every joint of a whole ``limb``),
    extract, write the constraint or limb file (and store it with the session when asked)."""
    work = request.work
    work.check(request)
    src = request.source
    path = Path(request.out)
    result, text, meta = work.run(request, path)
    if src.db is not None and request.store:
        with open_store(src.db, create=False) as st:
            result.boundary_id = st.boundaries.add(src.session_id, text, meta)
        result.session_id = src.session_id
    return result


def _load_limb(request: BoundaryRequest) -> JointData:
    """Every joint of the whole limb ``request.limb`` (J = 3): a whole-limb session's, or a
    file's segment columns (:func:`~rig.readback.files.limb_orientations_from_file`)."""
    src = request.source
    if src.file is not None:
        return limb_orientations_from_file(src.file, request.columns(), request.limb,
                                           src.frames or "rig")
    with open_store(src.db, create=False) as store:
        sess = store.sessions.get(src.session_id)
        session_shape(sess).require_whole_limb(src.session_id, sess)
        data = joint_orientations_from_store(store, src.session_id, fusion=src.fusion)
    if data.limb != request.limb:
        raise RigConfigError(f"session {src.session_id} recorded the {data.limb}, not "
                             f"the {request.limb}")
    return data


def extract(data: JointData, *, name: str | None = None, side: str | None = None,
            alpha_deg: float = 4.0, max_vertices: int = 64, by_swing: str = "auto",
            kind: str | None = None):
    """The fitted extractor of one joint's loaded orientations (J = 1), from the one
    extraction entry :class:`~calibration.boundary.LimbExtractor` on a limb of that joint — a
    :class:`~calibration.boundary.HingeExtractor` for a hinge (elbow, knee), else a
    :class:`~calibration.boundary.BoundaryExtractor` (a ``two-axis`` joint for the wrist and
    the ankle when the recorded twist is narrow enough) — its constraint named
    (:func:`default_name`) and bound to the recording's patient, joint and side. ``kind``
    replaces the joint's own kind (``forearm``: an elbow's flexion and pronation–supination,
    :mod:`calibration.kinds.forearm`)."""
    prov = dict(data.provenance)
    prov["recording"] = data.facts().as_dict()
    label = name or default_name(data)
    bs = {"auto": "auto", "on": True, "off": False}[by_swing]
    # the one extraction entry, for a limb of one joint (calibration.boundary.LimbExtractor):
    # a joint of a whole-limb session reads its measured error as --limb reads it, for the
    # twist's reach alone (the two agree on every joint the limb does not couple)
    ex = LimbExtractor((data.joint,), alpha_deg=alpha_deg, max_vertices=max_vertices,
                       by_swing=bs, limb_axis=data.limb_axis, name=label,
                       slow_insets=not _of_a_limb(data), kind=kind).fit(
        data.joint_q, status=data.status, t=data.t, provenance=prov,
        slow_error_deg={data.joint: data.slow_error_deg}).extractors_[data.joint]
    binding = {"side": side or data.side, "joint": data.joint, "patient": data.patient}
    binding = {k: v for k, v in binding.items() if v}
    if binding:
        d = ex.constraint_.to_dict()
        d.update(binding)
        try:
            ex.constraint_ = JointConstraint.from_dict(d)
        except ValueError:  # a binding the format refuses (a file's joint): kept in provenance
            d = ex.constraint_.to_dict()
            d.setdefault("provenance", {}).update(binding)
            ex.constraint_ = JointConstraint.from_dict(d)
    return ex


def one_joint_limb(constraint: JointConstraint, joint: str, *, name: str,
                   side: str | None = None) -> Limb:
    """A limb of one joint whose limits are ``constraint`` (the joint's segments from
    :data:`calibration.joints.JOINTS`): what a limb's report takes."""
    spec = JOINTS[joint]
    doc: dict[str, Any] = {"name": name, "joints": [{
        "name": joint, "parent": spec.parent, "child": spec.child,
        "constraint": inline_constraint(constraint)}]}
    if side is not None:
        doc["side"] = side
    return Limb.from_dict(doc, source=name)


def _of_a_limb(data: JointData) -> bool:
    """Whether ``data`` is one joint of a whole-limb recording (:meth:`JointData.select`)."""
    return data.provenance.get("limb") in ("arm", "leg")


def default_name(data: JointData) -> str:
    """``<patient>-session-<id>-<start, UTC>`` for a session (unique across databases: session
    ids restart in each), the file's stem for a file."""
    if "session" in data.provenance:
        name = f"session-{data.provenance['session']}"
        started = data.provenance.get("started_at")
        if started is not None:
            stamp = dt.datetime.fromtimestamp(float(started), dt.timezone.utc)
            name += stamp.strftime("-%Y%m%dT%H%M%SZ")
        return f"{data.patient}-{name}" if data.patient else name
    return Path(str(data.provenance.get("file", "recording"))).stem


def describe(ex, out_path: Path | None = None) -> str:
    """What an extraction gave, for people: samples used and dropped, the polygon (or a
    hinge's interval), how much of the recording is inside, the twist range and the sparse
    arcs."""
    r = ex.report()
    lines = []
    if out_path is not None:
        lines.append(f"wrote {out_path}")
    own = calibration_kind(r.get("kind", DEFAULT_KIND)).describe_extraction(ex, r)
    if own is not None:  # a kind that says it itself (the forearm's two intervals)
        return "\n".join(lines + own)
    if get_kind(r.get("kind", DEFAULT_KIND)).single_axis:
        lines.append(f"  samples     {r['samples']} ({r['samples_used']} used, "
                     f"{r['dropped_status']} dropped for IMU status, "
                     f"{r['spikes']} isolated spikes)")
        lo, hi = r["hinge_deg"]
        inset = r["noise_inset_deg"]
        lines.append(f"  hinge       {lo:.1f} .. {hi:.1f} deg about "
                     f"{', '.join(f'{v:g}' for v in ex.axis)} (noise inset {inset[0]:.2f} / "
                     f"{inset[1]:.2f} deg)")
        lines.append(f"  inside      {100 * r['inside']:.2f} % of the {r['samples_used']} "
                     f"recorded angles inside the interval written, "
                     f"{100 * r['inside_1deg']:.2f} % within 1 deg")
        lines.append(f"  off-axis    {r['off_axis_rms_deg']:.1f} deg RMS, "
                     f"{r['off_axis_p99_deg']:.1f} deg p99 (motion about other axes: "
                     "corrected to the hinge, not a limit)")
        return "\n".join(lines)
    lines.append(f"  samples     {r['samples']} ({r['samples_used']} used, "
                 f"{r['dropped_status']} dropped for IMU status, "
                 f"{r['spikes']} isolated spikes, {r['glitch_cluster_samples']} in glitch "
                 "clusters)")
    lines.append(f"  swing       polygon, {r['vertices']} vertices, alpha "
                 f"{r['alpha_used_deg']:.1f} deg, noise inset {r['noise_inset_deg']:.2f} deg")
    lines.append(f"  inside      {100 * r['inside']:.2f} % of the {r['directions']} recorded "
                 f"directions inside the boundary written, {100 * r['inside_1deg']:.2f} % "
                 "within 1 deg")
    tw = r["twist_deg"]
    extra = f", {r['by_swing_points']} swing regions" if r["by_swing_points"] else ""
    lines.append(f"  twist       {tw[0]:.1f} .. {tw[1]:.1f} deg{extra}")
    note = ex.constraint_.provenance.get("kind_note")
    if r.get("kind", DEFAULT_KIND) != DEFAULT_KIND or note:
        lines.append(f"  kind        {r['kind']}" + (f" ({note})" if note else ""))
    if r["sparse_arcs"]:
        lines.append(f"  sparse      {len(r['sparse_arcs'])} boundary arcs "
                     f"({r['sparse_length_deg']:.0f} deg) with fewer than "
                     f"{ex.sparse_min_samples} samples within {ex.sparse_deg:g} deg: "
                     "the boundary there is interpolated; record more there")
    else:
        lines.append("  sparse      none: every part of the boundary has samples nearby")
    return "\n".join(lines)


def extract_limb(data: JointData, *, name: str | None = None, side: str | None = None,
                 alpha_deg: float = 4.0, max_vertices: int = 64) -> LimbExtractor:
    """The fitted :class:`~calibration.boundary.LimbExtractor` of a whole limb's loaded
    orientations (J = 3), its limb file named (default: ``session-N`` or the file's stem, and
    the limb) and bound to the side; a session's provenance (session, calibration, fusion) and
    each joint's measured slow error
    (:attr:`JointData.slow_errors_deg <rig.readback.data.JointData.slow_errors_deg>`) go with
    it, a file's (file, segments, frames)."""
    slow = None
    if "session" in data.provenance:
        label = f"session-{data.provenance['session']}-{data.limb}"
        prov = {k: data.provenance[k] for k in ("session", "calibration_id", "fusion")
                if k in data.provenance}  # a servo limb's: no calibration, no fusion
        slow = data.slow_errors_deg
        if any(v is not None for v in slow.values()):
            prov["slow_error_deg"] = slow
    else:
        label = f"{Path(str(data.provenance.get('file', 'recording'))).stem}-{data.limb}"
        prov = dict(data.provenance)
    side = side or data.side
    side = side if side in ("left", "right") else None
    # a servo limb's session says its joints' kinds (a forearm elbow), an IMU one none
    return LimbExtractor(data.limb, name=name or label, alpha_deg=alpha_deg,
                         max_vertices=max_vertices,
                         kinds=data.provenance.get("kinds")).fit(
        data.joint_q, t=data.t, status=data.status, side=side, provenance=prov,
        slow_error_deg=slow)


def describe_limb(ex: LimbExtractor, path: Path, boundary_id: int | None = None,
                  session_id: int | None = None) -> str:
    """What ``rig boundary --limb`` prints: each joint's limits (or coupling), how much of the
    recording they hold, each tested coupling and why, and where the file was stored."""
    r = ex.report()
    lines = [f"wrote {path}", f"  limb        {ex.limb}, {len(ex.limb_.joints)} joints"]
    if boundary_id is not None:
        lines.append(f"  stored      boundary {boundary_id} of session {session_id}")
    for j in ex.limb_.joints:
        rep = r["joints"].get(j.name, {})
        if j.coupling is not None:
            what = (f"coupled to the {j.coupling.by}: keyframes at "
                    f"{', '.join(f'{a:.0f}' for a in j.coupling.at_deg)} deg")
        elif j.joint_kind.single_axis:
            lo, hi = rep["hinge_deg"]
            what = f"hinge {lo:.1f} .. {hi:.1f} deg"
        elif j.joint_kind.flexion_rotation:
            (flo, fhi), (rlo, rhi) = rep["flexion_deg"], rep["rotation_deg"]
            what = (f"forearm, flexion {flo:.1f} .. {fhi:.1f} deg, rotation {rlo:.1f} .. "
                    f"{rhi:.1f} deg")
        else:
            what = (f"{j.constraint.kind}, polygon of {rep.get('vertices', '?')} vertices, "
                    f"twist {rep['twist_deg'][0]:.1f} .. {rep['twist_deg'][1]:.1f} deg")
        inside, held = r["inside"][j.name], r["held"][j.name]
        lines.append(f"  {j.name:<11} {what}; {100 * inside:.2f} % of the recorded postures "
                     "inside" + ("" if held == inside else
                                 f", {100 * held:.2f} % within their measured error"))
    for name, c in r["couplings"].items():
        lines.append(f"  coupling    {name}: {'yes' if c['coupled'] else 'no'}: {c['note']}")
        if c["coupled"]:  # why `--joint` and `rig rom` on this file may read it otherwise
            lines.append(f"              (`rig rom` on this file reads the {name} as the "
                         f"largest over its keyframes, each from the postures at its "
                         f"{ex.limb_.joints[1].name} angle; `--joint {name}` takes every "
                         "posture at once: the peaks may differ)")
    lines.append(f"  inside      {100 * r['inside']['limb']:.2f} % of the recorded postures "
                 "inside in every joint")
    return "\n".join(lines)


def stored_limb(store, session_id: int):
    """The last limb file stored with a session (``rig boundary --limb``), as ``(Limb,
    boundary id)``, or None."""
    rows = store.boundaries.list(session_id, limb=True)
    if not rows:
        return None
    b = rows[-1]
    return loads_limb(b["constraint_yaml"], source=f"boundary {b['id']}"), int(b["id"])
