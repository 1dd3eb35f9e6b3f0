"""``rig demo --limb arm|leg``: a whole simulated arm or leg, recorded, extracted, trained,
evaluated and reported, stage by stage with a verdict per stage (:class:`LimbDemo`, run by
:func:`rig.demo.pipeline.run_demo`).

Stages (each calls the library function behind the corresponding ``rig`` command):

1. **patient** — the seeded anatomical limb :func:`rig.sim.patients.anatomical_limb`
   (``seed``, right side) with its couplings (leg: hip and ankle limits at keyframes of the
   knee angle; arm: shoulder limits at keyframes of the elbow angle), written as
   ``patient-<limb>.yaml``; the shipped ``sim-arm`` / ``sim-leg`` configuration re-pointed at
   that seed with scaled patient time in ``rigs/``.
2. **record** — ``rig record`` (:func:`rig.record.record_session`): four IMUs (noise, drift,
   misplaced straps) through the stream protocol; the limb calibration protocol (static pose,
   then each joint's flexion/extension), then free motion for ``motion_s`` of patient time.
   PASS: completed, nothing dropped, calibration residual reported.
3. **boundary** — ``rig boundary --limb`` on the session (:func:`rig.readback.run_boundary`):
   the limb file ``<limb>.yaml``. Verdicts against the truth: hinge interval ends within 2°,
   ball / two-axis boundaries within 2° mean distance (an extracted coupling's keyframes
   within 3° of the truth at the same angle; an uncoupled boundary against the truth at the
   coupling angle it matches best: the recording's union), ≥ 97 % of the recorded postures
   inside every joint within 1°; whether the truth's coupling was found is stated.
4. **train** — ``rig train`` on the limb file (:func:`rig.training.run_train`): preset
   ``network`` (a trained distance field for the coupled swing), or ``geometric`` (the exact
   oracle compiled, no training) at the quick size.
5. **evaluate** — ``rig evaluate`` (onnxruntime) on fresh held-out postures; verdict against
   issue 20's targets (:func:`rig.training.verdict.targets_for`). The model is registered with
   the session with this evaluation, which the report shows (one evaluation, one verdict).
6. **report** — the clinician's report of the limb (:mod:`rig.report.limb`): ``report.html``.
7. **live** (the arm) — ``rig enforce`` (:func:`rig.loop.run_enforce`) on the simulated
   7-servo arm ``sim-servo-arm`` (``rigs/sim-servo-arm.yaml``: its patient the recording's
   seeded arm, ``patient=patient-arm.yaml``) with the trained limb model and the extracted limb
   file, :data:`LIVE_S` seconds at 200 Hz on ``script:adversarial`` targets (far outside postures,
   discontinuities, invalid and stale targets, and the coupled segments: the elbow moved to an
   angle at which the held shoulder is outside, the shoulder moved to a reach valid only at
   another elbow angle). The IMU-recorded elbow is a hinge; the servo arm's elbow is a forearm
   joint whose flexion servo turns about the hinge's axis, so the hinge's limits hold its
   pronation servo at zero (:func:`rig.loop.binding.hinge_on_forearm`). PASS: 0 commanded
   postures beyond 1° in any joint (the exact limb oracle on the telemetry's
   ``<joint>_commanded_*`` columns), 0 safe states; overruns and each joint's tracking of
   valid targets reported.

Everything goes into one store, ``<out>/rig.db``.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from calibration.boundary import boundary_distance
from calibration.joints import LIMB_CHAINS, hinge_angles
from models.limb import dump_limb, load_limb
from models.oracle import ConstraintOracle
from rig.demo.stages import (
    DemoOptions,
    DemoResult,
    RecordingDisplay,
    StageResult,
    recording_failure,
    report_stage,
    shipped_config,
)
from rig.devices.config import load_rig_config
from rig.errors import RigConfigError
from rig.loop import EnforceHooks, EnforceRequest, Intervention, run_enforce
from rig.readback import BoundaryRequest, RecordingSource, run_boundary
from rig.readback.sessions import read_session
from rig.record import RecordOptions, record_session
from rig.sim.patients import anatomical_limb
from rig.sim.urls import with_keys, without_keys
from rig.store import open_store
from rig.training import TrainRequest, run_train
from rig.training.limb import evaluate_limb
from rig.training.verdict import (
    evaluation_record,
    evaluation_verdict,
    missed_targets,
    targets_for,
)

__all__ = ["LIMB_SIZES", "LIVE_RIGS", "LIVE_S", "LimbDemo", "LimbDemoSize", "commanded_beyond",
           "compare_limbs", "write_limb_rig", "write_servo_rig"]

#: The shipped servo rig of each limb the live stage drives (a limb without one has no live
#: stage).
LIVE_RIGS = {"arm": "sim-servo-arm"}

#: Seconds of live enforcement on the servo limb (the ``live`` stage), by size.
LIVE_S = {"full": 15.0, "quick": 3.0}

#: Verdict targets of the boundary stage (issue 21), degrees or shares.
HINGE_DEG = 2.0
BOUNDARY_MEAN_DEG = 2.0
KEYFRAME_DEG = 3.0
INSIDE_1DEG = 0.97


@dataclass(frozen=True)
class LimbDemoSize:
    """How much the limb demo records and evaluates.

    Attributes
    ----------
    motion_s : float
        Free motion after the calibration protocol, seconds of patient time.
    time_scale : float
        Patient time runs this many times faster than the host's clock.
    rate_hz : int
        Each IMU's sample rate (patient time).
    preset : str
        ``rig train`` preset for the limb.
    eval_n : int
        Held-out postures for ``rig evaluate``.
    """

    motion_s: float
    time_scale: float
    rate_hz: int
    preset: str
    eval_n: int


LIMB_SIZES = {
    "full": LimbDemoSize(motion_s=600.0, time_scale=20.0, rate_hz=100, preset="network",
                         eval_n=6000),
    "quick": LimbDemoSize(motion_s=150.0, time_scale=20.0, rate_hz=100, preset="geometric",
                          eval_n=1500),
}


def write_limb_rig(out: Path, limb: str, seed: int, size: LimbDemoSize) -> Path:
    """The shipped ``sim-<limb>`` configuration worn by the patient of ``seed``, patient time
    scaled; validated like any ``--rig FILE``."""
    cfg = shipped_config(f"sim-{limb}")
    cfg["sensors"]["port"] = with_keys(cfg["sensors"]["port"], seed=seed, rate=size.rate_hz,
                                       time_scale=f"{size.time_scale:g}")
    cfg["sensors"]["rate_hz"] = size.rate_hz
    cfg["description"] = f"demo: sim-{limb} worn by the demo's simulated patient, scaled time"
    rigs = out / "rigs"
    rigs.mkdir(parents=True, exist_ok=True)
    path = rigs / f"sim-{limb}.yaml"
    path.write_text("# written by `rig demo --limb`\n" + yaml.safe_dump(cfg, sort_keys=False))
    load_rig_config(str(path))
    return path


def write_servo_rig(out: Path, limb: str, seed: int, patient_file: Path) -> Path:
    """The shipped servo limb configuration (:data:`LIVE_RIGS`) back-driven by the demo's
    patient: its port's ``patient=`` the patient's limb file (the seeded limb the IMUs
    recorded, its joints' kinds its own), ``seed`` the demo's; validated like any
    ``--rig FILE``."""
    name = LIVE_RIGS[limb]
    cfg = shipped_config(name)
    port = without_keys(cfg["servos"]["port"], "limb", "side")
    cfg["servos"]["port"] = with_keys(port, patient=str(Path(patient_file).resolve()),
                                      seed=seed)
    cfg["description"] = (f"demo: {name} back-driven by the demo's simulated {limb} "
                          f"({patient_file.name}, seed {seed})")
    rigs = out / "rigs"
    rigs.mkdir(parents=True, exist_ok=True)
    path = rigs / f"{name}.yaml"
    path.write_text("# written by `rig demo --limb`\n" + yaml.safe_dump(cfg, sort_keys=False))
    load_rig_config(str(path))
    return path


def commanded_beyond(table: dict, limb, tol_deg: float = 1.0) -> dict[str, Any]:
    """How many commanded postures of a limb run lie beyond ``tol_deg`` of ``limb``'s limits
    in any joint, by the exact limb oracle (:class:`models.oracle.ConstraintOracle`) on the
    telemetry's ``<joint>_commanded_w..z`` columns (hierarchical: a coupled joint judged at
    its source joint's commanded angle). A cycle the supervisor flagged ``RECOVERY`` (the limb
    outside, its goal steered back towards the valid range under the monotone rule: motion
    back is always allowed) is counted apart.

    Parameters
    ----------
    table : dict
        Telemetry columns (:meth:`rig.loop.telemetry.Telemetry.table` or a CSV read back).
    limb : models.limb.Limb
    tol_deg : float

    Returns
    -------
    dict
        ``beyond``: commanded postures with a joint more than ``tol_deg`` outside, recovery
        cycles left out; ``recovering``: recovery cycles beyond it (steered back);
        ``judged``: cycles with a commanded posture (finite in every joint); ``worst_deg``:
        each joint's largest distance outside (degrees; 0 inside) over the judged cycles that
        are not recovery cycles.
    """
    names = limb.joint_names
    q = np.stack([np.stack([np.asarray(table[f"{n}_commanded_{c}"], dtype=np.float64)
                            for c in "wxyz"], axis=-1) for n in names], axis=1)
    flags = np.asarray(table["intervention"], dtype=np.float64)
    ok = np.isfinite(q).all(axis=(1, 2)) & (np.linalg.norm(q, axis=-1) > 0.5).all(axis=1)
    q, flags = q[ok], flags[ok]
    out: dict[str, Any] = {"beyond": 0, "recovering": 0, "judged": len(q),
                           "worst_deg": {n: 0.0 for n in names}}
    if not len(q):
        return out
    d = np.degrees(ConstraintOracle(limb).evaluate(q, normalize=True).distance)
    recovery = (np.nan_to_num(flags).astype(np.int64) & int(Intervention.RECOVERY)) != 0
    far = (d > tol_deg).any(axis=1)
    out["beyond"] = int(np.count_nonzero(far & ~recovery))
    out["recovering"] = int(np.count_nonzero(far & recovery))
    if (~recovery).any():
        out["worst_deg"] = {n: float(max(0.0, d[~recovery, j].max()))
                            for j, n in enumerate(names)}
    return out


class LimbDemo:
    """The limb demo (module docstring) as :func:`rig.demo.pipeline.run_demo` runs it: the
    options checked at once, then the patient and the stages that follow.

    Parameters
    ----------
    options : DemoOptions
        ``limb`` one of :data:`calibration.joints.LIMB_CHAINS` (``"arm"``, ``"leg"``); no
        hardware ports (the limb demo runs on the simulated limb).

    Raises
    ------
    RigConfigError
        An unknown limb or a hardware port given (one line), before anything is written.
    """

    def __init__(self, options: DemoOptions) -> None:
        limb = options.limb
        if limb not in LIMB_CHAINS:
            raise RigConfigError(f"--limb {limb!r}: expected one of {', '.join(LIMB_CHAINS)}")
        if options.dxl_port is not None or options.imu_port is not None:
            raise RigConfigError("--limb runs on the simulated limb: --dxl-port / --imu-port "
                                 "apply to the shoulder demo")
        self.options, self.limb = options, limb
        self.size = LIMB_SIZES["quick" if options.quick else "full"]
        self.live_s = LIVE_S["quick" if options.quick else "full"]

    def check(self, log: Callable[[str], None]) -> list[StageResult]:
        """No stage before the patient: the limb demo opens no hardware."""
        return []

    def patient(self, result: DemoResult, log: Callable[[str], None]):
        """Stage 1, the seeded anatomical limb and its rig (appended to ``result.stages``);
        returns the stages' shared state and the named stages that follow."""
        options, limb, out = self.options, self.limb, result.out
        t0 = time.perf_counter()
        truth = anatomical_limb(options.seed, limb, "right")
        patient_file = out / f"patient-{limb}.yaml"
        dump_limb(truth, patient_file)
        rig = write_limb_rig(out, limb, options.seed, self.size)
        coupled = [f"{j.name} by the {j.coupling.by} ({len(j.coupling.at_deg)} keyframes)"
                   for j in truth.joints if j.coupling is not None]
        result.stages.append(StageResult(
            "patient", seconds=time.perf_counter() - t0, verdict="INFO",
            detail=f"anatomical right {limb}, seed {options.seed}: "
                   f"{', '.join(f'{j.name} {j.kind}' for j in truth.joints)}; coupled: "
                   f"{', '.join(coupled) or 'none'}: {patient_file}"))
        ctx = _LimbCtx(options, self.size, limb, out, result, rig, truth, log)
        named = (("record", ctx.record), ("boundary", ctx.boundary), ("train", ctx.train),
                 ("evaluate", ctx.evaluate), ("report", ctx.report))
        if limb in LIVE_RIGS:
            ctx.servo_rig = write_servo_rig(out, limb, options.seed, patient_file)
            ctx.live_s = self.live_s
            named += (("live", ctx.live),)
        return ctx, named


