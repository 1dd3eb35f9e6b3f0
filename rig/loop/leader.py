"""The leader arm as a target source: a second servo chain, torque off, moved by a person.

A leader arm is a servo limb read instead of written (:class:`rig.devices.servo_limb.ServoLimb`:
a bus and its joints' kinematics). Each cycle :meth:`LeaderTargets.latest` does **one sync read**
of the leader's present positions (FAST SYNC READ where its servos support it), synchronously:
the loop calls it between sending the follower's read request and collecting its reply
(:mod:`rig.loop.runner`), so the leader's exchange on its own port overlaps the follower's
reply in flight. The ticks go through the leader's **own** calibration — its servos' models and
resolutions (``ticks_per_rev``), ``zero_ticks`` / ``direction``, Homing Offset / reverse frames,
its joints' kinematics (:meth:`~rig.devices.kinematics.LimbKinematics.forward`) — so a leader of
another servo model, other zeros or another number of servos per joint gives the same joint
orientations. The leader's joints are then taken **by name** in the follower limb file's order.

Mirroring (a patient's other arm)
---------------------------------
When the leader's side differs from the follower's, each joint's orientation is reflected
through the sagittal plane. Joint orientations are in the rig's segment frames (+X distal, +Y
anterior, +Z to the body's right: :mod:`calibration.joints`), the same frames for either side;
a reflection ``Z → −Z`` maps a rotation ``(w, x, y, z)`` to ``(w, −x, −y, z)``
(:func:`calibration.clinical.mirror_quaternions`, Wu et al. 2005 §2: left-side data mirrored
so that one set of definitions serves both sides). The left arm's posture and the right arm's
that mirrors it then give the same target, and mirroring twice is the identity.

Failures
--------
A failed read (a timeout, a garbled reply) or a posture with a non-finite value returns the
last good posture with its **old** time, so the target ages: with ``stale_target_s`` under two
periods (``rig enforce`` sets 1.5 periods for a leader unless ``--stale-target-ms`` is given)
the supervisor holds the follower from the cycle after the first failed read. An adapter that
went away (:class:`~rig.errors.RigConnectionError`) also sets :attr:`LeaderTargets.error`: once
the target is stale the loop ends in its safe state (``target source failed``). Every failure is
counted (:attr:`LeaderTargets.failures`).

The limit felt at the leader
----------------------------
With a spring (``open_leader(..., spring=SpringSettings(...))``, ``rig enforce
--leader-spring``) the loop hands every cycle's commanded posture back
(:meth:`LeaderTargets.feedback`, called by :class:`rig.loop.runner.EnforcementLoop` after the
follower's goal is written): the follower's joints are mapped back onto the leader's (the
inverse of the name mapping, mirrored back when mirrored; a leader joint the follower lacks
stays free) and :meth:`rig.loop.leader_spring.LeaderSpring.update` pulls the leader towards
them, from the ticks the cycle's read gave. The spring is armed by :meth:`LeaderTargets.arm_spring`
(``rig enforce`` calls it just before the loop starts; :meth:`LeaderTargets.start` arms it
otherwise) and disarmed by :meth:`LeaderTargets.close` (torque off: the leader is free again).
A spring that fails (a bus error on the leader's writes) never stops the follower: it is
counted, disarmed, and said once.

Figures
-------
:meth:`LeaderTargets.telemetry_values` gives each telemetry row ``leader_ms`` (the leader read's
time, ms), ``target_age_ms`` (from the leader's sample — the cycle's start of the read that
produced the target — to the end of the cycle's sync write of the follower's goal, ms) and
``leader_read`` (1: this cycle's read gave the target; 0: it failed, the target is an older
one); :meth:`LeaderTargets.summary` the run's ``leader`` figures, its latency over the cycles
whose read came (a failed read is a stale target, counted apart, not a latency).
"""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np

