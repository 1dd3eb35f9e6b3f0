"""Golden cases: sessions in a store, read back (``joint_orientations_from_store``, of one
joint and of a whole limb) and through the services and the CLI (``rig boundary``,
``rig boundary --limb``, ``rig rom``, ``rig export``, ``rig report``): one joint's IMU and
servo sessions, a whole arm's IMU session (with raw samples and neutral checkpoints).

The sessions are written into a fresh SQLite store per case exactly as the recorder writes
them (sensors, samples on the device clock with host times 100 s later, the fitted
calibration with its protocol, windows and clock origin, neutral checkpoints), from seeded
simulated patients measured offline: no thread, no wall clock in the samples.
"""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np

from calibration import ImuJointCalibration, LimbImuCalibration
from rig.readback import joint_orientations_from_store
from rig.sim.patients import record_servo, seeded_patient, star_constraint
from rig.store import SampleWriter, open_store
from tests.golden.cli import rig, root_relative
from tests.golden.harness import case, normalise, tmpdir
from tests.golden.util import html_text, jtext, long_text

HOST_OFFSET_S = 100.0  # host clock = device clock + this


def _measure(sim, t: np.ndarray):
    ms = sim.measure_many(t)
    q = np.stack([m.quaternions for m in ms])
    raw = np.concatenate([np.stack([m.accel for m in ms]), np.stack([m.gyro for m in ms]),
                          np.stack([m.mag for m in ms])], axis=-1)
    status = np.stack([m.calibration for m in ms]).astype(np.int64)
    return q, raw, status


@functools.cache
def _joint_imu():
    """A star patient (seed 5) with two IMUs: protocol, then 45 s of free motion with neutral
    checkpoints every 12 s, at 50 Hz; the device quaternions, raw readings and status bytes."""
    limb = seeded_patient(5, star_constraint(5), neutral=12.0)
    t = np.arange(round((limb.protocol_end_s + 45.0) * 50.0)) / 50.0
    q, raw, status = _measure(limb, t)
    return limb, t, q, raw, status


@functools.cache
def _arm_imu():
    """An anatomical arm (seed 6) with four IMUs: the limb protocol, then 50 s of free motion
    with neutral checkpoints every 12 s, at 25 Hz."""
    chain = seeded_patient(6, "arm", neutral=12.0)
    t = np.arange(round((chain.protocol_end_s + 50.0) * 25.0)) / 25.0
    q, raw, status = _measure(chain, t)
    return chain, t, q, raw, status


def _joint_db(db: Path, *, raw: bool = True) -> int:
    limb, t, q, rw, status = _joint_imu()
    p = limb.calibration_protocol
    w = {k: list(v) for k, v in p.windows().items()}
    t0 = limb.protocol_start_s
    st = (t >= t0 + w["static"][0]) & (t <= t0 + w["static"][1])
    fu = (t >= t0 + w["functional"][0]) & (t <= t0 + w["functional"][1])
    cal = ImuJointCalibration().fit(q[st, 0], q[st, 1], q[fu, 0], q[fu, 1])
    data = {**cal.to_dict(), "windows_s": w,
            "protocol": {"static_s": p.static_s, "functional_s": p.functional_s,
                         "flexion_deg": p.flexion_deg, "extension_deg": p.extension_deg,
                         "period_s": p.period_s, "settle_s": p.settle_s,
                         "origin": {"time": "device_t", "t0": t0}}}
    with open_store(db) as s:
        pid = s.patients.add("P-101", side="right")
        sid = s.sessions.start(pid, rig_name="sim-imu", joint="shoulder", side="right",
                              meta={"parent": "thorax_imu", "child": "humerus_imu"})
        s.samples.add_sensor(sid, "thorax_imu", segment="thorax", kind="sensor", port="sim://imu")
        s.samples.add_sensor(sid, "humerus_imu", segment="humerus", kind="sensor", port="sim://imu")
        with SampleWriter(s, sid) as wr:
            for i, name in enumerate(("thorax_imu", "humerus_imu")):
                wr.add_many(t + HOST_OFFSET_S, t, name, "sensor", q[:, i], status[:, i],
                            raw=rw[:, i] if raw else None)
        s.calibrations.add(sid, "imu-alignment", data, float(cal.residual_deg_))
        for a, b in limb.neutral_windows(float(t[-1])):
            s.calibrations.add(sid, "neutral-checkpoint",
                              {"window": [float(a), float(b)], "time": "device_t"}, 1.0)
        s.sessions.end(sid, status="completed", meta={})
    return sid


def _servo_db(db: Path) -> int:
    rec = record_servo(seeded_patient(7, star_constraint(7)), 120.0, 50.0)
    with open_store(db) as s:
        pid = s.patients.add("P-102")
        sid = s.sessions.start(pid, rig_name="sim-shoulder", joint="shoulder", side="left")
        s.samples.add_sensor(sid, "shoulder", segment="humerus", kind="joint", port="sim://dynamixel")
        with SampleWriter(s, sid) as wr:
            wr.add_many(rec.t, None, "shoulder", "joint", rec.limb, 0)
        s.sessions.end(sid, status="interrupted", meta={})
    return sid


