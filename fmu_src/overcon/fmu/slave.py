"""The FMI 2.0 co-simulation slave: every FMI call of the FMU binary (``native/overcon_fmi2.c``)
mapped onto :class:`overcon.simulate.Simulation`; no physics here.

Runs inside an FMU built by :mod:`overcon.fmu.build`, as a renamed copy of the package
(``overcon_<hash>``), with the scene and mechanism files and ``overcon_fmu.json`` (the build-time
facts: scene path, GUID, pre-check verdicts) in the FMU's ``resources/``. The binary calls the
methods below with C values (pointers as integers); each returns an ``fmi2Status`` and never
raises.

Behaviour
---------
* States (FMI 2.0 co-simulation): instantiated -> initialization mode -> slave initialized
  (stepping) -> terminated; ``error`` after a call that returned fmi2Error during stepping. A call
  not allowed in the current state returns fmi2Error with a message naming the call and the
  state (e.g. fmi2DoStep before fmi2ExitInitializationMode or after fmi2Terminate). In ``error``
  the outputs can still be read, and fmi2SetFMUstate, fmi2Reset, fmi2Terminate and
  fmi2FreeInstance are allowed.
* Variables: an unknown value reference, a value reference of another type, or a write to an
  output or constant returns fmi2Error with a message; nothing is set then.
* Parameters (``variables.table``) can be set until ``fmi2ExitInitializationMode`` (the work
  budget ``solver.max_internal_steps``/``solver.max_wall_time`` is tunable: also while stepping).
  A value that is non-finite or out of range is refused with fmi2Error and the reason; the
  instance keeps its previous value.
* ``redundancy`` (an Enumeration read and written with fmi2GetInteger/fmi2SetInteger: 1
  eliminate, 2 min-norm, 3 compliant, the last only for a scene with compliant joints; default
  the scene's ``[scene] redundancy``): set before initialization, the model is compiled again
  under that method (:func:`overcon.fmu.variables.with_redundancy`), so the run is the one of a scene file with that
  key. The constant ``motion_unique`` stays the build's pre-check verdict.
* Tolerance (the rule, also in the README): the integrator's tolerance is, first, the parameter
  ``solver.tolerance`` if the host set it (fmi2SetReal, before or after fmi2SetupExperiment);
  else the tolerance the host gave to ``fmi2SetupExperiment`` (``toleranceDefined``), as the FMI
  2.0 standard suggests for a slave with an error-controlled integrator; else the scene's
  ``solver.tolerance`` (also the modelDescription's DefaultExperiment tolerance). The choice is
  logged at info level (fmi2OK, category logEvents) by fmi2SetupExperiment and again at
  fmi2ExitInitializationMode ("from the ..."), and fmi2GetReal of ``solver.tolerance`` returns the
  tolerance used. A host tolerance outside the parameter's range [1e-14, 1e-2] is not used: that
  call returns fmi2Warning with the range (nothing is clamped); rk4 (fixed step) uses no tolerance.
* The model and the :class:`Simulation` are (re)built from the scene with the current parameters
  when first needed (outputs read in initialization mode, or ``fmi2ExitInitializationMode``). The
  start time comes from ``fmi2SetupExperiment``.
* ``do_step(t, h)`` integrates to ``t + h`` (the integrator keeps its own steps; any ``h >= 0``)
  and stores the outputs there. A run that cannot continue (engine failure, non-finite output,
  a communication point that is not the previous end time, a non-finite or negative step, the
  work budget exhausted) returns **fmi2Error** with the reason logged (error messages reach the
  host with debug logging off too); the instance enters ``error``, the outputs keep their last
  good values (never NaN), and later steps are refused until the state is set back
  (``fmi2SetFMUstate``) or the FMU is reset.
* Outputs the host does not read are not computed: ``fmi2DoStep`` always stores the positions;
  the reactions and friction forces (one evaluation of Eq. 18 at the communication point) only
  once the host has read one of them (fmpy's ``simulate_fmu`` reads every output, so for it
  nothing changes). A first read after steps that skipped them computes them at the current
  point (the same values the step would have stored); if that fails, that ``fmi2GetReal``
  returns fmi2Error with the reason. Repeated ``fmi2GetReal``/``fmi2GetBoolean`` of outputs are
  answered by the binary (published values, below).
* Published values: in an FMU the slave registers arrays it owns with the binary (once, at
  fmi2Instantiate, through the binary's ``register_published``): per value reference the slot of
  a Real output (or -1) and the value of a constant Boolean output (or -1), the published outputs
  and two flags (positions and constants valid; reactions and friction forces valid). The binary
  answers ``fmi2GetReal``/``fmi2GetBoolean`` of published references from there without entering
  Python while their flag is set, and clears both flags before every call into the slave that is
  not a getter. :meth:`OverconSlave._publish` sets them at the end of a successful
  ``fmi2DoStep`` and ``fmi2ExitInitializationMode`` (state ``slave initialized``, the outputs
  those the Python getter returns), the reactions' flag only while they are current and the host
  has read one through Python (so the laziness above is unchanged), and again once a read
  computed the reactions. Any other state (initialization mode, after fmi2SetReal, fmi2Reset,
  fmi2SetFMUstate, a failed step, fmi2Terminate) is answered by Python until the next successful
  step. The environment variable ``OVERCON_NO_PUBLISH=1`` at fmi2Instantiate switches the
  registration off (every get through Python, as before; for tests and diagnosis). In-process use
  (no binary) registers nothing.
* Work budget of one ``fmi2DoStep``: at most ``solver.max_internal_steps`` integrator steps and
  ``solver.max_wall_time`` seconds, checked after every internal step
  (:meth:`overcon.simulate.Simulation.advance`); the trajectory does not depend on the budget.
* FMU state: the full :meth:`Simulation.get_state` (integrator arrays, lam, counters, singularity
  monitor) plus the parameters, time, outputs and mode; set/get/serialize are exact (bit for bit).
"""
from __future__ import annotations

