"""The model file of an FMU that runs without Python (``resources/overcon_model.bin``): everything the
C FMI layer (``native/fmi2_*.c`` over the core) needs, written at ``overcon build`` from the
compiled model, the scene's solver settings and the variable table (:mod:`overcon.fmu.variables`).

Why a file of its own: the C FMU cannot read TOML nor compile a mechanism; the packing of
:class:`overcon.kernel.Kernel` (the ``ovk_model`` the core evaluates) is the compiled model, so the
file carries exactly those arrays, with the initial state, the output plan, the variables and the
parameters' rules (:data:`overcon.params.RULES`, with their messages' texts).

Layout (native byte order; int32 ``i``, float64 ``d``; a string is an int32 length including its
terminating zero, then the bytes and the zero; an array an int32 count then the items):

1. ``b"OVKFMU01"``, i format version (:data:`FORMAT`), i the core's ABI (:data:`overcon.kernel.ABI`),
   string GUID;
2. the model: 13 i counts and 2 d (baumgarte, tol) in ``ovk_model`` order, then its 25 arrays
   (int32 or float64 items, in ``ovk_model`` order), then its redundancy block: 5 i counts
   (:data:`overcon.kernel.REDUNDANCY_COUNTS`) and 10 arrays (:data:`overcon.kernel.REDUNDANCY_ARRAYS`),
   then i its formulation (:data:`overcon.kernel.FORMULATIONS`: 0 the eliminated form, 1 the
   augmented Lagrangian solve with step-end projections of ``solver.singular = "pass"``);
   then i the number of other redundancy methods the ``redundancy`` parameter may choose
   (:func:`overcon.fmu.variables.redundancy_methods` but the scene's own), and per method i its
   index in :data:`overcon.spec.REDUNDANCY_METHODS` (``OVK_ELIMINATE`` ...) and its packed model as
   above (the scene compiled under it: :func:`overcon.fmu.variables.with_redundancy`);
3. the run: i n, i nh, i quaternion (1: orientation coordinates are quaternions), d start time,
   d stop time, array d y0;
4. outputs: i count, then per output i kind (:data:`OUT_KINDS`), i a, i b (a position: the index
   into q; a velocity: the index into h; an energy: 0-3 in spec.ENERGY_OUTPUTS order; a reaction: joint
   and component; friction: joint);
5. variables: i count, then per variable string name, i type (:data:`TYPES`), i causality, i
   variability (:data:`VARIABILITIES`), i key kind (:data:`KEYS`), i key argument (the output index,
   the constant 0/1, the parameter index, the index into y = [q, h] of a continuous state or its
   derivative, an array's first output index, :data:`ALONG_ARGS` for the uniqueness along the motion);
6. parameters: i count, then per parameter string name, i type, i target (:data:`TARGETS`), i joint
   (friction parameters), i rule kind (0 real, 1 int, 2 choice), d low, d high, i has low, i has
   high, i low open, string range text, string why, i number of choices then the choices as
   strings, d default (numbers), string default (strings), i tunable;
7. messages logged at fmi2Instantiate: i count, then per message i fmi2Status, string text.
"""
from __future__ import annotations

import struct

import numpy as np

from .. import kernel as kernel_mod
from ..checks import compile_checked
from ..checks import watch_rows as _watch_rows
from ..params import rule_of
from ..spec import REDUNDANCY_METHODS
from .variables import redundancy_methods, redundancy_rule, with_redundancy

FORMAT = 5  # 5: each packed model ends with its inputs (nu, ukind, uidx, up)
MAGIC = b"OVKFMU01"
TYPES = {"Real": 0, "Integer": 1, "Boolean": 2, "String": 3, "Enumeration": 1}  # an Enumeration is an Integer in FMI 2.0's calls
CAUSALITIES = {"output": 0, "parameter": 1, "local": 2, "independent": 3, "input": 4}
VARIABILITIES = {"continuous": 0, "constant": 1, "fixed": 2, "tunable": 3, "discrete": 4}
KEYS = {"output": 0, "constant": 1, "param": 2, "stable_step": 3, "state": 4, "derivative": 5, "array": 6, "time": 7,
        "along": 8, "input": 9}
