"""The live enforcement loop: target → model → supervisor → IK → one sync write, at a fixed rate.

One cycle (``k``, due at ``t₀ + k/rate``, :class:`rig.loop.scheduler.Scheduler`)::

    sync read request sent (fast sync read where supported; the reply is on its way)
    latest target (source.latest(t)) → supervisor.admit (NaN / zero / stale → hold)
    model correction (onnxruntime, one session, single-sample path) → supervisor.step
    IK (nearest the previous goal) → goal ticks → FK → supervisor.accept (final exact check)
    the read's reply collected → present ticks → FK → present orientation
    [faults: timeout / garbled → retry while the cycle budget allows; adapter gone → safe state;
     hardware alert on any servo → safe state; a servo not holding the goal written the cycle
     before → safe state; servo data older than the watchdog → safe state]
    one sync write of the goal ticks (none when a fault sends the limb to the safe state)
    source.feedback(t, aimed) when the source has one (a leader's spring: rig.loop.leader;
    aimed: each joint's target brought into the limits, before the rate limits)
    telemetry row (preallocated chunk; written by another thread)

The goal needs the target and the last goal, not the present position, so it is computed while
the read's reply travels (:meth:`~rig.devices.bus.ServoBus.begin_read` sends the request,
:meth:`~rig.devices.bus.ServoBus.finish_read` collects the reply): the compute hides in the
bus's wait (the wire, the adapter's latency timer) instead of adding to it, and the cycle's
telemetry still pairs the target with the limb's state at the cycle's start. ``read_ms`` is the
time the loop spent in the read's calls (the request, what was left of the wait after the
compute, retries), ``compute_ms`` the compute's. A goal computed in a cycle that ends in the
safe state is never sent (its telemetry row shows the last command sent). Latency columns are
measured with ``time.perf_counter`` (real work time) whatever the loop clock is; the loop clock
(monotonic, or a :class:`~rig.sim.clock.ManualClock` in tests) drives deadlines, staleness and
``t_s``. While it runs, the objects alive at start are frozen out of the cyclic garbage
collector (``gc.freeze``), so a collection during a cycle has little to scan.

Safe state (``safe_state="hold"``, the default, or ``"torque-off"``)
--------------------------------------------------------------------
Entered at once on: the adapter going away, a hardware alert on any servo of the limb, a servo
that does not hold the goal written the cycle before (``GOAL_NOT_HELD``: on a bus that reads
the goals back, :attr:`~rig.devices.bus.ServoBus.held_goals` — its Bus Watchdog fired and it
refuses goals, it refused or clamped the goal, another servo answers for its ID), servo
data older than ``stale_present_s`` (reads failing beyond the retries), a failed write, a
stop request (SIGINT / SIGTERM), a target source whose device vanished (after its target went
stale: the goal already holds). ``hold`` writes Goal Position = Present Position, within the
servos' position limits (torque stays on: an arm without brakes would fall); ``torque-off``
disables torque. If the bus itself is gone nothing can be written: the servos' Bus Watchdog
(armed at start, ``watchdog_ms``) stops them. The run then ends; the summary says why. A
normal end (duration reached) leaves the limb holding its last goal with the watchdog armed.
"""

from __future__ import annotations

import copy
import gc
import math
import sys
import time
from collections import Counter
from dataclasses import dataclass, field

import numpy as np

from rig.devices.bus import ServoBus
from rig.devices.config import ServosConfig
from rig.devices.dynamixel import DynamixelBus
from rig.devices.servo_limb import ServoLimb
from rig.errors import (
    RigConfigError,
    RigConnectionError,
    RigError,
    RigProtocolError,
    RigTimeoutError,
    UnreachableError,
)
from rig.loop.backstop import (
    describe_limits,
    position_limits_from_boundary,
    position_limits_from_limb,
)
from rig.loop.limb_supervisor import LimbSupervisor
from rig.loop.scheduler import Scheduler
from rig.loop.supervisor import SAFETY_FLAGS, Intervention, SupervisorConfig
from rig.loop.targets import TargetSource
from rig.loop.telemetry import (
    Fault,
    Telemetry,
    intervention_counts,
    rate_limited_count,
    summarise,
    telemetry_columns,
)

__all__ = ["AT_END", "SAFE_STATES", "START_MISMATCH", "EnforcementLoop", "HoldTargets",
           "LoopConfig", "prepare_servo_limb"]

SAFE_STATES = ("hold", "torque-off")

GOAL_HISTORY = 40
"""A servo's goal read back may be any of the last this many written: a reply that comes late
(a loaded host, a stalled simulator, a retried read) answers a request sent writes earlier — a
fresh-clone run saw a 55 ms stall bring back a goal more than 4 writes old (0.2 s at 200 Hz). A
servo that refuses goals holds a value that leaves this window once the goal moves on."""
GOAL_NOT_HELD_CYCLES = 2
"""Reads in a row holding none of them before :attr:`Fault.GOAL_NOT_HELD`."""
_NO_SWITCH = object()  # EnforcementLoop._next_targets: no hand-over pending
#: What a start-up mismatch beyond ``start_mismatch_deg`` does (:class:`LoopConfig`).
START_MISMATCH = ("ramp", "refuse")
#: What a normal end of the run does (:class:`LoopConfig`).
AT_END = ("hold", "rest")
_NAN4 = (math.nan, math.nan, math.nan, math.nan)


