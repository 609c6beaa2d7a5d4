"""The FMI 2.0 co-simulation facade (a pythonfmu ``Fmi2Slave``): variables and FMI calls mapped
onto :class:`overcon.simulate.Simulation`; no physics here.

Runs inside an FMU built by :mod:`overcon.fmu.build`, as a renamed copy of the package
(``overcon_<hash>``), with the scene and mechanism files and ``overcon_fmu.json`` (the build-time
facts: scene path, GUID, pre-check verdicts) in the FMU's ``resources/``.

Behaviour
---------
* pythonfmu 0.7's wrapper passes only the start time of ``fmi2SetupExperiment`` to Python (its
  tolerance and stop time are dropped), so the integrator tolerance is the parameter
  ``solver.tolerance`` (default: the scene's); a tolerance given to :meth:`setup_experiment` by
  another caller is used unless ``solver.tolerance`` was set.
* Parameters (``variables.table``) can be set until ``fmi2ExitInitializationMode``. A value that is
  non-finite or out of range is refused: the reason is logged and the call fails. pythonfmu 0.7's C
  wrapper turns every Python exception into ``fmi2Fatal`` (there is no way to return
  ``fmi2Error`` from Python); the instance keeps its previous value and stays usable (see
  :func:`_fmi_call`), though FMI says a host should free an instance after ``fmi2Fatal``. Setting
  a parameter after initialization is refused the same way (variability fixed).
* The model and the :class:`Simulation` are (re)built from the scene with the current parameters
  when first needed (outputs read in initialization mode, or ``fmi2ExitInitializationMode``). The
  start time comes from ``fmi2SetupExperiment``.
* ``do_step(t, h)`` integrates to ``t + h`` (the integrator keeps its own steps; any ``h > 0``)
  and stores the outputs there. Any engine exception, a non-finite output, a communication point
  that is not the previous end time, or a non-finite/negative step makes it return False
  (``fmi2Discard``) with the reason logged; outputs keep their last good values (never NaN), and
  later steps are refused until the state is set back (``fmi2SetFMUstate``) or the FMU is reset.
* FMU state: the full :meth:`Simulation.get_state` (integrator arrays, lam, counters, singularity
  monitor) plus the parameters, time, outputs and mode; set/get/serialize are exact (bit for bit).
  ``fmi2Reset`` is done by pythonfmu's wrapper by instantiating this class again.
"""
from __future__ import annotations

import copy
import ctypes
import dataclasses
import functools
import json
import math
from pathlib import Path

import numpy as np
from pythonfmu.enums import Fmi2Causality, Fmi2Initial, Fmi2Status, Fmi2Variability
from pythonfmu.fmi2slave import Fmi2Slave
from pythonfmu.variables import Boolean, Integer, Real, String

from .. import scene as scene_mod
from ..model import compile_model
from ..simulate import Simulation
from . import statecodec, variables

MANIFEST = "overcon_fmu.json"
"""Build-time facts in the FMU's resources/: scene path, guid, reaction_unique, motion_unique."""

_TYPES = {"Real": Real, "Integer": Integer, "Boolean": Boolean, "String": String}
_FRICTION_FIELDS = {"mu": "mu", "v_reg": "v_reg", "mu_static": "mu_static", "v_stribeck": "v_stribeck"}


class ParameterRefused(ValueError):
    """A parameter value outside its admissible range, or set when it may no longer change."""


def pin_entry_namespace(namespace: dict) -> None:
    """Called at the top of the FMU's entry module, on each execution of its source.

    pythonfmu 0.7 bug worked around here: for every fmi2Instantiate the C wrapper's
    ``findClass`` imports the entry module, executes its source again in the module's namespace
    (``PyModule_GetDict``, a borrowed reference) and then ``Py_DECREF``s that dict. Each
    instantiation thus drops one reference to the module's namespace; after a few instantiations
    in one process it is freed (observed: "module has no attribute ..." on the third fmpy
    simulation of one FMU, then segmentation faults). Each execution of the entry module takes
    one reference back, so the namespace stays alive (the first, ordinary import leaves one extra
    reference: module namespaces live until the process ends anyway)."""
    ctypes.pythonapi.Py_IncRef(ctypes.py_object(namespace))


