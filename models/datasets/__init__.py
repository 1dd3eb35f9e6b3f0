"""Vector-field datasets of the thesis (ch. 3-4): generation, splitting, storage.

Chapter 3 (:mod:`models.datasets._chapter3`): 1-D interval (eq. 45-47), 2-D/3-D ball
(eq. 48-49), circle on the unit sphere with a vector or quaternion correction (eq. 50-56).
Chapter 4 (:mod:`models.datasets._chapter4`): orientation quaternion → corrective quaternion
for regular (cone, eq. 59-68) and irregular (polygon) boundaries, with the thesis's pattern
distributions (Fig. 34), orders (TABLE X) and hemisphere rules (TABLE IV). Limbs
(:mod:`models.datasets._limb`): postures of a limb file with the exact limb oracle's corrections.
:class:`Dataset` (:mod:`models.datasets._dataset`) holds the arrays, the region labels and the
provenance, and defines the ``.npz`` file format (no pickle).

Example::

    from models.datasets import cone_constraint, quaternion_dataset, split_dataset
    ds = quaternion_dataset(cone_constraint((1, 0, 0), 45), 2000, rng=1)
    train, val, test = split_dataset(ds, (0.7, 0.15, 0.15), rng=2)
    train.save("train.npz")
"""

from models.datasets._chapter3 import (
    ball_dataset,
    cone_constraint,
    interval_dataset,
    sphere_quaternion_dataset,
    sphere_vector_dataset,
)
from models.datasets._chapter4 import (
    CLUSTERED_BAND_DEG,
    DISTRIBUTIONS,
    EVEN_BAND_DEG,
    HEMISPHERES,
    ORDERS,
    common_test_set,
    quaternion_dataset,
)
from models.datasets._dataset import (
    FORMAT_NAME,
    FORMAT_VERSION,
    REGION_NAMES,
    Dataset,
    load_dataset,
)
from models.datasets._limb import (
    coupled_directions,
    coupled_targets,
    field_joints,
    field_samples,
    limb_dataset,
    limb_postures,
    training_postures,
)
from models.datasets._split import SPLIT_NAMES, split_dataset

__all__ = [
    "CLUSTERED_BAND_DEG",
    "DISTRIBUTIONS",
    "EVEN_BAND_DEG",
    "FORMAT_NAME",
    "FORMAT_VERSION",
    "HEMISPHERES",
    "ORDERS",
    "REGION_NAMES",
    "SPLIT_NAMES",
    "Dataset",
    "ball_dataset",
    "common_test_set",
    "cone_constraint",
    "coupled_directions",
    "coupled_targets",
    "field_joints",
    "field_samples",
    "interval_dataset",
    "limb_dataset",
    "limb_postures",
    "load_dataset",
    "quaternion_dataset",
    "sphere_quaternion_dataset",
    "sphere_vector_dataset",
    "split_dataset",
    "training_postures",
]
