"""PNG plots (matplotlib, Agg backend): one output over time, one line per variant, optionally
with a panel of differences to the first variant."""
from __future__ import annotations

from pathlib import Path
from typing import Mapping

import numpy as np


def plot_series(path: Path, time: np.ndarray, series: Mapping[str, np.ndarray], *, title: str,
                ylabel: str, differences: bool = True) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    labels = list(series)
    show_diff = differences and len(labels) > 1
    fig, axes = plt.subplots(2 if show_diff else 1, 1, figsize=(7.0, 6.0 if show_diff else 4.0),
                             sharex=True, squeeze=False)
    ax = axes[0, 0]
    styles = ["-", "--", ":", "-."]
    for k, label in enumerate(labels):
        ax.plot(time, series[label], styles[k % len(styles)], lw=1.6, label=label)
    ax.set_ylabel(ylabel)
    ax.set_title(title, fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    if show_diff:
        dax = axes[1, 0]
        ref = series[labels[0]]
        for k, label in enumerate(labels[1:], start=1):
            dax.plot(time, series[label] - ref, styles[k % len(styles)], lw=1.2, label=f"{label} − {labels[0]}")
        dax.set_ylabel(f"difference ({ylabel.split('(')[-1].rstrip(')') if '(' in ylabel else ''})")
        dax.grid(alpha=0.3)
        dax.legend(fontsize=8)
    axes[-1, 0].set_xlabel("time (s)")
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
