"""Import and export of orientation time series: OpenSim ``.sto`` and CSV.

OpenSim orientation ``.sto`` (what OpenSense's IMU placer and IMU inverse kinematics read,
written by OpenSim's ``STOFileAdapterQuaternion``)::

    DataRate=400.000000          \\
    DataType=Quaternion           | header: key=value lines (any others kept in ``meta``),
    version=3                     | lines without '=' (a table name, comments) are ignored
    OpenSimVersion=4.5           /
    endheader
    time<TAB>thorax_imu<TAB>humerus_imu
    0.0025<TAB>w,x,y,z<TAB>w,x,y,z            one row per time, one cell per column

Cells are scalar-first ``w,x,y,z`` (SimTK::Quaternion's order, the rig's convention too).
Columns whose cells are not four numbers (scalars, Vec3s from other exporters) are kept out of
the table and named in ``meta["ignored_columns"]``. OpenSim names IMU columns ``<body>_imu``;
:meth:`OrientationTable.get` accepts the name with or without that suffix.

CSV forms (comma-separated, one header line)::

    t_s,w,x,y,z                                     single orientation (also rig enforce targets)
    t_s,thorax_w,thorax_x,thorax_y,thorax_z,humerus_w,...          wide: several segments
    t_s,device_t_s,name,kind,w,x,y,z,status         long: one row per sample (session export)
    t_s,device_t_s,name,kind,w,x,y,z,status,acc_x,acc_y,acc_z,gyr_x,gyr_y,gyr_z,mag_x,mag_y,mag_z
                                                    long, with the IMUs' raw readings

The long form's raw columns (accelerometer m/s², gyroscope rad/s, magnetometer µT, sensor
frame; :data:`rig.store.schema.RAW_COLUMNS`) are written when any sample has a raw reading; an
empty cell is a value the sample does not have (NaN).

Validation, on every reader: a row with the wrong number of cells, a non-number, a NaN or
infinite value, a zero quaternion, or a quaternion whose norm differs from 1 by more than
:data:`NORM_TOLERANCE` is refused with :class:`~rig.errors.RigConfigError` naming the file, the
line and the column. Quaternions within the tolerance are returned *as written* -- never
silently renormalised -- so that export -> import is exact; times must be finite and strictly
increasing per series.

Writers use Python's shortest round-trip float repr, so ``write_sto`` -> ``read_sto`` (and the
CSV pair) reproduce every float64 bit for bit. Files are written to a temporary name and
renamed, so a crash never leaves half a file under the final name.
"""

from __future__ import annotations

import contextlib
import math
import os
import tempfile
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from rig import __version__
from rig.errors import RigConfigError
from rig.store.store import Store

#: Largest accepted | ||q|| - 1 | of an imported quaternion. Text written with 4 decimals is
#: within ~2e-4 of unit norm; anything further off is a unit error or a corrupted value.
NORM_TOLERANCE = 1e-3

#: Header keys written by :func:`write_sto` (OpenSim's order), then any of the table's meta.
STO_VERSION = "3"
OPENSIM_VERSION = "4.5"


@dataclass
class OrientationTable:
    """Orientations of one or more segments (or joints) at common times.

    Attributes
    ----------
    time : (N,) float64
        Seconds, strictly increasing.
    columns : dict[str, (N, 4) float64]
        Column label -> scalar-first quaternions ``w, x, y, z`` (as read; unit within
        :data:`NORM_TOLERANCE`). Insertion order is file order.
    rate_hz : float or None
        The file's ``DataRate`` (``.sto``), or None.
    meta : dict[str, str]
        Other header entries (``.sto``), ``ignored_columns``, ``source``.
    """

    time: np.ndarray
    columns: dict[str, np.ndarray]
    rate_hz: float | None = None
    meta: dict[str, str] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.time = np.asarray(self.time, dtype=np.float64).reshape(-1)
        n = self.time.shape[0]
        cols = {}
        for label, q in self.columns.items():
            q = np.asarray(q, dtype=np.float64)
            if q.shape != (n, 4):
                raise RigConfigError(f"column {label!r}: expected shape ({n}, 4), got {q.shape}")
            cols[str(label)] = q
        self.columns = cols

    def __len__(self) -> int:
        return int(self.time.shape[0])

    @property
    def labels(self) -> list[str]:
        return list(self.columns)

    def get(self, name: str) -> np.ndarray:
        """Quaternions (N, 4) of column ``name`` (``humerus`` also finds ``humerus_imu``)."""
        if name in self.columns:
            return self.columns[name]
        if name + "_imu" in self.columns:
            return self.columns[name + "_imu"]
        raise RigConfigError(
            f"no column {name!r} in {self.meta.get('source', 'the table')}; "
            f"columns: {', '.join(self.columns) or '(none)'}"
        )