class _LimbCtx:
    """State shared by the limb demo's stages — one method per stage."""

    def __init__(self, options, size, limb, out, result, rig, truth, log) -> None:
        self.options, self.size, self.limb, self.out = options, size, limb, out
        self.result, self.rig, self.truth, self.log = result, rig, truth, log
        self.progress = self.task = None
        self.session: int | None = None
        self.limb_file = out / f"{limb}.yaml"
        self.model_file = out / f"{limb}.onnx"
        self.extracted = None
        self.limb_boundary: int | None = None  # the limb file's id in the store
        self.calibration: dict | None = None
        self.metrics: dict | None = None
        self.servo_rig: Path | None = None
        self.live_s = 0.0

    def record(self, st: StageResult) -> None:
        display = RecordingDisplay(self.progress, self.task, f"IMUs on the {self.limb}",
                                    self.log)
        res = record_session(RecordOptions(rig=str(self.rig), db=str(self.result.db),
                                           patient=f"SIM-{self.limb.upper()}-"
                                                   f"{self.options.seed:04d}",
                                           duration_s=self.size.motion_s),
                             display=display)
        self.session = res.session_id
        self.result.sessions[self.limb] = res.session_id
        cal = res.calibration
        if cal is not None:
            self.calibration = cal.data.get("residuals_deg")
        st.figures.update({"session_id": res.session_id, "status": res.status,
                           "samples": res.samples, "dropped": res.dropped,
                           "calibration_residual_deg": None if cal is None else cal.residual_deg})
        st.detail = (f"session {res.session_id}: {res.samples:,} samples from 4 IMUs, "
                     f"{res.span_s:.0f} s of patient time (×{self.size.time_scale:g}), dropped "
                     f"{res.dropped}; " + ("limb calibration not performed" if cal is None else
                                           f"limb calibration residual {cal.residual_deg:.2f}°"))
        st.verdict = ("PASS" if res.status == "completed" and res.dropped == 0 and cal is not None
                      else "WARN" if res.status == "completed" else "FAIL")
        if res.status != "completed":
            st.detail = f"{recording_failure(res)}; {st.detail}"

    def boundary(self, st: StageResult) -> None:
        res = run_boundary(BoundaryRequest(
            RecordingSource(db=str(self.result.db), session_id=self.session), self.limb_file,
            limb=self.limb))
        self.extracted = res.extractor.limb_
        self.limb_boundary = res.boundary_id
        rep = res.extractor.report()
        figs = compare_limbs(self.extracted, self.truth)
        figs["inside_within_1deg"] = _inside_within(self.extracted, self.result.db, self.session)
        st.figures.update(figs)
        parts, ok = [], True
        for name, f in figs["joints"].items():
            if "hinge_error_deg" in f:
                good = f["hinge_error_deg"] <= HINGE_DEG
                parts.append(f"{name} hinge ends {f['hinge_error_deg']:.2f}° off")
            elif "keyframe_mean_deg" in f:
                good = max(f["keyframe_mean_deg"]) <= KEYFRAME_DEG
                parts.append(f"{name} keyframes at {', '.join(f'{a:.0f}' for a in f['at_deg'])}°"
                             f": {', '.join(f'{d:.2f}' for d in f['keyframe_mean_deg'])}° mean "
                             "distance")
            else:
                good = f["mean_deg"] <= BOUNDARY_MEAN_DEG
                parts.append(f"{name} {f['mean_deg']:.2f}° mean distance"
                             + (f" (truth at {f['matched_at_deg']:.0f}°)"
                                if f.get("matched_at_deg") is not None else ""))
            ok &= good
        inside = figs["inside_within_1deg"]
        ok &= inside >= INSIDE_1DEG
        couplings = []
        for name, c in rep["couplings"].items():
            truth_coupled = self.truth.joints[self.truth.joint_names.index(name)].coupling
            said = f"{name} coupling {'found' if c['coupled'] else 'not found'}"
            if c["coupled"] != (truth_coupled is not None):
                said += f" ({c['note']})"
                ok = False
            couplings.append(said)
        st.verdict = "PASS" if ok else "WARN"
        st.detail = (f"{self.limb_file}: {'; '.join(parts)}; {100 * inside:.1f} % of postures "
                     f"within 1° in every joint (≥ {100 * INSIDE_1DEG:g} %); "
                     + "; ".join(couplings))

    def train(self, st: StageResult) -> None:
        res = run_train(TrainRequest(self.model_file, constraint=str(self.limb_file),
                                     preset=self.size.preset, seed=self.options.seed))
        st.figures.update({"path": str(res.path), "preset": self.size.preset,
                           "seconds": res.seconds})
        st.verdict = "PASS"
        st.detail = (f"{res.path} ({res.path.stat().st_size / 1e3:.0f} kB), preset "
                     f"{self.size.preset}" + (" (the exact oracle compiled; --quick does not "
                                              "train)" if self.size.preset == "geometric"
                                              else ""))

    def evaluate(self, st: StageResult) -> None:
        limb = load_limb(self.limb_file)
        seed = self.options.seed + 77
        metrics, _ = evaluate_limb(str(self.model_file), limb, self.size.eval_n, seed)
        self.metrics = metrics
        # registered with the session and its stored limb file, with this evaluation: `rig
        # report` on the session finds the model without --model and shows these figures
        with open_store(self.result.db, create=False) as store:
            mid = store.models.add(self.model_file, boundary_id=self.limb_boundary,
                                   session_id=self.session,
                                   metrics=evaluation_record(metrics, n=self.size.eval_n,
                                                             seed=seed, by="rig evaluate"))
        st.figures.update({k: metrics.get(k) for k in targets_for(limb=True)})
        st.figures["model_id"] = mid
        ok, _ = evaluation_verdict(metrics, limb=True)
        misses = missed_targets(metrics, limb=True)
        st.verdict = "PASS" if ok else "WARN"
        st.detail = (f"{self.size.eval_n} held-out postures: end-point mean 3-D error "
                     f"{metrics['end_mean_3d_error_pct']:.3f} % (≤ 0.5), invalid left > 1° "
                     f"{100 * metrics['frac_invalid_violating_1deg']:.2f} % (≤ 1), valid moved "
                     f"{metrics['valid_moved_deg']:.3f}° (≤ 0.1), p99 end-point direction "
                     f"{metrics['end_p99_direction_error_deg']:.2f}° (≤ 3)"
                     + ("" if not misses else "; " + "; ".join(misses)))

    def report(self, st: StageResult) -> None:
        report_stage(st, self.result, self.session, self.model_file, self.truth,
                     self.size.eval_n)

    def live(self, st: StageResult) -> None:
        live_s = self.live_s
        self.progress.update(self.task, total=live_s,
                             description=f"live: adversarial targets on {self.servo_rig.stem}")
        t0 = time.perf_counter()

        def on_cycle(loop, k: int) -> None:
            if k % 50 == 0:
                self.progress.update(self.task, completed=min(live_s, time.perf_counter() - t0))

        telemetry = self.out / "live-telemetry.csv"
        res = run_enforce(EnforceRequest(
            rig=str(self.servo_rig), model=str(self.model_file), targets="script:adversarial",
            constraint=str(self.limb_file), rate_hz=200.0, duration_s=live_s,
            telemetry=str(telemetry), summary_json=str(self.out / "live-summary.json"),
            db=str(self.result.db), session_id=self.session, seed=self.options.seed),
            hooks=EnforceHooks(on_cycle=on_cycle, keep_telemetry=True))
        s = res.summary
        self.result.sessions["live"] = s.get("session_id")
        limb = load_limb(self.limb_file)
        judged_cmd = commanded_beyond(res.telemetry.table(), limb, 1.0)
        beyond, judged, worst = (judged_cmd["beyond"], judged_cmd["judged"],
                                 judged_cmd["worst_deg"])
        recovering = judged_cmd["recovering"]
        joints = s.get("joints") or {}
        st.figures.update({k: s.get(k) for k in (
            "achieved_hz", "cycles", "p99_cycle_ms", "p50_compute_us", "overruns",
            "overruns_by_cause", "max_violation_deg", "tolerance_deg", "interventions",
            "interventions_by_kind", "faults", "safe_state_entries", "safe_state_reason",
            "end_reason", "session_id", "run_id")})
        st.figures.update({"exit_status": res.exit_status, "commanded_beyond_1deg": beyond,
                           "commanded_judged": judged, "commanded_worst_deg": worst,
                           "recovery_cycles_beyond_1deg": recovering,
                           "joints": joints, "telemetry": str(telemetry)})
        cycles = s.get("cycles") or 0
        overruns = s.get("overruns") or 0

        def tracking(name: str) -> str:
            f = joints.get(name, {})
            p50, p95 = f.get("tracking_p50_deg"), f.get("tracking_p95_deg")
            if p50 is None:
                return f"{name} no valid target tracked"
            return f"{name} {p50:.2f}° / {p95:.2f}°"

        coupled = [f"the {j.name} by the {j.coupling.by}" for j in limb.joints
                   if j.coupling is not None]
        st.figures["coupled"] = coupled
        st.detail = (f"{self.servo_rig.stem}, {cycles:,} cycles at "
                     f"{s.get('achieved_hz') or 0:.0f} Hz (asked 200) on script:adversarial "
                     + (f"with coupled segments ({', '.join(coupled)})" if coupled else
                        "(no coupling in the limb file: no coupled segments)")
                     + f": {beyond} of {judged:,} commanded postures beyond "
                     f"1° in any joint (exact limb oracle; worst "
                     + ", ".join(f"{n} {w:.2f}°" for n, w in worst.items())
                     + (f"; {recovering} more on the way back from a start outside"
                        if recovering else "")
                     + f"); safe states {s.get('safe_state_entries')}; overruns {overruns} "
                     f"({100 * overruns / max(cycles, 1):.1f} %); compute p50 "
                     f"{s.get('p50_compute_us') or 0:.0f} µs; tracking of valid targets "
                     f"p50 / p95: " + ", ".join(tracking(n) for n in limb.joint_names)
                     + f"; {telemetry}")
        if beyond or res.exit_status not in (0, 1):
            st.verdict = "FAIL"
        elif s.get("safe_state_entries") or res.exit_status:
            st.verdict = "WARN"
            st.detail += f"; safe state entered ({s.get('safe_state_reason')})"
        else:
            st.verdict = "PASS"


