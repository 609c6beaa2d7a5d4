"""Per-joint reference (tests only): planar revolute joint (paper Eq. 36; friction App. A.5-A.8).

The plain single-joint form of :mod:`overcon.joints.revolute` (see tests/reference_joints/__init__.py)."""
from __future__ import annotations

import math

import numpy as np

from overcon.kinematics import OMEGA
from .point import phi  # noqa: F401  (point coincidence, Eq. 36/41)


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
    return law.size * law.coefficient(relative_speed(c, f)) * math.hypot(p_aux[0], p_aux[1])


def friction(c, f, fi, law):
    """Friction torque (A.6-A.8): C_i = C_j = I."""
    torque = friction_force(c, f, fi, law)
    return np.array([0.0, 0.0, torque]), np.array([0.0, 0.0, -torque])
