"""Evaluate a compiled :class:`overcon.model.Model` at (q, h): body frames, constraints Phi, the
Jacobian Phi_h, gamma, applied loads, coordinate rates and the reported reactions and friction
forces. :mod:`overcon.model` compiles; this module only evaluates (nothing here changes a Model).

Glossary and sign convention: :mod:`overcon.model`. Every joint term comes from the joint type's
batched producer module (:mod:`overcon.joints`), called once per joint type with the stacked
constants and scatter indices of ``Model.plan`` (built at compile time).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from .kinematics import (cos_sin, cross2, cross3, cross3_rows, euler_H_rows, euler_R_rows, matvec, quat_R_rows, rot2_rows, rowdot,
                         quat_rates_rows)

if TYPE_CHECKING:  # type names only: model stays below this module in the import order
    from .model import CompiledJoint, Model


class SingularConfiguration(ArithmeticError):
    """The retained constraint Jacobian lost rank (singular position), or the attachment points of a
    spring with a positive free length coincide (its force has no direction)."""


@dataclass
class Frames:
    """Body frames of one evaluation; slot -1 (the last) is the base."""

    r: np.ndarray
    R: np.ndarray
    v: np.ndarray
    w: np.ndarray
    phi: np.ndarray | None = None  # planar angles
    angles: np.ndarray | None = None  # spatial Euler angles (rotation "euler_zxz")
    quat: np.ndarray | None = None  # spatial quaternions as in q (rotation "quaternion"; R uses e / |e|)
    memo: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    def cached(self, name: str, d, compute):
        """``compute(d, self)`` once for these frames and the stacked joint constants ``d`` (the
        same object): geometry that several producers of one joint group need in one evaluation
        (phi, jac_h, gamma, the reaction frame), computed once with the same operations, so the
        same bits. The frames must not be changed after a call; callers must not write into the
        result."""
        key = (name, id(d))
        hit = self.memo.get(key)
        if hit is None or hit[0] is not d:
            hit = self.memo[key] = (d, compute(d, self))
        return hit[1]


def frames(model: Model, q: np.ndarray, h: np.ndarray | None = None) -> Frames:
    """Body frames at q (n,) and h (nh,; zeros if None): origins r (m), R body -> global,
    v (global, m/s), w (planar rad/s; spatial body axes, rad/s). A quaternion body's R is built
    from e / |e| (:func:`overcon.kinematics.quat_R_rows`)."""
    nb, d, k = model.nb, model.dim, model.nq_b
    Q = q.reshape(nb, k)
    H = np.zeros((nb, model.nh_b)) if h is None else h.reshape(nb, model.nh_b)
    r = np.zeros((nb + 1, d))
    r[:nb] = Q[:, :d]
    v = np.zeros((nb + 1, d))
    v[:nb] = H[:, :d]
    if model.kind == "planar":
        phi = np.zeros(nb + 1)
        phi[:nb] = Q[:, 2]
        R = rot2_rows(phi)
        w = np.zeros(nb + 1)
        w[:nb] = H[:, 2]
        return Frames(r=r, R=R, v=v, w=w, phi=phi)
    w = np.zeros((nb + 1, 3))
    w[:nb] = H[:, 3:]
    if model.rotation == "quaternion":
        quat = np.zeros((nb + 1, 4))
        quat[:nb] = Q[:, 3:]
        quat[nb, 0] = 1.0  # the base: identity
        return Frames(r=r, R=quat_R_rows(quat), v=v, w=w, quat=quat)
    angles = np.zeros((nb + 1, 3))
    angles[:nb] = Q[:, 3:]
    cs = cos_sin(angles)
    f = Frames(r=r, R=euler_R_rows(angles, cs), v=v, w=w, angles=angles)
    f.memo["euler.cos_sin"] = cs  # for coordinate_rates at the same q
    return f


def _stack_rows(model: Model, f: Frames, name: str) -> np.ndarray:
    """(m,) vector from every joint type's ``<name>`` rows, in equation order."""
    out = np.empty(model.m)
    for g in model.plan.groups:
        out[g.rows] = getattr(g.module, name)(g.data, f).reshape(-1)
    return out


