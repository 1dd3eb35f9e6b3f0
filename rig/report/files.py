"""The clinician's report of a file (``rig report FILE``): an OpenSim ``.sto`` or CSV of
orientations, or a motion lab's C3D or BVH (:mod:`rig.store.labfiles`), read as ``rig boundary``
and ``rig rom`` read it — the same :class:`~rig.readback.source.RecordingSource`, the same
``--parent`` / ``--child`` / ``--joint`` / ``--frames`` or ``--limb arm|leg --segments``
(:class:`~rig.readback.boundary.BoundaryRequest`, checked before any work).

One joint is a limb of one joint: its limits are extracted as ``rig boundary`` extracts them
(:func:`rig.readback.boundary.extract`) and put in a limb of that joint
(:func:`rig.readback.boundary.one_joint_limb`); a whole arm or leg's as ``rig boundary --limb``
does (:func:`rig.readback.boundary.extract_limb`, with its couplings) — the request's
``work`` chooses (:meth:`~rig.readback.boundary.OneJointBoundary.limits`). Either way the
page is a limb's report (:func:`rig.report.limb.limb_report_data`, the data object a
whole-limb session's report is made of, drawn by :func:`rig.report.limb.write_limb_report`):
the clinical table, the swing map or the hinge's interval, the couplings, the coupled clinical
tests when asked, the warnings. Only the header
differs: a file names no patient, so the page says "from file X" and what was read (the file,
its format, the marker set / skeleton / columns, the segment frames, samples, rate and
duration) where a session's page names the patient and the session.

The side is ``--side``, else the file's own (a ``.sto`` written by the rig says it), else what
the columns' names say (``femur_l`` → left, :func:`calibration.joints.segment_of_column`), else
the right — with a warning on the page, since a left limb read as a right one has its
abduction and rotations mirrored.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from calibration.joints import segment_of_column
from rig.readback.boundary import BoundaryRequest
from rig.readback.data import JointData
from rig.readback.files import file_format, is_lab_file
from rig.report.limb import LimbReportData, limb_report_data, write_limb_report

__all__ = ["file_facts", "file_report_data", "report_for_file"]


def _columns(data: JointData) -> list[str]:
    """The file's columns the recording was read from, proximal to distal."""
    prov = data.provenance
    if "segments" in prov:
        return [str(c) for c in prov["segments"]]
    return [str(c) for c in (prov.get("reference"), prov.get("limb")) if c is not None]


def _side(asked: str | None, data: JointData) -> tuple[str, str | None]:
    """The side read (module doc) and the warning when it was guessed (None otherwise)."""
    if asked is not None:
        return asked, None
    if data.side in ("left", "right"):
        return data.side, None
    sides = {segment_of_column(c)[1] for c in _columns(data)} - {None}
    if len(sides) == 1:
        return sides.pop(), None
    return "right", ("no side given and none in the file or its column names: read as the "
                     "right side (give --side left for a left limb: its abduction and "
                     "rotations would be mirrored)")


def file_facts(file: str, data: JointData) -> dict[str, str]:
    """What was read from ``file``, for the report's header: the file, its format, what its
    reader built the columns from and which columns, the segment frames, and the samples with
    their rate and duration."""
    prov = data.provenance
    cols = _columns(data)
    read = [str(prov["read"])] if prov.get("read") else []
    if cols:
        read.append(("segments " if "segments" in prov else "columns ") + " → ".join(cols))
    if is_lab_file(file):
        frames = "ISB, built by the reader (" + (
            "from the markers" if file.lower().endswith(".c3d") else
            "from the skeleton's rest pose") + "), turned into the rig's"
    else:
        frames = {"isb": "ISB / OpenSim (--frames isb)",
                  "rig": "the rig's (+X distal, +Y anterior, +Z right)"}.get(
                      str(prov.get("frames")), str(prov.get("frames")))
    t = np.asarray(data.t if data.t is not None else [], dtype=np.float64)
    n = len(data.joint_q)
    samples = f"{n:,}"
    if len(t) > 1 and t[-1] > t[0]:
        span = float(t[-1] - t[0])
        samples += f" at {(len(t) - 1) / span:.0f} Hz ({span:.1f} s)"
    if prov.get("dropped_frames") not in (None, "0"):
        samples += f"; {prov['dropped_frames']} frames dropped (a marker missing)"
    out = {"From file": Path(file).name, "Format": file_format(file)}
    if read:
        out["Read"] = "; ".join(read)
    out["Segment frames"] = frames
    out["Samples"] = samples
    return out


def file_report_data(request: BoundaryRequest, *, age: int | None = None,
                     sex: str | None = None, reference=None,
                     coupled_tests: bool = False) -> LimbReportData:
    """Everything the report of a file shows (module doc).

    Parameters
    ----------
    request : BoundaryRequest
        The file (``request.source``: its columns, joint and frames) and one joint or a whole
        ``limb`` with its ``segments``, the side and the extractor's parameters, as ``rig
        boundary`` takes them; ``request.out`` is the page to write (checked writable).
    age, sex : optional
        For the population reference column.
    reference : Limb, JointConstraint or path, optional
        Limits drawn dashed (a limb file, or one joint's constraint file).
    coupled_tests : bool
        Add the section "Coupled clinical tests" (a whole arm or leg).

    Raises
    ------
    RigConfigError
        Before any extraction: a missing file, an unknown format, ``--frames`` with a C3D or
        BVH file, columns that are not the joint's, a C3D without the markers or a BVH
        without the joints asked for (one line each).
    """
    request.check()
    data = request.load()
    side, guessed = _side(request.side, data)
    if reference is not None:  # its file read before the extraction
        reference = request.work.reference(reference, data, side)
    limb, how = request.work.limits(request, data, side)
    postures = {j: data.joint_q[:, k] for k, j in enumerate(limb.joint_names)}
    warnings = ([guessed] if guessed else []) + data.facts().warnings()
    file = str(request.source.file)
    out = limb_report_data(
        limb, postures, side=side, patient="", warnings=warnings,
        reference=reference, age=age, sex=sex,
        limits_source=f"extracted from the file's postures for this report (as `{how}` "
                      "extracts them)",
        coupled_tests=coupled_tests)
    out.from_file = file_facts(file, data)
    return out


def report_for_file(request: BoundaryRequest, out_path, *, age: int | None = None,
                    sex: str | None = None, reference=None,
                    coupled_tests: bool = False) -> Path:
    """Write the report of a file (:func:`file_report_data`); returns its path."""
    return write_limb_report(file_report_data(request, age=age, sex=sex, reference=reference,
                                              coupled_tests=coupled_tests), out_path)
