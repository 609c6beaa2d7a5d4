"""In-process simulation of a compiled model: the same engine the FMU facade drives.

State y = [q, h]; y' = [q'(q, h), h'(q, h)] in index-1 form (Eq. 18 with the chosen
elimination) with Baumgarte stabilisation ``gamma - 2 a Phi' - a^2 Phi`` (frequency a from the
solver options' ``baumgarte``, 1/s; default 10). The constraint drift max |Phi| over the accepted
steps is reported (:attr:`Simulation.max_drift`, m or rad; once per step, not per output point, so
a fine output grid costs nothing extra).

A :class:`Simulation` owns everything that changes during a run (integrator arrays, the last
converged lam used as the friction solve's warm start, counters); the :class:`Model` never
changes. ``get_state``/``set_state`` round-trip it exactly; outputs are read by dense output at
any time inside the last step and never disturb the integration.

Right-hand side: the compiled kernel (:mod:`overcon.kernel`) where the solver setting ``kernel``
and the model allow it, else :func:`overcon.dynamics.evaluate`; :attr:`Simulation.kernel_note`
says which (the FMU logs it), :attr:`Simulation.kernel_repeats` counts the evaluations the kernel
handed back to the numpy path.

Solver options (decided here): a Simulation is given the Model and, separately, the solver
options (:class:`overcon.spec.SolverSpec`, frozen; a scene's ``scene.solver``). The Model carries
none, so a new tolerance or method is a new Simulation of the same Model: no recompilation, no
rank analysis (the FMU relies on this).
"""
from __future__ import annotations

import copy
import csv
import dataclasses
import math
import time
from dataclasses import dataclass

import numpy as np

from . import kernel as kernel_mod
from .dynamics import evaluate
from . import integrators
from .evaluation import (SingularConfiguration, compliant_energy, constant_loads, constraints,  # noqa: F401
                         coordinate_rates, frames, friction_output, jacobian_h, kinetic_energy, normalized_coordinates,
                         physical_reaction, physical_reactions, potential_energy)
from .params import MAX_OUTPUT_POINTS, check_param, output_points
from .checks import check_initial_state, with_eliminated
from .model import InconsistentInitialState, Model, ModelError  # noqa: F401
from .spec import SceneSpec, SolverSpec
from .watch import (ALONG_RATIO, EliminationExpired, SingularityMonitor, SingularPosition,  # noqa: F401
                    Uniqueness, friction_on_nonunique, reselected, shown_ratio, valid_eliminations)


