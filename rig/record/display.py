"""What the clinician sees while recording: coverage per sector, counts, annotations.

Two renderers with one interface (``start``, ``update(status)``, ``message(text)``, ``stop``):

- :class:`LiveDisplay` — a ``rich`` live panel redrawn a few times a second on a terminal: a
  header (patient, elapsed sample time, samples, rate, dropped), one row per azimuthal sector
  (its direction, reach, a bar of boundary samples, twist extremes, explored or not) and a
  banner that turns green, **COVERAGE SUFFICIENT**, when every sector is explored; on a whole
  limb, the movements its other joints (elbow, wrist; knee, ankle) have reached.
- :class:`PlainDisplay` — one progress line every ``interval_s`` seconds, for CI, pipes and logs
  (chosen automatically when stdout is not a terminal).
"""

from __future__ import annotations

import math
import sys
import time
from dataclasses import dataclass, field
from typing import TextIO

import numpy as np

from calibration.coverage import CoverageSummary

__all__ = ["LiveDisplay", "PlainDisplay", "RecordStatus", "make_display"]

_COMPASS = ("→", "↗", "↑", "↖", "←", "↙", "↓", "↘")


@dataclass
class RecordStatus:
    """Everything the display shows (plain values; built by the recorder)."""

    patient: str
    phase: str
    elapsed_s: float = 0.0
    samples: int = 0
    rate_hz: float = 0.0
    dropped: int = 0
    coverage: CoverageSummary | None = None
    annotations: list[tuple[float, str]] = field(default_factory=list)
    duration_s: float | None = None
    checkpoints: int | None = None  # neutral checkpoints marked (None: not marking)
    enter: str | None = None
    """What pressing Enter does now (hardware: start the calibration, mark a neutral
    checkpoint); None when the recorder is not listening for Enter."""
    last_t: float = math.nan
    """Host time (``t``, monotonic seconds) of the newest sample written."""
    angles: dict = field(default_factory=dict)
    """A whole limb's other joints: ``{joint: {movement: degrees}}`` reached so far
    (:class:`rig.record.guided.AnglesReached`), refreshed with :attr:`coverage`."""
    reached: np.ndarray | None = None
    """(M, 2) float64, degrees: azimuth and reach (angle from the centre) of the swing-map
    cells visited so far (:meth:`calibration.coverage.CoverageMap.reached`), refreshed with
    :attr:`coverage`; None before the recording proper."""


def _fmt(x: float, nd: int = 0) -> str:
    return "–" if not math.isfinite(x) else f"{x:.{nd}f}"


def progress_line(st: RecordStatus) -> str:
    """One line: phase, time, samples, rate, dropped, sectors explored, sufficient or not."""
    parts = [f"[{st.phase}]", f"t={st.elapsed_s:.1f}s"]
    if st.duration_s is not None:
        parts[-1] += f"/{st.duration_s:g}s"
    parts += [f"samples={st.samples}", f"rate={st.rate_hz:.0f}/s", f"dropped={st.dropped}"]
    if st.checkpoints is not None:
        parts.append(f"neutral={st.checkpoints}")
    cov = st.coverage
    if cov is not None and cov.sectors:
        reach = " ".join(_fmt(s.reach_deg) for s in cov.sectors)
        parts.append(f"explored={cov.explored}/{len(cov.sectors)}")
        parts.append(f"reach°=[{reach}]")
        parts.append(f"twist°={_fmt(cov.twist_deg[0])}..{_fmt(cov.twist_deg[1])}")
        parts.append("COVERAGE SUFFICIENT" if cov.sufficient else "coverage incomplete")
    return " ".join(parts)


class PlainDisplay:
    """Progress lines on a stream (no terminal control codes).

    Parameters
    ----------
    stream : text stream
    interval_s : float
        Least real time between two progress lines.
    """

    def __init__(self, stream: TextIO | None = None, *, interval_s: float = 1.0) -> None:
        self.stream = stream if stream is not None else sys.stdout
        self.interval_s = float(interval_s)
        self._last = -math.inf
        self._sufficient_said = False

    def start(self) -> None:
        pass

    def update(self, st: RecordStatus, *, force: bool = False) -> None:
        now = time.monotonic()
        cov = st.coverage
        newly = cov is not None and cov.sufficient and not self._sufficient_said
        if not force and not newly and now - self._last < self.interval_s:
            return
        self._last = now
        if newly:
            self._sufficient_said = True
        print(progress_line(st), file=self.stream, flush=True)

    def message(self, text: str) -> None:
        print(text, file=self.stream, flush=True)

    def stop(self) -> None:
        pass


