"""How the simulated patient's segments move: the root segment's posture and a joint's motion
through its range of motion.

Free motion
-----------
A ball joint's swing direction is a 2-D excursion ``s(t)`` in the tangent plane at the centre
``c`` of the range of motion (exponential map: ``d = cos|s| c + sin|s| ŝ``), its twist ``φ(t)``
an excursion about the middle of the twist range; both are sums of sinusoids with seeded random
frequencies (0.03-0.3 Hz) and phases (:class:`Sinusoids`), so the motion is smooth, closed-form
and evaluable at any time (the swing angle saturates smoothly between 120° and 170° from the
centre: a push through the centre's antipode would flip its azimuth). Each axis's RMS is
``excursion`` times the reach of the range (cone radius, or the largest centre-to-vertex angle
of a polygon; half the twist range), so with ``excursion = 1`` about a third of the time the
raw motion lies outside the range; it is then brought onto the boundary (below), and the limb
slides **along the limit** — the motion a boundary recording needs
(:meth:`JointMotion.free`).

Continuity
----------
The nearest-point projection of a target outside a concave boundary jumps where the target
crosses the exterior's medial axis (on ``star_patient(204)``: up to 16,000°/s at 100 Hz; the
arm would teleport, and a gyroscope or accelerometer could not follow). Two things keep the
arm's motion physical:

- **Radial stop** (:meth:`JointMotion.project`). For a polygon range star-shaped about the
  motion's centre (every seeded star patient; checked at construction,
  :attr:`JointMotion.radial_stop`) a swing direction outside moves back along the great circle
  towards the centre onto the boundary, continuous in the target: the arm stops where its push
  meets the limit and slides along it as the push turns. Other ranges use the oracle's
  nearest point (a cone's is radial anyway). The twist is then clamped by the oracle
  (:class:`models.oracle.ConstraintOracle`, the one implementation the datasets, the
  evaluation and the live supervisor use too).
- **Smoothing** (:class:`SmoothPath`). The performed joint orientation is the uniform cubic
  B-spline with knots every ``step_s`` (40 ms) whose control points are the projected target
  on the global grid ``i · step_s``, brought into the range once more by the same projection
  (a B-spline cuts a concave corner): twice continuously differentiable except where that last
  projection acts, so the accelerometer sees finite accelerations (a brief jolt of tens of m/s²
  where the arm meets a concave limit, a few samples per minute) and the gyroscope integrates to
  the truth. Stateless: a value does not depend on what else is evaluated, or in which order.

Measured on star patients 201/204/212 at 1 kHz: angular speed p99 160-210°/s, max 180-320°/s;
evaluating 120 s at 1 kHz takes ~0.2 s.

Posture
-------
The root segment (thorax) relative to world is a fixed orientation times a slow postural sway
of ±``sway_deg`` about its first two axes, two more rows of the same seeded sinusoids
(:class:`Posture`).
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable, Hashable, Sequence
from dataclasses import dataclass

import numpy as np

from models import quaternion as Q
from models.constraint import JointConstraint
from models.limits import ConeSwing, PolygonSwing
from models.oracle import ConstraintOracle
from rig.sim.limb._rotations import exp_map, slerp

__all__ = ["JointMotion", "KnotCache", "Posture", "RateLimit", "Sinusoids", "SmoothPath",
           "StarRadial", "describe_range"]

_PUSH_KNEE = math.radians(120.0)  # raw swing angle from the centre beyond which it saturates
_PUSH_ROOM = math.radians(50.0)  # ... towards 170°
_CP_CACHE = 4096  # control points of a SmoothPath kept


@dataclass(frozen=True, eq=False)
class Sinusoids:
    """Seeded sums of sinusoids, one per row, each of unit RMS:
    ``x_r(t) = Σ_j a_rj sin(2π f_rj t + φ_rj)``.

    Attributes
    ----------
    freq : (R, 4) float64, Hz
    phase : (R, 4) float64, rad
    amp : (R, 4) float64, with ``Σ_j a_rj² / 2 = 1``
    """

    freq: np.ndarray
    phase: np.ndarray
    amp: np.ndarray

    @classmethod
    def draw(cls, rng: np.random.Generator, rows: int, speed: float = 1.0) -> Sinusoids:
        """``rows`` series: frequencies uniform in 0.03-0.3 Hz times ``speed``, uniform phases,
        weights uniform in 0.5-1 (three draws of ``(rows, 4)`` from ``rng``, in that order)."""
        freq = rng.uniform(0.03, 0.3, size=(rows, 4)) * speed
        phase = rng.uniform(0.0, 2.0 * math.pi, size=(rows, 4))
        w = rng.uniform(0.5, 1.0, size=(rows, 4))
        # RMS of Σ a sin(...) is sqrt(Σ a²/2): scale so every row has unit RMS
        amp = w * np.sqrt(2.0 / np.sum(w**2, axis=1, keepdims=True))
        return cls(freq, phase, amp)

    def rows(self, start: int, stop: int) -> Sinusoids:
        """The series ``start .. stop - 1``."""
        return Sinusoids(self.freq[start:stop], self.phase[start:stop], self.amp[start:stop])

    def __call__(self, row: int, t: np.ndarray) -> np.ndarray:
        """Series ``row`` at times ``t`` (N,) seconds, (N,)."""
        arg = 2.0 * math.pi * self.freq[row] * t[:, None] + self.phase[row]
        # a row-wise sum, not a matrix product: BLAS may round differently with the batch size,
        # and a value must not depend on what else is evaluated with it
        return (np.sin(arg) * self.amp[row]).sum(axis=1)


class Posture:
    """The root segment relative to world: ``world_from_root ⊗ exp(sway)``, the sway
    ``sway_deg × (x_0(t), x_1(t), 0)`` (two rows of ``series``)."""

    def __init__(self, world_from_root: Sequence[float], sway_deg: float,
                 series: Sinusoids) -> None:
        self.world_from_root = Q.check_quaternions(world_from_root, name="world_from_thorax")
        self.sway = math.radians(sway_deg)
        self.series = series

    def __call__(self, t) -> np.ndarray:
        """Root segment relative to world (N, 4) at times ``t`` (N,) seconds."""
        t = np.atleast_1d(np.asarray(t, dtype=np.float64))
        sway = np.stack((self.sway * self.series(0, t), self.sway * self.series(1, t),
                         np.zeros_like(t)), axis=-1)
        return Q.multiply(self.world_from_root, exp_map(sway))


def describe_range(constraint: JointConstraint
                   ) -> tuple[np.ndarray | None, float, tuple[float, float]]:
    """Centre, reach (deg) and twist interval (deg) the motion should explore."""
    centre, reach, twist = None, 60.0, (-45.0, 45.0)
    swing = constraint.swing
    if isinstance(swing, ConeSwing):
        centre, reach = np.asarray(swing.centre, float), float(swing.radius_deg)
    elif isinstance(swing, PolygonSwing):
        centre = Q.check_vectors(swing.interior)
        verts = Q.check_vectors(swing.vertices)
        reach = float(np.degrees(np.max(Q.angle_between(verts, centre))))
    if constraint.twist is not None:
        twist = (float(constraint.twist.min_deg), float(constraint.twist.max_deg))
    return centre, reach, twist


class JointMotion:
    """A ball joint's free motion through its range, and the stop at its limits.

    Parameters
    ----------
    constraint : JointConstraint
        The range of motion (child segment relative to parent).
    series : Sinusoids
        Three rows: the swing's two tangent components and the twist.
    centre : (3,) array_like, optional
        Centre of the motion (parent frame); default: the cone centre / polygon interior of
        the constraint, else the limb axis.
    reach_deg : float, optional
        Angular reach of the range from ``centre``; default from the constraint (60° if its
        swing is unlimited).
    twist_deg : (float, float), optional
        Twist interval the motion explores; default from the constraint or (-45, 45).
    excursion : float
        RMS of the raw motion relative to the reach.
    """

    def __init__(self, constraint: JointConstraint, series: Sinusoids, *,
                 centre: Sequence[float] | None = None, reach_deg: float | None = None,
                 twist_deg: tuple[float, float] | None = None, excursion: float = 1.0) -> None:
        self.constraint = constraint
        self.oracle = ConstraintOracle(constraint)
        self.series = series
        self.limb_axis = Q.check_vectors(constraint.limb_axis)
        c_default, reach_default, twist_default = describe_range(constraint)
        self.centre = Q.check_vectors(centre if centre is not None else
                                      (c_default if c_default is not None else self.limb_axis))
        self.reach = math.radians(reach_deg if reach_deg is not None else reach_default)
        tw = twist_deg if twist_deg is not None else twist_default
        self.twist_centre = math.radians(0.5 * (tw[0] + tw[1]))
        self.twist_half = math.radians(max(0.5 * (tw[1] - tw[0]), 5.0))
        self.excursion = float(excursion)
        self._u, self._v = Q.tangent_basis(self.centre)
        self._radial = StarRadial.of(constraint, self.centre)

    @property
    def radial_stop(self) -> bool:
        """Whether a swing outside the range stops radially (the range is a polygon
        star-shaped about :attr:`centre`); else the oracle's nearest point."""
        return self._radial is not None

    def free(self, t, *, reach_cap: float = math.inf, knee: float = _PUSH_KNEE,
             room: float = _PUSH_ROOM, twist_room: float = math.inf) -> np.ndarray:
        """Unconstrained joint orientation (N, 4) at times ``t`` (N,) seconds.

        The swing's RMS is ``excursion`` times the reach (at most ``reach_cap``, radians);
        beyond ``knee`` from the centre (default 120°) the push saturates smoothly (C1)
        towards ``room`` more (default 50°, so below 170°): a push through the centre's
        antipode would flip its azimuth, and the arm with it. The twist's excursion from the
        middle of its range saturates as ``twist_room · tanh(x / twist_room)`` (radians; none
        by default): below π it never reaches the middle of the excluded twists, where the
        clamp would change ends."""
        t = np.atleast_1d(np.asarray(t, dtype=np.float64))
        sigma = self.excursion * min(self.reach, reach_cap) / math.sqrt(2.0)
        su = sigma * self.series(0, t)
        sv = sigma * self.series(1, t)
        ang = np.hypot(su, sv)
        safe = np.where(ang > 1e-12, ang, 1.0)
        dirn = (su[:, None] * self._u + sv[:, None] * self._v) / safe[:, None]
        over = np.maximum(ang - knee, 0.0)
        ang = np.minimum(ang, knee) + room * np.tanh(over / room)
        d = np.cos(ang)[:, None] * self.centre + np.sin(ang)[:, None] * dirn
        swing = Q.from_two_vectors(self.limb_axis, d)
        phi = self.excursion * self.twist_half * self.series(2, t)
        if math.isfinite(twist_room):
            phi = twist_room * np.tanh(phi / twist_room)
        phi = self.twist_centre + phi
        return Q.multiply(swing, Q.from_axis_angle(self.limb_axis, phi))

    def project(self, q) -> np.ndarray:
        """Orientations (N, 4) brought into the range the way the patient's arm stops: the
        radial stop (:attr:`radial_stop`), then the oracle's projection (the twist clamp; the
        nearest point for other ranges)."""
        q = np.asarray(q, dtype=np.float64).reshape(-1, 4)
        q = q / np.linalg.norm(q, axis=1, keepdims=True)
        if self._radial is not None:
            d = Q.rotate(q, self.limb_axis)
            out = self.oracle.swing_distance(d) > 0.0
            if out.any():
                p = self._radial.boundary(d[out])
                old = Q.from_two_vectors(self.limb_axis, d[out])
                new = Q.from_two_vectors(self.limb_axis, p)
                q = q.copy()
                q[out] = Q.multiply(new, Q.multiply(Q.conjugate(old), q[out]))
        q = self.oracle.project(q, normalize=True).reshape(-1, 4)
        return q / np.linalg.norm(q, axis=1, keepdims=True)


