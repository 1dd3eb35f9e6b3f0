"""Which recording to read: a session in a store or an orientation file
(:class:`RecordingSource`, the part of ``rig boundary`` / ``rig rom`` / the report's requests
that names it), checked before any work and loaded as :class:`~rig.readback.data.JointData`."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from calibration.frames import direction_to_rig
from calibration.joints import JOINTS
from rig.errors import RigConfigError
from rig.readback.data import FUSION_CHOICES, JointData, parse_axis
from rig.readback.files import (
    FILE_SUFFIXES,
    check_columns,
    is_lab_file,
    joint_orientations_from_file,
)
from rig.readback.sessions import read_session, session_shape
from rig.store import open_store

__all__ = ["FUSION_CHOICES", "RecordingSource", "check_file", "check_joint",
           "load_joint_orientations"]


def check_joint(joint: str | None) -> None:
    """``--joint``: None or a joint of :data:`calibration.joints.JOINTS` (one-line error)."""
    if joint is not None:
        if joint not in JOINTS:
            raise RigConfigError(f"--joint {joint!r}: expected one of {', '.join(JOINTS)}")


def check_file(file: str, frames: str | None) -> None:
    """An orientation file as ``rig boundary`` / ``rig rom`` / ``rig report`` take it, before
    any work (one-line errors): it exists, its suffix is a format read
    (:data:`~rig.readback.files.FILE_SUFFIXES`), and ``--frames`` is not given with a C3D or
    BVH file, whose segment frames its reader builds (ISB, from the marker set or the
    skeleton's rest pose), so that the option could only mislead."""
    path = Path(file)
    suffix = path.suffix.lower()
    if suffix not in FILE_SUFFIXES:
        raise RigConfigError(f"{file}: unknown format {suffix or '(no suffix)'!r} (expected "
                             f"{', '.join(FILE_SUFFIXES[:-1])} or {FILE_SUFFIXES[-1]})")
    if not path.is_file():
        raise RigConfigError(f"{file}: no such file")
    if frames is not None and is_lab_file(file):
        made = "marker set" if suffix == ".c3d" else "skeleton's rest pose"
        raise RigConfigError(f"{file}: --frames does not apply to a {suffix[1:].upper()} file: "
                             f"its segment frames come from its {made} (ISB); leave "
                             "--frames out")


def check_session_side(db, session_id: int | None, side: str | None) -> None:
    """``--side`` must be the side the session recorded (one line, before reading its samples):
    a left side would mirror a right limb's clinical angles."""
    if side is None or db is None or session_id is None:
        return
    with open_store(db, create=False) as st:
        sess = st.sessions.get(session_id)
    recorded = sess.get("side")
    if recorded is not None and recorded != side:
        what = session_shape(sess).recorded(sess)
        raise RigConfigError(f"--side {side}: session {session_id} recorded the {recorded} "
                             f"{what}")


@dataclass(frozen=True)
class RecordingSource:
    """A session (``db`` + ``session_id``) or an orientation file (``file`` with its ``child``
    segment's column and optionally its ``parent``'s, ``--child COLUMN`` / ``--parent COLUMN``,
    in ``frames`` conventions: ``"rig"`` by default or ``"isb"``; ``child`` alone: the column
    holds joint orientations already).

    ``limb_axis`` is ``x,y,z`` text in the file's frame convention (default: the long axis,
    +X in rig frames, −Y in ISB frames; the foot's +X in either); ``fusion`` applies to IMU
    sessions (:data:`FUSION_CHOICES`). ``joint`` names the joint
    (:data:`calibration.joints.JOINTS`; None: the recording's own, else the shoulder): its
    segments say how a file's ISB frames turn into the rig's, its kind how the boundary is
    extracted and which clinical angles are read."""

    file: str | None = None
    db: str | None = None
    session_id: int | None = None
    parent: str | None = None
    child: str | None = None
    limb_axis: str | None = None
    frames: str | None = None
    fusion: str = "auto"
    joint: str | None = None

    def check(self, side: str | None = None) -> None:
        """Option combinations, the file's existence and, by their names, its columns against
        ``--joint`` and ``side``, before any work (one-line errors)."""
        file = self.file
        if file is not None and (self.db is not None or self.session_id is not None):
            raise RigConfigError("give either FILE or --db/--session, not both")
        if file is None and (self.db is None or self.session_id is None):
            raise RigConfigError("give a recording: FILE.sto|FILE.csv, or --db DB --session ID")
        if file is not None:
            if self.child is None:
                raise RigConfigError(f"{file}: --child COLUMN is required with a file")
            check_file(file, self.frames)
        elif self.parent is not None or self.child is not None:
            raise RigConfigError("--parent/--child apply to files; a session knows its "
                                 "segments")
        elif self.frames is not None:
            raise RigConfigError("--frames applies to files; a session is in the rig's frames")
        if self.fusion not in FUSION_CHOICES:
            raise RigConfigError(f"fusion must be one of {', '.join(FUSION_CHOICES)}, got "
                                 f"{self.fusion!r}")
        parse_axis(self.limb_axis)
        check_joint(self.joint)
        if file is not None:
            check_columns(file, self.parent, self.child, self.joint, side)
        else:
            check_session_side(self.db, self.session_id, side)

    @property
    def label(self) -> str:
        """The recording for people: the file's path or ``session N``."""
        return self.file if self.file is not None else f"session {self.session_id}"

    def load(self) -> JointData:
        """The one joint's orientations (J = 1), in rig frames (sessions:
        :func:`~rig.readback.sessions.read_session`, a whole limb's ``joint``, by default its
        proximal one; files: :func:`~rig.readback.files.joint_orientations_from_file`)."""
        self.check()
        if self.file is not None:
            frames = self.frames or "rig"
            spec = JOINTS[self.joint or "shoulder"]
            axis = parse_axis(self.limb_axis)
            if self.limb_axis is not None:
                axis = direction_to_rig(axis, frames, spec.child)
            return joint_orientations_from_file(self.file, self.parent, self.child, axis,
                                                frames, self.joint)
        axis = parse_axis(self.limb_axis)
        data = read_session(self.db, self.session_id, axis, self.fusion, self.joint)
        return data if len(data.joints) == 1 else data.select(data.joints[0], axis)


def load_joint_orientations(file: str | None = None, *, db: str | None = None,
                            session_id: int | None = None, parent: str | None = None,
                            child: str | None = None, limb_axis: str | None = None,
                            fusion: str = "auto", frames: str | None = None,
                            joint: str | None = None) -> JointData:
    """``RecordingSource(...).load()`` with the options as keywords."""
    return RecordingSource(file, db, session_id, parent, child, limb_axis, frames,
                           fusion, joint).load()
