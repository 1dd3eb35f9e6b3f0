"""The registry of joint kinds in ``calibration/``: per kind, the extraction of its limits from
recorded orientations, the clinical angles it measures and how a constraint of the kind is read
as a range of motion — registered under the name of its :mod:`models.kinds` kind.

Adding a kind: write its module (a :class:`~calibration.kinds.base.CalibrationKind`
subclass) and add one line to :data:`_REGISTRY` below.

=============  ======================================  ====================================
name           module                                  extraction
=============  ======================================  ====================================
``ball``       :mod:`calibration.kinds.ball`           swing polygon + twist (+ by-swing)
``hinge``      :mod:`calibration.kinds.hinge`          the angle interval about its axis
``two-axis``   :mod:`calibration.kinds.two_axis`       as a ball joint, narrow twist
``forearm``    :mod:`calibration.kinds.forearm`        flexion and pronation intervals
=============  ======================================  ====================================
"""

from __future__ import annotations

from calibration.kinds.ball import BallCalibration
from calibration.kinds.base import CalibrationKind
from calibration.kinds.forearm import ForearmCalibration
from calibration.kinds.hinge import HingeCalibration
from calibration.kinds.two_axis import TwoAxisCalibration
from models.errors import ConstraintError

__all__ = ["CalibrationKind", "calibration_kind", "registered"]

#: The registered kinds by name, in registration order.
_REGISTRY: dict[str, CalibrationKind] = {k.name: k for k in (
    BallCalibration(),
    HingeCalibration(),
    TwoAxisCalibration(),
    ForearmCalibration(),
)}

def calibration_kind(name: str) -> CalibrationKind:
    """The calibration side of the kind called ``name`` (:class:`ConstraintError` naming the
    known kinds otherwise)."""
    try:
        return _REGISTRY[name]
    except (KeyError, TypeError):
        raise ConstraintError(f"must be one of {', '.join(_REGISTRY)}, got {name!r}",
                              "kind") from None


def registered() -> tuple[CalibrationKind, ...]:
    """Every registered calibration kind, in registration order."""
    return tuple(_REGISTRY.values())