from calibration.clinical import mirror_quaternions
from rig.devices.config import load_rig_config
from rig.devices.dynamixel import DynamixelBus
from rig.devices.ports import open_port, real_time_port
from rig.devices.servo_limb import ServoLimb
from rig.errors import RigConfigError, RigConnectionError, RigProtocolError, RigTimeoutError
from rig.loop.leader_spring import LeaderSpring
from rig.loop.target_source import TargetSource

__all__ = ["LEADER_COLUMNS", "LEADER_STALE_PERIODS", "LeaderTargets", "leader_mapping",
           "mirror_posture", "open_leader", "posture_to_leader"]

#: Telemetry columns a leader adds after the loop's own (:meth:`LeaderTargets.telemetry_values`).
LEADER_COLUMNS = ("leader_ms", "target_age_ms", "leader_read")

#: The follower is taken to have caught up with the leader (a start-up ramp over) once every
#: joint is within this angle of its target, degrees (the tracking figure starts there).
CAUGHT_UP_DEG = 5.0

#: ``stale_target_s`` of a run driven by a leader, in loop periods: a target one period old
#: (the first failed read) is still used; two periods old (the second) holds.
LEADER_STALE_PERIODS = 1.5

#: SDK latency (ms) of a simulated leader's bus: packet timeout 2 × 2 + 2 = 6 ms, so a lost
#: leader reply costs a little more than one 200 Hz cycle.
SIM_LEADER_LATENCY_MS = 2.0


def mirror_posture(q) -> np.ndarray:
    """A posture's joint orientations reflected through the sagittal plane (left ↔ right).

    Parameters
    ----------
    q : (..., 4) array_like, scalar-first, rig segment frames

    Returns
    -------
    (..., 4) float64 ``(w, −x, −y, z)``: its own inverse.
    """
    return mirror_quaternions(q)


def leader_mapping(follower_joints, leader_joints, *, what: str = "the leader") -> list[int]:
    """For each follower joint, the index of the leader joint of the same name.

    Raises
    ------
    RigConfigError
        A follower joint the leader does not have (one line naming both joint lists).
    """
    leader_joints = tuple(leader_joints)
    missing = [n for n in follower_joints if n not in leader_joints]
    if missing:
        raise RigConfigError(f"{what} has no joint{'s' if len(missing) > 1 else ''} "
                             f"{', '.join(missing)} (its joints: {', '.join(leader_joints)}; the "
                             f"follower's: {', '.join(follower_joints)})")
    return [leader_joints.index(n) for n in follower_joints]


def posture_to_leader(commanded, index, n_leader: int, *, mirror: bool = False) -> np.ndarray:
    """A follower-ordered posture mapped back onto the leader's joints.

    Parameters
    ----------
    commanded : (J_f, 4) array_like, scalar-first
        The follower's joints, in its order.
    index : sequence of int
        For each follower joint the leader joint of its name (:func:`leader_mapping`).
    n_leader : int
        The leader's joints.
    mirror : bool
        Reflect back (:func:`mirror_posture`: its own inverse).

    Returns
    -------
    (n_leader, 4) float64
        Leader-ordered; a leader joint no follower joint maps to is NaN (left free).
    """
    out = np.full((n_leader, 4), np.nan)
    out[list(index)] = np.asarray(commanded, dtype=np.float64).reshape(len(index), 4)
    return mirror_posture(out) if mirror else out


