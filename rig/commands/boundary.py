"""``rig boundary``: a patient-specific constraint file from a recording.

Input is a recorded session (``--db DB --session ID``) or an imported orientation file
(``FILE.sto`` / ``FILE.csv`` with ``--reference COLUMN --limb COLUMN``: joint orientation =
reference⁻¹ ⊗ limb; with ``--limb`` alone the column already holds joint orientations). The
extraction is :class:`calibration.boundary.BoundaryExtractor`; the constraint file records its
provenance (session or file, parameters, sample counts, sparse arcs).

:func:`load_joint_orientations` is shared with ``rig rom``.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import click
import numpy as np

from calibration.frames import FRAMES
from rig.errors import RigConfigError

#: Session statuses that mean the recording stopped before its planned end.
_CUT_SHORT = ("interrupted", "device_lost", "failed")


@dataclass(frozen=True)
class RecordingFacts:
    """What a reader must know before trusting figures from a recording.

    ``interrupted``: the session ended before its planned end (Ctrl-C, SIGTERM, a lost device,
    a killed recorder), None for files (unknown). ``explored``/``sectors``/``sufficient``: the
    coverage of the swing sphere (:mod:`rig.record.coverage`: sectors around the range's
    centre where the limit was reached and stopped moving outward). ``simulated``: samples
    from a simulator (``sim://`` ports), None when unknown.
    """

    status: str | None = None
    interrupted: bool | None = None
    explored: int | None = None
    sectors: int | None = None
    sufficient: bool | None = None
    simulated: bool | None = None
    unmeasured_drift: bool = False  # IMU orientations with no neutral checkpoint accepted

    @property
    def coverage(self) -> float | None:
        """Share of the sectors explored, 0-1 (None before it is known)."""
        if not self.sectors:
            return None
        return self.explored / self.sectors

    def warnings(self) -> list[str]:
        """One line per reason to doubt the figures (empty when there is none)."""
        out = []
        if self.interrupted:
            out.append(f"the session was cut short (status {self.status!r}): the range of "
                       "motion may not have been recorded to the end")
        if self.sectors and not self.sufficient:
            out.append(f"coverage {self.explored} of {self.sectors} directions explored: "
                       "where a limit was not reached, the boundary and the peaks understate "
                       "the range")
        if self.unmeasured_drift:
            out.append("no neutral checkpoint was accepted: the IMUs' relative heading drift is "
                       "neither removed nor measured, so the rotations (and the boundary with "
                       "the arm raised) may be overstated by it")
        return out

    def as_dict(self) -> dict[str, Any]:
        return {"status": self.status, "interrupted": self.interrupted,
                "coverage": None if self.coverage is None else round(self.coverage, 4),
                "explored_sectors": self.explored, "sectors": self.sectors,
                "coverage_sufficient": self.sufficient, "simulated": self.simulated,
                "unmeasured_drift": self.unmeasured_drift}


@dataclass
class JointData:
    """Joint orientations from a session or file, and where they came from."""

    q: np.ndarray  # (N, 4) limb relative to reference
    status: np.ndarray | None  # (N,) IMU calibration bytes, or None
    limb_axis: np.ndarray  # (3,)
    side: str | None
    provenance: dict[str, Any] = field(default_factory=dict)
    patient: str | None = None
    joint: str | None = None
    t: np.ndarray | None = None  # (N,) sample times, seconds (any origin), or None

    recording: RecordingFacts | None = None

    def facts(self) -> RecordingFacts:
        """What a reader must know before trusting figures from this recording (coverage
        computed from the joint orientations when the recorder stored none)."""
        if self.recording is None:
            self.recording = RecordingFacts()
        if self.recording.sectors is None:
            from rig.record.coverage import coverage_of

            cov = coverage_of(self.q, self.t, limb_axis=self.limb_axis)
            self.recording = replace(self.recording, explored=cov.explored,
                                     sectors=len(cov.sectors), sufficient=cov.sufficient)
        return self.recording

    @property
    def directions(self) -> np.ndarray:
        """(N, 3) the recorded limb directions, parent frame (rig axes)."""
        from models import quaternion as Q

        return Q.rotate(self.q, self.limb_axis)

    @property
    def slow_error_deg(self) -> float | None:
        """Measured size of the slowly varying errors left in the orientations (the heading
        correction's own uncertainty, IMU sessions with neutral checkpoints), else None."""
        return (self.provenance.get("heading_correction") or {}).get("uncertainty_deg")

    @property
    def orientations(self) -> str | None:
        """Which IMU orientations an IMU session was read through, for people (None for joint
        samples and files)."""
        method = (self.provenance.get("fusion") or {}).get("method")
        return {"vqf": "fused on the host by VQF from the raw samples",
                "device": "as fused by the devices"}.get(method)


def _parse_axis(text: str | None) -> np.ndarray:
    if text is None:
        return np.array([1.0, 0.0, 0.0])
    try:
        v = np.array([float(c) for c in text.split(",")])
    except ValueError as err:
        raise RigConfigError(f"--limb-axis: expected x,y,z numbers, got {text!r}") from err
    if v.shape != (3,) or not np.isfinite(v).all() or np.linalg.norm(v) < 1e-9:
        raise RigConfigError(f"--limb-axis: expected a non-zero x,y,z vector, got {text!r}")
    return v / np.linalg.norm(v)


def check_source(file: str | None, db: str | None, session_id: int | None,
                 reference: str | None, limb: str | None, frames: str | None = None) -> None:
    """Option combinations, checked before any work (one-line errors)."""
    if file is not None and (db is not None or session_id is not None):
        raise RigConfigError("give either FILE or --db/--session, not both")
    if file is None and (db is None or session_id is None):
        raise RigConfigError("give a recording: FILE.sto|FILE.csv, or --db DB --session ID")
    if file is not None:
        if limb is None:
            raise RigConfigError(f"{file}: --limb COLUMN is required with a file")
        if not Path(file).is_file():
            raise RigConfigError(f"{file}: no such file")
    elif reference is not None or limb is not None:
        raise RigConfigError("--reference/--limb apply to files; a session knows its segments")
    elif frames is not None:
        raise RigConfigError("--frames applies to files; a session is in the rig's frames")


def load_joint_orientations(file: str | None = None, *, db: str | None = None,
                            session_id: int | None = None, reference: str | None = None,
                            limb: str | None = None, limb_axis: str | None = None,
                            fusion: str = "auto", frames: str | None = None) -> JointData:
    """Joint orientations of a session or an orientation file (see module doc); ``fusion``
    applies to sessions (:func:`joint_orientations_from_store`), files hold orientations.

    ``frames`` is the segment-frame convention of a file's orientations (``"rig"``, the
    default, or ``"isb"``: :mod:`calibration.frames`); ``limb_axis`` is given in the same
    convention (default: the long axis, +X in rig frames, −Y in ISB frames). The joint
    orientations returned are in rig frames either way."""
    check_source(file, db, session_id, reference, limb, frames)
    if file is not None:
        frames = frames or "rig"
        if limb_axis is None:
            axis = _parse_axis(None)
        else:
            from calibration.frames import direction_to_rig

            axis = direction_to_rig(_parse_axis(limb_axis), frames)
        return _from_file(file, reference, limb, axis, frames)
    return _from_session(db, session_id, _parse_axis(limb_axis), fusion)


def _from_file(file: str, reference: str | None, limb: str, axis: np.ndarray,
               frames: str = "rig") -> JointData:
    from calibration.alignment import joint_orientation
    from calibration.frames import joint_to_rig, segment_to_rig
    from rig.store.io import read_orientations

    table = read_orientations(file)
    if len(table) < 1:
        raise RigConfigError(f"{file}: no samples")
    child = table.get(limb)
    if reference is not None:
        q = joint_orientation(segment_to_rig(table.get(reference), frames),
                              segment_to_rig(child, frames))
    else:
        q = joint_to_rig(child, frames)
    prov = {"file": str(Path(file).name), "limb": limb, "frames": frames}
    if reference is not None:
        prov["reference"] = reference
    side = table.meta.get("rig_side")
    return JointData(q, None, axis, side if side in ("left", "right") else None, prov,
                     table.meta.get("rig_patient"), table.meta.get("rig_joint"),
                     np.asarray(table.time, dtype=np.float64))


def _from_session(db: str, session_id: int, axis: np.ndarray, fusion: str) -> JointData:
    from rig.store import open_store

    with open_store(db, create=False) as store:
        return joint_orientations_from_store(store, session_id, axis, fusion=fusion)


#: ``fusion`` values of :func:`joint_orientations_from_store` (``--fusion`` of the commands).
FUSION_CHOICES = ("auto", "device", "vqf")


def joint_orientations_from_store(store, session_id: int,
                                  axis: np.ndarray | None = None, *,
                                  heading: bool = True, fusion: str = "auto") -> JointData:
    """Joint orientations of a session in an opened store (joint samples as recorded; IMU
    samples through the session's ``imu-alignment`` calibration). Used by ``rig boundary``,
    ``rig rom`` and the report (:mod:`rig.report.session`).

    ``fusion`` chooses where IMU orientations come from:

    - ``"device"``: the quaternions the devices fused (stored ``q``), through the stored
      calibration;
    - ``"vqf"``: each sensor's raw samples (the store's ``raw``: acc, gyr, mag) fused on the
      host (:func:`calibration.fusion.fuse_vqf`, in the pairing clock: ``device_t`` where the
      device has one); the stored calibration's mounts absorbed the *device* worlds' heading
      offset, so :class:`~calibration.alignment.ImuJointCalibration` is re-fitted from the
      fused orientations on the calibration's own windows (``windows_s`` placed on the
      samples' clock by ``protocol.origin``). Fused samples are not filtered by the devices'
      status bytes (they describe the devices' fusion; VQF detects and rejects magnetic
      disturbances itself): ``JointData.status`` is None. Needs raw samples for every sample
      of both sensors and a calibration with ``protocol.origin``; otherwise a one-line error;
    - ``"auto"`` (default): ``"vqf"`` when those needs are met, else ``"device"``.

    The provenance's ``fusion`` entry records the method (and for VQF the library version, the
    parameters that differ from VQF's defaults, the resampling rate, each sensor's share of
    samples flagged as magnetically disturbed and final gyroscope bias, and the re-fit's
    residuals; for ``auto`` falling back to the device, why).

    IMU sessions with ``neutral-checkpoint`` calibrations (the patient back in the neutral pose
    during the recording, :mod:`rig.record.guided`) also have the two sensors' relative
    heading drift removed (:class:`calibration.heading.HeadingCorrection`, anchored at ψ = 0
    at the centre of the calibration's static window); ``heading=False`` leaves it in. The
    provenance says how many checkpoints were used (``heading_correction``).
    """
    from calibration.alignment import ImuJointCalibration
    from calibration.errors import CalibrationError

    if fusion not in FUSION_CHOICES:
        raise RigConfigError(f"fusion must be one of {', '.join(FUSION_CHOICES)}, got {fusion!r}")
    axis = _parse_axis(None) if axis is None else axis
    sess = store.get_session(session_id)
    sensors = store.sensors(session_id)
    cals = store.calibrations(session_id)
    names = [r["name"] for r in sensors if r.get("n_samples")]
    if not names:
        raise RigConfigError(f"session {session_id} has no samples")
    prov: dict[str, Any] = {"session": int(session_id), "started_at": sess.get("started_at")}
    is_joint = any(r["kind"] == "joint" for r in sensors if r.get("n_samples"))
    if is_joint:
        if fusion != "auto":
            raise RigConfigError(
                f"session {session_id} holds joint samples (a servo limb), not IMU ones: "
                f"--fusion {fusion} applies to IMU sessions"
            )
        s = store.samples(session_id)
        sel = s["kind"] == "joint"
        q, t = s["q"][sel], s["t"][sel]
        del s
        status = None
        prov["source"] = "joint samples"
    else:
        cal = next((c for c in reversed(cals) if c["kind"] == "imu-alignment"), None)
        if cal is None:
            raise RigConfigError(
                f"session {session_id} has IMU samples but no imu-alignment calibration (it "
                "was recorded without the calibration steps): its orientations are the "
                "sensors' frames, not anatomical ones; record again with calibration"
            )
        try:
            model = ImuJointCalibration.from_dict(cal["data"])
        except CalibrationError as err:
            raise RigConfigError(f"session {session_id}: {err}") from err
        parent, child = _segments(sess, sensors, names, session_id)
        # the orientations first; a sensor's raw readings only while it is fused
        per = {nm: store.samples(session_id, name=nm, raw=False) for nm in (parent, child)}
        # pair the two sensors' samples by the device timestamp when the device gives one (the
        # readings of one frame share it; host times are per batch and repeat), else host time
        key_name = ("device_t" if all(np.isfinite(p["device_t"]).all() for p in per.values())
                    else "t")
        use_vqf, why = _vqf_usable(store, session_id, per, key_name, cal["data"])
        if fusion == "vqf" and not use_vqf:
            raise RigConfigError(f"session {session_id}: --fusion vqf: {why}")
        use_vqf = use_vqf and fusion != "device"
        fusion_prov: dict[str, Any] = {"method": "device"}
        if use_vqf:
            fusion_prov = _fuse_sensors(store, session_id, per, key_name)
        elif fusion == "auto":
            fusion_prov["auto"] = why
        tp, qp, sp = (per[parent][k] for k in (key_name, "q", "status"))
        tc, qc, sc = (per[child][k] for k in (key_name, "q", "status"))
        _, ip, ic = np.intersect1d(tp, tc, return_indices=True)
        if len(ip) < 0.5 * min(len(tp), len(tc)):
            # different clocks: nearest-in-time pairing through the store's aligner
            from rig.store.io import align_series

            table, _ = align_series({parent: (tp, qp), child: (tc, qc)})
            qpar, qchi, status = table.columns[parent], table.columns[child], None
            times = {key_name: np.asarray(table.time)}
        else:
            qpar, qchi = qp[ip], qc[ic]
            status = np.minimum(sp[ip], sc[ic])
            # the child's times in the pairing clock first, its host times too
            times = {key_name: tc[ic], "t": per[child]["t"][ic]}
        del per, tp, qp, sp, tc, qc, sc, ip, ic
        if use_vqf:
            status = None  # the devices' status bytes do not describe the host's fusion
            model = _refit(qpar, qchi, times, cal["data"], session_id)
            fusion_prov["refit_residual_deg"] = round(float(model.residual_deg_), 3)
            fusion_prov["refit_residuals_deg"] = {k: round(float(v), 3)
                                                  for k, v in model.residuals_.items()}
        q = model.transform(qpar, qchi)
        t = times[key_name]
        prov.update({"source": "imu samples", "calibration_id": int(cal["id"]),
                     "calibration_residual_deg": cal.get("residual_deg"),
                     "fusion": fusion_prov})
        checkpoints = [c for c in cals if c["kind"] == "neutral-checkpoint"]
        if heading and checkpoints:
            q, prov["heading_correction"] = _heading_correction(
                q, times, status, checkpoints, cal["data"], session_id)
    side = sess.get("side")
    facts = _session_facts(store, sess, sensors)
    if not is_joint and not (prov.get("heading_correction") or {}).get("accepted"):
        facts = replace(facts, unmeasured_drift=True)
    return JointData(q, status, axis, side if side in ("left", "right") else None, prov,
                     sess.get("pseudonym"), sess.get("joint"), np.asarray(t, dtype=np.float64),
                     facts)


def _session_facts(store, sess: dict, sensors: list[dict]) -> RecordingFacts:
    """Status, interruption and the recorder's own final coverage of a session."""
    status = sess.get("status")
    cut = status in _CUT_SHORT
    if status == "running":  # a recorder that died without closing it counts as cut short
        cut = store.session_liveness(int(sess["id"])).state != "live"
    cov = (sess.get("meta") or {}).get("coverage") or {}  # the recorder's own, when it ended
    sectors = cov.get("sectors")
    meta = sess.get("meta") or {}
    simulated = meta.get("simulated")
    if simulated is None:
        ports = [str(r.get("port") or "") for r in sensors]
        simulated = bool(ports) and all(p.startswith("sim://") for p in ports)
    facts = RecordingFacts(status=status, interrupted=bool(cut), simulated=bool(simulated))
    if isinstance(sectors, list) and sectors and "explored_sectors" in cov:
        facts = replace(facts, explored=int(cov["explored_sectors"]), sectors=len(sectors),
                        sufficient=bool(cov.get("sufficient")))
    return facts


def _vqf_usable(store, session_id: int, per: dict[str, dict], key_name: str,
                cal_data: dict) -> tuple[bool, str]:
    """Can the two sensors' samples (``per``: name → samples, without raw) be fused on the
    host? (yes/no, why not); the raw readings are counted by the store, not fetched."""
    for name, s in per.items():
        n = len(s["t"])
        have = store.complete_raw_count(session_id, name)
        if have < n:
            return False, (f"sensor {name!r} has no raw samples for {n - have} of {n} samples "
                           "(record with sensors.raw: true)")
        if (np.diff(s[key_name]) <= 0).any():
            return False, f"sensor {name!r}: sample times repeat (no device clock to fuse on)"
    origin = (cal_data.get("protocol") or {}).get("origin")
    if not origin or not (cal_data.get("windows_s") or {}):
        return False, ("the imu-alignment calibration does not say where its windows are on "
                       "the samples' clock (protocol.origin), so it cannot be re-fitted")
    return True, ""


def _fuse_sensors(store, session_id: int, per: dict[str, dict], key_name: str) -> dict:
    """Each sensor's ``q`` (in ``per``: name → samples) replaced by its VQF orientation, one
    sensor at a time (its raw readings read for it and released); returns the provenance."""
    from importlib.metadata import version

    from calibration.errors import CalibrationError
    from calibration.fusion import fuse_vqf

    prov: dict[str, Any] = {"method": "vqf", "library": f"vqf {version('vqf')}"}
    info: dict[str, dict] = {}
    for name, s in per.items():
        raw = store.raw(session_id, name)
        try:
            res = fuse_vqf(s[key_name], raw)
        except CalibrationError as err:
            raise RigConfigError(f"session {session_id}: sensor {name!r}: {err}") from err
        del raw
        s["q"] = res.q
        prov["params"] = res.params
        info[name] = {"rate_hz": round(res.rate_hz, 3), "pieces": res.pieces,
                      "mag_disturbed_share": round(res.disturbed_share, 4),
                      "gyro_bias_dps": res.bias_dps}
    prov["sensors"] = info
    prov["status_filter"] = "none (VQF rejects magnetic disturbances itself)"
    return prov


def _refit(qpar: np.ndarray, qchi: np.ndarray, times: dict[str, np.ndarray], cal_data: dict,
           session_id: int):
    """:class:`~calibration.alignment.ImuJointCalibration` fitted on the paired (fused)
    orientations inside the stored calibration's static and functional windows."""
    from calibration.alignment import ImuJointCalibration
    from calibration.errors import CalibrationError

    origin = cal_data["protocol"]["origin"]
    clock = times.get(origin.get("time"))
    if clock is None:
        raise RigConfigError(f"session {session_id}: the calibration's windows are on the "
                             f"{origin.get('time')} clock, which the pairing did not keep")
    t0 = float(origin["t0"])
    sel = {}
    for name in ("static", "functional"):
        w = _window((cal_data["windows_s"] or {}).get(name))
        if w is None:
            raise RigConfigError(f"session {session_id}: the calibration has no {name} window")
        sel[name] = (clock >= t0 + w[0]) & (clock <= t0 + w[1])
    try:
        return ImuJointCalibration().fit(qpar[sel["static"]], qchi[sel["static"]],
                                         qpar[sel["functional"]], qchi[sel["functional"]])
    except CalibrationError as err:
        raise RigConfigError(f"session {session_id}: re-fitting the calibration on the VQF "
                             f"orientations: {err}") from err


def _heading_correction(q: np.ndarray, times: dict[str, np.ndarray], status, checkpoints,
                        cal_data: dict, session_id: int):
    """Fit and apply :class:`~calibration.heading.HeadingCorrection` on a session's joint
    orientations; the windows are taken in the clock they were stored in (``time``: the
    samples' ``device_t`` or host ``t``), checkpoints in a clock the pairing did not keep are
    rejected. The axis is +X whatever ``--limb-axis`` says: the IMU calibration's segment
    frames have +X along gravity in the neutral pose, the thorax vertical the drift turns
    about. Returns the corrected orientations and the provenance entry."""
    from calibration.errors import CalibrationError
    from calibration.heading import HeadingCorrection

    base = next(iter(times))
    t = times[base]
    windows, unusable = [], []
    for c in checkpoints:
        d = c.get("data") or {}
        w, clock = _window(d.get("window")), d.get("time", "t")
        if w is not None and clock != base:
            other = times.get(clock)
            # stored in another clock: its window through the samples (both clocks known)
            inside = (other >= w[0]) & (other <= w[1]) if other is not None else None
            w = ([float(t[inside].min()), float(t[inside].max())]
                 if inside is not None and inside.any() else None)
        if w is None:
            unusable.append({"window": d.get("window"),
                             "reason": f"no samples in its window ({clock} clock)"})
        else:
            windows.append(w)
    anchors = []
    origin = (cal_data.get("protocol") or {}).get("origin") or {}
    static = (cal_data.get("windows_s") or {}).get("static")
    if origin.get("time") == base and static is not None:
        anchors.append(float(origin["t0"]) + 0.5 * (float(static[0]) + float(static[1])))
    hc = HeadingCorrection((1.0, 0.0, 0.0))
    try:
        hc.fit(t, q, np.asarray(windows, dtype=np.float64).reshape(-1, 2), status=status,
               anchors=anchors)
    except CalibrationError as err:
        raise RigConfigError(f"session {session_id}: neutral checkpoints: {err}") from err
    rejected = [{"window": [a, b], "reason": r} for (a, b), r in hc.rejected_] + unusable
    uncertainty = hc.uncertainty_deg(float(t.min()), float(t.max())) if len(t) else None
    prov = {"neutral_checkpoints": len(checkpoints), "accepted": hc.accepted_count_,
            "rejected": rejected, "anchored": bool(anchors), "clock": base,
            "psi_deg": [round(float(x), 2) for x in hc.psi_window_deg_],
            "drift_model": dict(hc.drift_model_),
            "uncertainty_deg": None if uncertainty is None else round(uncertainty, 3)}
    return hc.apply(t, q), prov


def _window(w) -> list[float] | None:
    try:
        a, b = (float(x) for x in w)
    except (TypeError, ValueError):
        return None
    return [a, b] if np.isfinite([a, b]).all() and a <= b else None


def _segments(sess: dict, sensors: list[dict], names: list[str],
              session_id: int) -> tuple[str, str]:
    """(thorax sensor, limb sensor) of an IMU session; ``names``: the sensors with samples."""
    meta = sess.get("meta") or {}
    parent, child = meta.get("parent"), meta.get("child")
    if parent in names and child in names:
        return parent, child
    by_segment = {r.get("segment"): r.get("name") for r in sensors}
    parent = by_segment.get("thorax")
    others = [n for n in names if n != parent]
    if parent in names and len(others) == 1:
        return parent, others[0]
    raise RigConfigError(
        f"session {session_id}: cannot tell the thorax and limb sensors apart "
        f"(samples from {', '.join(names)})"
    )


@click.command()
@click.argument("file", required=False, type=click.Path(dir_okay=False))
@click.option("--db", default=None, help="Store: a file path, sqlite:///PATH or postgresql://...")
@click.option("--session", "session_id", default=None, type=click.IntRange(min=1),
              help="Session id (see rig session list).")
@click.option("--reference", default=None, help="FILE column of the reference segment (thorax).")
@click.option("--limb", default=None, help="FILE column of the limb segment (joint orientations "
              "when --reference is not given).")
@click.option("--limb-axis", default=None, help="Limb long axis in the limb frame, x,y,z "
              "(default: the long axis of --frames, 1,0,0 in rig frames).")
@click.option("--frames", type=click.Choice(FRAMES), default=None,
              help="Segment frames of FILE: rig (+X distal, +Y anterior, +Z right; default) or "
              "isb (+Y proximal, +X anterior, +Z right: ISB / OpenSim).")
@click.option("--out", "out", required=True, type=click.Path(dir_okay=False),
              help="Constraint file to write (YAML).")
@click.option("--name", default=None, help="Constraint name (default from the source).")
@click.option("--side", type=click.Choice(["left", "right"]), default=None,
              help="Arm side recorded in the constraint (default: the session's).")
@click.option("--alpha-deg", default=4.0, show_default=True, type=click.FloatRange(min=0.5),
              help="Alpha-shape radius: concavities narrower than ~2x this are bridged.")
@click.option("--max-vertices", default=64, show_default=True, type=click.IntRange(min=3),
              help="Vertex budget of the boundary polygon.")
@click.option("--by-swing", type=click.Choice(["auto", "on", "off"]), default="auto",
              show_default=True, help="Swing-dependent twist limits.")
@click.option("--store/--no-store", "store_result", default=True, show_default=True,
              help="With --db: also store the boundary in the session database.")
@click.option("--fusion", type=click.Choice(FUSION_CHOICES), default="auto", show_default=True,
              help="IMU sessions: orientations fused by the devices, or by VQF on the host "
              "from the raw samples (auto: VQF when every sample has raw data).")
def boundary(file, db, session_id, reference, limb, limb_axis, frames, out, name, side,
             alpha_deg, max_vertices, by_swing, store_result, fusion) -> None:
    """Extract a patient-specific constraint (swing polygon + twist range) from a recording.

    FILE is an OpenSim .sto or a CSV of orientations; or use --db DB --session ID.
    """
    check_source(file, db, session_id, reference, limb, frames)
    _parse_axis(limb_axis)
    if db is not None and store_result:
        from rig.store import open_store

        with open_store(db, create=False) as st:
            if st.readonly:
                raise RigConfigError(f"--db {db} is read-only: add --no-store to extract the "
                                     "boundary without storing it in the session")
    out_path = Path(out)
    if not out_path.parent.is_dir():
        raise RigConfigError(f"--out {out}: directory {out_path.parent} does not exist")
    data = load_joint_orientations(file, db=db, session_id=session_id, reference=reference,
                                   limb=limb, limb_axis=limb_axis, fusion=fusion, frames=frames)
    result = extract(data, name=name, side=side, alpha_deg=alpha_deg,
                     max_vertices=max_vertices, by_swing=by_swing)
    from models.constraint import dump_constraint

    dump_constraint(result.constraint_, out_path)
    if db is not None and store_result:
        from rig.store import open_store

        with open_store(db, create=False) as st:
            st.add_boundary(session_id, result.constraint_.to_yaml(),
                            {"path": str(out_path), **result.report()})
    click.echo(describe(result, out_path))
    for w in data.facts().warnings():
        click.echo(f"warning: {w}")


def extract(data: JointData, *, name: str | None = None, side: str | None = None,
            alpha_deg: float = 4.0, max_vertices: int = 64, by_swing: str = "auto"):
    """Run the extractor on loaded joint orientations (user errors become RigConfigError)."""
    from calibration.boundary import BoundaryExtractor
    from calibration.errors import CalibrationError

    bs = {"auto": "auto", "on": True, "off": False}[by_swing]
    label = name or _default_name(data)
    ex = BoundaryExtractor(alpha_deg=alpha_deg, max_vertices=max_vertices, by_swing=bs,
                           limb_axis=data.limb_axis, name=label)
    prov = dict(data.provenance)
    prov["recording"] = data.facts().as_dict()
    try:
        ex.fit(data.q, status=data.status, t=data.t, provenance=prov,
               slow_error_deg=data.slow_error_deg)
    except CalibrationError as err:
        raise RigConfigError(f"boundary extraction: {err}") from err
    side = side or data.side
    binding = {"side": side, "joint": data.joint, "patient": data.patient}
    binding = {k: v for k, v in binding.items() if v}
    if binding:
        from models.constraint import JointConstraint

        d = ex.constraint_.to_dict()
        d.update(binding)
        try:
            ex.constraint_ = JointConstraint.from_dict(d)
        except ValueError:  # a loader without the binding fields: keep them in provenance
            d = ex.constraint_.to_dict()
            d.setdefault("provenance", {}).update(binding)
            ex.constraint_ = JointConstraint.from_dict(d)
    return ex


def _default_name(data: JointData) -> str:
    """``<patient>-session-<id>-<start, UTC>`` for a session (unique across databases: session
    ids restart in each), the file's stem for a file."""
    if "session" in data.provenance:
        import datetime as dt

        name = f"session-{data.provenance['session']}"
        started = data.provenance.get("started_at")
        if started is not None:
            stamp = dt.datetime.fromtimestamp(float(started), dt.timezone.utc)
            name += stamp.strftime("-%Y%m%dT%H%M%SZ")
        return f"{data.patient}-{name}" if data.patient else name
    return Path(str(data.provenance.get("file", "recording"))).stem


def describe(ex, out_path: Path | None = None) -> str:
    r = ex.report()
    lines = []
    if out_path is not None:
        lines.append(f"wrote {out_path}")
    lines.append(f"  samples     {r['samples']} ({r['samples_used']} used, "
                 f"{r['dropped_status']} dropped for IMU status, "
                 f"{r['spikes']} isolated spikes, {r['glitch_cluster_samples']} in glitch "
                 "clusters)")
    lines.append(f"  swing       polygon, {r['vertices']} vertices, alpha "
                 f"{r['alpha_used_deg']:.1f} deg, noise inset {r['noise_inset_deg']:.2f} deg")
    lines.append(f"  inside      {100 * r['inside']:.2f} % of the {r['directions']} recorded "
                 f"directions inside the boundary written, {100 * r['inside_1deg']:.2f} % "
                 "within 1 deg")
    tw = r["twist_deg"]
    extra = f", {r['by_swing_points']} swing regions" if r["by_swing_points"] else ""
    lines.append(f"  twist       {tw[0]:.1f} .. {tw[1]:.1f} deg{extra}")
    if r["sparse_arcs"]:
        lines.append(f"  sparse      {len(r['sparse_arcs'])} boundary arcs "
                     f"({r['sparse_length_deg']:.0f} deg) with fewer than "
                     f"{ex.sparse_min_samples} samples within {ex.sparse_deg:g} deg: "
                     "the boundary there is interpolated; record more there")
    else:
        lines.append("  sparse      none: every part of the boundary has samples nearby")
    return "\n".join(lines)