def constraints(model: Model, f: Frames) -> np.ndarray:
    """Phi (m,)."""
    return _stack_rows(model, f, "phi")


def jacobian_h(model: Model, f: Frames) -> np.ndarray:
    """Phi_h (m, nh): planar Phi_q, spatial the modified Jacobian of Eq. 7."""
    return jacobian_h_blocks(model, f)[0]


def jacobian_h_blocks(model: Model, f: Frames) -> tuple[np.ndarray, list]:
    """Phi_h (m, nh) as :func:`jacobian_h`, and the (J_X)_i blocks (k, n_eq, n_coord) of every
    joint group (``model.plan.groups`` order), from the same ``jac_h`` calls (for the friction
    setup, which needs them again)."""
    out = np.zeros((model.m, model.nh))
    flat = out.reshape(-1)
    blocks_i = []
    for g in model.plan.groups:
        Ji, Jj = g.module.jac_h(g.data, f)
        # += on zeros, body i then body j (the per-joint assembly's order): -0.0 kept
        flat[g.flat_i] += Ji[g.sel_i].reshape(-1)
        flat[g.flat_j] += Jj[g.sel_j].reshape(-1)
        blocks_i.append(Ji)
    return out, blocks_i


def gamma(model: Model, f: Frames) -> np.ndarray:
    """gamma (m,): Phi_h h' = gamma (Eq. 11)."""
    return _stack_rows(model, f, "gamma")


def coordinate_rates(model: Model, q: np.ndarray, h: np.ndarray, f: Frames | None = None) -> np.ndarray:
    """q' (n,) from q (n,) and h (nh,): planar q' = h; spatial r' = v and Euler rates = H omega
    (Eq. 4; raises EulerSingularity near sin(beta) = 0) or quaternion rates
    e' = 1/2 e (x) (0, omega) + the norm stabilisation along e
    (:func:`overcon.kinematics.quat_rates_rows`; omega in body axes). ``f``: the frames at this
    q, if already built (their cosines and sines of the Euler angles are reused)."""
    if model.kind == "planar":
        return h.copy()
    nb = model.nb
    if model.rotation == "quaternion":
        Q, H = q.reshape(nb, 7), h.reshape(nb, 6)
        qd = np.empty((nb, 7))
        qd[:, :3] = H[:, :3]
        qd[:, 3:] = quat_rates_rows(Q[:, 3:], H[:, 3:])
        return qd.reshape(-1)
    qd = h.copy()
    cs = None if f is None else f.memo.get("euler.cos_sin")
    if cs is not None:
        cs = (cs[0][:nb, 1:], cs[1][:nb, 1:])
    H = euler_H_rows(q.reshape(nb, 6)[:, 3:], model.body_names, cs)
    qd.reshape(nb, 6)[:, 3:] = matvec(H, h.reshape(nb, 6)[:, 3:])
    return qd


def generalized_force(model: Model, f: Frames, b: int, point: np.ndarray, F: np.ndarray) -> np.ndarray:
    """Generalized force on body slot b of a global force F applied at a global point (the C_i
    matrices of App. A): planar [F, (p - r) x F]; spatial [F, s x (R^T F)] (torque in body axes)."""
    arm = point - f.r[b]
    if model.kind == "planar":
        return np.array([F[0], F[1], cross2(arm, F)])
    return np.concatenate([F, cross3(f.R[b].T @ arm, f.R[b].T @ F)])


def spring_points(f: Frames, ld) -> tuple[np.ndarray, np.ndarray]:
    """The global attachment points (m) of spring load ``ld`` on its bodies i and j."""
    return f.r[ld.bi] + f.R[ld.bi] @ ld.s_i, f.r[ld.bj] + f.R[ld.bj] @ ld.s_j


def kinetic_energy(model: Model, h: np.ndarray) -> float:
    """1/2 h^T M h (J): M is diagonal in h (mass for the translational entries, the principal
    inertias for the angular velocities in body axes)."""
    return 0.5 * float(np.dot(model.M * h, h))


