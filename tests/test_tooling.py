"""fmpy tooling: ``overcon run``, ``compare`` (groups and reference CSV), ``reproduce``; verdicts,
tolerances, exit codes and messages for bad input. FMUs are built into tmp from (modified copies
of) the scene files and run with short stop times."""
from __future__ import annotations

import re

import csv
import shutil
import zipfile
from pathlib import Path

import numpy as np
import pytest

from overcon.cli import main
from overcon.fmu.build import build_all
from overcon.verdict import lockstep_tolerance, uniqueness_tolerance
from overcon.tooling import InputError
from overcon.tooling.compare import check_grids, compare_group
from overcon.tooling.fmus import inspect_fmu
from overcon.tooling.run import Series, read_series

pytestmark = pytest.mark.integration  # every test here builds or runs FMUs, or shares a fixture that does

ROOT = Path(__file__).resolve().parent.parent
MECH = ROOT / "mechanisms"
QUIET = dict(echo=lambda s: None, echo_err=lambda s: None)


def _build(scenes: list[Path], out: Path) -> dict[str, Path]:
    code, res = build_all(scenes, out, allow_nonunique=True, refs=False, validate=False, **QUIET)
    assert code == 0, [m for r in res for m in r.messages]
    return {r.name: r.fmu for r in res if r.status == "built"}


def _scene_copy(dst: Path, name: str, *, mech_text: str | None = None, **replace) -> Path:
    """Copy of mechanisms/<name>.toml (and its mechanism file, possibly modified) into ``dst``."""
    dst.mkdir(parents=True, exist_ok=True)
    text = (MECH / f"{name}.toml").read_text()
    for old, new in replace.values():
        assert old in text
        text = text.replace(old, new)
    mech = "planar_sliders.toml" if name.startswith("planar") else "spatial_parallelogram.toml"
    (dst / mech).write_text(mech_text if mech_text is not None else (MECH / mech).read_text())
    out = dst / f"{name}.toml"
    out.write_text(text)
    return out


def _regrouped(dst: Path, name: str, group: str, new_name: str, *, mech_text: str | None = None) -> Path:
    """Copy of scene ``name`` renamed ``new_name`` in group ``group`` (see :func:`_scene_copy`)."""
    old_group = name.rsplit("_wo", 1)[0]
    return _scene_copy(dst, name, mech_text=mech_text, g=(f'group = "{old_group}"', f'group = "{group}"'),
                       n=(f'name = "{name}"', f'name = "{new_name}"'))


@pytest.fixture(scope="module")
def f45(tmp_path_factory) -> dict[str, Path]:
    out = tmp_path_factory.mktemp("f45")
    return _build([MECH / "planar_f45_wo4.toml", MECH / "planar_f45_wo6.toml"], out / "fmus")


@pytest.fixture(scope="module")
def run_csv(tmp_path_factory, f45) -> Path:
    """``overcon run`` of planar_f45_wo4 to 1 s: the reference CSV of the reference-mode tests."""
    out = tmp_path_factory.mktemp("run")
    assert main(["run", str(f45["planar_f45_wo4"]), "--stop-time", "1", "--out", str(out)]) == 0
    return out / "planar_f45_wo4.csv"


def _shifted_csv(src: Path, dst: Path, column: str, delta: float) -> Path:
    with src.open() as f:
        rows = list(csv.reader(f))
    k = rows[0].index(column)
    for row in rows[1:]:
        row[k] = repr(float(row[k]) + delta)
    with dst.open("w", newline="") as f:
        f.write(",".join(f'"{n}"' for n in rows[0]) + "\n")
        for row in rows[1:]:
            f.write(",".join(row) + "\n")
    return dst


# ------------------------------------------------------------------------------- run

