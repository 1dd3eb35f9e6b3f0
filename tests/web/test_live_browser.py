"""The guided recording in a real headless Chromium (Selenium, Debian's chromium-driver): the
form, the live coverage view updating while the simulated patient moves, the Continue button
where ``rig record`` waits for Enter, Interrupt. Every wait is for content (an event counted,
a text shown), bounded only so that a broken page fails instead of hanging.
"""

from __future__ import annotations

import pytest

from rig.store import open_store
from tests.rig.rigs import sim_imu_yaml
from tests.web.browser import quit_chromium, require_driver, start_chromium
from tests.web.server import live_app, opener_as_hardware, serving

pytestmark = pytest.mark.xdist_group("web-live-browser")

BOUND_S = 60.0  # the longest any wait may take before the test fails (never a measurement)


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    require_driver()
    tmp = tmp_path_factory.mktemp("web-browser")
    cfg = sim_imu_yaml(tmp, port_suffix="&time_scale=4")
    db = str(tmp / "rig.db")
    with open_store(db) as store:
        patient = store.patients.ensure("P-0077")
    app = live_app(db, tmp / "files", opener=opener_as_hardware("sim-shoulder"),
                   rigs={"test-imu": str(cfg), "sim-shoulder": "sim-shoulder"})
    with serving(app) as base:
        drv = start_chromium()
        try:
            yield {"base": base, "db": db, "patient": patient, "driver": drv}
        finally:
            quit_chromium(drv)


def _wait(drv, script, *args):
    """Wait until ``script`` (JS returning a value) returns something truthy; that value."""
    from selenium.webdriver.support.ui import WebDriverWait

    return WebDriverWait(drv, BOUND_S, poll_frequency=0.05).until(
        lambda d: d.execute_script(script, *args))


def _start(site, rig, *, duration=None, calibrate=True):
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import Select

    drv = site["driver"]
    drv.get(f"{site['base']}/record?patient={site['patient']}")
    Select(drv.find_element(By.NAME, "rig")).select_by_value(rig)
    if duration is not None:
        drv.find_element(By.NAME, "duration_s").send_keys(str(duration))
    box = drv.find_element(By.NAME, "calibrate")
    if box.is_selected() != calibrate:
        box.click()
    drv.find_element(By.ID, "start").click()
    _wait(drv, "return document.getElementById('job') && window.rigLive;")
    return drv


def test_the_live_view_fills_while_the_patient_moves(site):
    drv = _start(site, "test-imu", duration=8, calibrate=False)
    snap = ("const c = window.rigLive.events.coverage || 0;"
            "if (c < arguments[0]) return null;"
            "return [c, document.getElementById('samples').textContent,"
            " document.getElementById('swing-map').toDataURL(),"
            " document.getElementById('explored').textContent,"
            " document.getElementById('left').children.length];")
    first = _wait(drv, snap, 1)
    second = _wait(drv, snap, first[0] + 2)  # two coverage events later
    assert int(second[1]) > int(first[1])  # the sample counter moved
    assert second[2] != first[2]  # the swing map was redrawn with more cells
    assert first[3].endswith("/ 12") and first[4] >= 1  # directions left to explore listed
    end = _wait(drv, "return window.rigLive.ended;")
    assert end["status"] == "completed"
    assert drv.find_element("id", "state").text == "completed"
    assert drv.find_element("id", "next").is_displayed()
    draws = drv.execute_script("return window.rigLive.draws.length;")
    assert draws >= 2
    with open_store(site["db"], create=False) as store:
        sid = end["result"]["session_id"]
        assert store.samples.count(sid) == end["result"]["samples"] == int(
            drv.find_element("id", "samples").text)


def test_continue_where_rig_record_waits_for_enter_then_interrupt(site):
    from selenium.webdriver.common.by import By

    drv = _start(site, "sim-shoulder")
    _wait(drv, "const p = document.getElementById('prompt'); return p && !p.hidden;")
    assert drv.find_element(By.ID, "prompt-text").text == (
        "Continue: start the calibration: the patient is in the neutral pose")
    drv.find_element(By.ID, "continue").click()
    _wait(drv, "return [...document.querySelectorAll('#log li')].some("
               "li => li.textContent.startsWith('neutral pose: hold still'));")
    # the prompt goes with the next status event (the step's line may come first)
    _wait(drv, "return document.getElementById('prompt').hidden;")
    assert not drv.find_element(By.ID, "prompt").is_displayed()
    drv.find_element(By.ID, "interrupt").click()
    end = _wait(drv, "return window.rigLive.ended;")
    assert end["status"] == "interrupted" and end["result"]["samples"] > 0
    assert drv.find_element(By.ID, "end").text.startswith(
        f"session {end['result']['session_id']}: interrupted")


def test_a_refused_start_shows_the_one_line_in_the_page(site):
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import Select

    drv = site["driver"]
    drv.get(f"{site['base']}/record?patient={site['patient']}")
    Select(drv.find_element(By.NAME, "rig")).select_by_value("test-imu")
    Select(drv.find_element(By.NAME, "side")).select_by_value("left")
    drv.find_element(By.ID, "start").click()
    text = _wait(drv, "const e = document.getElementById('error');"
                      "return e && !e.hidden && e.textContent;")
    assert text.startswith("side 'left': the rig test-imu records the right shoulder")
    assert drv.current_url.endswith(f"/record?patient={site['patient']}")
