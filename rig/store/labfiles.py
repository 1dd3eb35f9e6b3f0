"""Files from motion labs read as orientation tables: C3D (markers, and the joint angles of the
lab's model) and BVH (joint rotations), each into an :class:`~rig.store.io.OrientationTable`
of segment columns in ISB frames, named as OpenSim's bodies (``pelvis``, ``femur_r``, …), so
``rig boundary`` / ``rig rom`` / ``rig report`` read them as they read a ``.sto``.

- **C3D** (:func:`read_c3d`, with ``ezc3d``, pyomeca's maintained reader and writer: wheels for
  CPython 3.10-3.12 on Linux): segment frames from the markers of a known marker set
  (:mod:`calibration.markers`), and a joint column per joint-angle output of Plug-in Gait the
  file carries (``LKneeAngles`` …). Subject prefixes (``Subject:LASI``) are cut. A frame where a
  segment's marker is missing (a gap) is dropped; a segment missing in more than half the
  frames is not built (named in the table's ``missing``).
- **BVH** (:func:`read_bvh`, with ``bvhio``, a maintained pure-Python reader: its joints,
  offsets, End Sites and per-frame rotations in each joint's own CHANNELS order): segment
  orientations per :mod:`calibration.bvh_skeleton`; time = frame × the file's Frame Time.

Both tables say ``meta["frames"] = "isb"`` and carry per column the segment(s) it is
(:attr:`LabTable.segments`), so that a reader may turn them into rig frames
(:func:`to_frames`).
"""

from __future__ import annotations

import os
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from calibration.bvh_skeleton import SEGMENT_KINDS as BVH_KINDS
from calibration.bvh_skeleton import segment_orientations
from calibration.frames import joint_to_rig, segment_to_rig
from calibration.markers import MODEL_OUTPUTS, model_joint_angles, segment_frames
from calibration.markers import SEGMENT_KINDS as C3D_KINDS
from rig.errors import RigConfigError
from rig.store.io import OrientationTable

__all__ = ["LAB_SUFFIXES", "LabTable", "read_bvh", "read_c3d", "read_lab_file", "to_frames"]

#: Suffixes of the files this module reads.
LAB_SUFFIXES = (".c3d", ".bvh")

_JOINT_SEGMENTS = {"hip": ("pelvis", "thigh"), "knee": ("thigh", "shank"),
                   "ankle": ("shank", "foot"), "elbow": ("upper-arm", "forearm")}


@dataclass
class LabTable(OrientationTable):
    """An :class:`~rig.store.io.OrientationTable` from a lab file, with per column its segment
    (``("thigh",)``) or, for a joint column, its parent and child segments, and per segment
    the file could not give the markers or joints it lacks."""

    segments: dict[str, tuple[str, ...]] = field(default_factory=dict)
    missing: dict[str, str] = field(default_factory=dict)

    def get(self, name: str) -> np.ndarray:
        if name in self.columns or name not in self.missing:
            return super().get(name)
        raise RigConfigError(
            f"{self.meta.get('source', 'the file')}: no {name!r}: it needs {self.missing[name]}"
            f", which the file lacks; it has columns {', '.join(self.columns) or '(none)'} and "
            f"{self.meta.get('has', '')}")


def _fail(path, why: str) -> RigConfigError:
    return RigConfigError(f"{path}: {why}")


def read_c3d(path: str | os.PathLike) -> LabTable:
    """A C3D file's segment orientations (from markers) and model joint angles (module doc)."""
    import ezc3d  # heavy binary extension: loaded when a C3D file is read

    try:
        c = ezc3d.c3d(str(path))
    except Exception as e:  # ezc3d raises plain RuntimeError/OSError for a damaged file
        raise _fail(path, f"not a readable C3D file ({e})") from None
    par = c["parameters"]
    labels = [str(x).split(":")[-1] for x in par["POINT"]["LABELS"]["value"]]
    pts = np.asarray(c["data"]["points"][:3], dtype=np.float64)  # (3, M, N)
    rate = float(np.ravel(par["POINT"]["RATE"]["value"])[0])
    units = np.ravel(par["POINT"].get("UNITS", {}).get("value", []))
    unit = str(units[0]).strip() if units.size else "mm"
    scale = 1000.0 if unit == "m" else 10.0 if unit == "cm" else 1.0
    proc = par.get("PROCESSING", {})
    params = {k: float(np.ravel(v["value"])[0]) for k, v in proc.items()
              if isinstance(v, dict) and np.size(v.get("value", [])) == 1
              and np.issubdtype(np.asarray(v["value"]).dtype, np.number)}
    markers = {lab: pts[:, i, :].T for i, lab in enumerate(labels)
               if lab not in MODEL_OUTPUTS}
    name, segs, missing = segment_frames(markers, params, scale_to_mm=scale)
    cols, kinds = {}, {}
    n = pts.shape[2]
    for seg, q in segs.items():
        bad = ~np.all(np.isfinite(q), axis=1)
        if bad.mean() > 0.5:
            missing[seg] = "markers visible in most frames"
            continue
        cols[seg], kinds[seg] = q, (C3D_KINDS[seg],)
    for i, lab in enumerate(labels):
        if lab in MODEL_OUTPUTS:
            q = model_joint_angles(pts[:, i, :].T, lab)
            cols[lab], kinds[lab] = q, _JOINT_SEGMENTS[MODEL_OUTPUTS[lab][0]]
    if not cols:
        raise _fail(path, f"no segment could be built and no joint angles of a known model: "
                          f"markers {', '.join(sorted(markers)[:30])}")
    keep = np.all([np.all(np.isfinite(q), axis=1) for q in cols.values()], axis=0)
    if not keep.any():
        raise _fail(path, "no frame has every segment's markers")
    has = f"marker set {name}" if name else "no known marker set"
    return LabTable(np.arange(n)[keep] / rate, {k: v[keep] for k, v in cols.items()}, rate,
                    {"source": str(path), "frames": "isb", "has": has,
                     "dropped_frames": str(int((~keep).sum()))},
                    segments=kinds, missing=missing)


