"""The paper's scene groups and figures (Figs. 3, 4, 5, 7, 8, 9), run in process, and the figures
beyond the paper (:data:`overcon.figures.BEYOND`: a paper group beside a compliant variant).

A *group* is the set of scene files with the same ``group`` field: one friction set under
different eliminations. Its motion is unique when the positions of lockstep runs (every variant
on one fixed grid) agree across the group (:mod:`overcon.verdict`); the pre-check predicts that
from the Jacobian alone.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from . import scene
from .figures import (ADAPTIVE_RUNS, BEYOND, FIGURES, BeyondFigure, Figure, Placement,  # noqa: F401  (the figures
                      beyond_series, figure_series, placement)  # are defined without the engine)
from .checks import compile_checked
from .precheck import precheck
from .simulate import Result, SimulationError, run_scene
from .spec import SceneSpec
from .verdict import (LOCKSTEP_METHOD, LOCKSTEP_STEP, LockstepGrid, equation_joints, lockstep_tolerance,
                      variant_label)


def scene_files(directory: Path) -> list[Path]:
    """Scene files (with a [scene] table) in a directory, sorted by name; unreadable files are
    kept so that the loader reports them against the file."""
    return [p for p in scene.toml_files([directory]) if scene.is_scene_file(p) is not False]


def scene_groups(directory: Path) -> dict[str, list[tuple[Path, SceneSpec]]]:
    groups: dict[str, list[tuple[Path, SceneSpec]]] = {}
    for p in scene_files(directory):
        spec = scene.load(p)
        groups.setdefault(spec.group or spec.name, []).append((p, spec))
    for items in groups.values():  # paper order: without eq. 4 before without eq. 6, 5 < 9 < 18
        items.sort(key=lambda item: (item[1].eliminate == "auto", item[1].eliminate if item[1].eliminate != "auto" else ()))
    return groups


def _positions(names) -> tuple[str, ...]:
    return tuple(n for n in names if "." in n and n.split(".")[1] in ("x", "y", "z", "phi"))


def _max_diffs(results: list[Result], names) -> dict[str, float]:
    """Per output: max over variants and samples of |y_k(t) - y_0(t)|."""
    return {n: max((float(np.max(np.abs(r.column(n) - results[0].column(n)))) for r in results[1:]), default=0.0)
            for n in names}


@dataclass
class GroupRun:
    """One group run in process. ``max_diff`` (the verdict) comes from the lockstep runs (every
    variant on the same fixed grid, :mod:`overcon.verdict`); ``adaptive_diff`` from the adaptive
    runs at the scenes' own settings (``results``, used for the figures), reported only."""

    group: str
    labels: list[str]
    results: list[Result]  # adaptive runs (empty when not asked for)
    predicted_unique: bool
    max_diff: dict[str, float]  # per position output: lockstep max |difference| to the first variant
    adaptive_diff: dict[str, float]  # the same for the adaptive runs (second figure, never decides)
    lockstep_step: float
    scale: dict[str, float]  # per output: max |value| (lockstep runs)
    lockstep: list[Result] = field(default_factory=list)  # the lockstep runs (positions only)

    def observed_unique(self) -> bool:
        return all(d <= lockstep_tolerance(self.scale[n]) for n, d in self.max_diff.items())


def _with_solver(spec: SceneSpec, **changes) -> SceneSpec:
    return dataclasses.replace(spec, solver=dataclasses.replace(spec.solver, **changes))


def _lockstep_runs(specs: list[SceneSpec], step: float, outputs) -> tuple[list[Result], float]:
    """Every variant on one rk4 grid (positions only); an unstable step (the rk4 integrator's
    refusal) repeats all of them as :class:`overcon.verdict.LockstepGrid` decides, the procedure
    of the FMU comparison and the sweep. Returns the runs and the step used."""
    def runs(h: float) -> list[Result]:
        return [run_scene(scene.as_scene(dataclasses.replace(
            _with_solver(spec, method=LOCKSTEP_METHOD, step=h), reactions=(),
            positions=outputs or spec.positions))) for spec in specs]

    grid = LockstepGrid(step)
    while True:
        try:
            return runs(grid.step), grid.step
        except SimulationError as exc:
            if not grid.retry([exc.stable_step]):
                raise