@dataclass
class LoopConfig:
    """Settings of one run.

    Attributes
    ----------
    rate_hz : float
        Cycle rate (default 200 Hz).
    duration_s : float or None
        Stop after this long (loop time); None runs until stopped or the target source ends.
    safe_state : {"hold", "torque-off"}
    read_attempts : int
        Sync-read attempts per cycle (retries only while the next deadline is not threatened).
    supervisor : SupervisorConfig
    watchdog_ms : int or None
        Bus Watchdog to arm (None: the rig configuration's; 0: off).
    settle_s : float
        When the target source has a natural end and no duration is given, run this long past
        it (the limb reaches the last target).
    switch_interval_s : float
        Python's thread switch interval while the loop runs (``sys.setswitchinterval``; the
        default 5 ms would let another thread hold the interpreter for a whole cycle).
    busy_wait : bool
        Spin between cycles instead of sleeping. The loop then keeps a whole core; in exchange
        no context switch precedes the cycle's compute, which runs as fast as it does alone
        (after a sleep the CPU's caches, TLB and branch predictors are cold: the same work takes
        2-3 times as long). For a core of its own (``--cpu N``).
    joint_supervisors : mapping of joint name → SupervisorConfig, optional
        Per-joint tolerance and rate limits of a limb (the others: ``supervisor``).
    servo_max_velocity_deg_s : float or None
        Per-servo velocity limit: a goal's step of any servo beyond ``limit × period`` is cut to
        it (every servo of the limb, in ticks), and the cut ticks' posture goes through the
        final check as any goal does (flag ``RATE_LIMITED`` on the joint). None: off.
    start_mismatch_deg : float
        The start-up check: the first admitted target further than this from the limb's
        present posture in any joint (angle between the two orientations, degrees) is a
        mismatch (a leader far from the follower).
    on_start_mismatch : {"ramp", "refuse"}
        ``ramp`` (default): one line is logged and the goal moves from the present posture to
        the first admissible goal under the rate limits, as it always does; ``refuse``: the run
        ends before any goal moves (:class:`~rig.errors.RigConfigError`, one line; torque is
        on, holding the present posture).
    at_end : {"hold", "rest"}
        A normal end (duration reached, the target source's end, ``max_cycles``): ``hold``
        (default) leaves the limb holding its last goal; ``rest`` first slides it to the rest
        pose (``rest_ticks``) under the rate limits and the supervisor (the nearest admissible
        posture to it), then ends. A fault or a stop request is the safe state, never this.
    rest_ticks : sequence of int, optional
        The rest pose as goal ticks, tick-vector order (default: each servo's ``zero_ticks``,
        the joints' zero pose).
    warm_up : bool
        Shortly before each deadline, run the cycle's compute once on the last cycle's
        target with throw-away copies (the supervisor's, nothing sent, nothing recorded), so
        the real compute finds the CPU's caches and branch predictors warm (see
        :meth:`EnforcementLoop._warm`). It costs that compute again in CPU time per cycle.
    """

    rate_hz: float = 200.0
    duration_s: float | None = None
    safe_state: str = "hold"
    read_attempts: int = 3
    supervisor: SupervisorConfig = field(default_factory=SupervisorConfig)
    watchdog_ms: int | None = None
    settle_s: float = 0.5
    switch_interval_s: float = 0.0005
    busy_wait: bool = False
    warm_up: bool = True
    joint_supervisors: dict | None = None
    servo_max_velocity_deg_s: float | None = None
    start_mismatch_deg: float = 20.0
    on_start_mismatch: str = "ramp"
    at_end: str = "hold"
    rest_ticks: tuple | None = None

    def __post_init__(self):
        if not (isinstance(self.rate_hz, (int, float)) and math.isfinite(self.rate_hz)
                and 0 < self.rate_hz <= 5000):
            raise ValueError(f"--rate: expected 0 < Hz <= 5000, got {self.rate_hz!r}")
        if self.duration_s is not None and not (math.isfinite(self.duration_s)
                                                and self.duration_s > 0):
            raise ValueError(f"--duration: expected a positive number of seconds, got "
                             f"{self.duration_s!r}")
        if self.safe_state not in SAFE_STATES:
            raise ValueError(f"--safe-state: expected one of {', '.join(SAFE_STATES)}, got "
                             f"{self.safe_state!r}")
        if self.read_attempts < 1:
            raise ValueError("read_attempts must be >= 1")
        v = self.servo_max_velocity_deg_s
        if v is not None and not (math.isfinite(v) and v > 0):
            raise ValueError(f"servo_max_velocity_deg_s: expected a positive number, got {v!r}")
        m = self.start_mismatch_deg
        if not (isinstance(m, (int, float)) and math.isfinite(m) and 0 < m <= 180):
            raise ValueError(f"--start-mismatch-deg: expected 0 < degrees <= 180, got {m!r}")
        if self.on_start_mismatch not in START_MISMATCH:
            raise ValueError(f"--on-start-mismatch: expected one of {', '.join(START_MISMATCH)}"
                             f", got {self.on_start_mismatch!r}")
        if self.at_end not in AT_END:
            raise ValueError(f"--at-end: expected one of {', '.join(AT_END)}, got "
                             f"{self.at_end!r}")


class HoldTargets(TargetSource):
    """A target source that holds one posture (fresh at every cycle): the loop's hand-over to
    "hold" (:meth:`EnforcementLoop.set_targets` with None) and its slide to the rest pose.

    Parameters
    ----------
    posture : (J, 4) array-like
        Joint orientations, scalar-first, the limb file's order.
    description : str
    """

    def __init__(self, posture, description: str = "hold"):
        p = np.asarray(posture, dtype=np.float64).reshape(-1, 4)
        self.posture = p
        self.n_joints = len(p)
        self.description = description

    def latest(self, t: float):
        return t, self.posture


