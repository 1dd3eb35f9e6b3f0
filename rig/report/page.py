"""The clinician's report: one self-contained HTML page (figures embedded as PNG data URIs).

Sections, each present when its data exists: patient and session; range of motion in clinical
terms next to normative values; the recorded swing boundary on an equal-area map with the
samples and the sparsely sampled arcs; calibration residuals; the trained model's accuracy with
its error map; the live enforcement summary. No external resources: the page can be filed,
mailed or printed as is.
"""

from __future__ import annotations

import base64
import datetime as _dt
import html
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

__all__ = ["ReportData", "RomRow", "render_html", "write_report"]


@dataclass
class RomRow:
    """One movement of the range-of-motion table (degrees)."""

    movement: str
    measured_deg: float | None
    aaos_deg: float | None = None  # None where AAOS measured it in another position
    population: str | None = None  # e.g. "152 (women, 45-49), Gill 2020"
    note: str | None = None  # why there is no AAOS comparison, e.g. "AAOS: at 90° abduction"


@dataclass
class ReportData:
    """Everything the report shows; sections with no data are left out."""

    patient: str
    session_id: int | str
    joint: str = "shoulder"
    side: str | None = None
    rig: str | None = None
    started: str | None = None
    duration_s: float | None = None
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
    software: str | None = None


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


def _e(x: Any) -> str:
    return html.escape(str(x))


def _fmt(v: Any, digits: int = 1) -> str:
    if v is None:
        return "–"
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, int):
        return f"{v:,}"
    if isinstance(v, float):
        return f"{v:,.{digits}f}"
    return _e(v)


def _img(png: bytes, alt: str) -> str:
    b64 = base64.b64encode(png).decode("ascii")
    return f'<img alt="{_e(alt)}" src="data:image/png;base64,{b64}">'


def _kv_table(rows: dict[str, Any], digits: int = 2) -> str:
    body = "".join(f"<tr><th>{_e(k)}</th><td>{_fmt(v, digits)}</td></tr>"
                   for k, v in rows.items())
    return f"<table>{body}</table>"


def _verdict(text: str | None) -> str:
    if not text:
        return ""
    cls = "ok" if text.lower().startswith(("ok", "pass", "within")) else "warn"
    return f'<p class="{cls}">{_e(text)}</p>'


def render_html(data: ReportData) -> str:
    """The whole report as one HTML string."""
    out: list[str] = [
        "<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>",
        f"<title>Range of motion report: {_e(data.patient)}, session {_e(data.session_id)}"
        "</title>",
        f"<style>{_CSS}</style></head><body>",
        f"<h1>Range of motion report — {_e(data.joint)}"
        f"{' (' + _e(data.side) + ')' if data.side else ''}</h1>",
        "<table class='meta'>",
        f"<tr><td>Patient (pseudonym)</td><td><b>{_e(data.patient)}</b></td></tr>",
        f"<tr><td>Session</td><td>{_e(data.session_id)}</td></tr>",
    ]
    meta = (("Started", _e(data.started) if data.started else None),
            ("Rig", _e(data.rig) if data.rig else None),
            ("Recorded", f"{data.duration_s:.0f} s of motion" if data.duration_s else None),
            ("Samples", _fmt(data.samples) if data.samples is not None else None),
            ("Dropped samples", _fmt(data.dropped) if data.dropped is not None else None))
    for label, value in meta:
        if value is not None:
            out.append(f"<tr><td>{label}</td><td>{value}</td></tr>")
    out.append("</table>")
    if data.simulated:
        out.append("<p class='warn'>Simulated patient: these figures come from the rig's "
                   "simulator, not from a person.</p>")
    for w in data.warnings:
        out.append(f"<p class='warn'>Warning: {_e(w)}.</p>")

    if not data.rom_rows and data.rom_note:  # no range of motion: say why
        out.append("<h2>Range of motion</h2>")
        out.append(f"<p class='warn'>No range of motion: {_e(data.rom_note)}</p>")
    if data.rom_rows:
        out.append("<h2>Range of motion</h2>")
        out.append("<table><tr><th>Movement</th><th>Measured (°)</th><th>AAOS normal (°)</th>"
                   "<th>% of AAOS</th><th>Population reference</th></tr>")
        notes = []
        for r in data.rom_rows:
            pct = (100.0 * r.measured_deg / r.aaos_deg
                   if r.measured_deg is not None and r.aaos_deg else None)
            aaos = _fmt(r.aaos_deg, 0)
            if r.note:
                notes.append(f"{r.movement}: {r.note}")
                aaos = f"{aaos}<sup>{len(notes)}</sup>"
            out.append(f"<tr><td>{_e(r.movement)}</td><td>{_fmt(r.measured_deg)}</td>"
                       f"<td>{aaos}</td><td>{_fmt(pct, 0)}</td>"
                       f"<td>{_e(r.population or '–')}</td></tr>")
        out.append("</table>")
        for k, n in enumerate(notes, 1):
            out.append(f"<p class='small'><sup>{k}</sup> {_e(n)}</p>")
        if data.rom_note:
            out.append(f"<p class='small'>{_e(data.rom_note)}</p>")

    if data.boundary_png is not None or data.boundary_facts:
        out.append("<h2>Recorded boundary</h2><div class='figs'>")
        if data.boundary_png is not None:
            out.append(_img(data.boundary_png, "recorded swing boundary and samples"))
        out.append("<div>")
        if data.boundary_facts:
            out.append(_kv_table(data.boundary_facts, 1))
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
                       f"<td>{_fmt(c.get('residual_deg'), 2)}</td></tr>")
        out.append("</table>")

    if data.model_metrics or data.error_map_png is not None:
        out.append("<h2>Learned constraint model</h2>")
        out.append(_verdict(data.model_verdict))
        out.append("<div class='figs'>")
        if data.error_map_png is not None:
            out.append(_img(data.error_map_png, "model error map"))
        if data.model_metrics:
            out.append(_kv_table(data.model_metrics, 3))
        out.append("</div>")

    if data.enforcement:
        out.append("<h2>Live enforcement</h2>")
        out.append(_verdict(data.enforcement_verdict))
        out.append(_kv_table(data.enforcement, 2))

    stamp = _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    out.append(f"<p class='small'>Generated {stamp}"
               f"{' by ' + _e(data.software) if data.software else ''}. Angles follow the ISB "
               "recommendation (Wu et al. 2005) for the humerus relative to the thorax. "
               "Research software: verify clinical decisions independently.</p>")
    out.append("</body></html>")
    return "\n".join(out)


def write_report(data: ReportData, path: str | Path) -> Path:
    """Write the report atomically and owner-only (it names the patient,
    :func:`models.fileio.write_owner_only`); returns the path."""
    from models.fileio import write_owner_only

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    return write_owner_only(path, render_html(data))
