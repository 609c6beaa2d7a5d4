"""Admissible values of every solver and friction parameter: ONE table, used by the scene loader
(reported against the file and field, e.g. ``solver.tolerance``), the command line (the flag,
e.g. ``--tolerance``) and the FMU (the parameter, e.g. ``solver.tolerance`` or ``joint4.mu``,
through :func:`overcon.fmu.variables.rule`).

:func:`check_param` checks one value against :data:`RULES`; :func:`check_relations` checks the
rules that tie parameters to the simulated interval (bounded work); :func:`check_mu_static` the
one cross-field friction rule; :func:`apply_overrides` applies named values to a scene and
returns the new scene or every problem.

Envelopes (why each bound; the costs behind them: docs/benchmarks.md, "Input limits")
-----------------------------------------------------------------------------------------
``solver.tolerance`` in [1e-14, 1e-2] (1): rtol = atol of the adaptive methods. dop853 and dopri5
at 1e-14 still run the paper scenes (0.1 s of planar_f45_wo4: 25 and 47 steps); below it the error
test asks for less than the double-precision round-off of the stages, the step collapses and the
run crawls (at 1e-300 it would never finish). Above 1e-2 the global error (20-100 x tolerance x scale,
docs/explanation/decisions.md, "Uniqueness tolerances") exceeds 1 m on the paper mechanisms: no usable result.

``solver.step`` (rk4) and ``solver.max_step`` (adaptive) in [1e-8, 1] s: 1e-8 s keeps t + h
distinguishable from t for |t| up to ~1e7 s (ulp(1e7) = 1.9e-9 s); 1 s is longer than any time
scale of a jointed rigid mechanism under gravity (the paper's: ~0.1 s); larger explicit steps
only diverge.

``solver.output_interval`` in [1e-8, 1e6] s: the floor as for steps; the number of output points
is bounded by :data:`MAX_OUTPUT_POINTS` below.

``solver.baumgarte`` in [0, 1e3] 1/s: the stabilisation adds a^2 Phi to the equations; an
explicit method needs h a < ~3, so beyond 1e3 1/s the step is limited to < 3 ms by the
stabilisation alone (stiff), with no accuracy gain (default 10).

``solver.friction_tol`` in [1e-14, 1e-3] (1, relative on lambda): below 1e-14 the fixed point
cannot meet the test (round-off of one Cholesky solve is ~1e-16 x cond); above 1e-3 friction
forces are off by more than 0.1 %.

``solver.friction_max_iter`` integer in [1, 1000]: force evaluations of each stage of the friction
solve per evaluation (Newton, at most min(this, 12); then the fixed point; then the Newton
fallback); each costs one evaluation of the friction forces and one back-substitution, so 1000
bounds the work of one evaluation.

``solver.method`` one of :data:`overcon.spec.METHODS`.
``solver.kernel`` one of :data:`overcon.spec.KERNELS` (:mod:`overcon.kernel`).
``solver.singular`` one of :data:`overcon.spec.SINGULAR` (stop at, or pass, a singular position).

Friction (per joint): ``mu`` in [0, 1e6] and ``mu_static`` >= ``mu`` (1; 1e6 is far beyond any
physical coefficient, and larger values overflow the friction solve into non-finite forces), ``v_reg`` > 0 and
``v_stribeck`` > 0 (m/s, rad/s for revolute), all finite. (A tiny ``v_reg`` makes the problem
stiff: dopri5 stops with "stiff", radau takes small steps inside the work budget of
:class:`overcon.simulate.Simulation`.)

Relations (bounded work, :func:`check_relations`): the number of output points
(stop - start) / output_interval + 1 <= :data:`MAX_OUTPUT_POINTS` = 1e6 (the result array is
1e6 x outputs x 8 bytes, 0.3 GB for 40 outputs; each point with reactions costs one friction
solve); the fewest internal steps the run can take, (stop - start) / step for rk4 or
(stop - start) / max_step for the adaptive methods, <= :data:`MAX_MIN_STEPS` = 1e6 (the paper
scenes need 80-200; at the measured cost of a step with friction, 1e6 steps take most of an hour).
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from numbers import Integral, Real

from .spec import KERNELS, METHODS, SINGULAR, SolverSpec

MAX_OUTPUT_POINTS = 1_000_000
"""Largest number of output points (stop - start) / output_interval + 1."""
MAX_MIN_STEPS = 1_000_000
"""Largest lower bound on the internal steps: (stop - start) / step (rk4) or / max_step."""


@dataclass(frozen=True)
class Rule:
    """Admissible values of one parameter: ``kind`` "real", "int" or "choice"; a real or integer
    must be finite and in [low, high] (``low_open``: > low instead of >= low); ``unit`` for the
    message; ``why`` the reason for the bounds (module docstring, shortened)."""

    kind: str
    low: float | None = None
    high: float | None = None
    low_open: bool = False
    unit: str = ""
    why: str = ""
    choices: tuple = ()

    def check(self, value) -> str | None:
        """None if ``value`` is admissible, else the reason (``must be ..., got ...``)."""
        if self.kind == "choice":
            return None if isinstance(value, str) and value in self.choices else \
                f"must be one of {', '.join(self.choices)}, got {value!r}"
        if isinstance(value, bool) or not isinstance(value, Real):
            return f"expected {'an integer' if self.kind == 'int' else 'a number'}, got {value!r}"
        if self.kind == "int" and not isinstance(value, Integral):
            return f"expected an integer, got {value!r}"
        try:
            x = float(value)
        except OverflowError:
            return f"number too large: {value!r}"
        if not math.isfinite(x):
            return f"must be finite, got {x!r}"
        too_low = self.low is not None and (x <= self.low if self.low_open else x < self.low)
        too_high = self.high is not None and x > self.high
        if too_low or too_high:
            return f"must be {self.range_text()}, got {value!r}" + (f" ({self.why})" if self.why else "")
        return None

    def range_text(self) -> str:
        unit = f" {self.unit}" if self.unit and self.unit != "1" else ""
        lo = None if self.low is None else f"{'>' if self.low_open else '>='} {self.low:g}{unit}"
        hi = None if self.high is None else f"<= {self.high:g}{unit}"
        if lo and hi and not self.low_open:
            return f"in [{self.low:g}, {self.high:g}]{unit}"
        return " and ".join(p for p in (lo, hi) if p)


RULES: dict[str, Rule] = {
    "solver.method": Rule("choice", choices=METHODS),
    "solver.kernel": Rule("choice", choices=KERNELS),
    "solver.singular": Rule("choice", choices=SINGULAR),
    "solver.tolerance": Rule("real", 1e-14, 1e-2, unit="1",
                             why="below 1e-14 the error test is under double-precision round-off and the "
                                 "step size collapses; above 1e-2 the error exceeds 1 m"),
    "solver.step": Rule("real", 1e-8, 1.0, unit="s",
                        why="rk4 step: below 1e-8 s t + h is not resolved for large t; above 1 s "
                            "explicit steps diverge"),
    "solver.max_step": Rule("real", 1e-8, 1.0, unit="s",
                            why="largest adaptive step: below 1e-8 s t + h is not resolved for large t"),
    "solver.output_interval": Rule("real", 1e-8, 1e6, unit="s", why="output grid interval"),
    "solver.baumgarte": Rule("real", 0.0, 1e3, unit="1/s",
                             why="above 1e3 1/s the stabilisation alone makes the problem stiff"),
    "solver.friction_tol": Rule("real", 1e-14, 1e-3, unit="1",
                                why="below 1e-14 the friction fixed point cannot converge in double "
                                    "precision; above 1e-3 friction forces are off by > 0.1 %"),
    "solver.friction_max_iter": Rule("int", 1, 1000, why="bounds the work of one evaluation"),
    "solver.max_internal_steps": Rule("int", 1, 100_000_000,
                                      why="work budget of one FMU fmi2DoStep (integrator steps)"),
    "solver.max_wall_time": Rule("real", 0.0, 86400.0, low_open=True, unit="s",
                                 why="work budget of one FMU fmi2DoStep (wall-clock seconds, at most a day)"),
    "mu": Rule("real", 0.0, 1e6, unit="1",
               why="a friction coefficient is >= 0; 1e6 is far beyond any physical one (< 10), above it the friction solve overflows"),
    "mu_static": Rule("real", 0.0, 1e6, unit="1",
                      why="a friction coefficient is >= 0; 1e6 is far beyond any physical one (< 10), above it the friction solve overflows"),
    "v_reg": Rule("real", 0.0, low_open=True, unit="m/s or rad/s"),
    "v_stribeck": Rule("real", 0.0, low_open=True, unit="m/s or rad/s"),
}
"""Parameter name -> rule. Solver parameters as ``solver.<field of SolverSpec>``; friction
parameters by their field name (``mu``), looked up for ``<joint>.mu`` too."""

SOLVER_FIELDS = tuple(f.name for f in dataclasses.fields(SolverSpec))
"""Scene solver settings (:class:`overcon.spec.SolverSpec`); the other ``solver.*`` rules are the
FMU's per-doStep work budget, parameters of the FMU only."""
FRICTION_FIELDS = ("mu", "v_reg", "mu_static", "v_stribeck")


