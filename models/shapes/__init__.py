"""The thesis's five irregular swing boundaries, shipped as constraint files.

Thesis ch. 4.2.2 tests the learned corrective constraint on irregular boundaries recorded with
an interactive virtual arm: *original* (one concave region), *small*, *large*, *C-shape*
(pronounced concavity) and *highly irregular*. The recorded outlines are not published, so
these are synthetic stand-ins with the same character. Each is a spherical polygon (great-circle
edges, :class:`models.limits.PolygonSwing`) around the limb axis +X, written as a radius
``ρ(φ)`` (angle from +X) against azimuth ``φ`` about +X; a polygon that is star-shaped about +X
in this sense is simple, because consecutive vertices less than π apart in azimuth span a convex
lune. Extents (angle from +X):

================  ========  ================================================================
name              vertices  outline
================  ========  ================================================================
original          36        68° × 44° ellipse with a 24° notch (one concave region)
small             24        the original × 0.45 (about 31° × 20°)
large             48        the original × 1.55 (about 105° × 68°)
c-shape           40        62° radius, a 150°-wide notch reaching to 10° of the centre
highly-irregular  60        45° ± lobes of 3, 7 and 11 cycles plus seeded jitter (23°-66°)
================  ========  ================================================================

The files are ordinary constraint YAML (:mod:`models.constraint`) and load with
:func:`models.constraint.load_constraint`; ``interior`` is +X for all five.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

from models.constraint import JointConstraint, loads_constraint
from models.errors import DatasetError

__all__ = ["SHAPES", "load_shape", "shape_path"]

#: Names of the shipped shapes, in the thesis's order.
SHAPES: tuple[str, ...] = ("original", "small", "large", "c-shape", "highly-irregular")


def _check_name(name: str) -> str:
    if name not in SHAPES:
        raise DatasetError(f"shape: unknown shape {name!r}; valid names are {', '.join(SHAPES)}")
    return name


def shape_path(name: str) -> Path:
    """Path of the shipped constraint file of shape ``name``.

    Raises
    ------
    DatasetError
        ``name`` is not one of :data:`SHAPES` (the message lists them).
    """
    res = resources.files(__name__).joinpath(f"{_check_name(name)}.yaml")
    return Path(str(res))


def load_shape(name: str) -> JointConstraint:
    """The shape ``name`` as a :class:`~models.constraint.JointConstraint` (polygon swing).

    Raises
    ------
    DatasetError
        ``name`` is not one of :data:`SHAPES`.
    """
    res = resources.files(__name__).joinpath(f"{_check_name(name)}.yaml")
    return loads_constraint(res.read_text(encoding="utf-8"), source=f"shape {name!r}")
