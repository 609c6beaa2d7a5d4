"""The compiled core, the project's one engine (the stage files in ``core/`` next to this file,
see ``core/core.h``), called through ctypes: an evaluation of Eq. 18, the joint rows, the
reported outputs, the uniqueness rule, the projections (:class:`Kernel`), and whole runs with
their integrators, watch and ledgers (:class:`Run`, core/sim.c), which ``overcon simulate`` and
the FMUs run.

Why ctypes (decided here): the core's interface is a handful of C functions over flat arrays,
called once per run (a whole output grid: :meth:`Run.grid`) or per point asked for, not per
arithmetic operation; ctypes needs no
compiler beyond the core's own build and no CPython ABI, so one ``libovercore`` serves every
Python version, and the FMU binaries load the same sources without Python.

What it covers (:func:`support`): planar mechanisms of revolute and translational joints, spatial
mechanisms with z-x-z Euler angles or quaternions and every spatial joint type (spherical,
revolute, prismatic, cylindrical, universal, fixed); gravity, forces, torques, springs; friction laws ``regularised`` and
``stribeck``; any number of friction joints (the friction solve's buffers are in the workspace,
sized from the model); every redundancy method of
:data:`overcon.spec.REDUNDANCY_METHODS` (``min-norm``: core/kkt_minnorm.c; ``compliant``:
core/compliance.c, packed by :func:`_redundancy_block`). A model outside that is refused with
the reason. Every failure of the core is a status (:data:`STATUS`) with a message
(:attr:`Kernel.last_message`).

The solver setting ``kernel`` (scene ``[solver] kernel``, ``--kernel``) stays accepted for the
scripts that set it: ``"auto"`` and ``"c"`` run the core, ``"numpy"`` is a deprecated alias that
warns and runs the core (the numpy evaluation path is retired).

Where the library comes from: the package installation compiles it (``setup.py``: ``pip install
-e .`` or ``pip install .``, about 1 s of the install) into :data:`LIBRARY`,
``overcon/core/libovercore.so`` (``.dylib``, ``.dll``), with ``$CC`` (default: the compiler Python
was built with) and the flags ``-O2 -ffp-contract=off -fno-fast-math -std=c11 -Wall -Wextra
-Werror``: no fused multiply-add contraction and no reassociation, so the numbers do not depend
on the CPU's FMA support. Nothing is compiled at run time. A source tree that was never installed
has no library: a run refuses to start, naming the fix (``pip install -e .``). An FMU does not load it: its binary is the core compiled with the FMI layer
(:mod:`overcon.fmu.build`).

One :class:`Kernel` per model and instance: it owns the core's workspace (``ovk_data``), so two
instances in one process, or in two threads, never share memory.
"""
from __future__ import annotations

import ctypes
import platform
import weakref
from pathlib import Path

import numpy as np

ABI = 11  # OVK_ABI in core/core.h: the layout of _CModel and the entry points' signatures

STATUS = {0: "ok", 1: "singular position (S not positive definite)", 2: "friction Newton solve gave up",
          3: "Euler angles singular", 4: "non-finite number", 5: "spring points coincide", 6: "out of memory",
          7: "invalid model or argument", 8: "step size too small", 9: "stiffness detected",
          10: "rk4 step unstable", 11: "work budget exhausted", 12: "singular position (monitor)",
          13: "time does not advance", 14: "elimination expired where it decides the motion",
          15: "projection onto the constraints did not converge"}
FORMULATIONS = {"stop": 0, "pass": 1}
"""``solver.singular`` -> ``ovk_model.formulation``: the eliminated form's Cholesky of S (kkt.c), or
the augmented Lagrangian solve of the kept rows with step-end projections (kkt_al.c, project.c)."""
PROJECTION_TOL = 1e-11  # m or rad: OVK_PROJ_TOL of core/core.h, the step-end projection's max |Phi|
PROJECTION_MAX_ITER = 20  # OVK_PROJ_MAX_ITER of core/core.h: its position corrections at most
PROJECTION_SLACK = 10.0  # OVK_PROJ_SLACK of core/core.h: near a singular position, where the corrections
# converge linearly, max |Phi| up to this times PROJECTION_TOL once a correction no longer halves it

_JOINTS = {("planar", "revolute"): 1, ("planar", "translational"): 2, ("spatial", "spherical"): 3,
           ("spatial", "spatial_revolute"): 4, ("spatial", "spatial_prismatic"): 5,
           ("spatial", "spatial_cylindrical"): 6, ("spatial", "spatial_universal"): 7, ("spatial", "spatial_fixed"): 8,
           ("planar", "driver"): 9, ("spatial", "driver"): 9,
           ("planar", "distance"): 10, ("spatial", "spatial_distance"): 10,
           ("planar", "point_on_line"): 11, ("spatial", "spatial_point_on_line"): 11}
_ROTATIONS = ("euler_zxz", "quaternion")
_AXIS_SIZES = {"spatial_revolute": ("radius", "length", "collar_radius"), "spatial_prismatic": ("length", "radius"),
               "spatial_cylindrical": ("length", "radius")}
"""Friction sizes of the spatial axis joints in jconst[30:33] (the order of their modules' ``stack``)."""
_LAWS = {"regularised": 1, "stribeck": 2}
_LOADS = {"force": 1, "torque": 2, "spring": 3}
NJC, NLP, NLD = 34, 5, 11  # doubles per joint, per friction law, per load (core/core.h)
MAXEQ, NREAC = 6, 9  # OVK_MAXEQ (equations per joint), OVK_NREAC (reported reaction entries per joint)


def _shared_suffix() -> str:
    return ".dll" if platform.system() == "Windows" else ".dylib" if platform.system() == "Darwin" else ".so"


LIBRARY = Path(__file__).resolve().parent / "core" / f"libovercore{_shared_suffix()}"
"""The compiled core, built by the package installation (setup.py) next to its sources."""


class KernelUnavailable(RuntimeError):
    """The compiled core cannot run here or cannot run this model (the message says why)."""

    def __init__(self, reason: str, setting: str = "the compiled core"):
        super().__init__(f"{setting}: {reason}")


# ----------------------------------------------------------------------------- the library

_state: dict = {"lib": None, "reason": None, "path": None, "tried": False}


