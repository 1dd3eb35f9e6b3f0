"""A user's path on the simulated 7-servo arm (issue 39), end to end through the CLI, short:
``rig record --rig sim-servo-arm`` (patient time ×10) → ``rig boundary --limb arm`` →
``rig train --preset geometric`` → ``rig enforce --rig sim-servo-arm`` (1.5 s); then the wrong
inputs a user gives that arm, each one line and exit status 2. And the binding rule the limb
demo's live stage relies on: an IMU-recorded hinge elbow's limits held by the servo arm's
forearm elbow (:func:`rig.loop.binding.hinge_on_forearm`)."""

from __future__ import annotations

import contextlib
import io
import json

import numpy as np
import pytest
import yaml

from models.constraint import JointConstraint, dump_constraint
from models.limb import Limb, dump_limb, load_limb
from models.limb_model import export_limb_model
from models.onnx_io import load_model
from models.oracle import ConstraintOracle
from rig.cli import main
from rig.demo.limb import commanded_beyond
from rig.demo.stages import shipped_config
from rig.devices.config import load_rig_config
from rig.loop.binding import ModelBindingError, bind_model, hinge_on_forearm
from rig.sim.patients import anatomical_limb
from rig.sim.urls import with_keys
from rig.store import open_store

# the module-scoped path is run once: its tests run on one xdist worker (apart, the workers
# that drew its tests each ran the whole path, 9 s)
pytestmark = pytest.mark.xdist_group("test_arm_path")


@pytest.fixture(scope="module")
def path_run(tmp_path_factory):
    """The user's path once per module: the shipped sim-servo-arm at patient time ×10, 4 s of
    recording without the calibration protocol (a servo limb's is a check of the zeros; at
    ×10 its 5 s static pose is 0.5 s of a loaded host's time, which once passed without a
    sample), its limb file, a geometric limb model, 1.5 s of enforcement on the session."""
    d = tmp_path_factory.mktemp("arm-path")
    cfg = shipped_config("sim-servo-arm")
    cfg["servos"]["port"] = with_keys(cfg["servos"]["port"], time_scale=10)
    rig = d / "sim-servo-arm.yaml"
    rig.write_text(yaml.safe_dump(cfg, sort_keys=False))
    db = d / "arm.db"
    steps = {
        "record": ["record", "--rig", rig, "--duration", "4", "--db", db, "--patient",
                   "P-ARM-01", "--display", "plain", "--no-calibration"],
        "boundary": ["boundary", "--db", db, "--session", "1", "--limb", "arm", "--out",
                     d / "arm.yaml"],
        "train": ["train", "--constraint", d / "arm.yaml", "--preset", "geometric", "--out",
                  d / "arm.onnx"],
        "enforce": ["enforce", "--rig", rig, "--model", d / "arm.onnx", "--db", db,
                    "--session", "1", "--targets", "script:adversarial", "--duration", "1.5",
                    "--stale-servo-ms", "1000", "--watchdog-ms", "1000", "--telemetry",
                    d / "t.csv", "--summary-json", d / "s.json"],
    }
    codes = {}
    for name, argv in steps.items():
        err = io.StringIO()
        with contextlib.redirect_stderr(err), pytest.raises(SystemExit) as exc:
            main([str(a) for a in argv])
        codes[name] = (exc.value.code, err.getvalue())
    return {"dir": d, "rig": rig, "db": db, "codes": codes}


def test_record_boundary_train_enforce_on_the_servo_arm(path_run):
    d = path_run["dir"]
    for name, (code, err) in path_run["codes"].items():
        assert code == 0, (name, err)
        assert "Traceback" not in err, (name, err)
    limb = load_limb(d / "arm.yaml")
    assert limb.joint_names == ("shoulder", "elbow", "wrist")
    assert [j.kind for j in limb.joints] == ["ball", "forearm", "two-axis"]  # the rig's kinds
    model = load_model(d / "arm.onnx", limb=True)
    assert tuple(model.joints) == limb.joint_names
    s = json.loads((d / "s.json").read_text())
    assert s["cycles"] > 100 and s["safe_state_entries"] == 0, s.get("safe_state_reason")
    assert set(s["joints"]) == set(limb.joint_names)
    # 0 commanded postures beyond 1° in any joint, by the exact limb oracle on the CSV (the
    # arm may start outside limits extracted from 4 s: its way back is recovery, allowed)
    rows = np.genfromtxt(d / "t.csv", delimiter=",", names=True)
    c = commanded_beyond({k: rows[k] for k in rows.dtype.names}, limb)
    assert c["judged"] > 100 and c["beyond"] == 0, c
    with open_store(path_run["db"], create=False) as store:
        kinds = sorted(x["kind"] for x in store.sessions.list())
        assert kinds == ["enforce", "record"]


