"""What the simulated patient does when: the guided calibration protocol, the hand-over to free
motion, and neutral checkpoints.

A :class:`Schedule` is immutable: performing another protocol makes a new one
(:meth:`Schedule.with_protocol`), so a simulator thread sampling the patient sees either the old
or the new schedule, never half of each. :meth:`Schedule.target` turns a joint's free motion
into the scripted target (before the projection into the range, which the patient's joint
applies: a pose outside the patient's range is performed at the nearest reachable pose, as a
real patient would).

Guided calibration protocol (optional)
--------------------------------------
With a ``protocol`` (duck-typed as :class:`calibration.protocol.CalibrationProtocol`:
``joint(u) -> (N, 4)``, ``duration_s``) the patient first performs it: neutral pose (the
identity joint orientation) until ``start_s``, then ``protocol.joint(t - start_s)``, then a
smooth hand-over to the free motion over ``blend_s`` seconds,
``q(t) = slerp(q_protocol_end, q_free(t), w)`` with ``w = smoothstep((t - t_end) / blend_s)``
(C¹: the velocity is continuous at both ends of the blend).

Neutral checkpoints (optional)
------------------------------
With ``every_s > 0`` the patient returns to the neutral pose at regular intervals (as a
clinician has them do between movements, so that the IMUs' relative heading can be re-zeroed).
Checkpoint ``k = 1, 2, ...`` holds the window ``[t_k, t_k + hold_s]``,
``t_k = start + k · every_s``, ``start = protocol_end_s + blend_s`` with a calibration protocol,
else 0 (:meth:`Schedule.neutral_windows`). The patient moves from the free motion to the
checkpoint's neutral pose ``n_k`` over ``[t_k - ramp, t_k]``, holds it, and moves back over
``[t_k + hold, t_k + hold + ramp]``: ``q(t) = slerp(q_free(t), n_k, w)``, ``w`` a smoothstep
rising over the first ramp, 1 over the hold, falling over the second (C¹).
``n_k = exp(r)`` is the identity perturbed by the patient's repeatability
(:class:`NeutralPoses`): ``r`` has the limb-axis (axial rotation) component
``N(0, sd_deg²)`` and the two others ``N(0, (sd_deg / 2)²)``, drawn from a seed sequence of its
own per checkpoint, so every other draw is the same with checkpoints on or off, and ``n_k``
does not depend on the order in which times are sampled.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from models import quaternion as Q
from rig.sim.limb._rotations import exp_map, slerp, smoothstep

__all__ = ["NeutralCheckpoints", "NeutralPoses", "Schedule"]

_NEUTRAL_KEY = 0x4E75  # spawn-key word of the neutral poses' seed sequences


@dataclass(frozen=True)
class NeutralCheckpoints:
    """When the patient returns to the neutral pose (module docstring); ``every_s = 0``: never.

    Raises
    ------
    ValueError
        ``hold_s`` or ``ramp_s`` not > 0; ``every_s`` neither 0 nor at least
        ``2 * ramp_s + hold_s + 1``.
    """

    every_s: float = 0.0
    hold_s: float = 2.0
    ramp_s: float = 1.5

    def __post_init__(self) -> None:
        every, hold, ramp = float(self.every_s), float(self.hold_s), float(self.ramp_s)
        if not (math.isfinite(hold) and hold > 0):
            raise ValueError(f"neutral_hold_s must be > 0, got {hold!r}")
        if not (math.isfinite(ramp) and ramp > 0):
            raise ValueError(f"neutral_ramp_s must be > 0, got {ramp!r}")
        least = 2.0 * ramp + hold + 1.0
        if not (math.isfinite(every) and (every == 0.0 or every >= least)):
            raise ValueError(f"neutral_every_s must be 0 (off) or >= 2 * neutral_ramp_s + "
                             f"neutral_hold_s + 1 = {least:g}, got {every!r}")
        object.__setattr__(self, "every_s", every)
        object.__setattr__(self, "hold_s", hold)
        object.__setattr__(self, "ramp_s", ramp)

    def windows(self, start: float, t_end: float) -> np.ndarray:
        """Hold windows (K, 2) of checkpoints ``k >= 1`` counted from ``start`` that end by
        ``t_end`` (seconds); ``(0, 2)`` when off."""
        every = self.every_s
        if every <= 0 or not t_end >= start + every + self.hold_s:
            return np.empty((0, 2))
        k = np.arange(1, math.floor((t_end - self.hold_s - start) / every) + 2)
        t0 = start + k * every
        t0 = t0[t0 + self.hold_s <= t_end]
        return np.stack((t0, t0 + self.hold_s), axis=1)

    def weights(self, t: np.ndarray, start: float) -> tuple[np.ndarray, np.ndarray]:
        """Checkpoint number ``k`` (N,) float and the weight ``w`` (N,) of its neutral pose at
        times ``t`` (N,): 0 in free motion, 1 during the hold, a smoothstep on the ramps.
        Counts only when ``k >= 1`` (and ``every_s > 0``)."""
        every, hold, ramp = self.every_s, self.hold_s, self.ramp_s
        k = np.floor((t - start + ramp) / every)
        x = t - (start + k * every)  # time since t_k, in [-ramp, every - ramp)
        s = np.clip(np.minimum((x + ramp) / ramp, (hold + ramp - x) / ramp), 0.0, 1.0)
        return k, smoothstep(s)


class NeutralPoses:
    """The neutral pose a joint takes at each checkpoint: the identity perturbed by the
    patient's repeatability (module docstring), deterministic per seed and checkpoint.

    Parameters
    ----------
    sd_deg : float
        Standard deviation of the axial rotation about ``axis``, degrees (>= 0); the two swing
        components have half of it.
    seed : numpy.random.SeedSequence
        Checkpoint ``k`` draws from ``SeedSequence(seed.entropy, spawn_key=(*seed.spawn_key,
        0x4E75, k))``: nothing is drawn from the patient's other streams.
    axis : (3,) float64, unit
        The joint's limb axis (child segment's long axis).
    """

    def __init__(self, sd_deg: float, seed: np.random.SeedSequence, axis: np.ndarray) -> None:
        sd = float(sd_deg)
        if not (math.isfinite(sd) and sd >= 0):
            raise ValueError(f"neutral_sd_deg must be >= 0, got {sd!r}")
        self.sd_deg = sd
        self.seed = seed
        self.axis = axis
        self._z: dict[int, np.ndarray] = {}

    def __call__(self, k) -> np.ndarray:
        """Poses (K, 4) of checkpoints ``k`` (int or (K,) ints >= 1)."""
        ks = np.atleast_1d(np.asarray(k, dtype=np.int64))
        if np.any(ks < 1):
            raise ValueError("neutral checkpoints are numbered from 1")
        sd = math.radians(self.sd_deg)
        u, v = Q.tangent_basis(self.axis)
        out = np.empty((len(ks), 4))
        ss = self.seed
        for i, kk in enumerate(ks.tolist()):
            z = self._z.get(kk)
            if z is None:
                child = np.random.SeedSequence(ss.entropy,
                                               spawn_key=(*ss.spawn_key, _NEUTRAL_KEY, kk))
                z = np.random.default_rng(child).standard_normal(3)
                self._z[kk] = z
            rotvec = sd * (z[0] * self.axis + 0.5 * z[1] * u + 0.5 * z[2] * v)
            out[i] = exp_map(rotvec)
        return out


@dataclass(frozen=True, eq=False)
class Schedule:
    """What the patient does when (module docstring). Immutable.

    Attributes
    ----------
    protocol : CalibrationProtocol or None
        Performed from ``start_s``; None: free motion from time 0.
    start_s : float
        Patient time (s) at which the protocol starts (0 without one).
    blend_s : float
        Length of the hand-over from the protocol's last pose to the free motion, seconds.
    checkpoints : NeutralCheckpoints
    """

    protocol: object = None
    start_s: float = 0.0
    blend_s: float = 3.0
    checkpoints: NeutralCheckpoints = field(default_factory=NeutralCheckpoints)

    def __post_init__(self) -> None:
        if not self.blend_s > 0:
            raise ValueError(f"blend_s must be > 0, got {self.blend_s!r}")
        object.__setattr__(self, "blend_s", float(self.blend_s))
        object.__setattr__(self, "start_s",
                           float(self.start_s) if self.protocol is not None else 0.0)

    def with_protocol(self, protocol, start_s: float = 2.0) -> Schedule:
        """This schedule with ``protocol`` performed from patient time ``start_s`` (None: free
        motion from time 0)."""
        if protocol is not None:
            if not (math.isfinite(start_s) and start_s >= 0):
                raise ValueError(f"protocol_start_s must be >= 0, got {start_s!r}")
            if not protocol.duration_s > 0:
                raise ValueError("the protocol must last > 0 s")
        return replace(self, protocol=protocol, start_s=start_s)

    @property
    def protocol_end_s(self) -> float:
        """Patient time at which the protocol has ended; 0 without a protocol."""
        return 0.0 if self.protocol is None else self.start_s + self.protocol.duration_s

    @property
    def neutral_start_s(self) -> float:
        """Patient time from which neutral checkpoints are counted: the end of the protocol's
        hand-over to free motion, or 0 without a protocol."""
        return 0.0 if self.protocol is None else (
            self.start_s + self.protocol.duration_s + self.blend_s)

    def neutral_windows(self, t_end: float) -> np.ndarray:
        """Hold windows (K, 2) of the neutral checkpoints that end by patient time ``t_end``."""
        return self.checkpoints.windows(self.neutral_start_s, t_end)

    def target(self, t: np.ndarray, free: np.ndarray,
               neutral: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
        """A joint's scripted orientation (N, 4), unprojected, at times ``t`` (N,): its free
        motion ``free`` (N, 4) with the protocol and the checkpoints' neutral poses
        (``neutral(k) -> (K, 4)``) blended in."""
        q = free
        if self.protocol is not None:
            u = t - self.start_s
            scripted = np.asarray(self.protocol.joint(u), dtype=np.float64).reshape(-1, 4)
            w = smoothstep(np.clip((u - self.protocol.duration_s) / self.blend_s, 0.0, 1.0))
            q = np.where((w >= 1.0)[:, None], q, slerp(scripted, q, w))
        if self.checkpoints.every_s > 0:
            q = self._neutral_blend(t, q, neutral)
        return q

    def _neutral_blend(self, t: np.ndarray, q: np.ndarray, neutral) -> np.ndarray:
        k, w = self.checkpoints.weights(t, self.neutral_start_s)
        active = (k >= 1) & (w > 0.0)
        if not active.any():
            return q
        uniq, inv = np.unique(k[active].astype(np.int64), return_inverse=True)
        pose = neutral(uniq)[inv]
        wa = w[active]
        out = q.copy()
        out[active] = np.where((wa >= 1.0)[:, None], pose, slerp(q[active], pose, wa))
        return out