class EnforcementLoop:
    """Runs the cycle against a servo limb of J joints (see the module docstring); a single
    joint is the same loop with one joint.

    Parameters
    ----------
    limb : rig.devices.servo_limb.ServoLimb
        Opened; its joints those of the enforced limb, in the limb file's order (one joint:
        the enforced constraint's). Its bus
        (:class:`~rig.devices.bus.ServoBus`: ``read_ticks``, ``write_goal_ticks``,
        ``set_torque``, ``alert_pending`` / ``poll_alerts``, ``arm_watchdog``) and its joint's
        kinematics; its ``backstop`` is reported.
    model : models.onnx_io.CorrectionModel or None
        The learned correction (None: targets go to the supervisor uncorrected); a limb's
        (``correct_one`` of a posture ``(J, 4)``) for J > 1.
    oracle : models.oracle.ConstraintOracle
        The enforced constraint (one joint) or limb (J joints, hierarchical:
        :class:`rig.loop.limb_supervisor.LimbSupervisor`).
    targets : rig.loop.targets.TargetSource
    config : LoopConfig
    clock, sleep : callables
        Loop clock (default ``time.monotonic`` / ``time.sleep``; tests pass a
        :class:`rig.sim.clock.ManualClock` ``clk`` as ``clock=clk, sleep=clk.sleep``).
    telemetry : Telemetry, optional
        Default: in memory only (``keep=True``).
    on_cycle : callable(loop, k), optional
        Called at the start of every cycle (fault injection in tests and benchmarks).
    log : callable(str), optional
        One-line messages (start-up, safe state).

    Attributes
    ----------
    summary : dict
        After :meth:`run`.
    """

    def __init__(self, limb: ServoLimb, model, oracle, targets,
                 config: LoopConfig | None = None, *, clock=time.monotonic, sleep=time.sleep,
                 telemetry: Telemetry | None = None, on_cycle=None, log=None):
        n_oracle = getattr(oracle, "n_joints", 1)
        if n_oracle != len(limb.kinematics):
            raise ValueError(f"the enforced limits have {n_oracle} joint(s); the servo limb has "
                             f"{len(limb.kinematics)}")
        self.limb = limb
        self.n_joints = len(limb.kinematics)
        self.joint_names = tuple(limb.kinematics.names)
        self.bus = limb.bus
        self.model = model
        self.oracle = oracle
        self.targets = targets
        self.config = config or LoopConfig()
        self.clock = clock
        manual = clock is not time.monotonic
        self._manual = manual
        spin = 1.0 / self.config.rate_hz if self.config.busy_wait else 0.0003
        self.scheduler = Scheduler(self.config.rate_hz, clock=clock, sleep=sleep,
                                   spin_s=0.0 if manual else spin)
        self.log = log or (lambda msg: None)
        # the per-cycle kernels (the oracle's query, IK, FK) compiled or loaded from numba's
        # cache now, not inside a cycle; a machine's first run compiles them (seconds)
        t_compile = time.perf_counter()
        self.supervisor = LimbSupervisor(oracle, self.config.supervisor,
                                         period_s=self.scheduler.period,
                                         joint_configs=self.config.joint_supervisors,
                                         names=self.joint_names)
        self.kin = limb.kinematics.compile()
        self.kins = self.kin.joints
        self.slices = self.kin.slices
        v = self.config.servo_max_velocity_deg_s
        # per servo, in its own ticks (an AX's 1228.8 a turn, an X's 4096: the same angle)
        self._max_step = None if v is None else np.array(
            [max(1, int(math.radians(v) * self.scheduler.period / r))
             for r in self.kin.rad_per_tick.tolist()], dtype=np.int64)
        t_compile = time.perf_counter() - t_compile
        if t_compile > 1.0:
            self.log(f"note: compiled the loop's kernels in {t_compile:.1f} s (numba; kept in "
                     f"its cache for the next runs)")
        columns = telemetry_columns(self.joint_names)
        self.telemetry = telemetry if telemetry is not None else Telemetry(keep=True,
                                                                           columns=columns)
        if self.telemetry.columns[:len(columns)] != columns:  # a source's extras follow
            raise ValueError("the telemetry's columns are not this limb's (Telemetry(..., "
                             "columns=telemetry_columns(joint names)))")
        self.on_cycle = on_cycle
        self.stop_reason: str | None = None
        self.safe = False
        self.safe_state_entries = 0
        self.safe_state_reason: str | None = None
        self.safe_state_note: str | None = None
        self.safe_state_cycle: int | None = None
        self.end_reason = ""
        self.watchdog_ms = 0
        self.limits: tuple[np.ndarray, np.ndarray] | None = limb.backstop
        self.fault_counts: Counter = Counter()
        self.intervention_bits: Counter = Counter()
        self.max_violation = 0.0
        self.joint_max_violation = [0.0] * self.n_joints
        self.joint_intervention_bits: list[Counter] = [Counter() for _ in range(self.n_joints)]
        self.warm_ups = 0
        self._warm_input = None  # the last usable target (the warm-up's input), per run
        self._warm_s = 0.0  # a running estimate of how long a warm-up takes, s
        self.summary: dict = {}
        self._setup_done = False
        # the goal ticks of the last GOAL_HISTORY writes that went out, newest last
        self._sent_ring = np.zeros((GOAL_HISTORY, 0), dtype=np.int64)  # a ring, one row a write
        self._sent_n = 0  # rows of it filled
        self._sent_i = 0  # the row the next write goes to
        self._not_held = np.zeros(0, dtype=np.int64)  # reads in a row holding none of them
        self._next_targets = _NO_SWITCH  # a hand-over asked for (set_targets), not yet done
        self._next_started = False
        self.handovers = 0
        #: joint name -> degrees between the first admitted target and the present posture
        self.start_mismatch: dict[str, float] | None = None
        self._start_pending = True
        #: at_end "rest": True once the rest pose's admissible goal was reached (None: not asked)
        self.rest_reached: bool | None = None
        self.rest_error_deg: float | None = None  # largest joint angle from it at the end
        kin_all = limb.kinematics
        rt = self.config.rest_ticks
        rest = np.asarray(kin_all.zero_ticks if rt is None else rt, dtype=np.int64).reshape(-1)
        if rest.shape != (len(self.kin.ids),):
            raise RigConfigError(f"rest_ticks: expected {len(self.kin.ids)} ticks (one per "
                                 f"servo, IDs {list(self.kin.ids)}), got {rest.size}")
        self._rest_ticks = rest

    # ------------------------------------------------------------------ start-up
    def setup(self) -> None:
        """Torque on, arm the Bus Watchdog, read the start posture, start the supervisor.

        The registers (return delay, status return level, position limits from the boundary)
        are written before, by :func:`prepare_servo_limb`, with torque off.

        Raises
        ------
        RigError
            The bus does not answer, or a servo is in hardware-error shutdown
            (:class:`~rig.errors.HardwareAlertError`), before any motion.
        """
        bus = self.bus
        _patiently(lambda: bus.set_torque(True))
        wd = self.config.watchdog_ms
        if wd is None:
            wd = bus.watchdog_ms
        self.watchdog_ms = _patiently(lambda: bus.arm_watchdog(int(wd))) if wd else 0
        if wd and not self.watchdog_ms:
            self.log(f"note: the servos have no Bus Watchdog (watchdog {int(wd)} ms not armed): "
                     f"if this host stops, they hold their last goal")
        ticks = _read_retrying(bus)
        self._present_ticks = ticks
        self._goal_ticks = ticks.copy()
        self._present = [kj.forward_one(ticks[sl]) for kj, sl in zip(self.kins, self.slices,
                                                                       strict=True)]
        self._commanded = list(self._present)
        self._setup_done = True

    def set_targets(self, source, *, started: bool = False) -> None:
        """Hand the loop over to another target source, at the next cycle's start (bumpless).

        The goal is not reset: it goes on from where it is, its velocity continuous, towards the
        new source's targets under the same rate limits and checks (the jump between the two
        sources is a lag the rate limiter closes, never a step). Safe to call from another
        thread or from ``on_cycle``; the last call before a cycle wins. The loop does not close
        the old source (its owner does), and no start-up mismatch check is made on a hand-over.

        Parameters
        ----------
        source : rig.loop.targets.TargetSource or None
            The new source (the limb's joints in its order); None holds the goal where it is
            at the switch (:class:`HoldTargets`).
        started : bool
            The source is already running (its :meth:`~rig.loop.targets.TargetSource.start`
            was called); otherwise the loop calls ``start`` with the switch's loop-clock time.
        """
        if source is not None and getattr(source, "n_joints", self.n_joints) != self.n_joints:
            raise ValueError(f"set_targets: the source gives postures of {source.n_joints} "
                             f"joint(s); the limb has {self.n_joints}")
        self._next_started = bool(started)
        self._next_targets = source

    def _switch_targets(self, now: float):
        """Make the pending hand-over (at a cycle's start); returns the new source."""
        src, self._next_targets = self._next_targets, _NO_SWITCH
        if src is None:
            src = HoldTargets([s.goal for s in self.supervisor.joints], "hold (hand-over)")
            self._next_started = False
        if not self._next_started:
            src.start(now)
        self.supervisor.new_source()
        self.targets = src
        self.handovers += 1
        return src

    def _check_start(self, tq, k: int) -> None:
        """The first admitted target against the posture the goal holds (the present one):
        log a mismatch beyond ``start_mismatch_deg`` (ramp), or refuse the run (refuse)."""
        self._start_pending = False
        cfg = self.config
        angles = {n: math.degrees(2.0 * math.acos(min(1.0, abs(
            sum(a * b for a, b in zip(q, s.goal, strict=True))))))
            for n, q, s in zip(self.joint_names, tq, self.supervisor.joints, strict=True)}
        self.start_mismatch = angles
        far = {n: a for n, a in angles.items() if a > cfg.start_mismatch_deg}
        if not far:
            return
        what = ", ".join(f"{n} {a:.1f}°" for n, a in far.items())
        if cfg.on_start_mismatch == "refuse":
            self.end_reason = "refused at start-up: target too far"
            raise RigConfigError(
                f"start-up: the first target is beyond --start-mismatch-deg "
                f"{cfg.start_mismatch_deg:g} from the limb's present posture ({what}); refused "
                f"(--on-start-mismatch refuse): nothing moved, torque on holding the present "
                f"posture")
        self.log(f"start-up: the first target is beyond --start-mismatch-deg "
                 f"{cfg.start_mismatch_deg:g} from the present posture ({what}): ramping to it "
                 f"at the velocity limits (cycle {k})")

    def _start_rest(self, k: int) -> int:
        """Hand over to the rest pose (at_end "rest"); returns the last cycle allowed for the
        slide (the time the rate limits need for the longest joint, plus 1 s)."""
        ticks = np.clip(self._rest_ticks, self.kin.min_ticks, self.kin.max_ticks)
        rest = [kj.forward_one(ticks[sl]) for kj, sl in zip(self.kins, self.slices,
                                                            strict=True)]
        need = 0.0
        for s, q in zip(self.supervisor.joints, rest, strict=True):
            a = 2.0 * math.acos(min(1.0, abs(sum(x * y for x, y in zip(q, s.goal,
                                                                         strict=True)))))
            need = max(need, a / s.vmax + 2.0 * s.vmax / s.amax)
        v = self.config.servo_max_velocity_deg_s
        if v is not None:
            step = np.abs(ticks - self._goal_ticks) / np.maximum(self._max_step, 1)
            need = max(need, float(step.max()) * self.scheduler.period)
        self._next_targets = HoldTargets(rest, "rest pose")
        self._next_started = False
        self.rest_reached = False
        self.log(f"end of run: sliding to the rest pose (at most {need + 1.0:.1f} s)")
        return k + math.ceil((need + 1.0) / self.scheduler.period)

    def _end_rest(self, commanded, stopped: bool) -> None:
        rest = self.targets.posture
        self.rest_error_deg = max(math.degrees(2.0 * math.acos(min(1.0, abs(
            sum(a * b for a, b in zip(c, r, strict=True)))))) for c, r in zip(commanded, rest,
                                                                             strict=True))
        self.rest_reached = stopped
        self.end_reason = ("completed (at rest)" if stopped else
                           "completed (rest pose not reached in time: holding)")
        self.log(f"end of run: {'stopped' if stopped else 'holding'} "
                 f"{self.rest_error_deg:.2f}° from the rest pose (the nearest admissible goal "
                 f"the supervisor reached)")

    @property
    def last_sent(self) -> np.ndarray | None:
        """The goal ticks of the last sync write that went out (None before the first)."""
        if not self._sent_n:
            return None
        return self._sent_ring[(self._sent_i - 1) % GOAL_HISTORY]

    def request_stop(self, reason: str) -> None:
        """Ask the loop to enter the safe state and end (signal handlers call this)."""
        if self.stop_reason is None:
            self.stop_reason = reason

    # ------------------------------------------------------------------ safe state
    def enter_safe_state(self, reason: str, cycle: int) -> None:
        """Command the configured safe state once (see the module docstring)."""
        if self.safe:
            return
        self.safe = True
        self.safe_state_entries += 1
        self.safe_state_reason = reason
        self.safe_state_cycle = cycle
        bus = self.bus
        bus.retries = self._driver_retries  # the safe state may take its time
        try:
            if self.config.safe_state == "torque-off":
                bus.set_torque(False)
            else:
                try:
                    ticks = np.asarray(bus.read_ticks(), dtype=np.int64)
                except (RigTimeoutError, RigProtocolError):
                    ticks = self._present_ticks
                # a servo can stand a tick or two past its limits (tracking, a push); holding it
                # there would be a goal the bus refuses, so hold it at the nearest limit
                ticks = np.clip(ticks, self.kin.min_ticks, self.kin.max_ticks)
                bus.write_goal_ticks(ticks)
                self._goal_ticks = ticks
        except RigError as err:
            self.safe_state_note = (f"could not command the safe state ({err}); " + (
                f"the servos' Bus Watchdog ({self.watchdog_ms} ms) stops them"
                if self.watchdog_ms else "the servos hold their last goal (no Bus Watchdog)"))
        self.log(f"safe state ({self.config.safe_state}): {reason}"
                 + (f"; {self.safe_state_note}" if self.safe_state_note else ""))

    # ------------------------------------------------------------------ the loop
    def run(self, max_cycles: int | None = None) -> dict:
        """Run until the duration, the target source's end, a stop request or the safe state.

        Returns
        -------
        dict
            The summary (also :attr:`summary`).
        """
        if not self._setup_done:
            self.setup()
        cfg = self.config
        sched, sup, kin, bus = self.scheduler, self.supervisor, self.kin, self.bus
        model, tel, targets, clock = self.model, self.telemetry, self.targets, self.clock
        duration = cfg.duration_s
        if duration is None and getattr(targets, "duration_s", None) is not None:
            duration = targets.duration_s + cfg.settle_s
        self.end_reason = "completed"
        self._driver_retries = bus.retries
        bus.retries = 0  # the loop retries, within the cycle budget
        old_switch = sys.getswitchinterval()
        sys.setswitchinterval(min(old_switch, cfg.switch_interval_s))
        # everything alive now (numpy, onnxruntime, the SDK, ...) leaves the cyclic garbage
        # collector's view: a full collection in the middle of a cycle then has little to scan.
        # Before cycle 0's deadline is set: the collection itself takes tens of milliseconds.
        gc.collect()
        gc.freeze()
        if self.watchdog_ms:
            # armed again now, not only at setup: a servo that heard nothing since then for
            # longer than its watchdog (a first run compiling kernels, a slow start) has stopped
            # and refuses goals until its watchdog is cleared (0) and set again
            _patiently(lambda: bus.arm_watchdog(self.watchdog_ms))  # clears a fired one first
        self._t_bus = clock()
        n_servos = len(self.kin.min_ticks)  # before the first write what they hold is unknown
        self._sent_ring = np.zeros((GOAL_HISTORY, n_servos), dtype=np.int64)
        self._sent_n = self._sent_i = 0
        self._not_held = np.zeros(n_servos, dtype=np.int64)
        t0 = sched.start()
        targets.start(t0)
        sup.reset(t0, self._present)
        try:
            self._cycles(sched, sup, kin, bus, model, tel, targets, duration, max_cycles, t0)
        finally:
            gc.unfreeze()
            sys.setswitchinterval(old_switch)
            bus.retries = self._driver_retries
        t_end = clock() - t0
        self.summary = self._summary(t_end if t_end > 0 else tel.rows * sched.period)
        return self.summary

    def _cycles(self, sched, sup, kin, bus, model, tel, targets, duration, max_cycles, t0):
        cfg = self.config
        perf = time.perf_counter
        clock = self.clock
        t_present = t0
        read_attempts = cfg.read_attempts
        wd_s = 1e-3 * self.watchdog_ms  # 0: no watchdog armed
        period = sched.period
        present = self._present
        commanded = self._commanded
        fc = self.fault_counts
        ib = self.intervention_bits
        jib = self.joint_intervention_bits
        jmax = self.joint_max_violation
        subs = sup.joints
        kins, slices = self.kins, self.slices
        nj = self.n_joints
        joints = range(nj)
        one = nj == 1
        nan_posture = [_NAN4] * nj
        max_viol = 0.0
        k = -1
        warm = self._warm if cfg.warm_up else None
        self._warm_input = None
        self._warm_s = 0.0
        rest_until = None  # at_end "rest": the last cycle of the slide to the rest pose
        feedback = getattr(targets, "feedback", None)  # the commanded posture back (a leader)
        still = 0  # cycles the goal ticks have not changed (the slide's end)
        prev_ticks = None
        while True:
            if warm is not None and self._warm_input is not None:
                # the warm-up ends about when the spin before the deadline begins
                lead = 0.0 if self._manual else (
                    sched.spin_s + min(2.0 * max(self._warm_s, 2e-4), 0.5 * period))
                k, due, start = sched.wait(warm, lead)
            else:
                k, due, start = sched.wait()
            c0 = perf()
            t = start - t0
            if self.on_cycle is not None:
                self.on_cycle(self, k)
            if self._next_targets is not _NO_SWITCH:  # a hand-over, at the cycle's start
                targets = self._switch_targets(start)
                feedback = getattr(targets, "feedback", None)
            faults = 0
            # -- 1. the sync read's request: its reply travels (wire, the adapter's latency
            # timer, the servos' return delay) while the goal is computed ---------------------
            fresh = False
            lost = False
            begun = False
            gap = clock() - self._t_bus
            if wd_s and gap > wd_s:  # the servos' watchdog fired: goals are refused from now
                faults |= Fault.WATCHDOG_GAP
            cb = perf()
            try:
                bus.begin_read()
                begun = True
            except RigConnectionError:
                faults |= Fault.CONNECTION_LOST
                lost = True
            except RigTimeoutError:
                faults |= Fault.READ_TIMEOUT
            except RigProtocolError:
                faults |= Fault.READ_CORRUPT
            # -- 2. target → model → supervisor → IK (what the goal needs is at hand: the target
            # and the last goal, not this cycle's read) --------------------------------------
            c2 = perf()
            target_t, target = targets.latest(start)
            tq = sup.admit(start, target, target_t)
            if self._start_pending and tq is not None:
                self._check_start(tq, k)
            prev_commanded = commanded
            prev_d = [s.last_commanded_distance for s in subs]
            goal_ticks = self._goal_ticks
            corr = nan_posture
            if tq is not None and model is not None:
                corr = self._correct(model, tq)
                goal = sup.step(start, tq, corr)
            else:
                goal = sup.step(start, tq, None)
            try:
                gt = self._inverse(goal, goal_ticks)
                cand = [kj.forward_one(gt[sl]) for kj, sl in zip(kins, slices, strict=True)]
                self._rounded_within_rate(gt, goal_ticks, cand, commanded, goal)
                if sup.accept(cand):
                    goal_ticks = gt
                    commanded = cand
                elif not one:
                    sup.revert(commanded)
            except UnreachableError:
                sup.revert(commanded, Intervention.UNREACHABLE)
            c3 = perf()
            # -- 3. present positions: the reply, retried within the cycle budget -------------
            for attempt in range(0 if lost else read_attempts):
                try:
                    if begun:
                        begun = False
                        ticks = bus.finish_read()
                    else:
                        ticks = bus.read_ticks()
                    fresh = True
                    break
                except RigTimeoutError:
                    faults |= Fault.READ_TIMEOUT
                except RigProtocolError:
                    faults |= Fault.READ_CORRUPT
                except RigConnectionError:
                    faults |= Fault.CONNECTION_LOST
                    lost = True
                    break
                if attempt + 1 < read_attempts and clock() < due + 0.5 * period:
                    faults |= Fault.READ_RETRY
                    continue
                break
            c1 = perf()
            held_bad = -1
            if fresh:
                held = bus.held_goals
                if held is not None and self._sent_n:
                    # one of the last GOAL_HISTORY goals written: a reply that came late (a
                    # loaded host, a stalled simulator, a retried read) is read as a later
                    # request's and shows the servos writes behind — present and held alike. A
                    # servo that refuses goals holds none of them once the goal moves on,
                    # cycle after cycle: a fault when that lasts GOAL_NOT_HELD_CYCLES reads
                    diff = ~(self._sent_ring[:self._sent_n] == held).any(axis=0)
                    self._not_held = np.where(diff, self._not_held + 1, 0)
                    bad = self._not_held >= GOAL_NOT_HELD_CYCLES
                    if bad.any():
                        faults |= Fault.GOAL_NOT_HELD
                        held_bad = int(bad.argmax())
                self._t_bus = clock()
                self._present_ticks = ticks
                present = [kj.forward_one(ticks[sl]) for kj, sl in zip(kins, slices, strict=True)]
                t_present = start
            else:
                faults |= Fault.READ_FAILED
            reason = None
            if lost:
                reason = "the bus adapter went away"
            elif faults & Fault.WATCHDOG_GAP:
                reason = (f"no bus traffic for {1e3 * gap:.0f} ms, longer than the servos' Bus "
                          f"Watchdog ({self.watchdog_ms} ms): they stopped")
            elif bus.alert_pending:
                try:
                    alerts = bus.poll_alerts()
                except RigConnectionError:
                    alerts, reason = (), "the bus adapter went away"
                    faults |= Fault.CONNECTION_LOST
                except (RigTimeoutError, RigProtocolError):
                    alerts = ()
                if alerts:
                    faults |= Fault.HARDWARE_ALERT
                    a = alerts[0]
                    reason = a.message
            if reason is None and held_bad >= 0:
                sent = self.last_sent
                window = self._sent_ring[:self._sent_n, held_bad]
                reason = (f"servo ID {bus.ids[held_bad]} holds goal {int(held[held_bad])} "
                          f"ticks, none of the last {self._sent_n} written (the "
                          f"last {int(sent[held_bad])}, all within {int(window.min())}.."
                          f"{int(window.max())}; present {int(ticks[held_bad])}) for "
                          f"{GOAL_NOT_HELD_CYCLES} reads in a row (its Bus Watchdog fired, or "
                          f"it refused or clamped the goal)")
            if reason is None and sup.present_stale(start, t_present):
                faults |= Fault.STALE_PRESENT
                reason = (f"servo data stale for {1e3 * (start - t_present):.0f} ms (limit "
                          f"{1e3 * sup.config.stale_present_s:.0f} ms)")
            if reason is None and self.stop_reason is not None:
                faults |= Fault.SIGNAL
                reason = f"stop requested ({self.stop_reason})"
            if reason is None and getattr(targets, "error", None) is not None \
                    and sup.flags & Intervention.HOLD_STALE:
                faults |= Fault.TARGET_LOST
                reason = f"target source failed: {targets.error}"
            if reason is None:
                self._goal_ticks = goal_ticks
                self._warm_input = tq  # the last usable target (None after a hold)
            else:  # nothing of this cycle's goal is sent: the telemetry says what was
                commanded = prev_commanded
                for s_, d_ in zip(subs, prev_d, strict=True):
                    s_.last_commanded_distance = d_
            # -- 3. one sync write ---------------------------------------------------------
            cw = perf()
            if reason is None:
                try:
                    bus.write_goal_ticks(self._goal_ticks)
                    self._sent_ring[self._sent_i] = self._goal_ticks
                    self._sent_i = (self._sent_i + 1) % GOAL_HISTORY
                    self._sent_n = min(self._sent_n + 1, GOAL_HISTORY)
                    self._t_bus = clock()
                except RigConnectionError:
                    faults |= Fault.CONNECTION_LOST
                    reason = "the bus adapter went away"
                except RigError as err:
                    faults |= Fault.WRITE_FAILED
                    reason = f"sync write failed: {err}"
            if reason is not None:
                self.enter_safe_state(reason, k)
            c4 = perf()
            if feedback is not None and reason is None:  # after the write: the goal never waits
                # where each joint's goal is heading (its target brought into the limits), not the
                # rate-limited goal that lags a fast leader: a spring pulls only at the limit
                aimed = np.array([s_.aimed if s_.aimed is not None else commanded[j]
                                  for j, s_ in enumerate(subs)], dtype=np.float64)
                feedback(start, aimed)
            # -- 4. telemetry ---------------------------------------------------------------
            over = sched.finish()
            if over:
                faults |= Fault.OVERRUN
            if faults:
                fc[faults] += 1
            tgt = target
            if one:
                s0 = subs[0]
                d = s0.last_commanded_distance
                viol = d if d > 0.0 else 0.0
                if viol > max_viol:
                    max_viol = viol
                bits = s0.flags if reason is None else 0
                if bits:
                    ib[bits] += 1
                tg = tgt if tgt is not None else _NAN4
                if tgt is not None and not isinstance(tgt, tuple):
                    tg = np.asarray(tgt, dtype=np.float64).reshape(-1)
                cr, cm, pr = corr[0], commanded[0], present[0]
                tel.record((
                    k, t,
                    tg[0], tg[1], tg[2], tg[3],
                    cr[0], cr[1], cr[2], cr[3],
                    cm[0], cm[1], cm[2], cm[3],
                    pr[0], pr[1], pr[2], pr[3],
                    math.degrees(s0.last_correction_angle), math.degrees(viol),
                    math.degrees(d),
                    1e3 * (c1 - c3 + c2 - cb), 1e3 * (c3 - c2), 1e3 * (c4 - cw),
                    1e3 * (perf() - c0),
                    1e3 * (start - due),
                    bits, int(faults), 1 if self.safe else 0,
                ))
            else:
                tg = nan_posture if tgt is None else _posture_rows(tgt, nj)
                row = [k, t]
                limb_viol = 0.0
                limb_bits = 0
                for j in joints:
                    s_ = subs[j]
                    d = s_.last_commanded_distance
                    viol = d if d > 0.0 else 0.0
                    if viol > jmax[j]:
                        jmax[j] = viol
                    if viol > limb_viol:
                        limb_viol = viol
                    bits = s_.flags if reason is None else 0
                    if bits:
                        jib[j][bits] += 1
                        limb_bits |= bits
                    row.extend(tg[j])
                    row.extend(corr[j])
                    row.extend(commanded[j])
                    row.extend(present[j])
                    row.append(math.degrees(s_.last_correction_angle))
                    row.append(math.degrees(viol))
                    row.append(math.degrees(d))
                    row.append(bits)
                if limb_viol > max_viol:
                    max_viol = limb_viol
                if limb_bits:
                    ib[limb_bits] += 1
                row.extend((math.degrees(limb_viol),
                            1e3 * (c1 - c3 + c2 - cb), 1e3 * (c3 - c2), 1e3 * (c4 - cw),
                            1e3 * (perf() - c0), 1e3 * (start - due),
                            limb_bits, int(faults), 1 if self.safe else 0))
                tel.record(row)
            if self.safe:
                self.end_reason = "safe state: " + (self.safe_state_reason or "?")
                break
            if rest_until is not None:  # sliding to the rest pose: until the goal stops
                # stopped: the goal ticks unchanged for 5 cycles (a goal still slowing down
                # moves less than a tick in 5 cycles only within 0.01° of its end)
                still = still + 1 if np.array_equal(self._goal_ticks, prev_ticks) else 0
                prev_ticks = self._goal_ticks
                if still >= 5 or k >= rest_until:
                    self._end_rest(commanded, still >= 5)
                    break
                continue
            if (duration is not None and t + period > duration - 1e-9) or (
                    max_cycles is not None and k + 1 >= max_cycles):
                if cfg.at_end != "rest":
                    break
                rest_until = self._start_rest(k)
                prev_ticks = self._goal_ticks
        self.max_violation = max_viol
        if one:
            jmax[0] = max_viol
        self._commanded = commanded

    def _correct(self, model, tq) -> list:
        """The model's corrections of the admitted target (J tuples of 4 floats)."""
        if self.n_joints == 1:
            cv = model.correct_one(tq[0])
            return [(float(cv[0]), float(cv[1]), float(cv[2]), float(cv[3]))]
        cv = np.asarray(model.correct_one(np.array(tq)), dtype=np.float64).reshape(-1, 4)
        return [tuple(r) for r in cv.tolist()]

    def _inverse(self, goal, near, sup=None) -> np.ndarray:
        """Goal ticks of every joint (nearest the previous goal ticks), each servo's step cut to
        the per-servo velocity limit when one is set."""
        if self.n_joints == 1:
            gt = self.kins[0].inverse(goal[0], near)
        else:
            gt = np.concatenate([kj.inverse(g, near[sl]) for kj, g, sl in
                                 zip(self.kins, goal, self.slices, strict=True)])
        m = self._max_step
        if m is not None:
            step = gt - near
            if (np.abs(step) > m).any():
                gt = near + np.clip(step, -m, m)
                for j, sl in enumerate(self.slices):
                    if (np.abs(step[sl]) > m[sl]).any():
                        (sup or self.supervisor).joints[j].flags |= Intervention.RATE_LIMITED
        return gt

    def _rounded_within_rate(self, gt: np.ndarray, near: np.ndarray, cand: list,
                             commanded: list, goal) -> None:
        """Hold the rounded goal's step within each joint's velocity limit × the step's time.

        The supervisor limits the step of its (unrounded) goal; the IK rounds each servo to the
        nearest tick, from a previous goal that was rounded too, so a rate-limited step could
        come out up to a tick longer (0.615° against 0.600° at 120°/s and 200 Hz). Where it
        does, the joint's ticks become :func:`whole_ticks_within`'s, ``gt`` and ``cand`` change
        in place, the joint is flagged ``RATE_LIMITED``, and its supervisor goes on from the
        posture sent (:meth:`~rig.loop.supervisor.Supervisor.settle_on`)."""
        m = self._max_step
        for j, (kj, sl, s) in enumerate(zip(self.kins, self.slices, self.supervisor.joints,
                                            strict=True)):
            cap = s.vmax * s.dt
            if _angle_rad(cand[j], commanded[j]) <= cap:
                continue
            t, q = whole_ticks_within(kj, goal[j], near[sl], commanded[j], cap,
                                      None if m is None else m[sl])
            gt[sl] = t
            cand[j] = q
            s.settle_on(q)
            s.flags |= Intervention.RATE_LIMITED

    def _warm(self) -> None:
        """The cycle's compute on the last usable target, on a copy of the supervisor (its
        state is plain values: a shallow copy of each joint's supervisor changes nothing of the
        original), its goal through IK and FK, its result thrown away. The loop calls it
        shortly before a deadline, so that the real compute, straight after, runs on warm
        caches and branch predictors — on this project's virtual machine the compute after a
        wait took 1.3-1.6 times as long as the same work run again at once
        (``docs/loop.md``)."""
        t0 = time.perf_counter()
        now = self.clock()
        real = self.supervisor
        sup = copy.copy(real)
        sup.joints = tuple(copy.copy(s) for s in real.joints)
        angles = [v.angle for v in real.views]
        try:
            done = self._warm_compute(sup, now)
        finally:  # the views are shared: the real supervisors' coupling angles as they were
            for v, a in zip(real.views, angles, strict=True):
                v.angle = a
        if not done:
            return
        self.warm_ups += 1
        took = time.perf_counter() - t0
        # a slow estimate of how long it takes: a single slow warm-up moves it little
        self._warm_s = took if self._warm_s == 0.0 else 0.9 * self._warm_s + 0.1 * took

    def _warm_compute(self, sup, now) -> bool:
        tq = sup.admit(now, self._warm_input, now)
        if tq is None:
            return False
        corr = None
        if self.model is not None:
            corr = self._correct(self.model, tq)
        goal = sup.step(now, tq, corr)
        try:
            gt = self._inverse(goal, self._goal_ticks, sup)
            sup.accept([kj.forward_one(gt[sl]) for kj, sl in zip(self.kins, self.slices,
                                                                 strict=True)])
        except UnreachableError:
            pass
        return True

    # ------------------------------------------------------------------ summary
    def _summary(self, duration_s: float) -> dict:
        fc: Counter = Counter()
        for bits, n in self.fault_counts.items():
            for f in Fault:
                if f.value and bits & f.value:
                    fc[f.name.lower()] += n
        interventions = sum(n for bits, n in self.intervention_bits.items()
                            if bits & SAFETY_FLAGS)
        counters = {
            "overruns": self.scheduler.overruns,
            "skipped_deadlines": self.scheduler.skipped,
            "max_violation_deg": math.degrees(self.max_violation),
            "tolerance_deg": self.config.supervisor.tolerance_deg,
            "interventions": int(interventions),
            "interventions_by_kind": intervention_counts(dict(self.intervention_bits)),
            "rate_limited": rate_limited_count(dict(self.intervention_bits)),
            "faults": dict(sorted(fc.items())),
            "safe_state": self.config.safe_state,
            "safe_state_entries": self.safe_state_entries,
            "safe_state_reason": self.safe_state_reason,
            "safe_state_cycle": self.safe_state_cycle,
            "safe_state_note": self.safe_state_note,
            "end_reason": self.end_reason,
            "watchdog_ms": self.watchdog_ms,
            "backstop_ticks": (None if self.limits is None else
                               {str(i): [int(a), int(b)] for i, a, b in
                                zip(self.kin.ids, self.limits[0], self.limits[1],
                                    strict=True)}),
        }
        if self.n_joints > 1:
            counters["joints"] = self._joint_summary()
            counters["joint_names"] = list(self.joint_names)  # the limb's order (JSON sorts)
        return summarise(rate_hz=self.config.rate_hz, telemetry=self.telemetry,
                         counters=counters, duration_s=duration_s)

    def _joint_summary(self) -> dict:
        """Per-joint figures of a limb's run: tolerance, largest violation, interventions by
        kind; with the rows kept (``Telemetry(keep=True)``), the tracking of valid targets held
        still: median / p95 of the angle between each joint's target and present orientation,
        degrees, over the cycles whose target posture the exact limb oracle finds valid in
        every joint and that posture has been held unchanged long enough for the goal to get
        there (:func:`settled_rows`). A target that keeps moving is never counted: its error is
        the rate limits' lag, not how well the limb is held."""
        out: dict = {}
        table = self.telemetry.table() if self.telemetry.keep else None
        settled = None
        if table is not None and self.telemetry.rows:
            tq = np.stack([np.stack([table[f"{n}_target_{c}"] for c in "wxyz"], axis=-1)
                           for n in self.joint_names], axis=1)
            pq = np.stack([np.stack([table[f"{n}_present_{c}"] for c in "wxyz"], axis=-1)
                           for n in self.joint_names], axis=1)
            ok = np.isfinite(tq).all(axis=(1, 2))
            ok &= (np.abs(np.linalg.norm(tq, axis=-1) - 1.0) < 1e-6).all(axis=1)
            valid = np.zeros(len(tq), dtype=bool)
            if ok.any():
                valid[ok] = self.oracle.is_valid(tq[ok]).all(axis=1)
            cfgs = [s.config for s in self.supervisor.joints]
            settled = valid & settled_rows(
                table["t_s"], tq, pq,
                vmax_deg_s=np.array([c.max_velocity_deg_s for c in cfgs]),
                amax_deg_s2=np.array([c.max_accel_deg_s2 for c in cfgs]))
        for j, name in enumerate(self.joint_names):
            cfg = self.supervisor.joints[j].config
            bits = dict(self.joint_intervention_bits[j])
            fig = {
                "tolerance_deg": cfg.tolerance_deg,
                "max_violation_deg": math.degrees(self.joint_max_violation[j]),
                "interventions": int(sum(n for b, n in bits.items() if b & SAFETY_FLAGS)),
                "interventions_by_kind": intervention_counts(bits),
                "rate_limited": rate_limited_count(bits),
            }
            if settled is not None:
                err = _angles_deg(tq[:, j], pq[:, j])
                e = err[settled & np.isfinite(err)]
                fig["tracked_cycles"] = len(e)
                fig["tracking_p50_deg"] = None if not len(e) else float(np.median(e))
                fig["tracking_p95_deg"] = None if not len(e) else float(np.percentile(e, 95))
            out[name] = fig
        return out