# ---------------------------------------------------------------------------------------------
# reading helpers


def _num(cell: str, where: str) -> float:
    try:
        v = float(cell)
    except ValueError:
        raise RigConfigError(f"{where}: {cell.strip()!r} is not a number") from None
    if not math.isfinite(v):
        raise RigConfigError(f"{where}: {cell.strip()} is not a finite number")
    return v


def _quat(parts: list[str], where: str) -> tuple[float, float, float, float]:
    vals = []
    for p in parts:
        try:
            vals.append(float(p))
        except ValueError:
            raise RigConfigError(f"{where}: {p.strip()!r} is not a number") from None
    if any(math.isnan(v) for v in vals):
        raise RigConfigError(f"{where}: NaN in quaternion {','.join(s.strip() for s in parts)}")
    if any(math.isinf(v) for v in vals):
        raise RigConfigError(f"{where}: infinite value in quaternion")
    n = math.sqrt(sum(v * v for v in vals))
    if n == 0.0:
        raise RigConfigError(f"{where}: zero quaternion (no orientation)")
    if abs(n - 1.0) > NORM_TOLERANCE:
        raise RigConfigError(
            f"{where}: quaternion norm {n:.6g} is not 1 (tolerance {NORM_TOLERANCE:g}); "
            "refusing to renormalise"
        )
    return vals[0], vals[1], vals[2], vals[3]


def _parse_rows(time_cells: list[str], quat_cells: list[str], n_cols: int):
    """Every data row at once: times (N,) and quaternions (N, C, 4) — or None when any cell
    would fail :func:`_rows_one_by_one` (not a number, not four components, NaN, infinite,
    zero, not unit), so that the per-row checks name it. Parses as ``float`` does."""
    if any(cell.count(",") != 3 for cell in quat_cells):
        return None
    try:
        t = np.array(time_cells).astype(np.float64)
        q = np.array(",".join(quat_cells).split(",")).astype(np.float64)
    except ValueError:
        return None
    q = q.reshape(len(time_cells), n_cols, 4)
    if not (np.isfinite(t).all() and np.isfinite(q).all()):
        return None
    n = np.sqrt(np.sum(q * q, axis=2))
    if not (np.abs(n - 1.0) <= NORM_TOLERANCE).all():
        return None
    return t, q


def _rows_one_by_one(data_lines, quat_cols: list[int], labels: list[str], src: str):
    """:func:`_parse_rows` a row at a time, raising for the first wrong cell with its line."""
    times, rows = [], []
    for ln, cells in data_lines:
        where = f"{src}:{ln}"
        times.append(_num(cells[0], f"{where}: time"))
        row = []
        for c in quat_cols:
            parts = cells[c].split(",")
            if len(parts) != 4:
                raise RigConfigError(f"{where}: column {labels[c]}: {len(parts)} components, "
                                     f"expected 4 (w,x,y,z)")
            row.append(_quat(parts, f"{where}: column {labels[c]}"))
        rows.append(row)
    return np.array(times), np.array(rows, dtype=np.float64)


def _check_time(t: np.ndarray, lines: list[int], src: str, what: str = "time") -> None:
    if t.size > 1:
        d = np.diff(t)
        bad = np.flatnonzero(d <= 0)
        if bad.size:
            i = int(bad[0]) + 1
            raise RigConfigError(
                f"{src}:{lines[i]}: {what} {float(t[i])!r} does not increase "
                f"(previous {float(t[i - 1])!r})"
            )


