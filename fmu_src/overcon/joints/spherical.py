"""Spatial spherical joint (paper Eq. 41, B.13; friction App. A.9-A.18).

Phi = r_i + R_i s_i - r_j - R_j s_j (3 equations). Velocities h_k = [r_k' (global), omega_k
(body axes)]; the modified Jacobian blocks are [I, -R_i skew(s_i)] and [-I, R_j skew(s_j)].
Auxiliary frame: origin at the ball centre P, axes parallel to body i (A.10). Physical reaction
p' = [Fx, Fy, Fz] in body i axes (the moment about P is zero).

All functions are batched (k joints at once): see :mod:`overcon.joints`; the type's facts are
its entry in :data:`overcon.joints.TYPES`.

Friction (A.11-A.18): contact point s'_C = -rho F'/|F'| with F' taken from the left-hand-side
generalized reaction (f_X)_i = (J_X)_i lam_X (a project decision, see README: the paper's figures cannot
tell this side from the opposite one), sliding velocity v' = omega'_ij x s'_C with
omega'_ij = R_i^T R_j omega_j - omega_i, friction force F'_fr = mu(|v'|)|F'| v'/|v'| applied to
body i at C, and the opposite force on body j.
"""
from __future__ import annotations

import numpy as np

from ..kinematics import cross3_rows, matvec, rowdot, skew
from .point import constants, phi, stack_points  # noqa: F401  (point coincidence, Eq. 41)


_EYE = np.eye(3)
_NEG_EYE = -np.eye(3)


def stack(joints) -> dict:
    """Constant stacked arrays of a list of compiled spherical joints (done once at compile)."""
    d = stack_points(joints, 3)
    d["skew_i"] = np.array([skew(v) for v in d["s_i"]]).reshape(-1, 3, 3)
    d["skew_j"] = np.array([skew(v) for v in d["s_j"]]).reshape(-1, 3, 3)
    d["neg_size"] = np.array([-law.size if law is not None else np.nan for law in d["laws"]], float)
    return d


def jac_h(d, f):
    """(Ji, Jj), each (k, 3, 6): the modified Jacobian blocks [I, -R_i skew(s_i)] and
    [-I, R_j skew(s_j)]."""
    k = len(d["bi"])
    Ji = np.empty((k, 3, 6))
    Jj = np.empty((k, 3, 6))
    Ji[:, :, :3] = _EYE
    Jj[:, :, :3] = _NEG_EYE
    Ji[:, :, 3:] = np.matmul(-f.R[d["bi"]], d["skew_i"])
    Jj[:, :, 3:] = np.matmul(f.R[d["bj"]], d["skew_j"])
    return Ji, Jj


def gamma(d, f):
    """(k, 3): -R_i (w_i x (w_i x s_i)) + R_j (w_j x (w_j x s_j)) (Eq. 11)."""
    bi, bj = d["bi"], d["bj"]
    wi, wj = f.w[bi], f.w[bj]
    return (matvec(-f.R[bi], cross3_rows(wi, cross3_rows(wi, d["s_i"])))
            + matvec(f.R[bj], cross3_rows(wj, cross3_rows(wj, d["s_j"]))))


def reaction_transform(d, f):
    """(k, 3, 6): the force rows of A_i (Eq. A.10), F' = R_i^T F^(0); the moment row is
    identically zero and not reported."""
    RiT = f.R[d["bi"]].transpose(0, 2, 1)
    A = np.zeros((len(RiT), 3, 6))
    A[:, :, :3] = RiT
    return A


def reaction(d, f, fi):
    """(k, 3): the physical reaction [Fx, Fy, Fz] = -A_i fi in body i axes."""
    return -matvec(reaction_transform(d, f), fi)


def friction_setup(d, f, Ji=None):
    """Per-evaluation constants of :func:`friction` (frames only, not the reaction): R_i, R_i^T,
    omega'_ij = R_i^T R_j omega_j - omega_i and R_j^T R_i. ``Ji`` is not needed: the force part
    of (J_X)_i is the identity."""
    Ri, Rj = f.R[d["bi"]], f.R[d["bj"]]
    RiT = Ri.transpose(0, 2, 1)
    omega = matvec(RiT, matvec(Rj, f.w[d["bj"]])) - f.w[d["bi"]]
    return {"Ri": Ri, "RiT": RiT, "omega": omega, "Rji": np.matmul(Rj.transpose(0, 2, 1), Ri)}


def _friction_vector(d, ctx, lam):
    """(F'_fr, s'_C, nonzero) in body i axes (A.11-A.14), given the joints' multipliers lam
    (k, 3). (J_X)_i = [I, -R_i skew(s_i)], so the force part of fi = (J_X)_i^T lam is lam itself.
    ``nonzero`` is None when every reaction is non-zero, else the mask of those that are (the
    others get zero friction: no contact point)."""
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
    return F_fr, s_C, (nonzero if zero else None)


