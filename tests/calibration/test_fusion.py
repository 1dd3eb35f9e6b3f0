"""Host-side VQF fusion of raw IMU samples (calibration.fusion) and the store read path with
``fusion="auto"|"device"|"vqf"`` (rig.readback.joint_orientations_from_store).

The recordings come from the simulated limb's raw measurements (``Measurement.accel``,
``gyro``, ``mag``). The patient's range is a cone: its projection is continuous, so the arm
never jumps (a gyroscope cannot follow a jump). Seed 11: not a seed of any benchmark.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from calibration.errors import CalibrationError
from calibration.fusion import VQF_PARAMS, fuse_vqf
from models import quaternion as Q
from models.constraint import JointConstraint
from rig.errors import RigConfigError
from rig.sim.patients import seeded_patient

SEED = 11
RATE = 100.0
FREE_S = 60.0


def _record(limb, t):
    ms = limb.measure_many(t)
    q = np.stack([m.quaternions for m in ms])  # (N, 2, 4) device fusion
    raw = np.concatenate([np.stack([m.accel for m in ms]), np.stack([m.gyro for m in ms]),
                          np.stack([m.mag for m in ms])], axis=-1)  # (N, 2, 9)
    truth = np.stack([m.truth.sensors[0] for m in ms])  # (N, 2, 4)
    joint = np.stack([m.truth.joint[0] for m in ms])
    status = np.stack([m.calibration for m in ms])
    return q, raw, truth, joint, status


@pytest.fixture(scope="module")
def session():
    """A cone patient wearing two misplaced IMUs: calibration protocol then 60 s free motion."""
    constraint = JointConstraint.cone((1.0, 0.0, 0.0), 60.0, twist=(-40.0, 40.0))
    limb = seeded_patient(SEED, constraint)
    t = np.arange(round((limb.protocol_end_s + FREE_S) * RATE)) / RATE
    q, raw, truth, joint, status = _record(limb, t)
    return limb, t, q, raw, truth, joint, status


def _rel_error_deg(qt, ql, tt, tl):
    est = Q.multiply(Q.conjugate(qt), ql)
    true = Q.multiply(Q.conjugate(tt), tl)
    return np.degrees(Q.angle(Q.multiply(Q.conjugate(true), est)))


def test_relative_orientation_of_two_fused_sensors_follows_the_truth(session):
    _, t, q, raw, truth, _, _ = session
    fused = [fuse_vqf(t, raw[:, i]) for i in range(2)]
    err = _rel_error_deg(fused[0].q, fused[1].q, truth[:, 0], truth[:, 1])
    dev = _rel_error_deg(q[:, 0], q[:, 1], truth[:, 0], truth[:, 1])
    late = t >= 5.0  # the first magnetic reference is taken after magNewFirstTime (5 s)
    # VQF's world is the earth frame for both sensors: no heading offset between them
    assert np.median(err[late]) < 1.0
    assert np.percentile(err[late], 95) < 4.0
    # the device model's relative heading drift (2° per sensor) is larger
    assert np.median(err[late]) < np.median(dev[late])
    for f in fused:
        assert f.q.shape == (len(t), 4) and np.allclose(np.linalg.norm(f.q, axis=1), 1.0)
        assert f.pieces == 1 and math.isclose(f.rate_hz, RATE, rel_tol=1e-6)


def test_thorax_sensor_is_not_flagged_disturbed_forever(session):
    _, t, _, raw, _, _, _ = session
    assert fuse_vqf(t, raw[:, 0]).disturbed_share < 0.1
    # with VQF's default magNewMinGyr (20 °/s) the thorax, which never turns that fast, never
    # gets a magnetic reference: the reason for VQF_PARAMS
    assert VQF_PARAMS["magNewMinGyr"] == 0.0
    assert fuse_vqf(t, raw[:, 0], params={"magNewMinGyr": 20.0}).disturbed_share == 1.0


def test_irregular_times_and_a_gap(session):
    _, t, _, raw, truth, _, _ = session
    rng = np.random.default_rng(3)
    keep = np.ones(len(t), bool)
    keep[rng.random(len(t)) < 0.1] = False  # 10 % of the samples lost: irregular intervals
    keep[(t > 30.0) & (t < 31.0)] = False  # a 1 s gap: fused as two pieces
    tk = t[keep] + rng.uniform(-1e-3, 1e-3, keep.sum())  # millisecond jitter
    fused = [fuse_vqf(tk, raw[keep, i]) for i in range(2)]
    assert [f.pieces for f in fused] == [2, 2]
    err = _rel_error_deg(fused[0].q, fused[1].q, truth[keep, 0], truth[keep, 1])
    assert np.median(err[tk >= 5.0]) < 1.0


def test_bad_inputs_are_clear_errors(session):
    _, t, _, raw, _, _, _ = session
    r = raw[:500, 0].copy()
    r[100, 7] = np.nan
    with pytest.raises(CalibrationError, match="1 of 500 are missing or not finite"):
        fuse_vqf(t[:500], r)
    with pytest.raises(CalibrationError, match="at least 10 samples"):
        fuse_vqf(t[:5], raw[:5, 0])
    with pytest.raises(CalibrationError, match=r"shape \(N, 9\)"):
        fuse_vqf(t[:50], raw[:50, 0, :6])
    with pytest.raises(CalibrationError, match="increase strictly"):
        fuse_vqf(np.r_[t[:20], t[19:40]], raw[:41, 0])
    with pytest.raises(CalibrationError, match="magNewMinGyro"):
        fuse_vqf(t[:50], raw[:50, 0], params={"magNewMinGyro": 0.0})


# -- the read path ---------------------------------------------------------------------------
class _Store:
    """A stand-in for :class:`rig.store.Store` holding one IMU session (the read path uses
    sessions.get, samples.read/raw/complete_raw_count/sensors, calibrations.list); ``raw``
    None: a store before schema v4."""

    def __init__(self, t, q, raw, status, cal_data):
        n = len(t)
        self._s = {"t": np.repeat(t + 100.0, 2), "device_t": np.repeat(t, 2),
                   "name": np.tile(np.array(["thorax_imu", "humerus_imu"], dtype=object), n),
                   "kind": np.full(2 * n, "sensor", dtype=object),
                   "q": q.reshape(-1, 4), "status": status.reshape(-1).astype(np.int64)}
        if raw is not None:
            self._s["raw"] = raw.reshape(-1, 9)
        self._cal = cal_data
        self.sessions = SimpleNamespace(get=self._session)
        self.samples = SimpleNamespace(read=self._read, raw=self._raw, sensors=self._sensors,
                                       complete_raw_count=self._complete_raw_count)
        self.calibrations = SimpleNamespace(list=self._calibrations)

    def _session(self, sid):
        return {"id": sid, "side": "right", "pseudonym": "P-1", "joint": "shoulder",
                "meta": {"parent": "thorax_imu", "child": "humerus_imu"}}

    def _read(self, sid, name=None, raw=True):
        s = dict(self._s)
        if not raw:
            s.pop("raw", None)
        if name is None:
            return s
        sel = s["name"] == name
        return {k: v[sel] for k, v in s.items()}

    def _raw(self, sid, name):
        return self._read(sid, name)["raw"]

    def _complete_raw_count(self, sid, name):
        if "raw" not in self._s:
            return 0
        sel = self._s["name"] == name
        return int(np.isfinite(self._s["raw"][sel]).all(axis=1).sum())

    def _sensors(self, sid):
        n = len(self._s["t"]) // 2
        return [{"name": "thorax_imu", "segment": "thorax", "kind": "sensor", "n_samples": n},
                {"name": "humerus_imu", "segment": "humerus", "kind": "sensor",
                 "n_samples": n}]

    def _calibrations(self, sid):
        return [{"id": 1, "kind": "imu-alignment", "data": self._cal, "residual_deg": 1.0}]


def _stored_calibration(limb, t, q):
    """What the recorder stores: the calibration fitted on the device quaternions, its
    protocol, windows and their origin on the device clock."""
    from calibration.alignment import ImuJointCalibration

    p = limb.calibration_protocol
    w = {k: list(v) for k, v in p.windows().items()}
    t0 = limb.protocol_start_s
    st = (t >= t0 + w["static"][0]) & (t <= t0 + w["static"][1])
    fu = (t >= t0 + w["functional"][0]) & (t <= t0 + w["functional"][1])
    cal = ImuJointCalibration().fit(q[st, 0], q[st, 1], q[fu, 0], q[fu, 1])
    return {**cal.to_dict(), "windows_s": w,
            "protocol": {"static_s": p.static_s, "functional_s": p.functional_s,
                         "origin": {"time": "device_t", "t0": t0}}}


def _joint_error_deg(q, truth):
    return np.degrees(Q.angle(Q.multiply(Q.conjugate(truth), q)))


def test_read_path_fuses_refits_and_records_provenance(session):
    from rig.readback import joint_orientations_from_store

    limb, t, q, raw, _, joint, status = session
    store = _Store(t, q, raw, status, _stored_calibration(limb, t, q))
    vqf = joint_orientations_from_store(store, 1, fusion="vqf")
    auto = joint_orientations_from_store(store, 1)
    dev = joint_orientations_from_store(store, 1, fusion="device")
    assert np.allclose(auto.q, vqf.q)
    f = vqf.provenance["fusion"]
    assert f["method"] == "vqf" and f["library"].startswith("vqf ")
    assert f["params"] == VQF_PARAMS and f["refit_residual_deg"] < 3.0
    assert set(f["sensors"]) == {"thorax_imu", "humerus_imu"}
    assert all(s["mag_disturbed_share"] < 0.1 for s in f["sensors"].values())
    assert vqf.status is None and dev.status is not None
    assert dev.provenance["fusion"] == {"method": "device"}
    free = t >= limb.protocol_end_s
    e_vqf = _joint_error_deg(vqf.q[free], joint[free])
    e_dev = _joint_error_deg(dev.q[free], joint[free])
    assert np.median(e_vqf) < 2.0
    assert np.median(e_vqf) < np.median(e_dev)


def test_read_path_without_raw(session):
    from rig.readback import joint_orientations_from_store

    limb, t, q, raw, _, _, status = session
    cal = _stored_calibration(limb, t, q)
    none = _Store(t, q, None, status, cal)
    with pytest.raises(RigConfigError,
                       match="--fusion vqf: sensor 'thorax_imu' has no raw samples for 8000 of"):
        joint_orientations_from_store(none, 1, fusion="vqf")
    auto = joint_orientations_from_store(none, 1)
    assert auto.provenance["fusion"]["method"] == "device"
    assert "no raw samples" in auto.provenance["fusion"]["auto"]
    part = raw.copy()
    part[:50, 1] = np.nan  # the limb sensor's first 50 samples without raw data
    with pytest.raises(RigConfigError, match="'humerus_imu' has no raw samples for 50 of"):
        joint_orientations_from_store(_Store(t, q, part, status, cal), 1, fusion="vqf")
    no_origin = {**cal, "protocol": {"static_s": 5.0}}
    with pytest.raises(RigConfigError, match=r"protocol\.origin"):
        joint_orientations_from_store(_Store(t, q, raw, status, no_origin), 1, fusion="vqf")
    with pytest.raises(RigConfigError, match="fusion must be one of"):
        joint_orientations_from_store(none, 1, fusion="madgwick")


# -- the commands ----------------------------------------------------------------------------
def _store_session(db, limb, t, q, raw, status):
    """A real store holding the simulated IMU session (raw samples where ``raw`` is given)."""
    from rig.store import SampleWriter, open_store

    with open_store(db) as st:
        pid = st.patients.add("P-002")
        sid = st.sessions.start(pid, rig_name="sim-imu", joint="shoulder", side="right",
                                meta={"parent": "thorax_imu", "child": "humerus_imu"})
        st.samples.add_sensor(sid, "thorax_imu", segment="thorax", kind="sensor")
        st.samples.add_sensor(sid, "humerus_imu", segment="humerus", kind="sensor")
        with SampleWriter(st, sid) as w:
            for i, name in enumerate(("thorax_imu", "humerus_imu")):
                w.add_many(t + 100.0, t, name, "sensor", q[:, i], status[:, i],
                           raw=None if raw is None else raw[:, i])
        st.calibrations.add(sid, "imu-alignment", _stored_calibration(limb, t, q), 1.0)
        st.sessions.end(sid, status="completed", meta={})
    return sid


def _run(args, capsys):
    from rig.cli import main

    with pytest.raises(SystemExit) as exc:
        main(args)
    out = capsys.readouterr()
    return exc.value.code, out.out, out.err


def test_boundary_and_rom_fusion_option(session, tmp_path, capsys):
    from models.constraint import load_constraint

    limb, t, q, raw, _, _, status = session
    db = tmp_path / "raw.db"
    sid = _store_session(db, limb, t, q, raw, status)
    out = tmp_path / "c.yaml"
    code, _, err = _run(["boundary", "--db", str(db), "--session", str(sid), "--out", str(out),
                         "--fusion", "vqf", "--no-store"], capsys)
    assert code == 0, err
    fusion = load_constraint(out).provenance["fusion"]
    assert fusion["method"] == "vqf" and fusion["refit_residual_deg"] < 3.0
    code, stdout, err = _run(["rom", "--db", str(db), "--session", str(sid), "--fusion",
                              "device"], capsys)
    assert code == 0, err
    assert "flexion" in stdout
    assert stdout.splitlines()[0] == f"session {sid} (IMU orientations as fused by the devices)"
    code, stdout, err = _run(["rom", "--db", str(db), "--session", str(sid)], capsys)
    assert code == 0, err
    assert "fused on the host by VQF" in stdout.splitlines()[0]  # auto: raw samples there
    # the clinician's report says so too, with the calibration re-fitted on VQF's orientations
    html = tmp_path / "r.html"
    code, _, err = _run(["report", "--db", str(db), "--session", str(sid), "--out", str(html)],
                        capsys)
    assert code == 0, err
    page = html.read_text()
    assert "fused on the host by VQF from the raw samples" in page
    assert "re-fitted on the VQF orientations" in page
    db2 = tmp_path / "noraw.db"
    sid2 = _store_session(db2, limb, t, q, None, status)
    for cmd in (["rom"], ["boundary", "--out", str(out)]):
        code, _, err = _run([*cmd, "--db", str(db2), "--session", str(sid2), "--fusion", "vqf"],
                            capsys)
        assert code == 2 and err.startswith("rig: error:") and "--fusion vqf:" in err
        assert "raw samples" in err and len(err.strip().splitlines()) == 1
    code, _, err = _run(["boundary", "--db", str(db), "--session", str(sid), "--out", str(out),
                         "--fusion", "madgwick"], capsys)
    assert code == 2 and "madgwick" in err


def test_fusion_option_on_a_servo_session_is_a_user_error(session, tmp_path, capsys):
    # a servo limb's session holds joint samples: asking for a fusion of IMUs there is a
    # mistake (one line, exit 2); the default (auto) reads it as it is
    from rig.store import SampleWriter, open_store

    limb, t, _, _, _, _, _ = session
    db = tmp_path / "servo.db"
    with open_store(db) as st:
        pid = st.patients.add("P-003")
        sid = st.sessions.start(pid, rig_name="sim-shoulder", joint="shoulder", side="right")
        st.samples.add_sensor(sid, "shoulder", kind="joint")
        with SampleWriter(st, sid) as w:
            w.add_many(t, None, "shoulder", "joint", limb.joint(t), np.zeros(len(t), int))
        st.sessions.end(sid, status="completed", meta={})
    for fusion in ("vqf", "device"):
        code, _, err = _run(["rom", "--db", str(db), "--session", str(sid), "--fusion",
                             fusion], capsys)
        assert code == 2 and err.startswith("rig: error:") and "joint samples" in err
        assert f"--fusion {fusion} applies to IMU sessions" in err
        assert len(err.strip().splitlines()) == 1
    code, stdout, err = _run(["rom", "--db", str(db), "--session", str(sid)], capsys)
    assert code == 0, err
    assert "flexion" in stdout
