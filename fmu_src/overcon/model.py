"""Compile a scene into an immutable :class:`Model`, and evaluate frames, constraints and loads.

Glossary (paper symbols spelled for code; shapes for b moving bodies, m equations)
-----------------------------------------------------------------------------------
``q``      (n,)     absolute coordinates, per body [x, y, phi] (planar, n = 3b) or
                    [x, y, z, alpha, beta, gamma] (spatial, z-x-z Euler, n = 6b); Eq. 33, 39.
``h``      (nh,)    velocities: planar q' (Eq. 2); spatial per body [r' (global), omega (body
                    axes)] (Eq. 3); nh = n.
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
type (``Fx, Fy, T`` planar, ``Fx, Fy, Fz`` spherical); units N and N.m.

The model is never mutated after :func:`compile_model`; everything that changes during a run
lives in the integrator state (see :mod:`overcon.simulate`).

Hot path: :func:`compile_model` also stores an :class:`AssemblyPlan` (``Model.plan``): per joint
type the stacked constant arrays of the joint module's ``batch_*`` functions and flat scatter
indices into Phi_h, and for the friction joints the multiplier gather and force scatter indices.
:func:`constraints`, :func:`jacobian_h` and :func:`gamma` evaluate all joints of a type at once
with it; the results are bitwise equal to the per-joint assembly (``*_per_joint``, kept as the
reference). A model changed by ``dataclasses.replace`` (other joints or retained equations) gets
a matching plan built on demand.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Mapping

import numpy as np

from . import analysis
from .friction_laws import Law, make_law
from .joints import TYPES
from .kinematics import euler_H, euler_R  # noqa: F401  (re-exported, as before)
from .kinematics import cross2, cross3, cross3_rows, euler_H_rows, euler_R_rows, matvec
from .spec import BASE, COORDINATES, JOINT_FIELDS, MechanismSpec, SceneSpec


GLOBAL_COMPONENTS = {"planar": ("Fx0", "Fy0"), "spatial": ("Fx0", "Fy0", "Fz0")}
"""Reaction force components in the global frame pi_0, reported after the auxiliary-frame ones."""


class ModelError(ValueError):
    """A scene that parses but cannot be simulated as asked (e.g. a bad elimination)."""


class InconsistentInitialState(ModelError):
    """q0 or h0 off the constraint manifold (refused by :func:`compile_model`, so ``check``,
    ``simulate`` and ``build`` all refuse it with the same message)."""


class SingularConfiguration(ArithmeticError):
    """The retained constraint Jacobian lost rank (singular position), or a spring has zero length."""


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
    def module(self):
        return TYPES[self.type]


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
class Model:
    scene: SceneSpec
    kind: str
    dim: int  # 2 planar, 3 spatial
    nq_b: int  # coordinates per body
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
    elimination_mode: str  # "given" or "auto"
    friction_joints: tuple[int, ...]
    position_outputs: tuple[tuple[str, int], ...] = field(default=())  # (name, index into q)
    reaction_joints: tuple[int, ...] = field(default=())
    friction_outputs: tuple[int, ...] = field(default=())  # joints with a <joint>.friction output
    plan: "AssemblyPlan | None" = field(default=None, repr=False, compare=False)  # filled by compile_model

    @property
    def n(self) -> int:
        return self.nb * self.nq_b

    @property
    def nh(self) -> int:
        return self.nb * self.nq_b

    def body_slice(self, b: int) -> slice:
        return slice(b * self.nq_b, (b + 1) * self.nq_b)

    def output_names(self) -> list[str]:
        names = [name for name, _ in self.position_outputs]
        for j in self.reaction_joints:
            c = self.joints[j]
            names += [f"{c.name}.{comp}" for comp in c.components]
        names += [f"{self.joints[j].name}.friction" for j in self.friction_outputs]
        return names


@dataclass
class Frames:
    """Body frames of one evaluation; slot -1 (the last) is the base."""

    r: np.ndarray
    R: np.ndarray
    v: np.ndarray
    w: np.ndarray
    phi: np.ndarray | None = None  # planar angles
    angles: np.ndarray | None = None  # spatial Euler angles


def frames(model: Model, q: np.ndarray, h: np.ndarray | None = None) -> Frames:
    nb, d, k = model.nb, model.dim, model.nq_b
    Q = q.reshape(nb, k)
    H = np.zeros((nb, k)) if h is None else h.reshape(nb, k)
    r = np.zeros((nb + 1, d))
    r[:nb] = Q[:, :d]
    v = np.zeros((nb + 1, d))
    v[:nb] = H[:, :d]
    if model.kind == "planar":
        phi = np.zeros(nb + 1)
        phi[:nb] = Q[:, 2]
        c, s = np.cos(phi), np.sin(phi)
        R = np.empty((nb + 1, 2, 2))
        R[:, 0, 0], R[:, 0, 1], R[:, 1, 0], R[:, 1, 1] = c, -s, s, c
        w = np.zeros(nb + 1)
        w[:nb] = H[:, 2]
        return Frames(r=r, R=R, v=v, w=w, phi=phi)
    angles = np.zeros((nb + 1, 3))
    angles[:nb] = Q[:, 3:]
    R = euler_R_rows(angles)
    w = np.zeros((nb + 1, 3))
    w[:nb] = H[:, 3:]
    return Frames(r=r, R=R, v=v, w=w, angles=angles)


# ----------------------------------------------------------------------------- assembly

def _place(model: Model, out: np.ndarray, rows, blocks) -> None:
    (Ji, Jj), c = blocks
    for b, block in ((c.bi, Ji), (c.bj, Jj)):
        if b >= 0:
            out[np.ix_(rows, range(b * model.nq_b, (b + 1) * model.nq_b))] += block


def _stack_rows(model: Model, f: Frames, batch: str) -> np.ndarray:
    """(m,) vector from every joint type's ``batch_<name>`` rows, in equation order."""
    out = np.empty(model.m)
    for g in plan_of(model).groups:
        out[g.rows] = getattr(g.module, batch)(g.data, f).reshape(-1)
    return out


