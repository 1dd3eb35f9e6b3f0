"""Host-side VQF fusion against the devices' fused quaternions, on simulated patients.

For each star patient (``rig.sim.patients.star_constraint``; dev seeds 201-205 by default — the
held-out seeds 101-105 of ``bench_record.py accuracy`` were not used to choose anything) two
misplaced IMUs are simulated through the calibration protocol and ``--seconds`` of free
motion at 100 Hz (``SimulatedJoint.measure_many``: device quaternions with the device-fusion
error model, and raw accelerometer / gyroscope / magnetometer samples). Per method:

- ``relhead``: the relative heading error of the two sensors' worlds, the heading (about
  world Z) of ``E_t⁻¹ ⊗ E_l`` with ``E = q_estimated ⊗ q_true⁻¹``, minus its circular mean
  (a constant offset is absorbed by the calibration); median |.| over the samples after the
  first 10 s, degrees;
- ``joint`` / ``twist``: :class:`calibration.alignment.ImuJointCalibration` fitted on the
  protocol's windows from that method's orientations, then the median angle / |twist| of
  ``truth⁻¹ ⊗ estimate`` over the free motion (no neutral checkpoints), degrees.

Run: ``.venv/bin/python benchmarks/bench_fusion.py [--seeds 201 202 ...] [--seconds 300]``.
"""

from __future__ import annotations

import argparse
import math

import common  # noqa: F401  (first: one BLAS thread, this checkout on sys.path)
import numpy as np

from calibration.alignment import ImuJointCalibration
from calibration.fusion import fuse_vqf
from models import quaternion as Q
from rig.sim.patients import seeded_patient, star_constraint

_Z = np.array([0.0, 0.0, 1.0])
_X = np.array([1.0, 0.0, 0.0])


def _simulate(seed: int, seconds: float, rate: float = 100.0):
    limb = seeded_patient(seed, star_constraint(seed))
    t = np.arange(round((limb.protocol_end_s + seconds) * rate)) / rate
    q, raw, truth, joint = [], [], [], []
    for i in range(0, len(t), 2000):
        ms = limb.measure_many(t[i:i + 2000])
        q.append(np.stack([m.quaternions for m in ms]))
        raw.append(np.concatenate([np.stack([m.accel for m in ms]),
                                   np.stack([m.gyro for m in ms]),
                                   np.stack([m.mag for m in ms])], axis=-1))
        truth.append(np.stack([m.truth.sensors[0] for m in ms]))
        joint.append(np.stack([m.truth.joint[0] for m in ms]))
    return limb, t, *(np.concatenate(a) for a in (q, raw, truth, joint))


def _relative_heading_deg(qt, ql, tt, tl, keep) -> float:
    et = Q.multiply(qt, Q.conjugate(tt))
    el = Q.multiply(ql, Q.conjugate(tl))
    h = Q.twist_angle(Q.multiply(Q.conjugate(et), el), _Z)[keep]
    c = math.atan2(np.mean(np.sin(h)), np.mean(np.cos(h)))
    d = (h - c + math.pi) % (2.0 * math.pi) - math.pi
    return float(np.degrees(np.median(np.abs(d))))


def _joint_errors(limb, t, qt, ql, joint) -> tuple[float, float]:
    w = limb.calibration_protocol.windows()
    t0 = limb.protocol_start_s
    st = (t >= t0 + w["static"][0]) & (t <= t0 + w["static"][1])
    fu = (t >= t0 + w["functional"][0]) & (t <= t0 + w["functional"][1])
    cal = ImuJointCalibration().fit(qt[st], ql[st], qt[fu], ql[fu])
    free = t >= limb.protocol_end_s
    err = Q.multiply(Q.conjugate(joint[free]), cal.transform(qt[free], ql[free]))
    return (float(np.degrees(np.median(Q.angle(err)))),
            float(np.degrees(np.median(np.abs(Q.twist_angle(err, _X))))))


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[201, 202, 203, 204, 205])
    ap.add_argument("--seconds", type=float, default=300.0)
    args = ap.parse_args(argv)
    rows = []
    print(f"{'patient':10s} {'method':7s} {'relhead°':>9s} {'joint°':>7s} {'twist°':>7s} "
          f"{'magdist%':>9s}")
    for seed in args.seeds:
        limb, t, q, raw, truth, joint = _simulate(seed, args.seconds)
        fused = [fuse_vqf(t, raw[:, i]) for i in range(2)]
        keep = t >= 10.0
        for name, qt, ql, dist in (("device", q[:, 0], q[:, 1], ""),
                                   ("vqf", fused[0].q, fused[1].q,
                                    "/".join(f"{100 * f.disturbed_share:.1f}" for f in fused))):
            rh = _relative_heading_deg(qt, ql, truth[:, 0], truth[:, 1], keep)
            je, tw = _joint_errors(limb, t, qt, ql, joint)
            rows.append((name, rh, je, tw))
            print(f"star-{seed:<5d} {name:7s} {rh:9.2f} {je:7.2f} {tw:7.2f} {dist:>9s}")
    for name in ("device", "vqf"):
        a = np.array([r[1:] for r in rows if r[0] == name])
        print(f"{'median':10s} {name:7s} {np.median(a[:, 0]):9.2f} {np.median(a[:, 1]):7.2f} "
              f"{np.median(a[:, 2]):7.2f}")


if __name__ == "__main__":
    main()
