"""Reader thread + bounded queue (rig.record.pump): losses are counted, never silent.

The source here is a plain in-memory :class:`OrientationSource` (the interface, not the wire):
the point is the queue's behaviour when the writer is slower than the reader, which a real
device cannot be made to provoke deterministically.
"""

from __future__ import annotations

import threading

import numpy as np

from rig.errors import RigConnectionError
from rig.record.pump import SamplePump, batch_from_samples


class _Sample:
    def __init__(self, t, name, q):
        self.t, self.device_t, self.name, self.kind, self.q, self.status = (
            t, t, name, "sensor", q, 3)


class _ListSource:
    """Yields ``n_batches`` batches of 4 samples, then raises ``end`` (or returns nothing)."""

    def __init__(self, n_batches: int, end: BaseException | None = None, gaps: int = 0):
        self.n = n_batches
        self.k = 0
        self.end = end
        self.dropped = gaps
        self.names = ("thorax", "humerus")
        self.released = threading.Event()

    def read(self, timeout):
        if self.k >= self.n:
            if self.end is not None:
                raise self.end
            self.released.wait(timeout)
            return []
        self.k += 1
        q = np.array([1.0, 0.0, 0.0, 0.0])
        return [_Sample(self.k + i / 4, ("thorax", "humerus")[i % 2], q) for i in range(4)]


def test_batch_from_samples_keeps_every_field():
    src = _ListSource(1)
    b = batch_from_samples(src.read(0.0))
    assert len(b) == 4 and b.q.shape == (4, 4) and list(b.name[:2]) == ["thorax", "humerus"]
    assert np.all(b.status == 3) and np.array_equal(b.time(), b.t)


def test_overflow_is_counted_not_silent():
    src = _ListSource(200, gaps=5)
    pump = SamplePump(src, maxsize=3).start()
    try:
        while not (src.k >= src.n):  # the writer takes nothing until the reader is done
            threading.Event().wait(0.01)
    finally:
        pump.stop()
    got = sum(len(b) for b in pump.drain())
    assert got == 3 * 4  # what the bounded queue held
    assert pump.overflow == 200 * 4 - got
    assert pump.received == 200 * 4
    assert pump.dropped == pump.overflow + 5  # plus the source's own sequence gaps


def test_vanished_device_ends_the_reader_with_its_error():
    src = _ListSource(10, end=RigConnectionError("adapter unplugged"))
    pump = SamplePump(src, maxsize=100).start()
    batches = []
    while not pump.finished:
        b = pump.get(timeout=0.05)
        if b is not None:
            batches.append(b)
    pump.stop()
    assert isinstance(pump.error, RigConnectionError)
    assert sum(len(b) for b in batches) == 40  # everything read before the failure is kept
    assert pump.overflow == 0
