"""``rig boundary`` as a library: a patient-specific constraint file from a recording.

:func:`run_boundary` takes a :class:`BoundaryRequest` (which recording, the extractor's
parameters, where to write) and returns a :class:`BoundaryResult`; :func:`extract` runs the
extractor (:class:`calibration.boundary.BoundaryExtractor`) on joint orientations already
loaded (the recorder's range of motion, the report, the demo). The constraint records its
provenance (session or file, parameters, sample counts, sparse arcs, the recording's facts) and
its binding (patient, joint, side).
"""

from __future__ import annotations

import datetime as dt
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from models.kinds import DEFAULT_KIND, get_kind
from rig.errors import RigConfigError
from rig.readback.data import FUSION_CHOICES, JointData
from rig.readback.source import RecordingSource

__all__ = ["BY_SWING_CHOICES", "BoundaryRequest", "BoundaryResult", "ChainRequest",
           "ChainResult", "default_name", "describe", "extract", "run_boundary", "run_chain"]

#: ``--by-swing``: swing-dependent twist limits when the data supports them, always, never.
BY_SWING_CHOICES = ("auto", "on", "off")


@dataclass(frozen=True)
class BoundaryRequest:
    """What ``rig boundary`` is asked.

    Attributes
    ----------
    source : RecordingSource
        The recording.
    out : str or Path
        Constraint file to write (YAML, owner-only).
    name : str, optional
        Constraint name (default: :func:`default_name`).
    side : {"left", "right"}, optional
        Side recorded in the constraint (default: the session's or file's).
    alpha_deg, max_vertices, by_swing
        The extractor's alpha-shape radius, vertex budget and swing-dependent twist choice.
    store : bool
        With a session: also store the boundary in the session's database (the database must
        be writable; checked first).
    """

    source: RecordingSource
    out: str | Path
    name: str | None = None
    side: str | None = None
    alpha_deg: float = 4.0
    max_vertices: int = 64
    by_swing: str = "auto"
    store: bool = True

    def check(self) -> None:
        """Everything that can be checked before reading the recording (one-line errors)."""
        self.source.check(side=self.side)
        if self.by_swing not in BY_SWING_CHOICES:
            raise RigConfigError(f"--by-swing {self.by_swing!r}: expected one of "
                                 f"{', '.join(BY_SWING_CHOICES)}")
        _check_side_and_out(self.side, self.out)
        if self.source.db is not None and self.store:
            _check_can_store(self.source.db)


@dataclass
class BoundaryResult:
    """What ``rig boundary`` produced: the fitted extractor (its ``constraint_`` and
    ``report()``), the joint orientations it saw, the file written, the stored boundary's id
    (None when not stored) and the reasons to doubt the recording (one line each)."""

    extractor: Any
    data: JointData
    path: Path
    boundary_id: int | None = None
    warnings: list[str] = field(default_factory=list)

    @property
    def constraint(self):
        """The :class:`~models.constraint.JointConstraint` written."""
        return self.extractor.constraint_

    def describe(self) -> str:
        """The summary ``rig boundary`` prints (:func:`describe`)."""
        return describe(self.extractor, self.path)


def _check_side_and_out(side: str | None, out: str | Path) -> None:
    """``--side`` and ``--out`` (a file this process can write), before any work."""
    from models.fileio import check_output

    if side not in (None, "left", "right"):
        raise RigConfigError(f"--side {side!r}: expected left or right")
    check_output(out, "--out")


def _check_can_store(db) -> None:
    """The result will be stored with the session: a read-only database is refused now, not
    after the extraction."""
    from rig.store import open_store

    with open_store(db, create=False) as st:
        if st.readonly:
            raise RigConfigError(f"--db {db} is read-only ({st.readonly_reason}): add "
                                 "--no-store to extract the boundary without storing it in "
                                 "the session")


def run_boundary(request: BoundaryRequest) -> BoundaryResult:
    """Check the request, read the recording, extract, write the constraint file (and store
    it with the session when asked)."""
    from models.constraint import dump_constraint

    request.check()
    data = request.source.load()
    ex = extract(data, name=request.name, side=request.side, alpha_deg=request.alpha_deg,
                 max_vertices=request.max_vertices, by_swing=request.by_swing)
    path = Path(request.out)
    dump_constraint(ex.constraint_, path)
    result = BoundaryResult(ex, data, path, warnings=data.facts().warnings())
    src = request.source
    if src.db is not None and request.store:
        from rig.store import open_store

        with open_store(src.db, create=False) as st:
            result.boundary_id = st.boundaries.add(src.session_id, ex.constraint_.to_yaml(),
                                                   {"path": str(path), **ex.report()})
    return result


