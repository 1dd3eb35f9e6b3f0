"""The clinician's report: one self-contained HTML page (figures embedded as PNG data URIs).

Sections, each present when its data exists: patient and session; range of motion in clinical
terms next to normative values; the recorded swing boundary on an equal-area map with the
samples and the sparsely sampled arcs; calibration residuals; the trained model's accuracy with
its error map; the live enforcement summary. No external resources: the page can be filed,
mailed or printed as is.

The page's parts — :func:`page_head` (styles, heading, facts), :func:`warnings_html`,
:func:`rom_table_html`, :func:`kv_table`, :func:`img_tag`, :func:`verdict_html`,
:func:`page_foot`, :func:`write_page` — are shared with a limb's report
(:mod:`rig.report.limb`).
"""

from __future__ import annotations

import base64
import datetime as _dt
import html
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from calibration.clinical import AAOS_NOT_COMPARABLE, NORMATIVE, population_reference
from calibration.joint_angles import beyond_reach
from models.fileio import write_owner_only

__all__ = ["ReportData", "RomRow", "escape", "fmt", "img_tag", "kv_table", "page_foot", "page_head",
           "render_html", "rom_rows", "rom_table_html", "verdict_html", "warnings_html",
           "write_page", "write_report"]


@dataclass
class RomRow:
    """One movement of the range-of-motion table (degrees)."""

    movement: str
    measured_deg: float | None
    aaos_deg: float | None = None  # None where AAOS measured it in another position
    population: str | None = None  # e.g. "152 (women, 45-49), Gill 2020"
    note: str | None = None  # why there is no AAOS comparison, e.g. "AAOS: at 90° abduction"
    allowed_deg: float | None = None  # what the joint's limits allow (a limb's report)
    extra: dict[str, Any] = field(default_factory=dict)  # further reference columns, by title
    #: why the joint's kind does not measure this movement (e.g. "not measured by a hinge",
    #: :func:`calibration.joint_angles.not_measured`): shown instead of a value, no comparison
    not_measured: str | None = None
    #: the line saying the measured value is beyond what people reach
    #: (:func:`calibration.joint_angles.beyond_reach`), shown among the page's warnings
    beyond_reach: str | None = None


@dataclass
class ReportData:
    """Everything the report shows; sections with no data are left out."""

    patient: str
    session_id: int | str
    joint: str = "shoulder"
    side: str | None = None
    rig: str | None = None
    started: str | None = None
    duration_s: float | None = None  # the samples' span, calibration steps included
    free_motion_s: float | None = None  # of which the free movement after the calibration
    calibrated: bool = False  # the session began with the guided calibration steps
    samples: int | None = None
    dropped: int | None = None
    rom_rows: list[RomRow] = field(default_factory=list)
    rom_note: str | None = None
    warnings: list[str] = field(default_factory=list)  # reasons to doubt the figures
    simulated: bool = False  # the samples come from the rig's simulator, not a person
    boundary_png: bytes | None = None
    boundary_facts: dict[str, Any] = field(default_factory=dict)
    sparse_arcs_deg: list[tuple[float, float]] = field(default_factory=list)
    sparse_arcs_text: list[str] = field(default_factory=list)  # arcs in clinical words
    calibrations: list[dict[str, Any]] = field(default_factory=list)
    model_metrics: dict[str, Any] = field(default_factory=dict)
    model_verdict: str | None = None
    error_map_png: bytes | None = None
    enforcement: dict[str, Any] = field(default_factory=dict)
    enforcement_verdict: str | None = None
    enforcement_joints: list[dict[str, Any]] = field(default_factory=list)  # a limb's joints
    leader: dict[str, Any] = field(default_factory=dict)  # a run driven by a leader arm
    software: str | None = None
    #: the progress section's HTML (:func:`rig.report.progress.progress_section_html`): the
    #: patient's visits of this joint, when there is more than one
    progress_html: list[str] = field(default_factory=list)