def _bind(path: Path) -> ctypes.CDLL:
    lib = ctypes.CDLL(str(path))
    if lib.ovk_abi() != ABI:
        raise OSError(f"{path}: core ABI {lib.ovk_abi()}, expected {ABI} (a library of another overcon version)")
    vp, i = ctypes.c_void_p, ctypes.c_int
    for name, res, args in (("ovk_make_data", vp, [vp]), ("ovk_free_data", None, [vp]),
                            ("ovk_message", ctypes.c_char_p, [vp]), ("ovk_data_status", i, [vp]),
                            ("ovk_evaluate", i, [vp, vp, ctypes.c_double, vp, i, vp, vp, vp, vp, vp, vp]),
                            ("ovk_outputs", i, [vp] * 6), ("ovk_rows", i, [vp] * 6),
                            ("ovk_rows_sparse", i, [vp] * 6),
                            ("ovk_evaluate_robust", i, [vp] * 8),
                            ("ovk_project", i, [vp, vp, ctypes.c_double, vp, ctypes.c_double, i, vp]),
                            ("ovk_sim_new", vp, [vp, vp, ctypes.c_double, vp]), ("ovk_sim_free", None, [vp]),
                            ("ovk_sim_status", i, [vp]), ("ovk_sim_message", ctypes.c_char_p, [vp]),
                            ("ovk_sim_step", i, [vp]),
                            ("ovk_sim_advance", i, [vp, ctypes.c_double, ctypes.c_longlong, ctypes.c_double, vp]),
                            ("ovk_sim_state_vector", None, [vp, vp]), ("ovk_sim_info", None, [vp, vp]),
                            ("ovk_sim_outputs", i, [vp, ctypes.c_double, vp, vp, vp]),
                            ("ovk_sim_energy", i, [vp, ctypes.c_double, vp, vp]),
                            ("ovk_sim_output_row", i, [vp, vp, i, ctypes.c_double, vp, vp]),
                            ("ovk_sim_grid", i, [vp, vp, i, vp, ctypes.c_longlong, vp, vp]),
                            ("ovk_sim_state_size", ctypes.c_size_t, [vp]),
                            ("ovk_sim_get_state", i, [vp, vp, ctypes.c_size_t]),
                            ("ovk_sim_set_state", i, [vp, vp, ctypes.c_size_t]),
                            ("ovk_unique", i, [vp] * 5), ("ovk_sim_uniqueness", i, [vp] * 3),
                            ("ovk_sim_events", i, [vp]),
                            ("ovk_sim_event", ctypes.c_char_p, [vp, i, vp, vp]),
                            ("ovk_pack_kept", i, [vp, vp, i, vp, vp, vp, vp]),
                            ("ovk_sim_watch_extremes", i, [vp, vp, i, vp]),
                            ("ovk_band_svd", i, [vp, i, i, i, ctypes.c_double, vp, vp]),
                            ("ovk_law_eval", i, [vp, i, ctypes.c_double, vp, vp]),
                            ("ovk_friction_joint_at", i, [vp, vp, vp, i, vp, vp, vp]),
                            ("ovk_set_inputs", i, [vp, vp, vp, vp, ctypes.c_double]),
                            ("ovk_sensors", i, [vp, vp, vp, vp, i, vp]),
                            ("ovk_sim_set_inputs", i, [vp, vp, vp]),
                            ("ovk_set_time", i, [vp, ctypes.c_double]), ("ovk_phi_t", i, [vp, vp, vp])):
        f = getattr(lib, name)
        f.restype, f.argtypes = res, args
    return lib


def disable(reason: str) -> None:
    """No compiled core in this process (runs refuse to start; ``reason`` is reported)."""
    _state.update(lib=None, reason=reason, path=None, tried=True)


def library_path() -> str | None:
    """The path of the core loaded in this process (None before :func:`library` found one)."""
    return _state["path"]


def library():
    """(the loaded core library or None, the reason it is None): :data:`LIBRARY`, the one the
    package installation compiled (unless :func:`disable` said otherwise)."""
    if not _state["tried"]:
        _state["tried"] = True
        if not LIBRARY.exists():
            _state["reason"] = (f"the compiled core {LIBRARY} is missing (a source tree that was never built): "
                                "run `pip install -e .` in the project directory, which compiles it")
        else:
            try:
                _state["lib"], _state["path"] = _bind(LIBRARY), str(LIBRARY)
            except OSError as exc:
                _state["reason"] = (f"cannot load {LIBRARY}: {exc}; `pip install -e .` in the project directory "
                                    "compiles it again")
    return _state["lib"], _state["reason"]


# ----------------------------------------------------------------------------- the model

def support(model) -> str | None:
    """None if the kernel covers ``model``, else the reason it does not."""
    from .joints import TYPES

    if model.kind == "spatial" and model.rotation not in _ROTATIONS:
        return f"rotation {model.rotation!r} (the kernel has z-x-z Euler angles and quaternions)"
    for c in model.joints:
        if (model.kind, c.type) not in _JOINTS:
            covered = ", ".join(TYPES[t].name for k, t in _JOINTS if k == model.kind)
            return (f"joint {c.name}: {model.kind} {TYPES[c.type].name} joints are not covered by the compiled "
                    f"kernel (it has {model.kind} {covered})")
        if c.law is not None and c.law.name not in _LAWS:
            return f"joint {c.name}: friction law {c.law.name!r} (the kernel has regularised and stribeck)"
    for ld in model.loads:
        if ld.type not in _LOADS:
            return f"load type {ld.type!r}"
    return None


REDUNDANCY_COUNTS = ("redundancy", "nrig", "nax", "nwatch", "nfull")
REDUNDANCY_ARRAYS = ("ckind", "ck", "cd", "rigpos", "rigrows", "rigbody", "axi", "axp", "watch", "full")
"""The redundancy block at the end of ``ovk_model`` (core/core.h), in its order."""
REDUNDANCY_DOUBLES = {"ck", "cd", "axp"}
INPUT_ARRAYS = ("ukind", "uidx", "up")
"""The inputs block at the end of ``ovk_model`` (core/core.h, core/inputs.c), after ``nu``."""
NUP = 8  # OVK_NUP: doubles per input (direction 3, point 3, frame, start)


def input_block(model) -> dict:
    """The inputs of ``model`` (:class:`overcon.model.CompiledInput`) as the core's arrays."""
    return {"nu": len(model.inputs), "ukind": [u.kind for u in model.inputs],
            "uidx": [(u.joint, u.bi, u.bj) for u in model.inputs],
            "up": [(*u.direction, *u.point, float(u.frame), u.start) for u in model.inputs]}


class _CModel(ctypes.Structure):
    """``ovk_model`` of core/core.h (same order)."""
    _fields_ = ([(n, ctypes.c_int) for n in ("dim", "nb", "nq_b", "nh_b", "m", "nR", "nj", "nl", "nx", "ncols",
                                             "nfj", "nfg", "max_iter")]
                + [("baumgarte", ctypes.c_double), ("tol", ctypes.c_double)]
                + [(n, ctypes.c_void_p) for n in ("retained", "Minv", "mass", "inertia", "gravity", "jtype", "jbi",
                                                  "jbj", "jneq", "jrows", "jconst", "jlaw", "jlawp", "ltype", "lbi",
                                                  "lbj", "lp", "xrows", "cols", "fj", "fgroup", "fx", "fci", "fcj",
                                                  "rbody")]
                + [(n, ctypes.c_int) for n in REDUNDANCY_COUNTS]
                + [(n, ctypes.c_void_p) for n in REDUNDANCY_ARRAYS]
                + [("formulation", ctypes.c_int)]
                + [("nu", ctypes.c_int)] + [(n, ctypes.c_void_p) for n in INPUT_ARRAYS])


_REDUNDANCY = {"eliminate": 0, "min-norm": 1, "compliant": 2}
"""OVK_ELIMINATE, OVK_MIN_NORM, OVK_COMPLIANT of core/core.h, by overcon.spec.REDUNDANCY_METHODS."""


