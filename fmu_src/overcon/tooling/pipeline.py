"""The commands as library functions: run FMUs, compare groups or against a reference, and the
main job :func:`reproduce` (build every paper scene, pre-check, run, compare, report).

Each returns data (results, comparisons); printing goes through ``echo``; bad input raises
:class:`~overcon.tooling.InputError`, a failed simulation :class:`~overcon.tooling.SimulationFailed`.
"""
from __future__ import annotations

import dataclasses
import math
import os
import platform
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from . import InputError
from ..figures import PAPER_GROUPS
from ..outfiles import write_text_atomic
from ..verdict import LOCKSTEP_MIN_STEP, LOCKSTEP_STEP, LockstepGrid, lockstep_start_values
from .compare import (Comparison, compare_group, compare_reference, failed_group, group_fmus, invalid_group,
                      order_groups, read_along, validate_group)
from .fmus import FmuInfo, inspect_all, inspect_fmu
from .report import console_table, markdown, plot_comparison, verdict_line
from .run import (Experiment, Job, RunResult, along_path, check_unique_models, experiment, read_series, run_fmus,
                  run_jobs, start_values_for, with_inputs)


def _echo(s: str) -> None:
    print(s, flush=True)


def _same_experiment(a: Experiment, b: Experiment) -> bool:
    return all(math.isclose(x, y, rel_tol=1e-12, abs_tol=1e-12) for x, y in
               ((a.start, b.start), (a.stop, b.stop), (a.step, b.step)))


def run_paths(paths, out_dir, *, stop_time=None, step=None, jobs: int = 2, echo=_echo,
              settings: dict | None = None, input_table=None, interpolation: str = "hold") -> list[RunResult]:
    """``overcon run``: every FMU (files, or the *.fmu of directories) to ``out_dir/<model>.csv``;
    ``settings`` (``--set``): FMU parameters (or inputs' start values) set in every run;
    ``input_table`` (``--input``, a CSV path): the table of every FMU's inputs, held over each
    communication step or, ``interpolation`` "linear", linear in it (:mod:`overcon.tooling.inputs`)."""
    infos = inspect_all(paths)
    exps = {i.model: with_inputs(i, dataclasses.replace(experiment(i, stop_time=stop_time, step=step),
                                                        start_values=tuple(start_values_for(i, settings or {}).items())),
                                 input_table, interpolation)
            for i in infos}
    return run_fmus(infos, out_dir, jobs=jobs, echo=echo, experiments=exps)


class _Verdicts:
    """The groups of an outcome by what became of them (``comparisons``: list of Comparison)."""

    comparisons: list[Comparison]

    @property
    def failed(self) -> list[Comparison]:
        """Groups with a failed simulation (no verdict, or a verdict without the adaptive runs)."""
        return [c for c in self.comparisons if c.run_failed]

    @property
    def invalid(self) -> list[Comparison]:
        """Groups that were not run: their FMUs do not form a group."""
        return [c for c in self.comparisons if c.invalid]


@dataclass
class CompareOutcome(_Verdicts):
    comparisons: list[Comparison]
    report: Path
    plots: dict = field(default_factory=dict)  # group -> [png]
    skipped: list[str] = field(default_factory=list)  # groups with one FMU
    results: dict = field(default_factory=dict)  # run key (model, lockstep/<model>) -> RunResult


def _select(infos: list[FmuInfo], group: str | None,
            one_group: bool = False) -> tuple[dict[str, list[FmuInfo]], list[str]]:
    """Groups to compare (those with two FMUs or more) and the names of single-FMU groups."""
    groups = group_fmus(infos)
    if group is not None:
        if group not in groups:
            raise InputError(f"--group {group}: no such group among the FMUs given (groups: "
                             f"{', '.join(sorted(groups))})")
        groups = {group: groups[group]}
    if one_group:
        pooled = [i for items in groups.values() for i in items]
        groups = order_groups({"+".join(groups): pooled})
    singles = [g for g, v in groups.items() if len(v) < 2]
    runnable = {g: v for g, v in groups.items() if len(v) >= 2}
    if not runnable:
        only = "; ".join(f"group {g}: {v[0].path}" for g, v in groups.items())
        raise InputError(f"nothing to compare: every group has a single FMU ({only}); give at least two "
                         "FMUs of one group, or one FMU with --ref CSV")
    return runnable, singles