def friction_force(d, ctx, lam):
    """(k,): magnitude |F'_fr| of the friction force at the contact point C (N, >= 0): its
    direction is the sliding velocity of body j relative to body i at C, which has no fixed axis
    to sign it against."""
    F_fr, _, nonzero = _friction_vector(d, ctx, lam)
    out = np.sqrt(rowdot(F_fr, F_fr))
    if nonzero is not None:
        out[~nonzero] = 0.0
    return out


def friction(d, ctx, lam):
    """(Qi, Qj), each (k, 6): F'_fr applied to body i at C and its opposite on body j (A.15-A.18),
    given the joints' multipliers lam (k, 3)."""
    F_fr, s_C, nonzero = _friction_vector(d, ctx, lam)
    RiF = matvec(ctx["Ri"], F_fr)
    Rji = ctx["Rji"]
    Qi = np.concatenate((RiF, cross3_rows(d["s_i"] + s_C, F_fr)), 1)
    Qj = np.concatenate(
        (RiF, cross3_rows(d["s_j"], matvec(Rji, F_fr)) + matvec(Rji, cross3_rows(s_C, F_fr))), 1)
    np.negative(Qj, out=Qj)
    if nonzero is not None:
        Qi[~nonzero] = 0.0
        Qj[~nonzero] = 0.0
    return Qi, Qj


def _skew_rows(a):
    """(k, 3, 3): skew(a[k]) (skew(a) @ b = a x b)."""
    out = np.zeros(a.shape[:-1] + (3, 3))
    out[..., 0, 1], out[..., 0, 2] = -a[..., 2], a[..., 1]
    out[..., 1, 0], out[..., 1, 2] = a[..., 2], -a[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -a[..., 1], a[..., 0]
    return out


def friction_jacobian(d, ctx, lam):
    """(dQi, dQj), each (k, 6, 3): derivatives of :func:`friction`'s (Qi, Qj) by the joints'
    multipliers lam (k, 3), for the friction solve's Newton step (N per N, N.m per N). Chain of
    A.11-A.18: F' = R_i^T lam, s'_C = -rho F'/|F'|, v' = omega'_ij x s'_C, F'_fr = m(|v'|) |F'| v'
    with m = mu_over_speed; zero for a zero reaction (no contact point) and, for the speed
    term, at zero sliding speed."""
    F = matvec(ctx["RiT"], lam)
    norm = np.sqrt(rowdot(F, F))
    nonzero = norm != 0.0
    n = np.where(nonzero, norm, 1.0)
    u = F / n[:, None]
    neg_rho = d["neg_size"]  # -rho (negation is exact)
    s_C = neg_rho[:, None] * u
    proj = (_EYE - u[:, :, None] * u[:, None, :]) / n[:, None, None]
    dsC = neg_rho[:, None, None] * proj  # d s_C / d F'
    W = _skew_rows(ctx["omega"])
    v = cross3_rows(ctx["omega"], s_C)
    dv = np.matmul(W, dsC)
    speed = np.sqrt(rowdot(v, v))
    m = np.array([law.mu_over_speed(x) for law, x in zip(d["laws"], speed)])
    slope = np.array([law.mu_over_speed_slope(x) if x > 0.0 else 0.0 for law, x in zip(d["laws"], speed)])
    dspeed = np.matmul((v / np.where(speed > 0.0, speed, 1.0)[:, None])[:, None, :], dv)[:, 0]  # (k, 3)
    F_fr = (m * norm)[:, None] * v
    dFfr = ((slope * norm)[:, None, None] * v[:, :, None] * dspeed[:, None, :]
            + m[:, None, None] * v[:, :, None] * u[:, None, :] + (m * norm)[:, None, None] * dv)
    Ri, Rji = ctx["Ri"], ctx["Rji"]
    d_arm = -np.matmul(_skew_rows(F_fr), dsC)  # d(s_C x F_fr) by F' through s_C
    top = np.matmul(Ri, dFfr)
    dQi = np.concatenate((top, d_arm + np.matmul(_skew_rows(d["s_i"] + s_C), dFfr)), 1)
    dQj = -np.concatenate((top, np.matmul(d["skew_j"], np.matmul(Rji, dFfr))
                           + np.matmul(Rji, d_arm + np.matmul(_skew_rows(s_C), dFfr))), 1)
    RiT = ctx["RiT"]
    dQi, dQj = np.matmul(dQi, RiT), np.matmul(dQj, RiT)  # d F' / d lam = R_i^T
    if not nonzero.all():
        dQi[~nonzero] = 0.0
        dQj[~nonzero] = 0.0
    return dQi, dQj
