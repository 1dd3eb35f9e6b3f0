"""Headless Chromium for the report tests: a screenshot of a page, and pixel counts on it."""

from __future__ import annotations

import io
import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest


def chromium() -> str:
    """Path of a Chromium; skips the test when none is installed."""
    for name in ("chromium", "chromium-browser", "google-chrome"):
        path = shutil.which(name)
        if path:
            return path
    pytest.skip("no Chromium installed (.ci/run installs Debian's chromium)")


def screenshot(page: Path, tmp: Path, *, width: int = 1200, height: int = 2600) -> np.ndarray:
    """``page`` as headless Chromium draws it: (height, width, 3) float RGB in [0, 1]."""
    import matplotlib.image

    shot = tmp / "shot.png"
    cmd = [chromium(), "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
           "--no-first-run", "--disable-background-networking", "--disable-component-update",
           "--disable-sync", f"--user-data-dir={tmp / 'profile'}", "--hide-scrollbars",
           f"--window-size={width},{height}", f"--screenshot={shot}", page.as_uri()]
    subprocess.run(cmd, check=True, capture_output=True, env={**os.environ, "HOME": str(tmp)})
    img = matplotlib.image.imread(io.BytesIO(shot.read_bytes()), format="png")[..., :3]
    assert img.shape[:2] == (height, width)
    return img


def pixels_near(img: np.ndarray, rgb_hex: str, tol: float) -> int:
    """How many pixels lie within ``tol`` (per channel, 0-1) of the colour ``#rrggbb``."""
    rgb = np.array([int(rgb_hex[i:i + 2], 16) for i in (1, 3, 5)]) / 255
    return int((np.abs(img - rgb).max(axis=2) < tol).sum())


def dark_fraction(img: np.ndarray) -> float:
    """Share of dark pixels (text, tables, outlines)."""
    return float((img.sum(axis=2) < 0.6).mean())
