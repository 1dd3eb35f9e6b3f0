"""Boundaries and clinical peaks on real human recordings our simulator did not produce.

The recordings (``data/real``, sources and licences in its README): optical motion capture of
two people dancing (CMU, shoulders and hips) and two inertial recordings of the lower body (x-io
x-IMU3, Xsens MTw via OpenSim's OpenSense example), all with segment orientations in ISB frames.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial import cKDTree

from calibration.frames import segment_to_rig
from models import quaternion as Q
from models.constraint import JointConstraint, load_constraint
from models.geometry import fibonacci_sphere
from models.oracle import ConstraintOracle
from rig.cli import main
from rig.readback import extract, load_joint_orientations
from rig.store.io import OrientationTable, read_sto, write_sto

DATA = Path(__file__).parent / "data" / "real"

#: (file, reference column, limb column, side)
JOINTS = [
    ("cmu_61_07_salsa.sto", "thorax", "humerus_r", "right"),
    ("cmu_61_07_salsa.sto", "thorax", "humerus_l", "left"),
    ("cmu_61_07_salsa.sto", "pelvis", "femur_r", "right"),
    ("cmu_61_07_salsa.sto", "pelvis", "femur_l", "left"),
    ("cmu_60_02_salsa.sto", "thorax", "humerus_r", "right"),
    ("cmu_60_02_salsa.sto", "thorax", "humerus_l", "left"),
    ("xio_ximu3_lower_body.sto", "pelvis", "femur_r", "right"),
    ("xio_ximu3_lower_body.sto", "pelvis", "femur_l", "left"),
    ("opensense_xsens_walking.sto", "pelvis", "femur_r", "right"),
    ("opensense_xsens_walking.sto", "pelvis", "femur_l", "left"),
]


def run(args, capsys):
    with pytest.raises(SystemExit) as exc:
        main(args)
    out = capsys.readouterr()
    return exc.value.code, out.out, out.err


def _swing_oracle(c: JointConstraint) -> ConstraintOracle:
    return ConstraintOracle(JointConstraint.from_dict({"name": "s", "swing": c.swing.to_dict()}))


def _area_far(c: JointConstraint, directions: np.ndarray, far_deg: float = 20.0) -> float:
    """Share of the swing region's area farther than ``far_deg`` from every recorded direction
    (the region sampled by a near-uniform grid of 50,000 directions on the sphere)."""
    grid = fibonacci_sphere(50_000)
    inside = grid[_swing_oracle(c).swing_distance(grid) <= 0.0]
    chord, _ = cKDTree(directions).query(inside)
    return float(np.mean(chord > 2.0 * math.sin(math.radians(far_deg) / 2.0)))


@pytest.mark.parametrize("file, reference, limb, side", JOINTS)
def test_the_boundary_holds_what_people_did(file, reference, limb, side):
    joint = "hip" if reference == "pelvis" else "shoulder"  # a hip is no default shoulder
    data = load_joint_orientations(str(DATA / file), parent=reference, child=limb,
                                   frames="isb", joint=joint)
    ex = extract(data, side=side)
    d = data.directions
    dist = _swing_oracle(ex.constraint_).swing_distance(d)
    inside = float(np.mean(dist <= 0.0))
    assert inside >= 0.97, f"{file} {limb}: {100 * inside:.2f} % of the directions inside"
    assert _area_far(ex.constraint_, d) <= 0.05
    # the figure stored (and printed) is the one measured on the boundary written
    assert ex.constraint_.provenance["inside"]["share"] == pytest.approx(inside, abs=1e-5)
    # the twist range holds the recorded twists too: whole orientations are valid
    valid = ConstraintOracle(ex.constraint_).signed_distance(data.q) <= 0.0
    assert float(np.mean(valid)) >= 0.97
    # clean recordings: no spike, no inset worth the name
    assert ex.n_spikes_ == 0 and ex.inset_deg_ < 0.1


def test_rig_boundary_prints_the_share_measured_on_the_file_it_writes(tmp_path, capsys):
    out = tmp_path / "shoulder.yaml"
    code, stdout, err = run(["boundary", str(DATA / "cmu_61_07_salsa.sto"), "--parent",
                             "thorax", "--child", "humerus_r", "--frames", "isb", "--out",
                             str(out)], capsys)
    assert code == 0, err
    c = load_constraint(out)
    data = load_joint_orientations(str(DATA / "cmu_61_07_salsa.sto"), parent="thorax",
                                   child="humerus_r", frames="isb")
    measured = float(np.mean(_swing_oracle(c).swing_distance(data.directions) <= 0.0))
    line = next(ln for ln in stdout.splitlines() if ln.strip().startswith("inside"))
    assert f"{100 * measured:.2f} % of the {len(data.q)} recorded directions" in line
    assert c.provenance["frames"] == "isb"
    # a dance is not a range-of-motion assessment: said so
    assert "warning: coverage" in stdout


def _rig_frames_copy(src: Path, dst: Path) -> None:
    """The same recording with every segment orientation in the rig's frames."""
    table = read_sto(src)
    cols = {k: segment_to_rig(v, "isb") for k, v in table.columns.items()}
    write_sto(dst, OrientationTable(time=table.time, columns=cols, rate_hz=table.rate_hz))


