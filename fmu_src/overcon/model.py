"""Compile a scene into an immutable :class:`Model` without evaluating it (evaluation: the
compiled core, :mod:`overcon.kernel`; the checks of the compiled model at its initial state and the
elimination: :mod:`overcon.checks`).

Glossary (paper symbols spelled for code; shapes for b moving bodies, m equations)
-----------------------------------------------------------------------------------
``q``      (n,)     absolute coordinates, per body [x, y, phi] (planar, n = 3b) or
                    [x, y, z, alpha, beta, gamma] (spatial, z-x-z Euler, n = 6b; Eq. 33, 39) or
                    [x, y, z, e0, e1, e2, e3] (spatial, ``rotation = "quaternion"``, n = 7b).
``h``      (nh,)    velocities: planar q' (Eq. 2); spatial per body [r' (global), omega (body
                    axes)] (Eq. 3); nh = 3b planar, 6b spatial (nh = n but for quaternions).
                    ``nq_b``/``nh_b``: coordinates/velocities per body; q' from (q, h): the
                    core's coordinate rates (core/rates.c).
``Phi``    (m,)     constraint equations, numbered as in the paper (Eq. 5, 37, 42).
``Phi_q``  (m, n)   exact derivative of Phi by q (Eq. 6).
``Phi_h``  (m, nh)  derivative by h: planar Phi_q, spatial the modified Jacobian (Eq. 7).
``J``      (nh, m)  ``Phi_h.T``, the transposed (modified) Jacobian (Eq. 8).
``gamma``  (m,)     Phi_h h' = gamma (Eq. 11).
``lam``    (m,)     Lagrange multipliers; eliminated equations carry lam = 0.
``M``      (nh,)    diagonal of the mass matrix (m, m, J per body; spatial principal inertias).
``Q``      (nh,)    applied generalized forces incl. gyroscopic terms (Eq. 1).

Sign convention (one place): equations of motion ``M h' + J lam = Q + Q_f`` (Eq. 18). The
generalized reaction of joint X on its bodies is ``f_X = J_X lam_X`` on the left-hand side, so the
*physical* reaction a joint exerts is ``-J_X lam_X``. Reactions are reported on body i of the joint
in its auxiliary frame: ``p' = -A_i (J_X)_i lam_X`` (Eq. 19), as components named by the joint
type (``Fx, Fy, T`` planar, ``Fx, Fy, Fz`` spherical, the non-vanishing ones of
``Fx, Fy, Fz, Tx, Ty, Tz`` for the other spatial joints: :mod:`overcon.joints.spatial_rows`),
computed by the core (core/outputs.c);
units N and N.m. Joint constants may depend on the bodies' rotation matrices at q0
(:class:`overcon.joints.InitialFrames`, from :func:`_rotations` of the bodies).

Immutability (decided here): a Model is a frozen dataclass whose arrays are read-only
(``writeable = False``, set by ``Model.__post_init__``, also in its compiled joints, loads and
plan); everything that changes during a run lives in the integrator state (see
:mod:`overcon.simulate`). A Model carries no solver options: ``Model.scene`` is the compiled scene
with ``solver=None``; the options (:class:`overcon.spec.SolverSpec`, a frozen record) are given to
:class:`overcon.simulate.Simulation`, so changing them never recompiles the Model nor reruns the
rank analysis.

Assembly plan: every Model holds an :class:`AssemblyPlan` (``Model.plan``), built by
``__post_init__`` from its joints and retained equations (so ``dataclasses.replace`` gives a new
model a matching plan; there is no cache): the friction joints grouped by type, with their
multiplier gather and force scatter indices, which :class:`overcon.kernel.Kernel` packs for the
core (the joints' own rows, constants and bodies it packs from ``Model.joints``).
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Mapping

import numpy as np

from .friction_laws import Law, make_law
from .joints import TYPES, InitialFrames
from .kinematics import cos_sin, euler_R_rows, quat_R_rows, rot2_rows
from .scene import SENSOR_JOINTS
from .spec import DRIVER_MOTIONS
from .spec import BASE, ENERGY_OUTPUTS, VELOCITIES_PER_BODY, VELOCITY_OUTPUTS, MechanismSpec, SceneSpec, coordinates


GLOBAL_COMPONENTS = {"planar": ("Fx0", "Fy0"), "spatial": ("Fx0", "Fy0", "Fz0")}
"""Reaction force components in the global frame pi_0, reported after the auxiliary-frame ones."""


class ModelError(ValueError):
    """A scene that parses but cannot be simulated as asked (e.g. a bad elimination). ``details``:
    data for ``check --json``'s error document (keys added beside ``file`` and ``error``; e.g. a
    refused elimination's ``valid_eliminations`` and ``joint_equations``)."""

    def __init__(self, message: str, details: dict | None = None):
        super().__init__(message)
        self.details = dict(details or {})