EVENT_KINDS = kernel_mod.EVENT_KINDS
"""Kinds of :attr:`Simulation.events` (``overcon simulate --events``): a singular position passed,
the kept equations chosen again, the rank or a friction joint's uniqueness changing along the
motion (:class:`overcon.watch.Uniqueness`: at the step's end, or at the located instant of the
singular position that stops the run), the run stopping (its reason). ``singular`` is not
recorded by this version: a singular position of the mechanism stops every method (no
formulation here passes one and keeps the branch, see the README), and the stop says so."""


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
        self.wall_time = 0.0  # s spent in advance()
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
        check_initial_state(model)
        for c in model.joints:
            if c.law is not None and c.law.name == "coulomb":
                raise ModelError(
                    f"joint {c.name}: friction law 'coulomb' (paper Fig. 1 variant A, mu sign(v)) is "
                    "discontinuous at v = 0: for analysis only, not for integration; use 'regularised'")
        self.n = model.n
        try:
            self._kernel, self.kernel_note = kernel_mod.select(model, self.solver)
        except kernel_mod.KernelUnavailable as exc:
            raise SimulationError(f"cannot start: {exc}") from exc
        self.kernel_repeats = 0  # evaluations the kernel handed back to the numpy path
        # auto, a model the kernel covers, and yet no library (none compiled, or it cannot be loaded)
        self.kernel_missing = (self._kernel is None and self.solver.kernel == "auto"
                               and kernel_mod.support(model) is None)
        self.lam = None  # last converged multipliers (friction warm start)
        self._warm = _ForcesHistory()  # friction forces of the integration's solves (warm start)
        self._step_warm = _ForcesHistory()  # the latest ones at the last two step ends (outputs' warm start)
        self._last_eval = None  # (t, y, lam) of the last right-hand side: reused by outputs() at that point
        self._derived = _DerivedPlan(model)
        self.friction_iterations = 0
        self.evaluations = 0
        self.max_drift = 0.0
        self.events: list[tuple[float, str, str]] = []  # (time s, kind, detail): see :data:`EVENT_KINDS`
        t0 = model.scene.start_time if start_time is None else start_time
        self._target = t0  # the time of the last advance()
        y0 = np.concatenate([model.q0, model.h0])
        try:
            self._integrator = integrators.create(self.method, self._rhs, t0, y0, dense_fun=self._rhs_dense,
                                                  **self.settings)
            self.monitor = SingularityMonitor(model, y0, t0, jac=self._jacobian_source(), passing=self._passing())
            self.along = Uniqueness(model, y0, self._kernel)
            self._work = _WorkLedger(t0, self._powers(t0, y0)) if model.energy_outputs else None
        except (ArithmeticError, np.linalg.LinAlgError) as exc:
            self.events.append((t0, "stopped", str(exc)))
            where = "" if str(exc).startswith("t = ") else f"t = {t0:.9g} s: "
            raise SimulationError(f"cannot start: {where}{exc}") from exc

    # -- right-hand side -------------------------------------------------------------------
    def _solve(self, t: float, y: np.ndarray, lam_guess, qf_guess):
        """One evaluation of Eq. 18 at (t, y): (the compiled kernel's (y', lam, qf, friction
        iterations), None) when this run has one and it succeeds, else (None, the
        :func:`overcon.dynamics.evaluate` Evaluation), also for every evaluation the kernel hands
        back (a singular position, the friction solve's fallback, ...). Warm start as
        :func:`overcon.dynamics.evaluate` (``qf_guess``, then ``lam_guess``)."""
        failed = 0
        if self._kernel is not None:
            r = self._kernel.evaluate(t, y, lam_guess, qf_guess)
            if r is not None:
                return r, None
            if self.solver.singular == "pass":  # the numpy path has only the eliminated form
                return self._core_only(t, y, lam_guess), None
            self.kernel_repeats += 1
            failed = self._kernel.newton_failed()
        return None, evaluate(self.model, t, y[: self.n], y[self.n:], lam_guess, solver=self.solver,
                              qf_guess=qf_guess, newton_failed=failed)

    def _core_only(self, t: float, y: np.ndarray, lam_guess):
        """Under ``solver.singular = "pass"``, an evaluation the core handed back: the friction solve
        finished by the core's robust path (as the numpy path's), any other status stops the step
        with the core's message."""
        kernel = self._kernel
        if kernel.last_status == 2:
            r = kernel.evaluate_robust(y, lam_guess)
            if r is not None:
                return r
        raise ArithmeticError(f"t = {t:.9g} s: {kernel.last_message} (compiled core, solver.singular = 'pass')")

    def _passing(self):
        """The watch's ``passing`` hook for ``solver.singular = "pass"`` (a ``singular`` event), else None."""
        if self.solver.singular != "pass":
            return None
        return lambda t, detail: self.events.append((t, "singular", detail))

    def _project(self, itg) -> None:
        """``solver.singular = "pass"``, after an accepted step: the state projected onto the
        constraints (every equation), mass-orthogonally (positions, then velocities: core/project.c through
        :meth:`overcon.kernel.Kernel.project`), and the integrator's last derivative (the FSAL
        stage of dopri5, the start of rk4's next step) evaluated again there. The dense output of
        the step keeps the unprojected end (within the drift, <= 1e-9 m at tolerance 1e-9)."""
        try:
            y, _ = self._kernel.project(itg.t, itg.y)
        except kernel_mod.ProjectionFailed as exc:
            raise ArithmeticError(str(exc)) from None
        itg.y = y
        itg.f = self._rhs(itg.t, y)

    def _evaluate(self, t: float, y: np.ndarray, lam_guess, qf_guess):
        """(y', lam, qf, friction iterations) at (t, y) (:meth:`_solve`; the numpy path adds the
        coordinate rates)."""
        r, ev = self._solve(t, y, lam_guess, qf_guess)
        if r is not None:
            return r
        rates = coordinate_rates(self.model, y[: self.n], y[self.n:], ev.frames)
        return np.concatenate([rates, ev.hdot]), ev.lam, ev.qf, ev.iterations

    def _rhs(self, t: float, y: np.ndarray) -> np.ndarray:
        out, lam, qf, iterations = self._evaluate(t, y, self.lam, self._warm.guess(t))
        if self.model.friction_joints:
            self.lam = lam
            self._warm.push(t, qf)
        self.friction_iterations += iterations
        self.evaluations += 1
        self._last_eval = (t, y.copy(), lam)
        if not np.all(np.isfinite(out)):
            raise SimulationError(f"t = {t:.9g} s: non-finite derivative")
        return out

    def _rhs_dense(self, t: float, y: np.ndarray) -> np.ndarray:
        """Right-hand side for dense-output stages only: warm-started from the integrator's lam but
        leaving it (and the counters) unchanged, so reading outputs never alters the trajectory."""
        return self._evaluate(t, y, None if self.lam is None else self.lam.copy(), self._warm.guess(t))[0]

    # -- stepping --------------------------------------------------------------------------
    @property
    def t(self) -> float:
        return self._integrator.t

    def advance(self, t_target: float, *, max_steps: int | None = None,
                max_wall_time: float | None = None) -> np.ndarray:
        """Integrate until the internal time reaches t_target; return y(t_target) by dense output.
        ``max_steps``/``max_wall_time``: the budget of this call (internal steps, seconds; e.g. one
        FMU doStep), checked after every step like the Simulation's own life budget."""
        itg = self._integrator
        self._target = t_target
        eps = 1e-12 * max(1.0, abs(t_target))
        started = time.perf_counter()
        call = (itg.nsteps, max_steps, max_wall_time)
        try:
            while itg.t < t_target - eps:
                try:
                    self._step(itg, started, call)
                except (ArithmeticError, ValueError, np.linalg.LinAlgError) as exc:
                    if not self._recover(itg, exc):
                        raise
                itg = self._integrator  # a new one when the kept equations were chosen again
        except (ArithmeticError, ValueError, np.linalg.LinAlgError) as exc:
            where = "" if str(exc).startswith("t = ") else f"t = {itg.t:.9g} s: "
            self.events.append((getattr(exc, "t", itg.t), "stopped", f"{where}{exc}"))
            err = SimulationError(f"integration stopped: {where}{exc}")
            err.stable_step = getattr(exc, "stable_step", None)
            raise err from exc
        finally:
            self.wall_time += time.perf_counter() - started
        if itg.t - t_target < -eps:
            raise SimulationError(f"could not reach t = {t_target}")
        return itg.dense(t_target) if abs(itg.t - t_target) > eps else itg.y.copy()

    def _step(self, itg, started: float, call) -> None:
        """One accepted step, watched (:meth:`_watch`), with the drift and the budget."""
        t_before = itg.t
        itg.step()
        if not itg.t > t_before:
            raise SimulationError(f"t = {t_before:.9g} s: time does not advance (step below the resolution of t)")
        if self.solver.singular == "pass":
            self._project(itg)
        if not self._watch(itg):
            return  # the step is taken again from its start, under another elimination
        if self.monitor.ratio < ALONG_RATIO:  # only there can the rank or a verdict change (watch.Uniqueness)
            self.events += self.along.update(itg.t, itg.y)
        if self._work is not None:
            mid = 0.5 * (itg.t_old + itg.t)
            self._work.step(itg.t, self._powers(mid, itg.dense(mid)), self._powers(itg.t, itg.y))
        if self._warm.items:
            self._step_warm.push(itg.t, self._warm.items[0][1])
        self.max_drift = max(self.max_drift, float(np.max(np.abs(self._constraints(itg.y)), initial=0.0)))
        self._check_budget(itg, started, call)

    def _recover(self, itg, exc) -> bool:
        """After a step failed with ``exc``: True if the cause was the elimination expiring
        (:meth:`overcon.watch.SingularityMonitor.expiring`) and the run goes on under another one
        (:meth:`_expired`); raises the expiry (with ``exc``'s message) when it cannot; False
        when the failure has another cause."""
        if isinstance(exc, (SingularConfiguration, BudgetExceeded)) or not hasattr(itg, "t_old"):
            return False
        found = self.monitor.expiring(itg.t, itg.y, itg.t - itg.t_old)
        if found is None:
            return False
        t_star, y_star = found
        expired = EliminationExpired(
            f"t = {t_star:.9g} s: the kept equations lose rank here while the mechanism stays regular: the elimination "
            f"chosen at the start expires (the step from t = {itg.t:.9g} s failed: {exc})", t_star, 0.0, y_star, itg.t)
        self._expired(expired, itg.t, itg.y.copy())
        return True

    def _jacobian_source(self):
        """Phi_h for the watch: the compiled core's rows when this run has the core (the same
        joint rows, without numpy's per-call overhead), else None (the numpy path). The rows
        of the last state asked for are kept (:meth:`_constraints` reads Phi from them)."""
        kernel = self._kernel
        if kernel is None:
            return None

        def jac(model, y):
            phi, J, _ = kernel.rows(y)
            self._rows_at = (y.copy(), phi)
            return J
        return jac

    def _constraints(self, y: np.ndarray) -> np.ndarray:
        """Phi at the state y: from the core's rows the watch just computed at y, else evaluated."""
        cached = getattr(self, "_rows_at", None)
        if cached is not None and np.array_equal(cached[0], y):
            return cached[1]
        return constraints(self.model, frames(self.model, y[: self.n]))

    def _powers(self, t: float, y: np.ndarray) -> np.ndarray:
        """[power dissipated by joint friction and the compliant joints' dampers (W, >= 0), power
        of the constant forces and torques (W)] at (t, y): one evaluation of Eq. 18 for the
        friction forces (warm-started like the dense output, leaving the integration's warm start
        alone; counted in ``evaluations``)."""
        h = y[self.n:]
        f = frames(self.model, y[: self.n], h)
        applied = float(h @ constant_loads(self.model, f))
        damper = compliant_energy(self.model, f, h)[1]
        if not self.model.friction_joints:
            return np.array([damper, applied])
        r, ev = self._solve(t, y, None if self.lam is None else self.lam.copy(), self._warm.guess(t))
        self.evaluations += 1
        qf = r[2] if r is not None else ev.friction
        return np.array([damper - float(h[self.model.plan.friction_cols] @ qf), applied])

    def work(self, t: float) -> np.ndarray:
        """[energy dissipated by friction and dampers, work of the constant loads] (J) from the start to t,
        t inside the last step (:class:`_WorkLedger`)."""
        return self._work.at(t)

    def _watch(self, itg) -> bool:
        """The singularity watch after an accepted step (:mod:`overcon.watch`). False when the
        kept equations expired inside the step and the motion does not depend on the
        elimination: the equations are then chosen again at that instant (pivoted QR), an
        ``elimination-reselected`` event is recorded, and the integration restarts from the
        step's start under the new elimination (the integrator is rebuilt; its counters go on).
        With friction on a joint whose reaction is not unique the elimination decides the
        motion: the run stops, naming the eliminations that stay valid."""
        try:
            f = getattr(itg, "f", None)
            if self.monitor.check(itg.t, itg.y, itg.dense, None if f is None else f[: self.n]):
                self._degraded(itg)
            return True
        except EliminationExpired as exc:
            self._expired(exc, itg.t_old, itg.y_old.copy())
            return False
        except SingularPosition as exc:  # the rank and the verdicts at the instant the run stops
            if exc.y is not None:
                self.events += self.along.update(exc.t, exc.y)
            raise

    def _degraded(self, itg) -> None:
        """The kept equations are becoming ill-conditioned while the mechanism is not: when the
        motion does not depend on the elimination, choose the equations again at the step's end
        and go on from there (an ``elimination-reselected`` event), before the
        ill-conditioning costs accuracy; else keep the elimination (it decides the motion), and
        the run stops if it expires."""
        if not friction_on_nonunique(self.model, itg.y):
            self._choose_again(itg.y, itg.t, f"the kept equations became ill-conditioned: sigma_min/sigma_max "
                                             f"{shown_ratio(self.monitor.ratio)}", itg.t, itg.y.copy())

    def _expired(self, exc: EliminationExpired, t: float, y: np.ndarray) -> None:
        """The kept equations expired at ``exc.t``: choose them again there and restart from
        (t, y), or, with friction on a joint whose reaction is not unique, raise the stop."""
        nonunique = friction_on_nonunique(self.model, exc.y)
        if nonunique:
            valid = valid_eliminations(self.model, exc.y)
            raise EliminationExpired(
                f"{exc}; with friction on {', '.join(nonunique)}, whose reaction is not unique, the elimination "
                f"decides the motion, so the run stops (eliminated: "
                f"{', '.join(f'Phi{i}' for i in self.model.eliminated) or 'none'}; other eliminations valid at the "
                f"start and here: {', '.join(valid) or 'none found'})", exc.t, exc.ratio, exc.y, exc.t_step) from None
        if not self._choose_again(exc.y, exc.t, f"the kept equations lost rank at t = {exc.t:.9g} s", t, y):
            raise exc

    def _choose_again(self, y_at: np.ndarray, t_event: float, why: str, t: float, y: np.ndarray) -> bool:
        """Choose the eliminated equations again at the state ``y_at`` (pivoted QR), record the
        ``elimination-reselected`` event at ``t_event`` and go on from (t, y); False when the
        choice is the elimination already in use."""
        before = self.model.eliminated
        model, eliminated = reselected(self.model, y_at)
        if list(before) == eliminated:
            return False
        self.events.append((t_event, "elimination-reselected", f"eliminated {list(before)} -> {eliminated} ({why})"))
        self._restart(model, t, y)
        return True

    def _restart(self, model: Model, t: float, y: np.ndarray) -> None:
        """Go on from (t, y) under ``model`` (another elimination of the same mechanism): a new
        integrator with the same settings and counters, warm starts, and :meth:`_adopt`."""
        old = self._integrator
        self.lam, self._warm, self._step_warm, self._last_eval = None, _ForcesHistory(), _ForcesHistory(), None
        self._adopt(model, t, y)  # first: the new integrator's first derivative is the new model's
        self._integrator = integrators.create(self.method, self._rhs, t, y, dense_fun=self._rhs_dense,
                                              **self.settings)
        self._integrator.nsteps, self._integrator.nfev = old.nsteps, old.nfev

    def _adopt(self, model: Model, t: float, y: np.ndarray) -> None:
        """Run ``model`` (another elimination of the same mechanism) from (t, y): its kernel, output
        plan and watch."""
        self.model = model
        self._kernel, self.kernel_note = kernel_mod.select(model, self.solver)
        self._derived = _DerivedPlan(model)
        self.monitor = SingularityMonitor(model, y, t, jac=self._jacobian_source(), passing=self._passing())
        if hasattr(self, "along"):  # the verdicts do not depend on the elimination: kept
            self.along.model, self.along.kernel = model, self._kernel

    def _check_budget(self, itg, started: float, call=(0, None, None)) -> None:
        """Raise BudgetExceeded when the step count or the wall time is used up: the Simulation's
        (over its life) or this :meth:`advance` call's (``call`` = steps at its start, its
        max_steps, its max_wall_time)."""
        n0, call_steps, call_wall = call
        if call_steps is not None and itg.nsteps - n0 > call_steps:
            raise BudgetExceeded(f"{itg.nsteps - n0} internal steps > {call_steps} allowed for this step, "
                                 f"at t = {itg.t:.9g} s")
        if call_wall is not None and time.perf_counter() - started > call_wall:
            raise BudgetExceeded(f"{time.perf_counter() - started:.3g} s wall time > {call_wall:g} s allowed for "
                                 f"this step, at t = {itg.t:.9g} s")
        if self.max_steps is not None and itg.nsteps >= self.max_steps:
            raise BudgetExceeded(
                f"work budget exhausted: {itg.nsteps} internal steps (max_steps = {self.max_steps}) reached "
                f"t = {itg.t:.9g} s of {self.model.scene.stop_time:g} s; raise it with --max-steps "
                "(Simulation(max_steps=...)) or use a larger step / looser tolerance")
        spent = self.wall_time + time.perf_counter() - started
        if self.max_wall_time is not None and spent > self.max_wall_time:
            raise BudgetExceeded(
                f"work budget exhausted: wall time {spent:.1f} s (max_wall_time = {self.max_wall_time:g} s) "
                f"reached t = {itg.t:.9g} s of {self.model.scene.stop_time:g} s after {itg.nsteps} steps; "
                "raise it with --max-wall-time (Simulation(max_wall_time=...)) or use a larger step / "
                "looser tolerance")

    def outputs(self, t: float, y: np.ndarray) -> np.ndarray:
        """Output vector (model.output_names() order) at (t, y): :meth:`state_outputs`, then
        :meth:`derived_outputs` (reactions, friction forces)."""
        pos = self.state_outputs(y, t)
        if not self._derived.size:
            return pos
        return np.concatenate((pos, self.derived_outputs(t, y)))

    def state_outputs(self, y: np.ndarray, t: float | None = None) -> np.ndarray:
        """The outputs of the state (Model.state_output_names): positions, velocities (m/s,
        rad/s: entries of h), energies (J; the dissipated and applied work at t, by default the
        time of the last :meth:`advance`)."""
        pos = self.position_outputs(y)
        model = self.model
        if not model.velocity_outputs and not model.energy_outputs:
            return pos
        h = y[self.n:]
        parts = [pos, h[self._derived.velocity_index]]
        if model.energy_outputs:
            q = normalized_coordinates(model, y[: self.n]) if model.rotation == "quaternion" else y[: self.n]
            f = frames(model, q, h)
            potential = potential_energy(model, f) + compliant_energy(model, f, h)[0]
            parts.append(np.array([kinetic_energy(model, h), potential]))
            parts.append(self.work(self._target if t is None else t))
        return np.concatenate(parts)

    def position_outputs(self, y: np.ndarray) -> np.ndarray:
        """The position outputs (m, rad; quaternions as e / |e|, the orientation the dynamics use)
        at the state y."""
        q = y[: self.n]
        if self.model.rotation == "quaternion":
            q = normalized_coordinates(self.model, q)
        return q[self._derived.position_index]

    def derived_outputs(self, t: float, y: np.ndarray) -> np.ndarray:
        """Reactions and friction forces at (t, y) (model.output_names() order after the
        positions; :func:`overcon.evaluation.physical_reaction`, :func:`overcon.evaluation.friction_output`,
        computed per joint type at once). They need lam at (t, y): the last right-hand side's if it was
        evaluated at exactly this (t, y) (an output at the end of a step: the last stage of
        dopri5/dop853 and rk4's step end, the same evaluation of Eq. 18), else one evaluation of Eq. 18
        warm-started from the friction forces at the ends of the last two integrator steps,
        interpolated linearly to t (so the values depend on the integrator's state only, never on
        the output grid), without changing the integrator's warm start."""
        model, plan = self.model, self._derived
        if not plan.size:
            return np.zeros(0)
        last = self._last_eval
        f = None
        if last is not None and last[0] == t and np.array_equal(last[1], y):
            lam = last[2]
        else:
            warm = self._step_warm if self._step_warm.items else self._warm
            r, ev = self._solve(t, y, None if self.lam is None else self.lam.copy(), warm.guess(t))
            f, lam = (None, r[1]) if r is not None else (ev.frames, ev.lam)
        if self._kernel is not None:
            return plan.values_from_kernel(*self._kernel.outputs(y, lam))
        return plan.values(model, frames(model, y[: self.n], y[self.n:]) if f is None else f, lam)
    # -- state -----------------------------------------------------------------------------
    def get_state(self) -> dict:
        return {"integrator": self._integrator.get_state(),
                "lam": None if self.lam is None else self.lam.copy(),
                "friction_warm": self._warm.state(), "step_warm": self._step_warm.state(),
                "last_eval": None if self._last_eval is None else tuple(
                    x.copy() if isinstance(x, np.ndarray) else x for x in self._last_eval),
                "friction_iterations": self.friction_iterations, "evaluations": self.evaluations,
                "max_drift": self.max_drift,
                "monitor": self.monitor.state(), "events": list(self.events), "target": self._target,
                "along": self.along.state(),
                "work": None if self._work is None else self._work.state(),
                "eliminated": self.model.eliminated}

    def set_state(self, state: dict) -> None:
        state = copy.deepcopy(state)
        self._integrator.set_state(state["integrator"])
        self.lam = state["lam"]
        self._warm.set_state(state.get("friction_warm", ()))  # states saved before: the lam warm start
        self._step_warm.set_state(state.get("step_warm", ()))
        self._last_eval = state.get("last_eval")  # states saved before it existed: None (a fresh solve)
        self.friction_iterations = state["friction_iterations"]
        self.evaluations = state["evaluations"]
        self.max_drift = state["max_drift"]
        self.events = list(state.get("events", ()))
        self._target = state.get("target", self._integrator.t)
        if self._work is not None:
            self._work.set_state(state["work"])
        if tuple(state.get("eliminated", self.model.eliminated)) != tuple(self.model.eliminated):
            self._use_elimination(state["eliminated"])
        self.monitor.set_state(state["monitor"])
        if "along" in state:  # states saved before it existed: the verdicts at the start
            self.along.set_state(state["along"])

    def _use_elimination(self, eliminated) -> None:
        """Take the elimination of a saved state (one chosen again during the run)."""
        self._adopt(with_eliminated(self.model, eliminated), self._integrator.t, self._integrator.y)


