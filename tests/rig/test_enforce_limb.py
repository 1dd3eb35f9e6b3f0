"""``rig enforce`` on a servo limb (issue 39): targets for a limb (CSV column groups, scripted
motions built from the limb's exact oracle, the mirror of a worn IMU limb), the binding's
refusals (one line, exit 2, before any device opens) and a short run of the simulated 7-servo
arm."""

from __future__ import annotations

import csv
import json
import math
import time
from pathlib import Path

import numpy as np
import pytest

from models import quaternion as Q
from models.constraint import JointConstraint, dump_constraint
from models.limb import Limb, dump_limb, load_limb
from models.limb_model import export_limb_model
from models.oracle import ConstraintOracle
from rig.cli import main
from rig.devices.config import load_rig_config
from rig.devices.sources import OrientationSample
from rig.errors import RigConfigError
from rig.loop.targets import (
    CsvTrajectory,
    MirrorTargets,
    ScriptedTargets,
    expected_header,
    load_trajectory,
    open_targets,
    valid_targets,
)
from rig.sim.patients import anatomical_limb

ROOT = Path(__file__).resolve().parents[2]
NAMES = ("shoulder", "elbow", "wrist")


@pytest.fixture(scope="module")
def arm():
    """The simulated servo arm's patient: a right arm, its elbow a forearm joint."""
    limb = anatomical_limb(3, "arm", kinds={"elbow": "forearm"})
    return limb, ConstraintOracle(limb)


@pytest.fixture(scope="module")
def files(tmp_path_factory, arm):
    d = tmp_path_factory.mktemp("enforce-limb")
    limb, _ = arm
    dump_limb(limb, d / "arm.yaml")
    export_limb_model(limb, d / "arm.onnx")  # the exact geometric graph: no training
    # a hinge elbow about another axis than the forearm elbow's flexion servo: not what the
    # rig's two servos drive (about +Z it is: rig.loop.binding.hinge_on_forearm)
    hinge = anatomical_limb(3, "arm").to_dict()
    hinge["joints"][1]["constraint"]["hinge"]["axis"] = [0.0, 0.6, 0.8]
    dump_limb(Limb.from_dict(hinge), d / "hinge-arm.yaml")
    dump_limb(anatomical_limb(3, "arm", "left", kinds={"elbow": "forearm"}), d / "left.yaml")
    dump_limb(anatomical_limb(3, "leg"), d / "leg.yaml")
    export_limb_model(anatomical_limb(5, "arm", kinds={"elbow": "forearm"}), d / "other.onnx")
    dump_constraint(JointConstraint.cone((1, 0, 0), 50.0, twist=(-40, 40), name="cone50"),
                    d / "cone.yaml")
    for src, out in ((d / "cone.yaml", "cone.onnx"), (ROOT / "models/shapes/original.yaml",
                                                      "orig.onnx")):
        with pytest.raises(SystemExit) as exc:
            main(["train", "--constraint", str(src), "--out", str(d / out)])
        assert exc.value.code == 0
    return d


def _csv(path, header, rows):
    path.write_text(",".join(header) + "\n" + "".join(",".join(str(v) for v in r) + "\n"
                                                      for r in rows))
    return path


# --------------------------------------------------------------------------- CSV
def test_a_limb_csv_has_a_column_group_per_joint_in_the_limb_files_order(tmp_path, arm):
    _limb, oracle = arm
    header = expected_header(NAMES)
    assert header[:5] == ["t_s", "shoulder_w", "shoulder_x", "shoulder_y", "shoulder_z"]
    assert header[-1] == "wrist_z" and len(header) == 13
    ident = [1, 0, 0, 0] * 3
    nan_row = [0.2] + [math.nan] * 12  # the supervisor holds: allowed in a file
    p = _csv(tmp_path / "arm.csv", header, [[0.0, *ident], [0.1, *([0.0, 1, 0, 0] * 3)],
                                            nan_row])
    t, q = load_trajectory(p, NAMES)
    assert t.tolist() == [0.0, 0.1, 0.2] and q.shape == (3, 3, 4)
    src = open_targets(str(p), oracle=oracle)
    assert isinstance(src, CsvTrajectory) and src.n_joints == 3 and src.joint_names == NAMES
    src.start(5.0)
    tt, posture = src.latest(5.15)
    assert tt == 5.15 and posture.shape == (3, 4) and posture.dtype == np.float64
    assert posture.tolist() == [[0.0, 1.0, 0.0, 0.0]] * 3


