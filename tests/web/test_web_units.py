"""Parts of the web app that need no server: the report cache's pruning."""

from __future__ import annotations

import os

from rig.web.clinic import prune_reports


def test_a_replaced_report_is_pruned_once_old(tmp_path):
    names = ["session-3-aaa.html", "session-3-bbb.html", "session-3-ccc.html",
             "session-31-ddd.html"]
    for k, name in enumerate(names):
        (tmp_path / name).write_text("x")
        os.utime(tmp_path / name, (1000.0 + k, 1000.0 + k))
    os.utime(tmp_path / "session-3-bbb.html", (1900.0, 1900.0))  # sent a moment ago
    gone = prune_reports(tmp_path / "session-3-ccc.html", grace_s=600, now=2000.0)
    assert [p.name for p in gone] == ["session-3-aaa.html"]
    assert sorted(p.name for p in tmp_path.iterdir()) == names[1:]
