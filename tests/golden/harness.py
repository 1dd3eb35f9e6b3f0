"""The golden harness: a case's outputs stored once, compared bit for bit ever after.

A *case* (``tests/golden/cases_*.py``) is a function ``case_<name>() -> dict`` registered with
:func:`case` under a kind, ``"joint"`` (one joint's workflow) or ``"limb"`` (a whole limb's). It
runs one piece of a workflow on deterministic input and returns its outputs: numpy arrays,
Python numbers and bools (stored as 0-d arrays of their numpy dtype), ``str`` and ``bytes``.

Storage (``tests/golden/data``), written only by ``python -m tests.golden.regen``:

- ``<name>.npz``: every array (and number) the case returned, under its key; an array larger
  than :data:`DIGEST_BYTES` is stored as its SHA-256 (in the JSON) plus :data:`N_SAMPLES`
  values at evenly spaced flat indices (``<key>.__samples__``), ``nanmin``/``nanmax``/
  ``nansum`` (``<key>.__stats__``) and the sums of :data:`N_CHUNKS` consecutive chunks
  (``<key>.__chunks__``), so a mismatch still says where and by how much.
- ``<name>.json``: the kind, the strings (exactly), the bytes (base64 up to
  :data:`DIGEST_BYTES`, else SHA-256 and length), and the digests of the large arrays.

Comparison (:func:`compare`): the same keys; arrays of the same dtype and shape whose raw bytes
are equal (``tobytes()``, so ``-0.0`` against ``0.0`` and NaN payloads count); strings and bytes
exactly equal. The failure message names every key that differs and, for numbers, the largest
difference and where it is.

Run-dependent text (wall-clock times, temporary paths, versions, pids, UUIDs) is removed from
strings by :func:`normalise` — the only normalisation there is; a case applies it to what it
returns, before storing and before comparing alike.
"""

from __future__ import annotations

import base64
import contextlib
import hashlib
import json
import re
import tempfile
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

DATA = Path(__file__).resolve().parent / "data"

#: Arrays and bytes larger than this are stored as a SHA-256 plus samples.
DIGEST_BYTES = 8 * 1024
#: Values kept of a digested array, at evenly spaced flat indices.
N_SAMPLES = 32
#: A digested array is also kept as the sums of this many consecutive chunks of its flat
#: elements (a difference anywhere shows in its chunk's sum, which locates it).
N_CHUNKS = 64

KINDS = ("joint", "limb")


@dataclass(frozen=True)
class Case:
    """A registered golden case: ``func() -> dict`` of outputs, ``kind`` joint or limb."""

    name: str
    kind: str
    func: Callable[[], dict[str, Any]]


#: Every case, by name (filled by the ``@case`` decorators of ``cases_*.py``).
REGISTRY: dict[str, Case] = {}


def case(kind: str) -> Callable:
    """Register ``case_<name>`` as golden case ``<name>`` of ``kind`` (``joint`` or ``limb``)."""
    if kind not in KINDS:
        raise ValueError(f"kind must be one of {KINDS}, got {kind!r}")

    def register(func: Callable[[], dict[str, Any]]) -> Callable[[], dict[str, Any]]:
        assert func.__name__.startswith("case_"), func.__name__
        name = func.__name__[len("case_"):]
        assert name not in REGISTRY, f"golden case {name!r} registered twice"
        REGISTRY[name] = Case(name, kind, func)
        return func

    return register


# -- normalisation ---------------------------------------------------------------------------
_TMP_PLACEHOLDER = "<TMP>"
_PATTERNS: tuple[tuple[re.Pattern[str], str], ...] = (
    # ISO 8601 date-times (with T or a space, optional seconds, fraction and zone)
    (re.compile(r"\d{4}-\d\d-\d\d[T ]\d\d:\d\d(?::\d\d(?:\.\d+)?)?(?:Z|[+-]\d\d:?\d\d)?"),
     "<TIME>"),
    # the same in ISO 8601's basic format (a name made from a session's start: 20261128T164924Z)
    (re.compile(r"(?<!\d)\d{8}T\d{6}Z?(?!\d)"), "<TIME>"),
    (re.compile(r"[0-9a-f]{8}-[0-9a-f]{4}-[0-9a-f]{4}-[0-9a-f]{4}-[0-9a-f]{12}", re.I), "<UUID>"),
    (re.compile(r"\bpid[ =:]+\d+", re.I), "pid <PID>"),
    # a time stamp's value after its key, in JSON, escaped JSON or YAML
    (re.compile(r"(\\?\"?\b(?:created_at|updated_at|started_at|ended_at|closed_at)\b\\?\"?"
                r"\s*:\s*)(?:\\?\"[^\"\\]*\\?\"|'[^']*'|[-0-9.e+]+)"), r"\1<TIME>"),
    (re.compile(r"(\b(?:jointlimits-rig|rig|rig_version|onnxruntime|numpy|onnx)[ =:/]+v?)"
                r"\d+(?:\.\d+)+(?:(?:a|b|rc|\.dev|\.post|\+)[\w.]*)?"), r"\1<VERSION>"),
    # wall-clock durations measured by the code (a JSON key, possibly inside escaped JSON)
    (re.compile(r"(\\?\"(?:build_s|seconds|elapsed_s|train_s)\\?\"\s*:\s*)[-0-9.e+]+"),
     r"\1<SECONDS>"),
    # ... and as ``rig train`` prints them: "wrote m.onnx (swing field) in 0.7 s", "trained in"
    (re.compile(r"(\) in |\btrained in )\d+(?:\.\d+)? s\b"), r"\1<SECONDS> s"),
)


