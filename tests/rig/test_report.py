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


# -- issue 37: what the report says and how its maps are drawn ---------------------------------
def test_recorded_time_says_what_it_counts():
    """A ``--duration 30`` session whose samples span 47 s (the calibration steps first) read
    "Recorded 47 s of motion"; it now says both."""
    from dataclasses import replace

    base = ReportData(patient="P-1", session_id=1, duration_s=47.2)
    assert "47 s of motion" in render_html(base)
    text = render_html(replace(base, free_motion_s=30.04, calibrated=True))
    assert "47 s in all: the calibration steps, then 30 s of free movement" in text
    assert "47 s of motion" not in text


def _captured_map(monkeypatch, **kw):
    """The figure :func:`boundary_figure` draws (not its PNG), for its artists' extents."""
    from rig.report import figures

    got = {}
    monkeypatch.setattr(figures, "to_png", lambda fig, dpi=110: got.setdefault("fig", fig))
    c = load_constraint(shape_path("original"))
    d = Q.limb_direction(ConstraintOracle(c).project(
        Q.random_quaternions(500, np.random.default_rng(1))))
    figures.boundary_figure(d, c.swing, **kw)
    fig = got["fig"]
    fig.canvas.draw()
    return fig


def test_map_legend_and_ring_labels_cover_no_anatomical_label(monkeypatch):
    """The legend sat over the label at the map's lower edge ("plantarflexion") and the ring
    labels on "anterior": the legend is now outside the map and the rings are labelled where
    no anatomical label is."""
    import matplotlib.pyplot as plt

    from rig.report.figures import anatomical_directions, joint_directions

    for side, labels in (("right", None), ("left", None), ("right", joint_directions("ankle",
                                                                                    "right"))):
        fig = _captured_map(monkeypatch, side=side, labels=labels)
        ax = fig.axes[0]
        r = fig.canvas.get_renderer()
        names = set(anatomical_directions(side) if labels is None else labels)
        texts = [t for t in ax.texts if t.get_text()]
        anat = [t for t in texts if any(t.get_text().startswith(n) for n in names)]
        rings = [t for t in texts if re.fullmatch(r"\d+°", t.get_text())]
        assert anat and rings
        legend = ax.get_legend().get_window_extent(r)
        assert legend.y1 <= ax.get_window_extent(r).y0 + 1  # below the map
        for a in anat:
            box = a.get_window_extent(r)
            assert not box.overlaps(legend), a.get_text()
            for t in rings:
                assert not box.overlaps(t.get_window_extent(r)), (a.get_text(), t.get_text())
        plt.close(fig)


def test_keyframe_outlines_never_share_a_style():
    from rig.report.figures import OUTLINE_COLOURS, outline_style

    styles = [outline_style(k) for k in range(2 * len(OUTLINE_COLOURS))]
    assert len(set(styles)) == len(styles)
    assert len(OUTLINE_COLOURS) >= 8 and "#4477aa" not in OUTLINE_COLOURS  # the samples' blue
