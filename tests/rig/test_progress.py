"""``rig progress``: a simulated patient over 6 visits with a known, changing range.

Each visit is a servo session of the right elbow (a hinge) and one of the right ankle (two
axes), written into a store offline as joint samples sweeping to the visit's true peaks
(:func:`calibration.joint_angles.from_angles`). Some movements improve by more than the MDC,
some by less; the elbow's 4th visit was interrupted and the ankle's 3rd had poor coverage
(both carry a value that would be a large change, so using them would show).
"""

from __future__ import annotations

import json
from itertools import pairwise

import numpy as np
import pytest

from calibration.joint_angles import from_angles
from calibration.mdc import MDC_TABLE, mdc_for, verdict
from calibration.norms import norm_band
from rig.cli import main
from rig.errors import RigConfigError
from rig.readback.progress import ProgressRequest, run_progress
from rig.report.progress import progress_section_html
from rig.report.session import ReportRequest, run_report
from rig.sim.patients import anatomical_limb
from rig.store import SampleWriter, open_store

DAY = 86_400.0
T0 = 1_780_000_000.0  # 2026-05-28
# true peaks per visit: elbow (flexion, extension), ankle (dorsiflexion, plantarflexion)
ELBOW = [(100, 10), (104, 12), (118, 11), (160, 40), (121, 21), (135, 20)]
ANKLE = [(8, 40), (10, 41), (35, 60), (20, 44), (21, 45), (30, 47)]
ELBOW_CUT, ANKLE_POOR = 3, 2  # visit indices (0-based)


