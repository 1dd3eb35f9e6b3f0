"""The safety supervisor: the last word on every goal the live loop sends to the limb.

Pure (no I/O, no clock of its own: the caller passes the loop time), deterministic, one
orientation per call, built on the exact oracle's single-orientation path
(:meth:`models.oracle.ConstraintOracle.evaluate`). Orientations are scalar-first ``(w, x, y,
z)`` joint orientations (limb relative to parent); the oracle's signed distance ``D(q)`` is the
angle of the exact correction (> 0 outside the constraint, ≤ 0 inside, radians).

One cycle
---------
``admit(t, target, target_t)`` → ``step(t, target, correction)`` → (caller: IK, FK of the goal
ticks) → ``accept(commanded)``:

1. **Admit the target.** Non-finite, zero or non-unit (``| |q| − 1 | > norm_tolerance``)
   targets, no target yet, and targets older than ``stale_target_s`` are not used: the goal
   **holds** (the last safe goal, goal velocity set to zero). Flags ``HOLD_INVALID`` /
   ``HOLD_STALE``.
2. **Candidate** ``c = correction ⊗ target`` (the learned model's output); a non-finite or
   non-unit correction is ignored (``c = target``, flag ``MODEL_INVALID``).
3. **Exact check of the candidate.** ``D(c) > τ − δ`` (``τ`` = ``tolerance_deg``, ``δ`` =
   ``quantum_deg``, the room kept for rounding the goal to encoder ticks): ``c`` is replaced by
   the exact projection (flag ``PROJECTED``).
4. **Rate limits.** From the previous goal ``g₀`` with goal angular velocity ``ω₀`` (parent
   frame, rad/s) towards ``c``: the candidate's own velocity ``v_c = log(c ⊗ c₋₁⁻¹)/Δt`` is fed
   forward (0 after a hold, or when it jumped faster than ``ω_max``); the lag
   ``e = log(c ⊗ g₀⁻¹) − v_c Δt`` is closed at speed ``s = min(ω_max, |e|/Δt, √(2 α_max |e|))``
   (the last term brakes in time); desired ``ω_d = v_c + s ê`` with ``|ω_d| ≤ ω_max``;
   ``ω₁ = ω₀ + clip(ω_d − ω₀, α_max Δt)``, ``|ω₁| ≤ ω_max``, ``g₁ = exp(ω₁ Δt) ⊗ g₀`` (flag
   ``RATE_LIMITED`` when ``g₁ ≠ c``). A path slower than the limits is therefore followed
   without lag; when a moving target stops, the goal overshoots by at most ``|ω|²/(2 α_max)``
   (caught by step 5 if that leaves the region).
5. **Exact check of the rate-limited goal** (a straight path between two valid orientations
   can leave a concave region): ``D(g₁) > τ − δ`` → ``g₁`` ← its exact projection (flag
   ``REPROJECTED``). Safety beats smoothness here: the projection moves the goal by at most
   ``D(g₁)``, which is at most one rate-limited step.
6. **Guard on what is actually sent** (``accept``): the caller rounds ``g₁`` to ticks and
   passes the orientation those ticks encode (forward kinematics); it is sent only if
   ``D(commanded) ≤ max(τ, C)`` (``C`` the ceiling below); otherwise the caller keeps the
   previous goal ticks (flag ``GUARD_HOLD``; never seen in the tests: ``δ`` covers rounding).

Bringing a limb back (the monotone rule)
----------------------------------------
A limb may start outside (or be found outside after a safe state). The supervisor keeps a
**ceiling** ``C ≥ 0``: at :meth:`reset` ``C = max(0, D(present))``; every accepted command
lowers it, ``C ← min(C, max(0, D(commanded)))``; it never rises. A command more than ``τ``
outside is sent only if ``D(commanded) ≤ C``, i.e. **no command is ever further outside than
any command before it (or than the limb was at start)**. While the internal goal is outside by
more than ``τ − δ`` (*recovery*), the supervisor ignores the target and steers the goal, under
the same rate limits, towards the exact projection of the goal itself — the shortest way back,
along which ``D`` falls by the step each cycle; a step that does not lower ``D`` is halved
(three times at most) or the goal holds. Once within ``τ − δ`` the target is tracked again.
Motion that reduces a violation is therefore always allowed, and motion that increases one
never is.

Watchdogs
---------
:meth:`present_stale` — the servos' data are older than ``stale_present_s`` (the caller enters
its safe state); stale targets are step 1.

Flags are :class:`Intervention` bits; :attr:`Supervisor.flags` holds the last cycle's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import IntFlag

from models import qscalar as qs

__all__ = ["SAFETY_FLAGS", "Intervention", "Supervisor", "SupervisorConfig"]


class Intervention(IntFlag):
    """What the supervisor did to a cycle's goal (bits, combined with ``|``)."""

    NONE = 0
    PROJECTED = 1        #: candidate beyond τ − δ → exact projection
    HOLD_INVALID = 2     #: NaN / zero / non-unit target → last safe goal
    HOLD_STALE = 4       #: no target, or older than stale_target_s → last safe goal
    RATE_LIMITED = 8     #: velocity / acceleration limit shaped the goal
    REPROJECTED = 16     #: rate-limited goal left the region → exact projection
    RECOVERY = 32        #: goal outside, steered back under the monotone rule
    MODEL_INVALID = 64   #: the model's correction was non-finite or non-unit → ignored
    UNREACHABLE = 128    #: IK found no solution within the tick limits → previous goal ticks
    GUARD_HOLD = 256     #: the ticks' orientation failed the final check → previous goal ticks
    HELD_FOR_COUPLED = 512  #: a limb's source joint held still while a joint coupled to it recovers


