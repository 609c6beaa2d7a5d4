"""The rigid limit of a compliant scene (``overcon converge``): the scene run over a range of
stiffnesses, how its positions and its friction joints' reactions converge, the measured order,
where the limit lies relative to the rigid eliminations' motions, and which stiffness is enough
for a given accuracy.

Scaling (one rule): at stiffness ``k`` every compliant joint's values are multiplied, the
stiffnesses (``stiffness`` and ``rotational_stiffness``, every axis) by f = k / k0 and the dampings
(``damping``, ``rotational_damping``) by sqrt(f), k0 the largest translational stiffness (N/m) of the
scene's compliant joints. So the ratios of the stiffnesses, which decide the rigid limit, and the
damping ratios stay those of the scene; ``k`` is the stiffest joint's translational stiffness.

Measures (over every output time and every column of the kind): positions are the bodies' x, y
(z) coordinates (m); reactions the reaction components of the friction joints (N, N.m), both the
largest absolute difference. The order p is the negated slope of a least-squares line through
log(difference between consecutive stiffnesses) against log(k) (1/k convergence: p = 1). The error
of run i is estimated as its difference to the stiffest run plus the stiffest run's own error,
extrapolated from the last difference with the order p as a geometric tail."""
from __future__ import annotations

from .outfiles import atomic, savefig_atomic

import csv
import dataclasses
import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .progress import bar

from . import scene as scene_mod
from .checks import compile_checked
from .simulate import SimulationError, run
from .spec import SceneSpec

MAX_RUNS = 50  # stiffnesses per command: each is a full (stiff) run


class ConvergeInputError(ValueError):
    """Bad input (the flag or file field at fault is named): exit 2."""


class ConvergeRunError(RuntimeError):
    """A run failed (its name, stiffness and cause are named): exit 3."""


def parse_range(text: str, flag: str = "--stiffness") -> np.ndarray:
    """``start:stop:count`` -> ``count`` log-spaced stiffnesses (N/m) from start to stop, both
    finite and > 0, start < stop, 2 <= count <= :data:`MAX_RUNS`."""
    parts = text.split(":")
    try:
        if len(parts) != 3:
            raise ValueError
        start, stop, count = float(parts[0]), float(parts[1]), int(parts[2])
    except ValueError:
        raise ConvergeInputError(f"{flag} {text!r}: expected start:stop:count, e.g. 1e4:1e10:7") from None
    if not (math.isfinite(start) and math.isfinite(stop) and 0 < start < stop):
        raise ConvergeInputError(f"{flag} {text!r}: start and stop must be finite with 0 < start < stop (N/m)")
    if not 2 <= count <= MAX_RUNS:
        raise ConvergeInputError(f"{flag} {text!r}: count must be in [2, {MAX_RUNS}], got {count}")
    return np.geomspace(start, stop, count)


def _stiffnesses(c) -> list[float]:
    s = c.stiffness
    return list(s) if isinstance(s, tuple) else [s]


def reference_stiffness(spec: SceneSpec) -> float:
    """k0: the largest translational stiffness (N/m) of the scene's compliant joints; raises
    :class:`ConvergeInputError` if the scene has none under ``redundancy = "compliant"``."""
    src = spec.source or spec.name
    if spec.redundancy != "compliant":
        raise ConvergeInputError(f"{src}: scene.redundancy is {spec.redundancy!r}: converge needs "
                                 "redundancy = \"compliant\"")
    ks = [k for j in spec.mechanism.joints if j.compliance is not None for k in _stiffnesses(j.compliance)]
    if not ks:
        raise ConvergeInputError(f"{src}: no joint of {spec.mechanism.source or spec.mechanism.name} has a "
                                 "[joints.compliance] table: nothing to converge")
    return max(ks)


def _scaled(value, factor: float):
    return tuple(v * factor for v in value) if isinstance(value, tuple) else value * factor


