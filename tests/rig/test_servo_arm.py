"""The simulated 7-servo arm (issue 39): back-driven by a seeded arm patient whose shoulder is
coupled to its forearm elbow, recorded into a limb session, extracted into a limb file."""

from __future__ import annotations

import numpy as np
import pytest

from models import quaternion as Q
from rig.devices import DynamixelBus, load_rig_config
from rig.devices.ports import open_port
from rig.readback.sessions import joint_orientations_from_store
from rig.sim.patients import anatomical_limb
from rig.store import open_store

ARM = load_rig_config("sim-servo-arm")
TICK_DEG = 360.0 / 4096


def _deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.degrees(Q.angle(Q.multiply(a, Q.conjugate(b))))


def test_the_forearm_elbow_is_an_option_and_todays_arm_is_unchanged():
    hinge = anatomical_limb(3, "arm")
    forearm = anatomical_limb(3, "arm", kinds={"elbow": "forearm"})
    assert [j.kind for j in forearm.joints] == ["ball", "forearm", "two-axis"]
    assert forearm.joints[0].coupling.by == "elbow"
    # drawn last: the rest of the arm is the hinge arm's
    a, b = hinge.to_dict()["joints"], forearm.to_dict()["joints"]
    assert a[0] == b[0] and a[2] == b[2]
    f = forearm.joints[1].constraint.limits
    h = hinge.joints[1].constraint.hinge
    assert (f.flexion_min_deg, f.flexion_max_deg) == pytest.approx((h.min_deg, h.max_deg))
    assert 70 <= -f.rotation_min_deg <= 85 and 75 <= f.rotation_max_deg <= 90
    with pytest.raises(ValueError, match="the simulated shoulder is a ball"):
        anatomical_limb(3, "arm", kinds={"shoulder": "forearm"})


def test_back_driven_servo_arm_holds_the_patients_posture_within_tick_rounding():
    """In this process on a manual clock: the servos' Present Position, read through the SDK,
    is the patient's posture through the arm's IK (FK of the ticks read); the shoulder (three
    servos) and the elbow (flexion, pronation) to within the ticks' rounding, the wrist (two
    servos: no twist) to the nearest orientation its axes reach."""
    url = ARM.servos.port.replace("process=on", "process=off") + "&clock=manual&wire_time=off"
    kin = ARM.servos.limb_kinematics()
    with open_port(url, baud=ARM.servos.baud) as port, DynamixelBus(port, ARM.servos) as bus:
        sp = port.simulated_patient
        assert sp.back_drives and sp.limb.joints(0.0).shape == (1, 3, 4)
        times = np.arange(0.0, 3.0005, 0.001)
        mech, missed = sp.follow(sp.limb.joints(times))
        assert missed == 0 and mech.shape == (len(times), 3, 4)
        seen, err_truth, err_mech = [], [], []
        for _ in range(6):
            port.simulator.clock.advance(0.5)
            ticks = bus.read_ticks()
            seen.append(tuple(ticks))
            q = kin.forward(ticks)
            i = round(sp.now() * 1000)
            err_truth.append(_deg(q, sp.limb.joints(sp.now())[0]))
            err_mech.append(_deg(q, mech[i]))
    err_truth, err_mech = np.array(err_truth), np.array(err_mech)
    rounding = 2.0 * TICK_DEG  # up to half a tick on each of 2-3 axes, and float noise
    assert err_mech.max() < rounding, err_mech
    assert err_truth[:, :2].max() < rounding, err_truth
    assert err_truth[:, 2].max() < 12.0, err_truth  # the wrist's twist, out of its reach
    assert len(set(seen)) == len(seen)  # the patient moves