#: Time a held target is given beyond what the rate limits need before its tracking counts, s.
SETTLE_S = 0.3


def whole_ticks_within(kj, goal, near: np.ndarray, prev, cap: float,
                       max_step: np.ndarray | None = None) -> tuple[np.ndarray, tuple]:
    """A joint's goal ticks whose orientation is within ``cap`` radians of ``prev``.

    Among the ticks either side of the unrounded IK solution of ``goal`` nearest ``near`` (each
    servo's floor or ceiling: 2ⁿ candidates), each cut to the per-servo step ``max_step`` from
    ``near`` when given and to the servo's tick limits, the one nearest ``goal`` whose angle from
    ``prev`` (what ``near`` encodes) is within ``cap``; failing any, the tick step from ``near``
    scaled down and truncated towards it until it is (each pass shortens every non-zero step: at
    worst ``near`` itself, a hold).

    Parameters
    ----------
    kj : rig.devices.kinematics.JointKinematics
    goal, prev : (4,) float
        Scalar-first orientations: the supervisor's goal, the previous goal's (``near``'s).
    near : (n,) int64
        The previous goal ticks (within the limits).
    cap : float
        The step allowed, radians (velocity limit × the step's time).
    max_step : (n,) int64, optional
        The per-servo step limit, ticks.

    Returns
    -------
    ticks : (n,) int64
    q : tuple of 4 float
        What ``ticks`` encode.
    """
    lo_t, hi_t = kj.min_ticks, kj.max_ticks
    base = np.asarray(near, dtype=np.int64)
    floor = np.floor(kj.inverse_float(goal, base)).astype(np.int64)
    n = len(floor)
    best, best_q, best_err = None, None, math.inf
    for bits in range(1 << n):
        t = floor + np.array([(bits >> i) & 1 for i in range(n)], dtype=np.int64)
        if max_step is not None:
            t = np.clip(t, base - max_step, base + max_step)
        t = np.clip(t, lo_t, hi_t)
        q = kj.forward_one(t)
        if _angle_rad(q, prev) > cap:
            continue
        err = _angle_rad(q, goal)
        if err < best_err:
            best, best_q, best_err = t, q, err
    if best is not None:
        return best, best_q
    d = np.rint(kj.inverse_float(goal, base)).astype(np.int64) - base
    if max_step is not None:
        d = np.clip(d, -max_step, max_step)
    q = kj.forward_one(np.clip(base + d, lo_t, hi_t))
    a = _angle_rad(q, prev)
    while a > cap:
        d = np.trunc(d * (cap / a)).astype(np.int64)
        q = kj.forward_one(base + d)
        a = _angle_rad(q, prev)
    return base + d, q