class InconsistentInitialState(ModelError):
    """q0 or h0 off the constraint manifold (refused by :func:`overcon.checks.compile_checked`, so ``check``,
    ``simulate`` and ``build`` all refuse it with the same message)."""


@dataclass(frozen=True)
class CompiledJoint:
    name: str
    type: str
    index: int
    bi: int  # body slot of body i (-1 = base)
    bj: int
    rows: tuple[int, ...]  # 0-based equation indices
    p: Mapping[str, object]
    law: Law | None  # friction switched on (None: frictionless)
    components: tuple[str, ...]

    @property
    def is_driver(self) -> bool:
        return self.type == "driver"

    @property
    def module(self):
        """Its type's module (:mod:`overcon.joints`: the constants and row facts)."""
        return TYPES[self.type].module


@dataclass(frozen=True)
class AxisCompliance:
    """A spatial compliant joint with per-axis values (:class:`overcon.spec.ComplianceSpec`):
    the stiffness and damping tensors K = F diag(k) F^T along its joint frame F (global: R_i
    ``frame``), restricted to its equations as U^T K U, U the equations' directions (translational
    rows: the velocity columns of a moving body; rotational rows: the angular ones, in global
    axes). Values per frame axis x, y, z: ``k_t``/``d_t`` (N/m, N.s/m) on the translational rows
    ``t_rows``, ``k_r``/``d_r`` (N.m/rad, N.m.s/rad) on the rotational rows ``r_rows`` (0-based)."""

    joint: int
    bi: int
    bj: int
    frame: np.ndarray  # (3, 3) joint frame axes (columns) in body i axes
    t_rows: tuple[int, ...]
    r_rows: tuple[int, ...]
    k_t: np.ndarray
    d_t: np.ndarray
    k_r: np.ndarray
    d_r: np.ndarray


@dataclass(frozen=True)
class CompiledLoad:
    type: str
    bi: int
    bj: int
    value: np.ndarray | None = None
    stiffness: float = 0.0
    free_length: float = 0.0
    s_i: np.ndarray | None = None
    s_j: np.ndarray | None = None


@dataclass(frozen=True)
class CompiledInput:
    """A scene input (:class:`overcon.spec.InputSpec`) packed for the core (core/inputs.c):
    ``kind`` 1 joint_torque, 2 joint_force, 3 force, 4 torque; ``joint`` (-1 none), bodies ``bi``,
    ``bj`` (-1 base); ``direction`` (unit, in ``frame``: 0 global, 1 body i's axes, 2 body j's),
    ``point`` (body i coordinates), ``start`` (N or N.m)."""

    name: str
    type: str
    kind: int
    joint: int
    bi: int
    bj: int
    direction: tuple[float, float, float]
    point: tuple[float, float, float]
    frame: int
    start: float
    unit: str


INPUT_KINDS = {"joint_torque": 1, "joint_force": 2, "force": 3, "torque": 4}


