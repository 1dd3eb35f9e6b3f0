"""Parts of the web app that need no server: the clinic layer on both stores, the report
cache's pruning."""

from __future__ import annotations

import os

import pytest

from rig.store import open_store
from rig.web import clinic
from rig.web.clinic import prune_reports


def test_a_replaced_report_is_pruned_once_old(tmp_path):
    names = ["session-3-aaa.html", "session-3-bbb.html", "session-3-ccc.html",
             "session-31-ddd.html"]
    for k, name in enumerate(names):
        (tmp_path / name).write_text("x")
        os.utime(tmp_path / name, (1000.0 + k, 1000.0 + k))
    os.utime(tmp_path / "session-3-bbb.html", (1900.0, 1900.0))  # sent a moment ago
    gone = prune_reports(tmp_path / "session-3-ccc.html", grace_s=600, now=2000.0)
    assert [p.name for p in gone] == ["session-3-aaa.html"]
    assert sorted(p.name for p in tmp_path.iterdir()) == names[1:]


def test_the_clinic_on_both_stores(db_url):
    """Patients and sessions as the pages read them, on SQLite and on PostgreSQL."""
    with open_store(db_url) as store:
        pid, warning = clinic.create_patient(store, "P-0001", "left")
        assert warning is None
        other = store.patients.add("P-0002")
        sid = store.sessions.start(other, rig_name="sim-servo", joint="elbow", side="right")
        with pytest.raises(clinic.PseudonymConcern, match="a date"):
            clinic.create_patient(store, "P 1961-04-12")
        assert [p["pseudonym"] for p in clinic.find_patients(store, "p-000")] == [
            "P-0002", "P-0001"]
        assert clinic.session_of(store, other, sid)["status"] == "running"
        with pytest.raises(clinic.NotFound, match=f"patient {pid} has no session {sid}"):
            clinic.session_of(store, pid, sid)
        assert [p["pseudonym"] for p in store.patients.list()] == ["P-0001", "P-0002"]
