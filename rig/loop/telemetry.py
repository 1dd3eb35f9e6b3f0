"""Per-cycle telemetry of the live loop: preallocated rows, a writer thread, the run summary.

The control loop hands one tuple per cycle to :meth:`Telemetry.record` (one numpy row
assignment into a preallocated chunk, no allocation beyond the tuple). Full chunks go to a
writer thread that appends them to the ``--telemetry`` CSV and to the store
(:class:`rig.store.TelemetryWriter`); the loop never waits on a disk or a database.
Cycle times and lateness are also kept in compact growing arrays for the summary.

Columns (:data:`COLUMNS`; orientations scalar-first joint orientations, parent frame)
-------------------------------------------------------------------------------------
=====================  =========================================================================
``cycle``              cycle index (deadline ``t0 + cycle / rate``; skipped indices = overruns)
``t_s``                loop time of the cycle's start, s since the loop started
``target_w..z``        the target as the source gave it (may be NaN / zero / non-unit)
``correction_w..z``    the learned model's correction (NaN when the target was not usable)
``commanded_w..z``     the orientation the goal ticks sent encode (forward kinematics)
``present_w..z``       present orientation (forward kinematics of the sync read)
``correction_deg``     angle of the model's correction, degrees
``violation_deg``      how far the commanded orientation is outside, degrees (0 inside)
``distance_deg``       signed distance of the commanded orientation (> 0 outside, < 0 margin)
``read_ms``            sync read (retries included), ms
``compute_ms``         model + supervisor + IK + FK, ms
``write_ms``           sync write, ms
``cycle_ms``           the whole cycle's work, ms
``late_ms``            start − deadline, ms
``intervention``       :class:`rig.loop.supervisor.Intervention` bits
``faults``             :class:`Fault` bits
``safe_state``         1 from the cycle the safe state was entered
=====================  =========================================================================

A run driven by a leader arm (``--targets leader:...``) adds, after these,
:data:`rig.loop.leader.LEADER_COLUMNS`: ``leader_ms`` (the leader's sync read, ms),
``target_age_ms`` (the target's age when the cycle's goal was written: from the leader's sample
to the end of the sync write, ms) and ``leader_read`` (1 when this cycle's read gave the target,
0 when it failed). Other runs' columns are unchanged.
"""

from __future__ import annotations

import json
import math
import queue
import threading
import time
from enum import IntFlag
from pathlib import Path

import numpy as np

from models.fileio import open_owner_only
from rig.loop.supervisor import SAFETY_FLAGS, Intervention

__all__ = ["CAUSES", "COLUMNS", "JOINT_COLUMNS", "LIMB_COLUMNS", "Fault", "Telemetry",
           "count_causes", "late_causes", "summarise", "telemetry_columns"]


class Fault(IntFlag):
    """Faults seen in a cycle (bits)."""

    NONE = 0
    READ_RETRY = 1        #: a sync read failed and was retried within the cycle
    READ_TIMEOUT = 2      #: a sync read attempt timed out (dropped status packets)
    READ_CORRUPT = 4      #: a sync read attempt got garbled bytes (bad CRC, truncated)
    READ_FAILED = 8       #: no fresh present position this cycle
    WRITE_FAILED = 16     #: the sync write raised
    HARDWARE_ALERT = 32   #: a servo reported a hardware error (overload, overheating, ...)
    CONNECTION_LOST = 64  #: the adapter went away
    STALE_PRESENT = 128   #: servo data older than the watchdog allows
    OVERRUN = 256         #: the cycle ended after the next deadline
    TARGET_LOST = 512     #: the target source failed (its device vanished)
    SIGNAL = 1024         #: SIGINT / SIGTERM
    WATCHDOG_GAP = 2048   #: no bus traffic for longer than the servos' Bus Watchdog: it fired
    GOAL_NOT_HELD = 4096  #: a servo does not hold the goal written the cycle before


#: Faults that send the limb to the safe state at once.
SAFE_STATE_FAULTS = int(Fault.HARDWARE_ALERT | Fault.CONNECTION_LOST | Fault.STALE_PRESENT
                        | Fault.SIGNAL | Fault.WATCHDOG_GAP | Fault.GOAL_NOT_HELD)

