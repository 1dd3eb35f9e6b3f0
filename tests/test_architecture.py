"""The rooms and arrows of the code (docs/architecture in README.md's map): computed from the
source's import statements, every one of them — at module level, inside functions and under
``if TYPE_CHECKING:``, since a lazy or a type-only import is still a dependency.

- no import cycle between modules anywhere (importing ``a.b.c`` from outside ``a.b`` runs
  ``a.b``'s ``__init__``: that edge counts too);
- ``firmware_protocol`` and ``models`` import nothing of ours, ``calibration`` only ``models``;
- nothing in ``rig/`` imports the CLI (``rig.commands``, ``rig.cli``) but the CLI itself and
  ``python -m rig`` (``rig/__main__.py``).
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("firmware_protocol", "models", "calibration", "rig")


def _modules() -> dict[str, Path]:
    out = {}
    for pkg in PACKAGES:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            parts = list(path.relative_to(ROOT).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts.pop()
            out[".".join(parts)] = path
    return out


MODULES = _modules()


def _imports(name: str, path: Path) -> set[str]:
    """The modules of ours that ``name`` imports (each resolved to the longest module name)."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    package = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
    found: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[: len(package) - (node.level - 1)]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            targets = [f"{mod}.{a.name}" if f"{mod}.{a.name}" in MODULES else mod
                       for a in node.names]
        else:
            continue
        for t in targets:
            while t and t not in MODULES:
                t = t.rpartition(".")[0]
            if not t or t == name:
                continue
            found.add(t)
            parent = t.rpartition(".")[0]
            while parent and not (name == parent or name.startswith(parent + ".")):
                if parent in MODULES:
                    found.add(parent)
                parent = parent.rpartition(".")[0]
    return found


GRAPH = {name: _imports(name, path) for name, path in MODULES.items()}


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    on_stack: set[str] = set()
    stack: list[str] = []
    out: list[list[str]] = []
    counter = 0
    for root in sorted(graph):
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on_stack.add(root)
        while work:
            v, children = work[-1]
            for w in children:
                if w not in index:
                    index[w] = low[w] = counter
                    counter += 1
                    stack.append(w)
                    on_stack.add(w)
                    work.append((w, iter(sorted(graph[w]))))
                    break
                if w in on_stack:
                    low[v] = min(low[v], index[w])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[v])
                if low[v] == index[v]:
                    comp = []
                    while True:
                        w = stack.pop()
                        on_stack.discard(w)
                        comp.append(w)
                        if w == v:
                            break
                    if len(comp) > 1:
                        out.append(sorted(comp))
    return out


def test_the_graph_sees_the_imports_it_should():
    # a known arrow of each kind: module level, inside a function, relative, a package's init
    assert "rig.errors" in GRAPH["rig.cli"]
    assert "rig.readback" in GRAPH["rig.record.session"]  # imported inside a function
    assert "rig.readback.boundary" in GRAPH["rig.commands.boundary"]
    assert "rig.readback" in GRAPH["rig.commands.boundary"]  # the package's __init__ runs too
    assert "models.quaternion" in GRAPH["calibration.coverage"]
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def test_no_import_cycles():
    cycles = _cycles(GRAPH)
    assert not cycles, "import cycles:\n" + "\n".join(" -> ".join(c) for c in cycles)


@pytest.mark.parametrize("package, allowed", [
    ("firmware_protocol", {"firmware_protocol"}),
    ("models", {"models"}),
    ("calibration", {"calibration", "models"}),
])
def test_library_packages_import_only_downwards(package, allowed):
    wrong = sorted(f"{m} imports {t}" for m, ts in GRAPH.items()
                   if m.split(".")[0] == package for t in ts if t.split(".")[0] not in allowed)
    assert not wrong, wrong


def test_nothing_in_rig_imports_the_cli():
    def is_cli(m: str) -> bool:
        return m in ("rig.cli", "rig.commands") or m.startswith("rig.commands.")

    wrong = sorted(f"{m} imports {t}" for m, ts in GRAPH.items()
                   if m.startswith("rig.") and not is_cli(m) and m != "rig.__main__"
                   for t in ts if is_cli(t))
    assert not wrong, wrong


def test_the_servo_bus_knows_no_kinematics():
    """Issue 38: a servo bus knows servos by ID, name and register; the joint and limb
    kinematics sit above it (``rig.devices.servo_limb`` composes the two)."""
    bus_side = ("rig.devices.servo", "rig.devices.bus", "rig.devices.dynamixel")
    wrong = sorted(f"{m} imports {t}" for m in bus_side for t in GRAPH[m]
                   if t in ("rig.devices.kinematics", "rig.devices.servo_limb"))
    assert not wrong, wrong
    assert "rig.devices.kinematics" in GRAPH["rig.devices.servo_limb"]


# --- issue 38: what the graph above does not say -------------------------------------------

def _function_imports(path: Path) -> list[tuple[int, str, bool]]:
    """(line, imported module, justified) for each import inside a function body."""
    text = path.read_text(encoding="utf-8")
    lines = text.splitlines()
    tree = ast.parse(text)
    out = []
    for node in ast.walk(tree):
        if not isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            continue
        for sub in ast.walk(node):
            if isinstance(sub, ast.Import):
                mods = [a.name for a in sub.names]
            elif isinstance(sub, ast.ImportFrom):
                mods = ["." * sub.level + (sub.module or "")]
            else:
                continue
            near = " ".join(lines[max(0, sub.lineno - 3): sub.end_lineno or sub.lineno])
            for m in mods:
                out.append((sub.lineno, m, "lazy" in near))
    return sorted(set(out))


def _ours(module: str) -> bool:
    return module.startswith(".") or module.split(".")[0] in PACKAGES


LAZY_ROOMS = ("rig.cli", "rig.__main__", "rig.commands")


def test_our_modules_are_imported_at_the_top():
    """An import of our own code inside a function hides a dependency from the top of the file.
    Allowed where laziness is the point: the CLI's command table and commands (start-up time),
    and a line that says why (a comment with "lazy" on it or just above it). Third-party
    imports inside functions are optional or heavy dependencies and stay allowed."""
    wrong = []
    for name, path in MODULES.items():
        if name in LAZY_ROOMS or name.startswith("rig.commands."):
            continue
        for line, mod, justified in _function_imports(path):
            if _ours(mod) and not justified:
                wrong.append(f"{path.relative_to(ROOT)}:{line} imports {mod} inside a function")
    assert not wrong, "\n".join(wrong)


def test_no_private_name_is_imported_from_another_module():
    wrong = []
    for path in MODULES.values():
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and (node.level or _ours(node.module or "")):
                for a in node.names:
                    if a.name.startswith("_") and not a.name.startswith("__"):
                        wrong.append(f"{path.relative_to(ROOT)}:{node.lineno} imports "
                                     f"{node.module}.{a.name}")
    assert not wrong, "\n".join(wrong)


def test_no_private_attribute_of_a_library_object_is_used():
    """onnxruntime's ``session._sess`` and its like: private APIs of other projects break on
    their next release."""
    wrong = []
    for path in MODULES.values():
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            if (isinstance(node, ast.Attribute) and node.attr in ("_sess", "_session")
                    and isinstance(node.value, ast.Attribute)):
                wrong.append(f"{path.relative_to(ROOT)}:{node.lineno} uses .{node.attr}")
    assert not wrong, "\n".join(wrong)
