"""Training / validation / test splits (thesis § 3.1.1: weights, GA fitness, unseen test).

Each region (thesis Fig. 34) is split in the requested proportions separately (stratified), so
every split keeps the region balance of the whole. The rows of each split keep their order in
the source dataset, so the order rule (valid-first, random, reversed) holds within each split.
Per region the counts are ``round(f_i · n_region)`` for all but the last split, which takes the
rest; a dataset without region labels is split as one stratum.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from models.datasets._common import make_rng
from models.datasets._dataset import Dataset
from models.errors import DatasetError

__all__ = ["SPLIT_NAMES", "split_dataset"]

#: ``meta["split"]`` of the parts of a three-way split.
SPLIT_NAMES: tuple[str, ...] = ("train", "validation", "test")


def split_dataset(
    ds: Dataset,
    fractions: tuple[float, ...] = (0.7, 0.15, 0.15),
    rng: np.random.Generator | int = 0,
) -> tuple[Dataset, ...]:
    """Split ``ds`` into ``len(fractions)`` datasets, stratified by region.

    Parameters
    ----------
    ds : Dataset
    fractions : tuple of float
        Non-negative, summing to 1 (within 1e-6); e.g. ``(train, validation, test)``.
    rng : numpy Generator or int seed
        Chooses which rows of each region go to which split.

    Returns
    -------
    tuple of Dataset
        One per fraction; ``meta["split"]`` names it (``train``/``validation``/``test`` for a
        three-way split, else ``part-<i>``) and ``meta["split_fractions"]`` records the request.
    """
    if not isinstance(ds, Dataset):
        raise DatasetError(f"ds: expected a Dataset, got {type(ds).__name__}")
    try:
        fr = tuple(float(f) for f in fractions)
    except (TypeError, ValueError) as err:
        raise DatasetError(f"fractions: expected numbers, got {fractions!r}") from err
    if (
        len(fr) < 1
        or any(not math.isfinite(f) or f < 0 for f in fr)
        or not math.isclose(sum(fr), 1.0, abs_tol=1e-6)
    ):
        raise DatasetError(
            f"fractions: expected non-negative numbers summing to 1, got {fractions!r}"
        )
    rng, _ = make_rng(rng)
    labels = ds.regions if ds.regions is not None else np.zeros(len(ds), dtype=np.int8)
    chosen: list[list[np.ndarray]] = [[] for _ in fr]
    for r in np.unique(labels):
        rows = rng.permutation(np.flatnonzero(labels == r))
        counts = [round(f * len(rows)) for f in fr[:-1]]
        counts.append(len(rows) - sum(counts))
        if counts[-1] < 0:  # rounding overshoot: take it from the largest
            counts[int(np.argmax(counts[:-1]))] += counts[-1]
            counts[-1] = 0
        bounds = np.concatenate(([0], np.cumsum(counts)))
        for i in range(len(fr)):
            chosen[i].append(rows[bounds[i] : bounds[i + 1]])
    names = SPLIT_NAMES if len(fr) == 3 else tuple(f"part-{i}" for i in range(len(fr)))
    out: list[Dataset] = []
    for i, parts in enumerate(chosen):
        idx = np.sort(np.concatenate(parts)) if parts else np.zeros(0, dtype=np.int64)
        extra: dict[str, Any] = {"split": names[i], "split_fractions": list(fr)}
        out.append(ds.subset(idx, **extra))
    return tuple(out)
