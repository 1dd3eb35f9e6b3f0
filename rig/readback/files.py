"""Joint orientations from an orientation file (OpenSim ``.sto`` or CSV, :mod:`rig.store.io`; a
motion lab's C3D or BVH, :mod:`rig.store.labfiles`): one column, or a parent and a child
segment's columns (joint orientation = parent⁻¹ ⊗ child), in rig or ISB segment frames
(:mod:`calibration.frames`). A lab file's segment frames are built by its reader (ISB, turned
into the rig's here), so ``frames`` does not apply to it: ``--frames rig`` and ``--frames isb``
read the same joints."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from calibration.alignment import joint_orientation
from calibration.frames import joint_to_rig, segment_to_rig
from calibration.joints import JOINTS, LIMB_CHAINS, columns_mismatch, joint_of_columns
from rig.errors import RigConfigError
from rig.readback.data import JointData, parse_axis
from rig.store.io import OrientationTable, read_orientations
from rig.store.labfiles import LAB_SUFFIXES, read_lab_file, to_frames

__all__ = ["FILE_SUFFIXES", "check_columns", "file_format", "is_lab_file",
           "joint_orientations_from_file", "limb_orientations_from_file", "read_table"]

#: The suffixes of the orientation files read (:func:`read_table`): OpenSim ``.sto``, CSV
#: (``.csv``, ``.txt``), and a motion lab's C3D and BVH.
FILE_SUFFIXES = (".sto", ".csv", ".txt", *LAB_SUFFIXES)

_FORMATS = {".sto": "OpenSim orientations (.sto)", ".csv": "CSV of orientations",
            ".txt": "CSV of orientations", ".c3d": "C3D (markers and model outputs)",
            ".bvh": "BVH (skeleton and joint rotations)"}


def is_lab_file(file: str) -> bool:
    """A C3D or BVH file (by suffix), read by :mod:`rig.store.labfiles`."""
    return Path(file).suffix.lower() in LAB_SUFFIXES


def file_format(file: str) -> str:
    """The format of an orientation file, for people (by its suffix)."""
    return _FORMATS.get(Path(file).suffix.lower(), Path(file).suffix or "unknown")


def _read_facts(table: OrientationTable) -> dict[str, str]:
    """What a lab file's reader built the columns from (``read``: its marker set or skeleton)
    and the frames it dropped for a marker gap, for the provenance (empty for a ``.sto``)."""
    out = {}
    if table.meta.get("has"):
        out["read"] = str(table.meta["has"])
    if table.meta.get("dropped_frames"):
        out["dropped_frames"] = str(table.meta["dropped_frames"])
    return out


def read_table(file: str, frames: str) -> tuple[OrientationTable, str]:
    """``file``'s table and the frames its columns are in: a lab file's turned into rig frames
    (its reader knows them), else as ``frames`` says."""
    if is_lab_file(file):
        return to_frames(read_lab_file(file), "rig"), "rig"
    return read_orientations(file), frames


def check_columns(file: str, parent: str | None, child: str, joint: str | None,
                  side: str | None, *, asked: bool = True) -> None:
    """A parent and a child column whose names say other segments than ``joint``'s (None:
    not judged) or another side than ``side`` are refused in one line
    (:func:`calibration.joints.columns_mismatch`): ``--joint elbow --parent femur_r --child
    tibia_r`` is a knee. ``asked``: the joint was given (--joint), else it is the file's own
    or the default."""
    spec = JOINTS[joint] if joint is not None else None
    cols = [child] if parent is None else [parent, child]
    segs = [None] * len(cols) if spec is None else \
        [spec.child] if parent is None else [spec.parent, spec.child]
    why = columns_mismatch(cols, segs, side=side)
    if why is None:
        return
    implied = joint_of_columns(parent, child)
    about = "" if joint is None else \
        f" (reading the {joint}: --joint {joint})" if asked else \
        f" (reading the {joint}, the file's joint or the default: give --joint)"
    hint = f"; these columns are a {implied}: --joint {implied}" if implied and \
        implied != joint else ""
    raise RigConfigError(f"{file}: {why}{about}{hint}")


def joint_orientations_from_file(file: str, parent: str | None, child: str, axis: np.ndarray,
                                 frames: str = "rig", joint: str | None = None) -> JointData:
    """Joint orientations (rig frames) of ``file``'s ``child`` column relative to its
    ``parent`` column (``child`` alone: the column holds joint orientations already);
    ``frames`` is the file's segment-frame convention, ``axis`` the limb axis in rig frames,
    ``joint`` the joint (:data:`calibration.joints.JOINTS`; None: the file's, else the
    shoulder) whose segments the columns are."""
    table, frames = read_table(file, frames)
    if len(table) < 1:
        raise RigConfigError(f"{file}: no samples")
    child_q = table.get(child)
    named = table.meta.get("rig_joint")
    asked = joint is not None
    if joint is None:
        joint = named if named in JOINTS else None
    spec = JOINTS[joint or "shoulder"]
    check_columns(file, parent, child, spec.name, None, asked=asked)
    if parent is not None:
        q = joint_orientation(segment_to_rig(table.get(parent), frames, spec.parent),
                              segment_to_rig(child_q, frames, spec.child))
    else:
        q = joint_to_rig(child_q, frames, spec.parent, spec.child)
    # the provenance keys stay "limb" and "reference": constraint files already carry them
    prov = {"file": str(Path(file).name), "limb": child, "frames": frames,
            **_read_facts(table)}
    if parent is not None:
        prov["reference"] = parent
    side = table.meta.get("rig_side")
    return JointData.of_joint(q, joint or named, t=np.asarray(table.time, dtype=np.float64),
                              limb_axis=axis, side=side if side in ("left", "right") else None,
                              provenance=prov, patient=table.meta.get("rig_patient"))


def limb_orientations_from_file(file: str, columns: list[str], limb: str,
                                frames: str = "rig") -> JointData:
    """A whole limb's postures from ``file``'s four segment ``columns`` (proximal to distal, the
    segments of :data:`calibration.joints.LIMB_CHAINS` ``[limb]``): the joint orientations
    (N, 3, 4), rig frames, each child relative to its parent, with the file's times, side
    and patient."""
    table, frames = read_table(file, frames)
    if len(table) < 1:
        raise RigConfigError(f"{file}: no samples")
    order = LIMB_CHAINS[limb]
    names = [order[0][1], *(c for _, _, c in order)]
    seg = [segment_to_rig(table.get(c), frames, n) for c, n in zip(columns, names, strict=True)]
    q = np.stack([joint_orientation(seg[i], seg[i + 1]) for i in range(3)], axis=1)
    side = table.meta.get("rig_side")
    return JointData(q, tuple(name for name, _, _ in order),
                     np.asarray(table.time, dtype=np.float64), None, parse_axis(None),
                     side if side in ("left", "right") else None,
                     {"file": Path(file).name, "segments": list(columns), "frames": frames,
                      **_read_facts(table)},
                     table.meta.get("rig_patient"), limb)
