"""The guided recording, its live events and a session's jobs, over HTTP to a real uvicorn
server on 127.0.0.1 with a real SQLite store (tests/web/server.py).

The simulated rig is the shipped ``sim-imu`` with its patient four times faster than the host's
clock (``time_scale=4``: the 15 s calibration protocol takes ~4 s); the Enter prompts are
driven on the shipped ``sim-shoulder`` opened so that it answers as hardware does (no simulated
patient the recorder may follow: it waits for Enter, as ``rig record`` does on hardware).
"""

from __future__ import annotations

import asyncio
import json
import os
import stat
import urllib.request

import pytest

from rig.store import open_store
from rig.web.jobs import Channel
from tests.rig.rigs import sim_imu_yaml
from tests.web.server import call, events, live_app, opener_as_hardware, serving

pytestmark = pytest.mark.xdist_group("web-live")


@pytest.fixture(scope="module")
def web(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("web")
    cfg = sim_imu_yaml(tmp, port_suffix="&time_scale=4")
    db = str(tmp / "rig.db")
    with open_store(db) as store:
        patient = store.patients.ensure("P-0042")
    app = live_app(db, tmp / "files", opener=opener_as_hardware("sim-shoulder"),
                   rigs={"test-imu": str(cfg), "sim-shoulder": "sim-shoulder",
                         "hardware-template": "hardware-template"})
    with serving(app) as base:
        yield {"base": base, "db": db, "patient": patient, "files": tmp / "files", "state": {},
               "jobs": app.state.jobs}


def _counts(db):
    with open_store(db, create=False) as store:
        return len(store.jobs.list()), len(store.sessions.list())


def test_a_guided_recording_streams_its_steps_and_coverage_and_keeps_every_sample(web):
    base = web["base"]
    code, started = call(base, "/api/record", {"patient_id": web["patient"], "rig": "test-imu",
                                               "side": "right", "duration_s": 2})
    assert code == 200 and started["url"] == f"/jobs/{started['job_id']}"
    got = list(events(base, started["job_id"]))
    names = [n for n, _ in got]
    said = [d["text"] for n, d in got if n == "message"]
    # the calibration's steps as rig record prints them
    assert said[0].startswith("calibration — 1) neutral pose:")
    assert any(s.startswith("calibration stored: imu-alignment, residual") for s in said)
    statuses = [d for n, d in got if n == "status"]
    assert len({s["samples"] for s in statuses}) >= 2  # the counters moved between events
    assert all(s["sample_ms"] is not None for s in statuses if s["samples"])
    cov = [d for n, d in got if n == "coverage"][-1]
    assert len(cov["sectors"]) == 12 and len(cov["reached"]) > 0
    assert names[-1] == "end" and "session" in names
    end = got[-1][1]
    assert end["status"] == "completed" and end["message"].startswith(
        f"session {end['result']['session_id']}: completed")
    sid = end["result"]["session_id"]
    with open_store(web["db"], create=False) as store:
        sess = store.sessions.get(sid)
        stored = store.samples.count(sid)
        job = store.jobs.get(started["job_id"])
    assert sess["status"] == "completed"
    assert stored == end["result"]["samples"] == statuses[-1]["samples"]
    assert end["result"]["dropped"] == 0
    assert job["state"] == "completed" and job["session_id"] == sid
    assert job["progress"]["messages"][0] == said[0]  # what a reloaded page starts from
    web["state"]["session"] = sid
    # a page opened after the end: the stored steps, state and end
    again = list(events(base, started["job_id"]))
    assert [d["text"] for n, d in again if n == "message"] == said[:len(
        job["progress"]["messages"])]
    assert again[-1] == ("end", {"status": "completed", "message": end["message"],
                                 "result": end["result"]})


def test_stop_ends_completed_a_second_recording_on_the_rig_is_refused(web):
    base = web["base"]
    before = _counts(web["db"])
    code, started = call(base, "/api/record", {"patient_id": web["patient"], "rig": "test-imu",
                                               "calibrate": False})
    assert code == 200
    job_id = started["job_id"]
    code, busy = call(base, "/api/record", {"patient_id": web["patient"], "rig": "test-imu"})
    assert code == 409 and busy["error"].startswith(f"busy: job {job_id} (record) is running "
                                                    "on the rig's port sim://imu-stream")
    stopped = False
    for name, data in events(base, job_id):
        if name == "status" and data["samples"] > 0 and not stopped:
            assert call(base, f"/api/jobs/{job_id}/stop", {}) == (200, {"ok": True})
            stopped = True
        last = (name, data)
    assert last[0] == "end" and last[1]["status"] == "completed"
    sid = last[1]["result"]["session_id"]
    with open_store(web["db"], create=False) as store:
        assert store.sessions.get(sid)["status"] == "completed"
        assert store.samples.count(sid) == last[1]["result"]["samples"] > 0
    assert _counts(web["db"]) == (before[0] + 1, before[1] + 1)  # the refused one wrote nothing


def test_a_recording_goes_on_when_its_page_is_closed(web):
    base = web["base"]
    code, started = call(base, "/api/record", {"patient_id": web["patient"], "rig": "test-imu",
                                               "calibrate": False, "duration_s": 4})
    job_id = started["job_id"]
    for name, data in events(base, job_id):  # the viewer leaves after the first counters
        if name == "status" and data["samples"] > 0:
            break
    assert web["jobs"].wait(job_id, 60)
    code, job = call(base, f"/api/jobs/{job_id}")
    assert code == 200 and job["state"] == "completed" and not job["live"]
    assert job["result"]["samples"] >= data["samples"]
    assert "writer_pid" not in job and "resource" not in job
    with open_store(web["db"], create=False) as store:
        assert store.samples.count(job["session_id"]) == job["result"]["samples"]


def test_continue_is_enter_where_rig_record_waits_for_it_and_interrupt_keeps_everything(web):
    base = web["base"]
    code, started = call(base, "/api/record", {"patient_id": web["patient"],
                                               "rig": "sim-shoulder"})
    assert code == 200
    job_id = started["job_id"]
    stage = "waiting"
    for name, data in events(base, job_id):
        if stage == "waiting" and name == "status" and data["enter"]:
            assert data["enter"] == "start the calibration: the patient is in the neutral pose"
            assert data["phase"] == "calibration: neutral pose, press Enter when ready"
            assert call(base, f"/api/jobs/{job_id}/continue", {}) == (200, {"ok": True})
            stage = "pressed"
        elif stage == "pressed" and name == "message" and data["text"].startswith(
                "neutral pose: hold still"):
            assert call(base, f"/api/jobs/{job_id}/interrupt", {}) == (200, {"ok": True})
            stage = "interrupted"
        last = (name, data)
    assert stage == "interrupted"
    assert last[0] == "end" and last[1]["status"] == "interrupted"
    sid = last[1]["result"]["session_id"]
    with open_store(web["db"], create=False) as store:
        assert store.sessions.get(sid)["status"] == "interrupted"
        assert store.samples.count(sid) == last[1]["result"]["samples"] > 0
    code, err = call(base, f"/api/jobs/{job_id}/continue", {})
    assert code == 400 and err == {"error": f"job {job_id}: no record job of that id is "
                                            "running"}


def test_boundary_then_training_from_the_session(web):
    base = web["base"]
    sid = web["state"].get("session")
    if sid is None:
        pytest.skip("needs the recording of the first test")
    code, err = call(base, f"/api/sessions/{sid}/train", {})
    assert code == 400 and err["error"] == f"session {sid} has no boundary yet: extract it first"
    code, started = call(base, f"/api/sessions/{sid}/boundary", {})
    assert code == 200
    got = list(events(base, started["job_id"]))
    end = got[-1][1]
    assert end["status"] == "completed", end
    assert any(d["text"].startswith("  swing       polygon") for n, d in got if n == "message")
    folder = web["files"] / f"session-{sid}"
    assert stat.S_IMODE(os.stat(folder / end["result"]["file"]).st_mode) == 0o600
    assert stat.S_IMODE(os.stat(folder).st_mode) == 0o700
    code, err = call(base, f"/api/sessions/{sid}/train", {"preset": "nope"})
    assert code == 400 and err["error"].startswith("preset 'nope': expected one of field, ")
    code, started = call(base, f"/api/sessions/{sid}/train", {})
    assert code == 200
    got = list(events(base, started["job_id"]))
    end = got[-1][1]
    assert end["status"] == "completed", end
    assert any("held-out metrics" in d["text"] for n, d in got if n == "message")
    with open_store(web["db"], create=False) as store:
        [model] = store.models.list(session_id=sid)
    assert model["id"] == end["result"]["model_id"] and model["boundary_id"] is not None
    assert stat.S_IMODE(os.stat(folder / end["result"]["file"]).st_mode) == 0o600
    page = _get_text(base, f"/sessions/{sid}/work")
    assert f"model {model['id']}" in page and "Extract the boundary" in page
    assert '<option value="compact">compact</option>' in page


def _get_text(base, path):
    with urllib.request.urlopen(base + path, timeout=30) as resp:
        return resp.read().decode()


@pytest.mark.parametrize("path, body, code, message", [
    ("/api/record", None, 400, "patient_id: expected a positive whole number, got None"),
    ("/api/record", {"patient_id": "abc", "rig": "test-imu"}, 400,
     "patient_id: expected a positive whole number, got 'abc'"),
    ("/api/record", {"patient_id": 999, "rig": "test-imu"}, 404, "no patient 999 in "),
    ("/api/record", {"patient_id": 1, "rig": "nope"}, 400,
     "rig 'nope': not one of test-imu, sim-shoulder, hardware-template"),
    ("/api/record", {"patient_id": 1, "rig": "../../etc/passwd"}, 400,
     "rig '../../etc/passwd': not one of"),
    ("/api/record", {"patient_id": 1}, 400, "rig: choose a rig"),
    ("/api/record", {"patient_id": 1, "rig": "test-imu", "side": "left"}, 400,
     "side 'left': the rig test-imu records the right shoulder (joint.side of its "
     "configuration); choose a rig configured for the left side"),
    ("/api/record", {"patient_id": 1, "rig": "test-imu", "side": "up"}, 400,
     "side: expected one of left, right, got 'up'"),
    ("/api/record", {"patient_id": 1, "rig": "test-imu", "duration_s": -1}, 400,
     "duration_s must be > 0 seconds, got -1"),
    ("/api/record", {"patient_id": 1, "rig": "test-imu", "duration_s": "soon"}, 400,
     "duration_s: expected seconds, got 'soon'"),
    ("/api/record", {"patient_id": 1, "rig": "test-imu", "calibrate": "yes"}, 400,
     "calibrate: expected true or false, got 'yes'"),
    ("/api/record", {"patient_id": 1, "rig": "hardware-template"}, 503, "/dev/ttyACM0"),
    ("/api/record", b"{not json", 400, "the request body must be a JSON object"),
    ("/api/record", b"[1, 2]", 400, "the request body must be a JSON object"),
    ("/api/record", b"x" * 20000, 400, "request body too large (20000 bytes > 16384)"),
    ("/api/sessions/999/boundary", {}, 404, "no session 999 in "),
    ("/api/sessions/999/train", {}, 404, "no session 999 in "),
    ("/api/jobs/999/stop", {}, 400, "job 999: no record job of that id is running"),
    ("/api/jobs/1/explode", {}, 400, "action 'explode': expected continue, stop or interrupt"),
    ("/api/jobs/999", None, 404, "no job 999 in "),
])
def test_a_bad_request_is_one_line_and_writes_nothing(web, path, body, code, message):
    before = _counts(web["db"])
    if path == "/api/jobs/999":
        got = call(web["base"], path)
    elif isinstance(body, bytes):
        got = call(web["base"], path, raw=body)
    else:
        got = call(web["base"], path, body if body is not None else {})
    assert got[0] == code and list(got[1]) == ["error"]
    text = got[1]["error"]
    assert text.startswith(message) or (code == 503 and message in text), text
    assert "\n" not in text and "Traceback" not in text
    assert _counts(web["db"]) == before


def test_a_job_of_a_server_that_died_reads_died_and_is_closed_so(tmp_path):
    db = str(tmp_path / "rig.db")
    gone = lambda pid: (False, None)  # noqa: E731  (the writer's process is gone)
    with open_store(db) as store:
        job = store.jobs.start("record", "rig:sim://x", params={"rig": "x"})
        store.jobs.update(job, progress={"status": {"samples": 5}})
        assert store.jobs.get(job)["state"] == "running"
        assert store.jobs.get(job, probe=gone)["state"] == "died"
        # a dead holder does not keep the rig busy
        other = store.jobs.start("record", "rig:sim://x", probe=gone)
        assert store.jobs.close_died(probe=gone) == [job, other]
        row = store.jobs.get(job)
    assert row["status"] == row["state"] == "died"
    assert row["progress"] == {"status": {"samples": 5}}
    assert row["message"].startswith("the server stopped while this job ran")


def test_a_slow_viewer_skips_to_the_newest_counters_but_gets_every_step():
    channel = Channel()
    channel.publish("message", {"text": "one"})
    for n in range(5):
        channel.publish("status", {"samples": n})
    channel.publish("message", {"text": "two"})
    channel.publish("coverage", {"explored": 1})
    channel.close()

    async def read(cursor):
        return [chunk async for chunk in channel.sse(cursor)]

    text = "".join(asyncio.run(read(0)))
    got = [(b.split("\nevent: ")[1].split("\n")[0], json.loads(b.split("\ndata: ")[1]))
           for b in text.split("\n\n") if "\ndata: " in b]
    assert got == [("message", {"text": "one"}), ("status", {"samples": 4}),
                   ("message", {"text": "two"}), ("coverage", {"explored": 1})]
    # a viewer reconnecting with Last-Event-ID gets only what it had not
    assert "two" not in "".join(asyncio.run(read(7)))
    assert channel.viewers == 0