def scaled_scene(spec: SceneSpec, k: float) -> SceneSpec:
    """The scene with its compliant joints scaled to stiffness ``k`` (the module's rule)."""
    f = k / reference_stiffness(spec)
    joints = []
    for j in spec.mechanism.joints:
        c = j.compliance
        if c is not None:
            c = dataclasses.replace(
                c, stiffness=_scaled(c.stiffness, f), rotational_stiffness=_scaled(c.rotational_stiffness, f),
                damping=_scaled(c.damping, math.sqrt(f)), rotational_damping=_scaled(c.rotational_damping, math.sqrt(f)))
        joints.append(dataclasses.replace(j, compliance=c))
    return dataclasses.replace(spec, mechanism=dataclasses.replace(spec.mechanism, joints=tuple(joints)))


def measured(spec: SceneSpec) -> SceneSpec:
    """The scene with the outputs converge compares: every body's length coordinates and the
    reactions of the friction joints."""
    coords = ("x", "y") if spec.mechanism.kind == "planar" else ("x", "y", "z")
    return dataclasses.replace(spec, positions=tuple(f"{b.name}.{c}" for b in spec.mechanism.bodies for c in coords),
                               reactions=tuple(spec.friction), friction_outputs=(), velocities=(), energy=False)


def rigid_scenes(spec: SceneSpec, path: Path) -> list[tuple[str, SceneSpec]]:
    """(label, scene) of the rigid eliminations to compare with: every scene of the same group in
    the scene's directory (the scene itself if it has no group), with ``redundancy = "eliminate"``
    and its own elimination; one per distinct elimination."""
    files = [Path(path)]
    if spec.group:
        files = sorted(p for p in Path(path).parent.glob("*.toml") if _group_of(p) == spec.group)
    out, seen = [], set()
    for p in files:
        s = scene_mod.load(p)
        elim = s.eliminate or "auto"  # a compliant scene need not name one: the pivoted-QR choice
        if elim in seen:
            continue
        seen.add(elim)
        label = "eliminate " + ("auto" if elim == "auto" else ",".join(str(i) for i in elim))
        out.append((label, dataclasses.replace(s, redundancy="eliminate", eliminate=elim)))
    return out


def _group_of(path: Path) -> str | None:
    """The ``group`` of a scene file, None for a mechanism file or an unreadable one."""
    import tomllib
    try:
        st = tomllib.loads(path.read_text(encoding="utf-8")).get("scene")
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError):
        return None
    return st.get("group") if isinstance(st, dict) else None


@dataclass
class Run:
    label: str
    names: list[str]
    time: np.ndarray
    positions: np.ndarray  # (t, columns) m
    reactions: np.ndarray  # (t, columns) N, N.m
    wall: float
    steps: int


def run_one(label: str, spec: SceneSpec, stop_time: float | None = None) -> Run:
    """Compile and run ``spec`` (its solver options); a failed run raises
    :class:`ConvergeRunError` naming ``label`` and the cause."""
    spec = measured(spec)
    start = time.perf_counter()
    try:
        res = run(compile_checked(spec), spec.solver, stop_time=stop_time)
    except SimulationError as exc:
        raise ConvergeRunError(f"run {label} ({spec.source or spec.name}) failed: {exc}") from exc
    wall = time.perf_counter() - start
    npos = len(spec.positions)  # the outputs of measured(): the positions, then the reactions
    return Run(label, res.names, res.time, res.values[:, :npos], res.values[:, npos:], wall, res.steps)


def max_diff(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.max(np.abs(a - b))) if a.size else 0.0


def fitted_order(ks: np.ndarray, diffs: np.ndarray) -> float:
    """-slope of log(diffs) against log(ks) (least squares over the positive differences); nan
    with fewer than two."""
    ok = diffs > 0
    if ok.sum() < 2:
        return math.nan
    return -float(np.polyfit(np.log(ks[ok]), np.log(diffs[ok]), 1)[0])