def test_recording_the_servo_arm_gives_a_limb_session(rig_cli, tmp_path):
    """``rig record --rig sim-servo-arm`` (the servos in their own process, real time, short):
    a limb session of three joints whose elbow the session says is a forearm joint, every
    joint's orientation at each read (FK of the ticks) — read back as a whole limb."""
    db = tmp_path / "rig.db"
    code, out = rig_cli(["record", "--rig", "sim-servo-arm", "--duration", "2", "--db", str(db),
                         "--patient", "p1", "--no-calibration", "--no-rom",
                         "--display", "plain"])[:2]
    assert code == 0, out
    with open_store(str(db)) as store:
        (sess,) = store.sessions.list()
        assert sess["meta"]["limb"] == "arm" and sess["meta"]["kinds"] == {"elbow": "forearm"}
        sensors = {r["name"]: r["segment"] for r in store.samples.sensors(sess["id"])}
        assert sensors == {"shoulder": "upper-arm", "elbow": "forearm", "wrist": "hand"}
        data = joint_orientations_from_store(store, sess["id"])
    assert data.joints == ("shoulder", "elbow", "wrist") and data.limb == "arm"
    assert data.joint_q.shape[1:] == (3, 4) and len(data.joint_q) >= 100
    assert data.provenance["kinds"] == {"elbow": "forearm"}
    # the elbow moves as a forearm joint: flexion about +Z, then a rotation about its +X
    limb = anatomical_limb(3, "arm", kinds={"elbow": "forearm"})
    elbow = limb.joints[1].joint_kind
    flexion = np.degrees(elbow.coupling_angle(limb.joints[1].constraint, data.joint_q[:, 1]))
    assert flexion.min() > -2.0 and flexion.max() < limb.provenance["clinical"]["elbow"][
        "flexion"] + 0.5


def test_the_servo_arms_postures_extract_into_a_coupled_limb_with_a_forearm_elbow():
    """300 s of patient 1's free motion at 25 Hz (offline: no pty for the motion) as the servo
    arm holds it (:meth:`SimulatedPatient.follow`, the back-drive's IK: what a recording of it
    reads), extracted as the session's kinds say: three joints, the elbow a forearm joint
    whose flexion and pronation-supination are the patient's, the shoulder coupled to the
    elbow's flexion."""
    from calibration.extraction import LimbExtractor
    from rig.sim.limb import NoiseModel
    from rig.sim.patients import seeded_patient

    truth = anatomical_limb(1, "arm", kinds={"elbow": "forearm"})
    patient = seeded_patient(1, truth, noise=NoiseModel.ideal(), calibrate=False)
    t = np.arange(0.0, 300.0, 0.04)
    url = (ARM.servos.port.replace("process=on", "process=off").replace("seed=3", "seed=1")
           + "&clock=manual&wire_time=off")
    with open_port(url, baud=ARM.servos.baud) as port:
        q, missed = port.simulated_patient.follow(patient.joints(t))
    assert missed < len(t) // 100
    ex = LimbExtractor("arm", kinds={"elbow": "forearm"}).fit(q, t=t, side="right")
    limb = ex.limb_
    assert [j.kind for j in limb.joints] == ["ball", "forearm", "two-axis"]
    assert ex.coupled_, ex.coupling_note_
    assert limb.joints[0].coupling is not None and limb.joints[0].coupling.by == "elbow"
    got, want = limb.joints[1].constraint.limits, truth.joints[1].constraint.limits
    for attr in ("flexion_min_deg", "flexion_max_deg", "rotation_min_deg", "rotation_max_deg"):
        assert getattr(got, attr) == pytest.approx(getattr(want, attr), abs=2.0), attr
    assert ex.params()["kinds"] == {"elbow": "forearm"}


@pytest.mark.parametrize(("url", "match"), [
    ("sim://dynamixel?ids=1,2,3&limb=arm&chain=sim-shoulder",
     r"chain 'sim-shoulder' has 1 joint \(joint\), the patient 3"),
    ("sim://dynamixel?ids=1,2,3&patient=original&chain=sim-servo-arm",
     r"chain 'sim-servo-arm' has 3 joints \(shoulder, elbow, wrist\), the patient 1"),
    ("sim://dynamixel?ids=1,2,3&limb=arm&chain=sim-servo-arm",
     r"needs servo IDs \[1, 2, 3, 4, 5, 6, 7\], the simulated bus has no ID 4"),
    ("sim://dynamixel?ids=1-7&limb=leg&chain=sim-servo-arm", r"kinds: the leg has no joint"),
])
def test_a_patient_that_is_not_the_chains_is_a_one_line_error(url, match):
    from rig.errors import RigConfigError

    with pytest.raises(RigConfigError, match=match):
        open_port(url + "&clock=manual")


def test_limb_extractor_kinds_are_checked():
    from calibration.extraction import LimbExtractor

    with pytest.raises(ValueError, match="the arm has no joint 'knee'"):
        LimbExtractor("arm", kinds={"knee": "forearm"})
    with pytest.raises(ValueError, match="the elbow drives the couplings; a two-axis joint"):
        LimbExtractor("arm", kinds={"elbow": "two-axis"})
    with pytest.raises(ValueError, match="kinds applies to a whole limb"):
        LimbExtractor(("elbow",), kinds={"elbow": "forearm"})