def extract(data: JointData, *, name: str | None = None, side: str | None = None,
            alpha_deg: float = 4.0, max_vertices: int = 64, by_swing: str = "auto"):
    """The fitted extractor of loaded joint orientations — a
    :class:`~calibration.boundary.HingeExtractor` for a hinge (elbow, knee), else a
    :class:`~calibration.boundary.BoundaryExtractor` (a ``two-axis`` joint for the wrist and
    the ankle when the recorded twist is narrow enough) — its constraint named
    (:func:`default_name`) and bound to the recording's patient, joint and side."""
    from calibration.boundary.joint import fit_joint, joint_extractor
    from models.constraint import JointConstraint

    prov = dict(data.provenance)
    prov["recording"] = data.facts().as_dict()
    label = name or default_name(data)
    bs = {"auto": "auto", "on": True, "off": False}[by_swing]
    ex = joint_extractor(data.joint, limb_axis=data.limb_axis, alpha_deg=alpha_deg,
                         max_vertices=max_vertices, by_swing=bs, name=label)
    # one extraction for a joint alone and a limb's joints (calibration.boundary.joint): a
    # joint of a whole-limb session reads its measured error as --chain reads it, for the
    # twist's reach alone (the two agree on every joint the chain does not couple)
    fit_joint(ex, data.q, status=data.status, t=data.t, provenance=prov,
              slow_error_deg=data.slow_error_deg, slow_insets=not _of_a_limb(data))
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


def _of_a_limb(data: JointData) -> bool:
    """Whether ``data`` is one joint of a whole-limb recording (``ChainData.joint``)."""
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


@dataclass(frozen=True)
class ChainRequest:
    """``rig boundary --chain arm|leg``: a limb file from an orientation file's segment
    columns, or from a whole-limb session.

    Attributes
    ----------
    file : str or None
        OpenSim ``.sto`` or CSV orientation file (or ``db`` + ``session_id``).
    limb : {"arm", "leg"}
    segments : str or None
        A file's segment columns proximal to distal, comma-separated: four (thorax or pelvis
        first), or three when ``reference`` names the first. None for a session.
    reference : str, optional
        The root segment's column (thorax / pelvis).
    frames : {"rig", "isb"}, optional
        The file's segment frames (default rig).
    out, name, side
        Limb file to write, its name (default: the file's stem or ``session-N``, and the limb),
        the body side.
    db, session_id
        A session recorded on a ``limb:`` rig (:func:`rig.readback.sessions.
        chain_orientations_from_store`), instead of ``file``.
    fusion : str
        Sessions: where the IMU orientations come from (:data:`FUSION_CHOICES`).
    store : bool
        Sessions: also store the limb file with the session (a boundary whose ``meta.kind`` is
        :data:`rig.store.LIMB_BOUNDARY`; :func:`stored_limb` reads the last one back), as
        ``rig boundary`` stores a joint's constraint.
    """

    file: str | None
    limb: str
    segments: str | None
    out: str | Path
    reference: str | None = None
    frames: str | None = None
    name: str | None = None
    side: str | None = None
    db: str | None = None
    session_id: int | None = None
    fusion: str = "auto"
    store: bool = True

    def columns(self) -> list[str]:
        """The four segment columns, proximal to distal."""
        cols = [c.strip() for c in (self.segments or "").split(",") if c.strip()]
        if self.reference is not None:
            cols = [self.reference, *cols]
        if len(cols) != 4 or len(set(cols)) != 4:
            raise RigConfigError(f"--segments {self.segments!r}: expected the {self.limb}'s four "
                                 "segment columns proximal to distal (or three with "
                                 "--reference), all different")
        return cols

    def check(self) -> None:
        """Everything that can be checked before reading the recording (one-line errors)."""
        from calibration.joints import LIMB_CHAINS

        if self.limb not in LIMB_CHAINS:
            raise RigConfigError(f"--chain {self.limb!r}: expected one of "
                                 f"{', '.join(LIMB_CHAINS)}")
        if self.file is not None and (self.db is not None or self.session_id is not None):
            raise RigConfigError("give either FILE or --db/--session, not both")
        if self.file is None:
            if self.db is None or self.session_id is None:
                raise RigConfigError("--chain needs a recording: FILE --segments COL,COL,COL, "
                                     "or --db DB --session ID")
            for flag, value in (("--segments", self.segments), ("--reference", self.reference),
                                ("--frames", self.frames)):
                if value is not None:
                    raise RigConfigError(f"{flag} applies to files; a session knows its "
                                         "segments")
            if self.fusion not in FUSION_CHOICES:
                raise RigConfigError(f"fusion must be one of {', '.join(FUSION_CHOICES)}, got "
                                     f"{self.fusion!r}")
            if self.store:
                _check_can_store(self.db)
            from rig.readback.source import check_session_side

            check_session_side(self.db, self.session_id, self.side)
        else:
            if self.segments is None:
                raise RigConfigError("--chain needs --segments COL,COL,COL (proximal to distal)")
            from calibration.joints import columns_mismatch

            chain = LIMB_CHAINS[self.limb]
            why = columns_mismatch(self.columns(), [chain[0][1], *(c for _, _, c in chain)],
                                   side=self.side, what="--segments")
            if why is not None:
                raise RigConfigError(f"{self.file}: {why} (reading the {self.limb}: --chain "
                                     f"{self.limb})")
            if not Path(self.file).is_file():
                raise RigConfigError(f"{self.file}: no such file")
        _check_side_and_out(self.side, self.out)


