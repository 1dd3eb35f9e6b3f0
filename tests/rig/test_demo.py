"""The main job (``rig demo``) runs end to end on the simulated rig."""

from __future__ import annotations

import pytest

from models.onnx_io import load_model
from models.shapes import load_shape
from rig.cli import main
from rig.commands.demo import run_demo


def test_quick_demo_runs_every_step_on_the_simulators(tmp_path):
    lines: list[str] = []
    report = run_demo(tmp_path, quick=True, echo=lines.append)
    for name in ("constraint.yaml", "train.npz", "validation.npz", "test.npz", "model.onnx"):
        assert (tmp_path / name).is_file(), name
    # the exported model carries the constraint it was trained for
    load_model(tmp_path / "model.onnx", expected_constraint=load_shape("original"))
    assert all(m == 1020 for m in report["servos"]["found"].values())  # XM430-W350 model number
    assert report["imu"]["chip_id"] == 0xA0
    assert report["eval_metrics"]["mse"] > 0
    assert any(line.startswith("[6/6]") for line in (s.strip() for s in lines))


def test_demo_rejects_bad_ids_in_one_line(capsys):
    with pytest.raises(SystemExit) as info:
        main(["demo", "--dxl-ids", "1,x"])
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert err.startswith("rig: error: --dxl-ids") and err.count("\n") == 1


@pytest.mark.parametrize(("args", "match"), [
    (["--dxl-port", "/dev/ttyUSB9"], "/dev/ttyUSB9: no such port"),
    (["--dxl-port", "/dev/null"], "not a serial port"),
    (["--dxl-ids", "1,1"], "duplicate ID 1"),
    (["--dxl-ids", "1,2,3,4"], "1 to 3 joints"),
    (["--dxl-port", "sim://dynamixel?ids=1,2,3&baud=57600"], "no servo answered at 1000000"),
    (["--dxl-port", "sim://dynamixel?ids=1,2"], "servo ID 3 did not answer"),
    (["--imu-port", "/dev/ttyUSB8"], "/dev/ttyUSB8: no such port"),
])
def test_demo_checks_devices_before_any_long_work(tmp_path, args, match, capsys):
    out = tmp_path / "out"
    with pytest.raises(SystemExit) as info:
        main(["demo", "--quick", "--out", str(out), *args])
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert err.startswith("rig: error: ") and err.count("\n") == 1 and match in err
    assert not out.exists()  # nothing was trained or written


def test_demo_takes_the_bus_baud_rate(tmp_path):
    lines: list[str] = []
    report = run_demo(tmp_path, quick=True, dxl_port="sim://dynamixel?ids=1,2&baud=57600",
                      dxl_ids=[1, 2], dxl_baud=57600, echo=lines.append)
    assert sorted(report["servos"]["found"]) == [1, 2]
