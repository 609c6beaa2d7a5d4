"""Planar translational joint (paper Eq. 34; friction App. A.1-A.4).

Phi = [ (r_i + R_i s_A - r_j - R_j s_B)^T R_j v ;  phi_i - phi_j - psi ].

Auxiliary frame (decided here; the paper fixes it only for joint 1, B_i = I): origin at A on body
i, x' along the guide, y' along v. In body j axes the guide is ``OMEGA.T @ v/|v|`` (so v = [0, 1]
gives x' = +x); B_i is that frame expressed in body i axes (rotated by -psi). Physical reaction
p' = [Fx (along the guide, zero without friction), Fy = N (normal), T (moment about A)].
Friction (A.2): magnitude mu(v_ij) (|N - T/l| + |T/l|) along x', v_ij the sliding velocity of
body j relative to body i along x', l the slider length.

Batched forms ``batch_*``: see :mod:`overcon.joints`.
"""
from __future__ import annotations

import numpy as np

from ..kinematics import OMEGA, cross2, matvec, rot2, rowdot

N_EQUATIONS = 2
REACTION_COMPONENTS = ("Fx", "Fy", "T")
FRICTION_UNIT = "N"  # friction_force: force along the guide


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


def friction_force(c, f, fi, law) -> float:
    """Friction force on body i along the guide x' (N), signed: positive along +x' (A.2),
    mu(v_ij) (|N - T/l| + |T/l|); it points the way body j slides relative to body i."""
    p_aux = reaction_transform(c, f) @ fi
    N, T = p_aux[1], p_aux[2]
    l = law.size
    magnitude = abs(N - T / l) + abs(T / l)
    return law.mu(relative_speed(c, f)) * magnitude


def friction(c, f, fi, law):
    """Generalized friction forces (A.2-A.4): t_i = [mu(v) (|N - T/l| + |T/l|), 0, 0] in the
    auxiliary frame, applied at A; Q_i = C_i t_i, Q_j = -C_j t_i."""
    point, e = _contact(c, f)
    F = friction_force(c, f, fi, law) * e
    Qi = np.array([F[0], F[1], cross2(point - f.r[c.bi], F)])
    Qj = -np.array([F[0], F[1], cross2(point - f.r[c.bj], F)])
    return Qi, Qj


# ----------------------------------------------------------------------------- batched forms

def batch_prepare(joints) -> dict:
    """Constant stacked arrays of a list of compiled translational joints (done once at compile)."""
    laws = tuple(c.law for c in joints)
    return {
        "bi": np.array([c.bi for c in joints], np.intp), "bj": np.array([c.bj for c in joints], np.intp),
        "s_A": np.array([c.p["s_A"] for c in joints], float).reshape(-1, 2),
        "s_B": np.array([c.p["s_B"] for c in joints], float).reshape(-1, 2),
        "v": np.array([c.p["v"] for c in joints], float).reshape(-1, 2),
        "psi": np.array([c.p["psi"] for c in joints], float),
        "B": np.array([c.p["B"] for c in joints], float).reshape(-1, 2, 2),
        "laws": laws,
        "size": np.array([law.size if law is not None else np.nan for law in laws], float),
    }


def _omega(x):
    return matvec(OMEGA, x)


def _batch_geometry(d, f):
    Ri, Rj = f.R[d["bi"]], f.R[d["bj"]]
    a_i = matvec(Ri, d["s_A"])
    b_j = matvec(Rj, d["s_B"])
    dd = f.r[d["bi"]] + a_i - f.r[d["bj"]] - b_j
    u = matvec(Rj, d["v"])
    return a_i, b_j, dd, u


def batch_phi(d, f):
    """(k, 2): :func:`phi` of every joint."""
    _, _, dd, u = _batch_geometry(d, f)
    out = np.empty((len(u), 2))
    out[:, 0] = rowdot(dd, u)
    out[:, 1] = f.phi[d["bi"]] - f.phi[d["bj"]] - d["psi"]
    return out