def normalise(text: str, tmp: str | Path | list[str | Path] | None = None) -> str:
    """``text`` with what differs between two runs of the same code replaced by placeholders.

    Strips, in this order:

    - the temporary directories ``tmp`` (and their resolved forms) → ``<TMP>``;
    - ISO 8601 date-times, extended or basic (``20261128T164924Z``) → ``<TIME>``;
    - UUIDs → ``<UUID>``; ``pid N`` → ``pid <PID>``;
    - the value of a key ``created_at``, ``updated_at``, ``started_at``, ``ended_at`` or
      ``closed_at`` (JSON, JSON escaped in a string, YAML) → ``<TIME>``;
    - the version after ``jointlimits-rig``, ``rig``, ``rig_version``, ``onnxruntime``,
      ``numpy`` or ``onnx`` → ``<VERSION>``;
    - a measured duration, the value of a JSON ``build_s``, ``seconds``, ``elapsed_s`` or
      ``train_s`` (also inside JSON escaped in a string), or ``in N s`` after a closing
      parenthesis or ``trained`` (``rig train``'s lines) → ``<SECONDS>``.

    Nothing else is touched.
    """
    dirs = [] if tmp is None else [tmp] if isinstance(tmp, (str, Path)) else list(tmp)
    forms = set()
    for d in dirs:
        forms.add(str(d))
        forms.add(str(Path(d).resolve()))
    for form in sorted(forms, key=len, reverse=True):
        text = text.replace(form, _TMP_PLACEHOLDER)
    for pattern, repl in _PATTERNS:
        text = pattern.sub(repl, text)
    return text


@contextlib.contextmanager
def tmpdir() -> Iterator[Path]:
    """A temporary directory, removed afterwards (pass it to :func:`normalise`)."""
    with tempfile.TemporaryDirectory(prefix="golden-") as d:
        yield Path(d)


# -- storage ---------------------------------------------------------------------------------
def _as_array(value: Any) -> np.ndarray:
    if isinstance(value, np.ndarray):
        arr = value
    elif isinstance(value, (bool, np.bool_)):
        arr = np.asarray(value, dtype=np.bool_)
    elif isinstance(value, (int, np.integer)):
        arr = np.asarray(value, dtype=np.int64 if isinstance(value, int) else value.dtype)
    elif isinstance(value, (float, np.floating)):
        arr = np.asarray(value, dtype=np.float64 if isinstance(value, float) else value.dtype)
    else:
        raise TypeError(f"unsupported golden value {type(value).__name__}")
    if arr.dtype.kind not in "biufc":
        raise TypeError(f"unsupported golden dtype {arr.dtype}")
    return np.ascontiguousarray(arr)


def _sample_index(size: int) -> np.ndarray:
    return np.unique(np.linspace(0, size - 1, min(N_SAMPLES, size)).astype(np.int64))


def _stats(arr: np.ndarray) -> np.ndarray:
    flat = arr.reshape(-1)
    if flat.dtype.kind == "b":
        flat = flat.astype(np.int64)
    if flat.dtype.kind == "c":
        flat = np.abs(flat)
    with np.errstate(all="ignore"):
        return np.array([np.nanmin(flat), np.nanmax(flat), np.nansum(flat.astype(np.float64))],
                        dtype=np.float64)