def potential_energy(model: Model, f: Frames) -> float:
    """Potential energy (J) of gravity, -sum m_b g . r_b (zero at the global origin), and of the
    springs, 1/2 k (|d| - l0)^2. Constant forces and torques are not counted (their work is not
    part of this output)."""
    nb = model.nb
    energy = -float(np.dot(model.mass, f.r[:nb] @ model.gravity))
    for ld in model.loads:
        if ld.type == "spring":
            pi, pj = spring_points(f, ld)
            stretch = float(np.linalg.norm(pi - pj)) - ld.free_length
            energy += 0.5 * ld.stiffness * stretch * stretch
    return energy


def compliant_energy(model: Model, f: Frames, h: np.ndarray) -> tuple[float, float]:
    """(elastic energy (J), damper power (W, >= 0)) of the compliant joints (redundancy
    "compliant") at the frames f and velocities h (nh,): the force law of
    :func:`overcon.dynamics._compliant_solve`, lam = k Phi + d Phi_h h on the scalar rows, is the
    spring of energy 1/2 k Phi^2 and the damper of power d (Phi_h h)^2; a per-axis joint
    (:class:`overcon.model.AxisCompliance`) has 1/2 sum_x k_x (F^T U Phi)_x^2 and
    sum_x d_x (F^T U Phi_h h)_x^2, the deformation and its rate in its joint frame. The C core's
    ``ovk_compliant_energy`` (core/energy.c) is the same formula. (0, 0)
    without compliant rows."""
    if not model.compliant_rows.size:
        return 0.0, 0.0
    Phi, PR = constraints(model, f), jacobian_h(model, f)[model.retained]
    rate = PR @ h
    elastic = damping = 0.0
    for p, row in enumerate(model.retained):
        k, d = float(model.row_stiffness[row]), float(model.row_damping[row])
        if k or d:
            elastic += 0.5 * k * float(Phi[row]) ** 2
            damping += d * float(rate[p]) ** 2
    kh = model.nh_b
    for ax in model.compliance_axes:
        F = f.R[ax.bi] @ ax.frame
        b = ax.bi if ax.bi >= 0 else ax.bj
        for rows, kv, dv, rot in ((ax.t_rows, ax.k_t, ax.d_t, False), (ax.r_rows, ax.k_r, ax.d_r, True)):
            if not rows:
                continue
            pos = np.searchsorted(model.retained, rows)
            U = f.R[b] @ PR[pos, b * kh + 3:b * kh + 6].T if rot else PR[pos, b * kh:b * kh + 3].T
            FU = F.T @ U
            dx, vx = FU @ Phi[list(rows)], FU @ rate[pos]
            elastic += float(0.5 * np.sum(kv * dx * dx))
            damping += float(np.sum(dv * vx * vx))
    return elastic, damping


def applied_forces(model: Model, f: Frames) -> np.ndarray:
    """Q (nh,): gravity, constant forces and torques, springs, gyroscopic terms -omega x J omega."""
    nb, d, k = model.nb, model.dim, model.nh_b
    Q = np.zeros((nb, k))
    Q[:, :d] = model.mass[:, None] * model.gravity[None, :]
    if model.kind == "spatial":
        Jw = model.inertia * f.w[:nb]
        Q[:, 3:] -= cross3_rows(f.w[:nb], Jw)
    for n, ld in enumerate(model.loads):
        if ld.type in ("force", "torque"):
            _add_constant_load(model, f, ld, Q)
        else:  # spring between two body points
            pi, pj = spring_points(f, ld)
            dvec = pi - pj
            if ld.free_length == 0.0:  # -k (|d| - 0) d / |d| = -k d: defined at coinciding points too
                F = -ld.stiffness * dvec
            else:
                length = float(np.linalg.norm(dvec))
                if length < 1e-12 * ld.free_length:
                    raise SingularConfiguration(
                        f"spring loads[{n}] ({_body_name(model, ld.bi)} - {_body_name(model, ld.bj)}): its "
                        f"attachment points coincide while its free length is {ld.free_length:g} m: the "
                        "direction of its force is undefined")
                F = -ld.stiffness * (length - ld.free_length) * dvec / length
            for b, point, sign in ((ld.bi, pi, 1.0), (ld.bj, pj, -1.0)):
                if b >= 0:
                    Q[b] += generalized_force(model, f, b, point, sign * F)
    return Q.reshape(-1)