def constraints(model: Model, f: Frames) -> np.ndarray:
    """Phi (m,)."""
    return _stack_rows(model, f, "batch_phi")


def jacobian_q(model: Model, f: Frames) -> np.ndarray:
    """Phi_q (m, n), exact derivative by q."""
    out = np.zeros((model.m, model.n))
    for c in model.joints:
        _place(model, out, list(c.rows), (c.module.jac_q(c, f), c))
    return out


def jacobian_h(model: Model, f: Frames) -> np.ndarray:
    """Phi_h (m, nh): planar Phi_q, spatial the modified Jacobian of Eq. 7."""
    plan = plan_of(model)
    out = np.zeros((model.m, model.nh))
    flat = out.reshape(-1)
    for g in plan.groups:
        Ji, Jj = g.module.batch_jac_h(g.data, f)
        # += on zeros, in the order of _place (body i, then body j): the same numbers, -0.0 included
        flat[g.flat_i] += Ji[g.sel_i].reshape(-1)
        flat[g.flat_j] += Jj[g.sel_j].reshape(-1)
    return out


def gamma(model: Model, f: Frames) -> np.ndarray:
    """gamma (m,): Phi_h h' = gamma (Eq. 11)."""
    return _stack_rows(model, f, "batch_gamma")


def constraints_per_joint(model: Model, f: Frames) -> np.ndarray:
    """Reference of :func:`constraints`: joint by joint with the joints' ``phi``."""
    return np.concatenate([c.module.phi(c, f) for c in model.joints])


def jacobian_h_per_joint(model: Model, f: Frames) -> np.ndarray:
    """Reference of :func:`jacobian_h`: joint by joint with the joints' ``jac_h``."""
    out = np.zeros((model.m, model.nh))
    for c in model.joints:
        _place(model, out, list(c.rows), (c.module.jac_h(c, f), c))
    return out


def gamma_per_joint(model: Model, f: Frames) -> np.ndarray:
    """Reference of :func:`gamma`: joint by joint with the joints' ``gamma``."""
    return np.concatenate([c.module.gamma(c, f) for c in model.joints])


