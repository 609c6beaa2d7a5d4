"""Planar translational joint (paper Eq. 34; friction App. A.1-A.4).

Phi = [ (r_i + R_i s_A - r_j - R_j s_B)^T R_j v ;  phi_i - phi_j - psi ].

Auxiliary frame (decided here; the paper fixes it only for joint 1, B_i = I): origin at A on body
i, x' along the guide, y' along v. In body j axes the guide is ``OMEGA.T @ v/|v|`` (so v = [0, 1]
gives x' = +x); B_i is that frame expressed in body i axes (rotated by -psi). Physical reaction
p' = [Fx (along the guide, zero without friction), Fy = N (normal), T (moment about A)].
Friction (A.2): magnitude mu(v_ij) (|N - T/l| + |T/l|) along x', v_ij the sliding velocity of
body j relative to body i along x', l the slider length.
"""
from __future__ import annotations

import numpy as np

from ..kinematics import OMEGA, cross2, rot2

N_EQUATIONS = 2
REACTION_COMPONENTS = ("Fx", "Fy", "T")


def prepare(params) -> dict:
    v = np.asarray(params["v"], float)
    psi = float(params.get("psi", 0.0))
    axis_j = OMEGA.T @ v / np.linalg.norm(v)
    axis_i = rot2(-psi) @ axis_j
    B = np.column_stack([axis_i, OMEGA @ axis_i])
    return {"s_A": np.asarray(params["s_A"], float), "s_B": np.asarray(params["s_B"], float),
            "v": v, "psi": psi, "B": B}


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


def friction(c, f, fi, law):
    """Generalized friction forces (A.2-A.4): t_i = [mu(v) (|N - T/l| + |T/l|), 0, 0] in the
    auxiliary frame, applied at A; Q_i = C_i t_i, Q_j = -C_j t_i."""
    p_aux = reaction_transform(c, f) @ fi
    N, T = p_aux[1], p_aux[2]
    l = law.size
    magnitude = abs(N - T / l) + abs(T / l)
    point, e = _contact(c, f)
    F = law.mu(relative_speed(c, f)) * magnitude * e
    Qi = np.array([F[0], F[1], cross2(point - f.r[c.bi], F)])
    Qj = -np.array([F[0], F[1], cross2(point - f.r[c.bj], F)])
    return Qi, Qj
