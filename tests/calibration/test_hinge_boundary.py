"""A hinge's interval from a recording (HingeExtractor) and the clinical table of the other
joints, from recordings and from constraints."""

from __future__ import annotations

import numpy as np
import pytest

from calibration.boundary import HingeExtractor
from calibration.errors import CalibrationError
from calibration.joint_angles import constraint_rom, from_angles, recorded_rom
from calibration.joints import JOINTS, hinge_angles, off_axis_angles
from models import quaternion as Q
from models.constraint import JointConstraint


def _knee(n=6000, lo=-3.0, hi=128.0, noise=0.0, off=0.0, seed=0):
    rng = np.random.default_rng(seed)
    t = np.arange(n) / 100.0
    a = np.clip(62.0 + 70.0 * np.sin(2 * np.pi * t / 7.0), lo, hi)  # dwells at both limits
    q = from_angles(a + rng.normal(0, noise, n), rng.normal(0, off, n), rng.normal(0, off, n),
                    "knee")
    return q, t


@pytest.mark.parametrize("side", ["right", "left"])
def test_hinge_angle_is_the_clinical_flexion_on_either_side(side):
    for joint in ("elbow", "knee"):
        q = from_angles(np.linspace(-10, 140, 16), 0.0, 0.0, joint, side)
        np.testing.assert_allclose(hinge_angles(q, JOINTS[joint].hinge_axis),
                                   np.linspace(-10, 140, 16), atol=1e-9)
        np.testing.assert_allclose(off_axis_angles(q, JOINTS[joint].hinge_axis), 0.0,
                                   atol=1e-6)


def test_clean_recording_interval_is_the_recorded_extremes():
    q, t = _knee()
    ex = HingeExtractor(JOINTS["knee"].hinge_axis).fit(q, t=t)
    lo, hi = ex.interval_deg_
    assert lo == pytest.approx(-3.0, abs=1e-6) and hi == pytest.approx(128.0, abs=1e-6)
    assert ex.inside_ == 1.0 and ex.n_spikes_ == 0
    c = ex.constraint_
    assert c.kind == "hinge" and c.hinge.min_deg <= lo and c.hinge.max_deg >= hi


def test_noise_moves_the_ends_in_by_the_measured_error_only():
    q, t = _knee(noise=0.5, off=2.0)
    ex = HingeExtractor(JOINTS["knee"].hinge_axis).fit(q, t=t)
    lo, hi = ex.interval_deg_
    assert abs(lo - -3.0) < 1.0 and abs(hi - 128.0) < 1.0  # the truth, within the noise
    assert ex.inside_1deg_ >= 0.99
    assert 2.0 < ex.off_axis_rms_deg_ < 4.0  # the out-of-axis motion is reported
    raw = HingeExtractor(JOINTS["knee"].hinge_axis, noise_correction=False).fit(q, t=t)
    assert raw.inside_ == 1.0 and raw.interval_deg_[1] > hi


def test_an_isolated_spike_is_not_the_range():
    q, t = _knee()
    q = q.copy()
    q[3000] = Q.from_axis_angle(np.array([0.0, 0.0, -1.0]), np.radians(170.0))
    ex = HingeExtractor(JOINTS["knee"].hinge_axis).fit(q, t=t)
    assert ex.n_spikes_ == 1 and ex.interval_deg_[1] < 128.5


def test_a_full_turn_is_not_a_hinge():
    t = np.arange(2000) / 100.0
    q = Q.from_axis_angle(np.array([0.0, 0.0, 1.0]), np.radians(np.linspace(-179, 179, 2000)))
    with pytest.raises(CalibrationError, match="all the way round"):
        HingeExtractor().fit(q, t=t)


def test_rom_of_a_hinge_constraint_and_of_its_recording_agree():
    q, t = _knee()
    rec = recorded_rom(q, "knee")
    c = HingeExtractor(JOINTS["knee"].hinge_axis).fit(q, t=t).constraint_
    con = constraint_rom(c, "knee")
    assert rec.peaks["flexion"] == pytest.approx(128.0, abs=0.01)
    assert rec.peaks["extension"] == pytest.approx(3.0, abs=0.01)
    assert con.peaks["flexion"] == pytest.approx(128.0, abs=0.01)
    assert con.peaks["extension"] == pytest.approx(3.0, abs=0.01)
    assert "knee range of motion" in con.table() and "135°" in con.table()