def coordinate_rates(model: Model, q: np.ndarray, h: np.ndarray) -> np.ndarray:
    """q' from (q, h): planar q' = h; spatial Euler rates = H omega (Eq. 4). Raises
    EulerSingularity near sin(beta) = 0."""
    if model.kind == "planar":
        return h.copy()
    nb = model.nb
    qd = h.copy()
    H = euler_H_rows(q.reshape(nb, 6)[:, 3:], model.body_names)
    qd.reshape(nb, 6)[:, 3:] = matvec(H, h.reshape(nb, 6)[:, 3:])
    return qd


def generalized_force(model: Model, f: Frames, b: int, point: np.ndarray, F: np.ndarray) -> np.ndarray:
    """Generalized force on body slot b of a global force F applied at a global point (the C_i
    matrices of App. A): planar [F, (p - r) x F]; spatial [F, s x (R^T F)] (torque in body axes)."""
    arm = point - f.r[b]
    if model.kind == "planar":
        return np.array([F[0], F[1], cross2(arm, F)])
    return np.concatenate([F, cross3(f.R[b].T @ arm, f.R[b].T @ F)])


def applied_forces(model: Model, f: Frames) -> np.ndarray:
    """Q (nh,): gravity, constant forces and torques, springs, gyroscopic terms -omega x J omega."""
    nb, d, k = model.nb, model.dim, model.nq_b
    Q = np.zeros((nb, k))
    Q[:, :d] = model.mass[:, None] * model.gravity[None, :]
    if model.kind == "spatial":
        Jw = model.inertia * f.w[:nb]
        Q[:, 3:] -= cross3_rows(f.w[:nb], Jw)
    for ld in model.loads:
        if ld.type == "force":
            Q[ld.bi, :d] += ld.value
        elif ld.type == "torque":
            Q[ld.bi, d:] += ld.value if model.kind == "planar" else f.R[ld.bi].T @ ld.value
        else:  # spring between two body points
            pi = f.r[ld.bi] + f.R[ld.bi] @ ld.s_i
            pj = f.r[ld.bj] + f.R[ld.bj] @ ld.s_j
            dvec = pi - pj
            length = float(np.linalg.norm(dvec))
            if length < 1e-12 * max(1.0, ld.free_length):
                raise SingularConfiguration("spring attachment points coincide: direction undefined")
            F = -ld.stiffness * (length - ld.free_length) * dvec / length
            for b, point, sign in ((ld.bi, pi, 1.0), (ld.bj, pj, -1.0)):
                if b >= 0:
                    Q[b] += generalized_force(model, f, b, point, sign * F)
    return Q.reshape(-1)


def reaction_on_body_i(model: Model, c: CompiledJoint, f: Frames, lam: np.ndarray) -> np.ndarray:
    """fi = (J_X)_i lam_X: left-hand-side generalized reaction of joint c on its body i."""
    Ji, _ = c.module.jac_h(c, f)
    return Ji.T @ lam[list(c.rows)]


def physical_reaction(model: Model, c: CompiledJoint, f: Frames, lam: np.ndarray) -> np.ndarray:
    """Physical reaction of joint c on body i: in its auxiliary frame, -A_i (J_X)_i lam_X
    (components ``REACTION_COMPONENTS`` of the joint type), followed by the force in the global
    frame pi_0 (components ``Fx0, Fy0(, Fz0)``: the paper's F^(0) of Eq. A.9, the frame of
    Fig. 7)."""
    fi = reaction_on_body_i(model, c, f, lam)
    local = c.module.reaction_transform(c, f) @ fi
    n_local = len(c.module.REACTION_COMPONENTS)
    return -np.concatenate([local[:n_local], fi[: model.dim]])


def friction_output(model: Model, c: CompiledJoint, f: Frames, lam: np.ndarray) -> float:
    """The friction output ``<joint>.friction`` of friction joint c (unit ``FRICTION_UNIT`` of
    the joint type): the joint module's ``friction_force`` at the multipliers lam. Sign
    convention (README "Conventions"): the friction on body i of the joint; translational:
    force along the guide x' (N), revolute: torque (N.m, counter-clockwise positive), both
    positive the way body j moves relative to body i; spherical: magnitude (N, >= 0)."""
    return float(c.module.friction_force(c, f, reaction_on_body_i(model, c, f, lam), c.law))


