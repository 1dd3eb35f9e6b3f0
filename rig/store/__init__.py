"""Session store: pseudonymised patients, recording sessions, samples, calibrations,
boundaries, trained models, and the live loop's runs and telemetry.

SQLite (WAL, owner-only file) by default, the same code on PostgreSQL by URL, on SQLAlchemy
Core. Nothing else in the project writes SQL. See ``docs/store.md``.

The rooms of the store (each module the only one writing its tables' SQL; arrows point down)::

    writers.py        SampleWriter, TelemetryWriter: batched background commits, on a Store
      |
    store.py          Store: the database -- open_store, transactions, schema version and
      |               migrations, read-only handling, close; one repository per concern:
      |   store.patients      patients.py      PatientRepository   add ensure find get list
      |   store.sessions      sessions.py      SessionRepository   start end get list liveness
      |                                        close_interrupted claim_writer set_dropped
      |                                        heartbeat merge_meta
      |   store.samples       samples.py       SampleRepository    add_sensor sensors read raw
      |                                        complete_raw_count span count t_range
      |                                        sensor_id insert_sensor insert
      |   store.calibrations  calibrations.py  CalibrationRepository  add list
      |   store.annotations   annotations.py   AnnotationRepository   add list
      |   store.boundaries    boundaries.py    BoundaryRepository     add get list
      |   store.models        trained_models.py  ModelRepository      add get list
      |   store.runs          runs.py          RunRepository       start end get list
      |                                        telemetry insert_telemetry
      |   store.jobs          jobs.py          JobRepository       start update end get list
      |                                        close_died (the web app's long work)
    rows.py           Repository base: rows as dicts, JSON columns, add/get/list once
    engine.py         the engine of a SQLite file (WAL, owner-only, read-only media) or a
                      PostgreSQL URL
    schema.py         the tables and their ordered migrations
    liveness.py       who writes a session, and whether that process is alive
    pseudonyms.py     the pseudonym policy: what a pseudonym must not look like
    io.py             OpenSim ``.sto`` / CSV import and export of orientation time series

>>> from rig.store import SampleWriter, open_store
>>> with open_store("rig.db") as store:                       # doctest: +SKIP
...     pid = store.patients.ensure("P-0042")
...     sid = store.sessions.start(pid, rig_name="sim-imu", joint="shoulder", side="right")
...     with SampleWriter(store, sid) as w:
...         w.add(t, None, "humerus", "sensor", q, 3)
...     store.sessions.end(sid, status="completed")
...     s = store.samples.read(sid, "humerus")
"""

from rig.store.boundaries import LIMB_BOUNDARY
from rig.store.engine import describe_url
from rig.store.jobs import JOB_KINDS, JOB_STATUSES, JobBusyError
from rig.store.runs import RUN_STATUSES
from rig.store.schema import SCHEMA_VERSION, TELEMETRY_COLUMNS
from rig.store.sessions import SESSION_KINDS, SESSION_STATUSES
from rig.store.store import Store, open_store
from rig.store.trained_models import file_sha256
from rig.store.writers import SampleWriter, TelemetryWriter

__all__ = [
    "JOB_KINDS",
    "JOB_STATUSES",
    "LIMB_BOUNDARY",
    "RUN_STATUSES",
    "SCHEMA_VERSION",
    "SESSION_KINDS",
    "SESSION_STATUSES",
    "TELEMETRY_COLUMNS",
    "JobBusyError",
    "SampleWriter",
    "Store",
    "TelemetryWriter",
    "describe_url",
    "file_sha256",
    "open_store",
]
