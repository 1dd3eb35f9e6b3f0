"""The registry of joint kinds: what is special about each kind of joint lives in its module.

A kind is registered here by its name (the ``kind:`` of a constraint file) and looked up by
name; everything in ``models/`` that differs between kinds — parsing, validating, writing and
summarising the kind's limits block, its exact oracle (batched and single-orientation paths),
whether it can drive a coupling — is a method of the kind (:class:`models.kinds.base.JointKind`).
``calibration.kinds`` registers the calibration side of the same kinds (boundary extraction,
clinical angles, norms) under the same names.

Adding a kind: write its module (a :class:`~models.kinds.base.JointKind` subclass) and add one
line to :data:`_REGISTRY` below.

=============  ==================================  ==================================
name           module                              limits
=============  ==================================  ==================================
``ball``       :mod:`models.kinds.ball`            swing region + twist interval
``hinge``      :mod:`models.kinds.hinge`           one axis + an angle interval
``two-axis``   :mod:`models.kinds.two_axis`        swing region + narrow twist
``forearm``    :mod:`models.kinds.forearm`         flexion + axial rotation intervals
=============  ==================================  ==================================
"""

from __future__ import annotations

from models.errors import ConstraintError
from models.kinds.ball import BallKind
from models.kinds.base import JointKind
from models.kinds.forearm import ForearmKind
from models.kinds.hinge import HingeKind
from models.kinds.two_axis import TwoAxisKind

__all__ = ["DEFAULT_KIND", "KINDS", "JointKind", "file_keys", "get_kind", "registered",
           "swing_twist_kinds"]

#: The registered kinds by name, in registration order (a file without ``kind:`` is a ball).
_REGISTRY: dict[str, JointKind] = {k.name: k for k in (
    BallKind(),
    HingeKind(),
    TwoAxisKind(),
    ForearmKind(),
)}

#: The kind of a constraint file that names none (a ball joint: files written before kinds
#: existed stay readable and are written back without ``kind:``).
DEFAULT_KIND = BallKind.name

#: The registered kinds' names (``kind:`` values), in registration order.
KINDS: tuple[str, ...] = tuple(_REGISTRY)


def get_kind(name: str, field: str | None = "kind", source: str | None = None) -> JointKind:
    """The registered kind called ``name``.

    Raises
    ------
    ConstraintError
        One line naming the known kinds when ``name`` is not one of them (``field`` and
        ``source`` name where it was read).
    """
    try:
        return _REGISTRY[name]
    except (KeyError, TypeError):
        raise ConstraintError(f"must be one of {', '.join(KINDS)}, got {name!r}", field,
                              source) from None


def registered() -> tuple[JointKind, ...]:
    """Every registered kind, in registration order."""
    return tuple(_REGISTRY.values())


def file_keys() -> tuple[str, ...]:
    """The top-level keys of a constraint file that hold some kind's limits (each once, in
    registration order)."""
    return tuple(dict.fromkeys(key for k in _REGISTRY.values() for key in k.file_keys))


def swing_twist_kinds() -> tuple[str, ...]:
    """The names of the kinds whose limits are a swing region and a twist (ball, two-axis)."""
    return tuple(k.name for k in _REGISTRY.values() if k.swing_twist)