# ----------------------------------------------------------------------------- assembly plan

@dataclass(frozen=True, eq=False)
class JointGroup:
    """All joints of one type: the module's ``batch_prepare`` data and where their blocks go."""

    type: str
    data: Mapping[str, object]
    joints: tuple[int, ...]  # joint indices, in model order
    rows: np.ndarray  # (k * n_equations,) equation rows, joint by joint
    sel_i: np.ndarray  # positions (in the group) of the joints whose body i is not the base
    flat_i: np.ndarray  # flat indices into Phi_h (m, nh) of their (J_X)_i blocks, row-major
    sel_j: np.ndarray
    flat_j: np.ndarray

    @property
    def module(self):
        return TYPES[self.type]


@dataclass(frozen=True, eq=False)
class FrictionGroup:
    """The friction joints of one type: ``batch_prepare`` data (laws included), where their
    multipliers are read from lam_R and where their forces go in the contribution list."""

    type: str
    data: Mapping[str, object]
    joints: tuple[int, ...]
    lam_index: np.ndarray  # (k, n_equations) into lam_R extended by one 0.0 (eliminated rows)
    out_i: np.ndarray  # (k,) rows of Qi in the contribution list
    out_j: np.ndarray

    @property
    def module(self):
        return TYPES[self.type]


@dataclass(frozen=True, eq=False)
class AssemblyPlan:
    """Compile-time index data of the batched hot path (built by :func:`build_plan`)."""

    joints: tuple[CompiledJoint, ...]  # the model's joints and retained rows it was built for
    retained: np.ndarray
    nb: int
    nq_b: int
    groups: tuple[JointGroup, ...]
    friction: tuple[FrictionGroup, ...]
    friction_slots: np.ndarray  # (2 nf,) body slot per contribution (joint order; i then j; base -> nb)
    friction_xrows: np.ndarray  # positions in lam_R of the retained friction rows (joint order)
    friction_pad: bool  # some friction row is eliminated (read as 0.0)

    def matches(self, model: "Model") -> bool:
        return (self.joints is model.joints and self.retained is model.retained
                and self.nb == model.nb and self.nq_b == model.nq_b)


def build_plan(model: Model) -> AssemblyPlan:
    k, nh = model.nq_b, model.nh
    by_type: dict[str, list[int]] = {}
    for c in model.joints:
        by_type.setdefault(c.type, []).append(c.index)
    groups = []
    for jtype, idx in by_type.items():
        js = [model.joints[i] for i in idx]
        ne = len(js[0].rows)
        blocks = {}
        for side in ("i", "j"):
            sel, flat = [], []
            for pos, c in enumerate(js):
                b = c.bi if side == "i" else c.bj
                if b >= 0:
                    sel.append(pos)
                    rows = np.array(c.rows)[:, None]
                    flat.append((rows * nh + b * k + np.arange(k)[None, :]).reshape(-1))
            blocks[side] = (np.array(sel, np.intp),
                            np.concatenate(flat).astype(np.intp) if flat else np.zeros(0, np.intp))
        groups.append(JointGroup(
            type=jtype, data=TYPES[jtype].batch_prepare(js), joints=tuple(idx),
            rows=np.array([r for c in js for r in c.rows], np.intp),
            sel_i=blocks["i"][0], flat_i=blocks["i"][1], sel_j=blocks["j"][0], flat_j=blocks["j"][1]))
    retained = model.retained
    pos = {int(row): p for p, row in enumerate(retained)}
    pad = len(retained)  # index of the appended 0.0
    fjoints = [model.joints[j] for j in model.friction_joints]
    order = {c.index: n for n, c in enumerate(fjoints)}
    fr_types: dict[str, list] = {}
    for c in fjoints:
        fr_types.setdefault(c.type, []).append(c)
    friction = []
    for jtype, js in fr_types.items():
        friction.append(FrictionGroup(
            type=jtype, data=TYPES[jtype].batch_prepare(js), joints=tuple(c.index for c in js),
            lam_index=np.array([[pos.get(r, pad) for r in c.rows] for c in js], np.intp),
            out_i=np.array([2 * order[c.index] for c in js], np.intp),
            out_j=np.array([2 * order[c.index] + 1 for c in js], np.intp)))
    slots = [b if b >= 0 else model.nb for c in fjoints for b in (c.bi, c.bj)]
    xrows = [pos[r] for c in fjoints for r in c.rows if r in pos]
    return AssemblyPlan(
        joints=model.joints, retained=retained, nb=model.nb, nq_b=k, groups=tuple(groups),
        friction=tuple(friction), friction_slots=np.array(slots, np.intp),
        friction_xrows=np.array(xrows, np.intp),
        friction_pad=any(r not in pos for c in fjoints for r in c.rows))