def _read_lines(path: str | os.PathLike) -> list[str]:
    p = Path(path)
    if p.is_dir():
        raise RigConfigError(f"{path}: is a directory")
    try:
        text = p.read_text(encoding="utf-8-sig")
    except FileNotFoundError:
        raise
    except UnicodeDecodeError as err:
        raise RigConfigError(f"{path}: not a text file ({err.reason})") from err
    return text.splitlines()


# ---------------------------------------------------------------------------------------------
# .sto


def read_sto(path: str | os.PathLike) -> OrientationTable:
    """Read an OpenSim orientation ``.sto`` file (see the module docstring)."""
    src = os.fspath(path)
    lines = _read_lines(path)
    meta: dict[str, str] = {"source": src}
    i = 0
    end = None
    while i < len(lines):
        line = lines[i].strip()
        i += 1
        if line.lower() == "endheader":
            end = i
            break
        if "=" in line:
            k, v = line.split("=", 1)
            if k.strip() and v.strip():
                meta[k.strip()] = v.strip()
    if end is None:
        raise RigConfigError(f"{src}: no 'endheader' line: not an OpenSim .sto file")
    dtype = meta.pop("DataType", None)
    if dtype is not None and dtype != "Quaternion":
        raise RigConfigError(
            f"{src}: DataType={dtype}, expected DataType=Quaternion (an orientations file)"
        )
    rate = None
    if "DataRate" in meta:
        try:
            rate = float(meta.pop("DataRate"))
        except ValueError:
            raise RigConfigError(f"{src}: DataRate is not a number") from None
    # column labels: first non-blank line after endheader
    while i < len(lines) and not lines[i].strip():
        i += 1
    if i >= len(lines):
        raise RigConfigError(f"{src}: no column labels after endheader")
    label_line = i + 1
    labels = [c.strip() for c in lines[i].rstrip("\r\n").split("\t")]
    i += 1
    if labels[0].lower() != "time":
        raise RigConfigError(
            f"{src}:{label_line}: first column must be 'time', got {labels[0]!r}"
        )
    ncol = len(labels)
    if len(set(labels)) != ncol:
        raise RigConfigError(f"{src}:{label_line}: duplicate column labels")
    time_cells: list[str] = []
    quat_cells: list[str] = []
    data_lines: list[tuple[int, list[str]]] = []
    quat_cols: list[int] | None = None
    for j in range(i, len(lines)):
        raw = lines[j].rstrip("\r\n")
        if not raw.strip():
            continue
        ln = j + 1
        cells = raw.split("\t")
        if len(cells) != ncol:
            raise RigConfigError(
                f"{src}:{ln}: {len(cells)} cells, expected {ncol} ({', '.join(labels)})"
            )
        if quat_cols is None:  # column kinds from the first data row
            quat_cols = [c for c in range(1, ncol) if cells[c].count(",") == 3]
            ignored = [labels[c] for c in range(1, ncol) if c not in quat_cols]
            if ignored:
                meta["ignored_columns"] = ",".join(ignored)
            if not quat_cols:
                raise RigConfigError(
                    f"{src}:{ln}: no quaternion columns (cells of four comma-separated numbers)"
                )
        time_cells.append(cells[0])
        quat_cells.extend(cells[c] for c in quat_cols)
        data_lines.append((ln, cells))
    if not data_lines:
        raise RigConfigError(f"{src}: no data rows")
    assert quat_cols is not None
    line_nos = [ln for ln, _ in data_lines]
    parsed = _parse_rows(time_cells, quat_cells, len(quat_cols))
    if parsed is None:  # some cell is wrong: row by row, the first one is named
        parsed = _rows_one_by_one(data_lines, quat_cols, labels, src)
    t, arr = parsed
    _check_time(t, line_nos, src)
    columns = {labels[c]: np.ascontiguousarray(arr[:, k, :]) for k, c in enumerate(quat_cols)}
    return OrientationTable(time=t, columns=columns, rate_hz=rate, meta=meta)


def _fmt(v: float) -> str:
    return repr(float(v))


