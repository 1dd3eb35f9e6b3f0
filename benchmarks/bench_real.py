"""Boundaries on real human recordings: what the written boundary holds, what it claims.

For every recording (OpenSim ``.sto`` of segment orientations; by default the excerpts in
``tests/calibration/data/real``, whose README names their sources) and every joint its columns
allow — shoulders (``thorax`` → ``humerus_r/l``), hips (``pelvis`` → ``femur_r/l``) — the
boundary ``rig boundary`` writes (:func:`rig.readback.extract`, default parameters) is
measured with the exact oracle:

- ``inside%``: recorded directions inside the written swing region (every sample of the file);
- ``in1°%``: within 1° of it;
- ``valid%``: whole recorded orientations (swing and twist) the written constraint accepts;
- ``far20%``: share of the region's area farther than 20° from every recorded direction
  (50,000 near-uniform directions);
- ``printed``: the share ``rig boundary`` prints and stores, and whether it equals the measured
  one; ``spikes``, ``inset°`` (the noise inset used), ``alpha°``, ``verts``.

Then two checks on the first shoulder recording: the same recording given in rig frames and in
ISB frames (boundary Hausdorff distance, largest clinical-peak difference), and the same
recording cut to the moments the arm is raised more than 25° (the arm at the side outside the
range): flexion, extension and abduction against the recorded extremes in those planes (in-plane
angle of the recorded directions within 5° of the plane).

Usage::

    .venv/bin/python benchmarks/bench_real.py [--dir DIR] [--frames isb|rig]
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
from pathlib import Path

import common  # noqa: F401  (first: one BLAS thread, this checkout on sys.path)
import numpy as np
from scipy.spatial import cKDTree

from calibration.boundary import boundary_distance
from calibration.clinical import range_of_motion
from calibration.frames import segment_to_rig
from calibration.joints import joint_of_columns
from models.constraint import JointConstraint
from models.geometry import fibonacci_sphere
from models.oracle import ConstraintOracle
from rig.readback import extract, load_joint_orientations
from rig.store.io import OrientationTable, read_sto, write_sto

DATA = Path(__file__).resolve().parents[1] / "tests" / "calibration" / "data" / "real"
PAIRS = [("shoulder", "thorax", "humerus"), ("hip", "pelvis", "femur")]
X = np.array([1.0, 0.0, 0.0])


def joints(table: OrientationTable):
    for joint, ref, seg in PAIRS:
        for s, side in (("r", "right"), ("l", "left")):
            if ref in table.columns and f"{seg}_{s}" in table.columns:
                yield f"{joint}_{s}", ref, f"{seg}_{s}", side


def swing_oracle(c: JointConstraint) -> ConstraintOracle:
    return ConstraintOracle(JointConstraint.from_dict({"name": "s", "swing": c.swing.to_dict()}))


def area_far(c: JointConstraint, d: np.ndarray, far_deg: float = 20.0) -> float:
    grid = fibonacci_sphere(50_000)
    inside = grid[swing_oracle(c).swing_distance(grid) <= 0.0]
    chord, _ = cKDTree(d).query(inside)
    return float(np.mean(chord > 2.0 * math.sin(math.radians(far_deg) / 2.0)))


def measure(path: Path, frames: str) -> list[dict]:
    rows = []
    for joint, ref, limb, side in joints(read_sto(path)):
        data = load_joint_orientations(str(path), parent=ref, child=limb, frames=frames,
                                       joint=joint_of_columns(ref, limb))
        ex = extract(data, side=side)
        d = data.directions
        dist = np.degrees(swing_oracle(ex.constraint_).swing_distance(d))
        valid = ConstraintOracle(ex.constraint_).signed_distance(data.q) <= 0.0
        rows.append({
            "recording": f"{path.stem} {joint}", "n": len(d),
            "inside": 100.0 * float(np.mean(dist <= 0.0)),
            "in1": 100.0 * float(np.mean(dist <= 1.0)),
            "valid": 100.0 * float(np.mean(valid)),
            "far20": 100.0 * area_far(ex.constraint_, d),
            "printed": 100.0 * ex.constraint_.provenance["inside"]["share"],
            "spikes": ex.n_spikes_, "inset": ex.inset_deg_, "alpha": ex.alpha_used_deg_,
            "verts": len(ex.vertices_)})
    return rows


def frames_check(path: Path, ref: str, limb: str, side: str) -> tuple[float, float, float]:
    """(boundary Hausdorff °, largest peak difference °, twist-limit difference °) between the
    recording read in ISB frames and its copy converted to rig frames."""
    table = read_sto(path)
    with tempfile.TemporaryDirectory() as tmp:
        rig_file = Path(tmp) / "rig.sto"
        write_sto(rig_file, OrientationTable(
            time=table.time, columns={k: segment_to_rig(v, "isb") for k, v in
                                      table.columns.items()}, rate_hz=table.rate_hz))
        out = []
        for frames, p in (("isb", path), ("rig", rig_file)):
            data = load_joint_orientations(str(p), parent=ref, child=limb, frames=frames,
                                           joint=joint_of_columns(ref, limb))
            c = extract(data, side=side).constraint_
            out.append((c, range_of_motion(c, side, directions=data.directions).to_dict()))
    (a, ra), (b, rb) = out
    peaks = [abs(ra[m] - rb[m]) for m in ra if m != "side" and ra[m] is not None
             and rb[m] is not None]
    twist = max(abs(a.twist.min_deg - b.twist.min_deg), abs(a.twist.max_deg - b.twist.max_deg))
    return boundary_distance(a, b)["hausdorff_deg"], max(peaks), twist


def recorded_extreme(d, toward, across, limit_deg, band_deg=5.0):
    near = np.abs(d @ across) <= math.sin(math.radians(band_deg))
    psi = np.degrees(np.arctan2(d[near] @ toward, d[near] @ X)) % 360.0
    psi = psi[psi <= limit_deg]
    return float(psi.max()) if len(psi) else None


def neutral_outside_check(path: Path, ref: str, limb: str, side: str):
    table = read_sto(path)
    data = load_joint_orientations(str(path), parent=ref, child=limb, frames="isb",
                                   joint=joint_of_columns(ref, limb))
    d = data.directions
    raised = np.degrees(np.arccos(np.clip(d @ X, -1.0, 1.0))) > 25.0
    with tempfile.TemporaryDirectory() as tmp:
        cut = Path(tmp) / "raised.sto"
        write_sto(cut, OrientationTable(time=table.time[raised],
                                        columns={k: v[raised] for k, v in table.columns.items()},
                                        rate_hz=table.rate_hz))
        part = load_joint_orientations(str(cut), parent=ref, child=limb, frames="isb",
                                       joint=joint_of_columns(ref, limb))
        c = extract(part, side=side).constraint_
        rom = range_of_motion(c, side, directions=part.directions)
    dm = part.directions * (np.array([1.0, 1.0, -1.0]) if side == "left" else 1.0)
    y, z = np.array([0.0, 1.0, 0.0]), np.array([0.0, 0.0, 1.0])
    rows = []
    for m, toward, across, limit in (("flexion", y, z, 240.0), ("extension", -y, z, 120.0),
                                     ("abduction", z, y, 240.0)):
        rows.append((m, getattr(rom, m), recorded_extreme(dm, toward, across, limit)))
    return rom.neutral_outside_deg, int(raised.sum()), rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--dir", type=Path, default=DATA, help="folder of .sto recordings")
    ap.add_argument("--frames", choices=["isb", "rig"], default="isb")
    a = ap.parse_args()
    files = sorted(a.dir.glob("*.sto"))
    if not files:
        sys.exit(f"bench_real: no .sto files in {a.dir}")
    rows = [r for f in files for r in measure(f, a.frames)]
    print(f"real recordings in {a.dir} ({a.frames} frames), default extraction")
    print(f"{'recording':34s} {'n':>5s} {'inside%':>8s} {'in1°%':>7s} {'valid%':>7s} "
          f"{'far20%':>7s} {'printed':>8s} {'=?':>3s} {'spikes':>6s} {'inset°':>6s} "
          f"{'alpha°':>6s} {'verts':>5s}")
    for r in rows:
        same = "yes" if abs(r["printed"] - r["inside"]) < 5e-4 else "NO"
        print(f"{r['recording']:34s} {r['n']:5d} {r['inside']:8.2f} {r['in1']:7.2f} "
              f"{r['valid']:7.2f} {r['far20']:7.2f} {r['printed']:8.2f} {same:>3s} "
              f"{r['spikes']:6d} {r['inset']:6.3f} {r['alpha']:6.1f} {r['verts']:5d}")
    for key, label in (("inside", "inside%"), ("valid", "valid%"), ("far20", "far20%")):
        v = [r[key] for r in rows]
        print(f"{label:>8s}: median {np.median(v):.2f}, worst "
              f"{(max(v) if key == 'far20' else min(v)):.2f} over {len(v)} joint recordings")
    first = next(((f, j) for f in files for j in joints(read_sto(f)) if j[0].startswith(
        "shoulder")), None)
    if first is None:
        return
    f, (joint, ref, limb, side) = first
    haus, peaks, twist = frames_check(f, ref, limb, side)
    print(f"\nrig vs ISB frames, {f.stem} {joint}: boundary Hausdorff {haus:.4f}°, largest "
          f"peak difference {peaks:.4f}°, twist limits {twist:.4f}°")
    gap, n, peaks_rows = neutral_outside_check(f, ref, limb, side)
    print(f"never at neutral, {f.stem} {joint} cut to the {n} samples with the arm raised > 25°:"
          f" arm at the side {gap:.1f}° outside the boundary")
    for m, got, want in peaks_rows:
        diff = "-" if got is None or want is None else f"{abs(got - want):.2f}°"
        print(f"  {m:10s} reported {got if got is None else round(got, 2)}°, recorded extreme "
              f"{want if want is None else round(want, 2)}°, difference {diff}")


if __name__ == "__main__":
    main()