COLUMNS: tuple[str, ...] = (
    "cycle", "t_s",
    "target_w", "target_x", "target_y", "target_z",
    "correction_w", "correction_x", "correction_y", "correction_z",
    "commanded_w", "commanded_x", "commanded_y", "commanded_z",
    "present_w", "present_x", "present_y", "present_z",
    "correction_deg", "violation_deg", "distance_deg",
    "read_ms", "compute_ms", "write_ms", "cycle_ms", "late_ms",
    "intervention", "faults", "safe_state",
)
#: One joint's columns in a run of several joints, each prefixed ``<joint>_``
#: (:func:`telemetry_columns`).
JOINT_COLUMNS: tuple[str, ...] = (
    "target_w", "target_x", "target_y", "target_z",
    "correction_w", "correction_x", "correction_y", "correction_z",
    "commanded_w", "commanded_x", "commanded_y", "commanded_z",
    "present_w", "present_x", "present_y", "present_z",
    "correction_deg", "violation_deg", "distance_deg", "intervention",
)
#: The whole limb's columns after the joints' in a run of several joints.
LIMB_COLUMNS: tuple[str, ...] = (
    "violation_deg", "read_ms", "compute_ms", "write_ms", "cycle_ms", "late_ms",
    "intervention", "faults", "safe_state",
)


def telemetry_columns(joint_names=None) -> tuple[str, ...]:
    """The telemetry's column names of a run over the joints ``joint_names``.

    One joint (or None): :data:`COLUMNS`, today's names exactly. Several: ``cycle``, ``t_s``,
    then for each joint in the limb file's order :data:`JOINT_COLUMNS` prefixed ``<joint>_``
    (e.g. ``elbow_target_w``, ``elbow_violation_deg``, ``elbow_intervention``), then the whole
    limb's :data:`LIMB_COLUMNS` (``violation_deg``: the largest joint's; ``intervention``: the
    joints' bits OR-ed).
    """
    names = tuple(joint_names or ())
    if len(names) <= 1:
        return COLUMNS
    return ("cycle", "t_s", *(f"{j}_{c}" for j in names for c in JOINT_COLUMNS), *LIMB_COLUMNS)


def _is_int_column(name: str) -> bool:
    return name in _INT_COLUMNS or name.endswith("_intervention")


_INT_COLUMNS = frozenset({"cycle", "intervention", "faults", "safe_state"})
_STORE_DROP = ("faults", "safe_state")

CHUNK = 2048
_SLICE = 64  # rows the writer formats before it pauses
_PAUSE_S = 0.0005
#: one CSV row (as ``csv.writer`` writes it: integers, floats to 9 significant digits, CRLF)
COLUMNS_ROW_FORMAT = ",".join("%d" if c in _INT_COLUMNS else "%.9g" for c in COLUMNS) + "\r\n"


def _fault_names(bits: int) -> str | None:
    if not bits:
        return None
    return "|".join(f.name.lower() for f in Fault if f.value and bits & f.value)