def _atomic_write(path: str | os.PathLike, head: str, lines: Iterable[str]) -> None:
    """Write ``head`` then each line (newline-terminated) to a temporary file beside ``path``,
    fsync, then rename over ``path``: a reader never sees a half-written export."""
    p = Path(path)
    if not p.parent.is_dir():
        raise RigConfigError(f"--out {path}: directory {p.parent} does not exist")
    fd, tmp = tempfile.mkstemp(prefix=f".{p.name}.", suffix=".tmp", dir=p.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8", newline="\n") as fh:
            fh.write(head)
            for line in lines:
                fh.write(line)
                fh.write("\n")
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, p)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def _rate_of(table: OrientationTable) -> float:
    if table.rate_hz is not None:
        return float(table.rate_hz)
    if len(table) > 1:
        return float(1.0 / np.median(np.diff(table.time)))
    return 0.0


def write_sto(path: str | os.PathLike, table: OrientationTable) -> None:
    """Write ``table`` as an OpenSim orientation ``.sto`` (exact float round trip).

    Header: ``DataRate`` (the table's, else 1 / median time step), ``DataType=Quaternion``,
    ``version=3``, ``OpenSimVersion``, the table's other ``meta`` entries (keys and values
    without tabs, newlines or '='), then ``endheader``.
    """
    if len(table) == 0:
        raise RigConfigError(f"{path}: nothing to write (no rows)")
    _check_time(table.time, list(range(1, len(table) + 1)), os.fspath(path), "time row")
    head = [
        f"DataRate={_rate_of(table):.6f}\n",
        "DataType=Quaternion\n",
        f"version={STO_VERSION}\n",
        f"OpenSimVersion={OPENSIM_VERSION}\n",
    ]
    for k, v in table.meta.items():
        if k in ("source", "DataRate", "DataType", "version", "OpenSimVersion"):
            continue
        k, v = str(k), str(v)
        if any(ch in k + v for ch in "\t\r\n") or "=" in k or not k or not v:
            continue
        head.append(f"{k}={v}\n")
    head.append("endheader\n")
    labels = list(table.columns)
    for lab in labels:
        if any(ch in lab for ch in "\t\r\n,") or not lab:
            raise RigConfigError(f"column label {lab!r} cannot be written to a .sto file")
    head.append("time\t" + "\t".join(labels) + "\n")
    cols = [table.columns[lab].tolist() for lab in labels]
    times = table.time.tolist()

    def lines():
        for r, t in enumerate(times):
            cells = [repr(t)]
            for c in cols:
                w, x, y, z = c[r]
                cells.append(f"{w!r},{x!r},{y!r},{z!r}")
            yield "\t".join(cells)

    _atomic_write(path, "".join(head), lines())


# ---------------------------------------------------------------------------------------------
# CSV

_LONG_REQUIRED = ("t_s", "name", "w", "x", "y", "z")
#: The long form's raw-reading columns (the store's, :data:`rig.store.schema.RAW_COLUMNS`).
RAW_CSV_COLUMNS = ("acc_x", "acc_y", "acc_z", "gyr_x", "gyr_y", "gyr_z",
                   "mag_x", "mag_y", "mag_z")


def _csv_header(lines: list[str], src: str) -> tuple[int, list[str]]:
    for i, line in enumerate(lines):
        if line.strip() and not line.lstrip().startswith("#"):
            cols = [c.strip() for c in line.split(",")]
            if len(set(cols)) != len(cols):
                raise RigConfigError(f"{src}:{i + 1}: duplicate column names")
            return i, cols
    raise RigConfigError(f"{src}: empty CSV file")


def _csv_rows(lines: list[str], header: int, ncols: int, src: str):
    """``(line number, cells)`` of the data rows after the header line ``header`` (blank and
    ``#`` lines skipped); a row with the wrong number of cells is named by its line."""
    for j in range(header + 1, len(lines)):
        raw = lines[j]
        if not raw.strip() or raw.lstrip().startswith("#"):
            continue
        cells = raw.split(",")
        if len(cells) != ncols:
            raise RigConfigError(f"{src}:{j + 1}: {len(cells)} cells, expected {ncols}")
        yield j + 1, cells