def _angle_rad(a, b) -> float:
    """The angle between two orientations (4 floats each, either sign), radians."""
    dot = abs(a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3])
    return 2.0 * math.acos(min(1.0, dot))


def _angles_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    dot = np.abs(np.einsum("...i,...i->...", a, b))
    return np.degrees(2.0 * np.arccos(np.clip(dot, 0.0, 1.0)))


def settled_rows(t_s: np.ndarray, target: np.ndarray, present: np.ndarray, *,
                 vmax_deg_s: np.ndarray, amax_deg_s2: np.ndarray,
                 settle_s: float = SETTLE_S) -> np.ndarray:
    """The telemetry rows whose target posture has been held unchanged long enough to be
    reached: since the row where it appeared, at least ``max_j (a_j / v_j + v_j / α_j)`` plus
    ``settle_s`` seconds, ``a_j`` the angle from joint j's present orientation to its target on
    that row and ``v_j``, ``α_j`` the joint's velocity and acceleration limits (a trapezoid's
    time, bounded above).

    Parameters
    ----------
    t_s : (N,) float
    target, present : (N, J, 4) float
    vmax_deg_s, amax_deg_s2 : (J,) float

    Returns
    -------
    (N,) bool
    """
    n = len(t_s)
    if n == 0:
        return np.zeros(0, dtype=bool)
    flat = np.nan_to_num(target.reshape(n, -1), nan=np.inf)
    new = np.ones(n, dtype=bool)
    new[1:] = (flat[1:] != flat[:-1]).any(axis=1)
    start = np.maximum.accumulate(np.where(new, np.arange(n), 0))
    jump = _angles_deg(target[start], present[start])  # (N, J)
    # fmax ignores a joint without a target; a row with none stays NaN (never settled)
    need = np.fmax.reduce(jump / vmax_deg_s + vmax_deg_s / amax_deg_s2, axis=1) + settle_s
    return (t_s - t_s[start]) >= need