OUT_KINDS = kernel_mod.OUT_KINDS
TARGETS = {"mu": 1, "v_reg": 2, "mu_static": 3, "v_stribeck": 4, "solver.method": 10, "solver.tolerance": 11,
           "solver.step": 12, "solver.max_step": 13, "solver.baumgarte": 14, "solver.friction_tol": 15,
           "solver.friction_max_iter": 16, "solver.kernel": 17, "solver.max_internal_steps": 18,
           "solver.max_wall_time": 19, "redundancy": 20}
"""What a parameter sets: a friction law's entry of ``jlawp`` (1-4) or a solver setting (10-19)."""
ALONG_ARGS = {"rank": 0, "motion": 1}
"""The argument of a variable of key "along": 0 rank, 1 motion_unique, 2 + j joint j's reaction_unique."""
INT_FIELDS = ("dim", "nb", "nq_b", "nh_b", "m", "nR", "nj", "nl", "nx", "ncols", "nfj", "nfg", "max_iter")
DOUBLE_FIELDS = {"Minv", "mass", "inertia", "gravity", "jconst", "jlawp", "lp"}


class _Out:
    def __init__(self):
        self.parts: list[bytes] = []

    def i(self, *v):
        self.parts.append(struct.pack(f"={len(v)}i", *v))

    def d(self, *v):
        self.parts.append(struct.pack(f"={len(v)}d", *v))

    def s(self, text: str):
        raw = str(text).encode("utf-8") + b"\0"
        self.i(len(raw))
        self.parts.append(raw)

    def ints(self, a):
        a = np.ascontiguousarray(a, dtype=np.int32).reshape(-1)
        self.i(a.size)
        self.parts.append(a.tobytes())

    def doubles(self, a):
        a = np.ascontiguousarray(a, dtype=np.float64).reshape(-1)
        self.i(a.size)
        self.parts.append(a.tobytes())


def _outputs(w: _Out, model) -> None:
    """The output plan in output order (``model.output_names()``; :func:`overcon.kernel.output_plan`)."""
    rows = kernel_mod.output_plan(model)
    w.i(len(rows))
    for r in rows.tolist():
        w.i(*r)


def _redundancy_param(w: _Out, model, var) -> None:
    """The ``redundancy`` parameter as an integer rule [1, number of methods] with the texts of
    :func:`overcon.fmu.variables.redundancy_rule`."""
    known, why = redundancy_rule(model)
    w.s(var.name)
    w.i(TYPES[var.type], TARGETS["redundancy"], -1, 1)
    w.d(1.0, float(len(redundancy_methods(model))))
    w.i(1, 1, 0)
    w.s(known)
    w.s(why)
    w.i(0)
    w.d(float(var.start))
    w.s("")
    w.i(0)


def _param(w: _Out, model, var) -> None:
    name = var.key[1]
    if name == "redundancy":
        return _redundancy_param(w, model, var)
    group, _, field = name.rpartition(".")
    joint = -1
    target = TARGETS.get(name)
    if target is None:
        target = TARGETS[field]
        joint = next(j for j, c in enumerate(model.joints) if c.name == group)
    rule = rule_of(name)
    kind = {"real": 0, "int": 1, "choice": 2}[rule.kind]
    w.s(name)
    w.i(TYPES[var.type], target, joint, kind)
    w.d(rule.low if rule.low is not None else 0.0, rule.high if rule.high is not None else 0.0)
    w.i(rule.low is not None, rule.high is not None, bool(rule.low_open))
    w.s(rule.range_text())
    w.s(rule.why)
    w.i(len(rule.choices))
    for c in rule.choices:
        w.s(c)
    w.d(float(var.start) if not isinstance(var.start, str) else 0.0)
    w.s(var.start if isinstance(var.start, str) else "")
    w.i(var.variability == "tunable")


