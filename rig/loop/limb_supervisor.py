"""The supervisor of a whole limb: the one-joint rules (:mod:`rig.loop.supervisor`) per joint,
hierarchically over the limb's couplings.

A :class:`LimbSupervisor` is built from one :class:`~rig.loop.supervisor.Supervisor` per joint —
one mechanism: a one-joint rig is the case ``J = 1`` (its one supervisor on the joint's own
oracle, bit for bit as before). Each joint's supervisor asks its joint of the limb oracle
(:meth:`models.oracle.ConstraintOracle.joint_query`) through a :class:`JointView`, a one-joint
oracle at a settable coupling angle.

One cycle (same calls as the one-joint supervisor, postures ``(J, 4)`` in the limb file's order)
--------------------------------------------------------------------------------------------
1. ``admit`` — every joint's target checked; any joint NaN / zero / non-unit / stale → the whole
   limb holds (every joint flagged).
2. ``step`` — joints in the limb's evaluation order (:attr:`models.limb.Limb.order`: a source
   before the joint coupled to it). A coupled joint is judged at the coupling angle of its
   source's **new goal** of this cycle (as the limb oracle judges a posture at the corrected
   source's angle): candidate ``c_j = correction_j ⊗ target_j``, exact projection, rate limits
   (the joint's own :class:`~rig.loop.supervisor.SupervisorConfig`), reprojection — the
   one-joint rules. When the source moves, the coupled joint's candidate and rate-limited goal
   are checked in the moved region, so a reach that becomes invalid only because another joint
   moved is projected, not sent.
3. **A source joint holds still while a joint coupled to it is recovering** (brought back from
   outside under the monotone rule; flag ``HELD_FOR_COUPLED``): otherwise the dependant's region
   would move under it and its distance need not fall. Motion back towards the valid range is
   always allowed, motion that increases a violation never is.
4. ``accept`` — the final check on the forward kinematics of all joints' goal ticks, each
   coupled joint judged at its source's *commanded* angle: every joint's ``D ≤ max(τ_j, C_j)``,
   else the whole limb keeps its previous goal ticks (``GUARD_HOLD`` on the joints that failed)
   and every joint's goal reverts to what those ticks encode (:meth:`revert`).

Flags: :attr:`joint_flags` per joint, :attr:`flags` their OR (the whole limb's).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np

from rig.loop.supervisor import Intervention, Supervisor, SupervisorConfig

__all__ = ["JointView", "LimbSupervisor"]

_HOLDS = int(Intervention.HOLD_INVALID | Intervention.HOLD_STALE)


class JointView:
    """One joint of a limb oracle seen as a one-joint oracle (``distance_projected_one``) at a
    coupling angle set by the caller (:attr:`angle`, radians; ignored by a joint with limits
    of its own).

    Parameters
    ----------
    query : callable(w, x, y, z, angle) -> (D, projection)
        :meth:`models.oracle.ConstraintOracle.joint_query`.
    """

    def __init__(self, query):
        self.query = query
        self.angle = math.nan

    def distance_projected_one(self, w: float, x: float, y: float, z: float):
        """``(D(q), projection of q)`` of the joint at :attr:`angle`."""
        return self.query(w, x, y, z, self.angle)


class LimbSupervisor:
    """Decides each cycle's goal posture of a limb (see the module docstring).

    Parameters
    ----------
    oracle : models.oracle.ConstraintOracle
        A limb's (postures) or one joint's constraint (a limb of one joint).
    config : SupervisorConfig
        Every joint's limits unless ``joint_configs`` names the joint; the watchdogs' thresholds.
    period_s : float
    joint_configs : mapping of joint name → SupervisorConfig, or sequence (one per joint)
        Per-joint tolerance and rate limits.
    names : sequence of str, optional
        The joints' names (default ``joint1``, ``joint2``, ...).

    Attributes
    ----------
    joints : tuple of Supervisor
        One per joint, the limb file's order.
    n_joints : int
    names : tuple of str
    order : tuple of int
    """

    def __init__(self, oracle, config: SupervisorConfig | None = None, *,
                 period_s: float = 0.005,
                 joint_configs: Mapping[str, SupervisorConfig] | Sequence | None = None,
                 names: Sequence[str] | None = None):
        self.oracle = oracle
        self.config = config or SupervisorConfig()
        oracle.prepare()  # not inside the first cycle
        n = oracle.n_joints
        self.names = tuple(names) if names is not None else tuple(
            f"joint{j + 1}" for j in range(n))
        if len(self.names) != n:
            raise ValueError(f"{len(self.names)} joint names for limits of {n} joint(s)")
        configs = self._configs(joint_configs, self.names)
        self.views = tuple(JointView(oracle.joint_query(j)) for j in range(n))
        self.joints = tuple(Supervisor(v, c, period_s=period_s)
                            for v, c in zip(self.views, configs, strict=True))
        self.sources = tuple(oracle.joint_source(j) for j in range(n))
        self.order = tuple(oracle.order)
        self.n_joints = len(self.joints)
        self.dependants = tuple(tuple(d for d, s in enumerate(self.sources) if s == j)
                                for j in range(self.n_joints))

    def _configs(self, joint_configs, names) -> list[SupervisorConfig]:
        if joint_configs is None:
            return [self.config] * len(names)
        if isinstance(joint_configs, Mapping):
            unknown = sorted(set(joint_configs) - set(names))
            if unknown:
                raise ValueError(f"supervisor settings for unknown joint(s) {', '.join(unknown)}"
                                 f"; the limb's joints: {', '.join(names)}")
            return [joint_configs.get(n, self.config) for n in names]
        out = list(joint_configs)
        if len(out) != len(names):
            raise ValueError(f"{len(out)} joint supervisor settings for {len(names)} joints")
        return out

    # ------------------------------------------------------------------ state
    @property
    def flags(self) -> int:
        """The whole limb's :class:`Intervention` bits of the last cycle (the joints' OR)."""
        f = 0
        for s in self.joints:
            f |= s.flags
        return f

    @property
    def joint_flags(self) -> list[int]:
        """Each joint's :class:`Intervention` bits of the last cycle."""
        return [int(s.flags) for s in self.joints]

    @property
    def recovering(self) -> bool:
        """Any joint's goal outside by more than its ``τ − δ``."""
        return any(s.recovering for s in self.joints)

    def _set_angle(self, j: int, posture) -> None:
        """Point joint ``j``'s view at the coupling angle of ``posture[source]``."""
        src = self.sources[j]
        if src is None:
            return
        q = posture[src]
        a = self.oracle.coupling_angle_one(src, float(q[0]), float(q[1]), float(q[2]),
                                           float(q[3]))
        view = self.views[j]
        if a != view.angle:  # NaN never equals: the first angle is always taken
            view.angle = a
            self.joints[j].forget()

    # ------------------------------------------------------------------ lifecycle
    def reset(self, t: float, present) -> None:
        """Start from the limb's present posture ``(J, 4)`` (each joint at its source's
        present angle)."""
        p = np.asarray(present, dtype=np.float64).reshape(self.n_joints, 4)
        for j in self.order:
            self._set_angle(j, p)
            self.joints[j].reset(t, p[j])

    # ------------------------------------------------------------------ one cycle
    def admit(self, t: float, target, target_t: float | None) -> list | None:
        """Check a target posture; returns its joints normalised (J tuples), or None (the whole
        limb holds; every joint flagged)."""
        if target is None or target_t is None:
            for s in self.joints:
                s.admit(t, None, None)
            return None
        if self.n_joints == 1 and np.ndim(target) == 1:  # one joint's (4,): as it came
            out1 = self.joints[0].admit(t, target, target_t)
            return None if out1 is None else [out1]
        arr = np.asarray(target, dtype=np.float64).reshape(-1, 4)
        if arr.shape[0] != self.n_joints:
            for s in self.joints:
                s.admit(t, None, None)
                s.flags = int(Intervention.HOLD_INVALID)
            return None
        out = [s.admit(t, arr[j], target_t) for j, s in enumerate(self.joints)]
        if self.n_joints > 1 and any(o is None for o in out):
            bits = 0
            for s in self.joints:
                bits |= s.flags & _HOLDS
            for s in self.joints:
                s.flags = bits
            return None
        return None if out[0] is None else out

    def step(self, t: float, target: list | None, correction=None) -> list:
        """The goal posture of this cycle: J tuples (unit), the limb file's order.

        Parameters
        ----------
        target : list of J tuples, or None
            What :meth:`admit` returned (None holds every joint).
        correction : (J, 4) array-like or None
            The limb model's corrections (``corrected_j = correction_j ⊗ target_j``).
        """
        goals: list = [None] * self.n_joints
        for j in self.order:
            sup = self.joints[j]
            self._set_angle(j, goals)
            if target is None:
                goals[j] = sup.step(t, None)
                continue
            if any(self.joints[d].recovering for d in self.dependants[j]):
                goals[j] = sup.step(t, None)  # hold still: its dependant's region must not move
                sup.flags |= Intervention.HELD_FOR_COUPLED
                continue
            goals[j] = sup.step(t, target[j], None if correction is None else correction[j])
        return goals

    def accept(self, commanded) -> bool:
        """Final check of the posture the goal ticks encode (J orientations); True → send them.

        On False the caller keeps the previous goal ticks and calls :meth:`revert` with what
        they encode (``GUARD_HOLD`` is set on the joints that failed)."""
        if self.n_joints == 1:
            return self.joints[0].accept(commanded[0])
        ds = [0.0] * self.n_joints
        ok = True
        for j in self.order:
            self._set_angle(j, commanded)
            sup = self.joints[j]
            d = sup.commanded_distance(commanded[j])
            ds[j] = d
            if not sup.allows(d):
                sup.flags |= Intervention.GUARD_HOLD
                ok = False
        if ok:
            for sup, d in zip(self.joints, ds, strict=True):
                sup.commit(d)
        return ok

    def revert(self, goals, flag: int = 0) -> None:
        """Every joint's goal returns to ``goals`` (J orientations: what the goal ticks kept
        encode), velocities zeroed, ``flag`` recorded (:meth:`Supervisor.revert`)."""
        for j in self.order:
            self._set_angle(j, goals)
            self.joints[j].revert(goals[j], flag)

    def new_source(self) -> None:
        """A hand-over between target sources (:meth:`Supervisor.new_source` on every joint)."""
        for s in self.joints:
            s.new_source()

    def present_stale(self, t: float, t_present: float | None) -> bool:
        """True if the servo data (read at loop time ``t_present``) are too old at ``t``."""
        return self.joints[0].present_stale(t, t_present)