class LeaderTargets(TargetSource):
    """Targets read from a leader arm, one synchronous sync read per cycle.

    Parameters
    ----------
    limb : rig.devices.servo_limb.ServoLimb
        The leader: its bus opened (torque is turned off here) and its joints' kinematics.
        Closed by :meth:`close`.
    joint_names : sequence of str
        The follower's joints, in its limb file's order; each must be a leader joint's name.
    mirror : bool
        Reflect every joint left ↔ right (:func:`mirror_posture`): the leader is the other side.
    port : rig.devices.ports.Port, optional
        The leader's port, closed after the bus by :meth:`close`.
    description : str
    spring : rig.loop.leader_spring.LeaderSpring, optional
        The limit felt at the leader (module docstring); None: the leader stays free.
    log : callable, optional
        ``log(line)``: the one line said when the spring fails.

    Attributes
    ----------
    reads, failures : int
        Reads attempted; failed or dropped (timeout, garbled, adapter gone, non-finite).
    spring_armed : bool
        The spring was armed for the run.
    spring_failures : int
        Spring updates or arming that failed (the spring is then disarmed).
    error : BaseException or None
        Set when the leader's adapter went away (the loop then ends in its safe state once the
        target is stale).
    """

    def __init__(self, limb, joint_names, *, mirror: bool = False, port=None,
                 description: str = "leader", spring=None, log=None):
        self.limb = limb
        self.bus = limb.bus
        self.port = port
        names = tuple(limb.kinematics.names)
        self.joint_names = tuple(joint_names)
        self.n_joints = len(self.joint_names)
        self._index = leader_mapping(self.joint_names, names)
        self.mirror = bool(mirror)
        kin = limb.kinematics.compile()
        self._fk = [(kin.joints[i], kin.slices[i]) for i in self._index]
        self._fk_all = list(zip(kin.joints, kin.slices, strict=True))
        self.n_leader = len(names)
        self.description = description
        self.reads = 0
        self.failures = 0
        self.error: BaseException | None = None
        self.t0 = 0.0
        self._last: np.ndarray | None = None
        self._last_t: float | None = None
        self._leader_ms = math.nan
        self._read_ok = False  # this cycle's read gave the target
        self.spring = spring
        self.log = log or (lambda line: None)
        self.spring_armed = False
        self.spring_failures = 0
        self._spring_ok = spring is not None
        self._spring_binding = 0
        self._spring_ma: list[float] = []
        self._ticks = None  # this cycle's leader ticks (None: the read failed)
        self._leader_q = None  # the leader's own posture (its joints, unmirrored)
        self.bus.set_torque(False)  # the person moves it
        self.bus.retries = 0  # one attempt a cycle: a failure ages the target instead

    def posture(self, ticks) -> np.ndarray:
        """The follower-ordered posture ``(n_joints, 4)`` of the leader's tick vector."""
        q = np.array([kj.forward_one(ticks[sl]) for kj, sl in self._fk], dtype=np.float64)
        return mirror_posture(q) if self.mirror else q

    def latest(self, t):
        c0 = time.perf_counter()
        self.reads += 1
        q = None
        self._ticks = None
        try:
            ticks = self.bus.read_ticks()
            if self.spring is not None:  # the leader's own posture, for the spring's feedback
                own = np.array([kj.forward_one(ticks[sl]) for kj, sl in self._fk_all],
                               dtype=np.float64)
                q = own[self._index]
                q = mirror_posture(q) if self.mirror else q
                self._ticks, self._leader_q = ticks, own
            else:
                q = self.posture(ticks)
        except (RigTimeoutError, RigProtocolError):
            pass
        except RigConnectionError as err:
            if self.error is None:
                self.error = err
        except Exception as err:  # a bus closed under us: the same as an adapter gone
            if self.error is None:
                self.error = err
        self._leader_ms = 1e3 * (time.perf_counter() - c0)
        if q is None or not np.isfinite(q).all():
            self.failures += 1
            self._read_ok = False
            return self._last_t, self._last
        self._last, self._last_t = q, float(t)
        self._read_ok = True
        return self._last_t, q

    # -- the spring -------------------------------------------------------------------------
    def start(self, t0: float) -> None:
        super().start(t0)
        if self.spring is not None and not self.spring_armed:
            self.arm_spring()

    def arm_spring(self) -> None:
        """Arm the spring (:meth:`~rig.loop.leader_spring.LeaderSpring.arm`); no-op without one
        or when already armed.

        Raises
        ------
        RigConfigError
            The spring's cap above a leader servo's Current Limit (before the follower moves).
        """
        if self.spring is None or self.spring_armed:
            return
        try:
            self.spring.arm()
        except RigConfigError:
            raise
        except Exception as err:
            self._spring_failed(err)
            return
        self.spring_armed = True

    def feedback(self, t: float, commanded) -> None:
        """The cycle's admitted posture (follower-ordered ``(J_f, 4)``, scalar-first: each
        joint's target brought into the limits, before the rate limits; the commanded goal where
        a joint holds) back to the leader: its spring pulls towards it (module docstring).
        Nothing without an armed spring, or when this cycle's leader read failed (the ticks
        would be stale)."""
        ticks = self._ticks
        if not self._spring_ok or ticks is None or not self.spring_armed:
            return
        spring = self.spring
        try:
            admitted = posture_to_leader(commanded, self._index, self.n_leader,
                                         mirror=self.mirror)
            current = spring.update(self._leader_q, admitted, ticks)
        except Exception as err:  # the follower goes on; the leader is let go
            self._spring_failed(err)
            return
        if spring.binding_.any():
            self._spring_binding += 1
        self._spring_ma.append(float(np.max(current)) if len(current) else 0.0)

    def _spring_failed(self, err: BaseException) -> None:
        self.spring_failures += 1
        self._spring_ok = False
        try:
            self.spring.disarm()
        except Exception:  # the bus that failed may fail again: the leader's torque off later
            pass
        self.log(f"leader spring off: {err} (the follower goes on; the leader is free)")

    def spring_summary(self) -> dict | None:
        """The run's ``leader.spring`` figures (None without a spring): ``armed``,
        ``binding_cycles`` (updates with a binding joint), ``current_ma`` ``{p95, max}`` (per
        update the largest servo current, mA), ``failures``."""
        if self.spring is None:
            return None
        ma = np.asarray(self._spring_ma, dtype=np.float64)
        return {"armed": bool(self.spring_armed), "binding_cycles": int(self._spring_binding),
                "current_ma": None if not len(ma) else {"p95": float(np.percentile(ma, 95)),
                                                        "max": float(ma.max())},
                "failures": int(self.spring_failures)}

    # -- figures --------------------------------------------------------------------------
    def telemetry_values(self, t_s: float, cycle_ms: float) -> tuple[float, float, float]:
        """``(leader_ms, target_age_ms, leader_read)`` of the cycle that started at loop time
        ``t_s`` (relative to :meth:`start`'s ``t0``) and whose work took ``cycle_ms`` up to its
        row: the target's age when the cycle's goal was written (NaN: no target yet), and
        whether this cycle's read gave it (1.0 / 0.0)."""
        st = self._last_t
        age = math.nan if st is None else 1e3 * (self.t0 + t_s - st) + cycle_ms
        return self._leader_ms, age, 1.0 if self._read_ok else 0.0

    def summary(self, table=None, oracle=None, is_valid=None) -> dict:
        """The run's ``leader`` figures.

        Parameters
        ----------
        table : dict of column → (N,) array, optional
            The run's telemetry (:meth:`rig.loop.telemetry.Telemetry.table`) with
            :data:`LEADER_COLUMNS` and the follower's target / present columns.
        oracle : models.oracle.ConstraintOracle, optional
            The enforced limits: tracking counts the cycles whose target is valid in every
            joint (admissible leader motion).
        is_valid : callable, optional
            ``is_valid(oracle, postures) -> (N,) bool``, the supervisor's judgement of targets
            (:func:`rig.loop.targets.valid_targets`); without it no tracking figure.

        Returns
        -------
        dict
            ``reads``, ``failures``, ``mirrored``, ``latency_ms`` ``{p50, p99}`` (target age at
            the goal's write, over the cycles whose read came), ``stale_cycles`` (cycles whose
            read failed: an older target, held from the second in a row), ``leader_ms``
            ``{p50, p99}``, ``tracking_deg`` ``{median, p95, cycles, from_cycle}``: per cycle
            the largest joint's angle between the target and the present orientation read at
            the cycle's start, over the cycles whose read came and whose target is admissible,
            from the first cycle the follower was within :data:`CAUGHT_UP_DEG` of the leader
            in every joint (None before it ever was).
        """
        out: dict = {"reads": int(self.reads), "failures": int(self.failures),
                     "mirrored": self.mirror, "latency_ms": None, "leader_ms": None,
                     "tracking_deg": None}
        if self.spring is not None:
            out["spring"] = self.spring_summary()
        if not table or "target_age_ms" not in table or not len(table["target_age_ms"]):
            return out

        def pct(a, p):
            a = a[np.isfinite(a)]
            return None if not len(a) else float(np.percentile(a, p))

        age = np.asarray(table["target_age_ms"], dtype=np.float64)
        lead = np.asarray(table["leader_ms"], dtype=np.float64)
        fresh = np.asarray(table.get("leader_read", np.ones_like(age)), dtype=np.float64) > 0.5
        out["latency_ms"] = {"p50": pct(age[fresh], 50), "p99": pct(age[fresh], 99)}
        out["stale_cycles"] = int((~fresh).sum())
        out["leader_ms"] = {"p50": pct(lead, 50), "p99": pct(lead, 99)}
        if oracle is None or is_valid is None:
            return out
        names = self.joint_names
        one = self.n_joints == 1 and "target_w" in table

        def posture(what):
            if one:
                return np.stack([table[f"{what}_{c}"] for c in "wxyz"], axis=-1)[:, None]
            return np.stack([np.stack([table[f"{n}_{what}_{c}"] for c in "wxyz"], axis=-1)
                             for n in names], axis=1)

        tq, pq = posture("target"), posture("present")
        ok = is_valid(oracle, tq if not one else tq[:, 0])
        with np.errstate(invalid="ignore"):
            dot = np.abs(np.einsum("nji,nji->nj", tq, pq))
            err = np.degrees(2.0 * np.arccos(np.clip(dot, 0.0, 1.0))).max(axis=1)
        # from the first cycle the follower was within CAUGHT_UP_DEG of the leader in every
        # joint: before it, a start-up ramp (a start mismatch) is not tracking
        near = np.flatnonzero(err < CAUGHT_UP_DEG)
        if len(near):
            ok[:near[0]] = False
            ok &= fresh
            if ok.any():
                out["tracking_deg"] = {"median": float(np.median(err[ok])),
                                       "p95": float(np.percentile(err[ok], 95)),
                                       "cycles": int(ok.sum()), "from_cycle": int(near[0])}
        return out

    def close(self) -> None:
        """Disarm the spring (torque off: the leader is free again), close the leader's bus and
        port (idempotent)."""
        arm, self.limb = self.limb, None
        if arm is not None and self.spring is not None and self.spring.armed:
            try:
                self.spring.disarm()
            except Exception as err:  # closing goes on; the port's close lets go too
                self.log(f"leader spring: disarming failed: {err}")
        if arm is not None:
            try:
                arm.close()
            finally:
                port, self.port = self.port, None
                if port is not None:
                    port.close()


