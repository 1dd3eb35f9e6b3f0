"""``rig enforce`` end to end: user mistakes (one line, exit 2, before anything moves), a run
with telemetry CSV, summary JSON and the store, CSV targets, --force-model, and SIGINT leaving
the servos held (a subprocess against a simulator served from this process)."""

from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from models.constraint import JointConstraint, dump_constraint
from rig.cli import main
from rig.sim.dynamixel import start_servo_bus

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("enforce")
    cone = JointConstraint.cone((1, 0, 0), 50.0, twist=(-40, 40), name="cone50")
    dump_constraint(cone, d / "cone.yaml")
    elbow = JointConstraint.cone((1, 0, 0), 50.0, twist=(-40, 40), name="cone50", joint="elbow")
    dump_constraint(elbow, d / "elbow.yaml")
    for name, src in (("orig", ROOT / "models/shapes/original.yaml"), ("cone", d / "cone.yaml"),
                      ("elbow", d / "elbow.yaml")):
        with pytest.raises(SystemExit) as exc:
            main(["train", "--constraint", str(src), "--out", str(d / f"{name}.onnx")])
        assert exc.value.code == 0
    return d


def _argv(files, *extra, model="orig.onnx", targets="script:adversarial", rig="sim-shoulder"):
    # runs in real time: generous servo-data and Bus Watchdog limits, so that a loaded test
    # machine stalling the loop for 100 ms does not end a run in the safe state
    # (tests/rig/test_loop.py checks both on a manual clock)
    return ["enforce", "--rig", rig, "--model", str(files / model), "--targets", targets,
            "--stale-servo-ms", "1000", "--watchdog-ms", "1000", *extra]