def _posture_rows(target, n: int) -> list:
    """A target posture as ``n`` rows of 4 floats (NaN rows when it is not ``(n, 4)``)."""
    arr = np.asarray(target, dtype=np.float64).reshape(-1)
    if arr.size != 4 * n:
        return [_NAN4] * n
    return arr.reshape(n, 4).tolist()


def _patiently(fn, attempts: int = 5):
    """``fn()`` again after a timeout or a garbled answer (idempotent start-up steps: the
    loop's bus has cycle-sized timeouts that a loaded host can miss)."""
    for k in range(attempts):
        try:
            return fn()
        except (RigTimeoutError, RigProtocolError):
            if k + 1 == attempts:
                raise
    raise AssertionError("unreachable")


def _read_retrying(bus: ServoBus, attempts: int = 5) -> np.ndarray:
    return np.asarray(_patiently(bus.read_ticks, attempts), dtype=np.int64)


def _open_bus(port, servos, latency_ms, attempts: int = 3) -> DynamixelBus:
    """Open the bus; a servo that missed its PINGs (a loaded host) is asked again, twice."""
    for k in range(attempts):
        try:
            return DynamixelBus(port, servos, latency_ms=latency_ms)
        except RigConnectionError as err:
            if k + 1 == attempts or "did not answer" not in str(err):
                raise
    raise AssertionError("unreachable")


