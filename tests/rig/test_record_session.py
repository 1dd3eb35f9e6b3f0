"""``rig record`` end to end on the simulated rigs: checks first, calibration, clean endings.

Every device is a simulator on a real pty, read by the real drivers (``rig.devices``).
"""

from __future__ import annotations

import io
import os
import signal
import subprocess
import sys
import threading
from pathlib import Path

import pytest

from rig.cli import main
from rig.record import PlainDisplay, RecordOptions, parse_annotation, record_session
from rig.record.rigio import load_config, open_rig
from rig.store import open_store
from tests.rig.rigs import sim_imu_yaml

REPO = Path(__file__).resolve().parents[2]


def _run_cli(args, capsys):
    with pytest.raises(SystemExit) as exc:
        main(args)
    out, err = capsys.readouterr()
    return exc.value.code, out, err


def _sim_imu_yaml(tmp_path: Path, port: str | None = None, extra: str = "") -> Path:
    return sim_imu_yaml(tmp_path, port=port, extra=extra)


@pytest.mark.parametrize("case", ["unknown-key", "unknown-rig", "wrong-port", "bad-duration",
                                  "raw-from-1.0-board"])
def test_user_mistakes_are_one_line_exit_2_and_record_nothing(tmp_path, capsys, case):
    db = tmp_path / "s.db"
    rig = "sim-imu"
    extra = []
    if case == "unknown-key":
        rig = str(_sim_imu_yaml(tmp_path, extra="sensros_rate: 3\n"))
    elif case == "unknown-rig":
        rig = "no-such-rig"
    elif case == "wrong-port":
        rig = str(_sim_imu_yaml(tmp_path, port="/dev/ttyUSB9"))
    elif case == "raw-from-1.0-board":  # firmware older than the rig file asks for
        rig = str(sim_imu_yaml(tmp_path, port_suffix="&protocol=1.0", extra="  raw: true\n"))
    else:
        extra = ["--duration", "-1"]
    code, _out, err = _run_cli(["record", "--rig", rig, "--db", str(db), "--patient", "P-1",
                               "--display", "plain", *extra], capsys)
    assert code == 2
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("rig: error:"), err
    assert "Traceback" not in err
    if case == "unknown-key":
        assert "sensros_rate" in err
    if case == "wrong-port":
        assert "/dev/ttyUSB9" in err
    if case == "raw-from-1.0-board":
        assert "speaks stream protocol 1.0; raw samples need 1.1" in err
    # nothing recorded: the store was not even created
    assert not db.exists()


def test_parse_annotation():
    a = parse_annotation("12.5:pain at the limit")
    assert (a.at_s, a.text) == (12.5, "pain at the limit")
    assert parse_annotation("post-op week 6").at_s is None
    assert parse_annotation("note: colon inside").text == "note: colon inside"


def test_sim_imu_records_and_completes(tmp_path):
    db = tmp_path / "s.db"
    out = io.StringIO()
    opts = RecordOptions(rig="sim-imu", db=str(db), patient="P-6", duration_s=2.0,
                         calibrate=False, annotations=[parse_annotation("0.5:half a second")])
    res = record_session(opts, display=PlainDisplay(out))
    assert res.status == "completed" and res.dropped == 0 and res.span_s >= 2.0
    # no calibration: nothing claims one, and no clinical angles from sensor frames
    assert res.calibration is None and res.calibrated is False
    assert res.rom is None and "not calibrated" in res.rom_note
    assert "recording, uncalibrated" in out.getvalue()
    assert "calibration stored" not in out.getvalue()
    with open_store(db) as store:
        s = store.sessions.get(res.session_id)
        assert s["meta"]["calibrated"] is False and "rom" not in s["meta"]
        assert store.calibrations.list(res.session_id) == []
        assert s["status"] == "completed" and s["meta"]["samples"] == res.samples
        data = store.samples.read(res.session_id)
        assert len(data["t"]) == res.samples > 0
        assert set(data["name"]) == {"thorax", "humerus"}
        assert [a["text"] for a in store.annotations.list(res.session_id)] == ["half a second"]
    assert "[completed]" in out.getvalue()


