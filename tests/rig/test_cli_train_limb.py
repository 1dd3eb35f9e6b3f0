"""``rig dataset make`` / ``rig train`` / ``rig evaluate`` on limb files (issue 20)."""

from __future__ import annotations

import json

import numpy as np
import onnx
import pytest

from models.datasets import limb_postures, load_dataset
from models.limb import dump_limb
from models.limb_evaluation import random_limb
from models.oracle import ConstraintOracle

CONE = "name: cone60y\nswing:\n  cone: {centre: [0, 1, 0], radius_deg: 60}\n"


@pytest.fixture
def leg(tmp_path):
    path = tmp_path / "leg.yaml"
    limb = random_limb(322, "leg")  # a development limb, below the held-out seeds
    dump_limb(limb, path)
    return path, limb


def test_dataset_train_evaluate_a_limb(tmp_path, leg, rig_cli):
    path, limb = leg
    data = tmp_path / "leg.npz"
    code, out, _ = rig_cli(["dataset", "make", "--constraint", str(path), "--n", "3000",
                           "--seed", "4", "--out", str(data)])
    assert code == 0, out
    assert "dataset kind 'limb': 3000 patterns, inputs 12-D, targets 12-D" in out
    ds = load_dataset(data)
    got_limb, q = limb_postures(ds)
    assert got_limb.content_hash() == limb.content_hash()
    # the targets are the exact limb oracle's corrections
    np.testing.assert_allclose(ds.targets.reshape(-1, 3, 4), ConstraintOracle(limb).correction(q))
    code, out, _ = rig_cli(["dataset", "info", str(data)])
    assert code == 0 and "coupled to knee" in out

    model = tmp_path / "leg.onnx"
    code, out, _ = rig_cli(["train", "--data", str(data), "--out", str(model), "--seed", "2"])
    assert code == 0, out
    assert "preset network, a distance field for hip" in out and "on 3000 postures" in out
    assert "end-point mean 3-D error (% of limb length)" in out
    meta = {p.key: p.value for p in onnx.load(model).metadata_props}
    training = json.loads(meta["jointlimits.training"])
    assert meta["jointlimits.method"] == "network"
    assert training["data_sha256"] == ds.content_hash() and training["samples"] == 3000
    # 3000 postures are too few to meet the targets: said so, in the terms
    assert "warning: end-point mean 3-D error" in out

    code, out, _ = rig_cli(["evaluate", "--model", str(model), "--constraint", str(path),
                           "--n", "600"])
    assert code == 0, out
    assert "limb model (network), 600 held-out postures of 'leg-322'" in out
    assert "mean direction error, knee (deg)" in out


def test_geometric_limb_model_meets_the_targets(tmp_path, leg, rig_cli):
    path, _ = leg
    model = tmp_path / "g.onnx"
    code, out, _ = rig_cli(["train", "--constraint", str(path), "--out", str(model),
                           "--preset", "geometric"])
    assert code == 0, out
    assert "the exact limb oracle compiled (geometric)" in out and "warning" not in out


@pytest.mark.parametrize(("args", "message"), [
    (["train", "--constraint", "{leg}", "--out", "{tmp}/m.onnx", "--preset", "best"],
     "--preset best: a single-joint preset; for a limb file use network or geometric"),
    (["train", "--constraint", "{cone}", "--out", "{tmp}/m.onnx", "--preset", "network"],
     "--preset network: for a limb file only"),
    (["train", "--constraint", "{leg}", "--out", "{tmp}/m.onnx", "--config", "{cone}"],
     "--config: for single-joint presets; a limb model takes none"),
    (["evaluate", "--model", "{tmp}/m.onnx", "--constraint", "{leg}", "--distribution",
      "even"], "--distribution/--twist: a limb model is evaluated on held-out postures only"),
    (["dataset", "make", "--constraint", "{leg}", "--n", "10", "--out", "{tmp}/d.npz",
      "--twist"], "--twist: not for a limb file"),
    (["dataset", "make", "--kind", "limb", "--n", "10", "--out", "{tmp}/d.npz"],
     "--kind limb: needs --constraint LIMB.yaml"),
    (["dataset", "make", "--kind", "limb", "--constraint", "{cone}", "--n", "10", "--out",
      "{tmp}/d.npz"], "is a single-joint constraint file, not a limb file"),
])
def test_limb_user_errors_are_one_line(tmp_path, leg, args, message, rig_cli):
    cone = tmp_path / "cone.yaml"
    cone.write_text(CONE)
    argv = [a.format(leg=leg[0], cone=cone, tmp=tmp_path) for a in args]
    code, _, err = rig_cli(argv)
    assert code == 2
    assert message in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "m.onnx").exists() and not (tmp_path / "d.npz").exists()


def test_train_refuses_a_dataset_of_another_limb(tmp_path, leg, rig_cli):
    path, _ = leg
    other = tmp_path / "arm.yaml"
    dump_limb(random_limb(323, "arm"), other)
    data = tmp_path / "arm.npz"
    assert rig_cli(["dataset", "make", "--constraint", str(other), "--n", "50", "--out",
                    str(data)])[0] == 0
    code, _, err = rig_cli(["train", "--data", str(data), "--constraint", str(path), "--out",
                            str(tmp_path / "m.onnx")])
    assert code == 2 and "was made for limb 'arm-323'" in err


def test_an_arm_with_a_forearm_elbow_is_checked_and_compiled(tmp_path, rig_cli):
    """``rig constraint check`` and ``rig train --preset geometric`` on an arm whose elbow is a
    forearm joint (issue 39): its flexion interval named, the model compiled."""
    path = tmp_path / "arm.yaml"
    dump_limb(random_limb(323, "arm", forearm=True), path)  # a development limb
    code, out, err = rig_cli(["constraint", "check", str(path)])
    assert code == 0, err
    assert "elbow forearm flexion" in out
    code, out, _ = rig_cli(["train", "--constraint", str(path), "--out",
                            str(tmp_path / "g.onnx"), "--preset", "geometric"])
    assert code == 0, out
    assert "warning" not in out