def watch_rows(model) -> tuple[list[int], list[int]]:
    """(rows watched, rows of the whole rigid Jacobian) of the C run's watch
    (:func:`overcon.checks.watch_rows`)."""
    return _watch_rows(model)


def _packed(w: _Out, k) -> None:
    """The packed model of the Kernel ``k`` (part 2 of the layout)."""
    cm = k._cmodel
    by_address = {a.ctypes.data: a for a in k._keep}
    w.i(*(getattr(cm, n) for n in INT_FIELDS))
    w.d(cm.baumgarte, cm.tol)
    red = set(kernel_mod.REDUNDANCY_COUNTS + kernel_mod.REDUNDANCY_ARRAYS)
    for name, _ in cm._fields_:
        if name in INT_FIELDS or name in ("baumgarte", "tol", "formulation", "nu") or name in red \
                or name in kernel_mod.INPUT_ARRAYS:
            continue
        (w.doubles if name in DOUBLE_FIELDS else w.ints)(by_address[getattr(cm, name)])
    w.i(*(getattr(cm, n) for n in kernel_mod.REDUNDANCY_COUNTS))
    for name in kernel_mod.REDUNDANCY_ARRAYS:
        (w.doubles if name in kernel_mod.REDUNDANCY_DOUBLES else w.ints)(by_address[getattr(cm, name)])
    w.i(cm.formulation)
    w.i(cm.nu)  # the inputs (kernel.INPUT_ARRAYS)
    w.ints(by_address[cm.ukind])
    w.ints(by_address[cm.uidx])
    w.doubles(by_address[cm.up])


def model_file(model, solver, table, guid: str, messages=()) -> bytes:
    """The bytes of ``resources/overcon_model.bin`` (module docstring) for ``model`` with the
    solver settings ``solver``, the variable table ``table`` and the GUID; ``messages``:
    (fmi2Status, text) logged at every fmi2Instantiate (the pre-check's warnings)."""
    lib, reason = kernel_mod.library()
    if lib is None:
        raise RuntimeError(f"the C FMU needs the compiled core: {reason}")
    w = _Out()
    w.parts.append(MAGIC)
    w.i(FORMAT, kernel_mod.ABI)
    w.s(guid)
    _packed(w, kernel_mod.Kernel(lib, model, solver, watch_rows(model)))
    others = [m for m in redundancy_methods(model) if m != model.scene.redundancy]
    w.i(len(others))
    for method in others:  # the models of the redundancy parameter's other values
        w.i(REDUNDANCY_METHODS.index(method))
        other = compile_checked(with_redundancy(model.scene, method))
        _packed(w, kernel_mod.Kernel(lib, other, solver, watch_rows(other)))
    w.i(model.n, model.nh, int(model.rotation == "quaternion"))
    w.d(model.scene.start_time, model.scene.stop_time)
    w.doubles(np.concatenate([model.q0, model.h0]))
    _outputs(w, model)
    params = [v for v in table if v.key[0] == "param"]
    index = {v.key[1]: n for n, v in enumerate(params)}
    w.i(len(table))
    for v in table:
        kind, arg = v.key
        a = (arg if kind in ("output", "state", "derivative", "array", "input") else int(bool(arg)) if kind == "constant"
             else index[arg] if kind == "param"
             else (ALONG_ARGS[arg] if arg in ALONG_ARGS else 2 + arg) if kind == "along" else 0)
        w.s(v.name)
        w.i(TYPES[v.type], CAUSALITIES[v.causality], VARIABILITIES[v.variability], KEYS[kind], a)
    w.i(len(params))
    for v in params:
        _param(w, model, v)
    w.i(len(messages))
    for status, text in messages:
        w.i(int(status))
        w.s(text)
    return b"".join(w.parts)
