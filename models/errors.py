"""Exceptions raised by :mod:`models`.

Hierarchy::

    ModelsError
     +-- QuaternionError (ValueError)      bad orientation: shape, NaN/inf, zero or non-unit norm
     +-- ConstraintError (ValueError)      invalid constraint file or definition; names the field
     +-- GeometryError (ValueError)        a spherical polygon is degenerate or self-intersecting
     +-- DatasetError (ValueError)         a dataset file or request is invalid
     +-- ModelFileError (ValueError)       model file missing, not ONNX, or not what was expected
     +-- OutputPathError (ValueError)      an output file or folder this process cannot write

Every message names what is wrong and, where it helps, what was expected, so that the CLI can
show it as one line.
"""

from __future__ import annotations


class ModelsError(Exception):
    """Base class of every error raised by :mod:`models`."""


class QuaternionError(ModelsError, ValueError):
    """An orientation array is malformed (shape, non-finite values, zero or non-unit norm)."""


class ConstraintError(ModelsError, ValueError):
    """A joint-constraint definition or file is invalid.

    Parameters
    ----------
    message : str
        What is wrong.
    field : str, optional
        Dotted path of the offending field (``swing.cone.radius_deg``).
    source : str, optional
        File the definition came from.
    """

    def __init__(self, message: str, field: str | None = None, source: str | None = None):
        self.field = field
        self.source = source
        where = ""
        if source:
            where += f"{source}: "
        if field:
            where += f"{field}: "
        super().__init__(where + message)


class GeometryError(ModelsError, ValueError):
    """A spherical polygon is degenerate, self-intersecting, or its interior point is not inside.

    Parameters
    ----------
    message : str
        What is wrong (names the vertices or edges involved).
    part : str
        ``"vertices"`` or ``"interior"``: which input is at fault.
    """

    def __init__(self, message: str, part: str = "vertices"):
        self.part = part
        super().__init__(message)


class DatasetError(ModelsError, ValueError):
    """A dataset request or dataset file is invalid."""


class ModelFileError(ModelsError, ValueError):
    """A model file is missing, unreadable, or does not match what the caller expects."""


class OutputPathError(ModelsError, ValueError):
    """An output path cannot be written: a folder, a missing or read-only folder, a file that
    may not be replaced (:func:`models.fileio.check_output`)."""