def _redundancy_block(model, watch=None) -> dict:
    """The redundancy block of ``ovk_model`` (core/core.h): the method, and for "compliant" the
    compliant rows' kinds and scalar values (:func:`overcon.model._compliance`), the rigid rows
    the eliminated solve keeps (positions in ``retained``, equations, bodies) and the per-axis
    joints (:class:`overcon.model.AxisCompliance`: bodies, row counts, retained positions; frame,
    k_t, d_t, k_r, d_r); for both methods the rows of the singularity watch of a run in C,
    ``watch`` = (rows watched, rows of the whole rigid Jacobian), chosen above this layer
    (:func:`overcon.fmu.cmodel.watch_rows`); without them (an evaluation only) the counts are -1
    and core/sim.c refuses to start a run. Arrays as lists; the keys are the field names."""
    method = "min-norm" if model.elimination_mode == "min-norm" else "compliant" if model.compliant_rows.size \
        else "eliminate"
    out = {"redundancy": _REDUNDANCY[method], "nrig": 0, "nax": 0, "nwatch": 0, "nfull": 0}
    if method == "eliminate":
        return out
    if watch is None:
        out.update(nwatch=-1, nfull=-1)
    else:
        out.update(nwatch=len(watch[0]), nfull=len(watch[1]), watch=list(watch[0]), full=list(watch[1]))
    if method != "compliant":
        return out
    R = [int(r) for r in model.retained]
    pos = {r: p for p, r in enumerate(R)}
    kind = np.zeros(len(R), int)
    kind[[pos[int(r)] for r in model.compliant_rows if int(r) in pos]] = 1
    bodies = {r: (c.bi, c.bj) for c in model.joints for r in c.rows}
    axi, axp = [], []
    for ax in model.compliance_axes:
        t = [pos[r] for r in ax.t_rows]
        r_ = [pos[r] for r in ax.r_rows]
        kind[t + r_] = 2
        axi.append([ax.bi, ax.bj, len(t), len(r_)] + (t + [-1] * 3)[:3] + (r_ + [-1] * 3)[:3])
        axp.append(np.concatenate([np.asarray(ax.frame, float).reshape(-1), ax.k_t, ax.d_t, ax.k_r, ax.d_r]))
    rig = [p for p in range(len(R)) if kind[p] == 0]
    out.update(nrig=len(rig), nax=len(axi), ckind=list(kind), ck=model.row_stiffness, cd=model.row_damping,
               rigpos=rig, rigrows=[R[p] for p in rig], rigbody=[bodies[R[p]] for p in rig], axi=axi, axp=axp)
    return out


def _joint_constants(model, c) -> np.ndarray:
    out = np.zeros(NJC)
    p = c.p
    if c.type == "driver":  # core/drivers.c: the layout ([8], the coordinate at q0, set by Kernel)
        out[0], out[1], out[2] = p["joint"], p["coordinate"], p["motion"]
        params = list(p["params"]) + ([p["start_time"]] if p["motion"] == 1 else [])
        out[3:3 + len(params)] = params
    elif c.type in ("distance", "spatial_distance"):  # core/joints_distance.c: s_i, s_j at 0 and 3, L at 6
        k = model.dim
        out[0:k], out[3:3 + k], out[6] = p["s_i"], p["s_j"], p["length"]
    elif c.type == "point_on_line":  # core/joints_planar.c: s_i, s_j, n_j, a_j
        out[0:2], out[2:4], out[4:6], out[6:8] = p["s_i"], p["s_j"], p["n_j"], p["a_j"]
    elif c.type == "spatial_point_on_line":  # core/joints_spatial.c: s_i, s_j, a_j, b1_j, b2_j at their places
        out[0:3], out[3:6], out[9:12], out[12:15], out[15:18] = p["s_i"], p["s_j"], p["a_j"], p["b1_j"], p["b2_j"]
    elif c.type == "translational":
        out[0:2], out[2:4], out[4:6] = p["s_A"], p["s_B"], p["v"]
        out[6] = p["psi"]
        out[7:11] = np.asarray(p["B"], float).reshape(-1)
    elif c.type.startswith("spatial_"):  # core/joints_spatial.c: the layout
        for n, key in enumerate(("s_i", "s_j", "a_i", "a_j", "b1_j", "b2_j", "c_i")):
            out[3 * n:3 * n + 3] = p[key]
        out[21:30] = np.asarray(p["E"], float).reshape(-1)
        if c.law is not None:
            for n, key in enumerate(_AXIS_SIZES.get(c.type, ())):
                out[30 + n] = c.law.size_of(key)
    else:
        k = model.dim
        out[0:k], out[k:2 * k] = p["s_i"], p["s_j"]
    return out


def _law_constants(law) -> np.ndarray:
    if law is None:
        return np.zeros(NLP)
    return np.array([law.mu, law.v_reg, law.size if law.size is not None else 0.0, law.mu_static if law.mu_static is not None else 0.0,
                     law.v_stribeck if law.v_stribeck is not None else 1.0])


def _load_constants(ld) -> np.ndarray:
    out = np.zeros(NLD)
    if ld.value is not None:
        v = np.atleast_1d(np.asarray(ld.value, float))
        out[: len(v)] = v
    if ld.s_i is not None:
        out[3:3 + len(ld.s_i)] = ld.s_i
    if ld.s_j is not None:
        out[6:6 + len(ld.s_j)] = ld.s_j
    out[9], out[10] = ld.stiffness, ld.free_length
    return out


def _pack_redundancy(m: _CModel, red: dict, arr) -> None:
    """The redundancy block ``red`` (:func:`_redundancy_block`) into ``m``; ``arr`` keeps each array."""
    for name in REDUNDANCY_COUNTS:
        setattr(m, name, red[name])
    for name in REDUNDANCY_ARRAYS:
        setattr(m, name, arr(red.get(name, ()), float if name in REDUNDANCY_DOUBLES else np.int32))


def _joint_rows(joints) -> np.ndarray:
    """(joints, MAXEQ) the equation rows of each joint, padded with -1."""
    rows = np.full((len(joints), MAXEQ), -1)
    for n, c in enumerate(joints):
        rows[n, :len(c.rows)] = c.rows
    return rows


def _friction_packing(plan, nh_b: int) -> tuple:
    """(fj, fgroup, fci, fcj) of the packed model: the friction joints group by group, the groups'
    bounds in it, and each joint's friction columns of its two bodies (6 a row, padded with the
    number of friction columns)."""
    fj = [j for g in plan.friction for j in g.joints]
    fgroup = np.cumsum([0] + [len(g.joints) for g in plan.friction])

    def pad_cols(a):
        out = np.full((len(a), 6), len(plan.friction_cols))
        out[:, :nh_b] = a
        return out

    fci = np.concatenate([pad_cols(g.col_i) for g in plan.friction]) if plan.friction else np.zeros((0, 6))
    fcj = np.concatenate([pad_cols(g.col_j) for g in plan.friction]) if plan.friction else np.zeros((0, 6))
    return fj, fgroup, fci, fcj