def _fmi_call(method):
    """Wrap a method that pythonfmu's C wrapper calls: an exception escaping it is logged (with
    fmi2Error status, unless already logged) and re-raised (the wrapper returns fmi2Fatal).

    pythonfmu 0.7 bug worked around here: on a Python exception the wrapper's
    ``handle_py_exception`` calls ``cleanPyObject()``, which ``Py_XDECREF``s its references to the
    slave class, the instance and the instance's log queue without clearing them, and the
    destructor releases them again. Two or three refused ``fmi2SetReal`` calls then free the live
    instance and the host crashes (observed: segmentation fault in fmpy). Before letting an
    exception escape, the slave therefore takes one extra reference to each of those three objects
    (only when the C wrapper created it: it passes the ``logger`` keyword), so the spurious release
    is balanced and the instance stays valid."""

    @functools.wraps(method)
    def call(self, *args, **kwargs):
        try:
            return method(self, *args, **kwargs)
        except Exception as exc:
            if not getattr(exc, "logged", False):
                self.log(f"{method.__name__}: {type(exc).__name__}: {exc}", Fmi2Status.error)
            if self._under_c_wrapper:
                for obj in (self, self.log_queue, type(self)):
                    ctypes.pythonapi.Py_IncRef(ctypes.py_object(obj))
            raise

    return call


