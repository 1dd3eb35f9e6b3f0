"""Errors of :mod:`calibration`.

Hierarchy::

    CalibrationError (ValueError)     calibration data that cannot give an answer: too few
                                      samples, no movement where one is needed, a pose sequence
                                      that does not determine the unknowns, an empty recording

Bad array shapes and non-unit quaternions raise :class:`models.errors.QuaternionError` (from
:func:`models.quaternion.check_quaternions`), unchanged. Messages name what is wrong and what
was expected, so that the CLI can show them as one line.
"""

from __future__ import annotations

__all__ = ["CalibrationError"]


class CalibrationError(ValueError):
    """Calibration or extraction input that cannot determine the result (see module doc)."""