def rule_of(name: str) -> Rule:
    """The rule of ``solver.tolerance``, ``mu`` or ``joint4.mu``; KeyError if there is none."""
    if name in RULES:
        return RULES[name]
    group, _, p = name.rpartition(".")
    if group and group != "solver" and p in FRICTION_FIELDS:
        return RULES[p]
    raise KeyError(f"no rule for parameter {name!r}")


def check_param(name: str, value) -> str | None:
    """None if ``value`` is admissible for parameter ``name``, else the reason."""
    return rule_of(name).check(value)


def check_mu_static(mu: float, mu_static: float | None, mu_name: str = "mu") -> str | None:
    """The Stribeck peak must not be below the kinetic coefficient: ``mu_static >= mu``."""
    if mu_static is not None and mu is not None and mu_static < mu:
        return f"must be >= {mu_name} ({mu!r}), got {mu_static!r}"
    return None


def min_steps(solver, start: float, stop: float) -> float:
    """Fewest internal steps a run from start to stop can take: the fixed rk4 step, or the
    adaptive methods' largest step ``max_step``."""
    h = solver.step if solver.method == "rk4" else solver.max_step
    return (stop - start) / h


def output_points(solver, start: float, stop: float) -> float:
    return (stop - start) / solver.output_interval + 1


