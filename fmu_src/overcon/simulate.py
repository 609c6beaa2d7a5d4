"""In-process simulation of a compiled model: the compiled core's run (core/sim.c through
:class:`overcon.kernel.Run`), the same engine, bit for bit, that the FMU runs.

State y = [q, h]; y' = [q'(q, h), h'(q, h)] in index-1 form (Eq. 18 with the chosen
elimination) with Baumgarte stabilisation ``gamma - 2 a Phi' - a^2 Phi`` (frequency a from the
solver options' ``baumgarte``, 1/s; default 10). The constraint drift max |Phi| over the accepted
steps is reported (:attr:`Simulation.max_drift`, m or rad; once per step, not per output point, so
a fine output grid costs nothing extra).

A :class:`Simulation` owns the core's run (integrator, warm starts, the singularity watch, the
uniqueness along the motion, the work ledger, counters, events); the :class:`Model` never
changes. ``get_state``/``set_state`` round-trip it exactly (the core's serialised state, bytes);
outputs are read by dense output at any time inside the last step and never disturb the
integration. :func:`run` (``overcon simulate``) has its whole output grid computed inside the
core (:meth:`Simulation.grid`, core/sim_out.c): every row of the model's output plan written into
one array allocated beforehand, no Python per output point; :meth:`Simulation.outputs` is the
same computation for one point. A point inside a step at whose end the kept equations are chosen
again comes from that step's dense output (the accepted trajectory, core/integrate_rk.c
ovk_rk_restart).

Solver options (decided here): a Simulation is given the Model and, separately, the solver
options (:class:`overcon.spec.SolverSpec`, frozen; a scene's ``scene.solver``). The Model carries
none, so a new tolerance or method is a new Simulation of the same Model: no recompilation, no
rank analysis. ``solver.kernel = "numpy"`` is a deprecated alias: it warns and runs the core (the
numpy evaluation path is retired).
"""
from __future__ import annotations

import csv
import dataclasses
import math
import warnings
from dataclasses import dataclass

import numpy as np

from . import kernel as kernel_mod
from .params import MAX_OUTPUT_POINTS, check_param, output_points
from .checks import check_initial_state, watch_rows
from .interpolation import check_interpolation
from .model import InconsistentInitialState, Model, ModelError, normalized_coordinates  # noqa: F401
from .spec import SceneSpec, SolverSpec


EVENT_KINDS = kernel_mod.EVENT_KINDS
"""Kinds of :attr:`Simulation.events` (``overcon simulate --events``): a singular position passed
(``solver.singular = "pass"``), the kept equations chosen again, the rank or a friction joint's
uniqueness changing along the motion (at the step's end, or at the located instant of the
singular position that stops the run), the run stopping (its reason)."""

NUMPY_DEPRECATED = ("solver.kernel = 'numpy' is deprecated: the numpy evaluation path is retired, and the run "
                    "uses the compiled core")
"""The warning of the deprecated ``kernel = "numpy"`` (``--kernel numpy``)."""


class SimulationError(RuntimeError):
    """Integration stopped: names the time and the cause. Raised by :func:`run`, it carries
    ``partial``: the :class:`Result` of the output points computed before the stop (possibly
    none), so that a failed run keeps what it computed."""

    partial: "Result | None" = None
    stable_step: float | None = None  # s: rk4 refused a step as unstable and named this one stable


MAX_STEPS = 1_000_000
"""Default work budget of a :class:`Simulation`: accepted internal steps over its life (the
integrator's step count, part of the saved state). The paper scenes take 80-5000 (the cost of a
step: docs/benchmarks.md)."""
MAX_WALL_TIME = 3600.0
"""Default wall-time budget (s) of a :class:`Simulation`: time spent inside :meth:`Simulation.advance`
over its life (not part of the saved state)."""


class BudgetExceeded(SimulationError):
    """The work budget (steps or wall time) of a Simulation ran out."""


BUDGET_HINT = ("; raise it with --max-steps / --max-wall-time (Simulation(max_steps=..., max_wall_time=...)) or use "
               "a larger step / looser tolerance")


