"""Planar revolute joint (paper Eq. 36; friction App. A.5-A.8).

Phi = r_i + R_i s_i - r_j - R_j s_j. Auxiliary frame: origin at the joint point P, axes parallel
to body i. Physical reaction p' = [Fx, Fy, T] (T = 0 for a revolute joint). Friction: a torque
a mu(omega_ij) sqrt(Fx^2 + Fy^2) on body i (minus on body j), omega_ij = phi_j' - phi_i'.

Batched forms ``batch_*``: see :mod:`overcon.joints`.
"""
from __future__ import annotations

import math

import numpy as np

from ..kinematics import OMEGA, matvec
from .point import batch_phi, phi, prepare  # noqa: F401  (point coincidence, Eq. 36/41)

N_EQUATIONS = 2
REACTION_COMPONENTS = ("Fx", "Fy", "T")
FRICTION_UNIT = "N.m"  # friction_force: torque


def jac_q(c, f):
    ti = OMEGA @ (f.R[c.bi] @ c.p["s_i"])
    tj = OMEGA @ (f.R[c.bj] @ c.p["s_j"])
    Ji = np.array([[1.0, 0.0, ti[0]], [0.0, 1.0, ti[1]]])
    Jj = np.array([[-1.0, 0.0, -tj[0]], [0.0, -1.0, -tj[1]]])
    return Ji, Jj


jac_h = jac_q


def gamma(c, f):
    return (f.R[c.bi] @ c.p["s_i"]) * f.w[c.bi] ** 2 - (f.R[c.bj] @ c.p["s_j"]) * f.w[c.bj] ** 2


def reaction_transform(c, f):
    """A_i of Eq. (A.5)."""
    Ri = f.R[c.bi]
    A = np.zeros((3, 3))
    A[:2, :2] = Ri.T
    A[2, :2] = -(OMEGA @ (Ri @ c.p["s_i"]))
    A[2, 2] = 1.0
    return A


def relative_speed(c, f):
    """Relative angular velocity of body j with respect to body i (rad/s)."""
    return f.w[c.bj] - f.w[c.bi]


def friction_force(c, f, fi, law) -> float:
    """Friction torque on body i (N.m), counter-clockwise positive (A.6): a mu(omega_ij)
    sqrt(Fx^2 + Fy^2); it turns body i the way body j turns relative to it."""
    p_aux = reaction_transform(c, f) @ fi
    return law.size * law.mu(relative_speed(c, f)) * math.hypot(p_aux[0], p_aux[1])


def friction(c, f, fi, law):
    """Friction torque (A.6-A.8): C_i = C_j = I."""
    torque = friction_force(c, f, fi, law)
    return np.array([0.0, 0.0, torque]), np.array([0.0, 0.0, -torque])


# ----------------------------------------------------------------------------- batched forms

def batch_prepare(joints) -> dict:
    """Constant stacked arrays of a list of compiled revolute joints (done once at compile)."""
    laws = tuple(c.law for c in joints)
    return {
        "bi": np.array([c.bi for c in joints], np.intp), "bj": np.array([c.bj for c in joints], np.intp),
        "s_i": np.array([c.p["s_i"] for c in joints], float).reshape(-1, 2),
        "s_j": np.array([c.p["s_j"] for c in joints], float).reshape(-1, 2),
        "laws": laws,
    }


def batch_jac_q(d, f):
    """(Ji, Jj), each (k, 2, 3): :func:`jac_q` of every joint."""
    ti = matvec(OMEGA, matvec(f.R[d["bi"]], d["s_i"]))
    tj = matvec(OMEGA, matvec(f.R[d["bj"]], d["s_j"]))
    k = len(ti)
    Ji = np.zeros((k, 2, 3))
    Jj = np.zeros((k, 2, 3))
    Ji[:, 0, 0] = Ji[:, 1, 1] = 1.0
    Jj[:, 0, 0] = Jj[:, 1, 1] = -1.0
    Ji[:, :, 2] = ti
    Jj[:, :, 2] = -tj
    return Ji, Jj


batch_jac_h = batch_jac_q


def batch_gamma(d, f):
    """(k, 2): :func:`gamma` of every joint."""
    bi, bj = d["bi"], d["bj"]
    return (matvec(f.R[bi], d["s_i"]) * (f.w[bi] ** 2)[:, None]
            - matvec(f.R[bj], d["s_j"]) * (f.w[bj] ** 2)[:, None])


def batch_reaction_transform(d, f):
    """(k, 3, 3): :func:`reaction_transform` of every joint."""
    Ri = f.R[d["bi"]]
    A = np.zeros((len(Ri), 3, 3))
    A[:, :2, :2] = Ri.transpose(0, 2, 1)
    A[:, 2, :2] = -matvec(OMEGA, matvec(Ri, d["s_i"]))
    A[:, 2, 2] = 1.0
    return A


def batch_friction_setup(d, f, Ji=None):
    """Per-evaluation constants of :func:`batch_friction`: (J_X)_i, A_i and size * mu(omega_ij)."""
    if Ji is None:
        Ji = batch_jac_h(d, f)[0]
    speed = f.w[d["bj"]] - f.w[d["bi"]]  # relative_speed
    return {"JiT": Ji.transpose(0, 2, 1), "A": batch_reaction_transform(d, f),
            "size_mu": [law.size * law.mu(v) for law, v in zip(d["laws"], speed)]}


def batch_friction(d, ctx, lam):
    """(Qi, Qj), each (k, 3): :func:`friction` of every joint, given the joints' multipliers lam
    (k, 2) (fi = (J_X)_i^T lam)."""
    p_aux = matvec(ctx["A"], matvec(ctx["JiT"], lam))
    k = len(p_aux)
    Qi = np.zeros((k, 3))
    Qj = np.zeros((k, 3))
    Qi[:, 2] = [sm * math.hypot(p[0], p[1]) for sm, p in zip(ctx["size_mu"], p_aux)]
    Qj[:, 2] = -Qi[:, 2]
    return Qi, Qj
