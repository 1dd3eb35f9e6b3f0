"""A headless Chromium driven by Selenium through Debian's chromium-driver (the same version
as the browser; ``.ci/run`` installs both). The driver's path is given, so Selenium Manager
downloads nothing. Tests skip, saying why, when either is missing."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest

DRIVERS = ("/usr/bin/chromedriver", "/usr/lib/chromium/chromedriver")


def chrome(tmp: Path, width: int = 1200, height: int = 900):
    """A headless Chromium (``selenium.webdriver.Chrome``); the caller quits it."""
    webdriver = pytest.importorskip("selenium.webdriver")
    from selenium.webdriver.chrome.service import Service

    browser = next((p for p in (shutil.which("chromium"), shutil.which("chromium-browser"))
                    if p), None)
    driver = next((p for p in (shutil.which("chromedriver"), *DRIVERS)
                   if p and os.path.exists(p)), None)
    if browser is None or driver is None:
        pytest.skip("no chromium and chromium-driver (.ci/run installs Debian's)")
    opts = webdriver.ChromeOptions()
    opts.binary_location = browser
    for arg in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                "--no-first-run", "--disable-background-networking", "--disable-sync",
                "--disable-component-update", f"--window-size={width},{height}",
                f"--user-data-dir={tmp / 'chrome-profile'}"):
        opts.add_argument(arg)
    service = Service(executable_path=driver, env={**os.environ, "HOME": str(tmp)})
    return webdriver.Chrome(options=opts, service=service)


def click_and_wait(browser, element, timeout: float = 60.0) -> None:
    """Click ``element`` and wait until the page it was on is gone (the next one loads)."""
    from selenium.webdriver.support import expected_conditions as ec
    from selenium.webdriver.support.ui import WebDriverWait

    page = browser.find_element("tag name", "html")
    element.click()
    WebDriverWait(browser, timeout).until(ec.staleness_of(page))