class Kernel:
    """The kernel bound to one model and solver settings: packed arrays, the core's workspace
    (``ovk_data``: one per instance, so instances never share memory) and output buffers made
    once. :meth:`evaluate` returns (y', lam, qf, friction iterations) or None when the core
    returned a status (kept in :attr:`last_status`, the core's message in :attr:`last_message`)."""

    def __init__(self, lib, model, solver, watch=None, rows_only: bool = False):
        # watch: see _redundancy_block (a C run's); rows_only: the rows are all it is for (a law
        # the core cannot integrate, coulomb, is then packed as none: the rows do not read it)
        self.model, self._fn, self._out_fn, self._msg_fn = model, lib.ovk_evaluate, lib.ovk_outputs, lib.ovk_message
        self._rows_fn, self._project_fn = lib.ovk_rows, lib.ovk_project
        self._lib_unique = lib.ovk_unique
        self._lib_robust = lib.ovk_evaluate_robust
        self._lib = lib
        plan = model.plan
        I32 = np.int32
        keep = self._keep = []

        def arr(a, dtype):
            a = np.ascontiguousarray(np.asarray(a, dtype).reshape(-1))
            if a.size == 0:
                a = np.zeros(1, dtype)
            keep.append(a)
            return a.ctypes.data

        joints = model.joints
        rows = _joint_rows(joints)
        fj, fgroup, fci, fcj = _friction_packing(plan, model.nh_b)
        m = _CModel(dim=model.dim, nb=model.nb, nq_b=model.nq_b, nh_b=model.nh_b, m=model.m, nR=len(model.retained),
                    nj=len(joints), nl=len(model.loads), nx=0, ncols=len(plan.friction_cols),
                    nfj=len(fj), nfg=len(plan.friction), max_iter=solver.friction_max_iter,
                    baumgarte=solver.baumgarte, tol=solver.friction_tol,
                    formulation=FORMULATIONS[getattr(solver, "singular", "stop")])
        m.retained = arr(model.retained, I32)
        m.Minv, m.mass = arr(model.Minv, float), arr(model.mass, float)
        m.inertia = arr(model.inertia if model.kind == "spatial" else np.zeros((model.nb, 3)), float)
        m.gravity = arr(model.gravity, float)
        m.jtype = arr([_JOINTS[(model.kind, c.type)] for c in joints], I32)
        m.jbi, m.jbj = arr([c.bi for c in joints], I32), arr([c.bj for c in joints], I32)
        m.jneq, m.jrows = arr([len(c.rows) for c in joints], I32), arr(rows, I32)
        jconst = np.array([_joint_constants(model, c) for c in joints], float).reshape(-1, NJC)
        m.jconst = arr(jconst, float)
        jconst = keep[-1]  # the packed copy the core reads (a driver's reference is written into it below)
        m.jlaw = arr([0 if c.law is None else _LAWS.get(c.law.name, 0) if rows_only else _LAWS[c.law.name]
                      for c in joints], I32)
        m.jlawp = arr([_law_constants(c.law) for c in joints], float)
        m.ltype = arr([_LOADS[ld.type] for ld in model.loads], I32)
        m.lbi, m.lbj = arr([ld.bi for ld in model.loads], I32), arr([ld.bj for ld in model.loads], I32)
        m.lp = arr([_load_constants(ld) for ld in model.loads], float)
        m.cols = arr(plan.friction_cols, I32)
        m.fj, m.fgroup = arr(fj, I32), arr(fgroup, I32)
        self._friction_plan = tuple(int(j) for j in fj)  # the friction joints in the core's plan order
        m.fci, m.fcj = arr(fci, I32), arr(fcj, I32)
        xrows, fx, rbody = self._pack_kept(lib, m, model.retained)
        m.xrows, m.fx, m.rbody = arr(xrows, I32), arr(fx, I32), arr(rbody, I32)
        _pack_redundancy(m, _redundancy_block(model, watch), arr)
        ub = input_block(model)
        m.nu = ub["nu"]
        m.ukind, m.uidx, m.up = arr(ub["ukind"], I32), arr(ub["uidx"], I32), arr(ub["up"], float)
        self._cmodel = m
        self._pm = ctypes.addressof(m)
        self._data = self._workspace(lib)
        lib.ovk_set_time(self._data, float(model.scene.start_time))  # the drivers' equations at the start
        self._make_buffers(model)
        self._set_driver_references(jconst)

    def _make_buffers(self, model) -> None:
        """The state, output and guess buffers the core writes into, made once, and the pointers
        to them that every call passes."""
        plan, joints = model.plan, model.joints
        n_y = model.n + model.nh
        self._y = np.zeros(n_y)
        self._ydot = np.zeros(n_y)
        self._lam = np.zeros(model.m)
        self._qf = np.zeros(max(1, len(plan.friction_cols)))
        self._guess_qf = np.zeros(max(1, len(plan.friction_cols)))
        self._guess_lam = np.zeros(model.m)
        self._its = ctypes.c_int(0)
        self._damped = ctypes.c_int(0)
        self._ptrs = (self._y.ctypes.data, self._ydot.ctypes.data, self._lam.ctypes.data, self._qf.ctypes.data,
                      ctypes.addressof(self._its), self._guess_qf.ctypes.data, self._guess_lam.ctypes.data,
                      ctypes.addressof(self._damped))
        self._ncols = len(plan.friction_cols)
        self.last_status = 0
        self._reac = np.zeros((len(joints), NREAC))
        self._fric = np.zeros(len(joints))
        self._lam_in = np.zeros(model.m)
        self._out_ptrs = (self._lam_in.ctypes.data, self._reac.ctypes.data, self._fric.ctypes.data)

    def _set_driver_references(self, jconst) -> None:
        """Writes each driver's reference into the packed joint constants ``jconst`` the core reads."""
        model = self.model
        y0 = np.concatenate([model.q0, model.h0])
        for c in model.joints:  # a driver's reference: its coordinate's raw value at q0 (core/inputs.c ovk_sensors)
            if c.type == "driver" and not (model.dim == 3 and c.p["coordinate"] == 0):
                raw = self.sensors(y0, None, c.p["joint"])
                jconst[c.index * NJC + 8] = raw[0] if c.p["coordinate"] == 0 else raw[2]

    @staticmethod
    def _pack_kept(lib, m, retained) -> tuple:
        """(xrows, fx, rbody) of the kept equations ``retained`` of the packed model ``m`` (whose
        other fields are set; ``m.nx`` is set here), from the core's packing (core/unique.c
        ovk_pack_kept), which a run in C uses again when it chooses the kept equations anew."""
        n_r, n_f = len(retained), m.nfj
        xrows, fx = np.zeros(MAXEQ * n_f + 1, np.int32), np.zeros(MAXEQ * n_f + 1, np.int32)
        rbody, iwork = np.zeros(2 * n_r + 1, np.int32), np.zeros(m.m + n_r + 1, np.int32)
        kept = np.ascontiguousarray(retained, np.int32)
        m.nx = lib.ovk_pack_kept(ctypes.addressof(m), kept.ctypes.data, n_r, xrows.ctypes.data, fx.ctypes.data,
                                 rbody.ctypes.data, iwork.ctypes.data)
        return xrows[: m.nx], fx[: MAXEQ * n_f], rbody[: 2 * n_r]

    def _workspace(self, lib) -> int:
        """The core's workspace for the packed model, freed with this object; raises when the
        core refuses the model (its message says why) or cannot allocate it."""
        data = lib.ovk_make_data(self._pm)
        if not data:
            raise MemoryError("the compiled core could not allocate its workspace")
        self._finalize = weakref.finalize(self, lib.ovk_free_data, data)
        self._data = data
        status = lib.ovk_data_status(data)
        if status:
            raise RuntimeError(f"the compiled core refused the packed model ({STATUS.get(status, status)}): "
                               f"{self._message()}")
        return data

    def _message(self) -> str:
        return self._msg_fn(self._data).decode("utf-8", "replace")

    @property
    def last_message(self) -> str:
        """The core's message for the last call's status (empty after a success), e.g. which
        body's Euler angles are singular or how many force evaluations the friction solve took."""
        return self._message() if self.last_status else ""

    @property
    def damped(self) -> bool:
        """The last call's undamped Newton solve gave up and the damped one ran."""
        return bool(self._damped.value)

    def newton_failed(self) -> int:
        """The force evaluations of the last call's Newton solves (undamped and damped) if their
        giving up is why it returned None (status 2), else 0 (for
        :meth:`evaluate_robust`: the fixed-point fallback starts)."""
        return self._its.value if self.last_status == 2 else 0

    def evaluate(self, t: float, y: np.ndarray, lam_guess=None, qf_guess=None):
        """(y' (n + nh,), lam (m,), qf (ncols,), iterations) at (t, y), warm-started from the
        friction forces qf_guess, else the multipliers lam_guess; None when the core returned a
        status (in :attr:`last_status`; status 2: :meth:`evaluate_robust` finishes it)."""
        py, pyd, plam, pqf, pits, pgq, pgl, pdamped = self._ptrs
        self._y[:] = y
        if qf_guess is not None and self._ncols:
            self._guess_qf[: self._ncols] = qf_guess
            mode, pg = 1, pgq
        elif lam_guess is not None:
            self._guess_lam[:] = lam_guess
            mode, pg = 2, pgl
        else:
            mode, pg = 0, pgq
        status = self._fn(self._pm, self._data, t, py, mode, pg, pyd, plam, pqf, pits, pdamped)
        self.last_status = status
        if status:
            return None
        return self._ydot.copy(), self._lam.copy(), self._qf[: self._ncols].copy(), self._its.value

    def evaluate_robust(self, y: np.ndarray, lam_guess=None):
        """The last :meth:`evaluate` at this ``y`` returned None with status 2 (Newton and damped
        Newton gave up): finish it by the core's robust path (core/friction_robust.c: the fixed
        point, then Newton with a finite-difference Jacobian, started from ``lam_guess``), as a
        run in C does. (y', lam, qf, its) or None (status in :attr:`last_status`)."""
        py, pyd, plam, pqf, pits = self._ptrs[:5]
        self._y[:] = y
        start = None
        if lam_guess is not None:
            self._guess_lam[:] = lam_guess
            start = self._ptrs[6]
        status = self._lib_robust(self._pm, self._data, py, start, pyd, plam, pqf, pits)
        self.last_status = status
        if status:
            return None
        return self._ydot.copy(), self._lam.copy(), self._qf[: self._ncols].copy(), self._its.value

    def outputs(self, y: np.ndarray, lam: np.ndarray):
        """(reactions (nj, 9), friction outputs (nj,)) at y and the multipliers lam (m,), every
        joint in model order: the reaction components of the joint type (planar Fx, Fy, T;
        spherical Fx, Fy, Fz in the auxiliary frame; an axis joint its components in the joint
        frame) then the force in the global frame (dim),
        zeros after; the friction output of a joint with friction (else 0) (core/outputs.c). Views of buffers overwritten by the next call."""
        plam, preac, pfric = self._out_ptrs
        self._y[:] = y
        self._lam_in[:] = lam
        status = self._out_fn(self._pm, self._data, self._ptrs[0], plam, preac, pfric)
        if status:
            raise RuntimeError(f"the compiled core's outputs failed ({STATUS.get(status, status)}): {self._message()}")
        return self._reac, self._fric

    def friction_joint_at(self, y: np.ndarray, j: int, lam: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(Q, dQ) of the friction joint ``j`` (an index of ``model.joints`` with a law) at y and its
        multipliers ``lam`` (its equations; core/api.c ovk_friction_joint_at): Q = [Qi, Qj] (2 nh_b,
        the generalized forces on body i and body j), dQ = dQ/dlam (2 nh_b, neq), the Jacobian the
        friction solve's Newton uses (analytic; the spatial axis types' by differences) (new arrays)."""
        if j not in self._friction_plan:
            raise ValueError(f"friction_joint_at: joint {j} has no friction law in this model")
        n = self._friction_plan.index(j)
        yy = np.ascontiguousarray(y, float)
        lam = np.ascontiguousarray(lam, float)
        neq = len(self.model.joints[j].rows)
        ny = self.model.n + self.model.nh
        if lam.shape != (neq,) or yy.shape != (ny,):
            raise ValueError(f"friction_joint_at: lam of shape {lam.shape} and y of shape {yy.shape}; joint {j} "
                             f"has {neq} equations and the state {ny} entries")
        kh = self.model.nh_b
        Q, dQ = np.zeros(2 * kh), np.zeros((2 * kh, lam.size))
        status = self._lib.ovk_friction_joint_at(self._pm, self._data, yy.ctypes.data, int(n), lam.ctypes.data,
                                                 Q.ctypes.data, dQ.ctypes.data)
        if status:
            raise RuntimeError(f"the compiled core's friction_joint_at failed ({STATUS.get(status, status)}): "
                               f"{self._message()}")
        return Q, dQ

    def set_inputs(self, t: float, values, slopes=None) -> None:
        """The inputs' values at t (model.inputs order; N, N.m) and slopes (per s; None: held) for
        the evaluations that follow (core/inputs.c)."""
        u, du = _input_arrays(self.model, values, slopes)
        status = self._lib.ovk_set_inputs(self._pm, self._data, u.ctypes.data,
                                          None if du is None else du.ctypes.data, float(t))
        if status:
            raise ValueError(f"inputs: {self._message()}")

    def sensors(self, y: np.ndarray, y0: np.ndarray, j: int) -> np.ndarray:
        """Joint j's [angle (rad), rate (rad/s), displacement (m), speed (m/s)] at y from their
        values at y0 (None: the raw values) (core/inputs.c ovk_sensors)."""
        out = np.zeros(4)
        yy = np.ascontiguousarray(y, float)
        y00 = None if y0 is None else np.ascontiguousarray(y0, float)
        status = self._lib.ovk_sensors(self._pm, self._data, yy.ctypes.data, None if y00 is None else y00.ctypes.data,
                                       int(j), out.ctypes.data)
        if status:
            raise RuntimeError(f"the compiled core's sensors failed ({STATUS.get(status, status)}): {self._message()}")
        return out

    def phi_t(self, t: float, y: np.ndarray) -> np.ndarray:
        """Phi_t (m,) of the drivers' equations at (t, y) (0 for the other equations; core/drivers.c)."""
        self._lib.ovk_set_time(self._data, float(t))
        self.rows(y)
        out = np.zeros(self.model.m)
        self._lib.ovk_phi_t(self._pm, self._data, out.ctypes.data)
        self._lib.ovk_set_time(self._data, float(self.model.scene.start_time))
        return out

    def unique(self, y: np.ndarray) -> tuple[int, np.ndarray]:
        """(rank of the whole Jacobian, each joint's reaction unique (nj bools, model order)) at
        the state y by the pre-check's one-factorisation rule (core/unique.c; the same verdicts as
        :func:`overcon.analysis.analyse` with ``methods = "svd"`` on Phi_h^T)."""
        rank, unique = ctypes.c_int(0), np.zeros(len(self.model.joints) or 1, np.intc)
        self._y[:] = y
        status = self._lib_unique(self._pm, self._data, self._ptrs[0], ctypes.addressof(rank), unique.ctypes.data)
        if status:
            raise RuntimeError(f"the compiled core's uniqueness failed ({STATUS.get(status, status)}): {self._message()}")
        return rank.value, unique[: len(self.model.joints)].astype(bool)

    def rows(self, y: np.ndarray):
        """(Phi (m,), Phi_h (m, nh), gamma (m,; without Baumgarte)) of the core at y: the joint rows
        it solves with, for checks. New arrays."""
        model = self.model
        phi, J, gam = np.zeros(model.m), np.zeros((model.m, model.nh)), np.zeros(model.m)
        self._y[:] = y
        status = self._rows_fn(self._pm, self._data, self._ptrs[0], phi.ctypes.data, J.ctypes.data, gam.ctypes.data)
        if status:
            raise RuntimeError(f"the compiled core's rows failed ({STATUS.get(status, status)}): {self._message()}")
        return phi, J, gam


    def project(self, t: float, y: np.ndarray, tol: float = PROJECTION_TOL, max_iter: int = PROJECTION_MAX_ITER):
        """(y projected onto every constraint equation, max |Phi| left) (core/project.c: positions then
        velocities, mass-orthogonal); t (s) names the instant in the message. Raises
        :class:`ProjectionFailed` with the core's message when the positions do not reach ``tol``."""
        out = np.ascontiguousarray(y, float).copy()
        drift = ctypes.c_double(0.0)
        status = self._project_fn(self._pm, self._data, t, out.ctypes.data, tol, max_iter, ctypes.byref(drift))
        self.last_status = status
        if status:
            raise ProjectionFailed(self._message())
        return out, drift.value