class _WorkLedger:
    """The work of friction and of the constant loads since the start (J), accumulated over the
    accepted steps by Simpson's rule on the powers at each step's start, middle (dense output) and
    end, and read inside the last step by the cubic Hermite interpolant of the work and its rate
    (the powers) at the step's ends: O(h^4) per step, like the rule, with no extra evaluation per
    output point (decided here: the integrator's own order is higher, so a tight tolerance keeps
    the balance within the integration's accuracy, not better)."""

    def __init__(self, t0: float, p0: np.ndarray):
        self.prev = self.cur = (t0, np.zeros(2), p0)

    def step(self, t: float, p_mid: np.ndarray, p_end: np.ndarray) -> None:
        t0, w0, p0 = self.cur
        self.prev = self.cur
        self.cur = (t, w0 + (t - t0) / 6.0 * (p0 + 4.0 * p_mid + p_end), p_end)

    def at(self, t: float) -> np.ndarray:
        (t0, w0, p0), (t1, w1, p1) = self.prev, self.cur
        if t1 <= t0 or t >= t1:
            return w1.copy()
        h, s = t1 - t0, (t - t0) / (t1 - t0)
        return ((2 * s**3 - 3 * s**2 + 1) * w0 + (s**3 - 2 * s**2 + s) * h * p0
                + (-2 * s**3 + 3 * s**2) * w1 + (s**3 - s**2) * h * p1)

    def state(self) -> tuple:
        return tuple((t, w.copy(), p.copy()) for t, w, p in (self.prev, self.cur))

    def set_state(self, s: tuple) -> None:
        self.prev, self.cur = ((t, w.copy(), p.copy()) for t, w, p in s)