_CSS = """
body{font-family:-apple-system,Segoe UI,Helvetica,Arial,sans-serif;margin:2em auto;max-width:60em;
color:#222;line-height:1.4;padding:0 1em}
h1{font-size:1.5em;margin-bottom:.2em}h2{font-size:1.15em;border-bottom:1px solid #ccc;
padding-bottom:.2em;margin-top:1.6em}
table{border-collapse:collapse;margin:.5em 0}td,th{border:1px solid #ccc;padding:.25em .6em;
text-align:right}th{background:#f3f3f3}td:first-child,th:first-child{text-align:left}
.meta td{border:none;text-align:left;padding:.1em .8em .1em 0}.figs{display:flex;flex-wrap:wrap;
gap:1em;align-items:flex-start}.figs img{max-width:100%;height:auto}
.ok{color:#1b7837;font-weight:600}
.warn{color:#b35806;font-weight:600}.small{font-size:.85em;color:#555}
@media print{body{margin:0}h2{page-break-after:avoid}}
"""


def escape(x: Any) -> str:
    """``x`` as HTML text."""
    return html.escape(str(x))


_e = escape


def fmt(v: Any, digits: int = 1) -> str:
    """A table cell: numbers with ``digits`` decimals, None as a dash, text escaped."""
    if v is None:
        return "–"
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, int):
        return f"{v:,}"
    if isinstance(v, float):
        return "–" if v != v else f"{v:,.{digits}f}"
    return _e(v)


def img_tag(png: bytes, alt: str) -> str:
    """An ``<img>`` with the PNG embedded as a data URI (no external resource)."""
    b64 = base64.b64encode(png).decode("ascii")
    return f'<img alt="{_e(alt)}" src="data:image/png;base64,{b64}">'


def kv_table(rows: dict[str, Any], digits: int = 2) -> str:
    """A two-column table: one row per key."""
    body = "".join(f"<tr><th>{_e(k)}</th><td>{fmt(v, digits)}</td></tr>"
                   for k, v in rows.items())
    return f"<table>{body}</table>"


def rows_table(rows: list[dict[str, Any]], digits: int = 2) -> str:
    """A table with one row per dict (the first's keys as the header)."""
    if not rows:
        return ""
    keys = list(rows[0])
    head = "".join(f"<th>{_e(k)}</th>" for k in keys)
    body = "".join("<tr>" + "".join(f"<td>{fmt(r.get(k), digits)}</td>" for k in keys)
                   + "</tr>" for r in rows)
    return f"<table><tr>{head}</tr>{body}</table>"


def verdict_html(text: str | None) -> str:
    """A verdict line, green when it starts with ok / pass / within, orange otherwise."""
    if not text:
        return ""
    cls = "ok" if text.lower().startswith(("ok", "pass", "within")) else "warn"
    return f'<p class="{cls}">{_e(text)}</p>'


def page_head(title: str, heading: str, meta: list[tuple[str, str | None]]) -> list[str]:
    """The page's start: title, styles, the heading and the table of facts (label, HTML
    value; rows whose value is None left out)."""
    out = ["<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>",
           f"<title>{_e(title)}</title>",
           f"<style>{_CSS}</style></head><body>",
           f"<h1>{_e(heading)}</h1>",
           "<table class='meta'>"]
    for label, value in meta:
        if value is not None:
            out.append(f"<tr><td>{_e(label)}</td><td>{value}</td></tr>")
    out.append("</table>")
    return out


def warnings_html(warnings, simulated: bool = False) -> list[str]:
    """Reasons to doubt the figures, at the top of the page."""
    out = []
    if simulated:
        out.append("<p class='warn'>Simulated patient: these figures come from the rig's "
                   "simulator, not from a person.</p>")
    for w in warnings:
        out.append(f"<p class='warn'>Warning: {_e(w)}.</p>")
    return out


