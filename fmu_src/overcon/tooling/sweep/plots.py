"""``sweep.png`` and, with pyarrow, ``sweep.parquet``."""
from __future__ import annotations

from ...outfiles import savefig_atomic

from pathlib import Path

from ...verdict import LOCKSTEP_FACTOR
from .grid import parse_param
from .rows import PARQUET_NAME, PNG_NAME, Sweep, _number

ZERO_FLOOR = 1e-17
"""Differences that are exactly 0 are drawn at this height (m or rad) on the log-scale plot."""

def write_parquet(csv_path: Path) -> Path | None:
    """``sweep.parquet`` next to ``csv_path`` when pyarrow is installed (else None)."""
    try:
        import pyarrow.csv as pacsv
        import pyarrow.parquet as pq
    except ImportError:
        return None
    table = pacsv.read_csv(str(csv_path))
    out = csv_path.with_name(PARQUET_NAME)
    pq.write_table(table, str(out))
    return out


def plot(sw: Sweep, rows: list[dict]) -> Path:
    """``sweep.png``: ``max_diff [m]`` (the non-uniqueness measure) against each swept numeric
    parameter, one marker series per group, log scale; differences of exactly 0 drawn at
    :data:`ZERO_FLOOR` with open markers (said in the legend), sets without a measure (a failed
    run) left out and counted in the title."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import MaxNLocator

    names = [n for n in (parse_param(t).name for t in sw.definition["params"])
             if any(_number(r[n]) is not None for r in rows)]
    per_set: dict[tuple[str, str], dict] = {}
    for r in rows:  # one point per group and parameter set (the rows of a set share the measure)
        per_set.setdefault((r["group"], r["key"].split(" ", 1)[1]), r)
    fig, axes = plt.subplots(1, max(1, len(names)), figsize=(5.5 * max(1, len(names)), 4.2), squeeze=False)
    groups = list(sw.groups)
    missing = sum(_number(r["max_diff [m]"]) is None for r in per_set.values())
    for ax, name in zip(axes[0], names or [None]):
        for k, g in enumerate(groups):
            pts = [(_number(r[name]) if name else 0.0, _number(r["max_diff [m]"])) for (gg, _), r in per_set.items()
                   if gg == g]
            pts = sorted((x, y) for x, y in pts if x is not None and y is not None)
            color = f"C{k}"
            pos = [(x, y) for x, y in pts if y > 0]
            zero = [(x, y) for x, y in pts if y == 0]
            if pos:
                ax.plot(*zip(*pos), "o-" if sw.definition["samples"] is None and len(names) == 1 else "o",
                        color=color, label=g)
            if zero:
                ax.plot([x for x, _ in zero], [ZERO_FLOOR] * len(zero), "v", mfc="none", color=color,
                        label=f"{g}: difference exactly 0 (drawn at {ZERO_FLOOR:g} m)")
        if sw.lockstep_step is not None:
            ax.axhline(LOCKSTEP_FACTOR, color="0.4", ls="--", lw=1,
                       label=f"lockstep verdict threshold {LOCKSTEP_FACTOR:g} m (outputs up to 1 m)")
        ax.set_yscale("log")
        ax.xaxis.set_major_locator(MaxNLocator(6))
        ax.set_xlabel(name or "")
        ax.set_ylabel("max position difference between eliminations (m)")
        ax.grid(alpha=0.3, which="both")
        if ax.get_legend_handles_labels()[0]:  # no labelled line (no set measured): no empty legend box
            ax.legend(fontsize=7)
    mode = (f"lockstep runs, rk4 {sw.lockstep_step:g} s" if sw.lockstep_step is not None
            else "the FMUs' own solver settings")
    title = f"overcon sweep: non-uniqueness of the motion\n({mode}"
    title += f"; {missing} parameter set(s) without a measure: a run failed)" if missing else ")"
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    out = sw.out_dir / PNG_NAME
    savefig_atomic(fig, out, dpi=110)
    plt.close(fig)
    return out