class SmoothPath:
    """The uniform cubic B-spline with knots every ``step_s`` through control points on the
    global grid ``i · step_s`` (module docstring, "Smoothing").

    The control points are a pure function of the grid index for a given ``key`` (the
    patient's schedule), kept in a :class:`KnotCache`. Thread-safe.
    """

    def __init__(self, step_s: float) -> None:
        if not (math.isfinite(step_s) and step_s > 0):
            raise ValueError(f"smooth_s must be > 0, got {step_s!r}")
        self.step_s = float(step_s)
        self._knots = KnotCache(step_s)

    def __call__(self, t, control: Callable[[np.ndarray], np.ndarray],
                 key: Hashable) -> np.ndarray:
        """The spline (N, ..., 4) at times ``t`` (N,) seconds (not normalised), its control
        points ``control(i · step_s)`` (M, ..., 4): one quaternion per time (a joint), or
        several (a chain's joints, (M, J, 4)), each splined on its own."""
        t = np.atleast_1d(np.asarray(t, dtype=np.float64))
        if not len(t):
            return np.empty((0, 4))
        x = t / self.step_s
        i0 = np.floor(x)
        f = (x - i0)[:, None]
        idx = i0[:, None] + np.arange(-1.0, 3.0)  # (N, 4) control points of each span
        uniq, inv = np.unique(idx, return_inverse=True)
        cp = self._knots(uniq, control, key)
        c = cp[inv.reshape(-1)].reshape(len(t), 4, *cp.shape[1:])
        c = c * np.where(np.sum(c * c[:, 1:2], axis=-1) < 0.0, -1.0, 1.0)[..., None]
        w = np.concatenate(((1.0 - f) ** 3, 3.0 * f**3 - 6.0 * f**2 + 4.0,
                            -3.0 * f**3 + 3.0 * f**2 + 3.0 * f + 1.0, f**3), axis=1) / 6.0
        w = w.reshape(len(t), 4, *([1] * (c.ndim - 3)))
        # term by term (elementwise, so a row's value does not depend on the batch)
        return w[:, 0:1] * c[:, 0] + w[:, 1:2] * c[:, 1] + w[:, 2:3] * c[:, 2] + w[:, 3:4] * c[:, 3]