class LiveDisplay:
    """A ``rich`` live panel (terminal only). Same interface as :class:`PlainDisplay`."""

    def __init__(self, console=None, *, refresh_per_second: float = 4.0) -> None:
        from rich.console import Console

        self.console = console if console is not None else Console()
        self.refresh_per_second = float(refresh_per_second)
        self._live = None
        self._last = -math.inf

    def start(self) -> None:
        from rich.live import Live

        self._live = Live(console=self.console, refresh_per_second=self.refresh_per_second,
                          transient=False, auto_refresh=False)
        self._live.start()

    def update(self, st: RecordStatus, *, force: bool = False) -> None:
        now = time.monotonic()
        if not force and now - self._last < 1.0 / self.refresh_per_second:
            return
        self._last = now
        if self._live is not None:
            self._live.update(render(st), refresh=True)

    def message(self, text: str) -> None:
        self.console.print(text)

    def stop(self) -> None:
        if self._live is not None:
            self._live.stop()
            self._live = None


def render(st: RecordStatus):
    """The panel for one status (a ``rich`` renderable)."""
    from rich.console import Group
    from rich.panel import Panel
    from rich.table import Table
    from rich.text import Text

    head = Text()
    head.append(f"patient {st.patient}  ", style="bold")
    head.append(f"{st.phase}  ", style="cyan")
    dur = f" / {st.duration_s:g}" if st.duration_s is not None else ""
    head.append(f"t {st.elapsed_s:6.1f}{dur} s   samples {st.samples}   "
                f"{st.rate_hz:5.0f}/s   ")
    head.append(f"dropped {st.dropped}", style="bold red" if st.dropped else "green")
    if st.checkpoints is not None:
        head.append(f"   neutral checkpoints {st.checkpoints}")
    parts: list = [head]
    cov = st.coverage
    if cov is not None and cov.sectors:
        table = Table(expand=False, box=None, pad_edge=False)
        table.add_column("sector")
        table.add_column("dir")
        table.add_column("reach °", justify="right")
        table.add_column("near-limit samples")
        table.add_column("twist °", justify="right")
        table.add_column("")
        need = max(1, _need(cov))
        for s in cov.sectors:
            mid = 0.5 * (s.azimuth_deg[0] + s.azimuth_deg[1])
            arrow = _COMPASS[int(((mid + 22.5) % 360) // 45)]
            frac = min(1.0, s.boundary_samples / need)
            bar = "█" * round(frac * 20) + "·" * (20 - round(frac * 20))
            state = ("[green]explored[/]" if s.explored else
                     "[yellow]still growing[/]" if s.samples and not s.stable else
                     "[yellow]needs samples[/]" if s.samples else "[red]not visited[/]")
            table.add_row(f"{s.azimuth_deg[0]:3.0f}-{s.azimuth_deg[1]:3.0f}°", arrow,
                          _fmt(s.reach_deg), bar,
                          f"{_fmt(s.twist_deg[0])}..{_fmt(s.twist_deg[1])}", state)
        parts.append(table)
        parts.append(Text(f"twist overall {_fmt(cov.twist_deg[0])}..{_fmt(cov.twist_deg[1])}°"))
        if cov.sufficient:
            parts.append(Text(" COVERAGE SUFFICIENT — you may stop (Ctrl-C) ",
                              style="bold white on green"))
        else:
            parts.append(Text(f" coverage: {cov.explored}/{len(cov.sectors)} sectors explored — "
                              "move to the limits in the sectors not yet explored ",
                              style="bold black on yellow"))
    for joint, moves in (st.angles or {}).items():  # a whole limb's other joints
        parts.append(Text(f"{joint} reached: " + ", ".join(
            f"{m.replace('_', ' ')} {v:.0f}°" for m, v in moves.items())))
    if st.annotations:
        last = st.annotations[-3:]
        parts.append(Text("notes: " + "; ".join(f"{t:.1f}s {txt}" for t, txt in last),
                          style="dim"))
    return Panel(Group(*parts), title="rig record", border_style="blue")


def _need(cov: CoverageSummary) -> int:
    # bars fill up at the map's threshold (or relative to the best sector without one)
    if cov.min_boundary_samples > 0:
        return cov.min_boundary_samples
    return max((s.boundary_samples for s in cov.sectors), default=1)


def make_display(kind: str = "auto", stream: TextIO | None = None):
    """``"live"`` (rich), ``"plain"`` (lines) or ``"auto"`` (live on a terminal)."""
    stream = stream if stream is not None else sys.stdout
    if kind == "auto":
        kind = "live" if getattr(stream, "isatty", lambda: False)() else "plain"
    if kind == "live":
        return LiveDisplay()
    if kind == "plain":
        return PlainDisplay(stream)
    raise ValueError(f"display must be auto, live or plain, got {kind!r}")