def _inside_within(limb, db: Path, session: int, tol_deg: float = 1.0) -> float:
    """Share of the session's postures within ``tol_deg`` of ``limb``'s limits in every joint:
    a hinge by its angle (its out-of-axis motion is corrected, not limited), the others by the
    exact limb oracle's distance."""
    chain = read_session(str(db), session)
    d = np.degrees(ConstraintOracle(limb).evaluate(chain.joint_q, normalize=True).distance)
    for j, joint in enumerate(limb.joints):
        if joint.joint_kind.single_axis and joint.constraint is not None:
            h = joint.constraint.hinge
            a = hinge_angles(chain.joint_q[:, j], h.axis)
            d[:, j] = np.maximum(h.min_deg - a, a - h.max_deg)
    return float(np.mean((d <= tol_deg).all(axis=1)))


def compare_limbs(extracted, truth) -> dict[str, Any]:
    """Per joint, how far an extracted limb's limits are from the truth's (degrees).

    - a hinge: ``hinge_error_deg``, the larger of the two ends' differences (against the
      truth's loosest interval when the truth's hinge is coupled);
    - a coupled extracted joint: ``keyframe_mean_deg``, the mean boundary distance of each
      keyframe to the truth's limits at the same angle (``at_deg``);
    - an uncoupled ball / two-axis joint: ``mean_deg`` against the truth's own constraint, or
      against the truth's limits at the keyframe it matches best (``matched_at_deg``) when the
      truth is coupled (the recording's union of angles);
    and ``twist_error_deg`` for ball / two-axis joints.
    """
    out: dict[str, Any] = {"joints": {}}
    for e, t in zip(extracted.joints, truth.joints, strict=True):
        f: dict[str, Any] = {}
        if e.joint_kind.single_axis:
            ec, tc = e.loosest(), t.loosest()
            f["hinge_deg"] = [ec.hinge.min_deg, ec.hinge.max_deg]
            f["hinge_error_deg"] = max(abs(ec.hinge.min_deg - tc.hinge.min_deg),
                                       abs(ec.hinge.max_deg - tc.hinge.max_deg))
        elif e.coupling is not None:
            f["at_deg"] = list(e.coupling.at_deg)
            f["keyframe_mean_deg"] = [
                boundary_distance(kf, _truth_at(t, a))["mean_deg"]
                for a, kf in zip(e.coupling.at_deg, e.coupling.keyframes, strict=True)]
        else:
            c = e.constraint
            if t.coupling is None:
                f["mean_deg"] = boundary_distance(c, t.constraint)["mean_deg"]
                f["twist_error_deg"] = _twist_error(c, t.constraint)
            else:
                best = min(((boundary_distance(c, kf)["mean_deg"], a, kf) for a, kf in
                            zip(t.coupling.at_deg, t.coupling.keyframes, strict=True)),
                           key=lambda x: x[0])
                f["mean_deg"], f["matched_at_deg"] = best[0], best[1]
                f["twist_error_deg"] = _twist_error(c, best[2])
        out["joints"][e.name] = f
    return out


def _truth_at(joint, angle_deg: float):
    return joint.constraint if joint.coupling is None else joint.coupling.at(angle_deg)


def _twist_error(a, b) -> float | None:
    ta, tb = getattr(a, "twist", None), getattr(b, "twist", None)
    if ta is None or tb is None:
        return None
    return float(max(abs(ta.min_deg - tb.min_deg), abs(ta.max_deg - tb.max_deg)))