class _ForcesHistory:
    """Warm start of the friction solve (``qf_guess`` of :func:`overcon.dynamics.evaluate`): the
    friction forces of the last two solves at distinct times, extrapolated linearly to the next
    solve's time when it is at most twice their distance ahead, else the last forces. Only the
    number of Newton iterations depends on it, not the solution (beyond the friction tolerance)."""

    def __init__(self):
        self.items: tuple = ()  # ((t, qf), (t_before, qf_before)), newest first

    def push(self, t: float, qf: np.ndarray | None) -> None:
        if qf is None:
            return
        older = self.items[1:] if self.items and self.items[0][0] == t else self.items[:1]
        self.items = ((t, qf),) + older

    def guess(self, t: float) -> np.ndarray | None:
        if not self.items:
            return None
        t1, q1 = self.items[0]
        if len(self.items) == 2:
            t0, q0 = self.items[1]
            if abs(t - t1) <= 2.0 * abs(t1 - t0):
                return q1 + (q1 - q0) * ((t - t1) / (t1 - t0))
        return q1

    def state(self) -> tuple:
        return tuple((t, qf.copy()) for t, qf in self.items)

    def set_state(self, items) -> None:
        self.items = tuple((float(t), np.array(qf, float)) for t, qf in items)


class _DerivedPlan:
    """Where a model's outputs come from: ``position_index`` into y, and per joint type the
    reaction joints and friction-output joints (positions in the type's ``Model.plan`` group) with
    the slots of their values in the derived part of the output vector."""

    def __init__(self, model: Model):
        self.position_index = np.array([i for _, i in model.position_outputs], np.intp)
        self.velocity_index = np.array([i for _, i in model.velocity_outputs], np.intp)
        where = {j: (n, pos) for n, g in enumerate(model.plan.groups) for pos, j in enumerate(g.joints)}
        self.reactions = {}  # group number -> (positions in the group, output slots (k, n_components))
        slot = 0
        for j in model.reaction_joints:
            n, pos = where[j]
            width = len(model.joints[j].components)
            self.reactions.setdefault(n, ([], []))
            self.reactions[n][0].append(pos)
            self.reactions[n][1].append(list(range(slot, slot + width)))
            slot += width
        self.reactions = {n: (np.array(p, np.intp), np.array(s, np.intp)) for n, (p, s) in self.reactions.items()}
        # the same outputs from the compiled kernel's per-joint table (overcon.kernel.Kernel.outputs):
        # (joint, component) of every reaction output, in output order (slots 0, 1, ...)
        pairs = [(j, comp) for j in model.reaction_joints for comp in range(len(model.joints[j].components))]
        n_reac = len(pairs)
        self.friction = []  # (module, stacked constants, multiplier rows (k, n_eq), output slots (k,))
        by_type: dict[str, list] = {}
        for j in model.friction_outputs:
            by_type.setdefault(model.joints[j].type, []).append((j, slot))
            slot += 1
        for jtype, items in by_type.items():
            js = [model.joints[j] for j, _ in items]
            self.friction.append((js[0].module, js[0].module.stack(js), np.array([c.rows for c in js], np.intp),
                                  np.array([s for _, s in items], np.intp)))
        self.size = slot
        self.kernel_reactions = np.array(pairs, np.intp).reshape(-1, 2).T  # (joints, components)
        self.kernel_friction = np.array(model.friction_outputs, np.intp)  # slots n_reac, n_reac + 1, ...
        self.n_reactions = n_reac

    def values_from_kernel(self, reac: np.ndarray, fric: np.ndarray) -> np.ndarray:
        """The derived outputs from the kernel's table (:meth:`overcon.kernel.Kernel.outputs`)."""
        out = np.empty(self.size)
        j, c = self.kernel_reactions
        out[: self.n_reactions] = reac[j, c]
        out[self.n_reactions:] = fric[self.kernel_friction]
        return out

    def values(self, model: Model, f, lam: np.ndarray) -> np.ndarray:
        """The derived outputs from the frames f and the multipliers lam (m,): per reaction joint
        ``-A_i fi`` in its auxiliary frame then ``-fi`` force part (global), fi = (J_X)_i^T lam_X;
        per friction-output joint the module's ``friction_force``."""
        out = np.empty(self.size)
        for n, (pos, slots) in self.reactions.items():
            g = model.plan.groups[n]
            out[slots] = physical_reactions(g.module, g.data, f, lam[g.rows].reshape(len(g.joints), -1), model.dim)[pos]
        for module, data, rows, slots in self.friction:
            out[slots] = module.friction_force(data, module.friction_setup(data, f), lam[rows])
        return out


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
    kernel_note: str = ""  # which right-hand side ran (Simulation.kernel_note)
    kernel_repeats: int = 0  # evaluations the compiled kernel handed back to the numpy path
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
        **settings) -> Result:
    """Simulate ``model`` with the solver options ``solver`` from the scene's start to ``stop_time``
    (default the scene's), outputs every ``output_interval`` (default ``solver.output_interval``);
    ``settings`` go to :class:`Simulation`."""
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
    rows = []
    try:
        for t in grid:
            y = sim.advance(t)
            rows.append(sim.outputs(t, y))
    except SimulationError as exc:
        exc.partial = _result(model, sim, grid[:len(rows)], rows)
        raise
    return _result(model, sim, grid, rows)


