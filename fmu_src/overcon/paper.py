"""The paper's scene groups and figures (Figs. 3, 4, 5, 7, 8, 9), run in process.

A *group* is the set of scene files with the same ``group`` field: one friction set under
different eliminations. Its motion is unique when every output agrees across the group within a
tolerance derived from the solver tolerance; the pre-check predicts that from the Jacobian alone.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from . import scene
from .model import compile_model
from .precheck import precheck
from .simulate import Result, run
from .spec import SceneSpec


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


UNIQUE_FACTOR = 100.0


def uniqueness_tolerance(solver_tolerance: float, scale: float) -> float:
    """Largest difference between eliminations still called "unique": 100 x the integration
    tolerance x the output's magnitude (at least 1).

    Why 100: dopri5 controls the local error per step; its global error over a paper run,
    measured against a 1e-12 reference, is 20-100 x tolerance x scale (planar_f45: 2.0e-6 m at
    1e-8, 4.0e-9 m at 1e-10; spatial_MN: 1.5e-6 m at 1e-8, 1.0e-8 m at 1e-10), and two variants whose
    adaptive step sequences diverge differ by up to that much although the motion is unique (with
    fixed steps, rk4, the same variants agree to 5e-14 m). At the scenes' tolerance 1e-9 the bound is
    2e-7 m for slider 1 (|x1| <= 2 m) and 2.4e-7 m for the platform: a 1e-6 m change is caught;
    unique groups differ by <= 4e-8 m there, non-unique ones by 0.3-0.6 m."""
    return UNIQUE_FACTOR * solver_tolerance * max(1.0, scale)


def variant_label(spec: SceneSpec) -> str:
    """Legend label as in the paper: "without eq. 4"."""
    if spec.eliminate == "auto":
        return "auto elimination"
    return "without eq. " + ", ".join(str(k) for k in spec.eliminate) if spec.eliminate else "no elimination"


@dataclass
class GroupRun:
    group: str
    labels: list[str]
    results: list[Result]
    predicted_unique: bool
    max_diff: dict[str, float]  # per position output: max |difference| to the first variant
    tolerance: float  # the integration tolerance the group ran at
    scale: dict[str, float]  # per output: max |value|

    def observed_unique(self) -> bool:
        return all(d <= uniqueness_tolerance(self.tolerance, self.scale[n]) for n, d in self.max_diff.items())


def run_group(items: list[tuple[Path, SceneSpec]], *, tolerance: float | None = None,
              outputs: tuple[str, ...] | None = None) -> GroupRun:
    labels, results, predicted = [], [], []
    for path, spec in items:
        model = compile_model(scene.as_scene(spec, tolerance=tolerance))
        predicted.append(precheck(model, str(path))["motion_unique"])
        labels.append(variant_label(spec))
        results.append(run(model))
    names = outputs or tuple(n for n in results[0].names if "." in n and n.split(".")[1] in ("x", "y", "z", "phi"))
    diff = {n: max((float(np.max(np.abs(r.column(n) - results[0].column(n)))) for r in results[1:]), default=0.0)
            for n in names}
    scale = {n: max(float(np.max(np.abs(r.column(n)))) for r in results) for n in names}
    tol = tolerance or items[0][1].solver.tolerance
    return GroupRun(items[0][1].group or items[0][1].name, labels, results, all(predicted), diff, tol, scale)


def make_figures(directory: Path, out: Path, *, tolerance: float | None = None, log=print) -> list[Path]:
    """Run the groups the paper's figures need and write fig3.png ... fig9.png into ``out``."""
    from .plots import plot_series

    groups = scene_groups(directory)
    cache: dict[str, GroupRun] = {}
    written = []
    for fig in FIGURES:
        series = {}
        time = None
        for g in fig.groups:
            if g not in groups:
                raise FileNotFoundError(f"{directory}: no scenes of group {g!r} (needed for {fig.name})")
            if g not in cache:
                cache[g] = run_group(groups[g], tolerance=tolerance)
                log(f"{g}: predicted {'unique' if cache[g].predicted_unique else 'not unique'}; "
                    f"max position difference between eliminations {max(cache[g].max_diff.values()):.3g}")
            gr = cache[g]
            for label, res in zip(gr.labels, gr.results):
                prefix = "" if len(fig.groups) == 1 else ("without friction, " if g.endswith("none") else "with friction, ")
                series[prefix + label] = res.column(fig.output)
                time = res.time
        written.append(plot_series(out / f"{fig.name}.png", time, series, title=fig.title, ylabel=fig.ylabel))
        log(f"wrote {written[-1]}")
    return written
