"""Golden cases: the CLI on files (``rig constraint``, ``rig boundary``, ``rig rom``): exit
status, stdout, stderr and the files written (joint and limb)."""

from __future__ import annotations

from models.shapes import SHAPES, shape_path
from tests.golden.cli import REAL, RIG_DATA, rig, root_relative
from tests.golden.harness import case, normalise, tmpdir


def _run(prefix: str, args: list, tmp, out: dict) -> dict:
    r = rig(args, tmp)
    out[f"{prefix}_exit"] = r["exit"]
    out[f"{prefix}_stdout"] = r["stdout"]
    out[f"{prefix}_stderr"] = r["stderr"]
    return r


def _file(path, tmp) -> str:
    return root_relative(normalise(path.read_text(), [tmp]))


@case("joint")
def case_cli_constraint_check() -> dict:
    """``rig constraint check`` on the five thesis shapes and on a bad file."""
    out: dict = {}
    with tmpdir() as d:
        _run("shapes", ["constraint", "check", *(shape_path(s) for s in SHAPES)], d, out)
        bad = d / "bad.yaml"
        bad.write_text("name: x\nswing:\n  cone: {centre: [1, 0, 0], radius_deg: 200}\n")
        _run("bad", ["constraint", "check", bad], d, out)
        _run("missing", ["constraint", "check", d / "missing.yaml"], d, out)
    return out


@case("joint")
def case_cli_boundary_and_rom_shoulder() -> dict:
    """A shoulder from real optical motion capture (CMU): ``rig boundary`` (the constraint file
    written), ``rig rom`` of the recording (table and JSON) and of the written constraint."""
    out: dict = {}
    with tmpdir() as d:
        c = d / "shoulder.yaml"
        _run("boundary", ["boundary", REAL / "cmu_61_07_salsa.sto", "--parent", "thorax",
                          "--child", "humerus_r", "--frames", "isb", "--out", c], d, out)
        out["constraint_yaml"] = _file(c, d)
        _run("rom", ["rom", REAL / "cmu_60_02_salsa.sto", "--parent", "thorax", "--child",
                     "humerus_l", "--frames", "isb", "--side", "left", "--age", "50", "--sex",
                     "female"], d, out)
        _run("rom_json", ["rom", REAL / "cmu_61_07_salsa.sto", "--parent", "thorax",
                          "--child", "humerus_r", "--frames", "isb", "--json"], d, out)
        _run("rom_constraint", ["rom", "--constraint", c, "--age", "40", "--sex", "male"], d,
             out)
        _run("rom_constraint_json", ["rom", "--constraint", c, "--json"], d, out)
        _run("rom_shape", ["rom", "--constraint", shape_path("original")], d, out)
    return out


@case("joint")
def case_cli_boundary_and_rom_knee_hip_ankle() -> dict:
    """Lower-body joints from the inertial recordings (x-io, Xsens): a knee hinge, a hip and an
    ankle boundary, their range of motion."""
    out: dict = {}
    with tmpdir() as d:
        xio, xsens = REAL / "xio_ximu3_lower_body.sto", REAL / "opensense_xsens_walking.sto"
        k = d / "knee.yaml"
        _run("knee", ["boundary", xio, "--joint", "knee", "--parent", "femur_l", "--child",
                      "tibia_l", "--frames", "isb", "--side", "left", "--out", k], d, out)
        out["knee_yaml"] = _file(k, d)
        _run("knee_rom", ["rom", xio, "--joint", "knee", "--parent", "femur_l", "--child",
                          "tibia_l", "--frames", "isb", "--side", "left", "--json"], d, out)
        _run("knee_rom_constraint", ["rom", "--constraint", k], d, out)
        h = d / "hip.yaml"
        _run("hip", ["boundary", xsens, "--joint", "hip", "--parent", "pelvis", "--child",
                     "femur_r", "--frames", "isb", "--out", h, "--max-vertices", "40"], d, out)
        out["hip_yaml"] = _file(h, d)
        _run("hip_rom", ["rom", xsens, "--joint", "hip", "--parent", "pelvis", "--child",
                         "femur_r", "--frames", "isb"], d, out)
        a = d / "ankle.yaml"
        _run("ankle", ["boundary", xio, "--joint", "ankle", "--parent", "tibia_r",
                       "--child", "calcn_r", "--frames", "isb", "--by-swing", "on", "--out", a],
             d, out)
        out["ankle_yaml"] = _file(a, d)
        _run("ankle_rom", ["rom", xio, "--joint", "ankle", "--parent", "tibia_r", "--child",
                           "calcn_r", "--frames", "isb", "--json"], d, out)
        _run("elbow_rom", ["rom", REAL / "cmu_60_02_salsa.sto", "--joint", "elbow",
                           "--parent", "humerus_r", "--child", "ulna_r", "--frames", "isb"],
             d, out)
        _run("wrist_rom", ["rom", REAL / "cmu_60_02_salsa.sto", "--joint", "wrist",
                           "--parent", "ulna_r", "--child", "hand_r", "--frames", "isb",
                           "--json"], d, out)
    return out


