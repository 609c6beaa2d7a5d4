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
