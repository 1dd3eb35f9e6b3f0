"""Metrics for people: one labelled line each (the one formatter of ``rig train`` and ``rig
evaluate``, single joints and limbs)."""

from __future__ import annotations

__all__ = ["labelled_lines"]


def labelled_lines(metrics: dict, labels: dict[str, str], width: int) -> list[str]:
    """``labels`` (key → label) of the keys present in ``metrics``, in order; fractions
    (``frac_*``) in %."""
    out = []
    for key, label in labels.items():
        if key in metrics:
            v = metrics[key]
            text = f"{100 * v:.3f} %" if key.startswith("frac_") else f"{v:.6g}"
            out.append(f"  {label:<{width}} {text}")
    return out