@pytest.mark.parametrize(("header", "message"), [
    (["t_s", "w", "x", "y", "z"], "a one-joint targets file (t_s,w,x,y,z) for a limb of 3"),
    (expected_header(NAMES)[:9], "missing column(s) wrist_w, wrist_x, wrist_y, wrist_z"),
    ([*expected_header(NAMES), "knee_w"], "unknown column(s) knee_w"),
    (["t_s", *expected_header(NAMES)[5:9], *expected_header(NAMES)[1:5],
      *expected_header(NAMES)[9:]], "columns out of order (joints elbow, shoulder, wrist"),
    (expected_header(NAMES)[:5] * 2 + expected_header(NAMES)[5:], "repeated column(s)"),
])
def test_a_bad_limb_csv_header_names_the_expected_one(tmp_path, header, message):
    p = _csv(tmp_path / "bad.csv", header, [[0.0] * len(header)])
    with pytest.raises(RigConfigError) as err:
        load_trajectory(p, NAMES)
    text = str(err.value)
    assert message in text and "expected a header t_s,shoulder_w," in text, text
    assert "shoulder, elbow, wrist" in text and "\n" not in text


def test_a_limb_csv_going_back_in_time_names_the_line(tmp_path):
    p = _csv(tmp_path / "t.csv", expected_header(NAMES), [[0.2] + [1, 0, 0, 0] * 3,
                                                          [0.1] + [1, 0, 0, 0] * 3])
    with pytest.raises(RigConfigError, match=r"t\.csv:3: t_s goes back in time"):
        load_trajectory(p, NAMES)


def test_one_joint_may_be_named_or_plain(tmp_path):
    p = _csv(tmp_path / "named.csv", ["t_s", "elbow_w", "elbow_x", "elbow_y", "elbow_z"],
             [[0.0, 1, 0, 0, 0]])
    _, q = load_trajectory(p, ("elbow",))
    assert q.shape == (1, 1, 4)
    _, q = load_trajectory(_csv(tmp_path / "plain.csv", ["t_s", "w", "x", "y", "z"],
                                [[0.0, 1, 0, 0, 0]]), ("elbow",))
    assert q.shape == (1, 1, 4)


# --------------------------------------------------------------------------- scripts
def test_slow_limb_script_stays_inside_every_joint(arm):
    _, oracle = arm
    src = ScriptedTargets("slow", oracle, seed=1, period_s=2.0)
    assert src.n_joints == 3 and src.joint_names == NAMES
    src.start(0.0)
    ts = np.arange(0.0, 8.0, 0.01)
    p = np.array([src.latest(t)[1] for t in ts])
    assert p.shape == (len(ts), 3, 4)
    d = oracle.signed_distance(p)
    # the way is checked 1° inside; a forearm elbow's posture between two of the path's points
    # is off its two axes by a rounding error (its distance: that error, not its depth)
    assert (d[:, [0, 2]] < -math.radians(0.9)).all() and (d[:, 1] < 1e-6).all()
    step = np.degrees(Q.angle(Q.multiply(p[1:], Q.conjugate(p[:-1])))).max()
    assert step < 3.0  # smooth
    assert valid_targets(oracle, p).all()


def test_sweep_limb_script_leaves_the_limits_and_comes_back(arm):
    _, oracle = arm
    src = ScriptedTargets("sweep", oracle, seed=1, period_s=1.0)
    src.start(0.0)
    p = np.array([src.latest(t)[1] for t in np.arange(0.0, 12.0, 0.01)])
    d = np.degrees(oracle.signed_distance(p).max(axis=1))
    assert d.max() > 15.0 and (d <= 0).mean() > 0.2


def test_adversarial_limb_script_has_every_segment(arm):
    limb, oracle = arm
    src = ScriptedTargets("adversarial", oracle, seed=2, segment_s=0.5, hold_s=0.2)
    assert set(src.kinds) == {"far", "coupled_source", "discontinuity", "coupled_dependent",
                              "invalid", "stale", "valid_jump"}
    src.start(10.0)
    seen: dict[str, list] = {}
    for t in np.arange(10.0, 10.0 + 8 * 0.5, 0.005):  # each segment once
        tt, p = src.latest(t)
        assert p.shape == (3, 4)
        seen.setdefault(src.segment(t), []).append((t, tt, p.copy()))
    far = np.array([p for *_, p in seen["far"]])
    assert (oracle.signed_distance(far).max(axis=1) > math.radians(30)).all()
    bad = np.array([p for *_, p in seen["invalid"]])
    assert not valid_targets(oracle, bad).any()
    assert all(tt < t - 0.5 for t, tt, _ in seen["stale"])
    jumps = np.array([p for *_, p in seen["valid_jump"]])
    assert valid_targets(oracle, jumps).all()
    # the coupled segments: a valid posture, then one joint moves until the shoulder alone is
    # outside — the elbow (its source) or the shoulder itself
    shoulder, elbow = 0, 1
    assert limb.joints[shoulder].coupling.by == "elbow"
    for kind, moving in (("coupled_source", elbow), ("coupled_dependent", shoulder)):
        p = np.array([p for *_, p in seen[kind]])
        d = oracle.signed_distance(p)
        assert (d[0] <= 0).all() and d[-1, shoulder] > math.radians(3), kind
        assert (d[-1, [elbow, 2]] <= 0).all(), kind
        still = [j for j in range(3) if j != moving]
        assert np.array_equal(p[0][still], p[-1][still]), kind
        assert not np.allclose(p[0][moving], p[-1][moving]), kind
    # valid, steady targets exist (the tracking figure's cycles), none in invalid or stale
    ts = np.arange(10.0, 18.0, 0.005)
    steady = np.array([src.steady(t, settle_s=0.1) for t in ts])
    valid = valid_targets(oracle, np.array([src.latest(t)[1] for t in ts]))
    assert (steady & valid).any()
    assert not any(src.steady(t) for t, _, _ in seen["invalid"] + seen["stale"])