class KnotCache:
    """Values of a pure function of the knot index ``i`` on the grid ``i · step_s``, for one
    ``key`` at a time: the last few thousand are kept (a simulator sampling at 200 Hz asks for
    each about 40 times), and dropped when the key changes. Thread-safe."""

    def __init__(self, step_s: float) -> None:
        self.step_s = float(step_s)
        self._cache: dict[int, np.ndarray] = {}
        self._key: object = None
        self._lock = threading.Lock()

    def __call__(self, index: np.ndarray, compute: Callable[[np.ndarray], np.ndarray],
                 key: Hashable) -> np.ndarray:
        """``compute(i · step_s)`` at knot indices ``index`` (M,), stacked (M, ...)."""
        keys = np.asarray(index).astype(np.int64).tolist()
        with self._lock:
            cache = self._cache
            if self._key is not key:  # a new schedule changes the target everywhere
                cache.clear()
                self._key = key
            missing = [k for k in keys if k not in cache]
            if missing:
                vals = compute(np.asarray(missing, dtype=np.float64) * self.step_s)
                if len(cache) > _CP_CACHE:  # the older half, but none this request needs
                    wanted = set(keys)
                    old = [k for k in cache if k not in wanted]
                    for k in old[:len(cache) // 2]:
                        del cache[k]
                cache.update(zip(missing, vals, strict=True))
            return np.array([cache[k] for k in keys])


class RateLimit:
    """A target on the knot grid followed the way a limb follows it: at a bounded speed, and
    around the range rather than through it, where the target jumps (a projection into a
    concave or coupled range switching branches, a twist clamp changing ends, a blend towards a
    pose on the far side) or where the straight way between two targets leaves the range.

    Knot ``i``'s value is the target's while the follower is on it and the shortest arc to the
    next target stays in the range (``inside`` at its thirds: a tolerance there keeps a
    target sliding along a limit on it); otherwise the follower moves
    towards the next target in steps of at most ``substep`` (rad) per joint, ``max_speed``
    (rad/s) in all, each step brought into the range by ``project`` ((n, J, 4) → (n, J, 4)).
    From a valid posture a step of ε lands within ε of the range, so its nearest point moves
    at most 2ε: the follower does not jump, not even across a notch's medial axis.

    The knots are computed in order from knot ``start`` and kept (a pure function of the knot
    index: a value does not depend on what else was evaluated, or in which order), ``chunk``
    targets at a time; dropped when the key (the patient's schedule) changes. Thread-safe."""

    def __init__(self, step_s: float, max_speed: float,
                 project: Callable[[np.ndarray], np.ndarray],
                 inside: Callable[[np.ndarray], np.ndarray], *,
                 substep: float = math.radians(1.0), start: int = -4, chunk: int = 256) -> None:
        if not (math.isfinite(max_speed) and max_speed > 0):
            raise ValueError(f"max_speed must be > 0, got {max_speed!r}")
        if chunk < 1:
            raise ValueError(f"chunk must be >= 1, got {chunk!r}")
        self.step_s = float(step_s)
        self.max_step = float(max_speed) * self.step_s
        self.substep = float(substep)
        self.project, self.inside = project, inside
        self.start, self.chunk = int(start), int(chunk)
        self._key: object = None
        self._values: np.ndarray | None = None  # knots start, start + 1, ... (capacity)
        self._n = 0
        self._last: tuple[np.ndarray, bool] | None = None  # last target, follower on it
        self._lock = threading.Lock()

    def __call__(self, ts, target: Callable[[np.ndarray], np.ndarray],
                 key: Hashable) -> np.ndarray:
        """The followed postures (M, J, 4) at knot times ``ts`` (M,), the targets
        ``target(times) -> (n, J, 4)`` (in range)."""
        idx = np.rint(np.asarray(ts, dtype=np.float64) / self.step_s).astype(np.int64)
        early = idx < self.start  # before the follower starts: the target itself
        parts = []
        if early.any():
            parts.append((early, target(idx[early] * self.step_s)))
        if not early.all():
            with self._lock:
                if self._key is not key:
                    self._key, self._values, self._n, self._last = key, None, 0, None
                self._extend(int(idx.max()) - self.start + 1, target)
                parts.append((~early, self._values[idx[~early] - self.start].copy()))
        out = np.empty((len(idx), *parts[0][1].shape[1:]))
        for rows, values in parts:
            out[rows] = values
        return out

    def _extend(self, n: int, target) -> None:
        """Knots ``start`` … ``start + n − 1`` followed (in order, ``chunk`` at a time)."""
        while self._n < n:
            first = self.start + self._n
            tg = target(np.arange(first, first + self.chunk, dtype=np.float64) * self.step_s)
            tg = tg / np.linalg.norm(tg, axis=-1, keepdims=True)
            if self._values is None or self._n + self.chunk > len(self._values):
                grown = np.empty((2 * (self._n + self.chunk), *tg.shape[1:]))
                if self._values is not None:
                    grown[:self._n] = self._values[:self._n]
                self._values = grown
            self._values[self._n:self._n + self.chunk] = self._follow(tg)
            self._n += self.chunk

    def _follow(self, tg: np.ndarray) -> np.ndarray:
        prev, on = self._last if self._last is not None else (tg[0], True)
        seq = np.concatenate((prev[None], tg))  # the arcs prev → tg[0] → tg[1] → ...
        a, b = seq[:-1], seq[1:]
        n, nj = a.shape[:2]
        step = Q.angle(Q.multiply(Q.conjugate(a), b))  # (n, J)
        thirds = [slerp(a.reshape(-1, 4), b.reshape(-1, 4), np.full(n * nj, w)).reshape(n, nj, 4)
                  for w in (1.0 / 3.0, 2.0 / 3.0)]
        clear = (step <= self.max_step).all(axis=1)
        for m in thirds:
            clear &= self.inside(m).all(axis=1)
        out = np.empty_like(tg)
        f = prev
        for i in range(n):
            if on and clear[i]:
                f = tg[i]
            else:
                f, on = self._towards(f, tg[i])
            out[i] = f
        self._last = (tg[-1], on)
        return out

    def _towards(self, f: np.ndarray, goal: np.ndarray) -> tuple[np.ndarray, bool]:
        """One knot's worth of following from ``f`` (J, 4) towards ``goal``: the follower and
        whether it is on the goal."""
        ang = Q.angle(Q.multiply(Q.conjugate(f), goal))  # (J,)
        move = np.minimum(ang, self.max_step)
        n = max(1, math.ceil(float(move.max()) / self.substep))
        for _ in range(n):
            ang = Q.angle(Q.multiply(Q.conjugate(f), goal))
            w = np.where(ang > 1e-12, np.minimum(1.0, (move / n) / np.maximum(ang, 1e-12)), 1.0)
            f = self.project(slerp(f, goal, w)[None])[0]
        on = bool((Q.angle(Q.multiply(Q.conjugate(f), goal)) < 1e-9).all())
        return (goal if on else f), on


class StarRadial:
    """Radial projection onto a spherical polygon star-shaped about a centre ``c``: the
    boundary point on the great circle from ``c`` through a direction. The vertices' azimuths
    about ``c`` turn monotonically once round, so each azimuth meets exactly one edge and the
    projection is continuous in the direction."""

    def __init__(self, vertices: np.ndarray, centre: np.ndarray, u: np.ndarray,
                 v: np.ndarray, az: np.ndarray) -> None:
        self.c, self.u, self.v, self.az = centre, u, v, az  # az ascending, one turn
        self.normal = Q.cross(vertices, np.roll(vertices, -1, axis=0))  # edge k: k → k+1

    @classmethod
    def of(cls, constraint: JointConstraint, centre: np.ndarray) -> StarRadial | None:
        """The projection, or None when the range is not a polygon star-shaped about
        ``centre`` (the oracle's nearest point is used then)."""
        swing = constraint.swing
        if not isinstance(swing, PolygonSwing):
            return None
        verts = Q.check_vectors(swing.vertices)
        if np.any(verts @ centre <= -1.0 + 1e-9):
            return None  # a vertex at the centre's antipode has no azimuth
        u, v = Q.tangent_basis(centre)
        az = np.unwrap(np.arctan2(verts @ v, verts @ u))
        if az[-1] < az[0]:  # clockwise about the centre: walk it the other way
            verts = verts[::-1]
            az = np.unwrap(np.arctan2(verts @ v, verts @ u))
        steps = np.diff(np.r_[az, az[0] + 2.0 * math.pi])
        if not np.all(steps > 0.0):
            return None  # not star-shaped about the centre
        return cls(verts, centre, u, v, az)

    def boundary(self, d: np.ndarray) -> np.ndarray:
        """Boundary points (N, 3) on the great circles from the centre through ``d`` (N, 3)."""
        a = np.arctan2(d @ self.v, d @ self.u)
        a = self.az[0] + (a - self.az[0]) % (2.0 * math.pi)
        k = np.clip(np.searchsorted(self.az, a, side="right") - 1, 0, len(self.az) - 1)
        p = Q.cross(Q.cross(self.c, d), self.normal[k])
        p /= np.linalg.norm(p, axis=1, keepdims=True)
        tangent = d - (d @ self.c)[:, None] * self.c
        return p * np.where(np.sum(p * tangent, axis=1) < 0.0, -1.0, 1.0)[:, None]