def _input_arrays(model, values, slopes):
    """(u, du or None) as contiguous arrays of the model's inputs, checked for their number."""
    n = len(model.inputs)
    u = np.ascontiguousarray(np.asarray(values, float).reshape(-1))
    du = None if slopes is None else np.ascontiguousarray(np.asarray(slopes, float).reshape(-1))
    if u.size != n or (du is not None and du.size != n):
        raise ValueError(f"inputs: {n} values expected (the model's inputs), got {u.size}")
    return (u if n else np.zeros(1)), (None if du is None else du if n else np.zeros(1))


def rows_kernel(model):
    """A :class:`Kernel` of ``model`` for its rows alone (default solver settings: the rows do not
    depend on them); raises :class:`KernelUnavailable` when no core can be loaded here."""
    from .spec import SolverSpec
    lib, reason = library()
    if lib is None:
        raise KernelUnavailable(reason, "the compiled core")
    return Kernel(lib, model, SolverSpec(), rows_only=True)


def rows_at(model, q: np.ndarray, h: np.ndarray | None = None):
    """(Phi (m,), Phi_h (m, nh), gamma (m,; without Baumgarte)) at the coordinates q (and the
    velocities h, default zero; gamma needs them), from the compiled core (core/joints*.c): the
    rows the pre-check, the initial-state checks and ``check --along`` judge. New arrays."""
    y = np.concatenate([np.asarray(q, float), np.zeros(model.nh) if h is None else np.asarray(h, float)])
    return rows_kernel(model).rows(y)