def _add_constant_load(model: Model, f: Frames, ld, Q: np.ndarray) -> None:
    """Add a constant force (global frame, at the centre of mass) or torque (planar; spatial: global
    frame, to body axes) ``ld`` to Q (nb, nh_b)."""
    d = model.dim
    if ld.type == "force":
        Q[ld.bi, :d] += ld.value
    else:
        Q[ld.bi, d:] += ld.value if model.kind == "planar" else f.R[ld.bi].T @ ld.value


def constant_loads(model: Model, f: Frames) -> np.ndarray:
    """Q (nh,) of the constant forces and torques alone: the loads whose work is
    ``energy.applied`` (gravity and springs have a potential instead)."""
    Q = np.zeros((model.nb, model.nh_b))
    for ld in model.loads:
        if ld.type in ("force", "torque"):
            _add_constant_load(model, f, ld, Q)
    return Q.reshape(-1)


def _body_name(model: Model, b: int) -> str:
    return "base" if b < 0 else model.body_names[b]


def normalized_coordinates(model: Model, q: np.ndarray) -> np.ndarray:
    """q (n,) with every quaternion replaced by e / |e| (the orientation the dynamics use, and
    what the position outputs report); other coordinates unchanged (a copy)."""
    out = np.array(q, float)
    if model.rotation == "quaternion":
        E = out.reshape(model.nb, 7)[:, 3:]
        E /= np.sqrt(rowdot(E, E))[:, None]
    return out


# ----------------------------------------------------------------------------- reported values

def _one(model: Model, c: CompiledJoint):
    """The joint's producer module and its constants as a batch of one (from ``Model.plan``)."""
    return c.module, model.plan.single[c.index]


def _rows(c: CompiledJoint, lam: np.ndarray) -> np.ndarray:
    return lam[list(c.rows)][None, :]


def reaction_on_body_i(model: Model, c: CompiledJoint, f: Frames, lam: np.ndarray) -> np.ndarray:
    """fi = (J_X)_i^T lam_X (n_coord,): left-hand-side generalized reaction of joint c on its
    body i."""
    mod, d = _one(model, c)
    Ji = mod.jac_h(d, f)[0]
    return matvec(Ji.transpose(0, 2, 1), _rows(c, lam))[0]


def physical_reactions(module, data, f: Frames, lam_rows: np.ndarray, dim: int) -> np.ndarray:
    """(k, n_components + dim): the physical reactions of k joints of one type (``module`` and
    its stacked constants ``data``) at their multipliers lam_rows (k, n_equations): in each
    joint's auxiliary frame -A_i fi (the module's ``reaction``), then the force -fi[:dim] in the
    global frame pi_0, fi = (J_X)_i^T lam_X."""
    Ji = module.jac_h(data, f)[0]
    fi = matvec(Ji.transpose(0, 2, 1), lam_rows)
    return np.concatenate((module.reaction(data, f, fi), -fi[:, :dim]), 1)


def physical_reaction(model: Model, c: CompiledJoint, f: Frames, lam: np.ndarray) -> np.ndarray:
    """Physical reaction of joint c on body i: in its auxiliary frame, -A_i (J_X)_i lam_X
    (components ``reaction`` of the joint type, from the joint module's ``reaction``), followed
    by the force in the global frame pi_0 (components ``Fx0, Fy0(, Fz0)``: the paper's F^(0) of
    Eq. A.9, the frame of Fig. 7); :func:`physical_reactions` of a batch of one."""
    mod, d = _one(model, c)
    return physical_reactions(mod, d, f, _rows(c, lam), model.dim)[0]


def friction_output(model: Model, c: CompiledJoint, f: Frames, lam: np.ndarray) -> float:
    """The friction output ``<joint>.friction`` of friction joint c (unit ``friction_unit`` of
    the joint type): the joint module's ``friction_force`` at the multipliers lam. Sign
    convention (README "Conventions"): the friction on body i of the joint; translational:
    force along the guide x' (N), revolute: torque (N.m, counter-clockwise positive), both
    positive the way body j moves relative to body i; spherical: magnitude (N, >= 0)."""
    mod, d = _one(model, c)
    ctx = mod.friction_setup(d, f)
    return float(mod.friction_force(d, ctx, _rows(c, lam))[0])