def read_samples_csv(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """Read a long-form CSV (``t_s,name,w,x,y,z`` and optionally ``device_t_s``, ``kind``,
    ``status``, the nine raw columns ``acc_x..mag_z`` -- all or none; other columns ignored)
    into arrays shaped like ``store.samples.read`` (``raw`` NaN where a cell is empty or the
    file has no raw columns)."""
    src = os.fspath(path)
    lines = _read_lines(path)
    h, cols = _csv_header(lines, src)
    missing = [c for c in _LONG_REQUIRED if c not in cols]
    if missing:
        raise RigConfigError(f"{src}:{h + 1}: long-form CSV needs columns {', '.join(missing)}")
    ix = {c: cols.index(c) for c in cols}
    raw_ix: list[int] = []
    if any(c in ix for c in RAW_CSV_COLUMNS):
        lacking = [c for c in RAW_CSV_COLUMNS if c not in ix]
        if lacking:
            raise RigConfigError(f"{src}:{h + 1}: raw columns come as all nine "
                                 f"({','.join(RAW_CSV_COLUMNS)}); missing {', '.join(lacking)}")
        raw_ix = [ix[c] for c in RAW_CSV_COLUMNS]
    t, dt, names, kinds, qs, st, lns, raws = [], [], [], [], [], [], [], []
    for ln, cells in _csv_rows(lines, h, len(cols), src):
        t.append(_num(cells[ix["t_s"]], f"{src}:{ln}: t_s"))
        if "device_t_s" in ix and cells[ix["device_t_s"]].strip() not in ("", "nan", "NaN"):
            dt.append(_num(cells[ix["device_t_s"]], f"{src}:{ln}: device_t_s"))
        else:
            dt.append(math.nan)
        name = cells[ix["name"]].strip()
        if not name:
            raise RigConfigError(f"{src}:{ln}: empty name")
        names.append(name)
        kinds.append(cells[ix["kind"]].strip() if "kind" in ix else "sensor")
        qs.append(_quat([cells[ix[c]] for c in "wxyz"], f"{src}:{ln}: {name}"))
        if "status" in ix and cells[ix["status"]].strip():
            try:
                st.append(int(cells[ix["status"]]))
            except ValueError:
                raise RigConfigError(f"{src}:{ln}: status {cells[ix['status']]!r} is not an "
                                     "integer") from None
        else:
            st.append(0)
        if raw_ix:
            raws.append([
                math.nan if cells[k].strip() in ("", "nan", "NaN")
                else _num(cells[k], f"{src}:{ln}: {cols[k]}")
                for k in raw_ix
            ])
        lns.append(ln)
    if not t:
        raise RigConfigError(f"{src}: no data rows")
    out = {
        "t": np.array(t), "device_t": np.array(dt), "name": np.array(names, dtype=object),
        "kind": np.array(kinds, dtype=object), "q": np.array(qs, dtype=np.float64),
        "status": np.array(st, dtype=np.int64),
        "raw": np.array(raws, dtype=np.float64) if raw_ix else np.full((len(t), 9), np.nan),
    }
    for nm in dict.fromkeys(names):
        sel = np.flatnonzero(out["name"] == nm)
        _check_time(out["t"][sel], [lns[k] for k in sel], src, f"t_s of {nm}")
    return out


def read_csv(path: str | os.PathLike) -> OrientationTable:
    """Read any of the three CSV forms into an :class:`OrientationTable`.

    Single form -> one column labelled ``orientation``; wide form -> one column per
    ``<name>_w..z`` group (other columns ignored, named in ``meta["ignored_columns"]``); long
    form -> the series aligned on common times by :func:`align_series`.
    """
    src = os.fspath(path)
    lines = _read_lines(path)
    h, cols = _csv_header(lines, src)
    if "t_s" not in cols:
        raise RigConfigError(f"{src}:{h + 1}: no t_s column (columns: {', '.join(cols)})")
    if "name" in cols:
        s = read_samples_csv(path)
        series = {
            nm: (s["t"][s["name"] == nm], s["q"][s["name"] == nm])
            for nm in dict.fromkeys(s["name"].tolist())
        }
        table, dropped = align_series(series)
        table.meta.update(source=src, aligned_dropped=str(dropped))
        return table
    groups: dict[str, list[int]] = {}
    if all(c in cols for c in "wxyz"):
        groups["orientation"] = [cols.index(c) for c in "wxyz"]
    for c in cols:
        if len(c) > 2 and c[-2] == "_" and c[-1] == "w":
            base = c[:-2]
            names = [f"{base}_{k}" for k in "wxyz"]
            if all(n in cols for n in names):
                groups[base] = [cols.index(n) for n in names]
    if not groups:
        raise RigConfigError(
            f"{src}:{h + 1}: no quaternion columns: expected t_s,w,x,y,z or "
            "t_s,<name>_w,<name>_x,<name>_y,<name>_z,... or t_s,name,w,x,y,z"
        )
    used = {cols.index("t_s")} | {k for g in groups.values() for k in g}
    meta = {"source": src}
    ignored = [c for k, c in enumerate(cols) if k not in used]
    if ignored:
        meta["ignored_columns"] = ",".join(ignored)
    ti = cols.index("t_s")
    t, rows, lns = [], [], []
    for ln, cells in _csv_rows(lines, h, len(cols), src):
        t.append(_num(cells[ti], f"{src}:{ln}: t_s"))
        rows.append([
            _quat([cells[k] for k in g], f"{src}:{ln}: {name}") for name, g in groups.items()
        ])
        lns.append(ln)
    if not rows:
        raise RigConfigError(f"{src}: no data rows")
    tt = np.array(t)
    _check_time(tt, lns, src, "t_s")
    arr = np.array(rows, dtype=np.float64)
    columns = {name: np.ascontiguousarray(arr[:, k, :]) for k, name in enumerate(groups)}
    return OrientationTable(time=tt, columns=columns, meta=meta)


def write_csv(path: str | os.PathLike, table: OrientationTable, *, single: bool = False) -> None:
    """Write the wide form (``t_s,<label>_w,...``), or with ``single=True`` and one column
    the single form ``t_s,w,x,y,z``. Exact float round trip."""
    labels = list(table.columns)
    if single and len(labels) != 1:
        raise RigConfigError(f"single-orientation CSV needs one column, table has {len(labels)}")
    header = ["t_s"]
    if single:
        header += list("wxyz")
    else:
        for lab in labels:
            if "," in lab or not lab:
                raise RigConfigError(f"column label {lab!r} cannot be written to CSV")
            header += [f"{lab}_{c}" for c in "wxyz"]
    cols = [table.columns[lab].tolist() for lab in labels]

    def lines():
        for r, t in enumerate(table.time.tolist()):
            cells = [repr(t)]
            for c in cols:
                cells.extend(repr(v) for v in c[r])
            yield ",".join(cells)

    _atomic_write(path, ",".join(header) + "\n", lines())


def write_samples_csv(path: str | os.PathLike, s: Mapping[str, np.ndarray]) -> None:
    """Write samples (as returned by ``store.samples.read``) in the long form
    ``t_s,device_t_s,name,kind,w,x,y,z,status``, followed by the nine raw columns
    ``acc_x..mag_z`` when any sample has a raw reading (``s["raw"]``, NaN written as an empty
    cell); lossless."""
    for nm in set(s["name"].tolist()) | set(s["kind"].tolist()):
        if "," in nm or "\n" in nm:
            raise RigConfigError(f"name {nm!r} cannot be written to CSV")
    raw = s.get("raw")
    n = len(s["t"])
    if raw is not None:
        raw = np.asarray(raw, dtype=np.float64)
        if raw.shape != (n, 9):
            raise RigConfigError(f"samples: raw must have shape ({n}, 9), got {raw.shape}")
        if np.isnan(raw).all():
            raw = None
    if raw is None:
        tails = [""] * n
    else:
        cells = np.where(np.isnan(raw), None, raw).tolist()
        tails = ["," + ",".join("" if v is None else repr(v) for v in r) for r in cells]

    def lines():
        q = s["q"].tolist()
        for t, d, nm, kd, qq, st, tail in zip(
            s["t"].tolist(), s["device_t"].tolist(), s["name"].tolist(), s["kind"].tolist(), q,
            s["status"].tolist(), tails, strict=True,
        ):
            dd = "" if math.isnan(d) else repr(d)
            yield f"{t!r},{dd},{nm},{kd},{qq[0]!r},{qq[1]!r},{qq[2]!r},{qq[3]!r},{st}{tail}"

    head = "t_s,device_t_s,name,kind,w,x,y,z,status"
    if raw is not None:
        head += "," + ",".join(RAW_CSV_COLUMNS)
    _atomic_write(path, head + "\n", lines())


def read_orientations(path: str | os.PathLike) -> OrientationTable:
    """Read a ``.sto`` or ``.csv`` file (chosen by suffix) into an :class:`OrientationTable`."""
    suffix = Path(path).suffix.lower()
    if suffix == ".sto":
        return read_sto(path)
    if suffix in (".csv", ".txt"):
        return read_csv(path)
    raise RigConfigError(f"{path}: unknown format {suffix!r} (expected .sto or .csv)")


# ---------------------------------------------------------------------------------------------
# sessions


def shared_instants(times: Sequence[np.ndarray]) -> tuple[np.ndarray, list[np.ndarray]]:
    """The instants every series has a sample at (sorted, (M,)) and, per series, the index of
    its first sample at each of them (exact matches: frames of one device share a timestamp;
    :func:`align_series` pairs series of different clocks by nearest time)."""
    common = np.asarray(times[0], dtype=np.float64)
    for t in times[1:]:
        common = np.intersect1d(common, t)
    common = np.unique(common)
    idx = []
    for t in times:
        uniq, first = np.unique(t, return_index=True)
        idx.append(first[np.searchsorted(uniq, common)])
    return common, idx


def align_series(series: Mapping[str, tuple[np.ndarray, np.ndarray]]
                 ) -> tuple[OrientationTable, int]:
    """Put several (t, q) series on common times.

    When every series has the same times the table is exact. Otherwise the series with the
    fewest samples is the reference; each other series contributes its sample nearest in time,
    if within half the reference's median period; reference rows without a match in every
    series are dropped. Samples are never interpolated.

    Returns
    -------
    table : OrientationTable
    dropped : int
        Reference rows left out.
    """
    if not series:
        raise RigConfigError("nothing to align: no series")
    names = list(series)
    ts = {n: np.asarray(series[n][0], dtype=np.float64) for n in names}
    qs = {n: np.asarray(series[n][1], dtype=np.float64) for n in names}
    first = ts[names[0]]
    if all(ts[n].shape == first.shape and np.array_equal(ts[n], first) for n in names):
        return OrientationTable(time=first.copy(), columns={n: qs[n].copy() for n in names}), 0
    ref = min(names, key=lambda n: ts[n].size)
    tr = ts[ref]
    tol = 0.5 * float(np.median(np.diff(tr))) if tr.size > 1 else 0.0
    keep = np.ones(tr.size, dtype=bool)
    picks = {}
    for n in names:
        if n == ref:
            continue
        tn = ts[n]
        if tn.size == 0:
            keep[:] = False
            picks[n] = np.zeros(tr.size, dtype=np.intp)
            continue
        j = np.clip(np.searchsorted(tn, tr), 1, max(tn.size - 1, 1))
        j0 = np.clip(j - 1, 0, tn.size - 1)
        j1 = np.clip(j, 0, tn.size - 1)
        best = np.where(np.abs(tn[j0] - tr) <= np.abs(tn[j1] - tr), j0, j1)
        keep &= np.abs(tn[best] - tr) <= tol
        picks[n] = best
    idx = np.flatnonzero(keep)
    cols = {n: (qs[n][idx] if n == ref else qs[n][picks[n][idx]]) for n in names}
    return OrientationTable(time=tr[idx], columns=cols), int(tr.size - idx.size)


def _series_times(t: np.ndarray, device_t: np.ndarray, anchors: dict) -> tuple[np.ndarray, str]:
    """Strictly increasing times for one sensor's samples (in recording order), and which
    clock they are: the host's when its times already increase; else the device's own clock
    (a stream board stamps every frame; the host stamps a whole batch with one time), moved
    onto the host clock by the median host − device offset (one offset per device clock, so
    sensors of one board stay on common times); else, with neither, the host times with each
    run of repeated times spread evenly up to the next one."""
    if t.size < 2 or (np.diff(t) > 0).all():
        return t, "host"
    if np.isfinite(device_t).all() and (np.diff(device_t) > 0).all():
        key = device_t.tobytes()
        if key not in anchors:
            anchors[key] = float(np.median(t - device_t))
        return device_t + anchors[key], "device clock on the host clock"
    out = t.astype(np.float64, copy=True)
    start = np.flatnonzero(np.r_[True, np.diff(t) > 0])
    ends = np.r_[start[1:], t.size]
    period = float(np.median(np.diff(t[start]))) if start.size > 1 else 1e-3
    for a, b in zip(start, ends, strict=True):
        if b - a > 1:
            nxt = t[b] if b < t.size else t[a] + period
            out[a:b] = t[a] + (nxt - t[a]) * np.arange(b - a) / (b - a)
    if not (np.diff(out) > 0).all():
        raise RigConfigError("sample times go back: cannot export them as a time series")
    return out, "host, repeated times spread evenly"


def session_table(store: Store, session_id: int) -> tuple[OrientationTable, int]:
    """A session's samples as a table: one column per sensor (``<name>_imu``) or joint
    (``<name>``), aligned by :func:`align_series`, each on strictly increasing times
    (:func:`_series_times`; the clock used is in ``meta["rig_time"]``). Returns (table,
    reference rows dropped)."""
    s = store.samples.read(session_id)
    if s["t"].size == 0:
        raise RigConfigError(f"session {session_id} has no samples to export")
    series, clocks, anchors = {}, set(), {}
    for nm in dict.fromkeys(s["name"].tolist()):
        sel = s["name"] == nm
        kind = s["kind"][sel][0]
        label = nm if (kind == "joint" or nm.endswith("_imu")) else f"{nm}_imu"
        t, dt, q = s["t"][sel], s["device_t"][sel], s["q"][sel]
        order = np.lexsort((dt, t)) if not np.isfinite(dt).all() else np.argsort(dt, kind="stable")
        t, clock = _series_times(t[order], dt[order], anchors)
        clocks.add(clock)
        series[label] = (t, q[order])
    table, dropped = align_series(series)
    sess = store.sessions.get(session_id)
    table.meta.update({
        "rig_session": str(session_id),
        "rig_patient": str(sess["pseudonym"]),
        "rig_version": __version__,
        "rig_time": "; ".join(sorted(clocks)),
    })
    if sess.get("joint"):
        table.meta["rig_joint"] = str(sess["joint"])
    if sess.get("side"):
        table.meta["rig_side"] = str(sess["side"])
    return table, dropped


EXPORT_FORMATS = ("sto", "csv")


def export_session(store: Store, session_id: int, fmt: str, out: str | os.PathLike) -> dict:
    """Write a session's samples to ``out``.

    ``sto``: the OpenSim orientation table of :func:`session_table` (orientations only).
    ``csv``: the long form, every sample exactly as stored (no alignment), with the raw
    readings' columns when the session has any. Returns a summary dict: ``rows``,
    ``columns`` (or ``names``), ``dropped_rows`` (sto alignment), ``path``.
    """
    if fmt not in EXPORT_FORMATS:
        raise RigConfigError(f"--format must be one of {', '.join(EXPORT_FORMATS)}, got {fmt!r}")
    if fmt == "sto":
        table, dropped = session_table(store, session_id)
        write_sto(out, table)
        return {"path": os.fspath(out), "rows": len(table), "columns": table.labels,
                "dropped_rows": dropped}
    s = store.samples.read(session_id)
    if s["t"].size == 0:
        raise RigConfigError(f"session {session_id} has no samples to export")
    write_samples_csv(out, s)
    return {"path": os.fspath(out), "rows": int(s["t"].size),
            "names": list(dict.fromkeys(s["name"].tolist())), "dropped_rows": 0}