@pytest.mark.parametrize("side", ["right", "left"])
def test_rom_of_a_two_axis_wrist_reads_its_corners(side):
    """A wrist whose swing region is the rectangle flexion 70 / extension 60 / ulnar 30 /
    radial 20 (in Cardan angles), narrow twist: the table reads those four values."""
    a = np.concatenate([np.linspace(-60, 70, 40, endpoint=False), np.full(20, 70.0),
                        np.linspace(70, -60, 40, endpoint=False), np.full(20, -60.0)])
    b = np.concatenate([np.full(40, -20.0), np.linspace(-20, 30, 20, endpoint=False),
                        np.full(40, 30.0), np.linspace(30, -20, 20, endpoint=False)])
    d = Q.rotate(from_angles(a, b, 0.0, "wrist", side), np.array([1.0, 0.0, 0.0]))
    c = JointConstraint.from_dict({
        "name": "wrist", "kind": "two-axis",
        "swing": {"polygon": {"vertices": d.tolist(), "interior": [1.0, 0.0, 0.0]}},
        "twist": {"min_deg": -5.0, "max_deg": 5.0}})
    rom = constraint_rom(c, "wrist", side)
    for m, v in (("flexion", 70.0), ("extension", 60.0), ("ulnar_deviation", 30.0),
                 ("radial_deviation", 20.0)):
        assert rom.peaks[m] == pytest.approx(v, abs=1.5), m


@pytest.mark.parametrize("side", ["right", "left"])
def test_hip_flexion_reads_whatever_the_abduction(side):
    """A knee raised to 90° of hip flexion with 25° of abduction (as in the x-io recording's
    high-knee raise) is 90° of flexion; abduction is read only near zero flexion and the
    rotations only near the neutral swing."""
    t = np.linspace(0.0, 1.0, 200)
    up = 90.0 * np.sin(np.pi * t)
    z = np.zeros(200)
    # a knee raise (abducted while flexed), then abduction, then external rotation at neutral
    a = np.concatenate([up, z, z])
    b = np.concatenate([np.where(up > 45.0, -25.0, 0.0), -8.0 * np.sin(np.pi * t), z])
    g = np.concatenate([z, z, 30.0 * np.sin(np.pi * t)])
    rom = recorded_rom(from_angles(a, b, -g, "hip", side), "hip", side)
    assert rom.peaks["flexion"] == pytest.approx(90.0, abs=0.1)
    assert rom.peaks["abduction"] == pytest.approx(8.0, abs=0.1)
    assert rom.peaks["external_rotation"] == pytest.approx(30.0, abs=0.1)


def test_rom_of_a_narrow_twist_ankle_reaches_what_its_constraint_allows():
    """The simulated ankle (twist held to a few degrees): the orientations the peaks are read
    from are all allowed, and no allowed orientation near them (2° of random rotation, kept
    where the oracle allows it) reads farther; each peak is within 1° of the farthest of those
    (a Cardan grid at 10° of rotation read the inversion 4.5° short)."""
    from calibration.joint_angles import _in_band, joint_angles
    from calibration.kinds.ball import allowed_boundary_samples
    from models.oracle import ConstraintOracle
    from rig.sim.patients import anatomical_limb

    joint = anatomical_limb(1, "leg", "right").joints[2]
    c = joint.coupling.at(float(joint.coupling.at_deg[0]))
    oracle = ConstraintOracle(c)
    q = allowed_boundary_samples(c)
    assert oracle.is_valid(q).all()
    rng = np.random.default_rng(7)
    near = Q.multiply(Q.from_axis_angle(Q.random_unit_vectors(len(q), rng),
                                        np.radians(rng.uniform(0.0, 2.0, len(q)))), q)
    near = near[oracle.is_valid(near)]
    ang = joint_angles(near, "ankle")
    where = _in_band(ang, 5.0)
    rom = constraint_rom(c, "ankle")
    for key, (pos, neg) in (("alpha", ("dorsiflexion", "plantarflexion")),
                            ("beta", ("inversion", "eversion"))):
        v = ang[key][where[key]]
        assert v.max() <= rom.peaks[pos] + 0.05 and -v.min() <= rom.peaks[neg] + 0.05, key
        assert v.max() >= rom.peaks[pos] - 1.0 and -v.min() >= rom.peaks[neg] - 1.0, key