@dataclass(frozen=True)
class Model:
    """A compiled scene (read-only arrays, see the module docstring). ``scene`` is the compiled
    scene with ``solver=None``: solver options go to :class:`overcon.simulate.Simulation`."""

    scene: SceneSpec
    kind: str
    dim: int  # 2 planar, 3 spatial
    nq_b: int  # coordinates per body (entries of q_i)
    nh_b: int  # velocities per body (entries of h_i): 3 planar, 6 spatial
    nb: int
    body_names: tuple[str, ...]
    mass: np.ndarray  # (nb,)
    inertia: np.ndarray  # (nb, 1) planar, (nb, 3) spatial
    M: np.ndarray  # (nh,) diagonal of the mass matrix
    Minv: np.ndarray
    gravity: np.ndarray
    joints: tuple[CompiledJoint, ...]
    loads: tuple[CompiledLoad, ...]
    q0: np.ndarray
    h0: np.ndarray
    m: int
    retained: np.ndarray  # 0-based indices of the equations kept
    eliminated: tuple[int, ...]  # 1-based paper indices removed
    elimination_mode: str  # "given", "auto", "min-norm" (none: spec.REDUNDANCY_METHODS), or "pending" (compiled, not admitted: overcon.checks)
    friction_joints: tuple[int, ...]
    position_outputs: tuple[tuple[str, int], ...] = field(default=())  # (name, index into q)
    velocity_outputs: tuple[tuple[str, int], ...] = field(default=())  # (name, index into h)
    energy_outputs: bool = False  # energy.kinetic, energy.potential (spec.ENERGY_OUTPUTS)
    reaction_joints: tuple[int, ...] = field(default=())
    friction_outputs: tuple[int, ...] = field(default=())  # joints with a <joint>.friction output
    rotation: str = "euler_zxz"  # spatial orientation coordinates (spec.ROTATIONS)
    # redundancy "compliant": the equations of compliant joints (0-based) and per equation (m,) the
    # stiffness and damping of the spring-damper on its violation (N/m, N.s/m or N.m/rad, N.m.s/rad)
    compliant_rows: np.ndarray = field(default_factory=lambda: np.arange(0))
    row_stiffness: np.ndarray = field(default_factory=lambda: np.zeros(0))
    row_damping: np.ndarray = field(default_factory=lambda: np.zeros(0))
    # compliant joints with per-axis values: their rows take the tensor of AxisCompliance (their
    # row_stiffness and row_damping are 0)
    compliance_axes: tuple[AxisCompliance, ...] = ()
    plan: "AssemblyPlan" = field(init=False, repr=False, compare=False)  # built by __post_init__
    # the pre-check's factorisation of the Jacobian at q0 (overcon.analysis.Factored), kept when
    # admission made it to choose the elimination (overcon.checks.admit); a replaced model has none
    factored_q0: object = field(init=False, repr=False, compare=False, default=None)
    inputs: tuple[CompiledInput, ...] = ()  # scene [[inputs]]
    sensor_outputs: tuple[tuple[str, int, int], ...] = ()  # (name, joint, 0 angle 1 rate 2 displacement 3 speed)

    def __post_init__(self):
        for name in ("mass", "inertia", "M", "Minv", "gravity", "q0", "h0", "retained", "compliant_rows",
                     "row_stiffness", "row_damping"):
            _read_only(getattr(self, name))
        object.__setattr__(self, "plan", build_plan(self))

    @property
    def n(self) -> int:
        return self.nb * self.nq_b

    @property
    def nh(self) -> int:
        return self.nb * self.nh_b

    def body_slice(self, b: int) -> slice:
        """Body slot b's entries of h (and of Q, the Jacobian's columns)."""
        return slice(b * self.nh_b, (b + 1) * self.nh_b)

    def state_output_names(self) -> list[str]:
        """The outputs that need the state only (no evaluation of Eq. 18): positions, velocities,
        energies; they come first in :meth:`output_names`."""
        names = [name for name, _ in self.position_outputs] + [name for name, _ in self.velocity_outputs]
        return names + ([name for name, _ in ENERGY_OUTPUTS] if self.energy_outputs else [])

    def output_names(self) -> list[str]:
        names = self.state_output_names()
        for j in self.reaction_joints:
            c = self.joints[j]
            names += [f"{c.name}.{comp}" for comp in c.components]
        names += [f"{self.joints[j].name}.friction" for j in self.friction_outputs]
        return names + [name for name, _, _ in self.sensor_outputs]