class Telemetry:
    """Collects rows; writes them off the hot path.

    Parameters
    ----------
    csv_path : str or Path, optional
        Telemetry CSV (header :data:`COLUMNS`).
    store_writer : object with ``add_many(rows)`` and ``close()``, optional
        :class:`rig.store.TelemetryWriter`.
    keep : bool
        Keep every row in memory as well (tests and short runs: :meth:`table`).
    columns : tuple of str, optional
        :func:`telemetry_columns` of the run's joints (default :data:`COLUMNS`), then the
        names of ``extra``'s values.
    extra : callable(t_s, cycle_ms) -> tuple of float, optional
        Values a target source adds to each row, after the loop's own (a leader arm's
        ``leader_ms``, ``target_age_ms``, ``leader_read``: :meth:`rig.loop.leader.LeaderTargets.
        telemetry_values`); called with the row's ``t_s`` and ``cycle_ms``.
    """

    def __init__(self, csv_path=None, store_writer=None, *, keep: bool = False,
                 columns: tuple[str, ...] | None = None, extra=None):
        self.extra = extra
        self.columns = COLUMNS if columns is None else tuple(columns)
        cols = self.columns
        self.n_col = len(cols)
        self._int = tuple(_is_int_column(c) for c in cols)
        self._row_format = (COLUMNS_ROW_FORMAT if cols == COLUMNS else
                            ",".join("%d" if i else "%.9g" for i in self._int) + "\r\n")
        self._ix = tuple(cols.index(c) for c in ("cycle_ms", "late_ms", "compute_ms",
                                                  "read_ms", "write_ms", "faults",
                                                  "intervention", "safe_state"))
        self.csv_path = None if csv_path is None else Path(csv_path)
        self.store_writer = store_writer
        self.keep = keep
        self.kept: list[np.ndarray] = []
        self._chunk = np.empty((CHUNK, self.n_col))
        self._i = 0
        self.rows = 0
        self._cycle_ms = np.empty(1 << 14)
        self._late_ms = np.empty(1 << 14)
        self._compute_ms = np.empty(1 << 14)
        self._bus_ms = np.empty(1 << 14)
        self._faults = np.empty(1 << 14, dtype=np.int64)
        self._q: queue.Queue = queue.Queue()
        self._fh = None
        self.error: BaseException | None = None
        if self.csv_path is not None:
            self.csv_path.parent.mkdir(parents=True, exist_ok=True)

            self._fh = open_owner_only(self.csv_path, "w", newline="")  # names the run
            self._fh.write(",".join(self.columns) + "\r\n")
        self._thread = None
        if self._fh is not None or store_writer is not None:
            self._thread = threading.Thread(target=self._run, name="rig-loop-telemetry",
                                            daemon=True)
            self._thread.start()

    # ------------------------------------------------------------------ hot path
    def record(self, row: tuple) -> None:
        """Append one cycle's row (a tuple in :data:`COLUMNS` order)."""
        ix = self._ix
        if self.extra is not None:
            row = (*row, *self.extra(row[1], row[ix[0]]))
        i = self._i
        self._chunk[i] = row
        n = self.rows
        if n >= len(self._cycle_ms):
            self._grow()
        self._cycle_ms[n] = row[ix[0]]
        self._late_ms[n] = row[ix[1]]
        self._compute_ms[n] = row[ix[2]]
        self._bus_ms[n] = row[ix[3]] + row[ix[4]]
        self._faults[n] = row[ix[5]]
        self.rows = n + 1
        i += 1
        if i == CHUNK:
            self._hand_over(self._chunk)
            self._chunk = np.empty((CHUNK, self.n_col))
            i = 0
        self._i = i

    def _grow(self) -> None:
        for name in ("_cycle_ms", "_late_ms", "_compute_ms", "_bus_ms", "_faults"):
            a = getattr(self, name)
            b = np.empty(2 * len(a), dtype=a.dtype)
            b[:len(a)] = a
            setattr(self, name, b)

    def _hand_over(self, block: np.ndarray) -> None:
        if self.keep:
            self.kept.append(block)
        if self._thread is not None:
            self._q.put(block)

    # ------------------------------------------------------------------ writer thread
    def _run(self) -> None:
        while True:
            block = self._q.get()
            if block is None:
                return
            try:
                self._write(block)
            except BaseException as err:  # reported by close()
                self.error = err

    def _write(self, block: np.ndarray) -> None:
        # in slices, pausing between them: the loop's thread never waits long for the
        # interpreter lock while a block is formatted (one %-format per CSV row)
        for lo in range(0, len(block), _SLICE):
            part = block[lo:lo + _SLICE]
            if self._fh is not None:
                fmt = self._row_format
                self._fh.write("".join(fmt % tuple(r) for r in part.tolist()))
            if self.store_writer is not None:
                rows = []
                ints, cols, ix = self._int, self.columns, self._ix
                for r in part.tolist():
                    d = {c: (int(v) if i else float(v))
                         for c, v, i in zip(cols, r, ints, strict=True)
                         if c not in _STORE_DROP}
                    d["fault"] = _fault_names(int(r[ix[5]]))
                    d["intervention_flags"] = int(r[ix[6]])
                    d["safe_state"] = int(r[ix[7]])
                    rows.append(d)
                self.store_writer.add_many(rows)
            time.sleep(_PAUSE_S)
        if self._fh is not None:
            self._fh.flush()

    def flush_partial(self) -> None:
        """Hand the rows recorded so far over (end of run)."""
        if self._i:
            self._hand_over(self._chunk[: self._i].copy())
            self._i = 0

    def close(self) -> None:
        """Flush everything, stop the thread, close the CSV (idempotent)."""
        self.flush_partial()
        if self._thread is not None:
            self._q.put(None)
            self._thread.join()
            self._thread = None
        if self._fh is not None:
            self._fh.close()
            self._fh = None
        if self.store_writer is not None:
            close = getattr(self.store_writer, "close", None)
            self.store_writer = None
            if close is not None:
                close()

    # ------------------------------------------------------------------ reading back
    def table(self) -> dict[str, np.ndarray]:
        """Every row kept (``keep=True``), one array per column."""
        blocks = [*self.kept]
        if self._i:
            blocks.append(self._chunk[: self._i])
        arr = np.concatenate(blocks) if blocks else np.empty((0, self.n_col))
        return {c: (arr[:, k].astype(np.int64) if i else arr[:, k])
                for k, (c, i) in enumerate(zip(self.columns, self._int, strict=True))}

    def cycle_ms(self) -> np.ndarray:
        return self._cycle_ms[: self.rows].copy()

    def late_ms(self) -> np.ndarray:
        return self._late_ms[: self.rows].copy()

    def compute_ms(self) -> np.ndarray:
        return self._compute_ms[: self.rows].copy()

    def bus_ms(self) -> np.ndarray:
        """Sync read + sync write time per cycle, ms."""
        return self._bus_ms[: self.rows].copy()

    def faults(self) -> np.ndarray:
        """:class:`Fault` bits per cycle."""
        return self._faults[: self.rows].copy()


