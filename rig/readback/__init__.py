"""A recording read back: joint orientations from a session or a file, the facts a reader must
know before trusting figures from them, and what the clinician asks of them — the boundary
(``rig boundary``) and the clinical range of motion (``rig rom``).

Modules
-------
:mod:`~rig.readback.source`
    :class:`RecordingSource`: which recording (a session in a store or an orientation file),
    checked before any work and loaded.
:mod:`~rig.readback.sessions`
    A session's joint orientations: servo joint samples, or IMU orientations through the
    calibration, VQF fusion of the raw samples and the heading-drift correction.
:mod:`~rig.readback.files`
    An orientation file's (.sto / CSV) joint orientations, rig or ISB frames.
:mod:`~rig.readback.data`
    :class:`JointData` (orientations + provenance) and :class:`RecordingFacts`.
:mod:`~rig.readback.boundary`
    :func:`run_boundary` (:class:`BoundaryRequest` → :class:`BoundaryResult`), :func:`extract`;
    a limb file from a file's segment columns: :func:`run_chain` (:class:`ChainRequest` →
    :class:`ChainResult`).
:mod:`~rig.readback.rom`
    :func:`run_rom` (:class:`RomRequest` → :class:`RomResult`).
"""

from rig.readback.boundary import (
    BoundaryRequest,
    BoundaryResult,
    ChainRequest,
    ChainResult,
    describe,
    extract,
    run_boundary,
    run_chain,
)
from rig.readback.data import JointData, RecordingFacts
from rig.readback.rom import RomRequest, RomResult, run_rom
from rig.readback.sessions import joint_orientations_from_store, read_session
from rig.readback.source import FUSION_CHOICES, RecordingSource, load_joint_orientations

__all__ = [
    "FUSION_CHOICES",
    "BoundaryRequest",
    "BoundaryResult",
    "ChainRequest",
    "ChainResult",
    "JointData",
    "RecordingFacts",
    "RecordingSource",
    "RomRequest",
    "RomResult",
    "describe",
    "extract",
    "joint_orientations_from_store",
    "load_joint_orientations",
    "read_session",
    "run_boundary",
    "run_chain",
    "run_rom",
]
