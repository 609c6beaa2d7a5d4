"""Planar revolute joint (paper Eq. 36; friction App. A.5-A.8).

Phi = r_i + R_i s_i - r_j - R_j s_j. Auxiliary frame: origin at the joint point P, axes parallel
to body i. Physical reaction p' = [Fx, Fy, T] (T = 0 for a revolute joint). Friction: a torque
a mu(omega_ij) sqrt(Fx^2 + Fy^2) on body i (minus on body j), omega_ij = phi_j' - phi_i'.

All functions are batched (k joints at once): see :mod:`overcon.joints`; the type's facts are
its entry in :data:`overcon.joints.TYPES`.
"""
from __future__ import annotations

import math

import numpy as np

from ..kinematics import OMEGA, matvec
from .point import arms, constants, phi, stack_points


def stack(joints) -> dict:
    """Constant stacked arrays of a list of compiled revolute joints (done once at compile)."""
    return stack_points(joints, 2)


def jac_h(d, f):
    """(Ji, Jj), each (k, 2, 3): Phi_q = Phi_h (planar), [I, OMEGA R_i s_i] and
    [-I, -OMEGA R_j s_j]."""
    a_i, a_j = arms(d, f)
    ti = matvec(OMEGA, a_i)
    tj = matvec(OMEGA, a_j)
    k = len(ti)
    Ji = np.zeros((k, 2, 3))
    Jj = np.zeros((k, 2, 3))
    Ji[:, 0, 0] = Ji[:, 1, 1] = 1.0
    Jj[:, 0, 0] = Jj[:, 1, 1] = -1.0
    Ji[:, :, 2] = ti
    Jj[:, :, 2] = -tj
    return Ji, Jj


def gamma(d, f):
    """(k, 2): R_i s_i w_i^2 - R_j s_j w_j^2 (Eq. 11)."""
    bi, bj = d["bi"], d["bj"]
    a_i, a_j = arms(d, f)
    return a_i * (f.w[bi] ** 2)[:, None] - a_j * (f.w[bj] ** 2)[:, None]


def reaction_transform(d, f):
    """(k, 3, 3): A_i of Eq. (A.5)."""
    Ri = f.R[d["bi"]]
    A = np.zeros((len(Ri), 3, 3))
    A[:, :2, :2] = Ri.transpose(0, 2, 1)
    A[:, 2, :2] = -matvec(OMEGA, arms(d, f)[0])
    A[:, 2, 2] = 1.0
    return A


def reaction(d, f, fi):
    """(k, 3): the physical reaction [Fx, Fy, T] = -A_i fi in the auxiliary frame (T = 0)."""
    return -matvec(reaction_transform(d, f), fi)


def friction_setup(d, f, Ji=None):
    """Per-evaluation constants of :func:`friction`: (J_X)_i, A_i and size * mu(omega_ij),
    omega_ij = phi_j' - phi_i' the relative angular velocity of body j."""
    if Ji is None:
        Ji = jac_h(d, f)[0]
    speed = f.w[d["bj"]] - f.w[d["bi"]]
    return {"JiT": Ji.transpose(0, 2, 1), "A": reaction_transform(d, f),
            "size_mu": [law.size * law.coefficient(v) for law, v in zip(d["laws"], speed)]}


def friction_force(d, ctx, lam):
    """(k,): friction torque on body i (N.m), counter-clockwise positive (A.6): a mu(omega_ij)
    sqrt(Fx^2 + Fy^2); it turns body i the way body j turns relative to it."""
    p_aux = matvec(ctx["A"], matvec(ctx["JiT"], lam))
    return np.array([sm * math.hypot(p[0], p[1]) for sm, p in zip(ctx["size_mu"], p_aux)], float)


def friction(d, ctx, lam):
    """(Qi, Qj), each (k, 3): the friction torque (A.6-A.8) on body i and its opposite on body j
    (C_i = C_j = I), given the joints' multipliers lam (k, 2) (fi = (J_X)_i^T lam)."""
    torque = friction_force(d, ctx, lam)
    k = len(torque)
    Qi = np.zeros((k, 3))
    Qj = np.zeros((k, 3))
    Qi[:, 2] = torque
    Qj[:, 2] = -Qi[:, 2]
    return Qi, Qj


def friction_jacobian(d, ctx, lam):
    """(dQi, dQj), each (k, 3, 2): derivatives of :func:`friction`'s (Qi, Qj) by the joints'
    multipliers lam (k, 2) (N.m per N), for the friction solve's Newton step; zero where the
    reaction force is zero (the norm has no derivative there)."""
    P = np.matmul(ctx["A"], ctx["JiT"])[:, :2]  # (k, 2, 2): [Fx, Fy] = P lam
    p = matvec(P, lam)
    norm = np.hypot(p[:, 0], p[:, 1])
    scale = np.array(ctx["size_mu"], float) / np.where(norm > 0.0, norm, 1.0)
    scale[norm == 0.0] = 0.0
    dT = scale[:, None] * (p[:, 0:1] * P[:, 0] + p[:, 1:2] * P[:, 1])  # (k, 2)
    dQi = np.zeros((len(p), 3, 2))
    dQi[:, 2] = dT
    return dQi, -dQi