def _tip(joint) -> np.ndarray:
    """Where ``joint``'s bone ends relative to it in the rest pose (bvhio joint): a hand with
    fingers at the mean of its fingers' bases (the thumb left out); else at its first child
    (or that child's first child, where the child sits on the joint), else at its End Site."""
    mid = [c for c in joint.Children if "thumb" not in c.Name.lower()]
    if len(mid) > 1:
        return np.mean([np.array(c.Offset, dtype=np.float64) for c in mid], axis=0)
    j, acc = joint, np.zeros(3)
    while j.Children:
        j = j.Children[0]
        acc = acc + np.array(j.Offset, dtype=np.float64)
        if np.linalg.norm(acc) > 1e-6:
            return acc
    return acc + np.array(j.EndSite, dtype=np.float64)


def read_bvh(path: str | os.PathLike) -> LabTable:
    """A BVH file's segment orientations (module doc)."""
    with warnings.catch_warnings():  # pyglm's notice about its own import name, not ours
        warnings.simplefilter("ignore", PendingDeprecationWarning)
        import bvhio  # pure-Python dependency, loaded when a BVH file is read

    try:
        bvh = bvhio.readAsBvh(str(path))
    except Exception as e:  # bvhio raises SyntaxError/ValueError with its own text
        raise _fail(path, f"not a readable BVH file ({e})") from None
    joints, parents = [], []

    def walk(j, p: int) -> None:
        joints.append(j)
        parents.append(p)
        me = len(joints) - 1
        for ch in j.Children:
            walk(ch, me)

    walk(bvh.Root, -1)
    n = int(bvh.FrameCount)
    local = np.array([[(k.Rotation.w, k.Rotation.x, k.Rotation.y, k.Rotation.z)
                       for k in j.Keyframes] for j in joints], dtype=np.float64)
    if local.shape[1] != n or n < 1:
        raise _fail(path, f"{n} frames declared, {local.shape[1]} read")
    offsets = np.array([np.array(j.Offset, dtype=np.float64) for j in joints])
    tips = np.array([_tip(j) for j in joints])
    names = [j.Name for j in joints]
    sk, cols, missing = segment_orientations(names, parents, offsets, tips, local)
    if not cols:
        raise _fail(path, f"no joint of a known skeleton (daz, mb, arena): joints "
                          f"{', '.join(names[:30])}")
    dt = float(bvh.FrameTime)
    return LabTable(np.arange(n) * dt, cols, 1.0 / dt if dt > 0 else None,
                    {"source": str(path), "frames": "isb", "has": f"skeleton {sk}"},
                    segments={c: (BVH_KINDS[c],) for c in cols}, missing=missing)


def read_lab_file(path: str | os.PathLike) -> LabTable:
    """:func:`read_c3d` or :func:`read_bvh` by suffix."""
    suffix = Path(path).suffix.lower()
    if suffix == ".c3d":
        return read_c3d(path)
    if suffix == ".bvh":
        return read_bvh(path)
    raise _fail(path, f"not a lab file (expected {' or '.join(LAB_SUFFIXES)})")


def to_frames(table: LabTable, frames: str) -> LabTable:
    """``table`` (ISB frames) in ``frames`` conventions: each segment column by
    :func:`~calibration.frames.segment_to_rig`, each joint column by
    :func:`~calibration.frames.joint_to_rig` (``"isb"``: unchanged)."""
    if frames == "isb":
        return table
    cols = {}
    for k, q in table.columns.items():
        seg = table.segments[k]
        cols[k] = segment_to_rig(q, "isb", seg[0]) if len(seg) == 1 else \
            joint_to_rig(q, "isb", seg[0], seg[1])
    return LabTable(table.time, cols, table.rate_hz, {**table.meta, "frames": frames},
                    segments=table.segments, missing=table.missing)
