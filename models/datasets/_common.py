"""Argument checks and helpers shared by the generators (not public)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from models.errors import DatasetError


def check_n(n: Any, name: str = "n") -> int:
    """A positive pattern count, or :class:`DatasetError` naming ``name``."""
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)):
        raise DatasetError(f"{name}: expected a positive integer, got {n!r}")
    if n <= 0:
        raise DatasetError(f"{name}: must be > 0, got {n}")
    return int(n)


def check_choice(value: Any, name: str, choices: tuple[str, ...]) -> str:
    if value not in choices:
        raise DatasetError(f"{name}: unknown value {value!r}; choose one of {', '.join(choices)}")
    return str(value)


def check_number(value: Any, name: str, lo: float, hi: float, *, closed: bool = False) -> float:
    """A finite number in ``(lo, hi)`` (``[lo, hi]`` with ``closed``)."""
    try:
        x = float(value)
    except (TypeError, ValueError) as err:
        raise DatasetError(f"{name}: expected a number, got {value!r}") from err
    ok = (lo <= x <= hi) if closed else (lo < x < hi)
    if not (math.isfinite(x) and ok):
        br = "[]" if closed else "()"
        raise DatasetError(f"{name}: must be in {br[0]}{lo:g}, {hi:g}{br[1]}, got {value!r}")
    return x


def make_rng(rng: Any) -> tuple[np.random.Generator, dict[str, Any]]:
    """A Generator from a Generator or an integer seed, plus metadata to reproduce it.

    The metadata holds ``seed`` (the integer, or ``None``) and ``rng_state`` (the bit generator
    state before any draw), so a dataset made from a Generator can be regenerated too.
    """
    if isinstance(rng, np.random.Generator):
        return rng, {"seed": None, "rng_state": rng.bit_generator.state}
    if isinstance(rng, (int, np.integer)) and not isinstance(rng, bool) and rng >= 0:
        g = np.random.default_rng(int(rng))
        return g, {"seed": int(rng), "rng_state": g.bit_generator.state}
    raise DatasetError(f"rng: expected a numpy Generator or a seed >= 0, got {rng!r}")


def equal_counts(n: int, k: int) -> list[int]:
    """``n`` split into ``k`` counts differing by at most one (the first ones larger)."""
    return [n // k + (1 if i < n % k else 0) for i in range(k)]


def label_regions(valid: np.ndarray, distance: np.ndarray, band: float) -> np.ndarray:
    """Region labels 0-3 from validity and signed distance (thesis Fig. 34).

    ``0`` valid with distance ``<= -band``; ``1`` valid otherwise; ``2`` invalid with
    ``distance <= band``; ``3`` invalid otherwise.
    """
    return np.where(
        valid,
        np.where(distance <= -band, 0, 1),
        np.where(distance <= band, 2, 3),
    ).astype(np.int8)


def order_index(valid: np.ndarray, order: str, rng: np.random.Generator) -> np.ndarray:
    """Row permutation for a pattern order (thesis TABLE X).

    ``valid-first``: valid patterns (shuffled) then invalid ones (shuffled); ``reversed``: the
    invalid ones first; ``random``: one shuffle of all.
    """
    if order == "random":
        return rng.permutation(len(valid))
    v = rng.permutation(np.flatnonzero(valid))
    iv = rng.permutation(np.flatnonzero(~valid))
    return np.concatenate((v, iv) if order == "valid-first" else (iv, v))
