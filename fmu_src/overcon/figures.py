"""The paper's figures (Figs. 3, 4, 5, 7, 8, 9) as data: which scene groups, which output, which
labels. Drawn from in-process runs by :mod:`overcon.paper` and from FMU results by
:mod:`overcon.tooling.pipeline`; this module needs neither the engine nor fmpy."""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Figure:
    name: str
    groups: tuple[str, ...]
    output: str
    ylabel: str
    title: str


PAPER_GROUPS = ("planar_none", "planar_f45", "planar_f1", "planar_f145",
                "spatial_none", "spatial_MN", "spatial_GH", "spatial_GHMN")
"""The paper's eight scene groups (friction set x mechanism): what ``overcon reproduce`` runs. A
scene of another group in the mechanisms directory is left out and named (decided: the paper's
report must not change because a user put a scene beside the paper's; user scenes are run by
``compare`` and ``regress``)."""

ADAPTIVE_RUNS = "adaptive runs (each scene's own solver settings)"
"""Which runs the in-process figures show (``overcon figures``)."""

FIGURES = (
    Figure("fig3", ("planar_none", "planar_f45"), "slider1.x", "displacement x1 (m)",
           "Fig. 3: slider 1 x, without friction and with friction in revolute joints 4, 5"),
    Figure("fig4", ("planar_f1",), "slider1.x", "displacement x1 (m)",
           "Fig. 4: slider 1 x, friction in translational joint 1"),
    Figure("fig5", ("planar_f145",), "slider1.x", "displacement x1 (m)",
           "Fig. 5: slider 1 x, friction in joints 1, 4, 5"),
    Figure("fig7", ("spatial_none",), "G.Fy0", "force (N)",
           "Fig. 7: joint G reaction, y component (global frame), no friction"),
    Figure("fig8", ("spatial_GH",), "platform.x", "displacement x7 (m)",
           "Fig. 8: platform x, friction in joints G, H"),
    Figure("fig9", ("spatial_GHMN",), "platform.x", "displacement x7 (m)",
           "Fig. 9: platform x, friction in joints G, H, M, N"),
)


def figure_series(fig: Figure, variants: dict[str, list[tuple[str, object]]]) -> tuple[dict, dict[str, str]]:
    """The curves of ``fig`` and their difference references: ``variants`` maps each of the
    figure's groups to its (label, values) in paper order. In a figure of two groups (Fig. 3:
    without and with friction) the labels get the group's prefix, and each variant is compared
    with the first variant of its own group: the difference between eliminations is what the
    figure shows, not the difference friction makes."""
    series: dict = {}
    reference: dict[str, str] = {}
    for g in fig.groups:
        prefix = "" if len(fig.groups) == 1 else ("without friction, " if g.endswith("none") else "with friction, ")
        first = None
        for label, values in variants[g]:
            series[prefix + label] = values
            first = first or prefix + label
            reference[prefix + label] = first
    return series, reference


@dataclass(frozen=True)
class BeyondFigure:
    """A figure beyond the paper: the rigid eliminations of a paper group and, on the same time
    grid, the runs of a compliant variant of its mechanism (the scenes of group
    ``compliant_group`` in the subdirectory ``directory`` of the mechanisms directory, named
    ``scenes``), which name the rigid group's eliminations; under ``redundancy = "compliant"``
    these do not apply, so their runs are one motion."""
    name: str
    rigid_group: str
    compliant_group: str
    directory: str
    scenes: tuple[str, ...]
    output: str
    ylabel: str
    title: str


BEYOND = (
    BeyondFigure("beyond_compliant_f1", "planar_f1", "compliant_planar_f1", "examples",
                 ("compliant_planar_f1_wo4", "compliant_planar_f1_wo6"), "slider1.x", "displacement x1 (m)",
                 "Beyond the paper: slider 1 x, friction in joint 1, rigid eliminations and compliant "
                 "joints 1, 2, 3"),
)

COMPLIANT_LABEL = "compliant joints"
"""Legend label of the compliant motion in a :class:`BeyondFigure`."""


@dataclass(frozen=True)
class Placement:
    """Where a compliant curve lies relative to two rigid eliminations' curves (same grid)."""
    spread: float  # largest difference between the compliant runs (0: one motion)
    share_between: float  # fraction of the samples at which it lies between the two rigid curves
    s: float  # least-squares position on the line from the first rigid curve (0) to the second (1)
    outside: float  # largest distance outside the band between the two rigid curves
    to_rigid: tuple[float, float]  # largest distance to each rigid curve
    rigid_apart: float  # largest distance between the two rigid curves


def placement(compliant: list, rigid: list) -> Placement:
    """:class:`Placement` of the first of the ``compliant`` runs (value arrays, one per scene)
    against the two ``rigid`` ones."""
    import numpy as np

    c = np.asarray(compliant[0], dtype=float)
    a, b = (np.asarray(r, dtype=float) for r in rigid)
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    ab = b - a
    return Placement(
        spread=max((float(np.max(np.abs(np.asarray(x, dtype=float) - c))) for x in compliant[1:]), default=0.0),
        share_between=float(np.mean((c >= lo) & (c <= hi))),
        s=float(np.dot(c - a, ab) / np.dot(ab, ab)),
        outside=float(np.max(np.maximum(lo - c, c - hi).clip(min=0.0))),
        to_rigid=(float(np.max(np.abs(c - a))), float(np.max(np.abs(c - b)))),
        rigid_apart=float(np.max(np.abs(ab))))


def beyond_series(fig: BeyondFigure, rigid: list[tuple[str, object]],
                  compliant: list) -> tuple[dict, dict[str, str]]:
    """The curves of ``fig``: the rigid eliminations (label, values) and the compliant motion (the
    first compliant run; the others are the same motion); the difference panel shows each rigid
    curve minus the compliant one."""
    series = {f"rigid, {label}": values for label, values in rigid}
    series[COMPLIANT_LABEL] = compliant[0]
    return series, {label: COMPLIANT_LABEL for label in series if label != COMPLIANT_LABEL}


def placement_text(fig: BeyondFigure, p: Placement, labels: list[str], unit: str = "m") -> str:
    """One paragraph for a report: the compliant motion's uniqueness and where it lies."""
    first, second = labels
    return (f"The compliant runs ({', '.join(fig.scenes)}: each names one rigid elimination, which does not "
            f"apply) differ by {p.spread:.3g} {unit}: one motion. Its {fig.output} lies between the two rigid "
            f"eliminations' curves at {p.share_between:.0%} of the output points and at most {p.outside:.3g} {unit} "
            f"outside them; on the line from the run {first} (s = 0) to the run {second} (s = 1) it lies at "
            f"s = {p.s:.2f} (least squares over the run). Largest distance to the run {first}: "
            f"{p.to_rigid[0]:.3g} {unit}, to the run {second}: {p.to_rigid[1]:.3g} {unit}; the two rigid runs are "
            f"up to {p.rigid_apart:.3g} {unit} apart.")
