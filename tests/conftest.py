"""Shared fixtures.

``no_leaks`` (autouse) fails any test that leaves a thread, a child process or a pseudo-terminal
running: simulators must be shut down by the test (context managers, fixtures), never left to
the interpreter's exit.
"""

from __future__ import annotations

import os
import threading
import time

import pytest


def _open_ptys() -> set[str]:
    found = set()
    fd_dir = "/proc/self/fd"
    try:
        names = os.listdir(fd_dir)
    except OSError:  # not Linux
        return found
    for name in names:
        try:
            target = os.readlink(os.path.join(fd_dir, name))
        except OSError:
            continue
        if target.startswith("/dev/pts/") or target == "/dev/ptmx":
            found.add(f"fd {name} -> {target}")
    return found


def _children() -> set[int]:
    kids: set[int] = set()
    task_dir = f"/proc/{os.getpid()}/task"
    try:
        tasks = os.listdir(task_dir)
    except OSError:
        return kids
    for tid in tasks:
        try:
            with open(f"{task_dir}/{tid}/children") as fh:
                kids.update(int(p) for p in fh.read().split())
        except OSError:
            continue
    # zombies already reaped by the test do not count; running ones do
    alive = set()
    for pid in kids:
        try:
            with open(f"/proc/{pid}/stat") as fh:
                if fh.read().split(") ", 1)[1][0] != "Z":
                    alive.add(pid)
        except OSError:
            continue
    return alive


@pytest.fixture(autouse=True)
def no_leaks():
    threads_before = set(threading.enumerate())
    ptys_before = _open_ptys()
    kids_before = _children()
    yield
    # a thread that was told to stop may need a moment to return from its last call
    deadline = time.monotonic() + 2.0
    for t in threading.enumerate():
        if t not in threads_before and t.is_alive():
            t.join(max(0.0, deadline - time.monotonic()))
    extra_threads = [t for t in threading.enumerate() if t not in threads_before and t.is_alive()]
    extra_ptys = _open_ptys() - ptys_before
    extra_kids = _children() - kids_before
    problems = []
    if extra_threads:
        problems.append(f"threads left running: {[t.name for t in extra_threads]}")
    if extra_ptys:
        problems.append(f"pseudo-terminals left open: {sorted(extra_ptys)}")
    if extra_kids:
        problems.append(f"child processes left running: {sorted(extra_kids)}")
    if problems:
        pytest.fail("; ".join(problems))


def pytest_collection_modifyitems(config, items):
    """Skip ``@pytest.mark.hardware`` tests unless an environment variable names a real port."""
    has_port = any(os.environ.get(v) for v in ("RIG_DXL_PORT", "RIG_IMU_PORT"))
    if has_port:
        return
    skip = pytest.mark.skip(reason="no hardware: set RIG_DXL_PORT or RIG_IMU_PORT to a real port")
    for item in items:
        if "hardware" in item.keywords:
            item.add_marker(skip)
