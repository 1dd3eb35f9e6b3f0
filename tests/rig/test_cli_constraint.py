"""``rig constraint check``: summary on success, one-line errors and exit 2 on bad files."""

from __future__ import annotations

import subprocess
import sys

import pytest

GOOD = (
    "name: demo\n"
    "swing: {cone: {centre: [1, 0, 0], radius_deg: 60}}\n"
    "twist: {min_deg: -45, max_deg: 45}\n"
)


def test_check_summarises_a_good_file(tmp_path, rig_cli):
    path = tmp_path / "good.yaml"
    path.write_text(GOOD)
    code, out, err = rig_cli(["constraint", "check", str(path), "--samples", "20000"])
    assert code == 0, err
    assert "OK" in out and "radius 60 deg" in out and "-45 .. 45 deg" in out
    # valid fraction of a 60° cone with ±45° twist: (1 - cos 60°)/2 * 90/360 = 6.25 %
    frac = float(out.split("valid")[1].split("%")[0])
    assert abs(frac - 6.25) < 0.6


@pytest.mark.parametrize(
    "content, expected",
    [
        ("swing: {cone: {centre: [1, 0, 0], radius_deg: 200}}", "swing.cone.radius_deg"),
        ("twist: {min_deg: 10, max_deg: -10}", "twist: min_deg (10) is greater"),
        ("swing: [", "not valid YAML"),
        # a misspelt key must not silently drop a limit
        (GOOD.replace("twist:", "twsit:"), "twsit: unknown key 'twsit' (did you mean 'twist'?)"),
        (
            GOOD.replace("max_deg: 45}", "max_deg: 45, by_swing: {bandwidth_deg: 20, pionts: []}}"),
            "twist.by_swing.pionts: unknown key",
        ),
    ],
)
def test_check_reports_bad_files_in_one_line(tmp_path, content, expected, rig_cli):
    path = tmp_path / "bad.yaml"
    path.write_text(content)
    code, _, err = rig_cli(["constraint", "check", str(path)])
    assert code == 2
    assert err.count("\n") == 1 and err.startswith("rig: error: ")
    assert str(path) in err and expected in err
    assert "Traceback" not in err


def test_check_summarises_swing_dependent_twist_and_binding(tmp_path, rig_cli):
    path = tmp_path / "table.yaml"
    path.write_text(
        "name: table\njoint: shoulder\nside: left\npatient: P-3\n"
        "swing: {cone: {centre: [1, 0, 0], radius_deg: 60}}\n"
        "twist:\n  min_deg: -45\n  max_deg: 45\n  by_swing:\n    bandwidth_deg: 30\n"
        "    points:\n"
        "      - {direction: [1, 0, 0], min_deg: -45, max_deg: 45}\n"
        "      - {direction: [0, 1, 0], min_deg: -10, max_deg: 10}\n"
        "provenance: {session: 7, samples: 1200}\n"
    )
    code, out, err = rig_cli(["constraint", "check", str(path), "--samples", "20000"])
    assert code == 0, err
    assert "by swing    2 points, bandwidth 30 deg" in out
    assert "bound to    joint shoulder, side left, patient P-3" in out
    assert "provenance  session: 7, samples: 1200" in out
    # narrower twist towards +Y: fewer valid orientations than the constant ±45° envelope
    frac = float(out.split("valid")[1].split("%")[0])
    assert 0.5 < frac < 6.25


def test_check_missing_file(tmp_path, rig_cli):
    code, _, err = rig_cli(["constraint", "check", str(tmp_path / "none.yaml")])
    assert code == 2 and "file not found" in err


def test_entry_points_report_version_and_help():
    for argv in (["--version"], ["--help"], ["constraint", "--help"]):
        r = subprocess.run(
            [sys.executable, "-m", "rig", *argv], capture_output=True, text=True, timeout=60
        )
        assert r.returncode == 0, r.stderr
    r = subprocess.run(
        [sys.executable, "-m", "rig", "--version"], capture_output=True, text=True, timeout=60
    )
    assert r.stdout.startswith("rig, version ")


#: a "billion laughs" document: nine levels of nine aliases each, under provenance
BOMB = GOOD + "provenance:\n  a0: &a0 [lol, lol, lol, lol, lol, lol, lol, lol, lol]\n" + "".join(
    f"  a{k}: &a{k} [{', '.join([f'*a{k - 1}'] * 9)}]\n" for k in range(1, 9))


@pytest.mark.parametrize("argv", [
    ["constraint", "check", "{path}"],
    ["train", "--constraint", "{path}", "--out", "{tmp}/m.onnx"],
    ["rom", "--constraint", "{path}"],
])
def test_yaml_anchors_and_aliases_are_refused_with_one_line(tmp_path, argv, rig_cli):
    path = tmp_path / "bomb.yaml"
    path.write_text(BOMB)
    argv = [a.format(path=path, tmp=tmp_path) for a in argv]
    code, _, err = rig_cli(argv)
    assert code == 2
    assert err.startswith("rig: error: ") and len(err.strip().splitlines()) == 1
    assert str(path) in err and "anchors are not accepted" in err
    assert not (tmp_path / "m.onnx").exists()


def test_a_rig_config_with_an_alias_is_refused(tmp_path, rig_cli):
    path = tmp_path / "rig.yaml"
    path.write_text("name: &n my-rig\njoint: {name: *n, side: right, parent: thorax, "
                    "child: humerus}\n")
    code, _, err = rig_cli(["record", "--rig", str(path), "--db", str(tmp_path / "x.db"),
                            "--patient", "P-1", "--duration", "1"])
    assert code == 2 and "anchors are not accepted" in err and str(path) in err
    assert len(err.strip().splitlines()) == 1
    assert not (tmp_path / "x.db").exists()


def test_rom_refuses_a_file_read_as_another_joint_or_side(tmp_path, rig_cli):
    """Issue 37, case 2: ``rig rom --constraint p42.yaml --joint hip`` read a shoulder file as a
    hip (extension 62.4° against a norm of 30°)."""
    shoulder = tmp_path / "p42.yaml"
    shoulder.write_text("name: p42\njoint: shoulder\nside: right\n"
                        "swing: {cone: {centre: [1, 0, 0], radius_deg: 60}}\n")
    elbow = tmp_path / "elbow.yaml"  # names no joint: its hinge is the elbow's (+Z)
    elbow.write_text("name: e\nkind: hinge\nhinge: {axis: [0, 0, 1], min_deg: 0, "
                     "max_deg: 140}\n")
    for args, message in (
            (["--constraint", shoulder, "--joint", "hip"],
             "constraint 'p42' is for the shoulder, not the hip (--joint hip)"),
            (["--constraint", shoulder, "--side", "left"],
             "constraint 'p42' is for the right side, not the left (--side left)"),
            (["--constraint", elbow, "--joint", "hip"],
             "holds hinge limits, but the hip is a ball joint"),
            (["--constraint", elbow, "--joint", "knee"],
             "is a hinge about [0.0, 0.0, 1.0], but the knee's turns about [0.0, 0.0, -1.0]")):
        code, out, err = rig_cli(["rom", *args])
        assert code == 2 and message in err and err.count("\n") == 1, err
    code, out, _ = rig_cli(["rom", "--constraint", elbow, "--joint", "elbow"])
    assert code == 0 and "flexion" in out