#: The causes a late cycle is put down to (:func:`late_causes`).
CAUSES = ("scheduler", "bus", "compute")

#: A cycle that starts this much after its deadline is *late* (ms): a 5 ms period's 10 %.
LATE_START_MS = 0.5


def late_causes(late_ms, bus_ms, compute_ms, overrun) -> np.ndarray:
    """The cause of each cycle's lateness, an index into :data:`CAUSES` (-1: on time).

    A cycle that **overran** (ended after the next deadline) is put down to the part of its
    span that exceeded its run median by the most: its start's lateness (``scheduler``: the
    host woke the loop late), the sync read + sync write (``bus``: replies slow or retried), or
    the model + supervisor + kinematics (``compute``). The loop computes while the read's reply
    travels (:mod:`rig.loop.runner`): ``read_ms`` is the time it was blocked on the read — the
    request, the wait left after the compute, the parse, retries — so a slow reply shows as
    ``bus`` and a compute longer than the reply's flight as ``compute``. A cycle that **started
    late** (> :data:`LATE_START_MS`) without overrunning inherits the cause of the overrun
    before it, if any, else ``scheduler`` (the host woke the loop late).

    Parameters
    ----------
    late_ms, bus_ms, compute_ms : array (N,)
        Telemetry columns ``late_ms``, ``read_ms + write_ms``, ``compute_ms``.
    overrun : array of bool (N,)
        The :attr:`Fault.OVERRUN` bit.

    Returns
    -------
    array of int (N,)
    """
    late = np.asarray(late_ms, dtype=np.float64)
    bus = np.asarray(bus_ms, dtype=np.float64)
    comp = np.asarray(compute_ms, dtype=np.float64)
    over = np.asarray(overrun, dtype=bool)
    out = np.full(len(late), -1, dtype=np.int64)
    if len(late) == 0:
        return out
    excess = np.stack([late - np.median(late), bus - np.median(bus),
                       comp - np.median(comp)], axis=1)
    out[over] = np.argmax(excess[over], axis=1)
    started_late = (late > LATE_START_MS) & ~over
    idx = np.flatnonzero(started_late)
    prev = idx - 1
    inherit = (prev >= 0) & over[np.maximum(prev, 0)]
    out[idx] = np.where(inherit, out[np.maximum(prev, 0)], 0)
    return out


def count_causes(causes: np.ndarray, mask=None) -> dict[str, int]:
    """``{cause: cycles}`` of :func:`late_causes` (only where ``mask``), every cause listed."""
    c = np.asarray(causes)
    if mask is not None:
        c = c[np.asarray(mask, dtype=bool)]
    return {name: int(np.count_nonzero(c == k)) for k, name in enumerate(CAUSES)}


def _pct(a: np.ndarray, p: float) -> float | None:
    return None if len(a) == 0 else float(np.percentile(a, p))