@dataclass
class ChainResult:
    """The fitted :class:`~calibration.boundary.ChainExtractor`, the file written and the
    stored boundary's id (None when not stored)."""

    extractor: Any
    path: Path
    boundary_id: int | None = None
    session_id: int | None = None

    def describe(self) -> str:
        """What ``rig boundary --chain`` prints."""
        ex = self.extractor
        r = ex.report()
        lines = [f"wrote {self.path}", f"  limb        {ex.limb}, {len(ex.limb_.joints)} joints"]
        if self.boundary_id is not None:
            lines.append(f"  stored      boundary {self.boundary_id} of session {self.session_id}")
        for j in ex.limb_.joints:
            rep = r["joints"].get(j.name, {})
            if j.coupling is not None:
                what = (f"coupled to the {j.coupling.by}: keyframes at "
                        f"{', '.join(f'{a:.0f}' for a in j.coupling.at_deg)} deg")
            elif j.joint_kind.single_axis:
                lo, hi = rep["hinge_deg"]
                what = f"hinge {lo:.1f} .. {hi:.1f} deg"
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


def run_chain(request: ChainRequest) -> ChainResult:
    """Check the request, read the segment columns, extract the limb and write it."""
    from calibration.boundary import ChainExtractor
    from models.limb import dump_limb
    from rig.readback.files import chain_orientations_from_file

    request.check()
    status, slow = None, None
    if request.file is None:
        from rig.readback.sessions import read_chain

        chain = read_chain(request.db, request.session_id, request.fusion)
        if chain.limb != request.limb:
            raise RigConfigError(f"session {request.session_id} recorded the {chain.limb}, not "
                                 f"the {request.limb}")
        q, t, status, side = chain.q, chain.t, chain.status, request.side or chain.side
        name = request.name or f"session-{request.session_id}-{request.limb}"
        prov = {k: chain.provenance[k] for k in ("session", "calibration_id", "fusion")}
        slow = chain.slow_error_deg
        if any(v is not None for v in slow.values()):
            prov["slow_error_deg"] = slow
    else:
        cols = request.columns()
        frames = request.frames or "rig"
        q, table = chain_orientations_from_file(request.file, cols, request.limb, frames)
        t = np.asarray(table.time, dtype=np.float64)
        side = request.side or table.meta.get("rig_side")
        name = request.name or f"{Path(request.file).stem}-{request.limb}"
        prov = {"file": Path(request.file).name, "segments": cols, "frames": frames}
    side = side if side in ("left", "right") else None
    ex = ChainExtractor(request.limb, name=name).fit(q, t=t, status=status, side=side,
                                                     provenance=prov, slow_error_deg=slow)
    path = Path(request.out)
    dump_limb(ex.limb_, path)
    result = ChainResult(ex, path)
    if request.file is None and request.store:
        from rig.store import LIMB_BOUNDARY, open_store

        with open_store(request.db, create=False) as st:
            result.boundary_id = st.boundaries.add(
                request.session_id, ex.limb_.to_yaml(),
                {"kind": LIMB_BOUNDARY, "limb": request.limb, "path": str(path),
                 "coupled": {k: bool(v["coupled"]) for k, v in ex.report()["couplings"].items()}})
            result.session_id = request.session_id
    return result


def stored_limb(store, session_id: int):
    """The last limb file stored with a session (``rig boundary --chain``), as ``(Limb,
    boundary id)``, or None."""
    from models.limb import loads_limb

    rows = store.boundaries.list(session_id, limb=True)
    if not rows:
        return None
    b = rows[-1]
    return loads_limb(b["constraint_yaml"], source=f"boundary {b['id']}"), int(b["id"])
