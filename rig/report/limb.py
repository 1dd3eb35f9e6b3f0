"""The clinician's report of a whole arm or leg: one self-contained HTML page from arrays.

Input: a limb's limits (:class:`models.limb.Limb`, ``docs/limb-format.md``: joints of kind
``ball``, ``hinge`` or ``two-axis``, couplings with keyframes) and the recorded joint
orientations of each of its joints (child relative to parent, rig segment frames,
:mod:`calibration.frames`; scalar-first). :func:`limb_report_data` assembles what the page
shows (:class:`LimbReportData`), :func:`write_limb_report` writes it with the shoulder report's
page mechanism (:mod:`rig.report.page`: the same styles, tables, embedded PNG figures).

Sections, per joint in the limb's order:

- **range of motion** in clinical terms (:mod:`calibration.joint_angles`: ISB / Grood-Suntay
  Cardan angles, left limbs mirrored): the recorded peak per movement
  (:func:`~calibration.joint_angles.recorded_rom`), what the limits allow
  (:func:`~calibration.joint_angles.constraint_rom`), the AAOS normal value and the recorded
  share of it, and every further reference column the normative table or the range-of-motion
  objects carry. A coupled swing joint's allowed range is, movement by movement, the largest
  over its keyframes (:func:`~calibration.joint_angles.allowed_rom`: what it allows at some
  angle of the joint it depends on, as ``rig rom --constraint`` reads it), a coupled hinge's
  the hull of its intervals; the coupling plot shows how the limits change. The shoulder's
  rows are the shoulder report's (:func:`rig.report.page.rom_rows`: the region's and the
  recording's reading, the smaller of the two), beside the region's own reading;
- **ball and two-axis joints**: the recorded directions of the child segment's long axis and
  the limits' swing boundary (each keyframe's, for a coupled joint) on the shoulder report's
  equal-area map (:func:`rig.report.figures.boundary_figure`), labelled with the anatomical
  directions the pure movements point to (:func:`rig.report.figures.joint_directions`:
  ``flexion / anterior``, ``abduction / lateral``, …, mirrored for a left limb); a two-axis
  joint's narrow twist is noted;
- **hinges**: the allowed interval as a bar with the recorded hinge angles' distribution and
  extremes (:func:`calibration.joints.hinge_angles`) and their out-of-axis motion
  (:func:`calibration.joints.off_axis_angles`), the AAOS normal arc beneath;
- **couplings**: the dependent joint's limits on its primary clinical angle (flexion /
  extension for the hip, shoulder and wrist; dorsiflexion / plantarflexion for the ankle; the
  interval of a hinge) against the coupling hinge's angle, evaluated on the limits the limb
  file defines at each angle (:meth:`models.limb.Coupling.at`: the keyframes and their
  interpolation, clamped beyond them), with the recorded postures scattered; a limb without a
  coupling says so in one line.

Then the calibration residuals (:attr:`calibration.limb_calibration.LimbImuCalibration.
residuals_`), the limb model's evaluation (:func:`models.evaluation.evaluate_model`)
against issue 20's targets (:func:`rig.training.verdict.targets_for`), and the warnings
(coverage, an interrupted session) at the top, as the shoulder report shows them.

How a limit on the primary angle α is read from a swing region: α of a ball joint's child
depends on its long axis's direction alone (the first Cardan angle is its sagittal-plane
angle), and on the region's boundary takes its extremes (α has no critical point inside a
region that does not hold the medio-lateral axis), so the limits are α's extremes over the
boundary, densified to 1°, at twists spanning the allowed twist interval (the ankle's α moves
a little with the foot's twist). The shoulder's are read by
:func:`calibration.clinical.range_of_motion` within 5° of the sagittal plane, its recorded
postures likewise.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from calibration.boundary import boundary_distance
from calibration.clinical import range_of_motion
from calibration.clinical_tests import REFERENCES, coupled_measures, measure_sources
from calibration.joint_angles import (
    CLINICAL_MOVEMENTS,
    JOINT_ANGLES,
    NORMATIVE,
    POPULATION,
    UNKNOWN_AGE,
    allowed_rom,
    beyond_reach,
    constraint_rom,
    joint_angles,
    largest_rom,
    not_measured,
    recorded_rom,
)
from calibration.joints import JOINTS, hinge_angles, off_axis_angles
from models import quaternion as Q
from models.geometry import polygon_area
from models.kinds import get_kind
from models.metrics import current_metric_names
from models.oracle import ConstraintOracle
from rig import __version__
from rig.report.figures import (
    boundary_figure,
    coupling_figure,
    hinge_figure,
    joint_directions,
    map_side_of,
    swing_map,
    swing_outline,
)
from rig.report.page import (
    RomRow,
    escape,
    fmt,
    img_tag,
    kv_table,
    page_foot,
    page_head,
    rom_rows,
    rom_table_html,
    verdict_html,
    warnings_html,
    write_page,
)
from rig.training.verdict import evaluation_verdict, judging

__all__ = ["NO_COUPLING", "CouplingSection", "JointSection", "LimbReportData",
           "limb_model_verdict", "limb_report_data", "render_limb_html", "write_limb_report"]

#: The line a limb without a coupling gets.
NO_COUPLING = "No coupling supported by this recording."

_SHOULDER_BAND_DEG = 5.0  # calibration.clinical.range_of_motion's default band
_CURVE_POINTS = 19  # coupling angles a coupling's limits are evaluated at (and its keyframes)
_NEAR_KEYFRAME_DEG = 10.0  # recorded postures "at" a keyframe: hinge within this of its angle

#: Issue 20's targets as the report words them: metric → (label, unit, scale shown).
_TARGET_LABELS: dict[str, tuple[str, str, float]] = {
    "end_mean_3d_error_pct": ("end-point mean 3-D error (% of limb length)", " %", 1.0),
    "frac_invalid_violating_1deg": ("invalid inputs left > 1° outside (%)", " %", 100.0),
    "valid_moved_deg": ("valid inputs moved, mean (°)", "°", 1.0),
    "end_p99_direction_error_deg": ("p99 end-point direction error (°)", "°", 1.0),
    # a one-joint model's (the page of a recording of one joint)
    "mean_3d_error_pct": ("mean 3-D error (%)", " %", 1.0),
    "mean_identity_error_deg": ("valid inputs moved, mean (°)", "°", 1.0),
    "p99_angular_error_deg": ("p99 direction error (°)", "°", 1.0),
}

#: Calibration residuals in the order the table shows them; others follow.
_RESIDUAL_ORDER = ("static", "functional", "range", "gravity", "orthogonality", "axes",
                   "heading")


@dataclass
class JointSection:
    """One joint's part of the report."""

    name: str
    kind: str  # ball, hinge, two-axis
    heading: str
    rom_rows: list[RomRow] = field(default_factory=list)
    rom_note: str | None = None
    figure_png: bytes | None = None
    figure_kind: str | None = None  # "map" (ball, two-axis) or "interval" (hinge)
    facts: dict[str, Any] = field(default_factory=dict)
    #: label → where the anatomical direction lies on the map from its centre (up, left, …)
    map_layout: dict[str, str] = field(default_factory=dict)
    caption: str | None = None