import copy
import ctypes
import enum
import functools
import json
import math
import os
import time
from pathlib import Path

import numpy as np

from .. import kernel
from .. import scene as scene_mod
from ..checks import compile_checked
from ..params import apply_overrides, check_mu_static
from ..precheck import friction_warnings, frictionless
from ..simulate import BudgetExceeded, Simulation
from . import statecodec, variables

MANIFEST = "overcon_fmu.json"
"""Build-time facts in the FMU's resources/: scene path, guid, reaction_unique, motion_unique."""

_LOG_FUNCTION = ctypes.CFUNCTYPE(None, ctypes.c_void_p, ctypes.c_int, ctypes.c_char_p)
_PUBLISH_FUNCTION = ctypes.CFUNCTYPE(None, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_int, ctypes.c_void_p,
                                     ctypes.c_void_p, ctypes.c_int, ctypes.c_int, ctypes.c_void_p)
"""register_published(component, flags, n_real_map, real_slot, real_values, n_pos, n_bool_map,
bool_value) of the binary (native/overcon_fmi2.c)."""
_C_TYPES = {"Real": ctypes.c_double, "Integer": ctypes.c_int, "Boolean": ctypes.c_int,
            "String": ctypes.c_char_p}


class Status(enum.IntEnum):
    """fmi2Status."""
    OK = 0
    WARNING = 1
    DISCARD = 2
    ERROR = 3
    FATAL = 4


class Mode(str, enum.Enum):
    INSTANTIATED = "instantiated"
    INITIALIZATION = "initialization mode"
    STEPPING = "slave initialized"
    ERROR = "error"
    TERMINATED = "terminated"


ANY_MODE = frozenset(Mode)
READABLE = frozenset({Mode.INITIALIZATION, Mode.STEPPING, Mode.ERROR, Mode.TERMINATED})
WRITABLE = frozenset({Mode.INSTANTIATED, Mode.INITIALIZATION, Mode.STEPPING})


class CallRefused(Exception):
    """The call cannot be done: it returns fmi2Error and the message is logged."""


class ParameterRefused(CallRefused, ValueError):
    """A parameter value outside its admissible range, or set when it may no longer change."""


class BudgetExhausted(ArithmeticError):
    """fmi2DoStep used up its work budget (solver.max_internal_steps or solver.max_wall_time)."""


def fmi_call(name: str, modes=ANY_MODE):
    """Wrap a method the binary calls as FMI function ``name``: refused outside ``modes``; a
    :class:`CallRefused` or any other exception becomes fmi2Error with its message logged; the
    method's own return value (a Status) or OK otherwise."""

    def wrap(method):
        @functools.wraps(method)
        def call(self, *args):
            if self._mode not in modes:
                allowed = ", ".join(sorted(m.value for m in modes))
                self.log(f"{name}: not allowed in state '{self._mode.value}' (allowed in: {allowed})",
                         Status.ERROR)
                return Status.ERROR
            try:
                status = method(self, *args)
            except CallRefused as exc:
                self.log(f"{name}: {exc}", Status.ERROR)
                return Status.ERROR
            except Exception as exc:  # a bug or an unexpected engine failure: never a crash
                self.log(f"{name}: {type(exc).__name__}: {exc}", Status.ERROR)
                return Status.ERROR
            return Status.OK if status is None else Status(status)

        return call

    return wrap


