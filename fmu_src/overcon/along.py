"""Uniqueness along the motion (``overcon check --along T``): the pre-check's tests repeated at
every output point of a run, so that a user sees where the Jacobian's rank, or the uniqueness of
a friction joint's reaction, differs from what the pre-check found at t = 0.

Decided here: the run is the scene's own (its solver options and elimination; in process), the
samples are its output points (``solver.output_interval``), and each sample runs the
one-factorisation test (:func:`overcon.analysis.analyse` with ``methods = "svd"``: one SVD of the
whole Jacobian at that configuration) with the pre-check's rank tolerance. What holds between two
samples is not seen, except that a loss of rank of the kept equations stops the run (the watch
of every run, core/watch.c), and the stop is reported. The samples are grouped into segments of
constant (rank, friction joints whose reaction is not unique).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .analysis import analyse, numerical_rank
from . import kernel as kernel_mod
from .kernel import rows_kernel
from .precheck import compliant_joints, frictionless
from .simulate import Simulation, output_grid


@dataclass(frozen=True)
class Segment:
    """Samples from ``start`` to ``end`` (s) with the same ``rank`` and the same friction joints
    whose reaction is not unique (``nonunique``, names in joint order)."""

    start: float
    end: float
    rank: int
    nonunique: tuple[str, ...]


@dataclass(frozen=True)
class AlongReport:
    stop_time: float  # s, asked
    interval: float  # s, between samples
    segments: tuple[Segment, ...]
    stopped: str | None  # the run's stop (its message), or None when it reached stop_time

    @property
    def friction_on_nonunique(self) -> bool:
        return any(s.nonunique for s in self.segments)

    def to_json(self) -> dict:
        return {"stop_time": self.stop_time, "interval": self.interval, "stopped": self.stopped,
                "segments": [{"from": s.start, "to": s.end, "rank": s.rank,
                              "nonunique_friction_joints": list(s.nonunique)} for s in self.segments]}


def _friction_names(model) -> list[str]:
    """Friction joints that exert a force and are rigid (a compliant joint's reaction is unique)."""
    compliant = compliant_joints(model)
    return [model.joints[j].name for j in model.friction_joints
            if not frictionless(model.joints[j].law) and model.joints[j].name not in compliant]


def sample(model, q: np.ndarray, names: list[str], rows=None) -> tuple[int, tuple[str, ...]]:
    """(rank of the rigid equations' Jacobian, friction joints ``names`` whose reaction is not
    unique) at the coordinates q. ``rows``: the model's :func:`overcon.kernel.rows_kernel`, made
    once for a run's samples (default: one made here)."""
    kern = rows_kernel(model) if rows is None else rows
    compliant = set(int(r) for r in model.compliant_rows)
    rigid = [i for i in range(model.m) if i not in compliant]
    J = kern.rows(np.concatenate([q, np.zeros(model.nh)]))[1].T[:, rigid]
    position = {row: k for k, row in enumerate(rigid)}
    wanted = set(names)
    groups = {c.name: [position[r] for r in c.rows] for c in model.joints if c.name in wanted}
    rank = numerical_rank(J)
    if not groups:
        return rank, ()
    verdicts = analyse(J, groups, methods="svd").joints
    return rank, tuple(n for n in names if not verdicts[n].unique)


def _segments(samples: list[tuple[float, int, tuple[str, ...]]]) -> tuple[Segment, ...]:
    out: list[Segment] = []
    for t, rank, nonunique in samples:
        if out and (out[-1].rank, out[-1].nonunique) == (rank, nonunique):
            out[-1] = Segment(out[-1].start, t, rank, nonunique)
        else:
            out.append(Segment(t, t, rank, nonunique))
    return tuple(out)


def along(model, solver, stop_time: float) -> AlongReport:
    """Run ``model`` to ``stop_time`` (s) and sample it (module docstring)."""
    start = model.scene.start_time
    if not stop_time > start:
        raise ValueError(f"--along {stop_time:g}: must be after the scene's start time {start:g} s")
    names = _friction_names(model)
    sim, rows = Simulation(model, solver), rows_kernel(model)
    grid = output_grid(start, stop_time, solver.output_interval)
    coordinates = np.array([(kernel_mod.STATE_KIND, i, 0) for i in range(model.n)], np.intc).reshape(-1, 3)
    q, done, stop = sim.grid(grid, coordinates)  # the run's whole grid inside the core
    samples = [(float(t), *sample(model, q[k], names, rows)) for k, t in enumerate(grid[:done])]
    return AlongReport(stop_time, solver.output_interval, _segments(samples), None if stop is None else str(stop))


def format_along(report: AlongReport) -> str:
    """The lines ``check --along`` adds to the table."""
    lines = [f"along the motion (sampled every {report.interval:g} s up to {report.stop_time:g} s):"]
    for s in report.segments:
        which = ("friction reactions unique" if not s.nonunique
                 else f"friction on non-unique joint(s): {', '.join(s.nonunique)}")
        lines.append(f"  t = {s.start:g}..{s.end:g} s: rank {s.rank}; {which}")
    if report.stopped:
        lines.append(f"  the run stopped: {report.stopped}")
    return "\n".join(lines)
