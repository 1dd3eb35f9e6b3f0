"""Running ``rig ARGS`` for a golden case: the real entry point (:func:`rig.cli.main`, which
always exits) inside click's runner isolation, so stdout and stderr are captured apart."""

from __future__ import annotations

import sys
from pathlib import Path

from click.testing import CliRunner

from rig.cli import main
from tests.golden.harness import normalise

ROOT = Path(__file__).resolve().parents[2]
REAL = ROOT / "tests" / "calibration" / "data" / "real"
RIG_DATA = ROOT / "tests" / "rig" / "data"

#: a fixed terminal for rich and click: output width and colour do not depend on the caller's
ENV = {"COLUMNS": "100", "LINES": "40", "NO_COLOR": "1", "TERM": "dumb", "RIG_DEBUG": None}


def rig(args: list, tmp: Path | None = None) -> dict:
    """``{"exit", "stdout", "stderr"}`` of ``rig ARGS``, text normalised (``tmp`` and the
    repository's root become placeholders)."""
    runner = CliRunner()
    with runner.isolation(env=ENV) as (out, err, _):
        try:
            main([str(a) for a in args])
            code = 0
        except SystemExit as exc:
            code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
        sys.stdout.flush()
        sys.stderr.flush()
        stdout, stderr = out.getvalue().decode(), err.getvalue().decode()
    dirs = [tmp] if tmp is not None else []
    return {"exit": code, "stdout": root_relative(normalise(stdout, dirs)),
            "stderr": root_relative(normalise(stderr, dirs))}


def root_relative(text: str) -> str:
    """``text`` with the repository's root directory written ``<ROOT>`` (the shipped files'
    paths do not depend on where the checkout is)."""
    return text.replace(str(ROOT), "<ROOT>")