# ----------------------------------------------------------------------------- assembly plan

@dataclass(frozen=True, eq=False)
class FrictionGroup:
    """The friction joints of one type (model order within the type; the core takes them group
    by group, ``ovk_model.fj``): where their multipliers are read from the friction multipliers x
    and where their forces go among the velocities ``AssemblyPlan.friction_cols``."""

    type: str
    joints: tuple[int, ...]
    x_index: np.ndarray  # (k, n_equations) into x = lam_R[friction_xrows], extended by one pad slot
    col_i: np.ndarray  # (k, n_coord) into friction_cols of body i's velocities, extended by one pad slot
    col_j: np.ndarray

    def __post_init__(self):
        _freeze_fields(self)


@dataclass(frozen=True, eq=False)
class AssemblyPlan:
    """Compile-time index data of the friction joints, packed for the core by
    :class:`overcon.kernel.Kernel` (built by :func:`build_plan`)."""

    friction: tuple[FrictionGroup, ...]
    friction_xrows: np.ndarray  # positions in lam_R of the retained friction rows (joint order)
    friction_cols: np.ndarray  # velocity indices (into h) that friction forces act on, sorted

    def __post_init__(self):
        _freeze_fields(self)


def _freeze_fields(obj) -> None:
    """Mark every array field of a dataclass instance read-only."""
    for name in obj.__dataclass_fields__:
        _read_only(getattr(obj, name))


def _read_only(x):
    """Mark an array (or the arrays in a dict) read-only; returns it."""
    if isinstance(x, np.ndarray):
        x.flags.writeable = False
    elif isinstance(x, dict):
        for v in x.values():
            _read_only(v)
    return x


def build_plan(model: Model) -> AssemblyPlan:
    """The plan of ``model``'s friction joints and retained equations (every array read-only)."""
    k = model.nh_b
    retained = model.retained
    pos = {int(row): p for p, row in enumerate(retained)}
    pad = len(retained)  # index of the appended 0.0
    fjoints = [model.joints[j] for j in model.friction_joints]
    fr_types: dict[str, list] = {}
    for c in fjoints:
        fr_types.setdefault(c.type, []).append(c)
    xrows = [pos[r] for c in fjoints for r in c.rows if r in pos]
    xpos = {row: n for n, row in enumerate(xrows)}
    fbodies = sorted({b for c in fjoints for b in (c.bi, c.bj) if b >= 0})
    cols = [b * k + i for b in fbodies for i in range(k)]
    cpos = {b: [n * k + i for i in range(k)] for n, b in enumerate(fbodies)}
    cpos[-1] = [len(cols)] * k  # the base: the pad slot
    friction = tuple(FrictionGroup(
        type=jtype, joints=tuple(c.index for c in js),
        x_index=np.array([[xpos.get(pos.get(r, pad), len(xrows)) for r in c.rows] for c in js], np.intp),
        col_i=np.array([cpos[c.bi] for c in js], np.intp), col_j=np.array([cpos[c.bj] for c in js], np.intp))
        for jtype, js in fr_types.items())
    return AssemblyPlan(friction=friction, friction_xrows=np.array(xrows, np.intp),
                        friction_cols=np.array(cols, np.intp))


# ----------------------------------------------------------------------------- compile

