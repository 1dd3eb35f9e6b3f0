"""What a recording of one joint and a recording of a whole limb do their own way — the
calibration procedure — chosen once (:func:`procedure_for`) from the rig configuration's
``limb``.

A one-joint rig (:class:`JointProcedure`) follows :class:`calibration.protocol.
CalibrationProtocol` (a static neutral pose, then flexion/extension of the straight arm),
solved by :class:`calibration.alignment.ImuJointCalibration` (IMU rigs; a servo rig's zero is
checked instead), and reads its range of motion from the extracted boundary. A whole-limb rig
(:class:`LimbProcedure`: one IMU per segment) follows :class:`calibration.protocol.
LimbCalibrationProtocol` (the static pose, then each joint's flexion/extension in turn),
solved by :class:`calibration.limb_calibration.LimbImuCalibration`, and reads every joint's
range of motion. These are different algorithms, not one in two sizes: the procedure is the
one object that knows which; :mod:`rig.record.guided`, :mod:`rig.record.rigio` and
:mod:`rig.record.session` ask it and never whether the rig is a limb.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calibration.alignment import ImuJointCalibration, functional_axis, status_ok
from calibration.clinical import format_rom_table, range_of_motion
from calibration.errors import CalibrationError
from calibration.joint_angles import JOINT_ANGLES, recorded_rom
from calibration.limb_calibration import LimbImuCalibration
from calibration.protocol import CalibrationProtocol, LimbCalibrationProtocol
from models import quaternion as Q
from rig.readback import extract, joint_orientations_from_store
from rig.record.pump import SampleBatch
from rig.store.io import shared_instants

__all__ = ["NEUTRAL_WORDS", "CalibrationResult", "JointProcedure", "LimbProcedure",
           "procedure_for"]


@dataclass
class CalibrationResult:
    """What is stored (``store.calibrations.add(session, kind, data, residual_deg)``) and what
    turns raw samples into joint orientations.

    Attributes
    ----------
    kind : str
        ``"imu-alignment"`` or ``"servo-zero"``.
    data : dict
        JSON-able calibration parameters plus the protocol windows.
    residual_deg : float
        The calibration's own residual, degrees.
    model : object or None
        The fitted :class:`~calibration.alignment.ImuJointCalibration` (IMU rigs).
    """

    kind: str
    data: dict
    residual_deg: float
    model: object = None


#: The neutral pose, by the rig's ``limb`` (None: the shoulder rigs): what a limb calibration's
#: static pose and every neutral checkpoint ask for, in the same words. The calibration makes
#: the static pose each joint's zero and a checkpoint is read against that zero (a forearm
#: turned otherwise at a checkpoint than in the static pose is indistinguishable from heading
#: drift), so the two must be one pose. The arm's palm faces the thigh: the forearm's clinical
#: zero between pronation and supination (AAOS: thumb up with the elbow bent), which the
#: normative 80° / 80° are measured from (:data:`calibration.joint_angles.NORMATIVE`).
NEUTRAL_WORDS = {
    None: "arm hanging at the side, forearm forward",
    "arm": "standing straight, arm hanging at the side, palm facing the thigh, fingers down",
    "leg": "standing straight, foot flat and pointing forward",
}




class JointProcedure:
    """The calibration procedure of a one-joint rig (the shoulder rigs: a thorax and a limb
    sensor, or a servo joint): :class:`~calibration.protocol.CalibrationProtocol`."""

    #: The protocol's parameters stored with the calibration (``protocol``).
    protocol_fields = ("static_s", "functional_s", "flexion_deg", "extension_deg",
                       "period_s", "settle_s")

    def name(self, config) -> str:
        """The rig's joint or limb, for people."""
        return config.joint.name

    def default_protocol(self) -> CalibrationProtocol:
        """The protocol followed when none is given."""
        return CalibrationProtocol()

    def accepts(self, protocol) -> bool:
        """Whether ``protocol`` is one this procedure follows (not a limb's)."""
        return not isinstance(protocol, LimbCalibrationProtocol)

    def phases(self, p) -> list[tuple[float, str, str]]:
        """The movement phases after the static pose: (start, what to say, short prompt)."""
        return [(p.static_s, "now flexion/extension: raise the straight arm forwards, then "
                 f"behind, slowly ({p.functional_s:g} s)", "flexion/extension")]

    def announcement(self, p) -> str:
        """What the display says when the protocol begins."""
        return (f"calibration — 1) neutral pose: patient upright, arm hanging relaxed at the "
                f"side, forearm forward; hold still {p.static_s:g} s. 2) then raise the straight "
                f"arm forwards and lower it behind (flexion/extension) for {p.functional_s:g} s")

    def solve(self, window, protocol, config, rig_kind: str) -> CalibrationResult:
        """The calibration from the protocol's windows (``window(name)``: the samples in it):
        an IMU rig's :class:`~calibration.alignment.ImuJointCalibration`, a servo rig's zero
        check."""
        static = window("static")
        functional = window("functional")
        if rig_kind == "servo":
            return _servo_check(static, functional)
        return _solve_imu(static, functional, config.joint.parent, config.joint.child)

    def live(self, model, parent_q: np.ndarray, child_q: np.ndarray) -> np.ndarray:
        """The live joint orientations from the parent and child sensors, calibration
        applied."""
        return model.transform(parent_q, child_q)

    def live_joints(self, model, batch: SampleBatch, protocol) -> dict[str, np.ndarray]:
        """The live orientations of the rig's other joints (none: one joint)."""
        return {}

    def session_meta(self) -> dict:
        """What the session's metadata says of the rig's shape (nothing: one joint)."""
        return {}

    def range_of_motion(self, store, result, config) -> None:
        """Boundary → clinical peaks of the recorded joint, stored in the session's metadata
        (never fails the session: ``result.rom_note`` says why there is none)."""
        try:

            side = config.joint.side if config.joint.side in ("left", "right") else "right"
            data = joint_orientations_from_store(store, result.session_id)
            constraint = extract(data, side=side).constraint_
            rom = range_of_motion(constraint, side, directions=data.directions)
        except Exception as err:  # too few samples, degenerate region: say so, keep the session
            result.rom_note = f"no range of motion: {err}"
            return
        result.rom = rom.to_dict()
        result.rom_table = "\n".join([*(f"warning: {w}" for w in data.facts().warnings()),
                                      format_rom_table(rom)])
        store.sessions.end(result.session_id, status=result.status,
                           meta={"rom": result.rom, "rom_source": "extracted boundary"})


