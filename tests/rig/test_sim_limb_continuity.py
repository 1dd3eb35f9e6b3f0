"""The simulated limb moves continuously: no teleport where the projection jumps."""

from __future__ import annotations

import numpy as np

from models import quaternion as Q
from rig.sim.limb import NoiseModel
from rig.sim.patients import patient_limb, star_patient


def _steps_deg(q):
    return np.degrees(Q.angle(Q.multiply(Q.conjugate(q[:-1]), q[1:])))


def test_speed_is_bounded_at_100_hz_and_the_limb_stays_in_range():
    limb = patient_limb(star_patient(204), 204, protocol=None)
    assert limb.max_speed_dps == 360.0
    t = np.arange(0.0, 120.0, 0.01)
    q = limb.joint(t)
    speed = _steps_deg(q) / 0.01
    # P(raw(t)) alone jumps up to thousands of deg/s on this patient
    closed = limb.oracle.project(limb.raw_joint(t), normalize=True)
    closed /= np.linalg.norm(closed, axis=1, keepdims=True)
    assert (_steps_deg(closed) / 0.01).max() > 5000.0
    assert speed.max() < 1.05 * limb.max_speed_dps
    assert limb.oracle.is_valid(q).all()
    # the closed form is kept wherever it does not jump: most samples equal it exactly
    same = np.all(q == closed, axis=1)
    assert same.mean() > 0.9


def test_values_do_not_depend_on_batching_or_order():
    c = star_patient(204)
    a, b = patient_limb(c, 204), patient_limb(c, 204)
    t = np.arange(0.0, 60.0, 0.013)
    whole = a.joint(t)
    rng = np.random.default_rng(1)
    order = rng.permutation(len(t))
    parts = np.empty_like(whole)
    for chunk in np.array_split(order, 37):  # scattered, late times first
        parts[chunk] = b.joint(t[chunk])
    assert np.array_equal(whole, parts)


def test_the_gyro_integrates_to_the_truth():
    limb = patient_limb(star_patient(204), 204, noise=NoiseModel.ideal())
    ts = np.arange(0.0, 40.0, 1e-3)
    ms = []
    for i in range(0, len(ts), 4000):
        ms.extend(limb.measure_many(ts[i:i + 4000]))
    gyro = np.stack([m.gyro[1] for m in ms])
    truth = np.stack([m.truth.sensors[0, 1] for m in ms])
    q = truth[0].copy()
    err = []
    for k in range(len(ts) - 1):
        w = gyro[k] * 1e-3
        ang = np.linalg.norm(w)
        dq = np.concatenate(([np.cos(ang / 2)], np.sin(ang / 2) * w / ang)) if ang else Q.IDENTITY
        q = Q.multiply(q, dq)
        if k % 1000 == 999:
            err.append(np.degrees(Q.angle(Q.multiply(Q.conjugate(truth[k + 1]), q))))
    assert max(err) < 1.0