@dataclass
class Study:
    """The result of :func:`converge` (see the module docstring for what each number means)."""

    stiffness: np.ndarray  # (N,) N/m
    runs: list[Run]
    rigid: list[Run]
    accuracy: float  # m
    pos_next: np.ndarray = field(init=False)  # (N-1,) m, run i against run i+1
    pos_last: np.ndarray = field(init=False)  # (N,) m, run i against the stiffest
    reac_next: np.ndarray = field(init=False)
    reac_last: np.ndarray = field(init=False)
    order: float = field(init=False)
    reaction_order: float = field(init=False)
    error: np.ndarray = field(init=False)  # (N,) m, estimated distance to the limit

    def __post_init__(self):
        r, k = self.runs, self.stiffness
        self.pos_next = np.array([max_diff(a.positions, b.positions) for a, b in zip(r, r[1:])])
        self.pos_last = np.array([max_diff(a.positions, r[-1].positions) for a in r])
        self.reac_next = np.array([max_diff(a.reactions, b.reactions) for a, b in zip(r, r[1:])])
        self.reac_last = np.array([max_diff(a.reactions, r[-1].reactions) for a in r])
        self.order = fitted_order(k[:-1], self.pos_next)
        self.reaction_order = fitted_order(k[:-1], self.reac_next)
        self.error = self.pos_last + self.tail

    @property
    def tail(self) -> float:
        """Estimated error of the stiffest run (m): the geometric tail of the last difference
        with the fitted order; inf when the differences do not shrink (order <= 0 or nan)."""
        if not self.order > 0:
            return math.inf
        r = (self.stiffness[-2] / self.stiffness[-1]) ** self.order
        return float(self.pos_next[-1] * r / (1.0 - r))

    def enough(self) -> tuple[float, bool]:
        """(stiffness, measured): the smallest run stiffness whose estimated error is within the
        accuracy (measured = True), else the extrapolated one k_N (tail / accuracy)^(1/p)
        (measured = False; inf if the order is not positive)."""
        for k, e in zip(self.stiffness, self.error):
            if e <= self.accuracy:
                return float(k), True
        if not self.order > 0:
            return math.inf, False
        return float(self.stiffness[-1] * (self.tail / self.accuracy) ** (1.0 / self.order)), False

    def to_rigid(self) -> list[tuple[str, float, float]]:
        """(label, positions m, reactions) of the stiffest run against each rigid elimination."""
        last = self.runs[-1]
        return [(g.label, max_diff(last.positions, g.positions), max_diff(last.reactions, g.reactions))
                for g in self.rigid]

    def between(self) -> tuple[float, float] | None:
        """With two rigid eliminations A, B: (s, residual m) of the stiffest run x as A + s (B - A)
        (least squares over every time and position column: 0 is A, 1 is B) and the largest
        |x - A - s (B - A)|; None otherwise."""
        if len(self.rigid) != 2:
            return None
        a, b, x = self.rigid[0].positions, self.rigid[1].positions, self.runs[-1].positions
        d = b - a
        den = float(np.sum(d * d))
        if den == 0.0:
            return None
        s = float(np.sum((x - a) * d) / den)
        return s, float(np.max(np.abs(x - a - s * d)))


def converge(path: Path, stiffness: np.ndarray, *, accuracy: float = 1e-6, stop_time: float | None = None,
             echo=print) -> Study:
    """Run the scene file ``path`` at each stiffness (the module's scaling) and its rigid
    eliminations (:func:`rigid_scenes`); every run on the scene's output grid."""
    if not (math.isfinite(accuracy) and accuracy > 0):
        raise ConvergeInputError(f"--accuracy {accuracy!r}: must be finite and > 0 (m)")
    spec = scene_mod.load(path)
    if stop_time is not None and not (math.isfinite(stop_time) and stop_time > spec.start_time):
        raise ConvergeInputError(f"--stop-time {stop_time!r}: must be finite and > the scene's start time "
                                 f"{spec.start_time:g} s")
    reference_stiffness(spec)  # refuses a scene without compliant joints
    runs = []
    rigid_list = list(rigid_scenes(spec, path))
    with bar(len(stiffness) + len(rigid_list), "converge", "run") as shown:
        for k in stiffness:
            runs.append(run_one(f"k = {k:.3g} N/m", scaled_scene(spec, float(k)), stop_time))
            echo(f"  k = {k:10.4g} N/m: {runs[-1].steps} steps, {runs[-1].wall:.2f} s")
            shown.update()
        rigid = []
        for label, s in rigid_list:
            rigid.append(run_one(label, s, stop_time))
            echo(f"  rigid, {label}: {rigid[-1].steps} steps, {rigid[-1].wall:.2f} s")
            shown.update()
    return Study(np.asarray(stiffness, float), runs, rigid, accuracy)


