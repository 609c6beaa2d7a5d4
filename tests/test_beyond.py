"""Beyond the paper (issue 24): the paper's non-unique group planar_f1 (friction in joint 1) run
also with compliant translational joints 1, 2, 3 (mechanisms/examples/compliant_planar_*). The
compliant motion is one motion whichever elimination its scene names, and the figure of
``overcon reproduce`` (and ``overcon figures``) shows where it lies relative to the two rigid
eliminations' curves."""
from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from overcon.cli import main
from overcon.figures import BEYOND, Placement, placement
from overcon.paper import beyond_figure, run_group, scene_groups

MECH = Path(__file__).resolve().parent.parent / "mechanisms"
FIG = BEYOND[0]


def test_placement_measures_where_a_curve_lies():
    """Synthetic curves: halfway between two lines, then beyond the second by 0.5."""
    a, b = np.zeros(4), np.array([0.0, 1.0, 2.0, 2.0])
    c = np.array([0.0, 0.5, 1.0, 2.5])
    p = placement([c, c.copy()], [a, b])
    assert p.spread == 0.0 and p.share_between == 0.75 and p.outside == 0.5
    assert p.to_rigid == (2.5, 1.0) and p.rigid_apart == 2.0
    assert p.s == pytest.approx(np.dot(c, b) / np.dot(b, b))


def test_compliant_group_lies_between_the_eliminations(tmp_path):
    """In process: the two compliant scenes give one motion, and it lies between the rigid
    eliminations' curves for most of the run, strictly inside the line between them (0 < s < 1),
    apart from both."""
    rigid = run_group(scene_groups(MECH)[FIG.rigid_group])
    path, where = beyond_figure(FIG, MECH, tmp_path, rigid)
    assert path.stat().st_size > 10_000
    assert isinstance(where, Placement) and where.spread <= 1e-12
    assert where.share_between > 0.5 and 0.0 < where.s < 1.0
    assert min(where.to_rigid) > 1e3 * where.spread + 1e-3  # a third motion, not one of the eliminations'
    print(f"\nbeyond: spread {where.spread:.3g} m, between at {where.share_between:.0%} of the points, "
          f"outside by at most {where.outside:.3g} m, s = {where.s:.3f}, to the rigid runs {where.to_rigid[0]:.3g} "
          f"and {where.to_rigid[1]:.3g} m (apart {where.rigid_apart:.3g} m)")


@pytest.mark.integration
def test_reproduce_draws_the_compliant_figure(tmp_path, capsys):
    """``overcon reproduce`` on the group planar_f1 with the compliant scenes beside it: the
    figure and a report section marked as beyond the paper; without the compliant scenes the
    figure is skipped and the report has no such section."""
    mech = tmp_path / "mech"
    (mech / FIG.directory).mkdir(parents=True)
    for f in ("planar_f1_wo4.toml", "planar_f1_wo6.toml", "planar_sliders.toml"):
        shutil.copy(MECH / f, mech / f)
    bare = tmp_path / "bare"
    assert main(["reproduce", "--mechanisms", str(mech), "--out", str(bare), "--stop-time", "1"]) == 0
    assert "beyond_compliant_f1: skipped" in capsys.readouterr().out
    assert "Beyond the paper" not in (bare / "report.md").read_text() and not (bare / f"{FIG.name}.png").exists()
    for f in (MECH / FIG.directory).glob("compliant_planar_*.toml"):
        shutil.copy(f, mech / FIG.directory / f.name)
    out = tmp_path / "repro"
    assert main(["reproduce", "--mechanisms", str(mech), "--out", str(out), "--stop-time", "1"]) == 0
    text = capsys.readouterr().out
    assert "beyond_compliant_f1: compliant runs differ by 0;" in text
    report = (out / "report.md").read_text()
    assert "## Beyond the paper: compliant joints" in report and "*Not in the paper.*" in report
    assert f"]({FIG.name}.png)" in report and (out / f"{FIG.name}.png").stat().st_size > 10_000
    assert report.index("## Beyond the paper") < report.index("## Groups")
