"""The :class:`Dataset` container and its on-disk format.

A dataset is a set of training patterns ``(input_i, target_i)`` of a vector field (thesis ch. 3-4:
input = a point P / vector V / orientation quaternion Qi, target = its correction C / O / Qo),
plus a metadata record and optional region labels (thesis Fig. 34)::

    0  inner valid              valid,   signed distance <= -band
    1  valid near boundary      valid,   -band < distance <= 0
    2  invalid near boundary    invalid, 0 < distance <= band
    3  outer invalid            invalid, distance > band

On-disk format (``.npz`` written by :func:`numpy.savez_compressed`, read with
``allow_pickle=False`` — nothing in the file is ever unpickled):

=============  ===============  ==========================================================
array          dtype, shape     content
=============  ===============  ==========================================================
``inputs``     float64 (N, d)   the patterns' inputs
``targets``    float64 (N, k)   the patterns' targets
``regions``    int8 (N,)        region labels 0-3 (absent when the dataset has none)
``record``     unicode, ()      JSON object ``{"format": "jointlimits-dataset",
                                "format_version": 1, "content_hash": <sha256 hex>,
                                "meta": {...}}``
=============  ===============  ==========================================================

``content_hash`` is :meth:`Dataset.content_hash`: SHA-256 over the format tag, each array's name,
dtype, shape and little-endian bytes, and the canonical JSON of ``meta`` (sorted keys, no
whitespace). It identifies the training data in ONNX model metadata; :func:`load_dataset`
recomputes it and rejects a file whose content no longer matches.
"""

from __future__ import annotations

import hashlib
import json
import os
import zipfile
import zlib
from dataclasses import dataclass, field
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import Any

import numpy as np

from models.constraint import JointConstraint, loads_constraint
from models.errors import ConstraintError, DatasetError

__all__ = [
    "FORMAT_NAME",
    "FORMAT_VERSION",
    "REGION_NAMES",
    "Dataset",
    "created_by",
    "load_dataset",
]

FORMAT_NAME = "jointlimits-dataset"
FORMAT_VERSION = 1

#: Names of the region labels 0-3 (thesis Fig. 34).
REGION_NAMES: tuple[str, ...] = (
    "inner-valid",
    "valid-near-boundary",
    "invalid-near-boundary",
    "outer-invalid",
)


def created_by() -> str:
    """``"jointlimits-rig <version>"`` for the ``created_by`` metadata field."""
    try:
        v = version("jointlimits-rig")
    except PackageNotFoundError:  # source tree, not installed
        v = "0.0.0+unknown"
    return f"jointlimits-rig {v}"


def dataset_meta(kind: str, generator: dict[str, Any], rng_meta: dict[str, Any],
                 **extra: Any) -> dict:
    """A generated dataset's metadata: its ``kind``, the ``generator``'s parameters, the seed
    facts of :func:`models.datasets._common.make_rng`, ``created_by``, the region names, then
    ``extra`` (in that key order: the file's JSON keeps it)."""
    return {
        "kind": kind,
        "generator": generator,
        **rng_meta,
        "created_by": created_by(),
        "region_names": list(REGION_NAMES),
        **extra,
    }


def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, (tuple, set)):
        return list(obj)
    raise TypeError(f"{type(obj).__name__} is not JSON-serialisable")


def _canonical_json(meta: dict[str, Any]) -> str:
    return json.dumps(meta, sort_keys=True, separators=(",", ":"), allow_nan=False)


