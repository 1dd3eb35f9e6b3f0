"""A whole limb's limits from a recording of its joints: :class:`LimbExtractor` → a limb file
(:mod:`models.limb`), with a coupling where the recording supports one.

Input: joint orientations ``q`` (N, 3, 4) of an arm (shoulder, elbow, wrist) or a leg (hip,
knee, ankle), each child relative to its parent in rig segment frames
(:data:`calibration.joints.JOINTS`), in recording order with their sample times.

Each joint alone
----------------
Each joint's limits are extracted from its own orientations by the one extraction
``rig boundary --joint`` runs too (:mod:`calibration.extraction.joint`): the hinge (elbow, knee)
by :class:`~calibration.boundary.HingeExtractor`, the others by
:class:`~calibration.boundary.BoundaryExtractor` (the distal joint as a ``two-axis`` joint when
its recorded twist allows). A joint left uncoupled is written as that extraction gives it, the
same limits ``--joint`` writes from the same session; a coupled one differs by its coupling.

The couplings (a swing joint's limits against the hinge's angle)
----------------------------------------------------------------
Two-joint muscles make the hip's range depend on the knee's angle (the hamstrings), the
ankle's on the knee's (the gastrocnemius: more dorsiflexion with the knee bent) and the
shoulder's on the elbow's (the biceps' long head). The proximal joint is tested first, then
the distal one (ankle, wrist) in the limb file with the proximal's outcome. Keyframes are
placed evenly over the hinge's
extracted interval, at least ``keyframe_spacing_deg`` apart (at most ``max_keyframes``); each
keyframe's limits are extracted from the proximal joint's samples recorded with the hinge within
``keyframe_band_deg`` of its angle (that band decides whether a keyframe is supported; its
limits are then extracted from every sample nearer its angle than another supported keyframe's,
so that every recorded posture is evidence for the limits it is judged by). **The data supports
a coupling** when

1. at least two keyframes are *supported*: each has at least ``min_keyframe_samples`` samples
   with the hinge within ``keyframe_band_deg`` of its angle, spread all round their centre — at
   least ``min_keyframe_coverage`` of the 12 azimuth sectors about their mean direction hold 5
   samples or more (samples on one side of the range would give a boundary that is only a band
   of it; :mod:`calibration.coverage`'s test of a reached limit needs a trajectory in time,
   which one keyframe's samples are not), and
2. the supported keyframes' boundaries differ: the largest symmetric mean boundary distance
   (:func:`~calibration.boundary.boundary_distance`) between two of them is at least
   ``min_difference_deg``, or they differ locally — along 5 % of the two boundaries' length
   (``p95_deg``) by at least ``min_local_difference_deg`` (the ankle's dependence is 5-8° of
   dorsiflexion in one direction: about 1° on average, 4.6-5.6° there, on simulated legs),
   provided the differences are graded (for keyframes at angles ``a < b < c``, the
   difference ``a``–``c`` at least the larger of ``a``–``b`` and ``b``–``c`` less half the
   threshold) and not one keyframe's alone (one differing from every other by the threshold
   while the others agree to within half of it): a keyframe whose samples fell short of part
   of the limit differs out of step with the angle (simulated wrists, arms 3 and 101: one
   keyframe 4.5-7.8° from its neighbours, which were 0.2-3.4° apart); otherwise the limits do
   not depend on the hinge, as far as the recording shows, and
3. the coupled limits hold what was recorded: at least ``min_held`` of the recorded postures
   lie inside the proximal joint's limits at their own hinge angle, or within 1° of them (the
   interpolation between keyframes is linear in the angle; the limits need not be, so a few
   postures between keyframes may lie just outside). A recording that is not a
   range-of-motion test (a dance, a walk) shows where the limb went at each hinge angle, which
   differs with the angle without being a limit that depends on it; limits interpolated from
   such keyframes would leave recorded postures outside, and are not written.

   Postures both keyframes hold may still lie outside the limits between them where the
   limits are not linear in the angle, or where the interpolation (:mod:`models.limb`)
   cuts a corner of a stretch both keyframes share. Boundaries are matched along such
   stretches (dynamic time warping) since e741674; paired by arc length alone they slid
   along them and cut their corners (on simulated range-of-motion tests with a true
   coupling, ``rig.sim.patients.simulated_patient``, 1-5 % of the postures out, up to 6°, and
   most couplings refused). That is the file format's interpolation, not evidence against
   the coupling, so the test is made in two steps. First the evidence: at least
   ``min_held`` of the postures lie within 1° of the limits or of both keyframes that bracket
   their hinge angle (of the end keyframe beyond it) — a dance's postures lie outside the
   neighbouring keyframe, not only outside the interpolation (the CMU dances: 97.0-98.6 %).
   Then, while the limits leave more than ``1 − min_held`` of the postures more than 1° out,
   a keyframe is added half-way between the two that leave most out — when the recording
   supports one there (test 1), the two are at least twice ``keyframe_band_deg`` apart and
   the file then holds more — and the samples are shared out among the keyframes again (up
   to twice ``max_keyframes``; listed with ``added``); the limits so written must hold
   ``min_held`` as stated above.

   Last, the coupled limits are made to hold what was recorded, within its measured error
   and no more (no 1° slack: ``held_``). A keyframe extracted from its nearest samples alone
   is evidence for one of the two keyframes a posture is interpolated from, and the other may
   leave it out: on a simulated leg session the keyframe at the knee's end, built from the
   few samples there, had a slit cut in to neutral, and the ankle held 93.7 % of its
   postures. So the postures the limits leave out are added to the samples of every keyframe
   whose span (between its neighbours' angles) holds them, and the keyframes are extracted
   again (at most 3 rounds, each kept only if the file then holds more; the count is in the
   note); the limits written must hold ``min_inside`` (99.5 %) of the postures, or the joint
   is not coupled and the reason is printed.

When the interpolation between two keyframes touches itself (a file that cannot be read), a
keyframe is added half-way between them where the recording supports one there and they are at
least twice ``keyframe_band_deg`` apart (listed with ``added`` and ``why``), until the file
reads; otherwise the keyframes are extracted again with fewer vertices (32, then 16), smoother —
as long as that moves none of them ``min_difference_deg`` or more from its boundary at the full
vertex budget: smoothing that large would be as large as the dependence the coupling is to show
(measured on simulated arms with 3° of slow sensor error: a shoulder's keyframes at 16 vertices
lay 4-13° from the recorded ones, and the coupling written from them 8-15° from the truth).

Measured errors
---------------
``slow_error_deg`` (per joint: the slow error left in its orientations, as measured — in an
IMU session the heading correction's own uncertainty for the joint's distal sensor relative
to its proximal one) gives each swing joint's and keyframe's twist envelope its singular
reach (:func:`calibration.boundary.twist.singular_reach`: a direction error ε turns the
swing-twist twist by up to ε·tan(s/2) at a swing s, so a sample at the arm or thigh raised
counts towards a twist end only beyond that reach), and test 3 counts each recorded posture
as held within 1° plus its own reach. That is the default, and all it does.

With ``slow_insets`` the limits are also moved in by what the error explains, as the one-
joint path does (:mod:`calibration.boundary.inset`: the closest approach of visits to the
swing limit; dwells at a twist limit). A keyframe holds too few visits and dwells for
estimates of its own (estimated per keyframe they differed by more than test 2 resolves: a
false wrist coupling), so keyframes are then extracted twice, the swing inset written the
median of the keyframes' estimates and the twist's from all their dwells together
(:func:`~calibration.boundary.twist.pooled_insets`; not from the joint's whole recording,
whose visits to the union of the keyframes' regions stop short of it), and test 3 counts a
posture held when its direction lies within 1° plus the swing inset of the swing limits and
its orientation within that plus the twist inset and its reach. Off by default: on held-out
simulated limbs (``benchmarks/bench_limb_imu.py``, 2026-11-25) it brought every boundary and
hinge end closer to the truth (shoulder peaks 2.16°), but the limits then lay inside the
truth by the calibration's bias (up to 1-1.5° at a twist end), the share of true postures
within 1° fell to 88.5 % (hip), the demo leg's boundary check failed (94.3 % within 1°, ≥ 97
% asked), and a wrist coupling was written on 2 of 6 arms where none is true.

Without measured errors (files, sessions without neutral checkpoints) nothing changes.

Unsupported keyframes are left out (the limits between supported ones are interpolated, and
clamped beyond the end ones, :mod:`models.limb`). Without support a joint's limits are
extracted from all of its samples, uncoupled, and the report says which test failed
(``couplings``: per tested joint).

What the limb file holds is measured on it (:class:`models.oracle.ConstraintOracle`): the share
of recorded postures valid in every joint, per joint (a coupled joint at its recorded hinge
angle), and for hinges the share of recorded hinge angles inside the interval (out-of-axis
motion of a hinge is corrected, not a limit: :mod:`calibration.boundary.hinge`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from calibration.boundary.compare import boundary_distance
from calibration.boundary.inset import NOISE_REACH
from calibration.boundary.twist import pooled_insets, singular_reach
from calibration.errors import CalibrationError
from calibration.extraction.joint import fit_joint, joint_extractor
from calibration.joints import JOINTS, LIMB_CHAINS, JointSpec, hinge_angles
from models import quaternion as Q
from models.constraint import JointConstraint
from models.errors import ConstraintError
from models.geometry import first_contact_along
from models.kinds import DEFAULT_KIND, get_kind
from models.limb import Limb, corresponding_polygons, inline_constraint
from models.limits import PolygonSwing
from models.oracle import ConstraintOracle

__all__ = ["METHOD", "LimbExtractor"]

#: The method a limb file's provenance names: the name limb files have always recorded (the
#: class was ``ChainExtractor`` before the word "chain" was retired for a limb), kept so that
#: every limb file is written byte for byte as before.
METHOD = "calibration.boundary.ChainExtractor"

_ONE_DEG = float(np.radians(1.0))
#: Rounds of keyframes grown by the postures their interpolation leaves out (``_grow``).
_GROW_ROUNDS = 3


class LimbExtractor:
    """Recorded limb postures → a limb file with its coupling (module doc); the one entry of
    boundary extraction, for a whole limb or a limb of one joint.

    A limb of one joint (``limb`` a tuple of one joint name, ``rig boundary --joint``,
    :func:`rig.readback.boundary.extract`) has nothing to couple: its joint's limits are the
    one extraction of :mod:`calibration.extraction.joint` (a hinge's interval, else a swing
    region and twist), available as ``constraint_`` and ``extractors_[joint]``; no limb file
    is written for it (``limb_`` is None) — its constraint is the file.

    Parameters
    ----------
    limb : {"arm", "leg"} or tuple of one joint name
        A whole limb, or a limb of one joint (:data:`calibration.joints.JOINTS`; None, or a
        name it does not list, is a ball joint).
    keyframe_spacing_deg, max_keyframes, keyframe_band_deg
        Where keyframes go and which samples each is extracted from.
    min_keyframe_samples, min_keyframe_coverage, min_difference_deg,
    min_local_difference_deg, min_held, min_inside
        The test of "the data supports a coupling".
    alpha_deg, max_vertices
        The swing extraction's alpha radius and vertex budget (each joint and keyframe).
    slow_insets : bool
        Move the limits in by the measured slow error's insets too, not only take its twist
        reach (module doc, "Measured errors"; off by default; one-joint IMU sessions read
        so, :mod:`calibration.extraction.joint`).
    name : str
    by_swing, limb_axis
        A limb of one joint: the swing-dependent twist choice (``"auto"``, True, False) and
        the limb axis (default the joint's); a whole limb's joints use their own.
    kind : str or None
        A limb of one joint: the joint kind to extract (:mod:`calibration.kinds`; e.g.
        ``forearm`` for an elbow recorded turning about its long axis); default the joint's.
    kinds : dict, optional
        A whole limb: joint → the kind to extract where it is not the joint's own (e.g.
        ``{"elbow": "forearm"}``: a servo arm's elbow turns about its long axis too; the
        couplings then follow the forearm's flexion, :meth:`models.kinds.JointKind.
        coupling_angle`).

    Attributes
    ----------
    extractors_ : dict, joint → its fitted extractor (a limb of one joint; a whole limb's
        joints are in ``reports_``)
    constraint_ : models.constraint.JointConstraint, the one joint's limits (a limb of one
        joint)
    limb_ : models.limb.Limb (None for a limb of one joint)
    couplings_ : dict, tested joint → ``coupled``, ``note`` (why or why not), ``keyframes``,
        ``difference_deg``, ``local_difference_deg``
    coupled_, coupling_note_, keyframes_ : the proximal joint's: whether coupled, why, every
        candidate keyframe (``at_deg``, ``samples``, ``coverage``, ``supported``, and
        ``added``: placed where the interpolation left postures out)
    inside_ : dict, joint → share of the recorded postures valid in that joint (hinges: their
        angle inside the interval); ``limb``: valid in every joint
    held_ : dict, the same within what each posture's measured error explains and no more
        (:meth:`_tolerance` without its 1° slack: the twist's singular reach; with
        ``slow_insets`` the insets too): a coupled joint's limits hold at least ``min_inside``
        of them, or it is not coupled (module doc, test 3)
    tolerance_deg_ : dict, joint → ``[swing, whole]``: how far outside its swing limits a
        recorded direction, and outside its limits a recorded orientation, still counted as
        held in test 3 (1° each, plus the insets its measured slow error made the extraction
        apply; the twist's reach at each posture's swing comes on top: module doc, "Measured
        errors")
    reports_ : dict, joint → its extractor's report
    """

    def __init__(self, limb: str = "leg", *, keyframe_spacing_deg: float = 30.0,
                 max_keyframes: int = 5, keyframe_band_deg: float = 10.0,
                 min_keyframe_samples: int = 300, min_keyframe_coverage: float = 0.75,
                 min_difference_deg: float = 3.0, min_local_difference_deg: float = 4.0,
                 min_held: float = 0.99, min_inside: float = 0.995,
                 alpha_deg: float = 4.0,
                 max_vertices: int = 64, name: str = "recorded-limb",
                 slow_insets: bool = False, by_swing: bool | str = "auto",
                 limb_axis=None, kind: str | None = None,
                 kinds: dict[str, str] | None = None) -> None:
        one = isinstance(limb, tuple) and len(limb) == 1
        if not one and limb not in LIMB_CHAINS:
            raise ValueError(f"limb must be one of {', '.join(LIMB_CHAINS)} or a tuple of one "
                             f"joint, got {limb!r}")
        if kind is not None and not one:
            raise ValueError("kind applies to a limb of one joint (a whole limb's joints have "
                             "their own kinds)")
        self.kind = kind
        self.kinds = dict(kinds or {})
        if self.kinds:
            if one:
                raise ValueError("kinds applies to a whole limb (a limb of one joint: kind)")
            names = [name for name, _, _ in LIMB_CHAINS[limb]]
            source = names[1]
            for joint, k in self.kinds.items():
                if joint not in names:
                    raise ValueError(f"kinds: the {limb} has no joint {joint!r}")
                if joint != source:
                    raise ValueError(f"kinds: only the {limb}'s {source} (the couplings' "
                                     f"source) takes another kind, not the {joint}")
                get_kind(k)  # registered, or ConstraintError naming the kinds
            if not get_kind(self.kinds.get(source, JOINTS[source].kind)).drives_couplings:
                raise ValueError(f"kinds: the {source} drives the couplings; a "
                                 f"{self.kinds[source]} joint does not")
        self.by_swing = by_swing
        self.limb_axis = limb_axis
        if max_keyframes < 2:
            raise ValueError(f"max_keyframes must be >= 2, got {max_keyframes}")
        for label, v in (("keyframe_spacing_deg", keyframe_spacing_deg),
                         ("keyframe_band_deg", keyframe_band_deg)):
            if not v > 0:
                raise ValueError(f"{label} must be > 0, got {v!r}")
        self.limb = limb
        self.keyframe_spacing_deg = float(keyframe_spacing_deg)
        self.max_keyframes = int(max_keyframes)
        self.keyframe_band_deg = float(keyframe_band_deg)
        self.min_keyframe_samples = int(min_keyframe_samples)
        self.min_keyframe_coverage = float(min_keyframe_coverage)
        self.min_difference_deg = float(min_difference_deg)
        self.min_local_difference_deg = float(min_local_difference_deg)
        self.min_held = float(min_held)
        self.min_inside = float(min_inside)
        self.alpha_deg = float(alpha_deg)
        self.max_vertices = int(max_vertices)
        self.name = name
        self.slow_insets = bool(slow_insets)

    def params(self) -> dict[str, Any]:
        return {"limb": self.limb, "keyframe_spacing_deg": self.keyframe_spacing_deg,
                "max_keyframes": self.max_keyframes,
                "keyframe_band_deg": self.keyframe_band_deg,
                "min_keyframe_samples": self.min_keyframe_samples,
                "min_keyframe_coverage": self.min_keyframe_coverage,
                "min_difference_deg": self.min_difference_deg,
                "min_local_difference_deg": self.min_local_difference_deg,
                "min_held": self.min_held, "min_inside": self.min_inside,
                "alpha_deg": self.alpha_deg,
                "max_vertices": self.max_vertices, "slow_insets": self.slow_insets,
                **({"kinds": dict(self.kinds)} if self.kinds else {})}

    # -- the parts --------------------------------------------------------------------------
    def _joint_extractor(self, spec, name: str, *, max_vertices: int | None = None,
                         by_swing: bool | str = "auto"):
        return joint_extractor(spec.name, limb_axis=spec.limb_axis, alpha_deg=self.alpha_deg,
                               max_vertices=max_vertices or self.max_vertices,
                               by_swing=by_swing, name=name, kind=spec.kind)

    def _fit_joint(self, ex, spec, q, t, status, insets=None):
        """``ex`` fitted on one joint's (or keyframe's) samples with the joint's measured slow
        error (and a keyframe with its joint's measured ``insets``); the largest swing and
        twist insets that error made it apply are remembered (``_tolerance``)."""
        slow = self._slow.get(spec.name)
        fit_joint(ex, q, t=t, status=status, slow_error_deg=slow, slow_insets=self.slow_insets,
                  insets=insets)  # without slow_insets: the error's twist reach alone
        if not self.slow_insets:
            return ex
        if slow:  # a hinge's two ends; a swing joint's region, and its twist's two ends
            cap = NOISE_REACH * slow
            sw, tw = self._applied[spec.name]
            sw = max(sw, min(float(np.max(ex.inset_deg_)), cap))
            twist = getattr(ex, "twist_inset_deg_", None)
            if twist is not None:
                tw = max(tw, min(max(twist), cap))
            self._applied[spec.name] = (sw, tw)
        return ex

    def _tolerance(self, spec, q: np.ndarray | None = None, slack_deg: float = 1.0):
        """How far outside a joint's limits a recorded posture still counts as held (tests
        2-3), radians: ``(swing, whole)`` — its direction within 1° plus the largest swing
        inset its measured slow error made the extraction apply of the swing limits, and its
        orientation within that plus the largest twist inset and, for each of the postures
        ``q`` (N, 4) when given, the reach the error has on its twist at its swing
        (:func:`calibration.boundary.twist.singular_reach`; module doc, "Measured errors").
        Without a measured error both are 1° (``slack_deg``; 0: what the limb file holds
        within the measured error alone, ``held_``)."""
        sw, tw = self._applied.get(spec.name, (0.0, 0.0))
        swing_tol = np.radians(slack_deg + sw)
        whole = swing_tol + np.radians(tw)
        slow = self._slow.get(spec.name)
        if q is None or not slow or not get_kind(spec.kind).swing_twist:
            return swing_tol, whole
        axis = np.asarray(spec.limb_axis, dtype=np.float64)
        swing = np.arccos(np.clip(Q.rotate(q, axis) @ axis, -1.0, 1.0))
        return swing_tol, whole + singular_reach(swing, slow)

    def _held(self, limb, j: int, q: np.ndarray, tol) -> np.ndarray:
        """(N,) bool: the postures ``q`` (N, 3, 4) whose joint ``j`` the limb file holds within
        ``tol`` (:meth:`_tolerance`): the whole orientation within its tolerance and, with a
        measured error, the direction within the swing's."""
        swing_tol, whole = tol
        held = ConstraintOracle(limb).evaluate(q, normalize=True).distance[:, j] <= whole
        if not (self.slow_insets and self._slow.get(limb.joints[j].name)):
            return held
        wide = _swing_only_limb(limb, j)
        return held & (ConstraintOracle(wide).evaluate(q, normalize=True).distance[:, j]
                       <= swing_tol)

    def _keyframe_angles(self, lo: float, hi: float) -> np.ndarray:
        k = int(min(self.max_keyframes, np.floor((hi - lo) / self.keyframe_spacing_deg) + 1))
        return np.linspace(lo, hi, k) if k >= 2 else np.array([0.5 * (lo + hi)])

    def fit(self, q, *, t=None, status=None, side: str | None = None,
            provenance: dict | None = None,
            slow_error_deg: dict[str, float | None] | None = None) -> LimbExtractor:
        """Extract the limb (module doc) from postures ``q`` (N, 3, 4), sample times ``t``
        (N,) and IMU ``status`` bytes (N,) when known (a sample's lowest over its sensors);
        ``slow_error_deg``: joint name → its measured slow error, degrees (module doc,
        "Measured errors"); a limb of one joint: postures (N, 1, 4) or (N, 4)."""
        if isinstance(self.limb, tuple):
            return self._fit_one(q, t=t, status=status, provenance=provenance,
                                 slow_error_deg=slow_error_deg)
        q = np.asarray(q, dtype=np.float64)
        if q.ndim != 3 or q.shape[1:] != (3, 4):
            raise CalibrationError(f"expected postures of shape (N, 3, 4), got {q.shape}")
        chain = LIMB_CHAINS[self.limb]
        specs = [_with_kind(JOINTS[name], self.kinds.get(name)) for name, _, _ in chain]
        prox, hinge, dist = specs
        slow = dict(slow_error_deg or {})
        unknown = sorted(set(slow) - {s.name for s in specs})
        if unknown:
            raise ValueError(f"slow_error_deg: no joint {', '.join(unknown)} in the {self.limb}")
        self._slow = {s.name: (float(slow[s.name]) if slow.get(s.name) else None)
                      for s in specs}
        self._applied = {s.name: (0.0, 0.0) for s in specs}
        self.reports_: dict[str, dict] = {}
        constraints: dict[str, Any] = {}
        for spec in (hinge, dist):
            ex = self._fit_joint(self._joint_extractor(spec, spec.name), spec,
                                 q[:, specs.index(spec)], t, status)
            constraints[spec.name] = ex.constraint_
            self.reports_[spec.name] = ex.report()
        h, theta = _coupling_angles(hinge, constraints[hinge.name], q[:, 1])
        ts = None if t is None else np.asarray(t)
        st = None if status is None else np.asarray(status)
        # the proximal joint's coupling first, then the distal one's with the proximal's
        # decided (each test measures the limb file it would write)
        kept: dict[int, list] = {}
        self.couplings_: dict[str, dict[str, Any]] = {}
        for j in (0, 2):
            spec = specs[j]
            if not get_kind(spec.kind).swing_twist:  # the hinge: the couplings' source
                continue
            found, info = self._coupling(j, chain, specs, constraints, q, ts, st, theta, h,
                                         kept, side, provenance)
            self.couplings_[spec.name] = info
            if found is not None:
                kept[j] = found
            elif spec.name not in constraints:  # uncoupled (the distal joint's is in hand)
                ex = self._fit_joint(self._joint_extractor(spec, spec.name), spec, q[:, j], t,
                                     status)
                constraints[spec.name] = ex.constraint_
                self.reports_[spec.name] = ex.report()
        first = self.couplings_[prox.name]
        self.coupled_ = first["coupled"]
        self.coupling_note_ = first["note"]
        self.keyframes_ = first["keyframes"]
        self.difference_deg_ = first["difference_deg"]
        self.limb_ = self._limb(chain, specs, constraints, kept, side, provenance)
        # what the file holds, measured on it
        valid = ConstraintOracle(self.limb_).evaluate(q, normalize=True).valid
        ok = np.stack([(theta >= h.min_deg) & (theta <= h.max_deg)
                       if s.hinge_axis is not None
                       else valid[:, i] for i, s in enumerate(specs)], axis=1)
        self.inside_ = {s.name: float(np.mean(ok[:, i])) for i, s in enumerate(specs)}
        self.inside_["limb"] = float(np.mean(ok.all(axis=1)))
        # ... and within what the measured error explains at each posture (no slack)
        held = np.stack([ok[:, i] if not get_kind(s.kind).swing_twist else ok[:, i] | self._held(
            self.limb_, i, q, self._tolerance(s, q[:, i], slack_deg=0.0))
            for i, s in enumerate(specs)], axis=1)
        self.held_ = {s.name: float(np.mean(held[:, i])) for i, s in enumerate(specs)}
        self.held_["limb"] = float(np.mean(held.all(axis=1)))
        self.tolerance_deg_ = {s.name: [float(np.degrees(x)) for x in self._tolerance(s)]
                               for s in specs}
        return self

    def _fit_one(self, q, *, t=None, status=None, provenance: dict | None = None,
                 slow_error_deg: dict[str, float | None] | None = None) -> LimbExtractor:
        """A limb of one joint: its one extraction (:mod:`calibration.extraction.joint`)."""
        (joint,) = self.limb
        if getattr(q, "ndim", 2) == 3:
            if q.shape[1] != 1:
                raise CalibrationError(f"expected postures of one joint, got {q.shape}")
            q = q[:, 0]
        slow = dict(slow_error_deg or {})
        unknown = sorted(set(slow) - {joint}, key=str)
        if unknown:
            raise ValueError(f"slow_error_deg: no joint {', '.join(map(str, unknown))} in a "
                             f"limb of the {joint}")
        ex = joint_extractor(joint, limb_axis=self.limb_axis, alpha_deg=self.alpha_deg,
                             max_vertices=self.max_vertices, by_swing=self.by_swing,
                             name=self.name, kind=self.kind)
        fit_joint(ex, q, status=status, t=t, provenance=provenance,
                  slow_error_deg=slow.get(joint), slow_insets=self.slow_insets)
        self.extractors_ = {joint: ex}
        self.constraint_ = ex.constraint_
        self.limb_ = None
        return self

    def _coupling(self, j, chain, specs, constraints, q, ts, st, theta, h, fixed, side,
                  provenance) -> tuple[list | None, dict[str, Any]]:
        """Joint ``j``'s limits against the hinge's angle, when the recording supports them
        (module doc, tests 1-3), the couplings already decided (``fixed``: joint index →
        keyframes) in the limb file it is judged in: (keyframes or None, what was found)."""
        spec, hinge = specs[j], specs[1]
        at = self._keyframe_angles(h.min_deg, h.max_deg)
        keyframes = [self._support(a, theta, q[:, j], spec) for a in at]
        info: dict[str, Any] = {"coupled": False, "keyframes": keyframes,
                                "difference_deg": 0.0, "local_difference_deg": 0.0}
        supported = [k for k in keyframes if k["supported"]]
        cells = _cells(theta, [float(k["at_deg"]) for k in supported])
        note = f"{len(supported)} supported keyframe(s) of {len(at)} (need 2)"
        # smoother keyframe boundaries (fewer vertices) when the interpolation between two of
        # them would cross itself, as long as smoothing moves them less than the dependence
        # the test resolves (min_difference_deg)
        budgets = dict.fromkeys((self.max_vertices, min(self.max_vertices, 32), 16))
        full: dict[float, Any] | None = None  # the keyframes at the full vertex budget
        for budget in budgets if len(supported) >= 2 else ():
            kept = self._keyframes(spec, j, q, ts, st, supported, cells, budget)
            if len(kept) < 2:
                note = f"{len(kept)} keyframe(s) could be extracted (need 2)"
                break
            if full is None:
                full = dict(kept)
            else:
                smooth = max((boundary_distance(c, full[a])["mean_deg"] for a, c in kept
                              if a in full), default=0.0)
                if smooth >= self.min_difference_deg:
                    note = (f"keyframes smoothed to {budget} vertices (the interpolation "
                            f"between the recorded ones crosses itself) would lie up to "
                            f"{smooth:.1f} deg from them (>= {self.min_difference_deg:g} "
                            f"deg, the smallest dependence on the {hinge.name} this test "
                            "tells)")
                    break
            pairs = {(i, k): boundary_distance(kept[i][1], kept[k][1])
                     for i in range(len(kept)) for k in range(i + 1, len(kept))}
            diff = max(d["mean_deg"] for d in pairs.values())
            local = _local_difference(pairs, len(kept), self.min_local_difference_deg)
            info["difference_deg"], info["local_difference_deg"] = float(diff), float(local)
            if diff < self.min_difference_deg and local < self.min_local_difference_deg:
                note = (f"keyframe boundaries differ by at most {diff:.1f} deg on average "
                        f"(< {self.min_difference_deg:g}) and "
                        + (f"{local:.1f} deg along 5 % of them (< "
                           f"{self.min_local_difference_deg:g})" if local > 0 else
                           "locally not step by step with the hinge angle (a keyframe whose "
                           "samples fell short of part of the limit)")
                        + f": no dependence on the {hinge.name}")
                break
            sup, unfolded = supported, []
            try:
                limb = self._limb(chain, specs, constraints, {**fixed, j: kept}, side,
                                  provenance)
            except ConstraintError as err:
                found = self._unfold(j, chain, specs, constraints, q, ts, st, theta, supported,
                                     kept, budget, fixed, side, provenance)
                if found is None:
                    note = f"keyframes could not be interpolated ({err})"
                    continue
                sup, kept, limb, unfolded = found
            tol = self._tolerance(spec, q[:, j])
            held = float(np.mean(self._held(limb, j, q, tol)
                                 | _held_by_keyframes(q[:, j], theta, kept, tol,
                                                      self.slow_insets
                                                      and bool(self._slow.get(spec.name)))))
            if held < self.min_held:
                note = (f"the coupled limits and their keyframes would hold {100 * held:.1f} % "
                        f"of the recorded postures within {np.degrees(tol[0]):.1f} deg (< "
                        f"{100 * self.min_held:g} %): "
                        "the recording shows where the "
                        f"{spec.name} went at each {hinge.name} angle, not a limit that depends "
                        "on it")
                break
            kept, limb, held, added = self._refine(j, chain, specs, constraints, q, ts, st,
                                                   theta, sup, kept, limb, budget,
                                                   fixed, side, provenance)
            added = [*unfolded, *added]
            if held < self.min_held:
                note = (f"the coupled limits would hold {100 * held:.1f} % of the recorded "
                        f"postures within {np.degrees(tol[0]):.1f} deg "
                        f"(< {100 * self.min_held:g} %) with "
                        f"{len(kept)} keyframes: the interpolation between them, or keyframes "
                        "extracted from too few samples, cut the recorded range")
                break
            kept, limb, inside, grown = self._grow(j, chain, specs, constraints, q, ts, st,
                                                   theta, kept, limb, budget, fixed, side,
                                                   provenance)
            if inside < self.min_inside:
                note = (f"the coupled limits would hold {100 * inside:.2f} % of the recorded "
                        f"postures (< {100 * self.min_inside:g} %; the {spec.name} alone holds "
                        "them all) with the postures they left out added to the keyframes "
                        "that bracket them: their interpolation cuts the recorded range")
                break
            info["coupled"] = True
            info["grown"] = grown
            info["keyframes"] = sorted([*keyframes, *added], key=lambda x: x["at_deg"])
            info["note"] = (f"{len(kept)} keyframes, boundaries differing by up to {diff:.1f} "
                            f"deg on average, {local:.1f} deg along 5 % of them"
                            + ("" if budget == self.max_vertices else f", {budget} vertices "
                               "each")
                            + (f"; {grown} postures the interpolation left out added to the "
                               "keyframes bracketing them" if grown else ""))
            return kept, info
        info["note"] = note
        return None, info

    def _support(self, a: float, theta: np.ndarray, q0: np.ndarray, prox) -> dict[str, Any]:
        """A candidate keyframe at hinge angle ``a``: its samples within the band, their
        coverage all round, and whether that supports it (module doc, test 1)."""
        sel = np.abs(theta - a) <= self.keyframe_band_deg
        info: dict[str, Any] = {"at_deg": round(float(a), 3), "samples": int(sel.sum()),
                                "coverage": None, "supported": False}
        if sel.sum() >= self.min_keyframe_samples:
            share = _sector_share(Q.rotate(q0[sel], np.asarray(prox.limb_axis)))
            info["coverage"] = round(float(share), 3)
            info["supported"] = bool(share >= self.min_keyframe_coverage)
        return info

    def _unfold(self, j, chain, specs, constraints, q, ts, st, theta, supported, kept, budget,
                fixed, side, provenance):
        """Keyframes of joint ``j`` added half-way between two whose interpolation touches
        itself (the limb file would not read), where the recording supports one (test 1) and
        the two are at least twice ``keyframe_band_deg`` apart: ``(supported, kept, limb,
        added)`` once the file reads, else None (the keyframes are then smoothed instead)."""
        spec = specs[j]
        added: list[dict] = []
        while len(kept) < 2 * self.max_keyframes:
            i = _folding_pair(kept)
            if i is None:
                return None  # not a fold: something else keeps the file from reading
            a0, a1 = kept[i][0], kept[i + 1][0]
            if a1 - a0 < 2 * self.keyframe_band_deg:
                return None
            found = self._with_keyframe(j, spec, q, ts, st, theta, supported,
                                        0.5 * (a0 + a1), budget)
            if found is None:
                return None
            info, trial, new = found
            info["added"] = True
            info["why"] = "the interpolation between its neighbours touched itself"
            added.append(info)
            supported, kept = trial, new
            try:
                limb = self._limb(chain, specs, constraints, {**fixed, j: kept}, side,
                                  provenance)
            except ConstraintError:
                continue
            return supported, kept, limb, added
        return None

    def _with_keyframe(self, j, spec, q, ts, st, theta, supported, at: float, budget):
        """A candidate keyframe of joint ``j`` at hinge angle ``at`` added to ``supported``:
        ``(its info, the keyframes' infos, their (angle, constraint))`` with the samples shared
        out again, or None when the recording does not support one there (test 1) or a
        keyframe does not extract."""
        info = self._support(at, theta, q[:, j], spec)
        if not info["supported"]:
            return None
        trial = sorted([*supported, info], key=lambda x: x["at_deg"])
        new = self._keyframes(spec, j, q, ts, st, trial,
                              _cells(theta, [float(x["at_deg"]) for x in trial]), budget)
        return None if len(new) != len(trial) else (info, trial, new)

    def _refine(self, j, chain, specs, constraints, q, ts, st, theta, supported, kept, limb,
                budget, fixed, side, provenance):
        """Keyframes of joint ``j`` added half-way between two whose interpolation leaves
        recorded postures more than 1° out (module doc), while fewer than ``min_held`` are
        held and the recording supports one there; each addition kept only if the file then
        holds more."""

        spec = specs[j]
        tol = self._tolerance(spec, q[:, j])

        def holds(lb) -> tuple[np.ndarray, float]:
            out = ~self._held(lb, j, q, tol)
            return out, float(np.mean(~out))

        out, held = holds(limb)
        added: list[dict] = []
        while held < self.min_held and len(kept) < 2 * self.max_keyframes:
            a = np.array([angle for angle, _ in kept])
            between = (theta > a[0]) & (theta < a[-1]) & out
            k = np.searchsorted(a, theta[between], side="right") - 1
            counts = np.bincount(k, minlength=len(a) - 1)
            i = int(np.argmax(counts))  # the interval leaving most out
            if counts[i] == 0 or a[i + 1] - a[i] < 2 * self.keyframe_band_deg:
                break
            found = self._with_keyframe(j, spec, q, ts, st, theta, supported,
                                        0.5 * (a[i] + a[i + 1]), budget)
            if found is None:
                break
            info, trial, new = found
            try:
                new_limb = self._limb(chain, specs, constraints, {**fixed, j: new}, side,
                                      provenance)
            except ConstraintError:
                break
            new_out, new_held = holds(new_limb)
            if new_held <= held:
                break
            info["added"] = True
            added.append(info)
            supported, kept, limb, out, held = trial, new, new_limb, new_out, new_held
        return kept, limb, held, added

    def _grow(self, j, chain, specs, constraints, q, ts, st, theta, kept, limb, budget, fixed,
              side, provenance):
        """Joint ``j``'s keyframes extracted again, each from its own samples plus the recorded
        postures in its span (:func:`_spans`) that the coupled limits leave out — within
        nothing but their measured error (:meth:`_tolerance` without the 1° slack) —, until
        they hold ``min_inside`` of the postures (at most 3 rounds): ``(kept, limb, share
        held, postures added)``. A keyframe built from its nearest samples alone is evidence
        for one of the two keyframes a posture is interpolated from: the other may leave it
        out (a keyframe at the hinge's end, from the few samples there, had a slit cut in to
        neutral; simulated legs: the ankle 93.7 % held)."""
        spec = specs[j]
        tol = self._tolerance(spec, q[:, j], slack_deg=0.0)
        extra = np.zeros(len(theta), dtype=bool)
        grown = 0
        inside = float(np.mean(self._held(limb, j, q, tol)))
        for _ in range(_GROW_ROUNDS):
            if inside >= self.min_inside:
                break
            extra |= ~self._held(limb, j, q, tol)
            at = [a for a, _ in kept]
            cells = [c | (extra & sp) for c, sp in zip(_cells(theta, at), _spans(theta, at),
                                                        strict=True)]
            infos = [{"at_deg": a} for a in at]
            new = self._keyframes(spec, j, q, ts, st, infos, cells, budget)
            if len(new) != len(kept):
                break
            try:
                new_limb = self._limb(chain, specs, constraints, {**fixed, j: new}, side,
                                      provenance)
            except ConstraintError:
                break
            new_inside = float(np.mean(self._held(new_limb, j, q, tol)))
            if new_inside <= inside:
                break
            kept, limb, inside, grown = new, new_limb, new_inside, int(extra.sum())
        return kept, limb, inside, grown

    def _keyframes(self, spec, j, q, ts, st, supported, cells, budget) -> list:
        """(angle, constraint) of each supported keyframe of joint ``j`` whose samples
        (``cells``) extract; with a measured slow error, extracted again with the insets
        pooled over the keyframes (module doc, "Measured errors")."""
        kept, fitted = self._keyframes_once(spec, j, q, ts, st, supported, cells, budget)
        slow = self._slow.get(spec.name)
        if slow and self.slow_insets and len(fitted) >= 2:
            pooled = (float(np.median([ex.inset_deg_ for ex in fitted])),
                      pooled_insets([ex.twist_envelope_ for ex in fitted],
                                    fitted[0].twist_settings(), slow))
            kept, _ = self._keyframes_once(spec, j, q, ts, st, supported, cells, budget,
                                           insets=pooled)
        return kept

    def _keyframes_once(self, spec, j, q, ts, st, supported, cells, budget,
                        insets=None) -> tuple[list, list]:
        kept, fitted = [], []
        for info, sel in zip(supported, cells, strict=True):
            ex = self._joint_extractor(spec, f"{spec.name}-at-{info['at_deg']:.0f}",
                                       max_vertices=budget, by_swing=False)
            try:
                self._fit_joint(ex, spec, q[sel, j], None if ts is None else ts[sel],
                                None if st is None else st[sel], insets=insets)
            except CalibrationError as err:
                info["error"] = str(err)
                continue
            info.pop("error", None)
            kept.append((float(info["at_deg"]), ex.constraint_))
            fitted.append(ex)
        return kept, fitted

    def _limb(self, chain, specs, constraints, kept: dict[int, list], side, provenance):
        """The limb file's contents as a validated :class:`models.limb.Limb`; ``kept``: the
        coupled joints' keyframes by joint index."""
        hinge = specs[1]
        joints = []
        for j, (name, parent, child) in enumerate(chain):
            entry: dict[str, Any] = {"name": name, "parent": parent, "child": child}
            if j in kept:
                entry["coupled"] = {"by": hinge.name, "keyframes": [
                    {"at_deg": a, "constraint": inline_constraint(c)} for a, c in kept[j]]}
            else:
                entry["constraint"] = inline_constraint(constraints[name])
            joints.append(entry)
        prov = dict(provenance or {})
        prov.update({"method": METHOD, "parameters": self.params(),
                     "couplings": {k: {"coupled": v["coupled"], "keyframes": v["keyframes"]}
                                   for k, v in self.couplings_.items()}})
        doc = {"name": self.name, "limb": self.limb, "joints": joints, "provenance": prov}
        if side is not None:
            doc["side"] = side
        return Limb.from_dict(doc, source="extracted limb")

    def report(self) -> dict[str, Any]:
        """What the extraction did, as plain types (``coupled``/``coupling``/``keyframes``:
        the proximal joint's; ``couplings``: every joint's that was tested; a limb of one
        joint: its extractor's report)."""
        if isinstance(self.limb, tuple):
            return self.extractors_[self.limb[0]].report()
        return {"limb": self.limb, "coupled": self.coupled_, "coupling": self.coupling_note_,
                "keyframes": self.keyframes_, "inside": dict(self.inside_),
                "held": dict(self.held_),
                "tolerance_deg": dict(self.tolerance_deg_),
                "couplings": {k: dict(v) for k, v in self.couplings_.items()},
                "joints": self.reports_}


@dataclass(frozen=True)
class _Interval:
    """The coupling angle's interval, degrees."""

    min_deg: float
    max_deg: float


def _with_kind(spec: JointSpec, kind: str | None) -> JointSpec:
    """``spec`` extracted as ``kind`` (None: its own); a hinge axis only for its own hinge."""
    if kind is None or kind == spec.kind:
        return spec
    return replace(spec, kind=kind, hinge_axis=None)


def _coupling_angles(source: JointSpec, constraint, q: np.ndarray
                     ) -> tuple[_Interval, np.ndarray]:
    """The couplings' source joint's interval and angle at each posture (degrees, (N,)): a
    hinge's about its own axis (:func:`calibration.joints.hinge_angles`), another kind's as
    the kind reads it (a forearm's flexion, :meth:`models.kinds.JointKind.coupling_angle`)."""
    if source.hinge_axis is not None:
        h = constraint.hinge
        return _Interval(h.min_deg, h.max_deg), hinge_angles(q, source.hinge_axis)
    kind = get_kind(source.kind)
    lo, hi = np.degrees(kind.coupling_range(constraint))
    qn = Q.check_quaternions(np.atleast_2d(q), normalize=True, name="joint orientation")
    return _Interval(float(lo), float(hi)), np.degrees(kind.coupling_angle(constraint, qn))


def _sector_share(d: np.ndarray, sectors: int = 12, min_samples: int = 5) -> float:
    """Share of the ``sectors`` azimuth sectors about the mean of directions ``d`` (N, 3) that
    hold at least ``min_samples`` of them (0 when the directions average out)."""
    m = d.mean(axis=0)
    if np.linalg.norm(m) < 1e-6:
        return 0.0
    c = m / np.linalg.norm(m)
    e1 = Q.perpendicular(c)
    e2 = Q.cross(c, e1)
    az = np.arctan2(d @ e2, d @ e1)
    k = np.floor((az + np.pi) / (2 * np.pi) * sectors).astype(int) % sectors
    return float(np.mean(np.bincount(k, minlength=sectors) >= min_samples))


def _held_by_keyframes(q: np.ndarray, theta: np.ndarray, kept: list,
                       tol=(_ONE_DEG, _ONE_DEG), measured: bool = False) -> np.ndarray:
    """(N,) bool: the postures ``q`` (N, 4) of the proximal joint within ``tol`` (radians,
    ``(swing, whole)``: :meth:`LimbExtractor._tolerance`; the swing's checked when the error
    was ``measured``) of both keyframes that bracket their hinge angle ``theta`` (beyond the
    end keyframes: of the end one).

    Such a posture may still lie outside the limits interpolated between the two keyframes
    (where the limits are not linear in the angle, or the interpolation cuts a corner of a
    shared stretch): the file format's interpolation, not evidence against the coupling
    (module doc, test 3)."""
    a = np.array([angle for angle, _ in kept])
    swing_tol, whole = tol
    near = np.stack([ConstraintOracle(c).signed_distance(q, normalize=True) <= whole
                     for _, c in kept], axis=1)
    if measured:
        near &= np.stack([ConstraintOracle(_swing_only(c)).signed_distance(q, normalize=True)
                          <= swing_tol for _, c in kept], axis=1)
    k = np.clip(np.searchsorted(a, theta, side="right") - 1, 0, len(a) - 2)
    rows = np.arange(len(q))
    both = near[rows, k] & near[rows, k + 1]
    return np.where(theta < a[0], near[:, 0], np.where(theta > a[-1], near[:, -1], both))


def _local_difference(pairs: dict[tuple[int, int], dict], n: int, threshold: float) -> float:
    """The keyframes' local difference (module doc, test 2): the largest ``p95_deg`` between
    two of them (keyframes in the order of their hinge angle), when the differences are
    graded — a dependence on the hinge moves the limits step by step, so for keyframes
    ``i < m < k`` the difference ``i``–``k`` is at least the larger of ``i``–``m`` and
    ``m``–``k`` less half the threshold — and not one keyframe's alone (with three or more,
    one that differs from every other by ``threshold`` or more while the others agree to
    within half of it). Otherwise 0: the differences are keyframes' samples falling short of
    part of the limit, not a dependence."""
    top = max(d["p95_deg"] for d in pairs.values())
    if n < 3:
        return top
    p = {key: d["p95_deg"] for key, d in pairs.items()}
    slack = 0.5 * threshold
    for i in range(n):
        for m in range(i + 1, n):
            for k in range(m + 1, n):
                if p[i, k] < max(p[i, m], p[m, k]) - slack:
                    return 0.0
    for out in range(n):
        mine = [v for key, v in p.items() if out in key]
        rest = [v for key, v in p.items() if out not in key]
        if min(mine) >= threshold and max(rest) < slack:
            return 0.0
    return top


def _folding_pair(kept: list) -> int | None:
    """The first ``i`` whose keyframes ``kept[i]``, ``kept[i + 1]`` (angle, constraint) have a
    polygon swing interpolation that touches itself (:func:`models.geometry.
    first_contact_along`), else None."""
    for i in range(len(kept) - 1):
        a, b = kept[i][1].swing, kept[i + 1][1].swing
        if isinstance(a, PolygonSwing) and isinstance(b, PolygonSwing):
            if first_contact_along(*corresponding_polygons(a, b)) is not None:
                return i
    return None


def _cells(theta: np.ndarray, at: list[float]) -> list[np.ndarray]:
    """Each keyframe's samples: those whose hinge angle ``theta`` is nearer its angle than any
    other keyframe's (the end keyframes take everything beyond them), so that every recorded
    posture is evidence for the keyframe its limits are interpolated from."""
    a = np.asarray(at, dtype=np.float64)
    mids = 0.5 * (a[1:] + a[:-1])
    k = np.searchsorted(mids, theta)
    return [k == i for i in range(len(a))]


def _spans(theta: np.ndarray, at: list[float]) -> list[np.ndarray]:
    """Each keyframe's span: the samples whose hinge angle ``theta`` lies between its two
    neighbours' angles (the end keyframes': everything beyond them too) — every posture whose
    limits the keyframe is interpolated into (:mod:`models.limb`)."""
    a = np.asarray(at, dtype=np.float64)
    lo = np.concatenate(([-np.inf], a[:-1]))
    hi = np.concatenate((a[1:], [np.inf]))
    return [(theta >= lo[i]) & (theta <= hi[i]) for i in range(len(a))]


def _swing_only(constraint):
    """The constraint with its twist left free: its swing limits alone."""
    d = constraint.to_dict()
    d["kind"] = DEFAULT_KIND
    d["twist"] = {"min_deg": -180.0, "max_deg": 180.0}
    return JointConstraint.from_dict(d)


def _swing_only_limb(limb, j: int):
    """The limb with joint ``j``'s twist left free (its own limits or every keyframe's)."""
    doc = limb.to_dict()
    entry = doc["joints"][j]
    joint = limb.joints[j]
    if "coupled" in entry:
        for kf, c in zip(entry["coupled"]["keyframes"], joint.coupling.keyframes, strict=True):
            kf["constraint"] = inline_constraint(_swing_only(c))
    else:
        entry["constraint"] = inline_constraint(_swing_only(joint.constraint))
    return Limb.from_dict(doc, source="swing limits")
