"""The report of a real (small) recorded session: assembled from the store, written by
``rig report``, drawn by headless Chromium."""

from __future__ import annotations

import io
import re
from dataclasses import replace

import pytest

from models.constraint import dump_constraint
from rig.cli import main
from rig.demo.joint import SIZES, patient_constraint, write_rig_configs
from rig.loop import EnforceRequest, run_enforce
from rig.record import PlainDisplay, RecordOptions, record_session
from rig.report.session import report_data_for_session
from rig.store import SampleWriter, open_store
from rig.training import TrainRequest, run_train
from tests.rig.browser import dark_fraction, pixels_near, screenshot

# the module-scoped recording is made once: its tests run on one xdist worker
pytestmark = pytest.mark.xdist_group("test_report_session")


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """A 6 s servo-limb recording (patient time ×10: the static calibration window is 0.4 s
    of host time, so a pause of the loaded host does not empty it), its boundary
    (``rig boundary``), a model (``rig train``) and a 1 s enforcement run (``rig enforce``), in
    one temp store."""
    tmp = tmp_path_factory.mktemp("report")
    truth = patient_constraint()
    dump_constraint(truth, tmp / "patient.yaml")
    rigs = write_rig_configs(tmp, tmp / "patient.yaml", 5,
                             replace(SIZES["quick"], servo_time_scale=10.0))
    db = tmp / "rig.db"
    res = record_session(RecordOptions(rig=str(rigs["sim-shoulder"]), db=str(db),
                                       patient="P-REPORT", duration_s=6.0,
                                       source_options={"rate_hz": 200.0}),
                         display=PlainDisplay(io.StringIO()))
    sid = res.session_id
    with pytest.raises(SystemExit) as info:
        main(["boundary", "--db", str(db), "--session", str(sid), "--out",
              str(tmp / "boundary.yaml")])
    assert info.value.code == 0
    run_train(TrainRequest(tmp / "model.onnx", constraint=str(tmp / "boundary.yaml")))
    with open_store(db) as store:
        store.models.add(tmp / "model.onnx", session_id=sid)
        empty = store.sessions.start(store.patients.ensure("P-EMPTY"), kind="record")
        store.sessions.end(empty)
    code = run_enforce(EnforceRequest(rig=str(rigs["sim-shoulder-live"]),
                                      model=str(tmp / "model.onnx"), targets="script:adversarial",
                                      duration_s=1.0, db=str(db), session_id=sid)).exit_status
    assert code in (0, 1)  # 1: a safe state on a loaded machine; the run is stored either way
    return {"tmp": tmp, "db": db, "session": sid, "empty": empty, "truth": truth}


def test_report_data_comes_from_the_store(recorded):
    with open_store(recorded["db"]) as store:
        data = report_data_for_session(store, recorded["session"], reference=recorded["truth"],
                                       age=45, sex="female", eval_n=600)
        enf = next(s for s in store.sessions.list() if s["kind"] == "enforce")
        enforce_view = report_data_for_session(store, enf["id"], eval_n=600)
    assert data.patient == "P-REPORT" and data.side == "right" and data.samples > 100
    rows = {r.movement: r for r in data.rom_rows}
    assert rows["Flexion"].aaos_deg == 180.0 and rows["Flexion"].measured_deg > 0
    assert rows["Abduction"].population.startswith("152 (women, 45-49)")
    # rotations measured with the arm at the side are not compared with AAOS (at 90° abduction)
    rot = rows["External rotation (arm at side)"]
    assert rot.aaos_deg is None and "90° abduction" in rot.note
    # a 4 s simulated recording: said to be simulated, and too short to cover the range
    assert data.simulated
    assert any("coverage" in w for w in data.warnings)
    assert "of 12 directions explored" in data.boundary_facts["coverage of the range"]
    assert data.boundary_png[:8] == b"\x89PNG\r\n\x1a\n"
    assert data.boundary_facts["joint orientations"] == data.samples
    assert data.boundary_facts["mean distance to reference (°)"] < 5.0
    # the model registered with the session is found and evaluated
    assert data.model_metrics["held-out orientations"] == 600
    assert data.model_verdict.startswith(("ok", "warning"))
    assert data.error_map_png[:8] == b"\x89PNG\r\n\x1a\n"
    # the run of the enforce session that names this recording
    assert data.enforcement["cycles"] > 0
    assert data.enforcement["max violation of the boundary (°)"] <= data.enforcement[
        "tolerance (°)"]
    assert data.enforcement_verdict.startswith("ok")
    # an enforce session's own report: its run, and its recording session's range of motion
    assert enforce_view.enforcement["cycles"] == data.enforcement["cycles"]
    assert [r.movement for r in enforce_view.rom_rows] == [r.movement for r in data.rom_rows]


