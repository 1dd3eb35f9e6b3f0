"""The recorder's seam to the devices (:func:`rig.record.rigio.open_rig`): simulated patients
reached only through :class:`rig.devices.ports.SimulatedPatient`."""

from __future__ import annotations

import numpy as np
import pytest

from rig.record.rigio import load_config, open_rig


def _imu_rig(tmp_path, extra: str):
    port = f"sim://imu-stream?sensors=2&rate=100&patient=original&seed=2&clock=manual{extra}"
    cfg = tmp_path / "rig.yaml"
    cfg.write_text("name: rigio-test\njoint: {name: shoulder, side: right, parent: thorax, "
                   f"child: humerus}}\nsensors:\n  port: \"{port}\"\n  protocol: stream\n"
                   "  rate_hz: 100\n  segments: {thorax: 0, humerus: 1}\n")
    return load_config(str(cfg))


@pytest.mark.parametrize(("extra", "performs"), [("", True), ("&calibrate=on", True),
                                                 ("&calibrate=off", False)])
def test_simulated_patient_performs_the_protocol_unless_the_port_string_says(
        tmp_path, extra, performs):
    with open_rig(_imu_rig(tmp_path, extra), calibrate=True) as rig:
        (limb,) = rig.patients
        assert (limb.calibration_protocol is not None) is performs
        assert rig.simulated_patients[0].protocol_pinned is bool(extra)
        if performs:  # a manual clock standing at patient time 0: the protocol starts at 2 s
            assert rig.protocol_start_s == 2.0 and rig.protocol is limb.calibration_protocol
        assert rig.device_t0 == 0.0
    with open_rig(_imu_rig(tmp_path, extra), calibrate=False) as rig:
        assert (rig.patients[0].calibration_protocol is not None) is (extra == "&calibrate=on")


def test_servo_patient_starts_the_protocol_two_seconds_after_opening_and_is_followed():
    from rig.devices import load_rig_config

    cfg = load_rig_config("sim-shoulder")
    assert cfg.servos is not None
    with open_rig(cfg, calibrate=True) as rig:
        (sp,) = rig.simulated_patients
        assert sp.back_drives and rig.kind == "servo"
        assert 2.0 <= rig.protocol_start_s <= 2.0 + sp.now()
        truth = sp.limb.joint(np.arange(0.0, 4.0, 0.05))
        chain_q, missed = sp.follow(truth)
        assert chain_q.shape == truth.shape and missed == 0
