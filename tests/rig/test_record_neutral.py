"""Neutral checkpoints on the IMU path: marked by the recorder, stored, applied by the read path.

A seeded patient on a simulated stream board on a real pty (noise, heading drift, magnetic
disturbances, straps 25° off) returns to the neutral pose every 20 s (``neutral=20``); the
recorder marks each return from the patient's schedule and stores it; the read path
(:func:`rig.readback.joint_orientations_from_store`) re-zeroes the relative heading at
each one (:class:`calibration.heading.HeadingCorrection`). Simulated time runs in lockstep with
the recorder (no wall-clock condition). Seed 3 is not a held-out seed of the benchmarks.
"""

from __future__ import annotations

import io
import os
import types

import numpy as np
import pytest

from models import quaternion as Q
from rig.readback import joint_orientations_from_store
from rig.record import PlainDisplay, RecordOptions, RecordStatus, record_session
from rig.record.guided import NeutralCheckpoints
from rig.record.lockstep import CountingDisplay, LockstepClock
from rig.record.pump import SampleBatch
from rig.record.rigio import load_config, open_rig
from rig.sim.patients import star_constraint
from rig.store import open_store

SEED, RATE, FREE_S, EVERY = 3, 100, 120.0, 20
X = np.array([1.0, 0.0, 0.0])


# the module-scoped recording is made once: its tests run on one xdist worker
pytestmark = pytest.mark.xdist_group("test_record_neutral")


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    from models.constraint import dump_constraint

    tmp = tmp_path_factory.mktemp("neutral")
    cpath = tmp / "patient.yaml"
    dump_constraint(star_constraint(SEED), cpath)
    port = (f"sim://imu-stream?sensors=2&rate={RATE}&patient={cpath}&seed={SEED}"
            f"&misplace_deg=25&clock=manual&flow=on&max_lag=none&neutral={EVERY}")
    cfg = tmp / "rig.yaml"
    cfg.write_text(f"name: neutral-imu\njoint: {{name: shoulder, side: right, parent: thorax, "
                   f"child: humerus}}\nsensors:\n  port: \"{port}\"\n  protocol: stream\n"
                   f"  rate_hz: {RATE}\n  segments: {{thorax: 0, humerus: 1}}\n")
    db = tmp / "neutral.db"
    rig = open_rig(load_config(str(cfg)), calibrate=True)
    limb = rig.patients[0]
    lines = io.StringIO()
    shown = CountingDisplay(PlainDisplay(lines))
    with LockstepClock(rig.simulators[0].clock, lambda: shown.samples, 2.0 * RATE) as lock:
        res = record_session(
            RecordOptions(rig=str(cfg), db=str(db), patient="NEUTRAL-3", duration_s=FREE_S),
            display=shown, rig=rig,
            on_event=lambda name, info: name == "session" and lock.start())
    return types.SimpleNamespace(res=res, db=db, limb=limb, rig=rig, shown=shown,
                                 lines=lines.getvalue().splitlines())


def test_checkpoints_are_marked_and_stored_in_the_samples_clock(recorded):
    res, limb, rig = recorded.res, recorded.limb, recorded.rig
    assert res.status == "completed" and res.dropped == 0
    with open_store(recorded.db, create=False) as store:
        cals = store.calibrations.list(res.session_id)
        s = store.samples.read(res.session_id, name="humerus")
        meta = store.sessions.get(res.session_id)["meta"]
    cps = [c for c in cals if c["kind"] == "neutral-checkpoint"]
    [cal] = [c for c in cals if c["kind"] == "imu-alignment"]
    # every window of the patient's schedule that ended during the recording, none other
    end = float(s["device_t"].max()) - rig.device_t0
    expected = limb.neutral_windows(end)
    assert len(expected) == 5
    assert res.neutral_checkpoints == len(cps) == len(expected) == meta["neutral_checkpoints"]
    got = np.array([c["data"]["window"] for c in cps])
    # on the samples' clock (device time, as the protocol windows): patient time + device_t0
    assert all(c["data"]["time"] == "device_t" for c in cps)
    np.testing.assert_allclose(got, expected + rig.device_t0, atol=1e-9)
    # the patient held the neutral pose there: the limb axis close to +X
    assert all(c["residual_deg"] is not None and c["residual_deg"] < 5.0 for c in cps)
    # the protocol's windows on the same clock
    origin = cal["data"]["protocol"]["origin"]
    assert origin["time"] == "device_t"
    assert origin["t0"] == pytest.approx(rig.device_t0 + limb.protocol_start_s, abs=1e-9)
    # the clinician was told, and the summary counts them
    msgs = recorded.shown.messages
    assert sum("return to the neutral pose" in m for m in msgs) == len(expected)
    assert f"neutral checkpoints marked: {len(expected)}" in msgs
    progress = [ln for ln in recorded.lines if ln.startswith("[")]
    assert f" neutral={len(expected)} " in progress[-1]


