"""The clinician's report: a self-contained HTML page (:mod:`rig.report.page`) with figures
drawn by matplotlib (:mod:`rig.report.figures`), assembled from a session in the store
(:mod:`rig.report.session`: :func:`run_report`, ``rig report`` as a library); a whole arm or
leg's report from arrays (:mod:`rig.report.limb`: :func:`limb_report_data`,
:func:`write_limb_report`); a file's report, one joint or a whole limb, drawn as a limb's
(:mod:`rig.report.files`: :func:`file_report_data`)."""

from rig.report.files import file_report_data
from rig.report.limb import LimbReportData, limb_report_data, write_limb_report
from rig.report.page import ReportData, RomRow, render_html, write_report
from rig.report.session import ReportRequest, ReportResult, run_report

__all__ = ["LimbReportData", "ReportData", "ReportRequest", "ReportResult", "RomRow",
           "file_report_data", "limb_report_data", "render_html", "run_report",
           "write_limb_report", "write_report"]