def test_rig_report_leaves_out_sections_without_data(recorded, capsys):
    out = recorded["tmp"] / "empty.html"
    with pytest.raises(SystemExit) as info:
        main(["report", "--db", str(recorded["db"]), "--session", str(recorded["empty"]),
              "--out", str(out)])
    assert info.value.code == 0
    html = out.read_text()
    # only the reason there is nothing to show
    assert "P-EMPTY" in html and html.count("<h2>") == 1
    assert ">Range of motion</h2>" in html and "has no samples" in html


@pytest.mark.parametrize(("args", "match"), [
    (["--session", "999"], "no session 999"),
    (["--out", "/nonexistent-dir/r.html"], "does not exist"),
    (["--model", "/nonexistent.onnx"], "no such file"),
])
def test_rig_report_user_errors_are_one_line(recorded, args, match, capsys):
    base = {"--session": str(recorded["session"]), "--out": str(recorded["tmp"] / "x.html")}
    for k, v in zip(args[::2], args[1::2], strict=True):
        base[k] = v
    argv = ["report", "--db", str(recorded["db"])] + [x for kv in base.items() for x in kv]
    with pytest.raises(SystemExit) as info:
        main(argv)
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert err.startswith("rig: error: ") and err.count("\n") == 1 and match in err


def test_report_of_a_recorded_session_renders_in_headless_chromium(recorded):
    page = recorded["tmp"] / "report.html"
    with pytest.raises(SystemExit) as info:
        main(["report", "--db", str(recorded["db"]), "--session", str(recorded["session"]),
              "--out", str(page), "--reference", str(recorded["tmp"] / "patient.yaml")])
    assert info.value.code == 0
    html = page.read_text()
    for heading in ("Range of motion", "Recorded boundary", "Learned constraint model",
                    "Live enforcement"):
        assert f">{heading}</h2>" in html
    assert "Simulated patient" in html and "Warning: coverage" in html
    assert not re.search(r"""(src|href)=["'](https?:|//|file:)""", html)
    img = screenshot(page, recorded["tmp"], height=3000)
    assert dark_fraction(img) > 0.002  # text, tables and outlines
    # recorded samples and the error map's boundary are drawn, the swing map's anatomical
    # direction labels too
    assert pixels_near(img, "#4477aa", 0.15) > 50 and pixels_near(img, "#cc3311", 0.08) > 200
    assert pixels_near(img, "#762a83", 0.06) > 30
    # the "ok" verdict of the enforcement section is styled
    assert pixels_near(img, "#1b7837", 0.08) > 20


def test_a_report_says_why_it_has_no_range_and_when_a_session_was_cut_short(tmp_path):
    import numpy as np

    from rig.report.session import report_for_session
    from rig.sim.patients import record_servo, seeded_patient, star_constraint

    rec = record_servo(seeded_patient(7, star_constraint(7)), 60.0, 50.0)
    db = tmp_path / "r.db"
    with open_store(db) as store:
        pid = store.patients.add("P-CUT")
        # an IMU session recorded without the calibration steps
        raw = store.sessions.start(pid, rig_name="sim-imu", joint="shoulder", side="right")
        for name in ("thorax", "humerus"):
            store.samples.add_sensor(raw, name, segment=name, kind="sensor", port="sim://imu-stream")
        with SampleWriter(store, raw) as w:
            w.add_many(rec.t, rec.t, "thorax", "sensor", rec.thorax, 0xFF)
            w.add_many(rec.t, rec.t, "humerus", "sensor", rec.limb, 0xFF)
        store.sessions.end(raw, status="completed", meta={"simulated": True})
        # a servo session stopped by Ctrl-C
        cut = store.sessions.start(pid, rig_name="sim-shoulder", joint="shoulder", side="right")
        store.samples.add_sensor(cut, "shoulder", segment="humerus", kind="joint",
                                 port="sim://dynamixel")
        with SampleWriter(store, cut) as w:
            w.add_many(rec.t, None, "shoulder", "joint", rec.limb, 0)
        store.sessions.end(cut, status="interrupted", meta={"simulated": True})
        page = report_for_session(store, raw, tmp_path / "raw.html", eval_n=200)
        html = page.read_text()
        assert ">Range of motion</h2>" in html and "No range of motion" in html
        assert "without the calibration steps" in html
        data = report_data_for_session(store, cut, eval_n=200)
        assert any("cut short" in w and "'interrupted'" in w for w in data.warnings)
        assert data.rom_rows and np.isfinite(data.rom_rows[0].measured_deg)
        html = report_for_session(store, cut, tmp_path / "cut.html", eval_n=200).read_text()
        assert "Warning: the session was cut short" in html


