"""The plots say which runs they show and keep one colour per variant; a difference curve hidden
under another is still read off the legend (overcon.plots, overcon.tooling.report, Fig. 3)."""
from __future__ import annotations

from pathlib import Path

import matplotlib
import numpy as np
import pytest

matplotlib.use("Agg")

from overcon import plots  # noqa: E402
from overcon.figures import FIGURES, figure_series  # noqa: E402
from overcon.tooling.run import Series  # noqa: E402
from overcon.tooling import report  # noqa: E402
from overcon.tooling.compare import compare_group  # noqa: E402
from overcon.tooling.fmus import FmuInfo, Output  # noqa: E402

T = np.linspace(0.0, 1.0, 11)


@pytest.fixture
def drawn(monkeypatch):
    """Every figure plot_series draws, kept open instead of closed (title, lines, legends)."""
    import matplotlib.pyplot as plt
    figures = []
    monkeypatch.setattr(plt, "close", lambda fig: figures.append(fig))
    return figures


def _lines(ax) -> dict[str, tuple]:
    return {line.get_label(): (line.get_color(), line.get_linestyle()) for line in ax.get_lines()}


def test_a_variant_keeps_its_colour_and_the_legend_gives_each_difference(tmp_path, drawn):
    series = {"a": T, "b": T + 1e-9, "c": T + 1e-9}  # b and c differ from a alike: the curves coincide
    plots.plot_series(tmp_path / "p.png", T, series, title="t", ylabel="x (m)", runs="lockstep runs (test)")
    top, bottom = drawn[0].axes
    assert top.get_title() == "t\nlockstep runs (test)"
    upper, lower = _lines(top), _lines(bottom)
    assert lower["b − a (max |Δ| 1e-09 m)"] == upper["b"] and lower["c − a (max |Δ| 1e-09 m)"] == upper["c"]
    assert len({colour for colour, _ in upper.values()}) == 3
    assert (tmp_path / "p.png").is_file()


def test_fig3_compares_eliminations_within_each_group(tmp_path, drawn):
    fig3 = next(f for f in FIGURES if f.name == "fig3")
    series, reference = figure_series(fig3, {"planar_none": [("without eq. 4", T), ("without eq. 6", T + 2e-15)],
                                             "planar_f45": [("without eq. 4", T + 0.1), ("without eq. 6", T + 0.1)]})
    plots.plot_series(tmp_path / "fig3.png", T, series, title=fig3.title, ylabel=fig3.ylabel, reference=reference)
    labels = list(_lines(drawn[0].axes[1]))
    assert labels == ["without friction, without eq. 6 − without friction, without eq. 4 (max |Δ| 2e-15 m)",
                      "with friction, without eq. 6 − with friction, without eq. 4 (max |Δ| 0 m)"]


def _group(tmp_path):
    outs = (Output("slider1.x", "m", "position"),)
    infos = [FmuInfo(tmp_path / f"g_wo{k}.fmu", f"g_wo{k}", 0.0, 1.0, 0.1, 1e-9, outs, "g", f"without eq. {k}",
                     friction=("joint1",), eliminate=(k,), motion_unique=False, lockstep=True) for k in (4, 6)]
    return infos


@pytest.mark.parametrize("adaptive_failed", [False, True])
def test_group_plot_shows_the_deciding_lockstep_runs_and_says_so(tmp_path, drawn, adaptive_failed):
    infos = _group(tmp_path)
    adaptive = [Series(T, {"slider1.x": T}), Series(T, {"slider1.x": T + 3e-8})]
    lock = [Series(T, {"slider1.x": T}), Series(T, {"slider1.x": T + 0.5})]
    c = compare_group("g", infos, None if adaptive_failed else adaptive, lockstep=lock, lockstep_step=5e-3,
                      adaptive_failure="rk4 failed" if adaptive_failed else None)
    (path,) = report.plot_comparison(c, tmp_path)
    top, bottom = drawn[0].axes
    title = top.get_title()
    assert "g: slider1.x (not unique; max difference 0.5 m)" in title
    assert "lockstep runs (rk4, step 0.005 s, identical steps for every variant)" in title
    assert ("the adaptive runs (not shown) differ by 3e-08 m" in title) is not adaptive_failed
    assert np.max(np.abs(bottom.get_lines()[0].get_ydata() - 0.5)) < 1e-12  # the lockstep runs (adaptive: 3e-8)
    assert _lines(bottom)["without eq. 6 − without eq. 4 (max |Δ| 0.5 m)"] == _lines(top)["without eq. 6"]
    assert Path(path).is_file()
