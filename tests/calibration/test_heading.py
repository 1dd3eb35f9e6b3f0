"""Heading re-zeroing at neutral checkpoints (calibration.heading) on synthetic recordings."""

from __future__ import annotations

import math

import numpy as np
import pytest

from calibration import CalibrationError, HeadingCorrection
from models import quaternion as Q

X = np.array([1.0, 0.0, 0.0])
RATE = 50.0
EVERY, HOLD = 20.0, 2.0


def _free_motion(t: np.ndarray) -> np.ndarray:
    """A known joint trajectory: swing up to ~70° in wandering directions, twist ±40°."""
    az = 0.31 * t + 0.8 * np.sin(0.07 * t)
    el = np.radians(35.0 + 35.0 * np.sin(0.23 * t))
    d = np.stack((np.cos(el), np.sin(el) * np.cos(az), np.sin(el) * np.sin(az)), axis=1)
    swing = Q.from_two_vectors(X, d)
    twist = Q.from_axis_angle(X, np.radians(40.0 * np.sin(0.17 * t + 1.0)))
    return Q.multiply(swing, twist)


def _windows(t_end: float) -> np.ndarray:
    t0 = np.arange(EVERY, t_end - HOLD, EVERY)
    return np.stack((t0, t0 + HOLD), axis=1)


def _truth(t: np.ndarray, windows: np.ndarray, neutral_sd_deg: float,
           rng: np.random.Generator) -> np.ndarray:
    """Free motion, except the identity (perturbed by the patient's repeatability) inside the
    checkpoint windows."""
    q = _free_motion(t)
    for t0, t1 in windows:
        rv = np.radians(rng.normal(0.0, [neutral_sd_deg, neutral_sd_deg / 2,
                                         neutral_sd_deg / 2]))
        ang = float(np.linalg.norm(rv))
        pose = (Q.from_axis_angle(rv / ang, ang) if ang > 0 else np.array([1.0, 0, 0, 0]))
        q[(t >= t0) & (t <= t1)] = pose
    return q


def _ou(t: np.ndarray, sd_deg: float, tau_s: float, rng: np.random.Generator) -> np.ndarray:
    """Relative heading drift (degrees) starting from 0: an Ornstein-Uhlenbeck process."""
    dt = np.diff(t, prepend=t[0])
    a = np.exp(-dt / tau_s)
    x = np.zeros(len(t))
    e = rng.normal(0.0, 1.0, len(t))
    for i in range(1, len(t)):
        x[i] = a[i] * x[i - 1] + sd_deg * math.sqrt(1.0 - a[i] ** 2) * e[i]
    return x


def _drifted(q: np.ndarray, psi_deg: np.ndarray) -> np.ndarray:
    return Q.multiply(Q.from_axis_angle(X, np.radians(psi_deg)), q)


def _twist_err_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.degrees(np.abs(Q.wrap_angle(Q.twist_angle(a, X) - Q.twist_angle(b, X))))


def _angle_err_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.degrees(Q.angle(Q.multiply(a, Q.conjugate(b))))


def test_exact_identity_without_drift():
    t = np.arange(0.0, 120.0, 1.0 / RATE)
    w = _windows(t[-1])
    q = _truth(t, w, 0.0, np.random.default_rng(0))
    hc = HeadingCorrection().fit(t, q, w, anchors=[1.0])
    assert hc.accepted_count_ == len(w) == 5 and hc.rejected_ == []
    assert np.all(hc.psi_deg_ == 0.0)
    np.testing.assert_array_equal(hc.apply(t, q), q)


def test_piecewise_linear_drift_is_recovered_exactly():
    # the model is exact when the drift is linear between checkpoints and the patient
    # returns exactly to neutral: every sample, not only the twist
    t = np.arange(0.0, 100.0, 1.0 / RATE)
    w = _windows(t[-1])
    centres = w.mean(axis=1)
    psi = np.interp(t, np.r_[0.0, centres], np.r_[0.0, 3.0, -4.0, 6.0, 1.0])
    truth = _truth(t, w, 0.0, np.random.default_rng(0))
    # inside a window the drift is not constant: hold it at the centre value there
    for (t0, t1), c in zip(w, centres, strict=True):
        psi[(t >= t0) & (t <= t1)] = np.interp(c, t, psi)
    rec = _drifted(truth, psi)
    hc = HeadingCorrection(drift="linear").fit(t, rec, w, anchors=[0.0])
    out = hc.apply(t, rec)
    free = np.ones(len(t), bool)
    for t0, t1 in w:
        free &= ~((t >= t0 - 1.0) & (t <= t1 + 1.0))
    assert _angle_err_deg(out[free], truth[free]).max() < 1e-6
    np.testing.assert_allclose(hc.psi_deg_, [0.0, 3.0, -4.0, 6.0, 1.0], atol=1e-9)


