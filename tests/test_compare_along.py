"""``overcon compare`` reports the uniqueness along the motion per group and per FMU: the FMUs'
discrete outputs ``rank``, ``motion_unique`` and ``<joint>.reaction_unique`` are recorded at every
output point (``<model>.along.csv``, beside the unchanged ``<model>.csv``), and the report shows
the intervals where the rank differs from t = 0's or a friction joint's reaction (or the motion)
is not unique, or one line saying they stayed as at t = 0.

The mechanism whose redundancy changes at a known time: tests/data/flat_parallelogram (rank 8 ->
7 and G0's reaction non-unique at its flat position, t = 1 s; the C FMU stops there under the
default ``singular = "stop"``), two eliminations of it in one group; beside it the paper group
planar_f1 (friction on joint 1, whose reaction is not unique at every position)."""
from __future__ import annotations

import csv
from pathlib import Path
from types import SimpleNamespace

import pytest

from overcon.fmu.build import build_all
from overcon.tooling.compare import read_along
from overcon.tooling.pipeline import compare_paths
from overcon.tooling.report import along_lines
from overcon.tooling.run import along_outputs, along_path, read_series

pytestmark = pytest.mark.integration

ROOT = Path(__file__).resolve().parent.parent
FLAT = ROOT / "tests" / "data" / "flat_parallelogram"
T_FLAT = 1.0  # s, the flat position (tests/data/flat_parallelogram/flat_parallelogram.toml)
STOP = 1.5  # s, past the flat position
STEP = 0.01  # s, the flat scene's output interval


def _flat_variant(dst: Path, name: str, eliminate: str) -> Path:
    text = (FLAT / "flat_parallelogram_f.toml").read_text()
    for old, new in (('name = "flat_parallelogram_f"', f'name = "{name}"\ngroup = "flat"'),
                     ("eliminate = []", f"eliminate = {eliminate}")):
        assert old in text
        text = text.replace(old, new)
    (dst / "flat_parallelogram.toml").write_text((FLAT / "flat_parallelogram.toml").read_text())
    out = dst / f"{name}.toml"
    out.write_text(text)
    return out


@pytest.fixture(scope="module")
def compared(tmp_path_factory):
    """The C FMUs of the two flat variants and of planar_f1 (wo4, wo6), compared to 1.5 s."""
    scenes = tmp_path_factory.mktemp("scenes")
    files = [_flat_variant(scenes, "flat_none", "[]"), _flat_variant(scenes, "flat_auto", '"auto"'),
             ROOT / "mechanisms" / "planar_f1_wo4.toml", ROOT / "mechanisms" / "planar_f1_wo6.toml"]
    fmus = tmp_path_factory.mktemp("fmus")
    code, res = build_all(files, fmus, allow_nonunique=True, refs=False, validate=False, runtime="c", kind="cs",
                          echo=lambda s: None, echo_err=lambda s: None)
    assert code == 0, [m for r in res for m in r.messages]
    out = tmp_path_factory.mktemp("compare")
    outcome = compare_paths([fmus], out, stop_time=STOP, echo=lambda s: None)
    return outcome, {c.group: c for c in outcome.comparisons}, out


def _start(fmu: Path, name: str) -> str:
    import fmpy
    return next(v.start for v in fmpy.read_model_description(str(fmu)).modelVariables if v.name == name)


def test_the_flat_group_reports_the_lost_rank_and_uniqueness_at_the_stop(compared):
    """Both flat runs stop at the flat position (the group FAILED, as before); each keeps rank 8
    and every verdict unique at every output point before it, and the row held at the stop says
    rank 7, G0 not unique, motion not unique; the report says so per FMU."""
    outcome, groups, out = compared
    c = groups["flat"]
    assert c.failure is not None and "singular position" in c.failure
    text = outcome.report.read_text()
    for info, a in zip(c.infos, c.along):
        rank0 = int(_start(info.path, "rank"))
        assert a.failed and len(a.intervals) == 2
        before, stop = a.intervals
        assert (before.start, before.rank, before.nonunique, before.motion_unique) == (0.0, rank0, (), True)
        assert T_FLAT - 2 * STEP < before.end < T_FLAT <= stop.end + 1e-9
        assert stop.at_stop and stop.end == pytest.approx(before.end + STEP, abs=1e-12)
        assert (stop.rank, stop.nonunique, stop.motion_unique) == (rank0 - 1, tuple(info.friction), False)
        line = (f"- {info.model}: at t = 0 rank {rank0}, friction joints' reactions unique, motion unique; "
                f"at the run's stop (between t = {before.end:g} and {stop.end:g} s): rank {rank0 - 1}, "
                f"reaction not unique: G0, motion NOT unique (rank at t = 0: {rank0})")
        assert line in text


def test_the_paper_group_stayed_as_at_t0(compared):
    """planar_f1: friction on joint 1, whose reaction is not unique at every position; the rank
    (the FMU's start value, the pre-check's) and the verdicts stay as at t = 0 over the run."""
    outcome, groups, out = compared
    c = groups["planar_f1"]
    assert c.failure is None and c.matches
    text = outcome.report.read_text()
    for info, a in zip(c.infos, c.along):
        rank0 = int(_start(info.path, "rank"))
        assert a.unchanged and not a.failed
        iv = a.initial
        assert (iv.start, iv.end, iv.rank, iv.nonunique, iv.motion_unique) == (0.0, STOP, rank0, ("joint1",), False)
        assert info.friction == ("joint1",) and info.motion_unique is False
        assert (f"- {info.model}: stayed as at t = 0 from 0 to {STOP:g} s: rank {rank0}, reaction not unique: "
                f"joint1, motion NOT unique") in text


def test_the_real_csv_is_unchanged_and_the_along_file_beside_it(compared):
    """``<model>.csv`` holds ``time`` and the Real outputs only (as before); ``<model>.along.csv``
    time, rank, motion_unique and the friction joints' reaction_unique as integers, on the same
    grid."""
    outcome, groups, out = compared
    info = groups["planar_f1"].infos[0]
    with open(out / f"{info.model}.csv", newline="") as f:
        assert next(csv.reader(f)) == ["time", *info.output_names]
    real = read_series(out / f"{info.model}.csv")
    with open(along_path(out / f"{info.model}.csv"), newline="") as f:
        rows = list(csv.reader(f))
    assert rows[0] == ["time", "rank", "motion_unique", "joint1.reaction_unique"]
    assert [float(r[0]) for r in rows[1:]] == list(real.time)
    assert {tuple(r[1:]) for r in rows[1:]} == {(_start(info.path, "rank"), "0", "0")}


def test_fmus_without_the_discrete_outputs_add_nothing(tmp_path):
    """An FMU whose verdicts are constants and that has no ``rank`` (older overcon, another tool)
    records no along file, so its group's report has no along lines."""
    def var(name, typ, variability):
        return SimpleNamespace(name=name, type=typ, causality="output", variability=variability)

    old = SimpleNamespace(modelVariables=[var("x", "Real", "continuous"), var("motion_unique", "Boolean", "constant"),
                                          var("G0.reaction_unique", "Boolean", "constant")])
    assert along_outputs(old) == []
    new = SimpleNamespace(modelVariables=[*old.modelVariables[:1], var("G0.reaction_unique", "Boolean", "discrete"),
                                          var("motion_unique", "Boolean", "discrete"), var("rank", "Integer", "discrete")])
    assert along_outputs(new) == ["rank", "motion_unique", "G0.reaction_unique"]
    assert read_along(tmp_path / "none.along.csv") is None
    assert along_lines(SimpleNamespace(along=[None, None], infos=[])) == []