def rows_sparse(model, q: np.ndarray, h: np.ndarray | None = None):
    """(Phi (m,), Phi_h (m, nh) by its nonzeros: (rows, columns, values), row-major with the
    columns ascending in a row, as ``np.nonzero`` of the dense Phi_h gives them) at the
    coordinates q (velocities h, default zero) from the compiled core (core/rows_sparse.c): the
    values of :func:`rows_at` without the dense m x nh matrix (each equation is nonzero on its
    joint's two bodies only)."""
    kern = rows_kernel(model)
    w = 2 * model.nh_b
    phi, cols, vals = np.zeros(model.m), np.full((model.m, w), -1, np.intc), np.zeros((model.m, w))
    y = np.concatenate([np.asarray(q, float), np.zeros(model.nh) if h is None else np.asarray(h, float)])
    kern._y[:] = y
    status = library()[0].ovk_rows_sparse(kern._pm, kern._data, kern._ptrs[0], phi.ctypes.data, cols.ctypes.data,
                                          vals.ctypes.data)
    if status:
        raise RuntimeError(f"the compiled core's rows failed ({STATUS.get(status, status)}): {kern._message()}")
    rows = np.repeat(np.arange(model.m), w).reshape(model.m, w)
    keep = (cols >= 0) & (vals != 0.0)
    rr, cc, vv = rows[keep], cols[keep].astype(np.intp), vals[keep]
    order = np.lexsort((cc, rr))
    return phi, (rr[order], cc[order], vv[order])


def jacobian(model, q: np.ndarray) -> np.ndarray:
    """Phi_h (m, nh) at the coordinates q (:func:`rows_at`)."""
    return rows_at(model, q)[1]


def band_svd(B: np.ndarray, p: int = 0, mu: float = 0.0) -> tuple[np.ndarray, np.ndarray | None]:
    """The singular values of the rows B (k, n), largest first, by the core's banded route
    (core/bandsvd.c: windowed QR, band-to-bidiagonal, bisection), and with p > 0 an orthonormal
    basis (k, p) of the right singular vectors of the p smallest (subspace inverse iteration with
    the factor of [R; mu I] on a block reaching 30 times the p-th value, then a Rayleigh-Ritz
    step). Dimensionless: B as given."""
    lib, reason = library()
    if lib is None:
        raise KernelUnavailable(reason, "the compiled core")
    B = np.ascontiguousarray(B, dtype=float)
    k, n = B.shape
    sv, N = np.zeros(max(k, 1)), np.zeros((max(k, 1), max(p, 1)))
    status = lib.ovk_band_svd(B.ctypes.data, k, n, p, float(mu), sv.ctypes.data, N.ctypes.data)
    if status:
        raise ValueError(f"band_svd: {STATUS.get(status, status)} ({k} x {n} rows, p = {p})")
    return sv[:k], (N[:k, :p] if p else None)


def rigid_rows(model) -> np.ndarray:
    """The equations that can lose rank: every one, except the compliant joints' under
    ``redundancy = "compliant"`` (they are forces)."""
    if model.compliant_rows.size:
        return np.setdiff1d(np.arange(model.m), model.compliant_rows)
    return np.arange(model.m)


class ProjectionFailed(ArithmeticError):
    """The step-end projection (core/project.c) could not take the state onto the constraints."""


def _unavailable(model) -> str | None:
    """Why the kernel cannot run ``model`` in this process (not covered, or no library), or None."""
    why = support(model)
    if why is None:
        lib, reason = library()
        if lib is None:
            why = f"no compiled kernel: {reason}"
    return why


def refusal(model, solver=None, *, here: bool = False) -> str | None:
    """Why the compiled core cannot run ``model``, or None: the model is not covered, and with
    ``here`` (a run in this process) no library is at hand either. ``check`` and ``build`` ask
    without ``here`` (an FMU carries its own library), ``simulate`` with it: all three refuse such
    a scene as bad input. Every ``solver.kernel`` runs the core (``numpy`` is a deprecated alias)."""
    return _unavailable(model) if here else support(model)


def select(model, solver):
    """(a :class:`Kernel`, a note naming the library) for ``model`` and ``solver``; raises
    :class:`KernelUnavailable` when the core cannot run here. Every ``solver.kernel`` selects the
    core (``numpy`` is a deprecated alias)."""
    why = _unavailable(model)
    if why is not None:
        raise KernelUnavailable(why, "the compiled core")
    return Kernel(_state["lib"], model, solver), f"right-hand side: compiled kernel ({_state['path']})"


# ----------------------------------------------------------------------------- a run in C