# ---------------------------------------------------------------------------------------------
def _looks_like_port(text: str) -> bool:
    return "://" in text or text.startswith("/dev/") or (
        text.upper().startswith("COM") and text[3:].isdigit())


def open_leader(spec: str, *, names, side, rig, separate_process: bool = True,
                spring=None, log=None) -> LeaderTargets:
    """``--targets leader:RIG|PORT``: check the leader against the follower, then open it.

    ``leader:RIG`` — a rig configuration (shipped name or file) whose ``servos`` section is the
    leader (its own port, models, calibration and joints; its ``joint.side`` its side).
    ``leader:PORT`` (``/dev/...``, ``COMn``, ``sim://...``) — a twin of the follower: the
    follower's own ``servos`` section on that port.

    ``spring`` (:class:`rig.loop.leader_spring.SpringSettings`, ``enabled``; None or disabled:
    none) builds the leader's :class:`~rig.loop.leader_spring.LeaderSpring` — a leader servo
    without current control is refused here, in one line — armed when the loop starts;
    ``log`` receives its one line if it fails.

    Raises
    ------
    RigConfigError
        (one line, before anything moves) no such rig, a rig without servos, a follower joint
        the leader lacks, the leader on the follower's own port, or no driven rig for a twin.
    RigConnectionError
        The leader's servos do not answer.
    """
    body = spec[len("leader:"):].strip()
    if not body:
        raise RigConfigError(f"--targets {spec}: expected leader:RIG (a rig configuration "
                             "describing the leader's servos) or leader:PORT (a twin of the "
                             "follower on that port)")
    follower_servos = getattr(rig, "servos", None)
    follower_names, follower_side = tuple(names), side
    if _looks_like_port(body):
        if follower_servos is None:
            raise RigConfigError(f"--targets {spec}: a twin leader needs the follower's servos "
                                 "configuration (--rig with servos)")
        servos = dataclasses.replace(follower_servos, port=body)
        leader_rig = rig
        name = f"twin of {rig.name} on {body}"
    else:
        try:
            leader_rig = load_rig_config(body)
        except RigConfigError as err:
            msg = str(err)
            msg = msg[len("--rig "):] if msg.startswith("--rig ") else msg
            raise RigConfigError(f"--targets {spec}: {msg}") from None
        servos = leader_rig.servos
        if servos is None:
            raise RigConfigError(f"--targets {spec}: rig {leader_rig.name!r} has no servos to "
                                 "read a leader arm from (a leader is a servo chain: e.g. "
                                 "leader:sim-leader-arm)")
        name = f"leader {leader_rig.name}"
    if follower_servos is not None and servos.port == follower_servos.port:
        raise RigConfigError(f"--targets {spec}: the leader's port is the follower's "
                             f"({servos.port}); a leader is a second chain on its own port")
    leader_names = servos.joint_names if servos.joints else (leader_rig.joint.name,)
    leader_mapping(follower_names, leader_names,
                   what=f"--targets {spec}: the leader ({name})")
    leader_side = leader_rig.joint.side
    mirror = bool(follower_side and leader_side and leader_side != follower_side)
    url, note = real_time_port(servos.port)  # the leader read in the loop's time too
    if note and log is not None:
        log(f"note: {note}")
    port = open_port(url, baud=servos.baud, separate_process=separate_process)
    arm = None
    try:
        kin = servos.limb_kinematics(None if servos.joints else leader_rig.joint.name)
        arm = ServoLimb(DynamixelBus(port, servos, latency_ms=servos.latency_ms), kin)
        latency = servos.latency_ms
        if latency is None and port.is_simulated:
            latency = SIM_LEADER_LATENCY_MS
        if latency is not None:  # the cycle's packet timeout, after the open's generous one
            arm.bus.set_latency(latency)
        feel = None
        if spring is not None and spring.enabled:
            try:
                feel = LeaderSpring(arm.bus, kin, spring)
            except RigConfigError as err:
                raise RigConfigError(f"--targets {spec}: {err}") from None
        desc = (f"{name} ({len(arm.bus.ids)} servos"
                + (f", mirrored {leader_side} → {follower_side}" if mirror else "")
                + (f", spring {spring.gain_ma_per_deg:g} mA/°, max {spring.max_current_ma:g} "
                   f"mA" if feel is not None else "") + ")")
        return LeaderTargets(arm, follower_names, mirror=mirror, port=port, description=desc,
                             spring=feel, log=log)
    except BaseException:
        if arm is not None:
            arm.close()
        port.close()
        raise
