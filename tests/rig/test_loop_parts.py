"""Scheduler, target sources, telemetry and model binding of the live loop (no devices)."""

from __future__ import annotations

import csv
import math

import numpy as np
import pytest

from models import quaternion as Q
from models.constraint import JointConstraint
from models.oracle import ConstraintOracle
from models.shapes import load_shape
from rig.errors import RigConfigError
from rig.loop import (
    COLUMNS,
    CsvTrajectory,
    ModelBindingError,
    Scheduler,
    ScriptedTargets,
    Telemetry,
    bind_model,
    open_targets,
)
from rig.loop.runner import SETTLE_S, settled_rows
from rig.loop.targets import load_trajectory
from rig.sim.clock import ManualClock


# --------------------------------------------------------------------------- scheduler
def test_scheduler_deadlines_are_absolute_and_drift_free():
    clk = ManualClock(10.0)
    # every sleep oversleeps by 0.1 ms and every cycle works 1 ms: neither accumulates
    s = Scheduler(200.0, clock=clk, sleep=lambda dt: clk.sleep(dt + 0.0001), spin_s=0.0)
    t0 = s.start()
    for k in range(1000):
        cycle, due, start = s.wait()
        assert cycle == k and due == pytest.approx(t0 + k * 0.005, abs=1e-9)
        # cycle 0 is due at once; every later one is late by one oversleep, never more
        assert start - due == pytest.approx(0.0 if k == 0 else 0.0001, abs=1e-9)
        clk.advance(0.001)
        assert not s.finish()
    # after 1000 cycles the deadline is exactly t0 + 1000 T: nothing accumulated
    cycle, due, _ = s.wait()
    assert due == pytest.approx(t0 + 5.0, abs=1e-9)
    assert s.overruns == 0


def test_scheduler_overrun_skips_missed_deadlines_without_a_burst():
    clk = ManualClock()
    s = Scheduler(100.0, clock=clk, sleep=clk.sleep, spin_s=0.0)
    s.start()
    s.wait()
    clk.advance(0.035)  # cycle 0 takes 3.5 periods
    assert s.finish()
    cycle, due, start = s.wait()
    # deadlines 1 and 2 are dropped; cycle 3 (due 0.03, passed last) runs at once, late
    assert cycle == 3 and s.skipped == 2 and s.overruns == 1
    assert start - due == pytest.approx(0.005, abs=1e-9)
    assert not s.finish()
    cycle, due, start = s.wait()
    assert cycle == 4 and start == pytest.approx(due)  # back on schedule


def test_scheduler_calls_before_its_lead_ahead_of_the_deadline_and_only_with_time_left():
    clk = ManualClock()
    s = Scheduler(100.0, clock=clk, sleep=clk.sleep, spin_s=0.0)
    s.start()
    calls = []
    s.wait(lambda: calls.append(clk()), 0.002)  # cycle 0 is due at once: no time left
    assert calls == [] and not s.finish()
    cycle, due, start = s.wait(lambda: calls.append(clk()), 0.002)
    assert cycle == 1 and calls == [pytest.approx(due - 0.002)] and start == pytest.approx(due)
    clk.advance(0.009)  # cycle 1 works 9 ms: 1 ms left before cycle 2, less than the lead
    assert not s.finish()
    cycle, _, _ = s.wait(lambda: calls.append(clk()), 0.002)
    assert cycle == 2 and len(calls) == 1


def test_scheduler_rejects_a_bad_rate():
    with pytest.raises(ValueError, match="rate"):
        Scheduler(0.0)


# --------------------------------------------------------------------------- CSV targets
def _write(path, text):
    path.write_text(text)
    return path


def test_csv_trajectory_zero_order_hold_against_the_loop_clock(tmp_path):
    p = _write(tmp_path / "t.csv", "t_s,w,x,y,z\n0.0,1,0,0,0\n0.5,0,1,0,0\n1.0,nan,0,0,0\n")
    src = CsvTrajectory(p)
    assert src.duration_s == 1.0
    src.start(100.0)
    assert src.latest(99.9) == (None, None)
    t, q = src.latest(100.2)
    assert q.shape == (1, 4) and q.dtype == np.float64  # one joint's posture: (1, 4)
    assert q.tolist() == [[1.0, 0.0, 0.0, 0.0]] and t == 100.2  # fresh while it runs
    t, q = src.latest(100.7)
    assert q.tolist() == [[0.0, 1.0, 0.0, 0.0]]
    t, q = src.latest(101.5)  # after the last row the target ages from its time
    assert math.isnan(q[0, 0]) and t == 101.0