@pytest.mark.integration
def test_run_writes_full_precision_csv(run_csv, capsys):
    header = run_csv.read_text().splitlines()[0]
    assert header.startswith('"time","slider1.x"') and '"joint6.Fy0"' in header
    assert "motion_unique" not in header  # Real outputs only
    s = read_series(run_csv)
    assert len(s.time) == 101 and s.time[-1] == pytest.approx(1.0)
    assert np.allclose(np.diff(s.time), 0.01)
    # full precision: a value written with fewer than 15 significant digits would be rounded
    digits = max(len(v.replace("-", "").replace(".", "").lstrip("0")) for v in
                 run_csv.read_text().splitlines()[50].split(","))
    assert digits >= 15


@pytest.mark.integration
def test_failed_simulation_exits_3_with_the_fmus_reason(tmp_path, capsys):
    # spring free length 0: the sliders reach the singular position K = L = O at t ~ 0.6 s
    mech = (MECH / "planar_sliders.toml").read_text().replace("free_length = 3.0", "free_length = 0.0")
    scene = _scene_copy(tmp_path / "s", "planar_none_wo4", mech_text=mech, s=("stop_time = 4.0", "stop_time = 2.0"))
    fmus = _build([scene], tmp_path / "fmus")
    assert main(["run", str(fmus["planar_none_wo4"]), "--out", str(tmp_path / "o")]) == 3
    err = capsys.readouterr().err
    # the FMU ends the run with fmi2Error and names the time (fmpy raises: no truncated result)
    assert re.search(r"stopped at t = 0\.(5[5-9]|6[0-5])\d* s", err), err
    assert "singular position" in err
    assert not (tmp_path / "o" / "planar_none_wo4.csv").exists()


# ------------------------------------------------------------------------------- compare: groups

@pytest.mark.integration
def test_compare_unique_group_exits_0(f45, tmp_path, capsys):
    out = tmp_path / "cmp"
    code = main(["compare", str(f45["planar_f45_wo4"].parent), "--group", "planar_f45", "--stop-time", "1",
                 "--out", str(out)])
    text = capsys.readouterr().out
    assert code == 0, text
    assert "planar_f45: observed UNIQUE, predicted unique (pre-check)" in text and "-- OK" in text
    assert "largest difference relative to its tolerance (lockstep)" in text
    assert "adaptive runs' largest difference (not deciding)" in text
    assert (out / "lockstep" / "planar_f45_wo4.csv").is_file()
    report = (out / "report.md").read_text()
    assert "| planar_sliders | planar_f45 (joint4, joint5) | Φ4; Φ6 | unique | unique |" in report
    assert "without eq. 4" in report and "Tolerance:" in report
    assert (out / "planar_f45_wo4.csv").is_file() and (out / "planar_f45_wo6.csv").is_file()
    pngs = list(out.glob("planar_f45_*.png"))
    assert pngs and pngs[0].stat().st_size > 10_000


@pytest.mark.integration
def test_group_differing_by_1e5_m_is_not_unique(tmp_path, capsys):
    """Two no-friction variants (predicted unique) whose slider 1 mass differs by 5e-5 relative:
    x1 differs by ~1e-5 m within 1 s -> observed not unique, MISMATCH, exit 1."""
    base = (MECH / "planar_sliders.toml").read_text()
    a = _scene_copy(tmp_path / "a", "planar_none_wo4")
    b = _scene_copy(tmp_path / "b", "planar_none_wo6", mech_text=base.replace("mass = 3.0", "mass = 3.00015", 1))
    fmus = _build([a, b], tmp_path / "fmus")
    out = tmp_path / "cmp"
    code = main(["compare", *map(str, fmus.values()), "--stop-time", "1", "--out", str(out)])
    text = capsys.readouterr().out
    assert code == 1, text
    assert "!!! MISMATCH !!! planar_none: observed NOT UNIQUE but the pre-check predicted unique" in text
    series = [read_series(out / f"{n}.csv") for n in ("planar_none_wo4", "planar_none_wo6")]
    diff = np.max(np.abs(series[0].values["slider1.x"] - series[1].values["slider1.x"]))
    assert 5e-6 < diff < 3e-5
    assert "MISMATCH" in (out / "report.md").read_text()