@pytest.mark.parametrize(("case", "message"), [
    ("no-model", "cannot read model file"),
    ("not-onnx", "not an ONNX model"),
    ("imu-rig", "has no servo chain"),
    ("rate", "--rate 0.0: expected a positive number"),
    ("duration", "--duration -1.0"),
    ("watchdog", "--watchdog-ms 3000: expected 0-2540 ms"),
    ("session-no-db", "--session needs --db"),
    ("wrong-model", "trained for constraint 'cone50', which differs from rig 'sim-shoulder'"),
    ("wrong-joint", "model is for joint 'elbow'"),
    ("targets", "--targets 'dance': expected PATH.csv"),
    ("bad-csv", "bad.csv:3: not a number"),
    ("telemetry-dir", "does not exist"),
    ("telemetry-proc", "--telemetry /proc/t.csv: cannot write in /proc"),
    ("summary-proc", "--summary-json /proc/s.json: cannot write in /proc"),
    ("bad-port", "/dev/ttyUSB97"),
    ("unknown-script-key", "unknown key 'speed'"),
    ("db-no-patient", "--db: say whose run this is"),
    ("tolerance", "--tolerance-deg 720.0: at most 10°"),
    ("binary-targets", "img.png: not a text CSV file"),
    ("cpu", "--cpu 4096: not a CPU this process may run on"),
])
def test_user_mistakes_are_one_line(files, tmp_path, case, message, rig_cli):
    argv = {
        "no-model": _argv(files, model="missing.onnx"),
        "not-onnx": _argv(files, model="cone.yaml"),
        "imu-rig": _argv(files, rig="sim-imu"),
        "rate": _argv(files, "--rate", "0"),
        "duration": _argv(files, "--duration", "-1"),
        "watchdog": _argv(files, "--watchdog-ms", "3000"),
        "session-no-db": _argv(files, "--session", "1"),
        "wrong-model": _argv(files, model="cone.onnx"),
        "wrong-joint": _argv(files, "--constraint", str(files / "cone.yaml"),
                             model="elbow.onnx"),
        "targets": _argv(files, targets="dance"),
        "bad-csv": _argv(files, targets=str(tmp_path / "bad.csv")),
        "telemetry-dir": _argv(files, "--telemetry", str(tmp_path / "no" / "t.csv")),
        # a folder that exists but takes no new file (root writes through permission bits)
        "telemetry-proc": _argv(files, "--telemetry", "/proc/t.csv"),
        "summary-proc": _argv(files, "--summary-json", "/proc/s.json"),
        "bad-port": _argv(files, rig=str(tmp_path / "rig.yaml")),
        "unknown-script-key": _argv(files, targets="script:slow?speed=3"),
        "db-no-patient": _argv(files, "--db", str(tmp_path / "x.db"), "--duration", "0.2"),
        "tolerance": _argv(files, "--tolerance-deg", "720"),
        "binary-targets": _argv(files, targets=str(tmp_path / "img.png")),
        "cpu": _argv(files, "--cpu", "4096"),
    }[case]
    (tmp_path / "img.png").write_bytes(b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR\xff\xfe" * 8)
    (tmp_path / "bad.csv").write_text("t_s,w,x,y,z\n0,1,0,0,0\n0.1,1,x,0,0\n")
    rig_text = (ROOT / "rig/configs/sim-shoulder.yaml").read_text()
    start = rig_text.index('  port: "sim://')
    end = rig_text.index("\n", start)
    (tmp_path / "rig.yaml").write_text(rig_text[:start] + "  port: /dev/ttyUSB97"
                                       + rig_text[end:])
    code, out, err = rig_cli(argv)
    assert code == 2, (out, err)
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("rig: error: "), err
    assert message in lines[0], lines[0]
    assert "Traceback" not in err
    # checked up front: the loop was never started (it announces itself before its first cycle)
    assert "enforcing" not in out and "cycles" not in out, out
    assert "backstop" not in out, out  # nor the servos' position limits written
    assert ".tmp" not in err


def test_a_run_writes_telemetry_summary_and_store(files, tmp_path, rig_cli):
    from rig.store import open_store

    tel, summ, db = tmp_path / "t.csv", tmp_path / "s.json", tmp_path / "rig.db"
    code, out, err = rig_cli(_argv(files, "--duration", "1", "--telemetry", str(tel),
                                  "--summary-json", str(summ), "--db", str(db),
                                  "--patient", "P-0042"))
    assert code == 0, (out, err)
    assert "enforcing 'original'" in out and "max violation" in out
    s = json.loads(summ.read_text())
    for key in ("rate_hz", "cycles", "p50_cycle_ms", "p99_cycle_ms", "overruns",
                "max_violation_deg", "interventions", "faults", "safe_state_entries"):
        assert key in s, key
    assert s["rate_hz"] == 200.0 and s["safe_state_entries"] == 0
    assert s["max_violation_deg"] <= 1.0
    # every overrun under one cause
    assert sum(s["overruns_by_cause"].values()) == s["overruns"]
    assert set(s["late_starts_by_cause"]) == {"scheduler", "bus", "compute"}
    with tel.open() as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == s["cycles"] > 0
    for col in ("t_s", "target_w", "commanded_z", "present_x", "read_ms", "compute_ms",
                "write_ms", "correction_deg", "intervention", "faults"):
        assert col in rows[0]
    assert max(float(r["violation_deg"]) for r in rows) <= 1.0
    with open_store(db) as store:
        run = store.runs.get(s["run_id"])
        assert run["status"] == "completed" and run["summary"]["cycles"] == s["cycles"]
        t = store.runs.telemetry(s["run_id"])
        assert len(t["t_s"]) == s["cycles"]
        np.testing.assert_allclose(t["commanded_w"], [float(r["commanded_w"]) for r in rows],
                                   atol=1e-8)
        sess = store.sessions.get(s["session_id"])
        assert sess["kind"] == "enforce" and sess["pseudonym"] == "P-0042"


def test_csv_targets_and_force_model(files, tmp_path, rig_cli):
    lines = ["t_s,w,x,y,z"]
    for k in range(40):  # 0.4 s: a swing out past the boundary, then a NaN row
        a = np.radians(2.0 * k)
        lines.append(f"{k * 0.01:.2f},{np.cos(a / 2):.6f},0,0,{np.sin(a / 2):.6f}")
    lines.append("0.40,nan,nan,nan,nan")
    (tmp_path / "traj.csv").write_text("\n".join(lines) + "\n")
    summ = tmp_path / "s.json"
    code, out, err = rig_cli(_argv(files, "--summary-json", str(summ), "--force-model",
                                  model="cone.onnx", targets=str(tmp_path / "traj.csv")))
    assert code == 0, (out, err)
    assert "warning:" in out and "--force-model" in out
    s = json.loads(summ.read_text())
    assert s["constraint"] == "original"  # the rig's constraint is still the one enforced
    assert s["interventions_by_kind"].get("hold_invalid", 0) > 0
    assert s["duration_s"] >= 0.4 and s["max_violation_deg"] <= 1.0


def test_sigint_leaves_the_servos_held(files, tmp_path):
    bus = start_servo_bus([1, 2, 3], return_delay_us=0)
    try:
        rig_text = (ROOT / "rig/configs/sim-shoulder.yaml").read_text()
        start = rig_text.index('  port: "sim://')
        end = rig_text.index("\n", start)
        (tmp_path / "rig.yaml").write_text(rig_text[:start] + f"  port: {bus.port}"
                                           + rig_text[end:])
        summ = tmp_path / "s.json"
        env = dict(os.environ, PYTHONPATH=str(ROOT))
        proc = subprocess.Popen(
            [sys.executable, "-m", "rig", *_argv(files, "--summary-json", str(summ),
                                                 rig=str(tmp_path / "rig.yaml"),
                                                 targets="script:sweep")],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
        try:
            line = ""
            while "enforcing" not in line:
                line = proc.stdout.readline()
                assert line, proc.stderr.read()
            time.sleep(0.5)  # let it move (any amount of motion will do)
            proc.send_signal(signal.SIGINT)
            _, err = proc.communicate(timeout=60)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.communicate()
        assert proc.returncode == 130, err
        s = json.loads(summ.read_text())
        assert s["safe_state_entries"] == 1 and "SIGINT" in s["safe_state_reason"]
        for i in (1, 2, 3):  # hold: torque on, goal where the limb is
            servo = bus.servo(i)
            assert servo.torque
            assert abs(servo.get("Goal Position") - bus.position(i)) <= 3
    finally:
        bus.close()


def test_mirroring_an_imu_worn_limb(files, tmp_path, rig_cli):
    tel = tmp_path / "t.csv"
    code, out, err = rig_cli(_argv(files, "--duration", "1.5", "--telemetry", str(tel),
                                  targets="mirror:sim-imu"))
    if code != 0 and tel.exists():  # say what the bus did
        with tel.open() as fh:
            tail = [(r["cycle"], r["t_s"], r["faults"], r["read_ms"], r["cycle_ms"])
                    for r in list(csv.DictReader(fh))[-12:]]
        err += f"\nlast rows (cycle, t_s, faults, read_ms, cycle_ms): {tail}"
    assert code == 0, (out, err)
    assert "mirror of sim-imu" in out
    with tel.open() as fh:
        rows = list(csv.DictReader(fh))
    target = np.array([[float(r[f"target_{c}"]) for c in "wxyz"] for r in rows])
    bits = np.array([int(r["intervention"]) for r in rows])
    followed = np.isfinite(target).all(1) & ((bits & 4) == 0)  # a fresh target was used
    assert followed.sum() > 0
    assert max(float(r["violation_deg"]) for r in rows) <= 1.0


def test_a_recorded_session_binds_constraint_and_patient(files, tmp_path, capsys, rig_cli):
    from models.shapes import load_shape
    from rig.store import open_store

    orig = load_shape("original")
    db = tmp_path / "rig.db"
    with open_store(db) as store:
        pid = store.patients.add("P-1")
        sid = store.sessions.start(pid, rig_name="sim-shoulder", joint="shoulder", side="right")
        store.boundaries.add(sid, orig.to_yaml(), {"source": "test"})
        store.sessions.end(sid)
    summ = tmp_path / "s.json"
    code, _, err = rig_cli(_argv(files, "--duration", "0.3", "--db", str(db), "--session",
                                str(sid), "--summary-json", str(summ)))
    assert code == 0, err
    s = json.loads(summ.read_text())
    assert s["constraint_source"] == f"session {sid}"
    with open_store(db) as store:
        run_session = store.sessions.get(s["session_id"])
        assert run_session["pseudonym"] == "P-1" and run_session["kind"] == "enforce"
        assert run_session["meta"]["recording_session"] == sid
    # a model trained for another patient's boundary (same limits) is refused
    other = load_shape("original")
    import dataclasses

    dump_constraint(dataclasses.replace(other, patient="P-2"), tmp_path / "p2.yaml")
    with pytest.raises(SystemExit) as exc:
        main(["train", "--constraint", str(tmp_path / "p2.yaml"), "--out",
              str(tmp_path / "p2.onnx")])
    assert exc.value.code == 0
    capsys.readouterr()
    code, _, err = rig_cli(["enforce", "--rig", "sim-shoulder", "--model",
                            str(tmp_path / "p2.onnx"), "--targets", "script:hold", "--db",
                            str(db), "--session", str(sid)])
    assert code == 2 and "model is for patient 'P-2', session" in err and "P-1" in err


def test_quiet_prints_only_the_summary_line(files, rig_cli):
    code, out, err = rig_cli(_argv(files, "--duration", "0.3", "--quiet"))
    assert code == 0, (out, err)
    lines = out.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("cycles ") and "max violation" in lines[0]
    assert "safe-state entries 0" in lines[0] and "end completed" in lines[0]


def test_a_read_only_store_is_refused_before_the_backstop(files, tmp_path, rig_cli):
    """Issue 37: ``rig enforce --db`` on an archive it cannot write wrote the servos' position
    limits, then failed to store the run."""
    import os
    import subprocess

    from rig.store import open_store

    db = tmp_path / "ro.db"
    with open_store(db) as store:
        store.patients.add("P-RO")
    if os.geteuid() == 0:  # permission bits do not stop root: make the file immutable
        r = subprocess.run(["chattr", "+i", str(db)], capture_output=True, text=True)
        if r.returncode != 0:
            pytest.skip(f"cannot make a file immutable here: {r.stderr.strip()}")
    else:
        db.chmod(0o444)
    try:
        code, out, err = rig_cli(_argv(files, "--db", db, "--patient", "P-RO", "--duration",
                                       "0.2"))
    finally:
        if os.geteuid() == 0:
            subprocess.run(["chattr", "-i", str(db)], check=True)
    assert code == 2 and "read-only" in err and err.count("\n") == 1, err
    assert "backstop" not in out and "enforcing" not in out, out
