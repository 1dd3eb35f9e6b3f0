"""The clinician's report: a self-contained HTML page (:mod:`rig.report.page`) with figures
drawn by matplotlib (:mod:`rig.report.figures`), assembled from a session in the store
(:mod:`rig.report.session`: :func:`run_report`, ``rig report`` as a library)."""

from rig.report.page import ReportData, RomRow, render_html, write_report
from rig.report.session import ReportRequest, ReportResult, run_report

__all__ = ["ReportData", "ReportRequest", "ReportResult", "RomRow", "render_html",
           "run_report", "write_report"]
