"""The clinician's report: a self-contained HTML page (:mod:`rig.report.page`) with figures
drawn by matplotlib (:mod:`rig.report.figures`), assembled from a session in the store
(:mod:`rig.report.session`)."""

from rig.report.page import ReportData, RomRow, render_html, write_report

__all__ = ["ReportData", "RomRow", "render_html", "write_report"]