def compile_model(scene: SceneSpec) -> Model:
    """Compile a validated scene: sizes, index maps, joint constants (from the bodies' rotation
    matrices at q0), loads, outputs. Nothing is evaluated: every equation is retained and the
    elimination is pending (``elimination_mode = "pending"``); :func:`overcon.checks.admit`
    checks q0/h0 and resolves ``scene.eliminate`` on the result, and
    :func:`overcon.checks.compile_checked` does both steps."""
    mech: MechanismSpec = scene.mechanism
    kind = mech.kind
    dim = 2 if kind == "planar" else 3
    rotation = mech.rotation if kind == "spatial" else "euler_zxz"
    coord_names = coordinates(kind, rotation)
    k = len(coord_names)
    names = tuple(b.name for b in mech.bodies)
    slot = {name: i for i, name in enumerate(names)}
    slot[BASE] = -1
    nb = len(names)
    particle = {b.name: b.particle for b in mech.bodies}
    mass = np.array([b.mass for b in mech.bodies], float)
    inertia = np.array([b.inertia for b in mech.bodies], float).reshape(nb, -1)
    M = np.concatenate([np.concatenate([np.full(dim, mass[i]), inertia[i]]) for i in range(nb)])
    loads = _compile_loads(mech, slot, dim)
    q0 = np.concatenate([np.asarray(b.q0, float) for b in mech.bodies])
    h0 = np.concatenate([np.asarray(b.h0, float) for b in mech.bodies])
    coord_index = {}
    for b, name in enumerate(names):
        for i, cname in enumerate(coord_names):
            coord_index[f"{name}.{cname}"] = b * k + i
    # the bodies alone (no joints yet): their frames at q0 give the joints' constants
    bodies = Model(
        scene=replace(scene, solver=None), kind=kind, dim=dim, nq_b=k, nh_b=VELOCITIES_PER_BODY[kind], nb=nb,
        body_names=names, mass=mass, rotation=rotation,
        inertia=inertia, M=M, Minv=1.0 / M, gravity=np.asarray(mech.gravity, float),
        joints=(), loads=tuple(loads), q0=q0, h0=h0, m=0, retained=np.arange(0), eliminated=(),
        elimination_mode="pending", friction_joints=(),
        position_outputs=tuple((p, coord_index[p]) for p in scene.positions),
        velocity_outputs=tuple((f"{b}.{v}", slot[b] * VELOCITIES_PER_BODY[kind] + i) for b in scene.velocities
                               for i, (v, _) in enumerate(VELOCITY_OUTPUTS[kind])
                               if not (particle[b] and i >= dim)),  # a particle: no rates of its frozen orientation
        energy_outputs=scene.energy)
    joints = _mechanism_joints(scene, slot, _rotations(bodies, q0))
    joint_index = {c.name: c.index for c in joints}
    sensors = tuple((f"{name}.{what}", joint_index[name], SENSOR_INDEX[what]) for name in scene.sensors
                    for what in SENSOR_JOINTS[joints[joint_index[name]].type])
    n_mech = len(joints)
    joints += _driver_joints(scene, joints, joint_index)
    row = sum(len(c.rows) for c in joints)  # the equations: each joint's and driver's, numbered in order
    base = replace(
        bodies, joints=tuple(joints), m=row, retained=np.arange(row), **_compliance(scene, joints, row),
        friction_joints=tuple(c.index for c in joints if c.law is not None),
        reaction_joints=tuple(joint_index[j] for j in scene.reactions) + tuple(range(n_mech, len(joints))),
        friction_outputs=tuple(joint_index[j] for j in
                               (scene.friction if scene.friction_outputs == "all" else scene.friction_outputs)),
        inputs=tuple(_compile_input(u, joints, joint_index, slot) for u in scene.inputs), sensor_outputs=sensors,
    )
    return base


def _compile_loads(mech: MechanismSpec, slot: dict, dim: int) -> list[CompiledLoad]:
    """The mechanism's loads with their bodies as slots (-1: the base)."""
    loads = []
    for ld in mech.loads:
        p = ld.params
        if ld.type in ("force", "torque"):
            loads.append(CompiledLoad(ld.type, slot[p["body"]], -1,
                                      value=_read_only(np.array(p["value"], float))))
        else:
            zero = np.zeros(dim)
            loads.append(CompiledLoad(
                "spring", slot[p["body_i"]], slot[p["body_j"]], stiffness=float(p["stiffness"]),
                free_length=float(p["free_length"]),
                s_i=_read_only(zero if p.get("s_i") is None else np.array(p["s_i"], float)),
                s_j=_read_only(zero.copy() if p.get("s_j") is None else np.array(p["s_j"], float))))
    return loads


