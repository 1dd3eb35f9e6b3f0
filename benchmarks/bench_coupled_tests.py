"""The coupled clinical tests (issue 42, item 2: straight-leg raise, popliteal angle,
Silfverskiöld, Thomas test, the shoulder's reach with the elbow straight vs bent) against the
truth on simulated limbs, and on the real recordings: the value or "not reached in this
recording", never an invented one.

    .venv/bin/python benchmarks/bench_coupled_tests.py [--seeds 200-209] [--recorded 180]
                                                       [--no-real]

Sections:

1. **Simulated limbs, from their limb files** — 10 legs and 10 arms
   (:func:`rig.sim.patients.anatomical_limb`, seeds ``--seeds``, odd seeds left, even right;
   the seeds ``tests/calibration/test_clinical_tests.py`` checks, which asserts ≤ 3°: this
   script prints the figures). Each test's value read from the limb's limits
   (:func:`calibration.clinical_tests.coupled_measures`, what ``rig rom --constraint LIMB.yaml
   --joint J`` shows) against its truth, the clinical limits the limb was drawn with
   (:func:`rig.sim.clinical_truth.coupled_test_truth`): per test the median and the largest
   absolute error. Target: within 3°.
2. **Simulated limbs, recorded** (``--recorded S``, default 180 s; 0 leaves it out: at 60 s
   the extractor finds no coupling in most limbs, its held-share test) — the same
   limbs performing ``S`` s of free motion (:func:`rig.sim.patients.seeded_patient`, its true
   joint orientations at 50 Hz: no sensor error, so the figures are the tests' own), the limb
   file extracted from those postures as ``rig boundary --limb`` does
   (:class:`calibration.extraction.LimbExtractor`), and the tests read as ``rig rom`` reads
   a whole-limb session (the extracted limits at the test positions the recording reached;
   "not reached" otherwise). Per test: how many limbs reached the position, the median and
   the largest absolute error of those that did, how many extracted limbs couple the two
   joints (uncoupled limits give the recording's reading, :mod:`calibration.clinical_tests`),
   and the recording's own reading (the farthest posture at the position) minus the truth.
   Free motion is not the passive end-range test: a limb that never pushed to the end of the
   test's range reads less; a value above the truth is the extracted limits' (their
   keyframes' angles and interpolation between them), not a posture the patient took.
3. **Real recordings** (``tests/calibration/data/real``, every file with a leg or an arm:
   ``.sto``, ``.c3d`` and ``.bvh``) — each test's value from the recording alone, or "not
   reached in this recording", with the number of samples at the test position; and the
   value from the limits extracted from the recording itself. No truth is known for a real
   person: what is checked is that no value is given where the recording never came to the
   test position.

Never asserts; figures printed.
"""

from __future__ import annotations

import argparse
import statistics
import time

import common  # first: one BLAS thread, this checkout on sys.path
import numpy as np

from calibration.clinical_tests import coupled_measures
from calibration.extraction import LimbExtractor
from rig.readback import load_joint_orientations
from rig.sim.clinical_truth import coupled_test_truth
from rig.sim.patients import anatomical_limb, seeded_patient

DATA = common.ROOT / "tests" / "calibration" / "data" / "real"
#: limb → its joints and their ISB segment columns ({} = r or l)
CHAINS = {"leg": (("hip", "knee", "ankle"), ("pelvis", "femur_{}", "tibia_{}", "calcn_{}")),
          "arm": (("shoulder", "elbow", "wrist"), ("thorax", "humerus_{}", "ulna_{}",
                                                   "hand_{}"))}
REAL_FILES = ("xio_ximu3_lower_body.sto", "opensense_xsens_walking.sto", "cmu_61_07_salsa.sto",
              "cmu_60_02_salsa.sto", "cmu_61_07_salsa_daz.bvh", "pycgm_vicon_movement_trial.c3d",
              "ezc3d_qualisys_gait.c3d")


def _seeds(text: str) -> list[int]:
    if "-" in text:
        a, b = text.split("-")
        return list(range(int(a), int(b) + 1))
    return [int(s) for s in text.split(",")]


def _summary(errors: dict[str, list[float]], reached: dict[str, int] | None = None,
             n: int | None = None) -> list[str]:
    rows = [f"  {'test':<28} {'n':>5} {'median |err|':>13} {'max |err|':>10}"]
    for key, errs in errors.items():
        count = f"{len(errs)}" if reached is None else f"{reached[key]}/{n}"
        if errs:
            rows.append(f"  {key:<28} {count:>5} {statistics.median(errs):>12.3f}° "
                        f"{max(errs):>9.3f}°")
        else:
            rows.append(f"  {key:<28} {count:>5} {'-':>13} {'-':>10}")
    return rows


def simulated_from_limits(seeds: list[int]) -> float:
    """Section 1; returns the largest error."""
    print("1. simulated limbs, the tests read from their limb files (rig rom --constraint)")
    worst = 0.0
    for kind in ("leg", "arm"):
        errors: dict[str, list[float]] = {}
        t0 = time.perf_counter()
        for seed in seeds:
            limb = anatomical_limb(seed, kind, "left" if seed % 2 else "right")
            truth = coupled_test_truth(limb)
            for m in coupled_measures(limb):
                err = abs(m.value - truth[m.spec.key]) if m.value is not None else float("inf")
                errors.setdefault(m.spec.key, []).append(err)
        dt = (time.perf_counter() - t0) / len(seeds)
        print(f" {len(seeds)} {kind}s ({dt:.2f} s a limb):")
        print("\n".join(_summary(errors)))
        worst = max([worst, *(max(e) for e in errors.values())])
    print(f" largest error: {worst:.3f}° (target 3°)")
    return worst


