"""What every demo shares (``rig demo``, ``rig demo --limb arm|leg``; :func:`rig.demo.run_demo`):
the options, a stage's result and the demo's, the recorder's progress display, the shipped rig
configurations, running the stages in order and the report stage."""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

from rich.progress import BarColumn, Progress, SpinnerColumn, TextColumn, TimeElapsedColumn

from models.yamlio import safe_load_yaml
from rig.report import ReportRequest, run_report

__all__ = ["DemoOptions", "DemoResult", "RecordingDisplay", "StageResult", "recording_failure",
           "report_stage", "run_stages", "shipped_config"]


@dataclass
class DemoOptions:
    """What ``rig demo`` takes: ``limb`` None for the shoulder, ``"arm"`` or ``"leg"`` for a
    whole limb (``--limb``); the servo and IMU ports, ids, baud and loop rate are the
    shoulder's."""

    out: Path = Path("demo-output")
    seed: int = 0
    quick: bool = False
    dxl_port: str | None = None
    dxl_ids: tuple[int, ...] = (1, 2, 3)
    dxl_baud: int = 1_000_000
    imu_port: str | None = None
    rate_hz: float = 200.0
    limb: str | None = None


@dataclass
class StageResult:
    """One stage: how long it took, its verdict and the figures behind it.

    ``verdict`` is ``PASS`` (a target met), ``WARN`` (ran, but a target missed for a reason
    the demo names), ``FAIL``, ``INFO`` (no target) or ``SKIP``.
    """

    name: str
    seconds: float = 0.0
    verdict: str = "INFO"
    detail: str = ""
    figures: dict[str, Any] = field(default_factory=dict)


@dataclass
class DemoResult:
    """Everything the demo produced."""

    out: Path
    db: Path
    stages: list[StageResult] = field(default_factory=list)
    report: Path | None = None
    sessions: dict[str, int] = field(default_factory=dict)
    total_s: float = 0.0

    def stage(self, name: str) -> StageResult:
        return next(s for s in self.stages if s.name == name)

    @property
    def ok(self) -> bool:
        """No stage failed."""
        return all(s.verdict != "FAIL" for s in self.stages)


def shipped_config(name: str) -> dict:
    """The shipped rig configuration ``rig/configs/<name>.yaml`` as a dict (to be re-pointed at
    the demo's patient and written into ``<out>/rigs``)."""
    return safe_load_yaml(resources.files("rig").joinpath("configs", f"{name}.yaml").read_text())


class RecordingDisplay:
    """The recorder's display interface (:class:`rig.record.PlainDisplay`) on a rich progress
    task: elapsed sample time against the duration, samples, rate, dropped."""

    def __init__(self, progress, task, label: str, log) -> None:
        self.progress, self.task, self.label, self.log = progress, task, label, log
        self.last = None

    def start(self) -> None:
        pass

    def update(self, st, *, force: bool = False) -> None:
        self.last = st
        total = st.duration_s or 1.0
        done = min(total, st.elapsed_s) if st.phase == "recording" else 0.0
        self.progress.update(self.task, total=total, completed=done,
                             description=f"{self.label}: {st.phase}, {st.samples:,} samples, "
                                         f"{st.rate_hz:,.0f}/s, dropped {st.dropped}")

    def message(self, text: str) -> None:
        self.log(f"    {text}")

    def stop(self) -> None:
        pass


def recording_failure(res) -> str:
    """Why a recording stage failed, first in its detail: the session's status and the
    device's error (``device_lost: … no answer to STOP (4 attempts)``)."""
    return f"session {res.session_id} {res.status}" + (f": {res.error}" if res.error else "")


def run_stages(ctx, named, stages: list[StageResult], console, log) -> None:
    """Run ``named`` ((name, method(StageResult)), ...) in order under one progress display,
    appending each stage's result to ``stages``: a stage that raises or ends FAIL (a recording
    that lost its device) stops the demo there with its own reason, and the rest are SKIP (the
    summary is still shown) — a later stage would only blame what the failed one left it.
    ``ctx.progress`` / ``ctx.task`` are set for the recording display."""
    with Progress(SpinnerColumn(), TextColumn("{task.description}"), BarColumn(),
                  TimeElapsedColumn(), console=console, transient=True) as progress:
        ctx.progress = progress
        failed: str | None = None
        for name, fn in named:
            st = StageResult(name)
            task = progress.add_task(name, total=None)
            ctx.task = task
            t = time.perf_counter()
            if failed:
                st.verdict, st.detail = "SKIP", f"not run: {failed} failed"
            else:
                try:
                    fn(st)
                    if st.verdict == "FAIL":  # failed without raising: it ends the run too
                        failed = name
                except Exception as err:  # a stage that breaks ends the run, summary still shown
                    st.verdict = "FAIL"
                    done = f"{st.detail}; " if st.detail else ""
                    st.detail = f"{done}{type(err).__name__}: {err}"
                    failed = name
                finally:
                    st.seconds = time.perf_counter() - t
                    progress.remove_task(task)
            stages.append(st)
            log(f"[{st.verdict}] {name} ({st.seconds:.1f} s): {st.detail}")


def report_stage(st: StageResult, result: DemoResult, session: int, model: Path, truth,
                 eval_n: int) -> None:
    """The demos' report stage: ``rig report`` of ``session`` into ``<out>/report.html``, the
    ``model`` scored on ``eval_n`` held-out inputs, ``truth`` drawn dashed."""
    path = run_report(ReportRequest(result.db, session, result.out / "report.html",
                                    model=model, reference=truth, eval_n=eval_n)).path
    result.report = path
    st.figures["path"] = str(path)
    st.verdict = "INFO"
    st.detail = f"{path} ({path.stat().st_size / 1024:.0f} KiB, figures embedded)"