def test_limb_scripts_are_seeded(arm):
    _, oracle = arm
    a = ScriptedTargets("adversarial", oracle, seed=4)
    b = ScriptedTargets("adversarial", oracle, seed=4)
    a.start(0.0)
    b.start(0.0)
    for t in np.arange(0.0, 8.0, 0.05):
        np.testing.assert_array_equal(a.latest(t)[1], b.latest(t)[1])


def test_one_joints_scripts_return_a_posture_of_one_joint():
    from models.shapes import load_shape

    oracle = ConstraintOracle(load_shape("original"))
    src = ScriptedTargets("slow", oracle)
    src.start(0.0)
    _, p = src.latest(0.3)
    assert p.shape == (1, 4) and src.n_joints == 1 and src.joint_names is None
    assert valid_targets(oracle, p[None]).all()


# --------------------------------------------------------------------------- mirror
class _Samples:
    """An orientation source of canned batches (what a worn IMU set delivers)."""

    def __init__(self, batches):
        self.batches = list(batches)
        self.dropped = 0

    def read(self, timeout):
        if self.batches:
            return self.batches.pop(0)
        time.sleep(timeout)
        return []

    def close(self):
        pass


def test_mirror_of_a_limb_composes_every_joint_from_its_segments(arm):
    rng = np.random.default_rng(7)
    segs = ("thorax", "upper-arm", "forearm", "hand")
    q = Q.random_quaternions(4, rng)
    samples = [OrientationSample(t=1.0 + 0.001 * k, device_t=None, name=s, kind="sensor",
                                 q=q[k], status=0) for k, s in enumerate(segs)]
    src = MirrorTargets(_Samples([samples[:2], samples[2:]]),
                        joints=[("thorax", "upper-arm"), ("upper-arm", "forearm"),
                                ("forearm", "hand")], joint_names=NAMES,
                        clock=lambda: 0.0)
    try:
        src.start(0.0)
        for _ in range(400):  # the reader thread: wait for its posture, not for a time
            if src.latest(0.0)[0] is not None:
                break
            time.sleep(0.005)
        t, p = src.latest(0.0)
    finally:
        src.close()
    assert p.shape == (3, 4) and t == pytest.approx(1.0)  # the oldest segment's time
    want = Q.multiply(Q.conjugate(q[:3]), q[1:])
    np.testing.assert_allclose(p, want, atol=1e-12)


def test_a_limb_mirror_needs_a_rig_worn_on_that_limb(arm, files):
    _, oracle = arm
    rig = load_rig_config("sim-servo-arm")
    with pytest.raises(RigConfigError, match="rig 'sim-servo-arm' has no sensors to mirror"):
        open_targets("mirror", oracle=oracle, rig=rig)
    with pytest.raises(RigConfigError, match="rig 'sim-leg' wears its sensors on the right "
                                             "leg, the enforced limb is the right arm"):
        open_targets("mirror:sim-leg", oracle=oracle, rig=rig)
    left = ConstraintOracle(load_limb(files / "left.yaml"))
    with pytest.raises(RigConfigError, match="the enforced limb is the left arm"):
        open_targets("mirror:sim-arm", oracle=left, rig=rig)


# --------------------------------------------------------------------------- the CLI
def _argv(files, *extra, model="arm.onnx", targets="script:adversarial", rig="sim-servo-arm"):
    return ["enforce", "--rig", rig, "--model", str(files / model), "--targets", targets,
            "--stale-servo-ms", "1000", "--watchdog-ms", "1000", *extra]