def run_group(items: list[tuple[Path, SceneSpec]], *, tolerance: float | None = None,
              outputs: tuple[str, ...] | None = None, adaptive: bool = True,
              lockstep_step: float = LOCKSTEP_STEP, stop_time: float | None = None) -> GroupRun:
    """Run every variant of a group twice: in lockstep (positions only, :data:`LOCKSTEP_METHOD`
    with ``lockstep_step``: the verdict) and, if ``adaptive``, with the scene's own solver at
    ``tolerance`` (default: the scene's) with every output (figures, second figure)."""
    labels, results, predicted, specs = [], [], [], []
    for path, spec in items:
        if stop_time is not None:
            spec = dataclasses.replace(spec, stop_time=stop_time)
        specs.append(spec)
        model = compile_checked(scene.as_scene(spec))
        predicted.append(precheck(model, str(path)).motion_unique)
        labels.append(variant_label(spec.eliminate, equation_joints(model.joints)))
        if adaptive:
            results.append(run_scene(scene.as_scene(spec, tolerance=tolerance)))
    lock, lockstep_step = _lockstep_runs(specs, lockstep_step, outputs)
    names = _positions(outputs or lock[0].names)
    scale = {n: max(float(np.max(np.abs(r.column(n)))) for r in lock) for n in names}
    adaptive_diff = _max_diffs(results, names) if results else {}
    return GroupRun(items[0][1].group or items[0][1].name, labels, results, all(predicted),
                    _max_diffs(lock, names), adaptive_diff, lockstep_step, scale, lock)


def make_figures(directory: Path, out: Path, *, tolerance: float | None = None, log=print) -> list[Path]:
    """Run the groups the paper's figures need and write fig3.png ... fig9.png into ``out``; then the
    figures beyond the paper (:data:`BEYOND`) whose compliant scenes are in ``directory``."""
    from .plots import plot_series

    groups = scene_groups(directory)
    cache: dict[str, GroupRun] = {}
    written = []
    for fig in FIGURES:
        for g in fig.groups:
            if g not in groups:
                raise FileNotFoundError(f"{directory}: no scenes of group {g!r} (needed for {fig.name})")
            if g not in cache:
                cache[g] = run_group(groups[g], tolerance=tolerance)
                log(f"{g}: predicted {'unique' if cache[g].predicted_unique else 'not unique'}; "
                    f"max position difference between eliminations {max(cache[g].max_diff.values()):.3g} "
                    f"(lockstep), {max(cache[g].adaptive_diff.values()):.3g} (adaptive)")
        series, reference = figure_series(fig, {g: [(lab, res.column(fig.output)) for lab, res in
                                                    zip(cache[g].labels, cache[g].results)] for g in fig.groups})
        time = cache[fig.groups[0]].results[0].time
        written.append(plot_series(out / f"{fig.name}.png", time, series, title=fig.title, ylabel=fig.ylabel,
                                   reference=reference, runs=ADAPTIVE_RUNS))
        log(f"wrote {written[-1]}")
    for fig in BEYOND:
        if all((directory / fig.directory / f"{name}.toml").is_file() for name in fig.scenes):
            if fig.rigid_group not in cache:
                cache[fig.rigid_group] = run_group(groups[fig.rigid_group], tolerance=tolerance)
            path, where = beyond_figure(fig, directory, out, cache[fig.rigid_group], tolerance=tolerance)
            written.append(path)
            log(f"wrote {path} (beyond the paper: compliant runs differ by {where.spread:.3g}, "
                f"s = {where.s:.2f} between the eliminations)")
    return written


def beyond_figure(fig: BeyondFigure, directory: Path, out: Path, rigid: GroupRun, *,
                  tolerance: float | None = None) -> tuple[Path, Placement]:
    """Run the compliant scenes of ``fig`` (in ``directory / fig.directory``) in process and draw
    them beside the rigid group's adaptive runs ``rigid`` (same time grid); the PNG's path and
    where the compliant motion lies."""
    from .plots import plot_series

    runs = [run_scene(scene.as_scene(scene.load(directory / fig.directory / f"{name}.toml"), tolerance=tolerance))
            for name in fig.scenes]
    time = rigid.results[0].time
    if any(r.time.shape != time.shape or not np.allclose(r.time, time, rtol=0, atol=1e-9) for r in runs):
        raise ValueError(f"{fig.name}: the compliant scenes' output grid is not the grid of group {fig.rigid_group}")
    compliant = [r.column(fig.output) for r in runs]
    rigid_curves = [(lab, res.column(fig.output)) for lab, res in zip(rigid.labels, rigid.results)]
    where = placement(compliant, [v for _, v in rigid_curves])
    series, reference = beyond_series(fig, rigid_curves, compliant)
    path = plot_series(out / f"{fig.name}.png", time, series, title=fig.title, ylabel=fig.ylabel,
                       reference=reference, runs=ADAPTIVE_RUNS + f"; compliant runs differ by {where.spread:.2g} m")
    return path, where
