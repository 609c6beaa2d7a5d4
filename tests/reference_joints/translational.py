"""Per-joint reference (tests only): planar translational joint (paper Eq. 34; friction App. A.1-A.4).

The plain single-joint form of :mod:`overcon.joints.translational` (see tests/reference_joints/__init__.py)."""
from __future__ import annotations

import numpy as np

from overcon.kinematics import OMEGA, cross2


def _geometry(c, f):
    p = c.p
    Ri, Rj = f.R[c.bi], f.R[c.bj]
    a_i = Ri @ p["s_A"]
    b_j = Rj @ p["s_B"]
    d = f.r[c.bi] + a_i - f.r[c.bj] - b_j
    u = Rj @ p["v"]
    return a_i, b_j, d, u


def phi(c, f):
    _, _, d, u = _geometry(c, f)
    return np.array([d @ u, f.phi[c.bi] - f.phi[c.bj] - c.p["psi"]])


def jac_q(c, f):
    a_i, b_j, d, u = _geometry(c, f)
    Ji = np.array([[u[0], u[1], (OMEGA @ a_i) @ u], [0.0, 0.0, 1.0]])
    Jj = np.array([[-u[0], -u[1], -(OMEGA @ b_j) @ u + d @ (OMEGA @ u)], [0.0, 0.0, -1.0]])
    return Ji, Jj


jac_h = jac_q


def gamma(c, f):
    a_i, b_j, d, u = _geometry(c, f)
    wi, wj = f.w[c.bi], f.w[c.bj]
    d_dot = f.v[c.bi] + OMEGA @ a_i * wi - f.v[c.bj] - OMEGA @ b_j * wj
    u_dot = OMEGA @ u * wj
    quad = (-a_i * wi**2 + b_j * wj**2) @ u + 2.0 * d_dot @ u_dot - d @ u * wj**2
    return np.array([-quad, 0.0])


def reaction_transform(c, f):
    """A_i of Eq. (A.1): p' = [Fx', Fy', T_A] = A_i (f_X)_i."""
    Ri = f.R[c.bi]
    A = np.zeros((3, 3))
    A[:2, :2] = c.p["B"].T @ Ri.T
    A[2, :2] = -(OMEGA @ (Ri @ c.p["s_A"]))  # moment of the force about A: T_A = T_O - (R s_A) x F
    A[2, 2] = 1.0
    return A


def _contact(c, f):
    Ri = f.R[c.bi]
    point = f.r[c.bi] + Ri @ c.p["s_A"]
    e = Ri @ c.p["B"][:, 0]
    return point, e


def relative_speed(c, f):
    """Sliding velocity of body j relative to body i along x' (m/s)."""
    point, e = _contact(c, f)
    vel_j = f.v[c.bj] + OMEGA @ (point - f.r[c.bj]) * f.w[c.bj]
    vel_i = f.v[c.bi] + OMEGA @ (point - f.r[c.bi]) * f.w[c.bi]
    return (vel_j - vel_i) @ e


def friction_force(c, f, fi, law) -> float:
    """Friction force on body i along the guide x' (N), signed: positive along +x' (A.2),
    mu(v_ij) (|N - T/l| + |T/l|); it points the way body j slides relative to body i."""
    p_aux = reaction_transform(c, f) @ fi
    N, T = p_aux[1], p_aux[2]
    l = law.size
    magnitude = abs(N - T / l) + abs(T / l)
    return law.coefficient(relative_speed(c, f)) * magnitude


def friction(c, f, fi, law):
    """Generalized friction forces (A.2-A.4): t_i = [mu(v) (|N - T/l| + |T/l|), 0, 0] in the
    auxiliary frame, applied at A; Q_i = C_i t_i, Q_j = -C_j t_i."""
    point, e = _contact(c, f)
    F = friction_force(c, f, fi, law) * e
    Qi = np.array([F[0], F[1], cross2(point - f.r[c.bi], F)])
    Qj = -np.array([F[0], F[1], cross2(point - f.r[c.bj], F)])
    return Qi, Qj
