"""Spatial spherical joint (paper Eq. 41, B.13; friction App. A.9-A.18).

Phi = r_i + R_i s_i - r_j - R_j s_j (3 equations). Velocities h_k = [r_k' (global), omega_k
(body axes)]; the modified Jacobian blocks are [I, -R_i skew(s_i)] and [-I, R_j skew(s_j)].
Auxiliary frame: origin at the ball centre P, axes parallel to body i (A.10). Physical reaction
p' = [Fx, Fy, Fz] in body i axes (the moment about P is zero).

Friction (A.11-A.18): contact point s'_C = -rho F'/|F'| with F' taken from the left-hand-side
generalized reaction (f_X)_i = (J_X)_i lam_X (a project decision, see README: the paper's figures cannot
tell this side from the opposite one), sliding velocity v' = omega'_ij x s'_C with
omega'_ij = R_i^T R_j omega_j - omega_i, friction force F'_fr = mu(|v'|)|F'| v'/|v'| applied to
body i at C, and the opposite force on body j.
"""
from __future__ import annotations

import numpy as np

from ..kinematics import cross3, euler_dR, skew

N_EQUATIONS = 3
REACTION_COMPONENTS = ("Fx", "Fy", "Fz")


def prepare(params) -> dict:
    return {"s_i": np.asarray(params["s_i"], float), "s_j": np.asarray(params["s_j"], float)}


def phi(c, f):
    return f.r[c.bi] + f.R[c.bi] @ c.p["s_i"] - f.r[c.bj] - f.R[c.bj] @ c.p["s_j"]


def _dpoint_dangles(angles, s):
    return np.column_stack([dR @ s for dR in euler_dR(angles)])


def jac_q(c, f):
    eye = np.eye(3)
    Ji = np.hstack([eye, _dpoint_dangles(f.angles[c.bi], c.p["s_i"])])
    Jj = np.hstack([-eye, -_dpoint_dangles(f.angles[c.bj], c.p["s_j"])])
    return Ji, Jj


def jac_h(c, f):
    eye = np.eye(3)
    Ji = np.hstack([eye, -f.R[c.bi] @ skew(c.p["s_i"])])
    Jj = np.hstack([-eye, f.R[c.bj] @ skew(c.p["s_j"])])
    return Ji, Jj


def gamma(c, f):
    wi, wj = f.w[c.bi], f.w[c.bj]
    si, sj = c.p["s_i"], c.p["s_j"]
    return -f.R[c.bi] @ cross3(wi, cross3(wi, si)) + f.R[c.bj] @ cross3(wj, cross3(wj, sj))


def reaction_transform(c, f):
    """Force rows of A_i (Eq. A.10): F' = R_i^T F^(0); the moment row is identically zero."""
    A = np.zeros((3, 6))
    A[:, :3] = f.R[c.bi].T
    return A


def _relative_omega(c, f):
    Ri, Rj = f.R[c.bi], f.R[c.bj]
    return Ri.T @ (Rj @ f.w[c.bj]) - f.w[c.bi]


def relative_speed(c, f, fi=None):
    """Sliding speed |v'| at the contact point (m/s); needs the reaction to place the contact."""
    if fi is None:
        return float(np.linalg.norm(_relative_omega(c, f)))
    F_aux = f.R[c.bi].T @ fi[:3]
    norm = np.linalg.norm(F_aux)
    if norm == 0.0:
        return 0.0
    return float(np.linalg.norm(cross3(_relative_omega(c, f), -F_aux / norm)))


def friction(c, f, fi, law):
    Ri, Rj = f.R[c.bi], f.R[c.bj]
    F_aux = Ri.T @ fi[:3]
    norm = np.linalg.norm(F_aux)
    if norm == 0.0:
        z = np.zeros(6)
        return z, z.copy()
    s_C = -law.size * F_aux / norm
    v_slip = cross3(_relative_omega(c, f), s_C)
    F_fr = law.mu_over_speed(np.linalg.norm(v_slip)) * norm * v_slip
    torque_i = cross3(c.p["s_i"] + s_C, F_fr)
    Qi = np.concatenate([Ri @ F_fr, torque_i])
    Rji = Rj.T @ Ri
    torque_j = cross3(c.p["s_j"], Rji @ F_fr) + Rji @ cross3(s_C, F_fr)
    Qj = -np.concatenate([Ri @ F_fr, torque_j])
    return Qi, Qj