def test_the_same_recording_in_rig_and_isb_frames_gives_the_same_results(tmp_path, capsys):
    from calibration.boundary import boundary_distance

    src = DATA / "cmu_61_07_salsa.sto"
    rig_file = tmp_path / "rig-frames.sto"
    _rig_frames_copy(src, rig_file)
    results = {}
    for frames, path in (("isb", src), ("rig", rig_file)):
        out = tmp_path / f"{frames}.yaml"
        code, _, err = run(["boundary", str(path), "--parent", "thorax", "--child",
                            "humerus_l", "--frames", frames, "--side", "left", "--out",
                            str(out)], capsys)
        assert code == 0, err
        code, stdout, err = run(["rom", str(path), "--parent", "thorax", "--child",
                                 "humerus_l", "--frames", frames, "--side", "left", "--json"],
                                capsys)
        assert code == 0, err
        results[frames] = (load_constraint(out), json.loads(stdout))
    (a, rom_a), (b, rom_b) = results["isb"], results["rig"]
    assert boundary_distance(a, b)["hausdorff_deg"] < 0.5
    assert a.twist.min_deg == pytest.approx(b.twist.min_deg, abs=0.5)
    assert a.twist.max_deg == pytest.approx(b.twist.max_deg, abs=0.5)
    for m in ("flexion", "extension", "abduction", "adduction", "horizontal_adduction",
              "internal_rotation", "external_rotation"):
        assert (rom_a[m] is None) == (rom_b[m] is None)
        if rom_a[m] is not None:
            assert rom_a[m] == pytest.approx(rom_b[m], abs=0.5), m
    # read as if in rig frames, an ISB file gives a different (meaningless) answer
    code, stdout, _ = run(["rom", str(src), "--parent", "thorax", "--child", "humerus_l",
                           "--side", "left", "--json"], capsys)
    assert code == 0 and json.loads(stdout)["flexion"] != rom_a["flexion"]


def _recorded_extreme(d: np.ndarray, toward: np.ndarray, across: np.ndarray,
                      limit_deg: float, band_deg: float = 5.0) -> float | None:
    """The farthest in-plane angle from the arm at the side (+X, rig frames) of the recorded
    directions within ``band_deg`` of the plane spanned by +X and ``toward``."""
    down = np.array([1.0, 0.0, 0.0])
    near = np.abs(d @ across) <= math.sin(math.radians(band_deg))
    psi = np.degrees(np.arctan2(d[near] @ toward, d[near] @ down)) % 360.0
    psi = psi[psi <= limit_deg]
    return float(psi.max()) if len(psi) else None


def test_a_recording_that_never_rests_at_neutral_gets_its_peaks(tmp_path, capsys):
    # the right arm of a dancer, every moment with the arm raised more than 25°: the arm at
    # the side lies outside the recorded range
    table = read_sto(DATA / "cmu_60_02_salsa.sto")
    thorax = segment_to_rig(table.columns["thorax"], "isb")
    humerus = segment_to_rig(table.columns["humerus_r"], "isb")
    d = Q.rotate(Q.multiply(Q.conjugate(thorax), humerus), np.array([1.0, 0.0, 0.0]))
    raised = np.degrees(np.arccos(np.clip(d[:, 0], -1.0, 1.0))) > 25.0
    path = tmp_path / "raised.sto"
    write_sto(path, OrientationTable(time=table.time[raised],
                                     columns={k: v[raised] for k, v in table.columns.items()},
                                     rate_hz=table.rate_hz))
    code, stdout, err = run(["rom", str(path), "--parent", "thorax", "--child", "humerus_r",
                             "--frames", "isb", "--side", "right", "--json"], capsys)
    assert code == 0, err
    rom = json.loads(stdout)
    assert rom["neutral_outside_deg"] > 5.0
    y, z = np.array([0.0, 1.0, 0.0]), np.array([0.0, 0.0, 1.0])
    for movement, toward, across, limit in (("flexion", y, z, 240.0),
                                            ("extension", -y, z, 120.0),
                                            ("abduction", z, y, 240.0)):
        want = _recorded_extreme(d[raised], toward, across, limit)
        assert want is not None, movement
        assert rom[movement] is not None, movement
        assert abs(rom[movement] - want) <= 3.0, (movement, rom[movement], want)
