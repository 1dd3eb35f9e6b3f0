"""Leader–follower teleoperation on the simulated rig, in real time: the figures of issue 41.

The follower is ``sim-servo-arm`` (7 XM430 in a process of their own), the patient's limb the
exact graph of ``anatomical_limb(3, "arm", kinds={"elbow": "forearm"})`` (no training: the limb
model is the oracle), the leader ``sim-leader-arm`` (7 XL330 in a process of their own, moved by
a simulated therapist), at 200 Hz through ``rig enforce`` (:func:`rig.loop.run_enforce`, the
CLI's own path). Sections (``--sections``, comma-separated, default all):

``push``
    The therapist goes past the patient's limits, coupled ones included (``excursion=1.5``,
    the shipped leader), for ``--seconds`` (default 60): cycles, follower goals beyond the
    1° tolerance by the exact limb oracle on the telemetry (judged per joint, commanded
    posture), the summary's largest violation, safe-state entries, overruns, leader → follower
    latency p50 / p99 over the cycles whose read came, the leader read's time.
``track``
    A therapist inside the patient's limits (``patient=`` the limb file, ``excursion=0.6``) for
    30 s: the tracking of admissible leader motion (median, p95: each cycle's largest joint
    angle between the target and the follower's present orientation), from the cycle the
    follower first caught up (within 5°).
``unplug``
    The leader's bus cable pulled by its own simulator after 600 instructions heard, for 0.5 s
    (``unplug_after=600&unplug_for=0.5``), 6 s into a store: failed reads, the first held
    cycle after the cut (cycles after it), goals moved while held, the largest step after the
    cut against the velocity limit × the step's time, cycles stored against cycles run.

Every figure printed beside the machine's speed that day (a Python loop of 10⁷ additions).
Figures only, never assertions. Run: ``.venv/bin/python benchmarks/bench_leader.py
[--sections push,track,unplug] [--seconds S]``.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import common  # first: one BLAS thread, this checkout on sys.path
import numpy as np
import yaml

from models.limb import dump_limb
from models.limb_model import export_limb_model
from models.oracle import ConstraintOracle
from rig.demo.limb import commanded_beyond
from rig.demo.stages import shipped_config
from rig.loop import EnforceHooks, EnforceRequest, run_enforce
from rig.loop.leader import LEADER_STALE_PERIODS
from rig.sim.patients import anatomical_limb
from rig.sim.urls import with_keys, without_keys
from rig.store import open_store

RATE_HZ = 200.0
VMAX_DEG_S = 120.0


def _leader_rig(d: Path, name: str, **keys) -> Path:
    cfg = shipped_config("sim-leader-arm")
    url = cfg["servos"]["port"]
    if "patient" in keys:  # a limb file's patient instead of the anatomical arm's
        url = without_keys(url, "limb")
    cfg["servos"]["port"] = with_keys(url, **keys)
    path = d / f"{name}.yaml"
    path.write_text(yaml.safe_dump(cfg, sort_keys=False))
    return path


def _run(d: Path, leader: Path, seconds: float, db: Path | None = None):
    req = EnforceRequest(rig="sim-servo-arm", model=str(d / "arm.onnx"),
                         targets=f"leader:{leader}", duration_s=seconds, rate_hz=RATE_HZ,
                         db=None if db is None else str(db),
                         patient=None if db is None else "P-BENCH-01")
    res = run_enforce(req, hooks=EnforceHooks(keep_telemetry=True))
    return res.summary, res.telemetry.table()


def _angles(c: np.ndarray) -> np.ndarray:
    return np.degrees(2.0 * np.arccos(np.clip(np.abs(np.sum(c[1:] * c[:-1], axis=1)), 0, 1)))


def push(d: Path, limb, seconds: float) -> None:
    s, t = _run(d, _leader_rig(d, "push"), seconds)
    beyond = commanded_beyond(t, limb)
    lead = s["leader"]
    print(f"push   {seconds:g} s: cycles {s['cycles']} at {s['achieved_hz']:.1f} Hz; follower "
          f"goals beyond 1° (exact oracle) {beyond['beyond']} of {beyond['judged']} judged; "
          f"max violation {s['max_violation_deg']:.4f}°; safe-state entries "
          f"{s['safe_state_entries']} ({s['safe_state_reason']}); overruns {s['overruns']} "
          f"({100.0 * s['overruns'] / max(1, s['cycles']):.2f} %) {s['overruns_by_cause']}")
    print(f"       latency p50 {lead['latency_ms']['p50']:.2f} ms, p99 "
          f"{lead['latency_ms']['p99']:.2f} ms (over {lead['reads'] - lead['stale_cycles']} "
          f"cycles whose read came; {lead['stale_cycles']} failed reads); leader read p50 "
          f"{lead['leader_ms']['p50']:.2f} ms, p99 {lead['leader_ms']['p99']:.2f} ms; "
          f"interventions {s['interventions_by_kind']}")


def track(d: Path, limb_file: Path) -> None:
    leader = _leader_rig(d, "track", patient=str(limb_file), excursion="0.6")
    s, _ = _run(d, leader, 30.0)
    tr = s["leader"]["tracking_deg"]
    if tr is None:
        print("track  30 s: the follower never caught up with the leader")
        return
    print(f"track  30 s (therapist inside the limits): tracking median {tr['median']:.2f}°, "
          f"p95 {tr['p95']:.2f}° over {tr['cycles']} cycles from cycle {tr['from_cycle']}; "
          f"latency p50 {s['leader']['latency_ms']['p50']:.2f} ms, p99 "
          f"{s['leader']['latency_ms']['p99']:.2f} ms; overruns {s['overruns']} of "
          f"{s['cycles']}")


def unplug(d: Path) -> None:
    db = d / "unplug.db"
    leader = _leader_rig(d, "unplug", unplug_after=600, unplug_for=0.5)
    s, t = _run(d, leader, 6.0, db)
    failed = np.asarray(t["leader_read"]) == 0
    period = 1.0 / RATE_HZ
    edges = np.flatnonzero(np.diff(np.r_[0, failed.astype(np.int8), 0]))
    if not len(edges):
        print("unplug 6 s: no failed read (the cut came after the run?)")
        return
    first, end = max(zip(edges[::2], edges[1::2], strict=True), key=lambda e: e[1] - e[0])
    age = np.asarray(t["target_age_ms"]) - np.asarray(t["cycle_ms"])
    held = failed & (age > 1e3 * LEADER_STALE_PERIODS * period + 1e-3)
    names = s["joint_names"]
    moved, worst = 0, 0.0
    ts = np.asarray(t["t_s"])
    for j in names:
        c = np.stack([np.asarray(t[f"{j}_commanded_{a}"]) for a in "wxyz"], axis=1)
        step = _angles(c)
        moved += int((np.abs(np.diff(c, axis=0)).max(axis=1)[held[1:]] > 1e-9).sum())
        allowed = VMAX_DEG_S * np.maximum(np.diff(ts), period)
        worst = max(worst, float((step[first:] / allowed[first:]).max()))
    first_held = int(np.flatnonzero(held[first:end])[0]) if held[first:end].any() else None
    with open_store(db, create=False) as store:
        sess = [x for x in store.sessions.list() if x["kind"] == "enforce"][-1]
        run = store.runs.list(sess["id"])[-1]
        stored = len(store.runs.telemetry(run["id"])["cycle"])
    print(f"unplug 6 s: cut at cycle {first}, {end - first} failed reads in a row "
          f"({ts[end - 1] - ts[first]:.3f} s), held from cycle {first} + {first_held} "
          f"({int(held.sum())} held cycles), goals moved while held {moved}; largest step "
          f"after the cut {worst:.3f} × the velocity limit × its time; safe-state entries "
          f"{s['safe_state_entries']} ({s['safe_state_reason']}); stored {stored} of "
          f"{s['cycles']} cycles, run {run['status']}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sections", default="push,track,unplug")
    ap.add_argument("--seconds", type=float, default=60.0, help="the push section's length")
    a = ap.parse_args()
    speed = common.additions_s()
    print(f"machine: a Python loop of 10⁷ additions took {speed:.2f} s")
    limb = anatomical_limb(3, "arm", kinds={"elbow": "forearm"})
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        dump_limb(limb, d / "arm.yaml")
        export_limb_model(limb, d / "arm.onnx")
        ConstraintOracle(limb).prepare()
        for section in a.sections.split(","):
            {"push": lambda: push(d, limb, a.seconds), "track": lambda: track(d, d / "arm.yaml"),
             "unplug": lambda: unplug(d)}[section.strip()]()
    print(f"machine after: {common.additions_s():.2f} s for 10⁷ additions")


if __name__ == "__main__":
    main()
