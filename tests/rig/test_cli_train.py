"""``rig train`` / ``rig evaluate`` end to end, and their one-line user errors."""

from __future__ import annotations

import pytest

CONE = "name: cone60y\nswing:\n  cone: {centre: [0, 1, 0], radius_deg: 60}\n"
TINY = """
evolution: {population: 6, generations: 2}
training: {max_epochs: 60, min_epochs: 20}
data: {train: 120, validation: 60, test: 200}
"""


@pytest.fixture
def files(tmp_path):
    c = tmp_path / "c.yaml"
    c.write_text(CONE)
    cfg = tmp_path / "tiny.yaml"
    cfg.write_text(TINY)
    return tmp_path, c, cfg


def test_train_then_evaluate_gmlp(files, rig_cli):
    tmp, c, cfg = files
    model = tmp / "out" / "m.onnx"
    model.parent.mkdir()  # rig train writes into a folder that exists, never makes one
    code, out, _ = rig_cli(["train", "--constraint", str(c), "--out", str(model), "--preset",
                           "best", "--config", str(cfg), "--seed", "3"])
    assert code == 0, out
    assert "generation   2/2" in out and "best fitness" in out and "elapsed" in out
    assert model.exists() and "mean 3-D error" in out
    # a tiny network cannot enforce the cone: said so, with the way out
    assert "warning: this model leaves" in out and "preset 'field'" in out
    code, out, _ = rig_cli(["evaluate", "--model", str(model), "--constraint", str(c),
                           "--n", "300", "--distribution", "even"])
    assert code == 0
    assert "300 held-out even orientations" in out and "MSE" in out
    code, out, _ = rig_cli(["evaluate", "--model", str(model), "--constraint", str(c),
                           "--n", "200", "--distribution", "uniform", "--twist"])
    assert code == 0 and "with twist" in out


def test_several_runs_are_numbered(files, rig_cli):
    tmp, c, cfg = files
    cfg.write_text(TINY.replace("generations: 2}", "generations: 1, repeats: 2}"))
    code, out, _ = rig_cli(["train", "--constraint", str(c), "--out", str(tmp / "r.onnx"),
                           "--preset", "best", "--config", str(cfg)])
    assert code == 0, out
    lines = [ln.split("generation")[0].strip() for ln in out.splitlines() if "generation " in ln]
    assert lines == ["run 1/2", "run 1/2", "run 2/2", "run 2/2"]


def test_default_preset_is_the_field_model(files, rig_cli):
    tmp, c, _ = files
    c.write_text(CONE + "twist: {min_deg: -30, max_deg: 80}\n")
    model = tmp / "f.onnx"
    code, out, _ = rig_cli(["train", "--constraint", str(c), "--out", str(model)])
    assert code == 0 and "preset field" in out and "swing field" in out
    assert "warning" not in out  # it meets the enforcement targets
    from models.onnx_io import load_model

    m = load_model(model)
    assert m.network_info["method"] == "field" and m.network_info["twist"] == "constant"
    assert m.metrics["mean_3d_error_pct"] < 0.5
    code, out, _ = rig_cli(["evaluate", "--model", str(model), "--constraint", str(c),
                           "--n", "2000"])
    assert code == 0 and "2000 held-out orientations (half uniform, half within 20°" in out
    line = next(ln for ln in out.splitlines() if "invalid inputs left > 1 deg outside" in ln)
    assert float(line.split()[-2]) < 1.0


@pytest.mark.parametrize("preset", ["field", "best"])
def test_train_on_a_dataset_records_its_hash(tmp_path, preset, rig_cli):
    from models.datasets import load_dataset
    from models.onnx_io import load_model

    data = tmp_path / "d.npz"
    code, out, _ = rig_cli(["dataset", "make", "--shape", "small", "--n", "400", "--split",
                           "0.7,0.15,0.15", "--out", str(data)])
    assert code == 0, out
    train = tmp_path / "d-train.npz"
    tiny = tmp_path / "tiny.yaml"
    tiny.write_text(TINY)
    model = tmp_path / "m.onnx"
    argv = ["train", "--data", str(train), "--out", str(model), "--preset", preset]
    code, out, _ = rig_cli(argv + (["--config", str(tiny)] if preset == "best" else []))
    assert code == 0, out
    ds = load_dataset(train)
    meta = load_model(model).metadata
    assert meta["jointlimits.training_data_sha256"] == ds.content_hash()
    assert f"{len(ds)} patterns of" in out
    # the model is bound to the dataset's constraint
    assert load_model(model, expected_constraint=ds.constraint()) is not None


def test_train_data_user_errors(tmp_path, files, rig_cli):
    _, c, _ = files
    data = tmp_path / "d.npz"
    code, _, _ = rig_cli(["dataset", "make", "--shape", "small", "--n", "100", "--out", str(data)])
    assert code == 0
    code, _, err = rig_cli(["train", "--data", str(data), "--constraint", str(c), "--out",
                           str(tmp_path / "m.onnx")])
    assert code == 2 and "differs from --constraint" in err
    assert len(err.strip().splitlines()) == 1
    ball = tmp_path / "b.npz"
    assert rig_cli(["dataset", "make", "--kind", "ball3", "--n", "50", "--out", str(ball)])[0] == 0
    code, _, err = rig_cli(["train", "--data", str(ball), "--out", str(tmp_path / "m.onnx")])
    assert code == 2 and "not a quaternion dataset" in err
    code, _, err = rig_cli(["train", "--out", str(tmp_path / "m.onnx")])
    assert code == 2 and "--constraint: required" in err


@pytest.mark.parametrize(("setup", "message"), [
    ("badfield", "evolution.populaton: unknown field"),
    ("badvalue", "training.stop_mse: expected a positive number"),
    ("noconstraint", "missing.yaml"),
])
def test_train_user_errors_are_one_line(files, setup, message, rig_cli):
    tmp, c, cfg = files
    if setup == "badfield":
        cfg.write_text("evolution: {populaton: 5}\n")
    elif setup == "badvalue":
        cfg.write_text("training: {stop_mse: -1}\n")
    else:
        c = tmp / "missing.yaml"
    code, _, err = rig_cli(["train", "--constraint", str(c), "--out", str(tmp / "m.onnx"),
                           "--config", str(cfg)])
    assert code == 2
    assert err.startswith("rig: error:") and message in err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err


def test_train_refuses_a_missing_output_folder_before_training(files, tmp_path, rig_cli):
    _, c, _ = files
    out = tmp_path / "no-such-folder" / "m.onnx"
    code, out_text, err = rig_cli(["train", "--constraint", str(c), "--out", str(out)])
    assert code == 2 and err.strip() == (f"rig: error: --out {out}: directory {out.parent} does "
                                         "not exist")
    assert not out.parent.exists() and "building" not in out_text  # nothing created, no work
    code, _, err = rig_cli(["train", "--constraint", str(c), "--out", str(tmp_path)])
    assert code == 2 and "is a directory" in err


def test_evaluate_refuses_wrong_files(files, rig_cli):
    tmp, c, _ = files
    code, _, err = rig_cli(["evaluate", "--model", str(c), "--constraint", str(c)])
    assert code == 2 and "not an ONNX model" in err
    model = tmp / "m.onnx"
    assert rig_cli(["train", "--constraint", str(c), "--out", str(model)])[0] == 0
    other = tmp / "other.yaml"
    other.write_text(CONE.replace("60", "30"))
    code, _, err = rig_cli(["evaluate", "--model", str(model), "--constraint", str(other)])
    assert code == 2 and "different constraint" in err
    assert len(err.strip().splitlines()) == 1