def _argv(path_run, *extra, model=None, targets="script:adversarial"):
    d = path_run["dir"]
    return ["enforce", "--rig", path_run["rig"], "--model", model or d / "arm.onnx",
            "--targets", targets, "--duration", "1", *extra]


@pytest.mark.parametrize("case", ["leg-file", "one-joint-model", "wrong-csv"])
def test_wrong_inputs_on_the_arm_rig_are_one_line(path_run, tmp_path, case, rig_cli):
    d = path_run["dir"]
    leg = tmp_path / "leg.yaml"
    dump_limb(anatomical_limb(3, "leg"), leg)
    cone = tmp_path / "cone.yaml"
    dump_constraint(JointConstraint.cone((1, 0, 0), 50.0, twist=(-40, 40), name="cone50"), cone)
    one_joint = tmp_path / "cone.onnx"
    if case == "one-joint-model":  # a one-joint model (rig train's default preset, ~5 s)
        code, _, err = rig_cli(["train", "--constraint", cone, "--out", one_joint])
        assert code == 0, err
    csv = tmp_path / "wrong.csv"  # the wrist's columns missing, a knee's instead
    csv.write_text("t_s," + ",".join(f"{j}_{c}" for j in ("shoulder", "elbow", "knee")
                                     for c in "wxyz") + "\n0" + ",1,0,0,0" * 3 + "\n")
    argv, message = {
        "leg-file": (_argv(path_run, "--constraint", leg, "--force-model"),
                     "(right leg: hip, knee, ankle), but rig 'sim-servo-arm' drives"),
        "one-joint-model": (_argv(path_run, model=one_joint), "limb model"),
        "wrong-csv": (_argv(path_run, "--constraint", d / "arm.yaml", targets=csv), "wrist"),
    }[case]
    code, out, err = rig_cli(argv)
    assert code == 2, (out, err)
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("rig: error: "), err
    assert message in lines[0], lines[0]
    assert "Traceback" not in err and "enforcing" not in out


# -------------------------------------------------------------- a hinge on a forearm's servos
def test_a_hinge_elbow_is_held_by_the_forearm_elbows_servos(tmp_path):
    rig = load_rig_config("sim-servo-arm")
    elbow_servos = rig.servos.joints[1]
    hinge = anatomical_limb(3, "arm")  # the IMU arm's patient: its elbow a hinge about +Z
    assert hinge_on_forearm(hinge.joints[1], elbow_servos)
    assert not hinge_on_forearm(hinge.joints[0], rig.servos.joints[0])  # a ball: its own kind
    d = hinge.to_dict()
    d["joints"][1]["constraint"]["hinge"]["axis"] = [0.0, 0.6, 0.8]
    tilted = Limb.from_dict(d)
    assert not hinge_on_forearm(tilted.joints[1], elbow_servos)

    export_limb_model(hinge, tmp_path / "hinge.onnx")
    model = load_model(tmp_path / "hinge.onnx", limb=True)
    b = bind_model(model, rig=rig, constraint=hinge)
    assert b.constraint is hinge and not b.mismatches
    with pytest.raises(ModelBindingError, match=r"not the hinge's axis \(0, 0.6, 0.8\)"):
        bind_model(model, rig=rig, constraint=tilted, force=True)
    # the hinge's oracle judges pronation: the forearm's rotation servo is held at its zero
    o = ConstraintOracle(hinge)
    flex = np.radians(60.0)
    rz = np.array([np.cos(flex / 2), 0.0, 0.0, np.sin(flex / 2)])
    pron = np.radians(20.0)
    rx = np.array([np.cos(pron / 2), np.sin(pron / 2), 0.0, 0.0])
    w, x, y, z = rz
    pronated = np.array([w * rx[0] - x * rx[1], w * rx[1] + x * rx[0], y * rx[0] + z * rx[1],
                         z * rx[0] - y * rx[1]])  # rz ⊗ rx
    posture = np.stack([np.array([1.0, 0, 0, 0]), pronated, np.array([1.0, 0, 0, 0])])
    dist = np.degrees(o.evaluate(posture[None]).distance[0])
    assert dist[1] == pytest.approx(20.0, abs=1e-6)
    posture[1] = rz
    assert np.degrees(o.evaluate(posture[None]).distance[0])[1] <= 0.0