def _stopped(exc: kernel_mod.RunStopped) -> SimulationError:
    """The core's stop as a :class:`SimulationError` (:class:`BudgetExceeded` for a work budget),
    worded by the core (``integration stopped: t = ...``, ``cannot start: ...``)."""
    text = str(exc)
    if exc.status == kernel_mod.BUDGET_STATUS:
        life = "work budget exhausted" in text
        err = BudgetExceeded(text.replace("; raise the budget or use a larger step / looser tolerance", BUDGET_HINT)
                             if life else text)
    else:
        err = SimulationError(text)
    err.stable_step = exc.stable_step
    return err


class Simulation:
    """A run of ``model`` (see the module docstring).

    Work budget (bounded work): ``max_steps`` accepted internal steps (default :data:`MAX_STEPS`)
    and ``max_wall_time`` seconds spent in :meth:`advance` (default :data:`MAX_WALL_TIME`), both
    over the Simulation's life; ``None`` means no limit. When one runs out, :meth:`advance` raises
    :class:`BudgetExceeded` (a :class:`SimulationError`) naming the budget, the time reached and
    how to raise it. Together with the envelopes of :mod:`overcon.params` and the input limits of
    :mod:`overcon.scene`, no run can go on without end.
    """

    def __init__(self, model: Model, solver: SolverSpec, *, method: str | None = None, tolerance: float | None = None,
                 step: float | None = None, max_step: float | None = None, start_time: float | None = None,
                 max_steps: int | None = MAX_STEPS, max_wall_time: float | None = MAX_WALL_TIME):
        self.model = model
        self.max_steps, self.max_wall_time = max_steps, max_wall_time
        given = {"method": method, "tolerance": tolerance, "step": step, "max_step": max_step}
        for name, value in given.items():  # arguments over the given (validated) solver: same rules
            reason = None if value is None else check_param(f"solver.{name}", value)
            if reason is not None:
                raise ValueError(f"Simulation({name}={value!r}): {reason}")
        self.solver = dataclasses.replace(solver, **{k: v for k, v in given.items() if v is not None})
        self.method = self.solver.method
        self.settings = {k: getattr(self.solver, k) for k in ("tolerance", "step", "max_step")}
        if model.elimination_mode == "pending":
            raise ModelError("Simulation: the model's elimination is pending: admit the compiled model first "
                             "(overcon.checks.admit, or overcon.checks.compile_checked)")
        try:
            check_initial_state(model)
        except kernel_mod.KernelUnavailable as exc:
            raise SimulationError(f"cannot start: {exc}") from exc
        for c in model.joints:
            if c.law is not None and c.law.name == "coulomb":
                raise ModelError(
                    f"joint {c.name}: friction law 'coulomb' (paper Fig. 1 variant A, mu sign(v)) is "
                    "discontinuous at v = 0: for analysis only, not for integration; use 'regularised'")
        if self.solver.kernel == "numpy":
            warnings.warn(NUMPY_DEPRECATED, DeprecationWarning, stacklevel=2)
        self.n = model.n
        self.t0 = model.scene.start_time if start_time is None else start_time
        self._target = self.t0  # the time of the last advance()
        try:
            self._run = kernel_mod.Run(model, self.solver, start_time=self.t0, max_steps=max_steps,
                                       max_wall_time=max_wall_time, watch=watch_rows(model))
        except kernel_mod.KernelUnavailable as exc:
            raise SimulationError(f"cannot start: {exc}") from exc
        except kernel_mod.RunStopped as exc:
            raise _stopped(exc) from exc
        self.kernel_note = f"right-hand side: compiled kernel ({kernel_mod.library_path()})"
        self._plans = _Plans(model)

    # -- counters of the core's run ----------------------------------------------------------
    @property
    def info(self) -> dict:
        """The core's counters (:data:`overcon.kernel.INFO`)."""
        return self._run.info

    @property
    def t(self) -> float:
        return self._run.info["t"]

    @property
    def evaluations(self) -> int:
        return int(self._run.info["evaluations"])

    @property
    def friction_iterations(self) -> int:
        return int(self._run.info["friction_iterations"])

    @property
    def max_drift(self) -> float:
        return self._run.info["max_drift"]

    @property
    def steps(self) -> int:
        return int(self._run.info["nsteps"])

    @property
    def stiff_steps(self) -> int:
        return int(self._run.info["stiff_steps"])

    @property
    def wall_time(self) -> float:
        """s spent in :meth:`advance` over the run's life."""
        return self._run.info["wall_time"]

    @property
    def events(self) -> list[tuple[float, str, str]]:
        """(time s, kind, detail) of the run so far (:data:`EVENT_KINDS`)."""
        return self._run.events

    def uniqueness(self) -> tuple[int, dict[str, bool], bool]:
        """(rank, joint name -> reaction unique, motion_unique) at the last evaluation of the
        uniqueness along the motion (:meth:`overcon.kernel.Run.uniqueness`)."""
        return self._run.uniqueness()

    # -- stepping --------------------------------------------------------------------------
    def advance(self, t_target: float, *, max_steps: int | None = None,
                max_wall_time: float | None = None) -> np.ndarray:
        """Integrate until the internal time reaches t_target; return y(t_target) by dense output.
        ``max_steps``/``max_wall_time``: the budget of this call (internal steps, seconds; e.g. one
        FMU doStep), checked after every step like the Simulation's own life budget."""
        self._target = t_target
        try:
            return self._run.advance(t_target, max_steps=max_steps, max_wall_time=max_wall_time)
        except kernel_mod.RunStopped as exc:
            raise _stopped(exc) from exc

    # -- outputs ---------------------------------------------------------------------------
    # Every output comes from the core's output plan (overcon.kernel.output_plan, core/sim_out.c),
    # the one computation :func:`run`'s grid and the FMUs use too.
    def outputs(self, t: float, y: np.ndarray) -> np.ndarray:
        """Output vector (model.output_names() order) at (t, y): :meth:`state_outputs`, then
        :meth:`derived_outputs` (reactions, friction forces)."""
        return self._row(t, y, None)

    def set_inputs(self, values, slopes=None) -> None:
        """The inputs' values (``model.inputs`` order; N, N.m) from the run's time on: held, or
        linear with ``slopes`` (per s), until set again. The run never steps past the target of
        :meth:`advance` while the model has inputs, so values set between two advances act from
        the time reached (co-simulation's communication points)."""
        try:
            self._run.set_inputs(values, slopes)
        except kernel_mod.RunStopped as exc:
            raise _stopped(exc) from exc

    def state_outputs(self, y: np.ndarray, t: float | None = None) -> np.ndarray:
        """The outputs of the state (Model.state_output_names): positions, velocities (m/s,
        rad/s: entries of h), energies (J: kinetic, potential, and the dissipated and applied
        work at t, by default the time of the last :meth:`advance`; core/energy.c)."""
        return self._row(self._target if t is None else t, y, self._plans.state)

    def position_outputs(self, y: np.ndarray) -> np.ndarray:
        """The position outputs (m, rad; quaternions as e / |e|, the orientation the dynamics use)
        at the state y."""
        return self._row(self._target, y, self._plans.position)

    def derived_outputs(self, t: float, y: np.ndarray) -> np.ndarray:
        """Reactions and friction forces at (t, y) (model.output_names() order after the
        positions; the core's table, core/outputs.c). They need lam at (t, y): the last
        evaluation's if it was at exactly this (t, y) (an output at a step's end), else one
        evaluation of Eq. 18 warm-started from the friction forces at the ends of the last two
        steps, interpolated linearly to t (so the values depend on the integrator's state only,
        never on the output grid), without changing the integration's warm start (core/sim.c)."""
        return self._row(t, y, self._plans.derived)

    def _row(self, t: float, y: np.ndarray, plan) -> np.ndarray:
        try:
            return self._run.output_row(t, y, plan)
        except kernel_mod.RunStopped as exc:
            raise _stopped(exc) from exc

    def grid(self, times: np.ndarray, plan: np.ndarray | None = None) -> tuple[np.ndarray, int, "SimulationError | None"]:
        """The run advanced through ``times`` (ascending, from the run's time on), the outputs
        (model.output_names() order; or those of the core's ``plan``, rows (kind, a, b) of
        :func:`overcon.kernel.output_plan`) at each computed inside the core (core/sim_out.c)
        into one preallocated array: (values (len(times), outputs), rows computed, the stop as a
        :class:`SimulationError` or None). Rows after a stop are NaN."""
        times = np.asarray(times, float)
        if times.size:
            self._target = float(times[-1])
        values, rows, stop = self._run.grid(times, plan)
        if rows < times.size and rows:
            self._target = float(times[rows - 1])
        return values, rows, None if stop is None else _stopped(stop)

    # -- state -----------------------------------------------------------------------------
    def get_state(self) -> bytes:
        """The run's whole state (the core's serialised bytes; core/sim_state.c)."""
        return self._run.get_state()

    def set_state(self, state: bytes) -> None:
        try:
            self._run.set_state(state)
        except kernel_mod.RunStopped as exc:
            raise ValueError(f"Simulation.set_state: {exc}") from exc


