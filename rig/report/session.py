"""Assemble the clinician's report of one session from the store; ``rig report`` as a library is
:func:`run_report` (:class:`ReportRequest` → :class:`ReportResult`), through the one entry
:func:`report_for_session` for a session of one joint or of a whole arm or leg (a whole limb's
page is drawn by :mod:`rig.report.limb`).

What each section of a joint's page is made of (a section with no data is left out):

- **patient and session** — the session row (pseudonym, side, rig, start, duration, samples,
  dropped samples);
- **range of motion** — :func:`calibration.clinical.range_of_motion` of the session's boundary
  (the last one stored with the session, else extracted from its samples with the defaults of
  ``rig boundary``), next to the AAOS values and the Gill et al. 2020 population reference
  (:func:`calibration.clinical.population_reference`: the age band and sex when given, women
  and men apart otherwise); AAOS values measured in another position are not compared;
- **recorded boundary** — the joint orientations' limb directions (thorax frame) and the
  boundary polygon on the equal-area map (:func:`rig.report.figures.boundary_figure`), sparse
  arcs in red, optionally a reference boundary (the simulated patient's truth) dashed;
- **calibration** — the session's calibrations and their residuals;
- **learned model** — a model file (given, or the last registered with the session) evaluated
  through onnxruntime on held-out orientations of its own constraint
  (:func:`models.evaluation.evaluate_model`), with per-orientation 3-D error (thesis ch. 5:
  distance between the limb endpoints corrected by the model and by the exact oracle, in % of
  its maximum 2) coloured at the limb direction of the input orientation;
- **live enforcement** — the runs of the session itself (an ``enforce`` session) or of the
  ``enforce`` sessions that name it as their ``recording_session``: achieved rate, cycles,
  interventions, max violation against the tolerance, faults, safe-state entries.

Verdicts compare with the project's targets (issue 9: mean 3-D error ≤ 0.8 %, invalid inputs
left > 1° outside ≤ 1 %, mean identity error ≤ 0.2°, p99 direction error ≤ 5°; issue 10: no
command beyond the tolerance).
"""

from __future__ import annotations

import datetime as _dt
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from calibration.alignment import trusted_samples
from calibration.boundary import boundary_distance
from calibration.clinical import isb_angles, range_of_motion
from calibration.extraction import LimbExtractor
from calibration.joints import LIMB_CHAINS, joint_mismatch
from models import quaternion as Q
from models.constraint import load_constraint, loads_constraint
from models.errors import ModelsError
from models.evaluation import evaluate_model, held_out_orientations
from models.fileio import check_output
from models.limb import load_limb
from models.metrics import three_d_error_percent
from models.onnx_io import load_model
from models.oracle import ConstraintOracle
from rig import __version__
from rig.errors import RigConfigError, user_errors
from rig.readback import extract, joint_orientations_from_store
from rig.readback.boundary import BoundaryRequest, one_joint_limb, stored_limb
from rig.readback.progress import (
    ProgressRequest,
    merged_progress,
    run_progress,
    sessions_of,
)
from rig.readback.sessions import latest_calibration, session_limb
from rig.report.figures import boundary_figure, error_map_figure
from rig.report.files import report_for_file
from rig.report.limb import limb_report_data, write_limb_report
from rig.report.page import ReportData, rom_rows, write_report
from rig.report.progress import progress_section_html
from rig.store import file_sha256, open_store
from rig.training.limb import evaluate_limb
from rig.training.verdict import (  # the one verdict, re-exported
    MODEL_TARGETS,
    evaluation_verdict,
    stored_evaluation,
)

__all__ = ["MODEL_TARGETS", "ReportRequest", "ReportResult", "evaluation_verdict",
           "report_data_for_session", "report_for_session", "run_report"]


