"""A simulated patient's knee over 6 visits, recorded end to end: ``rig record`` on the simulated
leg (four IMUs), one visit killed mid-recording, then ``rig progress --json``.

    python benchmarks/bench_progress_visits.py [--duration 180] [--time-scale 10] [--seed 3]

Each visit is a whole-leg recording through the real CLI (a child process, the simulated board
in a process of its own on a pty, sped up ``--time-scale`` times). The patient is the seeded
anatomical leg of ``rig.sim.patients.anatomical_limb`` with the knee's hinge changed per visit
(:data:`KNEE`: its flexion and extension limits; some changes over the knee's MDC, some under).
Each visit's motion, sensor misplacement and noise are seeded anew (``seed + 100·visit``), as
a patient never moves the same way twice. The hip and the ankle keep their limits, so their
true change is 0. Visit 4 has the widest range of all and is killed (SIGKILL) mid-recording: its
session is ``interrupted``, and had ``rig progress`` used it, its change would show.

Printed: each visit's knee values against the truth, each change since the first and the
previous usable visit against the true change, each MDC verdict against the verdict of the true
change (:func:`calibration.mdc.verdict` with the same MDC), the interrupted visit's exclusion,
and the hip's and ankle's changes (truth 0). The must-show of issue 42: every change recovered
within 2°, every verdict right, the interrupted visit excluded. Nothing is asserted; the figures
are printed.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from itertools import pairwise
from pathlib import Path

import common  # first: one BLAS thread, this checkout on sys.path
import yaml

from calibration.mdc import mdc_for, verdict
from rig.sim.patients import anatomical_limb

#: Per visit: the knee's (flexion limit, extension limit), degrees; extension is −min_deg
#: (hyperextension). No flexion contracture (a negative extension): the simulated patient stands
#: with the knee straight for the calibration and the neutral checkpoints, outside such a range
#: (docs/NOTES.md).
KNEE = [(110.0, 0.0), (114.0, 1.0), (130.0, 3.0), (155.0, 10.0), (127.0, 4.0), (141.0, 5.0)]
CUT = 3  # the visit killed mid-recording (0-based)


def _leg_file(base: dict, flexion: float, extension: float, path: Path) -> None:
    leg = json.loads(json.dumps(base))
    for j in leg["joints"]:
        if j["name"] == "knee":
            j["constraint"]["hinge"]["min_deg"] = -extension
            j["constraint"]["hinge"]["max_deg"] = flexion
    path.write_text(yaml.safe_dump(leg, sort_keys=False))


def _rig_file(patient: Path, seed: int, time_scale: float, path: Path) -> None:
    rig = yaml.safe_load((common.ROOT / "rig/configs/sim-leg.yaml").read_text())
    rig["name"] = "visit-leg"
    rig["sensors"]["port"] = (
        f"sim://imu-stream?sensors=4&patient={patient}&seed={seed}&rate=200&neutral=20"
        f"&flow=on&process=on&time_scale={time_scale:g}")
    path.write_text(yaml.safe_dump(rig, sort_keys=False))


def _record(rig: Path, db: Path, duration: float, kill_after_s: float | None) -> float:
    cmd = [sys.executable, "-m", "rig", "record", "--rig", str(rig), "--db", str(db),
           "--patient", "P-VISITS", "--duration", f"{duration:g}", "--display", "plain",
           "--no-rom"]
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, env=common.child_env(), stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True, start_new_session=True)
    if kill_after_s is None:
        _, err = proc.communicate()
        if proc.returncode != 0:
            raise SystemExit(f"rig record failed ({proc.returncode}): {err.strip()}")
    else:
        time.sleep(kill_after_s)
        os.killpg(proc.pid, signal.SIGKILL)  # the recorder and its simulator: a power cut
        proc.wait()
    return time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--duration", type=float, default=180.0, help="seconds per visit")
    ap.add_argument("--time-scale", type=float, default=10.0)
    ap.add_argument("--seed", type=int, default=3)
    ap.add_argument("--keep", default=None, help="keep the store in this folder")
    args = ap.parse_args()
    print(f"machine: 10^7 additions {common.additions_s():.2f} s; "
          f"{time.strftime('%Y-%m-%d %H:%M')}")
    base = yaml.safe_load(anatomical_limb(args.seed, "leg", "right").to_yaml())
    work = Path(args.keep or tempfile.mkdtemp(prefix="visits-"))
    work.mkdir(parents=True, exist_ok=True)
    db = work / "clinic.db"
    if db.exists():
        db.unlink()
    for i, (fl, ex) in enumerate(KNEE):
        leg, rig = work / f"leg{i}.yaml", work / f"rig{i}.yaml"
        _leg_file(base, fl, ex, leg)
        _rig_file(leg, args.seed + 100 * i, args.time_scale, rig)  # each visit moves anew
        kill = None if i != CUT else 0.3 * args.duration / args.time_scale + 5.0
        wall = _record(rig, db, args.duration, kill)
        print(f"visit {i + 1}: knee flexion {fl:g}°, extension {ex:g}°"
              f"{' (killed)' if kill else ''}: {wall:.1f} s")
    out = subprocess.run([sys.executable, "-m", "rig", "progress", "--db", str(db),
                          "--patient", "P-VISITS", "--json"], env=common.child_env(),
                         capture_output=True, text=True, check=True).stdout
    res = json.loads(out)
    visits = sorted(res["visits"], key=lambda v: (v["started_at"], v["joint"]))
    knee = [v for v in visits if v["joint"] == "knee"]
    print("\nknee visits:")
    for i, v in enumerate(knee):
        print(f"  {i + 1}: session {v['session']} {v['status']:<11} usable={v['usable']!s:<5} "
              f"{'; '.join(v['excluded']) or '-':<32} flexion {v['values'].get('flexion')} "
              f"(true {KNEE[i][0]:g}) extension {v['values'].get('extension')} "
              f"(true {KNEE[i][1]:g})")
    used = [i for i, v in enumerate(knee) if v["usable"]]
    cut_ok = not knee[CUT]["usable"] and knee[CUT]["interrupted"]
    print(f"interrupted visit {CUT + 1} excluded: {cut_ok}; usable visits: "
          f"{[i + 1 for i in used]}")
    worst, wrong, checked = 0.0, 0, 0
    print("\nchanges (measured vs true) and MDC verdicts (measured vs the true change's):")
    for k, move in enumerate(("flexion", "extension")):
        mdc, text = mdc_for("knee", move, "imu")
        print(f"  knee {move} — MDC {text}")
        first = used[0]
        for a, b in pairwise(used):
            va, vb, vf = (knee[x]["values"][move] for x in (a, b, first))
            for label, ref, truth_ref in (("first", vf, KNEE[first][k]),
                                          ("previous", va, KNEE[a][k])):
                d = vb - ref
                td = KNEE[b][k] - truth_ref
                vm, vt = verdict(d, mdc), verdict(td, mdc)
                worst = max(worst, abs(d - td))
                wrong += vm != vt
                checked += 1
                print(f"    visit {b + 1} since {label:<8}: {d:+7.2f}° (true {td:+6.1f}°, "
                      f"error {d - td:+5.2f}°) verdict {vm} (true {vt})"
                      f"{'' if vm == vt else '  <-- WRONG'}")
    print(f"\nknee: {checked} changes, largest error {worst:.2f}°, verdicts wrong {wrong}")
    for joint in ("hip", "ankle"):
        vs = [v for v in visits if v["joint"] == joint and v["usable"]]
        if len(vs) < 2:
            print(f"{joint}: {len(vs)} usable visit(s); no change to compare")
            continue
        moves = sorted(vs[0]["values"])
        spread = {m: max(v["values"][m] for v in vs) - min(v["values"][m] for v in vs)
                  for m in moves if all(v["values"].get(m) is not None for v in vs)}
        print(f"{joint} (true change 0): {len(vs)} usable visits; largest spread per movement "
              + ", ".join(f"{m} {s:.2f}°" for m, s in spread.items()))
    print(f"store: {db}")


if __name__ == "__main__":
    main()