def instantiate(instance_name: str, guid: str, resources: str, log_address: int, component: int,
                logging_on: bool, publish_address: int = 0) -> "OverconSlave":
    """fmi2Instantiate (through :func:`overcon.fmu.boot.instantiate`): the slave, logging through
    the binary's log function at ``log_address`` for ``component`` and publishing its outputs
    through ``register_published`` at ``publish_address`` (0 or ``OVERCON_NO_PUBLISH=1``: not)."""
    log_function = _LOG_FUNCTION(log_address)

    def log(status: int, message: str) -> None:
        log_function(component, int(status), message.encode("utf-8", "replace"))

    slave = OverconSlave(resources, guid=guid, instance_name=instance_name, log=log)
    if publish_address and os.environ.get("OVERCON_NO_PUBLISH", "") in ("", "0"):
        slave._register_published(_PUBLISH_FUNCTION(publish_address), component)
    return slave


class OverconSlave:
    """One FMU instance; everything scene specific is read from ``resources``. Without ``log``
    (in-process use) messages are kept in ``self.messages``."""

    def __init__(self, resources, *, guid: str | None = None, instance_name: str = "overcon", log=None):
        res = Path(resources)
        self._manifest = json.loads((res / MANIFEST).read_text(encoding="utf-8"))
        if guid is not None and guid != self._manifest["guid"]:
            raise CallRefused(f"fmi2Instantiate: GUID {guid} does not match this FMU's "
                              f"{self._manifest['guid']} (modelDescription.xml of another build?)")
        kernel_lib = self._manifest.get("kernel", {}).get("library")
        if kernel_lib:  # the compiled kernel built with this FMU (overcon.kernel): never compiled here
            kernel.use_library(res.parent / kernel_lib)
        else:
            kernel.disable("this FMU carries no compiled kernel")
        self.instance_name = instance_name
        self.messages: list[tuple[int, str]] = []
        self._log_sink = log
        spec = scene_mod.load(res / self._manifest["scene"])
        self._scene = spec
        self._model0 = compile_checked(spec)
        self._model, self._model_friction = self._model0, (spec.friction_params, spec.redundancy)  # compiled for these
        self._vars = variables.table(self._model0, spec.solver, self._manifest["reaction_unique"],
                                     self._manifest["motion_unique"])
        self._defaults = {v.key[1]: v.start for v in self._vars if v.key[0] == "param"}
        self._tunable = {v.key[1] for v in self._vars if v.key[0] == "param" and v.variability == "tunable"}
        self._states: dict[int, dict] = {}
        self._next_state = 1
        self._strings: list[bytes] = []  # fmi2GetString's results, valid until the next call
        self._ref_cache: dict[tuple[str, bytes], list] = {}
        self._n_positions = len(self._model0.state_output_names())  # outputs of the state alone, before the reactions
        # published values (see the module docstring); fixed arrays: the binary keeps their addresses
        self._publishing = False
        self._pub_flags = np.zeros(2, np.intc)
        self._pub_values = np.zeros(len(self._model0.output_names()))
        self._pub_real_slot = np.full(len(self._vars), -1, np.intc)
        self._pub_bool = np.full(len(self._vars), -1, np.intc)
        for r, v in enumerate(self._vars):
            if v.type == "Real" and v.key[0] == "output":
                self._pub_real_slot[r] = v.key[1]
            elif v.type == "Boolean" and v.key[0] == "constant" and v.causality == "output":
                self._pub_bool[r] = int(bool(v.key[1]))
        self._pub_along = [(r, v.key[1]) for r, v in enumerate(self._vars) if v.type == "Boolean" and v.key[0] == "along"]
        self._init_fields()
        for text in friction_warnings(self._model0):  # the pre-check's warnings (also in the manifest)
            self.log(text, Status.WARNING)

    def _init_fields(self) -> None:
        """The state after fmi2Instantiate (and fmi2Reset)."""
        self._params = dict(self._defaults)
        self._explicit: set[str] = set()
        self._tolerance_source = "the scene"  # who chose solver.tolerance (module docstring, "Tolerance")
        self._start_time = self._scene.start_time
        self._mode = Mode.INSTANTIATED
        self._sim: Simulation | None = None
        self._sim_key = None  # parameters the current Simulation was built with
        self._t = self._scene.start_time
        self._outputs = np.zeros(len(self._model0.output_names()))
        self._have_outputs = False
        self._failed: str | None = None
        self._stable_step = 0.0  # solver.stable_step: set when rk4 refuses a step as unstable
        self._events_logged = 0  # events of the run already logged (_log_events)
        self._y = None  # the state at self._t (for outputs computed when first read)
        self._derived_stale = False  # reactions/friction outputs not yet computed at self._t
        self._derived_read = False  # the host has read a reaction or friction output

    def _register_published(self, register, component: int) -> None:
        """Hand the published arrays to the binary (``register``: its register_published)."""
        self._pub_flags[:] = 0
        register(component, self._pub_flags.ctypes.data, len(self._pub_real_slot), self._pub_real_slot.ctypes.data,
                 self._pub_values.ctypes.data, self._n_positions, len(self._pub_bool), self._pub_bool.ctypes.data)
        self._publishing = True

    def _publish(self) -> None:
        """Publish the current outputs (state slave initialized, outputs current): positions and
        constants always; reactions and friction forces only if current and read by the host
        before (a first read goes through Python, which switches them on in later steps)."""
        if not self._publishing:
            return
        self._pub_values[:] = self._outputs
        for r, arg in self._pub_along:  # the discrete verdicts, as Python would answer them
            self._pub_bool[r] = int(bool(self._along(arg)))
        derived_ok = not self._derived_stale and (self._derived_read or len(self._outputs) == self._n_positions)
        self._pub_flags[1] = 1 if derived_ok else 0
        self._pub_flags[0] = 1

    def _log_events(self, sim, skip_stopped: bool = False) -> None:
        """Log the run's events (overcon.simulate.EVENT_KINDS: an elimination chosen again, ...)
        not logged yet, at info level (category logEvents); a failed step logs its stop itself
        (``skip_stopped``)."""
        for t, kind, detail in sim.events[self._events_logged:]:
            if not (skip_stopped and kind == "stopped"):
                self.log(f"t = {t:.9g} s: event {kind}: {detail}")
        self._events_logged = len(sim.events)

    def log(self, message: str, status=Status.OK) -> None:
        if self._log_sink is None:
            self.messages.append((int(status), str(message)))
        else:
            self._log_sink(int(status), str(message))

    # -- variables ---------------------------------------------------------------------------
    def _refs(self, vr_address: int, n: int, typ: str):
        """The (value reference, Var) pairs of a C array, all of type ``typ``, or CallRefused.
        Checked lists are cached by their bytes (hosts ask for the same references every step)."""
        if n and not vr_address:
            raise CallRefused(f"vr is NULL but nvr = {n}")
        raw = ctypes.string_at(vr_address, n * ctypes.sizeof(ctypes.c_uint)) if n else b""
        key = (typ, raw)
        cached = self._ref_cache.get(key)
        if cached is not None:
            return cached
        out = []
        for r in (ctypes.c_uint * n).from_buffer_copy(raw) if n else ():
            if r >= len(self._vars):
                raise CallRefused(f"value reference {r} does not exist (this FMU has 0 to {len(self._vars) - 1})")
            v = self._vars[r]
            if v.type != typ and not (v.type == "Enumeration" and typ == "Integer"):  # FMI: enumerations as Integer
                raise CallRefused(f"value reference {r} ({v.name}) is a {v.type} variable, not {typ}")
            out.append((r, v))
        if len(self._ref_cache) < 256:
            self._ref_cache[key] = out
        return out

    def _value(self, v: variables.Var):
        kind, arg = v.key
        if kind == "output":
            if not self._have_outputs:
                self._ensure_sim()
            if arg >= self._n_positions:
                self._read_derived()
            return float(self._outputs[arg])
        if kind == "constant":
            return arg
        if kind == "along":  # the run's last judgement of the uniqueness along the motion
            return self._along(arg)
        if kind == "stable_step":
            return self._stable_step
        return self._params[arg]

    def _along(self, arg):
        """``rank``, ``motion_unique`` or joint ``arg``'s ``reaction_unique`` of the run's
        :class:`overcon.watch.Uniqueness` (the run is made first when there is none)."""
        if self._sim is None:
            self._ensure_sim()
        along = self._sim.along
        if arg == "rank":
            return along.rank
        if arg == "motion":
            return along.motion_unique
        return along.unique[self._model0.joints[arg].name]

    def _get(self, typ: str, vr_address: int, n: int, values_address: int) -> None:
        refs = self._refs(vr_address, n, typ)
        if n and not values_address:
            raise CallRefused(f"value is NULL but nvr = {n}")
        if typ == "Real" and refs and all(v.key[0] == "output" for _, v in refs):
            if not self._have_outputs:
                self._ensure_sim()
            idx = [v.key[1] for _, v in refs]
            if max(idx) >= self._n_positions:
                self._read_derived()
            np.ctypeslib.as_array((ctypes.c_double * n).from_address(values_address))[:] = self._outputs[idx]
            return
        vals = [self._value(v) for _, v in refs]
        out = (_C_TYPES[typ] * n).from_address(values_address) if n else ()
        if typ == "String":
            self._strings = [str(x).encode("utf-8") for x in vals]
            for i, b in enumerate(self._strings):
                out[i] = b
        else:
            for i, x in enumerate(vals):
                out[i] = int(bool(x)) if typ == "Boolean" else x

    def _set(self, typ: str, vr_address: int, n: int, values_address: int) -> None:
        refs = self._refs(vr_address, n, typ)
        if n and not values_address:
            raise CallRefused(f"value is NULL but nvr = {n}")
        raw = list((_C_TYPES[typ] * n).from_address(values_address)) if n else []
        for (r, v), x in zip(refs, raw):
            if v.key[0] != "param":
                raise CallRefused(f"value reference {r} ({v.name}) is {v.causality} ({v.variability}): "
                                  "it cannot be set")
        for (r, v), x in zip(refs, raw):
            if typ == "String":
                x = None if x is None else x.decode("utf-8", "replace")
            elif typ == "Boolean":
                x = bool(x)
            self._set_param(v.key[1], x)

    def _accessor(function, modes, impl, typ):  # noqa: N805 (used in the class body below)
        return fmi_call(function, modes)(
            lambda self, vr_address, n, values_address: impl(self, typ, vr_address, n, values_address))

    get_real = _accessor("fmi2GetReal", READABLE, _get, "Real")
    get_integer = _accessor("fmi2GetInteger", READABLE, _get, "Integer")
    get_boolean = _accessor("fmi2GetBoolean", READABLE, _get, "Boolean")
    get_string = _accessor("fmi2GetString", READABLE, _get, "String")
    set_real = _accessor("fmi2SetReal", WRITABLE, _set, "Real")
    set_integer = _accessor("fmi2SetInteger", WRITABLE, _set, "Integer")
    set_boolean = _accessor("fmi2SetBoolean", WRITABLE, _set, "Boolean")
    set_string = _accessor("fmi2SetString", WRITABLE, _set, "String")
    del _accessor

    def _set_param(self, name: str, value) -> None:
        tunable = name in self._tunable
        if self._mode == Mode.STEPPING and not tunable:
            self._refuse(name, value, "variability fixed: it cannot change after initialization "
                                      "(fmi2Reset first)")
        if value is None:
            self._refuse(name, value, "a value is required")
        if name == "redundancy":
            reason = variables.redundancy_refusal(self._model0, value)
        else:
            reason = variables.rule(name).check(value)
        if reason is None and name.endswith(".mu_static"):
            mu_name = name[: -len("_static")]
            reason = check_mu_static(self._params[mu_name], value, mu_name)
        if reason is not None:
            self._refuse(name, value, reason)
        self._params[name] = value if isinstance(value, str) else type(self._defaults[name])(value)
        self._explicit.add(name)
        if name == "solver.tolerance":
            self._tolerance_source = "the parameter solver.tolerance"
        if not tunable:
            self._drop_sim()

    @staticmethod
    def _refuse(name, value, reason) -> None:
        raise ParameterRefused(f"parameter {name} = {value!r} refused: {reason}")

    # -- model and simulation ----------------------------------------------------------------
    def _drop_sim(self) -> None:
        """Forget the Simulation (parameters or start time changed before initialization)."""
        self._sim = self._sim_key = None
        self._have_outputs = False

    def _key(self):
        return (self._start_time, tuple(sorted((k, v) for k, v in self._params.items() if k not in self._tunable)))

    def _current_scene(self):
        """The scene with the current solver and friction parameters, through the one override
        function :func:`overcon.params.apply_overrides` (its range rules and ``mu_static >= mu``).
        Its run-length relations are not applied: an FMU's run length is the host's, bounded per
        fmi2DoStep by the work budget."""
        values = {k: v for k, v in self._params.items() if k not in self._tunable and k != "redundancy"}
        new, problems = apply_overrides(self._scene, values, relations=False)
        if problems:
            raise ParameterRefused("; ".join(f"parameter {name} refused: {msg}" for name, msg in problems))
        return variables.with_redundancy(new, variables.redundancy_methods(self._model0)[self._params["redundancy"] - 1])

    def _model_for(self, spec):
        """The compiled model of ``spec``: recompiled (rank analysis included) only when the
        friction parameters or the redundancy method changed. Solver options are not part of a Model (they go to the
        Simulation), so a new ``solver.*`` value never recompiles."""
        if (spec.friction_params, spec.redundancy) != self._model_friction:
            own = (spec.friction_params, spec.redundancy) == (self._scene.friction_params, self._scene.redundancy)
            self._model = self._model0 if own else compile_checked(spec)
            self._model_friction = (spec.friction_params, spec.redundancy)
            switched = [self._model.joints[j].name for j in self._model.friction_joints
                        if frictionless(self._model.joints[j].law) != frictionless(self._model0.joints[j].law)]
            if switched:
                self.log(f"friction in joint(s) {', '.join(switched)} switched between mu = 0 and mu > 0 by the "
                         "parameters: the constant motion_unique (the pre-check at the build's parameters) may "
                         "not hold for this run; run overcon check with these values", Status.WARNING)
        return self._model

    def _ensure_sim(self, compute_outputs: bool = True) -> Simulation:
        key = self._key()
        if self._sim is None or self._sim_key != key:
            self._sim = None
            spec = self._current_scene()
            sim = Simulation(self._model_for(spec), spec.solver, start_time=key[0])
            self._sim, self._sim_key = sim, key
            self._t = key[0]
            self._have_outputs = False
            self._events_logged = 0
        if compute_outputs and not self._have_outputs:
            y = self._sim.advance(self._t)
            out = self._sim.outputs(self._t, y)
            if not np.all(np.isfinite(out)):
                raise ArithmeticError(f"non-finite initial outputs at t = {self._t:.9g} s")
            self._outputs, self._have_outputs, self._y, self._derived_stale = out, True, y, False
        return self._sim

    def _read_derived(self) -> None:
        """The host reads a reaction or friction output: compute them at self._t if the last
        fmi2DoStep skipped them (nobody had read one before), and compute them in every later
        fmi2DoStep. A failure is this read's fmi2Error (the values keep their previous ones)."""
        self._derived_read = True
        if not self._derived_stale:
            if self._pub_flags[0] and not self._pub_flags[1]:
                self._publish()  # the first read: from now on the reactions are published too
            return
        try:
            vals = self._sim.derived_outputs(self._t, self._y)
            if not np.isfinite(vals).all():
                raise ArithmeticError("non-finite values")
        except Exception as exc:
            raise CallRefused(f"reactions and friction forces at t = {self._t!r} s could not be computed: "
                              f"{type(exc).__name__}: {exc}") from exc
        self._outputs[self._n_positions:] = vals
        self._derived_stale = False
        if self._pub_flags[0]:  # published positions are current: add the reactions
            self._publish()

    def _budget_exhausted(self, exc: BudgetExceeded) -> BudgetExhausted:
        """The fmi2DoStep error of a used-up doStep work budget (see the module docstring)."""
        p = self._params
        return BudgetExhausted(
            f"work budget exhausted in this doStep (solver.max_internal_steps = {p['solver.max_internal_steps']}, "
            f"solver.max_wall_time = {p['solver.max_wall_time']!r} s): "
            f"{str(exc).removeprefix('integration stopped: ')}; raise them or use shorter communication steps")

    # -- FMI calls ---------------------------------------------------------------------------
    @fmi_call("fmi2SetupExperiment", {Mode.INSTANTIATED})
    def setup_experiment(self, tolerance_defined: int, tolerance: float, start_time: float,
                         stop_time_defined: float = 0.0, stop_time: float = 0.0):
        start = float(start_time)
        if not math.isfinite(start):
            raise CallRefused(f"start time {start!r} refused (not finite)")
        if stop_time_defined and not stop_time >= start:
            raise CallRefused(f"stop time {stop_time!r} is before the start time {start!r}")
        self._start_time = start
        self._drop_sim()
        if tolerance_defined:
            return self._host_tolerance(tolerance)
        return Status.OK

    def _host_tolerance(self, tolerance: float):
        """fmi2SetupExperiment's tolerance (see the module docstring, "Tolerance"): used unless the
        host set the parameter ``solver.tolerance``; one outside that parameter's range is not used
        (fmi2Warning, the message names the range)."""
        rule = variables.rule("solver.tolerance")
        if "solver.tolerance" in self._explicit:
            self.log(f"fmi2SetupExperiment: tolerance {tolerance!r} not used: the host set the parameter "
                     f"solver.tolerance = {self._params['solver.tolerance']!r}, which wins", Status.OK)
            return Status.OK
        reason = rule.check(tolerance)
        if reason is not None:
            self.log(f"fmi2SetupExperiment: tolerance {tolerance!r} not used ({reason}); the integrator uses "
                     f"solver.tolerance = {self._params['solver.tolerance']!r}", Status.WARNING)
            return Status.WARNING
        self._params["solver.tolerance"] = float(tolerance)
        self._tolerance_source = "fmi2SetupExperiment"
        fixed = " (the fixed-step method rk4 does not use it)" if self._params["solver.method"] == "rk4" else ""
        self.log(f"fmi2SetupExperiment: tolerance {tolerance!r} used as solver.tolerance{fixed}", Status.OK)
        return Status.OK

    @fmi_call("fmi2EnterInitializationMode", {Mode.INSTANTIATED})
    def enter_initialization_mode(self):
        self._mode = Mode.INITIALIZATION

    @fmi_call("fmi2ExitInitializationMode", {Mode.INITIALIZATION})
    def exit_initialization_mode(self):
        try:
            self._ensure_sim()
        except Exception as exc:
            self._mode = Mode.ERROR
            raise CallRefused(f"initialization failed: {type(exc).__name__}: {exc}") from exc
        self._mode = Mode.STEPPING
        self.log(f"initialized at t = {self._t!r} s: method {self._params['solver.method']}, tolerance "
                 f"{self._params['solver.tolerance']!r} (from {self._tolerance_source}); {self._sim.kernel_note}",
                 Status.OK)
        if self._sim.kernel_missing:  # the FMU's own library should run this model: say it is slower
            self.log(f"the compiled kernel this FMU carries cannot be used ({self._sim.kernel_note}); it runs "
                     "on numpy and scipy alone, the same results, several times slower", Status.WARNING)
        self._publish()

    def do_step(self, current_time: float, step_size: float, no_set_fmu_state_prior: int = 0):
        """fmi2DoStep: in state slave initialized the step itself without the :func:`fmi_call`
        layer (this is the per-communication-point call; the step catches its own failures);
        otherwise the checked call, which refuses it with the message."""
        if self._mode is not Mode.STEPPING:
            return self._do_step_checked(current_time, step_size, no_set_fmu_state_prior)
        try:
            return self._step(current_time, step_size)
        except Exception as exc:  # as fmi_call: a bug is fmi2Error, never a crash
            self.log(f"fmi2DoStep: {type(exc).__name__}: {exc}", Status.ERROR)
            return Status.ERROR

    def _step(self, current_time: float, step_size: float, no_set_fmu_state_prior: int = 0):
        """The step of :meth:`do_step` (see the module docstring)."""
        try:
            if not (math.isfinite(current_time) and math.isfinite(step_size) and step_size >= 0):
                raise CallRefused("the communication step must be finite and >= 0")
            if abs(current_time - self._t) > 1e-9 * max(1.0, abs(self._t)):
                raise CallRefused(f"communication point {current_time!r} s is not the end of the previous "
                                  f"step ({self._t!r} s)")
            # while stepping, no parameter that builds the Simulation can change: no key check
            sim = self._sim if self._sim is not None else self._ensure_sim()
            t_new = current_time + step_size
            p = self._params  # the doStep work budget (typed when set: _set_param)
            try:
                y = sim.advance(t_new, max_steps=p["solver.max_internal_steps"],
                                max_wall_time=p["solver.max_wall_time"])
            except BudgetExceeded as exc:
                raise self._budget_exhausted(exc) from None
            self._log_events(sim)
            if self._derived_read or len(self._outputs) == self._n_positions:
                out = sim.outputs(t_new, y)
            else:  # reactions and friction forces only once the host reads one (_read_derived)
                out = self._outputs.copy()
                out[: self._n_positions] = sim.state_outputs(y)
            if not math.isfinite(sum(out.tolist())):  # cheaper than np.isfinite for a few outputs
                bad = [n for n, v in zip(self._model0.output_names(), out) if not math.isfinite(v)]
                if bad:  # (else the sum overflowed)
                    raise ArithmeticError(f"t = {t_new:.9g} s: non-finite outputs {', '.join(bad)}")
        except Exception as exc:  # the run cannot continue: fmi2Error, never NaN, never a crash
            if self._sim is not None:  # the events on the way to the stop (the stop itself: below)
                self._log_events(self._sim, skip_stopped=True)
            what = str(exc) if isinstance(exc, CallRefused) else f"{type(exc).__name__}: {exc}"
            if getattr(exc, "stable_step", None):
                self._stable_step = float(exc.stable_step)
            self._failed = f"fmi2DoStep({current_time!r}, {step_size!r}): {what}"
            self._mode = Mode.ERROR
            self.log(f"{self._failed}; the run stopped at t = {self._t!r} s (the outputs keep their values "
                     "there; fmi2SetFMUstate or fmi2Reset to continue)", Status.ERROR)
            return Status.ERROR
        self._outputs, self._t, self._have_outputs, self._y = out, t_new, True, y
        self._derived_stale = not self._derived_read and len(out) > self._n_positions
        self._publish()
        return Status.OK

    _do_step_checked = fmi_call("fmi2DoStep", {Mode.STEPPING})(_step)

    @fmi_call("fmi2Terminate", {Mode.STEPPING, Mode.ERROR})
    def terminate(self):
        self._mode = Mode.TERMINATED

    @fmi_call("fmi2Reset")
    def reset(self):
        self._init_fields()

    def free_instance(self) -> int:
        self._states.clear()
        self._publishing = False
        self._pub_flags[:] = 0
        self._sim = None
        self._log_sink = None
        return Status.OK

    @fmi_call("fmi2GetStatus")
    def get_status(self, function: str, kind: int, value_address: int):
        """fmi2Get*Status: fmi2LastSuccessfulTime (Real) and fmi2Terminated (Boolean) are known;
        this FMU never returns fmi2Pending, so the asynchronous kinds are not available."""
        if not value_address:
            raise CallRefused(f"{function}: value is NULL")
        if function == "fmi2GetRealStatus" and kind == 2:
            ctypes.c_double.from_address(value_address).value = self._t
            return Status.OK
        if function == "fmi2GetBooleanStatus" and kind == 3:
            ctypes.c_int.from_address(value_address).value = int(self._mode == Mode.ERROR)
            return Status.OK
        kinds = {0: "fmi2DoStepStatus", 1: "fmi2PendingStatus", 2: "fmi2LastSuccessfulTime", 3: "fmi2Terminated"}
        raise CallRefused(f"{function}({kinds.get(kind, kind)}): not available (this FMU never returns "
                          "fmi2Pending; known: fmi2GetRealStatus(fmi2LastSuccessfulTime), "
                          "fmi2GetBooleanStatus(fmi2Terminated))")

    @fmi_call("unsupported")
    def unsupported(self, function: str):
        raise CallRefused(f"{function} is not supported by this FMU (no inputs, no derivatives, "
                          "no asynchronous steps)")

    # -- FMU state ---------------------------------------------------------------------------
    def _snapshot(self) -> dict:
        return {
            "guid": self._manifest["guid"],
            "params": dict(self._params), "explicit": sorted(self._explicit),
            "start_time": self._start_time, "tolerance_source": self._tolerance_source, "mode": self._mode.value, "t": self._t,
            "outputs": self._outputs.copy(), "have_outputs": self._have_outputs, "failed": self._failed,
            "stable_step": self._stable_step,
            "y": None if self._y is None else self._y.copy(), "derived_stale": self._derived_stale,
            "sim": None if self._sim is None else copy.deepcopy(self._sim.get_state()),
        }

    def _restore(self, state: dict) -> None:
        if not isinstance(state, dict) or state.get("guid") != self._manifest["guid"]:
            raise CallRefused("the state does not belong to this FMU (GUID differs)")
        self._params = dict(state["params"])
        self._explicit = set(state["explicit"])
        self._start_time = state["start_time"]
        self._tolerance_source = state.get("tolerance_source", "the scene")
        if state["sim"] is None:
            self._drop_sim()
        else:
            self._ensure_sim(compute_outputs=False).set_state(state["sim"])
        self._mode, self._t = Mode(state["mode"]), state["t"]
        self._outputs = np.array(state["outputs"], float)
        self._have_outputs, self._failed = state["have_outputs"], state["failed"]
        self._stable_step = float(state.get("stable_step", 0.0))
        self._events_logged = 0 if self._sim is None else len(self._sim.events)  # a restored run logs on from here
        self._y = state.get("y")  # states of earlier versions: outputs complete
        self._derived_stale = bool(state.get("derived_stale", False)) and self._y is not None

    def _handle(self, address: int) -> int:
        if not address:
            raise CallRefused("FMUstate is NULL")
        return ctypes.c_void_p.from_address(address).value or 0

    def _state(self, handle: int) -> dict:
        if handle not in self._states:
            raise CallRefused(f"FMUstate {handle:#x} is not a state of this instance (freed or never got)")
        return self._states[handle]

    def _store(self, address: int, entry: dict) -> None:
        handle = self._handle(address)
        if handle not in self._states:  # NULL or foreign: a new state; else overwrite it (FMI 2.0)
            handle, self._next_state = self._next_state, self._next_state + 1
        self._states[handle] = entry
        ctypes.c_void_p.from_address(address).value = handle

    @fmi_call("fmi2GetFMUstate")
    def get_fmu_state(self, address: int):
        self._store(address, {"state": self._snapshot()})

    @fmi_call("fmi2SetFMUstate")
    def set_fmu_state(self, handle: int):
        self._restore(self._state(handle)["state"])

    @fmi_call("fmi2FreeFMUstate")
    def free_fmu_state(self, address: int):
        handle = self._handle(address)
        if handle:
            self._state(handle)
            del self._states[handle]
            ctypes.c_void_p.from_address(address).value = None

    def _serialized(self, handle: int) -> bytes:
        entry = self._state(handle)
        if "bytes" not in entry:
            entry["bytes"] = statecodec.dumps(entry["state"])
        return entry["bytes"]

    @fmi_call("fmi2SerializedFMUstateSize")
    def serialized_fmu_state_size(self, handle: int, size_address: int):
        if not size_address:
            raise CallRefused("size is NULL")
        ctypes.c_size_t.from_address(size_address).value = len(self._serialized(handle))

    @fmi_call("fmi2SerializeFMUstate")
    def serialize_fmu_state(self, handle: int, buffer: int, size: int):
        data = self._serialized(handle)
        if size < len(data) or not buffer:
            raise CallRefused(f"the buffer holds {size} bytes, the state needs {len(data)} "
                              "(fmi2SerializedFMUstateSize)")
        ctypes.memmove(buffer, data, len(data))

    @fmi_call("fmi2DeSerializeFMUstate")
    def deserialize_fmu_state(self, buffer: int, size: int, address: int):
        if size and not buffer:
            raise CallRefused(f"serializedState is NULL but size = {size}")
        try:
            state = statecodec.loads(ctypes.string_at(buffer, size) if size else b"")
        except ValueError as exc:
            raise CallRefused(f"the bytes are not an FMU state of this FMU: {exc}") from None
        if not isinstance(state, dict) or state.get("guid") != self._manifest["guid"]:
            raise CallRefused("the state does not belong to this FMU (GUID differs)")
        self._store(address, {"state": state})