def rom_table_html(rows: list[RomRow], note: str | None = None, *,
                   measured: str = "Measured (°)", population: bool = True) -> list[str]:
    """The range-of-motion table: movement, measured, what the limits allow (when a row has
    it), AAOS and the measured share of it, the population reference (``population``: always;
    otherwise when a row has one), every further reference column the rows carry
    (:attr:`RomRow.extra`); footnotes for the AAOS values not compared."""
    allowed = any(r.allowed_deg is not None for r in rows)
    pop = population or any(r.population for r in rows)
    extra: list[str] = []
    for r in rows:
        extra += [k for k in r.extra if k not in extra]
    out = ["<table><tr><th>Movement</th>"
           f"<th>{_e(measured)}</th>" + ("<th>Allowed by the limits (°)</th>" if allowed else "")
           + "<th>AAOS normal (°)</th><th>% of AAOS</th>"
           + ("<th>Population reference</th>" if pop else "")
           + "".join(f"<th>{_e(k)}</th>" for k in extra) + "</tr>"]
    notes = []
    for r in rows:
        if r.not_measured:  # no value, so no share of AAOS to misread as a deficit
            out.append(f"<tr><td>{_e(r.movement)}</td><td>{_e(r.not_measured)}</td>"
                       + ("<td>–</td>" if allowed else "") + "<td>–</td><td>–</td>"
                       + ("<td>–</td>" if pop else "")
                       + "".join("<td>–</td>" for _ in extra) + "</tr>")
            continue
        pct = (100.0 * r.measured_deg / r.aaos_deg
               if r.measured_deg is not None and r.aaos_deg else None)
        aaos = fmt(r.aaos_deg, 0)
        if r.note:
            notes.append(f"{r.movement}: {r.note}")
            aaos = f"{aaos}<sup>{len(notes)}</sup>"
        measured = fmt(r.measured_deg)
        if r.beyond_reach:
            measured += " <span class='warn'>(beyond what people reach)</span>"
        out.append(f"<tr><td>{_e(r.movement)}</td><td>{measured}</td>"
                   + (f"<td>{fmt(r.allowed_deg)}</td>" if allowed else "")
                   + f"<td>{aaos}</td><td>{fmt(pct, 0)}</td>"
                   + (f"<td>{_e(r.population or '–')}</td>" if pop else "")
                   + "".join(f"<td>{fmt(r.extra.get(k))}</td>" for k in extra) + "</tr>")
    out.append("</table>")
    for k, n in enumerate(notes, 1):
        out.append(f"<p class='small'><sup>{k}</sup> {_e(n)}</p>")
    if note:
        out.append(f"<p class='small'>{_e(note)}</p>")
    return out


def page_foot(software: str | None, angles: str) -> list[str]:
    """The page's end: when and by what it was made, the angle conventions (``angles``, one
    sentence), the research-software caveat."""
    stamp = _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    return [f"<p class='small'>Generated {stamp}"
            f"{' by ' + _e(software) if software else ''}. {_e(angles)} "
            "Research software: verify clinical decisions independently.</p>",
            "</body></html>"]


def _recorded_words(data: ReportData) -> str | None:
    """How long the session recorded: the samples' span and, when the free movement was
    shorter (the guided calibration steps came first), that too — ``--duration 30`` then
    reads "47 s in all: the calibration steps, then 30 s of free movement"."""
    total, free = data.duration_s, data.free_motion_s
    if not total:
        return None
    if free is None or total - free < 0.5:
        return f"{total:.0f} s of motion"
    before = "the calibration steps, then " if data.calibrated else ""
    return f"{total:.0f} s in all: {before}{free:.0f} s of free movement"


