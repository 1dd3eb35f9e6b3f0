"""The rooms and arrows of the code (docs/architecture in README.md's map): computed from the
source's import statements, every one of them — at module level, inside functions and under
``if TYPE_CHECKING:``, since a lazy or a type-only import is still a dependency.

- no import cycle between modules anywhere (importing ``a.b.c`` from outside ``a.b`` runs
  ``a.b``'s ``__init__``: that edge counts too);
- ``firmware_protocol`` and ``models`` import nothing of ours, ``calibration`` only ``models``;
- nothing in ``rig/`` imports the CLI (``rig.commands``, ``rig.cli``) but the CLI itself and
  ``python -m rig`` (``rig/__main__.py``);
- our own modules are imported at the top of a file, except in the CLI and where a comment
  says why the import is lazy; no private name is imported from another module;
- no kind name is compared outside the kinds' own modules, and no module of ``rig/`` starts
  to ask "one joint or a whole limb?" (the ones that still do are listed with the reason).
"""

from __future__ import annotations

import ast
import functools
from pathlib import Path

import pytest

from models.kinds import KINDS

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

# the module's tests walk the same sources' trees (reading them only): each parsed once, on
# one xdist worker, when a test first asks (not at collection)
pytestmark = pytest.mark.xdist_group("test_architecture")


@functools.cache
def _parse(text: str) -> ast.Module:
    """The syntax tree of a module's source ``text`` (cached: do not change it)."""
    return ast.parse(text)


def _imports(name: str, path: Path) -> set[str]:
    """The modules of ours that ``name`` imports (each resolved to the longest module name)."""
    tree = _parse(path.read_text(encoding="utf-8"))
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


@functools.cache
def _graph() -> dict[str, set[str]]:
    """Each of our modules' imports of our modules (:func:`_imports`)."""
    return {name: _imports(name, path) for name, path in MODULES.items()}


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
    assert "rig.errors" in _graph()["rig.cli"]
    assert "rig.readback" in _graph()["rig.record.procedures"]
    assert "rig.errors" in _graph()["rig.commands.boundary"]  # imported inside a function
    assert "rig.readback.boundary" in _graph()["rig.commands.boundary"]
    assert "rig.readback" in _graph()["rig.commands.boundary"]  # the package's __init__ runs too
    assert "models.quaternion" in _graph()["calibration.coverage"]
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def test_no_import_cycles():
    cycles = _cycles(_graph())
    assert not cycles, "import cycles:\n" + "\n".join(" -> ".join(c) for c in cycles)


@pytest.mark.parametrize("package, allowed", [
    ("firmware_protocol", {"firmware_protocol"}),
    ("models", {"models"}),
    ("calibration", {"calibration", "models"}),
])
def test_library_packages_import_only_downwards(package, allowed):
    wrong = sorted(f"{m} imports {t}" for m, ts in _graph().items()
                   if m.split(".")[0] == package for t in ts if t.split(".")[0] not in allowed)
    assert not wrong, wrong


def test_nothing_in_rig_imports_the_cli():
    def is_cli(m: str) -> bool:
        return m in ("rig.cli", "rig.commands") or m.startswith("rig.commands.")

    wrong = sorted(f"{m} imports {t}" for m, ts in _graph().items()
                   if m.startswith("rig.") and not is_cli(m) and m != "rig.__main__"
                   for t in ts if is_cli(t))
    assert not wrong, wrong


def test_the_servo_bus_knows_no_kinematics():
    """Issue 38: a servo bus knows servos by ID, name and register; the joint and limb
    kinematics sit above it (``rig.devices.servo_limb`` composes the two)."""
    bus_side = ("rig.devices.servo", "rig.devices.bus", "rig.devices.dynamixel")
    wrong = sorted(f"{m} imports {t}" for m in bus_side for t in _graph()[m]
                   if t in ("rig.devices.kinematics", "rig.devices.servo_limb"))
    assert not wrong, wrong
    assert "rig.devices.kinematics" in _graph()["rig.devices.servo_limb"]


