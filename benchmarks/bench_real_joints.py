"""The elbow, wrist, hip, knee and ankle on real human recordings: what ``rig boundary --joint``
writes holds, and where a hinge's interval sits against the recorded extremes.

For the excerpts in ``tests/calibration/data/real`` (sources in its README; segment
orientations in ISB frames) and every joint their columns allow, the constraint
:func:`rig.readback.extract` writes (default parameters) is measured on the whole recording:

- ``inside%``: hinges — recorded hinge angles inside the interval; other joints — whole
  recorded orientations (swing and twist) the written constraint accepts (the exact oracle);
- hinges: ``lo−min°`` / ``max−hi°``, how far each end of the interval lies inside the recorded
  extremes (negative: outside them), and the out-of-axis motion (RMS, p99) reported;
- others: the kind written (``two-axis`` when the recorded twist allows) and the twist width.

Then ``rig boundary --limb`` on each recording's limbs: coupled or not (and why), and the share
of recorded postures inside the limb file in every joint.

Usage::

    .venv/bin/python benchmarks/bench_real_joints.py
"""

from __future__ import annotations

from pathlib import Path

import common  # noqa: F401  (first: one BLAS thread, this checkout on sys.path)
import numpy as np

from calibration.extraction import LimbExtractor
from calibration.joints import JOINTS, hinge_angles
from models.oracle import ConstraintOracle
from rig.readback import RecordingSource, extract

DATA = Path(__file__).resolve().parent.parent / "tests" / "calibration" / "data" / "real"
PAIRS = {"elbow": ("humerus_{}", "ulna_{}"), "wrist": ("ulna_{}", "hand_{}"),
         "hip": ("pelvis", "femur_{}"), "knee": ("femur_{}", "tibia_{}"),
         "ankle": ("tibia_{}", "calcn_{}")}
CHAINS = {"arm": ("thorax", "humerus_{}", "ulna_{}", "hand_{}"),
          "leg": ("pelvis", "femur_{}", "tibia_{}", "calcn_{}")}


def main() -> None:
    from rig.store.io import read_orientations

    print(f"{'recording':<28} {'joint':<6} side {'inside%':>8}  details")
    for path in sorted(DATA.glob("*.sto")):
        cols = set(read_orientations(str(path)).columns)
        for joint, (p, c) in PAIRS.items():
            for s, side in (("r", "right"), ("l", "left")):
                ref, lim = p.format(s), c.format(s)
                if ref not in cols or lim not in cols:
                    continue
                data = RecordingSource(str(path), parent=ref, child=lim, frames="isb",
                                       joint=joint).load()
                ex = extract(data, side=side)
                con = ex.constraint_
                if JOINTS[joint].kind == "hinge":
                    th = hinge_angles(data.q, con.hinge.axis)
                    inside = np.mean((th >= con.hinge.min_deg) & (th <= con.hinge.max_deg))
                    r = ex.report()
                    detail = (f"hinge {con.hinge.min_deg:.1f}..{con.hinge.max_deg:.1f}, "
                              f"lo-min {con.hinge.min_deg - th.min():+.4f}°, "
                              f"max-hi {th.max() - con.hinge.max_deg:+.4f}°, off-axis "
                              f"{r['off_axis_rms_deg']:.1f}° RMS / {r['off_axis_p99_deg']:.1f}° "
                              "p99")
                else:
                    inside = np.mean(ConstraintOracle(con).signed_distance(data.q) <= 0.0)
                    width = con.twist.max_deg - con.twist.min_deg
                    detail = f"{con.kind}, twist {width:.1f}° wide, {ex.report()['vertices']} verts"
                print(f"{path.name:<28} {joint:<6} {s:>4} {100 * inside:8.2f}  {detail}")
    print()
    print(f"{'recording':<28} {'chain':<6} side {'inside%':>8}  coupling")
    from rig.readback.files import limb_orientations_from_file

    for path in sorted(DATA.glob("*.sto")):
        have = set(read_orientations(str(path)).columns)
        for limb, names in CHAINS.items():
            for s, side in (("r", "right"), ("l", "left")):
                cols = [n.format(s) for n in names]
                if not set(cols) <= have:
                    continue
                rec = limb_orientations_from_file(str(path), cols, limb, "isb")
                ex = LimbExtractor(limb).fit(rec.joint_q, t=rec.t, side=side)
                for k, (joint, c) in enumerate(ex.couplings_.items()):
                    head = (f"{path.name:<28} {limb:<6} {s:>4} {100 * ex.inside_['limb']:8.2f}"
                            if k == 0 else " " * 48)
                    print(f"{head}  {joint}: {'yes' if c['coupled'] else 'no'}: {c['note']}")


if __name__ == "__main__":
    main()
