"""Adversarial limb targets on the simulated 7-servo arm: safety and valid-target tracking, per
joint, from a run's telemetry.

Runs ``rig enforce --rig sim-servo-arm --model LIMB.onnx --targets script:NAME?seed=S``
(``--script``: adversarial, the default, slow or sweep)
in real time (the simulator in its own process, as hardware is) for ``--cycles`` cycles, or
reads the telemetry CSV of such a run (``--telemetry T.csv``), and prints:

- commanded postures more than 1° outside in any joint (the exact limb oracle on the
  ``<joint>_commanded_*`` columns, each coupled joint at its source's commanded angle);
- tracking of valid targets, per joint: the angle between the target and the commanded
  orientation (and the present one) on the cycles whose target is valid in every joint
  (:func:`rig.loop.targets.valid_targets`) and steady
  (:meth:`rig.loop.targets.ScriptedTargets.steady`: unchanged for ``--settle-s``), median and
  p95;
- the machine's 10⁷-additions loop time beside them.

The targets are regenerated from the script and seed (they are deterministic in loop time), so
the telemetry needs only its own columns. Without ``--model`` the limb's exact ``geometric``
graph is exported and used (the figure is then the supervisor's, not a trained network's).

Run: ``python benchmarks/bench_limb_targets.py [--cycles 10000] [--seed 1] [--script NAME]
[--model M.onnx] [--telemetry T.csv]``. Figures, never assertions.
"""

from __future__ import annotations

import argparse
import csv
import tempfile
from pathlib import Path

import common  # noqa: F401  (first: one BLAS thread, this checkout on sys.path)
import numpy as np
from common import additions_s

from models import quaternion as Q
from models.limb_model import export_limb_model
from models.onnx_io import load_model
from models.oracle import ConstraintOracle
from rig.loop import EnforceRequest, run_enforce
from rig.loop.targets import ScriptedTargets, valid_targets
from rig.sim.patients import anatomical_limb


def read_columns(path: Path) -> dict[str, np.ndarray]:
    with path.open(newline="") as fh:
        rows = list(csv.reader(fh))
    head, body = rows[0], np.array(rows[1:], dtype=np.float64)
    return {h: body[:, i] for i, h in enumerate(head)}


def posture(cols: dict, names, what: str) -> np.ndarray:
    return np.stack([np.stack([cols[f"{j}_{what}_{c}"] for c in "wxyz"], axis=1)
                     for j in names], axis=1)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--cycles", type=int, default=10_000)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--script", default="adversarial", choices=("adversarial", "slow", "sweep"))
    ap.add_argument("--model", default=None)
    ap.add_argument("--telemetry", default=None, help="analyse this run's telemetry instead")
    ap.add_argument("--settle-s", type=float, default=0.3)
    args = ap.parse_args()
    print(f"10^7 additions: {additions_s():.2f} s")
    tmp = Path(tempfile.mkdtemp(prefix="bench-limb-targets-"))
    model = args.model
    if model is None:
        model = str(tmp / "arm.onnx")
        export_limb_model(anatomical_limb(3, "arm", kinds={"elbow": "forearm"}), model)
    limb = load_model(model, limb=True).limb
    oracle = ConstraintOracle(limb)
    names = limb.joint_names
    spec = f"script:{args.script}?seed={args.seed}"
    tel = Path(args.telemetry) if args.telemetry else tmp / "t.csv"
    if args.telemetry is None:
        res = run_enforce(EnforceRequest(rig="sim-servo-arm", model=model, targets=spec,
                                         duration_s=args.cycles / 200.0, telemetry=str(tel),
                                         stale_servo_ms=1000.0))
        s = res.summary
        print(f"run: {s['cycles']} cycles at {s['achieved_hz']:.1f} Hz, overruns "
              f"{s['overruns']}, max violation {s['max_violation_deg']:.3f}°, safe-state "
              f"entries {s['safe_state_entries']}, compute p50 {s['p50_compute_us']:.0f} µs")
    cols = read_columns(tel)
    t = cols["t_s"]
    commanded = posture(cols, names, "commanded")
    d = np.degrees(oracle.signed_distance(Q.canonical(commanded)))
    beyond = (d > 1.0).any(axis=1)
    print(f"commanded postures beyond 1° in any joint: {int(beyond.sum())} of {len(t)} "
          f"(max per joint: "
          f"{', '.join(f'{n} {v:.3f}°' for n, v in zip(names, d.max(0), strict=True))})")
    src = ScriptedTargets(args.script, oracle, seed=args.seed)
    src.start(0.0)
    targets = np.array([src.latest(x)[1] for x in t])
    keep = valid_targets(oracle, targets) & np.array([src.steady(x, args.settle_s) for x in t])
    present = posture(cols, names, "present")
    print(f"valid, steady targets: {int(keep.sum())} cycles of {len(t)} "
          f"(settled {args.settle_s:g} s)")
    for j, name in enumerate(names):
        for what, q in (("commanded", commanded), ("present", present)):
            err = np.degrees(Q.angle(Q.multiply(q[keep, j], Q.conjugate(targets[keep, j]))))
            if len(err):
                print(f"  {name:<9} {what:<9} tracking median {np.median(err):.3f}°, p95 "
                      f"{np.percentile(err, 95):.3f}°")


if __name__ == "__main__":
    main()