@dataclass
class CouplingSection:
    """One coupling: the dependent joint's limits against the coupling hinge's angle."""

    joint: str
    by: str
    keyframes_deg: tuple[float, ...]
    angle_deg: np.ndarray  # (M,) coupling angles the limits were evaluated at
    lower_deg: np.ndarray  # (M,) the dependent joint's lower limit there (e.g. −extension)
    upper_deg: np.ndarray  # (M,) its upper limit (e.g. flexion)
    movements: tuple[str, str]  # (positive, negative) movement of the plotted angle
    keyframe_rows: list[dict[str, Any]] = field(default_factory=list)
    figure_png: bytes | None = None
    caption: str | None = None


@dataclass
class LimbReportData:
    """Everything the limb report shows; sections with no data are left out."""

    patient: str
    side: str
    limb: str | None
    limb_name: str
    joint_order: tuple[str, ...]
    samples: int
    session_label: str | None = None
    limits_source: str | None = None
    warnings: list[str] = field(default_factory=list)
    simulated: bool = False
    reference_name: str | None = None
    joints: list[JointSection] = field(default_factory=list)
    couplings: list[CouplingSection] = field(default_factory=list)
    coupling_note: str | None = None
    calibration: dict[str, dict[str, float]] = field(default_factory=dict)
    calibration_note: str | None = None
    evaluation_rows: list[dict[str, Any]] = field(default_factory=list)
    evaluation_facts: dict[str, Any] = field(default_factory=dict)
    evaluation_verdict: str | None = None
    software: str | None = None
    #: the progress section's HTML (:func:`rig.report.progress.progress_section_html`)
    progress_html: list[str] = field(default_factory=list)
    #: the coupled clinical tests (:func:`calibration.clinical_tests.coupled_measures`), shown
    #: by default; None: the section is left out (``rig report --no-coupled-tests``)
    coupled_tests: list | None = None
    #: a report from a file (``rig report FILE``): what was read, label → text (the file, its
    #: format, what it was read from, frames, rate, duration), shown in the header instead of
    #: the patient and the session (a file names no patient: none is invented)
    from_file: dict[str, str] = field(default_factory=dict)


# ---------------------------------------------------------------------------------------------
# Reading limits and recordings in clinical angles
# ---------------------------------------------------------------------------------------------
def _title(name: str) -> str:
    return name.replace("_", " ").capitalize()


def _movements(name: str) -> tuple[str, str]:
    """(positive, negative) movement of a joint's primary angle."""
    if name in JOINT_ANGLES:
        return JOINT_ANGLES[name].movements[0]
    return ("flexion", "extension")


def _clinical_hinge(name: str, axis) -> bool:
    """Is this hinge's angle the joint's clinical flexion (its axis the rig's, either side)?"""
    spec = JOINTS.get(name)
    return (spec is not None and spec.hinge_axis is not None
            and bool(np.allclose(np.asarray(axis, float), spec.hinge_axis, atol=1e-6)))


def _kind_words(name: str) -> str:
    """How a sentence names the kind of the joint called ``name`` ("joint" when unknown)."""
    kind = _kind_of(name)
    return "joint" if kind is None else get_kind(kind).words


def _kind_of(name: str) -> str | None:
    """The kind :data:`calibration.joints.JOINTS` gives a joint of this name (None: unknown)."""
    spec = JOINTS.get(name)
    return None if spec is None else spec.kind


def _swing_area(c) -> float:
    sw = c.swing
    if sw is None:
        return 4.0 * math.pi
    if hasattr(sw, "vertices"):
        return polygon_area(sw.vertices, sw.interior)
    return 2.0 * math.pi * (1.0 - math.cos(sw.radius))


def _widest(joint) -> tuple[Any, float | None]:
    """The limits a joint's allowed range is read at: its own, a coupled hinge's hull, or a
    coupled swing joint's widest keyframe (and that keyframe's angle)."""
    if joint.coupling is None:
        return joint.constraint, None
    if get_kind(joint.kind).single_axis:
        return joint.loosest(), None
    kf = joint.coupling.keyframes
    k = int(np.argmax([_swing_area(c) for c in kf]))
    return kf[k], float(joint.coupling.at_deg[k])


def _limits_at(joint, angle_deg: float):
    """A limb joint's limits at one coupling angle (its own when it has no coupling)."""
    return joint.constraint if joint.coupling is None else joint.coupling.at(float(angle_deg))


def _centre(swing) -> np.ndarray | None:
    if swing is None:
        return None
    c = getattr(swing, "interior", None)
    return np.asarray(c if c is not None else swing.centre, dtype=np.float64)


_ROM_CACHE: dict[str, Any] = {}


def _constraint_rom(constraint, name: str, side: str):
    """:func:`calibration.joint_angles.constraint_rom`, remembered per limits (a few seconds
    per swing joint; a limb's report asks again for the same limits when it is redrawn)."""
    key = json.dumps([name, side, _rounded(constraint.to_dict())], sort_keys=True)
    if key not in _ROM_CACHE:
        if len(_ROM_CACHE) > 64:
            _ROM_CACHE.clear()
        _ROM_CACHE[key] = constraint_rom(constraint, name, side)
    return _ROM_CACHE[key]


