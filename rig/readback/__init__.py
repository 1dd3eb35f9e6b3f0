"""A recording read back: joint orientations from a session or a file, the facts a reader must
know before trusting figures from them, and what the clinician asks of them — the boundary
(``rig boundary``) and the clinical range of motion (``rig rom``).

Modules
-------
:mod:`~rig.readback.source`
    :class:`RecordingSource`: which recording (a session in a store or an orientation file),
    checked before any work and loaded.
:mod:`~rig.readback.sessions`
    A session's joint orientations, one joint or a whole limb: servo joint samples, or IMU
    orientations through the calibration, VQF fusion of the raw samples and the heading-drift
    correction.
:mod:`~rig.readback.files`
    An orientation file's (.sto / CSV) joint orientations, rig or ISB frames: one joint's
    columns, or a whole limb's segment columns.
:mod:`~rig.readback.data`
    :class:`JointData` (N samples of J joints + provenance; one joint is J = 1) and
    :class:`RecordingFacts`.
:mod:`~rig.readback.boundary`
    :func:`run_boundary` (:class:`BoundaryRequest` → :class:`BoundaryResult`): a constraint
    file of one joint, or a limb file of a whole limb (``limb``); :func:`extract` (one joint)
    and :func:`extract_limb` (a whole limb) on orientations already loaded.
:mod:`~rig.readback.rom`
    :func:`run_rom` (:class:`RomRequest` → :class:`RomResult`).
"""

from rig.readback.boundary import (
    BoundaryRequest,
    BoundaryResult,
    describe,
    extract,
    extract_limb,
    run_boundary,
)
from rig.readback.data import JointData, RecordingFacts
from rig.readback.rom import RomRequest, RomResult, run_rom
from rig.readback.sessions import joint_orientations_from_store, read_session
from rig.readback.source import FUSION_CHOICES, RecordingSource, load_joint_orientations

__all__ = [
    "FUSION_CHOICES",
    "BoundaryRequest",
    "BoundaryResult",
    "JointData",
    "RecordingFacts",
    "RecordingSource",
    "RomRequest",
    "RomResult",
    "describe",
    "extract",
    "extract_limb",
    "joint_orientations_from_store",
    "load_joint_orientations",
    "read_session",
    "run_boundary",
    "run_rom",
]