def _iso(t: float | None) -> str | None:
    if t is None:
        return None
    return _dt.datetime.fromtimestamp(float(t), _dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")


def _arc_text(arc: dict, side: str) -> str:
    """A sparse boundary arc in clinical words: its length and where its middle points."""
    a, b = np.asarray(arc["from"], float), np.asarray(arc["to"], float)
    mid = a + b
    mid = mid / np.linalg.norm(mid) if np.linalg.norm(mid) > 1e-9 else a
    q = Q.from_two_vectors(np.array([1.0, 0.0, 0.0]), mid)
    ang = isb_angles(q, side)
    elev = float(ang["elevation"][0])
    plane = float(ang["plane_of_elevation"][0])
    where = (f"elevation {elev:.0f}°" if math.isnan(plane)
             else f"elevation {elev:.0f}° in the plane of elevation {plane:.0f}°")
    return f"{float(arc.get('length_deg', 0.0)):.0f}° of boundary around {where}"


def _boundary(store, session_id: int, joint) -> tuple[Any, dict, str]:
    """(constraint, extraction report, where it came from) — stored, else extracted."""
    stored = store.boundaries.list(session_id, limb=False)
    if stored:
        b = stored[-1]
        c = loads_constraint(b["constraint_yaml"], source=f"boundary {b['id']}")
        return c, dict(b.get("meta") or {}), f"boundary {b['id']} stored with the session"
    if joint is None:
        return None, {}, ""

    ex = extract(joint)
    return ex.constraint_, ex.report(), "extracted from the recorded samples for this report"


def _recording_session(store, sess: dict) -> int | None:
    if sess.get("kind") == "enforce":
        rec = (sess.get("meta") or {}).get("recording_session")
        return int(rec) if rec is not None else None
    return int(sess["id"])


def _runs(store, sess: dict, rec_id: int | None) -> list[dict]:
    runs = list(store.runs.list(sess["id"])) if sess.get("kind") == "enforce" else []
    if rec_id is not None:
        for other in store.sessions.list():
            if (other.get("kind") == "enforce" and other["id"] != sess["id"]
                    and (other.get("meta") or {}).get("recording_session") == rec_id):
                runs.extend(store.runs.list(other["id"]))
    return runs


def enforcement_facts(summary: dict) -> tuple[dict[str, Any], str]:
    """Report rows and verdict of one run's end-of-run summary (:mod:`rig.loop.telemetry`)."""
    tol = summary.get("tolerance_deg")
    viol = summary.get("max_violation_deg")
    facts = {
        "loop rate asked (Hz)": summary.get("rate_hz"),
        "loop rate achieved (Hz)": summary.get("achieved_hz"),
        "cycles": summary.get("cycles"),
        "p99 cycle time (ms)": summary.get("p99_cycle_ms"),
        "interventions of the supervisor": summary.get("interventions"),
        "max violation of the boundary (°)": viol,
        "tolerance (°)": tol,
        "safe-state entries": summary.get("safe_state_entries"),
        "targets": summary.get("targets"),
        "end": summary.get("end_reason"),
    }
    facts = {k: v for k, v in facts.items() if v is not None}
    if viol is None or tol is None:
        verdict = "no violation figures in this run's summary"
    elif viol <= tol:
        verdict = (f"ok: no command left the boundary by more than the tolerance "
                   f"(max {viol:.2f}° ≤ {tol:g}°)")
    else:
        verdict = f"VIOLATION: a command was {viol:.2f}° outside (tolerance {tol:g}°)"
    if summary.get("safe_state_entries"):
        verdict += f"; safe state entered: {summary.get('safe_state_reason')}"
    return facts, verdict


#: Interventions that mean the patient's limit was binding on a joint (its target left the
#: limits, or the goal was brought back into them), by their summary names.
LIMIT_KINDS = ("projected", "reprojected", "recovery")


def enforcement_joint_rows(summary: dict) -> list[dict[str, Any]]:
    """One row per joint of a limb run's summary (``joints``): the largest violation, how often
    the patient's limit was binding (:data:`LIMIT_KINDS`), held cycles (a stale or invalid
    target, a coupled joint recovering), rate-limited cycles and the tracking of admissible
    targets; empty for a run of one joint."""
    joints = summary.get("joints") or {}
    if len(joints) < 2:
        return []
    order = [n for n in summary.get("joint_names") or () if n in joints]
    order += [n for n in joints if n not in order]
    rows = []
    for name in order:
        j = joints[name]
        kinds = j.get("interventions_by_kind") or {}
        rows.append({
            "joint": name,
            "max violation (°)": j.get("max_violation_deg"),
            "limit binding (cycles)": sum(int(kinds.get(k, 0)) for k in LIMIT_KINDS),
            "held (cycles)": sum(int(v) for k, v in kinds.items() if k.startswith("hold")
                                 or k == "held_for_coupled"),
            "rate-limited (cycles)": j.get("rate_limited"),
            "tracking p50 (°)": j.get("tracking_p50_deg"),
            "tracking p95 (°)": j.get("tracking_p95_deg"),
        })
    return rows


def leader_facts(summary: dict) -> dict[str, Any]:
    """Report rows of a run driven by a leader arm (its summary's ``leader``); empty
    otherwise."""
    lead = summary.get("leader")
    if not lead:
        return {}

    def pair(d, a="p50", b="p99", digits=1):
        if not d or d.get(a) is None:
            return None
        return f"{d[a]:.{digits}f} / {d[b]:.{digits}f}"

    track = lead.get("tracking_deg") or {}
    facts = {
        "leader reads": lead.get("reads"),
        "failed reads (an older target; held from the second in a row)": lead.get("failures"),
        "leader → follower latency p50 / p99 (ms)": pair(lead.get("latency_ms")),
        "leader read p50 / p99 (ms)": pair(lead.get("leader_ms")),
        "tracking of admissible leader motion, median / p95 (°)":
            pair(track, "median", "p95") if track else None,
        "cycles with an admissible leader posture": track.get("cycles") if track else None,
        "mirrored (the patient's other arm leads)": lead.get("mirrored"),
    }
    spring = lead.get("spring")
    if spring:
        facts["spring at the leader"] = "armed" if spring.get("armed") else "not armed"
        facts["spring binding (cycles)"] = spring.get("binding_cycles")
        facts["spring current p95 / max (mA)"] = pair(spring.get("current_ma"), "p95", "max",
                                                      0)
        facts["spring failures"] = spring.get("failures")
    return {k: v for k, v in facts.items() if v is not None}


def evaluate_for_report(model_path, *, n: int = 4000, seed: int = 12_345):
    """(constraint, metrics, limb directions (n, 3), 3-D error % (n,)) of a model on held-out
    orientations of the constraint embedded in it."""
    model = load_model(model_path, limb=False)
    constraint = loads_constraint(model.constraint_yaml, source=str(model_path))
    oracle = ConstraintOracle(constraint)
    q = held_out_orientations(constraint, n, seed, oracle=oracle)
    metrics = evaluate_model(model, constraint, q=q, oracle=oracle)
    ideal = Q.canonical(oracle.correction(q))
    learned = np.asarray(model.correction(q), dtype=np.float64)
    learned /= np.linalg.norm(learned, axis=1, keepdims=True)
    err = three_d_error_percent(q, ideal, learned)
    return constraint, metrics, Q.limb_direction(q), err


def report_data_for_session(store, session_id: int, *, model=None, age: int | None = None,
                            sex: str | None = None, reference=None,
                            eval_n: int = 4000, fusion: str = "auto") -> ReportData:
    """Everything the report of ``session_id`` shows (see the module docstring).

    Parameters
    ----------
    store : rig.store.Store
        Opened store.
    session_id : int
        A recording session, or an ``enforce`` session (its recording session, if it names
        one, supplies the range of motion).
    model : path, optional
        ONNX model to evaluate; default the last model registered with the recording session
        (when its file exists).
    age, sex : optional
        For the population reference band.
    reference : JointConstraint, optional
        A boundary drawn dashed for comparison (e.g. the simulated patient's true range).
    eval_n : int
        Held-out orientations for the model section.
    fusion : {"auto", "device", "vqf"}
        Where an IMU recording's orientations come from when its boundary is extracted
        (:func:`rig.readback.joint_orientations_from_store`).
    """
    sess = store.sessions.get(session_id)
    side = sess.get("side") or "right"
    data = ReportData(patient=sess.get("pseudonym") or "?", session_id=session_id,
                      joint=sess.get("joint") or "shoulder", side=sess.get("side"),
                      rig=sess.get("rig_name"), started=_iso(sess.get("started_at")),
                      software=f"rig {__version__}")
    data.duration_s = store.samples.span(session_id)  # the samples' span, not wall time
    meta = sess.get("meta") or {}
    free = (meta.get("coverage") or {}).get("t_span_s")  # the recording after calibration
    data.free_motion_s = None if free is None else float(free)
    data.calibrated = bool(meta.get("calibrated"))
    data.samples = int(store.samples.count(session_id))
    data.dropped = sess.get("dropped")
    rec_id = _recording_session(store, sess)

    if rec_id is not None:
        joint = None
        try:
            joint = joint_orientations_from_store(store, rec_id, fusion=fusion)
        except user_errors() as err:  # a recording that cannot give joint orientations
            data.rom_note = f"Samples not usable for the boundary: {err}."
        rec_meta = store.sessions.get(rec_id).get("meta") or {}
        data.simulated = bool(rec_meta.get("simulated"))
        if joint is not None:
            facts = joint.facts()
            data.simulated = bool(facts.simulated)
            data.warnings = facts.warnings()
        constraint, rep, origin = _boundary(store, rec_id, joint)
        if constraint is not None:
            data.rom_rows = rom_rows(range_of_motion(
                constraint, side, directions=None if joint is None else joint.directions),
                age=age, sex=sex)
            data.warnings = data.warnings + [r.beyond_reach for r in data.rom_rows
                                             if r.beyond_reach]
            note = ("Peaks: the farthest reach along each clinical plane (within 5°) of the "
                    f"recorded boundary ({origin}) and of the recorded samples, the smaller of "
                    "the two; rotations with the arm at the side.")
            data.rom_note = note if data.rom_note is None else f"{data.rom_note} {note}"
            directions = np.empty((0, 3))
            if joint is not None:
                directions = Q.limb_direction(joint.q, joint.limb_axis)
            arcs = rep.get("sparse_arcs") or []
            pairs = [(np.asarray(a["from"], float), np.asarray(a["to"], float)) for a in arcs]

            data.boundary_png = boundary_figure(directions, constraint.swing, side=side,
                                                sparse_arcs=pairs,
                                                reference_swing=getattr(reference, "swing",
                                                                        None))
            facts: dict[str, Any] = {"joint orientations": len(directions)}
            if joint is not None and joint.facts().sectors:
                f = joint.facts()
                facts["coverage of the range"] = (
                    f"{f.explored} of {f.sectors} directions explored"
                    + ("" if f.sufficient else " (not sufficient)"))
            if joint is not None and joint.orientations is not None:
                facts["IMU orientations"] = joint.orientations
            verts = getattr(constraint.swing, "vertices", None)
            if verts is not None:
                facts["boundary vertices"] = len(verts)
            tw = constraint.twist
            if tw is not None:
                facts["twist range (°)"] = f"{tw.min_deg:.1f} … {tw.max_deg:.1f}"
            if "inside" in rep:
                facts["recorded directions inside the boundary (%)"] = \
                    100.0 * float(rep["inside"])
            if "inside_1deg" in rep:
                facts["… within 1° of it (%)"] = 100.0 * float(rep["inside_1deg"])
            if reference is not None:
                dist = boundary_distance(constraint, reference)
                facts["mean distance to reference (°)"] = dist["mean_deg"]
            data.boundary_facts = facts
            data.sparse_arcs_deg = []
            data.sparse_arcs_text = [_arc_text(a, side) for a in arcs]
        data.calibrations = _calibration_rows(store.calibrations.list(rec_id))
        refit = (None if joint is None else
                 (joint.provenance.get("fusion") or {}).get("refit_residual_deg"))
        if refit is not None:
            data.calibrations.append({"kind": "imu-alignment re-fitted on the VQF orientations",
                                      "residual_deg": float(refit)})
        if model is None:
            found = _last_registered_model(store, rec_id)
            model = None if found is None else found[1]

    if model is not None:
        stored = None if rec_id is None else stored_model_evaluation(store, rec_id, model)
        n, seed = (eval_n, REPORT_SEED) if stored is None else (stored[1]["n"],
                                                                 stored[1]["seed"])
        mc, metrics, dirs, err = evaluate_for_report(model, n=n, seed=seed)
        if stored is not None:  # the figures that evaluation gave, wherever it is shown
            metrics = stored[0]
        _, verdict = evaluation_verdict(metrics)
        data.model_verdict = verdict
        data.model_metrics = {
            "evaluation": _evaluation_words(stored, n, seed),
            "held-out orientations": int(metrics.get("n", len(err))),
            "mean 3-D error (%)": metrics["mean_3d_error_pct"],
            "p99 direction error (°)": metrics["p99_angular_error_deg"],
            "invalid inputs left > 1° outside (%)":
                100.0 * metrics["frac_invalid_violating_1deg"],
            "max violation (°)": metrics["max_violation_deg"],
            "mean identity error, valid inputs (°)": metrics["mean_identity_error_deg"],
            "model file": Path(model).name,
        }
        data.error_map_png = error_map_figure(dirs, err, mc.swing)

    runs = _runs(store, sess, rec_id)
    done = [r for r in runs if r.get("summary")]
    if done:
        last = done[-1]
        facts, verdict = enforcement_facts(last["summary"])
        if len(done) > 1:
            facts["runs"] = len(done)
            facts["max violation over all runs (°)"] = max(
                float(r["summary"].get("max_violation_deg") or 0.0) for r in done)
        data.enforcement = facts
        data.enforcement_verdict = verdict
        data.enforcement_joints = enforcement_joint_rows(last["summary"])
        data.leader = leader_facts(last["summary"])
        if sess.get("kind") == "enforce" and len(data.enforcement_joints) > 1:
            data.joint = ", ".join(r["joint"] for r in data.enforcement_joints)
    return data


def report_for_session(store, session_id: int, out_path, *, model=None, age=None, sex=None,
                       reference=None, eval_n: int = 4000, fusion: str = "auto",
                       db: str | Path | None = None,
                       coupled_tests: bool = True) -> Path:
    """Write the HTML report of a session in an opened store — one joint or a whole limb (a
    session of one joint is a limb of one joint; each has its page); returns its path.

    Parameters
    ----------
    store : rig.store.Store
        Opened store.
    session_id : int
        A recording session of one joint (or an ``enforce`` session naming one,
        :func:`report_data_for_session`), or of a whole arm or leg (:func:`_write_limb_report`).
    out_path : path
        The HTML file to write.
    model : path, optional
        A model to show; default the last registered with the session whose file is there. A
        joint's model must be made for the session's joint, side and patient
        (:class:`~rig.errors.RigConfigError`, one line, before any work).
    age, sex : optional
        For the population reference band.
    reference : JointConstraint, models.limb.Limb or path, optional
        The truth drawn dashed (a simulated patient's): a joint's constraint, a limb's limits,
        or the file of either.
    eval_n : int
        Held-out inputs of a model scored for the report (no evaluation stored with it).
    fusion : {"auto", "device", "vqf"}
        Where an IMU recording's orientations come from.
    db : path or URL, optional
        The store's path or URL: with it, a recording whose patient has more than one visit
        of its joint (a limb's: of its joints) gets the progress section
        (:mod:`rig.report.progress`).
    coupled_tests : bool
        A whole arm or leg: the section "Coupled clinical tests"
        (:mod:`calibration.clinical_tests`), shown unless False (``rig report
        --no-coupled-tests``); a session of one joint has none.
    """
    sess = store.sessions.get(session_id)  # no session N: before any work
    if session_limb(sess) is None and (sess.get("joint") or "shoulder") != "shoulder":
        if model is not None:
            _check_model_for_session(model, sess, session_id)
        if isinstance(reference, (str, Path)):
            reference = load_constraint(reference)
        return _write_joint_report(store, sess, out_path, model=model, age=age, sex=sex,
                                   reference=reference, eval_n=eval_n, fusion=fusion, db=db)
    if session_limb(sess) is not None:
        if isinstance(reference, (str, Path)):
            reference = load_limb(reference)
        return _write_limb_report(store, session_id, out_path, model=model, age=age, sex=sex,
                                  reference=reference, eval_n=eval_n, fusion=fusion, db=db,
                                  coupled_tests=coupled_tests)
    if model is not None:
        _check_model_for_session(model, sess, session_id)
    if isinstance(reference, (str, Path)):
        reference = load_constraint(reference)
    data = report_data_for_session(store, session_id, model=model, age=age, sex=sex,
                                   reference=reference, eval_n=eval_n, fusion=fusion)
    joint = sess.get("joint") or "shoulder"
    if (db is not None and sess.get("pseudonym") and sess.get("kind") == "record"
            and sessions_of(store, sess["pseudonym"], (joint,)) > 1):
        data.progress_html = progress_section_html(run_progress(ProgressRequest(
            str(db), sess["pseudonym"], joint, age=age, sex=sex)))
    return write_report(data, out_path)


#: The seed of the held-out set a report draws for a model with no stored evaluation (``rig
#: evaluate``'s default).
REPORT_SEED = 12_345


def stored_model_evaluation(store, session_id: int, model) -> tuple[dict, dict] | None:
    """``(metrics, which)`` of the evaluation stored with ``model`` (the file, unchanged since:
    the same SHA-256) among the models registered with the session, the newest
    (:func:`rig.training.verdict.stored_evaluation`: ``which`` has ``n``, ``seed``, ``by``
    and the model's ``id``); None when none is stored."""
    path = Path(model).resolve()
    digest = None
    for row in reversed(store.models.list(session_id=session_id)):
        if Path(row["path"]).resolve() != path:
            continue
        got = stored_evaluation(row)
        if got is None:
            continue
        digest = digest or file_sha256(path)
        if str(row.get("sha256") or "").lower() == digest:
            return got[0], {**got[1], "id": int(row["id"])}
    return None


def _evaluation_words(stored, n: int, seed: int) -> str:
    """Which evaluation the model section shows, for people."""
    if stored is None:
        return (f"drawn for this report: {n:,} held-out inputs, seed {seed} (no evaluation "
                "stored with the model)")
    which = stored[1]
    return (f"stored with model {which['id']} by {which.get('by') or 'its evaluation'}: "
            f"{n:,} held-out inputs, seed {seed}")


def _last_registered_model(store, session_id: int, accept=None) -> tuple[int, str] | None:
    """``(id, path)`` of the last model registered with the session whose file is still there
    (and that ``accept(path)`` takes, when given), else None."""
    for m in reversed(store.models.list(session_id=session_id)):
        if Path(m["path"]).is_file() and (accept is None or accept(str(m["path"]))):
            return int(m["id"]), str(m["path"])
    return None


def _is_limb_model_of(joints):
    """``accept`` for :func:`_last_registered_model`: a limb model of ``joints``."""
    def accept(path: str) -> bool:
        try:
            return load_model(path, limb=True).limb.joint_names == tuple(joints)
        except (ModelsError, OSError):
            return False  # a single joint's model, or a file replaced since
    return accept


def _write_joint_report(store, sess: dict, out_path, *, model=None, age=None, sex=None,
                        reference=None, eval_n: int = 4000, fusion: str = "auto",
                        db: str | Path | None = None) -> Path:
    """Write the report of a recording of one joint other than the shoulder (an elbow, a
    knee, an ankle, ...; an ``enforce`` session: its recording's): the page of a limb of one
    joint (:func:`rig.readback.boundary.one_joint_limb`, :mod:`rig.report.limb`), which reads
    every joint's clinical movements and draws a hinge's interval or a swing map — as ``rig
    report FILE`` does for one joint of a file. The shoulder's page
    (:func:`report_data_for_session`) reads the shoulder's movements only.

    The limits are the boundary stored with the session, else extracted from it as ``rig
    boundary`` does; the model (``model``, else the last one-joint model registered with the
    session whose file is there) is scored on ``eval_n`` held-out orientations of its
    embedded constraint (or the evaluation stored with it) against a single joint's targets;
    ``reference``: a constraint drawn dashed."""
    session_id = int(sess["id"])
    rec_id = _recording_session(store, sess)
    if rec_id is None:
        raise RigConfigError(f"session {session_id}: an enforcement run that names no "
                             "recording session: nothing to report")
    joint = sess.get("joint")
    side = sess.get("side") or "right"
    if reference is not None:  # a knee's limits drawn on an elbow would mislead
        why = joint_mismatch(reference, for_joint=joint, for_side=side)
        if why is not None:
            raise RigConfigError(f"--reference: the constraint {why}")
    data_j = joint_orientations_from_store(store, rec_id, fusion=fusion)
    constraint, _, origin = _boundary(store, rec_id, data_j)
    limb = one_joint_limb(constraint, joint, name=f"session-{rec_id}-{joint}", side=side)
    ref = (None if reference is None else
           one_joint_limb(reference, joint, name=str(getattr(reference, "name", None)
                                                      or "reference"), side=side))
    evaluation = evaluation_note = None
    if model is None:
        found = _last_registered_model(store, rec_id, _is_joint_model)
        model = None if found is None else found[1]
    if model is not None:
        stored = stored_model_evaluation(store, rec_id, model)
        if stored is None:
            _, evaluation, _, _ = evaluate_for_report(model, n=eval_n, seed=REPORT_SEED)
            evaluation_note = _evaluation_words(None, eval_n, REPORT_SEED)
        else:
            evaluation = stored[0]
            evaluation_note = _evaluation_words(stored, stored[1]["n"], stored[1]["seed"])
        evaluation_note += f"; model file {Path(model).name}"
    rec = store.sessions.get(rec_id)
    facts = data_j.facts()
    data = limb_report_data(
        limb, {joint: data_j.joint_q[:, 0]}, side=side, patient=sess.get("pseudonym") or "?",
        session_label=f"session {rec_id} ({rec.get('rig_name')}, started "
                      f"{_iso(rec.get('started_at')) or 'at an unknown time'}, "
                      f"{len(data_j.joint_q):,} orientations)",
        warnings=facts.warnings(), reference=ref, evaluation=evaluation,
        evaluation_note=evaluation_note, age=age, sex=sex,
        limits_source=f"the {origin}" if origin.startswith("boundary") else origin,
        coupled_tests=False)
    data.simulated = bool(facts.simulated)
    if (db is not None and sess.get("pseudonym") and rec.get("kind") == "record"
            and sessions_of(store, sess["pseudonym"], (joint,)) > 1):
        data.progress_html = progress_section_html(run_progress(ProgressRequest(
            str(db), sess["pseudonym"], joint, age=age, sex=sex)))
    return write_limb_report(data, out_path)


def _is_joint_model(path: str) -> bool:
    """``accept`` for :func:`_last_registered_model`: a one-joint model."""
    try:
        load_model(path, limb=False)
    except (ModelsError, OSError):
        return False  # a limb's model, or a file replaced since
    return True


def _write_limb_report(store, session_id: int, out_path, *, model=None, age=None, sex=None,
                       reference=None, eval_n: int = 4000, fusion: str = "auto",
                       db: str | Path | None = None,
                       coupled_tests: bool = True) -> Path:
    """Write the report of a whole-limb session (:mod:`rig.report.limb`); returns its path.

    The joints' orientations come from :func:`rig.readback.sessions.
    joint_orientations_from_store`. The limits shown are the ``model``'s (a limb model embeds
    the limb file it was made for; it is scored on ``eval_n`` held-out postures of it), else
    the last limb file stored with the session (``rig boundary --limb --db``), else extracted
    from the session as ``rig boundary --limb`` does; the page says which. Without ``model``
    the last limb model registered with the session (the limb demo registers its own) is
    used when its file is still there. ``reference``: a
    :class:`models.limb.Limb` drawn dashed (a simulated patient's truth)."""
    chain = joint_orientations_from_store(store, session_id, fusion=fusion)
    evaluation = evaluation_note = None
    registered = None
    if model is None:  # the last limb model registered with the session, if its file is there
        registered = _last_registered_model(store, session_id, _is_limb_model_of(chain.joints))
        if registered is not None:
            model = registered[1]
    if model is not None:
        limb = load_model(str(model), limb=True).limb
        if limb.joint_names != chain.joints:
            raise RigConfigError(f"--model {model}: a model of the joints "
                                 f"{', '.join(limb.joint_names)}, the session recorded "
                                 f"{', '.join(chain.joints)}")
        stored = stored_model_evaluation(store, session_id, model)
        if stored is None:
            evaluation, _ = evaluate_limb(str(model), limb, eval_n, REPORT_SEED)
            evaluation_note = _evaluation_words(None, eval_n, REPORT_SEED)
        else:  # the evaluation the demo (or rig evaluate) registered: its figures, its verdict
            evaluation = stored[0]
            evaluation_note = _evaluation_words(stored, stored[1]["n"], stored[1]["seed"])
        source = f"the limb file of the model {Path(model).name}" + (
            "" if registered is None else f" (model {registered[0]}, registered with the "
                                          "session)")
    else:
        found = stored_limb(store, session_id)
        if found is not None and found[0].joint_names == chain.joints:
            limb, bid = found
            source = f"boundary {bid} stored with the session (rig boundary --chain)"
        else:
            limb = LimbExtractor(chain.limb, name=f"session-{session_id}-{chain.limb}").fit(
                chain.joint_q, t=chain.t, status=chain.status, side=chain.side,
                slow_error_deg=chain.slow_errors_deg).limb_
            source = "extracted from the recorded postures for this report"
    cal = latest_calibration(store.calibrations.list(session_id), "imu-limb")
    residuals = None if cal is None else cal["data"].get("residuals_deg")
    note = None if cal is None else "The recorder's calibration (the devices' orientations)."
    fused = chain.provenance.get("fusion") or {}
    if fused.get("refit_residuals_deg"):  # the joints came through the host's re-fit
        residuals = fused["refit_residuals_deg"]
        lean = fused.get("root_lean_deg")
        note = ("Re-fitted on the raw samples fused on this computer (VQF)"
                + ("." if lean is None else
                   f"; the {LIMB_CHAINS[chain.limb][0][1]} leaned {lean:.2f}° during the "
                   "static pose, measured against the neutral checkpoints, and that lean was "
                   "taken off every segment."))
    sess = store.sessions.get(session_id)
    # the postures the sensors vouch for (as the extraction and the peaks use them)

    ok = trusted_samples(chain.status, len(chain.t))
    used = (f"{len(chain.t):,} postures" if ok.all() else
            f"{int(ok.sum()):,} of {len(chain.t):,} postures: those the sensors flagged "
            "(magnetic disturbance, uncalibrated) left out")
    data = limb_report_data(
        limb, {j: chain.joint_q[ok, k] for k, j in enumerate(chain.joints)},
        side=chain.side or "right", patient=chain.patient,
        session_label=f"session {session_id} ({sess.get('rig_name')}, started "
                      f"{_iso(sess.get('started_at')) or 'at an unknown time'}, {used})",
        warnings=chain.recording.warnings(), reference=reference,
        calibration=residuals, calibration_note=note,
        evaluation=evaluation, age=age, sex=sex, limits_source=source,
        evaluation_note=evaluation_note, coupled_tests=coupled_tests)
    data.simulated = bool(chain.recording.simulated)
    if db is not None and sess.get("pseudonym") and sessions_of(
            store, sess["pseudonym"], tuple(chain.joints)) > 1:
        data.progress_html = progress_section_html(merged_progress(
            [run_progress(ProgressRequest(str(db), sess["pseudonym"], j, age=age, sex=sex))
             for j in chain.joints]))
    return write_limb_report(data, out_path)


@dataclass(frozen=True)
class ReportRequest:
    """What ``rig report`` is asked: the store and session — or a file (``file``: the
    recording and which joint or whole limb to read from it, as ``rig boundary`` takes them,
    :mod:`rig.report.files`) —, the HTML file to write, a model to evaluate (default: the last
    registered with the session), the patient's age and sex (the population reference band),
    a constraint drawn dashed for comparison (a file path or a
    :class:`~models.constraint.JointConstraint`; a file's report: a limb too), the held-out
    orientations of the model section and where an IMU recording's orientations come from."""

    db: str | Path | None = None
    session_id: int | None = None
    out: str | Path = "report.html"
    model: str | Path | None = None
    age: int | None = None
    sex: str | None = None
    reference: Any = None
    eval_n: int = 4000
    fusion: str = "auto"
    coupled_tests: bool = True
    #: a file's report: its recording, one joint or a whole limb (``out`` is the page's);
    #: None: the session ``db`` / ``session_id``
    file: BoundaryRequest | None = None

    def check(self) -> None:
        """A recording, session or file, and the files given, before anything is drawn
        (one-line errors)."""
        if self.file is not None:
            if self.db is not None or self.session_id is not None:
                raise RigConfigError("give either FILE or --db/--session, not both")
            if self.model is not None:
                raise RigConfigError("--model applies to a session's report (the model "
                                     "registered with it), not to a file's")
            self.file.check()
        elif self.db is None or self.session_id is None:
            raise RigConfigError("give a recording: FILE (.sto, .csv, .c3d, .bvh), or --db DB "
                                 "--session ID")
        check_output(self.out, "--out")
        if self.model is not None and not Path(self.model).is_file():
            raise RigConfigError(f"--model {self.model}: no such file")


@dataclass
class ReportResult:
    """The report written."""

    path: Path


def run_report(request: ReportRequest) -> ReportResult:
    """Check the request and the session (``no session N`` before any work) or the file (its
    format, columns, markers or joints: before any extraction), then write the report."""
    request.check()
    if request.file is not None:
        return ReportResult(report_for_file(
            request.file, Path(request.out), age=request.age, sex=request.sex,
            reference=request.reference, coupled_tests=request.coupled_tests))
    with open_store(request.db, create=False) as store:
        return ReportResult(report_for_session(
            store, request.session_id, Path(request.out), model=request.model, age=request.age,
            sex=request.sex, reference=request.reference, eval_n=request.eval_n,
            fusion=request.fusion, db=request.db, coupled_tests=request.coupled_tests))


def _check_model_for_session(model, sess: dict, session_id: int) -> None:
    """``--model`` must be made for the session's joint, side and patient (one line, before any
    work): a knee's model in a shoulder's report would show another joint's figures."""
    text = load_model(model, limb=False).constraint_yaml
    if not text:
        return
    mc = loads_constraint(text, source=f"{model} (embedded constraint)")
    joint = sess.get("joint") or "shoulder"
    why = joint_mismatch(mc, for_joint=joint, for_side=sess.get("side"))
    if why is None and mc.patient is not None and sess.get("pseudonym") not in (None,
                                                                                 mc.patient):
        why = f"is for patient {mc.patient!r}, not {sess.get('pseudonym')!r}"
    if why is not None:
        raise RigConfigError(f"--model {model}: its constraint {mc.name!r} {why} (session "
                             f"{session_id} recorded the {sess.get('side') or ''} {joint})"
                             .replace("  ", " "))


def _calibration_rows(cals: list[dict]) -> list[dict]:
    """One row per calibration; the neutral checkpoints (one stored row each) as one row:
    their count and the median of their residuals (limb axis from neutral, degrees)."""
    rows = [{"kind": c.get("kind"), "residual_deg": c.get("residual_deg")}
            for c in cals if c.get("kind") != "neutral-checkpoint"]
    ck = [c.get("residual_deg") for c in cals if c.get("kind") == "neutral-checkpoint"]
    if ck:
        vals = [float(r) for r in ck if r is not None]
        rows.append({"kind": f"neutral checkpoints ×{len(ck)} (median)",
                     "residual_deg": float(np.median(vals)) if vals else None})
    return rows