@pytest.mark.parametrize("value", ["-1", "nan", "2", "1e-9"])
def test_lockstep_step_out_of_range_exits_2(f45, tmp_path, capsys, value):
    code = main(["compare", str(f45["planar_f45_wo4"].parent), f"--lockstep-step={value}", "--out", str(tmp_path / "o")])
    assert code == 2
    assert "--lockstep-step" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


@pytest.mark.integration
def test_lockstep_off_decides_on_the_adaptive_runs(f45, tmp_path, capsys):
    out = tmp_path / "cmp"
    assert main(["compare", str(f45["planar_f45_wo4"].parent), "--group", "planar_f45", "--stop-time", "0.5",
                 "--lockstep-step", "0", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "largest difference relative to its tolerance (adaptive)" in text
    assert "adaptive runs' largest difference" not in text
    assert not (out / "lockstep").exists()


@pytest.mark.integration
def test_compare_reports_every_group_when_one_run_fails(f45, tmp_path, capsys):
    """A group whose run fails (joint 4 with mu = 1e6 jams at once) is reported as FAILED with the
    reason; the healthy group keeps its verdict, report.md is written, and the exit code is 3."""
    mech = (MECH / "planar_sliders.toml").read_text().replace("mu = 0.1", "mu = 1e6", 1)
    broken = [_regrouped(tmp_path / "b", f"planar_f45_wo{k}", "broken", f"broken_wo{k}", mech_text=mech)
              for k in (4, 6)]
    fmus = _build(broken, tmp_path / "fmus")
    out = tmp_path / "cmp"
    code = main(["compare", *map(str, fmus.values()), *map(str, f45.values()), "--stop-time", "0.5",
                 "--out", str(out)])
    captured = capsys.readouterr()
    assert code == 3, captured.out
    assert "planar_f45: observed UNIQUE, predicted unique (pre-check)" in captured.out
    assert "!!! FAILED !!! broken: no verdict, a run failed" in captured.out
    assert "simulation failed for: broken" in captured.err
    report = (out / "report.md").read_text()
    assert "**FAILED** (no verdict)" in report and "| planar_f45 (joint4, joint5) |" in report


@pytest.mark.integration
def test_group_without_one_friction_set_is_not_compared_and_the_others_are(f45, tmp_path, capsys):
    """Two scenes in one group with different friction sets are a user's mistake, not a pre-check
    failure: that group is reported as not compared (exit 2), the healthy group keeps its verdict."""
    a = _regrouped(tmp_path / "a", "planar_f45_wo4", "mixed", "mixed_wo4")
    b = _regrouped(tmp_path / "b", "planar_none_wo6", "mixed", "mixed_wo6")
    fmus = _build([a, b], tmp_path / "fmus")
    out = tmp_path / "cmp"
    code = main(["compare", *map(str, fmus.values()), *map(str, f45.values()), "--stop-time", "0.2",
                 "--out", str(out)])
    captured = capsys.readouterr()
    assert code == 2, captured.out
    assert "!!! NOT COMPARED !!! mixed: group mixed: the FMUs do not share one friction set" in captured.out
    assert "planar_f45: observed UNIQUE, predicted unique (pre-check)" in captured.out
    assert not (out / "mixed_wo4.csv").exists()
    assert "**not compared** (invalid group)" in (out / "report.md").read_text()


@pytest.mark.integration
def test_failed_adaptive_runs_keep_the_lockstep_verdict(f45, tmp_path, capsys):
    """A budget of 2 internal steps per communication step is too small for dopri5 at tolerance
    1e-14 but enough for the lockstep grid (2 rk4 steps per 10 ms): the verdict stands, the failed
    adaptive runs are reported loudly, exit 3."""
    out = tmp_path / "cmp"
    code = main(["compare", *map(str, f45.values()), "--stop-time", "0.2", "--out", str(out),
                 "--set", "solver.tolerance=1e-14", "--set", "solver.max_internal_steps=2"])
    captured = capsys.readouterr()
    assert code == 3, captured.out
    assert "planar_f45: observed UNIQUE, predicted unique (pre-check)" in captured.out
    assert "ADAPTIVE RUN FAILED (verdict from the lockstep runs)" in captured.out
    assert "max_internal_steps" in captured.out
    assert "adaptive runs FAILED" in (out / "report.md").read_text()


@pytest.mark.parametrize("setting, message", [
    ("joint4.muu=0.2", "--set joint4.muu: no such parameter"),
    ("joint4.mu=abc", "--set joint4.mu=abc: not a valid Real value"),
    ("joint4.mu", "expected NAME=VALUE"),
])
def test_bad_set_exits_2_before_running(f45, tmp_path, capsys, setting, message):
    assert main(["compare", *map(str, f45.values()), "--set", setting, "--out", str(tmp_path / "o")]) == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "o" / "planar_f45_wo4.csv").exists()


@pytest.mark.parametrize("args", [["--step", "1e-9", "--stop-time", "0.1"], ["--stop-time", "1e9"]])
def test_run_refuses_unbounded_output_grids(f45, tmp_path, capsys, args):
    assert main(["run", str(f45["planar_f45_wo4"]), *args, "--out", str(tmp_path / "o")]) == 2
    assert "output points; at most 1e+06" in capsys.readouterr().err


@pytest.mark.integration
def test_set_reaches_the_fmu(f45, tmp_path, capsys):
    """--set joint4.mu=0.3 changes the motion of a run (against the default 0.1)."""
    base, changed = tmp_path / "base", tmp_path / "changed"
    fmu = str(f45["planar_f45_wo4"])
    assert main(["run", fmu, "--stop-time", "0.5", "--out", str(base)]) == 0
    assert main(["run", fmu, "--stop-time", "0.5", "--out", str(changed), "--set", "joint4.mu=0.3"]) == 0
    a, b = (read_series(d / "planar_f45_wo4.csv").values["slider1.x"] for d in (base, changed))
    assert np.max(np.abs(a - b)) > 1e-6


# ------------------------------------------------------------------------------- compare: reference

@pytest.mark.integration
def test_reference_mode_same_result_passes_and_1e6_m_is_caught(f45, run_csv, tmp_path, capsys):
    fmu = str(f45["planar_f45_wo4"])
    assert main(["compare", fmu, "--ref", str(run_csv), "--out", str(tmp_path / "same")]) == 0
    assert "WITHIN TOLERANCE" in capsys.readouterr().out
    shifted = _shifted_csv(run_csv, tmp_path / "shifted.csv", "slider1.x", 1e-6)
    code = main(["compare", fmu, "--ref", str(shifted), "--out", str(tmp_path / "shifted")])
    text = capsys.readouterr().out
    assert code == 1, text
    assert "DIFFERS" in text and "slider1.x" in text
    # the default tolerance at this scale is well below 1e-6 m
    assert uniqueness_tolerance(inspect_fmu(fmu).tolerance, 2.0) < 0.5e-6


def test_default_tolerance_catches_1e6_m_at_slider_scale():
    """Every planar slider position stays within |y| <= 3 m; the spatial platform within 2.5 m.
    Both the lockstep verdict and the adaptive fallback catch a 1e-6 m change there."""
    from overcon.paper import scene_groups

    tolerances = {spec.solver.tolerance for items in scene_groups(MECH).values() for _, spec in items}
    for scale in (1.0, 2.0, 3.0, 2.5):
        assert lockstep_tolerance(scale) < 1e-6
        for tol in tolerances:
            assert uniqueness_tolerance(tol, scale) < 1e-6


# ------------------------------------------------------------------------------- bad input: exit 2

def test_missing_fmu_file_exits_2(tmp_path, capsys):
    missing = tmp_path / "nope.fmu"
    for cmd in (["compare", str(missing), str(missing)], ["run", str(missing)]):
        assert main([*cmd, "--out", str(tmp_path / "o")]) == 2
        err = capsys.readouterr().err
        assert f"{missing}: no such FMU file" in err


def test_corrupt_zip_exits_2(tmp_path, capsys, f45):
    garbage = tmp_path / "garbage.fmu"
    garbage.write_bytes(b"this is not a zip archive" * 10)
    truncated = tmp_path / "truncated.fmu"
    data = f45["planar_f45_wo4"].read_bytes()
    truncated.write_bytes(data[: len(data) // 2])
    for bad in (garbage, truncated):
        assert main(["compare", str(bad), str(f45["planar_f45_wo6"]), "--out", str(tmp_path / "o")]) == 2
        err = capsys.readouterr().err
        assert str(bad) in err and "not an FMU (not a zip archive" in err
    nomd = tmp_path / "nomd.fmu"
    with zipfile.ZipFile(nomd, "w") as zf:
        zf.writestr("resources/x.txt", "x")
    assert main(["run", str(nomd), "--out", str(tmp_path / "o")]) == 2
    assert f"{nomd}: cannot read modelDescription.xml" in capsys.readouterr().err


def test_fmus_without_common_outputs_exit_2(tmp_path, capsys):
    a = _scene_copy(tmp_path / "a", "planar_none_wo4",
                    p=("positions = [", 'positions = ["slider1.x"]\n#'), r=('reactions = "all"', "reactions = []"))
    b = _scene_copy(tmp_path / "b", "planar_none_wo6",
                    p=("positions = [", 'positions = ["slider2.y"]\n#'), r=('reactions = "all"', "reactions = []"))
    fmus = _build([a, b], tmp_path / "fmus")
    assert main(["compare", *map(str, fmus.values()), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "no common outputs" in err and "planar_none_wo4.fmu has slider1.x" in err
    assert not (tmp_path / "o" / "planar_none_wo4.csv").exists()  # refused before running


def test_mismatched_time_grids_exit_2(tmp_path, capsys, f45, run_csv):
    a = _scene_copy(tmp_path / "a", "planar_none_wo4")
    b = _scene_copy(tmp_path / "b", "planar_none_wo6", s=("stop_time = 4.0", "stop_time = 3.0"))
    fmus = _build([a, b], tmp_path / "fmus")
    assert main(["compare", *map(str, fmus.values()), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "mismatched time grids in group planar_none" in err and "--stop-time and --step" in err
    # reference on another grid than the one asked for
    assert main(["compare", str(f45["planar_f45_wo4"]), "--ref", str(run_csv), "--step", "0.02",
                 "--out", str(tmp_path / "o2")]) == 2
    err = capsys.readouterr().err
    assert "mismatched time grids" in err and str(run_csv) in err
    # the library check: sample-by-sample, no interpolation
    t = np.linspace(0, 1, 11)
    with pytest.raises(InputError, match="mismatched time grids"):
        check_grids([Series(t, {}), Series(np.linspace(0, 1, 21), {})], ["a.csv", "b.csv"])


def test_unreadable_csv_exits_2(tmp_path, capsys, f45):
    fmu = str(f45["planar_f45_wo4"])
    bad = tmp_path / "bad.csv"
    bad.write_text('"time","slider1.x"\n0.0,abc\n0.01,2.0\n')
    missing = tmp_path / "missing.csv"
    ragged = tmp_path / "ragged.csv"
    ragged.write_text('"time","slider1.x"\n0.0,2.0\n0.01\n')
    for path in (bad, missing, ragged):
        assert main(["compare", fmu, "--ref", str(path), "--out", str(tmp_path / "o")]) == 2
        err = capsys.readouterr().err
        assert str(path) in err
    other = tmp_path / "other.csv"
    other.write_text('"time","foo"\n0.0,1.0\n0.01,1.0\n')
    assert main(["compare", fmu, "--ref", str(other), "--out", str(tmp_path / "o")]) == 2
    assert "no common outputs" in capsys.readouterr().err


def test_single_fmu_without_reference_exits_2(f45, tmp_path, capsys):
    assert main(["compare", str(f45["planar_f45_wo4"]), "--out", str(tmp_path / "o")]) == 2
    assert "nothing to compare" in capsys.readouterr().err


def test_unknown_group_exits_2(f45, tmp_path, capsys):
    assert main(["compare", str(f45["planar_f45_wo4"].parent), "--group", "nope", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "--group nope: no such group" in err and "(groups: planar_f45)" in err


# ------------------------------------------------------------------------------- verdict rules

def test_reactions_do_not_decide_and_prediction_must_agree(f45):
    infos = [inspect_fmu(f45["planar_f45_wo4"]), inspect_fmu(f45["planar_f45_wo6"])]
    assert infos[0].label == "without eq. 4 of joint2" and infos[0].group == "planar_f45" and infos[0].motion_unique
    assert infos[0].reaction_unique["joint4"] and not infos[0].reaction_unique["joint1"]
    t = np.linspace(0, 1, 11)

    def series(shift_pos=0.0, shift_reaction=0.0):
        vals = {o.name: np.full_like(t, 1.0) for o in infos[0].outputs}
        vals["slider1.x"] = vals["slider1.x"] + shift_pos
        vals["joint1.T"] = vals["joint1.T"] + shift_reaction
        return Series(t, vals)

    c = compare_group("planar_f45", infos, [series(), series(shift_reaction=50.0)])
    assert c.observed and c.matches  # a non-unique reaction differing does not make the motion non-unique
    d = {x.name: x for x in c.diffs}
    assert not d["joint1.T"].decides and d["joint1.T"].max_abs == 50.0 and d["joint1.T"].first_exceed == 0.0
    c = compare_group("planar_f45", infos, [series(), series(shift_pos=1e-6)])
    assert not c.observed and not c.matches
    assert {x.name: x for x in c.diffs}["slider1.x"].first_exceed == 0.0


# ------------------------------------------------------------------------------- reproduce

@pytest.mark.integration
def test_reproduce_planar_set(tmp_path, capsys):
    mech = tmp_path / "mech"
    mech.mkdir()
    for f in MECH.glob("planar_*.toml"):
        shutil.copy(f, mech / f.name)
    out = tmp_path / "repro"
    code = main(["reproduce", "--mechanisms", str(mech), "--out", str(out), "--stop-time", "1"])
    text = capsys.readouterr().out
    assert code == 0, text
    assert "every observed verdict equals its prediction" in text and f"report: {out / 'report.md'}" in text
    assert "pre-check: friction in joint1: friction on non-unique reaction(s) of joint1, motion NOT UNIQUE" in text
    report = (out / "report.md").read_text()
    for group, verdict in (("planar_none (none)", "unique | unique"), ("planar_f45 (joint4, joint5)", "unique | unique"),
                           ("planar_f1 (joint1)", "not unique | not unique"),
                           ("planar_f145 (joint1, joint4, joint5)", "not unique | not unique")):
        assert f"| planar_sliders | {group} | Φ4; Φ6 | {verdict} |" in report
    for fig in ("fig3", "fig4", "fig5"):
        assert (out / f"{fig}.png").stat().st_size > 10_000 and f"]({fig}.png)" in report
    assert not (out / "fig7.png").exists()  # spatial figures: not in this set
    assert len(list((out / "groups").glob("*.png"))) == 4
    assert len(list((out / "fmus").glob("*.fmu"))) == 8
    # the report shows the paper mechanism's drawing (overcon draw)
    assert "## The mechanisms" in report and "](mechanisms/planar_sliders.png)" in report
    assert (out / "mechanisms" / "planar_sliders.png").stat().st_size > 5_000


def test_one_group_needs_one_prediction(f45, tmp_path, capsys):
    """--one-group pools FMUs of different groups; they must share one friction set (and so one
    prediction), checked before running."""
    f1 = _build([MECH / "planar_f1_wo4.toml"], tmp_path / "fmus")["planar_f1_wo4"]
    assert main(["compare", str(f45["planar_f45_wo4"]), str(f1), "--out", str(tmp_path / "o")]) == 2
    assert "nothing to compare" in capsys.readouterr().err  # two groups of one FMU each
    assert main(["compare", str(f45["planar_f45_wo4"]), str(f1), "--one-group", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "do not share one friction set" in err and "planar_f1_wo4.fmu: joint1" in err
    assert not (tmp_path / "o" / "planar_f1_wo4.csv").exists()


def test_tooling_does_not_import_the_engine():
    """The fmpy black-box layer must not load the engine: importing every tooling module in a
    fresh interpreter leaves paper, simulate, model and dynamics unloaded."""
    import subprocess
    import sys
    code = ("import pkgutil, sys, overcon.tooling as t\n"
            "for m in pkgutil.iter_modules(t.__path__): __import__('overcon.tooling.' + m.name)\n"
            "print(' '.join(sorted(sys.modules)))")
    loaded = set(subprocess.run([sys.executable, "-c", code], check=True, capture_output=True,
                                text=True).stdout.split())
    assert "overcon.tooling.sweep" in loaded and "overcon.tooling.pipeline" in loaded
    engine = {f"overcon.{m}" for m in ("paper", "simulate", "model", "dynamics")}
    assert not engine & loaded, engine & loaded



# ------------------------------------------------------------------------------- the FMU's facts record

def _rewritten(src: Path, dst: Path, drop=(), replace=None) -> Path:
    """Copy of the FMU ``src`` without the entries ``drop``, with ``replace`` {name: bytes}."""
    replace = replace or {}
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dst, "w") as zout:
        for item in zin.infolist():
            if item.filename not in drop:
                zout.writestr(item, replace.get(item.filename, zin.read(item.filename)))
    return dst


def test_facts_record_gives_what_the_bundled_scene_says(f45):
    """The tooling's facts of an overcon FMU (read from resources/overcon_facts.json) are those the
    scene file and the pre-check give: group, label, friction set, elimination, mechanism,
    predictions; the record's outputs are the modelDescription's Real outputs."""
    from overcon import scene as scene_mod
    from overcon.checks import compile_checked
    from overcon.fmu import facts as facts_mod
    from overcon.precheck import precheck
    from overcon.verdict import equation_joints, variant_label

    for name, fmu in f45.items():
        spec = scene_mod.load(MECH / f"{name}.toml")
        report = precheck(compile_checked(spec), name)
        info = inspect_fmu(fmu)
        assert (info.group, info.label, info.friction, info.eliminate, info.mechanism) == (
            spec.group, variant_label(spec.eliminate, equation_joints(compile_checked(spec).joints)),
            tuple(spec.friction), spec.eliminate, spec.mechanism.name)
        assert info.motion_unique is report.motion_unique and info.reaction_unique == report.reaction_unique
        with zipfile.ZipFile(fmu) as zf:
            facts = facts_mod.decode(zf.read(facts_mod.PATH), str(fmu))
        assert facts["outputs"] == tuple(info.output_names)
        assert facts["solver"]["method"] == spec.solver.method and facts["solver"]["stop_time"] == spec.stop_time


def test_overcon_fmu_without_facts_record_is_refused(f45, tmp_path):
    old = _rewritten(f45["planar_f45_wo4"], tmp_path / "old.fmu", drop={"resources/overcon_facts.json"})
    with pytest.raises(InputError, match=r"old\.fmu: an overcon FMU without its facts record "
                                         r"resources/overcon_facts\.json .*rebuild it"):
        inspect_fmu(old)


def test_facts_record_of_another_format_is_refused(f45, tmp_path):
    src = f45["planar_f45_wo4"]
    with zipfile.ZipFile(src) as zf:
        data = zf.read("resources/overcon_facts.json").replace(b'"format": 1', b'"format": 2')
    newer = _rewritten(src, tmp_path / "newer.fmu", replace={"resources/overcon_facts.json": data})
    with pytest.raises(InputError, match=r"newer\.fmu: resources/overcon_facts\.json has format 2; "
                                         r"this overcon reads format 1"):
        inspect_fmu(newer)
    broken = _rewritten(src, tmp_path / "broken.fmu",
                        replace={"resources/overcon_facts.json": data.replace(b'"format": 2', b'"format": 1')
                                 .replace(b'"group"', b'"grup"')})
    with pytest.raises(InputError, match=r"broken\.fmu: resources/overcon_facts\.json: key 'group' missing"):
        inspect_fmu(broken)


def test_fmu_of_another_tool_joins_the_fmus_group_without_prediction(f45, tmp_path):
    """Without resources/overcon_fmu.json an FMU is another tool's: group ``fmus``, labelled with its
    model name; its predictions come only from constant outputs it declares (overcon's do)."""
    foreign = _rewritten(f45["planar_f45_wo4"], tmp_path / "foreign.fmu",
                         drop={"resources/overcon_facts.json", "resources/overcon_fmu.json"})
    info = inspect_fmu(foreign)
    assert (info.group, info.label, info.friction, info.eliminate, info.mechanism) == (
        "fmus", "planar_f45_wo4", (), None, "")


# ------------------------------------------------------------------------------- lockstep stability

STICKING = ROOT / "tests" / "data" / "sticking"


@pytest.mark.integration
def test_unstable_lockstep_step_is_repeated_smaller_and_the_verdict_holds(tmp_path):
    """The handle's friction sticks inside its regularisation band at once: rk4 at the default 5 ms
    is beyond its stability boundary there (its chatter made this unique group look NOT unique).
    The rk4 integrator refuses the step; compare repeats the group's lockstep runs at the stable
    step the refusal names (0.8 ms) and gets the predicted verdict, saying so."""
    fmus = _build([STICKING / "handle_a.toml", STICKING / "handle_b.toml"], tmp_path / "fmus")
    from overcon.tooling.pipeline import compare_paths
    out = compare_paths(list(fmus.values()), tmp_path / "cmp", echo=lambda s: None)
    (c,) = out.comparisons
    assert c.failure is None and c.mode == "lockstep"
    assert c.lockstep_step == pytest.approx(8e-4)
    assert "rk4 unstable at the lockstep step 0.005 s" in c.lockstep_note and "repeated at 0.0008 s" in c.lockstep_note
    assert c.predicted is True and c.observed is True and c.matches
    assert max(d.max_abs for d in c.diffs if d.decides) < 1e-12
    assert "repeated at 0.0008 s" in (tmp_path / "cmp" / "report.md").read_text()


def test_predicted_not_unique_observed_unique_is_consistent_not_a_mismatch(f45):
    """The pre-check's condition is one-directional: friction on a non-unique reaction lets the
    motion depend on the elimination, and loads that never reach the non-unique part leave the
    eliminations equal. Such a group is reported as "not excited" and counts as consistent."""
    from overcon.tooling.report import verdict_line
    infos = [inspect_fmu(f45[n]) for n in ("planar_f45_wo4", "planar_f45_wo6")]
    t = np.linspace(0.0, 1.0, 11)

    def series(shift=0.0):
        vals = {o.name: np.full_like(t, 1.0) for o in infos[0].outputs}
        vals["slider1.x"] = vals["slider1.x"] + shift
        return Series(t, vals)

    same = [series(), series()]
    c = compare_group("planar_f45", infos, same, lockstep=same, lockstep_step=5e-3)
    c.predicted = False
    assert c.observed and c.not_excited and c.matches
    assert "OK (not excited" in verdict_line(c)
    c.predicted = True
    assert not c.not_excited and c.matches
    moved = [series(), series(1e-3)]
    d = compare_group("planar_f45", infos, moved, lockstep=moved, lockstep_step=5e-3)
    d.predicted = True
    assert not d.observed and not d.matches and "MISMATCH" in verdict_line(d)
