"""Joint orientations of a recorded session: joint samples of a servo limb as recorded, or two
IMUs' orientations through the session's calibration — fused on the host by VQF from the raw
samples where the session has them (the calibration re-fitted on the fused orientations), and
the sensors' relative heading drift removed at the neutral checkpoints.

Every step's :class:`~calibration.errors.CalibrationError` reaches the caller named with the
session and the step (:func:`_about`); the CLI shows it as one line like every user error.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from dataclasses import replace
from importlib.metadata import version
from typing import Any

import numpy as np

from calibration.alignment import ImuJointCalibration
from calibration.errors import CalibrationError
from calibration.fusion import fuse_vqf
from calibration.heading import HeadingCorrection, LimbHeadingCorrection
from calibration.joints import LIMB_CHAINS
from calibration.limb_calibration import LimbImuCalibration
from calibration.protocol import LimbCalibrationProtocol
from rig.errors import RigConfigError
from rig.readback.data import (
    CUT_SHORT,
    FUSION_CHOICES,
    JointData,
    RecordingFacts,
    parse_axis,
)
from rig.store import open_store
from rig.store.io import align_series, shared_instants

__all__ = ["OneJointSession", "WholeLimbSession", "joint_orientations_from_store",
           "read_session", "session_limb", "session_shape"]


def read_session(db: str, session_id: int, axis: np.ndarray | None = None,
                 fusion: str = "auto", joint: str | None = None, *,
                 heading: bool = True) -> JointData:
    """:func:`joint_orientations_from_store` on the store at ``db`` (opened as it is: never
    created, read-only when the file is)."""
    with open_store(db, create=False) as store:
        return joint_orientations_from_store(store, session_id, axis, fusion=fusion,
                                             joint=joint, heading=heading)


def latest_calibration(cals: list[dict], kind: str) -> dict | None:
    """The last stored calibration of ``kind`` among a session's (``store.calibrations``), or
    None."""
    return next((c for c in reversed(cals) if c["kind"] == kind), None)


def session_limb(sess: dict) -> str | None:
    """The limb (``arm``/``leg``) a session recorded whole, or None (one joint):
    :func:`session_shape`'s."""
    return session_shape(sess).limb


