"""The MDC per measurement method (calibration.mdc): a lab's file (marker-based motion capture)
has its own published value in the hip's, knee's and ankle's sagittal plane; an IMU session
keeps the goniometer's value, marked as a reference."""

from __future__ import annotations

from calibration.mdc import MDC_TABLE, mdc_for


def test_a_lab_file_has_the_motion_capture_value_in_the_sagittal_plane_only():
    for joint, movement in (("hip", "flexion"), ("knee", "extension"), ("ankle", "dorsiflexion")):
        v, text = mdc_for(joint, movement, "file")
        assert v.instrument == "motion-capture" and not v.reference and v.high == 5.0
        assert "Wilken" in v.source and "Gait Posture 2012" in v.source and "reference" not in text
    # the transverse plane (largest errors, McGinley 2009): not carried there
    assert mdc_for("hip", "internal_rotation", "file")[0] is None
    # the wrist keeps its own motion-capture value (Reissner 2019)
    assert mdc_for("wrist", "flexion", "file")[0].high == 12.0


def test_an_imu_session_keeps_the_marked_goniometer_reference():
    v, text = mdc_for("knee", "flexion", "imu")
    assert v.instrument == "goniometer" and v.reference and "no published MDC for imu" in text
    assert not any(k[2] == "imu" for k in MDC_TABLE)  # none could be read and cited
    assert all(v.source for v in MDC_TABLE.values())
