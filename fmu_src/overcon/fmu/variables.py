"""The FMU's variables: one table, read by the modelDescription writer and by the slave.

Value references are the positions in :func:`table` (0-based), in this order:

1. outputs, exactly ``model.output_names()``: positions (m, rad; quaternion components 1), reaction components
   (N, N.m) and the friction forces ``<joint>.friction`` of the scene's friction joints (N, or
   N.m for revolute joints; the core's friction output, core/outputs.c), causality output,
   variability continuous, initial calculated;
2. uniqueness verdicts (Booleans, causality output, initial exact, the start value the pre-check's at
   t = 0): ``<joint>.reaction_unique`` per reaction joint of the scene (variability constant, the
   pre-check, for a joint without friction; discrete, judged along the motion
   (:class:`overcon.watch.Uniqueness`), for a friction joint), and ``motion_unique`` (discrete);
3. parameters (causality parameter, variability fixed, initial exact): per friction joint
   ``<joint>.mu`` and ``<joint>.v_reg`` (law ``stribeck`` also ``<joint>.mu_static`` and
   ``<joint>.v_stribeck``), then the solver settings ``solver.*`` of
   :class:`overcon.spec.SolverSpec`, then the work budget of one ``fmi2DoStep`` (``BUDGET_PARAMS``,
   FMU only, variability tunable);
4. ``solver.stable_step`` (local), then ``redundancy`` (:func:`redundancy_var`: an Enumeration
   parameter, variability fixed, start the scene's ``[scene] redundancy``), last so that adding it
   kept every earlier value reference.

5. after them (so that the older value references stay): ``<joint>.reaction_unique`` (discrete) of the
   friction joints that are no reaction joints, and ``rank`` (Integer, discrete): the whole
   Jacobian's rank along the motion.

The discrete outputs hold the verdict of the run's last evaluation (key ``("along", ...)``): the
communication point after a successful ``fmi2DoStep``, the instant a failed one stopped at.

6. with Model Exchange (``states=True``, C runtime): the continuous states y = [q, h] of the core,
   ``q.<body>.<coordinate>`` (m, rad; quaternion components 1, not normalised) and
   ``h.<body>.<velocity>`` (planar vx, vy, omega; spatial vx, vy, vz in the global frame and wx, wy, wz
   in the body's axes), causality local, variability continuous, initial exact (start: the scene's
   q0, h0), then their derivatives ``der(q.<body>.<coordinate>)``, ``der(h.<body>.<velocity>)``
   (initial calculated);
7. FMI 3.0 only (``fmi3=True``): per reaction joint the array ``<joint>.reaction`` of its reaction
   components in the order of the scalar outputs ``<joint>.<component>`` (which stay), then the
   independent variable ``time`` (s) that FMI 3.0 requires.

``UNITS`` gives every unit's SI base-unit exponents (FMI ``BaseUnit``).
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from ..joints import TYPES
from ..params import check_param, rule_of
from ..spec import (COORDINATE_UNITS, ENERGY_OUTPUTS, JOINT_SENSORS, REDUNDANCY_METHODS, VELOCITY_OUTPUTS,
                    coordinates)

SENSOR_NAMES = ("angle", "rate", "displacement", "speed")  # by the core's sensor index (overcon.model.SENSOR_INDEX)
SENSOR_TEXT = {"angle": "rotation of body i relative to body j about the joint axis, from q0",
               "rate": "rotation rate of body i relative to body j about the joint axis",
               "displacement": "displacement of body i relative to body j along the joint axis, from q0",
               "speed": "sliding speed of body i relative to body j along the joint axis"}
INPUT_TEXT = {"joint_torque": "torque about the joint axis on body i (its reaction on body j)",
              "joint_force": "force along the joint axis on body i (its reaction on body j)",
              "force": "force on a body (signed magnitude along its direction)",
              "torque": "torque on a body (signed magnitude about its direction)"}

UNITS: dict[str, dict[str, int]] = {
    "1": {},
    "m": {"m": 1},
    "rad": {"rad": 1},
    "s": {"s": 1},
    "1/s": {"s": -1},
    "m/s": {"m": 1, "s": -1},
    "rad/s": {"rad": 1, "s": -1},
    "m/s2": {"m": 1, "s": -2},
    "rad/s2": {"rad": 1, "s": -2},
    "N": {"kg": 1, "m": 1, "s": -2},
    "N.m": {"kg": 1, "m": 2, "s": -2},
    "J": {"kg": 1, "m": 2, "s": -2},
}
"""Units used by the variables, with the exponents of the SI base units (and rad)."""


COORDINATE_TEXT = {
    "x": "x coordinate of the origin (centre of mass), global frame",
    "y": "y coordinate of the origin (centre of mass), global frame",
    "z": "z coordinate of the origin (centre of mass), global frame",
    "phi": "rotation angle (counter-clockwise)",
    "alpha": "z-x-z Euler angle alpha",
    "beta": "z-x-z Euler angle beta",
    "gamma": "z-x-z Euler angle gamma",
    "e0": "orientation quaternion body -> global, scalar part e0 (unit quaternion e / |e|)",
    "e1": "orientation quaternion body -> global, vector part e1 (unit quaternion e / |e|)",
    "e2": "orientation quaternion body -> global, vector part e2 (unit quaternion e / |e|)",
    "e3": "orientation quaternion body -> global, vector part e3 (unit quaternion e / |e|)",
}



STATE_OUTPUT_TEXT = {
    "vx": "velocity of the origin (centre of mass), x component, global frame",
    "vy": "velocity of the origin (centre of mass), y component, global frame",
    "vz": "velocity of the origin (centre of mass), z component, global frame",
    "omega": "angular velocity (counter-clockwise)",
    "wx": "angular velocity, x component, body frame",
    "wy": "angular velocity, y component, body frame",
    "wz": "angular velocity, z component, body frame",
    "kinetic": "kinetic energy of the mechanism",
    "potential": "potential energy of gravity (zero at the global origin) and of the springs",
    "dissipated": "work dissipated by joint friction since the start (>= 0)",
    "applied": "work of the constant forces and torques since the start",
}


def state_outputs_beyond_positions(model) -> list[tuple[str, str]]:
    """(name, unit) of the velocity and energy outputs of ``model``, in output order."""
    units = dict(VELOCITY_OUTPUTS[model.kind])
    out = [(name, units[name.rsplit(".", 1)[1]]) for name, _ in model.velocity_outputs]
    return out + (list(ENERGY_OUTPUTS) if model.energy_outputs else [])


@dataclass(frozen=True)
class Var:
    """One scalar variable. ``type`` Real/Integer/Boolean/String/Enumeration (:data:`REDUNDANCY_TYPE`,
    read and written as an Integer); ``unit`` for Real only;
    ``start`` None where FMI forbids one (initial calculated); ``key`` what the slave reads or
    writes: ``("output", k)``, ``("constant", value)``, ``("param", name)``, ``("stable_step", None)``."""

    name: str
    type: str
    causality: str
    variability: str
    initial: str
    description: str
    unit: str | None = None
    start: object = None
    key: tuple = ()
    derivative: int | None = None  # a state's derivative: the 0-based table index of that state
    size: int = 1  # an array variable's number of elements (FMI 3.0)
    # an output of a scene with inputs: False when it does not depend directly on them (a function of
    # the state: positions, velocities, energies, sensors; ModelStructure says so), None otherwise
    feedthrough: bool | None = None


@dataclass(frozen=True)
class ParamRule:
    """Admissible values of parameter ``name``: ``check(value)`` returns None or the reason,
    from the one rules table :data:`overcon.params.RULES` (envelopes documented there)."""

    name: str

    def check(self, value) -> str | None:
        return check_param(self.name, value)

    def range_text(self) -> str:
        return rule_of(self.name).range_text()


SOLVER_PARAMS = {
    # name: (type, unit, description); admissible values: overcon.params.RULES["solver.<name>"]
    "method": ("String", None, "integrator: dopri5 or dop853 (adaptive explicit), rk4 (fixed step) or radau (implicit, for stiff friction)"),
    "tolerance": ("Real", "1",
                  "accuracy target of dopri5, dop853 and radau (rtol = atol); a tolerance given to "
                  "fmi2SetupExperiment is ignored (reported as a warning when it differs)"),
    "step": ("Real", "s", "fixed step of rk4"),
    "max_step": ("Real", "s", "largest internal step of the adaptive methods"),
    "baumgarte": ("Real", "1/s", "Baumgarte constraint stabilisation frequency (0 disables)"),
    "friction_tol": ("Real", "1", "friction fixed-point tolerance (relative, on lambda)"),
    "friction_max_iter": ("Integer", None, "friction fixed-point iteration limit"),
    "kernel": ("String", None, "right-hand side: auto (the compiled kernel where it covers the model, else numpy), "
                               "c (the compiled kernel, an error where it cannot run) or numpy"),
}

BUDGET_PARAMS = {
    # name: (type, unit, default, description); FMU parameters only (not scene settings);
    # admissible values: overcon.params.RULES["solver.<name>"]
    "max_internal_steps": ("Integer", None, 10000,
                           "work budget of one fmi2DoStep: integrator steps (exceeded: fmi2Error)"),
    "max_wall_time": ("Real", "s", 30.0,
                      "work budget of one fmi2DoStep: wall-clock seconds (exceeded: fmi2Error)"),
}

FRICTION_PARAMS = {
    "mu": "friction coefficient (kinetic)",
    "v_reg": "regularisation velocity of the friction law",
    "mu_static": "static (peak) friction coefficient of the Stribeck law, >= mu",
    "v_stribeck": "Stribeck velocity",
}


def _friction_param_names(law) -> tuple[str, ...]:
    return ("mu", "v_reg", "mu_static", "v_stribeck") if law.name == "stribeck" else ("mu", "v_reg")


def table(model, solver, reaction_unique: dict[str, bool], motion_unique: bool, rank: int | None = None, *,
          states: bool = False, fmi3: bool = False) -> list[Var]:
    """All variables of the FMU of ``model`` with the solver options ``solver`` (the start values
    of the ``solver.*`` parameters; see the module docstring for the order). Per joint type
    facts (units, texts) come from :data:`overcon.joints.TYPES`. ``reaction_unique``: pre-check
    verdict per joint name; ``motion_unique``, ``rank``: the scene's (start values; the run
    updates them, see the module docstring); ``states``: the continuous states and their
    derivatives (Model Exchange); ``fmi3``: the reaction arrays and ``time`` (FMI 3.0)."""
    out = [Var(name, "Real", "output", "continuous", "calculated", text, unit=unit, key=("output", k))
           for k, (name, text, unit) in enumerate(_output_specs(model))]
    out += _reaction_unique_vars(model, reaction_unique)
    out.append(_along_var("motion_unique", "Boolean", "the motion is unique: no friction on a joint whose reaction "
                          "is not unique (paper Eq. 17)", bool(motion_unique), "motion"))
    out += _parameter_vars(model, solver)
    out.append(Var("solver.stable_step", "Real", "local", "discrete", "calculated",
                   "the largest stable fixed step that rk4 named when it refused a step as unstable (s); 0 until it "
                   "does. Readable after the failed fmi2DoStep: the lockstep comparison repeats its runs with it",
                   unit="s", key=("stable_step", None)))
    out.append(redundancy_var(model))
    out += _along_outputs(model, reaction_unique, rank)
    out += _effort_unique_vars(model, reaction_unique)
    out += [Var(u.name, "Real", "input", "continuous", "", f"input: {INPUT_TEXT[u.type]}", unit=u.unit,
                start=float(u.start), key=("input", n)) for n, u in enumerate(model.inputs)]
    if model.inputs:
        out = _without_direct_feedthrough(model, out)
    return out + _interface_variables(model, out, states, fmi3)


def _output_specs(model) -> list[tuple[str, str, str]]:
    """(name, description, unit) of every Real output of the state, in the table's order: positions,
    the other state outputs, reactions (a driver's effort), friction, sensors."""
    body_of = {i: name for i, name in enumerate(model.body_names)}
    out = []
    for name, _ in model.position_outputs:
        body, coord = name.rsplit(".", 1)
        out.append((name, f"{body}: {COORDINATE_TEXT[coord]}", COORDINATE_UNITS[coord]))
    for name, unit in state_outputs_beyond_positions(model):
        out.append((name, STATE_OUTPUT_TEXT[name.rsplit(".", 1)[1]], unit))
    for j in model.reaction_joints:
        out += _reaction_output_specs(model, model.joints[j], body_of.get(model.joints[j].bi, "base"))
    for j in model.friction_outputs:
        c = model.joints[j]
        out.append((f"{c.name}.friction",
                    f"friction {TYPES[c.type].friction_text} of joint {c.name} on body {body_of.get(c.bi, 'base')} "
                    f"({c.law.name} law)", TYPES[c.type].friction_unit))
    for name, j, what in model.sensor_outputs:
        sensor = SENSOR_NAMES[what]
        out.append((name, f"joint {model.joints[j].name}: {SENSOR_TEXT[sensor]}", JOINT_SENSORS[sensor]))
    return out


def _reaction_output_specs(model, c, bi: str) -> list[tuple[str, str, str]]:
    """(name, description, unit) of the reaction outputs of joint ``c`` on body ``bi``: one per
    reaction component, or a driver's effort (core/drivers.c)."""
    if c.type == "driver":
        driven = model.joints[c.p["joint"]]
        rot = c.p["coordinate"] == 0
        return [(f"{c.name}.effort",
                 f"driver {c.name}: the {'torque about' if rot else 'force along'} the axis of joint "
                 f"{driven.name} that its motor exerts on body {bi} (its reaction on the other body) to "
                 "impose the motion", "N.m" if rot else "N")]
    units = dict(TYPES[c.type].reaction)
    out = []
    for comp in c.components:
        frame = "global frame" if comp.endswith("0") else f"auxiliary frame of the {TYPES[c.type].name} joint"
        what = "moment" if comp.startswith("T") else "force"
        out.append((f"{c.name}.{comp}", f"reaction {what} of joint {c.name} on body {bi}, component {comp}, {frame}",
                    units.get(comp, "N")))
    return out


def _reaction_unique_vars(model, reaction_unique: dict[str, bool]) -> list[Var]:
    """The pre-check's verdict per reaction joint (a driver's is ``effort_unique``): a constant, or
    an along-the-run output for a joint with friction."""
    out = []
    friction = set(model.friction_joints)
    for j in model.reaction_joints:
        if model.joints[j].type == "driver":
            continue  # effort_unique (_effort_unique_vars)
        name = model.joints[j].name
        val = bool(reaction_unique[name])
        if j in friction:
            out.append(_along_reaction(model, j, val))
            continue
        out.append(Var(f"{name}.reaction_unique", "Boolean", "output", "constant", "exact",
                       f"pre-check: the reaction of joint {name} is unique (does not depend on the "
                       "eliminated equations)", start=val, key=("constant", val)))
    return out


def _parameter_vars(model, solver) -> list[Var]:
    """The parameters: each friction joint's law, then the solver options and the work budgets."""
    out = []
    for j in model.friction_joints:
        c = model.joints[j]
        for p in _friction_param_names(c.law):
            value = getattr(c.law, p)
            unit = "1" if p.startswith("mu") else TYPES[c.type].sliding_unit
            name = f"{c.name}.{p}"
            out.append(Var(name, "Real", "parameter", "fixed", "exact",
                           f"joint {c.name} ({c.law.name} law): {FRICTION_PARAMS[p]} "
                           f"({rule(name).range_text()})", unit=unit,
                           start=float(value), key=("param", name)))
    for p, (typ, unit, text) in SOLVER_PARAMS.items():
        value = getattr(solver, p)
        value = float(value) if typ == "Real" else value
        rng = rule(f"solver.{p}").range_text()
        out.append(Var(f"solver.{p}", typ, "parameter", "fixed", "exact", f"{text} ({rng})" if rng else text, unit=unit,
                       start=value, key=("param", f"solver.{p}")))
    for p, (typ, unit, value, text) in BUDGET_PARAMS.items():
        rng = rule(f"solver.{p}").range_text()
        out.append(Var(f"solver.{p}", typ, "parameter", "tunable", "exact", f"{text} ({rng})", unit=unit,
                       start=value, key=("param", f"solver.{p}")))
    return out


def _effort_unique_vars(model, reaction_unique: dict[str, bool]) -> list[Var]:
    """``effort_unique`` when the model has drivers (none otherwise): its start value is every
    driver's and every acting friction joint's pre-check verdict."""
    drivers = [c for c in model.joints if c.type == "driver"]
    if not drivers:
        return []
    acting = [model.joints[j].name for j in model.friction_joints
              if not (model.joints[j].law.mu == 0 and not model.joints[j].law.mu_static)]
    start = all(reaction_unique.get(c.name, True) for c in drivers) and \
        all(reaction_unique.get(n, True) for n in acting)
    return [_along_var("effort_unique", "Boolean", "every driver's effort is unique: its equation a direct "
                       "summand of span(J) and no friction on a joint whose reaction is not unique",
                       bool(start), len(model.joints))]


def _without_direct_feedthrough(model, out: list[Var]) -> list[Var]:
    """``out`` with ``feedthrough=False`` on the Real outputs of the state: they do not depend
    directly on the inputs (the reactions and friction forces do)."""
    direct = {name for j in model.reaction_joints for name in
              ([f"{model.joints[j].name}.{c}" for c in model.joints[j].components])}
    direct |= {f"{model.joints[j].name}.friction" for j in model.friction_outputs}
    return [dataclasses.replace(v, feedthrough=False) if v.causality == "output" and v.type == "Real"
            and v.key and v.key[0] == "output" and v.name not in direct else v for v in out]


def _interface_variables(model, out: list[Var], states: bool, fmi3: bool) -> list[Var]:
    """After the table ``out``: the continuous states and their derivatives (Model Exchange), then
    FMI 3.0's reaction arrays and ``time`` (module docstring, items 6 and 7)."""
    more = _states(model, len(out)) if states else []
    if fmi3:
        more += _reaction_arrays(model, out + more)
        more.append(Var("time", "Real", "independent", "continuous", "", "simulation time", unit="s",
                        key=("time", None)))
    return more


_DERIVATIVE_UNITS = {"m": "m/s", "rad": "rad/s", "1": "1/s", "m/s": "m/s2", "rad/s": "rad/s2"}


def _states(model, first: int) -> list[Var]:
    """The continuous states y = [q, h] and their derivatives (module docstring, item 4); ``first``:
    the table index of the first state."""
    coords = coordinates(model.kind, model.rotation)
    names, units, texts = [], [], []
    for body in model.body_names:
        for c in coords:
            names.append(f"q.{body}.{c}")
            units.append(COORDINATE_UNITS[c])
            texts.append(f"{body}: {COORDINATE_TEXT[c]}" + (" (not normalised)" if c.startswith("e") else ""))
    for body in model.body_names:
        for v, unit in VELOCITY_OUTPUTS[model.kind]:
            names.append(f"h.{body}.{v}")
            units.append(unit)
            texts.append(f"{body}: {STATE_OUTPUT_TEXT[v]}")
    y0 = [float(x) for x in model.q0] + [float(x) for x in model.h0]
    assert len(names) == len(y0)
    out = [Var(n, "Real", "local", "continuous", "exact", f"continuous state: {t}", unit=u, start=y, key=("state", i))
           for i, (n, u, t, y) in enumerate(zip(names, units, texts, y0))]
    out += [Var(f"der({n})", "Real", "local", "continuous", "calculated", f"time derivative of {n}",
                unit=_DERIVATIVE_UNITS[u], key=("derivative", i), derivative=first + i)
            for i, (n, u) in enumerate(zip(names, units))]
    return out


def _reaction_arrays(model, table_so_far: list[Var]) -> list[Var]:
    """Per reaction joint the array of its reaction components (module docstring, item 5)."""
    index = {v.name: v.key[1] for v in table_so_far if v.key and v.key[0] == "output"}
    out = []
    for j in model.reaction_joints:
        c = model.joints[j]
        if c.type == "driver":
            continue  # a scalar effort
        units = {dict(TYPES[c.type].reaction).get(comp, "N") for comp in c.components}
        out.append(Var(f"{c.name}.reaction", "Real", "output", "continuous", "calculated",
                       f"reaction of joint {c.name}: the components {', '.join(c.components)} (the scalar outputs "
                       f"{c.name}.<component>) as one array", unit=units.pop() if len(units) == 1 else None,
                       key=("array", index[f"{c.name}.{c.components[0]}"]), size=len(c.components)))
    return out


def _along_outputs(model, reaction_unique, rank) -> list[Var]:
    """The uniqueness along the motion, after every older variable (their value references stay):
    ``<joint>.reaction_unique`` of the friction joints that are no reaction joints, then ``rank``."""
    out = [_along_reaction(model, j, bool(reaction_unique.get(model.joints[j].name, True)))
           for j in model.friction_joints if j not in set(model.reaction_joints)]
    out.append(_along_var("rank", "Integer", "rank of the whole constraint Jacobian (the pre-check's rule)",
                          int(rank) if rank is not None else 0, "rank"))
    return out


REDUNDANCY_TYPE = "overcon.Redundancy"
"""The FMI 2.0 TypeDefinition of the ``redundancy`` parameter: an Enumeration whose items are
:data:`overcon.spec.REDUNDANCY_METHODS` with values 1, 2, 3 in that order."""
REDUNDANCY_ITEMS = {
    "eliminate": "the paper's method: the scene's eliminated equations are removed",
    "min-norm": "every equation kept, minimum-norm multipliers (one motion, without physical ground)",
    "compliant": "joints with a [joints.compliance] table are spring-dampers (unique reactions); only for a "
                 "scene that has such joints",
}


def redundancy_methods(model) -> tuple[str, ...]:
    """The values the ``redundancy`` parameter of ``model``'s FMU takes: "compliant" only when a
    joint of the mechanism has a ``[joints.compliance]`` table."""
    compliant = any(j.compliance is not None for j in model.scene.mechanism.joints)
    return tuple(m for m in REDUNDANCY_METHODS if m != "compliant" or compliant)


def redundancy_rule(model) -> tuple[str, str]:
    """(the admissible values as a text, why "compliant" is not among them or ""): the rule of the
    ``redundancy`` parameter of ``model``'s FMU, written into the C FMU's model file too, so both
    runtimes refuse a value with the same words."""
    methods = redundancy_methods(model)
    known = "one of " + ", ".join(f"{i} ({m})" for i, m in enumerate(methods, start=1))
    why = "" if "compliant" in methods else (
        f"3 (compliant) needs a joint with a [joints.compliance] table: mechanism {model.scene.mechanism.name} "
        "has none")
    return known, why


def redundancy_refusal(model, value) -> str | None:
    """Why ``value`` (an Enumeration value: 1 eliminate, 2 min-norm, 3 compliant) is refused for
    the ``redundancy`` parameter of ``model``'s FMU, or None."""
    if isinstance(value, int) and not isinstance(value, bool) and 1 <= value <= len(redundancy_methods(model)):
        return None
    known, why = redundancy_rule(model)
    return f"must be {known}, got {value!r}" + (f" ({why})" if why else "")


def with_redundancy(spec, method: str):
    """``spec`` under the redundancy ``method`` (the FMU parameter ``redundancy``), exactly as the
    scene key ``[scene] redundancy`` would give it: "min-norm" and "compliant" choose no
    elimination (``eliminate = ()``); "eliminate" keeps the scene's eliminated equations, or
    ``"auto"`` (pivoted QR at q0, :func:`overcon.checks.resolve_elimination`) for a scene that
    names none."""
    if method == spec.redundancy:
        return spec
    if method == "eliminate":
        return dataclasses.replace(spec, redundancy=method, eliminate=spec.eliminate or "auto")
    return dataclasses.replace(spec, redundancy=method, eliminate=())


def redundancy_var(model) -> Var:
    """The ``redundancy`` parameter (issue 24): how the redundant constraints are handled, as the
    scene key ``[scene] redundancy``; set before initialization it changes the run exactly as that
    key would (:mod:`overcon.fmu.slave`)."""
    methods = redundancy_methods(model)
    return Var("redundancy", "Enumeration", "parameter", "fixed", "exact",
               "redundant constraints: " + "; ".join(f"{i} {m}: {REDUNDANCY_ITEMS[m]}"
                                                     for i, m in enumerate(methods, start=1)),
               start=REDUNDANCY_METHODS.index(model.scene.redundancy) + 1, key=("param", "redundancy"))


def _along_var(name: str, typ: str, text: str, start, arg) -> Var:
    """A discrete output judged along the motion (:class:`overcon.watch.Uniqueness`), its start
    value the pre-check's at t = 0."""
    return Var(name, typ, "output", "discrete", "exact", f"{text}, judged along the motion (start value: the "
               "pre-check at t = 0)", start=start, key=("along", arg))


def _along_reaction(model, j: int, start: bool) -> Var:
    """``<joint>.reaction_unique`` of friction joint ``j``."""
    name = model.joints[j].name
    return _along_var(f"{name}.reaction_unique", "Boolean", f"the reaction of joint {name} is unique (does not "
                      "depend on the eliminated equations)", start, j)


def rule(name: str) -> ParamRule:
    """The admissible values of parameter ``name`` (``joint4.mu``, ``solver.tolerance``): the
    rule of :data:`overcon.params.RULES`. KeyError for a name that is no parameter."""
    rule_of(name)  # KeyError now, not at check time
    return ParamRule(name)
