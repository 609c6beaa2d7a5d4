"""PNG plots (matplotlib, Agg backend): one output over time, one line per variant, optionally
with a panel of differences between variants.

Conventions (every plot of overcon): a variant keeps its colour and line style in both panels
(colour ``C<k>`` of matplotlib's default cycle for the k-th series); the difference panel's
legend gives each curve's largest absolute difference, so a curve hidden under another (two
equal differences, or two near zero) is still read off the legend; ``runs`` names which runs
the plot shows (a second title line)."""
from __future__ import annotations

from .outfiles import savefig_atomic

from pathlib import Path
from typing import Mapping

import numpy as np

STYLES = ("-", "--", ":", "-.")


def _unit(ylabel: str) -> str:
    """The unit in a label "name (unit)", or ""."""
    return ylabel.rsplit("(", 1)[-1].rstrip(")") if ylabel.endswith(")") and "(" in ylabel else ""


def difference_pairs(labels: list[str], reference: Mapping[str, str] | None = None) -> list[tuple[str, str]]:
    """(variant, reference variant) per curve of the difference panel: each label that is not a
    reference against its ``reference`` (default: every label against the first one)."""
    if reference is None:
        return [(lab, labels[0]) for lab in labels[1:]]
    return [(lab, reference[lab]) for lab in labels if lab in reference and reference[lab] != lab]


OUTSIDE = dict(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)
"""Legends beside the axes, never over a curve (decided: Fig. 7's legend covered the curve near
t = 9.5-10 s wherever matplotlib's "best" placed it)."""


def plot_series(path: Path, time: np.ndarray, series: Mapping[str, np.ndarray], *, title: str,
                ylabel: str, differences: bool = True, reference: Mapping[str, str] | None = None,
                runs: str = "") -> Path:
    """Write the PNG ``path``: ``series`` (label -> values on ``time``, s) in the upper panel; the
    differences of :func:`difference_pairs` in the lower one (if ``differences`` and there are
    any), in the unit of ``ylabel``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    labels = list(series)
    pairs = difference_pairs(labels, reference) if differences and len(labels) > 1 else []
    fig, axes = plt.subplots(2 if pairs else 1, 1, figsize=(9.5, 6.0 if pairs else 4.0), sharex=True, squeeze=False)
    look = {lab: dict(ls=STYLES[k % len(STYLES)], color=f"C{k % 10}") for k, lab in enumerate(labels)}
    ax = axes[0, 0]
    for lab in labels:
        ax.plot(time, series[lab], lw=1.6, label=lab, **look[lab])
    ax.set_ylabel(ylabel)
    ax.set_title(f"{title}\n{runs}" if runs else title, fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(**OUTSIDE)
    if pairs:
        unit = _unit(ylabel)
        dax = axes[1, 0]
        for lab, ref in pairs:
            d = np.asarray(series[lab]) - np.asarray(series[ref])
            biggest = float(np.max(np.abs(d))) if d.size else 0.0
            dax.plot(time, d, lw=1.2, label=f"{lab} − {ref} (max |Δ| {biggest:.2g}{' ' + unit if unit else ''})",
                     **look[lab])
        dax.set_ylabel(f"difference ({unit})" if unit else "difference")
        dax.grid(alpha=0.3)
        dax.legend(**OUTSIDE)
    axes[-1, 0].set_xlabel("time (s)")
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    savefig_atomic(fig, path, dpi=110)
    plt.close(fig)
    return path
