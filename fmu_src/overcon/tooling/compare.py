"""Compare results on one time grid: per output the largest difference, the first time it exceeds
its tolerance, and a uniqueness verdict per group next to the pre-check's prediction.

Rules (also stated in every report, :func:`rules_text`):

* **Grid**: results are compared sample by sample; their time columns must be identical (to
  1e-9 of the step). No interpolation: a mismatch is bad input (exit 2); run the FMUs with the
  same ``--stop-time``/``--step`` instead.
* **Differences** (group mode): every variant against the first one (paper order: without eq. 4
  before without eq. 6; 5 < 9 < 18). ``max abs`` = max over variants and samples of
  |y_k(t) − y_0(t)|; ``max rel`` = max abs / scale, where scale = max |y| over all variants and
  samples of that output (not given for outputs that are zero, scale <= 1e-12).
* **Lockstep verdict** (group mode, overcon FMUs): every variant is also run on one fixed grid
  (:mod:`overcon.verdict`: ``solver.method = rk4``, ``solver.step`` = the lockstep step, 5 ms by
  default), so the variants take identical steps and differ only by round-off unless the motion
  is not unique. The verdict comes from these runs, tolerance per output
  :func:`overcon.verdict.lockstep_tolerance` (1e-8 x max(1, scale)). The adaptive runs (the FMUs'
  own settings) are compared too; their largest difference is reported beside the verdict
  (``adaptive_diff``) and never decides.
* **Adaptive fallback** (FMUs without ``solver.method``/``solver.step``, e.g. other tools'):
  tolerance per output = :func:`overcon.verdict.uniqueness_tolerance` (solver tolerance, scale),
  the solver tolerance being the largest DefaultExperiment tolerance of the FMUs compared.
* ``--tolerance`` replaces either by one absolute value for every output.
* **What decides the verdict** (group mode): the positions (outputs in m or rad) only. Joint
  reactions are reported but never decide: the reactions of joints whose reaction is not unique
  differ between eliminations even when the motion is unique (paper §2.1), and the reactions of
  joints flagged unique carry the (tolerance-sized) position differences amplified through the
  accelerations and the stiff regularised friction law: in spatial_MN (unique motion) positions
  differ by 6e-7 m but the reactions of M, N by 8e-3 N, 1000 × a force tolerance derived like
  the position one. They are reported per joint, with the pre-check's ``reaction_unique``. FMUs
  with no position outputs (other tools' FMUs): every common output decides.
* **Driven groups** (FMUs of scenes with ``[[drivers]]``, which carry ``effort_unique``): the drivers
  prescribe the motion, so the positions agree whatever the elimination; the efforts
  ``<driver>.effort`` decide, and the prediction is ``effort_unique`` (docs/coupling.md, "Drivers").
* **Reference mode** (one FMU against a CSV): every common output decides.
* **Prediction**: the FMUs' constant ``motion_unique`` outputs (the pre-check); all FMUs of a
  group must agree. FMUs without it: the group is expected to be unique.
* **Uniqueness along the motion** (:class:`Along`, FMUs with the discrete outputs ``rank``,
  ``motion_unique``, ``<joint>.reaction_unique``, recorded by :mod:`.run` at every output point):
  per FMU, the samples are grouped into intervals of constant (rank, friction joints whose
  reaction is not unique, motion_unique), each from its first to its last sample; reported are
  the intervals where the rank differs from its value at t = 0 or a friction joint's reaction or
  the motion is not unique, or, when every sample equals the one at t = 0, that they stayed so.
  Taken from the adaptive runs (the FMUs' own settings), from the lockstep runs where those
  failed. Reported, never deciding: the verdict stays the observed comparison of positions.
"""
from __future__ import annotations

import csv
import math
import dataclasses
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..verdict import LOCKSTEP_FACTOR, UNIQUE_FACTOR, lockstep_tolerance, uniqueness_tolerance
from . import InputError
from .fmus import FmuInfo
from .run import Series

GRID_RTOL = 1e-9  # of the step: time columns equal to this are the same grid
REL_FLOOR = 1e-12  # outputs with max |y| below this are zero: no relative difference


@dataclass
class OutputDiff:
    name: str
    unit: str | None
    kind: str  # position, reaction, other
    decides: bool
    tolerance: float
    scale: float
    max_abs: float
    max_rel: float | None  # None: the output is zero (scale <= REL_FLOOR)
    first_exceed: float | None  # first time the difference exceeds the tolerance
    reaction_unique: bool | None = None  # reactions: the pre-check's verdict for the joint

    @property
    def within(self) -> bool:
        return self.max_abs <= self.tolerance


