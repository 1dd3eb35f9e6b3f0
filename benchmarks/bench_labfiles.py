"""Files from motion labs (C3D, BVH) read into joints: ranges and boundaries against the same
motion in another form.

For every excerpt in ``tests/calibration/data/real`` that is a lab file (its README names the
sources, licences and cuts), per source and format, the joints read and, per joint, the
principal movement's range (flexion; ankle: dorsiflexion; the hinge's own axis for the boundary):

- **pyCGM's Vicon trial, C3D** (markers → ISB frames, Plug-in Gait's lower and upper body)
  against the joint angles Plug-in Gait stored in the same file (``KneeAngles`` …,
  ``ElbowAngles``): the range from each, the largest absolute difference between them frame by
  frame, and the hinge boundary ``rig boundary`` writes from each (its two ends). For the elbow
  also the flexion from Plug-in Gait's own joint centres (the file's ``CLO``, ``HUO``, ``RAO``
  points) against its ``ElbowAngles``: what its angles are.
- **ezc3d's Qualisys gait, C3D** (ISB landmarks): the knee's range (no model outputs in the
  file: the README's plausibility, a walking stride's 55-75°).
- **CMU 61_07 (Daz skeleton), BVH** against the ``.sto`` made from it: the boundary from each.
- **Arena (University of Adelaide, cycling), BVH**: every joint's range, the knee and elbow
  against the file's own channel rotations (the largest difference of the rotation angle), and
  the plausibility checks of the README (no second format of this recording is public).

Figures are printed, never asserted (the tests assert the must-show thresholds).

Usage::

    .venv/bin/python benchmarks/bench_labfiles.py
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import common  # noqa: F401  (first: one BLAS thread, this checkout on sys.path)
import ezc3d
import numpy as np
from scipy.spatial.transform import Rotation

from calibration.joint_angles import joint_angles
from models import quaternion as Q
from rig.readback import RecordingSource, extract
from rig.store.io import OrientationTable, read_sto, write_sto
from rig.store.labfiles import read_bvh, read_lab_file

DATA = Path(__file__).resolve().parents[1] / "tests" / "calibration" / "data" / "real"
PIG = DATA / "pycgm_vicon_movement_trial.c3d"
ARMS = DATA / "pycgm_vicon_movement_trial_arms.c3d"
QUALISYS = DATA / "ezc3d_qualisys_gait.c3d"
DAZ = DATA / "cmu_61_07_salsa_daz.bvh"
DAZ_STO = DATA / "cmu_61_07_salsa.sto"
ARENA = DATA / "arena_louise_cycling.bvh"
SIDES = (("r", "R", "right"), ("l", "L", "left"))
PARENT = {"hip": ("pelvis", "femur_{}"), "knee": ("femur_{}", "tibia_{}"),
          "ankle": ("tibia_{}", "calcn_{}"), "elbow": ("humerus_{}", "ulna_{}")}


def flexion(file, joint: str, side: str, parent: str | None, child: str) -> np.ndarray:
    q = RecordingSource(str(file), parent=parent, child=child, joint=joint).load().q
    return joint_angles(q.reshape(-1, 4), joint, side)["alpha"]


def hinge(file, joint: str, side: str, parent: str | None, child: str,
          frames: str | None = None) -> tuple[float, float] | None:
    """The hinge interval ``rig boundary`` writes (None: the joint is not a hinge)."""
    data = RecordingSource(str(file), parent=parent, child=child, joint=joint,
                           frames=frames).load()
    h = extract(data, side=side).constraint_.hinge
    return None if h is None else (h.min_deg, h.max_deg)


def row(*cells: str) -> None:
    print("  " + " ".join(f"{c:<12}" for c in cells))


def plug_in_gait(path: Path, joints: tuple[str, ...]) -> None:
    t = read_lab_file(path)
    print(f"\n{path.name} (C3D, {t.meta['has']}): columns {', '.join(t.labels)}")
    row("joint", "side", "ROM mark", "ROM model", "|dROM|", "max|d|", "hinge mark",
        "hinge model", "|d ends|")
    for joint in joints:
        for s, S, side in SIDES:
            p, c = (x.format(s) for x in PARENT[joint])
            mine = flexion(path, joint, side, p, c)
            name = f"{S}{joint.capitalize()}Angles"
            pig = flexion(path, joint, side, None, name)
            hm, hp = hinge(path, joint, side, p, c), hinge(path, joint, side, None, name)
            ends = ("-", "-", "(not a hinge)") if hm is None or hp is None else (
                f"{hm[0]:.1f}..{hm[1]:.1f}", f"{hp[0]:.1f}..{hp[1]:.1f}",
                f"{max(abs(hm[0] - hp[0]), abs(hm[1] - hp[1])):.2f}")
            row(joint, side, f"{np.ptp(mine):.1f}", f"{np.ptp(pig):.1f}",
                f"{abs(np.ptp(mine) - np.ptp(pig)):.2f}", f"{np.max(np.abs(mine - pig)):.1f}",
                *ends)
    if "ankle" in joints:
        print("  (the ankle's max|d|: Plug-in Gait's static-trial offsets, a constant, which a "
              "dynamic trial's markers do not carry)")


def pig_own_elbow_centres() -> None:
    c = ezc3d.c3d(str(ARMS))
    labels = [str(x) for x in c["parameters"]["POINT"]["LABELS"]["value"]]
    print("  elbow flexion from Plug-in Gait's own centres (CLO, HUO, RAO) vs its ElbowAngles; "
          "ours vs its ElbowAngles:")
    for s, S, side in SIDES:
        p = {k: c["data"]["points"][:3, labels.index(f"{S}{k}"), :].T
             for k in ("CLO", "HUO", "RAO", "ELB")}
        a, b = p["CLO"] - p["HUO"], p["HUO"] - p["RAO"]
        geo = np.degrees(np.arccos(np.clip(np.sum(a * b, 1) / np.linalg.norm(a, axis=1)
                                           / np.linalg.norm(b, axis=1), -1, 1)))
        pig = flexion(ARMS, "elbow", side, None, f"{S}ElbowAngles")
        mine = flexion(ARMS, "elbow", side, f"humerus_{s}", f"ulna_{s}")
        print(f"    {side}: max|centres - ElbowAngles| {np.max(np.abs(geo - pig)):.3f}°; "
              f"ours - theirs: mean {np.mean(mine - pig):.3f}°, spread "
              f"{np.ptp(mine - pig):.2f}°")


def qualisys() -> None:
    t = read_lab_file(QUALISYS)
    print(f"\n{QUALISYS.name} (C3D, {t.meta['has']}): columns {', '.join(t.labels)}")
    for s, _, side in SIDES:
        k = flexion(QUALISYS, "knee", side, f"femur_{s}", f"tibia_{s}")
        print(f"  knee {side}: {k.min():.1f}..{k.max():.1f}° (ROM {np.ptp(k):.1f}°; no model "
              "outputs in the file; a walking stride flexes the knee 55-75°)")


def daz_vs_sto() -> None:
    t = read_bvh(DAZ)
    n = len(t)
    print(f"\n{DAZ.name} (BVH, {t.meta['has']}) vs {DAZ_STO.name} (the .sto made from it): "
          f"columns {', '.join(t.labels)}")
    sto = read_sto(DAZ_STO)
    with tempfile.TemporaryDirectory() as d:
        for joint, p, c, side in (("knee", "femur_r", "tibia_r", "right"),
                                  ("elbow", "humerus_l", "ulna_l", "left")):
            cut = OrientationTable(sto.time[:n], {k: sto.get(k)[:n] for k in (p, c)},
                                   sto.rate_hz)
            f = Path(d) / "cut.sto"
            write_sto(f, cut)
            a, b = hinge(DAZ, joint, side, p, c), hinge(f, joint, side, p, c, frames="isb")
            print(f"  {joint} {side}: BVH {a[0]:.2f}..{a[1]:.2f}°, .sto {b[0]:.2f}..{b[1]:.2f}° "
                  f"(ends {max(abs(a[0] - b[0]), abs(a[1] - b[1])):.3f}° apart)")


def arena_channels(joint: str) -> np.ndarray:
    text = ARENA.read_text().split("\n")
    names, k, cols = [], 0, None
    for line in text:
        w = line.split()
        if w[:1] in (["ROOT"], ["JOINT"]):
            names.append(w[1])
        if w[:1] == ["CHANNELS"]:
            if names[-1] == joint:
                cols = list(range(k + int(w[1]) - 3, k + int(w[1])))
            k += int(w[1])
        if w[:1] == ["MOTION"]:
            break
    start = text.index("MOTION") + 3
    rows = np.array([[float(x) for x in ln.split()] for ln in text[start:] if ln.strip()])
    return rows[:, cols]


def arena() -> None:
    t = read_bvh(ARENA)
    print(f"\n{ARENA.name} (BVH, {t.meta['has']}, {len(t)} frames at {t.rate_hz:.0f} Hz): "
          f"columns {', '.join(t.labels)}; not given: {', '.join(t.missing)}")
    knees = {}
    for joint in ("hip", "knee", "ankle", "elbow"):
        for s, _, side in SIDES:
            p, c = (x.format(s) for x in PARENT[joint])
            a = flexion(ARENA, joint, side, p, c)
            if joint == "knee":
                knees[side] = a
            print(f"  {joint:8} {side:5}: flexion {a.min():6.1f}..{a.max():6.1f}° "
                  f"(ROM {np.ptp(a):5.1f}°)")
    for joint, p, c in (("RightKnee", "femur_r", "tibia_r"), ("LeftKnee", "femur_l", "tibia_l"),
                        ("RightElbow", "humerus_r", "ulna_r"),
                        ("LeftElbow", "humerus_l", "ulna_l")):
        rel = Q.multiply(Q.conjugate(t.get(p)), t.get(c))
        mine = np.degrees(2 * np.arccos(np.clip(np.abs(rel[:, 0]), 0.0, 1.0)))
        ref = np.degrees(Rotation.from_euler("ZXY", arena_channels(joint),
                                             degrees=True).magnitude())
        print(f"  {joint} rotation vs the file's own channels: max|d| "
              f"{np.max(np.abs(mine - ref)):.4f}°")
    r, left = knees["right"], knees["left"]
    print(f"  plausibility: knee at the bottom of the stroke {r.min():.1f}° / {left.min():.1f}° "
          f"(saddle-height studies 20-40°); legs' correlation "
          f"{np.corrcoef(r, left)[0, 1]:.2f} (antiphase: -1)")


def main() -> None:
    plug_in_gait(PIG, ("hip", "knee", "ankle"))
    plug_in_gait(ARMS, ("elbow",))
    pig_own_elbow_centres()
    qualisys()
    daz_vs_sto()
    arena()


if __name__ == "__main__":
    main()