#: Flags that mean "the supervisor changed what would have been sent" (counted as interventions).
SAFETY_FLAGS = int(Intervention.PROJECTED | Intervention.HOLD_INVALID | Intervention.HOLD_STALE
                   | Intervention.REPROJECTED | Intervention.RECOVERY
                   | Intervention.MODEL_INVALID | Intervention.UNREACHABLE
                   | Intervention.GUARD_HOLD | Intervention.HELD_FOR_COUPLED)


@dataclass(frozen=True)
class SupervisorConfig:
    """Limits of the supervisor (degrees and seconds).

    Attributes
    ----------
    tolerance_deg : float
        No command is sent more than this far outside the boundary (except while bringing a
        limb back under the monotone rule).
    quantum_deg : float
        Room kept for rounding a goal to encoder ticks: goals beyond ``tolerance − quantum`` are
        projected. Three joints at 4096 ticks/rev round by ≤ 3 × 0.044° = 0.13°.
    max_velocity_deg_s, max_accel_deg_s2 : float
        Limits on the goal's angular velocity and acceleration (parent frame).
    stale_target_s : float
        A target older than this holds the last safe goal.
    stale_present_s : float
        Servo data older than this is a fault (see :meth:`Supervisor.present_stale`).
    norm_tolerance : float
        A target or correction whose norm differs from 1 by more than this is refused.
    """

    tolerance_deg: float = 1.0
    quantum_deg: float = 0.25
    max_velocity_deg_s: float = 120.0
    max_accel_deg_s2: float = 1200.0
    stale_target_s: float = 0.1
    stale_present_s: float = 0.1
    norm_tolerance: float = 0.02

    def __post_init__(self):
        for name in ("tolerance_deg", "max_velocity_deg_s", "max_accel_deg_s2",
                     "stale_target_s", "stale_present_s", "norm_tolerance"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"supervisor {name}: expected a positive number, got {v!r}")
        if not (0 <= self.quantum_deg < self.tolerance_deg):
            raise ValueError(f"supervisor quantum_deg: expected 0 <= quantum < tolerance "
                             f"({self.tolerance_deg}), got {self.quantum_deg!r}")