_PLAN_CACHE: dict = {}


def plan_of(model: Model) -> AssemblyPlan:
    """The model's assembly plan; built (and cached) when the model has none that matches."""
    plan = model.plan
    if plan is not None and plan.matches(model):
        return plan
    key = (id(model.joints), id(model.retained), model.nb, model.nq_b)
    plan = _PLAN_CACHE.get(key)
    if plan is None or not plan.matches(model):
        if len(_PLAN_CACHE) >= 16:
            _PLAN_CACHE.clear()
        plan = _PLAN_CACHE[key] = build_plan(model)  # holds joints/retained: ids stay valid
    return plan


# ----------------------------------------------------------------------------- compile

def compile_model(scene: SceneSpec, *, check_initial: bool = True) -> Model:
    """Compile a validated scene. Raises ModelError for an elimination the mechanism does not
    admit (removing an independent equation, or leaving dependent ones), naming the equations,
    and :class:`InconsistentInitialState` for q0/h0 off the constraints (before the elimination
    is checked: a rank at an inconsistent q0 means nothing). ``check_initial=False`` skips that
    check: only for evaluating kinematics at arbitrary configurations (tests); a Simulation
    checks again."""
    mech: MechanismSpec = scene.mechanism
    kind = mech.kind
    dim = 2 if kind == "planar" else 3
    k = 3 if kind == "planar" else 6
    names = tuple(b.name for b in mech.bodies)
    slot = {name: i for i, name in enumerate(names)}
    slot[BASE] = -1
    nb = len(names)
    mass = np.array([b.mass for b in mech.bodies], float)
    inertia = np.array([b.inertia for b in mech.bodies], float).reshape(nb, -1)
    M = np.concatenate([np.concatenate([np.full(dim, mass[i]), inertia[i]]) for i in range(nb)])
    friction_on = set(scene.friction)
    joints = []
    row = 0
    for idx, js in enumerate(mech.joints):
        ne = JOINT_FIELDS[js.type]["n_equations"]
        law = None
        if js.name in friction_on:
            fspec = scene.friction_params.get(js.name, js.friction)
            law = make_law(fspec)
        joints.append(CompiledJoint(
            name=js.name, type=js.type, index=idx, bi=slot[js.body_i], bj=slot[js.body_j],
            rows=tuple(range(row, row + ne)), p=TYPES[js.type].prepare(js.params), law=law,
            components=TYPES[js.type].REACTION_COMPONENTS + GLOBAL_COMPONENTS[kind]))
        row += ne
    loads = []
    for ld in mech.loads:
        p = ld.params
        if ld.type in ("force", "torque"):
            loads.append(CompiledLoad(ld.type, slot[p["body"]], -1, value=np.asarray(p["value"], float)))
        else:
            zero = np.zeros(dim)
            loads.append(CompiledLoad(
                "spring", slot[p["body_i"]], slot[p["body_j"]], stiffness=float(p["stiffness"]),
                free_length=float(p["free_length"]),
                s_i=zero if p.get("s_i") is None else np.asarray(p["s_i"], float),
                s_j=zero if p.get("s_j") is None else np.asarray(p["s_j"], float)))
    q0 = np.concatenate([np.asarray(b.q0, float) for b in mech.bodies])
    h0 = np.concatenate([np.asarray(b.h0, float) for b in mech.bodies])
    coord_index = {}
    for b, name in enumerate(names):
        for i, cname in enumerate(COORDINATES[kind]):
            coord_index[f"{name}.{cname}"] = b * k + i
    joint_index = {c.name: c.index for c in joints}
    base = Model(
        scene=scene, kind=kind, dim=dim, nq_b=k, nb=nb, body_names=names, mass=mass,
        inertia=inertia, M=M, Minv=1.0 / M, gravity=np.asarray(mech.gravity, float),
        joints=tuple(joints), loads=tuple(loads), q0=q0, h0=h0, m=row,
        retained=np.arange(row), eliminated=(), elimination_mode="given",
        friction_joints=tuple(c.index for c in joints if c.law is not None),
        position_outputs=tuple((p, coord_index[p]) for p in scene.positions),
        reaction_joints=tuple(joint_index[j] for j in scene.reactions),
        friction_outputs=tuple(joint_index[j] for j in
                               (scene.friction if scene.friction_outputs == "all" else scene.friction_outputs)),
    )
    if check_initial:
        check_initial_state(base)
    eliminated, mode = resolve_elimination(base, scene.eliminate)
    retained = np.array([i for i in range(row) if i + 1 not in set(eliminated)], int)
    model = replace(base, retained=retained, eliminated=tuple(eliminated), elimination_mode=mode)
    return replace(model, plan=build_plan(model))


