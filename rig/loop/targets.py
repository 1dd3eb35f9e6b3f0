"""Target sources for the live loop: where each cycle's posture target comes from.

Every source answers one non-blocking question per cycle, :meth:`TargetSource.latest`:
``(target_t, posture)`` — the target posture, a float64 array ``(J, 4)``: one scalar-first
orientation per joint of the driven limb, child relative to parent, in the limb file's joint
order (one joint: ``(1, 4)``), whose rows may be NaN, zero or anything else a real source can
produce — and the loop-clock time it was produced (None: no target yet). The supervisor decides
what to do with bad or stale targets; sources never filter. Every source has ``n_joints`` and
``joint_names``.

- :class:`CsvTrajectory` — a file ``t_s,w,x,y,z`` (one joint) or ``t_s`` then
  ``<joint>_w,<joint>_x,<joint>_y,<joint>_z`` for each joint in the limb file's order, played
  against the loop's clock (zero-order hold: a row is the target from its ``t_s`` until the
  next row; after the last row the target ages and goes stale, so the limb holds).
- :class:`ScriptedTargets` — motions computed from the enforced constraint or limb file:
  ``slow`` (a slow closed path well inside the region), ``sweep`` (sweeps out past the boundary
  and back) and ``adversarial`` (far outside, jumps across the correctional discontinuity,
  twist excursions, reaches that become invalid only because another joint moved, NaN / zero /
  infinite / non-unit and stale inputs).
- :class:`rig.loop.leader.LeaderTargets` — a leader arm (``leader:RIG|PORT``), read once a
  cycle (:mod:`rig.loop.leader`).
- :class:`MirrorTargets` — mirror an IMU-worn limb through the orientation-source interface
  (:mod:`rig.devices.sources`): each joint's orientation ``q_parent⁻¹ ⊗ q_child`` from its two
  segments' sensors, or a ``kind="joint"`` sample as it is; a reader thread keeps the latest.

:func:`open_targets` turns a ``--targets`` string into a source; :func:`valid_targets` says
which postures are valid targets (finite, unit, inside the limits in every joint).
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
from rig.loop.leader import open_leader
from rig.loop.target_source import TargetSource

__all__ = ["SCRIPTS", "CsvTrajectory", "MirrorTargets", "ScriptedTargets", "TargetSource",
           "expected_header", "load_trajectory", "open_targets", "valid_targets"]

SCRIPTS = ("slow", "sweep", "adversarial", "hold")

_NAN4 = (math.nan, math.nan, math.nan, math.nan)


def valid_targets(oracle, postures) -> np.ndarray:
    """Which postures are valid targets: finite, unit (within 1e-3) and inside the limits in
    every joint (hierarchically, as the supervisor judges them).

    Parameters
    ----------
    oracle : models.oracle.ConstraintOracle
        The enforced constraint's or limb file's oracle.
    postures : (N, J, 4) or (N, 4) array_like
        Targets as the sources return them (``(N, 4)``: one joint).

    Returns
    -------
    (N,) bool
    """
    q = np.asarray(postures, dtype=np.float64).reshape(len(postures), -1, 4)
    ok = np.isfinite(q).all(axis=(1, 2)) & (np.abs(np.linalg.norm(q, axis=2) - 1.0)
                                            < 1e-3).all(axis=1)
    out = np.zeros(len(q), dtype=bool)
    if ok.any():
        good = q[ok] / np.linalg.norm(q[ok], axis=2, keepdims=True)
        if oracle.limb is None:
            out[ok] = oracle.is_valid(good[:, 0])
        else:
            out[ok] = oracle.is_valid(good).all(axis=1)
    return out


# ---------------------------------------------------------------------------------------------
# CSV trajectories
# ---------------------------------------------------------------------------------------------
def expected_header(joint_names=None) -> list[str]:
    """The header of a targets file for these joints: ``t_s,w,x,y,z`` (one joint, None) or
    ``t_s`` then ``<joint>_w,<joint>_x,<joint>_y,<joint>_z`` for each joint."""
    if not joint_names:
        return ["t_s", "w", "x", "y", "z"]
    return ["t_s"] + [f"{j}_{c}" for j in joint_names for c in "wxyz"]


def _header_columns(path: Path, header: list[str], joint_names) -> list[int]:
    """Indices of the quaternion columns, joint by joint (one joint: ``w,x,y,z`` anywhere, or
    ``<joint>_w..z``; a limb: exactly ``t_s`` then each joint's in order)."""
    plain = expected_header()
    if len(joint_names or ()) <= 1:
        named = expected_header(joint_names) if joint_names else None
        if named is not None and all(c in header for c in named):
            return [header.index(c) for c in named[1:]]
        missing = [c for c in plain if c not in header]
        if missing:
            want = ",".join(plain) + (f" (or {','.join(named)})" if named else "")
            raise RigConfigError(f"{path}:1: missing column(s) {', '.join(missing)}; expected "
                                 f"a header {want} (got {','.join(header)})")
        return [header.index(c) for c in plain[1:]]
    want = expected_header(joint_names)
    say = (f"expected a header {','.join(want)} (t_s, then each joint of the limb in its "
           f"file's order: {', '.join(joint_names)})")
    if header == want:
        return list(range(1, len(want)))
    dup = sorted({c for c in header if header.count(c) > 1})
    if dup:
        raise RigConfigError(f"{path}:1: repeated column(s) {', '.join(dup)}; {say}")
    if header[1:] == plain[1:] or header == plain:
        raise RigConfigError(f"{path}:1: a one-joint targets file (t_s,w,x,y,z) for a limb of "
                             f"{len(joint_names)} joints; {say}")
    missing = [c for c in want if c not in header]
    if missing:
        raise RigConfigError(f"{path}:1: missing column(s) {', '.join(missing)}; {say}")
    extra = [c for c in header if c not in want]
    if extra:
        raise RigConfigError(f"{path}:1: unknown column(s) {', '.join(extra)}; {say}")
    got = [c.rsplit("_", 1)[0] for c in header[1:] if c != "t_s"]
    order = list(dict.fromkeys(got))
    raise RigConfigError(f"{path}:1: columns out of order (joints {', '.join(order)}, "
                         f"t_s at column {header.index('t_s') + 1}); {say}")


def load_trajectory(path: str | Path, joint_names=None) -> tuple[np.ndarray, np.ndarray]:
    """Read a targets CSV: ``t_s,w,x,y,z`` (one joint) or, for a limb (``joint_names``),
    ``t_s`` then ``<joint>_w,<joint>_x,<joint>_y,<joint>_z`` for each joint in that order.

    Parameters
    ----------
    path : str or Path
    joint_names : sequence of str, optional
        The driven limb's joints in its file's order (one name or None: one joint, which may
        also be written ``<joint>_w..z``).

    Returns
    -------
    t_s : (N,) float64, seconds, non-decreasing, finite
    q : (N, J, 4) float64, scalar-first targets, kept as written (NaN, zero or non-unit rows
        are allowed: the supervisor refuses them at run time, and adversarial files use them)

    Raises
    ------
    RigConfigError
        Missing, unknown, repeated or misordered columns (naming the expected header), a
        non-numeric cell, a non-finite or decreasing time (naming the file and line), or no
        rows.
    FileNotFoundError
    """
    path = Path(path)
    want = ",".join(expected_header(joint_names if joint_names and len(joint_names) > 1
                                    else None))
    if path.is_dir():
        raise RigConfigError(f"{path}: is a directory, not a {want} CSV file")
    try:
        with path.open(newline="", encoding="utf-8-sig") as fh:
            return _read_trajectory(path, fh, joint_names)
    except UnicodeDecodeError as err:
        raise RigConfigError(f"{path}: not a text CSV file ({err.reason} at byte "
                             f"{err.start}); expected a header {want}") from None


def _read_trajectory(path: Path, fh, joint_names) -> tuple[np.ndarray, np.ndarray]:
    """The rows of an opened targets CSV (see :func:`load_trajectory`)."""
    reader = csv.reader(fh)
    try:
        header = [h.strip() for h in next(reader)]
    except StopIteration:
        want = ",".join(expected_header(joint_names if joint_names and len(joint_names) > 1
                                        else None))
        raise RigConfigError(f"{path}: empty file; expected a header {want}") from None
    if "t_s" not in header:
        want = expected_header(joint_names if joint_names and len(joint_names) > 1 else None)
        raise RigConfigError(f"{path}:1: missing column(s) t_s; expected a header "
                             f"{','.join(want)} (got {','.join(header)})")
    idx = [header.index("t_s"), *_header_columns(path, header, joint_names)]
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
    return arr[:, 0].copy(), arr[:, 1:].reshape(len(arr), -1, 4).copy()


class CsvTrajectory(TargetSource):
    """A recorded or scripted trajectory, replayed against the loop clock (zero-order hold).

    Parameters
    ----------
    path : str or Path
        Targets CSV (see :func:`load_trajectory`); ``t_s`` is relative to the loop's start.
    frames : "rig" or "isb"
        Segment-frame convention of the file's joint orientations (:mod:`calibration.frames`);
        converted to the rig's on loading.
    joint_names : sequence of str, optional
        The driven limb's joints in its file's order (None: one joint).
    segments : sequence of (str, str), optional
        Each joint's (parent, child) segment names, for ``frames="isb"`` (None: the limb axis
        convention of one joint, as :func:`calibration.frames.joint_to_rig` without names).
    """

    def __init__(self, path: str | Path, frames: str = "rig", joint_names=None, segments=None):
        self.path = Path(path)
        self.t_s, q = load_trajectory(self.path, joint_names)
        self.n_joints = q.shape[1]
        self.joint_names = tuple(joint_names) if joint_names else None
        with np.errstate(invalid="ignore"):  # NaN / zero rows stay invalid for the supervisor
            for j in range(self.n_joints):
                pc = segments[j] if segments is not None else (None, None)
                q[:, j] = joint_to_rig(q[:, j], frames, *pc)
        self._q = np.ascontiguousarray(q)
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

        For a limb (an oracle of a limb file) the same scripts are built from the limb's exact
        oracle alone, whatever its joints' kinds (:class:`_LimbMotions`): ``slow`` goes from
        the deepest posture found out to valid postures (checked valid, with a 1° margin, all
        along the way) and back, one per ``period_s``; ``sweep`` goes from it past projected
        boundary postures, the joint moving most 30° beyond; ``adversarial`` adds, to far
        outside postures (every joint, or one), discontinuity pairs, invalid, stale and large
        valid jumps, the **coupled** segments: ``coupled_source`` holds a valid posture while
        the joint a coupled joint depends on (the elbow) moves to an angle (valid for it) at
        which the coupled joint's (the shoulder's) held orientation is outside its limits, and
        ``coupled_dependent`` holds the source at such an angle while the coupled joint moves
        to an orientation valid only at another angle of its source.
        With ``kinematics`` (the driven rig's servo limb), every valid posture of a limb's
        scripts is one its servos reach: the oracle's projections are taken to the nearest
        orientation each joint's servos reach within their tick limits
        (:meth:`rig.devices.kinematics.LimbKinematics.nearest_batch`) and kept only when the
        oracle still finds them valid with the script's margin; invalid postures are as
        adversarial as without.
    oracle : models.oracle.ConstraintOracle
        A joint's constraint's or a limb file's.
    seed : int
    period_s, segment_s, hold_s : float
    alternate_hz : float
    kinematics : rig.devices.kinematics.LimbKinematics, optional
        The rig's joints, in the limb file's order (a limb's scripts only).
    """

    def __init__(self, name: str, oracle, *, seed: int = 0, period_s: float = 8.0,
                 segment_s: float = 1.0, hold_s: float = 0.4, alternate_hz: float = 200.0,
                 kinematics=None):
        if name not in SCRIPTS:
            raise RigConfigError(f"--targets script:{name}: unknown script; known: "
                                 f"{', '.join(SCRIPTS)}")
        self.name = name
        self.oracle = oracle
        self.rng = np.random.default_rng(seed)
        self.n_joints = oracle.n_joints
        limb = oracle.limb
        self.joint_names = None if limb is None else tuple(limb.joint_names)
        if limb is not None:
            self.period_s = float(period_s)
            self.segment_s = float(segment_s)
            self.hold_s = float(hold_s)
            self.alternate_hz = float(alternate_hz)
            self.kinematics = kinematics
            self.description = f"script:{name} (seed {seed}, limb {limb.name}" + \
                (", reachable by the rig's servos)" if kinematics is not None else ")")
            self.t0 = 0.0
            self.duration_s = None
            self._limb = _LimbMotions(oracle, self.rng, self)
            self.kinds = list(self._limb.segments) if name == "adversarial" else []
            return
        self._limb = None
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
        if self._limb is not None:
            return self._limb.segments[int(e / self.segment_s) % len(self._limb.segments)]
        return self._segments[int(e / self.segment_s) % len(self._segments)][0]

    def steady(self, t: float, settle_s: float = 0.3) -> bool:
        """Whether the target at loop time ``t`` is one a limb can be tracking: a continuous
        motion's (``slow``, ``sweep``) after its first ``period_s`` (the limb coming to the path
        from wherever it was), ``hold``'s, or an adversarial target that has been the same
        posture since ``t - settle_s``, fresh (with :func:`valid_targets`: the cycles whose
        tracking the valid-target figures measure)."""
        e = t - self.t0
        if self.name != "adversarial":  # once the limb has had a lap to reach the path
            return e >= self.period_s or self.name == "hold"
        if e < settle_s or self.segment(t) in ("stale", "invalid", "discontinuity"):
            return False
        a, b = self.latest(t)[1], self.latest(t - settle_s)[1]
        return bool(np.array_equal(a, b)) and self.segment(t) == self.segment(t - settle_s)

    def latest(self, t):
        if self._limb is not None:
            return self._limb.latest(t)
        tt, q = self._latest_one(t)
        return tt, np.array(q, dtype=np.float64).reshape(1, 4)

    def _latest_one(self, t):
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


def _slerp(c: np.ndarray, b: np.ndarray, s) -> np.ndarray:
    """Per joint, the rotation from ``c`` towards ``b`` by the fraction ``s`` of the way (beyond
    ``b`` for ``s > 1``): ``exp(s log(b ⊗ c⁻¹)) ⊗ c``, the shorter way. ``c``, ``b`` (..., 4)
    broadcasting, ``s`` broadcasting against their leading shape."""
    c = np.asarray(c, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    rel = Q.multiply(b, Q.conjugate(c))
    rel = np.where((rel[..., :1] < 0), -rel, rel)
    ang = Q.angle(rel)
    vn = np.linalg.norm(rel[..., 1:], axis=-1, keepdims=True)
    axis = np.where(vn > 1e-15, rel[..., 1:] / np.where(vn > 1e-15, vn, 1.0),
                    np.array([1.0, 0.0, 0.0]))
    return Q.multiply(Q.from_axis_angle(axis, np.asarray(s, dtype=np.float64) * ang), c)


class _Path:
    """A path of postures precomputed at ``K`` points (``table`` (K, J, 4), consecutive rows a
    small rotation apart), played by :meth:`at`: the nearest row — every posture of the path
    the oracle's own (a posture between two rows of a hinge or forearm joint would be off its
    axes by a rounding error, which the oracle counts as outside) — and past its end the last
    step continued, in plain floats."""

    __slots__ = ("end", "last", "step_angles", "step_axes", "table")

    def __init__(self, table: np.ndarray):
        self.table = np.ascontiguousarray(table, dtype=np.float64)
        self.last = len(self.table) - 1
        rel = Q.multiply(self.table[1:], Q.conjugate(self.table[:-1]))
        rel = np.where(rel[..., :1] < 0, -rel, rel)
        self.step_angles = Q.angle(rel)  # (K-1, J)
        vn = np.linalg.norm(rel[..., 1:], axis=-1, keepdims=True)
        self.step_axes = np.where(vn > 1e-15, rel[..., 1:] / np.where(vn > 1e-15, vn, 1.0),
                                  0.0)
        self.end = list(zip(self.step_angles[-1].tolist(), self.step_axes[-1].tolist(),
                            self.table[-1].tolist(), strict=True))

    def step_deg(self) -> float:
        """The largest rotation of any joint between consecutive rows, degrees."""
        return float(np.degrees(self.step_angles.max(initial=0.0)))

    def beyond(self, extra_rad: float) -> float:
        """The ``u`` past 1 at which the last step, continued, has turned the joint it turns
        most by ``extra_rad`` (1.0 when the path ends still)."""
        step = float(self.step_angles[-1].max())
        return 1.0 if step < 1e-9 else 1.0 + extra_rad / step / self.last

    def at(self, u: float) -> np.ndarray:
        """The posture at ``u`` ∈ [0, 1] along the path (beyond 1: its last step continued)."""
        x = max(0.0, u) * self.last
        if x <= self.last:
            return self.table[int(x + 0.5)]
        f = x - self.last
        out = np.empty((len(self.end), 4))
        for j, (ang, (ax, ay, az), cq) in enumerate(self.end):
            h = 0.5 * f * ang
            sn = math.sin(h)
            out[j] = qs.mul((math.cos(h), ax * sn, ay * sn, az * sn), cq)
        return out


class _LimbMotions:
    """The scripts of :class:`ScriptedTargets` for a limb, built from its exact oracle alone
    (any joints' kinds: every posture is the oracle's or judged by it, never by a kind's
    geometry).

    Valid postures are projections of postures a fraction of the way from a deep valid posture
    (the **centre**) to projections of random postures (the projection keeps a hinge on its
    axis, a forearm joint on its two axes, which a straight way between two of their postures
    leaves), kept when the oracle says every joint is at least a margin inside its limits. The
    centre starts at the projection of the neutral posture (identity in every joint) and moves
    to the deepest such posture found. Paths are such projections at :data:`STEPS` points,
    played by :class:`_Path` (nearest point).
    """

    #: How far inside every joint a posture of the valid pools is (rad).
    MARGIN = math.radians(2.0)
    #: Points of a precomputed slow or sweep path (a row every ~4 ms at the default period).
    STEPS = 2049

    def __init__(self, oracle, rng: np.random.Generator, script: ScriptedTargets):
        self.o = oracle
        self.rng = rng
        self.s = script
        self.J = oracle.n_joints
        self.centre = self._find_centre()
        self.segments: tuple[str, ...] = ()
        if script.name == "slow":
            self._build_slow()
        elif script.name == "sweep":
            self._build_sweep()
        elif script.name == "adversarial":
            self._build_adversarial()

    # -- sampling ----------------------------------------------------------------------------
    def _depth(self, p: np.ndarray) -> np.ndarray:
        """(N,) how far inside its limits the least inside joint is (rad; < 0: outside)."""
        return -self.o.signed_distance(p).max(axis=1)

    def _random(self, n: int) -> np.ndarray:
        return Q.random_quaternions(n * self.J, self.rng).reshape(n, self.J, 4)

    def _boundary(self, n: int) -> np.ndarray:
        """Projections of ``n`` random postures: valid, most of them on the boundary."""
        return self.o.project(self._random(n))

    def _reachable(self, p: np.ndarray) -> np.ndarray:
        """``p`` (N, J, 4) as the rig's servos reach it nearest (as it is without a rig); a
        posture they cannot reach within their tick limits becomes the centre."""
        kin = self.s.kinematics
        if kin is None:
            return p
        r = kin.nearest_batch(p)
        bad = ~np.isfinite(r).all(axis=(1, 2))
        r[bad] = self.centre
        return r

    def _towards(self, b: np.ndarray, f) -> np.ndarray:
        """The projections of postures a fraction ``f`` of the way from the centre to ``b``
        (with a rig: reachable by its servos)."""
        return self._reachable(self.o.project(_slerp(self.centre[None], b, f)))

    def _find_centre(self) -> np.ndarray:
        ident = np.zeros((1, self.J, 4))
        ident[..., 0] = 1.0
        self.centre = self.o.project(ident)[0]
        self.centre = self._reachable(self.centre[None])[0]
        best = float(self._depth(self.centre[None])[0])
        for _ in range(4):
            b = self._boundary(1000)
            for f in (0.2, 0.4):
                m = self._towards(b, f)
                d = self._depth(m)
                k = int(np.argmax(d))
                if d[k] > best:
                    self.centre, best = m[k], float(d[k])
        self.depth = best
        return self.centre

    def _valid_pool(self, n: int, lo: float, hi: float, margin: float) -> np.ndarray:
        """Up to ``n`` valid postures ``margin`` inside every joint, a fraction ``lo``..``hi``
        of the way from the centre to the boundary."""
        out: list[np.ndarray] = []
        for _ in range(8):
            b = self._boundary(2 * n)
            p = self._towards(b, self.rng.uniform(lo, hi, (len(b), 1)))
            out.extend(p[self._depth(p) >= margin])
            if len(out) >= n:
                break
        return np.array(out[:n]).reshape(-1, self.J, 4)

    def _path(self, end: np.ndarray, steps: int) -> np.ndarray:
        """(steps, J, 4): the projected way from the centre to ``end``."""
        s = np.linspace(0.0, 1.0, steps)[:, None]
        return self._towards(np.broadcast_to(end, (steps, self.J, 4)), s)

    # -- slow and sweep ----------------------------------------------------------------------
    def _build_slow(self) -> None:
        paths = []
        ends = self._valid_pool(96, 0.3, 0.7, self.MARGIN)
        # within 40° of the centre in every joint: slow enough for any chain of servos
        reach = Q.angle(Q.multiply(ends, Q.conjugate(self.centre[None]))).max(axis=1)
        for end in ends[reach <= math.radians(40.0)]:
            table = self._path(end, 257)
            if (self._depth(table) >= math.radians(1.0)).all() and \
                    _Path(table).step_deg() < 2.0:
                # dense: a row per cycle or so at 200 Hz (steps < 0.25°)
                paths.append(_Path(self._path(end, self.STEPS)))
            if len(paths) == 8:
                break
        self._paths = paths or [_Path(np.stack([self.centre, self.centre]))]

    def _build_sweep(self) -> None:
        """12 sweeps, each of one joint in turn (the others at the centre) to a projected
        boundary posture and 30° beyond along the way's last step."""
        b = self._boundary(12)
        self._paths, self._reach = [], []
        for i, end in enumerate(b):
            one = self.centre.copy()
            one[i % self.J] = end[i % self.J]
            path = _Path(self._path(one, self.STEPS))
            self._paths.append(path)
            self._reach.append(path.beyond(math.radians(30.0)))

    # -- adversarial -------------------------------------------------------------------------
    def _build_adversarial(self) -> None:
        o, J, rng = self.o, self.J, self.rng
        valid = self._valid_pool(256, 0.1, 0.9, self.MARGIN)
        if not len(valid):
            valid = self.centre[None]
        self._valid = valid
        # far outside: every joint random, or one joint of a valid posture turned away
        r = self._random(3000)
        far_all = r[o.signed_distance(r).max(axis=1) > math.radians(30)][:64]
        one = valid[rng.integers(0, len(valid), 3000)].copy()
        jj = rng.integers(0, J, 3000)
        one[np.arange(3000), jj] = Q.random_quaternions(3000, rng)
        far_one = one[o.signed_distance(one).max(axis=1) > math.radians(30)][:64]
        far = [p for pair in zip(far_all, far_one, strict=False) for p in pair]
        self._far = np.array(far or [-self.centre]).reshape(-1, J, 4)
        # discontinuity: outside postures 1° apart in one joint whose projections are ≥ 10°
        # apart in some joint
        r = self._random(3000)
        jj = rng.integers(0, J, 3000)
        step = Q.from_axis_angle(Q.random_unit_vectors(3000, rng),
                                 np.full(3000, math.radians(1.0)))
        r2 = r.copy()
        r2[np.arange(3000), jj] = Q.multiply(step, r[np.arange(3000), jj])
        p1, p2 = o.project(r), o.project(r2)
        jump = Q.angle(Q.multiply(p1, Q.conjugate(p2))).max(axis=1) > math.radians(10)
        self._pairs = list(zip(r[jump][:32], r2[jump][:32], strict=True))
        # coupled: pairs of valid postures, one joint taken from the other
        near = self._valid_pool(1500, 0.5, 1.0, math.radians(0.5))
        self._coupled_source, self._coupled_dependent = self._coupled(near)
        bad = np.array([(math.nan,) * 4, (0.0,) * 4, (math.inf, 0.0, 0.0, 0.0),
                        (2.0, 0.0, 0.0, 0.0), (math.nan, 1.0, 0.0, 0.0), (0.5, 0.5, 0.5, 0.3)])
        invalid = np.repeat(valid[:1], len(bad) * J, axis=0)
        for k in range(len(bad) * J):
            invalid[k, k % J] = bad[k // J]
        self._invalid = invalid
        segs = ["far", "coupled_source", "discontinuity", "coupled_dependent", "invalid",
                "stale", "valid_jump", "far"]
        have = {"coupled_source": len(self._coupled_source),
                "coupled_dependent": len(self._coupled_dependent),
                "discontinuity": len(self._pairs)}
        self.segments = tuple(k for k in segs if have.get(k, 1))

    def _coupled(self, near: np.ndarray) -> tuple[list, list]:
        """Ramps ``(K, J, 4)``: a valid posture, then the joint a coupled joint depends on
        (``coupled_source``: its way projected, so that it stays a posture of its joint) or
        the coupled joint itself (``coupled_dependent``) moved to another valid posture's,
        after which the coupled joint alone is outside its limits (by 3° or more)."""
        o, J, limb = self.o, self.J, self.o.limb
        src_list: list = []
        dep_list: list = []
        if len(near) < 2:
            return src_list, dep_list
        n = 6000
        a = near[self.rng.integers(0, len(near), n)]
        b = near[self.rng.integers(0, len(near), n)]
        s = np.linspace(0.0, 1.0, 129)[:, None]
        for j, joint in enumerate(limb.joints):
            if joint.coupling is None:
                continue
            src = limb.index(joint.coupling.by)
            others = [k for k in range(J) if k != j]
            for moving, start, end_from, out in ((src, a, b, src_list), (j, b, a, dep_list)):
                end = start.copy()
                end[:, moving] = end_from[:, moving]
                d = o.signed_distance(end)
                hit = (d[:, j] > math.radians(3.0)) & (d[:, others] <= 0).all(axis=1)
                for k in np.flatnonzero(hit)[:16]:
                    ramp = np.repeat(start[k][None], len(s), axis=0)
                    ramp[:, moving] = _slerp(start[k][moving], end[k][moving], s[:, 0])
                    if moving == src:  # the source's own way: its projection
                        ramp[:, moving] = self._reachable(o.project(ramp))[:, moving]
                    out.append(_Path(ramp))
        return src_list, dep_list

    # -- the motion --------------------------------------------------------------------------
    def latest(self, t: float):
        sc = self.s
        e = t - sc.t0
        name = sc.name
        if name == "hold":
            return t, self.centre.copy()
        if name in ("slow", "sweep"):
            k = int(e // sc.period_s)
            frac = (e / sc.period_s) % 1.0
            i = k % len(self._paths)
            reach = self._reach[i] if name == "sweep" else 1.0
            return t, self._paths[i].at(reach * 0.5 * (1.0 - math.cos(2.0 * math.pi * frac)))
        e = max(0.0, e)
        seg_i = int(e / sc.segment_s)
        kind = self.segments[seg_i % len(self.segments)]
        in_seg = e - seg_i * sc.segment_s
        held = seg_i * 7 + int(in_seg / sc.hold_s)
        tick = int(e * sc.alternate_hz)
        if kind == "far":
            return t, self._far[held % len(self._far)]
        if kind in ("coupled_source", "coupled_dependent"):
            table = self._coupled_source if kind == "coupled_source" else \
                self._coupled_dependent
            u = in_seg / sc.segment_s  # held, moved over the middle half, held
            return t, table[seg_i % len(table)].at(min(1.0, max(0.0, (u - 0.3) / 0.5)))
        if kind == "discontinuity":
            a, b = self._pairs[held % len(self._pairs)]
            return t, (a if tick % 2 == 0 else b)
        if kind == "invalid":
            return t, self._invalid[tick % len(self._invalid)]
        if kind == "stale":
            return t - 1.0, self._valid[held % len(self._valid)]
        return t, self._valid[(held * 11) % len(self._valid)]


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
        One joint's segment names: ``q_joint = q_parent⁻¹ ⊗ q_child`` from ``kind="sensor"``
        samples (``joints`` instead, for a limb).
    joints : sequence of (str, str), optional
        Each joint's (parent, child) segment names, in the limb file's order.
    joint_names : sequence of str, optional
        The joints' names (a ``kind="joint"`` sample is that joint's orientation as it is; one
        joint: any joint sample).
    alignment : dict of str to (4,) array, optional
        Sensor-to-segment alignments ``q_segment = q_sensor ⊗ a`` (from calibration).
    clock : callable
        The host clock the samples' ``t`` use (``time.monotonic``).

    Notes
    -----
    A reader thread calls ``source.read(timeout=0.05)`` and, once every joint has been seen,
    keeps the newest posture ``(n_joints, 4)`` with the oldest of its joints' times;
    :meth:`latest` only reads it (no locking on the hot path: one tuple assignment is atomic).
    A vanished device stops the thread and leaves the last target to go stale (the supervisor
    then holds); :attr:`error` says why.
    """

    def __init__(self, source, *, parent: str | None = None, child: str | None = None,
                 joints=None, joint_names=None, alignment: dict | None = None,
                 clock=time.monotonic, description="mirror"):
        self.source = source
        self.joints = [tuple(pc) for pc in joints] if joints is not None else [(parent, child)]
        self.parent, self.child = self.joints[0]
        self.n_joints = len(self.joints)
        self.joint_names = tuple(joint_names) if joint_names else None
        self.alignment = {k: tuple(float(v) for v in a) for k, a in (alignment or {}).items()}
        self.clock = clock
        self.description = description
        self.error: BaseException | None = None
        self.dropped = 0
        self._latest: tuple[float, np.ndarray] | None = None
        self._seg: dict[str, tuple] = {}
        self._joint: list[tuple | None] = [None] * self.n_joints
        self._uses = {}  # segment name → the joints it is a segment of
        for j, (p, c) in enumerate(self.joints):
            for name in (p, c):
                self._uses.setdefault(name, []).append(j)
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

    def _joint_index(self, name: str) -> int | None:
        if self.n_joints == 1:
            return 0
        names = self.joint_names or ()
        return names.index(name) if name in names else None

    def _run(self) -> None:
        joint = self._joint
        try:
            while not self._stop.is_set():
                changed = False
                for s in self.source.read(0.05):
                    q = tuple(float(v) for v in s.q)
                    if s.kind == "joint":
                        j = self._joint_index(s.name)
                        if j is not None:
                            joint[j] = (s.t, q)
                            changed = True
                        continue
                    a = self.alignment.get(s.name)
                    if a is not None:
                        q = qs.mul(q, a)
                    self._seg[s.name] = (s.t, q)
                    for j in self._uses.get(s.name, ()):
                        p = self._seg.get(self.joints[j][0])
                        c = self._seg.get(self.joints[j][1])
                        if p is not None and c is not None:
                            joint[j] = (min(p[0], c[0]), qs.mul(qs.conj(p[1]), c[1]))
                            changed = True
                if changed and all(x is not None for x in joint):
                    self._latest = (min(x[0] for x in joint),
                                    np.array([x[1] for x in joint], dtype=np.float64))
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
                 frames: str | None = None, separate_process: bool = True,
                 spring=None, log=None) -> TargetSource:
    """A target source from a ``--targets`` string.

    ``PATH.csv`` (or any existing file) → :class:`CsvTrajectory` (its joint orientations in
    ``frames``, default the rig's; for a limb's oracle, a column group per joint of the limb);
    ``script:NAME[?seed=N&period_s=S&segment_s=S&hold_s=S]`` → :class:`ScriptedTargets`;
    ``mirror`` (the rig configuration's sensors) or ``mirror:RIG`` → :class:`MirrorTargets`
    (for a limb's oracle, every joint of the limb, from a rig wearing a sensor on each of its
    segments: ``mirror:sim-arm``); ``leader:RIG`` or ``leader:PORT`` →
    :class:`rig.loop.leader.LeaderTargets` (a leader arm: the servos of rig configuration RIG,
    or a twin of the driven rig's servos on PORT; :func:`rig.loop.leader.open_leader`).

    Parameters
    ----------
    spec : str
    oracle : models.oracle.ConstraintOracle
        The enforced constraint's or limb file's: the joints every posture holds.
    rig : rig.devices.config.RigConfig, optional
        The driven rig.
    seed : int
    frames : {"rig", "isb"}, optional
    separate_process : bool
        A simulated leader's bus served from a process of its own (as the follower's is;
        ``False`` with a manual clock).
    spring : rig.loop.leader_spring.SpringSettings, optional
        A leader's spring (the limit felt at the leader); refused for any other source.
    log : callable, optional
        Where a leader's spring says it failed.

    Raises
    ------
    RigConfigError
        Unknown form, script or key; ``mirror`` on a rig without sensors; a leader that is no
        servo rig or lacks a joint of the follower.
    """
    if not isinstance(spec, str) or not spec.strip():
        raise RigConfigError("--targets: expected PATH.csv, script:NAME, mirror or leader:RIG")
    spec = spec.strip()
    is_file = not spec.startswith(("script:", "leader:")) and not (spec == "mirror"
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
        return ScriptedTargets(name, oracle, kinematics=_rig_limb_kinematics(rig, oracle), **kw)
    if spring is not None and not spec.startswith("leader:"):
        raise RigConfigError(f"--leader-spring needs --targets leader:RIG|PORT, not {spec}")
    if spec.startswith("leader:"):
        names, side = _follower_joints(oracle, rig)
        return open_leader(spec, names=names, side=side, rig=rig,
                           separate_process=separate_process, spring=spring, log=log)
    if spec == "mirror" or spec.startswith("mirror:"):
        if oracle.limb is not None:
            return _open_limb_mirror(spec, rig, oracle.limb)
        return _open_mirror(spec, rig)
    path = Path(spec)
    if path.suffix.lower() == ".csv" or path.exists():
        if not path.exists():
            raise FileNotFoundError(2, "no such targets file", str(path))
        limb = oracle.limb
        if limb is None:
            return CsvTrajectory(path, frames or "rig")
        return CsvTrajectory(path, frames or "rig", joint_names=limb.joint_names,
                             segments=[(j.parent, j.child) for j in limb.joints])
    raise RigConfigError(f"--targets {spec!r}: expected PATH.csv, script:NAME "
                         f"({'|'.join(SCRIPTS)}), mirror or leader:RIG|PORT")


def _follower_joints(oracle, rig) -> tuple[tuple[str, ...], str | None]:
    """The driven joints' names (a limb file's, in its order; or the rig's one joint) and side:
    what a leader arm's joints are mapped onto."""
    limb = oracle.limb
    joint = getattr(rig, "joint", None)
    rig_side = getattr(joint, "side", None)
    if limb is not None:
        return tuple(limb.joint_names), limb.side or rig_side
    return ((joint.name if joint is not None else "joint"),), rig_side


def _rig_limb_kinematics(rig, oracle):
    """The rig's servo joints' kinematics when they are the limb file's joints (by name, in
    order), else None (a joint's constraint, a rig of sensors only, other joints)."""
    limb = oracle.limb
    servos = getattr(rig, "servos", None)
    if limb is None or servos is None or not servos.joints:
        return None
    if tuple(servos.joint_names) != tuple(limb.joint_names):
        return None
    return servos.limb_kinematics().compile()


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


def _open_limb_mirror(spec: str, rig, limb) -> MirrorTargets:
    """``mirror`` / ``mirror:RIG`` for a limb: every joint of ``limb`` from the sensors of a rig
    worn on that limb (same limb, same side, a sensor on each of its segments)."""
    driven = rig
    if spec.startswith("mirror:"):
        rig = load_rig_config(spec[len("mirror:"):])
    sensors = getattr(rig, "sensors", None)
    name = getattr(rig, "name", "?")
    if sensors is None:
        raise RigConfigError(f"--targets {spec}: rig {name!r} has no sensors to mirror; use "
                             "mirror:<rig with sensors on the limb> (e.g. mirror:sim-arm)")
    worn = getattr(rig, "limb", None)
    side = rig.joint.side
    what = f"{limb.side + ' ' if limb.side else ''}{limb.limb or 'limb'} {limb.name!r}"
    if (limb.limb and worn != limb.limb) or (limb.side and side != limb.side):
        raise RigConfigError(f"--targets {spec}: rig {name!r} wears its sensors on the {side} "
                             f"{worn or rig.joint.name}, the enforced limb is the {what}"
                             + (f" of rig {driven.name!r}" if driven is not None else ""))
    missing = [seg for j in limb.joints for seg in (j.parent, j.child)
               if seg not in sensors.segments]
    if missing:
        raise RigConfigError(f"--targets {spec}: rig {name!r} has no sensor on segment(s) "
                             f"{', '.join(dict.fromkeys(missing))} of the {what} (its sensors: "
                             f"{', '.join(sensors.segments)})")
    src = sources.open_source(rig, "sensors")
    return MirrorTargets(src, joints=[(j.parent, j.child) for j in limb.joints],
                         joint_names=limb.joint_names,
                         description=f"mirror of {rig.name} sensors ({limb.limb or 'limb'})")
