"""Planar translational joint (paper Eq. 34; friction App. A.1-A.4).

Phi = [ (r_i + R_i s_A - r_j - R_j s_B)^T R_j v ;  phi_i - phi_j - psi ].

Auxiliary frame (decided here; the paper fixes it only for joint 1, B_i = I): origin at A on body
i, x' along the guide, y' along v. In body j axes the guide is ``OMEGA.T @ v/|v|`` (so v = [0, 1]
gives x' = +x); B_i is that frame expressed in body i axes (rotated by -psi). Physical reaction
p' = [Fx (along the guide, zero without friction), Fy = N (normal), T (moment about A)].
Friction (A.2): magnitude mu(v_ij) (|N - T/l| + |T/l|) along x', v_ij the sliding velocity of
body j relative to body i along x', l the slider length.

All functions are batched (k joints at once): see :mod:`overcon.joints`; the type's facts are
its entry in :data:`overcon.joints.TYPES`.
"""
from __future__ import annotations

import numpy as np

from ..kinematics import OMEGA, matvec, rot2, rowdot


ROW_KINDS = ("translational", "rotational")
"""Phi1 is the distance from the guide line (m), Phi2 the relative angle (rad)."""


def constants(params, init=None) -> dict:
    """One joint's constants: s_A, s_B, v, psi and the auxiliary frame B_i (in body i axes)
    (``init``, the initial frames, is not needed: psi fixes the relative angle)."""
    v = np.asarray(params["v"], float)
    psi = float(params.get("psi", 0.0))
    axis_j = OMEGA.T @ v / np.linalg.norm(v)
    axis_i = rot2(-psi) @ axis_j
    B = np.column_stack([axis_i, OMEGA @ axis_i])
    return {"s_A": np.asarray(params["s_A"], float), "s_B": np.asarray(params["s_B"], float),
            "v": v, "psi": psi, "B": B}


def stack(joints) -> dict:
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


def _geometry(d, f):
    """(R_i s_A, R_j s_B, r_i + R_i s_A - r_j - R_j s_B, R_j v), each (k, 2), once per evaluation
    (:meth:`overcon.evaluation.Frames.cached`; read-only by convention)."""
    return f.cached("translational.geometry", d, _compute_geometry)


def _compute_geometry(d, f):
    Ri, Rj = f.R[d["bi"]], f.R[d["bj"]]
    a_i = matvec(Ri, d["s_A"])
    b_j = matvec(Rj, d["s_B"])
    dd = f.r[d["bi"]] + a_i - f.r[d["bj"]] - b_j
    u = matvec(Rj, d["v"])
    return a_i, b_j, dd, u


def phi(d, f):
    """(k, 2): [(r_i + R_i s_A - r_j - R_j s_B) . R_j v, phi_i - phi_j - psi]."""
    _, _, dd, u = _geometry(d, f)
    out = np.empty((len(u), 2))
    out[:, 0] = rowdot(dd, u)
    out[:, 1] = f.phi[d["bi"]] - f.phi[d["bj"]] - d["psi"]
    return out


def jac_h(d, f):
    """(Ji, Jj), each (k, 2, 3): Phi_q = Phi_h (planar)."""
    a_i, b_j, dd, u = _geometry(d, f)
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



def gamma(d, f):
    """(k, 2): gamma of Eq. 11 (second derivative of Phi without the h' terms, negated)."""
    a_i, b_j, dd, u = _geometry(d, f)
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


def reaction_transform(d, f):
    """(k, 3, 3): A_i of Eq. (A.1), p' = [Fx', Fy', T_A] = A_i (f_X)_i; the moment of the force
    about A is T_A = T_O - (R_i s_A) x F."""
    Ri = f.R[d["bi"]]
    A = np.zeros((len(Ri), 3, 3))
    A[:, :2, :2] = np.matmul(d["B"].transpose(0, 2, 1), Ri.transpose(0, 2, 1))
    A[:, 2, :2] = -_omega(_geometry(d, f)[0])
    A[:, 2, 2] = 1.0
    return A