def test_sim_imu_records_calibrates_and_completes(tmp_path):
    # the shipped sim-imu port, the patient's time 4x faster than real time (the protocol is
    # 2 s of standing + 15 s of calibration movements in patient time)
    port = load_config("sim-imu").sensors.port + "&time_scale=4"
    rig_yaml = _sim_imu_yaml(tmp_path, port=port)
    db = tmp_path / "s.db"
    out = io.StringIO()
    events = []
    opts = RecordOptions(rig=str(rig_yaml), db=str(db), patient="P-7", duration_s=3.0,
                         annotations=[parse_annotation("start note"),
                                      parse_annotation("1.0:one second in")])
    res = record_session(opts, display=PlainDisplay(out),
                         on_event=lambda n, i: events.append(n))
    assert res.status == "completed", res
    assert res.dropped == 0
    assert res.calibration is not None and res.calibration.residual_deg < 3.0
    assert res.calibrated is True and res.calibration.kind == "imu-alignment"
    assert {"session", "calibrated", "recording"} <= set(events)
    with open_store(db) as store:
        s = store.sessions.get(res.session_id)
        assert s["status"] == "completed" and s["dropped"] == 0
        assert s["meta"]["samples"] == res.samples
        data = store.samples.read(res.session_id)
        assert len(data["t"]) == res.samples > 0
        assert set(data["name"]) == {"thorax", "humerus"}
        cals = store.calibrations.list(res.session_id)
        assert len(cals) == 1 and cals[0]["residual_deg"] == pytest.approx(
            res.calibration.residual_deg)
        notes = [a["text"] for a in store.annotations.list(res.session_id)]
        assert notes == ["start note", "one second in"]
        # every frame's two readings are paired (by their shared device timestamp: host times
        # are per batch and repeat), and the calibration status comes along for the extractor
        from rig.readback import joint_orientations_from_store
        joint = joint_orientations_from_store(store, res.session_id)
        assert len(joint.q) == res.samples // 2
        assert joint.status is not None and len(joint.status) == len(joint.q)
    text = out.getvalue()
    assert "calibration stored" in text and "[completed]" in text


def test_vanished_device_ends_the_session_cleanly(tmp_path):
    db = tmp_path / "s.db"
    config = load_config("sim-imu")
    rig = open_rig(config)
    sim = rig.simulators[0]
    timers = []

    def on_event(name, info):
        if name == "recording":  # pull the plug a little into the recording
            t = threading.Timer(0.5, sim.disconnect)
            timers.append(t)
            t.start()

    opts = RecordOptions(rig="sim-imu", db=str(db), patient="P-8", calibrate=False)
    try:
        res = record_session(opts, display=PlainDisplay(io.StringIO()), on_event=on_event,
                             rig=rig)
    finally:
        for t in timers:
            t.join()
    assert res.status == "device_lost" and res.error
    assert res.samples > 0
    with open_store(db) as store:
        s = store.sessions.get(res.session_id)
        assert s["status"] == "device_lost"
        assert len(store.samples.read(res.session_id)["t"]) == res.samples


@pytest.mark.parametrize(("sig", "code"), [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_a_signal_ends_rig_record_cleanly_and_says_so(tmp_path, sig, code):
    db = tmp_path / "s.db"
    proc = subprocess.Popen(
        [sys.executable, "-m", "rig", "record", "--rig", "sim-imu", "--db", str(db),
         "--patient", "P-9", "--no-calibration", "--events", "--display", "plain"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=REPO,
        env={**os.environ, "PYTHONUNBUFFERED": "1"})
    try:
        import json

        committed = 0
        for line in proc.stdout:
            ev = json.loads(line)
            if ev["event"] == "committed" and ev["samples"] > 0:
                committed += 1
                if committed >= 2:
                    break
        proc.send_signal(sig)
        rest, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    # everything kept, and the exit status says it was stopped (128 + the signal)
    assert proc.returncode == code, err
    end = json.loads(rest.strip().splitlines()[-1])
    assert end["event"] == "end" and end["status"] == "interrupted"
    with open_store(db) as store:
        s = store.sessions.get(end["session_id"])
        assert s["status"] == "interrupted"
        assert len(store.samples.read(end["session_id"])["t"]) == end["samples"] > 0


def test_the_summary_line_is_one_for_the_terminal_and_the_browser():
    from rig.record import RecordResult

    res = RecordResult(session_id=3, patient_id=1, status="completed", samples=10, gaps=1,
                       span_s=2.04, calibrated=False, neutral_checkpoints=2,
                       coverage={"sufficient": False, "explored_sectors": 5,
                                 "sectors": list(range(12))})
    assert res.summary() == ("session 3: completed, 10 samples over 2.0 s, dropped 1 (sequence "
                             "gaps 1, queue overflow 0), NOT calibrated (sensor frames), 2 "
                             "neutral checkpoints, coverage 5/12 sectors")
