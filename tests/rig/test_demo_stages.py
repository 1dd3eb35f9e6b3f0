"""The demo's stages (issue 37, item 4): a stage that fails stops the demo there, with its own
reason — a recording that lost its device is the FAIL, and the boundary after it is not run to
blame "recorded without the calibration steps"."""

from __future__ import annotations

import io
import types

from rich.console import Console

from rig.demo.stages import StageResult, recording_failure, run_stages
from rig.record.session import RecordResult

LOST = ("sim://imu-stream?sensors=4&limb=arm: the IMU board stopped answering (STOP command: "
        "no answer to STOP (4 attempts)); reconnecting failed for 2.0 s")


def _run(named) -> tuple[list[StageResult], list[str]]:
    stages: list[StageResult] = []
    lines: list[str] = []
    run_stages(types.SimpleNamespace(), named, stages, Console(file=io.StringIO()),
               lines.append)
    return stages, lines


def test_a_stage_that_fails_without_raising_stops_the_demo_with_its_own_reason():
    ran = []
    lost = RecordResult(7, 1, status="device_lost", samples=23_800, error=LOST)

    def record(st: StageResult) -> None:  # as the record stages end on a lost device
        ran.append("record")
        st.verdict = "FAIL"
        st.detail = f"{recording_failure(lost)}; session 7: 23,800 samples from 4 IMUs"

    def boundary(st: StageResult) -> None:
        ran.append("boundary")
        raise RuntimeError("session 7 was recorded without the calibration steps")

    def train(st: StageResult) -> None:
        ran.append("train")

    stages, lines = _run((("record", record), ("boundary", boundary), ("train", train)))
    assert ran == ["record"]  # before: the boundary ran, and failed for another reason
    assert [(s.name, s.verdict) for s in stages] == [
        ("record", "FAIL"), ("boundary", "SKIP"), ("train", "SKIP")]
    assert stages[0].detail.startswith(f"session 7 device_lost: {LOST}")
    assert stages[1].detail == "not run: record failed"
    assert "calibration steps" not in "\n".join(lines)


def test_a_stage_that_raises_still_stops_the_demo():
    def boundary(st: StageResult) -> None:
        raise RuntimeError("no boundary")

    stages, _ = _run((("record", lambda st: None), ("boundary", boundary),
                      ("train", lambda st: None)))
    assert [s.verdict for s in stages] == ["INFO", "FAIL", "SKIP"]
    assert stages[1].detail == "RuntimeError: no boundary"


def test_a_recording_failure_names_the_status_and_the_device_error():
    assert recording_failure(RecordResult(3, 1, status="interrupted")) == "session 3 interrupted"
    assert recording_failure(RecordResult(3, 1, status="device_lost", error=LOST)) == (
        f"session 3 device_lost: {LOST}")
