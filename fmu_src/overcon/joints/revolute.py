"""Planar revolute joint (paper Eq. 36; friction App. A.5-A.8).

Phi = r_i + R_i s_i - r_j - R_j s_j. Auxiliary frame: origin at the joint point P, axes parallel
to body i. Physical reaction p' = [Fx, Fy, T] (T = 0 for a revolute joint). Friction: a torque
a mu(omega_ij) sqrt(Fx^2 + Fy^2) on body i (minus on body j), omega_ij = phi_j' - phi_i'.
"""
from __future__ import annotations

import math

import numpy as np

from ..kinematics import OMEGA

N_EQUATIONS = 2
REACTION_COMPONENTS = ("Fx", "Fy", "T")


def prepare(params) -> dict:
    return {"s_i": np.asarray(params["s_i"], float), "s_j": np.asarray(params["s_j"], float)}


def phi(c, f):
    return f.r[c.bi] + f.R[c.bi] @ c.p["s_i"] - f.r[c.bj] - f.R[c.bj] @ c.p["s_j"]


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


def friction(c, f, fi, law):
    """Friction torque (A.6-A.8): C_i = C_j = I."""
    p_aux = reaction_transform(c, f) @ fi
    torque = law.size * law.mu(relative_speed(c, f)) * math.hypot(p_aux[0], p_aux[1])
    return np.array([0.0, 0.0, torque]), np.array([0.0, 0.0, -torque])