def test_read_path_applies_them_and_the_twist_error_drops(recorded):
    res, limb, rig = recorded.res, recorded.limb, recorded.rig
    with open_store(recorded.db, create=False) as store:
        on = joint_orientations_from_store(store, res.session_id)
        off = joint_orientations_from_store(store, res.session_id, heading=False)
        s = store.samples.read(res.session_id, name="humerus")
    hc = on.provenance["heading_correction"]
    assert hc["neutral_checkpoints"] == 5 and hc["accepted"] >= 4
    assert hc["anchored"] is True and hc["clock"] == "device_t"
    assert hc["drift_model"]["method"] == "gp"  # 5 checkpoints + the anchor: the process
    assert len(hc["rejected"]) == 5 - hc["accepted"]
    assert "heading_correction" not in off.provenance
    # paired one to one with the truth at the same instants
    truth = limb.joint(np.sort(s["device_t"]) - rig.device_t0)
    assert len(on.q) == len(off.q) == len(truth)
    ok = (np.asarray(on.status).astype(np.int64) >> 6) >= 2

    def twist_err(q):
        return np.abs(np.degrees(Q.wrap_angle(Q.twist_angle(q, X) - Q.twist_angle(truth, X))))

    e_on, e_off = twist_err(on.q)[ok], twist_err(off.q)[ok]
    # measured on this recording: median 3.3° without, 1.2° with
    assert np.median(e_on) < 2.0
    assert np.median(e_on) < 0.6 * np.median(e_off)
    assert np.sqrt(np.mean(e_on**2)) < np.sqrt(np.mean(e_off**2))
    # the session's stored range of motion came through the corrected read path
    assert recorded.res.rom is not None


def test_live_panel_shows_the_count():
    from rich.console import Console

    from rig.record.display import render

    console = Console(file=io.StringIO(), width=120)
    console.print(render(RecordStatus(patient="P", phase="recording — return to neutral",
                                      checkpoints=3)))
    text = console.file.getvalue()
    assert "neutral checkpoints 3" in text and "return to neutral" in text


def _batch(t: np.ndarray) -> SampleBatch:
    n = len(t)
    return SampleBatch(t, np.full(n, np.nan), np.array(["humerus"] * n, object),
                       np.array(["sensor"] * n, object), np.tile([1.0, 0, 0, 0], (n, 1)),
                       np.full(n, 0xFF, np.int64))


def test_hardware_enter_marks_a_one_second_window_of_sample_time():
    rig = types.SimpleNamespace(kind="imu", simulated=False, patients=[])
    r, w = os.pipe()
    shown = CountingDisplay()
    with os.fdopen(r, "r") as stdin:
        cps = NeutralCheckpoints(rig, display=shown, stdin=stdin)
        assert cps.active
        cps.begin()
        assert any("press Enter" in m for m in shown.messages)
        os.write(w, b"\n")
        os.close(w)  # EOF after the press: the reader counts it, then ends
        cps._reader.join()
        t = np.arange(100.0, 100.5, 0.01)
        assert cps.feed(_batch(t), np.tile([1.0, 0, 0, 0], (len(t), 1)), t) == []
        t_press = float(t[-1])
        done = []
        for k in range(1, 5):  # bounded: the window ends 1 s of sample time later
            t = t_press + np.arange(0.01, 0.51, 0.01) + 0.5 * (k - 1)
            q = Q.from_axis_angle(np.array([0.0, 0.0, 1.0]), np.full(len(t), np.radians(3.0)))
            done += cps.feed(_batch(t), q, t)
        cps.close()
    [cp] = done
    assert cp.data == {"window": [t_press, t_press + 1.0], "time": "t"}
    assert cp.residual_deg == pytest.approx(3.0, abs=1e-6)
    assert cps.count == 1


def test_inactive_without_a_schedule_or_on_a_servo_rig():
    servo = types.SimpleNamespace(kind="servo", simulated=False, patients=[])
    assert not NeutralCheckpoints(servo, display=CountingDisplay()).active
    limb = types.SimpleNamespace(neutral_every_s=0.0, neutral_windows=lambda t: np.empty((0, 2)))
    sim = types.SimpleNamespace(kind="imu", simulated=True, patients=[limb])
    assert not NeutralCheckpoints(sim, display=CountingDisplay()).active
    old = types.SimpleNamespace(kind="imu", simulated=True, patients=[object()])  # before A
    assert not NeutralCheckpoints(old, display=CountingDisplay()).active


def test_the_heading_uncertainty_is_measured_and_without_checkpoints_it_is_said(recorded):
    # the read path passes the heading correction's own uncertainty to the extractor as the
    # measured slow error; read without the correction, the drift is neither removed nor
    # measured, and the facts say so
    res = recorded.res
    with open_store(recorded.db, create=False) as store:
        on = joint_orientations_from_store(store, res.session_id)
        off = joint_orientations_from_store(store, res.session_id, heading=False)
    u = on.provenance["heading_correction"]["uncertainty_deg"]
    assert 0.0 < u < 5.0 and on.slow_error_deg == u
    assert not on.facts().unmeasured_drift
    assert off.slow_error_deg is None and off.facts().unmeasured_drift
    assert any("neutral checkpoint" in w for w in off.facts().warnings())