def batch_jac_q(d, f):
    """(Ji, Jj), each (k, 2, 3): :func:`jac_q` of every joint."""
    a_i, b_j, dd, u = _batch_geometry(d, f)
    k = len(u)
    Ji = np.zeros((k, 2, 3))
    Jj = np.zeros((k, 2, 3))
    Ji[:, 0, :2] = u
    Ji[:, 0, 2] = rowdot(_omega(a_i), u)
    Ji[:, 1, 2] = 1.0
    Jj[:, 0, :2] = -u
    Jj[:, 0, 2] = rowdot(-_omega(b_j), u) + rowdot(dd, _omega(u))
    Jj[:, 1, 2] = -1.0
    return Ji, Jj


batch_jac_h = batch_jac_q


def batch_gamma(d, f):
    """(k, 2): :func:`gamma` of every joint."""
    a_i, b_j, dd, u = _batch_geometry(d, f)
    bi, bj = d["bi"], d["bj"]
    wi, wj = f.w[bi], f.w[bj]
    d_dot = f.v[bi] + _omega(a_i) * wi[:, None] - f.v[bj] - _omega(b_j) * wj[:, None]
    u_dot = _omega(u) * wj[:, None]
    wi2, wj2 = wi ** 2, wj ** 2
    quad = (rowdot(-a_i * wi2[:, None] + b_j * wj2[:, None], u) + rowdot(2.0 * d_dot, u_dot)
            - rowdot(dd, u) * wj2)
    out = np.zeros((len(u), 2))
    out[:, 0] = -quad
    return out


def batch_reaction_transform(d, f):
    """(k, 3, 3): :func:`reaction_transform` of every joint."""
    Ri = f.R[d["bi"]]
    A = np.zeros((len(Ri), 3, 3))
    A[:, :2, :2] = np.matmul(d["B"].transpose(0, 2, 1), Ri.transpose(0, 2, 1))
    A[:, 2, :2] = -_omega(matvec(Ri, d["s_A"]))
    A[:, 2, 2] = 1.0
    return A


def batch_friction_setup(d, f, Ji=None):
    """Per-evaluation constants of :func:`batch_friction`: (J_X)_i, A_i, the contact point's arms
    from both body origins, the guide direction e and mu(v_ij)."""
    if Ji is None:
        Ji = batch_jac_h(d, f)[0]
    bi, bj = d["bi"], d["bj"]
    Ri = f.R[bi]
    point = f.r[bi] + matvec(Ri, d["s_A"])  # _contact
    e = matvec(Ri, d["B"][:, :, 0])
    vel_j = f.v[bj] + _omega(point - f.r[bj]) * f.w[bj][:, None]  # relative_speed
    vel_i = f.v[bi] + _omega(point - f.r[bi]) * f.w[bi][:, None]
    speed = rowdot(vel_j - vel_i, e)
    return {"JiT": Ji.transpose(0, 2, 1), "A": batch_reaction_transform(d, f), "e": e,
            "arm_i": point - f.r[bi], "arm_j": point - f.r[bj],
            "mu": np.array([law.mu(v) for law, v in zip(d["laws"], speed)], float)}


def batch_friction(d, ctx, lam):
    """(Qi, Qj), each (k, 3): :func:`friction` of every joint, given the joints' multipliers lam
    (k, 2) (fi = (J_X)_i^T lam)."""
    p_aux = matvec(ctx["A"], matvec(ctx["JiT"], lam))
    N, T, l = p_aux[:, 1], p_aux[:, 2], d["size"]
    magnitude = np.abs(N - T / l) + np.abs(T / l)
    F = (ctx["mu"] * magnitude)[:, None] * ctx["e"]
    arm_i, arm_j = ctx["arm_i"], ctx["arm_j"]
    k = len(F)
    Qi = np.empty((k, 3))
    Qj = np.empty((k, 3))
    Qi[:, :2] = F
    Qi[:, 2] = arm_i[:, 0] * F[:, 1] - arm_i[:, 1] * F[:, 0]
    Qj[:, :2] = F
    Qj[:, 2] = arm_j[:, 0] * F[:, 1] - arm_j[:, 1] * F[:, 0]
    np.negative(Qj, out=Qj)
    return Qi, Qj
