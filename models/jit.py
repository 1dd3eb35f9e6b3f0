"""How this project compiles its per-sample kernels: numba, with one set of options.

The control loop evaluates one orientation at a time (the supervisor's exact oracle, the
servo chain's inverse and forward kinematics). In plain Python that maths costs tens of µs per
call, mostly interpreter overhead; compiled by numba the same expressions take about a µs.
Every kernel is compiled with :func:`njit` below, so the options are chosen once:

- ``cache=True``: the machine code is kept on disk beside the module, in ``__pycache__`` as
  Python keeps its bytecode (a read-only install falls back to the user's cache directory;
  ``NUMBA_CACHE_DIR`` moves it), so only the first run on a machine pays the compile (about
  8 s for the loop's kernels on the project's 2-core machine, 0.3 s to load them after).
  These files are numba's own, written and read by it alone like ``.pyc`` files; no data of
  ours passes through them (patient data, models and configurations are never pickled);
- ``nogil=True``: a kernel never holds the GIL, so threads of the same process (the telemetry
  writer, an in-process simulator) are not held up by it;
- ``error_model="numpy"``: a division by zero gives inf/NaN as numpy does instead of raising
  (the kernels guard every division that can meet a zero, as the Python they replace did),
  which keeps the checks out of the inner loops;
- no ``fastmath``: IEEE arithmetic in the order written, so a kernel and the batched numpy
  path it twins compute the same keys and pick the same answer on ties.

Kernels are compiled lazily, on their first call; code that must not pay for it at a bad
moment (a control loop's first cycle) calls the owner's ``prepare``/``compile`` first.
"""

from __future__ import annotations

import numba

__all__ = ["njit"]


def njit(*args, **kwargs):
    """:func:`numba.njit` with the project's options (keyword arguments override them)."""
    opts = {"cache": True, "nogil": True, "error_model": "numpy"}
    opts.update(kwargs)
    return numba.njit(*args, **opts)