def _chunk_sums(arr: np.ndarray) -> np.ndarray:
    flat = arr.reshape(-1)
    if flat.dtype.kind == "c":
        flat = np.abs(flat)
    flat = flat.astype(np.float64)
    with np.errstate(all="ignore"):
        return np.array([np.nansum(c) for c in np.array_split(flat, N_CHUNKS)])


def _sha(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def encode(outputs: dict[str, Any]) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """``(arrays for the .npz, document for the .json)`` of a case's outputs."""
    arrays: dict[str, np.ndarray] = {}
    doc: dict[str, Any] = {"strings": {}, "bytes": {}, "digests": {}}
    for key in sorted(outputs):
        value = outputs[key]
        if "." in key:
            raise ValueError(f"golden key {key!r}: no dots in keys")
        if isinstance(value, str):
            doc["strings"][key] = value
        elif isinstance(value, bytes):
            doc["bytes"][key] = ({"base64": base64.b64encode(value).decode()}
                                 if len(value) <= DIGEST_BYTES else
                                 {"sha256": _sha(value), "len": len(value)})
        else:
            arr = _as_array(value)
            if arr.nbytes <= DIGEST_BYTES:
                arrays[key] = arr
            else:
                doc["digests"][key] = {"sha256": _sha(arr.tobytes()), "dtype": arr.dtype.str,
                                       "shape": list(arr.shape)}
                arrays[f"{key}.__samples__"] = arr.reshape(-1)[_sample_index(arr.size)]
                arrays[f"{key}.__stats__"] = _stats(arr)
                arrays[f"{key}.__chunks__"] = _chunk_sums(arr)
    return arrays, doc


def save(name: str, kind: str, outputs: dict[str, Any], data: Path = DATA) -> None:
    """Write ``<name>.npz`` and ``<name>.json`` for a case's outputs."""
    arrays, doc = encode(outputs)
    doc = {"kind": kind, **doc}
    data.mkdir(parents=True, exist_ok=True)
    with open(data / f"{name}.npz", "wb") as fh:
        np.savez_compressed(fh, **arrays)
    (data / f"{name}.json").write_text(json.dumps(doc, indent=1, sort_keys=True,
                                                  ensure_ascii=False) + "\n")


def load(name: str, data: Path = DATA) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """The stored ``(arrays, document)`` of a case."""
    with np.load(data / f"{name}.npz", allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    doc = json.loads((data / f"{name}.json").read_text())
    return arrays, doc


# -- comparison ------------------------------------------------------------------------------
def _largest_difference(expected: np.ndarray, got: np.ndarray) -> str:
    if expected.shape != got.shape or expected.size == 0:
        return ""
    if expected.dtype.kind == "b" or got.dtype.kind == "b":
        n = int(np.count_nonzero(expected != got))
        first = np.argwhere(expected != got)
        at = tuple(int(i) for i in first[0]) if len(first) else ()
        return f"; {n} of {expected.size} differ, first at {at}"
    with np.errstate(all="ignore"):
        e = expected.astype(np.complex128 if expected.dtype.kind == "c" else np.float64)
        g = got.astype(np.complex128 if got.dtype.kind == "c" else np.float64)
        diff = np.abs(e - g)
        nan_mismatch = np.isnan(e) != np.isnan(g)
        diff = np.where(nan_mismatch, np.inf, np.where(np.isnan(diff), 0.0, diff))
        bits = (np.frombuffer(expected.tobytes(), np.uint8).reshape((*expected.shape, -1))
                != np.frombuffer(got.tobytes(), np.uint8).reshape((*got.shape, -1))
                if expected.dtype == got.dtype else None)
    n_diff = (int(np.count_nonzero(bits.any(axis=-1))) if bits is not None
              else int(np.count_nonzero(diff)))
    i = np.unravel_index(int(np.argmax(diff)), diff.shape) if diff.ndim else ()
    at = tuple(int(k) for k in i)
    d_, e_, g_ = (x[i] if x.ndim else x for x in (diff, e, g))
    return (f"; {n_diff} of {expected.size} elements differ; largest difference "
            f"{d_.item()!r} at {at}: expected {e_.item()!r}, got {g_.item()!r}")


def _compare_array(key: str, expected: np.ndarray, got: np.ndarray) -> str | None:
    if expected.dtype != got.dtype:
        return f"{key}: dtype {got.dtype}, expected {expected.dtype}"
    if expected.shape != got.shape:
        return f"{key}: shape {got.shape}, expected {expected.shape}"
    if expected.tobytes() == got.tobytes():
        return None
    return f"{key}: values differ" + _largest_difference(expected, got)


def _first_line_diff(expected: str, got: str) -> str:
    el, gl = expected.splitlines(), got.splitlines()
    for n, (a, b) in enumerate(zip(el, gl, strict=False), 1):
        if a != b:
            return f"line {n}: expected {a!r}, got {b!r}"
    return f"{len(gl)} lines, expected {len(el)} (first {min(len(el), len(gl))} equal)" \
        if len(el) != len(gl) else "trailing whitespace/newline differs"


def compare(name: str, outputs: dict[str, Any], data: Path = DATA) -> list[str]:
    """Differences between a case's outputs and its stored golden (empty: bit-identical)."""
    exp_arrays, doc = load(name, data)
    got_arrays, got_doc = encode(outputs)
    problems: list[str] = []
    exp_keys = ({k for k in exp_arrays if "." not in k} | set(doc["strings"]) | set(doc["bytes"])
                | set(doc["digests"]))
    got_keys = set(outputs)
    if exp_keys != got_keys:
        missing, extra = sorted(exp_keys - got_keys), sorted(got_keys - exp_keys)
        problems.append(f"keys differ: missing {missing}, unexpected {extra}")
    for key in sorted(exp_keys & got_keys):
        if key in doc["strings"]:
            got = outputs[key]
            if not isinstance(got, str):
                problems.append(f"{key}: a {type(got).__name__}, expected a str")
            elif got != doc["strings"][key]:
                where = _first_line_diff(doc["strings"][key], got)
                problems.append(f"{key}: text differs, {where}")
        elif key in doc["bytes"]:
            got = outputs[key]
            if not isinstance(got, bytes):
                problems.append(f"{key}: a {type(got).__name__}, expected bytes")
            elif got_doc["bytes"][key] != doc["bytes"][key]:
                exp = doc["bytes"][key]
                n = exp["len"] if "len" in exp else len(base64.b64decode(exp["base64"]))
                problems.append(f"{key}: bytes differ ({len(got)} bytes, expected {n})")
        elif key in doc["digests"]:
            want = doc["digests"][key]
            if key not in got_doc["digests"]:
                arr = _as_array(outputs[key]) if not isinstance(outputs[key], (str, bytes)) \
                    else None
                what = (f"dtype {arr.dtype} shape {arr.shape}" if arr is not None
                        else type(outputs[key]).__name__)
                problems.append(f"{key}: {what}, expected dtype {want['dtype']} shape "
                                f"{tuple(want['shape'])}")
                continue
            have = got_doc["digests"][key]
            if have == want:
                continue
            if have["dtype"] != want["dtype"] or have["shape"] != want["shape"]:
                problems.append(f"{key}: dtype {have['dtype']} shape {tuple(have['shape'])}, "
                                f"expected {want['dtype']} {tuple(want['shape'])}")
                continue
            size = int(np.prod(want["shape"]))
            msg = f"{key}: SHA-256 differs (array of {size} stored as digest)"
            s = _compare_array("samples", exp_arrays[f"{key}.__samples__"],
                               got_arrays[f"{key}.__samples__"])
            msg += "; " + (s if s else f"the {N_SAMPLES} sampled values are equal")
            ce, cg = exp_arrays[f"{key}.__chunks__"], got_arrays[f"{key}.__chunks__"]
            bad = np.flatnonzero(ce.view(np.uint64) != cg.view(np.uint64))
            if len(bad):
                bounds = np.cumsum([0] + [len(c) for c in np.array_split(np.empty(size),
                                                                          N_CHUNKS)])
                k = int(bad[0])
                first = np.unravel_index(int(bounds[k]), tuple(want["shape"]))
                msg += (f"; {len(bad)} of {N_CHUNKS} chunks differ, the first from element "
                        f"{tuple(int(i) for i in first)} (flat {int(bounds[k])}..."
                        f"{int(bounds[k + 1]) - 1}): its sum {float(cg[k])!r}, expected "
                        f"{float(ce[k])!r}")
            st = _compare_array("stats", exp_arrays[f"{key}.__stats__"],
                                got_arrays[f"{key}.__stats__"])
            if st:
                msg += f"; nanmin/nanmax/nansum {got_arrays[f'{key}.__stats__'].tolist()}, " \
                       f"expected {exp_arrays[f'{key}.__stats__'].tolist()}"
            problems.append(msg)
        else:
            got = outputs[key]
            if isinstance(got, (str, bytes)):
                problems.append(f"{key}: a {type(got).__name__}, expected an array")
                continue
            p = _compare_array(key, exp_arrays[key], _as_array(got))
            if p:
                problems.append(p)
    return problems
