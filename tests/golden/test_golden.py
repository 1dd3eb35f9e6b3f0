"""The golden outputs: every registered case (``tests/golden/cases_*.py``) run and compared bit
for bit with its stored data (``tests/golden/data``, written by ``python -m tests.golden.regen``).

One joint's workflows (kind ``joint``) and a whole limb's (kind ``limb``); see
:mod:`tests.golden.harness` for what "bit for bit" means and what :func:`normalise` strips.
"""

from __future__ import annotations

import numpy as np
import pytest

from tests.golden.cases import CASES
from tests.golden.harness import DATA, compare, encode, load, normalise

# the cases share module-level caches (a recorded session, simulated patients): one worker
pytestmark = pytest.mark.xdist_group("golden")


@pytest.mark.parametrize("name", sorted(CASES), ids=lambda n: f"{CASES[n].kind}-{n}")
def test_case_matches_its_golden(name):
    c = CASES[name]
    assert (DATA / f"{name}.npz").exists(), (
        f"no golden data for {name!r}: run `python -m tests.golden.regen {name}` on the code "
        "whose behaviour is the reference")
    _, doc = load(name)
    assert doc["kind"] == c.kind, f"{name}: stored as {doc['kind']}, registered as {c.kind}"
    problems = compare(name, c.func())
    assert not problems, f"golden case {name!r} ({c.kind}) differs:\n  " + "\n  ".join(problems)


def test_every_stored_golden_has_a_case():
    stored = {p.stem for p in DATA.glob("*.npz")}
    assert stored == set(CASES), f"stored without a case: {sorted(stored - set(CASES))}; " \
                                 f"case without data: {sorted(set(CASES) - stored)}"


def test_both_kinds_are_covered():
    kinds = [c.kind for c in CASES.values()]
    assert kinds.count("joint") > 0 and kinds.count("limb") > 0


# -- the one normalisation -------------------------------------------------------------------
def test_normalise_strips_exactly_the_run_dependent_parts(tmp_path):
    text = (f"wrote {tmp_path}/out.yaml at 2026-11-28T16:37:54.123456+00:00\n"
            "session 3 started 2026-11-28 16:37:54 by pid 4242\n"
            "model 123e4567-e89b-12d3-a456-426614174000\n"
            "name: P-101-session-1-20261128T164924Z\nrig_version=0.1.0\nversion=3\n"
            '{"created_at": "Sat Nov 28", "closed_at": 1764347874.5, "n": 12}\n'
            '"{\\"started_at\\": 1764347874.5}"\n  started_at: 1795884768.5679164\n'
            "jointlimits-rig 0.1.0, onnxruntime 1.20.1, by rig 0.1.0.\n"
            '{"network": "{\\"build_s\\": 0.028, \\"grid\\": 60}", "seconds": 1.5}\n'
            "wrote m.onnx (swing field) in 0.7 s; hip: trained in 291.6 s; in 5 s\n"
            "angles 12.5 -0.0 nan 2026 3.14159 seed=12345 pid-free text\n")
    assert normalise(text, tmp_path) == (
        "wrote <TMP>/out.yaml at <TIME>\n"
        "session 3 started <TIME> by pid <PID>\n"
        "model <UUID>\n"
        "name: P-101-session-1-<TIME>\nrig_version=<VERSION>\nversion=3\n"
        '{"created_at": <TIME>, "closed_at": <TIME>, "n": 12}\n'
        '"{\\"started_at\\": <TIME>}"\n  started_at: <TIME>\n'
        "jointlimits-rig <VERSION>, onnxruntime <VERSION>, by rig <VERSION>.\n"
        '{"network": "{\\"build_s\\": <SECONDS>, \\"grid\\": 60}", "seconds": <SECONDS>}\n'
        "wrote m.onnx (swing field) in <SECONDS> s; hip: trained in <SECONDS> s; in 5 s\n"
        "angles 12.5 -0.0 nan 2026 3.14159 seed=12345 pid-free text\n")


# -- the comparison itself -------------------------------------------------------------------
def _check(tmp_path, stored, got):
    from tests.golden.harness import save

    save("x", "joint", stored, data=tmp_path)
    return compare("x", got, data=tmp_path)


def test_compare_is_bitwise_and_names_the_key_and_the_largest_difference(tmp_path):
    a = np.array([0.0, 1.0, np.nan, 3.0])
    assert _check(tmp_path, {"a": a, "s": "x"}, {"a": a.copy(), "s": "x"}) == []
    (p,) = _check(tmp_path, {"a": a}, {"a": np.array([-0.0, 1.0, np.nan, 3.0])})
    assert p.startswith("a: values differ") and "1 of 4" in p
    (p,) = _check(tmp_path, {"a": a}, {"a": np.array([0.0, 1.0, np.nan, 3.5])})
    assert "largest difference 0.5 at (3,)" in p
    (p,) = _check(tmp_path, {"a": a}, {"a": a.astype(np.float32)})
    assert p == "a: dtype float32, expected float64"
    (p,) = _check(tmp_path, {"s": "one\ntwo"}, {"s": "one\nthree"})
    assert p == "s: text differs, line 2: expected 'two', got 'three'"
    (p,) = _check(tmp_path, {"a": a}, {"b": a})
    assert p == "keys differ: missing ['a'], unexpected ['b']"


def test_a_large_array_is_stored_as_a_digest_that_still_locates_a_difference(tmp_path):
    big = np.random.default_rng(0).standard_normal(10_000)
    arrays, doc = encode({"big": big})
    assert "big" in doc["digests"] and "big" not in arrays
    moved = big.copy()
    moved[0] += 1.0  # sample index 0 is always kept
    (p,) = _check(tmp_path, {"big": big}, {"big": moved})
    assert "SHA-256 differs" in p and "largest difference" in p
    moved = big.copy()
    moved[5001] += 1e-9  # not a sample: found by its chunk's sum
    (p,) = _check(tmp_path, {"big": big}, {"big": moved})
    assert "sampled values are equal" in p and "the first from element (4852,)" in p, p