def _limb_orientations(store, session_id: int, sess: dict, limb: str, axis: np.ndarray, *,
                       fusion: str, heading: bool) -> JointData:
    """Every joint of a whole-limb session (one IMU per segment, ``limb`` in the rig
    configuration): the four sensors' orientations at the instants all of them have a sample
    (paired by the device timestamp where there is one), through the session's ``imu-limb``
    calibration (:class:`calibration.limb_calibration.LimbImuCalibration`).

    ``fusion`` as for one joint: ``vqf`` fuses each
    sensor's raw samples on the host and re-fits the limb calibration on the fused
    orientations inside its stored windows; ``auto`` does so when every sensor has raw samples
    and the calibration says where its windows are, else uses the devices' orientations
    (``device``). With ``heading`` (default)
    and ``neutral-checkpoint`` calibrations in the session, each sensor's heading drift
    relative to its proximal neighbour is removed
    (:class:`calibration.heading.LimbHeadingCorrection`, anchored at the calibration's static
    window; provenance ``heading_correction``); with none accepted the facts say the drift
    was neither removed nor measured.
    """
    cals = store.calibrations.list(session_id)
    cal = latest_calibration(cals, "imu-limb")
    if cal is None:
        raise RigConfigError(
            f"session {session_id} has no imu-limb calibration (it was recorded without the "
            "calibration steps): its orientations are the sensors' frames, not anatomical "
            "ones; record again with calibration")
    with _about(session_id, "limb calibration"):
        model = LimbImuCalibration.from_dict(cal["data"])
    segs = model.segments_
    sensors = store.samples.sensors(session_id)
    by_segment = {r.get("segment"): r.get("name") for r in sensors if r.get("n_samples")}
    missing = [s for s in segs if s not in by_segment]
    if missing:
        raise RigConfigError(f"session {session_id}: no samples from the "
                             f"{', '.join(missing)} sensor(s)")
    by_name = {by_segment[s]: store.samples.read(session_id, name=by_segment[s], raw=False)
               for s in segs}
    per = list(by_name.values())
    key, use_vqf, fusion_prov = _fuse_if_asked(store, session_id, by_name, fusion, cal["data"])
    common, idx = shared_instants([p[key] for p in per])
    if not len(common):
        raise RigConfigError(f"session {session_id}: the {limb}'s sensors have no sample time in "
                             "common")
    q = np.stack([p["q"][i] for p, i in zip(per, idx, strict=True)], axis=1)
    status = np.min(np.stack([p["status"][i] for p, i in zip(per, idx, strict=True)]), axis=0)
    del per, by_name
    common = np.asarray(common, dtype=np.float64)
    checkpoints = [c for c in cals if c["kind"] == "neutral-checkpoint"]
    # the checkpoints' windows in the pairing clock, the unusable ones, the static anchor
    marks = _checkpoint_windows({key: common}, checkpoints, cal["data"])
    if use_vqf:
        status = None  # the devices' status bytes do not describe the host's fusion
        model = _refit_limb(q, {key: common}, cal["data"], session_id, marks[0])
        fusion_prov["refit_residual_deg"] = round(float(model.residual_deg_), 3)
        fusion_prov["refit_residuals_deg"] = {
            name: {k: round(float(v), 3) for k, v in r.items()}
            for name, r in model.residuals_.items()}
        fusion_prov["root_lean_deg"] = (None if model.lean_deg_ is None
                                        else round(float(model.lean_deg_), 3))
    prov = {"session": int(session_id), "started_at": sess.get("started_at"),
            "source": "imu samples", "limb": limb, "calibration_id": int(cal["id"]),
            "calibration_residual_deg": cal.get("residual_deg"),
            "fusion": fusion_prov}
    if heading and checkpoints:
        q, prov["heading_correction"] = _limb_heading_correction(
            model, q, common, key, status, len(checkpoints), marks, session_id)
    joints = model.transform(q)
    side = sess.get("side")
    facts = _session_facts(store, sess, sensors)
    if not (prov.get("heading_correction") or {}).get("accepted"):
        facts = replace(facts, unmeasured_drift=True)
    # each joint's measured slow error: its distal sensor's, relative to its proximal one
    segs = (prov.get("heading_correction") or {}).get("segments") or {}
    slow = {name: (segs.get(child) or {}).get("uncertainty_deg")
            for name, _, child in LIMB_CHAINS[limb]}
    return JointData(joints, tuple(model.joints_), common, status, axis,
                     side if side in ("left", "right") else None, prov, sess.get("pseudonym"),
                     limb, facts, slow)


@contextlib.contextmanager
def _about(session_id: int, step: str | None = None) -> Iterator[None]:
    """A :class:`CalibrationError` raised inside, named with the session (and the step)."""
    try:
        yield
    except CalibrationError as err:
        where = f"session {session_id}: " + (f"{step}: " if step else "")
        raise CalibrationError(where + str(err)) from err