def check_initial_state(model: Model, tol: float = 1e-9) -> None:
    """Refuse q0/h0 off the constraint manifold: |Phi| or |Phi_h h0| above tol (m or rad; m/s
    or rad/s), scaled by max(1, max |q0|) (max(1, max |h0|)); a non-finite value is refused too.
    Raises :class:`InconsistentInitialState` naming the violated equations."""
    f = frames(model, model.q0, model.h0)
    with np.errstate(all="ignore"):
        Phi = constraints(model, f)
        scale = max(1.0, float(np.max(np.abs(model.q0))))
        bad = [i + 1 for i in np.flatnonzero(~(np.abs(Phi) <= tol * scale))]
        if bad:
            absphi = np.where(np.isfinite(Phi), np.abs(Phi), np.inf)
            worst = int(np.argmax(absphi))
            raise InconsistentInitialState(
                "initial coordinates q0 violate the constraints "
                + ", ".join(f"Phi{i}" for i in bad)
                + f" (largest |Phi{worst + 1}| = {abs(Phi[worst]):.3g})")
        vel = jacobian_h(model, f) @ model.h0
        hscale = max(1.0, float(np.max(np.abs(model.h0))))
        bad = [i + 1 for i in np.flatnonzero(~(np.abs(vel) <= tol * hscale))]
    if bad:
        raise InconsistentInitialState(
            "initial velocities h0 violate the velocity constraints " + ", ".join(f"Phi{i}" for i in bad))


def resolve_elimination(model: Model, eliminate) -> tuple[list[int], str]:
    """Check (or choose, for "auto") the eliminated equations at q0. Returns 1-based indices."""
    f = frames(model, model.q0, model.h0)
    J = jacobian_h(model, f).T
    r = analysis.numerical_rank(J)
    if eliminate == "auto":
        removed = sorted(i + 1 for i in analysis.auto_eliminate(J))
        return removed, "auto"
    removed = sorted(eliminate)
    kept = [i for i in range(model.m) if i + 1 not in set(removed)]
    r_kept = analysis.numerical_rank(J[:, kept]) if kept else 0
    listed = ", ".join(f"Phi{i}" for i in removed) or "nothing"
    if r_kept < r:
        raise ModelError(
            f"eliminating {listed} removes an independent equation: rank of the kept equations is "
            f"{r_kept} < rank {r} of all {model.m}; the mechanism would gain {r - r_kept} DOF")
    if r_kept < len(kept):
        raise ModelError(
            f"eliminating {listed} leaves {len(kept)} equations of rank {r_kept}: "
            f"{len(kept) - r_kept} more must be eliminated (the mechanism has {model.m - r} redundant)")
    return removed, "given"