class LimbProcedure:
    """The calibration procedure of a whole-limb rig (``limb: arm|leg``, one IMU per segment):
    :class:`~calibration.protocol.LimbCalibrationProtocol`, each joint's movement in turn."""

    #: The protocol's parameters stored with the calibration (``protocol``).
    protocol_fields = ("limb", "static_s", "movement_s", "period_s", "settle_s")

    def __init__(self, limb: str) -> None:
        self.limb = limb

    def name(self, config) -> str:
        """The rig's joint or limb, for people."""
        return self.limb

    def default_protocol(self) -> LimbCalibrationProtocol:
        """The protocol followed when none is given."""
        return LimbCalibrationProtocol(self.limb)

    def accepts(self, protocol) -> bool:
        """Whether ``protocol`` is one this procedure follows (the same limb's)."""
        return isinstance(protocol, LimbCalibrationProtocol) and protocol.limb == self.limb

    def phases(self, p) -> list[tuple[float, str, str]]:
        """The movement phases after the static pose, one per joint (proximal first):
        (start, what to say, short prompt)."""
        out = []
        for i, joint in enumerate(p.joints):
            what = _LIMB_MOVEMENTS[joint]
            out.append((p.static_s + i * p.movement_s,
                        f"now the {joint}: {what}, slowly, the rest still ({p.movement_s:g} s)",
                        f"{joint} flexion/extension"))
        return out

    def announcement(self, p) -> str:
        """What the display says when the protocol begins."""
        return (f"calibration of the {self.limb} — 1) neutral pose: {NEUTRAL_WORDS[self.limb]}; "
                f"hold still {p.static_s:g} s. 2) then flex and extend each joint in turn, "
                f"{', '.join(p.joints)}, {p.movement_s:g} s each")

    def solve(self, window, protocol, config, rig_kind: str) -> CalibrationResult:
        """The :class:`~calibration.limb_calibration.LimbImuCalibration` from the static
        window and each joint's movement window (``window(name)``: the samples in it); a servo
        limb's zero check (:func:`_servo_limb_check`)."""
        static = window("static")
        movements = {j: window(j) for j in protocol.joints}
        if rig_kind == "servo":
            return _servo_limb_check(static, movements)
        return _solve_limb(static, movements, self.limb, config.joint.side, protocol)

    def live(self, model, parent_q: np.ndarray, child_q: np.ndarray) -> np.ndarray:
        """The live orientations of the limb's proximal joint (coverage, checkpoints)."""
        return _apply_limb(model, parent_q, child_q)

    def live_joints(self, model, batch: SampleBatch, protocol) -> dict[str, np.ndarray]:
        """The live orientations of every joint of the limb but the proximal one, calibration
        applied (:meth:`LimbImuCalibration.joints`), at the instants all of the limb's sensors
        have a sample in ``batch``: ``{joint: (M, 4)}``."""
        q, _ = _chain_samples(batch, protocol.segments)
        if not len(q):
            return {}
        joints = model.joints(q)
        return {j: joints[j] for j in protocol.joints[1:] if j in joints}

    def session_meta(self) -> dict:
        """What the session's metadata says of the rig's shape: the whole limb, every joint of
        which is read back from the session."""
        return {"limb": self.limb}

    def range_of_motion(self, store, result, config) -> None:
        """Every joint's clinical peaks (:func:`calibration.joint_angles.recorded_rom`; the
        shoulder's from its extracted boundary as for a shoulder session), stored in the
        session's metadata as ``rom`` = ``{joint: table}`` (never fails the session)."""
        try:
            side = config.joint.side if config.joint.side in ("left", "right") else "right"
            chain = joint_orientations_from_store(store, result.session_id)
            roms, tables = {}, []
            for k, j in enumerate(chain.joints):
                if j in JOINT_ANGLES:
                    r = recorded_rom(chain.joint_q[:, k], j, side, status=chain.status)
                    roms[j], table = r.to_json(), r.table()
                else:  # the shoulder: peaks of its boundary, as for a shoulder session
                    data = chain.select(j)
                    r = range_of_motion(extract(data, side=side).constraint_, side,
                                        directions=data.directions)
                    roms[j], table = r.to_dict(), f"{j} ({side})\n{format_rom_table(r)}"
                tables.append(table)
        except Exception as err:  # too few samples: say so, keep the session
            result.rom_note = f"no range of motion: {err}"
            return
        result.rom = roms
        result.rom_table = "\n".join([*(f"warning: {w}" for w in chain.recording.warnings()),
                                      *tables])
        store.sessions.end(result.session_id, status=result.status,
                           meta={"rom": result.rom, "rom_source": "recorded joint angles"})


