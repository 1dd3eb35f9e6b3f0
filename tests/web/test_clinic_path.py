"""The clinician's path through the real ``rig serve`` (a child process on 127.0.0.1) in headless
Chromium: a new patient → the guided recording on a simulated rig with the live coverage view
→ the boundary extracted off the request path → the report → a second visit → the progress
across visits. Every wait is for content (an event counted, a state shown), bounded only so
that a broken page fails instead of hanging. With ``RIG_WEB_SHOTS=DIR`` each page is saved
there as a PNG (``docs/web/path-*.png``).
"""

from __future__ import annotations

import os

import pytest

from rig.store import open_store
from tests.rig.rigs import sim_imu_yaml
from tests.web.browser import quit_chromium, require_driver, start_chromium
from tests.web.clinic import running

pytestmark = pytest.mark.xdist_group("web-clinic-path")

BOUND_S = 90.0  # the longest any wait may take before the test fails (never a measurement)


def _wait(drv, script, *args):
    from selenium.webdriver.support.ui import WebDriverWait

    return WebDriverWait(drv, BOUND_S, poll_frequency=0.05).until(
        lambda d: d.execute_script(script, *args))


def _click_and_load(drv, element):
    from selenium.webdriver.support import expected_conditions as ec
    from selenium.webdriver.support.ui import WebDriverWait

    old = drv.find_element("tag name", "html")
    element.click()
    WebDriverWait(drv, BOUND_S).until(ec.staleness_of(old))


def _record(drv, shot, n: int) -> int:
    """From the patient's page: the guided recording's form, the live view until the
    recording ends; returns the session id."""
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import Select

    _click_and_load(drv, drv.find_element(By.ID, "record-link"))
    Select(drv.find_element(By.NAME, "rig")).select_by_value("clinic-imu")
    drv.find_element(By.NAME, "duration_s").send_keys("12")
    assert drv.find_element(By.NAME, "calibrate").is_selected()  # the guided calibration
    shot(f"record-form-{n}")
    drv.find_element(By.ID, "start").click()
    _wait(drv, "return document.getElementById('job') && window.rigLive;")
    snap = ("const c = window.rigLive.events.coverage || 0;"
            "if (c < arguments[0]) return null;"
            "return [c, document.getElementById('samples').textContent,"
            " document.getElementById('swing-map').toDataURL()];")
    first = _wait(drv, snap, 1)
    second = _wait(drv, snap, first[0] + 2)
    assert int(second[1]) > int(first[1]) and second[2] != first[2]  # the live view moved
    shot(f"live-{n}")
    end = _wait(drv, "return window.rigLive.ended;")
    assert end["status"] == "completed", end
    return int(end["result"]["session_id"])


def test_new_patient_two_visits_boundary_report_progress(tmp_path):
    from selenium.webdriver.common.by import By

    require_driver()
    cfg = sim_imu_yaml(tmp_path, port_suffix="&time_scale=10", name="clinic-imu")
    db = tmp_path / "clinic.db"
    shots = os.environ.get("RIG_WEB_SHOTS")
    with running(["--db", str(db), "--cache", str(tmp_path / "cache"), "--rig", str(cfg)],
                 tmp_path) as server:
        drv = start_chromium(height=1000)

        def shot(name: str) -> None:
            if shots:
                drv.save_screenshot(os.path.join(shots, f"path-{name}.png"))

        try:
            base = server.url
            drv.get(base + "/patients")
            drv.find_element(By.ID, "pseudonym").send_keys("P-0100")
            _click_and_load(drv, drv.find_element(By.ID, "create"))
            assert drv.find_element(By.ID, "patient-pseudonym").text == "P-0100"
            assert "P-0100" not in drv.current_url
            patient_url = drv.current_url
            shot("patient")

            first = _record(drv, shot, 1)
            # the boundary, extracted by a job on the server
            _click_and_load(drv, drv.find_element(By.ID, "work-link"))
            shot("work")
            drv.find_element(By.CSS_SELECTOR, "button.start-job").click()
            end = _wait(drv, "return window.rigLive && window.rigLive.ended;")
            assert end["status"] == "completed", end
            shot("boundary-job")
            # the session's page and its report, which uses the stored boundary
            _click_and_load(drv, drv.find_element(By.ID, "session-link"))
            assert f"/sessions/{first}" in drv.current_url
            assert "constraint (YAML)" in drv.find_element(By.ID, "downloads").text  # to take
            shot("session")
            _click_and_load(drv, drv.find_element(By.ID, "report-link"))
            page = drv.page_source
            assert "Range of motion report" in page and "stored with the session" in page
            shot("report")

            drv.get(patient_url)  # the second visit
            second = _record(drv, shot, 2)
            assert second != first
            drv.get(patient_url)
            _click_and_load(drv, drv.find_element(By.ID, "progress-link"))
            text = drv.find_element(By.ID, "progress").text
            assert "Progress across visits" in text
            for sid in (first, second):
                assert drv.find_elements(By.LINK_TEXT, str(sid))  # both visits listed
            shot("progress")
            assert "Traceback" not in drv.page_source
        finally:
            quit_chromium(drv)
    with open_store(db, create=False) as store:  # what the pages showed is what was stored
        sessions = store.sessions.list(patient="P-0100")
        assert [s["status"] for s in sessions] == ["completed", "completed"]
        assert len(store.boundaries.list(first)) == 1
        assert all(store.samples.count(s["id"]) > 0 for s in sessions)