def _sweep(pos: float, neg: float, n: int = 160) -> np.ndarray:
    """A movement from -neg to +pos and back, holding each end for 10 samples."""
    up = np.linspace(0.0, pos, n // 4)
    down = np.linspace(pos, -neg, n // 2)
    back = np.linspace(-neg, 0.0, n // 4)
    return np.concatenate([up, np.full(10, pos), down, np.full(10, -neg), back])


def _session(store, pid: int, joint: str, t: float, alpha: np.ndarray, beta: np.ndarray,
             status: str, meta: dict | None = None) -> int:
    sid = store.sessions.start(pid, rig_name="sim-servo", joint=joint, side="right",
                               started_at=t)
    store.samples.add_sensor(sid, joint, segment=joint, kind="joint", port="sim://dynamixel")
    q = from_angles(alpha, beta, 0.0, joint, "right")
    with SampleWriter(store, sid) as w:
        w.add_many(np.arange(len(q)) / 50.0, None, joint, "joint", q)
    store.sessions.end(sid, status=status, meta=meta or {})
    return sid


def _coverage(sufficient: bool) -> dict:
    return {"coverage": {"sectors": list(range(12)), "explored_sectors": 12 if sufficient else 5,
                         "sufficient": sufficient}}


@pytest.fixture(scope="module")
def clinic(tmp_path_factory):
    db = tmp_path_factory.mktemp("progress") / "clinic.db"
    with open_store(db) as store:
        pid = store.patients.add("P-0042")
        store.patients.add("P-EMPTY")
        for i in range(6):
            t = T0 + i * 14 * DAY
            fl, ex = ELBOW[i]
            _session(store, pid, "elbow", t, _sweep(fl, ex), np.zeros(1),
                     "interrupted" if i == ELBOW_CUT else "completed")
            df, pf = ANKLE[i]
            a = _sweep(df, pf)
            alpha = np.concatenate([a, np.zeros(60)])  # then inversion / eversion at α = 0
            beta = np.concatenate([np.zeros(len(a)), _sweep(15, 10, 40)])
            _session(store, pid, "ankle", t + 600, alpha, beta, "completed",
                     _coverage(i != ANKLE_POOR))
    return str(db)


def _true_changes(truth: list[tuple], k: int, skip: int):
    used = [i for i in range(6) if i != skip]
    first = truth[used[0]][k]
    out = {}
    for a, b in pairwise(used):
        out[b] = (truth[b][k] - first, truth[b][k] - truth[a][k])
    return out


def test_progress_recovers_every_change_and_verdict(clinic):
    res = run_progress(ProgressRequest(clinic, "P-0042"))
    assert res.computed == 12 and res.cached == 0
    by = {(v.joint, v.session_id): v for v in res.visits}
    cut = [v for v in res.visits if v.joint == "elbow" and not v.usable]
    poor = [v for v in res.visits if v.joint == "ankle" and not v.usable]
    assert len(cut) == 1 and cut[0].interrupted and "interrupted" in cut[0].excluded[0]
    assert len(poor) == 1 and "poor coverage" in poor[0].excluded[0]
    worst = 0.0
    for joint, truth, skip, moves in (("elbow", ELBOW, ELBOW_CUT, ("flexion", "extension")),
                                      ("ankle", ANKLE, ANKLE_POOR,
                                       ("dorsiflexion", "plantarflexion"))):
        series = res.series[(joint, "right")]
        for k, m in enumerate(moves):
            pts = series[m]
            assert len(pts) == 5  # the excluded visit is no point of the series
            want = _true_changes(truth, k, skip)
            used = [i for i in range(6) if i != skip]
            for i, p in zip(used, pts, strict=True):
                assert by[(joint, p.session_id)].usable
                assert abs(p.value - truth[i][k]) < 2.0
                if i == used[0]:
                    assert p.since_first is None
                    continue
                d_first, d_prev = want[i]
                worst = max(worst, abs(p.since_first - d_first), abs(p.since_previous - d_prev))
                mdc, _ = mdc_for(joint, m, "servo")
                assert p.first_verdict == verdict(d_first, mdc)
                assert p.previous_verdict == verdict(d_prev, mdc)
    assert worst < 2.0
    # the verdicts the truth was built to give: over and under the MDC
    fl = res.series[("elbow", "right")]["flexion"]
    assert [p.previous_verdict for p in fl[1:]] == ["within", "exceeds", "within", "exceeds"]
    df = res.series[("ankle", "right")]["dorsiflexion"]
    assert [p.previous_verdict for p in df[1:]] == ["within", "exceeds", "within", "exceeds"]
    assert df[1].mdc.reference and df[1].mdc.instrument == "goniometer"
    pf = res.series[("ankle", "right")]["plantarflexion"]
    assert pf[1].first_verdict is None and "no published MDC" in pf[1].mdc_text
    # the second call reads the cache only
    again = run_progress(ProgressRequest(clinic, "P-0042", joint="elbow"))
    assert again.computed == 0 and again.cached == 6
    assert [p.value for p in again.series[("elbow", "right")]["flexion"]] == \
        [p.value for p in fl]
    assert all(v.tests == {} for v in again.visits)  # sessions of one joint: no coupled tests


def test_progress_cli_table_json_and_errors(clinic, capsys):
    with pytest.raises(SystemExit) as e:
        main(["progress", "--db", clinic, "--patient", "P-0042", "--json"])
    assert e.value.code == 0
    out = json.loads(capsys.readouterr().out)
    assert len(out["visits"]) == 12 and sum(not v["usable"] for v in out["visits"]) == 2
    with pytest.raises(SystemExit):
        main(["progress", "--db", clinic, "--patient", "P-0042", "--joint", "ankle"])
    text = capsys.readouterr().out
    assert "poor coverage" in text and "dorsiflexion" in text and "exceeds" in text
    for args, msg in ((["--patient", "P-NONE"], "no patient 'P-NONE'"),
                      (["--patient", "P-EMPTY"], "has no recording sessions"),
                      (["--patient", "P-0042", "--joint", "hip"], "no session of the hip"),
                      (["--patient", "P-0042", "--joint", "toe"], "--joint")):
        with pytest.raises(SystemExit) as e:
            main(["progress", "--db", clinic, *args])
        assert e.value.code == 2
        err = capsys.readouterr().err
        assert msg in err and len(err.strip().splitlines()) == 1


def test_mdc_table_is_cited_and_verdicts_three_way():
    assert all(v.source and v.low <= v.high for v in MDC_TABLE.values())
    v, text = mdc_for("wrist", "flexion", "imu")
    assert v.low == 8 and v.high == 18 and v.reference and "no published MDC for imu" in text
    assert [verdict(d, v) for d in (5, 10, 20)] == ["within", "uncertain", "exceeds"]
    assert mdc_for("hip", "flexion", "servo")[0] is None
    assert mdc_for("wrist", "flexion", "file")[0].instrument == "motion-capture"


def test_progress_with_age_and_sex_gives_each_movements_norm(clinic, capsys):
    """``--age 50 --sex female``: each movement's published norm for a woman of 50
    (:func:`calibration.norms.norm_band`), with its source and method, in the series, the JSON,
    the table and the report's section; none is asked without them."""
    res = run_progress(ProgressRequest(clinic, "P-0042", age=50, sex="female"))
    for joint, moves in (("elbow", ("flexion", "extension")),
                         ("ankle", ("dorsiflexion", "plantarflexion"))):
        for m in moves:
            want = norm_band(joint, m, age=50, sex="female")
            assert res.norms[joint].get(m, []) == want
    dorsi = res.norms["ankle"]["dorsiflexion"][0]
    assert dorsi.sex == "female" and dorsi.contains(50)
    assert dorsi.source.key == "soucie2011"
    assert run_progress(ProgressRequest(clinic, "P-0042")).norms is None
    with pytest.raises(SystemExit) as e:
        main(["progress", "--db", clinic, "--patient", "P-0042", "--age", "50", "--sex",
              "female", "--json"])
    assert e.value.code == 0
    out = json.loads(capsys.readouterr().out)
    assert out["norms_for"] == {"age": 50, "sex": "female"}
    ankle = next(x for x in out["series"] if x["joint"] == "ankle")
    got = ankle["norms"]["dorsiflexion"][0]
    assert got["value"] == dorsi.value and got["age"] == [45, 69]
    assert "Soucie" in got["cite"] and "goniometer" in got["method"]
    with pytest.raises(SystemExit):
        main(["progress", "--db", clinic, "--patient", "P-0042", "--sex", "male"])
    text = capsys.readouterr().out
    assert "norms for: male, age unknown" in text and "norm dorsiflexion:" in text
    assert "(men," in text
    page = "\n".join(progress_section_html(res))
    assert "Norms for the patient" in page and "women, 45-69" in page
    with pytest.raises(SystemExit) as e:
        main(["progress", "--db", clinic, "--patient", "P-0042", "--age", "5"])
    assert e.value.code == 2


def test_report_has_the_progress_section(clinic, tmp_path):
    out = run_report(ReportRequest(clinic, 11, tmp_path / "r.html", age=50,
                                   sex="female")).path
    page = out.read_text()
    assert "Progress across visits" in page and "interrupted" in page
    assert page.count("data:image/png") >= 1 and "exceeds" in page
    assert "Norms for the patient" in page and "149 (women, 18-59)" in page  # Macedo 2008
    # an elbow's session: the elbow's own page, movements and norms (was: the shoulder's page,
    # with the shoulder's abduction, rotations and AAOS 180° flexion)
    assert "Elbow — hinge" in page and "Abduction" not in page and "Boone 1979" in page
    knee = tmp_path / "knee.yaml"  # a knee's limits drawn on the elbow's page: refused
    knee.write_text("name: k\nkind: hinge\njoint: knee\nhinge: {axis: [0, 0, -1], min_deg: 0, "
                    "max_deg: 140}\n")
    with pytest.raises(RigConfigError, match="--reference: the constraint is for the knee"):
        run_report(ReportRequest(clinic, 11, tmp_path / "k.html", reference=str(knee)))
    assert not (tmp_path / "k.html").exists()


def test_coupled_limits_compare_across_visits(tmp_path):
    """Two leg visits with stored limb files: each coupled joint's range at the same keyframe
    angles of the knee, from each visit's own limb file; the visits without samples are listed
    with why, never evidence."""
    db = tmp_path / "leg.db"
    limbs = [anatomical_limb(seed, "leg", "right") for seed in (3, 4)]
    with open_store(db) as store:
        pid = store.patients.add("P-LEG")
        for i, limb in enumerate(limbs):
            sid = store.sessions.start(pid, rig_name="sim-leg", side="right",
                                       meta={"limb": "leg"}, started_at=T0 + i * DAY)
            store.boundaries.add(sid, limb.to_yaml(), {"kind": "limb"})
            store.sessions.end(sid, status="completed")
    res = run_progress(ProgressRequest(str(db), "P-LEG", joint="ankle"))
    assert [v.usable for v in res.visits] == [False, False]
    assert "calibration" in res.visits[0].excluded[0]
    for v, limb in zip(res.visits, limbs, strict=True):
        c = v.coupled["ankle"]
        lj = limb.joints[limb.index("ankle")]
        assert c["by"] == "knee" and c["at_deg"] == [float(a) for a in lj.coupling.at_deg]
        # more dorsiflexion with the knee bent (the gastrocnemius slack), as the file says
        at = [f"{a:g}" for a in lj.coupling.at_deg]
        assert c["rom"][at[-1]]["dorsiflexion"] > c["rom"][at[0]]["dorsiflexion"]
    a, b = (v.coupled["ankle"]["rom"] for v in res.visits)
    assert a.keys() == b.keys() and a["0"]["dorsiflexion"] != b["0"]["dorsiflexion"]
    page = "\n".join(progress_section_html(res))
    assert "Coupled limits across visits" in page and "knee 90°" in page
    again = run_progress(ProgressRequest(str(db), "P-LEG", joint="ankle"))
    assert [v.coupled for v in again.visits] == [v.coupled for v in res.visits]
