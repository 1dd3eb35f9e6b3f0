"""Shared simulated recordings for the calibration tests (seeded, module-scoped: made once)."""

from __future__ import annotations

import pytest

from rig.sim.patients import record_servo, seeded_patient, star_constraint

#: the servo-path patient (rig.sim.patients.star_constraint); not a held-out seed of the
#: benchmarks (bench_boundary 100-104, bench_record accuracy 101-105)
SERVO_SEED = 7


@pytest.fixture(scope="session")
def servo_patient():
    """A concave star patient recorded through the servo path (encoder-quantised truth)."""
    c = star_constraint(SERVO_SEED)
    rec = record_servo(seeded_patient(SERVO_SEED, c), 300.0, 50.0)
    return c, rec