class _Plans:
    """The core's output plans of the parts of a model's outputs (rows of
    :func:`overcon.kernel.output_plan`): the state's (positions, velocities, energies), the
    positions', and the derived ones (reactions, friction forces, joint sensors)."""

    def __init__(self, model: Model):
        plan = kernel_mod.output_plan(model)
        kinds = plan[:, 0]
        K = kernel_mod.OUT_KINDS
        pick = lambda *names: np.ascontiguousarray(plan[np.isin(kinds, [K[n] for n in names])])  # noqa: E731
        self.state = pick("position", "velocity", "energy")
        self.position = pick("position")
        self.derived = pick("reaction", "friction", "sensor")


@dataclass
class Result:
    names: list[str]
    time: np.ndarray
    values: np.ndarray  # (len(time), len(names))
    max_drift: float
    evaluations: int
    friction_iterations: int
    steps: int
    stiff_steps: int = 0  # dopri5 steps whose size was limited by stability (Hairer's test)
    kernel_note: str = ""  # which engine ran (Simulation.kernel_note)
    events: tuple = ()  # (time s, kind, detail) of Simulation.events (EVENT_KINDS)

    def column(self, name: str) -> np.ndarray:
        return self.values[:, self.names.index(name)]


def output_grid(start: float, stop: float, interval: float) -> np.ndarray:
    """start, start + interval, ..., stop (the last point is stop itself)."""
    n = int(math.floor((stop - start) / interval * (1 + 1e-12) + 1e-9))
    grid = start + interval * np.arange(n + 1)
    if stop - grid[-1] > 1e-9 * interval:
        grid = np.append(grid, stop)
    else:
        grid[-1] = stop
    return grid