class Supervisor:
    """Decides each cycle's goal orientation (see the module docstring for the rules).

    Parameters
    ----------
    oracle : models.oracle.ConstraintOracle
        The exact constraint being enforced.
    config : SupervisorConfig
    period_s : float
        Nominal cycle period, used as ``Δt`` for the first step and when the clock does not
        advance.

    Attributes
    ----------
    goal : tuple of 4 float
        The current (continuous) goal orientation, unit, parent frame.
    goal_distance : float
        ``D(goal)``, radians.
    ceiling : float
        The monotone rule's ceiling ``C``, radians (≥ 0).
    velocity : tuple of 3 float
        Goal angular velocity, rad/s, parent frame.
    flags : int
        :class:`Intervention` bits of the last cycle.
    last_correction_angle : float
        Angle of the model correction used in the last step (radians; 0 when none).
    last_commanded_distance : float
        ``D`` of the last accepted command, radians.
    """

    def __init__(self, oracle, config: SupervisorConfig | None = None, *, period_s: float = 0.005):
        if not (period_s > 0 and math.isfinite(period_s)):
            raise ValueError(f"period_s: expected a positive number, got {period_s!r}")
        self.oracle = oracle
        prepare = getattr(oracle, "prepare", None)
        if prepare is not None:  # not inside the first cycle
            prepare()
        self.config = config or SupervisorConfig()
        c = self.config
        self.period_s = float(period_s)
        self.tol = math.radians(c.tolerance_deg)
        self.tol_eff = math.radians(c.tolerance_deg - c.quantum_deg)
        self.vmax = math.radians(c.max_velocity_deg_s)
        self.amax = math.radians(c.max_accel_deg_s2)
        self._query = oracle.distance_projected_one
        self.goal: qs.Quat = qs.IDENTITY
        self.goal_distance = 0.0
        self.ceiling = 0.0
        self.velocity: qs.Vec = (0.0, 0.0, 0.0)
        self.flags = 0
        self.last_correction_angle = 0.0
        self.last_commanded_distance = 0.0
        self._t: float | None = None
        self.dt = self.period_s  # the last step's time, s
        self._c_prev: qs.Quat | None = None
        self._cache_c: qs.Quat | None = None
        self._cache_c_result = (0.0, qs.IDENTITY)
        self._cache_cmd: qs.Quat | None = None
        self._cache_cmd_d = 0.0
        self._ready = False

    # ------------------------------------------------------------------ oracle access
    def _eval(self, q) -> tuple[float, qs.Quat]:
        """``(D(q), projection of q)`` from the oracle's compiled single-orientation path."""
        return self._query(float(q[0]), float(q[1]), float(q[2]), float(q[3]))

    def distance(self, q) -> float:
        """``D(q)``: signed angular distance to the boundary, radians (> 0 outside)."""
        return self._eval(q)[0]

    # ------------------------------------------------------------------ lifecycle
    def reset(self, t: float, present) -> None:
        """Start (or restart after a safe state) from the limb's present orientation.

        Parameters
        ----------
        t : float
            Loop time, s.
        present : (4,) array-like
            Present joint orientation (forward kinematics of the servos), unit.
        """
        p = qs.normalize(tuple(float(v) for v in present))
        d = self.distance(p)
        self.goal = p
        self.goal_distance = d
        self.ceiling = max(0.0, d)
        self.last_commanded_distance = d
        self.velocity = (0.0, 0.0, 0.0)
        self.flags = 0
        self._t = float(t)
        self._c_prev = None
        self._ready = True

    @property
    def recovering(self) -> bool:
        """True while the goal is outside by more than ``τ − δ`` (steering back)."""
        return self.goal_distance > self.tol_eff

    # ------------------------------------------------------------------ one cycle
    @property
    def aimed(self) -> qs.Quat | None:
        """This cycle's target as corrected and brought into the limits (projected), before the
        rate limits: where the goal is heading. None while holding or recovering."""
        return self._c_prev

    def admit(self, t: float, target, target_t: float | None) -> qs.Quat | None:
        """Check a target; returns it normalised, or None (the goal will hold).

        Parameters
        ----------
        t : float
            Loop time now, s.
        target : (4,) array-like or None
            Target joint orientation, scalar-first.
        target_t : float or None
            Loop time at which the target was produced (None: no target yet).
        """
        self.flags = 0
        self.last_correction_angle = 0.0
        if target is None or target_t is None:
            self.flags = Intervention.HOLD_STALE
            return None
        w, x, y, z = float(target[0]), float(target[1]), float(target[2]), float(target[3])
        n = math.sqrt(w * w + x * x + y * y + z * z)
        if not math.isfinite(n) or abs(n - 1.0) > self.config.norm_tolerance:
            self.flags = Intervention.HOLD_INVALID
            return None
        if t - target_t > self.config.stale_target_s:
            self.flags = Intervention.HOLD_STALE
            return None
        return (w / n, x / n, y / n, z / n)

    def step(self, t: float, target: qs.Quat | None, correction=None) -> qs.Quat:
        """The goal orientation for this cycle.

        Parameters
        ----------
        t : float
            Loop time, s.
        target : tuple of 4 float or None
            What :meth:`admit` returned (None holds the last safe goal).
        correction : (4,) array-like or None
            The learned model's correction of ``target`` (``corrected = correction ⊗ target``);
            None uses the target as it is.

        Returns
        -------
        tuple of 4 float
            Goal orientation (unit); also in :attr:`goal`.
        """
        if not self._ready:
            raise RuntimeError("Supervisor.step before reset(t, present)")
        dt = t - self._t if self._t is not None else self.period_s
        if not (dt > 1e-6):
            dt = self.period_s
        self._t = t
        self.dt = dt  # the step's time: the runner holds the rounded goal's step to vmax · dt
        g0 = self.goal
        if target is None:  # hold the last safe goal, stop its motion
            self.velocity = (0.0, 0.0, 0.0)
            self._c_prev = None
            return g0
        c = target
        if correction is not None:
            cw, cx, cy, cz = (float(correction[0]), float(correction[1]), float(correction[2]),
                              float(correction[3]))
            cn = math.sqrt(cw * cw + cx * cx + cy * cy + cz * cz)
            if math.isfinite(cn) and abs(cn - 1.0) <= self.config.norm_tolerance:
                corr = (cw / cn, cx / cn, cy / cn, cz / cn)
                self.last_correction_angle = qs.angle(corr)
                c = qs.normalize(qs.mul(corr, target))
            else:
                self.flags |= Intervention.MODEL_INVALID
        if self.recovering:
            self._c_prev = None
            return self._recover(g0, dt)
        if c == self._cache_c:  # a held target: D is a function of c alone
            c_dist, proj = self._cache_c_result
        else:
            c_dist, proj = self._eval(c)
            self._cache_c, self._cache_c_result = c, (c_dist, proj)
        if c_dist > self.tol_eff:
            c = proj
            self.flags |= Intervention.PROJECTED
            c_dist = 0.0
        g1, limited = self._rate_limit(g0, c, dt, self._c_prev)
        self._c_prev = c
        if not limited:
            self.goal, self.goal_distance = c, c_dist
            return c
        self.flags |= Intervention.RATE_LIMITED
        d1, p1 = self._eval(g1)
        if d1 > self.tol_eff:
            g1 = p1
            self.flags |= Intervention.REPROJECTED
            self._set_velocity(g0, g1, dt)
            self.goal, self.goal_distance = g1, 0.0
        else:
            self.goal, self.goal_distance = g1, d1
        return self.goal

    def accept(self, commanded) -> bool:
        """Final check of the orientation the goal ticks encode; True → send them.

        On True the ceiling is lowered to ``max(0, D(commanded))`` if that is lower. On False
        the caller must keep the previous goal ticks (flag ``GUARD_HOLD`` is set).

        Parameters
        ----------
        commanded : (4,) array-like
            Forward kinematics of the goal ticks, unit.
        """
        d = self.commanded_distance(commanded)
        if self.allows(d):
            self.commit(d)
            return True
        self.flags |= Intervention.GUARD_HOLD
        return False

    def commanded_distance(self, commanded) -> float:
        """``D(commanded)`` (radians), remembered for the same orientation next cycle (the
        ticks of a holding goal); :meth:`accept`'s first half."""
        cmd = (float(commanded[0]), float(commanded[1]), float(commanded[2]),
               float(commanded[3]))
        if cmd == self._cache_cmd:  # the same ticks as last cycle (a holding goal)
            return self._cache_cmd_d
        d = self.distance(cmd)
        self._cache_cmd, self._cache_cmd_d = cmd, d
        return d

    def allows(self, d: float) -> bool:
        """The final check on a command at distance ``d``: ``d ≤ max(τ, C)``."""
        return d <= self.tol or d <= self.ceiling

    def commit(self, d: float) -> None:
        """A command at distance ``d`` is sent: lower the ceiling (:meth:`accept`'s second
        half)."""
        if d < self.ceiling:
            self.ceiling = max(0.0, d)
        self.last_commanded_distance = d

    def forget(self) -> None:
        """Drop the remembered answers of the oracle (its limits changed: a coupled joint's
        source moved)."""
        self._cache_c = None
        self._cache_cmd = None

    def revert(self, goal, flag: int = 0) -> None:
        """The caller could not send this cycle's goal (e.g. IK unreachable) and kept the
        previous ticks: the goal returns to ``goal`` (what those ticks encode), its velocity is
        zeroed and ``flag`` (an :class:`Intervention`) recorded.
        """
        g = qs.normalize(tuple(float(v) for v in goal))
        self.goal = g
        self.goal_distance = self.distance(g)
        self.velocity = (0.0, 0.0, 0.0)
        self._c_prev = None
        self.flags |= int(flag)

    def settle_on(self, goal) -> None:
        """The goal becomes ``goal`` (what the rounded goal ticks encode, cut to this cycle's
        step: :meth:`rig.loop.runner.EnforcementLoop._rounded_within_rate`); its velocity is
        kept, so the next step starts from what was sent, not from an unrounded goal that ran
        ahead of it (and a hold holds what was sent)."""
        g = qs.normalize(tuple(float(v) for v in goal))
        self.goal = g
        self.goal_distance = self.commanded_distance(g)

    def new_source(self) -> None:
        """The targets now come from another source (a hand-over): the last candidate is
        forgotten, so the jump between the two sources is never fed forward as the target's
        velocity; the goal keeps its velocity and closes the gap under the rate limits."""
        self._c_prev = None

    def present_stale(self, t: float, t_present: float | None) -> bool:
        """True if the servo data (read at loop time ``t_present``) are too old at ``t``."""
        return t_present is None or t - t_present > self.config.stale_present_s

    # ------------------------------------------------------------------ internals
    def _rate_limit(self, g0: qs.Quat, c: qs.Quat, dt: float,
                    c_prev: qs.Quat | None = None) -> tuple[qs.Quat, bool]:
        r = qs.relative(g0, c)
        wv = qs.log_vec(r)
        # the candidate's own velocity (feed-forward), unless it jumped faster than ω_max
        vt = (0.0, 0.0, 0.0)
        if c_prev is not None:
            m = qs.log_vec(qs.relative(c_prev, c))
            k = 1.0 / dt
            m = (m[0] * k, m[1] * k, m[2] * k)
            if m[0] * m[0] + m[1] * m[1] + m[2] * m[2] <= self.vmax * self.vmax:
                vt = m
        e = (wv[0] - vt[0] * dt, wv[1] - vt[1] * dt, wv[2] - vt[2] * dt)  # the lag
        th = math.sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2])
        v0 = self.velocity
        if th > 1e-12:
            s = min(self.vmax, th / dt, math.sqrt(2.0 * self.amax * th))
            k = s / th
            vd = (vt[0] + e[0] * k, vt[1] + e[1] * k, vt[2] + e[2] * k)
        else:
            vd = vt
        vn = math.sqrt(vd[0] * vd[0] + vd[1] * vd[1] + vd[2] * vd[2])
        if vn > self.vmax:
            k = self.vmax / vn
            vd = (vd[0] * k, vd[1] * k, vd[2] * k)
        dv = (vd[0] - v0[0], vd[1] - v0[1], vd[2] - v0[2])
        dvn = math.sqrt(dv[0] * dv[0] + dv[1] * dv[1] + dv[2] * dv[2])
        lim = self.amax * dt
        if dvn > lim:
            k = lim / dvn
            dv = (dv[0] * k, dv[1] * k, dv[2] * k)
        v1 = (v0[0] + dv[0], v0[1] + dv[1], v0[2] + dv[2])
        vn = math.sqrt(v1[0] * v1[0] + v1[1] * v1[1] + v1[2] * v1[2])
        if vn > self.vmax:
            k = self.vmax / vn
            v1 = (v1[0] * k, v1[1] * k, v1[2] * k)
        self.velocity = v1
        st = (v1[0] * dt, v1[1] * dt, v1[2] * dt)
        e = (st[0] - wv[0], st[1] - wv[1], st[2] - wv[2])
        if e[0] * e[0] + e[1] * e[1] + e[2] * e[2] < 1e-18:
            return c, False
        return qs.normalize(qs.mul(qs.exp_vec(st), g0)), True

    def _set_velocity(self, g0: qs.Quat, g1: qs.Quat, dt: float) -> None:
        v = qs.log_vec(qs.relative(g0, g1))
        k = 1.0 / dt
        v = (v[0] * k, v[1] * k, v[2] * k)
        vn = math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
        if vn > self.vmax:
            k = self.vmax / vn
            v = (v[0] * k, v[1] * k, v[2] * k)
        self.velocity = v

    def _recover(self, g0: qs.Quat, dt: float) -> qs.Quat:
        """Steer the goal towards its own exact projection; ``D`` must fall (monotone rule)."""
        self.flags |= Intervention.RECOVERY
        target = self._eval(g0)[1]
        d0 = self.goal_distance
        g1, _ = self._rate_limit(g0, target, dt)
        for _ in range(4):
            d1 = self.distance(g1)
            if d1 < d0 or d1 <= self.tol_eff:
                self.goal, self.goal_distance = g1, d1
                return g1
            # halve the step (same direction)
            half = qs.log_vec(qs.relative(g0, g1))
            g1 = qs.normalize(qs.mul(qs.exp_vec((0.5 * half[0], 0.5 * half[1], 0.5 * half[2])),
                                     g0))
        self.velocity = (0.0, 0.0, 0.0)
        return g0
