"""What is special about a joint kind lives in its own modules (issue 38): outside
``models/kinds/`` and ``calibration/kinds/`` no code compares anything with a kind's name
(``joint.kind == "hinge"``, ``kind in ("ball", "two-axis")``, ``"hinge" in c``): it asks the
registries (:func:`models.kinds.get_kind`, :func:`calibration.kinds.calibration_kind`)."""

from __future__ import annotations

import ast
from pathlib import Path

from models.kinds import KINDS

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("firmware_protocol", "models", "calibration", "rig")
KINDS_MODULES = ("models/kinds/", "calibration/kinds/")


def _strings(node: ast.AST) -> list[str]:
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        return [node.value]
    if isinstance(node, (ast.Tuple, ast.List, ast.Set)):
        return [s for e in node.elts for s in _strings(e)]
    return []


def test_no_kind_name_comparisons_outside_the_kinds_modules():
    names = set(KINDS)
    found = []
    for pkg in PACKAGES:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            rel = path.relative_to(ROOT).as_posix()
            if rel.startswith(KINDS_MODULES):
                continue
            for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
                if isinstance(node, ast.Compare) and any(
                        s in names for o in (node.left, *node.comparators) for s in _strings(o)):
                    found.append(f"{rel}:{node.lineno}: {ast.unparse(node)}")
    assert not found, "compare with a kind's name outside its module:\n" + "\n".join(found)