def joint_orientations_from_store(store, session_id: int,
                                  axis: np.ndarray | None = None, *,
                                  heading: bool = True, fusion: str = "auto",
                                  joint: str | None = None) -> JointData:
    """Joint orientations of a session in an opened store (joint samples as recorded; IMU
    samples through the session's ``imu-alignment`` calibration). Used by ``rig boundary``,
    ``rig rom``, the recorder's range of motion and the report.

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

    A whole-limb session (:func:`session_limb`: one IMU per segment, ``limb`` in the rig
    configuration) gives every joint of the limb (J = 3, :func:`_limb_orientations`), or the
    one named by ``joint`` (:meth:`JointData.select <rig.readback.data.JointData.select>`,
    ``axis`` its limb axis); a one-joint session gives its joint (J = 1) and must be asked
    for its own joint (``joint`` None or its name).

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
    if fusion not in FUSION_CHOICES:
        raise RigConfigError(f"fusion must be one of {', '.join(FUSION_CHOICES)}, got {fusion!r}")
    sess = store.sessions.get(session_id)
    return session_shape(sess).read(store, session_id, sess, axis, fusion=fusion,
                                    heading=heading, joint=joint)


class OneJointSession:
    """A session of one joint (a thorax and a limb IMU through an ``imu-alignment``
    calibration, or a servo joint's samples): what :func:`session_shape` gives for it."""

    #: The whole limb recorded: none.
    limb = None

    def recorded(self, sess: dict) -> str:
        """What the session recorded, for people: its joint."""
        return sess.get("joint") or "shoulder"

    def require_whole_limb(self, session_id: int, sess: dict) -> None:
        """Refuse a whole limb's request (``--limb``) on this session (one line)."""
        raise RigConfigError(f"session {session_id} recorded the {self.recorded(sess)}, not a "
                             "whole arm or leg (no --limb)")

    def read(self, store, session_id: int, sess: dict, axis: np.ndarray | None, *,
             fusion: str, heading: bool, joint: str | None) -> JointData:
        """The joint's orientations (J = 1; :func:`joint_orientations_from_store`); ``joint``
        must be None or the session's own."""
        axis = parse_axis(None) if axis is None else axis
        if joint is not None and joint != self.recorded(sess):
            raise RigConfigError(f"session {session_id} recorded the {self.recorded(sess)}, "
                                 f"not the {joint}")
        sensors = store.samples.sensors(session_id)
        names = [r["name"] for r in sensors if r.get("n_samples")]
        if not names:
            raise RigConfigError(f"session {session_id} has no samples")
        prov: dict[str, Any] = {"session": int(session_id),
                                "started_at": sess.get("started_at")}
        is_joint = any(r["kind"] == "joint" for r in sensors if r.get("n_samples"))
        if is_joint:
            q, t, status = _joint_samples(store, session_id, fusion)
            prov["source"] = "joint samples"
        else:
            q, t, status = _imu_orientations(store, session_id, sess, sensors, names,
                                             fusion=fusion, heading=heading, prov=prov)
        side = sess.get("side")
        facts = _session_facts(store, sess, sensors)
        if not is_joint and not (prov.get("heading_correction") or {}).get("accepted"):
            facts = replace(facts, unmeasured_drift=True)
        return JointData.of_joint(q, sess.get("joint"), t=np.asarray(t, dtype=np.float64),
                                  status=status, limb_axis=axis,
                                  side=side if side in ("left", "right") else None,
                                  provenance=prov, patient=sess.get("pseudonym"),
                                  recording=facts)


class WholeLimbSession:
    """A session of a whole limb (one IMU per segment through an ``imu-limb`` calibration:
    :class:`~calibration.limb_calibration.LimbImuCalibration`, a different algorithm from one
    joint's): what :func:`session_shape` gives for it."""

    def __init__(self, limb: str) -> None:
        self.limb = limb

    def recorded(self, sess: dict) -> str:
        """What the session recorded, for people: its limb."""
        return self.limb

    def require_whole_limb(self, session_id: int, sess: dict) -> None:
        """A whole limb's request (``--limb``) is this session's kind of request."""

    def read(self, store, session_id: int, sess: dict, axis: np.ndarray | None, *,
             fusion: str, heading: bool, joint: str | None) -> JointData:
        """Every joint of the limb (J = 3: a servo limb's joint samples as recorded,
        :func:`_limb_joint_samples`, else the IMUs through the limb calibration,
        :func:`_limb_orientations`), or the one named by ``joint`` (:meth:`JointData.select
        <rig.readback.data.JointData.select>`, ``axis`` its limb axis)."""
        sensors = store.samples.sensors(session_id)
        if any(r["kind"] == "joint" for r in sensors if r.get("n_samples")):
            data = _limb_joint_samples(store, session_id, sess, self.limb, sensors, fusion)
        else:
            data = _limb_orientations(store, session_id, sess, self.limb, parse_axis(None),
                                      fusion=fusion, heading=heading)
        return data if joint is None else data.select(joint, axis)


def _limb_joint_samples(store, session_id: int, sess: dict, limb: str, sensors: list[dict],
                        fusion: str) -> JointData:
    """Every joint of a servo limb's session: each joint's samples (named by the joint: the
    servos' ticks through the limb's forward kinematics, as recorded) at the instants all of
    them have one (one bus read gives every joint's)."""
    _joint_samples(store, session_id, fusion)  # the same refusal of --fusion as one joint's
    names = tuple(name for name, _, _ in LIMB_CHAINS[limb])
    have = {r["name"] for r in sensors if r.get("n_samples") and r["kind"] == "joint"}
    missing = [n for n in names if n not in have]
    if missing:
        raise RigConfigError(f"session {session_id}: no samples of the {limb}'s "
                             f"{', '.join(missing)}")
    per = [store.samples.read(session_id, name=n, raw=False) for n in names]
    common, idx = shared_instants([p["t"] for p in per])
    if not len(common):
        raise RigConfigError(f"session {session_id}: the {limb}'s joints have no sample time "
                             "in common")
    q = np.stack([p["q"][i] for p, i in zip(per, idx, strict=True)], axis=1)
    side = sess.get("side")
    prov = {"session": int(session_id), "started_at": sess.get("started_at"),
            "source": "joint samples", "limb": limb}
    kinds = (sess.get("meta") or {}).get("kinds")
    if kinds:  # the servo limb's joint kinds where not the joints' own (a forearm elbow)
        prov["kinds"] = dict(kinds)
    return JointData(q, names, np.asarray(common, dtype=np.float64), None, parse_axis(None),
                     side if side in ("left", "right") else None, prov, sess.get("pseudonym"),
                     limb, _session_facts(store, sess, sensors), {})


def session_shape(sess: dict) -> OneJointSession | WholeLimbSession:
    """How a session is read back, chosen from what it recorded: a whole limb (``limb`` in
    its metadata: ``arm``/``leg``, :class:`WholeLimbSession`) or one joint
    (:class:`OneJointSession`). The one place that asks which; the read path, ``rig
    boundary`` and the side check ask the object it gives."""
    limb = (sess.get("meta") or {}).get("limb")
    return WholeLimbSession(limb) if limb in ("arm", "leg") else OneJointSession()


def _joint_samples(store, session_id: int, fusion: str):
    """(q, t, status=None) of a servo-limb session's joint samples."""
    if fusion != "auto":
        raise RigConfigError(
            f"session {session_id} holds joint samples (a servo limb), not IMU ones: "
            f"--fusion {fusion} applies to IMU sessions"
        )
    s = store.samples.read(session_id)
    sel = s["kind"] == "joint"
    return s["q"][sel], s["t"][sel], None


def _imu_orientations(store, session_id: int, sess: dict, sensors: list[dict],
                      names: list[str], *, fusion: str, heading: bool, prov: dict):
    """(q, t, status) of an IMU session: the thorax and limb sensors paired in time, through
    the calibration (re-fitted on VQF orientations when fused on the host), the heading drift
    removed at the neutral checkpoints; ``prov`` receives the provenance entries."""
    cals = store.calibrations.list(session_id)
    cal = latest_calibration(cals, "imu-alignment")
    if cal is None:
        raise RigConfigError(
            f"session {session_id} has IMU samples but no imu-alignment calibration (it "
            "was recorded without the calibration steps): its orientations are the "
            "sensors' frames, not anatomical ones; record again with calibration"
        )
    with _about(session_id):
        model = ImuJointCalibration.from_dict(cal["data"])
    parent, child = _segments(sess, sensors, names, session_id)
    # the orientations first; a sensor's raw readings only while it is fused
    per = {nm: store.samples.read(session_id, name=nm, raw=False) for nm in (parent, child)}
    key_name, use_vqf, fusion_prov = _fuse_if_asked(store, session_id, per, fusion, cal["data"])
    tp, qp, sp = (per[parent][k] for k in (key_name, "q", "status"))
    tc, qc, sc = (per[child][k] for k in (key_name, "q", "status"))
    _, ip, ic = np.intersect1d(tp, tc, return_indices=True)
    if len(ip) < 0.5 * min(len(tp), len(tc)):
        # different clocks: nearest-in-time pairing through the store's aligner
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
    return q, t, status


def _session_facts(store, sess: dict, sensors: list[dict]) -> RecordingFacts:
    """Status, interruption and the recorder's own final coverage of a session."""
    status = sess.get("status")
    cut = status in CUT_SHORT
    if status == "running":  # a recorder that died without closing it counts as cut short
        cut = store.sessions.liveness(int(sess["id"])).state != "live"
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


def _fuse_if_asked(store, session_id: int, per: dict[str, dict], fusion: str,
                   cal_data: dict) -> tuple[str, bool, dict[str, Any]]:
    """The pairing clock of the sensors' samples (``per``: name → samples, without raw) —
    the device timestamp when every sample has one (the readings of one frame share it; host
    times are per batch and repeat), else host time — and, as ``fusion`` asks, each sensor's
    ``q`` replaced by its VQF orientation: (clock, fused on the host?, provenance)."""
    key = "device_t" if all(np.isfinite(p["device_t"]).all() for p in per.values()) else "t"
    use_vqf, why = _vqf_usable(store, session_id, per, key, cal_data)
    if fusion == "vqf" and not use_vqf:
        raise RigConfigError(f"session {session_id}: --fusion vqf: {why}")
    use_vqf = use_vqf and fusion != "device"
    prov: dict[str, Any] = {"method": "device"}
    if use_vqf:
        prov = _fuse_sensors(store, session_id, per, key)
    elif fusion == "auto":
        prov["auto"] = why
    return key, use_vqf, prov


def _vqf_usable(store, session_id: int, per: dict[str, dict], key_name: str,
                cal_data: dict) -> tuple[bool, str]:
    """Can the sensors' samples (``per``: name → samples, without raw) be fused on the
    host? (yes/no, why not); the raw readings are counted by the store, not fetched."""
    for name, s in per.items():
        n = len(s["t"])
        have = store.samples.complete_raw_count(session_id, name)
        if have < n:
            return False, (f"sensor {name!r} has no raw samples for {n - have} of {n} samples "
                           "(record with sensors.raw: true)")
        if (np.diff(s[key_name]) <= 0).any():
            return False, f"sensor {name!r}: sample times repeat (no device clock to fuse on)"
    origin = (cal_data.get("protocol") or {}).get("origin")
    if not origin or not (cal_data.get("windows_s") or {}):
        return False, ("the calibration does not say where its windows are on "
                       "the samples' clock (protocol.origin), so it cannot be re-fitted")
    return True, ""


def _fuse_sensors(store, session_id: int, per: dict[str, dict], key_name: str) -> dict:
    """Each sensor's ``q`` (in ``per``: name → samples) replaced by its VQF orientation, one
    sensor at a time (its raw readings read for it and released); returns the provenance."""
    prov: dict[str, Any] = {"method": "vqf", "library": f"vqf {version('vqf')}"}
    info: dict[str, dict] = {}
    for name, s in per.items():
        raw = store.samples.raw(session_id, name)
        with _about(session_id, f"sensor {name!r}"):
            res = fuse_vqf(s[key_name], raw)
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
    sel = _in_windows(times, cal_data, session_id)
    for name in ("static", "functional"):
        if name not in sel:
            raise RigConfigError(f"session {session_id}: the calibration has no {name} window")
    with _about(session_id, "re-fitting the calibration on the VQF orientations"):
        return ImuJointCalibration().fit(qpar[sel["static"]], qchi[sel["static"]],
                                         qpar[sel["functional"]], qchi[sel["functional"]])


def _in_windows(times: dict[str, np.ndarray], cal_data: dict, session_id: int
                ) -> dict[str, np.ndarray]:
    """Each stored calibration window (``windows_s``, on the clock its ``protocol.origin``
    names) as a mask over the samples' times in that clock (``times``: clock → times)."""
    origin = cal_data["protocol"]["origin"]
    clock = times.get(origin.get("time"))
    if clock is None:
        raise RigConfigError(f"session {session_id}: the calibration's windows are on the "
                             f"{origin.get('time')} clock, which the pairing did not keep")
    t0 = float(origin["t0"])
    sel = {}
    for name, w in (cal_data.get("windows_s") or {}).items():
        w = _window(w)
        if w is None:
            raise RigConfigError(f"session {session_id}: the calibration's {name} window is "
                                 "not a time interval")
        sel[name] = (clock >= t0 + w[0]) & (clock <= t0 + w[1])
    return sel


def _refit_limb(q: np.ndarray, times: dict[str, np.ndarray], cal_data: dict, session_id: int,
                upright_windows=()):
    """:class:`~calibration.limb_calibration.LimbImuCalibration` fitted on the four sensors'
    (fused) orientations ``q`` (N, 4, 4) inside the stored calibration's static and movement
    windows, with the protocol it stored; the session's neutral checkpoints' windows
    (``upright_windows`` (K, 2), in the clock of ``times``) are further upright standings of
    the root (its lean during the static pose taken off: the host's fusion puts every sensor
    in one world, which that needs)."""
    stored = cal_data["protocol"]
    sel = _in_windows(times, cal_data, session_id)
    with _about(session_id, "re-fitting the limb calibration on the VQF orientations"):
        try:
            protocol = LimbCalibrationProtocol(**{k: v for k, v in stored.items()
                                                  if k != "origin"})
        except (TypeError, ValueError) as err:
            raise CalibrationError(f"stored protocol: {err}") from err
        if "static" not in sel:
            raise CalibrationError("the calibration has no static window")
        t = next(iter(times.values()))
        upright = [q[(t >= a) & (t <= b)] for a, b in upright_windows]
        model = LimbImuCalibration(cal_data["limb"], cal_data["side"], protocol=protocol)
        return model.fit(q[sel["static"]], {j: q[sel[j]] for j in protocol.joints if j in sel},
                         upright=upright or None)


def _checkpoint_windows(times: dict[str, np.ndarray], checkpoints, cal_data: dict
                        ) -> tuple[np.ndarray, list[dict], list[float]]:
    """A session's neutral checkpoint windows in the pairing clock (the first of ``times``;
    each stored in the clock named by its ``time``: ``device_t`` or host ``t``, converted through
    the samples when it is another one), the unusable ones with their reason, and the anchor:
    the centre of the calibration's static window (ψ = 0 there by construction) when its
    protocol origin is in the pairing clock."""
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
    return np.asarray(windows, dtype=np.float64).reshape(-1, 2), unusable, anchors


def _heading_correction(q: np.ndarray, times: dict[str, np.ndarray], status, checkpoints,
                        cal_data: dict, session_id: int):
    """Fit and apply :class:`~calibration.heading.HeadingCorrection` on a session's joint
    orientations (windows and anchor: :func:`_checkpoint_windows`). The axis is +X whatever
    ``--limb-axis`` says: the IMU calibration's segment frames have +X along gravity in the
    neutral pose, the thorax vertical the drift turns about. Returns the corrected
    orientations and the provenance entry."""
    t = times[next(iter(times))]
    windows, unusable, anchors = _checkpoint_windows(times, checkpoints, cal_data)
    hc = HeadingCorrection((1.0, 0.0, 0.0))
    with _about(session_id, "neutral checkpoints"):
        hc.fit(t, q, windows, status=status, anchors=anchors)
    prov = {"neutral_checkpoints": len(checkpoints), **_fitted(hc, t), "anchored": bool(anchors),
            "clock": next(iter(times))}
    prov["rejected"] += unusable
    return hc.apply(t, q), prov


def _fitted(hc, t: np.ndarray) -> dict:
    """Provenance of one fitted :class:`~calibration.heading.HeadingCorrection` over the
    samples' times ``t``: checkpoints accepted, rejected (with their reason), ψ at each, the
    drift model and the uncertainty it leaves."""
    u = hc.uncertainty_deg(float(t.min()), float(t.max())) if len(t) else None
    return {"accepted": hc.accepted_count_,
            "rejected": [{"window": [a, b], "reason": r} for (a, b), r in hc.rejected_],
            "psi_deg": [round(float(x), 2) for x in hc.psi_window_deg_],
            "drift_model": dict(hc.drift_model_),
            "uncertainty_deg": None if u is None else round(u, 3)}


def _limb_heading_correction(model, q: np.ndarray, t: np.ndarray, key: str, status,
                             n_checkpoints: int, marks, session_id: int):
    """Fit and apply :class:`~calibration.heading.LimbHeadingCorrection` on a limb session's
    four sensors (N, 4, 4) at times ``t`` (clock ``key``), at the checkpoints' ``marks``
    (:func:`_checkpoint_windows`); the corrected sensors and the provenance entry (per segment
    after the root: accepted checkpoints, rejected ones with their reason, ψ per window, the
    drift model, the uncertainty left)."""
    windows, unusable, anchors = marks
    hc = LimbHeadingCorrection(model)
    with _about(session_id, "neutral checkpoints"):
        hc.fit(t, q, windows, status=status, anchors=anchors)
    per = {seg: _fitted(c, t) for seg, c in hc.sensors_.items()}
    prov = {"neutral_checkpoints": n_checkpoints, "accepted": hc.accepted_count_,
            "rejected": unusable, "anchored": bool(anchors), "clock": key,
            "relative_to": "each sensor's proximal neighbour", "segments": per}
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

