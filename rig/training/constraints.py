"""``rig constraint check`` as a library: validate a constraint or limb file and describe it
(what is described is the file's training kind's, :func:`rig.training.kinds.training_kind`)."""

from __future__ import annotations

from models.limb import load_limits
from rig.training.kinds import training_kind

__all__ = ["summarise"]


def summarise(path: str, samples: int = 200_000, seed: int = 0) -> str:
    """Validate ``path`` and describe it: limits, and the fraction of orientations it allows
    (one joint's, :func:`rig.training.joint.describe_joint`; a limb's,
    :func:`rig.training.limb.describe_limb`)."""

    c = load_limits(path)  # read and parsed once, either kind
    return training_kind(c).describe(path, c, samples, seed)