def _rounded(value: Any) -> Any:
    if isinstance(value, float):
        return round(value, 9) + 0.0
    if isinstance(value, dict):
        return {k: _rounded(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_rounded(v) for v in value]
    return value


def _primary_limits(c, name: str, side: str) -> tuple[float, float]:
    """(lower, upper) of a joint's primary clinical angle (degrees) under limits ``c`` (module
    doc); NaN where the limits do not bound it."""
    if c.joint_kind.single_axis:
        return float(c.hinge.min_deg), float(c.hinge.max_deg)
    if name == "shoulder":
        r = range_of_motion(c, side)
        return (math.nan if r.extension is None else -r.extension,
                math.nan if r.flexion is None else r.flexion)
    if name not in JOINT_ANGLES or c.swing is None:
        return math.nan, math.nan
    axis = np.asarray(c.limb_axis, dtype=np.float64)
    d = swing_outline(c.swing)
    twists = (np.linspace(c.twist.min, c.twist.max, 5) if c.twist is not None
              and c.twist.by_swing is None else np.radians(np.arange(-180.0, 180.0, 10.0)))
    swing = Q.from_two_vectors(np.broadcast_to(axis, d.shape), d)
    tw = Q.from_axis_angle(axis, twists)
    q = Q.multiply(np.repeat(swing, len(tw), axis=0), np.tile(tw, (len(swing), 1)))
    alpha = joint_angles(q, name, side)["alpha"]
    return float(alpha.min()), float(alpha.max())


def _primary_angles(q: np.ndarray, name: str, side: str, joint) -> tuple[np.ndarray,
                                                                       np.ndarray]:
    """The primary clinical angle (degrees) of recorded orientations ``q`` (N, 4) and which
    samples it is read at (the shoulder's: within the sagittal band)."""
    every = np.ones(len(q), dtype=bool)
    if get_kind(joint.kind).single_axis:
        return hinge_angles(q, joint.loosest().hinge.axis), every
    d = Q.limb_direction(q, np.asarray(joint.limb_axis, dtype=np.float64))
    if name == "shoulder":
        band = np.abs(d[:, 2]) <= math.sin(math.radians(_SHOULDER_BAND_DEG))
        return np.degrees(np.arctan2(d[:, 1], d[:, 0])), band
    if name in JOINT_ANGLES:
        return joint_angles(q, name, side)["alpha"], every
    return np.full(len(q), np.nan), ~every


# ---------------------------------------------------------------------------------------------
# Range-of-motion rows
# ---------------------------------------------------------------------------------------------
_KNOWN_JSON = ("joint", "side", "arc", "population", "population_values", "population_source",
               "population_for", "not_measured")


def _json_columns(rom_json: Mapping[str, Any], movement: str) -> dict[str, Any]:
    """Reference columns beyond AAOS and the population that a range of motion's plain form
    (:meth:`~calibration.joint_angles.JointRangeOfMotion.to_json`) carries: every entry that
    maps movements to a number or a text."""
    out: dict[str, Any] = {}
    for key, val in rom_json.items():
        if key in _KNOWN_JSON or not isinstance(val, Mapping):
            continue
        v = val.get(movement)
        if isinstance(v, (int, float, str)) and not isinstance(v, bool):
            out[_title(key)] = v
    return out


def _joint_rom_rows(name: str, q: np.ndarray, side: str, limits: list, at: str | None, *,
                    age: float | None, sex: str | None) -> tuple[list[RomRow], str | None]:
    """The range-of-motion rows of one joint (module doc) and the note under them; ``limits``
    its constraint, or a coupled joint's keyframes (the largest over them)."""
    where = f" ({at})" if at else ""
    if name == "shoulder":
        rows = rom_rows(allowed_rom(limits, name, side, directions=Q.limb_direction(
            q, limits[0].limb_axis)), age=None if age is None else int(age), sex=sex)
        allowed = allowed_rom(limits, name, side)
        for r, m in zip(rows, allowed.MOVEMENTS, strict=True):  # rom_rows' order
            r.allowed_deg = getattr(allowed, m)
        return rows, ("Recorded: the farthest reach along each clinical plane (within 5°) of "
                      "the limits and of the recorded directions, the smaller of the two; "
                      f"allowed: the limits' own reach{where}; rotations with the arm at the "
                      "side (Wu et al. 2005 angles, as in the shoulder report). Population: "
                      "Gill et al. 2020.")
    if name not in CLINICAL_MOVEMENTS:
        return [], f"No clinical angles are defined for a joint named {name!r}."
    rec = recorded_rom(q, name, side)
    allowed = largest_rom([_constraint_rom(c, name, side) for c in limits])
    rec_json = rec.to_json(age=age, sex=sex)
    pop_src = POPULATION.get(name)
    aaos = NORMATIVE["aaos"].get(name, {})
    unmeasured = not_measured(name)
    far = beyond_reach(rec)
    rows = []
    for m in CLINICAL_MOVEMENTS[name]:
        if m in unmeasured:
            rows.append(RomRow(_title(m), None, not_measured=unmeasured[m]))
            continue
        why = NORMATIVE["not_comparable"].get((name, m))
        ref = aaos.get(m)
        pop = (rec_json.get("population") or {}).get(m)
        rows.append(RomRow(_title(m), rec.peaks.get(m), None if why else ref,
                           population=None if pop is None else
                           f"{pop}, {pop_src['short']}" if pop_src else pop,
                           note=None if why is None else
                           f"not compared with AAOS ({fmt(ref, 0)}°): {why}",
                           allowed_deg=allowed.peaks.get(m), extra=_json_columns(rec_json, m),
                           beyond_reach=far[m]["text"] if m in far else None))
    pos, neg = _movements(name)
    arcs = []
    for label, rom in (("recorded", rec), ("allowed", allowed)):
        if rom.arc is not None:
            arcs.append(f"{label} {rom.arc[0]:.1f}° … {rom.arc[1]:.1f}°")
    note = ("Recorded: each movement's farthest angle held over 5 samples, read where a "
            "goniometer reads it (calibration.joint_angles.recorded_rom); allowed: the same "
            f"reading of the limits{where} (constraint_rom). Arc of {pos} (negative: {neg}): "
            + "; ".join(arcs) + ".")
    if unmeasured:
        which = " and ".join(m.replace("_", " ") for m in unmeasured)
        note += (f" {which.capitalize()}: the {name} is modelled as a "
                 f"{_kind_words(name)}, which has no such movement "
                 "(not reported, not a deficit).")
    if pop_src is None:
        note += f" No published population values found for the {name}."
    else:
        note += f" Population: {pop_src['cite']} ({pop_src['measured']})"
        note += (f"; age unknown: the band of a {UNKNOWN_AGE}-year-old." if age is None
                 else ".")
    return rows, note


# ---------------------------------------------------------------------------------------------
# Sections
# ---------------------------------------------------------------------------------------------
def _heading(limb, joint) -> str:
    text = f"{_title(joint.name)} — {get_kind(joint.kind).words}"
    if joint.coupling is not None:
        text += f", limits coupled to the {joint.coupling.by}"
    return text


def _interval_text(lo: float, hi: float) -> str:
    return f"{lo:.1f} … {hi:.1f}"


def _swing_section(sec: JointSection, limb, j: int, q: np.ndarray, side: str, result,
                   reference) -> None:
    joint = limb.joints[j]
    axis = np.asarray(joint.limb_axis, dtype=np.float64)
    dirs = Q.limb_direction(q, axis)
    widest, _ = _widest(joint)
    centre = _centre(widest.swing)
    if centre is None:
        centre = dirs.mean(axis=0) if np.linalg.norm(dirs.mean(axis=0)) > 1e-6 else axis
    ref_joint = _reference_joint(reference, joint.name, joint.kind)
    labels = joint_directions(joint.name, side)
    kw: dict[str, Any] = {"centre": centre, "side": side, "labels": labels}
    twist_note = ""
    if joint.coupling is None:
        c = joint.constraint
        kw["outlines"] = [(c.swing, "limits")]
        ref = None if ref_joint is None else _widest(ref_joint)[0]  # a coupled one's widest
        if ref is not None:
            kw["reference_outlines"] = [ref.swing]
        if c.swing is not None and hasattr(c.swing, "vertices"):
            sec.facts["boundary vertices"] = len(c.swing.vertices)
        twists = [c.twist] if c.twist is not None else []
        if ref is not None and c.swing is not None and ref.swing is not None:
            sec.facts["mean distance to the reference boundary (°)"] = boundary_distance(
                c, ref)["mean_deg"]
    else:
        cp = joint.coupling
        kw["outlines"] = [(c.swing, f"limits at {cp.by} {a:.1f}°")
                          for a, c in zip(cp.at_deg, cp.keyframes, strict=True)]
        if ref_joint is not None:
            kw["reference_outlines"] = [_limits_at(ref_joint, a).swing for a in cp.at_deg]
            dist = [boundary_distance(c, r)["mean_deg"]
                    for a, c in zip(cp.at_deg, cp.keyframes, strict=True)
                    if c.swing is not None and (r := _limits_at(ref_joint, a)).swing is not None]
            if dist:
                sec.facts["mean distance to the reference boundary (°)"] = float(np.mean(dist))
        if hasattr(cp.keyframes[0].swing, "vertices"):
            sec.facts["boundary vertices per keyframe"] = ", ".join(
                str(len(c.swing.vertices)) for c in cp.keyframes)
        twists = [c.twist for c in cp.keyframes if c.twist is not None]
    sec.facts = {"recorded postures": len(q),
                 "inside the limits (%)": 100.0 * float(result.valid[:, j].mean()),
                 "within 1° of them (%)": 100.0 * float(
                     (result.distance[:, j] <= math.radians(1.0)).mean()),
                 **sec.facts}
    rec_tw = np.degrees(Q.twist_angle(q, axis))
    intervals = [t for t in twists if t.by_swing is None]
    if intervals:  # a coupled joint's: the hull of its keyframes' intervals
        lo, hi = min(t.min_deg for t in intervals), max(t.max_deg for t in intervals)
        sec.facts["twist allowed (°)"] = _interval_text(lo, hi)
        if get_kind(joint.kind).narrow_twist:
            twist_note = f"; narrow twist {_interval_text(lo, hi)}°"
    else:
        sec.facts["twist allowed"] = ("depends on the direction (by_swing table)" if twists
                                      else "free")
    sec.facts["twist recorded (°)"] = _interval_text(float(rec_tw.min()), float(rec_tw.max()))
    child = limb.joints[j].child
    kind = (f"{get_kind(joint.kind).words}: swing region" if get_kind(joint.kind).narrow_twist
            else "swing region")
    kw["title"] = (f"{_title(joint.name)} ({side}): the {child}'s direction, {kind}"
                   f"{twist_note}")
    sec.figure_png = boundary_figure(dirs, None, **kw)
    sec.figure_kind = "map"
    m = swing_map(centre, side)
    sec.map_layout = {label: map_side_of(m, d) for label, d in labels.items()}
    placed = [f"{label} {where}" for label, where in sec.map_layout.items()
              if where in ("up", "down", "left", "right")]
    sec.caption = (f"Equal-area map of the {child}'s long axis in the {joint.parent}'s frame, "
                   f"seen from outside ({side} side): " + "; ".join(placed) + "."
                   + (f" The {joint.name} is a two-axis joint: its twist about the "
                      f"{child}'s long axis is narrow (twist allowed "
                      f"{sec.facts.get('twist allowed (°)', '?')}°)."
                      if get_kind(joint.kind).narrow_twist else ""))


def _hinge_section(sec: JointSection, limb, j: int, q: np.ndarray, side: str, result,
                   reference) -> None:
    joint = limb.joints[j]
    h = joint.loosest().hinge
    angles = hinge_angles(q, h.axis)
    off = off_axis_angles(q, h.axis)
    clinical = _clinical_hinge(joint.name, h.axis)
    pos, neg = _movements(joint.name)
    label = (f"{joint.name} {pos} (°; negative: {neg})" if clinical
             else f"{joint.name} hinge angle about {np.round(h.axis, 3).tolist()} (°)")
    norm = None
    aaos = NORMATIVE["aaos"].get(joint.name, {})
    if clinical and pos in aaos and neg in aaos:
        norm = (0.0 - aaos[neg], aaos[pos])  # 0.0 -: no negative zero
    ref_joint = _reference_joint(reference, joint.name, joint.kind)
    ref = None
    if ref_joint is not None and get_kind(ref_joint.kind).single_axis:
        rh = ref_joint.loosest().hinge
        ref = (rh.min_deg, rh.max_deg)
    sec.facts = {
        "recorded postures": len(q),
        "hinge angle inside the interval (%)": 100.0 * float(
            ((angles >= h.min_deg - 1e-9) & (angles <= h.max_deg + 1e-9)).mean()),
        "allowed (°)": _interval_text(h.min_deg, h.max_deg),
        "recorded (°)": _interval_text(float(angles.min()), float(angles.max())),
        "off-axis motion, median / 95th pct / max (°)":
            f"{np.median(off):.1f} / {np.percentile(off, 95):.1f} / {off.max():.1f}",
    }
    if joint.coupling is not None:
        sec.facts["allowed"] = f"the hull of its keyframes at {joint.coupling.by} " + ", ".join(
            f"{a:g}°" for a in joint.coupling.at_deg)
    if norm is not None:
        sec.facts["AAOS normal (°)"] = _interval_text(*norm)
    if ref is not None:
        sec.facts["reference (°)"] = _interval_text(*ref)
        sec.facts["largest difference from the reference (°)"] = max(
            abs(h.min_deg - ref[0]), abs(h.max_deg - ref[1]))
    sec.figure_png = hinge_figure(angles, (h.min_deg, h.max_deg), label=label, norm=norm,
                                  reference=ref, off_axis_deg=off,
                                  title=f"{_title(joint.name)} ({side}): allowed interval and "
                                        "recorded hinge angles")
    sec.figure_kind = "interval"
    sec.caption = (f"The {joint.name}'s allowed interval (grey bar), the recorded hinge angles "
                   "above it (blue: distribution and extremes)"
                   + (", the AAOS normal arc beneath (green)" if norm else "")
                   + ". Out-of-axis motion is rotation away from the hinge axis: corrected, "
                   "not a limit.")


def _coupling_section(limb, j: int, q: np.ndarray, side: str,
                      reference) -> CouplingSection:
    joint = limb.joints[j]
    cp = joint.coupling
    src = limb.joints[limb.index(cp.by)]
    sc = src.loosest()
    if src.joint_kind.single_axis:
        sh = sc.hinge
        lo, hi, axis = sh.min_deg, sh.max_deg, sh.axis
        xs = hinge_angles(q[:, limb.index(cp.by)], sh.axis)
    else:  # another source kind (a forearm: its flexion)
        lo, hi = (math.degrees(v) for v in sc.joint_kind.coupling_range(sc))
        axis = sc.joint_kind.coupling_axis(sc)
        xs = np.degrees(sc.joint_kind.coupling_angle(sc, q[:, limb.index(cp.by)]))
    at = np.asarray(cp.at_deg, dtype=np.float64)
    x = np.unique(np.concatenate((np.linspace(min(lo, at[0]), max(hi, at[-1]),
                                              _CURVE_POINTS), at)))
    lim = np.array([_primary_limits(cp.at(a), joint.name, side) for a in x])
    ref_curve = None
    ref_joint = _reference_joint(reference, joint.name, joint.kind)
    if ref_joint is not None:
        rl = np.array([_primary_limits(_limits_at(ref_joint, a), joint.name, side) for a in x])
        ref_curve = (x, rl[:, 0], rl[:, 1])
    ys, read = _primary_angles(q[:, j], joint.name, side, joint)
    pos, neg = _movements(joint.name)
    clinical_src = _clinical_hinge(cp.by, axis)
    src_pos, _ = _movements(cp.by)
    xlabel = f"{cp.by} {src_pos} (°)" if clinical_src else f"{cp.by} hinge angle (°)"
    if get_kind(joint.kind).single_axis:
        ylabel = f"{joint.name} hinge angle (°)"
    else:
        ylabel = f"{joint.name} {pos} (+) / {neg} (−) (°)"
        if joint.name == "shoulder":
            ylabel += ", sagittal plane"
    rows = []
    for a in at:
        k = int(np.flatnonzero(x == a)[0])
        near = read & (np.abs(xs - a) <= _NEAR_KEYFRAME_DEG)
        rows.append({f"{cp.by} (°)": float(a), f"upper limit: {pos} (°)": float(lim[k, 1]),
                     f"lower limit (°; −{neg})": float(lim[k, 0]),
                     f"recorded postures within {_NEAR_KEYFRAME_DEG:g}°": int(near.sum()),
                     "recorded highest (°)": float(ys[near].max()) if near.any() else None,
                     "recorded lowest (°)": float(ys[near].min()) if near.any() else None})
    what = ("within 5° of the sagittal plane" if joint.name == "shoulder" else "all")
    png = coupling_figure(x, lim[:, 0], lim[:, 1], keyframes_deg=at, recorded=(xs[read],
                                                                                ys[read]),
                          reference=ref_curve, xlabel=xlabel, ylabel=ylabel,
                          title=f"{_title(joint.name)} limits against {cp.by} angle ({side})")
    caption = (f"The {joint.name}'s {pos} and {neg} limits against the {cp.by}'s angle: the "
               f"limb file's keyframes at {cp.by} " + ", ".join(f"{a:g}°" for a in at)
               + " (orange) and their interpolation between them, clamped beyond; "
               f"recorded postures ({what}) in blue"
               + ("; the reference dashed" if ref_curve is not None else "") + ".")
    return CouplingSection(joint.name, cp.by, tuple(float(a) for a in at), x, lim[:, 0],
                           lim[:, 1], (pos, neg), rows, png, caption)


def _reference_joint(reference, name: str, kind: str):
    """The reference's joint of that name, when it is one to compare with (a hinge with a
    hinge, a swing joint with a swing joint)."""
    if reference is None or name not in reference.joint_names:
        return None
    ref = reference.joints[reference.index(name)]
    return ref if get_kind(ref.kind).single_axis == get_kind(kind).single_axis else None


# ---------------------------------------------------------------------------------------------
# Calibration and evaluation
# ---------------------------------------------------------------------------------------------
def limb_model_verdict(metrics: Mapping[str, Any], *,
                       limb: bool | None = True) -> tuple[bool, str, list[dict[str, Any]]]:
    """(all targets met, one-line verdict, one row per target) of a limb model's held-out
    metrics (:func:`models.evaluation.evaluate_model`) against issue 20's targets
    (:func:`rig.training.verdict.targets_for` a limb: end-point mean 3-D error ≤ 0.5 % of the limb's
    length, invalid inputs left > 1° outside ≤ 1 %, valid inputs moved ≤ 0.1° mean, p99
    end-point direction error ≤ 3°) — or, ``limb`` None, whose targets the metrics tell
    (:func:`rig.training.verdict.judging`: a one-joint model's on the page of a recording of
    one joint). A metric absent from ``metrics`` is shown, not judged."""
    metrics = current_metric_names(dict(metrics))
    rows = []
    for key, (limit, *_) in judging(metrics, limb=limb).targets().items():
        label, unit, scale = _TARGET_LABELS.get(key, (key, "", 1.0))
        v = metrics.get(key)
        rows.append({"metric": label, "key": key,
                     "value": None if v is None else scale * float(v),
                     "target": f"≤ {scale * limit:g}{unit}",
                     "met": None if v is None else bool(float(v) <= limit)})
    ok, verdict = evaluation_verdict(metrics, limb=limb)
    return ok, verdict, rows


def _evaluation_facts(metrics: Mapping[str, Any], names: Sequence[str]) -> dict[str, Any]:
    facts: dict[str, Any] = {}
    if metrics.get("n") is not None:
        facts["held-out postures"] = int(metrics["n"])
    if metrics.get("valid_fraction") is not None:
        facts["valid postures among them (%)"] = 100.0 * float(metrics["valid_fraction"])
    if metrics.get("end_max_3d_error_pct") is not None:
        facts["max end-point 3-D error (% of limb length)"] = float(
            metrics["end_max_3d_error_pct"])
    per_joint = metrics.get("joint_mean_direction_error_deg")
    if per_joint is not None:
        facts["mean segment direction error per joint (°)"] = ", ".join(
            f"{n} {float(v):.3f}" for n, v in zip(names, per_joint, strict=False))
    for key, label in (("mean_violation_deg", "mean violation after correction (°)"),
                       ("max_violation_deg", "max violation after correction (°)")):
        if metrics.get(key) is not None:
            facts[label] = float(metrics[key])
    for key, v in metrics.items():  # anything else the evaluation gave
        known = {"n", "valid_fraction", "end_max_3d_error_pct",
                 "joint_mean_direction_error_deg", "mean_violation_deg", "max_violation_deg",
                 *_TARGET_LABELS}
        if key not in known and isinstance(v, (int, float, str)):
            facts[key.replace("_", " ")] = v
    return facts


# ---------------------------------------------------------------------------------------------
# Assembly
# ---------------------------------------------------------------------------------------------
def _postures(limb, joints: Mapping[str, Any]) -> np.ndarray:
    """(N, J, 4) unit postures from the per-joint arrays, in the limb's joint order."""
    if not isinstance(joints, Mapping):
        raise ValueError(f"joints: expected a mapping joint name -> (N, 4) orientations, got "
                         f"{type(joints).__name__}")
    missing = [n for n in limb.joint_names if n not in joints]
    if missing:
        raise ValueError(f"joints: no orientations for {', '.join(missing)} (the limb's joints: "
                         f"{', '.join(limb.joint_names)})")
    arrs = []
    for n in limb.joint_names:
        a = np.asarray(joints[n], dtype=np.float64)
        if a.ndim != 2 or a.shape[1] != 4 or len(a) == 0:
            raise ValueError(f"joints[{n!r}]: expected shape (N, 4) with N >= 1 (scalar-first "
                             f"quaternions), got {a.shape}")
        arrs.append(Q.check_quaternions(a, normalize=True, name=f"joints[{n!r}]"))
    lengths = {len(a) for a in arrs}
    if len(lengths) != 1:
        raise ValueError("joints: every joint needs the same number of orientations, got "
                         + ", ".join(f"{n} {len(a)}" for n, a in zip(limb.joint_names, arrs,
                                                                       strict=True)))
    return np.stack(arrs, axis=1)


def limb_report_data(limb, joints: Mapping[str, Any], *, side: str, patient: str,
                     session_label: str | None = None, warnings: Sequence[str] = (),
                     reference=None, calibration: Mapping[str, Mapping[str, float]] | None = None,
                     evaluation: Mapping[str, Any] | None = None, age: float | None = None,
                     sex: str | None = None, limits_source: str | None = None,
                     calibration_note: str | None = None,
                     evaluation_note: str | None = None,
                     coupled_tests: bool = True) -> LimbReportData:
    """Everything the report of one arm or leg shows (module doc).

    Parameters
    ----------
    limb : models.limb.Limb
        The limits: joints proximal to distal, couplings with keyframes.
    joints : mapping joint name → (N, 4) float
        Recorded joint orientations (child relative to parent, rig segment frames,
        scalar-first), one array per joint of ``limb``, the same N (sample ``i`` of every
        joint is one posture).
    side : {"right", "left"}
        The limb's side (clinical angles of a left limb are mirrored; its map labels lie on
        the other side). A limb file bound to the other side is refused.
    patient : str
        Pseudonym.
    session_label : str, optional
        How the page names the session (e.g. ``"12 (2026-11-23)"``).
    limits_source : str, optional
        Where the limits come from (a model's limb file, a limb file stored with the session,
        or extracted for the report), shown beside the limb.
    warnings : sequence of str
        Reasons to doubt the figures (coverage, an interrupted session), shown at the top.
    reference : models.limb.Limb, optional
        Another limb's limits drawn dashed (a simulated patient's truth), joint by joint by
        name.
    calibration : mapping, optional
        Residuals (degrees) per joint and segment, as
        :attr:`calibration.limb_calibration.LimbImuCalibration.residuals_`.
    calibration_note : str, optional
        Which calibration those are (the recorder's, or re-fitted on the host's fusion) and
        what it measured beyond them (the root's lean), shown beneath them.
    evaluation : mapping, optional
        A limb model's metrics (:func:`models.evaluation.evaluate_model`), judged
        against issue 20's targets (:func:`limb_model_verdict`); for a limb of one joint (no
        ``limb.limb``), that joint's model's, against a single joint's targets.
    evaluation_note : str, optional
        Which evaluation those metrics are (stored with the model, or drawn for the report),
        shown beside them.
    age, sex : optional
        The patient's, for the population reference column
        (:func:`calibration.joint_angles.population_reference`; the shoulder's
        :func:`calibration.clinical.population_reference`).
    coupled_tests : bool
        The section "Coupled clinical tests" (default; False leaves it out): the limits'
        value at each test position and the recording's, "not reached in this recording"
        where the postures never came there (:func:`calibration.clinical_tests.coupled_measures`).

    Raises
    ------
    ValueError
        A bad side, a limb bound to the other side, missing or malformed orientations.
    """
    if side not in ("right", "left"):
        raise ValueError(f"side must be 'right' or 'left', got {side!r}")
    if limb.side is not None and limb.side != side:
        raise ValueError(f"side {side!r}: the limb {limb.name!r} is a {limb.side} "
                         f"{limb.limb or 'limb'}")
    q = _postures(limb, joints)
    result = ConstraintOracle(limb).evaluate(q)
    data = LimbReportData(patient=patient, side=side, limb=limb.limb, limb_name=limb.name,
                          joint_order=limb.joint_names, samples=len(q),
                          session_label=session_label, limits_source=limits_source,
                          warnings=[str(w) for w in warnings],
                          reference_name=None if reference is None else reference.name,
                          software=f"rig {__version__}")
    for j, joint in enumerate(limb.joints):
        sec = JointSection(joint.name, joint.kind, _heading(limb, joint))
        limits, where = [joint.constraint], None
        if joint.coupling is not None and get_kind(joint.kind).single_axis:
            limits, where = [joint.loosest()], "the hull of its keyframes"
        elif joint.coupling is not None:
            cp = joint.coupling
            limits = list(cp.keyframes)
            where = (f"the largest over its keyframes at {cp.by} "
                     + ", ".join(f"{a:g}" for a in cp.at_deg)
                     + "°; the coupling plot shows how its limits change")
        sec.rom_rows, sec.rom_note = _joint_rom_rows(joint.name, q[:, j], side, limits, where,
                                                     age=age, sex=sex)
        data.warnings += [r.beyond_reach for r in sec.rom_rows if r.beyond_reach]
        if get_kind(joint.kind).single_axis:
            _hinge_section(sec, limb, j, q[:, j], side, result, reference)
        else:
            _swing_section(sec, limb, j, q[:, j], side, result, reference)
        data.joints.append(sec)
    for j in limb.coupled:
        data.couplings.append(_coupling_section(limb, j, q, side, reference))
    if not data.couplings:
        data.coupling_note = NO_COUPLING
    if coupled_tests:
        data.coupled_tests = coupled_measures(limb, q, side=side)
    if calibration:
        data.calibration = {str(k): {str(a): float(b) for a, b in v.items()}
                            for k, v in calibration.items()}
        data.calibration_note = calibration_note
    if evaluation:
        _, data.evaluation_verdict, data.evaluation_rows = limb_model_verdict(
            evaluation, limb=None)  # told by the metrics: a limb of one joint, its joint's
        data.evaluation_facts = _evaluation_facts(evaluation, limb.joint_names)
        if evaluation_note:
            data.evaluation_facts = {"evaluation": evaluation_note, **data.evaluation_facts}
    return data


# ---------------------------------------------------------------------------------------------
# The page
# ---------------------------------------------------------------------------------------------
def _calibration_html(res: dict[str, dict[str, float]]) -> list[str]:
    kinds = [k for k in _RESIDUAL_ORDER if any(k in r for r in res.values())]
    for r in res.values():
        kinds += [k for k in r if k not in kinds]
    head = "".join(f"<th>{escape('range of the movement (not an error)' if k == 'range' else k)}"
                   "</th>" for k in kinds)
    out = [f"<table><tr><th>Joint or segment</th>{head}</tr>"]
    for name, r in res.items():
        out.append(f"<tr><td>{escape(name)}</td>"
                   + "".join(f"<td>{fmt(r.get(k), 2)}</td>" for k in kinds) + "</tr>")
    out.append("</table>")
    worst = [v for r in res.values() for k, v in r.items() if k != "range"]
    if worst:
        out.append(f"<p class='small'>Residuals in degrees; the largest (the movement ranges "
                   f"left out): {max(worst):.2f}°.</p>")
    return out


def render_limb_html(data: LimbReportData) -> str:
    """The whole limb report as one HTML string (the shoulder report's page mechanism)."""
    one = data.joint_order[0] if len(data.joint_order) == 1 else None
    what = f"{data.side} {data.limb or one or 'limb'}"
    if data.from_file:  # a file: what was read, and no patient
        meta = [(k, escape(v)) for k, v in data.from_file.items()]
        whose = f"from file {next(iter(data.from_file.values()))}"
    else:
        meta = [("Patient (pseudonym)", f"<b>{escape(data.patient)}</b>"),
                ("Session", escape(data.session_label) if data.session_label else None)]
        whose = data.patient
    meta += [("Limb" if one is None else "Joint", f"{escape(what)} ({escape(data.limb_name)})"),
            ("Limits", escape(data.limits_source) if data.limits_source else None),
            ("Joints", None if one else escape(" → ".join(data.joint_order))),
            ("Recorded postures", fmt(data.samples)),
            ("Reference (dashed)", escape(data.reference_name) if data.reference_name else None)]
    out = page_head(f"Range of motion report: {whose}, {what}",
                    f"Range of motion report — {what}", meta)
    out += warnings_html(data.warnings, data.simulated)
    for sec in data.joints:
        out.append(f"<section class='joint' data-joint='{escape(sec.name)}' "
                   f"data-kind='{escape(sec.kind)}'><h2>{escape(sec.heading)}</h2>")
        if sec.rom_rows:
            out += rom_table_html(sec.rom_rows, sec.rom_note, measured="Recorded (°)")
        elif sec.rom_note:
            out.append(f"<p class='small'>{escape(sec.rom_note)}</p>")
        out.append("<div class='figs'>")
        if sec.figure_png is not None:
            alt = (f"{sec.name}: equal-area map of the recorded directions and the limits"
                   if sec.figure_kind == "map" else
                   f"{sec.name}: interval bar of the hinge angle")
            out.append(img_tag(sec.figure_png, alt))
        if sec.facts:
            out.append(kv_table(sec.facts, 1))
        out.append("</div>")
        if sec.caption:
            out.append(f"<p class='small'>{escape(sec.caption)}</p>")
        out.append("</section>")
    if one is None or data.couplings:  # one joint: nothing to couple
        out.append("<h2>Couplings</h2>")
    if not data.couplings and one is None:
        out.append(f"<p>{escape(data.coupling_note or NO_COUPLING)}</p>")
    for c in data.couplings:
        out.append(f"<section class='coupling' data-joint='{escape(c.joint)}' "
                   f"data-by='{escape(c.by)}'><h3>{escape(_title(c.joint))} limits against the "
                   f"{escape(c.by)}</h3><div class='figs'>")
        if c.figure_png is not None:
            out.append(img_tag(c.figure_png, f"{c.joint} against {c.by}: coupling plot"))
        if c.keyframe_rows:
            cols = list(c.keyframe_rows[0])
            out.append("<table><tr>" + "".join(f"<th>{escape(k)}</th>" for k in cols) + "</tr>")
            for r in c.keyframe_rows:
                out.append("<tr>" + "".join(f"<td>{fmt(r[k])}</td>" for k in cols) + "</tr>")
            out.append("</table>")
        out.append("</div>")
        if c.caption:
            out.append(f"<p class='small'>{escape(c.caption)}</p>")
        out.append("</section>")
    out += data.progress_html
    if data.coupled_tests is not None:
        out += _coupled_tests_html(data.coupled_tests)
    if data.calibration:
        out.append("<h2>Calibration</h2>")
        out += _calibration_html(data.calibration)
        if data.calibration_note:
            out.append(f"<p class='small'>{escape(data.calibration_note)}</p>")
    if data.evaluation_rows or data.evaluation_facts:
        out.append("<h2>Learned limb model</h2>")
        out.append(verdict_html(data.evaluation_verdict))
        out.append("<table><tr><th>Target</th><th>Value</th><th>Goal</th><th>Verdict</th></tr>")
        for r in data.evaluation_rows:
            verdict = ("–" if r["met"] is None else
                       "<span class='ok'>met</span>" if r["met"] else
                       "<span class='warn'>missed</span>")
            out.append(f"<tr><td>{escape(r['metric'])}</td><td>{fmt(r['value'], 3)}</td>"
                       f"<td>{escape(r['target'])}</td><td>{verdict}</td></tr>")
        out.append("</table>")
        if data.evaluation_facts:
            out.append(kv_table(data.evaluation_facts, 3))
    out += page_foot(data.software, _angles_sentence(data.joint_order))
    return "\n".join(out)


def _coupled_tests_html(measures: list) -> list[str]:
    """The section "Coupled clinical tests": one row per measure (its definition, the value,
    the limits' and the recording's readings, the norm or threshold, the verdict)."""
    out = ["<h2>Coupled clinical tests</h2>"]
    if not measures:
        return [*out, "<p>No test applies to these joints.</p>"]
    out.append("<table><tr><th>Test</th><th>Definition</th><th>Value (°)</th>"
               "<th>Limits (°)</th><th>Recorded (°)</th><th>Norm or threshold</th>"
               "<th>Reading</th></tr>")
    for m in measures:
        ref = REFERENCES[m.spec.reference]
        value = ("not reached in this recording" if m.status.startswith("not reached")
                 else fmt(m.value))
        reading = "; ".join(x for x in (m.verdict, *m.notes) if x)
        out.append(f"<tr><td>{escape(m.spec.label)}</td><td>{escape(m.spec.definition)}"
                   f"<br><span class='small'>{escape(m.spec.angles)}</span></td>"
                   f"<td>{escape(value)}</td><td>{fmt(m.from_limits)}</td>"
                   f"<td>{fmt(m.recorded)}</td>"
                   f"<td>{escape(ref.get('threshold') or ref.get('norm') or '-')}</td>"
                   f"<td>{escape(reading)}</td></tr>")
    out.append("</table>")
    sources = measure_sources(measures)
    out.append("<p class='small'>Sources: " + escape("; ".join(sources)) + ".</p>")
    return out


def _angles_sentence(joints: Sequence[str]) -> str:
    """The footer's angle conventions, naming this limb's joints only (a leg's page does not
    speak of the shoulder)."""
    parts = []
    for name in joints:
        if name == "shoulder":
            parts.append("shoulder Wu et al. 2005, J Biomech 38:981 (as in the shoulder "
                         "report)")
        elif name in JOINT_ANGLES:
            parts.append(f"{name} {JOINT_ANGLES[name].source}")
    return ("Angles, the joint coordinate systems of: " + "; ".join(parts)
            + "; left limbs mirrored. AAOS 1965 normal values.")


def write_limb_report(data: LimbReportData, path: str | Path) -> Path:
    """Write the limb report atomically and owner-only (it names the patient,
    :func:`rig.report.page.write_page`); returns the path."""
    return write_page(render_limb_html(data), path)
