"""Every output path is checked writable before the work that fills it (issue 37 item 6):
one line naming the option, the path and the reason, no temporary file name, nothing left in
the folder. The folders are real: ``/proc`` (exists, takes no new file, even for root) and a
folder made unwritable (immutable for root, ``0555`` otherwise)."""

from __future__ import annotations

import contextlib
import os
import subprocess
from pathlib import Path

import numpy as np
import pytest

from models.errors import OutputPathError
from models.fileio import check_output
from rig.store import SampleWriter, open_store

ROOT = Path(__file__).resolve().parents[2]
SHAPE = ROOT / "models/shapes/original.yaml"
STO = ROOT / "tests/rig/data/opensense_orientations.sto"
ARM = ROOT / "tests/calibration/data/real/cmu_60_02_salsa.sto"


@contextlib.contextmanager
def unwritable(folder: Path):
    """``folder`` made to take no new file for this process: ``chattr +i`` as root (whom
    permission bits do not stop), ``chmod 555`` otherwise; undone on the way out."""
    folder.mkdir(exist_ok=True)
    if os.geteuid() == 0:
        r = subprocess.run(["chattr", "+i", str(folder)], capture_output=True, text=True)
        if r.returncode != 0:
            pytest.skip(f"chattr +i unavailable here: {r.stderr.strip()}")
        try:
            yield folder
        finally:
            subprocess.run(["chattr", "-i", str(folder)], check=True)
    else:
        folder.chmod(0o555)
        try:
            yield folder
        finally:
            folder.chmod(0o755)


@pytest.fixture
def db(tmp_path):
    """A store with one ended session of 200 samples."""
    path = tmp_path / "clinic.db"
    rng = np.random.default_rng(3)
    with open_store(path) as store:
        sid = store.sessions.start(store.patients.add("P-OUT"), rig_name="sim-shoulder",
                                   joint="shoulder", side="right")
        q = rng.normal(size=(200, 4))
        q /= np.linalg.norm(q, axis=1, keepdims=True)
        with SampleWriter(store, sid) as w:
            w.add_many(np.arange(200) / 50.0, None, "shoulder", "joint", q)
        store.sessions.end(sid, status="completed")
    return path


def _commands(out: Path, folder: Path, db: Path) -> dict[str, list]:
    return {
        "boundary": ["boundary", STO, "--child", "humerus_r_imu", "--parent", "torso_imu",
                     "--out", out / "b.yaml"],
        "boundary-session": ["boundary", "--db", db, "--session", 1, "--no-store",
                             "--out", out / "b.yaml"],
        "boundary-limb": ["boundary", ARM, "--limb", "arm", "--segments",
                           "thorax,humerus_r,ulna_r,hand_r", "--frames", "isb",
                           "--out", out / "limb.yaml"],
        "train": ["train", "--constraint", SHAPE, "--out", out / "m.onnx"],
        "report": ["report", "--db", db, "--session", 1, "--out", out / "r.html"],
        "export": ["export", "--db", db, "--session", 1, "--out", out / "s.sto"],
        "dataset": ["dataset", "make", "--kind", "quaternion", "--constraint", SHAPE,
                    "--n", 100, "--out", out / "d.npz"],
        "demo": ["demo", "--quick", "--out", out / "demo"],
        "demo-limb": ["demo", "--limb", "arm", "--quick", "--out", out / "demo"],
        "record": ["record", "--rig", "sim-shoulder", "--patient", "P-1", "--duration", 1,
                   "--db", out / "new.db"],
    }


COMMANDS = ["boundary", "boundary-session", "boundary-limb", "train", "report", "export",
            "dataset", "demo", "demo-limb", "record"]


def _one_line_before_the_work(code, out, err, option_path: str, where: str):
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert code == 2, (out, err)
    assert len(lines) == 1 and lines[0].startswith("rig: error: "), err
    assert f"{option_path}: cannot write in {where}" in lines[0], lines[0]
    assert ".tmp" not in err and "Errno" not in err and "Traceback" not in err
    # nothing was built, trained or recorded first
    assert "building" not in out and "wrote" not in out and "[1]" not in out, out


@pytest.mark.parametrize("command", COMMANDS)
def test_an_output_in_proc_is_refused_before_the_work(command, tmp_path, db, rig_cli):
    argv = _commands(Path("/proc"), tmp_path, db)[command]
    code, out, err = rig_cli(argv)
    _one_line_before_the_work(code, out, err, f"{argv[-2]} {argv[-1]}", "/proc")


@pytest.mark.parametrize("command", COMMANDS)
def test_an_output_in_a_read_only_folder_is_refused_before_the_work(command, tmp_path, db,
                                                                    rig_cli):
    with unwritable(tmp_path / "ro") as ro:
        argv = _commands(ro, tmp_path, db)[command]
        code, out, err = rig_cli(argv)
        assert list(ro.iterdir()) == []  # no probe, no temporary file left behind
    _one_line_before_the_work(code, out, err, f"{argv[-2]} {argv[-1]}", str(ro))


def test_check_output_names_the_mistake(tmp_path):
    (tmp_path / "d").mkdir()
    with pytest.raises(OutputPathError, match=r"^--out .*/d: is a directory \(give a file"):
        check_output(tmp_path / "d")
    with pytest.raises(OutputPathError, match=r"^--out .*/no/x.yaml: directory .*/no does not"):
        check_output(tmp_path / "no" / "x.yaml")
    (tmp_path / "f").write_text("kept\n")
    with pytest.raises(OutputPathError, match=r"^--report .*/f: is a file, expected a folder"):
        check_output(tmp_path / "f", "--report", folder=True)
    with pytest.raises(OutputPathError, match=r"^--out: empty path"):
        check_output("")
    # a file that can be written: returned, left as it was, nothing else in its folder
    assert check_output(tmp_path / "f") == tmp_path / "f"
    assert check_output(tmp_path / "new.yaml", "--telemetry") == tmp_path / "new.yaml"
    assert check_output(tmp_path / "a" / "b", folder=True) == tmp_path / "a" / "b"
    assert (tmp_path / "f").read_text() == "kept\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["d", "f"]


def test_an_existing_file_that_may_not_be_replaced_is_refused(tmp_path):
    f = tmp_path / "old.yaml"
    f.write_text("kept\n")
    if os.geteuid() == 0:
        r = subprocess.run(["chattr", "+i", str(f)], capture_output=True, text=True)
        if r.returncode != 0:
            pytest.skip(f"chattr +i unavailable here: {r.stderr.strip()}")
        undo = ["chattr", "-i", str(f)]
    else:
        f.chmod(0o444)
        undo = ["chmod", "644", str(f)]
    try:
        with pytest.raises(OutputPathError, match=r"old.yaml: cannot replace it \("):
            check_output(f)
    finally:
        subprocess.run(undo, check=True)
    assert f.read_text() == "kept\n"


def test_the_boundary_request_checks_its_output_before_reading(tmp_path):
    from rig.readback import BoundaryRequest, RecordingSource

    req = BoundaryRequest(RecordingSource(file=str(STO), child="humerus_r_imu"),
                          out="/proc/x.yaml")
    with pytest.raises(OutputPathError, match="cannot write in /proc"):
        req.check()