def check_relations(solver, start: float, stop: float) -> list[tuple[str, str]]:
    """Bounded work of a run of ``solver`` (a SolverSpec) from ``start`` to ``stop`` (s):
    [(parameter name, message)] for the number of output points and the fewest internal steps
    (see the module docstring). Call only with values that pass :func:`check_param`."""
    out = []
    span = stop - start
    n_out = output_points(solver, start, stop)
    if not n_out <= MAX_OUTPUT_POINTS:
        out.append(("solver.output_interval",
                    f"{solver.output_interval!r} s gives {n_out:.3g} output points over {span:g} s "
                    f"(stop - start); at most {MAX_OUTPUT_POINTS:.0e} (memory and one friction solve per "
                    "point): use a larger output interval or a shorter run"))
    n_steps = min_steps(solver, start, stop)
    if not n_steps <= MAX_MIN_STEPS:
        name = "solver.step" if solver.method == "rk4" else "solver.max_step"
        what = "rk4 step" if solver.method == "rk4" else "largest adaptive step"
        h = solver.step if solver.method == "rk4" else solver.max_step
        out.append((name, f"{what} {h!r} s needs at least {n_steps:.3g} steps over {span:g} s (stop - start); "
                          f"at most {MAX_MIN_STEPS:.0e} (1-3 ms each: 0.3-1 h): use a larger step or "
                          "a shorter run"))
    return out


def apply_overrides(scene, values: dict, *, relations: bool = True):
    """``scene`` with ``values`` applied: names ``solver.<field>`` (SolverSpec) or
    ``<joint>.<friction field>`` (a friction joint of the scene). Returns ``(new scene, [])`` or
    ``(None, [(name, message), ...])`` with every problem (each value against its rule, a name
    that is not a parameter, ``mu_static >= mu``, and, unless ``relations`` is false, the
    relations of :func:`check_relations` for the changed solver over the scene's interval,
    reported against the changed parameter when it is one of them). The FMU passes
    ``relations=False``: its run length is the host's, bounded per step by its work budget.

    This is the one override function: the scene loader (``as_scene``), the command line
    (``simulate``/``check`` flags) and the FMU (its parameters) all call it."""
    problems: list[tuple[str, str]] = []
    solver_changes: dict = {}
    friction_changes: dict[str, dict] = {}
    for name, value in values.items():
        group, _, p = name.rpartition(".")
        if group == "solver" and p in SOLVER_FIELDS:
            target = solver_changes
        elif group in scene.friction_params and p in FRICTION_FIELDS:
            target = friction_changes.setdefault(group, {})
        else:
            problems.append((name, "not a parameter of this scene (solver.<field> or "
                                   "<friction joint>.mu/v_reg/mu_static/v_stribeck)"))
            continue
        reason = check_param(name, value)
        if reason is not None:
            problems.append((name, reason))
        else:
            target[p] = value if isinstance(value, str) else (int(value) if rule_of(name).kind == "int" else float(value))
    fparams = dict(scene.friction_params)
    for joint, changes in friction_changes.items():
        fs = dataclasses.replace(fparams[joint], **changes)
        reason = check_mu_static(fs.mu, fs.mu_static, f"{joint}.mu")
        if reason is not None:
            problems.append((f"{joint}.mu_static", reason))
        fparams[joint] = fs
    if problems:
        return None, problems
    solver = dataclasses.replace(scene.solver, **solver_changes)
    for name, msg in check_relations(solver, scene.start_time, scene.stop_time) if relations else ():
        changed = [n for n in ("solver.output_interval", "solver.step", "solver.max_step", "solver.method")
                   if n.split(".", 1)[1] in solver_changes]
        problems.append((name if name.split(".", 1)[1] in solver_changes or not changed else changed[0], msg))
    if problems:
        return None, problems
    return dataclasses.replace(scene, solver=solver, friction_params=fparams), []
