"""Golden cases: ``rig train``, ``rig evaluate`` and ``rig dataset`` through the CLI — a joint's
field model, a limb's geometric model (the limb's ``network`` preset trains for minutes: not
here) — the text printed and the models written (metadata normalised)."""

from __future__ import annotations

import numpy as np

from models.shapes import shape_path
from rig.sim.patients import anatomical_limb
from tests.golden.cli import rig
from tests.golden.harness import case, tmpdir
from tests.golden.util import onnx_bytes


def _cli(prefix: str, args: list, tmp, out: dict) -> None:
    r = rig(args, tmp)
    out[f"{prefix}_exit"] = r["exit"]
    out[f"{prefix}_stdout"] = r["stdout"]
    out[f"{prefix}_stderr"] = r["stderr"]


@case("joint")
def case_cli_train_evaluate_joint() -> dict:
    """``rig train`` (field preset) on a thesis shape, ``rig evaluate`` of it on the held-out
    and the thesis's distributions, and the ONNX file."""
    out: dict = {}
    with tmpdir() as d:
        c = shape_path("small")
        _cli("train", ["train", "--constraint", c, "--out", d / "s.onnx"], d, out)
        out["onnx"] = onnx_bytes(d / "s.onnx", d)
        _cli("evaluate", ["evaluate", "--model", d / "s.onnx", "--constraint", c, "--n", "2000"],
             d, out)
        _cli("evaluate_even", ["evaluate", "--model", d / "s.onnx", "--constraint", c, "--n",
                               "1000", "--distribution", "even", "--twist", "--seed", "3"],
             d, out)
        _cli("evaluate_other", ["evaluate", "--model", d / "s.onnx", "--constraint",
                                shape_path("large"), "--n", "100"], d, out)
    return out


@case("limb")
def case_cli_train_evaluate_limb() -> dict:
    """``rig train --preset geometric`` on an anatomical leg's limb file, ``rig evaluate`` of
    it, and the ONNX file."""
    out: dict = {}
    with tmpdir() as d:
        f = d / "leg.yaml"
        f.write_text(anatomical_limb(11, "leg").to_yaml())
        _cli("train", ["train", "--constraint", f, "--preset", "geometric", "--out",
                       d / "l.onnx"], d, out)
        out["onnx"] = onnx_bytes(d / "l.onnx", d)
        _cli("evaluate", ["evaluate", "--model", d / "l.onnx", "--constraint", f, "--n",
                          "1000"], d, out)
        _cli("train_joint_preset", ["train", "--constraint", f, "--preset", "compact",
                                    "--out", d / "x.onnx"], d, out)
    return out


@case("joint")
def case_cli_dataset() -> dict:
    """``rig dataset make`` (a shape, a cone with twist, a split) and ``rig dataset info``."""
    out: dict = {}
    with tmpdir() as d:
        _cli("shape", ["dataset", "make", "--shape", "original", "--n", "2000", "--seed", "4",
                       "--out", d / "a.npz"], d, out)
        _cli("cone", ["dataset", "make", "--cone-radius", "40", "--cone-centre", "0,1,0",
                      "--n", "1000", "--twist", "--distribution", "clustered", "--seed", "5",
                      "--split", "0.7,0.15,0.15", "--out", d / "b.npz"], d, out)
        _cli("info", ["dataset", "info", d / "a.npz"], d, out)
        with np.load(d / "a.npz", allow_pickle=False) as z:
            for k in z.files:
                if z[k].dtype.kind in "biuf":
                    out[f"a_{k}"] = z[k]
        out["b_files"] = "\n".join(sorted(p.name for p in d.iterdir()))
    return out
