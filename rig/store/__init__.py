"""Session store: pseudonymised patients, recording sessions, samples, calibrations,
boundaries, trained models, and the live loop's runs and telemetry.

One small module in front of SQLAlchemy Core; SQLite (WAL, owner-only file) by default, the
same code on PostgreSQL by URL. Nothing else in the project writes SQL. See ``docs/store.md``.

>>> from rig.store import open_store
>>> with open_store("rig.db") as store:                       # doctest: +SKIP
...     pid = store.ensure_patient("P-0042")
...     sid = store.start_session(pid, rig_name="sim-imu", joint="shoulder", side="right")
...     with store.sample_writer(sid) as w:
...         w.add(t, None, "humerus", "sensor", q, 3)
...     store.end_session(sid, status="completed")

Import/export of orientation time series (OpenSim ``.sto``, CSV) lives in :mod:`rig.store.io`.
"""

from rig.store.schema import SCHEMA_VERSION, TELEMETRY_COLUMNS
from rig.store.store import (
    LIMB_BOUNDARY,
    RUN_STATUSES,
    SESSION_KINDS,
    SESSION_STATUSES,
    Store,
    describe_url,
    file_sha256,
    open_store,
)
from rig.store.writers import SampleWriter, TelemetryWriter

__all__ = [
    "LIMB_BOUNDARY",
    "RUN_STATUSES",
    "SCHEMA_VERSION",
    "SESSION_KINDS",
    "SESSION_STATUSES",
    "TELEMETRY_COLUMNS",
    "SampleWriter",
    "Store",
    "TelemetryWriter",
    "describe_url",
    "file_sha256",
    "open_store",
]
