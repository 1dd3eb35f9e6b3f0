"""Golden cases: simulated patients (one joint: star patients and SimulatedLimb; a limb:
anatomical limbs and SimulatedChain), their recordings, and the IMU calibrations and heading
corrections fitted on them (joint and limb); host-side sensor fusion."""

from __future__ import annotations

import functools

import numpy as np

from calibration import ImuJointCalibration, LimbImuCalibration, status_ok
from calibration.fusion import fuse_vqf
from calibration.heading import HeadingCorrection, LimbHeadingCorrection
from calibration.joints import LIMB_CHAINS
from rig.sim.limb import NoiseModel
from rig.sim.patients import (
    chain_patient,
    patient_limb,
    record_chain_imu,
    record_imu,
    record_servo,
    star_patient,
)
from tests.golden.harness import case
from tests.golden.util import jtext

#: fixed instants of the truth cases (seconds): the protocol, free motion and checkpoints
TIMES = np.linspace(0.0, 60.0, 241)


@functools.cache
def _joint_recording():
    """A star patient (seed 2) with noise, drift and neutral checkpoints every 12 s, recorded at
    50 Hz: 50 s of free motion after the protocol."""
    limb = patient_limb(star_patient(2), 2, neutral_every_s=12.0)
    rec = record_imu(limb, 50.0, rate_hz=50.0)
    return limb, rec


@functools.cache
def _chain_recording(limb: str):
    """An anatomical arm (seed 3) or leg (seed 4) with four IMUs and neutral checkpoints every
    12 s, recorded at 25 Hz: 60 s of free motion after the limb protocol."""
    chain = chain_patient(3 if limb == "arm" else 4, limb, neutral=12.0)
    rec = record_chain_imu(chain, 60.0, rate_hz=25.0)
    return chain, rec


@case("joint")
def case_sim_star_patient() -> dict:
    """Star patients (constraint files) and a SimulatedLimb's truth at fixed times; its sensors
    measured one instant at a time; the IMU and servo recordings."""
    out: dict = {f"star_{s}": star_patient(s).to_yaml() for s in (1, 2, 7)}
    limb = patient_limb(star_patient(4), 4, noise=NoiseModel(), neutral_every_s=10.0)
    tr = limb.truth(TIMES)
    out.update(joint=tr.joint, thorax=tr.thorax, sensors=tr.sensors,
               target=limb.target(TIMES), raw_joint=limb.raw_joint(TIMES),
               project=limb.project(tr.joint), neutral_windows=limb.neutral_windows(60.0))
    ms = [limb.measure(t) for t in (0.5, 1.0, 7.25, 12.0, 30.0)]
    for k in ("quaternions", "gyro", "calibration", "accel", "mag"):
        out[f"measure_{k}"] = np.stack([getattr(m, k) for m in ms])
    _, rec = _joint_recording()
    out.update(rec_t=rec.t, rec_thorax=rec.thorax, rec_limb=rec.limb, rec_status=rec.status,
               rec_truth=rec.truth)
    servo = record_servo(patient_limb(star_patient(4), 4, noise=NoiseModel.ideal()), 5.0, 50.0)
    out.update(servo_limb=servo.limb, servo_truth=servo.truth)
    return out


@case("joint")
def case_calibration_joint() -> dict:
    """ImuJointCalibration fitted on the recorded star patient; its joint orientations; the
    heading correction (HeadingCorrection) fitted at the neutral checkpoints and applied."""
    limb, rec = _joint_recording()
    s, f = rec.window("static"), rec.window("functional")
    cal = ImuJointCalibration().fit(rec.thorax[s], rec.limb[s], rec.thorax[f], rec.limb[f],
                                    static_ok=status_ok(rec.status[s]),
                                    functional_ok=status_ok(rec.status[f]))
    q = cal.transform(rec.thorax, rec.limb)
    again = ImuJointCalibration.from_dict(cal.to_dict()).transform(rec.thorax, rec.limb)
    windows = limb.neutral_windows(float(rec.t[-1]))
    out = {"calibration": jtext(cal.to_dict()), "residual_deg": float(cal.residual_deg_),
           "residuals": jtext(cal.residuals_), "joint": q, "joint_from_dict": again,
           "windows": np.asarray(windows, dtype=np.float64)}
    for drift in ("gp", "linear"):
        hc = HeadingCorrection(drift=drift).fit(rec.t, q, windows, status=rec.status,
                                                anchors=[float(rec.start_s)])
        out[f"{drift}_corrected"] = hc.apply(rec.t, q)
        out[f"{drift}_psi_deg"] = hc.psi_deg(rec.t[::10])
        out[f"{drift}_fitted"] = jtext(hc.to_dict())
        out[f"{drift}_uncertainty_deg"] = jtext(hc.uncertainty_deg(0.0, float(rec.t[-1])))
    return out