def test_csv_trajectory_in_isb_frames_is_the_same_motion_in_rig_frames(tmp_path):
    from calibration.frames import joint_to_rig
    from models import quaternion as Q

    rng = np.random.default_rng(4)
    q_isb = Q.random_quaternions(3, rng)
    rows = "".join(f"{0.1 * k},{','.join(repr(float(v)) for v in row)}\n"
                   for k, row in enumerate(q_isb))
    p = _write(tmp_path / "isb.csv", "t_s,w,x,y,z\n" + rows + "0.3,nan,0,0,0\n")
    src = CsvTrajectory(p, frames="isb")
    src.start(0.0)
    _, q = src.latest(0.15)
    q = q[0]
    np.testing.assert_allclose(q, joint_to_rig(q_isb[1], "isb"), atol=1e-12)
    # the same joint orientation: the limb's long axis (-Y in ISB) lands on the rig's +X
    np.testing.assert_allclose(Q.rotate(np.array(q), np.array([1.0, 0.0, 0.0])),
                               Q.rotate(q_isb[1], np.array([0.0, -1.0, 0.0])) @ np.array(
                                   [[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]),
                               atol=1e-12)
    _, q = src.latest(0.35)
    assert math.isnan(q[0, 0])  # an invalid row stays invalid for the supervisor
    with pytest.raises(RigConfigError, match="--frames applies to a targets file"):
        open_targets("script:sweep", oracle=ConstraintOracle(load_shape("original")),
                     frames="isb")


@pytest.mark.parametrize(("text", "message"), [
    ("", "empty file"),
    ("t,w,x,y,z\n0,1,0,0,0\n", "missing column(s) t_s"),
    ("t_s,w,x,y,z\n0,1,0,0,0\n0.1,1,zero,0,0\n", ":3: not a number"),
    ("t_s,w,x,y,z\n0.2,1,0,0,0\n0.1,1,0,0,0\n", ":3: t_s goes back in time"),
    ("t_s,w,x,y,z\n0,1,0,0\n", ":2: expected 5 columns"),
    ("t_s,w,x,y,z\n", "no rows"),
    ("t_s,w,x,y,z\ninf,1,0,0,0\n", ":2: t_s must be finite"),
])
def test_csv_trajectory_errors_name_the_line(tmp_path, text, message):
    p = _write(tmp_path / "bad.csv", text)
    with pytest.raises(RigConfigError) as err:
        load_trajectory(p)
    assert message in str(err.value) and str(p) in str(err.value)


def test_open_targets_forms_and_errors(tmp_path):
    oracle = ConstraintOracle(load_shape("original"))
    p = _write(tmp_path / "t.csv", "t_s,w,x,y,z\n0,1,0,0,0\n")
    assert isinstance(open_targets(str(p), oracle=oracle), CsvTrajectory)
    src = open_targets("script:sweep?seed=3&period_s=2", oracle=oracle)
    assert isinstance(src, ScriptedTargets) and src.period_s == 2.0
    with pytest.raises(RigConfigError, match="unknown script"):
        open_targets("script:dance", oracle=oracle)
    with pytest.raises(RigConfigError, match="unknown key 'speed'"):
        open_targets("script:slow?speed=2", oracle=oracle)
    with pytest.raises(RigConfigError, match=r"expected PATH\.csv"):
        open_targets("nowhere", oracle=oracle)
    with pytest.raises(FileNotFoundError):
        open_targets(str(tmp_path / "missing.csv"), oracle=oracle)
    with pytest.raises(RigConfigError, match="no sensors to mirror"):
        from rig.devices.config import load_rig_config

        open_targets("mirror", oracle=oracle, rig=load_rig_config("sim-shoulder"))
    # issue 37: a leg's sensors are no shoulder's targets (refused before any port opens)
    with pytest.raises(RigConfigError, match="rig 'sim-leg' wears its sensors on the right "
                                             "hip, rig 'sim-shoulder' drives the right shoulder"):
        open_targets("mirror:sim-leg", oracle=oracle, rig=load_rig_config("sim-shoulder"))


# --------------------------------------------------------------------------- scripts
@pytest.mark.parametrize("shape", ["original", "c-shape"])
def test_slow_script_stays_well_inside(shape):
    oracle = ConstraintOracle(load_shape(shape))
    src = ScriptedTargets("slow", oracle, period_s=4.0)
    src.start(0.0)
    q = np.array([src.latest(t)[1][0] for t in np.linspace(0, 4, 400)])
    d = oracle.signed_distance(q)
    assert (d < -math.radians(1.0)).all()
    step = np.degrees(Q.angle(Q.multiply(q[1:], Q.conjugate(q[:-1]))))
    assert step.max() < 5.0  # a smooth path


def test_sweep_script_leaves_the_region_and_comes_back():
    oracle = ConstraintOracle(JointConstraint.cone((1, 0, 0), 40.0, name="c40"))
    src = ScriptedTargets("sweep", oracle, period_s=1.0)
    src.start(0.0)
    d = np.degrees(oracle.signed_distance(np.array([src.latest(t)[1][0]
                                                    for t in np.linspace(0, 12, 1200)])))
    assert d.max() > 25.0 and d.min() < -30.0


def test_adversarial_script_has_every_kind():
    c = load_shape("original")
    oracle = ConstraintOracle(JointConstraint.polygon(c.swing.vertices, c.swing.interior,
                                                      twist=(-45, 70), name="o+t"))
    src = ScriptedTargets("adversarial", oracle, seed=2, segment_s=0.1)
    src.start(0.0)
    seen: dict[str, list] = {}
    for t in np.arange(0, 2.0, 0.005):
        tt, q = src.latest(t)
        seen.setdefault(src.segment(t), []).append((t, tt, q[0]))
    assert set(seen) == {"far", "discontinuity", "twist", "invalid", "stale", "valid_jump"}
    far = np.array([q for _, _, q in seen["far"]])
    assert (oracle.signed_distance(far) > math.radians(30)).all()
    # discontinuity: consecutive targets ≤ ~1.5° apart with exact projections ≥ 10° apart
    pairs = np.array([q for _, _, q in seen["discontinuity"]])
    proj = oracle.project(pairs)
    near = np.degrees(Q.angle(Q.multiply(pairs[1:], Q.conjugate(pairs[:-1])))) < 1.6
    jump = np.degrees(Q.angle(Q.multiply(proj[1:], Q.conjugate(proj[:-1])))) > 10
    assert (near & jump).sum() >= 5
    tw = np.array([q for _, _, q in seen["twist"]])
    assert (oracle.signed_distance(tw) > math.radians(15)).all()
    bad = [q for _, _, q in seen["invalid"]]
    assert all(not (np.isfinite(q).all() and abs(np.linalg.norm(q) - 1) < 0.02) for q in bad)
    assert all(tt < t - 0.5 for t, tt, _ in seen["stale"])


# --------------------------------------------------------------------------- telemetry
def test_telemetry_csv_and_store_rows(tmp_path):
    class Sink:
        def __init__(self):
            self.rows, self.closed = [], False

        def add_many(self, rows):
            self.rows.extend(rows)

        def close(self):
            self.closed = True

    sink = Sink()
    tel = Telemetry(tmp_path / "t.csv", sink, keep=True)
    n = 5000  # more than two chunks
    for k in range(n):
        row = [float(k)] * len(COLUMNS)
        row[COLUMNS.index("faults")] = 3 if k == 7 else 0
        tel.record(tuple(row))
    tel.close()
    with open(tmp_path / "t.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == n and list(rows[0]) == list(COLUMNS)
    assert rows[4321]["t_s"] == "4321" and rows[7]["faults"] == "3"
    assert len(sink.rows) == n and sink.closed
    assert sink.rows[7]["fault"] == "read_retry|read_timeout" and sink.rows[8]["fault"] is None
    table = tel.table()
    assert table["cycle"].dtype == np.int64 and len(table["cycle"]) == n
    assert len(tel.cycle_ms()) == n


# --------------------------------------------------------------------------- binding
class _FakeModel:
    """Stands in for CorrectionModel: binding only reads ``path`` and ``constraint_yaml``."""

    def __init__(self, constraint):
        self.path = "m.onnx"
        self.constraint_yaml = constraint.to_yaml()


def _rig(joint="shoulder", side="right", constraint="original"):
    from rig.devices.config import load_rig_config

    rig = load_rig_config("sim-shoulder")
    import dataclasses

    return dataclasses.replace(rig, joint=dataclasses.replace(rig.joint, name=joint, side=side),
                               constraint=constraint)


def test_binding_authority_and_refusals():
    orig = load_shape("original")
    cone = JointConstraint.cone((1, 0, 0), 50.0, name="c50")
    b = bind_model(_FakeModel(orig), rig=_rig())
    assert b.constraint == orig and "rig" in b.source and not b.mismatches
    # the rig says 'original', the model was made for a cone
    with pytest.raises(ModelBindingError, match="differs from rig"):
        bind_model(_FakeModel(cone), rig=_rig())
    b = bind_model(_FakeModel(cone), rig=_rig(), force=True)
    assert b.constraint == orig and b.mismatches  # still enforces the rig's constraint
    # an explicit constraint outranks the rig's
    b = bind_model(_FakeModel(cone), rig=_rig(), constraint=cone)
    assert b.constraint == cone and not b.mismatches
    # joint / side / patient
    elbow = JointConstraint.cone((1, 0, 0), 50.0, name="c50", joint="elbow")
    with pytest.raises(ModelBindingError, match="joint 'elbow'"):
        bind_model(_FakeModel(elbow), rig=_rig(), constraint=cone)
    left = JointConstraint.cone((1, 0, 0), 50.0, name="c50", side="left")
    with pytest.raises(ModelBindingError, match="left side"):
        bind_model(_FakeModel(left), rig=_rig(), constraint=cone)
    p7 = JointConstraint.cone((1, 0, 0), 50.0, name="c50", patient="P-7")
    with pytest.raises(ModelBindingError, match="patient 'P-7'"):
        bind_model(_FakeModel(p7), rig=_rig(constraint=None), session_constraint=cone,
                   session_id=3, session_patient="P-8")
    # another patient's model with other limits: the refusal speaks of the patients
    with pytest.raises(ModelBindingError) as err:
        bind_model(_FakeModel(p7), rig=_rig(constraint=None), session_constraint=orig,
                   session_id=3, session_patient="P-8")
    assert "model is for patient 'P-7', session 3 is patient 'P-8'" in str(err.value)
    b = bind_model(_FakeModel(p7), rig=_rig(constraint=None), session_constraint=orig,
                   session_id=3, session_patient="P-8", force=True)
    assert any("'c50' of patient 'P-7'" in m and "of patient 'P-8'" in m for m in b.mismatches)
    # no rig constraint: the model's own is enforced
    b = bind_model(_FakeModel(cone), rig=_rig(constraint=None))
    assert b.constraint == cone and b.source == "the model's embedded constraint"


def test_a_constraint_for_another_joint_is_refused_even_with_force_model():
    """Issue 37, case 1: a knee file enforced on the shoulder rig with --force-model. The model
    may be forced; what the rig drives may not: a file named for another joint or side, or a
    hinge's limits standing for a ball joint, is refused whatever its source."""
    shoulder = JointConstraint.cone((1, 0, 0), 50.0, name="c50", joint="shoulder",
                                    side="right")
    knee = JointConstraint.hinge_joint((0, 0, 1), 0.0, 140.0, name="p42-knee", joint="knee")
    unnamed_hinge = JointConstraint.hinge_joint((0, 0, 1), 0.0, 140.0, name="h")
    left = JointConstraint.cone((1, 0, 0), 50.0, name="c50", side="left")
    for enforced, why in ((knee, "is for the knee, not the shoulder"),
                          (unnamed_hinge, "holds hinge limits, but the shoulder is a ball joint"),
                          (left, "is for the left side, not the right")):
        for kw in ({"constraint": enforced}, {"session_constraint": enforced, "session_id": 4}):
            with pytest.raises(ModelBindingError, match=why) as err:
                bind_model(_FakeModel(shoulder), rig=_rig(), force=True, **kw)
            assert "rig 'sim-shoulder' drives the right shoulder" in str(err.value)
    # with nothing else given, the model's own constraint is the one enforced: checked alike
    with pytest.raises(ModelBindingError, match="is for the knee"):
        bind_model(_FakeModel(knee), rig=_rig(constraint=None), force=True)


def test_tracking_counts_a_held_target_once_the_rate_limits_let_it_arrive():
    """A limb's summary tracks valid targets held still: a row counts once the target has been
    held the trapezoid's time from where the joint stood plus the settle time, never while the
    target moves."""
    t = np.arange(400) * 0.005
    target = np.zeros((400, 2, 4))
    target[..., 0] = 1.0
    # a 60° jump of joint 0 at row 100, held to the end; joint 1 still
    jumped = Q.from_axis_angle(np.array([0.0, 0.0, 1.0]), np.radians(60.0))
    target[100:, 0] = jumped
    present = target.copy()
    present[100:, 0] = [1.0, 0.0, 0.0, 0.0]  # where it stood when the target appeared
    ok = settled_rows(t, target, present, vmax_deg_s=np.array([120.0, 120.0]),
                      amax_deg_s2=np.array([1200.0, 1200.0]))
    need = 60.0 / 120.0 + 120.0 / 1200.0 + SETTLE_S  # 0.9 s after row 100
    first = int(np.argmax(ok[100:])) + 100
    assert abs((t[first] - t[100]) - need) < 0.0051
    assert not ok[100:first].any() and ok[first:].all()
    # before the jump the posture was held from row 0 at no distance: counted after SETTLE_S
    assert ok[int(np.ceil((SETTLE_S + 0.1) / 0.005)):100].all() and not ok[:50].any()
    # a target that changes every row is never settled
    moving = target.copy()
    moving[:, 1, 0] = np.cos(np.linspace(0, 1, 400))
    moving[:, 1, 3] = np.sin(np.linspace(0, 1, 400))
    assert not settled_rows(t, moving, present, vmax_deg_s=np.array([120.0, 120.0]),
                            amax_deg_s2=np.array([1200.0, 1200.0])).any()