#: SDK latency (ms) of the loop's bus on a simulator: packet timeout 2 × 4 + 2 = 10 ms, so a
#: lost reply costs two cycles at 200 Hz, not the ~100 ms the driver allows for opening.
SIM_LOOP_LATENCY_MS = 4.0


def prepare_servo_limb(port, servos: ServosConfig, oracle=None, *, backstop: bool = True,
                       margin_deg: float = 5.0, latency_ms: float | None = None,
                       log=None) -> ServoLimb:
    """Open a rig's servos for the loop — its bus and its joints' kinematics — and write their
    start-up registers.

    1. Open :class:`rig.devices.dynamixel.DynamixelBus` on the opened ``port`` with the
       driver's own (generous) timeouts; read torque and the start posture.
    2. With ``backstop`` and torque off: the position limits of
       :func:`rig.loop.backstop.position_limits_from_boundary` (widened to contain each servo's
       zero; a limb's: :func:`~rig.loop.backstop.position_limits_from_limb`, each joint from its
       envelope — a coupled joint's limits over all its coupling angles) replace the
       configured ones, in the kinematics and on the bus;
       :meth:`~rig.devices.dynamixel.DynamixelBus.configure` writes them to the servos'
       Min/Max Position Limit registers with the other start-up registers. EEPROM is
       written only with torque off: if a servo's torque is already on (a limb holding), the
       registers are left as they are and a line is logged (the supervisor stays the primary
       limit).
    3. Set the loop's packet timeout on the open bus: ``latency_ms``, else the rig
       config's ``latency_ms``, else :data:`SIM_LOOP_LATENCY_MS` on a simulator and the
       driver's default (the adapter's detected latency timer) on hardware. The loop turns the
       driver's retries off while it runs (it retries within its cycle budget).

    Parameters
    ----------
    port : rig.devices.ports.Port
        Opened port (the caller closes it).
    servos : rig.devices.config.ServosConfig
    oracle : models.oracle.ConstraintOracle, optional
        Needed for the backstop (one joint's, or a limb's with the servos' joints).

    Returns
    -------
    ServoLimb
        The rig's joints, with ``backstop = (min_ticks, max_ticks)`` or None.
    """
    log = log or (lambda msg: None)
    if latency_ms is None:
        latency_ms = servos.latency_ms
    if latency_ms is None and port.is_simulated:
        latency_ms = SIM_LOOP_LATENCY_MS
    kinematics = servos.limb_kinematics()
    limb = ServoLimb(_open_bus(port, servos, servos.latency_ms), kinematics)
    bus = limb.bus
    limits = None
    try:
        torque_on = bool(np.asarray(bus.torque()).any())
        if torque_on:
            log("servo torque is already on: position-limit registers left as they are "
                "(turn torque off to let the loop write the boundary's backstop)")
        elif backstop and oracle is not None:
            ticks = _read_retrying(bus)
            kin = limb.kinematics
            if len(kin) == 1:  # one joint: as before, bit for bit
                kj = kin.joint(0)
                lo, hi = position_limits_from_boundary(kj, oracle, ticks, margin_deg=margin_deg)
                lo = np.minimum(lo, kj.zero_ticks)
                hi = np.maximum(hi, kj.zero_ticks)
            else:
                lo, hi = position_limits_from_limb(kin, oracle, ticks, margin_deg=margin_deg)
            limb.set_position_limits(lo, hi)
            limits = (lo, hi)
            log(f"backstop position limits: {describe_limits(kin, lo, hi)}")
        if not torque_on:
            bus.configure()
        else:  # the goal's read-back is RAM: mapped whatever the torque
            bus.map_read_back()
        if latency_ms is not None:
            bus.set_latency(latency_ms)
    except BaseException:
        limb.close()
        raise
    limb.backstop = limits
    return limb
