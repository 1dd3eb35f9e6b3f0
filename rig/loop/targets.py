"""Target sources for the live loop: where each cycle's joint-orientation target comes from.

Every source answers one non-blocking question per cycle, :meth:`TargetSource.latest`:
``(target_t, q)`` — the target joint orientation (scalar-first, limb relative to parent, a
tuple of 4 floats which may be NaN, zero or anything else a real source can produce) and the
loop-clock time it was produced (None: no target yet). The supervisor decides what to do with
bad or stale targets; sources never filter.

- :class:`CsvTrajectory` — a file ``t_s,w,x,y,z`` played against the loop's clock (zero-order
  hold: a row is the target from its ``t_s`` until the next row; after the last row the target
  ages and goes stale, so the limb holds).
- :class:`ScriptedTargets` — motions computed from the enforced constraint: ``slow`` (a slow
  closed path well inside the region), ``sweep`` (radial sweeps out past the boundary and back)
  and ``adversarial`` (far outside, jumps across the correctional discontinuity and concave
  notches, twist excursions, NaN / zero / infinite / non-unit and stale inputs).
- :class:`MirrorTargets` — mirror an IMU-worn limb through the orientation-source interface
  (:mod:`rig.devices.sources`): joint orientation ``q_parent⁻¹ ⊗ q_child`` from two segment
  sensors, or a ``kind="joint"`` sample as it is; a reader thread keeps the latest.

:func:`open_targets` turns a ``--targets`` string into a source.
"""

from __future__ import annotations

import csv
import math
import threading
import time
import urllib.parse
from pathlib import Path

import numpy as np

from calibration.frames import joint_to_rig
from models import qscalar as qs
from models import quaternion as Q
from rig.devices import sources
from rig.devices.config import load_rig_config
from rig.errors import RigConfigError

__all__ = ["SCRIPTS", "CsvTrajectory", "MirrorTargets", "ScriptedTargets", "TargetSource",
           "load_trajectory", "open_targets"]

SCRIPTS = ("slow", "sweep", "adversarial", "hold")

_NAN4 = (math.nan, math.nan, math.nan, math.nan)


class TargetSource:
    """Base class: a context manager answering :meth:`latest` once per cycle.

    Attributes
    ----------
    duration_s : float or None
        Natural length of the motion (None: endless).
    description : str
        One line for logs and run metadata.
    """

    duration_s: float | None = None
    description = "targets"

    def start(self, t0: float) -> None:
        """The loop starts: loop-clock time ``t0`` is the motion's time 0."""
        self.t0 = float(t0)

    def latest(self, t: float) -> tuple[float | None, tuple[float, float, float, float] | None]:
        """``(target_t, q)`` at loop time ``t``; ``(None, None)`` when there is no target yet."""
        raise NotImplementedError

    def close(self) -> None:
        """Release resources (idempotent)."""

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