@dataclass(frozen=True)
class Interval:
    """Samples from ``start`` to ``end`` (s) with one ``rank``, the friction joints whose reaction
    is not unique there (``nonunique``, in the FMU's order) and ``motion_unique``; ``at_stop``:
    the row a failed run held at its stop (between the previous sample and ``end``)."""

    start: float
    end: float
    rank: int
    nonunique: tuple[str, ...]
    motion_unique: bool
    at_stop: bool = False


@dataclass(frozen=True)
class Along:
    """The discrete uniqueness outputs of one run (module docstring): its intervals in time order
    and whether the run failed (then the last interval is the row held at the stop)."""

    intervals: tuple[Interval, ...]
    failed: bool = False

    @property
    def initial(self) -> Interval:
        return self.intervals[0]

    @property
    def unchanged(self) -> bool:
        """Every sample as at t = 0."""
        return len(self.intervals) == 1

    def off(self) -> list[Interval]:
        """The intervals where the rank differs from t = 0's, or a friction joint's reaction or the
        motion is not unique."""
        r0 = self.initial.rank
        return [iv for iv in self.intervals if iv.rank != r0 or iv.nonunique or not iv.motion_unique]


def read_along(path, *, failed: bool = False) -> Along | None:
    """The :class:`Along` of an along file written by :mod:`.run` (None when there is none: an
    FMU without the discrete outputs); ``failed``: the run failed, its last row is the one held
    at the stop. :class:`InputError` naming the file when it is not such a file."""
    path = Path(path)
    if not path.is_file():
        return None
    with open(path, encoding="utf-8", newline="") as f:
        rows = list(csv.reader(f))
    head = rows[0] if rows else []
    if head[:1] != ["time"] or "rank" not in head or len(rows) < 2:
        raise InputError(f"{path}: not an along file of overcon.tooling.run (header \"time\",\"rank\",... "
                         "and at least one row expected)")
    col = {n: k for k, n in enumerate(head)}
    joints = [n[: -len(".reaction_unique")] for n in head if n.endswith(".reaction_unique")]
    out: list[Interval] = []
    for k, row in enumerate(rows[1:]):
        try:
            t, rank, flags = float(row[0]), int(row[col["rank"]]), {n: int(row[col[n]]) for n in head[1:]}
        except (ValueError, IndexError, KeyError) as exc:
            raise InputError(f"{path}: row {k + 2} is not a time and integers: {row}") from exc
        if not math.isfinite(t) or len(row) != len(head):
            raise InputError(f"{path}: row {k + 2}: a finite time and {len(head)} columns expected: {row[:4]}")
        iv = Interval(t, t, rank, tuple(j for j in joints if flags[j + ".reaction_unique"] == 0),
                      bool(flags.get("motion_unique", 1)), failed and k == len(rows) - 2)
        last = out[-1] if out else None
        if last is not None and not iv.at_stop and (last.rank, last.nonunique, last.motion_unique) == \
                (iv.rank, iv.nonunique, iv.motion_unique):
            out[-1] = dataclasses.replace(last, end=t)
        else:
            out.append(iv)
    return Along(tuple(out), failed)


