"""``rig train`` / ``rig evaluate`` end to end, and their one-line user errors."""

from __future__ import annotations

import pytest

from rig.cli import main

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


def _run(argv, capsys):
    with pytest.raises(SystemExit) as exc:
        main(argv)
    out = capsys.readouterr()
    return exc.value.code, out.out, out.err


def test_train_then_evaluate(files, capsys):
    tmp, c, cfg = files
    model = tmp / "out" / "m.onnx"
    code, out, _ = _run(["train", "--constraint", str(c), "--out", str(model),
                         "--config", str(cfg), "--seed", "3"], capsys)
    assert code == 0, out
    assert "generation   2/2" in out and "best fitness" in out and "elapsed" in out
    assert model.exists() and "mean 3-D error" in out
    code, out, _ = _run(["evaluate", "--model", str(model), "--constraint", str(c),
                         "--n", "300"], capsys)
    assert code == 0
    assert "300 held-out even orientations" in out and "MSE" in out
    code, out, _ = _run(["evaluate", "--model", str(model), "--constraint", str(c),
                         "--n", "200", "--twist"], capsys)
    assert code == 0 and "with twist" in out


def test_thesis_preset_flag(files, capsys):
    tmp, c, cfg = files
    code, out, _ = _run(["train", "--constraint", str(c), "--out", str(tmp / "t.onnx"),
                         "--config", str(cfg), "--preset", "thesis"], capsys)
    assert code == 0 and "preset thesis" in out


@pytest.mark.parametrize(("setup", "message"), [
    ("badfield", "evolution.populaton: unknown field"),
    ("badvalue", "training.stop_mse: expected a positive number"),
    ("noconstraint", "missing.yaml"),
])
def test_train_user_errors_are_one_line(files, capsys, setup, message):
    tmp, c, cfg = files
    if setup == "badfield":
        cfg.write_text("evolution: {populaton: 5}\n")
    elif setup == "badvalue":
        cfg.write_text("training: {stop_mse: -1}\n")
    else:
        c = tmp / "missing.yaml"
    code, _, err = _run(["train", "--constraint", str(c), "--out", str(tmp / "m.onnx"),
                         "--config", str(cfg)], capsys)
    assert code == 2
    assert err.startswith("rig: error:") and message in err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err


def test_evaluate_refuses_wrong_files(files, capsys):
    tmp, c, cfg = files
    code, _, err = _run(["evaluate", "--model", str(c), "--constraint", str(c)], capsys)
    assert code == 2 and "not an ONNX model" in err
    model = tmp / "m.onnx"
    assert _run(["train", "--constraint", str(c), "--out", str(model), "--config", str(cfg)],
                capsys)[0] == 0
    other = tmp / "other.yaml"
    other.write_text(CONE.replace("60", "30"))
    code, _, err = _run(["evaluate", "--model", str(model), "--constraint", str(other)], capsys)
    assert code == 2 and "different constraint" in err
    assert len(err.strip().splitlines()) == 1
