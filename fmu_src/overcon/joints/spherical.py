"""Spatial spherical joint (paper Eq. 41, B.13; friction App. A.9-A.18).

Phi = r_i + R_i s_i - r_j - R_j s_j (3 equations). Velocities h_k = [r_k' (global), omega_k
(body axes)]; the modified Jacobian blocks are [I, -R_i skew(s_i)] and [-I, R_j skew(s_j)].
Auxiliary frame: origin at the ball centre P, axes parallel to body i (A.10). Physical reaction
p' = [Fx, Fy, Fz] in body i axes (the moment about P is zero).

Batched forms ``batch_*``: see :mod:`overcon.joints`.

Friction (A.11-A.18): contact point s'_C = -rho F'/|F'| with F' taken from the left-hand-side
generalized reaction (f_X)_i = (J_X)_i lam_X (a project decision, see README: the paper's figures cannot
tell this side from the opposite one), sliding velocity v' = omega'_ij x s'_C with
omega'_ij = R_i^T R_j omega_j - omega_i, friction force F'_fr = mu(|v'|)|F'| v'/|v'| applied to
body i at C, and the opposite force on body j.
"""
from __future__ import annotations

import numpy as np

from ..kinematics import cross3, cross3_rows, euler_dR, matvec, rowdot, skew
from .point import batch_phi, phi, prepare  # noqa: F401  (point coincidence, Eq. 36/41)

N_EQUATIONS = 3
REACTION_COMPONENTS = ("Fx", "Fy", "Fz")
FRICTION_UNIT = "N"  # friction_force: magnitude of the force at the contact point


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


def _friction_vector(c, f, fi, law):
    """(F'_fr, s'_C) in body i axes (A.11-A.14), or None when the reaction is zero."""
    F_aux = f.R[c.bi].T @ fi[:3]
    norm = np.linalg.norm(F_aux)
    if norm == 0.0:
        return None
    s_C = -law.size * F_aux / norm
    v_slip = cross3(_relative_omega(c, f), s_C)
    return law.mu_over_speed(np.linalg.norm(v_slip)) * norm * v_slip, s_C


def friction_force(c, f, fi, law) -> float:
    """Magnitude |F'_fr| of the friction force at the contact point C (N, >= 0): its direction is
    the sliding velocity of body j relative to body i at C, which has no fixed axis to sign it
    against."""
    fv = _friction_vector(c, f, fi, law)
    return 0.0 if fv is None else float(np.linalg.norm(fv[0]))


def friction(c, f, fi, law):
    Ri, Rj = f.R[c.bi], f.R[c.bj]
    fv = _friction_vector(c, f, fi, law)
    if fv is None:
        z = np.zeros(6)
        return z, z.copy()
    F_fr, s_C = fv
    torque_i = cross3(c.p["s_i"] + s_C, F_fr)
    Qi = np.concatenate([Ri @ F_fr, torque_i])
    Rji = Rj.T @ Ri
    torque_j = cross3(c.p["s_j"], Rji @ F_fr) + Rji @ cross3(s_C, F_fr)
    Qj = -np.concatenate([Ri @ F_fr, torque_j])
    return Qi, Qj


# ----------------------------------------------------------------------------- batched forms

_EYE = np.eye(3)
_NEG_EYE = -np.eye(3)


def batch_prepare(joints) -> dict:
    """Constant stacked arrays of a list of compiled spherical joints (done once at compile)."""
    s_i = np.array([c.p["s_i"] for c in joints], float).reshape(-1, 3)
    s_j = np.array([c.p["s_j"] for c in joints], float).reshape(-1, 3)
    laws = tuple(c.law for c in joints)
    return {
        "bi": np.array([c.bi for c in joints], np.intp), "bj": np.array([c.bj for c in joints], np.intp),
        "s_i": s_i, "s_j": s_j,
        "skew_i": np.array([skew(v) for v in s_i]).reshape(-1, 3, 3),
        "skew_j": np.array([skew(v) for v in s_j]).reshape(-1, 3, 3),
        "laws": laws,
        "neg_size": np.array([-law.size if law is not None else np.nan for law in laws], float),
    }


def batch_jac_h(d, f):
    """(Ji, Jj), each (k, 3, 6): :func:`jac_h` of every joint."""
    k = len(d["bi"])
    Ji = np.empty((k, 3, 6))
    Jj = np.empty((k, 3, 6))
    Ji[:, :, :3] = _EYE
    Jj[:, :, :3] = _NEG_EYE
    Ji[:, :, 3:] = np.matmul(-f.R[d["bi"]], d["skew_i"])
    Jj[:, :, 3:] = np.matmul(f.R[d["bj"]], d["skew_j"])
    return Ji, Jj


def batch_gamma(d, f):
    """(k, 3): :func:`gamma` of every joint."""
    bi, bj = d["bi"], d["bj"]
    wi, wj = f.w[bi], f.w[bj]
    return (matvec(-f.R[bi], cross3_rows(wi, cross3_rows(wi, d["s_i"])))
            + matvec(f.R[bj], cross3_rows(wj, cross3_rows(wj, d["s_j"]))))


def batch_friction_setup(d, f, Ji=None):
    """Per-evaluation constants of :func:`batch_friction` (frames only, not the reaction)."""
    Ri, Rj = f.R[d["bi"]], f.R[d["bj"]]
    RiT = Ri.transpose(0, 2, 1)
    omega = matvec(RiT, matvec(Rj, f.w[d["bj"]])) - f.w[d["bi"]]  # _relative_omega
    return {"Ri": Ri, "RiT": RiT, "omega": omega, "Rji": np.matmul(Rj.transpose(0, 2, 1), Ri)}


def batch_friction(d, ctx, lam):
    """(Qi, Qj), each (k, 6): :func:`friction` of every joint, given the joints' multipliers lam
    (k, 3). (J_X)_i = [I, -R_i skew(s_i)], so the force part of fi = (J_X)_i^T lam is lam itself."""
    F_aux = matvec(ctx["RiT"], lam)
    norm = np.sqrt(rowdot(F_aux, F_aux))
    zero = 0.0 in norm.tolist()
    if zero:  # those joints get zero forces, as in friction()
        nonzero = norm != 0.0
        norm = np.where(nonzero, norm, 1.0)
    s_C = d["neg_size"][:, None] * F_aux / norm[:, None]
    v_slip = cross3_rows(ctx["omega"], s_C)
    speed = np.sqrt(rowdot(v_slip, v_slip))
    if zero:
        mos = [law.mu_over_speed(v) if nz else 0.0 for law, v, nz in zip(d["laws"], speed, nonzero)]
    else:
        mos = [law.mu_over_speed(v) for law, v in zip(d["laws"], speed)]
    F_fr = (np.array(mos) * norm)[:, None] * v_slip
    RiF = matvec(ctx["Ri"], F_fr)
    Rji = ctx["Rji"]
    Qi = np.concatenate((RiF, cross3_rows(d["s_i"] + s_C, F_fr)), 1)
    Qj = np.concatenate(
        (RiF, cross3_rows(d["s_j"], matvec(Rji, F_fr)) + matvec(Rji, cross3_rows(s_C, F_fr))), 1)
    np.negative(Qj, out=Qj)
    if zero:
        Qi[~nonzero] = 0.0
        Qj[~nonzero] = 0.0
    return Qi, Qj