@dataclass
class Comparison:
    group: str
    labels: list[str]
    infos: list[FmuInfo]
    series: list[Series]
    diffs: list[OutputDiff]
    predicted: bool | None  # None: no prediction (reference mode, or FMUs of other tools)
    solver_tolerance: float | None
    tolerance_override: float | None
    reference: Path | None = None
    wall_seconds: list[float] = field(default_factory=list)
    mode: str = "adaptive"  # what decided: "lockstep" runs, or the "adaptive" runs (fallback, reference)
    lockstep_step: float | None = None  # s
    adaptive_diff: dict = field(default_factory=dict)  # deciding output -> max abs difference, adaptive runs
    failure: str | None = None  # a run of the group failed, or the group is invalid: no verdict (the reason)
    invalid: bool = False  # the group was not run: its FMUs do not form a group (``failure`` says why)
    adaptive_failure: str | None = None  # the adaptive runs failed, the lockstep runs gave the verdict
    lockstep_note: str | None = None  # why the lockstep step differs from the one asked for (unstable rk4)
    lockstep_series: list[Series] | None = None  # the lockstep runs (mode "lockstep"): they decide, plots show them
    along: list = field(default_factory=list)  # per FMU (infos' order): its Along, or None (no discrete outputs)

    @property
    def observed(self) -> bool:
        """Unique (group mode) / within tolerance (reference mode); False when a run failed."""
        return self.failure is None and all(d.within for d in self.diffs if d.decides)

    @property
    def expected(self) -> bool:
        return True if self.predicted is None else self.predicted

    @property
    def not_excited(self) -> bool:
        """Predicted not unique, observed unique: consistent with the pre-check, whose condition is
        one-directional (friction only on unique reactions guarantees unique motion; friction on a
        non-unique reaction lets the motion depend on the elimination, and it does as soon as the
        loads reach the non-unique part of that reaction — a planar load on a mechanism of spatial
        revolute joints with parallel axes, for instance, never does)."""
        return self.failure is None and self.predicted is False and self.observed

    @property
    def matches(self) -> bool:
        """The observed verdict is consistent with the prediction: equal, or :attr:`not_excited`."""
        return self.failure is None and (self.observed == self.expected or self.not_excited)

    @property
    def run_failed(self) -> bool:
        """A simulation of the group failed (adaptive or lockstep)."""
        return (self.failure is not None and not self.invalid) or self.adaptive_failure is not None

    def worst(self, *, deciding: bool = True) -> OutputDiff | None:
        """The deciding output with the largest difference relative to its tolerance."""
        ds = [d for d in self.diffs if d.decides or not deciding]
        return max(ds, key=lambda d: (d.max_abs / d.tolerance if d.tolerance > 0 else np.inf, d.max_abs),
                   default=None)

    def max_diff_by_unit(self, *, deciding: bool = True) -> dict[str, float]:
        out: dict[str, float] = {}
        for d in self.diffs:
            if d.decides or not deciding:
                out[d.unit or ""] = max(out.get(d.unit or "", 0.0), d.max_abs)
        return out

    def adaptive_max(self) -> float | None:
        return max(self.adaptive_diff.values()) if self.adaptive_diff else None

    def verdict_text(self, value: bool | None = None) -> str:
        if value is None and self.failure is not None:
            return "failed"
        v = self.observed if value is None else value
        if self.reference is not None:
            return "within tolerance" if v else "differs"
        return "unique" if v else "not unique"


def check_grids(series: list[Series], sources: list[str]) -> None:
    """Identical time columns, or :class:`InputError` naming the files and their grids."""
    t0 = series[0].time
    step = float(np.min(np.diff(t0))) if len(t0) > 1 else 1.0
    for s, src in zip(series[1:], sources[1:]):
        same = len(s.time) == len(t0) and np.all(np.abs(s.time - t0) <= GRID_RTOL * step)
        if not same:
            raise InputError(
                f"mismatched time grids: {sources[0]} has {_grid_text(t0)}, {src} has {_grid_text(s.time)}; "
                "results are compared sample by sample (no interpolation): run them with the same "
                "--stop-time and --step")


def _grid_text(t: np.ndarray) -> str:
    d = np.diff(t)
    spacing = f"every {d[0]:g} s" if len(d) and np.allclose(d, d[0], rtol=1e-9, atol=0) else "non-uniform"
    return f"{len(t)} points, t = {t[0]:g}..{t[-1]:g} s {spacing}"


def common_outputs(infos_or_names: list[list[str]], sources: list[str]) -> list[str]:
    first = infos_or_names[0]
    common = [n for n in first if all(n in other for other in infos_or_names[1:])]
    if not common:
        raise InputError("no common outputs: " + "; ".join(
            f"{src} has {', '.join(names[:4])}{', ...' if len(names) > 4 else ''}"
            for src, names in zip(sources, infos_or_names)))
    return common


def _solver_tolerance(infos: list[FmuInfo], override: float | None) -> float | None:
    tols = [i.tolerance for i in infos if i.tolerance is not None]
    if override is None and not tols:
        raise InputError(f"{infos[0].path}: no DefaultExperiment tolerance to derive the comparison "
                         "tolerance from: give --tolerance")
    return max(tols) if tols else None


def _diff(name, unit, kind, decides, ref: np.ndarray, others: list[np.ndarray], time: np.ndarray,
          solver_tol, override, reaction_unique=None, lockstep: bool = False) -> OutputDiff:
    scale = float(max(np.max(np.abs(ref)), *(np.max(np.abs(o)) for o in others)))
    dev = np.max(np.abs(np.stack([o - ref for o in others])), axis=0)
    max_abs = float(np.max(dev))
    if override is not None:
        tol = float(override)
    elif lockstep:
        tol = lockstep_tolerance(scale)
    else:
        tol = uniqueness_tolerance(solver_tol, scale)
    over = np.nonzero(dev > tol)[0]
    return OutputDiff(name, unit, kind, decides, tol, scale, max_abs, max_abs / scale if scale > REL_FLOOR else None,
                      float(time[over[0]]) if len(over) else None, reaction_unique)