@pytest.mark.parametrize(("case", "message"), [
    ("one-joint-model", "not a limb model"),
    ("limb-model-on-shoulder", "a limb model"),
    ("limb-file-on-shoulder", "arm.yaml: a limb file (shoulder, elbow, wrist), not one joint's "
                              "constraint file"),
    ("joint-file-on-arm", "a one joint's constraint 'cone50', but rig 'sim-servo-arm' drives "
                          "the right arm's 3 joints (shoulder, elbow, wrist)"),
    ("leg-on-arm", "(right leg: hip, knee, ankle), but rig 'sim-servo-arm' drives the right "
                   "arm's 3 joints"),
    ("left-on-right", "is for the left side"),
    ("hinge-elbow", "joint 'elbow' of limb file 'sim-arm-3' (right arm: shoulder, elbow, "
                    "wrist) holds hinge limits, but rig 'sim-servo-arm' drives its elbow as a "
                    "forearm joint (2 servos) whose flexion servo turns about (0, 0, 1), not "
                    "the hinge's axis (0, 0.6, 0.8)"),
    ("other-limb-model", "model trained for limb 'sim-arm-5', which differs from --constraint"),
    ("one-joint-csv", "a one-joint targets file (t_s,w,x,y,z) for a limb of 3 joints"),
])
def test_a_limb_mistake_is_one_line_before_any_device(files, tmp_path, case, message, rig_cli):
    (tmp_path / "one.csv").write_text("t_s,w,x,y,z\n0,1,0,0,0\n")
    argv = {
        "one-joint-model": _argv(files, model="cone.onnx"),
        "limb-model-on-shoulder": _argv(files, rig="sim-shoulder"),
        "limb-file-on-shoulder": _argv(files, "--constraint", files / "arm.yaml",
                                       "--force-model", rig="sim-shoulder", model="orig.onnx"),
        "joint-file-on-arm": _argv(files, "--constraint", files / "cone.yaml", "--force-model"),
        "leg-on-arm": _argv(files, "--constraint", files / "leg.yaml", "--force-model"),
        "left-on-right": _argv(files, "--constraint", files / "left.yaml", "--force-model"),
        "hinge-elbow": _argv(files, "--constraint", files / "hinge-arm.yaml", "--force-model"),
        "other-limb-model": _argv(files, "--constraint", files / "arm.yaml",
                                  model="other.onnx"),
        "one-joint-csv": _argv(files, targets=tmp_path / "one.csv"),
    }[case]
    code, out, err = rig_cli(argv)
    assert code == 2, (out, err)
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("rig: error: "), err
    assert message in lines[0], lines[0]
    assert "enforcing" not in out and "backstop" not in out, out


def test_a_short_run_of_the_simulated_arm(files, tmp_path, rig_cli):
    summ = tmp_path / "s.json"
    tel = tmp_path / "t.csv"
    code, out, err = rig_cli(_argv(files, "--duration", "0.5", "--summary-json", summ,
                                   "--telemetry", tel))
    assert code == 0, err
    assert "enforcing 'sim-arm-3'" in out and "targets script:adversarial" in out
    s = json.loads(summ.read_text())
    assert s["safe_state_entries"] == 0, s["safe_state_reason"]
    header = tel.read_text().splitlines()[0].split(",")
    assert "elbow_target_w" in header and "wrist_commanded_z" in header
    # nothing commanded beyond 1° — unless the patient left the arm outside when the run began:
    # then only on the way back, never further out than any command before (the monotone rule)
    rows = list(csv.DictReader(tel.open()))
    for n in ("shoulder", "elbow", "wrist"):
        v = np.array([float(r[f"{n}_violation_deg"]) for r in rows])
        before = np.minimum.accumulate(np.concatenate([[v[0]], v[:-1]]))
        assert ((v <= 1.0 + 1e-9) | (v <= before + 1e-9)).all(), (n, v[v > 1.0][:10])


@pytest.mark.parametrize("script", ["slow", "adversarial"])
def test_scripted_limb_targets_a_servo_rig_can_take(arm, script):
    """Given the servo arm, a script's valid postures are ones its servos reach (the elbow's and
    wrist's two servos included) and the exact oracle still finds valid; the adversarial
    script keeps its coupled segments and its invalid postures."""
    _, oracle = arm
    rig = load_rig_config("sim-servo-arm")
    kin = rig.servos.limb_kinematics()
    src = open_targets(f"script:{script}", oracle=oracle, rig=rig, seed=2)
    assert "reachable by the rig's servos" in src.description
    src.start(0.0)
    p = np.array([src.latest(t)[1] for t in np.arange(0.0, 16.0, 0.02)])
    ok = valid_targets(oracle, p)
    assert ok.sum() > 100
    reached = kin.nearest_batch(p[ok])
    assert np.degrees(Q.angle(Q.multiply(reached, Q.conjugate(p[ok])))).max() < 1e-3
    if script == "adversarial":
        assert {"coupled_source", "coupled_dependent"} <= set(src.kinds)
        assert (~ok).sum() > 100
