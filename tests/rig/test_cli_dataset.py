"""``rig dataset make`` / ``rig dataset info`` through the real entry point."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from models.datasets import load_dataset

REPO = Path(__file__).resolve().parents[2]


def test_make_quaternion_with_split_and_info(tmp_path, rig_cli):
    out = tmp_path / "c.npz"
    code, text, err = rig_cli(
        ["dataset", "make", "--shape", "c-shape", "--n", "400", "--seed", "5",
         "--split", "0.5,0.25,0.25", "--hemisphere", "centre", "--out", str(out)],
    )  # fmt: skip
    assert code == 0, err
    for part, size in (("train", 200), ("validation", 100), ("test", 100)):
        path = tmp_path / f"c-{part}.npz"
        assert f"wrote {path}" in text
        ds = load_dataset(path)
        assert len(ds) == size and ds.meta["split"] == part
        assert ds.meta["generator"]["hemisphere"] == "centre" and ds.meta["seed"] == 5
    assert "inner-valid" in text and "valid fraction 0.500" in text
    code, text, err = rig_cli(["dataset", "info", str(tmp_path / "c-train.npz")])
    assert code == 0, err
    assert "c-shape" in text and "PCA of 200 quaternions" in text and "PC4" in text


@pytest.mark.parametrize(
    ("args", "kind", "dims"),
    [
        (["--kind", "interval", "--lower", "-0.2", "--upper", "0.4"], "interval", (1, 1)),
        (["--kind", "ball3", "--radius", "0.125"], "ball3", (3, 3)),
        (["--kind", "sphere-vector", "--cone-radius", "30"], "sphere-vector", (3, 3)),
        (["--kind", "sphere-quaternion", "--cone-centre", "0,1,0"], "sphere-quaternion", (3, 4)),
        (["--cone-centre", "0,0,1", "--cone-radius", "20", "--twist", "--order", "random"],
         "quaternion", (4, 4)),
    ],
)  # fmt: skip
def test_make_each_kind(tmp_path, args, kind, dims, rig_cli):
    out = tmp_path / "d.npz"
    code, text, err = rig_cli(["dataset", "make", "--n", "50", "--out", str(out), *args])
    assert code == 0, err
    ds = load_dataset(out)
    assert ds.meta["kind"] == kind and (ds.inputs.shape[1], ds.targets.shape[1]) == dims
    assert f"wrote {out}" in text


@pytest.mark.parametrize(
    ("args", "word"),
    [
        (["--cone-radius", "200", "--n", "10"], "--cone-radius: must be in (0, 180)"),
        (["--cone-radius", "20", "--n", "abc"], "--n"),
        (["--cone-radius", "20", "--n", "0"], "--n: must be > 0"),
        (["--shape", "banana", "--n", "10"], "banana"),
        (["--shape", "small", "--cone-radius", "20", "--n", "10"], "only one constraint"),
        (["--n", "10"], "needs a constraint"),
        (
            ["--cone-radius", "20", "--n", "10", "--distribution", "lumpy"],
            "--distribution: unknown",
        ),
        (["--cone-radius", "20", "--n", "10", "--split", "0.5,x"], "--split"),
        (["--cone-radius", "20", "--n", "10", "--split", "0.5,0.6"], "--split: expected"),
        (["--kind", "cube", "--n", "10"], "--kind"),
        (["--kind", "ball2", "--n", "10", "--twist"], "--twist"),
        (["--constraint", "/nonexistent/c.yaml", "--n", "10"], "/nonexistent/c.yaml"),
    ],
)
def test_bad_make_requests_are_one_line(tmp_path, args, word, rig_cli):
    code, _, err = rig_cli(["dataset", "make", "--out", str(tmp_path / "x.npz"), *args])
    assert code == 2
    assert err.startswith("rig: error: ") and err.count("\n") == 1, err
    assert word in err and "Traceback" not in err
    assert not (tmp_path / "x.npz").exists()


def test_missing_out_and_bad_info_files(tmp_path, rig_cli):
    code, _, err = rig_cli(["dataset", "make", "--cone-radius", "20", "--n", "10"])
    assert code == 2 and "--out" in err and err.count("\n") == 1
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"\x00" * 64)
    for path in (bad, tmp_path / "absent.npz"):
        code, _, err = rig_cli(["dataset", "info", str(path)])
        assert code == 2 and str(path) in err and err.count("\n") == 1, err


def test_python_dash_m_rig(tmp_path):
    env = {**os.environ, "PYTHONPATH": str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    env.pop("RIG_DEBUG", None)
    out = tmp_path / "q.npz"
    cmd = [sys.executable, "-m", "rig", "dataset", "make", "--shape", "small", "--n", "40",
           "--out", str(out)]  # fmt: skip
    ok = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=60, check=False)
    assert ok.returncode == 0, ok.stderr
    assert load_dataset(out).regions.shape == (40,)
    bad = subprocess.run(
        [*cmd[:-2], "--n", "-3", "--out", str(out)], capture_output=True, text=True, env=env,
        timeout=60, check=False,
    )  # fmt: skip
    assert bad.returncode == 2
    assert bad.stderr.strip().count("\n") == 0 and "Traceback" not in bad.stderr
