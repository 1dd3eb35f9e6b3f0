"""The two-axis joint: a swing region with a fixed or narrow twist (a wrist, an ankle).

File block: a ball joint's (:mod:`models.kinds.ball`) with ``kind: two-axis``; both ``swing``
and ``twist`` are required and the twist interval is at most
:data:`TWO_AXIS_MAX_TWIST_DEG` wide (wider: it is a ball joint). Its oracle is the ball
joint's.
"""

from __future__ import annotations

from typing import Any

from models.errors import ConstraintError
from models.kinds.ball import BallKind

__all__ = ["TWO_AXIS_MAX_TWIST_DEG", "TwoAxisKind"]

#: Widest twist interval of a ``two-axis`` joint, degrees (wider: it is a ball joint).
TWO_AXIS_MAX_TWIST_DEG = 30.0


class TwoAxisKind(BallKind):
    """A two-axis joint: a ball joint's limits with a required, narrow twist."""

    name = "two-axis"
    words = "two-axis joint"
    narrow_twist = True
    servo_axes = 2

    def parse(self, data: dict, source: str | None) -> dict[str, Any]:
        out = super().parse(data, source)
        swing, twist = out["swing"], out["twist"]
        if swing is None or twist is None:
            raise ConstraintError("a two-axis joint needs a 'swing' region and a (fixed or "
                                  "narrow) 'twist' interval", source=source)
        width = twist.max_deg - twist.min_deg
        if width > TWO_AXIS_MAX_TWIST_DEG:
            raise ConstraintError(
                f"a two-axis joint's twist interval is at most "
                f"{TWO_AXIS_MAX_TWIST_DEG:g} degrees wide, got {width:g} (a wider twist "
                f"is a ball joint: kind: ball)", "twist", source)
        return out

    def summary_lines(self, constraint: Any) -> list[str]:
        return [f"  kind        {self.name}", *super().summary_lines(constraint)]
