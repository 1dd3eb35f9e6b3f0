"""Reader thread → bounded queue → writer: moving samples from an orientation source to the store.

Why this shape
--------------
The device must be read at its own rate whatever the disk does (an fsync can take tens of
milliseconds), and the store must commit at least once a second whatever the device does. A
reader thread does nothing but ``source.read(timeout)`` and ``queue.put_nowait``; the caller's
thread (the writer) takes batches off the queue, writes them, updates the live coverage and the
display. The queue is **bounded** (``maxsize`` batches): if the writer falls behind for longer
than the queue covers, the newest batch is dropped *and counted* rather than memory growing
without bound. Samples lost before they reach the host (sequence gaps the driver sees) are
``source.dropped``. Both counts are reported; nothing is lost silently.

The reader stops on :meth:`SamplePump.stop` or when the source raises (a vanished device:
:class:`rig.errors.RigConnectionError`); the error is kept in :attr:`SamplePump.error` and the
writer sees :attr:`SamplePump.finished` once the queue is drained.
"""

from __future__ import annotations

import queue
import threading
from dataclasses import dataclass

import numpy as np

__all__ = ["SampleBatch", "SamplePump", "batch_from_samples"]


@dataclass(frozen=True)
class SampleBatch:
    """Samples as arrays (one row per sample).

    Attributes
    ----------
    t : (N,) float64, host monotonic seconds
    device_t : (N,) float64, device seconds (NaN where the device has no clock)
    name : (N,) object, sensor / segment / joint name
    kind : (N,) object, ``"sensor"`` or ``"joint"``
    q : (N, 4) float64, scalar-first unit quaternions
    status : (N,) int64, calibration status byte or 0
    raw : (N, 9) float64, the IMUs' raw readings (accelerometer m/s², gyroscope rad/s,
        magnetometer µT, sensor frame; ``OrientationSample.raw``), NaN where a sample has none;
        ``None`` given to the constructor means none at all
    """

    t: np.ndarray
    device_t: np.ndarray
    name: np.ndarray
    kind: np.ndarray
    q: np.ndarray
    status: np.ndarray
    raw: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.raw is None:
            object.__setattr__(self, "raw", np.full((len(self.t), 9), np.nan))

    def __len__(self) -> int:
        return len(self.t)

    def time(self) -> np.ndarray:
        """The best clock per sample: device time where present, else host time (seconds)."""
        return np.where(np.isnan(self.device_t), self.t, self.device_t)

    def select(self, mask: np.ndarray) -> SampleBatch:
        """Rows where ``mask`` is true."""
        return SampleBatch(self.t[mask], self.device_t[mask], self.name[mask], self.kind[mask],
                           self.q[mask], self.status[mask], self.raw[mask])


def batch_from_samples(samples) -> SampleBatch:
    """Arrays from a list of ``OrientationSample`` (see :mod:`rig.devices.sources`)."""
    n = len(samples)
    t = np.empty(n)
    dt = np.empty(n)
    q = np.empty((n, 4))
    status = np.empty(n, dtype=np.int64)
    name = np.empty(n, dtype=object)
    kind = np.empty(n, dtype=object)
    raw = np.full((n, 9), np.nan)
    for i, s in enumerate(samples):
        t[i] = s.t
        dt[i] = np.nan if s.device_t is None else s.device_t
        q[i] = s.q
        status[i] = s.status
        name[i] = s.name
        kind[i] = s.kind
        r = getattr(s, "raw", None)  # duck-typed samples may not have it
        if r is not None:
            raw[i] = r
    return SampleBatch(t, dt, name, kind, q, status, raw)


class SamplePump:
    """A reader thread filling a bounded queue from an orientation source.

    Parameters
    ----------
    source : OrientationSource
        Opened source (``read(timeout) -> list[OrientationSample]``, ``dropped``).
    maxsize : int
        Queue capacity in batches (a batch is what one ``read`` returned).
    read_timeout_s : float
        Longest a single ``read`` blocks, so :meth:`stop` is noticed promptly.

    Attributes
    ----------
    overflow : int
        Samples dropped because the queue was full.
    error : BaseException or None
        What ended the reader, if it was not :meth:`stop` (e.g. RigConnectionError).
    """

    def __init__(self, source, *, maxsize: int = 1024, read_timeout_s: float = 0.05) -> None:
        if maxsize < 1:
            raise ValueError(f"maxsize must be >= 1, got {maxsize}")
        self.source = source
        self.queue: queue.Queue[SampleBatch] = queue.Queue(maxsize=maxsize)
        self.read_timeout_s = float(read_timeout_s)
        self.overflow = 0
        self.received = 0
        self.error: BaseException | None = None
        self._stop = threading.Event()
        self._done = threading.Event()
        self._thread = threading.Thread(target=self._run, name="rig-record-reader", daemon=True)

    def start(self) -> SamplePump:
        self._thread.start()
        return self

    def _run(self) -> None:
        try:
            while not self._stop.is_set():
                samples = self.source.read(self.read_timeout_s)
                if not samples:
                    continue
                batch = batch_from_samples(samples)
                self.received += len(batch)
                try:
                    self.queue.put_nowait(batch)
                except queue.Full:
                    self.overflow += len(batch)
        except BaseException as err:  # surfaced to the writer; a vanished device ends here
            self.error = err
        finally:
            self._done.set()

    @property
    def dropped(self) -> int:
        """All samples lost: sequence gaps at the source plus queue overflow."""
        return int(getattr(self.source, "dropped", 0) or 0) + self.overflow

    @property
    def reader_done(self) -> bool:
        """The reader thread has returned (stopped or failed)."""
        return self._done.is_set()

    @property
    def finished(self) -> bool:
        """The reader has returned and every batch has been taken off the queue."""
        return self._done.is_set() and self.queue.empty()

    def get(self, timeout: float) -> SampleBatch | None:
        """Next batch, or None after ``timeout`` seconds (or at once when finished)."""
        if self.finished:
            return None
        try:
            return self.queue.get(timeout=timeout)
        except queue.Empty:
            return None

    def drain(self) -> list[SampleBatch]:
        """Every batch still queued (call after :meth:`stop`)."""
        out = []
        while True:
            try:
                out.append(self.queue.get_nowait())
            except queue.Empty:
                return out

    def stop(self) -> None:
        """Ask the reader to return and wait for it (idempotent)."""
        self._stop.set()
        if self._thread.ident is not None:
            self._thread.join()
