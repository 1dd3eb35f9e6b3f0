"""Shared simulated recordings for the calibration tests (seeded, module-scoped: made once)."""

from __future__ import annotations

import pytest

from tests.calibration.patients import make_limb, record_servo, star_patient


@pytest.fixture(scope="session")
def servo_patient():
    """A concave star patient recorded through the servo path (encoder-quantised truth)."""
    c = star_patient(7, max_tilt_deg=10)
    rec = record_servo(make_limb(c, 7), 300.0, 50.0)
    return c, rec
