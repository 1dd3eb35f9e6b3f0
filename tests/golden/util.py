"""Small helpers the golden cases share: JSON text of results, flattening, seeded inputs."""

from __future__ import annotations

import hashlib
import json
import re
from typing import Any

import numpy as np

from models import quaternion as Q


def plain(obj: Any) -> Any:
    """``obj`` with numpy scalars and arrays turned into Python ones (float32 → float exactly),
    tuples into lists; mapping keys kept in their order."""
    if isinstance(obj, dict):
        return {str(k): plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [plain(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return plain(obj.tolist())
    if isinstance(obj, np.bool_):
        return bool(obj)
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.floating):
        return float(obj)
    return obj


def jtext(obj: Any) -> str:
    """JSON text of ``obj`` (float64 round-trips exactly through ``repr``; key order kept), one
    item a line so a difference names its line."""
    return json.dumps(plain(obj), indent=1, ensure_ascii=False, allow_nan=True)


def quats(n: int, seed: int) -> np.ndarray:
    """``n`` seeded unit quaternions (N, 4), both hemispheres."""
    return Q.random_quaternions(n, np.random.default_rng(seed))


def prefixed(prefix: str, d: dict[str, Any]) -> dict[str, Any]:
    """``{prefix_key: value}``."""
    return {f"{prefix}_{k}": v for k, v in d.items()}


def onnx_bytes(path, tmp=None) -> bytes:
    """An ONNX file's bytes with its metadata values passed through
    :func:`tests.golden.harness.normalise` (a training's measured duration), re-serialised."""
    import onnx

    from tests.golden.harness import normalise

    model = onnx.load_from_string(open(path, "rb").read())
    for p in model.metadata_props:
        p.value = normalise(p.value, tmp)
    return model.SerializeToString()


def long_text(prefix: str, text: str, head: int = 40) -> dict[str, Any]:
    """A long text as its first ``head`` lines, its line count and its SHA-256 (a difference
    past the head still fails, by the digest)."""
    lines = text.splitlines()
    return {f"{prefix}_head": "\n".join(lines[:head]), f"{prefix}_lines": len(lines),
            f"{prefix}_sha256": hashlib.sha256(text.encode()).hexdigest()}


_IMAGE = re.compile(r"data:image/(png|jpeg|svg\+xml);base64,([A-Za-z0-9+/=]+)")


def html_text(prefix: str, html: str) -> dict[str, Any]:
    """An HTML page as its text with every embedded image replaced by the SHA-256 of its
    base64 data (a difference names its line), plus the SHA-256 of the whole page."""
    text = _IMAGE.sub(lambda m: f"data:image/{m.group(1)};sha256,"
                      f"{hashlib.sha256(m.group(2).encode()).hexdigest()}", html)
    return {f"{prefix}_html": text,
            f"{prefix}_html_sha256": hashlib.sha256(html.encode()).hexdigest()}
