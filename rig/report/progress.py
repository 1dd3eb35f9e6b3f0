"""The report's progress section: a patient's range of motion across visits
(:func:`rig.readback.progress.run_progress`), one figure per joint and side — each movement over
the usable visits with the band of the minimal detectable change around the first — and the
table of values, changes and verdicts; the visits not used as evidence are listed with why;
with the patient's age or sex (``rig report --age --sex``), each movement's published norm for
them, with its source and method (:func:`rig.readback.progress.norms_of`).
"""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

from rig.readback.progress import ProgressResult, coupled_test_rows, norm_words
from rig.report.figures import to_png
from rig.report.page import escape, img_tag

__all__ = ["progress_figure", "progress_section_html"]


def progress_figure(joint: str, side: str | None, movements: dict) -> bytes:
    """PNG: each movement's peak (degrees) per usable visit (x: the visits in order, labelled
    by date), with the band first value ± MDC (the MDC's upper end; none where no MDC is
    published) — a point outside its band is a change beyond the measurement's error."""
    fig, ax = plt.subplots(figsize=(6.4, 3.4))
    dates: list[str] = []
    for k, (m, pts) in enumerate(movements.items()):
        xs = [i for i, p in enumerate(pts) if p.value is not None]
        ys = [pts[i].value for i in xs]
        if not ys:
            continue
        colour = f"C{k % 10}"
        ax.plot(xs, ys, "o-", color=colour, label=m.replace("_", " "))
        mdc = next((p.mdc for p in pts if p.mdc is not None), None)
        if mdc is not None:
            ax.axhspan(ys[0] - mdc.high, ys[0] + mdc.high, color=colour, alpha=0.12, lw=0)
        if len(pts) > len(dates):
            dates = [p.date[:10] for p in pts]
    ax.set_xticks(range(len(dates)), dates, rotation=30, ha="right", fontsize=8)
    ax.set_ylabel("peak (°)")
    ax.set_title(f"{joint} ({side or 'side unknown'}): shaded = first visit ± MDC", fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="best")
    return to_png(fig)


def _cell(d: float | None, v: str | None) -> str:
    if d is None:
        return "—"
    cls = " class='ok'" if v == "exceeds" else ""
    return f"<span{cls}>{d:+.1f}{' ' + v if v else ''}</span>"


def progress_section_html(result: ProgressResult) -> list[str]:
    """The section's HTML (empty when the patient has one visit of the joint or none)."""
    if len({v.session_id for v in result.visits}) < 2:
        return []
    out = ["<h2>Progress across visits</h2>"]
    bad = [v for v in result.visits if not v.usable]
    if bad:
        out.append("<p class='warn'>Not used as evidence: " + "; ".join(
            f"session {v.session_id} ({escape(v.date)}, {escape(v.joint)}): "
            f"{escape(', '.join(v.excluded))}" for v in bad) + "</p>")
    for (joint, side), mv in result.series.items():
        out.append(f"<h3>{escape(joint)} ({escape(side or 'side unknown')})</h3>")
        out.append("<div class='figs'>" + img_tag(progress_figure(joint, side, mv),
                                                  f"{joint} range of motion over visits"))
        out.append("<table><tr><th>Movement</th><th>Session</th><th>Date (UTC)</th>"
                   "<th>Value (°)</th><th>Since first (°)</th><th>Since previous (°)</th>"
                   "</tr>")
        for m, pts in mv.items():
            for p in pts:
                out.append(f"<tr><td>{escape(m.replace('_', ' '))}</td>"
                           f"<td>{p.session_id}</td><td>{escape(p.date)}</td>"
                           f"<td>{'—' if p.value is None else f'{p.value:.1f}'}</td>"
                           f"<td>{_cell(p.since_first, p.first_verdict)}</td>"
                           f"<td>{_cell(p.since_previous, p.previous_verdict)}</td></tr>")
        out.append("</table></div>")
        out.append("<p class='small'>" + "<br>".join(
            f"MDC {escape(m.replace('_', ' '))}: "
            + escape(" | ".join(dict.fromkeys(p.mdc_text for p in pts)))
            for m, pts in mv.items()) + "</p>")
        norms = {m: ns for m, ns in (result.norms or {}).get(joint, {}).items() if m in mv}
        if norms:
            out.append("<p class='small'>Norms for the patient: " + "<br>".join(
                f"{escape(m.replace('_', ' '))}: {escape(norm_words(ns))}"
                for m, ns in norms.items()) + "</p>")
    coupled = [(v, j, c) for v in result.visits for j, c in v.coupled.items()]
    if coupled:
        out.append("<h3>Coupled limits across visits</h3><table><tr><th>Session</th>"
                   "<th>Date (UTC)</th><th>Joint</th><th>At</th><th>Range allowed (°)</th>"
                   "</tr>")
        for v, j, c in coupled:
            for at, vals in c["rom"].items():
                text = ", ".join(f"{m.replace('_', ' ')} {x:.1f}" for m, x in vals.items()
                                 if x is not None)
                out.append(f"<tr><td>{v.session_id}</td><td>{escape(v.date)}</td>"
                           f"<td>{escape(j)}</td><td>{escape(c['by'])} {escape(at)}°</td>"
                           f"<td>{escape(text)}</td></tr>")
        out.append("</table><p class='small'>Each visit's limb file (rig boundary --limb): "
                   "the coupled joint's range at each keyframe angle of the joint it depends "
                   "on, so visits compare at the same coupling angles.</p>")
    tests = coupled_test_rows(result.visits)
    if tests:
        out.append("<h3>Coupled clinical tests across visits</h3><table><tr><th>Test</th>"
                   "<th>Session</th><th>Date (UTC)</th><th>Value</th><th>Evidence</th>"
                   "</tr>")
        for r in tests:
            out.append(f"<tr><td>{escape(r['label'])}</td><td>{r['session']}</td>"
                       f"<td>{escape(r['date'])}</td><td>{escape(r['text'])}</td>"
                       f"<td>{'yes' if r['usable'] else 'no'}</td></tr>")
        out.append("</table><p class='small'>Each visit's straight-leg raise, popliteal angle, "
                   "Silfverskiöld and Thomas tests (the arm: the shoulder's reach with the elbow "
                   "straight and bent), read as <code>rig rom</code> reads a whole-limb session; "
                   "'not reached in this recording' where the visit never came to the test "
                   "position.</p>")
    out.append("<p class='small'>'exceeds': a change larger than the minimal detectable "
               "change of the joint, movement and method (a real change); 'within': not "
               "distinguishable from measurement error; 'uncertain': inside a published MDC "
               "range. Interrupted or poorly covered visits are neither a reference nor a "
               "change.</p>")
    return out