def _arm_db(db: Path) -> int:
    chain, t, q, rw, status = _arm_imu()
    p = chain.calibration_protocol
    w = {k: list(v) for k, v in p.windows().items()}
    t0 = chain.protocol_start_s
    sel = {k: (t >= t0 + a) & (t <= t0 + b) for k, (a, b) in w.items()}
    cal = LimbImuCalibration("arm", "right", protocol=p).fit(
        q[sel["static"]], {j: q[sel[j]] for j in p.joints})
    data = {**cal.to_dict(), "windows_s": w,
            "protocol": {"limb": p.limb, "static_s": p.static_s, "movement_s": p.movement_s,
                         "period_s": p.period_s, "settle_s": p.settle_s,
                         "origin": {"time": "device_t", "t0": t0}}}
    names = ("thorax", "upper-arm", "forearm", "hand")
    with open_store(db) as s:
        pid = s.patients.add("P-103", side="right")
        sid = s.sessions.start(pid, rig_name="sim-arm", joint="shoulder", side="right",
                              meta={"limb": "arm", "parent": "thorax", "child": "upper-arm"})
        for name in names:
            s.samples.add_sensor(sid, name, segment=name, kind="sensor", port="sim://imu-stream")
        with SampleWriter(s, sid) as wr:
            for i, name in enumerate(names):
                wr.add_many(t + HOST_OFFSET_S, t, name, "sensor", q[:, i], status[:, i],
                            raw=rw[:, i])
        s.calibrations.add(sid, "imu-limb", data, float(cal.residual_deg_))
        for a, b in chain.neutral_windows(float(t[-1])):
            s.calibrations.add(sid, "neutral-checkpoint",
                              {"window": [float(a), float(b)], "time": "device_t"}, 1.0)
        s.sessions.end(sid, status="completed", meta={})
    return sid


def _joint_data(prefix: str, d, tmp, out: dict) -> None:
    out[f"{prefix}_q"] = d.q
    out[f"{prefix}_t"] = np.asarray(d.t, dtype=np.float64)
    out[f"{prefix}_directions"] = d.directions
    if d.status is not None:
        out[f"{prefix}_status"] = np.asarray(d.status)
    out[f"{prefix}_about"] = normalise(jtext({
        "limb_axis": d.limb_axis, "side": d.side, "patient": d.patient, "joint": d.joint,
        "provenance": d.provenance, "facts": d.facts().as_dict(),
        "warnings": d.facts().warnings(), "slow_error_deg": d.slow_error_deg,
        "orientations": d.orientations}), tmp)


def _cli(prefix: str, args: list, tmp, out: dict) -> None:
    r = rig(args, tmp)
    out[f"{prefix}_exit"] = r["exit"]
    out[f"{prefix}_stdout"] = r["stdout"]
    out[f"{prefix}_stderr"] = r["stderr"]


def _file(path: Path, tmp) -> str:
    return root_relative(normalise(path.read_text(), [tmp])) if path.exists() else "<missing>"


@case("joint")
def case_store_joint_readback() -> dict:
    """An IMU shoulder session read back: device fusion, VQF fusion (re-fitted calibration),
    with and without raw samples; the heading correction's provenance."""
    out: dict = {}
    with tmpdir() as d:
        db = d / "s.db"
        sid = _joint_db(db)
        with open_store(db, create=False) as s:
            for fusion in ("device", "vqf"):
                _joint_data(fusion, joint_orientations_from_store(s, sid, fusion=fusion), d,
                            out)
        db2 = d / "noraw.db"
        sid2 = _joint_db(db2, raw=False)
        with open_store(db2, create=False) as s:
            _joint_data("auto_noraw", joint_orientations_from_store(s, sid2), d, out)
    return out