@pytest.mark.parametrize(("drift", "neutral_sd_deg", "bound_deg", "ratio"), [
    ("linear", 2.0, 1.8, 0.8), ("linear", 0.5, 1.2, 0.5),
    # the process estimate weighs the checkpoints by their scatter: with a 2.8° drift it is as
    # good as the line; with very repeatable checkpoints (0.5°) it smooths a little too much
    # (1.15° against the line's 0.90° here) — the price of not trusting them blindly
    ("gp", 2.0, 1.8, 0.8), ("gp", 0.5, 1.2, 0.6)])
def test_drift_with_repeatability_noise_corrected_twist_is_small(drift, neutral_sd_deg,
                                                                 bound_deg, ratio):
    # two sensors, 2° OU heading drift each, 30 s correlation: relative drift from 0 at the
    # calibration (t = 0); checkpoints every 20 s; four seeded 300 s recordings pooled
    before, after, whole_before, whole_after = [], [], [], []
    for seed in range(4):
        rng = np.random.default_rng(seed)
        t = np.arange(0.0, 300.0, 1.0 / RATE)
        w = _windows(t[-1])
        truth = _truth(t, w, neutral_sd_deg, rng)
        psi = _ou(t, 2.0 * math.sqrt(2.0), 30.0, rng)
        rec = _drifted(truth, psi)
        hc = HeadingCorrection(drift=drift).fit(t, rec, w, anchors=[0.0])
        assert hc.accepted_count_ == len(w) == 14
        out = hc.apply(t, rec)
        before.append(_twist_err_deg(rec, truth))
        after.append(_twist_err_deg(out, truth))
        whole_before.append(_angle_err_deg(rec, truth))
        whole_after.append(_angle_err_deg(out, truth))
        # a left rotation about +X adds exactly to the twist: the twist error is ψ's error
        np.testing.assert_allclose(after[-1], np.abs(hc.psi_deg(t) - psi), atol=1e-6)
    b, a = np.median(np.concatenate(before)), np.median(np.concatenate(after))
    assert b > 1.5
    assert a < bound_deg and a < ratio * b
    # the whole orientation too, not only the twist
    assert np.median(np.concatenate(whole_after)) < ratio * np.median(np.concatenate(whole_before))


@pytest.mark.parametrize(("drift_sd_deg", "tau_s"), [(1.0, 60.0), (0.7, 120.0)])
def test_small_drift_noisy_checkpoints_the_process_estimate_does_not_add_error(drift_sd_deg,
                                                                               tau_s):
    # a host-side 9-D fusion leaves ~1° of relative heading drift; the checkpoints carry 2° of
    # repeatability: joining them with straight lines adds error, the process estimate must not
    line, gp, none = [], [], []
    for seed in range(4):
        rng = np.random.default_rng(seed)
        t = np.arange(0.0, 300.0, 1.0 / RATE)
        w = _windows(t[-1])
        truth = _truth(t, w, 2.0, rng)
        rec = _drifted(truth, _ou(t, drift_sd_deg, tau_s, rng))
        for drift, out in (("linear", line), ("gp", gp)):
            hc = HeadingCorrection(drift=drift).fit(t, rec, w, anchors=[0.0])
            out.append(_twist_err_deg(hc.apply(t, rec), truth))
        none.append(_twist_err_deg(rec, truth))
        assert hc.drift_model_["method"] == "gp"
        assert set(hc.drift_model_) == {"method", "sigma_deg", "time_constant_s", "noise_deg"}
    line, gp, none = (float(np.median(np.concatenate(x))) for x in (line, gp, none))
    assert line > 1.4 * none  # the line makes it worse than no correction at all
    assert gp < 0.75 * line and gp < 1.25 * none  # within a quarter of doing nothing


def test_window_not_at_neutral_is_rejected():
    rng = np.random.default_rng(3)
    t = np.arange(0.0, 120.0, 1.0 / RATE)
    w = _windows(t[-1])
    truth = _truth(t, w, 1.0, rng)
    # the patient did not return for the third checkpoint: the arm stayed raised 40°
    raised = Q.from_axis_angle(np.array([0.0, 0.0, 1.0]), math.radians(40.0))
    third = (t >= w[2, 0]) & (t <= w[2, 1])
    truth[third] = Q.multiply(raised, Q.from_axis_angle(X, math.radians(25.0)))
    # at the fourth they held the neutral pose but with the forearm turned 30° (axial rotation)
    fourth = (t >= w[3, 0]) & (t <= w[3, 1])
    truth[fourth] = Q.from_axis_angle(X, math.radians(30.0))
    rec = _drifted(truth, np.full(len(t), 2.0))
    hc = HeadingCorrection().fit(t, rec, w)
    reasons = {tuple(win): r for win, r in hc.rejected_}
    assert set(reasons) == {tuple(w[2]), tuple(w[3])}
    assert "not at neutral" in reasons[tuple(w[2])]
    assert "from the others'" in reasons[tuple(w[3])]
    assert hc.accepted_count_ == len(w) - 2
    assert np.all(np.abs(np.asarray(hc.psi_window_deg_) - 2.0) < 4.0)
    d = hc.to_dict()
    assert d["neutral_checkpoints"] == len(w) and d["accepted"] == len(w) - 2
    assert len(d["rejected"]) == 2