# --- issue 38: what the graph above does not say -------------------------------------------

def _says_lazy(lines: list[str], first: int, last: int) -> bool:
    """Whether a run of imports (lines ``first``..``last``, 1-based) or the comments just
    above it say why it is lazy (a comment with "lazy")."""
    if "lazy" in " ".join(lines[first - 1: last]):
        return True
    k = first - 2
    while k >= 0 and lines[k].strip().startswith("#"):
        if "lazy" in lines[k]:
            return True
        k -= 1
    return False


def _function_imports(path: Path) -> list[tuple[int, str, bool]]:
    """(line, imported module, justified) for each import inside a function body; a run of
    consecutive imports shares the comment above its first one."""
    text = path.read_text(encoding="utf-8")
    lines = text.splitlines()
    tree = _parse(text)
    out = []
    for fn in ast.walk(tree):
        if not isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)):
            continue
        for block in ast.walk(fn):
            for body in (getattr(block, f, None) for f in ("body", "orelse", "finalbody")):
                if not isinstance(body, list):
                    continue
                run_start = None
                for stmt in body:
                    if not isinstance(stmt, (ast.Import, ast.ImportFrom)):
                        run_start = None
                        continue
                    run_start = run_start or stmt.lineno
                    if isinstance(stmt, ast.Import):
                        mods = [a.name for a in stmt.names]
                    else:
                        mods = ["." * stmt.level + (stmt.module or "")]
                    ok = _says_lazy(lines, run_start, stmt.end_lineno or stmt.lineno)
                    out.extend((stmt.lineno, m, ok) for m in mods)
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
        tree = _parse(path.read_text(encoding="utf-8"))
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
        tree = _parse(path.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            if (isinstance(node, ast.Attribute) and node.attr in ("_sess", "_session")
                    and isinstance(node.value, ast.Attribute)):
                wrong.append(f"{path.relative_to(ROOT)}:{node.lineno} uses .{node.attr}")
    assert not wrong, "\n".join(wrong)


# --- one contract for a joint and a limb: where "is this a limb?" is still asked -----------

#: The modules of ``rig/`` that still ask "one joint or a whole limb?", and why. A module not
#: listed here must not start to; a listed one that stops is taken off (the test says so).
#: The aim (issue 38) is an empty table: each entry is a place where a one-joint path and a
#: limb path still differ in what they compute, not only in size.
LIMB_OR_JOINT: dict[str, str] = {
    "rig/demo/pipeline.py": "--limb chooses JointDemo or LimbDemo, the one place that does",
    "rig/loop/binding.py": "the enforced limits of a rig of one joint are a constraint, of a "
                           "servo limb a limb file (_limb_of: the one question), each checked "
                           "against what the rig drives",
    "rig/loop/targets.py": "the scripted targets of one joint from its swing and twist geometry "
                           "(kept bit for bit) or of a limb from its oracle alone; a posture "
                           "is one joint's (N, 4) or a limb's (N, J, 4) for the oracle; a limb's "
                           "joints name a targets file's columns and the segments mirrored",
    "rig/readback/boundary.py": "BoundaryRequest.work: the user's --limb arm|leg, the one "
                                "place choosing a limb file or one joint's constraint",
    "rig/readback/rom.py": "clinical peaks of a constraint file or a limb file",
    "rig/record/procedures.py": "procedure_for: the one place choosing a rig's calibration "
                                "procedure (ImuJointCalibration or LimbImuCalibration, "
                                "different algorithms) from the configuration's limb",
    "rig/report/session.py": "the one joint's page or the limb's",
    "rig/sim/imu.py": "the default patient when no motion source is given (limb=None)",
    "rig/sim/patients.py": "a port string's patient= file: a limb file makes an arm or leg",
    "rig/store/boundaries.py": "the caller's filter list(limb=None|True|False) on the stored tag",
    "rig/training/verdict.py": ("the one place (`judging`) that turns a caller's `limb=` "
                                "word, or its absence, into whose targets judge an evaluation"),
}


def _limb_or_joint_sites(path: Path) -> list[str]:
    """Tests of "limb or joint" in a module: ``isinstance(x, Limb | JointConstraint)``, ``limb
    is None`` / ``is not None`` (a name or attribute called ``limb``), ``is_limb``, and
    ``session_limb(...)`` used as a condition."""
    tree = _parse(path.read_text(encoding="utf-8"))
    out = []
    for node in ast.walk(tree):
        if (isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
                and node.func.id == "isinstance" and len(node.args) == 2):
            names = {n.id if isinstance(n, ast.Name) else getattr(n, "attr", "")
                     for n in ast.walk(node.args[1])}
            if names & {"Limb", "JointConstraint"}:
                out.append(f"{node.lineno}: {ast.unparse(node)}")
        elif isinstance(node, ast.Compare) and any(isinstance(op, (ast.Is, ast.IsNot))
                                                   for op in node.ops):
            left = node.left
            name = left.id if isinstance(left, ast.Name) else getattr(left, "attr", "")
            if name == "limb":
                out.append(f"{node.lineno}: {ast.unparse(node)}")
        elif isinstance(node, (ast.Name, ast.Attribute)):
            name = node.id if isinstance(node, ast.Name) else node.attr
            if name in ("is_limb", "_is_limb"):
                out.append(f"{node.lineno}: {name}")
        elif isinstance(node, (ast.If, ast.IfExp, ast.While)):
            for sub in ast.walk(node.test):
                if (isinstance(sub, ast.Call) and isinstance(sub.func, ast.Name)
                        and sub.func.id == "session_limb"):
                    out.append(f"{node.lineno}: {ast.unparse(node.test)}")
    return out


def _limb_or_joint_modules() -> dict[str, list[str]]:
    found = {}
    for name, path in MODULES.items():
        if not name.startswith("rig.") or name.startswith("rig.commands"):
            continue
        sites = _limb_or_joint_sites(path)
        if sites:
            found[path.relative_to(ROOT).as_posix()] = sites
    return found


def test_no_new_module_asks_whether_it_has_a_limb_or_a_joint():
    found = _limb_or_joint_modules()
    new = {k: v for k, v in found.items() if k not in LIMB_OR_JOINT}
    assert not new, "modules that now branch on limb or joint:\n" + "\n".join(
        f"{k}: {'; '.join(v)}" for k, v in new.items())
    gone = sorted(set(LIMB_OR_JOINT) - set(found))
    assert not gone, f"no longer branch on limb or joint, take them off LIMB_OR_JOINT: {gone}"


def test_the_limb_or_joint_check_sees_what_it_should(tmp_path):
    p = tmp_path / "m.py"
    p.write_text("def f(c, limb=None, sess=None):\n"
                 "    if isinstance(c, Limb):\n        pass\n"
                 "    if limb is not None:\n        pass\n"
                 "    if session_limb(sess):\n        pass\n"
                 "    return is_limb\n", encoding="utf-8")
    assert len(_limb_or_joint_sites(p)) == 4


# --- joint kinds: what is special about a kind lives in its own modules ---------------------
# Outside ``models/kinds/`` and ``calibration/kinds/`` no code compares anything with a kind's
# name (``joint.kind == "hinge"``, ``kind in ("ball", "two-axis")``): it asks the registries
# (:func:`models.kinds.get_kind`, :func:`calibration.kinds.calibration_kind`).

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
    for path in MODULES.values():
        rel = path.relative_to(ROOT).as_posix()
        if rel.startswith(KINDS_MODULES):
            continue
        for node in ast.walk(_parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Compare) and any(
                    s in names for o in (node.left, *node.comparators) for s in _strings(o)):
                found.append(f"{rel}:{node.lineno}: {ast.unparse(node)}")
    assert not found, "compare with a kind's name outside its module:\n" + "\n".join(found)
