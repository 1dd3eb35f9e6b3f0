"""End to end on the IMU path: a seeded patient with a known concave range and twist limits,
recorded by ``rig record``'s machinery through a simulated stream board on a real pty (noise,
drift, magnetic disturbances, straps 25° off, raw accelerometer/gyroscope/magnetometer samples
too), calibrated by the guided protocol the simulated patient performs, stored, read back
through host-side VQF fusion and the re-fitted calibration, boundary extracted — and compared
with the truth. Simulated time runs in lockstep with the recorder (faster than real
time, no wall-clock condition), the patient returning to neutral every 20 s. The held-out
figures over several patients and the servo path
are ``benchmarks/bench_record.py accuracy`` (other seeds; this one is seed 7).
"""

from __future__ import annotations

from benchmarks.record_accuracy import record_imu_patient
from rig.sim.patients import star_constraint
from rig.store import open_store


def test_imu_patient_recorded_through_the_whole_stack(tmp_path):
    truth = star_constraint(7)
    r = record_imu_patient(truth, 7, tmp_path, free_s=300.0)
    assert r.status == "completed" and r.dropped == 0
    # the board streamed raw samples too, and the read path fused them on the host (VQF)
    assert r.fusion == "vqf"
    # the guided calibration ran on the simulated patient and recovered the straps
    assert r.calibration_residual_deg is not None and r.calibration_residual_deg < 3.0
    # targets of the issue, met on every held-out patient: boundary within 2° mean distance
    # (0.4° here), nothing recorded left out by more than 2° (beyond a fraction of a percent)
    assert r.mean_deg < 2.0
    assert r.out2_pct < 1.0
    # twist range within the 3°: the patient returns to neutral every 20 s (heading
    # re-zeroed) and each limit is the median of the patient's dwells at it (0.9° here)
    assert r.twist_deg < 3.0
    # the seven clinical peaks within the 2° (0.9° here; swing peaks 0.4°)
    assert r.peaks_deg < 2.0
    (lo, hi), (tlo, thi) = r.twist
    assert lo < 0 < hi and tlo < 0 < thi
    # the stored session says what it is
    with open_store(tmp_path / "imu-7.db", create=False) as store:
        sess = store.sessions.list()[-1]
        meta = store.sessions.get(sess["id"])["meta"]
        assert meta["calibrated"] is True
        kinds = [c["kind"] for c in store.calibrations.list(sess["id"])]
        # the guided calibration, then the patient's returns to neutral every 20 s of the 300 s
        assert kinds.count("imu-alignment") == 1
        assert kinds.count("neutral-checkpoint") >= 12 and set(kinds) == {
            "imu-alignment", "neutral-checkpoint"}
        # the clinical peaks stored at the end of the session are those of its boundary
        rom = meta["rom"]
        for movement, (extracted, _truth) in r.peaks.items():
            if extracted is None:
                assert rom[movement] is None
            else:
                assert abs(rom[movement] - extracted) < 1e-6, movement