@dataclass(eq=False)
class Dataset:
    """Patterns of a corrective vector field with their provenance.

    Parameters
    ----------
    inputs : (N, d_in) float64
        Pattern inputs, e.g. orientation quaternions ``(w, x, y, z)``, limb relative to parent.
    targets : (N, d_out) float64
        Pattern targets, e.g. corrective quaternions in the parent frame (``w >= 0``).
    meta : dict
        JSON-serialisable metadata: ``kind``, ``constraint`` (YAML text, if any), ``generator``
        (the parameters), ``seed`` / ``rng_state``, ``created_by``, ``region_names``... Numpy
        scalars and arrays are converted to plain JSON values on construction.
    regions : (N,) int8, optional
        Region labels 0-3 (:data:`REGION_NAMES`).

    Raises
    ------
    DatasetError
        Arrays of the wrong rank, non-finite values, mismatched lengths, labels outside 0-3, or
        metadata that is not JSON-serialisable.
    """

    inputs: np.ndarray
    targets: np.ndarray
    meta: dict[str, Any] = field(default_factory=dict)
    regions: np.ndarray | None = None

    def __post_init__(self) -> None:
        self.inputs = _as_matrix(self.inputs, "inputs")
        self.targets = _as_matrix(self.targets, "targets")
        n = len(self.inputs)
        if len(self.targets) != n:
            raise DatasetError(
                f"targets: {len(self.targets)} rows, expected {n} (one per input row)"
            )
        if self.regions is not None:
            r = np.asarray(self.regions)
            if r.shape != (n,):
                raise DatasetError(f"regions: expected shape ({n},), got {r.shape}")
            if r.size and (not np.issubdtype(r.dtype, np.integer) or r.min() < 0 or r.max() > 3):
                raise DatasetError("regions: labels must be integers 0-3")
            self.regions = np.ascontiguousarray(r, dtype=np.int8)
        if not isinstance(self.meta, dict):
            raise DatasetError(f"meta: expected a dict, got {type(self.meta).__name__}")
        try:
            self.meta = json.loads(json.dumps(self.meta, default=_json_default, allow_nan=False))
        except (TypeError, ValueError) as err:
            raise DatasetError(f"meta: not JSON-serialisable ({err})") from err

    # -- views ------------------------------------------------------------------------------
    def __len__(self) -> int:
        return len(self.inputs)

    @property
    def valid(self) -> np.ndarray | None:
        """(N,) bool, True for regions 0-1; ``None`` when the dataset has no region labels."""
        return None if self.regions is None else self.regions <= 1

    def region_counts(self) -> dict[str, int]:
        """Pattern count per region name (empty when there are no labels)."""
        if self.regions is None:
            return {}
        counts = np.bincount(self.regions, minlength=4)
        return {name: int(c) for name, c in zip(REGION_NAMES, counts, strict=True)}

    def constraint(self) -> JointConstraint | None:
        """The constraint the dataset was generated from (``meta["constraint"]``), if any."""
        text = self.meta.get("constraint")
        if not text:
            return None
        try:
            return loads_constraint(text, source="dataset metadata")
        except ConstraintError as err:
            raise DatasetError(f"meta.constraint: {err}") from err

    def subset(self, index: np.ndarray, **meta_updates: Any) -> Dataset:
        """Rows ``index`` (integer array or bool mask) as a new dataset; meta updated."""
        meta = dict(self.meta)
        meta.update(meta_updates)
        return Dataset(
            inputs=self.inputs[index],
            targets=self.targets[index],
            meta=meta,
            regions=None if self.regions is None else self.regions[index],
        )

    # -- identity and storage ---------------------------------------------------------------
    def _arrays(self) -> dict[str, np.ndarray]:
        arrays = {"inputs": self.inputs, "targets": self.targets}
        if self.regions is not None:
            arrays["regions"] = self.regions
        return arrays

    def content_hash(self) -> str:
        """SHA-256 (hex) of the arrays and the metadata; equal datasets give equal hashes."""
        h = hashlib.sha256(f"{FORMAT_NAME}/{FORMAT_VERSION}\n".encode())
        for name, arr in self._arrays().items():
            le = np.ascontiguousarray(arr, dtype=arr.dtype.newbyteorder("<"))
            h.update(f"{name}:{le.dtype.str}:{le.shape}\n".encode())
            h.update(le.tobytes())
        h.update(_canonical_json(self.meta).encode())
        return h.hexdigest()

    def save(self, path: str | Path) -> Path:
        """Write the dataset to ``path`` (``.npz``, see the module docstring), atomically.

        Returns the path written. The suffix is not changed (numpy's habit of appending
        ``.npz`` is avoided by writing through a file object).
        """
        path = Path(path)
        record = {
            "format": FORMAT_NAME,
            "format_version": FORMAT_VERSION,
            "content_hash": self.content_hash(),
            "meta": self.meta,
        }
        tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
        try:
            with open(tmp, "wb") as fh:
                np.savez_compressed(fh, record=np.array(_canonical_json(record)), **self._arrays())
            tmp.replace(path)
        except OSError as err:
            tmp.unlink(missing_ok=True)
            raise DatasetError(f"{path}: cannot write ({err.strerror or err})") from err
        return path

    def summary(self) -> str:
        """A few human-readable lines: kind, sizes, region counts and valid fraction."""
        g = self.meta.get("generator", {})
        lines = [
            f"dataset kind {self.meta.get('kind', '?')!r}: {len(self)} patterns, "
            f"inputs {self.inputs.shape[1]}-D, targets {self.targets.shape[1]}-D"
        ]
        if g:
            lines.append("  generator   " + ", ".join(f"{k}={v}" for k, v in g.items()))
        if self.meta.get("constraint_name"):
            lines.append(f"  constraint  {self.meta['constraint_name']}")
        if self.regions is not None and len(self):
            for name, c in self.region_counts().items():
                lines.append(f"  {name:<22}{c:>8}")
            lines.append(f"  valid fraction {float(np.mean(self.valid)):.3f}")
        lines.append(f"  content hash {self.content_hash()[:16]}")
        return "\n".join(lines)


