"""``rig demo --limb arm`` ends with the live stage on the simulated 7-servo arm (issue 39,
item 6): the limb model trained in the demo, in ``rig enforce``'s loop on ``sim-servo-arm``
back-driven by the recording's seeded patient, against adversarial targets with coupled
segments; its verdict from the exact limb oracle on the commanded columns. A shortened quick
run (60 s of motion at patient time ×10, 2 s live): the figures of the full size are in
docs/demo.md."""

from __future__ import annotations

import io
import re
from dataclasses import replace

import pytest
from rich.console import Console

from models.limb import load_limb
from rig.commands.demo import print_summary
from rig.demo import DemoOptions, run_demo
from rig.demo import limb as limb_demo
from rig.devices.config import load_rig_config
from rig.store import open_store

pytestmark = pytest.mark.xdist_group("test_demo_limb_arm")


@pytest.fixture(scope="module")
def arm_demo(tmp_path_factory):
    out = tmp_path_factory.mktemp("arm-demo")
    sizes, live = dict(limb_demo.LIMB_SIZES), dict(limb_demo.LIVE_S)
    limb_demo.LIMB_SIZES["quick"] = replace(sizes["quick"], motion_s=60.0, eval_n=400,
                                            time_scale=10.0)
    limb_demo.LIVE_S["quick"] = 2.0
    try:
        console = Console(file=io.StringIO(), width=200)
        result = run_demo(DemoOptions(out=out, seed=5, quick=True, limb="arm"), console=console)
        print_summary(result, console)  # what `rig demo` prints at the end
        text = console.file.getvalue()
    finally:
        limb_demo.LIMB_SIZES.update(sizes)
        limb_demo.LIVE_S.update(live)
    return {"out": out, "result": result, "text": text}


def test_the_arm_demo_ends_with_the_live_stage_on_the_servo_arm(arm_demo):
    result, text, out = arm_demo["result"], arm_demo["text"], arm_demo["out"]
    verdicts = {s.name: s.verdict for s in result.stages}
    assert list(verdicts) == ["patient", "record", "boundary", "train", "evaluate", "report",
                              "live"]
    assert "FAIL" not in verdicts.values() and "SKIP" not in verdicts.values(), text
    # every stage's verdict printed, and the total time
    for name, verdict in verdicts.items():  # as each stage ends, and in the summary table
        if name != "patient":  # the first stage, before the stages' display
            assert re.search(rf"^\[{verdict}\] {name} \(", text, re.M), (name, text)
        assert re.search(rf"│ {name}\s+│\s+[0-9.]+ s │ {verdict}", text), (name, text)
    assert re.search(r"every stage ran in \d+ s", text), text
    assert re.search(r"│ total\s+│\s+[0-9.]+ s", text), text

    # the servo arm's patient is the recording's: the seeded arm of patient-arm.yaml
    rig = load_rig_config(str(out / "rigs" / "sim-servo-arm.yaml"))
    assert f"patient={(out / 'patient-arm.yaml').resolve()}" in rig.servos.port
    assert "limb=" not in rig.servos.port and "seed=5" in rig.servos.port
    # the IMU-recorded elbow is a hinge, held on the servo arm's forearm elbow
    limb = load_limb(out / "arm.yaml")
    assert [j.kind for j in limb.joints] == ["ball", "hinge", "two-axis"]
    assert [j.kind for j in rig.servos.joints] == ["ball", "forearm", "two-axis"]

    live = result.stage("live").figures
    assert live["commanded_judged"] > 200 and live["commanded_beyond_1deg"] == 0, live
    assert live["exit_status"] in (0, 1)  # 1: a safe state (WARN), never a command beyond
    assert set(live["joints"]) == {"shoulder", "elbow", "wrist"}
    for f in live["joints"].values():
        assert "tracking_p50_deg" in f and "tracking_p95_deg" in f
    assert (out / "live-telemetry.csv").is_file() and (out / "live-summary.json").is_file()
    detail = result.stage("live").detail
    assert "commanded postures beyond 1° in any joint" in detail and "overruns" in detail
    assert "tracking of valid targets" in detail

    # the run is stored as an enforce session naming the arm's recording
    with open_store(out / "rig.db", create=False) as store:
        enf = store.sessions.get(result.sessions["live"])
        assert enf["kind"] == "enforce" and enf["rig_name"] == "sim-servo-arm"
        assert enf["meta"]["recording_session"] == result.sessions["arm"]
        (run,) = store.runs.list(enf["id"])
        assert run["summary"]["cycles"] == live["cycles"]