C_METHODS = {"dopri5": 0, "rk4": 1, "dop853": 2, "radau": 3}
"""The core's integrators by ``solver.method``: dopri5, rk4 and dop853 (core/integrate_rk.c; the
tableaux of SciPy's RK45/DOP853) and radau (core/integrate_radau.c: Radau IIA of order 5 with its
own LU, core/lu.c)."""
BUDGET_STATUS = 11  # OVK_BUDGET: a work budget ran out (STATUS)
EVENT_KINDS = ("singular", "elimination-reselected", "rank-change", "uniqueness-change", "stopped")
"""The kinds of a run's events, in the order of core/core.h's OVK_EV_* (overcon.simulate.EVENT_KINDS)."""
INFO = ("t", "h", "nsteps", "nfev", "evaluations", "friction_iterations", "max_drift", "min_ratio", "stiff_steps",
        "stable_step", "wall_time", "singular_passed", "last_singular", "projection_drift", "watch_time",
        "watch_capped", "along_time", "along_certified")
"""The entries of ovk_sim_info, in order (core/sim.c)."""
WALL_TIMES = ("wall_time", "watch_time", "along_time")
"""The entries of :data:`INFO` that are wall times: no state, they differ between equal runs."""


OUT_KINDS = {"position": 1, "velocity": 2, "reaction": 5, "friction": 6, "energy": 7, "sensor": 8}
"""The kinds of a model output in the core's plan (``OVK_OUT_*`` of core/core.h, core/sim_out.c)."""
STATE_KIND = 3
"""The core's plan kind of an entry of the state y = [q, h] as it is (quaternions not normalised):
not a model output, for callers that need the state along a grid (``check --along``)."""


def output_plan(model) -> np.ndarray:
    """The core's output plan of ``model`` (rows (kind, a, b) in ``model.output_names()`` order,
    int32): a position's index into q, a velocity's into h, an energy's 0-3 (kinetic, potential,
    dissipated, applied: spec.ENERGY_OUTPUTS), a reaction's joint and component, a friction
    output's joint, a sensor's joint and entry (angle, rate, displacement, speed). ``overcon simulate`` and the FMUs' model file (:mod:`overcon.fmu.cmodel`) use it."""
    rows = [(OUT_KINDS["position"], i, 0) for _, i in model.position_outputs]
    rows += [(OUT_KINDS["velocity"], i, 0) for _, i in model.velocity_outputs]
    rows += [(OUT_KINDS["energy"], k, 0) for k in range(4)] if model.energy_outputs else []
    rows += [(OUT_KINDS["reaction"], j, comp) for j in model.reaction_joints
             for comp in range(len(model.joints[j].components))]
    rows += [(OUT_KINDS["friction"], j, 0) for j in model.friction_outputs]
    rows += [(OUT_KINDS["sensor"], j, what) for _, j, what in model.sensor_outputs]  # a joint's entry 0-3
    if len(rows) != len(model.output_names()):
        raise ValueError(f"output plan: {len(rows)} outputs for the model's {len(model.output_names())} names")
    return np.ascontiguousarray(np.array(rows, np.intc).reshape(-1, 3))


class _CRkOpts(ctypes.Structure):
    """``ovk_rk_opts`` of core/core.h."""
    _fields_ = [("method", ctypes.c_int), ("detect_stiffness", ctypes.c_int), ("tolerance", ctypes.c_double),
                ("max_step", ctypes.c_double), ("first_step", ctypes.c_double), ("step", ctypes.c_double)]


class _CSimOpts(ctypes.Structure):
    """``ovk_sim_opts`` of core/core.h."""
    _fields_ = [("rk", _CRkOpts), ("max_steps", ctypes.c_longlong), ("max_wall_time", ctypes.c_double),
                ("ratio_tol", ctypes.c_double), ("stop_time", ctypes.c_double), ("energy", ctypes.c_int)]


class RunStopped(RuntimeError):
    """A run in C stopped: ``status`` (:data:`STATUS`), the message as
    :class:`overcon.simulate.SimulationError` carries it, and rk4's ``stable_step`` when it refused a step."""

    def __init__(self, status: int, message: str, stable_step: float | None = None):
        super().__init__(message)
        self.status, self.stable_step = status, stable_step