def write_table(study: Study, path: Path) -> Path:
    """CSV, one row per stiffness: k (N/m), the position and reaction differences (to the next
    and to the stiffest run), the estimated error (m), the distance to each rigid elimination (m),
    the run's steps and wall time (s)."""
    with atomic(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["stiffness_N_per_m", "positions_to_next_m", "positions_to_stiffest_m", "reactions_to_next",
                    "reactions_to_stiffest", "estimated_error_m",
                    *(f"positions_to_{g.label.replace(' ', '_')}_m" for g in study.rigid), "steps", "wall_s"])
        for i, (k, r) in enumerate(zip(study.stiffness, study.runs)):
            nxt = (repr(float(study.pos_next[i])), repr(float(study.reac_next[i]))) if i < len(study.runs) - 1 \
                else ("", "")
            w.writerow([repr(float(k)), nxt[0], repr(float(study.pos_last[i])), nxt[1],
                        repr(float(study.reac_last[i])), repr(float(study.error[i])),
                        *(repr(max_diff(r.positions, g.positions)) for g in study.rigid), r.steps, f"{r.wall:.3f}"])
    return path


def write_plot(study: Study, path: Path, title: str) -> Path:
    """PNG, log-log against k: the position differences (consecutive, to the stiffest, estimated
    error) with the accuracy, and the distance to each rigid elimination."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    k = study.stiffness
    fig, ax = plt.subplots(figsize=(7, 4.5))
    ax.loglog(k[:-1], np.maximum(study.pos_next, 1e-300), "o-", label=f"to the next k (order {study.order:.2f})")
    ax.loglog(k[:-1], np.maximum(study.pos_last[:-1], 1e-300), "s--", label="to the stiffest k")
    ax.loglog(k, np.maximum(study.error, 1e-300), ":", label="estimated error")
    for j, g in enumerate(study.rigid):
        ax.loglog(k, [max(max_diff(r.positions, g.positions), 1e-300) for r in study.runs], "-.",
                  color=f"C{3 + j}", label=f"to rigid, {g.label}")
    ax.axhline(study.accuracy, color="grey", lw=0.8, label=f"accuracy {study.accuracy:g} m")
    ax.set_xlabel("stiffness k (N/m)")
    ax.set_ylabel("max position difference (m)")
    ax.set_title(title)
    ax.legend(fontsize=8)
    fig.tight_layout()
    savefig_atomic(fig, path, dpi=110)
    plt.close(fig)
    return path


def summary(study: Study) -> list[str]:
    """The report's lines."""
    k, acc = study.stiffness, study.accuracy
    lines = [f"positions (m): to the next stiffness {_series(study.pos_next)}; measured order {study.order:.3f}",
             f"positions (m): to the stiffest (k = {k[-1]:.3g} N/m) {_series(study.pos_last[:-1])}"]
    if study.runs[-1].reactions.size:
        lines.append(f"friction joints' reactions (N, N.m): to the next {_series(study.reac_next)}; "
                     f"measured order {study.reaction_order:.3f}")
    for label, dp, dr in study.to_rigid():
        lines.append(f"stiffest run against rigid {label}: positions {dp:.3e} m, reactions {dr:.3e}")
    if len(study.rigid) == 2:
        gap = max_diff(study.rigid[0].positions, study.rigid[1].positions)
        s, res = study.between()
        lines.append(f"the rigid eliminations are {gap:.3e} m apart; the stiffest run lies at s = {s:.3f} "
                     f"on the line from {study.rigid[0].label} (0) to {study.rigid[1].label} (1), "
                     f"{res:.3e} m off it")
    kk, ok = study.enough()
    how = "measured" if ok else "extrapolated with the measured order"
    lines.append(f"estimated error of the stiffest run: {study.tail:.3e} m; accuracy {acc:g} m needs "
                 f"k >= {kk:.3g} N/m ({how})")
    return lines


def _series(values: np.ndarray) -> str:
    return ", ".join(f"{v:.3e}" for v in values)
