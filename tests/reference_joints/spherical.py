"""Per-joint reference (tests only): spatial spherical joint (paper Eq. 41, B.13; friction App. A.9-A.18).

The plain single-joint form of :mod:`overcon.joints.spherical` (see tests/reference_joints/__init__.py)."""
from __future__ import annotations

import numpy as np

from overcon.kinematics import cross3, euler_dR, skew
from .point import phi  # noqa: F401  (point coincidence, Eq. 36/41)


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