@case("joint")
def case_cli_boundary_opensense_imus() -> dict:
    """``rig boundary`` and ``rig rom`` on the OpenSense sensor-orientation file (rig frames,
    the joint orientations from two columns; a tiny recording)."""
    out: dict = {}
    with tmpdir() as d:
        c = d / "c.yaml"
        sto = RIG_DATA / "opensense_orientations.sto"
        _run("boundary", ["boundary", sto, "--parent", "torso_imu", "--child",
                          "humerus_r_imu", "--out", c, "--name", "os"], d, out)
        out["constraint_yaml"] = _file(c, d) if c.exists() else ""
        _run("rom", ["rom", sto, "--parent", "torso_imu", "--child", "humerus_r_imu",
                     "--json"], d, out)
    return out


@case("joint")
def case_cli_errors() -> dict:
    """One-line user errors of ``rig boundary`` / ``rig rom`` (exit status 2)."""
    out: dict = {}
    xio = REAL / "xio_ximu3_lower_body.sto"
    with tmpdir() as d:
        c = str(d / "c.yaml")
        cases = {
            "no_recording": ["boundary", "--out", c],
            "missing_file": ["boundary", d / "missing.sto", "--child", "h", "--out", c],
            "no_limb": ["boundary", xio, "--out", c],
            "bad_column": ["boundary", xio, "--parent", "thx", "--child", "femur_r", "--out",
                           c],
            "bad_axis": ["boundary", xio, "--child", "femur_r", "--limb-axis", "1,0", "--out", c],
            "wrong_joint": ["boundary", xio, "--joint", "elbow", "--parent", "femur_r",
                            "--child", "tibia_r", "--frames", "isb", "--out", c],
            "hip_as_shoulder": ["boundary", xio, "--parent", "pelvis", "--child", "femur_r",
                                "--frames", "isb", "--out", c],
            "mixed_sides": ["boundary", xio, "--limb", "leg", "--segments",
                            "pelvis,femur_l,tibia_r,calcn_r", "--frames", "isb", "--out", c],
            "arm_from_leg": ["boundary", xio, "--limb", "arm", "--segments",
                             "pelvis,femur_r,tibia_r,calcn_r", "--frames", "isb", "--out", c],
            "rom_bad_joint": ["rom", xio, "--frames", "isb", "--joint", "toe"],
            "rom_no_constraint": ["rom", "--constraint", d / "nope.yaml"],
            "rom_frames_with_constraint": ["rom", "--constraint", d / "nope.yaml", "--frames",
                                           "isb"],
        }
        for name, args in cases.items():
            _run(name, args, d, out)
    return out


@case("limb")
def case_cli_boundary_chain_arm() -> dict:
    """``rig boundary --limb arm`` on CMU optical capture (right and left arms): the limb file
    written and the summary; ``rig rom`` of the limb file refused without --joint."""
    out: dict = {}
    with tmpdir() as d:
        for side in ("r", "l"):
            f = d / f"arm_{side}.yaml"
            _run(f"arm_{side}", ["boundary", REAL / "cmu_61_07_salsa.sto", "--limb", "arm",
                                 "--segments", f"thorax,humerus_{side},ulna_{side},hand_{side}",
                                 "--frames", "isb", "--out", f], d, out)
            out[f"arm_{side}_yaml"] = _file(f, d)
        _run("rom_limb_file", ["rom", "--constraint", d / "arm_r.yaml"], d, out)
        _run("rom_limb_file_joint", ["rom", "--constraint", d / "arm_r.yaml", "--joint",
                                     "elbow"], d, out)
    return out


@case("limb")
def case_cli_boundary_chain_leg() -> dict:
    """``rig boundary --limb leg`` on the two inertial lower-body recordings and CMU's legs."""
    out: dict = {}
    with tmpdir() as d:
        for name, file, side in (("xio", "xio_ximu3_lower_body.sto", "r"),
                                 ("xsens", "opensense_xsens_walking.sto", "l"),
                                 ("cmu", "cmu_61_07_salsa.sto", "r")):
            f = d / f"{name}.yaml"
            _run(name, ["boundary", REAL / file, "--limb", "leg", "--segments",
                        f"pelvis,femur_{side},tibia_{side},calcn_{side}", "--frames", "isb",
                        "--out", f], d, out)
            out[f"{name}_yaml"] = _file(f, d) if f.exists() else ""
    return out
