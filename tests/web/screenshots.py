"""The screenshots of the guided recording's pages in docs/ (``docs/web.md``), regenerated with

    .venv/bin/python -m tests.web.screenshots

from the checkout's root: the live router on the minimal app of :mod:`tests.web.server`, the
shipped simulated rigs (``sim-imu`` four times faster than the host's clock), headless Chromium.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

from selenium.webdriver.common.by import By
from selenium.webdriver.support.ui import Select, WebDriverWait

from rig.store import open_store
from tests.rig.rigs import sim_imu_yaml
from tests.web.browser import quit_chromium, start_chromium
from tests.web.server import live_app, serving

ELAPSED = "const s = window.rigLive && window.rigLive.status; return s && s.elapsed_s > %g;"


def until(d, js, t=120):
    """Wait for ``js`` to return something truthy (bounded)."""
    return WebDriverWait(d, t, poll_frequency=0.2).until(lambda d: d.execute_script(js))


def main() -> None:
    out = Path("docs")
    tmp = Path(tempfile.mkdtemp())
    cfg = sim_imu_yaml(tmp, port_suffix="&time_scale=4", name="sim-imu-fast")
    db = str(tmp / "rig.db")
    with open_store(db) as st:
        pid = st.patients.ensure("P-0042")
    rigs = {k: k for k in ["sim-imu", "sim-shoulder", "sim-arm", "sim-leg", "sim-servo-arm",
                           "hardware-template"]}
    rigs["sim-imu-fast"] = str(cfg)
    app = live_app(db, tmp / "files", rigs=rigs)
    with serving(app) as base:
        d = start_chromium(width=1000, height=1250)
        try:
            d.get(f"{base}/record?patient={pid}")
            d.save_screenshot(str(out / "web-record.png"))
            Select(d.find_element(By.NAME, "rig")).select_by_value("sim-imu-fast")
            d.find_element(By.NAME, "duration_s").send_keys("60")
            d.find_element(By.ID, "start").click()
            until(d, ELAPSED % 40)
            d.save_screenshot(str(out / "web-live.png"))
            until(d, "return window.rigLive.ended")
            sid = d.execute_script("return window.rigLive.ended.result.session_id")
            d.get(f"{base}/sessions/{sid}/work")
            d.find_elements(By.CSS_SELECTOR, "button.start-job")[0].click()
            until(d, "return window.rigLive && window.rigLive.ended")
            d.save_screenshot(str(out / "web-boundary.png"))
            d.get(f"{base}/sessions/{sid}/work")
            d.find_elements(By.CSS_SELECTOR, "button.start-job")[1].click()
            until(d, "return window.rigLive && window.rigLive.ended")
            d.get(f"{base}/sessions/{sid}/work")
            d.save_screenshot(str(out / "web-session-work.png"))
            d.get(f"{base}/record?patient={pid}")
            Select(d.find_element(By.NAME, "rig")).select_by_value("sim-servo-arm")
            d.find_element(By.NAME, "duration_s").send_keys("12")
            d.find_element(By.NAME, "calibrate").click()
            d.find_element(By.ID, "start").click()
            until(d, ELAPSED % 8)
            d.save_screenshot(str(out / "web-live-arm.png"))
            until(d, "return window.rigLive.ended")
        finally:
            quit_chromium(d)


if __name__ == "__main__":
    main()
