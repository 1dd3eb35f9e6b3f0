"""Joint orientations from an orientation file (OpenSim ``.sto`` or CSV, :mod:`rig.store.io`):
one column, or a reference and a limb column (joint orientation = reference⁻¹ ⊗ limb), in rig or
ISB segment frames (:mod:`calibration.frames`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from rig.errors import RigConfigError
from rig.readback.data import JointData

__all__ = ["joint_orientations_from_file"]


def joint_orientations_from_file(file: str, reference: str | None, limb: str, axis: np.ndarray,
                                 frames: str = "rig") -> JointData:
    """Joint orientations (rig frames) of ``file``'s ``limb`` column relative to its
    ``reference`` column (``limb`` alone: the column holds joint orientations already);
    ``frames`` is the file's segment-frame convention, ``axis`` the limb axis in rig frames."""
    from calibration.alignment import joint_orientation
    from calibration.frames import joint_to_rig, segment_to_rig
    from rig.store.io import read_orientations

    table = read_orientations(file)
    if len(table) < 1:
        raise RigConfigError(f"{file}: no samples")
    child = table.get(limb)
    if reference is not None:
        q = joint_orientation(segment_to_rig(table.get(reference), frames),
                              segment_to_rig(child, frames))
    else:
        q = joint_to_rig(child, frames)
    prov = {"file": str(Path(file).name), "limb": limb, "frames": frames}
    if reference is not None:
        prov["reference"] = reference
    side = table.meta.get("rig_side")
    return JointData(q, None, axis, side if side in ("left", "right") else None, prov,
                     table.meta.get("rig_patient"), table.meta.get("rig_joint"),
                     np.asarray(table.time, dtype=np.float64))