def procedure_for(limb: str | None) -> JointProcedure | LimbProcedure:
    """The calibration procedure of a rig whose configuration names ``limb`` (``arm``/``leg``:
    a whole limb; None: one joint). The one place that asks whether a rig records one joint or
    a whole limb: everything that differs between the two is the procedure's."""
    return JointProcedure() if limb is None else LimbProcedure(limb)


def _pairs(b: SampleBatch, parent: str, child: str
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Parent and child orientations at the same instants (equal sample times), and whether
    both sensors' calibration status is trustworthy there (:func:`calibration.alignment.
    status_ok`: a magnetic disturbance drops it)."""

    clock = b.time()
    sp = b.name == parent
    sc = b.name == child
    _, ip, ic = np.intersect1d(clock[sp], clock[sc], assume_unique=False, return_indices=True)
    ok = status_ok(np.stack((b.status[sp][ip], b.status[sc][ic]), axis=1)) if len(ip) else \
        np.zeros(0, bool)
    return b.q[sp][ip], b.q[sc][ic], ok


def _usable(ok: np.ndarray):
    """The status mask, unless it leaves too little (then every sample, as on hardware whose
    status byte is not meaningful)."""
    return ok if ok.sum() >= max(20, len(ok) // 4) else None


def _solve_imu(static: SampleBatch, functional: SampleBatch, parent: str, child: str):

    st, sl, sok = _pairs(static, parent, child)
    ft, fl, fok = _pairs(functional, parent, child)
    cal = ImuJointCalibration().fit(st, sl, ft, fl, static_ok=_usable(sok),
                                    functional_ok=_usable(fok))
    return CalibrationResult("imu-alignment", cal.to_dict(), float(cal.residual_deg_), cal)


def _apply_imu(model, parent_q: np.ndarray, child_q: np.ndarray) -> np.ndarray:
    return model.transform(parent_q, child_q)


#: What the patient does for each joint's calibration movement: flexion first, as the protocol
#: scripts it (the ankle's flexion is dorsiflexion, toes up). A movement begun the other way is
#: still calibrated (its axis is flipped by its neighbours' and named in ``flipped_``), but only
#: through that fallback.
_LIMB_MOVEMENTS = {
    "shoulder": "raise the straight arm forwards, then back behind",
    "elbow": "bend and straighten the elbow, palm facing the body",
    "wrist": "bend the wrist towards the palm, then back the other way",
    "hip": "raise the straight leg forwards, then back behind",
    "knee": "bend and straighten the knee",
    "ankle": "pull the toes up, then point the foot down",
}


def _chain_samples(b: SampleBatch, names: tuple[str, ...]) -> tuple[np.ndarray, np.ndarray]:
    """The sensors ``names`` (proximal to distal) at the instants all of them have a sample
    (M, S, 4), and whether every sensor's status is trustworthy there (M,)."""

    clock = b.time()
    sel = [b.name == n for n in names]
    common, idx = shared_instants([clock[m] for m in sel])
    q = np.stack([b.q[m][i] for m, i in zip(sel, idx, strict=True)], axis=1)
    st = np.stack([b.status[m][i] for m, i in zip(sel, idx, strict=True)], axis=1)
    return q, status_ok(st) if len(common) else np.zeros(0, bool)


def _solve_limb(static: SampleBatch, movements: dict[str, SampleBatch], limb: str, side: str,
                protocol) -> CalibrationResult:

    segs = protocol.segments
    st, sok = _chain_samples(static, segs)
    moves = {j: _chain_samples(b, segs) for j, b in movements.items()}
    cal = LimbImuCalibration(limb, side if side in ("left", "right") else "right",
                             protocol=protocol).fit(
        st, {j: q for j, (q, _) in moves.items()}, static_ok=_usable(sok),
        functional_ok={j: ok for j, (_, ok) in moves.items() if _usable(ok) is not None})
    return CalibrationResult("imu-limb", cal.to_dict(), float(cal.residual_deg_), cal)


def _apply_limb(model, parent_q: np.ndarray, child_q: np.ndarray) -> np.ndarray:
    """The limb's proximal joint from its first two sensors (each segment is its sensor's
    orientation turned by its heading and mount alone: :meth:`LimbImuCalibration.
    segment_orientations`)."""
    seg = model.segment_orientations(np.stack([parent_q, child_q, parent_q, parent_q], axis=1))
    return Q.multiply(Q.conjugate(seg[:, 0]), seg[:, 1])


def _servo_check(static: SampleBatch, functional: SampleBatch) -> CalibrationResult:
    """Servo chain: the neutral pose must read as the identity through the forward kinematics
    (a wrong zero offset or direction shows here), the functional movement as a rotation about
    one axis. No correction is applied: the chain's zeros are the rig configuration's."""

    qs = static.q[static.kind == "joint"]
    qf = functional.q[functional.kind == "joint"]
    if not len(qs):
        raise CalibrationError("no joint samples arrived during the static pose: the chain's "
                               "zeros cannot be checked")
    zero = np.degrees(Q.angle(qs))
    static_rms = float(np.sqrt(np.mean(zero**2)))
    data = {"kind": "servo-chain-check", "static_rms_deg": static_rms,
            "static_max_deg": float(np.max(zero))}
    residual = static_rms
    if len(qf) >= 2:
        axis, off_axis, flex_range = functional_axis(qf)
        data.update({"functional_axis": [float(v) for v in axis],
                     "functional_deg": float(off_axis), "functional_range_deg": float(flex_range)})
        residual = max(residual, float(off_axis))
    return CalibrationResult("servo-zero", data, residual, None)




def _servo_limb_check(static: SampleBatch, movements: dict[str, SampleBatch]
                      ) -> CalibrationResult:
    """Servo limb: :func:`_servo_check` of every joint — its samples in the static pose and in
    its own movement window (joint samples are named by their joint). No correction is
    applied: the limb's zeros are the rig configuration's."""
    data: dict = {"kind": "servo-limb-check", "joints": {}}
    residual = 0.0
    for joint, moving in movements.items():
        one = _servo_check(static.select(static.name == joint),
                           moving.select(moving.name == joint))
        data["joints"][joint] = one.data
        residual = max(residual, one.residual_deg)
    return CalibrationResult("servo-zero", data, residual, None)