@case("limb")
def case_sim_chain_patient() -> dict:
    """Anatomical arm and leg patients (SimulatedChain): truth at fixed times, protocol and
    checkpoint windows, one-instant measurements; the arm's recording (raw readings too)."""
    out: dict = {}
    for name in ("arm", "leg"):
        chain = chain_patient(3 if name == "arm" else 4, name, neutral=15.0)
        tr = chain.truth(TIMES)
        out.update({f"{name}_joints": tr.joints, f"{name}_root": tr.root,
                    f"{name}_sensors": tr.sensors, f"{name}_target": chain.target(TIMES),
                    f"{name}_raw_joints": chain.raw_joints(TIMES),
                    f"{name}_project": chain.project(tr.joints),
                    f"{name}_neutral_windows": np.asarray(chain.neutral_windows(60.0)),
                    f"{name}_protocol_windows": jtext(chain.protocol_windows()),
                    f"{name}_truth_limb": chain.limb.to_yaml()})
        ms = [chain.measure(t) for t in (0.5, 3.0, 9.75, 20.0)]
        for k in ("quaternions", "gyro", "calibration", "accel", "mag"):
            out[f"{name}_measure_{k}"] = np.stack([getattr(m, k) for m in ms])
    _, rec = _chain_recording("arm")
    for k in ("t", "quaternions", "gyro", "accel", "mag", "status", "joints", "root",
              "sensors_true"):
        out[f"rec_{k}"] = getattr(rec, k)
    out["rec_windows"] = jtext({"windows": rec.windows, "segments": rec.segments,
                                "start_s": rec.start_s, "end_s": rec.end_s})
    return out


def _limb_calibration(limb: str) -> dict:
    chain, rec = _chain_recording(limb)
    st = rec.window("static")
    names = [j for j in rec.windows if j != "static"]
    windows = np.asarray(chain.neutral_windows(float(rec.t[-1])), dtype=np.float64)
    windows = windows.reshape(-1, 2)
    up = [rec.quaternions[(rec.t >= a) & (rec.t <= b)] for a, b in windows]
    cal = LimbImuCalibration(limb, "right").fit(
        rec.quaternions[st], {j: rec.quaternions[rec.window(j)] for j in names},
        upright=up or None)
    out = {"calibration": jtext(cal.to_dict()), "residual_deg": float(cal.residual_deg_),
           "residuals": jtext(cal.residuals_), "mounts": cal.mounts_,
           "headings_deg": cal.headings_deg_, "neutral_chain": cal.neutral_chain(),
           "segment_orientations": cal.segment_orientations(rec.quaternions),
           "joints": cal.transform(rec.quaternions),
           "joints_from_dict": LimbImuCalibration.from_dict(cal.to_dict()).transform(
               rec.quaternions)}
    for k, v in cal.joints(rec.quaternions[::25]).items():
        out[f"joint_{k}"] = v
    a, b = rec.windows["static"]
    hc = LimbHeadingCorrection(cal).fit(rec.t, rec.quaternions, windows,
                                        anchors=[0.5 * (a + b)])
    out["heading_corrected"] = hc.apply(rec.t, rec.quaternions)
    out["heading_psi_deg"] = np.asarray(hc.psi_deg(rec.t[::10]))
    out["heading_fitted"] = jtext(hc.to_dict())
    t0, t1 = float(rec.t.min()), float(rec.t.max())
    out["heading_slow"] = jtext({n: hc.sensors_[c].uncertainty_deg(t0, t1)
                                 if c in hc.sensors_ else None
                                 for n, _, c in LIMB_CHAINS[limb]})
    return out


@case("limb")
def case_calibration_limb_arm() -> dict:
    """LimbImuCalibration of the recorded arm (mounts, headings, joints) and its
    LimbHeadingCorrection at the neutral checkpoints."""
    return _limb_calibration("arm")


@case("limb")
def case_calibration_limb_leg() -> dict:
    """LimbImuCalibration and LimbHeadingCorrection of the recorded leg."""
    return _limb_calibration("leg")


@case("limb")
def case_fusion_vqf() -> dict:
    """Host-side fusion (VQF) of the recorded arm's raw readings, sensor by sensor."""
    _, rec = _chain_recording("arm")
    out = {}
    for k in range(rec.quaternions.shape[1]):
        r = fuse_vqf(rec.t, np.concatenate((rec.accel[:, k], rec.gyro[:, k], rec.mag[:, k]),
                                           axis=1))
        out[f"sensor{k}"] = r.q
    return out
