"""Every file that carries a patient's data is created owner-only (0600), whatever the umask:
the constraint, the model, the report, the enforcement telemetry and summary, the export."""

from __future__ import annotations

import os
import stat
from pathlib import Path

import pytest

from rig.cli import main
from rig.store import open_store

REAL = Path(__file__).resolve().parents[1] / "calibration" / "data" / "real"


def _mode(path: Path) -> int:
    return stat.S_IMODE(path.stat().st_mode)


def _ok(argv, capsys):
    with pytest.raises(SystemExit) as exc:
        main(argv)
    err = capsys.readouterr().err
    assert exc.value.code == 0, err


@pytest.fixture
def open_umask():
    old = os.umask(0o022)  # what makes plain open() give 0644
    yield
    os.umask(old)


def test_patient_files_are_owner_only(tmp_path, capsys, open_umask):
    from models.constraint import JointConstraint, dump_constraint

    # a constraint bound to a patient, a model trained on it
    c = JointConstraint.cone((1, 0, 0), 50.0, twist=(-40, 40), name="p", patient="P-0042")
    dump_constraint(c, tmp_path / "p.yaml")
    _ok(["train", "--constraint", str(tmp_path / "p.yaml"), "--out", str(tmp_path / "p.onnx")],
        capsys)
    # a boundary from a recording
    _ok(["boundary", str(REAL / "xio_ximu3_lower_body.sto"), "--joint", "hip", "--parent",
         "pelvis", "--child", "femur_r", "--frames", "isb", "--out", str(tmp_path / "b.yaml")],
        capsys)
    # a session, its export and report
    db = tmp_path / "s.db"
    with open_store(db) as store:
        sid = store.sessions.start(store.patients.add("P-0042"), rig_name="x")
        store.sessions.end(sid)
    _ok(["report", "--db", str(db), "--session", str(sid), "--out", str(tmp_path / "r.html")],
        capsys)
    # a short enforcement run with telemetry and summary
    _ok(["enforce", "--rig", "sim-shoulder", "--model", str(tmp_path / "p.onnx"),
         "--constraint", str(tmp_path / "p.yaml"), "--force-model", "--targets",
         "script:hold", "--duration", "0.2", "--stale-servo-ms", "1000", "--watchdog-ms", "1000",
         "--telemetry", str(tmp_path / "t.csv"), "--summary-json", str(tmp_path / "s.json")],
        capsys)
    for name in ("p.yaml", "p.onnx", "b.yaml", "r.html", "t.csv", "s.json", "s.db"):
        assert _mode(tmp_path / name) == 0o600, name


def test_overwriting_a_world_readable_file_leaves_it_owner_only(tmp_path, open_umask):
    from models.fileio import open_owner_only, write_owner_only

    old = tmp_path / "old.html"
    old.write_text("x")
    os.chmod(old, 0o644)
    write_owner_only(old, "report")
    assert old.read_text() == "report" and _mode(old) == 0o600
    log = tmp_path / "log.csv"
    log.write_text("a\n")
    os.chmod(log, 0o664)
    with open_owner_only(log, "a") as fh:
        fh.write("b\n")
    assert log.read_text() == "a\nb\n" and _mode(log) == 0o600
    assert not [p for p in tmp_path.iterdir() if p.name.endswith(".tmp")]
