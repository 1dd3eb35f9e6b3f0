"""Write the golden data: ``python -m tests.golden.regen [case ...]`` (all cases by default).

A deliberate command, never run by the tests: it records what the code of the working tree
does *now* as what it must keep doing. ``--list`` prints the cases with their kind.
"""

from __future__ import annotations

import sys
import time

from tests.golden.cases import CASES
from tests.golden.harness import DATA, save


def main(argv: list[str]) -> int:
    if argv[:1] == ["--list"]:
        for name, c in CASES.items():
            print(f"{c.kind:5} {name}")
        return 0
    names = argv or list(CASES)
    unknown = [n for n in names if n not in CASES]
    if unknown:
        print(f"unknown case(s): {', '.join(unknown)}; see --list", file=sys.stderr)
        return 2
    for name in names:
        c = CASES[name]
        t0, c0 = time.perf_counter(), time.process_time()
        outputs = c.func()
        cpu = time.process_time() - c0
        save(name, c.kind, outputs)
        size = (DATA / f"{name}.npz").stat().st_size + (DATA / f"{name}.json").stat().st_size
        print(f"{c.kind:5} {name:40} {time.perf_counter() - t0:6.2f} s wall {cpu:6.2f} s cpu "
              f"{size / 1024:8.1f} KiB")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
