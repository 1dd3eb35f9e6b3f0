"""``rig demo``: the whole job on the simulated rig, stage by stage, with a verdict per stage —
one pipeline for the shoulder (:mod:`rig.demo.joint`) and a whole arm or leg
(``--limb arm|leg``, :mod:`rig.demo.limb`).

:func:`run_demo` checks the options (one-line errors before anything is opened or written),
checks the output folder, runs the demo's checks before anything is written (the shoulder's:
the hardware given by port), writes the simulated patient (the first stage) and runs the
stages that follow in order under one progress display (:func:`rig.demo.stages.run_stages`: a
stage that fails stops the demo there, the rest are SKIP). Everything goes into one store,
``<out>/rig.db``; the last stage writes the report, ``<out>/report.html``.
"""

from __future__ import annotations

import time

from rich.console import Console

from models.fileio import check_output
from rig.demo.joint import JointDemo
from rig.demo.limb import LimbDemo
from rig.demo.stages import DemoOptions, DemoResult, StageResult, run_stages

__all__ = ["run_demo"]


def run_demo(options: DemoOptions, *, console=None) -> DemoResult:
    """Run every stage of the demo ``options`` asks for: the shoulder's (``options.limb``
    None) or a whole arm's or leg's; returns the stages and what they produced.

    Parameters
    ----------
    options : DemoOptions
    console : rich.console.Console, optional
        Where progress and the summary go (default: stdout).

    Raises
    ------
    RigError
        A bad option or an unreachable device given by port, before anything is written.
    """
    # --limb chooses the demo, here only: what differs lives in JointDemo / LimbDemo
    demo = LimbDemo(options) if options.limb is not None else JointDemo(options)
    console = console if console is not None else Console()
    out = check_output(options.out, "--out", folder=True)  # before any stage
    t_all = time.perf_counter()
    stages: list[StageResult] = []

    def log(text: str) -> None:
        console.print(text, highlight=False, markup=False)

    early = demo.check(log)  # hardware given by port: before anything is written
    out.mkdir(parents=True, exist_ok=True)
    result = DemoResult(out=out, db=out / "rig.db", stages=stages)
    stages.extend(early)
    ctx, named = demo.patient(result, log)
    run_stages(ctx, named, stages, console, log)
    result.total_s = time.perf_counter() - t_all
    return result