def test_too_few_samples_and_status_masking():
    t = np.arange(0.0, 60.0, 1.0 / RATE)
    w = np.array([[20.0, 22.0], [40.0, 40.1], [50.0, 52.0]])
    q = _drifted(_truth(t, w, 0.0, np.random.default_rng(0)), np.full(len(t), 5.0))
    status = np.full(len(t), 0xFF)
    status[(t >= 50.0) & (t <= 52.0)] = 0x7F  # system level 1 there: a magnetic disturbance
    hc = HeadingCorrection().fit(t, q, w, status=status)
    assert hc.accepted_ == [(20.0, 22.0)]
    assert [r for _, r in hc.rejected_] == ["6 usable samples (< 10)", "0 usable samples (< 10)"]
    np.testing.assert_allclose(hc.psi_deg(np.array([0.0, 30.0, 59.0])), 5.0, atol=1e-9)


def test_wraps_through_180_degrees():
    # a drift through ±180° (a large heading offset): the correction stays continuous
    t = np.arange(0.0, 100.0, 1.0 / RATE)
    w = _windows(t[-1])
    truth = _truth(t, w, 0.0, np.random.default_rng(1))
    psi = 170.0 + 0.2 * t  # 170° .. 190° (= -170°)
    for t0, t1 in w:
        psi[(t >= t0) & (t <= t1)] = 170.0 + 0.2 * 0.5 * (t0 + t1)
    rec = _drifted(truth, psi)
    gp = HeadingCorrection().fit(t, rec, w)
    assert np.all(np.abs(np.diff(gp.psi_deg(t))) < 1.0)  # continuous through ±180° too
    hc = HeadingCorrection(drift="linear").fit(t, rec, w)
    assert np.all(np.abs(np.diff(hc.psi_deg_)) < 10.0)  # unwrapped, not a 360° jump
    err = _angle_err_deg(hc.apply(t, rec), truth)
    free = (t >= w[0, 1]) & (t <= w[-1, 0])
    for t0, t1 in w:
        free &= ~((t >= t0) & (t <= t1))  # the drift is held there, not linear
    assert err[free].max() < 1e-6


def test_identity_when_nothing_is_accepted_and_errors():
    t = np.arange(0.0, 10.0, 1.0 / RATE)
    q = _free_motion(t)
    hc = HeadingCorrection().fit(t, q, np.empty((0, 2)))
    assert hc.accepted_count_ == 0 and len(hc.times_) == 0
    np.testing.assert_array_equal(hc.apply(t, q), q)
    with pytest.raises(CalibrationError, match="call fit"):
        HeadingCorrection().apply(t, q)
    with pytest.raises(CalibrationError, match="t0 <= t1"):
        HeadingCorrection().fit(t, q, [[5.0, 4.0]])
    with pytest.raises(CalibrationError, match="times for"):
        HeadingCorrection().fit(t[:-1], q, [[1.0, 2.0]])


def test_a_long_session_is_corrected_through_a_grid_equal_to_the_process():
    # an hour at 50 Hz with a checkpoint every 20 s: the drift is evaluated on a grid and
    # interpolated (memory linear in the samples); it equals the process's own prediction
    rng = np.random.default_rng(21)
    t = np.arange(0.0, 3600.0, 1.0 / RATE)
    w = _windows(t[-1])
    rec = _drifted(_truth(t, w, 1.0, rng), _ou(t, 1.5, 60.0, rng))
    hc = HeadingCorrection().fit(t, rec, w, anchors=[0.0])
    assert hc.drift_model_["method"] == "gp" and len(hc.times_) > 150
    psi = hc.psi_deg(t)
    some = rng.choice(len(t), 3000, replace=False)
    exact = hc._gp.predict(t[some].reshape(-1, 1)) + hc._gp_mean
    np.testing.assert_allclose(psi[some], exact, atol=0.01)
    assert hc.uncertainty_deg(t[0], t[-1]) > 0.0