def validate_group(group: str, infos: list[FmuInfo]) -> tuple[list[str], bool | None]:
    """Before running: at least two FMUs, common outputs, one prediction. Returns (common output
    names, prediction); :class:`InputError` otherwise."""
    if len(infos) < 2:
        raise InputError(f"group {group}: only {infos[0].path} — nothing to compare (give at least two "
                         "FMUs, or --ref CSV)")
    names = common_outputs([i.output_names for i in infos], [str(i.path) for i in infos])
    for what, key in (("mechanism", lambda i: i.mechanism or "none"),
                      ("friction set", lambda i: ", ".join(sorted(i.friction)) or "none")):
        if len({key(i) for i in infos}) > 1:
            raise InputError(f"group {group}: the FMUs do not share one {what} ("
                             + "; ".join(f"{i.path.name}: {key(i)}" for i in infos)
                             + "): a group is one friction set of one mechanism under different eliminations; "
                             "give the scenes separate group names")
    # a driven group (drivers prescribe the motion) is decided on its efforts (issue 38)
    preds = {i.effort_unique if i.effort_unique is not None else i.motion_unique for i in infos}
    if len(preds) > 1:
        raise InputError(f"group {group}: the FMUs disagree on the pre-check's motion_unique ("
                         + ", ".join(f"{i.path.name}: {i.motion_unique}" for i in infos)
                         + "): they do not share a friction set; compare them in separate groups")
    return names, preds.pop()


def compare_group(group: str, infos: list[FmuInfo], series: list[Series] | None, *,
                  tolerance: float | None = None, lockstep: list[Series] | None = None,
                  lockstep_step: float | None = None, adaptive_failure: str | None = None) -> Comparison:
    """Variants of one group (same outputs, different eliminations) against the first one.
    ``series``: the adaptive runs (None when they failed, ``adaptive_failure`` saying why: the
    lockstep runs still decide and are plotted); ``lockstep``: the same FMUs run on one fixed grid
    of step ``lockstep_step`` (s), which then decide (module docstring)."""
    names, predicted = validate_group(group, infos)
    sources = [str(i.path) for i in infos]
    if series is None:
        if lockstep is None:
            raise ValueError("compare_group needs the adaptive or the lockstep runs")
        series = lockstep
    else:
        check_grids(series, sources)
    solver_tol = _solver_tolerance(infos, tolerance) if lockstep is None else None
    meta = {o.name: o for o in infos[0].outputs}
    has_positions = any(meta[n].kind == "position" for n in names)
    deciding = [n for n in names if (meta[n].kind == "position" if has_positions else True)]
    if any(meta[n].kind == "effort" for n in names):  # driven: the motion is prescribed, the efforts decide
        deciding = [n for n in names if meta[n].kind == "effort"]
    decisive = series
    if lockstep is not None:
        check_grids(lockstep, [s + " (lockstep run)" for s in sources])
        decisive = lockstep
    diffs = []
    for n in names:
        o = meta[n]
        ru = None
        if o.kind == "reaction":
            vals = {i.reaction_unique.get(o.joint) for i in infos}
            ru = vals.pop() if len(vals) == 1 else None
        diffs.append(_diff(n, o.unit, o.kind, n in deciding, decisive[0].values[n],
                           [s.values[n] for s in decisive[1:]], decisive[0].time, solver_tol, tolerance, ru,
                           lockstep=lockstep is not None))
    adaptive = {} if adaptive_failure is not None else {
        n: float(np.max(np.abs(np.stack([s.values[n] - series[0].values[n] for s in series[1:]])))) for n in deciding}
    return Comparison(group, [i.label for i in infos], infos, series, diffs, predicted, solver_tol, tolerance,
                      mode="lockstep" if lockstep is not None else "adaptive", lockstep_step=lockstep_step,
                      adaptive_diff=adaptive, adaptive_failure=adaptive_failure, lockstep_series=lockstep)


def failed_group(group: str, infos: list[FmuInfo], reason: str) -> Comparison:
    """A group one of whose deciding runs failed: no verdict, the reason is reported."""
    _, predicted = validate_group(group, infos)
    return Comparison(group, [i.label for i in infos], infos, [], [], predicted, None, None, failure=reason)