def simulated_recorded(seeds: list[int], seconds: float, rate: float = 50.0) -> None:
    """Section 2."""
    print(f"\n2. simulated limbs, {seconds:g} s of free motion (true joint orientations, "
          f"{rate:g} Hz), limits extracted, the tests read as for a limb session")
    t = np.arange(0.0, seconds, 1.0 / rate)
    for kind in ("leg", "arm"):
        errors: dict[str, list[float]] = {}
        alone: dict[str, list[float]] = {}
        reached: dict[str, int] = {}
        low: dict[str, int] = {}
        coupled: dict[str, int] = {}
        t0 = time.perf_counter()
        for seed in seeds:
            side = "left" if seed % 2 else "right"
            truth_limb = anatomical_limb(seed, kind, side)
            truth = coupled_test_truth(truth_limb)
            patient = seeded_patient(seed, kind, side, calibrate=False)
            q = np.asarray(patient.joints(t))
            extracted = LimbExtractor(kind).fit(q, t=t, side=side).limb_
            for m in coupled_measures(extracted, q, side=side):
                key = m.spec.key
                coupled[key] = coupled.get(key, 0) + bool(m.coupled)
                errors.setdefault(key, [])
                reached.setdefault(key, 0)
                low.setdefault(key, 0)
                if m.value is None:
                    continue
                reached[key] += 1
                alone.setdefault(key, []).append(m.recorded - truth[key])
                d = m.value - truth[key]
                errors[key].append(abs(d))
                low[key] += d < 0
        dt = (time.perf_counter() - t0) / len(seeds)
        print(f" {len(seeds)} {kind}s ({dt:.1f} s a limb); n = limbs whose recording reached "
              "the test position:")
        print("\n".join(_summary(errors, reached, len(seeds))))
        print("  the extracted limb couples the two joints: "
              + ", ".join(f"{k} {v}/{len(seeds)}" for k, v in coupled.items()))
        print("  below the truth (free motion short of the end range): "
              + ", ".join(f"{k} {v}" for k, v in low.items()))
        print("  the recording alone (the farthest recorded at the position) minus the truth, "
              "min .. max: " + ", ".join(f"{k} {min(v):+.1f}..{max(v):+.1f}°"
                                         for k, v in alone.items()))


def _chain(path, kind: str, letter: str) -> np.ndarray:
    names, segs = CHAINS[kind]
    segs = [s.format(letter) for s in segs]
    return np.stack([load_joint_orientations(str(path), parent=p, child=c, frames="isb",
                                             joint=j).q
                     for j, p, c in zip(names, segs[:-1], segs[1:], strict=True)], axis=1)


def real_recordings() -> int:
    """Section 3; returns how many values were given without a sample at the test position
    (must be 0)."""
    print("\n3. real recordings: each test's value from the recording alone, or not reached "
          "(samples at the test position); and from the limits extracted from it")
    invented = 0
    for name in REAL_FILES:
        path = DATA / name
        for kind in ("leg", "arm"):
            for letter, side in (("r", "right"), ("l", "left")):
                try:
                    q = _chain(path, kind, letter)
                except Exception as err:
                    if "no" in str(err).lower():
                        continue
                    raise
                names = CHAINS[kind][0]
                alone = coupled_measures(None, q, joint_names=names, side=side)
                try:
                    lb = LimbExtractor(kind).fit(q, side=side).limb_
                    with_limits = {m.spec.key: m for m in coupled_measures(lb, q, side=side)}
                except Exception as err:
                    with_limits, why = {}, str(err).splitlines()[0][:60]
                print(f" {name} {side} {kind} ({len(q)} samples)"
                      + ("" if with_limits else f" [limits not extracted: {why}]"))
                for m in alone:
                    if m.value is not None and m.samples_at_position == 0:
                        invented += 1
                    rec = ("not reached in this recording" if m.value is None
                           else f"{m.value:6.1f}° ({m.samples_at_position} samples)")
                    lim = with_limits.get(m.spec.key)
                    lim_txt = ("" if lim is None else "; with its extracted limits: "
                               + (f"{lim.value:.1f}° ({lim.status})" if lim.value is not None
                                  else lim.status))
                    print(f"   {m.spec.label:<34} {rec}{lim_txt}")
    print(f" values given without a recorded sample at the test position: {invented}")
    return invented


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", default="200-209", help="Seeds: A-B or a,b,c (default 200-209).")
    ap.add_argument("--recorded", type=float, default=180.0,
                    help="Seconds of simulated free motion per limb for section 2 (0: skip).")
    ap.add_argument("--no-real", action="store_true", help="Skip the real recordings.")
    args = ap.parse_args()
    seeds = _seeds(args.seeds)
    simulated_from_limits(seeds)
    if args.recorded > 0:
        simulated_recorded(seeds, args.recorded)
    if not args.no_real:
        real_recordings()


if __name__ == "__main__":
    main()