def run(model: Model, solver: SolverSpec, *, stop_time: float | None = None, output_interval: float | None = None,
        inputs=None, input_interpolation: str = "hold", progress=None, **settings) -> Result:
    """Simulate ``model`` with the solver options ``solver`` from the scene's start to ``stop_time``
    (default the scene's), outputs every ``output_interval`` (default ``solver.output_interval``);
    ``inputs`` an input table (:class:`overcon.tooling.inputs.InputTable`, a column per input of
    ``model.inputs``) set at every output point as a co-simulation host sets them at its
    communication points, ``input_interpolation`` "hold" (the default: the value there, held over the
    interval) or "linear" (with fmpy's first derivative there: :meth:`InputTable.step`; another
    name is a ``ValueError``: :func:`overcon.interpolation.check_interpolation`); the outputs
    at an output point see the values of the interval that ends there (the start's: its own), as an
    FMU's after fmi2DoStep; ``progress(t)``, if given, is called at every output point (``overcon
    simulate``'s bar); ``settings`` go to :class:`Simulation`."""
    if inputs is not None:
        check_interpolation(input_interpolation)
    scene = model.scene
    stop = scene.stop_time if stop_time is None else stop_time
    interval = solver.output_interval if output_interval is None else output_interval
    reason = check_param("solver.output_interval", interval)
    if reason is None and not output_points(dataclasses.replace(solver, output_interval=interval),
                                           scene.start_time, stop) <= MAX_OUTPUT_POINTS:
        reason = f"more than {MAX_OUTPUT_POINTS:.0e} output points from {scene.start_time:g} to {stop:g} s"
    if reason is not None:
        raise ValueError(f"run(output_interval={interval!r}): {reason}")
    sim = Simulation(model, solver, **settings)
    grid = output_grid(scene.start_time, stop, interval)
    if inputs is None:
        values, rows, stop_exc = _grid_in_chunks(sim, grid, progress)
    else:  # point by point: the inputs are set between two output points, as a host sets them
        names = [u.name for u in model.inputs]
        values = np.full((len(grid), len(model.output_names())), np.nan)
        rows, stop_exc = 0, None
        for k, t in enumerate(grid):
            if k == 0:  # the values at the start, before its outputs
                _feed(sim, inputs, names, grid, k, input_interpolation)
            row, got, stop_exc = sim.grid(grid[k:k + 1])
            values[k:k + got] = row[:got]
            rows += got
            if stop_exc is not None:
                break
            if k + 1 < len(grid):  # the outputs at t saw the last interval's values
                _feed(sim, inputs, names, grid, k, input_interpolation)
            if progress is not None:
                progress(t)
    if stop_exc is not None:
        stop_exc.partial = _result(model, sim, grid[:rows], values[:rows])
        raise stop_exc
    return _result(model, sim, grid, values)