def summarise(*, rate_hz: float, telemetry: Telemetry, counters: dict, duration_s: float,
              extra: dict | None = None) -> dict:
    """The end-of-run summary (JSON-ready).

    Keys: ``rate_hz`` (configured), ``achieved_hz``, ``cycles``, ``duration_s``,
    ``p50_cycle_ms``, ``p99_cycle_ms``, ``max_cycle_ms``, ``p50_late_ms``, ``p99_late_ms``,
    ``max_late_ms``,
    ``overruns``, ``overruns_by_cause`` and ``late_starts_by_cause`` (:func:`late_causes`: the
    overruns, and the cycles that started more than :data:`LATE_START_MS` late without
    overrunning, by cause), ``skipped_deadlines``, ``p50_compute_us``, ``max_violation_deg``,
    ``interventions`` (cycles with any safety intervention), ``interventions_by_kind`` (each
    such cycle under one kind: they add up to ``interventions``), ``rate_limited`` (cycles the
    velocity / acceleration limits shaped; not interventions),
    ``faults`` (counts by kind), ``safe_state_entries``, ``safe_state_reason``, plus ``extra``.
    """
    cyc = telemetry.cycle_ms()
    late = telemetry.late_ms()
    comp = telemetry.compute_ms()
    n = telemetry.rows
    out = {
        "rate_hz": float(rate_hz),
        "achieved_hz": (n / duration_s) if duration_s > 0 else None,
        "cycles": int(n),
        "duration_s": float(duration_s),
        "p50_cycle_ms": _pct(cyc, 50),
        "p99_cycle_ms": _pct(cyc, 99),
        "max_cycle_ms": None if n == 0 else float(cyc.max()),
        "p50_late_ms": _pct(late, 50),
        "p99_late_ms": _pct(late, 99),
        "max_late_ms": None if n == 0 else float(late.max()),
        "p50_compute_us": None if n == 0 else 1e3 * float(np.median(comp)),
    }
    over = (telemetry.faults() & int(Fault.OVERRUN)) != 0
    causes = late_causes(late, telemetry.bus_ms(), comp, over)
    out["overruns_by_cause"] = count_causes(causes, over)
    out["late_starts_by_cause"] = count_causes(causes, ~over)
    out.update(counters)
    if extra:
        out.update(extra)
    return json.loads(json.dumps(out, default=_jsonable))


def _jsonable(o):
    if isinstance(o, (np.integer,)):
        return int(o)
    if isinstance(o, (np.floating,)):
        v = float(o)
        return v if math.isfinite(v) else None
    if isinstance(o, np.ndarray):
        return o.tolist()
    return str(o)


#: The kind an intervention cycle is counted under when it carries several safety flags: the
#: most consequential first (a goal held back outranks one steered or projected).
INTERVENTION_PRIORITY = (Intervention.GUARD_HOLD, Intervention.UNREACHABLE,
                         Intervention.HOLD_STALE, Intervention.HOLD_INVALID,
                         Intervention.MODEL_INVALID, Intervention.RECOVERY,
                         Intervention.HELD_FOR_COUPLED,
                         Intervention.REPROJECTED, Intervention.PROJECTED)


def intervention_counts(bits_seen: dict[int, int]) -> dict[str, int]:
    """Intervention cycles by kind, from a histogram of bit patterns: each cycle with a safety
    flag counted once, under its first flag in :data:`INTERVENTION_PRIORITY`, so the counts add
    up to the number of intervention cycles. Rate limiting alone is not an intervention."""
    out: dict[str, int] = {}
    for bits, n in bits_seen.items():
        kind = next((f for f in INTERVENTION_PRIORITY if bits & f.value), None)
        if kind is not None:
            out[kind.name.lower()] = out.get(kind.name.lower(), 0) + n
    return out


def rate_limited_count(bits_seen: dict[int, int]) -> int:
    """Cycles whose goal the velocity / acceleration limits shaped (any other flags too)."""
    return int(sum(n for bits, n in bits_seen.items() if bits & Intervention.RATE_LIMITED))


def is_intervention(bits: int) -> bool:
    """True if the bits contain a safety intervention (rate limiting alone is not one)."""
    return bool(bits & SAFETY_FLAGS)
