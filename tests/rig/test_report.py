"""The clinician's report: content of the HTML, and the page as headless Chromium draws it."""

from __future__ import annotations

import base64
import re

import numpy as np

from models import quaternion as Q
from models.constraint import load_constraint
from models.oracle import ConstraintOracle
from models.shapes import shape_path
from rig.report import ReportData, RomRow, render_html, write_report
from rig.report.figures import EqualAreaMap, boundary_figure, error_map_figure
from tests.rig.browser import dark_fraction, pixels_near, screenshot


def _data() -> ReportData:
    rng = np.random.default_rng(3)
    c = load_constraint(shape_path("original"))
    d = Q.limb_direction(ConstraintOracle(c).project(Q.random_quaternions(4000, rng)))
    v = c.swing.vertices
    dirs = Q.random_unit_vectors(1500, rng)
    return ReportData(
        patient="P-7F3A", session_id=12, side="right", rig="sim-imu",
        started="2026-11-23 13:00", duration_s=95.0, samples=38000, dropped=0,
        rom_rows=[RomRow("Flexion", 151.3, 180.0, "Gill 2020"), RomRow("Extension", 44.0, 60.0)],
        boundary_png=boundary_figure(d, c.swing, sparse_arcs=[(v[0], v[1])]),
        boundary_facts={"vertices": len(v)}, sparse_arcs_deg=[(12.0, 40.0)],
        calibrations=[{"kind": "static", "residual_deg": 0.7}],
        model_metrics={"mean 3-D error (%)": 0.41}, model_verdict="ok: within targets",
        error_map_png=error_map_figure(dirs, rng.random(len(dirs)), c.swing),
        enforcement={"rate_hz": 200.0, "interventions": 7}, enforcement_verdict="ok",
    )


def test_equal_area_map_keeps_the_centre_and_ring_radii():
    m = EqualAreaMap([0.0, 1.0, 0.0])
    np.testing.assert_allclose(m.project(np.array([[0.0, 1.0, 0.0]])), [[0.0, 0.0]], atol=1e-12)
    d = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
    r = np.linalg.norm(m.project(d), axis=1)
    np.testing.assert_allclose(r, [m.ring_radius(90), m.ring_radius(90), 2.0], atol=1e-12)


def test_html_is_self_contained_and_carries_every_section():
    text = render_html(_data())
    assert "P-7F3A" in text and "session 12" in text
    for heading in ("Range of motion", "Recorded boundary", "Calibration",
                    "Learned constraint model", "Live enforcement"):
        assert f">{heading}</h2>" in text
    assert "151.3" in text and "84" in text  # 151.3 / 180 = 84 %
    assert "12°–40°" in text  # the sparse arc is named
    # no external resources: every image is an embedded PNG
    assert not re.search(r"""(src|href)=["'](https?:|//|file:)""", text)
    images = re.findall(r'src="data:image/png;base64,([^"]+)"', text)
    assert len(images) == 2
    for b64 in images:
        assert base64.b64decode(b64)[:8] == b"\x89PNG\r\n\x1a\n"


def test_sections_without_data_are_left_out():
    text = render_html(ReportData(patient="P-1", session_id=1))
    assert "P-1" in text and "<h2>" not in text


def test_report_renders_in_headless_chromium(tmp_path):
    page = write_report(_data(), tmp_path / "report.html")
    img = screenshot(page, tmp_path, height=2600)
    assert dark_fraction(img) > 0.002  # text and outlines
    # the sparse arc / error-map boundary red and the sample blue are drawn
    assert pixels_near(img, "#cc3311", 0.08) > 200
    assert pixels_near(img, "#4477aa", 0.15) > 50
    # the verdict colour of the "ok" lines shows the page was styled
    assert pixels_near(img, "#1b7837", 0.08) > 20