def _longest_first(jobs: list[Job]) -> list[Job]:
    """Run order for the worker pool: longest runs first (simulated time, then lockstep runs, then
    friction joints), so that no long run starts last on an otherwise idle pool."""
    return sorted(jobs, key=lambda j: (-(j.experiment.stop - j.experiment.start), not j.key.startswith("lockstep/"),
                                       -len(j.info.friction)))


def _check_lockstep_step(h: float | None) -> float | None:
    if h is not None and not (math.isfinite(h) and LOCKSTEP_MIN_STEP <= h <= 1.0):
        raise InputError(f"--lockstep-step {h!r}: must be a step in s between {LOCKSTEP_MIN_STEP:g} and 1")
    return h


def _run_and_compare(groups: dict[str, list[FmuInfo]], exps: dict[str, Experiment], out_dir: Path, *,
                     jobs: int, lockstep_step: float | None, tolerance: float | None,
                     echo, settings: dict | None = None, input_table=None,
                     interpolation: str = "hold") -> tuple[list[Comparison], dict[str, RunResult]]:
    """Run every FMU of every group (adaptive, into ``out_dir/<model>.csv``) and, for groups whose
    FMUs all take the lockstep parameters and unless ``lockstep_step`` is None, once more on the
    lockstep grid (``out_dir/lockstep/<model>.csv``); compare each group. ``settings``: FMU
    parameters set in every run (``--set``; the lockstep runs' ``solver.method``/``solver.step`` win);
    ``input_table``, ``interpolation``: the ``--input`` table of every run, adaptive and lockstep.

    Failures: a failed deciding run (lockstep; adaptive without lockstep) makes its group a failed
    comparison with the reason; a failed adaptive run beside successful lockstep runs keeps the
    verdict and is reported (``Comparison.adaptive_failure``). The other groups are still compared.
    A group whose lockstep runs failed on an unstable rk4 step has all its lockstep runs repeated at
    a smaller common step, as :class:`overcon.verdict.LockstepGrid` (the one procedure) decides;
    the step used is reported."""
    user = {i.model: start_values_for(i, settings or {}) for items in groups.values() for i in items}
    check_unique_models([i for items in groups.values() for i in items], out_dir)
    todo, lock_groups = [], set()
    for g, items in groups.items():
        use_lock = lockstep_step is not None and all(i.lockstep for i in items)
        if use_lock:
            lock_groups.add(g)
        elif lockstep_step is not None and any(i.real_inputs and i.motion_unique is not None for i in items):
            echo(f"{g}: FMUs with inputs refuse rk4, the method of the lockstep runs: verdict from the adaptive "
                 "runs (not lockstep)")
        elif lockstep_step is not None:
            echo(f"{g}: not every FMU has the parameters solver.method and solver.step: verdict from the "
                 "adaptive runs (not lockstep)")
        for i in items:
            ex = with_inputs(i, dataclasses.replace(exps[i.model], start_values=tuple(user[i.model].items())),
                             input_table, interpolation)
            todo.append(Job(i.model, i, ex, out_dir / f"{i.model}.csv", along=True))
    grids = {g: LockstepGrid(lockstep_step) for g in lock_groups}
    todo += _lockstep_jobs({g: groups[g] for g in lock_groups}, grids, todo, user, out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    results, failures = run_jobs(_longest_first(todo), workers=jobs, echo=echo, announce_failures=False)
    announced: set[str] = set()
    while True:
        steps = {g: grids[g].step for g in lock_groups}
        retry = {g: groups[g] for g in lock_groups if _lockstep_retry(grids[g], groups[g], failures, echo, g)}
        for g, items in retry.items():
            for i in items:
                key = f"lockstep/{i.model}"
                if key in failures:  # not a failure of the comparison: the run is taken again
                    echo(f"{key}: repeated at step {grids[g].step:g} s (rk4 unstable at {steps[g]:g} s)")
                failures.pop(key, None)
                results.pop(key, None)
        _announce(failures, announced, echo)
        if not retry:
            break
        more, more_failures = run_jobs(_longest_first(_lockstep_jobs(retry, grids, todo, user, out_dir)),
                                       workers=jobs, echo=echo, announce_failures=False)
        results.update(more)
        failures.update(more_failures)
    comparisons = []
    for g, items in groups.items():
        adaptive_failed = [str(failures[i.model]) for i in items if i.model in failures]
        lock_failed = [str(failures[k]) for k in (f"lockstep/{i.model}" for i in items) if k in failures]
        from_lockstep = bool(adaptive_failed) and g in lock_groups and not lock_failed
        along = _along(items, out_dir, failures, adaptive=not from_lockstep)
        if lock_failed or (adaptive_failed and g not in lock_groups):
            comparisons.append(failed_group(g, items, "\n".join(lock_failed + adaptive_failed)))
            comparisons[-1].along = along
            continue
        series = None if adaptive_failed else [read_series(results[i.model].csv) for i in items]
        lock = [read_series(results[f"lockstep/{i.model}"].csv) for i in items] if g in lock_groups else None
        c = compare_group(g, items, series, tolerance=tolerance, lockstep=lock,
                          lockstep_step=grids[g].step if lock is not None else None,
                          adaptive_failure="\n".join(adaptive_failed) or None)
        c.lockstep_note = grids[g].note if g in grids else None
        c.along = along
        c.wall_seconds = [] if adaptive_failed else [results[i.model].sim_seconds for i in items]
        comparisons.append(c)
    return comparisons, results


def _announce(failures: dict, announced: set, echo) -> None:
    """Say each failed run that is not taken again, once: its group has no verdict (or, for an
    adaptive run beside lockstep ones, a reported failure); the reason follows in the report."""
    for key in failures:
        if key not in announced:
            announced.add(key)
            echo(f"{key}: FAILED (reason below)")


def _along(items: list[FmuInfo], out_dir: Path, failures: dict, *, adaptive: bool) -> list:
    """Per FMU of a group, the :class:`~overcon.tooling.compare.Along` of its adaptive runs (of its
    lockstep runs when ``adaptive`` is False: the adaptive ones failed and those did not), None for an FMU without
    the discrete outputs (:mod:`overcon.tooling.compare`, rules)."""
    out = []
    for i in items:
        key = i.model if adaptive else f"lockstep/{i.model}"
        csv = out_dir / f"{i.model}.csv" if adaptive else out_dir / "lockstep" / f"{i.model}.csv"
        out.append(read_along(along_path(csv), failed=key in failures))
    return out


def _lockstep_retry(grid: LockstepGrid, items: list[FmuInfo], failures: dict, echo, group: str) -> bool:
    """The group's lockstep runs failed and ``grid`` (the one procedure) repeats them."""
    failed = [failures[k] for k in (f"lockstep/{i.model}" for i in items) if k in failures]
    if not failed or not grid.retry([f.stable_step for f in failed]):
        return False
    echo(f"{group}: {grid.note}")
    return True


def _lockstep_jobs(groups: dict[str, list[FmuInfo]], grids: dict[str, LockstepGrid], adaptive: list[Job], user: dict,
                   out_dir: Path) -> list[Job]:
    """The lockstep runs of ``groups``: each FMU's adaptive experiment (from ``adaptive``) with the
    lockstep parameters at its group's step (the user's ``--set`` values kept otherwise)."""
    exp_of = {j.key: j.experiment for j in adaptive}
    out = []
    for g, items in groups.items():
        for i in items:
            values = {**user[i.model], **lockstep_start_values(grids[g].step)}
            lex = dataclasses.replace(exp_of[i.model], start_values=tuple(values.items()))
            out.append(Job(f"lockstep/{i.model}", i, lex, out_dir / "lockstep" / f"{i.model}.csv", along=True))
    return out


def _valid_groups(groups: dict[str, list[FmuInfo]], echo) -> tuple[dict[str, list[FmuInfo]], list[Comparison]]:
    """(groups that can be compared, invalid groups as not-run comparisons); before any run.
    :class:`InputError` when no group is valid."""
    valid, invalid = {}, []
    for g, items in groups.items():
        try:
            validate_group(g, items)
        except InputError as exc:
            invalid.append(invalid_group(g, items, str(exc)))
            echo(f"{g}: not compared: {exc}")
            continue
        valid[g] = items
    if not valid:
        raise InputError("\n".join(c.failure for c in invalid))
    return valid, invalid


def _group_experiments(groups: dict[str, list[FmuInfo]], stop_time, step) -> dict[str, Experiment]:
    exps = {}
    for g, items in groups.items():
        ex = {i.model: experiment(i, stop_time=stop_time, step=step) for i in items}
        first = items[0]
        for i in items[1:]:
            if not _same_experiment(ex[first.model], ex[i.model]):
                a, b = ex[first.model], ex[i.model]
                raise InputError(
                    f"mismatched time grids in group {g}: {first.path} runs t = {a.start:g}..{a.stop:g} s every "
                    f"{a.step:g} s, {i.path} t = {b.start:g}..{b.stop:g} s every {b.step:g} s (their "
                    "DefaultExperiments differ); results are compared sample by sample (no interpolation): "
                    "give --stop-time and --step to run them on one grid")
        exps.update(ex)
    return exps


def compare_paths(paths, out_dir, *, group: str | None = None, one_group: bool = False,
                  tolerance: float | None = None, stop_time=None, step=None, jobs: int = 2, plots="worst",
                  echo=_echo, title: str = "overcon compare",
                  lockstep_step: float | None = LOCKSTEP_STEP, settings: dict | None = None,
                  input_table=None, interpolation: str = "hold") -> CompareOutcome:
    """``overcon compare``: group the FMUs by scene group (``one_group``: all of them together),
    run them (adaptive, and in lockstep for the verdict unless ``lockstep_step`` is None), compare
    each group, write ``out_dir/report.md`` and the PNGs. FMUs of one group share a
    DefaultExperiment (or ``--stop-time``/``--step`` put them on one grid). A failed run does not
    stop the others: its group is reported as FAILED (``CompareOutcome.failed``). ``input_table``
    (``--input``), ``interpolation``: as :func:`run_paths`, the same table for every FMU."""
    if tolerance is not None and not (math.isfinite(tolerance) and tolerance > 0):
        raise InputError(f"--tolerance {tolerance!r}: must be a positive finite number")
    _check_lockstep_step(lockstep_step)
    out_dir = Path(out_dir)
    infos = _dedupe(inspect_all(paths))
    groups, singles = _select(infos, group, one_group)
    for g in singles:
        echo(f"{g}: one FMU only, skipped (nothing to compare it with)")
    groups, invalid = _valid_groups(groups, echo)  # before any run: outputs, one friction set, one prediction
    exps = _group_experiments(groups, stop_time, step)
    comparisons, results = _run_and_compare(groups, exps, out_dir, jobs=jobs, lockstep_step=lockstep_step,
                                            tolerance=tolerance, echo=echo, settings=settings,
                                            input_table=input_table, interpolation=interpolation)
    comparisons += invalid
    plot_files = {c.group: plot_comparison(c, out_dir, plots) for c in comparisons}
    report = out_dir / "report.md"
    write_text_atomic(report, markdown(comparisons, out_dir, title=title, plots=plot_files), encoding="utf-8")
    for c in comparisons:
        echo("")
        echo(console_table(c))
        echo(verdict_line(c))
    return CompareOutcome(comparisons, report, plot_files, singles, results)


def _dedupe(infos: list[FmuInfo]) -> list[FmuInfo]:
    seen, out = set(), []
    for i in infos:
        key = i.path.resolve()
        if key not in seen:
            seen.add(key)
            out.append(i)
    return out


def _reference_grid(ref_time: np.ndarray, ref_path: Path) -> tuple[float, float]:
    d = np.diff(ref_time)
    if not np.allclose(d[:-1], d[0], rtol=1e-6, atol=0) or d[-1] > d[0] * (1 + 1e-6):
        raise InputError(f"mismatched time grids: {ref_path} is not on a uniform time grid, which an FMU run "
                         "cannot reproduce (no interpolation)")
    return float(ref_time[-1]), float(d[0])


def compare_with_reference(fmu, ref_csv, out_dir, *, tolerance: float | None = None, stop_time=None,
                           step=None, plots="worst", echo=_echo, input_table=None,
                           interpolation: str = "hold") -> CompareOutcome:
    """``overcon compare FMU --ref CSV``: run the FMU on the reference's grid (its last time and
    spacing, unless ``--stop-time``/``--step`` are given) and compare every common output
    (``input_table``, ``interpolation``: the FMU's ``--input``, as :func:`run_paths`)."""
    if tolerance is not None and not (math.isfinite(tolerance) and tolerance > 0):
        raise InputError(f"--tolerance {tolerance!r}: must be a positive finite number")
    out_dir = Path(out_dir)
    ref_csv = Path(ref_csv)
    ref = read_series(ref_csv)
    info = inspect_fmu(fmu)
    from ..outfiles import check_input_outside, check_out_dir, check_outputs
    why = (check_out_dir("--out", out_dir, {"--ref": ref_csv, "--input": input_table})
           or check_input_outside("--out", out_dir, "--input", input_table))
    if why:
        raise InputError(why)
    written = {"the result CSV": out_dir / f"{info.model}.csv", "the along CSV": along_path(out_dir / f"{info.model}.csv"),
               "the report": out_dir / "report.md"}
    # a missing --out is made later (check_out_dir above): its files can be no input, nor exist
    why = check_outputs(written, {"--ref": ref_csv, "--input": input_table}) if out_dir.is_dir() else None
    if why:
        raise InputError(why)
    common = [n for n in ref.names if n in info.output_names]
    if not common:
        raise InputError(f"no common outputs: {ref_csv} has {', '.join(ref.names[:4])}, {info.path} has "
                         f"{', '.join(info.output_names[:4])}")
    ref_stop, ref_step = _reference_grid(ref.time, ref_csv)
    ex = experiment(info, stop_time=ref_stop if stop_time is None else stop_time,
                    step=ref_step if step is None else step)
    n = int(round((ex.stop - ex.start) / ex.step))
    predicted = ex.start + ex.step * np.arange(n + 1)
    if len(predicted) != len(ref.time) or not np.allclose(predicted, ref.time, rtol=0, atol=1e-9 * ex.step):
        raise InputError(f"mismatched time grids: {ref_csv} has {len(ref.time)} points, t = {ref.time[0]:g}.."
                         f"{ref.time[-1]:g} s every {ref_step:g} s; {info.path} would run t = {ex.start:g}.."
                         f"{ex.stop:g} s every {ex.step:g} s (no interpolation)")
    ex = with_inputs(info, ex, input_table, interpolation)
    results = run_fmus([info], out_dir, jobs=1, echo=echo, experiments={info.model: ex})
    res = read_series(results[0].csv)
    c = compare_reference(info, res, ref, ref_csv, tolerance=tolerance)
    c.wall_seconds = [results[0].sim_seconds]
    plot_files = {c.group: plot_comparison(c, out_dir, plots)}
    report = out_dir / "report.md"
    write_text_atomic(report, markdown([c], out_dir, title="overcon compare (reference)", plots=plot_files), encoding="utf-8")
    echo("")
    echo(console_table(c))
    echo(verdict_line(c))
    return CompareOutcome([c], report, plot_files, [], {info.model: results[0]})


# ---------------------------------------------------------------------------------------------
# the main job

@dataclass
class ReproduceOutcome(_Verdicts):
    comparisons: list[Comparison]
    report: Path
    figures: list[Path]
    seconds: dict  # phase -> wall seconds
    beyond: dict = field(default_factory=dict)  # figure name -> Placement (figures beyond the paper)

    @property
    def all_match(self) -> bool:
        return all(c.matches for c in self.comparisons)


def _figures(comparisons: list[Comparison], out_dir: Path, echo) -> list[tuple[str, Path]]:
    """The paper's Figs. 3-5, 7-9 (:data:`overcon.figures.FIGURES`) from the FMU results."""
    from ..figures import FIGURES, figure_series
    from ..plots import plot_series
    from .report import shown_runs

    by_group = {c.group: c for c in comparisons if c.failure is None}
    out = []
    for fig in FIGURES:
        missing = [g for g in fig.groups if g not in by_group]
        if missing:
            echo(f"{fig.name}: skipped (group {', '.join(missing)} not in this set, or its runs failed)")
            continue
        for g in fig.groups:
            if fig.output not in by_group[g].series[0].values:
                raise InputError(f"{fig.name}: group {g} has no output {fig.output}")
        series, reference = figure_series(fig, {g: [(lab, s.values[fig.output]) for lab, s in
                                                    zip(by_group[g].labels, by_group[g].series)] for g in fig.groups})
        shown = {shown_runs(by_group[g]) for g in fig.groups}
        p = plot_series(out_dir / f"{fig.name}.png", by_group[fig.groups[0]].series[0].time, series, title=fig.title,
                        ylabel=fig.ylabel, reference=reference, runs="; ".join(sorted(shown)))
        out.append((fig.title, p))
    return out


def _beyond(comparisons: list[Comparison], mech: Path, out_dir: Path, *, jobs: int, stop_time,
            echo) -> tuple[list[str], dict]:
    """The figures beyond the paper (:data:`overcon.figures.BEYOND`): build the compliant scenes of
    each (in ``mech / fig.directory``) as FMUs, run them on the rigid group's grid and draw them
    beside that group's adaptive runs. The report's section (Markdown lines) and each figure's
    :class:`~overcon.figures.Placement`. A figure whose scenes or rigid group are missing is
    skipped, a failed run reported, neither stops the job."""
    from ..figures import BEYOND, beyond_series, placement, placement_text
    from ..fmu.build import build_all
    from ..plots import plot_series

    by_group = {c.group: c for c in comparisons if c.failure is None and c.series}
    lines, where = [], {}
    for fig in BEYOND:
        files = [mech / fig.directory / f"{name}.toml" for name in fig.scenes]
        if fig.rigid_group not in by_group or not all(f.is_file() for f in files):
            echo(f"{fig.name}: skipped (group {fig.rigid_group} or the scenes {', '.join(fig.scenes)} not in this set)")
            continue
        rigid = by_group[fig.rigid_group]
        lines += [f"### {fig.title}", ""]
        _, res = build_all(files, out_dir / "fmus" / "beyond", allow_nonunique=True, refs=False, jobs=jobs, echo=echo)
        infos = [inspect_fmu(r.fmu) for r in res if r.status == "built"]
        jobs_ = [Job(i.model, i, experiment(i, stop_time=stop_time), out_dir / "results" / "beyond" / f"{i.model}.csv")
                 for i in infos]
        results, failures = run_jobs(jobs_, workers=jobs, echo=echo) if len(infos) == len(files) else ({}, {})
        if len(results) != len(files):
            why = "; ".join(str(f) for f in failures.values()) or "a compliant scene was not built (see above)"
            echo(f"!!! {fig.name}: not drawn: {why}")
            lines += [f"**Not drawn**: {why}", ""]
            continue
        series = [read_series(results[i.model].csv) for i in infos]
        time_ = rigid.series[0].time
        if any(s.time.shape != time_.shape or not np.allclose(s.time, time_, rtol=0, atol=1e-9) for s in series):
            raise InputError(f"{fig.name}: the compliant scenes' output grid is not the grid of group {fig.rigid_group}")
        compliant = [s.values[fig.output] for s in series]
        rigid_curves = [(lab, s.values[fig.output]) for lab, s in zip(rigid.labels, rigid.series)]
        where[fig.name] = p = placement(compliant, [v for _, v in rigid_curves])
        curves, reference = beyond_series(fig, rigid_curves, compliant)
        png = plot_series(out_dir / f"{fig.name}.png", time_, curves, title=fig.title, ylabel=fig.ylabel,
                          reference=reference, runs="adaptive runs (each FMU's own solver settings); compliant runs "
                          f"differ by {p.spread:.2g} m")
        lines += [placement_text(fig, p, list(rigid.labels)), "", f"![{fig.title}]({png.name})", ""]
        echo(f"{fig.name}: compliant runs differ by {p.spread:.3g}; between the eliminations at "
             f"{p.share_between:.0%} of the points, s = {p.s:.2f}")
    return lines, where


def paper_scenes(mech: Path) -> tuple[list[Path], list[Path]]:
    """The scene files of ``mech`` (not its subdirectories) whose ``group`` is one of the paper's
    (:data:`overcon.figures.PAPER_GROUPS`), and the other scene files. Mechanism files and files
    that do not parse are neither (the build reports the latter when it reads them)."""
    import tomllib

    paper, others = [], []
    for f in sorted(mech.glob("*.toml")):
        try:
            doc = tomllib.loads(f.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError):
            paper.append(f)  # the build names what is wrong with it
            continue
        sc = doc.get("scene")
        if isinstance(sc, dict):
            (paper if sc.get("group") in PAPER_GROUPS else others).append(f)
    return paper, others


def _drawings(paper: list[Path], out_dir: Path, draw, echo) -> list[str]:
    """Report lines showing each paper mechanism's drawing, made by ``draw(mechanism file, png)``
    (overcon.draw.draw, handed in by the command line: the tooling reads no scene itself); the
    mechanism files are those the paper scenes name (their [scene] mechanism key)."""
    import tomllib

    if draw is None:
        return []
    mechs: dict[Path, None] = {}
    for f in paper:
        try:
            name = tomllib.loads(f.read_text(encoding="utf-8"))["scene"]["mechanism"]
        except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError, KeyError, TypeError):
            continue  # the build has reported this scene
        if isinstance(name, str):
            mechs[(f.parent / name).resolve()] = None
    lines = ["## The mechanisms", ""] if mechs else []
    for m in mechs:
        png = out_dir / "mechanisms" / f"{m.stem}.png"
        png.parent.mkdir(parents=True, exist_ok=True)
        draw(m, png)
        echo(f"drawing: {png}")
        lines += [f"![{m.stem} at q0](mechanisms/{png.name})", ""]
    return lines