def render_html(data: ReportData) -> str:
    """The whole report as one HTML string."""
    meta = [("Patient (pseudonym)", f"<b>{_e(data.patient)}</b>"),
            ("Session", _e(data.session_id)),
            ("Started", _e(data.started) if data.started else None),
            ("Rig", _e(data.rig) if data.rig else None),
            ("Recorded", _recorded_words(data)),
            ("Samples", fmt(data.samples) if data.samples is not None else None),
            ("Dropped samples", fmt(data.dropped) if data.dropped is not None else None)]
    what = ("Live enforcement report" if data.enforcement and not data.rom_rows
            and not data.boundary_facts else "Range of motion report")
    out = page_head(f"{what}: {data.patient}, session {data.session_id}",
                    f"{what} — {data.joint}"
                    f"{' (' + data.side + ')' if data.side else ''}", meta)
    out += warnings_html(data.warnings, data.simulated)

    if not data.rom_rows and data.rom_note:  # no range of motion: say why
        out.append("<h2>Range of motion</h2>")
        out.append(f"<p class='warn'>No range of motion: {_e(data.rom_note)}</p>")
    if data.rom_rows:
        out.append("<h2>Range of motion</h2>")
        out += rom_table_html(data.rom_rows, data.rom_note)

    out += data.progress_html

    if data.boundary_png is not None or data.boundary_facts:
        out.append("<h2>Recorded boundary</h2><div class='figs'>")
        if data.boundary_png is not None:
            out.append(img_tag(data.boundary_png, "recorded swing boundary and samples"))
        out.append("<div>")
        if data.boundary_facts:
            out.append(kv_table(data.boundary_facts, 1))
        if data.sparse_arcs_deg or data.sparse_arcs_text:
            arcs = "; ".join([f"{a:.0f}°–{b:.0f}°" for a, b in data.sparse_arcs_deg]
                             + list(data.sparse_arcs_text))
            what = "azimuth ranges" if not data.sparse_arcs_text else "red on the map"
            out.append(f"<p class='warn'>Sparsely sampled boundary ({_e(what)}): {_e(arcs)}. "
                       "The boundary there is not supported by recorded motion; consider "
                       "recording again.</p>")
        else:
            out.append("<p class='ok'>Every part of the boundary has samples nearby.</p>")
        out.append("</div></div>")

    if data.calibrations:
        out.append("<h2>Calibration</h2><table><tr><th>Step</th><th>Residual (°)</th></tr>")
        for c in data.calibrations:
            out.append(f"<tr><td>{_e(c.get('kind', '?'))}</td>"
                       f"<td>{fmt(c.get('residual_deg'), 2)}</td></tr>")
        out.append("</table>")

    if data.model_metrics or data.error_map_png is not None:
        out.append("<h2>Learned constraint model</h2>")
        out.append(verdict_html(data.model_verdict))
        out.append("<div class='figs'>")
        if data.error_map_png is not None:
            out.append(img_tag(data.error_map_png, "model error map"))
        if data.model_metrics:
            out.append(kv_table(data.model_metrics, 3))
        out.append("</div>")

    if data.enforcement:
        out.append("<h2>Live enforcement</h2>")
        out.append(verdict_html(data.enforcement_verdict))
        out.append(kv_table(data.enforcement, 2))
    if data.enforcement_joints:
        out.append("<h3>Per joint</h3>")
        out.append(rows_table(data.enforcement_joints, 2))
        out.append("<p class='small'>Limit binding: cycles whose target the supervisor brought "
                   "into the patient's limits. Held: cycles whose target was stale or invalid "
                   "(the last safe goal kept), or a joint kept still while a coupled joint "
                   "recovered. Tracking: the angle between each admissible target and the "
                   "servos' present orientation once the target was held long enough to be "
                   "reached.</p>")
    if data.leader:
        out.append("<h3>Leader arm</h3>")
        out.append(kv_table(data.leader, 2))

    out += page_foot(data.software, "Angles follow the ISB recommendation (Wu et al. 2005) "
                     "for the humerus relative to the thorax.")
    return "\n".join(out)


def write_page(text: str, path: str | Path) -> Path:
    """Write an HTML page atomically and owner-only (a report names the patient,
    :func:`models.fileio.write_owner_only`); returns the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    return write_owner_only(path, text)


def write_report(data: ReportData, path: str | Path) -> Path:
    """Write the report atomically and owner-only (it names the patient,
    :func:`write_page`); returns the path."""
    return write_page(render_html(data), path)


#: The shoulder's movements as the report names them.
_ROM_LABELS = {
    "flexion": "Flexion", "extension": "Extension", "abduction": "Abduction",
    "adduction": "Adduction", "horizontal_adduction": "Horizontal adduction",
    "internal_rotation": "Internal rotation (arm at side)",
    "external_rotation": "External rotation (arm at side)",
}


def rom_rows(rom, *, age: int | None = None, sex: str | None = None) -> list[RomRow]:
    """The range-of-motion table of a shoulder's range of motion
    (:class:`calibration.clinical.RangeOfMotion`: a boundary's reading and, when it was given
    the recorded limb directions, the smaller of that and the recording's). AAOS values
    measured in another position (the rotations: at 90° abduction) are not compared; the
    population reference is the age band and sex when known, women and men apart
    otherwise."""
    far = beyond_reach(rom, "shoulder")
    rows = []
    for m in rom.MOVEMENTS:
        pop = population_reference(m, age=age, sex=sex)
        other = AAOS_NOT_COMPARABLE.get(m)
        rows.append(RomRow(_ROM_LABELS[m], getattr(rom, m),
                           None if other else NORMATIVE["aaos"].get(m),
                           None if pop is None else f"{pop}, Gill 2020",
                           None if other is None else
                           f"not compared with AAOS ({NORMATIVE['aaos'][m]:.0f}°): {other}; "
                           "measured here with the arm at the side",
                           beyond_reach=far[m]["text"] if m in far else None))
    return rows
