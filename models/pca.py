r"""Principal component analysis of quaternion datasets in R⁴ (thesis § 4.2.1, TABLES III-V).

Maths
-----
For quaternions ``q_i ∈ R⁴`` (scalar-first, i = 1..N) with mean ``μ`` the covariance is
``Σ = (1/(N−1)) Σ_i (q_i − μ)(q_i − μ)ᵀ`` (thesis eq. 36-44 describe PCA by the eigen-
decomposition ``Σ a_k = λ_k a_k``). Results are ordered ``λ_1 >= ... >= λ_4``; each unit axis
``a_k`` is defined up to sign and reported with the sign of :func:`models.quaternion.canonical`
(``w >= 0``, or the first non-zero component positive).

Figures used by the thesis:

- *contribution* of component k: ``100 λ_k / Σ λ`` percent (Fig. 28);
- *variance of the eigenvector contributions* (TABLES III-IV): the population variance of the
  four contributions — 0 for a hyper-spherical data set, 1875 when one component holds all
  the variance; larger means more elongated;
- *angle to the identity* of each axis (Fig. 18, 27): ``acos(|a_k · (1, 0, 0, 0)|)`` in degrees,
  treating ``±a_k`` as the same axis (the rotation angle of ``a_k`` read as a quaternion is
  twice this);
- *4-D difference* between two data sets' principal axes (TABLE V "4D Pythagorean distance",
  Fig. 26): "subtracting each vector in the principal component matrix (4 × 4) to give the
  difference for each as a four-dimensional vector; the average length of these vectors is
  the distance" — :func:`pca_difference` ``= (1/K) Σ_k |a_k − s_k b_k|``. The thesis does not
  say how it handled the sign of an eigenvector; here ``s_k = ±1`` aligns ``b_k`` with ``a_k``
  (``a_k · s_k b_k >= 0``), so the value does not depend on the solver's arbitrary signs; each
  term is then in ``[0, √2]``.

TABLE IV/V compare a data set with itself after forcing every quaternion to ``w >= 0``:
:func:`ambiguity_removal_effect`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from models import quaternion as Q
from models.errors import DatasetError

__all__ = [
    "AmbiguityEffect",
    "PCAResult",
    "ambiguity_removal_effect",
    "pca_difference",
    "quaternion_pca",
]


@dataclass(frozen=True)
class PCAResult:
    """PCA of N quaternions in R⁴.

    Attributes
    ----------
    n : int
        Number of quaternions.
    mean : (4,) float64
        Mean quaternion (not normalised), scalar-first.
    eigenvalues : (4,) float64
        Variances along the axes, descending.
    axes : (4, 4) float64
        Row ``k`` is the unit axis of component ``k`` (scalar-first, canonical sign).
    explained : (4,) float64
        Fraction of the total variance per component (sums to 1).
    angle_to_identity_deg : (4,) float64
        ``acos(|axes[k, 0]|)`` in degrees, in [0, 90].
    """

    n: int
    mean: np.ndarray
    eigenvalues: np.ndarray
    axes: np.ndarray
    explained: np.ndarray
    angle_to_identity_deg: np.ndarray

    @property
    def contributions(self) -> np.ndarray:
        """(4,) percent of the variance per component (thesis Fig. 28)."""
        return 100.0 * self.explained

    @property
    def contribution_variance(self) -> float:
        """Population variance of :attr:`contributions` (thesis TABLES III-IV)."""
        return float(np.var(self.contributions))

    def summary(self) -> str:
        """Human-readable lines: one per component."""
        lines = [
            f"PCA of {self.n} quaternions (variance of contributions "
            f"{self.contribution_variance:.2f})"
        ]
        for k in range(4):
            ax = ", ".join(f"{c:+.3f}" for c in self.axes[k])
            lines.append(
                f"  PC{k + 1}  eigenvalue {self.eigenvalues[k]:.4g}  "
                f"{self.contributions[k]:5.1f} %  axis [{ax}]  "
                f"{self.angle_to_identity_deg[k]:5.1f} deg from identity"
            )
        return "\n".join(lines)


def quaternion_pca(q) -> PCAResult:
    """PCA of quaternions in R⁴ (no unit-norm requirement).

    Parameters
    ----------
    q : (N, 4) array_like, N >= 2
        Scalar-first quaternions, e.g. a dataset's inputs (either sign: the sign changes the
        result, which is the point of TABLES IV-V).

    Returns
    -------
    PCAResult

    Raises
    ------
    DatasetError
        Wrong shape, fewer than two rows, or non-finite values.
    """
    try:
        x = np.asarray(q, dtype=np.float64)
    except (TypeError, ValueError) as err:
        raise DatasetError(f"q: not a numeric array ({err})") from err
    if x.ndim != 2 or x.shape[1] != 4:
        raise DatasetError(f"q: expected shape (N, 4) scalar-first quaternions, got {x.shape}")
    if len(x) < 2:
        raise DatasetError(f"q: PCA needs at least 2 quaternions, got {len(x)}")
    if not np.isfinite(x).all():
        raise DatasetError("q: has a NaN or infinite value")
    mean = x.mean(axis=0)
    cov = np.cov(x, rowvar=False)
    vals, vecs = np.linalg.eigh(cov)  # ascending
    order = np.argsort(vals)[::-1]
    vals = np.clip(vals[order], 0.0, None)
    axes = Q.canonical(vecs[:, order].T)
    total = float(vals.sum())
    explained = vals / total if total > 0 else np.full(4, 0.25)
    angle = np.degrees(np.arccos(np.clip(np.abs(axes[:, 0]), 0.0, 1.0)))
    return PCAResult(
        n=len(x),
        mean=mean,
        eigenvalues=vals,
        axes=axes,
        explained=explained,
        angle_to_identity_deg=angle,
    )


def pca_difference(a, b, *, components: int = 4, align_signs: bool = True) -> float:
    """The thesis's "4-D difference" between two PCAs' axes (TABLE V, Fig. 26).

    Parameters
    ----------
    a, b : PCAResult or (4, 4) array_like
        Principal axes as rows (descending variance).
    components : int
        Use the first ``components`` axes (1-4).
    align_signs : bool
        Flip ``b``'s axis where ``a_k · b_k < 0`` before subtracting (see the module docstring).

    Returns
    -------
    float
        Mean Euclidean length of ``a_k − b_k``, k < ``components``.
    """
    A = a.axes if isinstance(a, PCAResult) else np.asarray(a, dtype=np.float64)
    B = b.axes if isinstance(b, PCAResult) else np.asarray(b, dtype=np.float64)
    if A.shape != (4, 4) or B.shape != (4, 4):
        raise DatasetError(f"axes: expected (4, 4) arrays, got {A.shape} and {B.shape}")
    if isinstance(components, bool) or components not in (1, 2, 3, 4):
        raise DatasetError(f"components: must be 1, 2, 3 or 4, got {components!r}")
    A, B = A[:components], B[:components]
    if align_signs:
        B = np.where((np.sum(A * B, axis=1) < 0.0)[:, None], -B, B)
    return float(np.mean(np.linalg.norm(A - B, axis=1)))


@dataclass(frozen=True)
class AmbiguityEffect:
    """What forcing every quaternion to ``w >= 0`` does to a data set (TABLES IV-V).

    Attributes
    ----------
    moved_fraction : float
        Fraction of quaternions whose sign was flipped.
    difference : float
        :func:`pca_difference` between the PCA before and after.
    contribution_variance_change : float
        Variance of contributions after minus before (TABLE IV, first row).
    before, after : PCAResult
    """

    moved_fraction: float
    difference: float
    contribution_variance_change: float
    before: PCAResult
    after: PCAResult


def ambiguity_removal_effect(q) -> AmbiguityEffect:
    """PCA of ``q`` and of ``canonical(q)`` (all ``w >= 0``), compared (thesis § 4.2.1).

    Parameters
    ----------
    q : (N, 4) array_like
        Quaternions as generated (e.g. ``hemisphere="centre"`` or ``"ambiguous"``).
    """
    x = np.asarray(q, dtype=np.float64)
    before = quaternion_pca(x)
    forced = Q.canonical(x)
    after = quaternion_pca(forced)
    moved = float(np.mean(np.any(forced != x, axis=1)))
    return AmbiguityEffect(
        moved_fraction=moved,
        difference=pca_difference(before, after),
        contribution_variance_change=after.contribution_variance - before.contribution_variance,
        before=before,
        after=after,
    )