def _as_matrix(a: Any, name: str) -> np.ndarray:
    try:
        arr = np.asarray(a, dtype=np.float64)
    except (TypeError, ValueError) as err:
        raise DatasetError(f"{name}: not a numeric array ({err})") from err
    if arr.ndim != 2:
        raise DatasetError(f"{name}: expected a 2-D array (N, d), got shape {arr.shape}")
    if not np.isfinite(arr).all():
        row = int(np.argmin(np.isfinite(arr).all(axis=1)))
        raise DatasetError(f"{name}[{row}] has a NaN or infinite value")
    return np.ascontiguousarray(arr)


def load_dataset(path: str | Path) -> Dataset:
    """Read a dataset written by :meth:`Dataset.save`.

    Raises
    ------
    DatasetError
        Missing file, not an ``.npz`` archive, damaged archive, pickled content, missing
        arrays, bad metadata record, unknown format or version, content-hash mismatch. The
        message names the file and what is wrong.
    """
    path = Path(path)
    where = str(path)
    if not path.exists():
        raise DatasetError(f"{where}: file not found")
    if path.is_dir():
        raise DatasetError(f"{where}: is a directory, not a dataset file")
    try:
        with open(path, "rb") as fh:
            magic = fh.read(4)
    except OSError as err:
        raise DatasetError(f"{where}: cannot read ({err.strerror or err})") from err
    if magic != b"PK\x03\x04":
        what = "an empty file" if not magic else f"starts with {magic!r}"
        raise DatasetError(f"{where}: not a dataset file (expected an .npz archive; {what})")
    try:
        npz = np.load(path, allow_pickle=False)
    except (ValueError, OSError, EOFError, zipfile.BadZipFile) as err:
        raise DatasetError(f"{where}: not a dataset file (.npz archive): {err}") from err
    if not isinstance(npz, np.lib.npyio.NpzFile):
        raise DatasetError(f"{where}: a single .npy array, not a dataset .npz archive")
    with npz:
        names = set(npz.files)
        for key in ("record", "inputs", "targets"):
            if key not in names:
                raise DatasetError(
                    f"{where}: missing array {key!r} (found {sorted(names)}); "
                    "not written by Dataset.save"
                )
        try:
            arrays = {k: npz[k] for k in ("record", "inputs", "targets", "regions") if k in names}
        except ValueError as err:
            if "pickle" in str(err):
                raise DatasetError(f"{where}: contains pickled objects, which are refused") from err
            raise DatasetError(f"{where}: damaged array data: {err}") from err
        except (OSError, EOFError, zipfile.BadZipFile, zlib.error, KeyError) as err:
            raise DatasetError(f"{where}: damaged archive: {err}") from err
    rec_arr = arrays.pop("record")
    if rec_arr.shape != () or rec_arr.dtype.kind != "U":
        raise DatasetError(f"{where}: 'record' must be a JSON string, got {rec_arr.dtype}")
    try:
        record = json.loads(str(rec_arr))
    except json.JSONDecodeError as err:
        raise DatasetError(f"{where}: metadata record is not valid JSON ({err})") from err
    if not isinstance(record, dict) or record.get("format") != FORMAT_NAME:
        fmt = record.get("format") if isinstance(record, dict) else None
        raise DatasetError(f"{where}: format is {fmt!r}, expected {FORMAT_NAME!r}")
    ver = record.get("format_version")
    if ver != FORMAT_VERSION:
        raise DatasetError(
            f"{where}: format_version {ver!r} is not supported (this version reads "
            f"{FORMAT_VERSION})"
        )
    meta = record.get("meta")
    if not isinstance(meta, dict):
        raise DatasetError(f"{where}: metadata 'meta' must be a JSON object")
    try:
        ds = Dataset(
            inputs=arrays["inputs"],
            targets=arrays["targets"],
            meta=meta,
            regions=arrays.get("regions"),
        )
    except DatasetError as err:
        raise DatasetError(f"{where}: {err}") from err
    stored = record.get("content_hash")
    if stored != ds.content_hash():
        raise DatasetError(
            f"{where}: content hash mismatch (stored {str(stored)[:16]}..., computed "
            f"{ds.content_hash()[:16]}...): the file was altered or damaged"
        )
    return ds