# ---------------------------------------------------------------------------------------------
# CSV trajectories
# ---------------------------------------------------------------------------------------------
def load_trajectory(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """Read a ``t_s,w,x,y,z`` CSV.

    Returns
    -------
    t_s : (N,) float64, seconds, non-decreasing, finite
    q : (N, 4) float64, scalar-first targets, kept as written (NaN, zero or non-unit rows are
        allowed: the supervisor refuses them at run time, and adversarial files use them)

    Raises
    ------
    RigConfigError
        Missing header columns, a non-numeric cell, a non-finite or decreasing time (naming the
        file and line), or no rows.
    FileNotFoundError
    """
    path = Path(path)
    if path.is_dir():
        raise RigConfigError(f"{path}: is a directory, not a t_s,w,x,y,z CSV file")
    try:
        with path.open(newline="", encoding="utf-8-sig") as fh:
            return _read_trajectory(path, fh)
    except UnicodeDecodeError as err:
        raise RigConfigError(f"{path}: not a text CSV file ({err.reason} at byte "
                             f"{err.start}); expected a header t_s,w,x,y,z") from None


def _read_trajectory(path: Path, fh) -> tuple[np.ndarray, np.ndarray]:
    """The rows of an opened ``t_s,w,x,y,z`` CSV (see :func:`load_trajectory`)."""
    reader = csv.reader(fh)
    try:
        header = [h.strip() for h in next(reader)]
    except StopIteration:
        raise RigConfigError(f"{path}: empty file; expected a header t_s,w,x,y,z") from None
    need = ["t_s", "w", "x", "y", "z"]
    missing = [c for c in need if c not in header]
    if missing:
        raise RigConfigError(f"{path}:1: missing column(s) {', '.join(missing)}; expected "
                             f"a header t_s,w,x,y,z (got {','.join(header)})")
    idx = [header.index(c) for c in need]
    rows = []
    last_t = -math.inf
    for line_no, row in enumerate(reader, start=2):
        if not row or all(not c.strip() for c in row):
            continue
        try:
            vals = [float(row[i]) for i in idx]
        except IndexError:
            raise RigConfigError(f"{path}:{line_no}: expected {len(header)} columns, got "
                                 f"{len(row)}") from None
        except ValueError as err:
            raise RigConfigError(f"{path}:{line_no}: not a number ({err})") from None
        if not math.isfinite(vals[0]):
            raise RigConfigError(f"{path}:{line_no}: t_s must be finite, got {row[idx[0]]}")
        if vals[0] < last_t:
            raise RigConfigError(f"{path}:{line_no}: t_s goes back in time "
                                 f"({vals[0]} after {last_t})")
        last_t = vals[0]
        rows.append(vals)
    if not rows:
        raise RigConfigError(f"{path}: no rows after the header")
    arr = np.array(rows, dtype=np.float64)
    return arr[:, 0].copy(), arr[:, 1:].copy()


class CsvTrajectory(TargetSource):
    """A recorded or scripted trajectory, replayed against the loop clock (zero-order hold).

    Parameters
    ----------
    path : str or Path
        ``t_s,w,x,y,z`` CSV (see :func:`load_trajectory`); ``t_s`` is relative to the loop's
        start.
    frames : "rig" or "isb"
        Segment-frame convention of the file's joint orientations (:mod:`calibration.frames`);
        converted to the rig's on loading.
    """

    def __init__(self, path: str | Path, frames: str = "rig"):
        self.path = Path(path)
        self.t_s, q = load_trajectory(self.path)
        with np.errstate(invalid="ignore"):
            q = joint_to_rig(q, frames)  # NaN / zero rows stay invalid for the supervisor
        self._q = [tuple(float(v) for v in row) for row in q]
        self.duration_s = float(self.t_s[-1])
        self.description = f"csv {self.path} ({len(self._q)} rows, {self.duration_s:.3g} s)"
        self._ts = self.t_s.tolist()
        self._i = -1
        self.t0 = 0.0

    def start(self, t0: float) -> None:
        super().start(t0)
        self._i = -1

    def latest(self, t):
        e = t - self.t0
        ts = self._ts
        i = self._i
        n = len(ts)
        while i + 1 < n and ts[i + 1] <= e:
            i += 1
        self._i = i
        if i < 0:
            return None, None
        # fresh while the trajectory runs; after its last row the target ages from there
        tt = t if i + 1 < n else self.t0 + ts[i]
        return tt, self._q[i]


# ---------------------------------------------------------------------------------------------
# Scripted motions
# ---------------------------------------------------------------------------------------------
def _fib_sphere(n: int) -> np.ndarray:
    i = np.arange(n) + 0.5
    phi = np.arccos(1 - 2 * i / n)
    theta = math.pi * (1 + 5 ** 0.5) * i
    return np.stack([np.cos(theta) * np.sin(phi), np.sin(theta) * np.sin(phi), np.cos(phi)], 1)


def _orientation(axis: np.ndarray, d: np.ndarray, twist: np.ndarray) -> np.ndarray:
    """Joint orientations with limb directions ``d`` (N, 3) and twists (N,) rad about ``axis``."""
    swing = Q.from_two_vectors(np.broadcast_to(axis, d.shape), d)
    tw = Q.from_axis_angle(np.broadcast_to(axis, d.shape), twist)
    return Q.multiply(swing, tw)


class ScriptedTargets(TargetSource):
    """Motions computed from the enforced constraint.

    Parameters
    ----------
    name : {"slow", "sweep", "adversarial", "hold"}
        ``slow``: a closed path around the deepest point of the region at half its depth, twist
        swinging through the middle half of its range, one lap per ``period_s`` (default 8 s):
        always valid, slow enough to track. ``sweep``: straight swings from the deepest point to
        30° beyond the boundary and back, in turn in 12 directions. ``adversarial``: segments of
        ``segment_s`` (default 1 s) each, every target held ``hold_s`` (default 0.4 s: long
        enough for the goal to reach the boundary and press on it): far outside (≥ 30°),
        alternating at ``alternate_hz`` (every cycle at 200 Hz) between the two sides of a
        correctional discontinuity (outside points ≤ 1° apart whose exact projections are ≥ 10°
        apart — the antipode of a cone, the mouth of a concave notch), valid swing with twist
        20-120° beyond its limits, NaN / zero / infinite / non-unit targets (a new one every
        tick), stale targets (timestamped 1 s in the past), and large valid jumps.
        ``hold``: the deepest point, still.
    oracle : models.oracle.ConstraintOracle
    seed : int
    period_s, segment_s, hold_s : float
    alternate_hz : float
    """

    def __init__(self, name: str, oracle, *, seed: int = 0, period_s: float = 8.0,
                 segment_s: float = 1.0, hold_s: float = 0.4, alternate_hz: float = 200.0):
        if name not in SCRIPTS:
            raise RigConfigError(f"--targets script:{name}: unknown script; known: "
                                 f"{', '.join(SCRIPTS)}")
        self.name = name
        self.oracle = oracle
        self.rng = np.random.default_rng(seed)
        self.axis = np.asarray(oracle.constraint.limb_axis, dtype=np.float64)
        self.period_s = float(period_s)
        self.segment_s = float(segment_s)
        self.hold_s = float(hold_s)
        self.alternate_hz = float(alternate_hz)
        self.description = f"script:{name} (seed {seed})"
        self.t0 = 0.0
        self._deepest()
        if name == "adversarial":
            self._build_adversarial()
            self.kinds = [k for k, _ in self._segments]
        self.duration_s = None

    # -- geometry of the region --------------------------------------------------------------
    def _deepest(self) -> None:
        pts = _fib_sphere(4000)
        dist = self.oracle.swing_distance(pts)
        k = int(np.argmin(dist))
        self.centre = pts[k]
        self.depth = float(-dist[k]) if math.isfinite(dist[k]) else math.pi / 2
        tw = self.oracle.constraint.twist
        if tw is None:
            self.twist_mid, self.twist_half = 0.0, math.pi / 2
        else:
            lo, hi = math.radians(tw.min_deg), math.radians(tw.max_deg)
            q_c = _orientation(self.axis, self.centre[None], np.zeros(1))[0]
            lo, hi = self._twist_range_at(q_c, lo, hi)
            self.twist_mid, self.twist_half = 0.5 * (lo + hi), 0.5 * (hi - lo)

    def _twist_range_at(self, q_c, lo, hi):
        """Twist interval valid at the centre direction (swing-dependent limits): bisect."""
        def ok(phi):
            q = _orientation(self.axis, self.centre[None], np.array([phi]))[0]
            return bool(self.oracle.is_valid(q))
        mid = 0.5 * (lo + hi)
        if not ok(mid):
            return mid, mid
        a, b = lo, mid
        for _ in range(30):
            m = 0.5 * (a + b)
            a, b = (a, m) if ok(m) else (m, b)
        lo_v = b
        a, b = mid, hi
        for _ in range(30):
            m = 0.5 * (a + b)
            a, b = (m, b) if ok(m) else (a, m)
        return lo_v, a

    def _basis(self):
        c = self.centre
        e1 = Q.perpendicular(c)
        e2 = Q.cross(c, e1)
        return c, e1, e2

    def _direction(self, azimuth: float, polar: float) -> np.ndarray:
        c, e1, e2 = self._basis()
        u = math.cos(azimuth) * e1 + math.sin(azimuth) * e2
        return math.cos(polar) * c + math.sin(polar) * u

    def _q(self, d: np.ndarray, twist: float) -> tuple[float, float, float, float]:
        q = _orientation(self.axis, d[None], np.array([twist]))[0]
        return (float(q[0]), float(q[1]), float(q[2]), float(q[3]))

    # -- adversarial table -------------------------------------------------------------------
    def _build_adversarial(self) -> None:
        rng = self.rng
        o = self.oracle
        # far outside: random orientations ≥ 30° from the region
        q = Q.random_quaternions(4000, rng)
        far = q[o.signed_distance(q) > math.radians(30)]
        # discontinuity pairs: outside directions ≤ 1° apart whose nearest boundary points
        # are ≥ 10° apart
        pairs = []
        if o.constraint.swing is not None:
            d = Q.random_unit_vectors(6000, rng)
            out = d[o.swing_distance(d) > math.radians(2)]
            step = Q.random_unit_vectors(len(out), rng)
            step -= (step * out).sum(1, keepdims=True) * out
            step /= np.linalg.norm(step, axis=1, keepdims=True)
            d2 = out + math.radians(1.0) * step
            d2 /= np.linalg.norm(d2, axis=1, keepdims=True)
            b1 = o.nearest_swing_point(out)
            b2 = o.nearest_swing_point(d2)
            jump = Q.angle_between(b1, b2) > math.radians(10)
            # add the exact antipode of the deepest point (a cone's correctional discontinuity)
            pairs = [(a, b) for a, b in zip(out[jump], d2[jump], strict=True)]
            anti = -self.centre
            e = Q.perpendicular(anti)
            pairs.append((anti, (anti + math.radians(0.5) * e) / np.linalg.norm(
                anti + math.radians(0.5) * e)))
        # twist excursions: valid swing, twist 20-120° beyond a limit (both sides)
        tw = o.constraint.twist
        twist_q = []
        for _ in range(64):
            pol = rng.uniform(0, 0.8 * self.depth)
            d = self._direction(rng.uniform(0, 2 * math.pi), pol)
            extra = math.radians(rng.uniform(20, 120))
            if tw is not None:
                phi = (math.radians(tw.max_deg) + extra if rng.random() < 0.5
                       else math.radians(tw.min_deg) - extra)
            else:
                phi = rng.uniform(-math.pi, math.pi)
            twist_q.append(self._q(d, phi))
        # large valid jumps
        valid = q[o.is_valid(q)]
        if len(valid) < 8:
            valid = np.array([self._q(self._direction(rng.uniform(0, 2 * math.pi),
                                                      rng.uniform(0, 0.9 * self.depth)),
                                      self.twist_mid) for _ in range(32)])
        bad = [_NAN4, (0.0, 0.0, 0.0, 0.0), (math.inf, 0.0, 0.0, 0.0), (2.0, 0.0, 0.0, 0.0),
               (math.nan, 1.0, 0.0, 0.0), (0.5, 0.5, 0.5, 0.3)]
        tup = lambda a: tuple(float(v) for v in a)  # noqa: E731
        self._far = [tup(v) for v in far] or [self._q(-self.centre, 0.0)]
        self._pairs = []
        for a, b in pairs:  # b's orientation = a's turned by the small rotation taking a to b
            qa = self._q(a, self.twist_mid)
            step = Q.from_two_vectors(a, b)
            self._pairs.append((qa, tuple(float(v) for v in Q.multiply(step, np.array(qa)))))
        self._twist = twist_q
        self._valid = [tup(v) for v in valid]
        self._bad = bad
        segs = [("far", None), ("discontinuity", None), ("twist", None), ("invalid", None),
                ("stale", None), ("valid_jump", None), ("discontinuity", None), ("far", None)]
        if not self._pairs:
            segs = [s for s in segs if s[0] != "discontinuity"]
        self._segments = segs

    # -- TargetSource ------------------------------------------------------------------------
    def segment(self, t: float) -> str:
        """Name of the adversarial segment playing at loop time ``t`` ("" for other scripts)."""
        if self.name != "adversarial":
            return ""
        e = max(0.0, t - self.t0)
        return self._segments[int(e / self.segment_s) % len(self._segments)][0]

    def latest(self, t):
        e = t - self.t0
        if self.name == "hold":
            return t, self._q(self.centre, self.twist_mid)
        if self.name == "slow":
            ph = 2 * math.pi * e / self.period_s
            d = self._direction(ph, 0.5 * self.depth)
            return t, self._q(d, self.twist_mid + 0.5 * self.twist_half * math.sin(2 * ph))
        if self.name == "sweep":
            n_dir = 12
            k = int(e / self.period_s)
            az = 2 * math.pi * (k % n_dir) / n_dir
            frac = (e / self.period_s) % 1.0
            reach = self._reach(az)
            pol = reach * (1 - math.cos(2 * math.pi * frac)) / 2
            return t, self._q(self._direction(az, pol), self.twist_mid)
        # adversarial
        e = max(0.0, e)
        seg_i = int(e / self.segment_s)
        kind = self._segments[seg_i % len(self._segments)][0]
        held = seg_i * 7 + int((e - seg_i * self.segment_s) / self.hold_s)  # which target
        tick = int(e * self.alternate_hz)
        if kind == "far":
            return t, self._far[held % len(self._far)]
        if kind == "discontinuity":
            a, b = self._pairs[held % len(self._pairs)]
            return t, (a if tick % 2 == 0 else b)
        if kind == "twist":
            return t, self._twist[held % len(self._twist)]
        if kind == "invalid":
            return t, self._bad[tick % len(self._bad)]
        if kind == "stale":
            return t - 1.0, self._valid[held % len(self._valid)]
        return t, self._valid[(held * 11) % len(self._valid)]

    def _reach(self, azimuth: float) -> float:
        """Polar angle 30° beyond the boundary in this azimuth (bisection on the swing)."""
        cache = self.__dict__.setdefault("_reach_cache", {})
        if azimuth in cache:
            return cache[azimuth]
        a, b = 0.0, math.pi
        for _ in range(40):
            m = 0.5 * (a + b)
            if self.oracle.swing_distance(self._direction(azimuth, m)) <= 0:
                a = m
            else:
                b = m
        r = min(math.pi * 0.95, a + math.radians(30))
        cache[azimuth] = r
        return r


# ---------------------------------------------------------------------------------------------
# Mirroring an IMU-worn limb
# ---------------------------------------------------------------------------------------------
class MirrorTargets(TargetSource):
    """Mirror a person's limb measured by an orientation source.

    Parameters
    ----------
    source : rig.devices.sources.OrientationSource
        Opened source (context manager entered by this object, closed by :meth:`close`).
    parent, child : str or None
        Segment names giving ``q_joint = q_parent⁻¹ ⊗ q_child`` from ``kind="sensor"``
        samples; ``kind="joint"`` samples are used as they are.
    alignment : dict of str to (4,) array, optional
        Sensor-to-segment alignments ``q_segment = q_sensor ⊗ a`` (from calibration).
    clock : callable
        The host clock the samples' ``t`` use (``time.monotonic``).

    Notes
    -----
    A reader thread calls ``source.read(timeout=0.05)`` and keeps the newest joint
    orientation; :meth:`latest` only reads it (no locking on the hot path: one tuple
    assignment is atomic). A vanished device stops the thread and leaves the last target to
    go stale (the supervisor then holds); :attr:`error` says why.
    """

    def __init__(self, source, *, parent: str | None = None, child: str | None = None,
                 alignment: dict | None = None, clock=time.monotonic, description="mirror"):
        self.source = source
        self.parent, self.child = parent, child
        self.alignment = {k: tuple(float(v) for v in a) for k, a in (alignment or {}).items()}
        self.clock = clock
        self.description = description
        self.error: BaseException | None = None
        self.dropped = 0
        self._latest: tuple[float, tuple] | None = None
        self._seg: dict[str, tuple] = {}
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.t0 = 0.0
        self._loop_minus_host = 0.0

    def start(self, t0: float, loop_now: float | None = None) -> None:
        super().start(t0)
        # map host sample times onto the loop clock (identical when both are monotonic)
        now_loop = t0 if loop_now is None else loop_now
        self._loop_minus_host = now_loop - self.clock()
        if self._thread is None:
            self._thread = threading.Thread(target=self._run, name="rig-loop-mirror",
                                            daemon=True)
            self._thread.start()

    def _run(self) -> None:
        try:
            while not self._stop.is_set():
                for s in self.source.read(0.05):
                    q = tuple(float(v) for v in s.q)
                    if s.kind == "joint":
                        self._latest = (s.t, q)
                        continue
                    a = self.alignment.get(s.name)
                    if a is not None:
                        q = qs.mul(q, a)
                    self._seg[s.name] = (s.t, q)
                    if s.name in (self.parent, self.child):
                        p = self._seg.get(self.parent)
                        c = self._seg.get(self.child)
                        if p is not None and c is not None:
                            self._latest = (min(p[0], c[0]), qs.mul(qs.conj(p[1]), c[1]))
                self.dropped = int(getattr(self.source, "dropped", 0) or 0)
        except BaseException as err:  # a vanished device: the target goes stale
            self.error = err

    def latest(self, t):
        got = self._latest
        if got is None:
            return None, None
        return got[0] + self._loop_minus_host, got[1]

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(2.0)
            self._thread = None
        close = getattr(self.source, "close", None)
        if close is not None:
            close()


# ---------------------------------------------------------------------------------------------
def open_targets(spec: str, *, oracle, rig=None, seed: int = 0,
                 frames: str | None = None) -> TargetSource:
    """A target source from a ``--targets`` string.

    ``PATH.csv`` (or any existing file) → :class:`CsvTrajectory` (its joint orientations in
    ``frames``, default the rig's);
    ``script:NAME[?seed=N&period_s=S&segment_s=S&hold_s=S]`` → :class:`ScriptedTargets`;
    ``mirror`` (the rig configuration's sensors) → :class:`MirrorTargets`.

    Raises
    ------
    RigConfigError
        Unknown form, script or key; ``mirror`` on a rig without sensors.
    """
    if not isinstance(spec, str) or not spec.strip():
        raise RigConfigError("--targets: expected PATH.csv, script:NAME or mirror")
    spec = spec.strip()
    is_file = not spec.startswith("script:") and not (spec == "mirror"
                                                      or spec.startswith("mirror:"))
    if frames is not None and not is_file:
        raise RigConfigError(f"--frames applies to a targets file, not to --targets {spec}")
    if spec.startswith("script:"):
        body = spec[len("script:"):]
        name, _, query = body.partition("?")
        try:
            params = urllib.parse.parse_qs(query, strict_parsing=bool(query))
        except ValueError as err:
            raise RigConfigError(f"--targets {spec!r}: bad query ({err})") from None
        known = {"seed": int, "period_s": float, "segment_s": float, "hold_s": float}
        kw = {}
        for k, v in params.items():
            if k not in known:
                raise RigConfigError(f"--targets {spec!r}: unknown key {k!r}; known: "
                                     f"{', '.join(sorted(known))}")
            try:
                kw[k] = known[k](v[-1])
            except ValueError:
                raise RigConfigError(f"--targets {spec!r}: {k}: not a number: {v[-1]!r}") \
                    from None
        kw.setdefault("seed", seed)
        return ScriptedTargets(name, oracle, **kw)
    if spec == "mirror" or spec.startswith("mirror:"):
        return _open_mirror(spec, rig)
    path = Path(spec)
    if path.suffix.lower() == ".csv" or path.exists():
        if not path.exists():
            raise FileNotFoundError(2, "no such targets file", str(path))
        return CsvTrajectory(path, frames or "rig")
    raise RigConfigError(f"--targets {spec!r}: expected PATH.csv, script:NAME "
                         f"({'|'.join(SCRIPTS)}) or mirror")


def _open_mirror(spec: str, rig) -> MirrorTargets:
    driven = rig
    if spec.startswith("mirror:"):
        rig = load_rig_config(spec[len("mirror:"):])
        mine, theirs = getattr(driven, "joint", None), rig.joint
        if mine is not None and (mine.name, mine.side) != (theirs.name, theirs.side):
            # a hip's orientations are no shoulder's targets; another side's would need
            # reflecting, which the mirror does not do
            raise RigConfigError(f"--targets {spec}: rig {rig.name!r} wears its sensors on the "
                                 f"{theirs.side} {theirs.name}, rig {driven.name!r} drives the "
                                 f"{mine.side} {mine.name}")
    if rig is None or getattr(rig, "sensors", None) is None:
        name = getattr(rig, "name", "?")
        raise RigConfigError(f"--targets {spec}: rig {name!r} has no sensors to mirror; use "
                             "mirror:<rig with sensors> (e.g. mirror:sim-imu)")

    src = sources.open_source(rig, "sensors")
    joint = rig.joint
    return MirrorTargets(src, parent=joint.parent, child=joint.child,
                         description=f"mirror of {rig.name} sensors")