@case("joint")
def case_store_joint_cli() -> dict:
    """``rig boundary|rom|export`` on the IMU shoulder session and on an interrupted servo
    session: printed text, files written, what is stored."""
    out: dict = {}
    with tmpdir() as d:
        db = d / "s.db"
        sid = _joint_db(db)
        c = d / "c.yaml"
        _cli("boundary", ["boundary", "--db", db, "--session", sid, "--out", c], d, out)
        out["boundary_yaml"] = _file(c, d)
        _cli("boundary_device", ["boundary", "--db", db, "--session", sid, "--out",
                                 d / "dev.yaml", "--fusion", "device", "--no-store"], d, out)
        out["boundary_device_yaml"] = _file(d / "dev.yaml", d)
        _cli("rom", ["rom", "--db", db, "--session", sid, "--age", "50", "--sex", "female"], d,
             out)
        _cli("rom_json", ["rom", "--db", db, "--session", sid, "--json"], d, out)
        _cli("export_sto", ["export", "--db", db, "--session", sid, "--out", d / "e.sto"], d,
             out)
        out.update(long_text("export_sto", _file(d / "e.sto", d)))
        _cli("export_csv", ["export", "--db", db, "--session", sid, "--out", d / "e.csv"], d,
             out)
        out.update(long_text("export_csv", _file(d / "e.csv", d)))
        with open_store(db, create=False) as s:
            out["stored_boundaries"] = normalise(jtext(
                [{k: b[k] for k in sorted(b) if k not in ("id", "created_at")}
                 for b in s.boundaries.list(sid)]), d)
        sdb = d / "servo.db"
        ssid = _servo_db(sdb)
        _cli("servo_boundary", ["boundary", "--db", sdb, "--session", ssid, "--out",
                                d / "servo.yaml", "--no-store"], d, out)
        out["servo_yaml"] = _file(d / "servo.yaml", d)
        _cli("servo_rom", ["rom", "--db", sdb, "--session", ssid, "--json"], d, out)
        with open_store(sdb, create=False) as s:
            _joint_data("servo", joint_orientations_from_store(s, ssid), d, out)
    return out


@case("limb")
def case_store_limb_readback() -> dict:
    """A whole-arm IMU session read back: device fusion and VQF (the limb calibration
    re-fitted), with and without the heading correction."""
    out: dict = {}
    with tmpdir() as d:
        db = d / "arm.db"
        sid = _arm_db(db)
        with open_store(db, create=False) as s:
            for name, kw in (("device", {"fusion": "device"}), ("vqf", {"fusion": "vqf"}),
                             ("noheading", {"heading": False})):
                c = joint_orientations_from_store(s, sid, **kw)
                out[f"{name}_q"] = c.joint_q
                out[f"{name}_t"] = np.asarray(c.t, dtype=np.float64)
                if c.status is not None:
                    out[f"{name}_status"] = np.asarray(c.status)
                out[f"{name}_about"] = normalise(jtext({
                    "limb": c.limb, "joints": c.joints, "side": c.side,
                    "provenance": c.provenance, "patient": c.patient,
                    "facts": c.recording.as_dict() if c.recording is not None else None}), d)
    return out


@case("limb")
def case_store_limb_cli() -> dict:
    """``rig boundary --limb``, ``rig boundary --joint`` and ``rig rom --joint`` on the arm
    session; the limb file written and stored."""
    out: dict = {}
    with tmpdir() as d:
        db = d / "arm.db"
        sid = _arm_db(db)
        f = d / "arm.yaml"
        _cli("chain", ["boundary", "--db", db, "--session", sid, "--limb", "arm", "--out", f],
             d, out)
        out["chain_yaml"] = _file(f, d)
        _cli("chain_device", ["boundary", "--db", db, "--session", sid, "--limb", "arm",
                              "--fusion", "device", "--no-store", "--out", d / "dev.yaml"],
             d, out)
        out["chain_device_yaml"] = _file(d / "dev.yaml", d)
        for joint in ("shoulder", "elbow", "wrist"):
            _cli(f"{joint}_boundary", ["boundary", "--db", db, "--session", sid, "--joint",
                                       joint, "--no-store", "--out", d / f"{joint}.yaml"],
                 d, out)
            out[f"{joint}_yaml"] = _file(d / f"{joint}.yaml", d)
            _cli(f"{joint}_rom", ["rom", "--db", db, "--session", sid, "--joint", joint,
                                  "--json"], d, out)
        with open_store(db, create=False) as s:
            out["stored_boundaries"] = normalise(jtext(
                [{k: b[k] for k in sorted(b) if k not in ("id", "created_at")}
                 for b in s.boundaries.list(sid)]), d)
    return out


@case("joint")
def case_report_joint_session() -> dict:
    """``rig report`` of the IMU shoulder session (HTML, images by digest) and of the
    interrupted servo session."""
    out: dict = {}
    with tmpdir() as d:
        sid = _joint_db(d / "s.db")
        _cli("report", ["report", "--db", d / "s.db", "--session", sid, "--out", d / "r.html",
                        "--age", "50", "--sex", "male"], d, out)
        out.update(html_text("report", _file(d / "r.html", d)))
        ssid = _servo_db(d / "servo.db")
        _cli("servo_report", ["report", "--db", d / "servo.db", "--session", ssid, "--out",
                              d / "servo.html", "--fusion", "device"], d, out)
        out.update(html_text("servo_report", _file(d / "servo.html", d)))
    return out


@case("limb")
def case_report_limb_session() -> dict:
    """``rig report`` of the whole-arm session (every joint's section, the couplings)."""
    out: dict = {}
    with tmpdir() as d:
        sid = _arm_db(d / "a.db")
        _cli("report", ["report", "--db", d / "a.db", "--session", sid, "--out", d / "a.html"],
             d, out)
        out.update(html_text("report", _file(d / "a.html", d)))
    return out
