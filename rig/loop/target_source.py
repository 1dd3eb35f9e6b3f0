"""The interface of a live loop's target source (:class:`TargetSource`): a leaf module, so
that the sources of :mod:`rig.loop.targets` and :mod:`rig.loop.leader` share it without
importing each other."""

from __future__ import annotations

import numpy as np

__all__ = ["TargetSource"]


class TargetSource:
    """Base class: a context manager answering :meth:`latest` once per cycle.

    Attributes
    ----------
    duration_s : float or None
        Natural length of the motion (None: endless).
    description : str
        One line for logs and run metadata.
    n_joints : int
        Joints of every posture :meth:`latest` returns.
    joint_names : tuple of str or None
        Their names, in the limb file's order (None: one joint, unnamed).
    """

    duration_s: float | None = None
    description = "targets"
    n_joints: int = 1
    joint_names: tuple[str, ...] | None = None

    def start(self, t0: float) -> None:
        """The loop starts: loop-clock time ``t0`` is the motion's time 0."""
        self.t0 = float(t0)

    def latest(self, t: float) -> tuple[float | None, np.ndarray | None]:
        """``(target_t, posture (n_joints, 4))`` at loop time ``t``; ``(None, None)`` when there
        is no target yet."""
        raise NotImplementedError

    def close(self) -> None:
        """Release resources (idempotent)."""

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
