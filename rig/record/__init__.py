"""Recording sessions: guided calibration, crash-safe sample capture, live coverage.

Public API
----------
record_session(options, ...) -> RecordResult
    One session from rig configuration to stored samples (:mod:`rig.record.session`).
RecordOptions, RecordResult, Annotation, parse_annotation
CoverageMap, CoverageSummary
    Coverage of the swing sphere near the boundary, per azimuthal sector
    (:mod:`calibration.coverage`).
SamplePump
    Reader thread + bounded queue (:mod:`rig.record.pump`).
make_display, PlainDisplay, LiveDisplay
    What the clinician sees (:mod:`rig.record.display`).
"""

from calibration.coverage import CoverageMap, CoverageSummary, SectorCoverage
from rig.record.display import LiveDisplay, PlainDisplay, RecordStatus, make_display
from rig.record.pump import SampleBatch, SamplePump
from rig.record.session import (
    Annotation,
    RecordOptions,
    RecordResult,
    parse_annotation,
)
from rig.record.session import record as record_session

__all__ = [
    "Annotation",
    "CoverageMap",
    "CoverageSummary",
    "LiveDisplay",
    "PlainDisplay",
    "RecordOptions",
    "RecordResult",
    "RecordStatus",
    "SampleBatch",
    "SamplePump",
    "SectorCoverage",
    "make_display",
    "parse_annotation",
    "record_session",
]
