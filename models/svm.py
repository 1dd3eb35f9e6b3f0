"""Binary joint constraints learned by support vector machines (thesis ch. 6).

The thesis trained SVMLight on valid/invalid orientations with linear, polynomial, RBF and
sigmoid kernels (poly and RBF best; quaternion inputs better than 3-D limb directions; no gain
beyond ~2000 patterns). Here scikit-learn's :class:`sklearn.svm.SVC` fits, and the decision
function is re-implemented in numpy from the fitted support vectors so that a model persists
without pickle (``.npz`` arrays + ``.json`` metadata) and runs without scikit-learn::

    f(x) = Σ_i α_i y_i K(s_i, x) + b        valid ⇔ f(x) > 0

    linear   K = sᵀx
    poly     K = (γ sᵀx + c₀)^d
    rbf      K = exp(-γ |s - x|²)
    sigmoid  K = tanh(γ sᵀx + c₀)

Features: ``"quaternion"`` — the orientation canonicalised to ``w ≥ 0`` (q and -q are the same
rotation); ``"direction"`` — the limb direction ``R(q) X`` (3-D, ignores twist).
"""

from __future__ import annotations

import io
import json
from pathlib import Path

import numpy as np

from models import quaternion as quat
from models.errors import ModelFileError
from models.fileio import write_owner_only

KERNELS = ("linear", "poly", "rbf", "sigmoid")
FEATURES = ("quaternion", "direction")
FORMAT = "jointlimits-svm/1"


def features(q: np.ndarray, kind: str = "quaternion") -> np.ndarray:
    """SVM features of orientations (N, 4): canonical quaternion (N, 4) or limb direction (N, 3)."""
    q = np.asarray(q, dtype=np.float64).reshape(-1, 4)
    if kind == "quaternion":
        return quat.canonical(q)
    if kind == "direction":
        return quat.limb_direction(q)
    raise ValueError(f"features must be one of {FEATURES}, got {kind!r}")


class BinaryConstraintSVM:
    """Valid/invalid classifier of orientations.

    Parameters
    ----------
    kernel : {"linear", "poly", "rbf", "sigmoid"}
    C : float
        Soft-margin penalty.
    gamma : float or "scale"
    degree : int
        Polynomial degree.
    coef0 : float
        Kernel offset (poly, sigmoid).
    feature : {"quaternion", "direction"}

    Attributes
    ----------
    support_vectors_ : (S, F) float64
    dual_coef_ : (S,) float64
        ``α_i y_i``.
    intercept_ : float
    gamma_ : float
        The numeric γ used.
    """

    def __init__(self, kernel: str = "rbf", C: float = 10.0, gamma="scale", degree: int = 3,
                 coef0: float = 1.0, feature: str = "quaternion"):
        if kernel not in KERNELS:
            raise ValueError(f"kernel must be one of {KERNELS}, got {kernel!r}")
        if feature not in FEATURES:
            raise ValueError(f"feature must be one of {FEATURES}, got {feature!r}")
        self.kernel, self.C, self.gamma, self.degree = kernel, C, gamma, degree
        self.coef0, self.feature = coef0, feature

    def fit(self, q: np.ndarray, valid: np.ndarray) -> BinaryConstraintSVM:
        """Fit on orientations ``q`` (N, 4) with labels ``valid`` (N,) bool."""
        from sklearn.svm import SVC

        x = features(q, self.feature)
        y = np.asarray(valid, dtype=bool).astype(int)
        svc = SVC(kernel=self.kernel, C=self.C, gamma=self.gamma, degree=self.degree,
                  coef0=self.coef0)
        svc.fit(x, y)
        self.sklearn_ = svc
        self.support_vectors_ = np.asarray(svc.support_vectors_, dtype=np.float64)
        self.dual_coef_ = np.asarray(svc.dual_coef_[0], dtype=np.float64)
        self.intercept_ = float(svc.intercept_[0])
        self.gamma_ = float(svc._gamma)
        return self

    def _kernel(self, x: np.ndarray) -> np.ndarray:
        sv = self.support_vectors_
        if self.kernel == "rbf":
            d2 = (x * x).sum(1)[:, None] + (sv * sv).sum(1)[None, :] - 2.0 * x @ sv.T
            return np.exp(-self.gamma_ * np.maximum(d2, 0.0))
        dot = x @ sv.T
        if self.kernel == "linear":
            return dot
        if self.kernel == "poly":
            return (self.gamma_ * dot + self.coef0) ** self.degree
        return np.tanh(self.gamma_ * dot + self.coef0)

    def decision_function(self, q: np.ndarray) -> np.ndarray:
        """(N,) signed score, > 0 for valid (numpy only)."""
        x = features(q, self.feature)
        return self._kernel(x) @ self.dual_coef_ + self.intercept_

    def predict(self, q: np.ndarray) -> np.ndarray:
        """(N,) bool: predicted valid."""
        return self.decision_function(q) > 0.0

    def save(self, path: str | Path, constraint_yaml: str = "") -> tuple[Path, Path]:
        """Write ``<path>.npz`` (arrays) and ``<path>.json`` (metadata); no pickle."""
        base = Path(path).with_suffix("")
        base.parent.mkdir(parents=True, exist_ok=True)
        npz, meta = base.with_suffix(".npz"), base.with_suffix(".json")
        buf = io.BytesIO()  # the constraint may name a patient: both files owner-only
        np.savez(buf, support_vectors=self.support_vectors_, dual_coef=self.dual_coef_)
        write_owner_only(npz, buf.getvalue())
        write_owner_only(meta, json.dumps({
            "format": FORMAT, "kernel": self.kernel, "C": self.C, "gamma": self.gamma_,
            "degree": self.degree, "coef0": self.coef0, "feature": self.feature,
            "intercept": self.intercept_, "constraint": constraint_yaml,
        }, indent=1))
        return npz, meta

    @classmethod
    def load(cls, path: str | Path) -> BinaryConstraintSVM:
        """Read a model written by :meth:`save` (``allow_pickle=False``)."""
        base = Path(path).with_suffix("")
        try:
            meta = json.loads(base.with_suffix(".json").read_text())
            with np.load(base.with_suffix(".npz"), allow_pickle=False) as z:
                sv, dc = z["support_vectors"], z["dual_coef"]
        except (OSError, ValueError, KeyError) as err:
            raise ModelFileError(f"{base}: not a readable SVM model ({err})") from None
        if meta.get("format") != FORMAT:
            raise ModelFileError(f"{base}.json: format {meta.get('format')!r}, expected {FORMAT!r}")
        m = cls(meta["kernel"], meta["C"], meta["gamma"], meta["degree"], meta["coef0"],
                meta["feature"])
        m.support_vectors_, m.dual_coef_ = sv, dc
        m.intercept_, m.gamma_ = float(meta["intercept"]), float(meta["gamma"])
        m.constraint_yaml = meta.get("constraint", "")
        return m