def _result(model: Model, sim: Simulation, time: np.ndarray, rows: list) -> Result:
    """The :class:`Result` of the output points ``time`` and their ``rows`` so far, with the
    run's counters."""
    itg = sim._integrator
    values = np.array(rows) if rows else np.zeros((0, len(model.output_names())))
    return Result(model.output_names(), np.asarray(time), values, sim.max_drift, sim.evaluations,
                  sim.friction_iterations, itg.nsteps, getattr(itg, "stiff_steps", 0), sim.kernel_note,
                  sim.kernel_repeats, tuple(sim.events))


def run_scene(scene: SceneSpec, **kw) -> Result:
    """Compile ``scene`` and :func:`run` it with its own solver options ``scene.solver``."""
    from .checks import compile_checked
    return run(compile_checked(scene), scene.solver, **kw)


def write_events(events, path) -> None:
    """The events of a run (:data:`EVENT_KINDS`) as CSV: ``time`` (s), ``kind``, ``detail``; the
    header alone when there were none."""
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["time", "kind", "detail"])
        for t, kind, detail in events:
            w.writerow([repr(float(t)), kind, detail])


def write_csv(result: Result, path) -> None:
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["time", *result.names])
        for t, row in zip(result.time, result.values):
            w.writerow([repr(float(t)), *(repr(float(v)) for v in row)])
