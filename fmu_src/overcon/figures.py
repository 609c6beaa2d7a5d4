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