def _mechanism_joints(scene: SceneSpec, slot: dict, R0) -> list[CompiledJoint]:
    """The mechanism's joints, their equations numbered in order from row 0, their constants from
    the bodies' rotation matrices ``R0`` at q0, a friction law on each joint of ``scene.friction``."""
    friction_on = set(scene.friction)
    global_components = GLOBAL_COMPONENTS[scene.mechanism.kind]
    joints = []
    row = 0
    for idx, js in enumerate(scene.mechanism.joints):
        jt = TYPES[js.type]
        ne = jt.n_equations
        law = None
        if js.name in friction_on:
            fspec = scene.friction_params.get(js.name, js.friction)
            law = make_law(fspec, jt.friction_sizes(fspec) if jt.friction_extra else None)
        bi, bj = slot[js.body_i], slot[js.body_j]
        joints.append(CompiledJoint(
            name=js.name, type=js.type, index=idx, bi=bi, bj=bj, rows=tuple(range(row, row + ne)),
            p=_read_only(jt.module.constants(js.params, InitialFrames(R0[bi], R0[bj]))), law=law,
            components=jt.reaction_components + global_components))
        row += ne
    return joints


def _driver_joints(scene: SceneSpec, joints: list, joint_index: dict) -> list[CompiledJoint]:
    """The scene's drivers, one equation each, numbered after the mechanism ``joints``' (their
    efforts: outputs)."""
    n_mech = len(joints)
    row = sum(len(c.rows) for c in joints)
    out = []
    for k, dv in enumerate(scene.drivers):
        c = joints[joint_index[dv.joint]]
        out.append(CompiledJoint(
            name=dv.name, type=DRIVER, index=n_mech + k, bi=c.bi, bj=c.bj, rows=(row,),
            p=_read_only({"joint": c.index, "coordinate": 0 if dv.coordinate == "angle" else 1,
                          "motion": DRIVER_MOTION_CODES[dv.motion],
                          "params": tuple(float(dv.params[key]) for key in DRIVER_MOTIONS[dv.motion]),
                          "start_time": float(scene.start_time)}),
            law=None, components=("effort",)))
        row += 1
    return out


SENSOR_INDEX = {"angle": 0, "rate": 1, "displacement": 2, "speed": 3}
DRIVER = "driver"
"""``CompiledJoint.type`` of a driver (scene ``[[drivers]]``): one rheonomic equation on a joint's
coordinate (core/drivers.c), its reaction the effort; not a mechanism joint type
(:data:`overcon.joints.TYPES`)."""
DRIVER_MOTION_CODES = {"constant_speed": 1, "ramp": 2, "harmonic": 3}
"""The entries of the core's sensors of a joint (core/inputs.c ovk_sensors)."""


def _compile_input(u, joints, joint_index: dict, slot: dict) -> CompiledInput:
    """The input ``u`` (:class:`overcon.spec.InputSpec`) for the core: a joint input takes its
    joint's axis (planar revolute: z; planar translational: the guide in body j's axes,
    OMEGA^T v / |v|, at s_A; spatial: a_i in body i's axes at s_i), a body input its direction
    and point."""
    from .spec import INPUT_TYPES
    pad = lambda v: tuple(float(x) for x in v) + (0.0,) * (3 - len(v))  # noqa: E731
    if u.joint is not None:
        c = joints[joint_index[u.joint]]
        if c.type == "revolute":
            d, pt, frame = (0.0, 0.0, 1.0), (0.0, 0.0, 0.0), 1
        elif c.type == "translational":
            v = np.asarray(c.p["v"], float)
            d, pt, frame = pad(np.array([v[1], -v[0]]) / np.linalg.norm(v)), pad(c.p["s_A"]), 2
        else:
            d, pt, frame = pad(c.p["a_i"]), pad(c.p["s_i"]), 1
        return CompiledInput(u.name, u.type, INPUT_KINDS[u.type], c.index, c.bi, c.bj, d, pt, frame,
                             float(u.start), INPUT_TYPES[u.type])
    d = pad(u.direction) if u.direction is not None else (1.0, 0.0, 0.0)
    pt = pad(u.point) if u.point is not None else (0.0, 0.0, 0.0)
    return CompiledInput(u.name, u.type, INPUT_KINDS[u.type], -1, slot[u.body], -1, d, pt,
                         1 if u.frame == "body" else 0, float(u.start), INPUT_TYPES[u.type])