def test_the_report_shows_the_evaluation_stored_with_the_model(recorded, tmp_path):
    """Issue 37: one model, two verdicts — the demo's evaluate stage judged one held-out set,
    the report drew another. The report now shows the evaluation registered with the model:
    its figures and the same verdict function's verdict."""
    import shutil

    from rig.training import EvaluateRequest, run_evaluate
    from rig.training.verdict import evaluation_record, evaluation_verdict

    db = tmp_path / "rig.db"
    for suffix in ("", "-wal", "-shm"):
        src = recorded["db"].with_name(recorded["db"].name + suffix)
        if src.exists():
            shutil.copy(src, db.with_name(db.name + suffix))
    model, sid = recorded["tmp"] / "model.onnx", recorded["session"]
    metrics = run_evaluate(EvaluateRequest(str(model), str(recorded["tmp"] / "boundary.yaml"),
                                           n=300, seed=7)).metrics
    with open_store(db) as store:
        mid = store.models.add(model, session_id=sid, metrics=evaluation_record(
            metrics, n=300, seed=7, by="rig evaluate"))
        data = report_data_for_session(store, sid, eval_n=600)
        assert data.model_metrics["held-out orientations"] == 300  # not a fresh 600
        assert data.model_metrics["p99 direction error (°)"] == metrics["p99_angular_error_deg"]
        assert data.model_metrics["mean 3-D error (%)"] == metrics["mean_3d_error_pct"]
        assert data.model_verdict == evaluation_verdict(metrics)[1]
        assert data.model_metrics["evaluation"] == (f"stored with model {mid} by rig evaluate: "
                                                    "300 held-out inputs, seed 7")
        # the stored verdict stands, whatever another held-out set would give
        missed = {**metrics, "p99_angular_error_deg": 5.3}
        store.models.add(model, session_id=sid, metrics=evaluation_record(
            missed, n=300, seed=7, by="rig evaluate"))
        data = report_data_for_session(store, sid, eval_n=600)
        assert data.model_verdict == evaluation_verdict(missed)[1]
        assert "p99 direction error 5.3° > 5°" in data.model_verdict
        # --model naming the registered file: its stored evaluation too
        named = report_data_for_session(store, sid, eval_n=600, model=model)
        assert named.model_verdict == data.model_verdict
        # a file with no stored evaluation is evaluated for the report, which says so
        shutil.copy(model, tmp_path / "other.onnx")
        other = report_data_for_session(store, sid, eval_n=600, model=tmp_path / "other.onnx")
    assert other.model_metrics["held-out orientations"] == 600
    assert other.model_metrics["evaluation"].startswith("drawn for this report: 600")


def test_a_model_for_another_joint_side_or_patient_is_refused(recorded, tmp_path, capsys):
    """Issue 37: a model bound to another joint, side or patient in a session's report."""
    from models.constraint import JointConstraint

    for kw, match in (({"joint": "hip"}, "is for the hip, not the shoulder"),
                      ({"side": "left"}, "is for the left side, not the right"),
                      ({"patient": "P-7"}, "is for patient 'P-7', not 'P-REPORT'")):
        c = JointConstraint.cone((1, 0, 0), 50.0, name="other", **kw)
        dump_constraint(c, tmp_path / "c.yaml")
        run_train(TrainRequest(tmp_path / "m.onnx", constraint=str(tmp_path / "c.yaml")))
        with pytest.raises(SystemExit) as info:
            main(["report", "--db", str(recorded["db"]), "--session", str(recorded["session"]),
                  "--model", str(tmp_path / "m.onnx"), "--out", str(tmp_path / "r.html")])
        err = capsys.readouterr().err
        assert info.value.code == 2 and match in err and err.count("\n") == 1, err
        assert not (tmp_path / "r.html").exists()