def invalid_group(group: str, infos: list[FmuInfo], reason: str) -> Comparison:
    """A group whose FMUs do not form a group (:func:`validate_group`): not run, reported."""
    return Comparison(group, [i.label for i in infos], infos, [], [], None, None, None, failure=reason, invalid=True)


def compare_reference(info: FmuInfo, result: Series, ref: Series, ref_path: Path, *,
                      tolerance: float | None = None) -> Comparison:
    """One FMU run against a reference CSV: every common output decides."""
    check_grids([ref, result], [str(ref_path), str(info.path)])
    names = common_outputs([ref.names, result.names], [str(ref_path), str(info.path)])
    solver_tol = _solver_tolerance([info], tolerance)
    meta = {o.name: o for o in info.outputs}
    diffs = []
    for n in names:
        o = meta.get(n)
        diffs.append(_diff(n, o.unit if o else None, o.kind if o else "other", True, ref.values[n],
                           [result.values[n]], ref.time, solver_tol, tolerance))
    return Comparison(info.group, ["reference", info.label], [info], [ref, result], diffs, None,
                      solver_tol, tolerance, reference=Path(ref_path))


def group_fmus(infos: list[FmuInfo]) -> dict[str, list[FmuInfo]]:
    """FMUs by scene group; groups in paper order (per mechanism: predicted unique first, then by
    number of friction joints), the FMUs of a group by eliminated equations (4 < 6; 5 < 9 < 18)."""
    groups: dict[str, list[FmuInfo]] = {}
    for i in infos:
        groups.setdefault(i.group, []).append(i)
    return order_groups(groups)


def order_groups(groups: dict[str, list[FmuInfo]]) -> dict[str, list[FmuInfo]]:
    """Groups in paper order, FMUs of a group by eliminated equations (see :func:`group_fmus`)."""

    def key(i: FmuInfo):
        e = i.eliminate
        return (0 if isinstance(e, tuple) else 1, e if isinstance(e, tuple) else (), i.model)

    def group_key(item):  # paper order: per mechanism, predicted unique first, fewer friction joints first
        g, v = item
        return (v[0].mechanism, v[0].motion_unique is False, len(v[0].friction), g)

    return {g: sorted(v, key=key) for g, v in sorted(groups.items(), key=group_key)}


def rules_text(comparisons: list[Comparison]) -> str:
    tols = sorted({c.solver_tolerance for c in comparisons if c.solver_tolerance is not None})
    steps = sorted({c.lockstep_step for c in comparisons if c.mode == "lockstep" and c.lockstep_step})
    override = {c.tolerance_override for c in comparisons} - {None}
    parts = []
    if steps:
        parts.append("Lockstep verdict: every variant of a group is run a second time on one fixed grid "
                     f"(rk4, step {', '.join(f'{h:g}' for h in steps)} s), so the variants take identical steps "
                     "and differ by round-off only unless their motion differs; the verdict comes from these runs. "
                     "The adaptive runs (the FMUs' own solver settings; figures and plots) are compared too: their "
                     "largest difference is reported as a second figure and does not decide.")
    if override:
        parts.append(f"Tolerance: absolute {', '.join(f'{t:g}' for t in sorted(override))} (--tolerance) for "
                     "every output.")
    else:
        if steps:
            parts.append(f"Tolerance: {LOCKSTEP_FACTOR:g} × max(1, scale) per output for the lockstep runs, "
                         "scale = max |y| of the output.")
        if tols:
            parts.append(f"Tolerance for the adaptive runs of FMUs that cannot run in lockstep: {UNIQUE_FACTOR:g} × solver "
                         f"tolerance × max(1, scale), scale = max |y| of the output; solver tolerance (the FMUs' "
                         f"DefaultExperiment tolerance) {', '.join(f'{t:g}' for t in tols)}.")
    return (" ".join(parts) + " Results are compared sample by sample on identical time grids (no "
            "interpolation); differences are taken against the first variant. The verdict of a group "
            "comes from the positions (outputs in m or rad); reactions are reported but do not decide "
            "(non-unique reactions differ legitimately when the motion is unique). Reference mode: "
            "every common output decides. Prediction: the FMUs' constant output `motion_unique` (pre-check). "
            "A group one of whose runs failed has no verdict (FAILED, with the reason)."
            + (" Uniqueness along the motion: the FMUs' discrete outputs `rank`, `motion_unique` and "
               "`<joint>.reaction_unique` at every output point, per FMU the intervals (first to last sample) in "
               "which the rank differs from t = 0's or a friction joint's reaction or the motion is not unique; "
               "reported, not deciding." if any(a is not None for c in comparisons for a in c.along) else ""))