def friction_setup(d, f, Ji=None):
    """Per-evaluation constants of :func:`friction`: (J_X)_i, A_i, the contact point's arms
    from both body origins, the guide direction e and mu(v_ij)."""
    if Ji is None:
        Ji = jac_h(d, f)[0]
    bi, bj = d["bi"], d["bj"]
    Ri = f.R[bi]
    point = f.r[bi] + _geometry(d, f)[0]  # contact point A
    e = matvec(Ri, d["B"][:, :, 0])
    vel_j = f.v[bj] + _omega(point - f.r[bj]) * f.w[bj][:, None]  # sliding velocity of j relative to i along x'
    vel_i = f.v[bi] + _omega(point - f.r[bi]) * f.w[bi][:, None]
    speed = rowdot(vel_j - vel_i, e)
    return {"JiT": Ji.transpose(0, 2, 1), "A": reaction_transform(d, f), "e": e,
            "arm_i": point - f.r[bi], "arm_j": point - f.r[bj],
            "mu": np.array([law.coefficient(v) for law, v in zip(d["laws"], speed)], float)}


def reaction(d, f, fi):
    """(k, 3): the physical reaction [Fx, Fy, T] = -A_i fi in the auxiliary frame (Fx along the
    guide, zero without friction; Fy = N the normal force; T the moment about A)."""
    return -matvec(reaction_transform(d, f), fi)


def friction_force(d, ctx, lam):
    """(k,): friction force on body i along the guide x' (N), signed, positive along +x' (A.2):
    mu(v_ij) (|N - T/l| + |T/l|); it points the way body j slides relative to body i."""
    p_aux = matvec(ctx["A"], matvec(ctx["JiT"], lam))
    N, T, l = p_aux[:, 1], p_aux[:, 2], d["size"]
    magnitude = np.abs(N - T / l) + np.abs(T / l)
    return ctx["mu"] * magnitude


def friction(d, ctx, lam):
    """(Qi, Qj), each (k, 3): generalized friction forces (A.2-A.4), the force
    :func:`friction_force` along x' applied at A on body i (Q_i = C_i t_i) and its opposite on body
    j (Q_j = -C_j t_i), given the joints' multipliers lam (k, 2) (fi = (J_X)_i^T lam)."""
    F = friction_force(d, ctx, lam)[:, None] * ctx["e"]
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


def friction_jacobian(d, ctx, lam):
    """(dQi, dQj), each (k, 3, 2): derivatives of :func:`friction`'s (Qi, Qj) by the joints'
    multipliers lam (k, 2), for the friction solve's Newton step (N per N). The magnitude
    |N - T/l| + |T/l| is piecewise linear in lam; at a kink the derivative of the side where
    the argument is positive is taken (sign(0) = 0 there)."""
    P = np.matmul(ctx["A"], ctx["JiT"])  # (k, 3, 2): p_aux = P lam
    l = d["size"][:, None]
    PN, PT = P[:, 1], P[:, 2] / l
    p_aux = matvec(P, lam)
    N, T = p_aux[:, 1], p_aux[:, 2] / d["size"]
    dmag = np.sign(N - T)[:, None] * (PN - PT) + np.sign(T)[:, None] * PT  # (k, 2)
    dF = ctx["mu"][:, None] * dmag
    e, arm_i, arm_j = ctx["e"], ctx["arm_i"], ctx["arm_j"]
    ci = np.stack((e[:, 0], e[:, 1], arm_i[:, 0] * e[:, 1] - arm_i[:, 1] * e[:, 0]), 1)
    cj = np.stack((e[:, 0], e[:, 1], arm_j[:, 0] * e[:, 1] - arm_j[:, 1] * e[:, 0]), 1)
    return ci[:, :, None] * dF[:, None, :], -cj[:, :, None] * dF[:, None, :]