def _compliance(scene: SceneSpec, joints, m: int) -> dict:
    """The compliant equations and their per-equation stiffness and damping (redundancy
    "compliant": the joints with a compliance table; otherwise none); a joint with per-axis
    values gets an :class:`AxisCompliance` instead of per-equation values."""
    k, d = np.zeros(m), np.zeros(m)
    rows, axes = [], []
    if scene.redundancy == "compliant":
        for c, js in zip(joints, scene.mechanism.joints):
            if js.compliance is None:
                continue
            cs = js.compliance
            kinds = TYPES[c.type].row_kinds
            rows.extend(c.rows)
            if cs.per_axis:
                axes.append(_axis_compliance(c, cs, kinds))
                continue
            for r, kind in zip(c.rows, kinds):
                rot = kind == "rotational"
                k[r] = cs.rotational_stiffness if rot else cs.stiffness
                d[r] = cs.rotational_damping if rot else cs.damping
    return {"compliant_rows": np.array(rows, int), "row_stiffness": k, "row_damping": d,
            "compliance_axes": tuple(axes)}


def _axis_compliance(c: CompiledJoint, cs, kinds) -> AxisCompliance:
    """The tensors of a per-axis compliant joint: a scalar value is the same on the three axes;
    the frame is the joint's reaction frame ``E`` (axis types) or body i's axes (spherical)."""
    def vec(x):
        return _read_only(np.array(x if isinstance(x, tuple) else (x, x, x), float))
    frame = np.asarray(c.p["E"], float) if "E" in c.p else np.eye(3)
    return AxisCompliance(
        joint=c.index, bi=c.bi, bj=c.bj, frame=_read_only(frame.copy()),
        t_rows=tuple(r for r, kind in zip(c.rows, kinds) if kind != "rotational"),
        r_rows=tuple(r for r, kind in zip(c.rows, kinds) if kind == "rotational"),
        k_t=vec(cs.stiffness), d_t=vec(cs.damping), k_r=vec(cs.rotational_stiffness), d_r=vec(cs.rotational_damping))


def _rotations(model: Model, q: np.ndarray) -> np.ndarray:
    """Rotation matrices body -> global of every body at q, (nb + 1, d, d), slot -1 the base
    (identity), for the joint constants and the initial-state messages."""
    nb, k = model.nb, model.nq_b
    Q = q.reshape(nb, k)
    if model.kind == "planar":
        phi = np.zeros(nb + 1)
        phi[:nb] = Q[:, 2]
        return rot2_rows(phi)
    if model.rotation == "quaternion":
        quat = np.zeros((nb + 1, 4))
        quat[:nb] = Q[:, 3:]
        quat[nb, 0] = 1.0
        return quat_R_rows(quat)
    angles = np.zeros((nb + 1, 3))
    angles[:nb] = Q[:, 3:]
    return euler_R_rows(angles, cos_sin(angles))


def normalized_coordinates(model: Model, q: np.ndarray) -> np.ndarray:
    """q (n,) with every quaternion replaced by e / |e| (the orientation the dynamics use, and
    what the position outputs report); other coordinates unchanged (a copy)."""
    out = np.array(q, float)
    if model.rotation == "quaternion":
        E = out.reshape(model.nb, 7)[:, 3:]
        E /= np.sqrt(((E[:, 0] * E[:, 0] + E[:, 1] * E[:, 1]) + E[:, 2] * E[:, 2]) + E[:, 3] * E[:, 3])[:, None]
    return out