class OverconSlave(Fmi2Slave):
    """One FMU instance. The generated entry module subclasses this (model identifier = scene
    name); everything scene specific is read from ``resources``."""

    _under_c_wrapper = False

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self._under_c_wrapper = isinstance(kwargs.get("logger"), int)
        res = Path(self.resources)
        self._manifest = json.loads((res / MANIFEST).read_text(encoding="utf-8"))
        spec = scene_mod.load(res / self._manifest["scene"])
        self._scene = spec
        self._model0 = compile_model(spec)
        self.modelName = spec.name
        self.description = spec.description or None
        self._vars = variables.table(self._model0, self._manifest["reaction_unique"],
                                     self._manifest["motion_unique"])
        self._defaults = {v.key[1]: v.start for v in self._vars if v.key[0] == "param"}
        self._params = dict(self._defaults)
        self._explicit: set[str] = set()
        self._start_time = spec.start_time
        self._setup_tolerance: float | None = None
        self._mode = "instantiated"  # -> "initialization" -> "stepping"
        self._sim: Simulation | None = None
        self._sim_key = None  # parameters the current Simulation was built with
        self._t = spec.start_time
        self._outputs = np.zeros(len(self._model0.output_names()))
        self._have_outputs = False
        self._failed: str | None = None
        for v in self._vars:
            self.register_variable(self._make_var(v), nested=False)

    def log(self, msg: str, status=Fmi2Status.ok, category=None, debug=None):
        """pythonfmu's wrapper passes the message to the host's fmi2CallbackLogger as its printf
        format string, so a literal % is doubled. pythonfmu 0.7 forwards messages (of every
        status) only while debug logging is on (fmi2Instantiate loggingOn, fmi2SetDebugLogging)."""
        super().log(str(msg).replace("%", "%%"), status, category)

    # -- variables ---------------------------------------------------------------------------
    def _make_var(self, v: variables.Var):
        kind, arg = v.key
        if kind == "output":
            getter, setter = (lambda k=arg: self._output(k)), None
        elif kind == "constant":
            getter, setter = (lambda val=arg: val), None
        else:
            getter = lambda name=arg: self._params[name]  # noqa: E731
            setter = lambda value, name=arg: self._set_param(name, value)  # noqa: E731
        return _TYPES[v.type](
            v.name, causality=Fmi2Causality[v.causality], variability=Fmi2Variability[v.variability],
            initial=Fmi2Initial[v.initial], description=v.description, getter=getter, setter=setter)

    def _output(self, k: int) -> float:
        if not self._have_outputs and self._failed is None:
            try:
                self._ensure_sim()
            except Exception as exc:  # reported once; the value stays 0.0 (never NaN)
                self._fail(f"cannot compute the initial outputs: {exc}", Fmi2Status.error)
        return float(self._outputs[k])

    def _set_param(self, name: str, value) -> None:
        if self._mode == "stepping":
            self._refuse(name, value, "variability fixed: it cannot change after initialization "
                                      "(fmi2Reset first)")
        reason = variables.rule(name).check(value)
        if reason is None and name.endswith(".mu_static"):
            mu = self._params[name[: -len("_static")]]
            if value < mu:
                reason = f"must be >= {name[: -len('_static')]} ({mu!r}), got {value!r}"
        if reason is not None:
            self._refuse(name, value, reason)
        self._params[name] = value if isinstance(value, str) else type(self._defaults[name])(value)
        self._explicit.add(name)
        self._drop_sim()

    def _refuse(self, name, value, reason) -> None:
        msg = f"parameter {name} = {value!r} refused: {reason}"
        self.log(msg, Fmi2Status.error)
        exc = ParameterRefused(msg)
        exc.logged = True
        raise exc

    # -- model and simulation ----------------------------------------------------------------
    def _drop_sim(self) -> None:
        """Forget the Simulation (parameters or start time changed before initialization)."""
        self._sim = self._sim_key = None
        self._have_outputs = False
        self._failed = None

    def _key(self):
        tol = self._params["solver.tolerance"]
        if "solver.tolerance" not in self._explicit and self._setup_tolerance is not None:
            tol = self._setup_tolerance
        return (self._start_time, tol, tuple(sorted(self._params.items())))

    def _build_model(self, key):
        start, tol, _ = key
        spec, p = self._scene, self._params
        solver = dataclasses.replace(
            spec.solver, method=p["solver.method"], tolerance=tol, step=p["solver.step"],
            max_step=p["solver.max_step"], baumgarte=p["solver.baumgarte"],
            friction_tol=p["solver.friction_tol"], friction_max_iter=int(p["solver.friction_max_iter"]))
        fparams = dict(spec.friction_params)
        for jname, fspec in spec.friction_params.items():
            changes = {f: p[f"{jname}.{f}"] for f in _FRICTION_FIELDS if f"{jname}.{f}" in p}
            fparams[jname] = dataclasses.replace(fspec, **changes)
            if fparams[jname].mu_static is not None and fparams[jname].mu_static < fparams[jname].mu:
                raise ParameterRefused(f"{jname}.mu_static ({fparams[jname].mu_static!r}) must be >= "
                                       f"{jname}.mu ({fparams[jname].mu!r})")
        stop = spec.stop_time if spec.stop_time > start else start + 1.0  # unused by Simulation
        new = dataclasses.replace(spec, solver=solver, friction_params=fparams, start_time=start,
                                  stop_time=stop)
        if new == spec:
            return self._model0
        return compile_model(new)

    def _ensure_sim(self, compute_outputs: bool = True) -> Simulation:
        key = self._key()
        if self._sim is None or self._sim_key != key:
            self._sim = None
            sim = Simulation(self._build_model(key))
            self._sim, self._sim_key = sim, key
            self._t = key[0]
            self._have_outputs = False
        if compute_outputs and not self._have_outputs:
            y = self._sim.advance(self._t)
            out = self._sim.outputs(self._t, y)
            if not np.all(np.isfinite(out)):
                raise ArithmeticError(f"non-finite initial outputs at t = {self._t:.9g} s")
            self._outputs, self._have_outputs = out, True
        return self._sim

    # -- FMI calls (every method the C wrapper calls is wrapped by _fmi_call) ------------------
    get_real = _fmi_call(Fmi2Slave.get_real)
    get_integer = _fmi_call(Fmi2Slave.get_integer)
    get_boolean = _fmi_call(Fmi2Slave.get_boolean)
    get_string = _fmi_call(Fmi2Slave.get_string)
    set_real = _fmi_call(Fmi2Slave.set_real)
    set_integer = _fmi_call(Fmi2Slave.set_integer)
    set_boolean = _fmi_call(Fmi2Slave.set_boolean)
    set_string = _fmi_call(Fmi2Slave.set_string)
    terminate = _fmi_call(Fmi2Slave.terminate)

    @_fmi_call
    def setup_experiment(self, start_time: float = 0.0, stop_time=None, tolerance=None):
        start = 0.0 if start_time is None else float(start_time)
        if not math.isfinite(start):
            self.log(f"fmi2SetupExperiment: start time {start!r} refused (not finite)", Fmi2Status.error)
            raise ParameterRefused(f"start time {start!r} is not finite")
        self._start_time = start
        if tolerance is not None:
            tol = float(tolerance)
            if 0.0 < tol < 1.0:
                self._setup_tolerance = tol
            else:
                self.log(f"fmi2SetupExperiment: tolerance {tol!r} ignored (must be in (0, 1)); "
                         f"using solver.tolerance = {self._params['solver.tolerance']!r}",
                         Fmi2Status.warning)
        self._drop_sim()

    @_fmi_call
    def enter_initialization_mode(self):
        self._mode = "initialization"

    @_fmi_call
    def exit_initialization_mode(self):
        try:
            self._ensure_sim()
        except Exception as exc:
            self.log(f"initialization failed: {type(exc).__name__}: {exc}", Fmi2Status.error)
            exc.logged = True
            raise
        self._mode = "stepping"

    @_fmi_call
    def do_step(self, current_time: float, step_size: float, no_set_fmu_state_prior=None) -> bool:
        if self._failed is not None:
            self.log(f"do_step refused: an earlier step failed ({self._failed}); set an earlier FMU "
                     "state or reset", Fmi2Status.discard)
            return False
        try:
            if not (math.isfinite(current_time) and math.isfinite(step_size) and step_size >= 0):
                self.log(f"do_step({current_time!r}, {step_size!r}) refused: the step must be finite "
                         "and >= 0", Fmi2Status.discard)
                return False
            sim = self._ensure_sim()
            if abs(current_time - self._t) > 1e-9 * max(1.0, abs(self._t)):
                self.log(f"do_step refused: communication point {current_time!r} s is not the end "
                         f"of the previous step ({self._t!r} s)", Fmi2Status.discard)
                return False
            t_new = current_time + step_size
            y = sim.advance(t_new)
            out = sim.outputs(t_new, y)
            if not np.all(np.isfinite(out)):
                bad = [n for n, v in zip(self._model0.output_names(), out) if not math.isfinite(v)]
                raise ArithmeticError(f"t = {t_new:.9g} s: non-finite outputs {', '.join(bad)}")
        except Exception as exc:  # any engine failure: fmi2Discard, never NaN, never a crash
            return self._fail(f"do_step({current_time!r}, {step_size!r}): "
                              f"{type(exc).__name__}: {exc}", Fmi2Status.discard)
        self._outputs, self._t, self._have_outputs = out, t_new, True
        return True

    def _fail(self, reason: str, status) -> bool:
        self._failed = reason
        self.log(reason, status)
        return False

    # -- FMU state ---------------------------------------------------------------------------
    @_fmi_call
    def _get_fmu_state(self):
        return {
            "guid": self._manifest["guid"],
            "params": dict(self._params), "explicit": sorted(self._explicit),
            "start_time": self._start_time, "setup_tolerance": self._setup_tolerance,
            "mode": self._mode, "t": self._t, "outputs": self._outputs.copy(),
            "have_outputs": self._have_outputs, "failed": self._failed,
            "sim": None if self._sim is None else copy.deepcopy(self._sim.get_state()),
        }

    @_fmi_call
    def _set_fmu_state(self, state):
        if isinstance(state, dict) and "invalid" in state:
            raise ValueError(f"fmi2SetFMUstate: {state['invalid']}")
        if not isinstance(state, dict) or state.get("guid") != self._manifest["guid"]:
            raise ValueError("fmi2SetFMUstate: the state does not belong to this FMU (GUID differs)")
        self._params = dict(state["params"])
        self._explicit = set(state["explicit"])
        self._start_time = state["start_time"]
        self._setup_tolerance = state["setup_tolerance"]
        if state["sim"] is None:
            self._drop_sim()
        else:
            self._ensure_sim(compute_outputs=False).set_state(state["sim"])
        self._mode, self._t = state["mode"], state["t"]
        self._outputs = np.array(state["outputs"], float)
        self._have_outputs, self._failed = state["have_outputs"], state["failed"]

    # Called on the class (no instance to log to or to protect, see _fmi_call): they never raise.
    # A state that cannot be (de)serialized becomes {"invalid": reason}, refused by
    # fmi2SetFMUstate with that reason.
    @staticmethod
    def _fmu_state_to_bytes(state) -> bytes:
        try:
            return statecodec.dumps(state)
        except Exception as exc:
            return statecodec.dumps({"invalid": f"the FMU state could not be serialized: {exc}"})

    @staticmethod
    def _fmu_state_from_bytes(data: bytes):
        try:
            return statecodec.loads(data)
        except Exception as exc:
            return {"invalid": f"the bytes given to fmi2DeSerializeFMUstate are not an FMU state: {exc}"}
