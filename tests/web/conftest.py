"""tests/web: a server's thread pool is not a leak.

The root ``no_leaks`` fixture fails a test that leaves a thread running; a module's server
(:mod:`tests.web.server`) runs its blocking routes on AnyIO's worker threads, which stay in
the pool, idle, for a while after a request. This override keeps every check of the root
fixture and leaves out those pooled threads only.
"""

from __future__ import annotations

import threading
import time

import pytest

from tests.conftest import _children, _open_ptys

POOLED = ("AnyIO worker thread",)


@pytest.fixture(autouse=True)
def no_leaks():
    threads_before = set(threading.enumerate())
    ptys_before = _open_ptys()
    kids_before = _children()
    yield

    def extra():
        return [t for t in threading.enumerate() if t not in threads_before and t.is_alive()
                and t.name not in POOLED]

    deadline = time.monotonic() + 2.0
    for t in extra():
        t.join(max(0.0, deadline - time.monotonic()))
    problems = []
    if extra():
        problems.append(f"threads left running: {[t.name for t in extra()]}")
    if _open_ptys() - ptys_before:
        problems.append(f"pseudo-terminals left open: {sorted(_open_ptys() - ptys_before)}")
    if _children() - kids_before:
        problems.append(f"child processes left running: {sorted(_children() - kids_before)}")
    if problems:
        pytest.fail("; ".join(problems))