PROGRESS_CHUNKS = 200
"""A run with a progress callback computes its grid in at most this many calls of the core."""


def _grid_in_chunks(sim: "Simulation", grid: np.ndarray, progress) -> tuple:
    """:meth:`Simulation.grid` over the whole grid (one call), or in chunks with ``progress(t)``
    called after each (``overcon simulate``'s bar): the same rows either way."""
    if progress is None:
        return sim.grid(grid)
    values = np.full((len(grid), len(sim.model.output_names())), np.nan)
    rows = 0
    for part in np.array_split(np.arange(len(grid)), min(PROGRESS_CHUNKS, len(grid))):
        if not part.size:
            continue
        chunk, got, stop_exc = sim.grid(grid[part[0]:part[-1] + 1])
        values[part[0]:part[0] + got] = chunk[:got]
        rows += got
        if stop_exc is not None:
            return values, rows, stop_exc
        progress(float(grid[part[-1]]))
    return values, rows, None


def _feed(sim: Simulation, table, names, grid, k: int, interpolation: str) -> None:
    """The inputs over the output interval from grid[k] (:meth:`InputTable.step`)."""
    value, slope = table.step(grid[k], interpolation)
    sim.set_inputs([value[n] for n in names], [slope[n] for n in names] if interpolation == "linear" else None)


def _result(model: Model, sim: Simulation, time: np.ndarray, values: np.ndarray) -> Result:
    """The :class:`Result` of the output points ``time`` and their rows ``values`` so far, with
    the run's counters."""
    return Result(model.output_names(), np.asarray(time), values, sim.max_drift, sim.evaluations,
                  sim.friction_iterations, sim.steps, sim.stiff_steps, sim.kernel_note, tuple(sim.events))


def run_scene(scene: SceneSpec, **kw) -> Result:
    """Compile ``scene`` and :func:`run` it with its own solver options ``scene.solver``."""
    from .checks import compile_checked
    return run(compile_checked(scene), scene.solver, **kw)


def write_events(events, path) -> None:
    """The events of a run (:data:`EVENT_KINDS`) as CSV: ``time`` (s), ``kind``, ``detail``; the
    header alone when there were none. Written whole or not at all (overcon.outfiles)."""
    from .outfiles import atomic
    with atomic(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["time", "kind", "detail"])
        for t, kind, detail in events:
            w.writerow([repr(float(t)), kind, detail])


def write_csv(result: Result, path) -> None:
    """The result as CSV (time, then the outputs), written whole or not at all (overcon.outfiles)."""
    from .outfiles import atomic
    with atomic(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["time", *result.names])
        for t, row in zip(result.time, result.values):
            w.writerow([repr(float(t)), *(repr(float(v)) for v in row)])