def reproduce(out_dir, *, mechanisms="mechanisms", jobs: int = 2, echo=_echo, stop_time=None,
              lockstep_step: float | None = LOCKSTEP_STEP, fmi: int = 2, draw=None) -> ReproduceOutcome:
    """Build an FMU per scene of ``mechanisms`` (pre-check printed, non-unique scenes built too),
    run them with fmpy (``jobs`` processes), compare every group, write ``out_dir/report.md`` with
    the verdict table, the paper's figures and per-group details and plots. ``fmi`` 3: the FMUs
    are FMI 3.0 (C runtime, co-simulation and Model Exchange, run through co-simulation); the
    compliant scenes beyond the paper stay FMI 2.0 (the C runtime does not cover compliant joints).
    Only the scenes of the paper's groups are taken (:func:`paper_scenes`); ``draw``, when given,
    draws each paper mechanism into ``out_dir/mechanisms/`` for the report (:func:`_drawings`)."""
    from ..fmu.build import EXIT_INPUT, build_all

    t0 = time.perf_counter()
    _check_lockstep_step(lockstep_step)
    out_dir = Path(out_dir)
    mech = Path(mechanisms)
    if not mech.is_dir():
        raise InputError(f"{mech}: no such directory (--mechanisms: the directory of the scene files)")
    paper, others = paper_scenes(mech)
    if others:
        echo(f"reproduce: {len(others)} scene(s) of {mech} not of the paper's groups left out "
             f"({', '.join(p.name for p in others)}): run your own scenes with overcon compare or overcon regress")
    echo(f"== build: one FMU per scene of the paper in {mech} (pre-check first) -> {out_dir / 'fmus'}")
    version = {"runtime": "c", "fmi": 3} if fmi == 3 else {}
    code, built = build_all(paper, out_dir / "fmus", allow_nonunique=True, refs=False, jobs=jobs, echo=echo,
                            **version) if paper else (0, [])
    if code == EXIT_INPUT:
        raise InputError(f"{mech}: some scenes could not be built (see above)")
    fmus = [r.fmu for r in built if r.status == "built"]
    if not fmus:
        raise InputError(f"{mech}: no scene files")
    t_build = time.perf_counter() - t0
    infos = [inspect_fmu(f) for f in fmus]
    groups, singles = _select(infos, None)
    for g in singles:
        echo(f"{g}: one scene only, not compared")
    groups, invalid = _valid_groups(groups, echo)
    exps = _group_experiments(groups, stop_time, None)
    n = sum(len(v) for v in groups.values())
    echo(f"== run: {n} FMUs with fmpy.simulate_fmu, adaptive"
         + (f" and in lockstep (rk4, {lockstep_step:g} s)" if lockstep_step is not None else "")
         + f", {jobs} process(es) -> {out_dir / 'results'}")
    t1 = time.perf_counter()
    comparisons, results = _run_and_compare(groups, exps, out_dir / "results", jobs=jobs,
                                            lockstep_step=lockstep_step, tolerance=None, echo=echo)
    comparisons += invalid
    t_run = time.perf_counter() - t1
    echo("== compare")
    for c in comparisons:
        echo(verdict_line(c))
    t2 = time.perf_counter()
    figures = _figures(comparisons, out_dir, echo)
    beyond, where = _beyond(comparisons, mech, out_dir, jobs=jobs, stop_time=stop_time, echo=echo)
    plots = {c.group: plot_comparison(c, out_dir / "groups", "worst") for c in comparisons}
    t_plot = time.perf_counter() - t2
    total = time.perf_counter() - t0
    seconds = {"build": t_build, "run": t_run, "plots": t_plot, "total": total,
               "simulation_sum": sum(r.sim_seconds for r in results.values())}
    intro = [
        "Frączek & Wojtyra, *Mechanism and Machine Theory* 46 (2011) 312–334: every scene of "
        f"`{mech}` built as an FMI 2.0 co-simulation FMU (`{out_dir / 'fmus'}`), pre-checked, simulated "
        "with `fmpy.simulate_fmu` and compared across eliminations. *Predicted*: the pre-check "
        "(reaction uniqueness of the friction joints, paper Eq. 17), carried by each FMU as the "
        "constant output `motion_unique`. *Observed*: whether the simulated positions of the lockstep "
        "runs (every elimination on one fixed grid) agree across the eliminations within the tolerance "
        "below, stated by the deciding output whose largest difference is the largest multiple of its "
        "tolerance (with its unit); the adaptive runs' largest difference per unit is given beside it. "
        "Wall time: simulation seconds "
        "per variant, adaptive run (inside `simulate_fmu`).",
        "",
        f"Total wall time {total:.1f} s on {os.cpu_count()} CPU(s), {jobs} worker process(es) "
        f"(build {t_build:.1f} s, simulations {t_run:.1f} s wall / {seconds['simulation_sum']:.1f} s summed, "
        f"plots {t_plot:.1f} s); {platform.python_implementation()} {platform.python_version()}.",
    ]
    intro += [""] + _drawings(paper, out_dir, draw, echo)
    report = out_dir / "report.md"
    write_text_atomic(report, markdown(comparisons, out_dir, title="overcon reproduce: uniqueness of the simulated motion",
                               intro=intro, figures=figures, plots=plots, beyond=beyond), encoding="utf-8")
    return ReproduceOutcome(comparisons, report, [p for _, p in figures], seconds, where)