class Run:
    """A whole run in C (core/sim.c: the integrator of core/integrate_rk.c or integrate_radau.c over the core's
    right-hand side, with warm starts, the singularity watch, the uniqueness along the motion,
    the work ledger and the step-end checks), for the methods of :data:`C_METHODS`. A stop is a
    :class:`RunStopped` with the core's status and message. :class:`overcon.simulate.Simulation`
    wraps it in process; the C FMU runs the same code (fmu/native/fmu_run.c)."""

    def __init__(self, model, solver, *, start_time: float | None = None, max_steps: int | None = None,
                 max_wall_time: float | None = None, ratio_tol: float = 1e-6, detect_stiffness: bool = True,
                 energy: bool | None = None, watch=None):
        """``energy``: keep the work ledger of :meth:`energies` (default: when the model has energy
        outputs; it costs two evaluations a step with friction). ``watch``: the watch's rows under
        min-norm or compliant (:func:`overcon.checks.watch_rows`; the
        run refuses to start without them)."""
        lib, reason = library()
        if lib is None:
            raise KernelUnavailable(reason)
        why = support(model)
        if why is not None or solver.method not in C_METHODS:
            raise KernelUnavailable(why or f"method {solver.method!r} (the C integrators: {', '.join(C_METHODS)})")
        self._lib, self.kernel = lib, Kernel(lib, model, solver, watch)
        self.ny = model.n + model.nh
        rk = _CRkOpts(method=C_METHODS[solver.method], detect_stiffness=int(detect_stiffness),
                      tolerance=solver.tolerance, max_step=solver.max_step, first_step=0.0, step=solver.step)
        self._opts = _CSimOpts(rk=rk, max_steps=max_steps or 0, max_wall_time=max_wall_time or 0.0,
                               ratio_tol=ratio_tol, stop_time=model.scene.stop_time,
                               energy=int(model.energy_outputs if energy is None else energy))
        t0 = model.scene.start_time if start_time is None else start_time
        y0 = np.ascontiguousarray(np.concatenate([model.q0, model.h0]), float)
        sim = lib.ovk_sim_new(self.kernel._pm, ctypes.byref(self._opts), t0, y0.ctypes.data)
        if not sim:
            raise MemoryError("the compiled core could not allocate a run")
        self._sim = sim
        self._finalize = weakref.finalize(self, lib.ovk_sim_free, sim)
        self._y = np.zeros(self.ny)
        self._info = np.zeros(len(INFO))
        self._plan = output_plan(model)
        status = lib.ovk_sim_status(sim)
        if status:
            raise RunStopped(status, self._message())

    def _message(self) -> str:
        return self._named(self._lib.ovk_sim_message(self._sim).decode("utf-8", "replace"))

    def _named(self, text: str) -> str:
        """The core's ``joints[k]`` (joints named by number in its messages and events) named."""
        if "joints[" in text:
            for j, c in reversed(list(enumerate(self.kernel.model.joints))):
                text = text.replace(f"joints[{j}]", c.name)
        return text

    def _raise(self, status: int):
        stable = self.info["stable_step"] if status == 10 else None
        raise RunStopped(status, self._message(), stable)

    @property
    def info(self) -> dict:
        """t, h, nsteps, nfev, evaluations, friction_iterations, max_drift, min_ratio, stiff_steps,
        stable_step, wall_time, ... (:data:`INFO`); watch_time, along_time: seconds of wall time in
        the singularity watch and, within it, in the uniqueness along the motion."""
        self._lib.ovk_sim_info(self._sim, self._info.ctypes.data)
        return dict(zip(INFO, self._info.tolist()))

    @property
    def y(self) -> np.ndarray:
        self._lib.ovk_sim_state_vector(self._sim, self._y.ctypes.data)
        return self._y.copy()

    def watch_extremes(self, y: np.ndarray, *, cold: bool = False) -> tuple[float, float]:
        """(sigma_min, sigma_max) of the watched rows at state ``y`` (Phi_h equilibrated by
        core/watch_scale.c, unit-norm rows: core/watch_eig.c's estimate, to its relative accuracy
        1e-9 with a floor of 1e-13 sigma_max), warm-started from the run's tracked vectors, or
        from the fixed start with ``cold``; the run is left as it was."""
        y = np.ascontiguousarray(y, float)
        if y.shape != (self.ny,):
            raise ValueError(f"watch_extremes: a state of {self.ny} entries, got shape {y.shape}")
        out = np.zeros(2)
        status = self._lib.ovk_sim_watch_extremes(self._sim, y.ctypes.data, int(cold), out.ctypes.data)
        if status:
            raise RunStopped(status, self._message())
        return float(out[0]), float(out[1])

    def step(self) -> None:
        status = self._lib.ovk_sim_step(self._sim)
        if status:
            self._raise(status)

    def advance(self, t_target: float, *, max_steps: int | None = None, max_wall_time: float | None = None):
        """y(t_target) (a new array), as :meth:`overcon.simulate.Simulation.advance`."""
        out = np.zeros(self.ny)
        status = self._lib.ovk_sim_advance(self._sim, t_target, -1 if max_steps is None else max_steps,
                                           max_wall_time or 0.0, out.ctypes.data)
        if status:
            self._raise(status)
        return out

    def outputs(self, t: float, y: np.ndarray):
        """(reactions (nj, 9), friction outputs (nj,)) at (t, y) of the last step, as
        :meth:`Kernel.outputs` with the multipliers of :meth:`overcon.simulate.Simulation.derived_outputs`."""
        k = self.kernel
        yy = np.ascontiguousarray(y, float)
        reac, fric = np.zeros_like(k._reac), np.zeros_like(k._fric)
        status = self._lib.ovk_sim_outputs(self._sim, t, yy.ctypes.data, reac.ctypes.data, fric.ctypes.data)
        if status:
            self._raise(status)
        return reac, fric

    def output_row(self, t: float, y: np.ndarray, plan: np.ndarray | None = None) -> np.ndarray:
        """The outputs of ``plan`` (default the model's :func:`output_plan`, ``model.output_names()``
        order) at (t, y) of the last step (core/sim_out.c), a new array; the run's state is left
        as it was."""
        plan = self._plan if plan is None else np.ascontiguousarray(plan, np.intc).reshape(-1, 3)
        yy = np.ascontiguousarray(y, float)
        if yy.shape != (self.ny,):
            raise ValueError(f"output_row: a state of {self.ny} entries, got shape {yy.shape}")
        out = np.zeros(len(plan))
        status = self._lib.ovk_sim_output_row(self._sim, plan.ctypes.data, len(plan), t, yy.ctypes.data,
                                              out.ctypes.data)
        if status:
            self._raise(status)
        return out

    def grid(self, times: np.ndarray, plan: np.ndarray | None = None) -> tuple[np.ndarray, int, RunStopped | None]:
        """The run advanced through ``times`` (ascending, finite, from the run's time on) with the
        row of ``plan`` (default the model's :func:`output_plan`) at each, all inside the core
        (core/sim_out.c, ovk_sim_grid) into one preallocated array: (values (len(times),
        len(plan)), rows written, the stop or None). A stop leaves the rows before it; rows after
        it are NaN."""
        plan = self._plan if plan is None else np.ascontiguousarray(plan, np.intc).reshape(-1, 3)
        times = np.ascontiguousarray(times, float).reshape(-1)
        values = np.full((len(times), len(plan)), np.nan)
        rows = ctypes.c_longlong(0)
        status = self._lib.ovk_sim_grid(self._sim, plan.ctypes.data, len(plan), times.ctypes.data, len(times),
                                        values.ctypes.data, ctypes.addressof(rows))
        stop = None
        if status:
            stop = RunStopped(status, self._message(), self.info["stable_step"] if status == 10 else None)
        return values, int(rows.value), stop

    def energies(self, t: float, y: np.ndarray) -> np.ndarray:
        """[kinetic, potential, dissipated, applied] (J) at (t, y) of the last step, as the energy
        outputs of :meth:`overcon.simulate.Simulation.state_outputs` (the work from the ledger:
        zeros when the run keeps none)."""
        yy = np.ascontiguousarray(y, float)
        out = np.zeros(4)
        status = self._lib.ovk_sim_energy(self._sim, t, yy.ctypes.data, out.ctypes.data)
        if status:
            self._raise(status)
        return out

    @property
    def events(self) -> list[tuple[float, str, str]]:
        """The run's events (time s, kind, detail) as :attr:`overcon.simulate.Simulation.events`
        (kinds :data:`overcon.simulate.EVENT_KINDS`; the core's ``joints[k]`` named)."""
        t, kind, out = ctypes.c_double(0.0), ctypes.c_int(0), []
        for k in range(self._lib.ovk_sim_events(self._sim)):
            detail = self._lib.ovk_sim_event(self._sim, k, ctypes.addressof(t), ctypes.addressof(kind))
            out.append((t.value, EVENT_KINDS[kind.value], self._named(detail.decode("utf-8", "replace"))))
        return out

    def uniqueness(self) -> tuple[int, dict[str, bool], bool]:
        """(rank, joint name -> reaction unique, motion_unique) at the last evaluation of the
        uniqueness along the motion (core/watch.c: the start, and the steps it evaluates at)."""
        joints = self.kernel.model.joints
        rank, unique = ctypes.c_int(0), np.zeros(len(joints) or 1, np.intc)
        motion = self._lib.ovk_sim_uniqueness(self._sim, ctypes.addressof(rank), unique.ctypes.data)
        return rank.value, {c.name: bool(u) for c, u in zip(joints, unique)}, bool(motion)

    def set_inputs(self, values, slopes=None) -> None:
        """The inputs' values (model.inputs order) from the run's time on, held or with
        ``slopes`` (per s) linear (core/sim.c ovk_sim_set_inputs); a non-finite value is a
        ValueError, other failures a :class:`RunStopped`."""
        u, du = _input_arrays(self.kernel.model, values, slopes)
        status = self._lib.ovk_sim_set_inputs(self._sim, u.ctypes.data, None if du is None else du.ctypes.data)
        if status and not self._lib.ovk_sim_status(self._sim):  # refused values: the run goes on
            raise ValueError(self._message())
        if status:
            self._raise(status)

    def sensors(self, y: np.ndarray) -> np.ndarray:
        """(nj, 4) [angle, rate, displacement, speed] of the sensor joints at y, from q0 (rows of
        the other joints zero)."""
        model = self.kernel.model
        out = np.zeros((len(model.joints), 4))
        y0 = np.concatenate([model.q0, model.h0])
        for j in sorted({j for _, j, _ in model.sensor_outputs}):
            out[j] = self.kernel.sensors(y, y0, j)
        return out

    def get_state(self) -> bytes:
        size = self._lib.ovk_sim_state_size(self._sim)
        buf = ctypes.create_string_buffer(size)
        status = self._lib.ovk_sim_get_state(self._sim, buf, size)
        if status:
            self._raise(status)
        return buf.raw

    def set_state(self, state: bytes) -> None:
        status = self._lib.ovk_sim_set_state(self._sim, state, len(state))
        if status:
            self._raise(status)
