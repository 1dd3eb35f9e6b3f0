"""Headless Chromium driven by Selenium for the web app's browser tests and benchmarks.

Debian's ``chromium`` with Debian's ``chromium-driver`` (the same version; ``.ci/run`` installs
both): the driver's path is given explicitly, so Selenium Manager never downloads anything.
:func:`driver_paths` skips the test, saying why, when either is missing.
"""

from __future__ import annotations

import os
import shutil
import tempfile

import pytest

DRIVERS = ("/usr/bin/chromedriver", "/usr/lib/chromium/chromedriver")


def driver_paths() -> tuple[str, str] | None:
    """``(chromium, chromedriver)``, or None when either is not installed."""
    browser = next((shutil.which(n) for n in ("chromium", "chromium-browser")
                    if shutil.which(n)), None)
    driver = shutil.which("chromedriver") or next(
        (p for p in DRIVERS if os.access(p, os.X_OK)), None)
    if browser is None or driver is None:
        return None
    return browser, driver


def require_driver() -> tuple[str, str]:
    """:func:`driver_paths`, or skip the test."""
    paths = driver_paths()
    if paths is None:
        pytest.skip("no chromium and chromium-driver (.ci/run installs Debian's packages)")
    try:
        import selenium  # noqa: F401
    except ImportError:
        pytest.skip("selenium is not installed (the dev extra)")
    return paths


def start_chromium(*, width: int = 1200, height: int = 1400):
    """A headless Chromium under Selenium (the caller quits it). Its profile is a temporary
    folder removed at quit (``driver.rig_profile``)."""
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    browser, driver = driver_paths() or require_driver()
    profile = tempfile.mkdtemp(prefix="rig-chromium-")
    opts = webdriver.ChromeOptions()
    opts.binary_location = browser
    for arg in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                "--no-first-run", "--disable-background-networking",
                "--disable-component-update", "--disable-sync", "--disable-extensions",
                "--disable-background-timer-throttling",
                "--disable-renderer-backgrounding",
                f"--user-data-dir={profile}", f"--window-size={width},{height}"):
        opts.add_argument(arg)
    service = Service(executable_path=driver, env={**os.environ, "HOME": profile})
    drv = webdriver.Chrome(service=service, options=opts)
    drv.rig_profile = profile
    return drv


def quit_chromium(drv) -> None:
    """Quit the browser and its driver and remove the profile."""
    try:
        drv.quit()
    finally:
        shutil.rmtree(getattr(drv, "rig_profile", ""), ignore_errors=True)
